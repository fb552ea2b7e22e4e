//! A machine model of whichever kind the architecture names: the one entry point the command
//! line, sweeps and latency reports replay traces through.

pub mod ir;
pub mod o2;

use crate::arch::{Arch, Machine};
use crate::blocks::occu_stage::OccuModel;
use crate::effects::Effects;
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

impl MachineModel {
    /// Build the machine `arch` describes for a `width` x `height` viewport.
    pub fn new(arch: &Arch, width: u32, height: u32) -> Result<MachineModel, SimError> {
        MachineModel::with_effects(arch, width, height, Effects::ALL)
    }

    /// The machine building only `effects` ([`crate::effects`]; a scan must have proved the
    /// others unobservable on the stream it will replay).
    pub fn with_effects(
        arch: &Arch,
        width: u32,
        height: u32,
        effects: Effects,
    ) -> Result<MachineModel, SimError> {
        Ok(match arch.machine() {
            Machine::O2 => MachineModel::O2(O2Machine::with_effects(arch, width, height, effects)?),
            Machine::Ir => MachineModel::Ir(IrMachine::with_effects(arch, width, height, effects)?),
        })
    }

    /// Build the machine with its Occlusion Unit modelled as `occu` says (the `cycle` and
    /// `rtl` fidelity levels).
    pub fn with_occu_model(
        arch: &Arch,
        width: u32,
        height: u32,
        occu: OccuModel,
    ) -> Result<MachineModel, SimError> {
        Ok(match arch.machine() {
            Machine::O2 => MachineModel::O2(O2Machine::with_occu_model(arch, width, height, occu)?),
            Machine::Ir => MachineModel::Ir(IrMachine::with_occu_model(arch, width, height, occu)?),
        })
    }

    /// The machine building only `effects` that starts from a functional model's render
    /// state and depths (the sampled level's machines, started mid-stream). `storage`, a
    /// buffer a finished machine handed back ([`Self::finish_recycling`]), is reused for the
    /// copy of `depth` when given.
    pub fn resume(
        arch: &Arch,
        effects: Effects,
        state: &RenderState,
        depth: &DepthBuffer,
        storage: Option<DepthBuffer>,
    ) -> Result<MachineModel, SimError> {
        let (width, height) = (state.width, state.height);
        let copy = match storage {
            Some(mut storage) => {
                storage.copy_from(depth);
                storage
            }
            None => depth.clone(),
        };
        Ok(match arch.machine() {
            Machine::O2 => MachineModel::O2(O2Machine::resume(
                arch, width, height, effects, state, copy,
            )?),
            Machine::Ir => MachineModel::Ir(IrMachine::resume(
                arch, width, height, effects, state, copy,
            )?),
        })
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
