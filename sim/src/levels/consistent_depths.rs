//! Consistent depths: the depth buffer a machine started in the middle of a trace needs,
//! without the fragments before it.
//!
//! A machine's depth tests decide which fragments pass, and so which write depth, draw,
//! count in the Occlusion Unit and hit. The true depth buffer at a warm-up window's start is
//! the work of every fragment before it; the trace's depth-test blocks
//! ([`occsim_traces::trace::depth_tests`]) record instead whether each fragment passed. A
//! depth buffer *consistent* with those results serves as well: one under which every
//! fragment the machine replays passes exactly when it passed in the trace.
//!
//! The rule. Each pixel is unknown until the run writes it (a passing fragment with the
//! depth mask on and writes allowed) or clears it; the true depth `S` of an unknown pixel is
//! the one it held at the run's start. Each result at an unknown pixel bounds `S`: under
//! LESS, a pass says `S > z` and a fail `S <= z`; under EQUAL, a pass says `S = z` and a fail
//! `S != z`; and so on for every function. Before the machine replays a fragment at an
//! unknown pixel, the pixel is given a depth within every bound so far (`low..=high`, none
//! of the excluded values), keeping the one it has when that still is.
//!
//! Why it is exact. (1) The true `S` meets every bound, so a depth within them exists
//! (else the trace contradicts itself: an error). (2) Every fragment at an unknown pixel is
//! tested against a depth within its own bound, set before it is replayed and changed
//! afterwards only to another within it (bounds only narrow), so however long the machine
//! queues the fragment before testing it, it passes as it did in the trace. (3) Once a
//! fragment writes the pixel (in the trace, so in the machine, by (2)), the pixel holds what
//! it holds in the true buffer, and is never set again; likewise after a clear. (4) Pixels
//! the run never tests do not matter. So every depth test the machine makes has the trace's
//! outcome, and everything that follows from it (writes, the Occlusion Unit's counts, hits,
//! the port's traffic) is what the true buffer gives.

use crate::error::SimError;
use occsim_traces::golden::{prefetch_line, DepthBuffer};
use occsim_traces::state::{DepthFunc, RenderState};
use occsim_traces::trace::DepthTestResults;
use occsim_traces::Span;
use std::collections::HashMap;

/// What a run has learnt of one pixel's depth at the run's start.
#[derive(Clone, Copy)]
struct PixelBounds {
    /// `run` when `low` and `high` are this run's, `run + 1` once the pixel is known
    /// (written or cleared in this run); anything else, unknown and unbounded.
    stamp: u32,
    low: u32,
    high: u32,
}

/// A pixel's bounds as stored, in 64 bits: its stamp (the top [`STAMP_BITS`]), `low` and
/// `high` ([`BOUND_BITS`] each); zero before a run first bounds it. Depths are 24-bit (at
/// most `DEPTH_ONE`), so a `low` (at most `DEPTH_ONE + 1`) and a `high` fit, with
/// [`NO_HIGH`] for none. (Three 32-bit words a pixel made the bounds of the rows a run
/// tests 1.5x the bytes, fetched cold at every run's first test of a pixel: `sampled:10`
/// on the demo spent a tenth of its time here.)
type StoredBounds = u64;

/// Bits of a stored bound.
const BOUND_BITS: u32 = 25;
const BOUND_MASK: u64 = (1 << BOUND_BITS) - 1;
/// `high` when no test has bounded a pixel from above: above every depth.
const NO_HIGH: u32 = BOUND_MASK as u32;
/// Bits of a stored stamp: runs are even stamps below `1 << STAMP_BITS`, so the rows are
/// forgotten (reallocated) every 8,191 runs.
const STAMP_BITS: u32 = 64 - 2 * BOUND_BITS;

impl PixelBounds {
    fn load(stored: StoredBounds) -> PixelBounds {
        PixelBounds {
            stamp: (stored >> (2 * BOUND_BITS)) as u32,
            low: (stored >> BOUND_BITS & BOUND_MASK) as u32,
            high: (stored & BOUND_MASK) as u32,
        }
    }

    fn store(self) -> StoredBounds {
        debug_assert!(self.low as u64 <= BOUND_MASK && self.high as u64 <= BOUND_MASK);
        (self.stamp as u64) << (2 * BOUND_BITS) | (self.low as u64) << BOUND_BITS | self.high as u64
    }

    /// The stamp of a stored pixel's bounds.
    fn stamp_of(stored: StoredBounds) -> u32 {
        (stored >> (2 * BOUND_BITS)) as u32
    }

