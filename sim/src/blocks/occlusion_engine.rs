//! One Occlusion Engine: the counters and registers of the tiles dealt to it.
//!
//! Per tile and per fragment inside the tile: PHC += 1; if the depth test passed, NOHC += 1,
//! the screen box and z range grow to include the fragment, and in verbose mode the hit is
//! sent to OccU Control while the tile's buffer has room for it (`buffer_entries - 8`). A hit
//! beyond the room marks the buffer overflowed; OccU Control then writes the -1 terminator
//! over the last hit (a buffer with no room for hits gets no terminator either).
//! Counters are `counter_bits` wide and saturate at `2^counter_bits - 1`.

use occsim_rtl::tile_locator::TileLocator;
use occsim_traces::query::BRIEF_RECORD_ENTRIES;
use occsim_traces::{Fragment, Span, Tile, TileResult};
use std::sync::Arc;

/// Tiles up to which an engine scans them all for each fragment; past it, a
/// [`TileLocator`] names the few that may hold it. (Scanning every tile for every fragment,
/// a lazy-grid walk's queries of hundreds of tiles had made the IR's cycle level slower
/// than its rtl level, which locates them.)
const SCAN_TILES: usize = 8;

/// One tile's registers inside an engine that tests every tile it holds.
#[derive(Clone, Debug)]
struct TileRegisters {
    /// The tile's position in the query's list.
    index: usize,
    rect: Tile,
    result: TileResult,
    /// Hits sent to OccU Control (at most `hit_room`).
    hits_sent: u64,
}

/// The tiles a located engine holds ([`OcclusionEngine::load`]): each one's position in the
/// query's list and its rectangle, and the locator that names the few that may hold a
/// pixel. The same for every unit that loads the query (its engines deal the tiles alike),
/// so built once and shared ([`crate::blocks::occlusion_unit::SharedLocatedTiles`]); each
/// engine keeps beside them only the counters of the tiles a fragment fell in
/// (`CountedTile`). On the InfiniteReality-like machine's 320 units, the `hom` driver's
/// 8,000-tile queries at ir4's cycle level took 236 MB with every tile's registers in every
/// unit, 97 MB with an outline of every tile in every unit and counters made on first use,
/// and 29 MB so.
#[derive(Debug)]
pub struct LocatedTiles {
    outlines: Vec<(usize, Tile)>,
    locator: TileLocator,
}

/// A located tile's counters, from the first fragment inside it on (before it, its result
/// is `TileResult::default()`, what OccU Control reports for a tile no engine hands it).
#[derive(Clone, Debug)]
struct CountedTile {
    /// Its position among the engine's tiles ([`LocatedTiles::outlines`]).
    position: u32,
    result: TileResult,
    /// Hits sent to OccU Control (at most `hit_room`).
    hits_sent: u64,
}

/// [`OcclusionEngine::slots`]' mark of a tile with no counters yet.
const UNCOUNTED: u32 = u32::MAX;

#[derive(Clone, Debug, Default)]
pub struct OcclusionEngine {
    /// The loaded query's tiles where the engine scans them...
    tiles: Vec<TileRegisters>,
    /// ...or where a locator names them, when it holds more than [`SCAN_TILES`] (not
    /// hardware: the comparators still decide, and every count equals a scan's; shared
    /// with the other units that load the same tiles).
    located: Option<Arc<LocatedTiles>>,
    /// Per located tile, where its counters are in `counted` ([`UNCOUNTED`]: none yet).
    slots: Vec<u32>,
    /// The located tiles a fragment fell in, in the order they were first counted.
    counted: Vec<CountedTile>,
    verbose: bool,
    hit_room: u64,
    /// Hits each tile's result lists (`QuerySpec::listed_hits_per_tile`).
    hit_list_cap: usize,
    counter_max: u64,
    /// Cycles spent testing tiles.
    pub busy_cycles: u64,
    /// Cycles held by OccU Control (its write buffer full).
    pub stall_cycles: u64,
}

