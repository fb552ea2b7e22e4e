//! The sampled level (`sampled:K`): the cycle model on every K-th window and on the windows
//! whose queries the formulas predict slowest, the rest extrapolated, on either machine.
//!
//! Windows are the runs of events between query ends ([`crate::levels`]): a query is the
//! unit whose latency the user asks about, and a frame of the demo holds hundreds of them, so
//! windows sample far more finely than frames would. Window `w` (from 0) is simulated when
//! `w % K == 0` (the *systematic* sample), or, on the O2-like machine at K from 2 to 15, when
//! it is one of the *slowest*: the windows of the top fifteenth of the queries by the
//! latency the formulas predict, the `ceil(n / 15)` largest of `n` (of equal ones the earlier;
//! [`SampledModel::slowest_windows`], [`QUERIES_PER_SLOWEST`], [`simulates_slowest`]),
//! found by a first pass of the formulas alone over the trace ([`SampledModel::predicting`];
//! the replay reads the trace twice, the first time as the analytic level would).
//!
//! - Why the slowest: a latency's p95 rests on the queries near the top of the
//!   distribution, and on the O2 the formulas miss a few cycles of some queries of 10 to 30
//!   (when this was measured, the port reserved cycles in a fixed phase no count told).
//!   Extrapolated from every K-th query
//!   alone, the p95 came out cycles off; with the top tenth measured (stratified sampling:
//!   that stratum is simulated whole, the rest sampled one in K), the p95's queries are
//!   measured ones. On the small corpus at sampled:10 on every machine and engine count,
//!   the worst p95 error went from 4.2% to 0.25% on the demo, 15.8% to 0% on the
//!   hierarchical walks and 5.0% to 0% on the adaptive walk; at the full scale on the O2
//!   from 4.44% to 0% on the 1x1 and 4x4 demos. What was left then, one cycle of 18 to 30,
//!   was the measured windows' own: a machine started mid-trace met the reserved cycles in
//!   another phase. Since the port's other clients became a debt that forgets its past
//!   ([`crate::blocks::memory_port`]), a machine started mid-trace meets the same port as
//!   one that ran from the start once its warm-up has let the port idle, and every class
//!   of the small corpus takes its p95 to within 0.62%. What is left is the stratum's: a
//!   query the formulas rank low and the machine finds slow is extrapolated (on the full
//!   4x4 demo at 16 engines, a samples query whose record waits behind a port the next
//!   query's reads and writes saturate: 34 cycles, predicted and given 22). It costs
//!   windows: sampled:10 on the demo on the O2 ran 319 M instructions (callgrind,
//!   the whole process), 459 M with them, 442 M since its runs decode and bound less.
//! - Only the systematic sample calibrates the extrapolation (the pipe's cycles, the
//!   latencies' regression and donors), and of it only the windows outside the slowest
//!   stratum: the slowest are not a sample of the others, which are what is extrapolated.
//!   (With the systematic windows among the slowest calibrating too, the full corpus's
//!   demo runs on the O2, at 1, 4 and 16 engines, had their worst mean latency at
//!   sampled:10 1.50% off and every query's own latency error 6.2% at the p95; now 0.91%
//!   and 0%; the small 1x1-4x4 retiled demos' worst mean on the O2 2.69%, now 0.51%; no
//!   other class moved.) A slowest window's cost and latency are measured like any
//!   simulated window's.
//! - A slowest window that is not systematic is simulated over its last fragments alone
//!   (after its warm-up) when it can be cut (below): its latency is what is wanted, and its
//!   cost past the cut is measured, the head's extrapolated.
//!
//! - Results: the functional model runs on every event, so every query's result is exact
//!   (and checked against the golden results in the stream).
//! - Cool-down: on the O2, after a sampled window the machine runs on for `L + 1` fragments
//!   (`L = min(prefetch_depth_fragments, fifo_raster_to_depth_entries)`): the prefetch
//!   issues those fragments' depth reads before the query's records reach the in-order port,
//!   so the query's latency is final only then. The InfiniteReality-like machine's latency
//!   is final at the query's end: no cool-down.
//! - Warm-up: the cycle model also runs the fragments before each
//!   sampled window and the events among them ([`warm_up_fragments`]: 4,096 on either
//!   machine at K up to 10, on the InfiniteReality-like machine up to 12,288 past it), over
//!   as many windows as that takes (from
//!   a clear fewer than that many fragments before them when there is one: a clear's port
//!   time outlasts any such count, `SampledModel::starts_at_clear`). The windows' sizes
//!   come up to K windows ahead from the trace's window table
//!   ([`occsim_traces::trace::windows`], format version 8), else from a second reading of
//!   the stream ([`WindowScout`], [`feed_window_sizes`]: the window index, else the
//!   events), the same sizes either way; a
//!   model given no sizes runs the whole window before the sampled one. A machine starts
//!   (when none is running) with the render state there and the functional model's depth
//!   buffer, or, read from the window index, depths made consistent with the trace's
//!   depth-test results ([`crate::levels::consistent_depths`]): either way its depth tests,
//!   writes, hits and counts are right, but with empty FIFOs, an idle port and a cold
//!   prefetch. Its host and geometry stage take up where the formulas' timeline has them
//!   there ([`crate::levels::predicted_loop`], the same blocks), moved onto its clock, its
//!   host waiting for the queries that ended before the start until that timeline has
//!   them answered, and its pipe starts where the formulas have the work so far
//!   ([`MachineModel::resume_front`]): a host at reset, level with the pipe, would issue
//!   again after the start the draws it had issued while the pipe worked through the ones
//!   before, and hold the pipe for them. Started inside an open query, it is told the query begins, and that query's
//!   golden result (of which it saw only the last fragments) is not given it to check. It
//!   keeps running while the next window is sampled or warm-up too, and is dropped at the
//!   first window that is neither. For K = 1 one machine runs the whole stream, and for
//!   K = 2 too unless a window is cut (below). A long window right after a simulated one
//!   is cut too: the machine that ran that one cools down in it and finishes, and a machine
//!   starts again for its tail (at the demo's sampled:10, one window of 600,000 fragments
//!   after a sampled one had been simulated whole), and so does a warm-up window whose
//!   warm-up starts past the running machine's cool-down: on the demo at sampled:10 on the
//!   O2 a machine had run on through a 316,000-fragment window to warm up the query with no
//!   fragments after it; that fix and the clear rule took the replay from 529 M to 443 M
//!   instructions (callgrind), the same 118 windows simulated.
//! - Tails: a sampled window longer than its warm-up and its machine's tail
//!   ([`tail_fragments`]: 4,096 fragments on the O2, 16,384 on the InfiniteReality-like
//!   machine; its size known, and not the last) is simulated over its tail alone. Its
//!   *head* ends at the first event other than a fragment after all but the tail's
//!   fragments (where the formulas can be read: a stretch of the index is never split),
//!   and is extrapolated as an unsampled window, its work the formulas' prediction for the
//!   window so far. The
//!   machine starts its warm-up before the cut (at a clear among them, or fewer
//!   than that many before them, as a warm-up would) and its cost is measured from the
//!   cycle its next event would have entered the pipe at the cut
//!   ([`MachineModel::entry_cycle`]); the window's work for calibration is the rest of the
//!   formulas' prediction. Its query's latency is measured as any sampled window's.
//! - From the window index (the O2 at the index's depth layout), the formulas count
//!   stretches, every window's results are the stream's golden ones, and only the simulated
//!   windows' fragments are read ([`occsim_traces::trace::TestedFragments`]): the event
//!   blocks in between are not even decompressed. The result is the one decoding every
//!   fragment gives, bit for bit (`sim/tests/window_index.rs`).
//! - A sampled window's cost is the cycle its query's `end` entered the pipe minus that of
//!   the window before it in the same machine (the final window: the machine's total cycles
//!   minus that); its query's latency is the machine's.
//! - A `swap` also ends a window (a sampled one costs up to the machine's frame end), so
//!   frames are sums of windows: each frame's time is its windows' costs, laid end to end in
//!   stream order, and a frame's end, and the run's, wait for every query answered so far,
//!   each its latency after its end token (`timeline`; an extrapolated window's swap
//!   takes the wait the formulas' timeline gives it, the answers' calibrated latencies may
//!   lengthen it).
//! - Every other window (warm-up ones included) costs `gap + pipe'`. The window's
//!   time on the analytic level's timeline ([`crate::levels::predicted_loop`]) is split
//!   into `pipe`, the formulas' `T_w` (the pipe's own work), and `gap`, the rest: the
//!   cycles the pipe waited for the host and geometry stage to release it, which the
//!   closed loop gives exactly at every level. `pipe'` calibrates `pipe` on the sampled
//!   (non-final) windows of its class `c` = (its query's mode, `s` = OccU cycles per
//!   fragment of its query), or on all sampled windows when none is of its class: within
//!   the range of their `pipe`s, by `r_c`, the ratio of the pipe's part of their measured
//!   cycles (measured minus `gap`) to their `pipe`; past the largest, the formulas' own
//!   slope (1) carries on ([`Calibration::scaled`]). The cycle model calibrates the
//!   formulas where they are off, and only there. (Scaling the whole window, host gaps
//!   included, carried a ratio learnt on a few pipe-bound windows into windows the host
//!   had held for 200,000 cycles: 11.7% short on a one-frame adaptive walk on o2, now 3.4%.)
//!   Its query's latency comes from the formulas' latency for it by a regression on the
//!   sampled queries of its class, with one slope fitted within the classes
//!   ([`Calibration::extrapolate`], [`common_slope`]), else as a window's pipe cycles
//!   come, from the sampled queries of its mode, else of all ([`Calibration::scaled`]):
//!   their ratio of measured to predicted latency below the largest of them, and past it
//!   the error that ratio gives the largest carried on (the formulas' own slope, 1).
//!   (Their mean error added at every latency, a busy-grid walk of
//!   the city at 640x480 on ir1 with one engine, whose one sampled query at K = 100 was a
//!   300-tile query the formulas take 283 cycles short, had every other query, of 138 to
//!   7,303 cycles, 283 cycles long: their median error 71.5%, now 1.2%.) A query waiting behind a
//!   clear keeps the wait the formulas see, which a mean over a few sampled queries would
//!   lose, and where the formulas' variation from query to query is noise, the mean stands.
//!   Where the formulas give many sampled queries of its class its own latency, it takes
//!   instead its nearest such query's difference from their mean ([`Donors`]), so that the
//!   latencies keep the spread the machine gives them.
//! - Bias: a machine started in a warm-up window misses whatever backlog the pipe carried
//!   to that point; the warm-up absorbs it unless it is shorter than the FIFOs (or than a
//!   clear's port time, when the clear came before the warm-up). `sampled:1` runs one
//!   machine over the whole stream, so it equals `cycle`
//!   exactly (tested); `sampled:2` too, except that half its costs are extrapolated.

use crate::arch::{Arch, Machine};
use crate::effects::Effects;
use crate::error::SimError;
use crate::levels::analytic::{service_cycles, Formulas};
use crate::levels::consistent_depths::ConsistentDepths;
use crate::levels::functional::FunctionalCore;
use crate::levels::level::{LevelResult, SampledWindows};
use crate::levels::predicted_loop::PredictedLoop;
use crate::machines::{MachineBuilder, MachineModel};
use occsim_traces::golden::DepthBuffer;
use occsim_traces::state::RenderState;
use occsim_traces::trace::{IndexItem, ReadError, TestedFragments};
pub use occsim_traces::trace::{WindowScout, WindowSize};
use occsim_traces::{Event, QueryMode, QuerySpec, Span};
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::io::Read;

