//! A stretch's densest runs of depth reads: what its counts, summed over the whole stretch,
//! do not show.
//!
//! The O2-like machine's memory port grants one depth read a free cycle, and once the
//! display refresh and the host have fallen their slack behind their share `f` of its
//! cycles they take that share by force, so `n` reads in a row take about `c · n` cycles
//! (less the slack), `c = 1 / (1 - f)` (1.31 at the O2's `f` = 0.234). The rasterizer
//! emits a fragment a cycle and the prefetch asks for its read as it is emitted; no block
//! behind the rasterizer takes more than a fragment a cycle, so a lag once built stays until
//! the rasterizer idles. A run of `m` fragments of which `n` read a new word (a sliver one
//! or two pixels wide, a triangle's tip, where every fragment reads) therefore leaves the
//! depth test `c · n - m` cycles (less what the slack absorbs) further behind than the
//! rasterizer, however sparsely the
//! rest of the stretch reads: the stretch ends `max over runs (c · n - m)` later than its
//! emission (plus a read's latency). Summed over the stretch, its reads average out (a
//! box query of the city at 160x120 ending with a 168-fragment sliver, 0.6 reads a
//! fragment, took the machine 20 cycles and the formulas 9).
//!
//! The run that maximises `c · n - m` depends on `c`, which the architecture sets (display,
//! host share), so a stretch keeps the best run at each of the read costs
//! [`DENSE_READ_COSTS`] (exact ratios, so that counting is integer and the same wherever it
//! is done), and a model takes the largest `c · n - m` over them at its own `c`: exact at
//! those costs, the best of their runs between them. Found by Kadane's maximum-subarray
//! scan over the fragments' weights `p · read - q` for each cost `p / q`: one pass, a few
//! integer operations a fragment and a cost, and a run of fragments of a word already read
//! in one step.
//!
//! Where the run sits matters too: a run that ends at the stretch's last fragment leaves
//! the port behind (and the other clients owed) when the next work comes, a run inside it
//! has been worked off by then. So a stretch also keeps, at each cost, the run that ends at
//! its last fragment ([`StretchRuns::ending`]): Kadane's scan has it at every step, the
//! best run ending where the scan is.
//!
//! In a stretch that draws, the depth test's writes reach the in-order port between the
//! prefetch's reads, and a read between two writes keeps them from sharing a cycle: a read
//! then costs the port its own cycle and the cycle of the writes it splits off, `2 / (1 -
//! f)` (2.61 at the O2's `f`), which the two dearest costs cover.

/// The read costs `c = p / q` (port cycles a depth read takes, forced cycles included)
/// at which a stretch keeps its runs: `f` = 1/9, 1/5, 1/4 and 1/3 of the port's cycles
/// reserved, and (its ending runs only) for a read that splits the writes of a stretch
/// that draws (two port cycles), `f` = 1/5 and 1/3 again (5/2 and 3/1). The O2's 0.234
/// (its display refresh 0.184 and the host's 0.05) lies between 1/5 and 1/4; the host's
/// plausible 0..0.15 keeps `f` within 0.18..0.34, and below 1/9 (no display refresh) a
/// run must read 24 fragments in a row to leave the [`KEPT_LAG_CYCLES`]. Above 1/3 a model
/// takes the runs kept at 3/2 (3/1 for a drawing stretch's).
pub const DENSE_READ_COSTS: [(u64, u64); 6] = [(9, 8), (5, 4), (4, 3), (3, 2), (5, 2), (3, 1)];

/// Costs kept.
const COSTS: usize = DENSE_READ_COSTS.len();

/// The first costs of [`DENSE_READ_COSTS`], a read's own (the others a drawing stretch's):
/// the densest runs are kept at them, where a model takes their lag, the ending runs at
/// every cost.
pub const READ_ONLY_COSTS: usize = 4;