    /// A pixel's bounds in run `run`, stored as `stored` (not known yet): its bounds when
    /// they are this run's, else none.
    fn in_run(stored: StoredBounds, run: u32) -> PixelBounds {
        match PixelBounds::load(stored) {
            bounds if bounds.stamp == run => bounds,
            _ => PixelBounds {
                stamp: run,
                low: 0,
                high: NO_HIGH,
            },
        }
    }
}

/// The bounds on each pixel's depth at a run's start, over one run.
pub struct ConsistentDepths {
    width: usize,
    /// Per row, per pixel (a pixel's test reads its stamp and bounds in one word).
    /// A row is allocated when a span first tests it and empty before: memory follows the
    /// rows the runs test. (One zeroed vector of every pixel, 16 MB at 1280x1024, was
    /// written whole at every replay in a process that had freed one before, as a benchmark
    /// or a sweep does: 8% of a `sampled:100` run of the demo.)
    rows: Vec<Vec<StoredBounds>>,
    /// The run's stamp (even).
    run: u32,
    /// A clear in this run: every pixel is known.
    cleared: bool,
    /// Depths a pixel must not hold (an EQUAL test failed there, or a NOTEQUAL passed).
    excluded: HashMap<usize, Vec<u32>>,
    /// Fragments seen (for errors).
    fragments: u64,
}

impl ConsistentDepths {
    pub fn new(width: u32, height: u32) -> ConsistentDepths {
        ConsistentDepths {
            width: width as usize,
            rows: vec![Vec::new(); height as usize],
            run: 2,
            cleared: false,
            excluded: HashMap::new(),
            fragments: 0,
        }
    }

    /// A new machine starts: every pixel unknown again.
    pub fn restart(&mut self) {
        self.run += 2;
        if self.run + 1 >= 1 << STAMP_BITS {
            self.rows.iter_mut().for_each(|row| *row = Vec::new());
            self.run = 2;
        }
        self.cleared = false;
        self.excluded.clear();
    }

    /// A clear: every pixel holds the clear depth, known.
    pub fn clear(&mut self) {
        self.cleared = true;
    }

    /// Before the machine replays `span` under `state` (`writes_allowed`: no
    /// occlusion-render-mode query open), with the trace's `results` for it: give each
    /// unknown pixel it tests a depth in `depth` that gives its result.
    pub fn span(
        &mut self,
        state: &RenderState,
        writes_allowed: bool,
        span: Span,
        results: DepthTestResults,
        depth: &mut DepthBuffer,
    ) -> Result<(), SimError> {
        let first = self.fragments;
        self.fragments += span.depths.len() as u64;
        if !state.depth_test || self.cleared {
            return Ok(());
        }
        let writes = state.depth_mask && writes_allowed;
        // The next span is most likely the next row's, over about the same columns (as in
        // the functional model): its pixels' bounds start on their way into the cache.
        let columns = span.x as usize..span.x as usize + span.depths.len();
        if let Some(below) = self
            .rows
            .get(span.y as usize + 1)
            .and_then(|row| row.get(columns.clone()))
        {
            for line in below.chunks(8) {
                prefetch_line(line.as_ptr());
            }
            // And the machine's depths there, which `span_bounded` reads first (cold: a
            // run's first test of a pixel is this module's), then the machine.
            let last = span.x as usize + span.depths.len().max(1) - 1;
            depth.prefetch(span.y + 1, span.x, last as u16);
        }
        if self.excluded.is_empty()
            && !matches!(state.depth_func, DepthFunc::Equal | DepthFunc::Notequal)
        {
            return self.span_bounded(state.depth_func, writes, span, results, depth, first);
        }
        self.touch_row(span.y);
        let run = self.run;
        for (i, &z) in span.depths.iter().enumerate() {
            let (x, y) = (span.x + i as u16, span.y);
            let stored = self.stored(x, y);
            if PixelBounds::stamp_of(*stored) == run + 1 {
                continue;
            }
            if PixelBounds::stamp_of(*stored) != run {
                *stored = PixelBounds::in_run(*stored, run).store();
            }
            let passed = results.passed(i);
            self.bound(x, y, state.depth_func, z, passed)
                .and_then(|()| self.choose(x, y, depth.get(x, y)))
                .map(|chosen| depth.set(x, y, chosen))
                .ok_or_else(|| SimError::InconsistentDepthTests {
                    fragment: first + i as u64,
                    x,
                    y,
                })?;
            if passed && writes {
                let stored = self.stored(x, y);
                *stored = PixelBounds {
                    stamp: run + 1,
                    ..PixelBounds::load(*stored)
                }
                .store();
            }
        }
        Ok(())
    }

