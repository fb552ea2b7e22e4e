//! The Occlusion Unit: `engines` Occlusion Engines behind the depth test, in lockstep.
//!
//! Rules: a query's tiles are dealt to the engines round-robin (tile t to engine t mod E), so
//! engine e holds k_e tiles. The unit takes one fragment at a time from the depth-to-OccU
//! FIFO; every engine tests its tiles one per cycle, so the fragment occupies the unit for
//! `s = max(1, max_e k_e)` cycles (`s = 1` with `all_tiles_one_cycle`, and `s = 1` when no
//! query is open: the fragment just passes). Fragment `i`, readable from `ready_i`
//! (= depth test cycle + 1), starts in `o_i = max(ready_i, c_{i-1} + 1)` and is done counting
//! in `o_i + s - 1`; it leaves the unit in `c_i`, which is later only when OccU Control's
//! write buffer has no room for its hit words ([`crate::blocks::occu_control`]). The unit reads the
//! FIFO entry (frees its slot) in `o_i`.

use crate::arch::O2Arch;
use crate::blocks::occlusion_engine::{hit_room, LocatedTiles, OcclusionEngine};
use occsim_traces::{Fragment, QueryMode, QuerySpec, Span, TileResult};
use std::sync::Arc;

/// The located tiles of a query's engines (their outlines and locators), made by the first
/// unit that loads the query and taken by the rest: every Image Engine of the
/// InfiniteReality-like machine deals the same tiles to its engines. Building a query of
/// hundreds of tiles' locators in each of 320 units had been an eighth of the cycle level's
/// time on a lazy-grid walk of the city on ir4, and an outline of each tile in each unit
/// most of the memory of the `hom` driver's 8,000-tile queries. (Not hardware: the
/// comparators still decide; the locator only names the candidates.)
#[derive(Default)]
pub struct SharedLocatedTiles {
    /// The query they were built for, and each engine's tiles as located (none where it
    /// scans).
    query: Option<u64>,
    located: Vec<Option<Arc<LocatedTiles>>>,
}

pub struct OcclusionUnit {
    pub engines: Vec<OcclusionEngine>,
    all_tiles_one_cycle: bool,
    counter_max: u64,
    /// Cycles one fragment occupies the unit under the open query.
    service_cycles: u64,
    /// Per engine, cycles one fragment keeps it testing.
    engine_cycles: Vec<u64>,
    /// Engines holding at least one tile of the open query.
    active: usize,
    /// Some engine locates the open query's tiles (else each scans its few).
    located: bool,
    /// Fragments and stall cycles of the open query (for the engines' statistics).
    query_fragments: u64,
    query_stall_cycles: u64,
    /// First cycle the unit is free.
    free: u64,
    pub busy_cycles: u64,
    pub stall_cycles: u64,
}

impl OcclusionUnit {
    pub fn new(arch: &O2Arch) -> OcclusionUnit {
        OcclusionUnit::with_engines(
            arch.occu.engines,
            arch.occu.all_tiles_one_cycle,
            arch.counter_max(),
        )
    }

    /// A unit of `engines` engines with `counter_max`-saturating counters (any machine).
    pub fn with_engines(
        engines: usize,
        all_tiles_one_cycle: bool,
        counter_max: u64,
    ) -> OcclusionUnit {
        OcclusionUnit {
            engines: vec![OcclusionEngine::default(); engines],
            all_tiles_one_cycle,
            counter_max,
            service_cycles: 1,
            engine_cycles: vec![0; engines],
            active: 0,
            located: false,
            query_fragments: 0,
            query_stall_cycles: 0,
            free: 0,
            busy_cycles: 0,
            stall_cycles: 0,
        }
    }

    /// Configure the engines for a query.
    pub fn begin(&mut self, spec: &QuerySpec) {
        self.begin_sharing(spec, None);
    }