/// A window's time on the predicted timeline: the formulas' `T_w` (its pipe's work) and
/// the cycles the pipe waited for the host and geometry stage before and around it. Only
/// the pipe's part is the machine's to calibrate: the closed loop's host is the same blocks
/// at every level.
#[derive(Clone, Copy, Debug, Default)]
struct Work {
    pipe: f64,
    host_gap: f64,
}

impl Work {
    /// A window that took `duration` cycles on the timeline, `cycles` of them (at most) the
    /// pipe's.
    fn of(duration: f64, cycles: f64) -> Work {
        let duration = duration.max(0.0);
        let pipe = cycles.clamp(0.0, duration);
        Work {
            pipe,
            host_gap: duration - pipe,
        }
    }

    /// What is left of this work after its `head`.
    fn after(self, head: Work) -> Work {
        Work {
            pipe: (self.pipe - head.pipe).max(0.0),
            host_gap: (self.host_gap - head.host_gap).max(0.0),
        }
    }
}

struct Window {
    /// Set when the window's query ends, its frame ends, or at the end.
    work: Work,
    /// The window's class: its query's mode code and OccU cycles per fragment.
    class: Class,
    /// The window's query ended; it closes before the next event that is not its result.
    query_ended: bool,
    /// A `swap` ended the frame inside it; it closes before the next event.
    frame_ended: bool,
    /// Its fragments so far.
    fragments: u64,
    /// Sampled over its tail alone: its head ends at the first event other than a fragment
    /// once this many of its fragments have passed ([`tail_fragments`]).
    cut_at: Option<u64>,
    /// The head's work, once cut (the window's work is the rest).
    head: Option<Work>,
    /// The head's fragments, once cut.
    head_fragments: u64,
}

impl Window {
    fn empty() -> Window {
        Window {
            work: Work::default(),
            class: None,
            query_ended: false,
            frame_ended: false,
            fragments: 0,
            cut_at: None,
            head: None,
            head_fragments: 0,
        }
    }
}

/// Fragments before a sampled window that an O2-like machine started for it replays (its
/// warm-up: the end of the window before, and of earlier windows while that one is shorter;
/// [`warm_up_fragments`]): I, plausible 4,096..65,536. The O2's state that outlives a few
/// hundred fragments is bounded by its queues (a FIFO of 16 entries, the prefetch, the write
/// buffer, one port: tens of cycles), which this many fragments fill and drain many times
/// over; a clear in the warm-up, whose port time can outlast any such count, starts the
/// machine at the clear instead. Measured with `occsim fidelity --corpus --machines o2
/// --no-rtl`, full and small, at sampled:10: every class's cycles error within 0.01% of a
/// 16,384-fragment warm-up's (the demo 0.05% -> 0.06%), its latency errors moved by a cycle
/// or none (then the phase of the port's reserved cycles at a query's end, which no warm-up
/// fixed; the port's debt now forgets it); 2,048 fragments took the demo's cycles to 0.33%. A warm-up of the
/// window before alone, however short, had left an empty window's machine with its host and
/// clears cold (the hard cases' cycles 7.7% off, now 0.7%).
pub const O2_WARM_UP_FRAGMENTS: u64 = 4_096;

/// Fragments before a sampled window that an InfiniteReality-like machine started for it
/// replays ([`warm_up_fragments`]): I, plausible 4,096..65,536. An Image Engine's queue holds
/// thousands of cycles of work when its Occlusion Unit binds (hundreds of cycles a fragment
/// on a lazy-grid walk at one engine). This was 12,288 while a machine started with its host
/// at reset: shorter warm-ups left sampled windows after host-bound ones long (8,192 took
/// the full corpus's demo to 2.27% at sampled:10, 4,096 the full demo on ir4 to 2.6%), the
/// host issuing again what it had issued before the start. With the host taken up from the
/// formulas' timeline ([`MachineModel::resume_front`]), 4,096 keeps every IR class of both
/// corpora within its bounds (`occsim fidelity --corpus --scale full|small --machines
/// ir1,ir2,ir4 --no-rtl`, worst cycles error against 12,288's with the host at reset: full,
/// the demo 0.19% -> 0.20%, the 1x1-4x4 retiled demos 0.38% -> 0.42%, the random triangles
/// 0.59% -> 0.78%, the adaptive walks 0.38% -> 0.33%, the rest within 0.02%; small, the
/// random triangles 0.58% -> 0.86%, the rest the same; every latency error as it was but
/// the small random triangles' mean, 0.11% -> 0.27%). The random triangles, which have no closed loop, are what a longer
/// warm-up still buys (8,192: 0.69% and 0.65%): their windows' costs hang on the Image
/// Engines' backlogs, which even 12,288 fragments leave a few cycles off. sampled:10 on ir4
/// then replays the demo in 75 ms against 98, the lazy-grid walk in 86 against 99 and the
/// city's hierarchical walk in 43 against 47 (one process, best of 5 interleaved; 8,192:
/// 84, 90 and 44). That is at K up to 10; past it the warm-up grows
/// ([`warm_up_fragments`]).
pub const IR_WARM_UP_FRAGMENTS: u64 = 4_096;

/// The fragments before a sampled window that `machine`'s model replays as its warm-up at
/// sampled:`every` ([`O2_WARM_UP_FRAGMENTS`], [`IR_WARM_UP_FRAGMENTS`]). On the
/// InfiniteReality-like machine it grows with K, one [`IR_WARM_UP_FRAGMENTS`] every 10 up
/// to three (12,288 from K = 21 on): the fewer windows a run samples, the less a longer
/// warm-up costs it (the formulas' pass is most of a sampled:100 run there), and the less
/// room their sampling noise leaves for the bias a short warm-up gives each window (the
/// Image Engines' backlogs a few cycles off). On the
/// small random triangles on ir4 at 4 engines, sampled:100's cycles error went from 1.18%
/// to 0.75% (over the 1% bound before) for 10% more time; at K = 10 the same warm-up would
/// take 0.87% to 0.59% for 18% more, which sampled:10's speed target does not leave.
pub fn warm_up_fragments(machine: Machine, every: u32) -> u64 {
    match machine {
        Machine::O2 => O2_WARM_UP_FRAGMENTS,
        Machine::Ir => IR_WARM_UP_FRAGMENTS * every.div_ceil(10).clamp(1, 3) as u64,
    }
}

/// Fragments at the end of a long sampled window that its machine simulates (after its
/// warm-up), on the O2-like machine; the window's head before them is extrapolated as an
/// unsampled window would be ([`tail_fragments`]): I, plausible 8,192..65,536. Windows are
/// as long as their queries make them (the demo's run from 2 to 709,000 fragments, half of
/// its fragments in windows over 150,000), so sampling every K-th window whole simulated
/// about a K-th of the fragments however large K; a fixed-size unit is what makes sampling
/// cheap (SMARTS measures units of 1,000 instructions). The tail keeps what the window's
/// cost and its query's latency depend on beyond the formulas: the pipe's state at its end,
/// which on the O2 is its FIFOs' and the port's tens of cycles. Measured with `occsim
/// fidelity --corpus --machines o2 --no-rtl`, full and small: every class's cycles and p95
/// latency errors at sampled:10 the same with a tail of 16,384 as with 65,536 (cycles within
/// 0.05%), and a sampled:10 replay of the demo and of the lazy-grid walk from their files
/// 1.2-2.0x sooner (single runs on a shared machine, whole process). With 8,192 and the
/// O2's shorter warm-up ([`O2_WARM_UP_FRAGMENTS`]) every class's cycles error is within
/// 0.01% of 16,384's and 16,384's warm-up (the demo 0.05% -> 0.06%), its latency errors a
/// cycle or none apart, and sampled:10 on the demo in one process 1.5x sooner (best of 10:
/// 46-48 -> 30-31 ms, with blocks of 256 KB). Since the port's other clients became a debt
/// that forgets its past, 4,096 against 8,192 (the same corpus runs, o2): every class's
/// latency errors (mean, p95, per-query) the same at both scales, its cycles error the same
/// but the full grid walks' (0.01% -> 0.08%); sampled:10 on the demo 8.5x -> 9.0x the cycle
/// level's rate in `cargo bench -p occsim-sim --bench fidelity` (660 -> 733 M fragments/s),
/// sampled:100 48x -> 50x; the whole process 1.06x sooner. Tried and not kept: 2,048
/// (after the index's ending runs, the same corpus runs): every class's p95 the same, but
/// the full hierarchical walks' mean latency error 0.02% -> 0.58% (their worst query 43%
/// -> 86%) and the full grid walks' cycles error 0.08% -> 0.15%, for a sampled:10 replay of
/// the demo 1.04x sooner (whole process, best of 15 interleaved, measured before them).
pub const O2_TAIL_FRAGMENTS: u64 = 4_096;

/// Fragments at the end of a long sampled window that its machine simulates on the
/// InfiniteReality-like machine ([`tail_fragments`]): I, plausible 16,384..262,144. An Image
/// Engine's queue holds thousands of cycles of work when its Occlusion Unit binds (hundreds
/// of cycles a fragment on a lazy-grid walk at one engine), and a head extrapolated by the
/// formulas carries their error there: when the formulas dealt stretches of 64 fragments,
/// tails of 16,384 took the full corpus's grid walks at one engine 1.1-2.5% long at
/// sampled:10, and this was 65,536. Since the formulas count bands of rows, 16,384 holds
/// every class within its bounds (`occsim fidelity --corpus --scale full --machines
/// ir1,ir2,ir4 --no-rtl`, worst cycles error of each class against 65,536's: the demo 0.38%
/// -> 0.61%, the adaptive walks 0.02% -> 0.39%, the grid walks 0.29% -> 0.40%, the hard
/// cases 0.65% both; every latency error within 0.01%), and sampled:10 on ir4 replays the
/// lazy-grid walk in 119 ms instead of 161, the city's hierarchical walk in 63 instead of 83
/// and the demo in 119 instead of 147 (in one process, best of 9 interleaved). A warm-up of
/// 8,192 with it took the demo to 2.27% and the random triangles to 2.62%. A head is cut
/// only where the formulas can be (at the first event other than a fragment once all but
/// this many have passed), so the tail may be shorter.
pub const IR_TAIL_FRAGMENTS: u64 = 16_384;

/// The fragments at the end of a long sampled window that `machine`'s model simulates: its
/// tail ([`O2_TAIL_FRAGMENTS`], [`IR_TAIL_FRAGMENTS`]).
pub fn tail_fragments(machine: Machine) -> u64 {
    match machine {
        Machine::O2 => O2_TAIL_FRAGMENTS,
        Machine::Ir => IR_TAIL_FRAGMENTS,
    }
}

/// Fragments from which a sampled window (or a tail) measures a rate its class keeps past
/// it ([`Calibration::of_pipe`]): half the InfiniteReality-like machine's tail, since a tail
/// is cut where the formulas can be read, most often a few fragments short of it. I,
/// plausible 8,192 to 65,536: the error a window's start and end make is tens of cycles on
/// the O2 and up to a few thousand on the InfiniteReality-like machine (an Image Engine's
/// queue at hundreds of cycles a fragment), a percent or less of the cycles this many
/// fragments take. The O2's tails are shorter and measure no rate of their own: past the
/// largest sampled window of a class the formulas' slope carries on there. From 32,768
/// (with the longer tail) to 8,192, the O2's runs of the full corpus (`occsim fidelity
/// --corpus --scale full --machines o2 --no-rtl`) kept every error but the quadtree walks'
/// sampled:10 cycles (0.01% -> 0.04%).
pub const LONG_WINDOW_FRAGMENTS: u64 = IR_TAIL_FRAGMENTS / 2;

/// Where a sampled model's window sizes come from ([`SampledModel::wants_window_size`]).
pub trait WindowSizes {
    /// The next window's size; None after the last window.
    fn next_size(&mut self) -> Result<Option<WindowSize>, SimError>;
}