impl OcclusionEngine {
    /// Load the tiles of a new query: `(index in the query, rectangle)`. `verbose` queries
    /// send hits while a tile's buffer has `hit_room` entries for them, listing the first
    /// `hit_list_cap` of a tile's hits in its result. `shared` is what another unit made of
    /// the same tiles where given ([`Self::located_tiles`]:
    /// [`crate::blocks::occlusion_unit::SharedLocatedTiles`]), else the engine makes it here.
    pub fn load(
        &mut self,
        tiles: impl Iterator<Item = (usize, Tile)>,
        verbose: bool,
        hit_room: u64,
        hit_list_cap: usize,
        counter_max: u64,
        shared: Option<&Option<Arc<LocatedTiles>>>,
    ) {
        self.verbose = verbose;
        self.hit_room = hit_room;
        self.hit_list_cap = hit_list_cap;
        self.counter_max = counter_max;
        self.tiles.clear();
        self.counted.clear();
        let scanned = |(index, rect)| TileRegisters {
            index,
            rect,
            result: TileResult::default(),
            hits_sent: 0,
        };
        self.located = match shared {
            Some(Some(located)) => {
                debug_assert_eq!(tiles.count(), located.outlines.len(), "another query's");
                Some(located.clone())
            }
            // Another unit scans these tiles: so does this one.
            Some(None) => {
                self.tiles.extend(tiles.map(scanned));
                None
            }
            None => match Self::locate(tiles.collect()) {
                Ok(located) => Some(located),
                Err(outlines) => {
                    self.tiles.extend(outlines.into_iter().map(scanned));
                    None
                }
            },
        };
        if let Some(located) = &self.located {
            self.slots.clear();
            self.slots.resize(located.outlines.len(), UNCOUNTED);
        }
    }

    /// `outlines` located, where they are more than [`SCAN_TILES`] and a locator can be
    /// built for them; else given back, to be scanned.
    fn locate(outlines: Vec<(usize, Tile)>) -> Result<Arc<LocatedTiles>, Vec<(usize, Tile)>> {
        if outlines.len() <= SCAN_TILES {
            return Err(outlines);
        }
        let rects: Vec<[u32; 4]> = (outlines.iter())
            .map(|(_, rect)| [rect.x, rect.y, rect.width, rect.height])
            .collect();
        let mut locator = TileLocator::default();
        match locator.build(&rects) {
            true => Ok(Arc::new(LocatedTiles { outlines, locator })),
            false => Err(outlines),
        }
    }

    /// The loaded tiles as located (none where they are scanned).
    pub fn located_tiles(&self) -> &Option<Arc<LocatedTiles>> {
        &self.located
    }

    /// Tiles held: the cycles one fragment costs (one tile per cycle).
    pub fn tile_count(&self) -> usize {
        self.tiles.len() + self.located.as_ref().map_or(0, |l| l.outlines.len())
    }

    /// Count one fragment in every tile that holds it (those the locator names, else every
    /// tile tested); returns the hit words sent to OccU Control.
    #[inline]
    pub fn fragment(&mut self, fragment: Fragment, passed: bool) -> u32 {
        if self.located.is_some() {
            return self.located_fragment(fragment, passed);
        }
        self.scanned_fragment(fragment, passed)
    }

    /// Whether the loaded query's tiles are located (else [`Self::scanned_fragment`] is
    /// [`Self::fragment`]).
    pub fn is_located(&self) -> bool {
        self.located.is_some()
    }

    /// [`Self::fragment`] with every tile tested: for an engine whose query is not located
    /// (the Occlusion Unit decides once for all its engines, so that its few-tile loop,
    /// inlined into the machines' fragment loops, takes no branch an engine). The loop
    /// counts as [`Self::count_in`] does, written out: through it, the IR's cycle level on
    /// the demo took 1.2% more instructions.
    #[inline(always)]
    pub fn scanned_fragment(&mut self, fragment: Fragment, passed: bool) -> u32 {
        let counter_max = self.counter_max;
        let (x, y) = (fragment.x as u32, fragment.y as u32);
        let mut hit_words = 0;
        for tile in &mut self.tiles {
            if !tile.rect.contains(x, y) {
                continue;
            }
            let r = &mut tile.result;
            r.phc = (r.phc + 1).min(counter_max);
            if passed {
                r.nohc = (r.nohc + 1).min(counter_max);
                r.xmin = r.xmin.min(x);
                r.xmax = r.xmax.max(x);
                r.ymin = r.ymin.min(y);
                r.ymax = r.ymax.max(y);
                r.zmin = r.zmin.min(fragment.z);
                r.zmax = r.zmax.max(fragment.z);
                if self.verbose {
                    if tile.hits_sent < self.hit_room {
                        tile.hits_sent += 1;
                        r.hits.push((fragment.x, fragment.y), self.hit_list_cap);
                        hit_words += 1;
                    } else {
                        r.overflowed = true;
                    }
                }
            }
        }
        hit_words
    }