    /// [`Self::begin`], the engines' located tiles taken from `shared` where it holds query
    /// `generation`'s for as many engines, else made and left there.
    pub fn begin_sharing(
        &mut self,
        spec: &QuerySpec,
        shared: Option<(&mut SharedLocatedTiles, u64)>,
    ) {
        let count = self.engines.len();
        let (shared, generation) = match shared {
            Some((shared, generation)) => (Some(shared), generation),
            None => (None, 0),
        };
        let built = shared.as_ref().is_some_and(|shared| {
            shared.query == Some(generation) && shared.located.len() == count
        });
        let verbose = spec.mode == QueryMode::Verbose;
        let room = if verbose {
            hit_room(spec.buffer_entries)
        } else {
            0
        };
        for (e, engine) in self.engines.iter_mut().enumerate() {
            let dealt = spec
                .tiles
                .iter()
                .copied()
                .enumerate()
                .skip(e)
                .step_by(count);
            let locator = match (&shared, built) {
                (Some(shared), true) => Some(&shared.located[e]),
                _ => None,
            };
            let cap = spec.listed_hits_per_tile();
            engine.load(dealt, verbose, room, cap, self.counter_max, locator);
        }
        if let (Some(shared), false) = (shared, built) {
            shared.query = Some(generation);
            shared.located = self
                .engines
                .iter()
                .map(|e| e.located_tiles().clone())
                .collect();
        }
        self.engine_cycles =
            engine_service_cycles(spec.tiles.len(), count, self.all_tiles_one_cycle);
        self.service_cycles = self.engine_cycles.iter().copied().max().unwrap_or(0).max(1);
        self.active = count.min(spec.tiles.len());
        self.located = self.engines.iter().any(OcclusionEngine::is_located);
    }

    /// Cycles one fragment occupies the unit now.
    pub fn service_cycles(&self) -> u64 {
        self.service_cycles
    }

    /// Count one fragment readable from `ready`; returns its start cycle and the hit words it
    /// sends to OccU Control.
    #[inline]
    pub fn fragment(
        &mut self,
        fragment: Fragment,
        passed: bool,
        ready: u64,
        query_open: bool,
    ) -> (u64, u32) {
        let start = ready.max(self.free);
        let hit_words = if query_open {
            self.count(fragment, passed)
        } else {
            0
        };
        (start, hit_words)
    }

    /// Count one fragment in the open query's tiles; returns the hit words it sends.
    #[inline]
    pub fn count(&mut self, fragment: Fragment, passed: bool) -> u32 {
        if self.located {
            return self.count_located(fragment, passed);
        }
        // Round-robin dealing gives tiles to engines 0..active only.
        self.engines[..self.active]
            .iter_mut()
            .map(|engine| engine.scanned_fragment(fragment, passed))
            .sum()
    }

    /// [`Self::count`] where an engine locates its tiles (a query of many tiles), out of
    /// line. (Deciding for each engine in the loop above had made the IR's cycle level on
    /// the demo 9% slower, 4.1% more instructions; deciding here, 3.5% and 1.3%.)
    #[cold]
    #[inline(never)]
    fn count_located(&mut self, fragment: Fragment, passed: bool) -> u32 {
        self.engines[..self.active]
            .iter_mut()
            .map(|engine| engine.fragment(fragment, passed))
            .sum()
    }

    /// Count a span's fragments (`passed[i]` for its fragment `i`) in the open query's
    /// tiles at once (a fast-forward; no verbose query open, so no hit words).
    pub fn count_span(&mut self, span: Span, passed: &[bool]) {
        for engine in &mut self.engines[..self.active] {
            engine.count_span(span, passed);
        }
    }

    /// Time one fragment that sends no hit word, readable from `ready`: it starts in
    /// `max(ready, free)` and leaves when done counting. Returns its start cycle.
    #[inline]
    pub fn time_without_hits(&mut self, ready: u64, query_open: bool) -> u64 {
        let start = ready.max(self.free);
        self.complete(start, start + self.service_cycles - 1, query_open);
        start
    }

    /// Time `count` fragments that send no hit word, readable from `first_ready` and each one
    /// cycle after the one before, under a one-cycle service (a fast-forward): they start in
    /// consecutive cycles, as `count` calls of [`Self::time_without_hits`] give. Returns the
    /// first one's start.
    #[inline]
    pub fn time_run_without_hits(&mut self, first_ready: u64, count: u64, query_open: bool) -> u64 {
        debug_assert_eq!(self.service_cycles, 1, "one cycle a fragment");
        let start = first_ready.max(self.free);
        self.busy_cycles += count;
        if query_open {
            self.query_fragments += count;
        }
        self.free = start + count;
        start
    }

    /// The fragment that started in `start` leaves in `leave` (>= start + s - 1).
    #[inline]
    pub fn complete(&mut self, start: u64, leave: u64, query_open: bool) {
        let done = start + self.service_cycles - 1;
        let stalled = leave - done;
        self.busy_cycles += self.service_cycles;
        self.stall_cycles += stalled;
        if query_open {
            // Engine statistics are settled at the query's end, keeping this path short.
            self.query_fragments += 1;
            self.query_stall_cycles += stalled;
        }
        self.free = leave + 1;
    }

