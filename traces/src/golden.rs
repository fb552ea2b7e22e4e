//! The functional golden model: a depth buffer and the query semantics, giving every query's
//! exact result. Every timing model must reproduce its counts.

use crate::depth_run::{test_and_write, with_kernel_in, KernelIsa, RunKernel, WithKernel};
use crate::event::{Event, Fragment, GeometryBatch, Span, DEPTH_ONE};
use crate::query::{verbose_hits_kept, QueryMode, QueryResult, QuerySpec, RunTally, TileResult};
use crate::raster::{PlaneDepths, RasterProfile, RasterSink, Rasterizer};
use crate::scene::Command;
use crate::state::{DepthFunc, Rect, RenderState};
use std::collections::HashMap;
use std::ops::Range;

/// The depth buffer: 24-bit depths, one per pixel, row by row from the bottom.
#[derive(Clone)]
pub struct DepthBuffer {
    width: u32,
    depths: Vec<u32>,
}

/// A buffer the size of a user's viewport that the allocator would not give: the viewport
/// needs more memory than the process may have (a 16384x16384 viewport's depth buffer is
/// 1 GiB).
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "the {width}x{height} viewport's {buffer} ({} MiB) could not be allocated: not enough memory for this process (a smaller viewport, or a higher memory limit)",
    bytes >> 20
)]
pub struct ViewportBufferTooLarge {
    /// What the buffer is: `depth buffer`, `ray mask`.
    pub buffer: &'static str,
    pub width: u32,
    pub height: u32,
    pub bytes: u64,
}

/// Whether the allocator gives `count` items of `T` for the `buffer` of a `width` x
/// `height` viewport: asked for the room and given it back untouched (no stable
/// allocation is both fallible and zeroed lazily, as a buffer whose pages are mapped only
/// as they are first touched must be; a room reserved and never written maps no page).
/// Every buffer the size of a user's viewport is asked for so before it is made, so that a
/// process under a memory limit stops with an error, its outputs removed, where it had
/// aborted and left a temporary file behind.
pub fn ask_for_viewport_buffer<T>(
    buffer: &'static str,
    (width, height): (u32, u32),
    count: usize,
) -> Result<(), ViewportBufferTooLarge> {
    let mut room: Vec<T> = Vec::new();
    room.try_reserve_exact(count)
        .map_err(|_| ViewportBufferTooLarge {
            buffer,
            width,
            height,
            bytes: (count as u64).saturating_mul(std::mem::size_of::<T>() as u64),
        })
}

impl DepthBuffer {
    /// A buffer cleared to 1.0, or the error when the allocator will not give it (every
    /// depth buffer of a user's viewport is made so, or by [`Self::try_unset`]:
    /// [`ask_for_viewport_buffer`]).
    pub fn try_new(width: u32, height: u32) -> Result<DepthBuffer, ViewportBufferTooLarge> {
        DepthBuffer::fits(width, height)?;
        Ok(DepthBuffer::new(width, height))
    }

    /// [`Self::unset`], or the error when the allocator will not give it.
    pub fn try_unset(width: u32, height: u32) -> Result<DepthBuffer, ViewportBufferTooLarge> {
        DepthBuffer::fits(width, height)?;
        Ok(DepthBuffer::unset(width, height))
    }

    fn fits(width: u32, height: u32) -> Result<(), ViewportBufferTooLarge> {
        let pixels = width as usize * height as usize;
        ask_for_viewport_buffer::<u32>("depth buffer", (width, height), pixels)
    }

    /// A buffer cleared to 1.0, for a viewport known to be small (tests, fixed sizes): a
    /// failed allocation aborts, as any collection's does ([`Self::try_new`] for a user's).
    pub fn new(width: u32, height: u32) -> DepthBuffer {
        DepthBuffer {
            width,
            depths: vec![DEPTH_ONE; width as usize * height as usize],
        }
    }

    /// A buffer of zeros, for a user that sets every pixel before reading it: its pages are
    /// mapped only as they are first touched (a cleared one is written whole up front). For
    /// a viewport known to be small ([`Self::try_unset`] for a user's).
    pub fn unset(width: u32, height: u32) -> DepthBuffer {
        DepthBuffer {
            width,
            depths: vec![0; width as usize * height as usize],
        }
    }

    pub fn clear(&mut self) {
        self.depths.fill(DEPTH_ONE);
    }

    /// Become a copy of `other`, reusing this buffer's memory when it is large enough (a
    /// fresh multi-megabyte buffer costs a page fault per page; a reused one does not).
    pub fn copy_from(&mut self, other: &DepthBuffer) {
        self.width = other.width;
        self.depths.clone_from(&other.depths);
    }

    pub fn get(&self, x: u16, y: u16) -> u32 {
        self.depths[y as usize * self.width as usize + x as usize]
    }

    pub fn set(&mut self, x: u16, y: u16, depth: u32) {
        self.depths[y as usize * self.width as usize + x as usize] = depth;
    }