/// The least lag a run must leave to be kept, in cycles. The O2 formulas' depth test trails
/// the rasterizer after any stretch that reads by a read's latency (2 cycles at least, a
/// page hit) and the longest run of reserved cycles a read waits out (1 for any `f` up to
/// 1/2), so a run leaving less than 3 cycles tells them nothing; and most stretches then
/// keep none (on the lazy-grid walk 81% of the stretches kept a run leaving 2).
pub const KEPT_LAG_CYCLES: u64 = 3;

/// A run of consecutive fragments: how many, and how many of them read a new depth word.
/// (32 bits each keep a stretch's record small, which the analytic level copies for every
/// stretch it reads; a run of more fragments, which no primitive has, is not kept.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadRun {
    pub reads: u32,
    pub fragments: u32,
}

impl ReadRun {
    /// The cycles the run leaves the depth test behind the rasterizer at a read cost of
    /// `cost` port cycles: `cost · reads - fragments`.
    pub fn lag(self, cost: f64) -> f64 {
        cost * f64::from(self.reads) - f64::from(self.fragments)
    }
}

/// A stretch's densest runs: at each cost of [`DENSE_READ_COSTS`] the run that leaves the
/// most lag, when that is at least [`KEPT_LAG_CYCLES`]; distinct, in the costs' order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DenseRuns {
    runs: [ReadRun; COSTS],
    len: u8,
}

impl DenseRuns {
    /// No run.
    pub const NONE: DenseRuns = DenseRuns {
        runs: [ReadRun {
            reads: 0,
            fragments: 0,
        }; COSTS],
        len: 0,
    };

    /// The runs, as kept.
    #[inline]
    pub fn runs(&self) -> &[ReadRun] {
        &self.runs[..self.len as usize]
    }

    /// Add `run` unless it is kept already, or [`DENSE_READ_COSTS`]' count are.
    pub fn push(&mut self, run: ReadRun) {
        if self.runs().contains(&run) {
            return;
        }
        if let Some(slot) = self.runs.get_mut(self.len as usize) {
            *slot = run;
            self.len += 1;
        }
    }

    /// The most lag any run leaves at a read cost of `cost` port cycles (0 with none).
    pub fn lag(&self, cost: f64) -> f64 {
        self.runs()
            .iter()
            .map(|run| run.lag(cost))
            .fold(0.0, f64::max)
    }
}

/// A stretch's runs of reads as a [`DenseReadFinder`] takes them: its densest, and those
/// that end at its last fragment.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StretchRuns {
    /// At each of the [`READ_ONLY_COSTS`], the run that leaves the most lag ([`DenseRuns`]).
    pub densest: DenseRuns,
    /// At each cost, the run ending at the last fragment that leaves the most lag, when that
    /// is at least [`KEPT_LAG_CYCLES`]: what the port still owes as the stretch ends.
    pub ending: DenseRuns,
}

impl StretchRuns {
    /// No run.
    pub const NONE: StretchRuns = StretchRuns {
        densest: DenseRuns::NONE,
        ending: DenseRuns::NONE,
    };
}

/// A run being counted: reads and fragments.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Counted {
    reads: u64,
    fragments: u64,
}

/// Kadane's scan at one cost `p / q`: the best run ending at the last fragment (empty when
/// every such run leaves less than none) and the best run so far, each with its score
/// `p · reads - q · fragments`.
#[derive(Clone, Copy, Debug, Default)]
struct Scan {
    current: Counted,
    current_score: i64,
    best: Counted,
    best_score: i64,
}

/// Finds a stretch's [`StretchRuns`] as its fragments pass.
#[derive(Clone, Debug, Default)]
pub struct DenseReadFinder {
    scans: [Scan; COSTS],
    /// A fragment read a new word since the last [`Self::take`] (else no run scores).
    read: bool,
}

