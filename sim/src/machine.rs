//! A machine model of whichever kind the architecture names: the one entry point the command
//! line, sweeps and latency reports replay traces through.

use crate::arch::{Arch, Machine};
use crate::error::SimError;
use crate::o2::O2Machine;
use crate::occu_stage::OccuModel;
use crate::report::Report;
use occsim_traces::Event;

/// A machine being replayed.
pub enum MachineModel {
    O2(O2Machine),
}

impl MachineModel {
    /// Build the machine `arch` describes for a `width` x `height` viewport.
    pub fn new(arch: &Arch, width: u32, height: u32) -> Result<MachineModel, SimError> {
        Ok(match arch.machine() {
            Machine::O2 => MachineModel::O2(O2Machine::new(arch, width, height)?),
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
        })
    }

    /// Replay one event.
    #[inline]
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        match self {
            MachineModel::O2(machine) => machine.event(event),
        }
    }

    /// End the replay and report.
    pub fn finish(self) -> Result<Report, SimError> {
        match self {
            MachineModel::O2(machine) => machine.finish(),
        }
    }
}