    /// The depths of pixels `x..x + len` of row `y` (inside the buffer).
    pub fn row_mut(&mut self, x: u16, y: u16, len: usize) -> &mut [u32] {
        let start = y as usize * self.width as usize + x as usize;
        &mut self.depths[start..start + len]
    }

    /// How many fragments of `span` (inside the buffer) pass a depth test by `func` against
    /// the depths stored now (a span's pixels are distinct: what testing them one by one,
    /// writing none, gives). One loop per function, so the comparison vectorises.
    #[inline]
    pub fn count_passing(&self, func: DepthFunc, span: Span) -> u64 {
        let start = span.y as usize * self.width as usize + span.x as usize;
        let row = &self.depths[start..start + span.depths.len()];
        macro_rules! count_with {
            ($($func:ident),*) => {
                match func {
                    $(
                        DepthFunc::$func => span
                            .depths
                            .iter()
                            .zip(row)
                            .map(|(&z, &s)| DepthFunc::$func.passes(z, s) as u64)
                            .sum(),
                    )*
                }
            };
        }
        count_with!(Never, Less, Equal, Lequal, Greater, Notequal, Gequal, Always)
    }

    /// How many of `span`'s last fragments (inside the buffer) pass a depth test by `func`
    /// one after another, against the depths stored now: its fragments from the last back
    /// to the first that fails.
    #[inline]
    pub fn passing_tail(&self, func: DepthFunc, span: Span) -> usize {
        let start = span.y as usize * self.width as usize + span.x as usize;
        let row = &self.depths[start..start + span.depths.len()];
        (span.depths.iter().zip(row).rev())
            .take_while(|(&z, &stored)| func.passes(z, stored))
            .count()
    }

    /// Start fetching the depths of pixels `first..=last` of row `y` into the cache: a span
    /// of a mid-sized triangle is a few cache lines a row apart, cold in a large buffer, and
    /// waiting for each row's first miss would dominate the depth test's cost.
    #[inline(always)]
    pub fn prefetch(&self, y: u16, first: u16, last: u16) {
        let row = y as usize * self.width as usize;
        // (Columns past the row's end are not fetched: `last` may be a guess.)
        let last = (last as usize).min(self.width.saturating_sub(1) as usize);
        let span = row + first as usize..row + last + 1;
        if let Some(depths) = self.depths.get(span) {
            for line in depths.chunks(16) {
                prefetch_line(line.as_ptr());
            }
        }
    }

    /// The depth test and write of one fragment under `state`. Returns whether it passed.
    /// `writes_allowed` is false in the occlusion render modes, which never write.
    #[inline(always)]
    pub fn test(&mut self, state: &RenderState, fragment: Fragment, writes_allowed: bool) -> bool {
        if !state.depth_test {
            return true;
        }
        let slot =
            &mut self.depths[fragment.y as usize * self.width as usize + fragment.x as usize];
        let passed = state.depth_func.passes(fragment.z, *slot);
        if passed && state.depth_mask && writes_allowed {
            *slot = fragment.z;
        }
        passed
    }

    /// The depth test and write of a span inside the buffer under `state`: `passed[i]` says
    /// whether fragment `i` passed. Its pixels are distinct, so testing them all before
    /// writing any gives what testing them one by one gives.
    #[inline]
    pub fn test_span(
        &mut self,
        state: &RenderState,
        span: Span,
        writes_allowed: bool,
        passed: &mut Vec<bool>,
    ) {
        passed.clear();
        if !state.depth_test {
            passed.resize(span.depths.len(), true);
            return;
        }
        let start = span.y as usize * self.width as usize + span.x as usize;
        let row = &mut self.depths[start..start + span.depths.len()];
        // One loop per function and write enable (each a constant in its arm), so neither
        // the comparison nor the write is a jump per fragment.
        let (depths, write) = (span.depths, state.depth_mask && writes_allowed);
        macro_rules! test_with {
            ($($func:ident),*) => {
                match (state.depth_func, write) {
                    $(
                        (DepthFunc::$func, false) => {
                            test_row::<false>(depths, row, passed, |z, s| DepthFunc::$func.passes(z, s))
                        }
                        (DepthFunc::$func, true) => {
                            test_row::<true>(depths, row, passed, |z, s| DepthFunc::$func.passes(z, s))
                        }
                    )*
                }
            };
        }
        test_with!(Never, Less, Equal, Lequal, Greater, Notequal, Gequal, Always);
    }

    /// The depth test and write of a run of a row inside the buffer by `kernel`, tallied.
    #[inline(always)]
    fn test_run<K: RunKernel>(&mut self, kernel: K, run: Span) -> RunTally {
        let start = run.y as usize * self.width as usize + run.x as usize;
        let stored = &mut self.depths[start..start + run.depths.len()];
        kernel.test_and_tally(run.depths, stored)
    }

    /// The depth test and write of a run of a row inside the buffer by `test`, where nothing
    /// counts its outcomes.
    #[inline]
    fn test_run_uncounted(&mut self, test: RunTest, run: Span) {
        if test.write {
            let start = run.y as usize * self.width as usize + run.x as usize;
            let stored = &mut self.depths[start..start + run.depths.len()];
            test_and_write(test.func, run.depths, stored);
        }
    }
}

