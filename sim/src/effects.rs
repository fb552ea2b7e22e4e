//! Only the effects a scene calls for: which of the cycle model's effect models a trace can
//! observe, decided before the replay from three facts about the trace ([`TraceFacts`]):
//! whether a query is verbose, the most tiles a query has, and whether a fragment can write
//! depth. A trace file's header records them (`occsim trace gen` writes them back when it
//! finishes), so deciding costs nothing; a trace without them (streamed to a pipe, or
//! written by an older version) is scanned first.
//!
//! An effect is switched off only when a rule proves that its model cannot change any
//! result, any cycle, or any statistic of the report on this trace; everything else stays on.
//! Fast-forward (below) takes bulk paths only where its rule holds. So `--effects all` and
//! the automatic choice give the same report, bit for bit (the tests check this on every
//! built-in trace and on random streams, `sim/tests/fast_forward.rs` with and without
//! fast-forward, and debug builds assert each rule at the hook that relies on it).
//!
//! Rules (a trace is scanned in order, with the render state it sets):
//! - `verbose_hit_writes`: on iff some query is verbose. Without one the engines send no hit
//!   words, so OccU Control's per-fragment hit path is skipped.
//! - `multi_tile_serialisation`: on iff some query has more tiles than the machine has
//!   engines (and `all_tiles_one_cycle` is off). Otherwise every fragment costs the OccU one
//!   cycle; reported, but the OccU computes its service time once per query, so nothing per
//!   fragment is skipped.
//! - `depth_write_traffic`: on iff some fragment arrives while the depth test and depth
//!   writes are on and no occlusion-render-mode query (brief, verbose) is open: only such a
//!   fragment can write depth. Otherwise the depth pipeline skips the write-buffer path.
//! - `page_model`: on unless the viewport lies inside one framebuffer tile (page). Then every
//!   depth read is in page 0: the first read is a page miss and every later one a page hit,
//!   which the prefetch knows without computing pages.
//! - On the InfiniteReality-like machine the same scan decides `verbose_hit_writes` (every
//!   Image Engine's OccU Control skips its hit path) and `multi_tile_serialisation`; that
//!   machine has no depth-write traffic or page model, so they are never active there. Its
//!   tile merges are always observable: every query's latency runs through them.
//!
//! # Fast-forward
//! `fast_forward` is no effect model but a shortcut the automatic choice takes (on a
//! retiled trace too) and `--effects all`, the exact reference, does not: the O2's cycle
//! model takes a span of fragments (a row run, as traces hand them on) in bulk where a rule,
//! checked as the replay goes, proves the bulk path gives what the fragments one by one give
//! ([`crate::machines::o2::O2Machine::span`]; `replay` reports how many fragments it took).
//! The sampled level's machines fast-forward too (they take the trace's spans whole, up to
//! a cool-down's end). A replay with a timeline or at the rtl fidelity (which clock or
//! record every fragment) takes fragments one by one. So does, in its timing, the
//! InfiniteReality-like machine ([`crate::machines::ir::IrMachine::span`] takes a span's
//! depth tests and interleave units at once, then times each fragment as one by one):
//! under its columns interleave a row's fragments go to as many Image Engines, one each,
//! so timing each at its own engine's FIFO, depth stage and Occlusion Unit is the work
//! itself; no rule here proves a stretch of them closed-form, and it fast-forwards nothing.
//!
//! A span is fast-forwarded when nothing records the blocks' intervals, the Occlusion Unit is
//! the event-timestamp one, the lookahead window (the fragments the front end let in that the
//! back end has not tested) holds fragments only, no verbose query is open and the span lies
//! inside the viewport. Then, with the rules of [`crate::machines::o2`]:
//! 1. Depth tests and counts. The span's depth tests are taken at once as it enters, after
//!    those of the queued fragments not yet taken. Nothing but fragments is queued, so each
//!    fragment meets the render state and the query it would meet when the back end reached
//!    it, in the same order; a span's pixels are distinct, so testing them all before
//!    writing any gives the one-by-one outcomes ([`occsim_traces::golden::DepthBuffer`]).
//!    Without a verbose query no hit word is sent, and a tile's counters, box and depth range
//!    do not depend on the order of its fragments (a counter saturating at `max` after `m`
//!    steps is `min(c + m, max)`), so the span is counted in every tile at once.
//! 2. Timing. The units of work are those of the one-by-one path, in its order: the back
//!    end's oldest fragment, then the front end's next. A unit is timed by the rules one by
//!    one, except in a *lockstep run*: from a unit where the rasterizer is free from `a`, the
//!    depth test from `d`, the Occlusion Unit from `o` with a one-cycle service (`s = 1`), and
//!    the last depth request was in `r` (`q = max(a + 1, r + 1)`), unit `u` of the run emits
//!    in `a + u`, requests in `q + u`, tests in `d + u` and starts in the unit in
//!    `max(d + 1, o) + u`, when
//!    - (L1) the fragment it tests was readable, with its depth data, by `d + u`, and, if it
//!      writes, the write buffer has a slot by `d + u`;
//!    - (L2) the depth-to-OccU FIFO (`C2` entries) has a slot by `d + u`: for `u < C2` from the
//!      departures recorded before the run, after that when `o <= d + C2`;
//!    - (L3) the rasterizer FIFO (`C`) has a slot by `a + u`: for `u < C - L` (`L` the
//!      lookahead) from the departures recorded, after that when `d <= a + C - L`;
//!    - (L4) the prefetch slots (`P`) free one by `q + u`: for `u < P - L` recorded, after
//!      that when `d <= q + P - L`.
//!
//!    Proof, by induction on `u`: the slot a unit waits for is the departure of the fragment
//!    `capacity` places earlier, recorded before the run (checked) or the run's own unit
//!    `u - (capacity - L)` (for the depth-to-OccU FIFO `u - C2`), whose departure the
//!    induction gives in closed form, so (L2)-(L4) bound every slot. Then every `max` of
//!    rules 1-4 takes its "one cycle after the last" term: `a_u = a + u`, `q_u = q + u`,
//!    `d_u = d + u`, `o_u = max(d + 1, o) + u`, and each fragment leaves the unit as it is
//!    done counting (no hit word). No cycle is a stall, so the blocks' busy counts grow by
//!    the run's units and their stall counts by nothing, and the FIFOs record consecutive
//!    departures (only their last `capacity` can be read again). The port's requests (the
//!    tested fragment's writes, then the entering fragment's depth read if its word is not
//!    the last read's; the others are word hits) are made exactly, in the one-by-one order,
//!    with the same ready cycles, so the port, the prefetch's page state and every statistic
//!    come out the same. Each unit is checked before any of its requests is made, so a run
//!    stops where the rule fails with every block's state that of the units it took, and the
//!    next unit is timed one by one. The checks cost the FIFOs' capacities a run and a few
//!    comparisons a unit.