impl DenseReadFinder {
    /// A fragment that `read` a new word or not, then `then_same_word` fragments that read
    /// none (the rest of its word's run along a row): the same as each given alone.
    #[inline]
    pub fn fragments(&mut self, read: bool, then_same_word: u64) {
        self.read |= read;
        if !self.read {
            // Every run is empty: fragments that read nothing leave it so.
            return;
        }
        for (scan, &(p, q)) in self.scans.iter_mut().zip(&DENSE_READ_COSTS) {
            let (p, q) = (p as i64, q as i64);
            if read {
                scan.current.reads += 1;
                scan.current.fragments += 1;
                scan.current_score += p - q;
                // A run's score rises only at a read: the best can change only here.
                if scan.current_score > scan.best_score {
                    scan.best = scan.current;
                    scan.best_score = scan.current_score;
                }
            }
            scan.skip(q, then_same_word + u64::from(!read));
        }
    }

    /// No fragment read a new word since the last [`Self::take`]: it would give no run.
    #[inline]
    pub fn is_empty(&self) -> bool {
        !self.read
    }

    /// The stretch's densest runs and the runs ending at its last fragment (those leaving
    /// [`KEPT_LAG_CYCLES`] or more), and a new stretch.
    pub fn take(&mut self) -> StretchRuns {
        let mut runs = StretchRuns::NONE;
        if self.read {
            for (cost, (scan, &(_, q))) in self.scans.iter().zip(&DENSE_READ_COSTS).enumerate() {
                let kept = (KEPT_LAG_CYCLES * q) as i64;
                if cost < READ_ONLY_COSTS && scan.best_score >= kept {
                    runs.densest.push_counted(scan.best);
                }
                if scan.current_score >= kept {
                    runs.ending.push_counted(scan.current);
                }
            }
        }
        *self = DenseReadFinder::default();
        runs
    }
}

impl DenseRuns {
    /// Add a counted run, unless its counts do not fit a [`ReadRun`] (no primitive has so
    /// many fragments).
    fn push_counted(&mut self, run: Counted) {
        if let (Ok(reads), Ok(fragments)) = (u32::try_from(run.reads), u32::try_from(run.fragments))
        {
            self.push(ReadRun { reads, fragments });
        }
    }
}