/// The depth test a span's fragments take under a state: its function (`Always` with the
/// test off) and whether a passing fragment writes its depth.
#[derive(Clone, Copy, Debug)]
struct RunTest {
    func: DepthFunc,
    write: bool,
}

impl RunTest {
    /// `writes_allowed` is false in the occlusion render modes, which never write.
    fn new(state: &RenderState, writes_allowed: bool) -> RunTest {
        match state.depth_test {
            true => RunTest {
                func: state.depth_func,
                write: state.depth_mask && writes_allowed,
            },
            false => RunTest {
                func: DepthFunc::Always,
                write: false,
            },
        }
    }
}

/// `passed[i] = passes(depths[i], stored[i])` and, with `WRITE`, `stored[i] = depths[i]`
/// where it passed, in one pass for one depth function known at compile time (a select,
/// not a branch: the loop vectorises).
#[inline(always)]
fn test_row<const WRITE: bool>(
    depths: &[u32],
    stored: &mut [u32],
    passed: &mut Vec<bool>,
    passes: impl Fn(u32, u32) -> bool,
) {
    // Into a slice made room for first: an `extend` through the zipped iterators wrote one
    // flag at a time (a tenth of the O2's cycle level on the random triangles).
    let start = passed.len();
    passed.resize(start + depths.len(), false);
    for ((&z, s), flag) in depths.iter().zip(stored).zip(&mut passed[start..]) {
        let pass = passes(z, *s);
        if WRITE {
            *s = if pass { z } else { *s };
        }
        *flag = pass;
    }
}