    /// Row `y`'s bounds, allocated (every pixel unbounded) if no run has tested it yet.
    fn touch_row(&mut self, y: u16) -> &mut [StoredBounds] {
        let row = &mut self.rows[y as usize];
        if row.is_empty() {
            *row = vec![0; self.width];
        }
        row
    }

    /// Pixel `(x, y)`'s stored bounds (its row touched already).
    fn stored(&mut self, x: u16, y: u16) -> &mut StoredBounds {
        &mut self.rows[y as usize][x as usize]
    }

    /// The key of pixel `(x, y)` among the excluded values.
    fn pixel(&self, x: u16, y: u16) -> usize {
        y as usize * self.width + x as usize
    }

    /// [`Self::span`] under a function whose results never exclude a value (neither
    /// `EQUAL` nor `NOTEQUAL`), with no value excluded in the run: the same rule, one pass
    /// over the span's row of bounds and of depths, where the depth chosen (the current
    /// one when it lies within the bounds, else the lowest that does) needs no lookup.
    /// It took `sampled:10` on the demo from 110-115 to 100-102 ms a run (whole process,
    /// best of 9), where this module had been about a fifth of the run.
    fn span_bounded(
        &mut self,
        func: DepthFunc,
        writes: bool,
        span: Span,
        results: DepthTestResults,
        depth: &mut DepthBuffer,
        first: u64,
    ) -> Result<(), SimError> {
        let (run, known) = (self.run, self.run + 1);
        let bounds = &mut self.touch_row(span.y)[span.x as usize..][..span.depths.len()];
        let depths = depth.row_mut(span.x, span.y, span.depths.len());
        for (i, ((&z, stored), current)) in span.depths.iter().zip(bounds).zip(depths).enumerate() {
            if PixelBounds::stamp_of(*stored) == known {
                continue;
            }
            let PixelBounds {
                mut low, mut high, ..
            } = PixelBounds::in_run(*stored, run);
            // `Some(true)` (a value excluded) cannot come: the caller rules out EQUAL and NOTEQUAL.
            let passed = results.passed(i);
            if narrow(func, passed, z, &mut low, &mut high) != Some(false) || low > high {
                return Err(SimError::InconsistentDepthTests {
                    fragment: first + i as u64,
                    x: span.x + i as u16,
                    y: span.y,
                });
            }
            if !(low..=high).contains(current) {
                *current = low;
            }
            let stamp = if passed && writes { known } else { run };
            *stored = PixelBounds { stamp, low, high }.store();
        }
        Ok(())
    }

    /// Narrow the pixel's bounds by a test of depth `z` under `func` that `passed`; None
    /// when no depth passes it so.
    fn bound(&mut self, x: u16, y: u16, func: DepthFunc, z: u32, passed: bool) -> Option<()> {
        let mut bounds = PixelBounds::load(*self.stored(x, y));
        if narrow(func, passed, z, &mut bounds.low, &mut bounds.high)? {
            let pixel = self.pixel(x, y);
            self.excluded.entry(pixel).or_default().push(z);
        }
        *self.stored(x, y) = bounds.store();
        (bounds.low <= bounds.high).then_some(())
    }

    /// A depth within the pixel's bounds: `current` if it is, else the lowest.
    fn choose(&self, x: u16, y: u16, current: u32) -> Option<u32> {
        let PixelBounds { low, high, .. } = PixelBounds::load(self.rows[y as usize][x as usize]);
        // Exclusions come only from EQUAL and NOTEQUAL tests: most runs have none, and then
        // a fragment costs no hash.
        let excluded = match self.excluded.is_empty() {
            true => &[][..],
            false => self
                .excluded
                .get(&self.pixel(x, y))
                .map_or(&[][..], Vec::as_slice),
        };
        if (low..=high).contains(&current) && !excluded.contains(&current) {
            return Some(current);
        }
        // At most `excluded.len()` candidates are ruled out.
        (low..=high).find(|depth| !excluded.contains(depth))
    }
}

