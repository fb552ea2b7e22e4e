//! How a machine is to be built: the architecture, the effect models and the Occlusion
//! Unit's fidelity ([`MachineBuilder`]). The machines read it in their one constructor; the
//! building itself (`build`, `resume`, `o2`, `ir`) is in [`crate::machines`].

use crate::arch::Arch;
use crate::blocks::occu_stage::OccuModel;
use crate::effects::Effects;
use crate::timeline::Timeline;

/// The one way to build a machine: the architecture (which names the machine), the effect
/// models to build, the Occlusion Unit's fidelity, then a viewport at reset or a warm start.
///
/// ```
/// # use occsim_sim::{Arch, MachineBuilder, MachineModel, OccuModel};
/// let arch = Arch::builtin("ir4").unwrap();
/// let rtl = MachineBuilder::new(&arch)
///     .occu(OccuModel::Rtl { waveform: None })
///     .build(640, 480)
///     .unwrap();
/// # let _ = rtl;
/// ```
pub struct MachineBuilder<'a> {
    pub(crate) arch: &'a Arch,
    pub(crate) effects: Effects,
    pub(crate) occu: OccuModel,
    pub(crate) timeline: Option<Timeline>,
}

impl<'a> MachineBuilder<'a> {
    /// Every effect modelled, the OccU at the cycle level.
    pub fn new(arch: &'a Arch) -> MachineBuilder<'a> {
        MachineBuilder {
            arch,
            effects: Effects::ALL,
            occu: OccuModel::Cycle,
            timeline: None,
        }
    }

    /// Build only `effects` ([`crate::effects`]; a scan must have proved the others
    /// unobservable on the stream the machine will replay).
    pub fn effects(self, effects: Effects) -> MachineBuilder<'a> {
        MachineBuilder { effects, ..self }
    }

    /// Model every Occlusion Unit as `occu` says (the `cycle` and `rtl` fidelity levels).
    pub fn occu(self, occu: OccuModel) -> MachineBuilder<'a> {
        MachineBuilder { occu, ..self }
    }

    /// Report the blocks' busy and stall intervals to `timeline` ([`crate::timeline`]).
    pub fn timeline(self, timeline: Timeline) -> MachineBuilder<'a> {
        MachineBuilder {
            timeline: Some(timeline),
            ..self
        }
    }
}