use crate::arch::{Arch, IrArch, Machine, O2Arch};
use crate::error::SimError;
use occsim_traces::trace::TraceFeatures;
use occsim_traces::{Event, QueryMode};
use serde::Serialize;

/// Which effect models the cycle model builds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Effects {
    /// Verbose hit-list writes from the engines through OccU Control.
    pub verbose_hit_writes: bool,
    /// A fragment occupying the OccU one cycle per tile an engine holds (tiles > engines).
    pub multi_tile_serialisation: bool,
    /// Depth writes through the depth write buffer to the memory port.
    pub depth_write_traffic: bool,
    /// The prefetch's page-hit / page-miss latency distinction.
    pub page_model: bool,
    /// Spans of fragments may be fast-forwarded in bulk where the fast-forward rule (module
    /// docs) proves it exact. Not an effect model but a shortcut: off under `--effects all`,
    /// the exact reference, and not listed among the active effects.
    #[serde(skip)]
    pub fast_forward: bool,
}

impl Effects {
    /// Every effect model on (`--effects all`).
    pub const ALL: Effects = Effects {
        verbose_hit_writes: true,
        multi_tile_serialisation: true,
        depth_write_traffic: true,
        page_model: true,
        fast_forward: false,
    };

    /// Every effect model `machine` has (`--effects all`): the InfiniteReality-like machine
    /// models no depth-write traffic and no pages.
    pub fn every_model_of(machine: Machine) -> Effects {
        match machine {
            Machine::O2 => Effects::ALL,
            Machine::Ir => Effects {
                depth_write_traffic: false,
                page_model: false,
                ..Effects::ALL
            },
        }
    }