/// A hint to the cache that the line at `address` will be read soon; no effect on results.
#[inline(always)]
pub fn prefetch_line<T>(address: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: prefetching is only a hint: it never faults, reads nothing into the program
    // and is defined for any address.
    unsafe {
        std::arch::x86_64::_mm_prefetch(address as *const i8, std::arch::x86_64::_MM_HINT_T0);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = address;
}

/// Finds the tiles of a query that hold a pixel. Few tiles are scanned; many are bucketed
/// into a coarse grid so a grid of thousands of cells costs a lookup, not a scan.
struct TileIndex {
    /// log2 of a bucket's side in pixels.
    shift: u32,
    columns: usize,
    /// Per bucket, the range in `entries` of the tiles overlapping it.
    buckets: Vec<(u32, u32)>,
    entries: Vec<u32>,
}

/// Tile counts up to which a plain scan beats the index.
const SCAN_TILES: usize = 8;
/// Most tile references the index may hold (bounds memory for many large overlapping tiles).
const MAX_INDEX_ENTRIES: u64 = 1 << 24;

impl TileIndex {
    fn build(spec: &QuerySpec, state: &RenderState) -> Option<TileIndex> {
        if spec.tiles.len() <= SCAN_TILES {
            return None;
        }
        let shift = 5;
        let columns = (state.width as usize).div_ceil(1 << shift);
        let rows = (state.height as usize).div_ceil(1 << shift);
        // The buckets each tile overlaps (clamped to the grid), in tile order.
        let cells = |tile: &Rect| {
            let (c0, c1) = (tile.x >> shift, (tile.x + tile.width - 1) >> shift);
            let (r0, r1) = (tile.y >> shift, (tile.y + tile.height - 1) >> shift);
            let (c1, r1) = (c1.min(columns as u32 - 1), r1.min(rows as u32 - 1));
            (r0..=r1).flat_map(move |r| (c0..=c1).map(move |c| r as usize * columns + c as usize))
        };
        // Counting sort: count each bucket's tiles, then place them, so building costs two
        // allocations however many buckets and tiles there are.
        let mut total = 0u64;
        let mut counts = vec![0u32; columns * rows + 1];
        for tile in &spec.tiles {
            for cell in cells(tile) {
                counts[cell + 1] += 1;
                total += 1;
            }
            if total > MAX_INDEX_ENTRIES {
                return None;
            }
        }
        for cell in 1..counts.len() {
            counts[cell] += counts[cell - 1];
        }
        let buckets: Vec<(u32, u32)> = counts.windows(2).map(|w| (w[0], w[1])).collect();
        let mut entries = vec![0u32; total as usize];
        let mut next = counts;
        for (index, tile) in spec.tiles.iter().enumerate() {
            for cell in cells(tile) {
                entries[next[cell] as usize] = index as u32;
                next[cell] += 1;
            }
        }
        Some(TileIndex {
            shift,
            columns,
            buckets,
            entries,
        })
    }

    #[inline]
    fn candidates(&self, x: u16, y: u16) -> &[u32] {
        let bucket = (y as usize >> self.shift) * self.columns + (x as usize >> self.shift);
        let (start, end) = self.buckets[bucket];
        &self.entries[start as usize..end as usize]
    }
}

/// A verbose tile's room for hits and how many of them its result lists.
#[derive(Clone, Copy, Debug)]
struct HitRoom {
    room: u64,
    listed: usize,
}

/// Account a fragment inside a tile. Hits beyond the room are only counted (in NOHC);
/// `OpenQuery::finish` trims the list on overflow.
#[inline(always)]
fn record_in_tile(result: &mut TileResult, fragment: Fragment, passed: bool, hits: HitRoom) {
    result.record(fragment.x, fragment.y, fragment.z, passed);
    if passed && result.hits.len() < hits.room {
        result.hits.push((fragment.x, fragment.y), hits.listed);
    }
}

/// Account a run of fragments, all inside this tile, as [`record_in_tile`] does one by one:
/// the counters and bounds once, the hits in order.
#[inline]
fn record_run(result: &mut TileResult, run: Span, passed: &[bool], hits: HitRoom) {
    let Some((first, last)) = result.record_run(run.x, run.y, run.depths, passed, u64::MAX) else {
        return;
    };
    if result.hits.len() < hits.room {
        let room = hits.room - result.hits.len();
        (first..=last)
            .filter(|&i| passed[i])
            .map(|i| (run.x + i as u16, run.y))
            .take(room.min(usize::MAX as u64) as usize)
            .for_each(|hit| result.hits.push(hit, hits.listed));
    }
}

/// The fragments of `span` (indices into it) in columns `from..to` that lie inside `tile`,
/// if any do.
#[inline(always)]
fn tile_part(tile: &Rect, span: Span, from: u32, to: u32) -> Option<Range<usize>> {
    if !(tile.y..tile.y + tile.height).contains(&(span.y as u32)) {
        return None;
    }
    let first = tile.x.max(from);
    let end = (tile.x + tile.width).min(to);
    let x0 = span.x as u32;
    (first < end).then(|| (first - x0) as usize..(end - x0) as usize)
}

/// `part(tile, fragments)` for every tile of `spec` that holds fragments of `span`, with
/// the indices of those fragments in the span: each fragment once per tile, in order
/// within a tile.
#[inline(always)]
fn for_each_tile_part(
    spec: &QuerySpec,
    index: Option<&TileIndex>,
    span: Span,
    mut part: impl FnMut(usize, Range<usize>),
) {
    let (x0, len) = (span.x as u32, span.depths.len() as u32);
    let mut part_of = |tile: usize, from: u32, to: u32| {
        if let Some(inside) = tile_part(&spec.tiles[tile], span, from, to) {
            part(tile, inside);
        }
    };
    let Some(index) = index else {
        (0..spec.tiles.len()).for_each(|tile| part_of(tile, x0, x0 + len));
        return;
    };
    // Many tiles: the span cut at the index's buckets; in each piece, the tiles of its
    // bucket (each once per bucket, so each fragment once per tile, pieces in order).
    let mut from = x0;
    while from < x0 + len {
        let to = (((from >> index.shift) + 1) << index.shift).min(x0 + len);
        for &tile in index.candidates(from as u16, span.y) {
            part_of(tile as usize, from, to);
        }
        from = to;
    }
}

/// A span to test and account in the open query, with the kernel of its test.
struct SpanTally<'q, 's> {
    query: &'q mut OpenQuery,
    depth: &'q mut DepthBuffer,
    test: RunTest,
    span: Span<'s>,
}

impl WithKernel for SpanTally<'_, '_> {
    type Output = ();

    #[inline(always)]
    fn run<K: RunKernel>(self, kernel: K) {
        let SpanTally {
            query,
            depth,
            test,
            span,
        } = self;
        query.test_and_record_span(depth, (kernel, test), span);
    }
}

/// The open query's running results.
struct OpenQuery {
    spec: QuerySpec,
    tiles: Vec<TileResult>,
    index: Option<TileIndex>,
    /// Hit-list room per tile when every hit fits (verbose only), and the hits listed.
    hit_room: HitRoom,
}

impl OpenQuery {
    fn new(spec: QuerySpec, state: &RenderState) -> OpenQuery {
        let tiles = vec![TileResult::default(); spec.tiles.len()];
        let index = TileIndex::build(&spec, state);
        let hit_room = HitRoom {
            room: match spec.mode {
                QueryMode::Verbose => spec.hit_capacity() as u64,
                _ => 0,
            },
            listed: spec.listed_hits_per_tile(),
        };
        OpenQuery {
            spec,
            tiles,
            index,
            hit_room,
        }
    }

    /// Account a span (its depth tests' outcomes in `passed`) in every tile that holds its
    /// fragments.
    fn record_span(&mut self, span: Span, passed: &[bool]) {
        let OpenQuery {
            spec,
            tiles,
            index,
            hit_room,
        } = self;
        for_each_tile_part(spec, index.as_ref(), span, |tile, inside| {
            let run = span.part(inside.clone());
            record_run(&mut tiles[tile], run, &passed[inside], *hit_room);
        });
    }

    /// Whether [`Self::test_and_record_span`] may take a span under `test`: it lists no hits
    /// (they need every fragment's outcome), and testing a fragment once per tile holding it
    /// gives what testing it once gives (nothing is written, or one tile holds it).
    fn tallies_spans(&self, test: RunTest) -> bool {
        self.hit_room.room == 0 && (!test.write || self.spec.tiles.len() == 1)
    }

    /// Test a span in `depth` by `kernel` (taking `test`) and account it in every tile that
    /// holds its fragments, each part tested and tallied in one pass (when
    /// [`Self::tallies_spans`]).
    #[inline(always)]
    fn test_and_record_span<K: RunKernel>(
        &mut self,
        depth: &mut DepthBuffer,
        (kernel, test): (K, RunTest),
        span: Span,
    ) {
        let OpenQuery {
            spec, tiles, index, ..
        } = self;
        if !K::WRITES {
            // The fragments outside every tile change nothing: they are not tested.
            for_each_tile_part(spec, index.as_ref(), span, |tile, inside| {
                let run = span.part(inside);
                let tally = depth.test_run(kernel, run);
                tiles[tile].record_tally(run.x, run.y, tally, u64::MAX);
            });
            return;
        }
        // One tile: the span tested whole, its part inside the tile tallied.
        let len = span.depths.len();
        let inside = tile_part(
            &spec.tiles[0],
            span,
            span.x as u32,
            span.x as u32 + len as u32,
        )
        .unwrap_or(len..len);
        // (A span inside its tile, as most are, has no part outside: nothing to test.)
        for outside in [0..inside.start, inside.end..len] {
            if !outside.is_empty() {
                depth.test_run_uncounted(test, span.part(outside));
            }
        }
        if !inside.is_empty() {
            let run = span.part(inside);
            let tally = depth.test_run(kernel, run);
            tiles[0].record_tally(run.x, run.y, tally, u64::MAX);
        }
    }

    /// Account a fragment in every tile that holds it.
    #[inline(always)]
    fn record(&mut self, fragment: Fragment, passed: bool) {
        let OpenQuery {
            spec,
            tiles,
            index,
            hit_room,
        } = self;
        let (x, y) = (fragment.x as u32, fragment.y as u32);
        if let ([tile], [result]) = (&spec.tiles[..], &mut tiles[..]) {
            // One tile (every samples and any query): no index, no loop.
            if tile.contains(x, y) {
                record_in_tile(result, fragment, passed, *hit_room);
            }
            return;
        }
        let mut record_in = |tile: usize| {
            if spec.tiles[tile].contains(x, y) {
                record_in_tile(&mut tiles[tile], fragment, passed, *hit_room);
            }
        };
        match index {
            None => (0..spec.tiles.len()).for_each(&mut record_in),
            Some(index) => index
                .candidates(fragment.x, fragment.y)
                .iter()
                .for_each(|&tile| record_in(tile as usize)),
        }
    }

    fn finish(mut self) -> QueryResult {
        let mut overflowed_buffers = 0;
        if self.spec.mode == QueryMode::Verbose {
            for tile in &mut self.tiles {
                let (kept, overflowed) = verbose_hits_kept(self.spec.buffer_entries, tile.nohc);
                tile.hits.truncate(kept);
                tile.overflowed = overflowed;
                overflowed_buffers += overflowed as u32;
            }
        }
        QueryResult {
            id: self.spec.id,
            mode: self.spec.mode,
            tiles: self.tiles,
            overflowed_buffers,
        }
    }
}

/// How a span is tested and accounted under the current state and query: decided when they
/// change, not per span.
#[derive(Clone, Copy, Debug)]
enum SpanPlan {
    /// No query is open: the span is tested (and written) only.
    Uncounted(RunTest),
    /// Each tile's part is tested and tallied in one pass ([`OpenQuery::tallies_spans`]).
    Tallied(RunTest),
    /// Every fragment's outcome first, then accounted (hits are listed, or a written
    /// fragment may lie in several tiles).
    Outcomes,
}

/// The golden model's semantics over a fragment stream: state, depth buffer, queries.
/// It consumes [`Event`]s, so it replays a trace as readily as it follows the rasterizer.
pub struct FunctionalModel {
    state: RenderState,
    depth: DepthBuffer,
    query: Option<OpenQuery>,
    /// The last span's depth-test outcomes (reused, so spans allocate nothing).
    passed: Vec<bool>,
    plan: SpanPlan,
    /// The instructions the span kernels run in (the best this CPU has).
    isa: KernelIsa,
}

impl FunctionalModel {
    /// A model over a viewport known to be small (tests, fixed sizes; [`Self::try_new`]
    /// for a user's).
    pub fn new(width: u32, height: u32) -> FunctionalModel {
        FunctionalModel::with_depth(width, height, DepthBuffer::new(width, height))
    }

    /// A model over a user's viewport, or the error when its depth buffer cannot be had.
    pub fn try_new(width: u32, height: u32) -> Result<FunctionalModel, ViewportBufferTooLarge> {
        let depth = DepthBuffer::try_new(width, height)?;
        Ok(FunctionalModel::with_depth(width, height, depth))
    }

    fn with_depth(width: u32, height: u32, depth: DepthBuffer) -> FunctionalModel {
        let state = RenderState::new(width, height);
        FunctionalModel {
            state,
            depth,
            query: None,
            passed: Vec::new(),
            plan: SpanPlan::Uncounted(RunTest::new(&state, true)),
            isa: KernelIsa::best(),
        }
    }

    /// The plan for spans under the current state and query.
    fn span_plan(&self) -> SpanPlan {
        let test = RunTest::new(&self.state, self.writes_allowed());
        match &self.query {
            None => SpanPlan::Uncounted(test),
            Some(query) if query.tallies_spans(test) => SpanPlan::Tallied(test),
            Some(_) => SpanPlan::Outcomes,
        }
    }

    pub fn state(&self) -> &RenderState {
        &self.state
    }

    pub fn depth_buffer(&self) -> &DepthBuffer {
        &self.depth
    }

    /// Whether a passing fragment may write depth and colour now: no occlusion-render-mode
    /// query (brief, verbose) is open.
    pub fn writes_allowed(&self) -> bool {
        !self
            .query
            .as_ref()
            .is_some_and(|q| q.spec.mode.is_occlusion_render_mode())
    }

    /// Test one fragment and account it in the open query.
    #[inline(always)]
    pub fn fragment(&mut self, fragment: Fragment) {
        let writes_allowed = self.writes_allowed();
        let passed = self.depth.test(&self.state, fragment, writes_allowed);
        if let Some(query) = &mut self.query {
            query.record(fragment, passed);
        }
    }

    /// Test a span inside the viewport and account it in the open query: the same as its
    /// fragments one by one.
    #[inline]
    pub fn span(&mut self, span: Span) {
        // The next span is most likely the next row's, over about the same columns give or
        // take a triangle's edge steps: its depths (and a cache line either side) start on
        // their way into the cache while this one is tested. (The random triangles'
        // functional replay from a file, 40 runs each taking turns: best 55.2 ms and
        // median 73.5 over the row's columns alone, 54.7 and 60.7 with a line either side;
        // 65-69 ms at best with no prefetch.)
        if let Some(more) = (span.depths.len() as u16).checked_sub(1) {
            let last = span.x.wrapping_add(more);
            let (first, last) = (span.x.saturating_sub(16), last.saturating_add(16));
            self.depth.prefetch(span.y.wrapping_add(1), first, last);
        }
        match (self.plan, self.query.as_mut()) {
            (SpanPlan::Uncounted(test), _) => self.depth.test_run_uncounted(test, span),
            (SpanPlan::Tallied(test), Some(query)) => {
                let job = SpanTally {
                    query,
                    depth: &mut self.depth,
                    test,
                    span,
                };
                with_kernel_in(self.isa, test.func, test.write, job)
            }
            _ => self.span_by_outcomes(span),
        }
    }

    /// A span's fragments tested first, their outcomes then accounted in the open query.
    fn span_by_outcomes(&mut self, span: Span) {
        let writes_allowed = self.writes_allowed();
        self.depth
            .test_span(&self.state, span, writes_allowed, &mut self.passed);
        if let Some(query) = &mut self.query {
            query.record_span(span, &self.passed);
        }
    }

    /// Apply one event; a `QueryEnd` returns the query's result. `QueryResult` events (the
    /// answers stored in a trace) are ignored: this model computes its own.
    pub fn event(&mut self, event: &Event) -> Option<QueryResult> {
        if self.state.apply(event) {
            self.plan = self.span_plan();
            return None;
        }
        match event {
            Event::Clear => self.depth.clear(),
            Event::QueryBegin(spec) => {
                self.query = Some(OpenQuery::new(spec.clone(), &self.state));
                self.plan = self.span_plan();
            }
            Event::QueryEnd => {
                let result = self.query.take().map(OpenQuery::finish);
                self.plan = self.span_plan();
                return result;
            }
            Event::Fragment(f) => self.fragment(*f),
            _ => {}
        }
        None
    }
}

/// Receives an event stream (the golden model's, a trace reader's): a trace writer, a
/// machine model. The first error stops the stream where it happened.
pub trait EventSink {
    /// What can go wrong taking an event ([`std::convert::Infallible`] for sinks that cannot
    /// fail).
    type Error;

    fn event(&mut self, event: &Event) -> Result<(), Self::Error>;

    /// A span of fragments: by default its fragments one by one. Sinks that can take a whole
    /// row at once (the functional model) override this.
    #[inline]
    fn span(&mut self, span: Span) -> Result<(), Self::Error> {
        for fragment in span.fragments() {
            self.event(&Event::Fragment(fragment))?;
        }
        Ok(())
    }

    /// A span of `len` fragments at `(x, y)` whose depths `plane` gives there (a trace's
    /// plane span, format 13): by default evaluated into `room` and taken as a
    /// [`Self::span`]. A sink may take them otherwise: evaluated where it keeps depths, or
    /// not at all where it will not read them.
    #[inline(always)]
    fn plane_span(
        &mut self,
        (x, y): (u16, u16),
        len: usize,
        plane: &PlaneDepths,
        room: &mut Vec<u32>,
    ) -> Result<(), Self::Error> {
        if room.len() < len {
            room.resize(len, 0);
        }
        plane.fill(x, y, &mut room[..len]);
        self.span(Span {
            x,
            y,
            depths: &room[..len],
        })
    }

    /// The primitive just begun (its `Primitive` event sent) has the depths of `plane` at
    /// its pixels ([`crate::raster::RasterSink::depth_plane`]): not an event, a hint a
    /// trace writer keeps in place of its fragments' depths. The default ignores it.
    #[inline(always)]
    fn depth_plane(&mut self, plane: &PlaneDepths) -> Result<(), Self::Error> {
        let _ = plane;
        Ok(())
    }
}

/// The value of a result whose error cannot happen (a sink that cannot fail, as
/// [`Discard`]).
#[inline(always)]
pub fn infallible<T>(result: Result<T, std::convert::Infallible>) -> T {
    match result {
        Ok(value) => value,
        Err(never) => match never {},
    }
}

/// A sink that keeps nothing.
pub struct Discard;

impl EventSink for Discard {
    type Error = std::convert::Infallible;
    #[inline(always)]
    fn event(&mut self, _: &Event) -> Result<(), Self::Error> {
        Ok(())
    }
}

impl EventSink for Vec<Event> {
    type Error = std::convert::Infallible;
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        self.push(event.clone());
        Ok(())
    }
}

