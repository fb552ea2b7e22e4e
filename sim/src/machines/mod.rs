//! A machine model of whichever kind the architecture names: the one entry point the command
//! line, sweeps and latency reports replay traces through.

pub mod builder;
pub mod ir;
pub mod o2;

pub use builder::MachineBuilder;

use crate::arch::{Arch, Machine};
use crate::error::SimError;
use crate::machines::ir::IrMachine;
use crate::machines::o2::O2Machine;
use crate::report::Report;
use occsim_traces::golden::DepthBuffer;
use occsim_traces::state::RenderState;
use occsim_traces::Event;

/// A machine being replayed.
// One per replay, never in a collection: boxing would only add an indirection per event.
#[allow(clippy::large_enum_variant)]
pub enum MachineModel {
    O2(O2Machine),
    Ir(IrMachine),
}

impl<'a> MachineBuilder<'a> {
    /// The machine at reset for a `width` x `height` viewport.
    pub fn build(self, width: u32, height: u32) -> Result<MachineModel, SimError> {
        Ok(match self.arch.machine() {
            Machine::O2 => MachineModel::O2(self.o2(width, height)?),
            Machine::Ir => MachineModel::Ir(self.ir(width, height)?),
        })
    }

    /// The machine started from a functional model's render state and depths (the sampled
    /// level's machines, started mid-stream). `storage`, a buffer a finished machine handed
    /// back ([`MachineModel::finish_recycling`]), is reused for the copy of `depth` when
    /// given.
    pub fn resume(
        self,
        state: &RenderState,
        depth: &DepthBuffer,
        storage: Option<DepthBuffer>,
    ) -> Result<MachineModel, SimError> {
        let (width, height) = (state.width, state.height);
        crate::error::check_viewport(width, height)?;
        let copy = match storage {
            Some(mut storage) => {
                storage.copy_from(depth);
                storage
            }
            None => depth.clone(),
        };
        Ok(match self.arch.machine() {
            Machine::O2 => {
                MachineModel::O2(O2Machine::assemble(self, width, height, copy, Some(state))?)
            }
            Machine::Ir => {
                MachineModel::Ir(IrMachine::assemble(self, width, height, copy, Some(state))?)
            }
        })
    }

    /// The O2-like machine at reset (an error when the architecture names another).
    pub fn o2(self, width: u32, height: u32) -> Result<O2Machine, SimError> {
        crate::error::check_viewport(width, height)?;
        O2Machine::assemble(self, width, height, DepthBuffer::new(width, height), None)
    }

    /// The InfiniteReality-like machine at reset (an error when the architecture names
    /// another).
    pub fn ir(self, width: u32, height: u32) -> Result<IrMachine, SimError> {
        self.arch.ir()?;
        crate::error::check_viewport(width, height)?;
        IrMachine::assemble(self, width, height, DepthBuffer::new(width, height), None)
    }
}

impl MachineModel {
    /// The machine `arch` describes at reset: shorthand for [`MachineBuilder::build`] with
    /// every effect modelled and the OccU at the cycle level.
    pub fn new(arch: &Arch, width: u32, height: u32) -> Result<MachineModel, SimError> {
        MachineBuilder::new(arch).build(width, height)
    }

    /// [`Self::finish`], handing the depth buffer's memory back for reuse.
    pub fn finish_recycling(self) -> Result<(Report, DepthBuffer), SimError> {
        match self {
            MachineModel::O2(machine) => machine.finish_recycling(),
            MachineModel::Ir(machine) => machine.finish_recycling(),
        }
    }

    /// Replay one event.
    #[inline]
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        match self {
            MachineModel::O2(machine) => machine.event(event),
            MachineModel::Ir(machine) => machine.event(event),
        }
    }

    /// End the replay and report.
    pub fn finish(self) -> Result<Report, SimError> {
        match self {
            MachineModel::O2(machine) => machine.finish(),
            MachineModel::Ir(machine) => machine.finish(),
        }
    }
}