    /// The effects on in both.
    fn and(self, other: Effects) -> Effects {
        Effects {
            verbose_hit_writes: self.verbose_hit_writes && other.verbose_hit_writes,
            multi_tile_serialisation: self.multi_tile_serialisation
                && other.multi_tile_serialisation,
            depth_write_traffic: self.depth_write_traffic && other.depth_write_traffic,
            page_model: self.page_model && other.page_model,
            fast_forward: self.fast_forward && other.fast_forward,
        }
    }

    /// `(name, active)` pairs in a fixed order, for reports.
    pub fn list(&self) -> [(&'static str, bool); 4] {
        [
            ("verbose_hit_writes", self.verbose_hit_writes),
            ("multi_tile_serialisation", self.multi_tile_serialisation),
            ("depth_write_traffic", self.depth_write_traffic),
            ("page_model", self.page_model),
        ]
    }

    /// The active effects' names, comma separated ("none" when none is).
    pub fn active_names(&self) -> String {
        let names: Vec<&str> = self
            .list()
            .iter()
            .filter(|(_, on)| *on)
            .map(|(name, _)| *name)
            .collect();
        if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        }
    }
}

/// How the effects are chosen (`--effects auto|all`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum EffectsChoice {
    /// From a scan of the trace: only the effects it can observe.
    #[default]
    Auto,
    /// Every effect model on.
    All,
}

impl std::str::FromStr for EffectsChoice {
    type Err = String;
    fn from_str(text: &str) -> Result<EffectsChoice, String> {
        match text {
            "auto" => Ok(EffectsChoice::Auto),
            "all" => Ok(EffectsChoice::All),
            other => Err(format!("unknown effects choice '{other}' (auto or all)")),
        }
    }
}

/// What the rules need to know of a trace: from a scan of its events ([`EffectScan`]) or,
/// without reading them, from its header ([`TraceFacts::from_features`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraceFacts {
    /// Some query is verbose.
    pub verbose: bool,
    /// The most tiles any query has.
    pub max_query_tiles: u64,
    /// Some fragment arrives with the depth test and depth writes on and no brief or verbose
    /// query open.
    pub depth_writes: bool,
}

impl TraceFacts {
    /// The facts a trace header's features record (None for traces written before they
    /// recorded all of them: scan those).
    pub fn from_features(features: &TraceFeatures) -> Option<TraceFacts> {
        Some(TraceFacts {
            verbose: features.verbose,
            max_query_tiles: features.max_query_tiles?,
            depth_writes: features.depth_writes?,
        })
    }
}

/// The rules of the module docs for one machine on one viewport.
#[derive(Clone, Copy, Debug)]
pub struct EffectRules {
    engines: usize,
    all_tiles_one_cycle: bool,
    /// The viewport lies inside one framebuffer tile (page).
    one_page: bool,
    /// The models the machine has at all.
    models: Effects,
}

impl EffectRules {
    /// The rules for the O2 machine `arch` on a `width` x `height` viewport.
    pub fn o2(arch: &O2Arch, width: u32, height: u32) -> EffectRules {
        EffectRules {
            engines: arch.occu.engines,
            all_tiles_one_cycle: arch.occu.all_tiles_one_cycle,
            one_page: width <= arch.framebuffer_tile_width_pixels
                && height <= arch.framebuffer_tile_height_pixels,
            models: Effects::ALL,
        }
    }