/// Scene commands in, events and query results out.
pub struct GoldenModel {
    functional: FunctionalModel,
    rasterizer: Rasterizer,
    draw: DrawCount,
    /// Whether each query that has ended passed a fragment (what conditional rendering
    /// reads); none kept where no draw is conditioned ([`Self::without_conditions`]).
    passed: Option<HashMap<u32, bool>>,
    /// Inside `begin_conditional`: whether its draws are discarded.
    discarding: Option<bool>,
}

/// The current draw's submitted triangles not yet reported in a [`GeometryBatch`].
#[derive(Default)]
struct DrawCount {
    /// Triangles given to the rasterizer since the last batch.
    pending: u32,
    /// Triangles discarded by conditional rendering in this draw.
    discarded: u32,
    /// Whether this draw has reported a batch already.
    started: bool,
}

impl DrawCount {
    /// The batch of the pending triangles, if any: it goes out before their first primitive.
    fn take_batch(&mut self) -> Option<GeometryBatch> {
        if self.pending == 0 {
            return None;
        }
        let batch = GeometryBatch {
            vertices: self.pending.saturating_mul(3),
            triangles: self.pending,
            starts_draw: !self.started,
            discarded: false,
        };
        self.pending = 0;
        self.started = true;
        Some(batch)
    }
}

