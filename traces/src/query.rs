//! Query semantics: what a query asks (its mode, tiles, buffers) and what it answers.

use crate::hit_list::{listed_hits_per_tile, HitList};
use crate::state::Rect;
use serde::{Deserialize, Serialize};

/// Entries of the brief record at the head of every occlusion buffer:
/// NOHC, PHC, Xmin, Xmax, Ymin, Ymax, Zmin, Zmax.
pub const BRIEF_RECORD_ENTRIES: u32 = 8;
/// Default occlusion buffer size in entries for brief mode (just the record).
pub const DEFAULT_BRIEF_BUFFER: u32 = BRIEF_RECORD_ENTRIES;
/// Default occlusion buffer size in entries for verbose mode (the record and 256 hits).
pub const DEFAULT_VERBOSE_BUFFER: u32 = BRIEF_RECORD_ENTRIES + 256;
/// Largest occlusion buffer accepted, in entries (bounds memory on hostile input).
pub const MAX_BUFFER_ENTRIES: u32 = 1 << 24;
/// Largest number of tiles in one query (`GL_MAX_OCCLUSION_TILES`).
pub const MAX_TILES: usize = 65536;

/// What a query measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum QueryMode {
    /// `GL_SAMPLES_PASSED`: the number of fragments that pass; draws write as the state says.
    Samples,
    /// `GL_ANY_SAMPLES_PASSED`: did any fragment pass.
    Any,
    /// `GL_BRIEF_OCCLUSION`: per tile NOHC, PHC, box and z range; the framebuffer is untouched.
    Brief,
    /// `GL_VERBOSE_OCCLUSION`: brief, plus the list of passing pixels up to the buffer size.
    Verbose,
}

impl QueryMode {
    pub const ALL: [QueryMode; 4] = [
        QueryMode::Samples,
        QueryMode::Any,
        QueryMode::Brief,
        QueryMode::Verbose,
    ];

    pub fn name(self) -> &'static str {
        match self {
            QueryMode::Samples => "samples",
            QueryMode::Any => "any",
            QueryMode::Brief => "brief",
            QueryMode::Verbose => "verbose",
        }
    }

    pub fn from_name(name: &str) -> Option<QueryMode> {
        QueryMode::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Occlusion render modes never change the framebuffer (like `GL_SELECT`).
    pub fn is_occlusion_render_mode(self) -> bool {
        matches!(self, QueryMode::Brief | QueryMode::Verbose)
    }

    pub fn code(self) -> u8 {
        self as u8
    }

    pub fn from_code(code: u8) -> Option<QueryMode> {
        QueryMode::ALL.get(code as usize).copied()
    }
}

/// An occlusion tile: a window rectangle whose fragments one engine counts.
pub type Tile = Rect;

/// A query as `begin` states it.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct QuerySpec {
    /// The application's name for the query (need not be unique).
    pub id: u32,
    pub mode: QueryMode,
    /// Occlusion buffer size per tile, in entries (at least 8: the brief record).
    pub buffer_entries: u32,
    /// The occlusion tiles; `samples` and `any` queries have exactly one, the viewport.
    pub tiles: Vec<Tile>,
}

impl QuerySpec {
    /// Room for hits in one verbose buffer, in entries, when they all fit.
    pub fn hit_capacity(&self) -> u32 {
        self.buffer_entries - BRIEF_RECORD_ENTRIES
    }

    /// Hits each tile's result lists (the rest are counted and digested only): every
    /// model of the query lists the same ones.
    pub fn listed_hits_per_tile(&self) -> usize {
        listed_hits_per_tile(self.tiles.len())
    }
}

/// What a query's begin says but its tiles' rectangles: what a reader that skims the
/// trace's queries gets ([`crate::trace::TraceReader::skim_queries`]), and all the O2's
/// formulas and the stream's checks ask of a begin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueryShape {
    pub id: u32,
    pub mode: QueryMode,
    pub buffer_entries: u32,
    pub tiles: usize,
}

impl QuerySpec {
    pub fn shape(&self) -> QueryShape {
        QueryShape {
            id: self.id,
            mode: self.mode,
            buffer_entries: self.buffer_entries,
            tiles: self.tiles.len(),
        }
    }
}