    /// The rules for the InfiniteReality-like machine `arch`.
    pub fn ir(arch: &IrArch) -> EffectRules {
        EffectRules {
            engines: arch.occu.engines,
            all_tiles_one_cycle: arch.occu.all_tiles_one_cycle,
            one_page: false,
            models: Effects::every_model_of(Machine::Ir),
        }
    }

    /// The rules for whichever machine `arch` describes, on a `width` x `height` viewport.
    pub fn for_arch(arch: &Arch, width: u32, height: u32) -> Result<EffectRules, SimError> {
        Ok(match arch.machine() {
            Machine::O2 => EffectRules::o2(&arch.o2()?, width, height),
            Machine::Ir => EffectRules::ir(&arch.ir()?),
        })
    }

    /// The effects a trace with these facts can observe, fast-forward allowed.
    pub fn effects(&self, facts: TraceFacts) -> Effects {
        let observed = Effects {
            verbose_hit_writes: facts.verbose,
            multi_tile_serialisation: !self.all_tiles_one_cycle
                && facts.max_query_tiles > self.engines as u64,
            depth_write_traffic: facts.depth_writes,
            page_model: !self.one_page,
            fast_forward: true,
        };
        Effects {
            fast_forward: true,
            ..observed.and(self.models)
        }
    }
}

/// Scans an event stream for the facts the rules need. Cheap: a few flag tests per
/// fragment, no depth buffer.
pub struct EffectScan {
    rules: EffectRules,
    depth_test: bool,
    depth_mask: bool,
    /// An occlusion-render-mode query (no depth writes) is open.
    occlusion_mode_open: bool,
    facts: TraceFacts,
}

impl EffectScan {
    /// A scan for the O2 machine `arch` on a `width` x `height` viewport.
    pub fn new(arch: &O2Arch, width: u32, height: u32) -> EffectScan {
        EffectScan::with(EffectRules::o2(arch, width, height))
    }

    /// A scan for the InfiniteReality-like machine `arch`.
    pub fn for_ir(arch: &IrArch) -> EffectScan {
        EffectScan::with(EffectRules::ir(arch))
    }

    /// A scan for whichever machine `arch` describes, on a `width` x `height` viewport.
    pub fn for_arch(arch: &Arch, width: u32, height: u32) -> Result<EffectScan, SimError> {
        Ok(EffectScan::with(EffectRules::for_arch(
            arch, width, height,
        )?))
    }

    fn with(rules: EffectRules) -> EffectScan {
        EffectScan {
            rules,
            depth_test: true,
            depth_mask: true,
            occlusion_mode_open: false,
            facts: TraceFacts::default(),
        }
    }

    /// Scan one event.
    #[inline]
    pub fn event(&mut self, event: &Event) {
        match event {
            Event::Fragment(_) => {
                self.facts.depth_writes |=
                    self.depth_test && self.depth_mask && !self.occlusion_mode_open;
            }
            Event::DepthTest(on) => self.depth_test = *on,
            Event::DepthMask(on) => self.depth_mask = *on,
            Event::QueryBegin(spec) => {
                self.occlusion_mode_open = spec.mode.is_occlusion_render_mode();
                self.facts.verbose |= spec.mode == QueryMode::Verbose;
                self.facts.max_query_tiles =
                    self.facts.max_query_tiles.max(spec.tiles.len() as u64);
            }
            Event::QueryEnd => self.occlusion_mode_open = false,
            _ => {}
        }
    }

    /// The facts found so far.
    pub fn facts(&self) -> TraceFacts {
        self.facts
    }

    /// The effects the scanned stream can observe.
    pub fn finish(&self) -> Effects {
        self.rules.effects(self.facts)
    }
}