/// The rasterizer's output into the functional model and the caller's sink. The rasterizer's
/// loops cannot stop, so the sink's first error waits here, and nothing more reaches the
/// sink after it ([`GoldenModel::execute`] returns it when the triangle is done).
struct Forward<'a, S: EventSink> {
    functional: &'a mut FunctionalModel,
    draw: &'a mut DrawCount,
    sink: &'a mut S,
    error: Option<S::Error>,
}

impl<S: EventSink> Forward<'_, S> {
    #[inline(always)]
    fn send(&mut self, event: &Event) {
        if self.error.is_none() {
            if let Err(error) = self.sink.event(event) {
                self.error = Some(error);
            }
        }
    }

    fn into_result(self) -> Result<(), S::Error> {
        self.error.map_or(Ok(()), Err)
    }
}

impl<S: EventSink> RasterSink for Forward<'_, S> {
    #[inline(always)]
    fn next_span(&mut self, y: u16, first: u16, last: u16) {
        self.functional.depth.prefetch(y, first, last);
    }

    #[inline(always)]
    fn primitive(&mut self) {
        if let Some(batch) = self.draw.take_batch() {
            self.send(&Event::Geometry(batch));
        }
        self.send(&Event::Primitive);
    }

    #[inline(always)]
    fn fragment(&mut self, fragment: Fragment) {
        self.functional.fragment(fragment);
        self.send(&Event::Fragment(fragment));
    }

    #[inline(always)]
    fn depth_plane(&mut self, plane: PlaneDepths) {
        if self.error.is_none() {
            if let Err(error) = self.sink.depth_plane(&plane) {
                self.error = Some(error);
            }
        }
    }
}