    /// First cycle the unit is free.
    pub fn free_cycle(&self) -> u64 {
        self.free
    }

    /// Collect the tiles' results in the query's order and return the unit to pass-through.
    pub fn end(&mut self, tile_count: usize) -> Vec<TileResult> {
        for (engine, &cycles) in self.engines.iter_mut().zip(&self.engine_cycles) {
            engine.busy_cycles += cycles * self.query_fragments;
            if cycles > 0 {
                engine.stall_cycles += self.query_stall_cycles;
            }
        }
        self.query_fragments = 0;
        self.query_stall_cycles = 0;
        let mut results = vec![TileResult::default(); tile_count];
        for engine in &mut self.engines {
            for (index, result) in engine.drain() {
                results[index] = result;
            }
        }
        self.service_cycles = 1;
        self.engine_cycles.fill(0);
        self.active = 0;
        results
    }
}

/// The cycles each of `engines` engines tests one fragment of a query of `tiles` tiles
/// dealt round-robin (engine `e` holds tiles `e, e + engines, ...`): one a tile it holds,
/// or one for all of them with `all_tiles_one_cycle`.
pub fn engine_service_cycles(tiles: usize, engines: usize, all_tiles_one_cycle: bool) -> Vec<u64> {
    (0..engines)
        .map(|e| {
            let held = tiles.saturating_sub(e).div_ceil(engines.max(1)) as u64;
            if all_tiles_one_cycle {
                held.min(1)
            } else {
                held
            }
        })
        .collect()
}

/// Statistics the report needs from an Occlusion Unit stage (either fidelity).
pub struct OccuStats {
    pub busy_cycles: u64,
    pub stall_cycles: u64,
    /// Per engine: (busy cycles, stall cycles).
    pub engines: Vec<(u64, u64)>,
    pub words_written: u64,
    pub port_cycles: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use occsim_traces::rng::SplitMix64;
    use occsim_traces::Rect;

    /// A brief query of `tiles` random tiles over a 320x240 viewport.
    fn query(rng: &mut SplitMix64, tiles: usize) -> QuerySpec {
        let tile = |rng: &mut SplitMix64| {
            let (x, y) = (rng.below(300) as u32, rng.below(220) as u32);
            Rect::new(x, y, 1 + rng.below(40) as u32, 1 + rng.below(40) as u32)
        };
        QuerySpec {
            id: 1,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: (0..tiles).map(|_| tile(rng)).collect(),
        }
    }

    #[test]
    fn units_loading_one_query_share_its_located_tiles_and_count_as_a_unit_alone() {
        // Three units of 4 engines load a query of 200 tiles (50 an engine: located)
        // through one `SharedLocatedTiles`: the second and third take the first's outlines and
        // locators (the same ones, not copies), and each counts the same fragments as a
        // unit that loaded the query alone. A second query (another generation) is built
        // again.
        let mut rng = SplitMix64(11);
        let mut shared = SharedLocatedTiles::default();
        for generation in [1, 2] {
            let spec = query(&mut rng, 200);
            let mut alone = OcclusionUnit::with_engines(4, false, 1 << 20);
            alone.begin(&spec);
            let mut units: Vec<OcclusionUnit> = (0..3)
                .map(|_| OcclusionUnit::with_engines(4, false, 1 << 20))
                .collect();
            for unit in &mut units {
                unit.begin_sharing(&spec, Some((&mut shared, generation)));
            }
            assert!(units[0].located, "generation {generation}");
            for unit in &units[1..] {
                for (engine, first) in unit.engines.iter().zip(&units[0].engines) {
                    let (Some(taken), Some(built)) =
                        (engine.located_tiles(), first.located_tiles())
                    else {
                        panic!("an engine of 50 tiles is located");
                    };
                    assert!(Arc::ptr_eq(taken, built), "generation {generation}");
                }
            }
            for cycle in 0..2_000 {
                let fragment = Fragment {
                    x: rng.below(320) as u16,
                    y: rng.below(240) as u16,
                    z: rng.below(1 << 24) as u32,
                };
                let passed = rng.below(2) == 0;
                alone.fragment(fragment, passed, cycle, true);
                for unit in &mut units {
                    unit.fragment(fragment, passed, cycle, true);
                }
            }
            let expected = alone.end(spec.tiles.len());
            for unit in &mut units {
                assert_eq!(
                    unit.end(spec.tiles.len()),
                    expected,
                    "generation {generation}"
                );
            }
        }
    }
}