/// Give `model` the window sizes it wants from `sizes`.
pub fn feed_window_sizes(
    model: &mut SampledModel,
    sizes: &mut impl WindowSizes,
) -> Result<(), SimError> {
    while model.wants_window_size() {
        model.window_size(sizes.next_size()?);
    }
    Ok(())
}

/// Extrapolation classes: (query mode code, OccU cycles per fragment) of a window's query.
type Class = Option<(u8, u64)>;

/// A closed window, as the extrapolation needs it.
struct Closed {
    work: Work,
    class: Class,
    /// The index (in the run's queries) and mode of its query, if it had one.
    query: Option<(usize, QueryMode)>,
    sampled: bool,
    /// Sampled as one of every K.
    systematic: bool,
    /// Sampled as one of every K and not one of the slowest: its measurements calibrate
    /// the extrapolation of the windows neither kind simulates.
    calibrates: bool,
    last: bool,
    /// Its fragments (a cut window's after its head).
    fragments: u64,
    /// The frame it belongs to, and whether its end is that frame's end.
    frame: u64,
    frame_ended: bool,
    /// A sampled window's head, cut while its machine ran: the cycle the machine's next
    /// event would have entered the pipe at the cut, where the tail's measured cost begins.
    mark: Option<u64>,
    /// Where it comes in the stream among the closed windows (a cut window's head before
    /// its tail).
    order: u64,
}

/// A window on the level's timeline: measured (sampled) or extrapolated.
struct Timed {
    order: u64,
    frame: u64,
    frame_ended: bool,
    /// Its cycles from the end of the window before.
    cost: f64,
    /// Its query (the index in the run's queries) and the cycles into the window its end
    /// token entered.
    token: Option<(usize, f64)>,
}

/// The run's cycles from its windows in stream order, each frame's into `frame_cycles`: a
/// window's cost after the one before, its query answered its latency (`latencies`, by
/// query) after its end token; a frame's end, and the run's, wait for every answer so far
/// (on the IR a query's merge can outlast the windows after it: a 256-tile query of a
/// one-frame scene on ir4 answered 21,214 cycles after its token, where the windows' costs
/// ended the frame at 3,890).
fn timeline(windows: &[Timed], latencies: &[Option<u64>], frame_cycles: &mut [f64]) -> f64 {
    let (mut now, mut answered) = (0.0f64, 0.0f64);
    for (k, window) in windows.iter().enumerate() {
        let start = now;
        now += window.cost;
        if let Some((index, token)) = window.token {
            let latency = latencies[index].unwrap_or(0) as f64;
            answered = answered.max(start + token + latency);
        }
        if window.frame_ended || k + 1 == windows.len() {
            now = now.max(answered);
        }
        frame_cycles[window.frame as usize] += now - start;
    }
    now
}

/// Sampled windows' figures, measured (m) beside the formulas' prediction (p) for each (a
/// query's latency, or the pipe's cycles): the sums a regression estimator needs.
#[derive(Clone, Copy, Debug, Default)]
struct Calibration {
    count: f64,
    m: f64,
    p: f64,
    pp: f64,
    pm: f64,
    /// The largest prediction among the samples.
    p_max: f64,
    /// The measured rate of the sample with the largest prediction, when it is long
    /// ([`Calibration::of_pipe`]): the slope past `p_max`, else the formulas' own (1).
    largest_rate: Option<f64>,
}

impl Calibration {
    fn of(measured: u64, predicted: u64) -> Calibration {
        Calibration::of_f64(measured as f64, predicted as f64)
    }

    fn of_f64(m: f64, p: f64) -> Calibration {
        Calibration {
            count: 1.0,
            m,
            p,
            pp: p * p,
            pm: p * m,
            p_max: p,
            largest_rate: None,
        }
    }

    /// A sampled window's pipe cycles, measured `m` and predicted `p`. A window `long` (of
    /// at least [`LONG_WINDOW_FRAGMENTS`]) measures a rate, `m / p`: the error its start
    /// and end make (the pipe filling, the backlog left behind) is small beside it, and
    /// what is left scales with the work.
    fn of_pipe(m: f64, p: f64, long: bool) -> Calibration {
        Calibration {
            largest_rate: (long && p > 0.0).then(|| m / p),
            ..Calibration::of_f64(m, p)
        }
    }

    fn add(&mut self, other: Calibration) {
        if self.count == 0.0 || other.p_max > self.p_max {
            self.largest_rate = other.largest_rate;
        }
        self.count += other.count;
        self.m += other.m;
        self.p += other.p;
        self.pp += other.pp;
        self.pm += other.pm;
        self.p_max = self.p_max.max(other.p_max);
    }

    /// Σ (p - mean p)² and Σ (p - mean p)(m - mean m) over these samples.
    fn spread(&self) -> (f64, f64) {
        if self.count == 0.0 {
            return (0.0, 0.0);
        }
        let (mean_m, mean_p) = (self.m / self.count, self.p / self.count);
        (
            self.pp - self.count * mean_p * mean_p,
            self.pm - self.count * mean_p * mean_m,
        )
    }

    /// A query's latency from the formulas' prediction for it, by survey sampling's
    /// regression estimator: these samples' mean, moved by `slope` times how far the
    /// prediction lies from their mean prediction. Past the largest sampled prediction the
    /// samples are no evidence of the slope, and the formulas' own (1) carries on: a query
    /// the formulas see waiting behind a clear, 1,300 cycles past any sampled one, waits
    /// that long whatever the few sampled queries' noise made of the slope (on the
    /// hard cases at K = 10 a slope of 0 otherwise gave the clear-held queries the
    /// sampled mean, 20 cycles for 2,700). Never below zero; None without samples.
    fn extrapolate(&self, predicted: u64, slope: f64) -> Option<f64> {
        self.extrapolate_f64(predicted as f64, slope)
    }

    /// A window's pipe cycles from the formulas' `pipe` for it (or a query's latency from
    /// theirs, where no query of its class was sampled): within the range of the sampled
    /// windows' predictions, the ratio of their measured to their predicted cycles (the
    /// cycle model calibrating the formulas where they are off); past the largest, the
    /// formulas' own slope (1), unless the largest was long and measured its own rate. A
    /// ratio learnt on small windows, whose error is mostly a constant of tens of cycles
    /// each, had scaled windows forty times their size by it: the demo at 1280x1024 on ir1,
    /// its brief windows sampled at 592-4,806 cycles (ratio 1.06) and the rest up to
    /// 183,000 (their own ratio 1.002), came out 1.56% long; 0.35% now. A long window's
    /// rate carries on past it: on the forest's lazy-grid walk on ir4 with one engine, a
    /// 300-tile query's sampled tail measured 0.953 of the formulas' 737,000 cycles, and
    /// the same queries' whole windows, four times that, measured 0.953 too; at slope 1
    /// past the tail they came out 3.4% long each, the run 1.9%. None without samples.
    fn scaled(&self, pipe: f64) -> Option<f64> {
        let ratio = if self.p > 0.0 { self.m / self.p } else { 1.0 };
        self.extrapolate_f64(pipe, ratio)
    }

    fn extrapolate_f64(&self, predicted: f64, slope: f64) -> Option<f64> {
        (self.count > 0.0).then(|| {
            let (mean_m, mean_p) = (self.m / self.count, self.p / self.count);
            let within = predicted.min(self.p_max.max(mean_p));
            let beyond = self.largest_rate.unwrap_or(1.0);
            (mean_m + slope * (within - mean_p) + beyond * (predicted - within)).max(0.0)
        })
    }
}