/// The effects a trace can observe on `arch`, from its header's features alone (None when
/// the header lacks them: a trace streamed to a pipe, or written by an older version).
pub fn effects_of_features(
    arch: &Arch,
    width: u32,
    height: u32,
    features: Option<&TraceFeatures>,
) -> Result<Option<Effects>, SimError> {
    let Some(facts) = features.and_then(TraceFacts::from_features) else {
        return Ok(None);
    };
    Ok(Some(
        EffectRules::for_arch(arch, width, height)?.effects(facts),
    ))
}

/// The effects of `events` on the machine `arch` describes (a scan of the whole stream).
pub fn observe(
    arch: &Arch,
    width: u32,
    height: u32,
    events: &[Event],
) -> Result<Effects, SimError> {
    let mut scan = EffectScan::for_arch(arch, width, height)?;
    for event in events {
        scan.event(event);
    }
    Ok(scan.finish())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::Arch;
    use occsim_traces::{Fragment, QuerySpec, Rect};

    #[test]
    fn plain_fragments_write_depth_and_nothing_else_is_observed() {
        let events = [Event::Fragment(Fragment { x: 0, y: 0, z: 1 })];
        let effects = observe(&Arch::builtin("o2").unwrap(), 1024, 1024, &events).unwrap();
        assert_eq!(
            effects,
            Effects {
                verbose_hit_writes: false,
                multi_tile_serialisation: false,
                depth_write_traffic: true,
                page_model: true,
                fast_forward: true,
            }
        );
    }

    #[test]
    fn a_brief_query_with_many_tiles_serialises_but_writes_no_depth() {
        let tiles = (0..9).map(|i| Rect::new(i, 0, 1, 1)).collect();
        let events = [
            Event::QueryBegin(QuerySpec {
                id: 1,
                mode: QueryMode::Brief,
                buffer_entries: 8,
                tiles,
            }),
            Event::Fragment(Fragment { x: 0, y: 0, z: 1 }),
            Event::QueryEnd,
            Event::DepthMask(false),
            Event::Fragment(Fragment { x: 0, y: 0, z: 1 }),
        ];
        let mut arch = Arch::builtin("o2").unwrap();
        arch.set("engines=4").unwrap();
        let effects = observe(&arch, 16, 16, &events).unwrap();
        assert!(effects.multi_tile_serialisation);
        assert!(!effects.depth_write_traffic);
        assert!(!effects.verbose_hit_writes);
        assert!(!effects.page_model, "16x16 fits one framebuffer tile");
        arch.set("all_tiles_one_cycle=true").unwrap();
        assert!(
            !observe(&arch, 16, 16, &events)
                .unwrap()
                .multi_tile_serialisation
        );
    }

    #[test]
    fn the_ir_never_has_depth_traffic_or_pages_and_scans_the_rest() {
        let verbose = QuerySpec {
            id: 1,
            mode: QueryMode::Verbose,
            buffer_entries: 16,
            tiles: (0..3).map(|i| Rect::new(i, 0, 1, 1)).collect(),
        };
        let events = [
            Event::Fragment(Fragment { x: 0, y: 0, z: 1 }),
            Event::QueryBegin(verbose),
            Event::QueryEnd,
        ];
        let mut arch = Arch::builtin("ir4").unwrap();
        arch.set("engines=2").unwrap();
        let effects = observe(&arch, 2048, 2048, &events).unwrap();
        assert_eq!(
            effects,
            Effects {
                verbose_hit_writes: true,
                multi_tile_serialisation: true,
                depth_write_traffic: false,
                page_model: false,
                fast_forward: true,
            }
        );
        assert_eq!(
            effects,
            Effects {
                fast_forward: true,
                ..Effects::every_model_of(Machine::Ir)
            }
        );
        let plain = observe(&arch, 2048, 2048, &events[..1]).unwrap();
        assert_eq!(plain.active_names(), "none");
    }

    #[test]
    fn effects_choice_parses() {
        assert_eq!("auto".parse(), Ok(EffectsChoice::Auto));
        assert_eq!("all".parse(), Ok(EffectsChoice::All));
        assert!("some".parse::<EffectsChoice>().is_err());
    }
}