    /// [`Self::fragment`] in the tiles the locator names (out of line: the scan of a few
    /// tiles is the common path, inlined into the machines' fragment loops).
    #[cold]
    #[inline(never)]
    fn located_fragment(&mut self, fragment: Fragment, passed: bool) -> u32 {
        let query = (
            self.counter_max,
            self.verbose,
            self.hit_room,
            self.hit_list_cap,
        );
        let (x, y) = (fragment.x as u32, fragment.y as u32);
        let mut hit_words = 0;
        let Some(located) = &self.located else {
            return 0;
        };
        for t in located.locator.candidates(x, y, 0, u64::MAX) {
            if located.outlines[t as usize].1.contains(x, y) {
                let tile = counters_of(&mut self.slots, &mut self.counted, t as u32);
                hit_words += Self::count_in(tile, fragment, passed, query);
            }
        }
        hit_words
    }

    /// Count a fragment inside `tile`: PHC, and if it passed, NOHC, the box, the depth
    /// range and a verbose query's hit (`(counter_max, verbose, hit_room, hit_list_cap)`);
    /// returns the hit words sent.
    #[inline(always)]
    fn count_in(
        tile: &mut CountedTile,
        fragment: Fragment,
        passed: bool,
        (counter_max, verbose, hit_room, hit_list_cap): (u64, bool, u64, usize),
    ) -> u32 {
        let (x, y) = (fragment.x as u32, fragment.y as u32);
        let r = &mut tile.result;
        r.phc = (r.phc + 1).min(counter_max);
        if !passed {
            return 0;
        }
        r.nohc = (r.nohc + 1).min(counter_max);
        r.xmin = r.xmin.min(x);
        r.xmax = r.xmax.max(x);
        r.ymin = r.ymin.min(y);
        r.ymax = r.ymax.max(y);
        r.zmin = r.zmin.min(fragment.z);
        r.zmax = r.zmax.max(fragment.z);
        if !verbose {
            return 0;
        }
        if tile.hits_sent < hit_room {
            tile.hits_sent += 1;
            r.hits.push((fragment.x, fragment.y), hit_list_cap);
            1
        } else {
            r.overflowed = true;
            0
        }
    }

    /// Count a span's fragments (`passed[i]` for its fragment `i`) in every tile at once, as
    /// a fast-forward does ([`crate::effects`]): only without a verbose query, so no hit is
    /// sent, and then the counters, boxes and depth ranges do not depend on the order the
    /// fragments come in (saturating at `counter_max` after `m` steps is saturating once).
    pub fn count_span(&mut self, span: Span, passed: &[bool]) {
        debug_assert!(!self.verbose, "a verbose query's hits are sent one by one");
        let counter_max = self.counter_max;
        let Some(located) = &self.located else {
            for tile in &mut self.tiles {
                if let Some((from, pieces)) = run_inside(tile.rect, span) {
                    tile.result.record_run(
                        from,
                        span.y,
                        &span.depths[pieces.clone()],
                        &passed[pieces],
                        counter_max,
                    );
                }
            }
            return;
        };
        // The span cut where the locator's buckets end; in each piece, the tiles of its
        // bucket (a tile listed in several buckets counts each piece once).
        let side = located.locator.bucket_side();
        let (mut at, end) = (span.x as u32, span.x as u32 + span.depths.len() as u32);
        while at < end {
            let to = ((at / side + 1) * side).min(end);
            let (first, last) = ((at - span.x as u32) as usize, (to - span.x as u32) as usize);
            let piece = Span {
                x: at as u16,
                y: span.y,
                depths: &span.depths[first..last],
            };
            for t in located.locator.candidates(at, span.y as u32, 0, u64::MAX) {
                if let Some((from, pieces)) = run_inside(located.outlines[t as usize].1, piece) {
                    let tile = counters_of(&mut self.slots, &mut self.counted, t as u32);
                    tile.result.record_run(
                        from,
                        piece.y,
                        &piece.depths[pieces.clone()],
                        &passed[first..last][pieces],
                        counter_max,
                    );
                }
            }
            at = to;
        }
    }