/// A query's result summed over its tiles: what a reader that skims the trace's queries
/// gets, and all a level that predicts time asks of a result.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueryTotals {
    pub id: u32,
    pub mode: QueryMode,
    pub tiles: usize,
    /// NOHC and PHC summed over the tiles.
    pub nohc: u64,
    pub phc: u64,
    /// Hits the tiles' verbose buffers hold, summed ([`HitList::len`]).
    pub held_hits: u64,
    pub overflowed_buffers: u32,
}

impl QueryTotals {
    /// The value a GL program reads: the passing count for `samples`, 0 or 1 for `any`,
    /// the NOHC sum over tiles for the occlusion modes.
    pub fn value(&self) -> u64 {
        match self.mode {
            QueryMode::Any => (self.nohc > 0) as u64,
            _ => self.nohc,
        }
    }
}

/// One tile's answer: the brief record and, in verbose mode, the stored hits.
///
/// Empty box and z range (no passing fragment) read as min = `u32::MAX`, max = 0, as the
/// hardware's reset values.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TileResult {
    /// Non-occlusion hits: fragments inside the tile that passed the depth test.
    pub nohc: u64,
    /// Projection hits: fragments inside the tile.
    pub phc: u64,
    pub xmin: u32,
    pub xmax: u32,
    pub ymin: u32,
    pub ymax: u32,
    pub zmin: u32,
    pub zmax: u32,
    /// Verbose mode: the (x, y) of passing fragments, in arrival order, as many as fit
    /// (counted and digested exactly; the first ones listed, see [`HitList`]).
    pub hits: HitList,
    /// Verbose mode: more hits arrived than the buffer holds (it ends with -1 then).
    pub overflowed: bool,
}

impl Default for TileResult {
    fn default() -> TileResult {
        TileResult {
            nohc: 0,
            phc: 0,
            xmin: u32::MAX,
            xmax: 0,
            ymin: u32::MAX,
            ymax: 0,
            zmin: u32::MAX,
            zmax: 0,
            hits: HitList::default(),
            overflowed: false,
        }
    }
}

impl TileResult {
    /// Account one fragment inside this tile.
    #[inline]
    pub fn record(&mut self, x: u16, y: u16, z: u32, passed: bool) {
        self.phc += 1;
        if passed {
            self.nohc += 1;
            self.xmin = self.xmin.min(x as u32);
            self.xmax = self.xmax.max(x as u32);
            self.ymin = self.ymin.min(y as u32);
            self.ymax = self.ymax.max(y as u32);
            self.zmin = self.zmin.min(z);
            self.zmax = self.zmax.max(z);
        }
    }

    /// Account a run of fragments of row `y` from column `x` on, all inside this tile
    /// (`passed[i]` for the one at depth `depths[i]`), as [`Self::record`] does one by one
    /// with both counters saturating at `counter_max`. Returns the first and last passing
    /// fragment's index, if one passed.
    #[inline]
    pub fn record_run(
        &mut self,
        x: u16,
        y: u16,
        depths: &[u32],
        passed: &[bool],
        counter_max: u64,
    ) -> Option<(usize, usize)> {
        self.record_tally(x, y, RunTally::of(depths, passed), counter_max)
    }

    /// Account a run of fragments of row `y` from column `x` on, all inside this tile, by its
    /// [`RunTally`], with both counters saturating at `counter_max`. Returns the first and
    /// last passing fragment's index, if one passed.
    #[inline]
    pub fn record_tally(
        &mut self,
        x: u16,
        y: u16,
        tally: RunTally,
        counter_max: u64,
    ) -> Option<(usize, usize)> {
        self.phc = self
            .phc
            .saturating_add(tally.fragments as u64)
            .min(counter_max);
        if tally.passed == 0 {
            return None;
        }
        self.nohc = self
            .nohc
            .saturating_add(tally.passed as u64)
            .min(counter_max);
        let (x, y) = (x as u32, y as u32);
        // x grows along the run: the box's x ends are the first and last passing.
        self.xmin = self.xmin.min(x + tally.first);
        self.xmax = self.xmax.max(x + tally.last);
        self.ymin = self.ymin.min(y);
        self.ymax = self.ymax.max(y);
        self.zmin = self.zmin.min(tally.zmin);
        self.zmax = self.zmax.max(tally.zmax);
        Some((tally.first as usize, tally.last as usize))
    }

