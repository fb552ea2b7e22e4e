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
    /// Each query's report keeps every tile's (else the tiles' totals only).
    pub(crate) tile_reports: bool,
}

impl<'a> MachineBuilder<'a> {
    /// Every effect modelled, the OccU at the cycle level.
    pub fn new(arch: &'a Arch) -> MachineBuilder<'a> {
        MachineBuilder {
            arch,
            effects: Effects::ALL,
            occu: OccuModel::Cycle,
            timeline: None,
            tile_reports: true,
        }
    }

    /// Keep each query's tile totals only, not every tile's report: what a level's result
    /// takes, so that memory follows the queries, not their tiles (300 queries of 65,536
    /// tiles each had taken the cycle level 1.1 GB where the functional level takes 17 MB).
    pub fn totals_only(self) -> MachineBuilder<'a> {
        MachineBuilder {
            tile_reports: false,
            ..self
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