    /// Hand the tiles' results to OccU Control: `(index in the query, result)`, a located
    /// tile's only where a fragment fell in it (every other's is `TileResult::default()`).
    /// In no particular order: OccU Control places each result at its index.
    pub fn drain(&mut self) -> impl Iterator<Item = (usize, TileResult)> + '_ {
        let scanned = self.tiles.drain(..).map(|t| (t.index, t.result));
        let outlines = self.located.as_ref().map_or(&[][..], |l| &l.outlines[..]);
        let located =
            (self.counted.drain(..)).map(|tile| (outlines[tile.position as usize].0, tile.result));
        scanned.chain(located)
    }
}

/// The counters of located tile `position`, made at its first fragment.
#[inline(always)]
fn counters_of<'a>(
    slots: &mut [u32],
    counted: &'a mut Vec<CountedTile>,
    position: u32,
) -> &'a mut CountedTile {
    let slot = &mut slots[position as usize];
    if *slot == UNCOUNTED {
        *slot = counted.len() as u32;
        counted.push(CountedTile {
            position,
            result: TileResult::default(),
            hits_sent: 0,
        });
    }
    &mut counted[*slot as usize]
}

/// Where `span` runs inside `rect`: its first pixel's x there and the span's fragments
/// inside it (none: `None`).
#[inline(always)]
fn run_inside(rect: Tile, span: Span) -> Option<(u16, std::ops::Range<usize>)> {
    let (span_x, y) = (span.x as u64, span.y as u32);
    if y.wrapping_sub(rect.y) >= rect.height {
        return None;
    }
    let span_end = span_x + span.depths.len() as u64;
    let from = span_x.max(rect.x as u64);
    let to = span_end.min(rect.x as u64 + rect.width as u64);
    if from >= to {
        return None;
    }
    Some((
        from as u16,
        (from - span_x) as usize..(to - span_x) as usize,
    ))
}