/// What a test of depth `z` under `func` that `passed` says of the depth `S` stored:
/// `low..=high` narrowed, and true when it says `S != z` instead (`EQUAL` failed,
/// `NOTEQUAL` passed); None when no depth passes it so.
#[inline(always)]
fn narrow(func: DepthFunc, passed: bool, z: u32, low: &mut u32, high: &mut u32) -> Option<bool> {
    match (func, passed) {
        (DepthFunc::Less, true) | (DepthFunc::Gequal, false) => {
            *low = (*low).max(z.checked_add(1)?)
        }
        (DepthFunc::Less, false) | (DepthFunc::Gequal, true) => *high = (*high).min(z),
        (DepthFunc::Lequal, true) | (DepthFunc::Greater, false) => *low = (*low).max(z),
        (DepthFunc::Lequal, false) | (DepthFunc::Greater, true) => {
            *high = (*high).min(z.checked_sub(1)?)
        }
        (DepthFunc::Equal, true) | (DepthFunc::Notequal, false) => {
            (*low, *high) = ((*low).max(z), (*high).min(z))
        }
        (DepthFunc::Equal, false) | (DepthFunc::Notequal, true) => return Some(true),
        (DepthFunc::Always, true) | (DepthFunc::Never, false) => {}
        (DepthFunc::Always, false) | (DepthFunc::Never, true) => return None,
    }
    Some(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use occsim_traces::rng::SplitMix64;
    use occsim_traces::Fragment;

    const SIDE: u16 = 6;

    /// One-fragment spans with their results packed as the trace packs them.
    fn replay(
        consistent: &mut ConsistentDepths,
        state: &RenderState,
        writes_allowed: bool,
        fragment: Fragment,
        passed: bool,
        depth: &mut DepthBuffer,
    ) -> Result<(), SimError> {
        let bits = [passed as u8];
        let span = Span {
            x: fragment.x,
            y: fragment.y,
            depths: &[fragment.z],
        };
        consistent.span(
            state,
            writes_allowed,
            span,
            DepthTestResults::new(&bits, 0),
            depth,
        )
    }

    #[test]
    fn every_test_a_machine_makes_from_consistent_depths_has_the_traces_outcome() {
        // A random stream's true buffer starts at random depths (the fragments before the
        // run); a machine's buffer starts elsewhere (garbage) and is made consistent
        // fragment by fragment. Every test on it must pass as on the true one, whatever the
        // functions, masks, clears and occlusion-render modes.
        for seed in 0..200 {
            let mut rng = SplitMix64(seed);
            let (w, h) = (SIDE as u32, SIDE as u32);
            let mut truth = DepthBuffer::new(w, h);
            let mut machine = DepthBuffer::new(w, h);
            for y in 0..SIDE {
                for x in 0..SIDE {
                    truth.set(x, y, rng.below(6) as u32 * 10);
                    machine.set(x, y, rng.below(100) as u32);
                }
            }
            let mut state = RenderState::new(w, h);
            state.depth_test = true;
            let mut consistent = ConsistentDepths::new(w, h);
            consistent.restart();
            for _ in 0..60 {
                if rng.chance(10) {
                    state.depth_func = rng.pick(&DepthFunc::ALL);
                }
                if rng.chance(5) {
                    state.depth_mask = !state.depth_mask;
                }
                if rng.chance(1) {
                    truth.clear();
                    machine.clear();
                    consistent.clear();
                }
                let writes_allowed = rng.chance(70);
                let fragment = Fragment {
                    x: rng.below(SIDE as u64) as u16,
                    y: rng.below(SIDE as u64) as u16,
                    z: rng.below(6) as u32 * 10,
                };
                let passed = truth.test(&state, fragment, writes_allowed);
                replay(
                    &mut consistent,
                    &state,
                    writes_allowed,
                    fragment,
                    passed,
                    &mut machine,
                )
                .unwrap();
                assert_eq!(
                    machine.test(&state, fragment, writes_allowed),
                    passed,
                    "seed {seed}: {fragment:?} under {:?}",
                    state.depth_func
                );
            }
        }
    }

    #[test]
    fn results_no_depth_gives_are_an_error_naming_the_fragment() {
        // LESS at depth 50: a pass says S > 50; a later fail of depth 70 says S <= 70, fine;
        // a fail of depth 40 then says S <= 40: no S is both above 50 and at most 40.
        let mut state = RenderState::new(4, 4);
        state.depth_test = true;
        state.depth_func = DepthFunc::Less;
        state.depth_mask = false;
        let mut depth = DepthBuffer::new(4, 4);
        let mut consistent = ConsistentDepths::new(4, 4);
        consistent.restart();
        let at = |z| Fragment { x: 1, y: 2, z };
        let mut run = |z, passed| replay(&mut consistent, &state, true, at(z), passed, &mut depth);
        run(50, true).unwrap();
        run(70, false).unwrap();
        let error = run(40, false).unwrap_err().to_string();
        assert!(error.contains("fragment 2 at (1, 2)"), "{error}");
        // ALWAYS cannot fail.
        let mut always = ConsistentDepths::new(4, 4);
        always.restart();
        state.depth_func = DepthFunc::Always;
        assert!(replay(&mut always, &state, true, at(5), false, &mut depth).is_err());
    }

    /// A 2x2 viewport tested LESS with the depth mask off, its buffer and its consistent
    /// depths.
    fn less_without_writes() -> (RenderState, DepthBuffer, ConsistentDepths) {
        let mut state = RenderState::new(2, 2);
        state.depth_test = true;
        state.depth_func = DepthFunc::Less;
        state.depth_mask = false;
        (state, DepthBuffer::new(2, 2), ConsistentDepths::new(2, 2))
    }

    #[test]
    fn a_restart_forgets_the_last_runs_bounds() {
        // Run 1 bounds pixel (0, 0) to S <= 10 (LESS, 10 failed); run 2 sees 20 pass there
        // (S > 20): fine only if run 1's bound is forgotten.
        let (state, mut depth, mut consistent) = less_without_writes();
        let at = |z| Fragment { x: 0, y: 0, z };
        consistent.restart();
        replay(&mut consistent, &state, true, at(10), false, &mut depth).unwrap();
        consistent.restart();
        replay(&mut consistent, &state, true, at(20), true, &mut depth).unwrap();
        assert!(depth.get(0, 0) > 20);
    }

    #[test]
    fn a_run_whose_stamp_comes_round_again_forgets_the_bounds_stored_under_it() {
        // Stamps are the even numbers from 4 to 16,382 (`run + 1`, the known stamp, below
        // 2^14), then 2 after the rows are forgotten, then 4 again: 8,191 restarts after
        // the run with stamp 4 (16,382 - 4) / 2 = 8,189 bring 16,382, one more the wrap
        // to 2, one more 4. The bound S <= 10 stored in the first run with stamp 4 must not
        // hold in the second: 20 passing LESS there (S > 20) is consistent.
        let (state, mut depth, mut consistent) = less_without_writes();
        let at = |z| Fragment { x: 0, y: 0, z };
        consistent.restart();
        assert_eq!(consistent.run, 4);
        replay(&mut consistent, &state, true, at(10), false, &mut depth).unwrap();
        for _ in 0..8_191 {
            consistent.restart();
        }
        assert_eq!(consistent.run, 4);
        replay(&mut consistent, &state, true, at(20), true, &mut depth).unwrap();
        assert!(depth.get(0, 0) > 20);
    }

    #[test]
    fn the_largest_bounds_a_depth_gives_are_stored_whole() {
        // DEPTH_ONE (2^24 - 1) failing LESS says S <= DEPTH_ONE (high = 2^24 - 1); passing
        // LEQUAL at 2^24 - 2 then says S >= 2^24 - 2; the pixel is chosen within, and a
        // third test, DEPTH_ONE - 1 failing LESS (S <= 2^24 - 2), pins it: every bound
        // survived its 25 bits.
        let one = occsim_traces::event::DEPTH_ONE;
        let mut state = RenderState::new(2, 2);
        state.depth_test = true;
        state.depth_mask = false;
        let mut depth = DepthBuffer::new(2, 2);
        depth.set(0, 0, 0);
        let mut consistent = ConsistentDepths::new(2, 2);
        consistent.restart();
        let at = |z| Fragment { x: 0, y: 0, z };
        state.depth_func = DepthFunc::Less;
        replay(&mut consistent, &state, true, at(one), false, &mut depth).unwrap();
        state.depth_func = DepthFunc::Lequal;
        replay(&mut consistent, &state, true, at(one - 1), true, &mut depth).unwrap();
        state.depth_func = DepthFunc::Less;
        replay(
            &mut consistent,
            &state,
            true,
            at(one - 1),
            false,
            &mut depth,
        )
        .unwrap();
        assert_eq!(depth.get(0, 0), one - 1);
        let bounds = PixelBounds::load(consistent.rows[0][0]);
        assert_eq!((bounds.low, bounds.high), (one - 1, one - 1));
    }
}