impl GoldenModel {
    /// A model rasterizing with the default profile ([`RasterProfile::Llvmpipe`]).
    pub fn new(width: u32, height: u32) -> GoldenModel {
        GoldenModel::with_profile(width, height, RasterProfile::default())
    }

    /// A model over a viewport known to be small (tests, fixed sizes;
    /// [`Self::try_with_profile`] for a user's).
    pub fn with_profile(width: u32, height: u32, profile: RasterProfile) -> GoldenModel {
        GoldenModel::with_functional(FunctionalModel::new(width, height), profile)
    }

    /// A model over a user's viewport, or the error when its depth buffer cannot be had.
    pub fn try_with_profile(
        width: u32,
        height: u32,
        profile: RasterProfile,
    ) -> Result<GoldenModel, ViewportBufferTooLarge> {
        let functional = FunctionalModel::try_new(width, height)?;
        Ok(GoldenModel::with_functional(functional, profile))
    }

    fn with_functional(functional: FunctionalModel, profile: RasterProfile) -> GoldenModel {
        GoldenModel {
            functional,
            rasterizer: Rasterizer::new(profile),
            draw: DrawCount::default(),
            passed: Some(HashMap::new()),
            discarding: None,
        }
    }

    /// The same model keeping no query's outcome for conditional rendering: for a driver
    /// that conditions no draw and numbers its queries on without end (the walkthroughs'),
    /// where the outcomes kept grew with every query (a walk of 100,000 frames of a small
    /// OBJ model took 8.7 MB more than one of 1,000). A conditional draw under it is drawn,
    /// as one on a query never ended is.
    pub fn without_conditions(self) -> GoldenModel {
        GoldenModel {
            passed: None,
            ..self
        }
    }

