//! One Occlusion Engine: the counters and registers of the tiles dealt to it.
//!
//! Per tile and per fragment inside the tile: PHC += 1; if the depth test passed, NOHC += 1,
//! the screen box and z range grow to include the fragment, and in verbose mode the hit is
//! sent to OccU Control while the tile's buffer has room for it (`buffer_entries - 8`). A hit
//! beyond the room marks the buffer overflowed; OccU Control then writes the -1 terminator
//! over the last hit (a buffer with no room for hits gets no terminator either).
//! Counters are `counter_bits` wide and saturate at `2^counter_bits - 1`.

use occsim_traces::query::BRIEF_RECORD_ENTRIES;
use occsim_traces::{Fragment, Span, Tile, TileResult};

/// One tile's registers inside an engine.
#[derive(Clone, Debug)]
struct TileRegisters {
    /// The tile's position in the query's list.
    index: usize,
    rect: Tile,
    result: TileResult,
    /// Hits sent to OccU Control (at most `hit_room`).
    hits_sent: u64,
}

#[derive(Clone, Debug, Default)]
pub struct OcclusionEngine {
    tiles: Vec<TileRegisters>,
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
    /// `hit_list_cap` of a tile's hits in its result.
    pub fn load(
        &mut self,
        tiles: impl Iterator<Item = (usize, Tile)>,
        verbose: bool,
        hit_room: u64,
        hit_list_cap: usize,
        counter_max: u64,
    ) {
        self.verbose = verbose;
        self.hit_room = hit_room;
        self.hit_list_cap = hit_list_cap;
        self.counter_max = counter_max;
        self.tiles.clear();
        self.tiles.extend(tiles.map(|(index, rect)| TileRegisters {
            index,
            rect,
            result: TileResult::default(),
            hits_sent: 0,
        }));
    }

    /// Tiles held: the cycles one fragment costs (one tile per cycle).
    pub fn tile_count(&self) -> usize {
        self.tiles.len()
    }

    /// Count one fragment in every tile; returns the hit words sent to OccU Control.
    #[inline]
    pub fn fragment(&mut self, fragment: Fragment, passed: bool) -> u32 {
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

    /// Count a span's fragments (`passed[i]` for its fragment `i`) in every tile at once, as
    /// a fast-forward does ([`crate::effects`]): only without a verbose query, so no hit is
    /// sent, and then the counters, boxes and depth ranges do not depend on the order the
    /// fragments come in (saturating at `counter_max` after `m` steps is saturating once).
    pub fn count_span(&mut self, span: Span, passed: &[bool]) {
        debug_assert!(!self.verbose, "a verbose query's hits are sent one by one");
        let counter_max = self.counter_max;
        let (span_x, y) = (span.x as u64, span.y as u32);
        let span_end = span_x + span.depths.len() as u64;
        for tile in &mut self.tiles {
            let rect = tile.rect;
            if y.wrapping_sub(rect.y) >= rect.height {
                continue;
            }
            let from = span_x.max(rect.x as u64);
            let to = span_end.min(rect.x as u64 + rect.width as u64);
            if from >= to {
                continue;
            }
            let (first, last) = ((from - span_x) as usize, (to - span_x) as usize);
            tile.result.record_run(
                from as u16,
                span.y,
                &span.depths[first..last],
                &passed[first..last],
                counter_max,
            );
        }
    }

    /// Hand the tiles' results to OccU Control: `(index in the query, result)`.
    pub fn drain(&mut self) -> impl Iterator<Item = (usize, TileResult)> + '_ {
        self.tiles.drain(..).map(|t| (t.index, t.result))
    }
}

/// Hit room of a verbose buffer of `buffer_entries` entries.
pub fn hit_room(buffer_entries: u32) -> u64 {
    buffer_entries.saturating_sub(BRIEF_RECORD_ENTRIES) as u64
}