    /// Fold another partial result for the same tile into this one (hits concatenated and
    /// listed up to `list_cap`; counters add saturating at `u64::MAX`).
    pub fn merge(&mut self, other: &TileResult, list_cap: usize) {
        self.nohc = self.nohc.saturating_add(other.nohc);
        self.phc = self.phc.saturating_add(other.phc);
        self.xmin = self.xmin.min(other.xmin);
        self.xmax = self.xmax.max(other.xmax);
        self.ymin = self.ymin.min(other.ymin);
        self.ymax = self.ymax.max(other.ymax);
        self.zmin = self.zmin.min(other.zmin);
        self.zmax = self.zmax.max(other.zmax);
        self.hits.append(&other.hits, list_cap);
        self.overflowed |= other.overflowed;
    }
}

/// What a run of fragments of one row gives its tile's record: how many there are and how
/// many passed, the passing ones' depth range, and the first and last passing one's index
/// in the run (meaningless when none passed). A run is at most one row, so counts fit 32
/// bits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RunTally {
    pub fragments: u32,
    pub passed: u32,
    /// `u32::MAX` when none passed.
    pub zmin: u32,
    /// 0 when none passed.
    pub zmax: u32,
    pub first: u32,
    pub last: u32,
}

impl RunTally {
    /// The tally of fragments at `depths` whose tests gave `passed`.
    #[inline]
    pub fn of(depths: &[u32], passed: &[bool]) -> RunTally {
        // One whole-run reduction without branches per fragment (it vectorises).
        // (A passing fragment's mask is all ones, a failing one's zero.)
        let (mut count, mut zmin, mut zmax) = (0u32, u32::MAX, 0u32);
        for (&z, &pass) in depths.iter().zip(passed) {
            let mask = (pass as u32).wrapping_neg();
            count += pass as u32;
            zmin = zmin.min(z | !mask);
            zmax = zmax.max(z & mask);
        }
        let (mut first, mut last) = (0, 0);
        if count > 0 {
            first = passed.iter().position(|&pass| pass).unwrap_or(0);
            last = passed.iter().rposition(|&pass| pass).unwrap_or(0);
        }
        RunTally {
            fragments: depths.len() as u32,
            passed: count,
            zmin,
            zmax,
            first: first as u32,
            last: last as u32,
        }
    }
}

/// Hits a verbose buffer of `buffer_entries` keeps out of `total_hits`, and whether it
/// overflowed. On overflow the last entry holds the -1 terminator, so one hit fewer fits;
/// a buffer of exactly 8 entries has no room for hits nor terminator.
pub fn verbose_hits_kept(buffer_entries: u32, total_hits: u64) -> (u64, bool) {
    let room = (buffer_entries - BRIEF_RECORD_ENTRIES) as u64;
    if total_hits <= room {
        (total_hits, false)
    } else {
        (room.saturating_sub(1), true)
    }
}

/// A query's answer.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct QueryResult {
    pub id: u32,
    pub mode: QueryMode,
    /// One per tile, in the order the query listed them.
    pub tiles: Vec<TileResult>,
    /// How many tiles' verbose buffers overflowed (what `glRenderMode(GL_RENDER)` returns).
    pub overflowed_buffers: u32,
}

impl QueryResult {
    /// The value a GL program reads ([`QueryTotals::value`]).
    pub fn value(&self) -> u64 {
        self.totals().value()
    }

    /// Its tiles summed.
    pub fn totals(&self) -> QueryTotals {
        let mut totals = QueryTotals {
            id: self.id,
            mode: self.mode,
            tiles: self.tiles.len(),
            nohc: 0,
            phc: 0,
            held_hits: 0,
            overflowed_buffers: self.overflowed_buffers,
        };
        for tile in &self.tiles {
            totals.nohc += tile.nohc;
            totals.phc += tile.phc;
            totals.held_hits += tile.hits.len();
        }
        totals
    }
}