/// How far the formulas' latency tracks the measured one within a class, pooled over the
/// classes (the least-squares slope of measured on predicted with an intercept a class,
/// held to 0..=1): near 1 where the formulas see what makes one query wait longer than
/// another (a clear ahead of it), near 0 where their variation from query to query is noise
/// (the IR's merge-dominated latency). Between classes the formulas' differences are not
/// evidence of it: each class has its own mean. Where the classes' sampled predictions
/// spread less than one squared cycle about their means in all (none varies, or two a
/// cycle apart at most), the samples cannot tell a slope, and the formulas' own (1) is
/// taken.
fn common_slope<'a>(classes: impl Iterator<Item = &'a Calibration>) -> f64 {
    let (variance, covariance) = classes
        .map(Calibration::spread)
        .fold((0.0, 0.0), |(v, c), (dv, dc)| (v + dv, c + dc));
    // Too little spread to fit a slope to: a predicted cycle more or less is the
    // formulas' rounding as much as the query's.
    if variance >= 1.0 {
        (covariance / variance).clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// Sampled queries a cell (a class and a formulas' latency, [`Donors`]) must hold before its
/// extrapolated queries take their donors' spread: I, plausible 5..30. Fewer are too few to
/// tell the spread from the one query that happened to be sampled. Measured with
/// `occsim fidelity --corpus --scale full --machines o2 --no-rtl` (the O2's latencies, 10 to
/// 25 cycles, are where the formulas are blind to a few cycles): sampled:10's p95 latency
/// error went from 28.0% to 12.0% on the hierarchical walks, 8.70% to 0.00% on the random
/// triangles, 1.27% to 0.00% on the quadtree walk, and no class's p95 or mean latency error
/// grew, on the small corpus either; the largest error of a single query grew (the demo's
/// from 240% to 400%: a query of 5 cycles given a donor's 25). With every cell donating
/// (a minimum of 1), the 1x1 and 4x4 demos' p95 error on o2 and ir2 at 4 engines went from
/// 5.3% to 10.5%.
const MIN_CELL_DONORS: usize = 10;

/// The sampled queries' measured latencies, by *cell*: their class and the formulas'
/// latency for them. Where the formulas give a cell's queries one latency, the regression
/// gives them one too, though the machine's vary (on the O2, when the port reserved cycles
/// in a fixed pattern, by a few cycles of a 10 to 25 cycle latency: which reads of a
/// query's last primitives waited for them, which no count told). So when a cell holds at least [`MIN_CELL_DONORS`] sampled
/// queries, each of its extrapolated queries takes the measured latency of the cell's
/// sampled query nearest it in the stream (its *donor*: survey sampling's nearest-neighbour
/// hot deck), moved so that the cell's mean stays the regression's. The latencies' spread,
/// and so their p95, is then the one measured, where the regression had collapsed it; each
/// query's own latency is a draw from its cell rather than the cell's mean, so its own
/// error can grow (see [`MIN_CELL_DONORS`]).
#[derive(Default)]
struct Donors {
    /// Per cell, its sampled queries' (index, measured latency), in stream order.
    by_cell: BTreeMap<(Class, u64), Vec<(usize, u64)>>,
}

impl Donors {
    /// Sampled query `index` of `class`, predicted `predicted`, measured `measured` (in
    /// stream order).
    fn add(&mut self, class: Class, predicted: u64, index: usize, measured: u64) {
        let cell = self.by_cell.entry((class, predicted)).or_default();
        debug_assert!(cell.last().is_none_or(|&(last, _)| last < index));
        cell.push((index, measured));
    }

    /// The measured latency of the sampled query of query `index`'s cell nearest it in the
    /// stream (the earlier of two as near); None when the cell has none.
    fn nearest(&self, class: Class, predicted: u64, index: usize) -> Option<u64> {
        let cell = self.by_cell.get(&(class, predicted))?;
        if cell.len() < MIN_CELL_DONORS {
            return None;
        }
        let after = cell.partition_point(|&(sampled, _)| sampled < index);
        let before = after.checked_sub(1).map(|i| cell[i]);
        let candidates = before.into_iter().chain(cell.get(after).copied());
        candidates
            .min_by_key(|&(sampled, _)| sampled.abs_diff(index))
            .map(|(_, measured)| measured)
    }
}

/// Queries per slowest window: the sampled level simulates the windows of the top
/// fifteenth of the queries by the formulas' latency ([`slowest_of`]): I, plausible 10..20
/// (a share of 5% to 10%). The p95 the reports give is the smallest of the top 5%, and the
/// formulas misrank queries near it by a cycle or two, so the stratum reaches past it.
/// Measured with `occsim fidelity --corpus --scale full --machines o2 --no-rtl`: with the
/// top tenth, sampled:10's p95 error on the 1x1 and 4x4 demos went from 4.44% to 0.00% and
/// on the hard cases from 1.40% to 0.04%; with the top twentieth (and every 10th window)
/// the demo's went from 3.45% to 10.3%, and at sampled:20 with the top twentieth to 13.8%:
/// the p95 fell at the stratum's edge, on queries the regression had put a few cycles low.
/// Since the formulas take the runs of reads ending a stretch (format version 9), they rank
/// those queries better: the top twentieth left only the full demo's p95 off (3.70%, a
/// cycle), and the top fifteenth against the top tenth keeps every class's p95 error at
/// 0.00% at both scales (o2, 1, 4 and 16 engines), moves the mean latency errors by 0.26
/// points at most (the full 1x1 and 4x4 demos 0.97% -> 1.23%, the hard cases 0.59% ->
/// 0.84%; the small demo 0.67% -> 0.61%), and takes a sampled:10 replay of the demo 1.08x
/// sooner (whole process, best of 15 interleaved).
pub const QUERIES_PER_SLOWEST: usize = 15;

/// Whether `sampled:every` on `machine` simulates the slowest windows besides every K-th:
/// on the O2-like machine at K from 2 to [`QUERIES_PER_SLOWEST`] (past it they would be
/// more windows than every K-th; at K = 1 every window is simulated anyway). Not on the
/// InfiniteReality-like machine: its latencies, hundreds of cycles, are ones its formulas
/// extrapolate to within 1.7% at the p95 on every class of the small corpus at sampled:10
/// (every machine and engine count), and its first pass would run the formulas over the
/// whole band index once more, about the analytic level's time (15.7 ms on the demo on
/// ir4, against sampled:10's 56 ms). (Before the band index that pass decoded every
/// fragment: sampled:10 on the demo on ir4 went from 3.0x to 1.6x the cycle level's rate
/// with it.)
pub fn simulates_slowest(every: u32, machine: Machine) -> bool {
    machine == Machine::O2 && (2..=QUERIES_PER_SLOWEST as u32).contains(&every)
}

/// The windows of the top fifteenth ([`QUERIES_PER_SLOWEST`]) of the queries by
/// `latencies`, the `ceil(n / 15)` largest of `n` (of equal ones, the earlier), each query's
/// window in `windows`.
fn slowest_of(latencies: &[u64], windows: &[u64]) -> BTreeSet<u64> {
    let mut ranked: Vec<(u64, u64)> = latencies
        .iter()
        .copied()
        .zip(windows.iter().copied())
        .collect();
    ranked.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    ranked.truncate(latencies.len().div_ceil(QUERIES_PER_SLOWEST));
    ranked.into_iter().map(|(_, window)| window).collect()
}

/// One cycle-model machine over consecutive simulated windows.
struct Run {
    machine: MachineModel,
    windows: Vec<Closed>,
    /// Cooling down: fragments still to feed before the machine is finished.
    cooldown: Option<usize>,
    /// A query is open in the machine (a cool-down may stop inside one).
    query_open: bool,
    /// The machine started inside the open query, so it saw only its last fragments: its
    /// golden result is not the machine's to check.
    partial_query: bool,
    /// The cycle its pipe started at (its first window's cost counts from there).
    start: u64,
}

pub struct SampledModel {
    arch: Arch,
    effects: Effects,
    every: u32,
    /// Windows simulated besides every K-th: those whose queries the formulas predict
    /// slowest ([`SampledModel::slowest_windows`]).
    slowest: BTreeSet<u64>,
    /// No window is simulated: the formulas alone, to find the slowest
    /// ([`SampledModel::predicting`]).
    predicting: bool,
    /// Per query (in order): the window it ends.
    query_windows: Vec<u64>,
    engines: usize,
    all_tiles_one_cycle: bool,
    /// Fragments after a query's end that the machine must see before that query's
    /// latency is final (O2: the prefetch lookahead + 1; IR: none).
    cooldown_fragments: usize,
    core: FunctionalCore,
    /// The analytic formulas: every window's work.
    formulas: Formulas,
    /// The open query.
    open: Option<QuerySpec>,
    /// The formulas' windows in the closed loop: the analytic level's timeline, whose
    /// window durations are the work the sampled windows calibrate.
    predicted: PredictedLoop,
    window: Window,
    /// Windows closed so far (the index of the current one).
    windows: u64,
    run: Option<Run>,
    /// The depth buffer of the last machine that finished, reused by the next.
    spare_depth: Option<DepthBuffer>,
    sampled: u64,
    /// Of them, windows simulated only as one of the slowest.
    sampled_slowest: u64,
    /// Σ measured cycles and Σ work of the sampled, non-final windows, per class.
    pipe_by_class: BTreeMap<Class, Calibration>,
    /// Per class: the latency its sampled queries measured and the formulas predicted.
    latency_by_class: BTreeMap<Class, Calibration>,
    /// The sampled queries' measured latencies by class and the formulas' latency.
    donors: Donors,
    /// Windows closed so far (heads of cut windows included).
    closed: u64,
    /// Where the last window ended on the predicted timeline: its query's end token's
    /// entry (the machine measures its windows from token to token; a query that draws no
    /// primitive ends its window at its token, after the host's time, where the pipe's
    /// work ended long before), or the frame's end at a swap.
    boundary: f64,
    /// Windows to extrapolate.
    extrapolated: Vec<Closed>,
    /// Per query (in order): its latency if sampled.
    latencies: Vec<Option<u64>>,
    /// The latencies of the queries sampled as one of every K and not among the slowest
    /// (index, measured), in order: those that calibrate.
    calibrating_latencies: Vec<(usize, u64)>,
    /// Per query (in order): the formulas' latency, the last resort of extrapolation.
    predicted_latencies: Vec<u64>,
    /// Frames ended so far (the index of the current one).
    frames: u64,
    /// Whether the stream has closed-loop records (frames are timed only then).
    closed_loop: bool,
    /// The sampled windows, measured.
    measured: Vec<Timed>,
    width: u32,
    height: u32,
    /// Read from a window index: the machines' depths are made consistent with the trace's
    /// depth-test results as they go, instead of copied from the functional model's.
    consistent: Option<ConsistentDepths>,
    /// Queries the machines checked against the stream's golden results.
    machine_checked: u64,
    /// Window sizes handed in ahead ([`Self::window_size`]), the first for window
    /// `sizes_first`; `sizes_end` once the last was handed in. Without sizes (a model fed no
    /// [`WindowSizes`]), a warm-up window's machine runs the whole window.
    sizes: VecDeque<WindowSize>,
    sizes_first: u64,
    sizes_wanted: bool,
    sizes_end: bool,
    /// The current window is a warm-up window whose machine starts before its fragment of
    /// this number (from 0), or at a clear before it.
    warm_start: Option<u64>,
    warm_up_fragments: u64,
    /// A sampled window longer than its warm-up and this many fragments is simulated over
    /// its last `tail_fragments` alone (when its size is known).
    tail_fragments: u64,
    /// The current window's plan (sampled, warm-up, neither) is made.
    planned: bool,
    /// Sampled windows simulated over their tails alone.
    tails: u64,
}

impl SampledModel {
    pub fn new(
        arch: &Arch,
        width: u32,
        height: u32,
        effects: Effects,
        every: u32,
    ) -> Result<SampledModel, SimError> {
        let core = FunctionalCore::new(width, height)?;
        SampledModel::with_core(arch, (width, height), effects, every, core, None)
    }

    /// The model for a replay from the window index, items by
    /// [`SampledModel::index_item`]: the formulas count stretches, results are the stream's
    /// golden ones (each simulated window's still checked by its machine), and only the
    /// simulated windows' fragments are read, with their depth-test results, by a second
    /// reader ([`TestedFragments`]). The same result as [`SampledModel::new`] fed the
    /// events, at the cost of the simulated windows alone.
    pub fn from_window_index(
        arch: &Arch,
        width: u32,
        height: u32,
        effects: Effects,
        every: u32,
    ) -> Result<SampledModel, SimError> {
        let core = FunctionalCore::trusting_golden(width, height)?;
        let consistent = Some(ConsistentDepths::new(width, height));
        SampledModel::with_core(arch, (width, height), effects, every, core, consistent)
    }

    fn with_core(
        arch: &Arch,
        (width, height): (u32, u32),
        effects: Effects,
        every: u32,
        core: FunctionalCore,
        consistent: Option<ConsistentDepths>,
    ) -> Result<SampledModel, SimError> {
        let (engines, all_tiles_one_cycle, cooldown_fragments) = match arch.machine() {
            Machine::O2 => {
                let o2 = arch.o2()?;
                let lookahead = o2
                    .prefetch_depth_fragments
                    .min(o2.fifo_raster_to_depth_entries);
                (o2.occu.engines, o2.occu.all_tiles_one_cycle, lookahead + 1)
            }
            Machine::Ir => {
                let ir = arch.ir()?;
                (ir.occu.engines, ir.occu.all_tiles_one_cycle, 0)
            }
        };
        let model = SampledModel {
            arch: arch.clone(),
            effects,
            every: every.max(1),
            slowest: BTreeSet::new(),
            predicting: false,
            query_windows: Vec::new(),
            engines,
            all_tiles_one_cycle,
            cooldown_fragments,
            core,
            formulas: Formulas::new(arch, width, height)?,
            open: None,
            predicted: PredictedLoop::new(arch)?,
            window: Window::empty(),
            windows: 0,
            run: None,
            spare_depth: None,
            sampled: 0,
            sampled_slowest: 0,
            pipe_by_class: BTreeMap::new(),
            latency_by_class: BTreeMap::new(),
            donors: Donors::default(),
            closed: 0,
            boundary: 0.0,
            extrapolated: Vec::new(),
            latencies: Vec::new(),
            calibrating_latencies: Vec::new(),
            predicted_latencies: Vec::new(),
            frames: 0,
            closed_loop: false,
            measured: Vec::new(),
            width,
            height,
            consistent,
            machine_checked: 0,
            sizes: VecDeque::new(),
            sizes_first: 0,
            sizes_wanted: false,
            sizes_end: false,
            warm_start: None,
            warm_up_fragments: warm_up_fragments(arch.machine(), every),
            tail_fragments: u64::MAX,
            planned: false,
            tails: 0,
        };
        // Window 0 is planned at the first call (`plan`): a builder (`predicting`,
        // `with_slowest`, `with_window_sizes`) may yet change what it simulates, and a
        // machine started here would be dropped with its depth buffer (two 5 MB buffers
        // allocated and faulted in for nothing in the demo's sampled:10 replay).
        Ok(model)
    }

    /// Window `window` is one of every K.
    fn is_systematic(&self, window: u64) -> bool {
        !self.predicting && window.is_multiple_of(self.every as u64)
    }

    /// Window `window` is simulated: one of every K, or one of the slowest.
    fn is_sampled(&self, window: u64) -> bool {
        self.is_systematic(window) || self.slowest.contains(&window)
    }

    /// The fragments at the end of sampled window `window` its machine simulates when the
    /// window is long: [`Self::tail_fragments`] for one of every K (whose cost calibrates the
    /// rest unless it is among the slowest too); none for one simulated only as one of the
    /// slowest (unless every sampled window is simulated whole), whose query's latency is
    /// what is wanted: its machine starts its warm-up before the window's last fragments. (The demo at sampled:10 on the O2: 459 M
    /// instructions, against 549 M with the same tail for both.)
    fn tail_of(&self, window: u64) -> u64 {
        match self.is_systematic(window) || self.tail_fragments == u64::MAX {
            true => self.tail_fragments,
            false => 0,
        }
    }

    /// The first window after `window` that is simulated, if any is.
    fn next_sampled_after(&self, window: u64) -> Option<u64> {
        let every = self.every as u64;
        let systematic = (!self.predicting).then(|| window - window % every + every);
        let slowest = self.slowest.range(window + 1..).next().copied();
        match (systematic, slowest) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// This model simulates no window: it runs the formulas alone, so that
    /// [`Self::slowest_windows`] finds the windows a sampled model should simulate besides
    /// every K-th.
    pub fn predicting(mut self) -> SampledModel {
        self.predicting = true;
        self.slowest.clear();
        self
    }

    /// Besides every K-th window, simulate `windows` (from [`Self::slowest_windows`] of a
    /// predicting model over the same stream).
    pub fn with_slowest(mut self, windows: BTreeSet<u64>) -> SampledModel {
        self.slowest = windows;
        self
    }

    /// At the stream's end, the windows whose queries the formulas predict slowest: those
    /// of the `ceil(n / 15)` of the `n` queries with the largest latencies the formulas give
    /// (of equal ones, the earlier; [`slowest_of`]), the top stratum the sampled level
    /// simulates whole (see the module docs). None where [`simulates_slowest`] says so.
    pub fn slowest_windows(mut self) -> Result<BTreeSet<u64>, SimError> {
        self.plan()?;
        self.formulas.close_head();
        self.settle();
        self.close_window(true)?;
        if !simulates_slowest(self.every, self.arch.machine()) {
            return Ok(BTreeSet::new());
        }
        Ok(slowest_of(&self.predicted_latencies, &self.query_windows))
    }

    /// The model will be given the windows' sizes ahead ([`feed_window_sizes`] before every
    /// call), so that a sampled window's machine starts `warm_up_fragments` before it, and a
    /// sampled window longer than that and `tail_fragments` is simulated over its tail.
    pub fn with_window_sizes(
        mut self,
        warm_up_fragments: u64,
        tail_fragments: u64,
    ) -> SampledModel {
        self.sizes_wanted = true;
        self.warm_up_fragments = warm_up_fragments;
        self.tail_fragments = tail_fragments;
        self
    }

    /// Whether the model wants the next window's size before its next call: it keeps the
    /// sizes of the windows up to the next sampled one and one more.
    pub fn wants_window_size(&self) -> bool {
        let known = self.sizes_first + self.sizes.len() as u64;
        self.sizes_wanted && !self.sizes_end && known < self.windows + self.every as u64 + 2
    }

    /// The next window's size (None: there is no next window).
    pub fn window_size(&mut self, size: Option<WindowSize>) {
        match size {
            Some(size) => self.sizes.push_back(size),
            None => self.sizes_end = true,
        }
    }

    /// The current window needs the cycle model: sampled, or the warm-up of a sampled one.
    fn start_window(&mut self) -> Result<(), SimError> {
        let w = self.windows;
        self.warm_start = None;
        self.planned = true;
        // Where this window's machine would start, and where a sampled window's head ends.
        let (cut, start) = match self.is_sampled(w) {
            true => match self.head_fragments(w) {
                Some(head) => (Some(head), Some(head - self.warm_up_fragments)),
                None => (None, Some(0)),
            },
            false => (None, self.warm_up_start(w)),
        };
        let running = self.run.is_some();
        let warm_up = match start {
            // A machine still running from a simulated window before, and this window's
            // starting past its cool-down (a long sampled window's tail, or a long warm-up
            // window's warm-up): that one cools down and finishes, and a machine starts
            // again there.
            Some(first) if running && first > self.cooldown_fragments as u64 => {
                self.window.cut_at = cut;
                self.warm_start = Some(first);
                None
            }
            // Otherwise the running machine runs on through the window, uncut.
            Some(_) if running => Some(0),
            Some(first) => {
                self.window.cut_at = cut;
                Some(first)
            }
            None => None,
        };
        match (warm_up, &mut self.run) {
            (Some(_), Some(run)) => run.cooldown = None,
            (Some(0), None) => self.start_machine()?,
            (Some(first), None) => self.warm_start = Some(first),
            (None, _) if self.cooldown_fragments == 0 => self.flush_run()?,
            (None, Some(run)) => {
                run.cooldown.get_or_insert(self.cooldown_fragments);
            }
            (None, None) => {}
        }
        Ok(())
    }

    /// Plan the window if it is not yet (window 0 of a model given window sizes).
    fn plan(&mut self) -> Result<(), SimError> {
        match self.planned {
            true => Ok(()),
            false => self.start_window(),
        }
    }

    /// Drop the sizes of the windows before `w`: whether `w`'s is known.
    fn sizes_from(&mut self, w: u64) -> bool {
        while self.sizes_first < w && self.sizes.pop_front().is_some() {
            self.sizes_first += 1;
        }
        self.sizes_first == w && !self.sizes.is_empty()
    }

    /// The fragments of sampled window `w`'s head, when it has one.
    fn head_fragments(&mut self, w: u64) -> Option<u64> {
        self.sizes_from(w);
        self.head_ahead(0)
    }

    /// The fragments of the head of the window `ahead` after the first whose size is known,
    /// when it has one: it is longer than its warm-up and tail, and not the last window (a
    /// cut needs an event after it). Its warm-up is then within it. At K = 1 no window is
    /// cut: one machine runs the whole stream, the cycle level.
    ///
    /// Whatever its host does: a machine started mid-window takes its host up from the
    /// formulas' timeline ([`MachineModel::resume_front`]). While it started with its host
    /// at reset, a window was cut only where its host had nothing left to do from the
    /// warm-up on (a cold host did after the start what it had done long before: on an
    /// adaptive walk of the city on ir4 a tail measured 55,000 cycles for 18,000 of the
    /// pipe's work, 12% on the run's cycles). Without that rule, every class of both corpora
    /// keeps its errors but the cycles of the full frustum walks on the IR, 0.00% -> 0.03%,
    /// of the small random triangles, 0.86% -> 0.87%, and of the small hierarchical walks,
    /// 0.02% -> 0.01%, and the full frustum walks at sampled:10 run 4.0x cycle's rate instead of 1.2x on the IR
    /// and 3.6x instead of 1.2x on the O2, the full random triangles 4.2x instead of 2.4x
    /// on the O2 (one corpus run each, `occsim fidelity --corpus --no-rtl`): their windows
    /// draw to their last fragments.
    fn head_ahead(&self, ahead: usize) -> Option<u64> {
        if self.every == 1 {
            return None;
        }
        let size = *self
            .sizes
            .get(ahead)
            .filter(|_| self.sizes.len() > ahead + 1)?;
        let head = size
            .fragments
            .checked_sub(self.tail_of(self.sizes_first + ahead as u64))?;
        // A warm-up from the window's first fragment on is the whole window's.
        head.checked_sub(self.warm_up_fragments)
            .filter(|&start| start > 0)
            .map(|_| head)
    }

    /// A window ending at `end` on the predicted timeline, `cycles` of it the pipe's: its
    /// work from the last window's end on, which then moves to `end`.
    fn work_to(&mut self, end: f64, cycles: f64) -> Work {
        let work = Work::of(end - self.boundary, cycles);
        self.boundary = self.boundary.max(end);
        work
    }

    /// The formulas' work in the open window so far (its pipe cycles), and where on the
    /// predicted timeline the window would end were that all its work.
    fn work_so_far(&self) -> (f64, f64) {
        let cycles = self.formulas.finish().map_or(0.0, |end| end.cycles);
        (cycles, self.predicted.end_if_closed(cycles))
    }

    /// The window's head ends (an event other than a fragment comes after its last
    /// fragment): its work is the formulas' prediction so far, extrapolated as an unsampled
    /// window's; the machine, running since the warm-up, marks where the tail's cost begins.
    fn cut_head(&mut self) {
        self.window.cut_at = None;
        self.window.head_fragments = self.window.fragments;
        self.tails += 1;
        let (cycles, end) = self.work_so_far();
        let head = Work::of(end - self.boundary, cycles);
        self.window.head = Some(head);
        let closed = Closed {
            work: head,
            class: self.window.class,
            query: None,
            sampled: false,
            systematic: false,
            calibrates: false,
            last: false,
            fragments: self.window.fragments,
            frame: self.frames,
            frame_ended: false,
            mark: None,
            order: self.closed,
        };
        self.closed += 1;
        match &mut self.run {
            Some(run) => run.windows.push(Closed {
                mark: Some(run.machine.entry_cycle()),
                ..closed
            }),
            None => self.extrapolated.push(closed),
        }
    }

    /// Where the warm-up of the next sampled window begins in window `w` (not sampled):
    /// before its fragment of the number returned, so that [`Self::warm_up_fragments`]
    /// fragments precede the sampled window, or None when the warm-up lies wholly after
    /// `w` (or no sampled window follows). Without the windows' sizes, the warm-up is the
    /// whole window before the sampled one.
    fn warm_up_start(&mut self, w: u64) -> Option<u64> {
        let sampled = self.next_sampled_after(w)?;
        self.sizes_from(w);
        let ahead = (sampled - w) as usize;
        let known = self.sizes_first == w && self.sizes.len() > ahead;
        if known && self.head_ahead(ahead).is_some() {
            return None;
        }
        if !known {
            // At the stream's end the sizes stop with the last window: none is sampled after.
            let ended = self.sizes_end && self.sizes_first == w;
            return (!ended && self.is_sampled(w + 1)).then_some(0);
        }
        let after: u64 = self.sizes.range(1..ahead).map(|size| size.fragments).sum();
        let left = self
            .warm_up_fragments
            .checked_sub(after)
            .filter(|&left| left > 0)?;
        Some(self.sizes[0].fragments.saturating_sub(left))
    }

    /// A clear starts the machine of a pending warm-up when it comes fewer than
    /// [`Self::warm_up_fragments`] fragments before the warm-up, in a head or in a warm-up
    /// window: fragments after a clear beyond what the FIFOs hold enter the pipe only once
    /// the clear's hold on the depth test ends, so the clear's backlog is gone that many
    /// fragments later. (A warm-up window's machine had started at any clear in it: on the
    /// demo on the O2 a query with no fragments after a frame's first window, 594,707
    /// fragments from its clear, was warmed up over all of them, a third of sampled:10's
    /// machine work.)
    fn starts_at_clear(&self) -> bool {
        self.warm_start
            .is_some_and(|first| first < self.window.fragments + self.warm_up_fragments)
    }

    /// The warm-up window's machine starts before fragment `k` of the next `count` (a span or
    /// stretch), if it does.
    fn machine_starts_within(&self, count: u64) -> Option<u64> {
        match self.warm_start {
            Some(first) if first < self.window.fragments + count => {
                Some(first.saturating_sub(self.window.fragments))
            }
            _ => None,
        }
    }

    /// Start a machine from the current render state: with the functional model's depths,
    /// or with depths made consistent as it goes (from the window index). Started inside an
    /// open query, it is told the query begins.
    fn start_machine(&mut self) -> Result<(), SimError> {
        self.warm_start = None;
        // A machine still cooling down (a clear came before its cool-down's end) finishes.
        self.flush_run()?;
        let builder = MachineBuilder::new(&self.arch).effects(self.effects);
        let state = self.core.functional.state();
        let mut machine = match &mut self.consistent {
            None => builder.resume(
                state,
                self.core.functional.depth_buffer(),
                self.spare_depth.take(),
            )?,
            Some(consistent) => {
                // Every pixel's depth is set before its first test: the buffer's contents do
                // not matter. (The core's model has a one-pixel viewport.)
                consistent.restart();
                let (width, height) = (self.width, self.height);
                let depth = match self.spare_depth.take() {
                    Some(depth) => depth,
                    None => DepthBuffer::try_unset(width, height)?,
                };
                let state = RenderState {
                    width,
                    height,
                    ..*state
                };
                builder.resume_with_depths(&state, depth)?
            }
        };
        // The level's result takes the queries' tile totals only.
        machine.keep_tile_reports(false);
        let open = self.open.as_ref().filter(|_| !self.window.query_ended);
        if let Some(spec) = open {
            machine.event(&Event::QueryBegin(spec.clone()))?;
        }
        // Its host and geometry stage where the predicted timeline has them, its pipe
        // starting where the formulas have the window's work so far (after the begin
        // above, whose host work was done long before).
        let origin = self.work_so_far().1.round() as u64;
        let leads = self.formulas.board_leads();
        let merges = self.formulas.merges();
        let start = machine.resume_front(self.predicted.front(), origin, &leads, merges)?;
        self.run = Some(Run {
            start,
            machine,
            windows: Vec::new(),
            cooldown: None,
            query_open: open.is_some(),
            partial_query: open.is_some(),
        });
        Ok(())
    }

    /// Feed one event.
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        if let Event::Primitive = event {
            return self.primitive();
        }
        self.plan()?;
        if !matches!(event, Event::QueryResult(_)) {
            self.close_ended_window()?;
        }
        if self.cut_due() && !matches!(event, Event::Fragment(_)) {
            self.cut_head();
        }
        let starts = match event {
            Event::Fragment(_) => self.machine_starts_within(1).is_some(),
            Event::Clear => self.starts_at_clear(),
            _ => false,
        };
        if starts {
            self.start_machine()?;
        }
        match event {
            Event::Fragment(fragment) => {
                // In the viewport before the formulas read its depth.
                self.core.check_fragment(fragment)?;
                self.formulas.fragment(*fragment, &self.core.functional);
                self.settle();
                self.window.fragments += 1;
            }
            Event::QueryBegin(spec) => {
                let service =
                    service_cycles(spec.tiles.len(), self.engines, self.all_tiles_one_cycle);
                self.window.class = Some((spec.mode.code(), service));
                self.open = Some(spec.clone());
            }
            Event::QueryEnd => self.window.query_ended = true,
            // A frame's end closes its window: the formulas' work so far, as if the stream
            // ended there.
            Event::Swap => self.window.frame_ended = true,
            _ => {}
        }
        self.formulas.before_event(event);
        self.settle();
        let formulas = &mut self.formulas;
        let mut cut_cycles = 0.0;
        self.predicted.event(event, || {
            let cut = formulas.cut();
            cut_cycles = cut.map_or(0.0, |end| end.cycles);
            cut
        });
        if matches!(event, Event::Swap) {
            self.window.work = self.work_to(self.predicted.pipe_end(), cut_cycles);
        }
        self.formulas.idle(self.predicted.take_idle());
        self.settle();
        self.closed_loop |= event.is_closed_loop_record();
        self.formulas
            .event(event, &self.predicted, self.core.next_event())?;
        if let Some(run) = &mut self.run {
            // A wait or conditional on a query that ended before the machine started is
            // answered where the predicted timeline answers it.
            if let Event::Wait(id) | Event::ConditionalBegin(id) = event {
                if let Some(answer) = self.predicted.answer(*id) {
                    run.machine.take_answer(*id, answer);
                }
            }
            match event {
                Event::QueryResult(_) if run.partial_query => run.partial_query = false,
                _ => run.machine.event(event)?,
            }
            match event {
                Event::QueryBegin(_) => run.query_open = true,
                Event::QueryEnd => run.query_open = false,
                _ => {}
            }
            if let (Some(left), Event::Fragment(_)) = (&mut run.cooldown, event) {
                *left -= 1;
                if *left == 0 {
                    self.flush_run()?;
                }
            }
        }
        if let Some(result) = self.core.event(event)? {
            self.latencies.push(None);
            // The core ended a query, so it began here: `open` holds it.
            let predicted = self.open.take().map_or(0, |spec| {
                let start = self.predicted.window_start();
                let release = self.predicted.command_release();
                let end = self
                    .formulas
                    .end_query(&spec.shape(), &result, start, release);
                self.predicted.end_query(end, &result);
                // The window's work: its time on the predicted timeline, host gaps and all, up
                // to its end token's entry, where the machine's measured windows end too.
                let token = self.predicted.last_token();
                self.window.work = self.work_to(token, end.cycles);
                end.latency.ceil() as u64
            });
            self.predicted_latencies.push(predicted);
        }
        Ok(())
    }

    /// A primitive, as [`Self::event`] takes any other event, its steps called directly (a
    /// window index's items are nearly all primitives and stretches): the window that
    /// ended closes, a head due is cut, the formulas' run ends, the predicted front releases
    /// it (the pipe idle until then if it starts a window), the rasterizer sets it up no
    /// earlier, and a running machine takes it.
    fn primitive(&mut self) -> Result<(), SimError> {
        self.plan()?;
        self.close_ended_window()?;
        if self.cut_due() {
            self.cut_head();
        }
        self.formulas.end_run();
        self.settle();
        self.predicted.primitive();
        self.formulas.idle(self.predicted.take_idle());
        self.settle();
        self.formulas.primitive(self.predicted.release_in_window());
        if let Some(run) = &mut self.run {
            run.machine.event(&Event::Primitive)?;
        }
        self.core.primitive();
        Ok(())
    }

    /// The window's head is to be cut before the next event: its fragments reached the cut.
    fn cut_due(&self) -> bool {
        self.window
            .cut_at
            .is_some_and(|at| self.window.fragments >= at)
    }

    /// A span of fragments: the formulas, the functional model and a running machine take it
    /// whole (the machine no further than its cool-down's end).
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        self.plan()?;
        self.close_ended_window()?;
        self.core.check_span(span)?;
        self.formulas.span(span, &self.core.functional);
        self.settle();
        let len = span.depths.len();
        // A running machine takes the span whole (it may fast-forward it), or up to the end
        // of its cool-down; then a machine waiting to start starts inside it.
        let taken = self.run_share(len as u64) as usize;
        if let Some(run) = &mut self.run {
            run.machine.span(span.part(0..taken))?;
        }
        self.cool_down(taken as u64)?;
        let starts = self.machine_starts_within(len as u64);
        self.window.fragments += len as u64;
        if let Some(first) = starts {
            // The warm-up machine starts inside the span: with the depths before its part.
            let first = first as usize;
            debug_assert!(
                first >= taken,
                "a machine starts after the cool-down before it"
            );
            self.core.apply_span(span.part(0..first));
            self.start_machine()?;
            let rest = span.part(first..len);
            if let Some(run) = &mut self.run {
                run.machine.span(rest)?;
            }
            self.core.apply_span(rest);
            return Ok(());
        }
        self.core.apply_span(span);
        Ok(())
    }

    /// One item of a window index (a model made by [`SampledModel::from_window_index`]):
    /// an event, or a stretch of fragments the formulas count whole and a running machine
    /// takes from `fragments` (the rest are passed over there, unread).
    pub fn index_item<R: Read>(
        &mut self,
        item: &IndexItem,
        fragments: &mut TestedFragments<R>,
    ) -> Result<(), ReadError<SimError>> {
        self.plan().map_err(ReadError::Sink)?;
        if let IndexItem::Event(event) = item {
            self.event(event).map_err(ReadError::Sink)?;
            if let (Event::Clear, Some(consistent)) = (event, &mut self.consistent) {
                consistent.clear();
            }
            return Ok(());
        }
        self.close_ended_window().map_err(ReadError::Sink)?;
        let state = *self.core.functional.state();
        // The O2's formulas count the window index's stretches, the IR's the band index's
        // bands.
        let count = match item {
            IndexItem::Stretch(stretch) => {
                self.formulas.stretch(stretch, &state);
                stretch.fragments
            }
            IndexItem::Band(band) => {
                self.formulas.band(band);
                band.fragments()
            }
            IndexItem::Event(_) => return Ok(()),
            IndexItem::Shape(_) | IndexItem::Totals(_) => {
                unreachable!("the sampled level reads whole queries: its machines begin with them")
            }
        };
        self.settle();
        self.core.count_fragments(count);
        // A running machine takes the stretch, or its cool-down's part of it; then a machine
        // waiting to start starts inside it (after a cool-down that ends there).
        let taken = self.run_takes(fragments, count, &state)?;
        let starts = self.machine_starts_within(count);
        self.window.fragments += count;
        let Some(first) = starts else {
            fragments.skip(count - taken);
            return Ok(());
        };
        debug_assert!(
            first >= taken,
            "a machine starts after the cool-down before it"
        );
        fragments.skip(first - taken);
        self.start_machine().map_err(ReadError::Sink)?;
        self.run_takes(fragments, count - first, &state)?;
        Ok(())
    }

    /// The running machine (if any) takes the next `count` of the index's fragments, or as
    /// many as its cool-down has left (then it finishes): how many it took.
    fn run_takes<R: Read>(
        &mut self,
        fragments: &mut TestedFragments<R>,
        count: u64,
        state: &RenderState,
    ) -> Result<u64, ReadError<SimError>> {
        let taken = self.run_share(count);
        let (Some(run), Some(consistent)) = (&mut self.run, &mut self.consistent) else {
            return Ok(0);
        };
        let writes_allowed = self.core.writes_allowed();
        fragments.take(taken, |span, results| {
            let depth = run.machine.depth_buffer_mut();
            consistent.span(state, writes_allowed, span, results, depth)?;
            run.machine.span(span)
        })?;
        self.cool_down(taken).map_err(ReadError::Sink)?;
        Ok(taken)
    }

    /// How many of the next `count` fragments the running machine takes: all of them, or
    /// those up to its cool-down's end; none without a machine.
    fn run_share(&self, count: u64) -> u64 {
        self.run.as_ref().map_or(0, |run| {
            run.cooldown.map_or(count, |left| count.min(left as u64))
        })
    }

    /// The running machine took `taken` fragments: a cooling machine counts them off its
    /// cool-down, and finishes at its end.
    fn cool_down(&mut self, taken: u64) -> Result<(), SimError> {
        if let Some(left) = self.run.as_mut().and_then(|run| run.cooldown.as_mut()) {
            *left -= taken as usize;
            if *left == 0 {
                self.flush_run()?;
            }
        }
        Ok(())
    }

    /// After a query's end and its golden result, or a frame's end, the next event opens a
    /// new window.
    fn close_ended_window(&mut self) -> Result<(), SimError> {
        if self.window.query_ended || self.window.frame_ended {
            self.close_window(false)?;
            self.window = Window::empty();
            self.start_window()?;
        }
        Ok(())
    }

    /// Close the current window: hand it to the running machine's run or to extrapolation.
    /// A window whose query ended closes only after that query's result (its golden one,
    /// read from an index), or it is the error that it is missing.
    fn close_window(&mut self, last: bool) -> Result<(), SimError> {
        if last && !self.window.query_ended && !self.window.frame_ended {
            // On the predicted timeline: from the last window's end to this one's.
            let start = self.predicted.window_start();
            self.window.work = self.formulas.finish().map_or(Work::default(), |w| {
                Work::of(start + w.cycles - self.boundary, w.cycles)
            });
        }
        // Every window closed on a query's end took one of the latencies, this one the next.
        if self.window.query_ended && self.latencies.len() <= self.query_windows.len() {
            return Err(SimError::MissingGolden);
        }
        let query = self
            .window
            .query_ended
            .then(|| self.latencies.len() - 1)
            .map(|index| (index, self.core.query_mode(index)));
        if query.is_some() {
            self.query_windows.push(self.windows);
        }
        let work = match self.window.head {
            Some(head) => self.window.work.after(head),
            None => self.window.work,
        };
        let closed = Closed {
            work,
            class: self.window.class,
            query,
            sampled: self.is_sampled(self.windows),
            systematic: self.is_systematic(self.windows),
            calibrates: self.is_systematic(self.windows) && !self.slowest.contains(&self.windows),
            last,
            fragments: self.window.fragments - self.window.head_fragments,
            frame: self.frames,
            frame_ended: self.window.frame_ended,
            mark: None,
            order: self.closed,
        };
        self.closed += 1;
        self.frames += self.window.frame_ended as u64;
        self.windows += 1;
        match &mut self.run {
            Some(run) => run.windows.push(closed),
            None => self.extrapolated.push(Closed {
                sampled: false,
                systematic: false,
                calibrates: false,
                ..closed
            }),
        }
        Ok(())
    }

    /// Finish the running machine and measure its sampled windows.
    fn flush_run(&mut self) -> Result<(), SimError> {
        let Some(mut run) = self.run.take() else {
            return Ok(());
        };
        if run.query_open {
            // A cool-down stopped inside a query: end it (its report is not used).
            run.machine.event(&Event::QueryEnd)?;
        }
        let (report, depth) = run.machine.finish_recycling()?;
        self.spare_depth = Some(depth);
        self.machine_checked += report.summary.checked_queries;
        let mut queries = report.queries.iter();
        // The machine's frame ends, in its own cycles (its frames are its run's swaps).
        let mut frame_ends = report.frames.iter().scan(0, |end, frame| {
            *end += frame.cycles;
            Some(*end)
        });
        let mut previous_end = run.start;
        for window in run.windows {
            let query = window.query.and_then(|_| queries.next());
            let frame_end = window.frame_ended.then(|| frame_ends.next()).flatten();
            let mark = window.mark;
            if window.sampled {
                self.sampled += 1;
                self.sampled_slowest += !window.systematic as u64;
                let end = match (query, frame_end) {
                    (_, Some(end)) if !window.last => end,
                    (Some(q), _) if !window.last => q.end_cycle,
                    _ => report.summary.cycles,
                };
                let cost = end.saturating_sub(previous_end);
                let token = query.zip(window.query).map(|(q, (index, _))| {
                    (index, q.end_cycle.saturating_sub(previous_end) as f64)
                });
                self.measured.push(Timed {
                    order: window.order,
                    frame: window.frame,
                    frame_ended: window.frame_ended,
                    cost: cost as f64,
                    token,
                });
                if let (Some(q), Some((index, _))) = (query, window.query) {
                    self.latencies[index] = Some(q.latency_cycles);
                }
                // One of the slowest only is measured, but is no sample of the others.
                if window.calibrates && !window.last {
                    // The pipe's part of the measured cost, against the formulas' pipe.
                    self.pipe_by_class
                        .entry(window.class)
                        .or_default()
                        .add(Calibration::of_pipe(
                            cost as f64 - window.work.host_gap,
                            window.work.pipe,
                            window.fragments >= LONG_WINDOW_FRAGMENTS,
                        ));
                }
                if let (Some(q), Some((index, _)), true) = (query, window.query, window.calibrates)
                {
                    self.calibrating_latencies.push((index, q.latency_cycles));
                    self.donors.add(
                        window.class,
                        self.predicted_latencies[index],
                        index,
                        q.latency_cycles,
                    );
                    self.latency_by_class
                        .entry(window.class)
                        .or_default()
                        .add(Calibration::of(
                            q.latency_cycles,
                            self.predicted_latencies[index],
                        ));
                }
            } else {
                self.extrapolated.push(window);
            }
            previous_end = mark
                .or(frame_end)
                .or(query.map(|q| q.end_cycle))
                .unwrap_or(previous_end);
        }
        Ok(())
    }

    /// The formulas' followed latency of the last query, if they know it now, to the
    /// predicted timeline and the predicted latencies ([`PredictedLoop::settle`]).
    fn settle(&mut self) {
        let followed = self.formulas.take_followed();
        self.predicted
            .settle(followed, &mut self.predicted_latencies);
    }

    pub fn finish(mut self) -> Result<LevelResult, SimError> {
        self.plan()?;
        self.formulas.close_head();
        self.settle();
        self.close_window(true)?;
        self.flush_run()?;
        // A class without a sampled window takes every sampled window's calibration.
        let mut pooled = Calibration::default();
        self.pipe_by_class.values().for_each(|c| pooled.add(*c));
        let pipe_cycles = |class: &Class, pipe: f64| {
            let calibration = self.pipe_by_class.get(class).unwrap_or(&pooled);
            calibration.scaled(pipe).unwrap_or(pipe)
        };
        let modes: Vec<QueryMode> = (0..self.latencies.len())
            .map(|index| self.core.query_mode(index))
            .collect();
        // The sampled queries of each mode, and of all, pooled once (not once for each
        // query that takes them: a long trace has as many of those as queries).
        let (mut of_mode, mut of_all) = (BTreeMap::new(), Calibration::default());
        for &(index, measured) in &self.calibrating_latencies {
            let sample = Calibration::of(measured, self.predicted_latencies[index]);
            of_mode
                .entry(modes[index].code())
                .or_insert_with(Calibration::default)
                .add(sample);
            of_all.add(sample);
        }
        let slope = common_slope(self.latency_by_class.values());
        let mut filled = self.latencies.clone();
        let mut timed = std::mem::take(&mut self.measured);
        // Each extrapolated query's latency by regression, and its donor's, if it has one.
        let regressed: Vec<Option<(f64, Option<u64>)>> = self
            .extrapolated
            .iter()
            .map(|window| {
                let (index, mode) = window.query?;
                let predicted = self.predicted_latencies[index];
                let latency = self
                    .latency_by_class
                    .get(&window.class)
                    .and_then(|sample| sample.extrapolate(predicted, slope))
                    // Another class's queries say nothing of this one's slope, nor of an
                    // error that stays whatever the latency: theirs scaled to it, below
                    // them, and past the largest the error that gives it carried on.
                    .or_else(|| {
                        let sample = of_mode.get(&mode.code())?;
                        sample.scaled(predicted as f64)
                    })
                    .or_else(|| of_all.scaled(predicted as f64))
                    .unwrap_or(predicted as f64);
                Some((latency, self.donors.nearest(window.class, predicted, index)))
            })
            .collect();
        // Per cell, the mean of the latencies its extrapolated queries take from donors.
        let mut donated: BTreeMap<(Class, u64), (f64, f64)> = BTreeMap::new();
        for (window, regressed) in self.extrapolated.iter().zip(&regressed) {
            if let (Some((index, _)), Some((_, Some(donor)))) = (window.query, regressed) {
                let cell = donated
                    .entry((window.class, self.predicted_latencies[index]))
                    .or_default();
                (cell.0, cell.1) = (cell.0 + *donor as f64, cell.1 + 1.0);
            }
        }
        for (window, regressed) in self.extrapolated.iter().zip(regressed) {
            let cost = window.work.host_gap + pipe_cycles(&window.class, window.work.pipe);
            timed.push(Timed {
                order: window.order,
                frame: window.frame,
                frame_ended: window.frame_ended,
                cost,
                // Its end token enters as its work ends.
                token: window.query.map(|(index, _)| (index, cost)),
            });
            if let (Some((index, _)), Some((latency, donor))) = (window.query, regressed) {
                // The donor's difference from its cell's donated mean, on the regression.
                let latency = donor.map_or(latency, |donor| {
                    let (sum, count) = donated[&(window.class, self.predicted_latencies[index])];
                    (latency + donor as f64 - sum / count).max(0.0)
                });
                filled[index] = Some(latency.round() as u64);
            }
        }
        timed.sort_unstable_by_key(|window| window.order);
        let mut frame_cycles = vec![0f64; self.frames as usize + 1];
        let total = timeline(&timed, &filled, &mut frame_cycles);
        let windows = SampledWindows {
            simulated: self.sampled,
            slowest: self.sampled_slowest,
            tails: self.tails,
            total: self.windows,
        };
        let mut result = self.core.finish()?;
        if self.consistent.is_some() {
            // The results are the golden ones; the simulated windows' machines checked theirs.
            result.checked_queries = self.machine_checked;
        }
        for (query, latency) in result.queries.iter_mut().zip(filled) {
            query.latency_cycles = latency;
        }
        result.level = crate::levels::level::Fidelity::Sampled { every: self.every };
        result.effects = Some(self.effects);
        result.sampled_windows = Some(windows);
        result.set_timing(total.round() as u64);
        if self.closed_loop {
            // A last frame of nothing (the stream ended on its swap) is no frame.
            if frame_cycles.len() > 1 && frame_cycles.last() == Some(&0.0) {
                frame_cycles.pop();
            }
            let frame_cycles = frame_cycles.iter().map(|c| c.round() as u64).collect();
            result.set_frames(frame_cycles, self.arch.clock_mhz()?);
        }
        Ok(result)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn samples(pairs: &[(u64, u64)]) -> Calibration {
        let mut sample = Calibration::default();
        for &(measured, predicted) in pairs {
            sample.add(Calibration::of(measured, predicted));
        }
        sample
    }

    #[test]
    fn an_extrapolated_query_takes_the_latency_of_its_cells_nearest_sampled_query() {
        let brief = Some((0, 1));
        let mut donors = Donors::default();
        // Cell (brief, 8): the sampled queries 0, 10, ..., 90 measured 10, 11, ..., 19.
        for k in 0..MIN_CELL_DONORS {
            donors.add(brief, 8, 10 * k, 10 + k as u64);
        }
        // Query 44 lies nearest query 40 (14); query 45 as near 40 as 50, and takes the
        // earlier; before the first and past the last, the first and the last.
        assert_eq!(donors.nearest(brief, 8, 44), Some(14));
        assert_eq!(donors.nearest(brief, 8, 46), Some(15));
        assert_eq!(donors.nearest(brief, 8, 45), Some(14));
        assert_eq!(donors.nearest(brief, 8, 0), Some(10));
        assert_eq!(donors.nearest(brief, 8, 500), Some(19));
        // Another formulas' latency, or another class, is another cell: none sampled.
        assert_eq!(donors.nearest(brief, 9, 44), None);
        assert_eq!(donors.nearest(Some((0, 2)), 8, 44), None);
        // A cell of one fewer sampled query than the minimum donates nothing.
        let mut few = Donors::default();
        for k in 1..MIN_CELL_DONORS {
            few.add(brief, 8, 10 * k, 20);
        }
        assert_eq!(few.nearest(brief, 8, 44), None);
    }

    #[test]
    fn a_window_splits_into_the_pipes_work_and_the_hosts_gap() {
        // 1,000 cycles on the timeline, 300 of them the formulas' T_w: the pipe waited 700
        // for the host. A window the pipe's work outlasts (a last release stretching it is
        // the other way round) is all pipe; no duration is no work.
        let held = Work::of(1000.0, 300.0);
        assert_eq!((held.pipe, held.host_gap), (300.0, 700.0));
        let busy = Work::of(250.0, 300.0);
        assert_eq!((busy.pipe, busy.host_gap), (250.0, 0.0));
        let none = Work::of(-3.0, 10.0);
        assert_eq!((none.pipe, none.host_gap), (0.0, 0.0));
    }

    #[test]
    fn a_windows_pipe_takes_the_sampled_ratio_within_their_range_and_slope_one_past_it() {
        // Sampled windows predicted 600 and 1,000 pipe cycles measured 630 and 1,060: ratio
        // 1,690 / 1,600 = 1.05625, mean prediction 800, mean measured 845. A window
        // predicted 800 gets 845; one predicted 700, 845 + 1.05625 * (700 - 800) =
        // 739.375; one predicted 100,000, past the largest (1,000), 845 + 1.05625 * 200 +
        // 99,000 = 100,056.25, where the ratio alone gave 105,625.
        let class = Calibration::of_f64(630.0, 600.0);
        let mut both = class;
        both.add(Calibration::of_f64(1060.0, 1000.0));
        let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-9);
        assert!(close(both.scaled(800.0), 845.0));
        assert!(close(both.scaled(700.0), 739.375));
        assert!(close(both.scaled(100_000.0), 100_056.25));
        assert_eq!(Calibration::default().scaled(5.0), None);
    }

    #[test]
    fn past_a_long_sampled_window_its_rate_carries_on() {
        // A long window predicted 1,000 pipe cycles measured 950: one predicted 4,000 gets
        // 950 + 0.95 * 3,000 = 3,800 (the rate), where a short one's 950 + 3,000 = 3,950
        // (slope 1). Below the largest prediction nothing changes: a short window predicted
        // 500 and measured 520 beside it, ratio 1,470 / 1,500 = 0.98, mean (750, 735); one
        // predicted 600 gets 735 + 0.98 * (600 - 750) = 588, and one predicted 4,000,
        // 735 + 0.98 * 250 + 0.95 * 3,000 = 3,830.
        let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-9);
        let long = Calibration::of_pipe(950.0, 1000.0, true);
        let short = Calibration::of_pipe(950.0, 1000.0, false);
        assert!(close(long.scaled(4000.0), 3800.0));
        assert!(close(short.scaled(4000.0), 3950.0));
        let mut both = Calibration::of_pipe(520.0, 500.0, false);
        both.add(long);
        assert!(close(both.scaled(600.0), 588.0));
        assert!(close(both.scaled(4000.0), 3830.0));
        // The largest sample decides: past a short one larger than the long one, slope 1.
        // Mean (1,500, 1,525), ratio 3,050 / 3,000: 1,525 + 500 * 3,050 / 3,000 + 2,000 =
        // 4,033 1/3.
        let mut larger_short = long;
        larger_short.add(Calibration::of_pipe(2100.0, 2000.0, false));
        let third = larger_short.scaled(4000.0).unwrap() - 4033.0;
        assert!((third - 1.0 / 3.0).abs() < 1e-9, "{third}");
    }

    #[test]
    fn without_spread_in_the_predictions_the_formulas_slope_is_kept() {
        // Three samples predicted 18 each, measured 19, 21, 20: mean 20, mean prediction
        // 18. A query predicted 1,344 gets 20 + 1 * (1344 - 18) = 1346.
        let class = samples(&[(19, 18), (21, 18), (20, 18)]);
        let slope = common_slope([class].iter());
        assert_eq!(slope, 1.0);
        assert_eq!(class.extrapolate(1344, slope), Some(1346.0));
    }

    #[test]
    fn predictions_that_do_not_track_the_measurements_leave_the_mean() {
        // Predicted 150 and 200, both measured 215: covariance 0, slope 0, so any
        // prediction up to the largest sampled one, 200, gets the mean, 215.
        let class = samples(&[(215, 150), (215, 200)]);
        let slope = common_slope([class].iter());
        assert_eq!(slope, 0.0);
        assert_eq!(class.extrapolate(120, slope), Some(215.0));
        assert_eq!(class.extrapolate(180, slope), Some(215.0));
        // Past 200 the samples say nothing of the slope and the formulas' own carries on:
        // 6,797 gets 215 + 0 * (200 - 175) + (6797 - 200) = 6,812.
        assert_eq!(class.extrapolate(6797, slope), Some(6812.0));
    }

    #[test]
    fn the_slope_is_fitted_within_classes_not_between_them() {
        // Class a: predicted 100, 110 measured 200, 205: Σ(p - p̄)² = 2 * 5² = 50,
        // Σ(p - p̄)(m - m̄) = (-5)(-2.5) + (5)(2.5) = 25. Class b: predicted 400, 420
        // measured 450, 450: Σ(p - p̄)² = 200, covariance 0. Pooled: 25 / 250 = 0.1, though
        // between the classes prediction and measurement rise together.
        let a = samples(&[(200, 100), (205, 110)]);
        let b = samples(&[(450, 400), (450, 420)]);
        let slope = common_slope([a, b].iter());
        assert!((slope - 0.1).abs() < 1e-12, "{slope}");
        // Class b's mean 450 and mean prediction 410: a query predicted 416 gets
        // 450 + 0.1 * 6 = 450.6; one predicted 510, past the largest sampled 420, gets
        // 450 + 0.1 * 10 + (510 - 420) = 541.
        let latency = b.extrapolate(416, slope).unwrap();
        assert!((latency - 450.6).abs() < 1e-9, "{latency}");
        let latency = b.extrapolate(510, slope).unwrap();
        assert!((latency - 541.0).abs() < 1e-9, "{latency}");
    }

    #[test]
    fn a_slope_outside_zero_to_one_is_held_and_a_latency_never_goes_below_zero() {
        // Predicted 10, 20 measured 0, 100: slope 10, held to 1. Mean 50, mean prediction
        // 15: a query predicted 0 gets 50 - 15 = 35; with samples measured 0 and 10 (mean 5)
        // a prediction of 0 would be 5 - 15 < 0, so 0.
        let steep = samples(&[(0, 10), (100, 20)]);
        assert_eq!(common_slope([steep].iter()), 1.0);
        assert_eq!(steep.extrapolate(0, 1.0), Some(35.0));
        let low = samples(&[(0, 10), (10, 20)]);
        assert_eq!(low.extrapolate(0, 1.0), Some(0.0));
        assert_eq!(Calibration::default().extrapolate(5, 1.0), None);
    }

    /// A sampled:3 model at the default O2, warm-ups of 10 fragments and tails of 20, told
    /// these window sizes (fragments, host work until).
    #[test]
    fn the_slowest_are_the_top_fifteenth_of_the_queries_by_predicted_latency_earlier_first() {
        // Five queries ending windows 0, 1, 2, 4 and 5 (a frame's end closed window 3),
        // predicted 5, 9, 9, 3, 7 cycles: ceil(5 / 15) = 1 slowest, of the two 9s the
        // earlier query's window, 1.
        let (latencies, windows) = ([5, 9, 9, 3, 7], [0, 1, 2, 4, 5]);
        assert_eq!(slowest_of(&latencies, &windows), BTreeSet::from([1]));
        // Sixteen queries, query q ending window 2q, predicted 100 - q: ceil(16 / 15) = 2,
        // queries 0 and 1, windows 0 and 2.
        let latencies: Vec<u64> = (0..16).map(|q| 100 - q).collect();
        let windows: Vec<u64> = (0..16).map(|q| 2 * q).collect();
        assert_eq!(slowest_of(&latencies, &windows), BTreeSet::from([0, 2]));
        assert_eq!(slowest_of(&[], &[]), BTreeSet::new());
    }

    #[test]
    fn only_the_o2_at_k_from_2_to_15_simulates_the_slowest() {
        assert!(
            !simulates_slowest(1, Machine::O2),
            "every window is simulated at K = 1"
        );
        assert!(simulates_slowest(2, Machine::O2));
        assert!(simulates_slowest(15, Machine::O2));
        assert!(!simulates_slowest(16, Machine::O2), "more than every K-th");
        assert!(!simulates_slowest(10, Machine::Ir));
    }

    #[test]
    fn a_systematic_window_among_the_slowest_does_not_calibrate() {
        // sampled:2 over four queries, window q ending query q, window 0 also one of the
        // slowest: windows 0 and 2 are simulated, and only window 2's query calibrates
        // (the slowest are not a sample of the windows extrapolated).
        use occsim_traces::{Fragment, Rect};
        let arch = Arch::builtin("o2").unwrap();
        let mut model = SampledModel::new(&arch, 8, 8, Effects::ALL, 2)
            .unwrap()
            .with_slowest(BTreeSet::from([0]));
        for id in 0..4 {
            model
                .event(&Event::QueryBegin(QuerySpec {
                    id,
                    mode: QueryMode::Samples,
                    buffer_entries: 8,
                    tiles: vec![Rect::new(0, 0, 8, 8)],
                }))
                .unwrap();
            model.event(&Event::Primitive).unwrap();
            for x in 0..8 {
                let fragment = Fragment {
                    x,
                    y: id as u16,
                    z: 100,
                };
                model.event(&Event::Fragment(fragment)).unwrap();
            }
            model.event(&Event::QueryEnd).unwrap();
        }
        // The last window closes at the next event.
        model.event(&Event::Primitive).unwrap();
        model.flush_run().unwrap();
        let calibrating: Vec<usize> = (model.calibrating_latencies.iter())
            .map(|&(query, _)| query)
            .collect();
        assert_eq!(calibrating, [2]);
        assert_eq!((model.sampled, model.sampled_slowest), (2, 0));
    }

    fn model_with_sizes(sizes: &[(u64, u64)]) -> SampledModel {
        let arch = Arch::builtin("o2").unwrap();
        let mut model = SampledModel::new(&arch, 8, 8, Effects::ALL, 3)
            .unwrap()
            .with_window_sizes(10, 20);
        for &(fragments, host_until) in sizes {
            model.window_size(Some(WindowSize {
                fragments,
                host_until,
            }));
        }
        model
    }

    #[test]
    fn a_sampled_window_is_cut_only_when_long_and_not_last() {
        // 31 fragments = 10 + 20 + 1: a head of 11, its warm-up from fragment 1.
        assert_eq!(
            model_with_sizes(&[(31, 1), (5, 0)]).head_fragments(0),
            Some(11)
        );
        // 30 fragments: all warm-up and tail.
        assert_eq!(model_with_sizes(&[(30, 0), (5, 0)]).head_fragments(0), None);
        // Host work up to its last fragments: cut all the same (the machine takes its
        // host up from the formulas' timeline).
        assert_eq!(
            model_with_sizes(&[(31, 30), (5, 0)]).head_fragments(0),
            Some(11)
        );
        // The last window (no size after it): nothing would end its head.
        assert_eq!(model_with_sizes(&[(100, 0)]).head_fragments(0), None);
        // Window 3, the next sampled one, seen from window 1: its warm-up is its own, so
        // windows 1 and 2 warm nothing up.
        let mut model = model_with_sizes(&[(5, 0), (5, 0), (5, 0), (100, 0), (5, 0)]);
        assert_eq!(model.warm_up_start(1), None);
        assert_eq!(model.warm_up_start(2), None);
        // Window 3 too short to cut (30 = warm-up and tail): window 2 warms it up.
        let mut uncut = model_with_sizes(&[(5, 0), (5, 0), (5, 0), (30, 0), (5, 0)]);
        assert_eq!(uncut.warm_up_start(2), Some(0));
    }

    #[test]
    fn a_clear_starts_a_pending_warm_up_only_within_a_warm_up_of_it() {
        // Warm-ups of 10 fragments; a warm-up window whose warm-up starts at its fragment
        // 50. A clear after 35 of its fragments, 15 before the warm-up, leaves no backlog
        // by then: the machine waits. After 41, 9 before: it starts at the clear.
        let mut model = model_with_sizes(&[(60, 0), (5, 0)]);
        model.warm_start = Some(50);
        model.window.fragments = 35;
        assert!(!model.starts_at_clear());
        model.window.fragments = 41;
        assert!(model.starts_at_clear());
        // The same in a head (a window cut for its tail).
        model.window.cut_at = Some(60);
        model.window.fragments = 35;
        assert!(!model.starts_at_clear());
        // No warm-up pending: nothing to start.
        model.warm_start = None;
        model.window.fragments = 49;
        assert!(!model.starts_at_clear());
    }
}