impl Scan {
    /// `count` fragments that read nothing: the current run's score falls by `q` each, and
    /// once below none the run is dropped (it falls monotonically, so one step is the same).
    #[inline(always)]
    fn skip(&mut self, q: i64, count: u64) {
        if count == 0 {
            return;
        }
        let score = self.current_score - q * count as i64;
        if score < 0 {
            self.current = Counted::default();
            self.current_score = 0;
        } else {
            self.current.fragments += count;
            self.current_score = score;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    fn runs_of(pattern: &str) -> DenseRuns {
        let mut finder = DenseReadFinder::default();
        for c in pattern.chars() {
            finder.fragments(c == 'R', 0);
        }
        finder.take().densest
    }

    fn ending_of(pattern: &str) -> DenseRuns {
        let mut finder = DenseReadFinder::default();
        for c in pattern.chars() {
            finder.fragments(c == 'R', 0);
        }
        finder.take().ending
    }

    #[test]
    fn a_sliver_of_reads_is_found_inside_a_sparse_stretch() {
        // 40 sparse fragments (a read every 8), 12 that all read, 40 sparse again. At every
        // cost but 9/8 the 12 reads in a row are the densest run: 5/4 leaves 12 · 5/4 - 12
        // = 3 cycles, 4/3 4, 3/2 6 (a lone read 1/2 at most); 9/8 leaves 1.5, under the
        // three cycles kept. The same run at every cost: kept once.
        let sparse = "...R....".repeat(5);
        let pattern = format!("{sparse}{}{sparse}", "R".repeat(12));
        let runs = runs_of(&pattern);
        assert_eq!(
            runs.runs(),
            &[ReadRun {
                reads: 12,
                fragments: 12
            }]
        );
        assert_eq!(runs.lag(4.0 / 3.0), 4.0);
        assert_eq!(runs.lag(1.0), 0.0);
    }

    #[test]
    fn the_best_run_depends_on_the_cost() {
        // "RRRRRR" then ".RR" eight times: 22 reads in 30 fragments. At 3/2 (weights: a
        // read +1, a fragment without one -2) RRRRRR scores 6 and every ".RR" 0, no
        // better: RRRRRR, leaving 9 - 6 = 3 cycles. At 4/3 (+1, -3) every ".RR" scores -1:
        // RRRRRR again, leaving 2 (not kept). At 5/4 and 9/8 less. Had the costs gone to
        // 2/1 (+1, -1), every ".RR" would add 1: the whole, 44 - 30 = 14 cycles.
        let runs = runs_of(&format!("RRRRRR{}", ".RR".repeat(8)));
        assert_eq!(
            runs.runs(),
            &[ReadRun {
                reads: 6,
                fragments: 6
            }]
        );
        // At 3/2 the whole pattern leaves 33 - 30 = 3, as RRRRRR does.
        assert_eq!(runs.lag(1.5), 3.0);
        // Between the costs and past them, the kept runs give a lower bound: at 2, RRRRRR
        // alone, 12 - 6 = 6, where the whole would leave 14.
        assert_eq!(runs.lag(2.0), 6.0);
        // A longer dense stretch changes the best run by cost: 24 reads in a row, then
        // ".RRR" six times (42 reads in 48 fragments). At 9/8 (+1, -8) the 24 in a row
        // score 24 (lag 3) and every ".RRR" -5: the 24. At 3/2 (+1, -2) every ".RRR"
        // adds 1: the whole, 63 - 48 = 15.
        let runs = runs_of(&format!("{}{}", "R".repeat(24), ".RRR".repeat(6)));
        assert!(runs.runs().contains(&ReadRun {
            reads: 24,
            fragments: 24
        }));
        assert!(runs.runs().contains(&ReadRun {
            reads: 42,
            fragments: 48
        }));
        assert_eq!(runs.lag(1.125), 3.0);
        assert_eq!(runs.lag(1.5), 15.0);
    }

    #[test]
    fn runs_leaving_less_than_three_cycles_are_not_kept() {
        // A read every other fragment leaves at most 3/2 · k - (2k - 1) < 1. Five reads in a
        // row leave 7.5 - 5 = 2.5 at the dearest cost, 3/2: not kept; six leave 3.
        assert!(runs_of(&"R.".repeat(30)).runs().is_empty());
        assert!(runs_of("..RRRRR..").runs().is_empty());
        let runs = runs_of("..RRRRRR..");
        assert_eq!(
            runs.runs(),
            &[ReadRun {
                reads: 6,
                fragments: 6
            }]
        );
        assert_eq!(runs.lag(1.5), 3.0);
    }

    #[test]
    fn a_drawing_stretchs_ending_runs_are_kept_at_the_dearer_costs() {
        // At a cost `c`, `k` reads in a row leave `c · k - k`. Two in a row end a stretch
        // leaving 4 at 3/1 and 3 at 5/2 (kept, once), 1 at 3/2 (no densest run); a lone
        // read leaves 2 at 3/1 (none), as does a read every fourth fragment (two of them
        // 6 - 5 = 1).
        let two = ReadRun {
            reads: 2,
            fragments: 2,
        };
        assert_eq!(ending_of("..RR").runs(), &[two]);
        assert_eq!(ending_of("..RR").lag(3.0), 4.0);
        assert!(runs_of("..RR").runs().is_empty());
        assert!(ending_of("..R").runs().is_empty());
        assert!(ending_of(&"...R".repeat(30)).runs().is_empty());
    }

    #[test]
    fn a_run_worked_off_before_the_stretch_ends_does_not_end_it() {
        // 12 reads in a row, then 40 sparse fragments (a read every 8): the 12 are the
        // densest run, but the sparse ones work them off at every cost (at 3/1, weights +2
        // and -1, the 12 score 24 and every "...R...." -5, so -1 after five): no ending
        // run. The other way round, the 12 end the stretch at every cost that keeps them
        // (not at 9/8: 12 · 9/8 - 12 = 1.5 cycles), as its densest run too (a sparse
        // fragment before them would score less at every cost: "R...." -2 at 3/1).
        let sparse = "...R....".repeat(5);
        let twelve = ReadRun {
            reads: 12,
            fragments: 12,
        };
        let worked_off = format!("{}{sparse}", "R".repeat(12));
        assert_eq!(runs_of(&worked_off).runs(), &[twelve]);
        assert!(ending_of(&worked_off).runs().is_empty());
        let ending = format!("{sparse}{}", "R".repeat(12));
        assert_eq!(runs_of(&ending).runs(), &[twelve]);
        assert_eq!(ending_of(&ending).runs(), &[twelve]);
        assert_eq!(ending_of(&ending).lag(4.0 / 3.0), 4.0);
    }

    #[test]
    fn a_word_run_in_one_step_is_its_fragments_one_by_one() {
        let mut rng = SplitMix64(15);
        for _ in 0..200 {
            let mut whole = DenseReadFinder::default();
            let mut single = DenseReadFinder::default();
            for _ in 0..rng.below(60) {
                let read = rng.chance(50);
                let rest = rng.below(9);
                whole.fragments(read, rest);
                single.fragments(read, 0);
                for _ in 0..rest {
                    single.fragments(false, 0);
                }
            }
            assert_eq!(whole.take(), single.take());
        }
    }

    /// 300 random patterns of up to 40 fragments (60% reading), scanned: at each of
    /// `costs`, the runs `kept` of those taken never beat `best` (the brute force's lag of
    /// the pattern at the cost), and match it where it leaves [`KEPT_LAG_CYCLES`] or more.
    fn matches_brute_force(
        seed: u64,
        costs: &[(u64, u64)],
        kept: impl Fn(StretchRuns) -> DenseRuns,
        best: impl Fn(&[bool], f64) -> f64,
    ) {
        let mut rng = SplitMix64(seed);
        for _ in 0..300 {
            let reads: Vec<bool> = (0..rng.below(40)).map(|_| rng.chance(60)).collect();
            let mut finder = DenseReadFinder::default();
            for &read in &reads {
                finder.fragments(read, 0);
            }
            let runs = kept(finder.take());
            for &(p, q) in costs {
                let cost = p as f64 / q as f64;
                let best = best(&reads, cost);
                assert!(runs.lag(cost) <= best + 1e-9, "{reads:?} at {cost}");
                if best >= KEPT_LAG_CYCLES as f64 {
                    assert!((runs.lag(cost) - best).abs() < 1e-9, "{reads:?} at {cost}");
                }
            }
        }
    }

    /// The most lag of `runs` of `reads` at `cost` (none below 0).
    fn best_lag<'a>(runs: impl Iterator<Item = &'a [bool]>, cost: f64) -> f64 {
        runs.map(|run| cost * run.iter().filter(|&&r| r).count() as f64 - run.len() as f64)
            .fold(0.0, f64::max)
    }

    #[test]
    fn the_scan_finds_the_best_run_by_brute_force() {
        // The densest runs, at the read-only costs: the best of every run.
        matches_brute_force(
            16,
            &DENSE_READ_COSTS[..READ_ONLY_COSTS],
            |runs| runs.densest,
            |reads, cost| {
                let runs = (0..reads.len()).flat_map(|i| (i..reads.len()).map(move |k| (i, k)));
                best_lag(runs.map(|(i, k)| &reads[i..=k]), cost)
            },
        );
    }

    #[test]
    fn the_ending_runs_are_the_best_suffixes_by_brute_force() {
        // The ending runs, at every cost: the best of the runs ending at the last fragment.
        matches_brute_force(
            17,
            &DENSE_READ_COSTS,
            |runs| runs.ending,
            |reads, cost| best_lag((0..reads.len()).map(|i| &reads[i..]), cost),
        );
    }
}