/// Hit room of a verbose buffer of `buffer_entries` entries.
pub fn hit_room(buffer_entries: u32) -> u64 {
    buffer_entries.saturating_sub(BRIEF_RECORD_ENTRIES) as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use occsim_traces::rng::SplitMix64;
    use occsim_traces::Rect;

    /// `count` random tiles over a 300 x 200 corner: small ones, a few large overlapping
    /// ones, and where `wraps`, one wrapping past 2^32 (what a slot register holds).
    fn random_tiles(rng: &mut SplitMix64, count: usize, wraps: bool) -> Vec<Tile> {
        let mut tiles: Vec<Tile> = (0..count)
            .map(|_| {
                let (w, h) = match rng.below(8) {
                    0 => (100 + rng.below(150), 80 + rng.below(100)),
                    _ => (1 + rng.below(24), 1 + rng.below(24)),
                };
                Rect::new(
                    rng.below(300) as u32,
                    rng.below(200) as u32,
                    w as u32,
                    h as u32,
                )
            })
            .collect();
        if wraps {
            tiles[0] = Rect::new(u32::MAX - 3, 10, 20, 5);
        }
        tiles
    }

    /// A located engine keeps counters only for the tiles a fragment fell in, and hands
    /// over only theirs: memory that follows the fragments, not the query's tiles.
    #[test]
    fn located_tiles_hold_counters_only_once_counted() {
        // A 10 x 2 grid of 8 x 8 tiles (20, past the 8 an engine scans); one fragment at
        // (9, 9): in the tile at column 1, row 1, index 11.
        let tiles = (0..20).map(|i| (i, Rect::new(i as u32 % 10 * 8, i as u32 / 10 * 8, 8, 8)));
        let mut engine = OcclusionEngine::default();
        engine.load(tiles, false, 0, 0, 1000, None);
        assert!(engine.is_located());
        assert_eq!(engine.tile_count(), 20, "every tile loaded costs its cycle");
        engine.fragment(Fragment { x: 9, y: 9, z: 5 }, true);
        assert_eq!(engine.counted.len(), 1);
        assert_eq!(engine.slots.iter().filter(|&&s| s != UNCOUNTED).count(), 1);
        let handed: Vec<(usize, TileResult)> = engine.drain().collect();
        assert_eq!(handed.len(), 1);
        assert_eq!((handed[0].0, handed[0].1.phc, handed[0].1.nohc), (11, 1, 1));
    }

    /// One engine reloaded query after query, located and scanned in turn and with fewer
    /// and more tiles, counts as a fresh engine loaded with each query alone: nothing of a
    /// query's counters or slots is left to the next.
    #[test]
    fn a_reloaded_engine_counts_as_a_fresh_one() {
        let mut rng = SplitMix64(7);
        let mut reused = OcclusionEngine::default();
        // 30 tiles (located), 5 (scanned), 12 and 60 (located), 3 (scanned), 30 again.
        for (query, count) in [30, 5, 12, 60, 3, 30].into_iter().enumerate() {
            let tiles = random_tiles(&mut rng, count, false);
            let verbose = query % 2 == 1;
            let mut fresh = OcclusionEngine::default();
            for engine in [&mut reused, &mut fresh] {
                let dealt = tiles.iter().copied().enumerate();
                engine.load(dealt, verbose, 5, 4, 1000, None);
            }
            assert_eq!(reused.is_located(), count > SCAN_TILES, "query {query}");
            for _ in 0..500 {
                let fragment = Fragment {
                    x: rng.below(320) as u16,
                    y: rng.below(220) as u16,
                    z: rng.below(1 << 24) as u32,
                };
                let passed = rng.below(3) > 0;
                let words = reused.fragment(fragment, passed);
                assert_eq!(words, fresh.fragment(fragment, passed), "query {query}");
            }
            let by_index = |engine: &mut OcclusionEngine| {
                let mut results: Vec<(usize, TileResult)> = engine.drain().collect();
                results.sort_by_key(|(index, _)| *index);
                results
            };
            assert_eq!(by_index(&mut reused), by_index(&mut fresh), "query {query}");
        }
    }

    #[test]
    fn located_tiles_count_what_each_tile_alone_counts() {
        // An engine of many tiles (located) against one engine a tile (each scanning its
        // one tile), fed the same fragments and spans: every tile's result, its hits and
        // the hit words sent must agree. Verbose runs feed fragments one by one (a small
        // buffer, so that some overflow); others mix in spans.
        for (seed, verbose, wraps) in [
            (1, false, false),
            (2, true, false),
            (3, false, true),
            (4, true, true),
        ] {
            let mut rng = SplitMix64(seed);
            let tiles = random_tiles(&mut rng, 60, wraps);
            let (room, cap, max) = (5, 4, 1000);
            let mut located = OcclusionEngine::default();
            let dealt = tiles.iter().copied().enumerate();
            located.load(dealt, verbose, room, cap, max, None);
            let tiles_located = located.located_tiles().clone().expect("located");
            // Spans cross buckets (a wrapping tile's extent makes one bucket of it all).
            let side = tiles_located.locator.bucket_side();
            assert_eq!(side < 64, !wraps, "seed {seed}");
            let mut alone: Vec<OcclusionEngine> = tiles
                .iter()
                .enumerate()
                .map(|(index, &tile)| {
                    let mut engine = OcclusionEngine::default();
                    engine.load([(index, tile)].into_iter(), verbose, room, cap, max, None);
                    engine
                })
                .collect();
            for step in 0..3000 {
                let (x, y) = (rng.below(320) as u16, rng.below(220) as u16);
                if verbose || rng.below(3) > 0 {
                    let fragment = Fragment {
                        x,
                        y,
                        z: rng.below(1 << 24) as u32,
                    };
                    let passed = rng.below(3) > 0;
                    let words = located.fragment(fragment, passed);
                    let alone_words: u32 =
                        alone.iter_mut().map(|e| e.fragment(fragment, passed)).sum();
                    assert_eq!(words, alone_words, "seed {seed} step {step}");
                } else {
                    let len = 1 + rng.below(90) as usize;
                    let depths: Vec<u32> = (0..len).map(|_| rng.below(1 << 24) as u32).collect();
                    let passed: Vec<bool> = (0..len).map(|_| rng.below(2) == 0).collect();
                    let span = Span {
                        x,
                        y,
                        depths: &depths,
                    };
                    located.count_span(span, &passed);
                    alone.iter_mut().for_each(|e| e.count_span(span, &passed));
                }
            }
            // A located tile without counters is reported as OccU Control fills it in.
            let mut results = vec![TileResult::default(); tiles.len()];
            for (index, result) in located.drain() {
                results[index] = result;
            }
            let expected: Vec<TileResult> = alone
                .iter_mut()
                .flat_map(|e| e.drain())
                .map(|(_, r)| r)
                .collect();
            assert_eq!(results, expected, "seed {seed}");
            assert!(expected.iter().any(|r| r.phc > 0), "some tile counted");
        }
    }
}