    pub fn profile(&self) -> RasterProfile {
        self.rasterizer.profile()
    }

    pub fn state(&self) -> &RenderState {
        self.functional.state()
    }

    /// Execute one command (the scene's `viewport` is the constructor's business and is
    /// ignored here), sending its events to `sink`. Returns the result of a query it ends, or
    /// the sink's first error (the command's events after it are not sent).
    ///
    /// Consecutive `tri` commands form one draw, and the rasterizer may hold a draw's
    /// triangles back until it ends (see [`Rasterizer`]): any other command ends it first,
    /// and [`GoldenModel::finish`] ends the last one. Every submitted triangle is reported in
    /// an [`Event::Geometry`] batch before the first primitive it produces (or at the draw's
    /// end, when it produces none).
    ///
    /// Inside `begin_conditional ID`, triangles are discarded when query ID passed no
    /// fragment (a query that never ended counts as passing: nothing is discarded).
    pub fn execute<S: EventSink>(
        &mut self,
        command: &Command,
        sink: &mut S,
    ) -> Result<Option<QueryResult>, S::Error> {
        if let Command::Tri(vertices) = command {
            if self.discarding == Some(true) {
                self.draw.discarded = self.draw.discarded.saturating_add(1);
                return Ok(None);
            }
            self.draw.pending = self.draw.pending.saturating_add(1);
            let state = *self.functional.state();
            let mut forward = Forward {
                functional: &mut self.functional,
                draw: &mut self.draw,
                sink,
                error: None,
            };
            self.rasterizer.triangle(&state, vertices, &mut forward);
            forward.into_result()?;
            return Ok(None);
        }
        self.finish(sink)?;
        let event = match command {
            Command::Viewport { .. } | Command::Tri(_) | Command::EndDraw => return Ok(None),
            Command::Clear => Event::Clear,
            Command::DepthFunc(f) => Event::DepthFunc(*f),
            Command::DepthMask(b) => Event::DepthMask(*b),
            Command::DepthTest(b) => Event::DepthTest(*b),
            Command::Cull(b) => Event::Cull(*b),
            Command::Scissor(s) => Event::Scissor(*s),
            Command::Begin(spec) => Event::QueryBegin(spec.clone()),
            Command::End => Event::QueryEnd,
            Command::Wait(id) => Event::Wait(*id),
            Command::BeginConditional(id) => {
                let passed = self.passed.as_ref().and_then(|passed| passed.get(id));
                self.discarding = Some(!passed.copied().unwrap_or(true));
                Event::ConditionalBegin(*id)
            }
            Command::EndConditional => {
                self.discarding = None;
                Event::ConditionalEnd
            }
            Command::Host(work) => Event::HostWork(*work),
            Command::Swap => Event::Swap,
        };
        sink.event(&event)?;
        let result = self.functional.event(&event);
        if let Some(result) = &result {
            if let Some(passed) = &mut self.passed {
                passed.insert(result.id, result.value() > 0);
            }
            sink.event(&Event::QueryResult(result.clone()))?;
        }
        Ok(result)
    }

    /// End the current draw: every triangle given so far reaches `sink` (call it at the end
    /// of a scene, or before looking at the depth buffer), and its geometry is reported.
    pub fn finish<S: EventSink>(&mut self, sink: &mut S) -> Result<(), S::Error> {
        let state = *self.functional.state();
        let mut forward = Forward {
            functional: &mut self.functional,
            draw: &mut self.draw,
            sink,
            error: None,
        };
        self.rasterizer.end_draw(&state, &mut forward);
        forward.into_result()?;
        if let Some(batch) = self.draw.take_batch() {
            sink.event(&Event::Geometry(batch))?;
        }
        if self.draw.discarded > 0 {
            sink.event(&Event::Geometry(GeometryBatch {
                vertices: self.draw.discarded.saturating_mul(3),
                triangles: self.draw.discarded,
                starts_draw: !self.draw.started,
                discarded: true,
            }))?;
        }
        self.draw = DrawCount::default();
        Ok(())
    }
}
