//! The seam where a machine computes an Occlusion Unit and its OccU Control (the O2's one,
//! every InfiniteReality Image Engine's own): either the event-timestamp model
//! ([`crate::blocks::occlusion_unit`], [`crate::blocks::occu_control`]) or the clocked register-transfer
//! model of `occsim-rtl` ([`crate::blocks::rtl_occu`]). Both follow the timing rules of
//! [`crate::machines::o2`] (records to memory at the end, [`OccuStage::end`]) or of
//! [`crate::blocks::image_engine`] (hit words only; the partial report to the merge network,
//! [`OccuStage::partial_report`]) and produce the same cycles and results.

use crate::arch::{IrArch, O2Arch};
use crate::blocks::memory_port::MemoryPort;
use crate::blocks::occlusion_unit::OcclusionUnit;
use crate::blocks::occlusion_unit::{OccuStats, SharedLocatedTiles};
use crate::blocks::occu_control::OccuControl;
use crate::blocks::rtl_occu::RtlOccu;
use crate::blocks::waveform::WaveformOptions;
use occsim_traces::{Fragment, QuerySpec, TileResult};

/// How the Occlusion Unit and OccU Control are modelled.
#[derive(Default)]
pub enum OccuModel {
    /// Event timestamps per fragment (the `cycle` fidelity).
    #[default]
    Cycle,
    /// The `occsim-rtl` register-transfer model, clocked cycle by cycle (the `rtl`
    /// fidelity), optionally dumping a waveform.
    Rtl { waveform: Option<WaveformOptions> },
}

// The cycle variant is the hot path and stays inline; the rtl one is boxed.
#[allow(clippy::large_enum_variant)]
pub enum OccuStage {
    Cycle {
        occu: OcclusionUnit,
        control: OccuControl,
    },
    Rtl(Box<RtlOccu>),
}

impl OccuStage {
    pub fn new(arch: &O2Arch, model: OccuModel) -> OccuStage {
        match model {
            OccuModel::Cycle => OccuStage::Cycle {
                occu: OcclusionUnit::new(arch),
                control: OccuControl::new(arch.occu.occu_write_buffer_words),
            },
            OccuModel::Rtl { waveform } => OccuStage::Rtl(Box::new(RtlOccu::new(arch, waveform))),
        }
    }

    /// The unit of one InfiniteReality Image Engine.
    pub fn for_image_engine(arch: &IrArch, model: OccuModel) -> OccuStage {
        match model {
            OccuModel::Cycle => OccuStage::Cycle {
                occu: OcclusionUnit::with_engines(
                    arch.occu.engines,
                    arch.occu.all_tiles_one_cycle,
                    arch.counter_max(),
                ),
                control: OccuControl::new(arch.occu.occu_write_buffer_words),
            },
            OccuModel::Rtl { waveform } => {
                OccuStage::Rtl(Box::new(RtlOccu::for_image_engine(arch, waveform)))
            }
        }
    }

    pub fn begin(&mut self, spec: &QuerySpec) {
        match self {
            OccuStage::Cycle { occu, .. } => occu.begin(spec),
            OccuStage::Rtl(rtl) => rtl.begin(spec),
        }
    }

    /// [`Self::begin`] for query `generation`, its located tiles shared with the other
    /// units through `shared` ([`SharedLocatedTiles`]; the register-transfer model locates
    /// its own).
    pub fn begin_sharing(
        &mut self,
        spec: &QuerySpec,
        shared: &mut SharedLocatedTiles,
        generation: u64,
    ) {
        match self {
            OccuStage::Cycle { occu, .. } => occu.begin_sharing(spec, Some((shared, generation))),
            OccuStage::Rtl(rtl) => rtl.begin(spec),
        }
    }

    /// One fragment, readable from `ready` (depth test cycle + 1): returns the cycle it
    /// starts in the unit (`o_i`, when it leaves the FIFO). `verbose_hit_writes` is the
    /// effect hook ([`crate::effects`]): without verbose queries no fragment sends hit words,
    /// and the cycle model skips OccU Control's hit path.
    #[inline]
    pub fn fragment(
        &mut self,
        fragment: Fragment,
        passed: bool,
        ready: u64,
        query_open: bool,
        port: &mut MemoryPort,
        verbose_hit_writes: bool,
    ) -> u64 {
        match self {
            OccuStage::Cycle { occu, control } => {
                let (start, hit_words) = occu.fragment(fragment, passed, ready, query_open);
                let counted = start + occu.service_cycles() - 1;
                let leave = if verbose_hit_writes {
                    control.hits(hit_words, counted, port)
                } else {
                    debug_assert_eq!(hit_words, 0, "verbose_hit_writes off, yet hits");
                    counted
                };
                occu.complete(start, leave, query_open);
                start
            }
            OccuStage::Rtl(rtl) => rtl.fragment(fragment, passed, ready, port),
        }
    }

    /// The event-timestamp Occlusion Unit, at the cycle fidelity (None at the rtl one, which
    /// clocks every fragment): what a fast-forward counts and times in bulk.
    pub fn cycle_unit(&mut self) -> Option<&mut OcclusionUnit> {
        match self {
            OccuStage::Cycle { occu, .. } => Some(occu),
            OccuStage::Rtl(_) => None,
        }
    }

    /// First cycle the unit is free.
    pub fn free_cycle(&self) -> u64 {
        match self {
            OccuStage::Cycle { occu, .. } => occu.free_cycle(),
            OccuStage::Rtl(rtl) => rtl.free_cycle(),
        }
    }

    /// The query's end token, through the depth pipeline in `through_depth`: returns the
    /// tiles' results, the cycle the result is available and the overflowed buffers.
    pub fn end(
        &mut self,
        spec: &QuerySpec,
        through_depth: u64,
        port: &mut MemoryPort,
    ) -> (Vec<TileResult>, u64, u32) {
        match self {
            OccuStage::Cycle { occu, control } => {
                let through_occu = (through_depth + 1).max(occu.free_cycle());
                let mut tiles = occu.end(spec.tiles.len());
                let (available, overflowed) =
                    control.records(spec, &mut tiles, through_occu + 1, port);
                (tiles, available, overflowed)
            }
            OccuStage::Rtl(rtl) => rtl.end(spec, through_depth, port),
        }
    }

    /// The loaded query's end token at an Image Engine, once its last fragment has left:
    /// the tiles' partial results for the merge network (no record is written).
    pub fn partial_report(&mut self, tiles: usize) -> Vec<TileResult> {
        match self {
            OccuStage::Cycle { occu, .. } => occu.end(tiles),
            OccuStage::Rtl(rtl) => rtl.partial_report(),
        }
    }

    /// The port grant of the last word OccU Control wrote (`None` before any).
    pub fn last_grant(&self) -> Option<u64> {
        match self {
            OccuStage::Cycle { control, .. } => {
                (control.words_written() > 0).then(|| control.last_grant())
            }
            OccuStage::Rtl(rtl) => rtl.last_grant(),
        }
    }

    /// End of the stream: the statistics (the RTL drains and closes its waveform).
    pub fn finish(&mut self) -> Result<OccuStats, crate::error::SimError> {
        Ok(match self {
            OccuStage::Cycle { occu, control } => OccuStats {
                busy_cycles: occu.busy_cycles,
                stall_cycles: occu.stall_cycles,
                engines: occu
                    .engines
                    .iter()
                    .map(|e| (e.busy_cycles, e.stall_cycles))
                    .collect(),
                words_written: control.words_written(),
                port_cycles: control.port_cycles(),
            },
            OccuStage::Rtl(rtl) => rtl.finish()?,
        })
    }
}
