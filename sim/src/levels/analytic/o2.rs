//! The O2-like machine's closed-form bottleneck model. The work is counted per *stretch*
//! (a primitive's fragments; the window index's stretches sum into them) and the pipe is
//! followed stretch by stretch as a fluid, so that a *window* (the events from just after
//! one query's end to the next query's end, see [`crate::levels`]) ends with the backlog the
//! FIFOs really hold. Counts of a stretch:
//!
//! | count | meaning |
//! |---|---|
//! | `F`, `P` | fragments and primitives |
//! | `S` | OccU cycles: `Σ s` over fragments, `s = ceil(tiles / engines)` under an open query (1 with `all_tiles_one_cycle` or no query) |
//! | `R`, `M` | depth reads (fragments, depth test on, whose memory word differs from the last read's: the prefetch's exact rule) and of them page misses (a different 64 KB page) |
//! | `W` | depth writes (passing fragments with depth test and mask on, outside brief/verbose queries) |
//! | `K`, `B` | colour writes (passing fragments outside brief/verbose queries, with colour bits) and, under `blending`, as many colour reads |
//!
//! The blocks behind the rasterizer take a stretch in (`V` = `memory_port_bits_per_cycle`,
//! `L = min(prefetch_depth_fragments, fifo_raster_to_depth_entries)`, `λ̄ = (M · page_miss +
//! (R - M) · page_hit) / R`, `f` the port share the display refresh and the host need,
//! [`crate::arch::O2Arch::reserved_port_share`], `σ` how far behind it they may fall,
//! `other_clients_slack_cycles`, and `δ` how far behind they are as the stretch starts):
//!
//! ```text
//! depth    = F                       (a cycle a fragment; its reads' stalls: see below)
//! occu     = S
//! work     = R + max(ceil((W · depth_bits + (K + B) · colour_bits) / V),
//!                    min(max(W, K), R + B) + min(R, B))
//! port     = max(work, (work + δ - σ) / (1 - f))   (the other clients force cycles past σ)
//! prefetch = R · (λ̄ + 1) / L          (Little's law: L reads in flight, each λ̄ + 1 cycles)
//! down     = max(depth, occu, prefetch)          (the port runs on its own clock, below)
//! ```
//!
//! The debt `δ` is followed beside the port's clock ([`O2Formulas::port_time`],
//! [`O2Formulas::debt_after`]): over the `span` cycles a stretch's transfers are asked
//! in (its fragments' emission, or the port's own time when longer) it grows by `busy -
//! (1 - f) · span` within `0..=σ`, and each idle cycle between stretches takes `1 - f` off.
//! `busy` is `work`, or more where writes come a cycle apart: each takes a port cycle of
//! its own while the port has room (they pack only once queued), so `busy = max(work,
//! min(span, R + write entries))` (on the small corpus's hard cases this took the analytic
//! cycles error from 0.11% to 0.03% and the p95 from 1.34% to 1.23%, and moved no other
//! class).
//! A stretch is *forced* when its port time passes both its work and its span: only
//! then do the reserved cycles reach the depth test (below), and on the corpus few do.
//!
//! The fluid: the rasterizer's clock `g` and the cycle `d` the blocks behind it are through
//! their work, from the window's start. A stretch's primitive is set up (`setup` =
//! `primitive_setup_cycles`) from `start = max(g, r) + setup · P` (`r`: its release by
//! the host and geometry, from the window's start), its fragments are emitted one a
//! cycle to `start + F`, and the blocks behind take them from `b = max(d, start)`, fragment
//! `j` in `b + j · pace` with `pace = (max(b + down, p - t + λ_hit, start + F + V) - b) / F`,
//! so `d = max(b + down, p - t + λ_hit, start + F + V, start + F)` (`V`: the lag its densest
//! run of reads leaves, below; 0 without one). The port runs on a clock of its own, `p = max(p, start) +
//! port`: the prefetch asks for a fragment's read as the fragment is emitted, so the port
//! works through a stretch's reads while the depth test still works through the backlog
//! before it, and a lag already built is slack for them; the last read's data comes
//! `λ_hit` (the page hit latency) after the port is through them, or `λ_miss` when the
//! stretch's last fragment read a word on another page (its read is the port's last).
//! Through them, not through the stretch's work: `t` of the port's cycles are the writes
//! of its last `min(L, depth_write_buffer_entries)` fragments (under blending each after its
//! colour read), which rule 5 puts after the last read and the write buffer holds while the
//! depth test goes on ([`O2Formulas::trailing_write_cycles`]). Where a stretch's blended
//! writes bind the port they are about 1.6 cycles a fragment, and at a query's end the
//! machine's depth test is 16 of them ahead of its port: with the depth test through only
//! once the port was, the rasterizer was held back as much too long, and the small demo's
//! slowest samples queries under blending drained in 33, 73 and 65 cycles where the
//! machine takes 55, 104 and 81 (now 55, 104 and 81 at the sampled level, which simulates
//! them, and its p95 0% off where it was 12.5%: the formulas' error had moved every query it
//! calibrates by 3 cycles).
//! The rasterizer emits fragment `k` only when fragment `k - Q` has left the FIFO (`Q` =
//! `C1`, the FIFO before the depth test, and `+ C2`, the one after it, when the OccU
//! binds): `g = max(start + F, the cycle fragment k_last - Q leaves)`, looked up in the
//! recent stretches.
//! The OccU takes a fragment from its FIFO as it starts on it (`b + j · pace`); the depth
//! test takes one once its read is in, at the end of its pace (`b + (j + 1) · pace`). A
//! clear holds the depth test for its `clear_words / (1 - f)` port cycles: `d = max(d, g) +
//! clear`; the rasterizer runs on until the FIFO is full.
//!
//! Both measured on the O2 runs of the fidelity corpus (1, 4 and 16 engines, full and
//! small scale, against the cycle level): the worst full-scale class's p95 latency error
//! went from 16.0% (the 1x1 demo at one engine, 29 cycles against 25) to 9.5% (the city's
//! adaptive walk, 19 against 21, as before), the small scale's from 36.8% to 26.3% (the
//! city's hierarchical walk, 14 against 19), the worst mean latency error from 12.4% to
//! 8.7%. On the demo, whose brief queries end with one-pixel columns that read every
//! fragment, the formulas had put the token 22.2 cycles behind the FIFO's 16 fragments
//! (latency 33) where the machine's depth test is 21 behind (29). Counting the port's
//! reads after the depth test's backlog, as before, double-counts them; taking them one
//! cycle after the port rather than a page hit's latency left the small walks at 31.6%.
//!
//! What a stretch's counts do not show, it keeps beside them: its densest runs of reads
//! ([`occsim_traces::trace::dense_reads`]). Where a primitive's part reads a new word every
//! fragment or two (a sliver one or two pixels wide, a triangle's tip) and the rest
//! sparsely, the port, at `1 - f` of its cycles, falls behind on the dense part and the
//! FIFO fills; no block behind the rasterizer takes more than one fragment a cycle, so the
//! rest cannot drain it. Counted whole, the primitive's reads average out. A run of `m`
//! fragments with `n` reads takes the port `max(n, c · (n + δ - σ))` cycles (`c = 1 / (1 -
//! f)`: past the slack, each read its port cycle and the forced ones among them), so it
//! leaves the depth test `V = max(n - m, c · n - m - c · (σ - δ))` cycles behind the
//! fragments' emission, its last read's data a page hit later: the stretch ends no sooner
//! than `start + F + V + λ_hit` when `V > 0`, with `V` the largest over its runs and at
//! most `C1` (once the FIFO before the depth test is full the rasterizer waits). With the
//! O2's slack of 16 a run must read 68 fragments in a row from no debt before a cycle is
//! forced; with a slack of 1, the sliver of `tests/fidelity.rs` lags 11.2 cycles, and
//! formulas and machine agree on its latency at every slack from 1 to 16. (Under the
//! fixed pattern of reserved cycles this model had before, a box query of the city at
//! 160x120 ending with a sliver whose first 47 fragments all read, 168 fragments and 101
//! reads, took the machine 20 cycles where the formulas without runs gave 9.) On the small corpus's O2 runs
//! (1, 4 and 16 engines) the hierarchical walks' p95 latency error went from 26.3% to
//! 5.3%, the adaptive walk's from 20.0% to 5.0%. (Following the pipe every 32 fragments
//! of a primitive had found these too, but the window index would then keep a stretch
//! every 32 fragments: the demo's from 79 KB to 529 KB, the analytic level's run from about
//! 10 ms to 100 ms. The runs add a few bytes to the few stretches that have one.)
//!
//! Where a run sits matters as the stretch ends: a run that ends at its last fragment leaves
//! the port behind and the other clients owed when the next work comes, where the counts
//! spread it over the whole stretch. So a stretch also keeps the runs ending at its last
//! fragment (format version 9), and [`O2Formulas::ending_runs`] takes what they leave: a
//! run of `m` fragments and `n` reads, each read `a = 1 + min(1, writes / R)` port cycles
//! (in a stretch that draws, the depth test's writes reach the in-order port between the
//! reads, and a read between two writes keeps them from sharing a cycle), keeps the port
//! busy `a · n` cycles over `max(m, a · n)`: the clients end at least `min(a · n - (1 - f)
//! · m, f · a · n)` behind (at most `σ`), and the port `max(a · n - m, c · a · n - m - c ·
//! (σ - δ))` behind the last fragment's emission (at most `C1`). Both were missing on the
//! full 4x4-retiled demo at 16 engines, measured against the machine's port grants at each
//! end token: a samples query whose last primitive drew every fragment and read every one
//! of its last ten, the port 9 cycles behind at the token where the formulas had it through
//! (latency 34, predicted 27, now 34); and a query after a run of reads across two
//! primitives that left the clients 16 behind at the second one's start where the
//! stretch's averaged debt was 0 (the machine's depth test 16 behind with its FIFO full,
//! predicted 8: latency 35, predicted 28, now 37). That run's p95 latency error went from
//! 14.71% to 2.94%; decoding, the full corpus's mean latency errors on o2 went from 1.77%
//! to 0.51% on the demo, from 1.68% to 0.39% on the 1x1 demo at 4 and 16 engines and from
//! 1.45% to 0.10% on the city's hierarchical walk (the forest's went from 0.04% to 0.10%,
//! the 4x4 demo's at 16 engines from 0.37% to 0.45%), and no run's p95 moved but that one.
//!
//! Where a stretch's drawn fragments sit matters too: a primitive whose last rows draw in
//! front of what was drawn before, after a stretch where few did, ends with a run of drawn
//! fragments whose writes (under blending each after its colour read, about 1.6 port cycles
//! a fragment) bind the port, where its counts, spread over the whole primitive, leave it
//! idle. So a stretch also keeps its *drawn tail*, the fragments that draw one after another
//! up to its last and the words they read (format version 12), and
//! [`O2Formulas::drawn_tail`] takes what it leaves when it binds the port: a tail of `m`
//! fragments whose `r` reads and writes take the port `work` cycles is through `max(work -
//! m, c · work - m - c · (σ - δ))` after the last one's emission, the depth test takes its
//! fragments at the port's pace, `(m + lag) / m`, so the rasterizer waits on the FIFO's
//! last departures at that pace, and its writes are the ones after the last read. On the
//! random triangles at the full scale under blending on o2, queries whose last triangle
//! ends in 54 to 218 drawn fragments took the machine 63 to 77 cycles and the formulas 17 to
//! 27 (now 62 to 73); the class's analytic p95 latency error went from 57.7% to 17.3%, its
//! mean from 10.9% to 3.4%, sampled:10's p95 from 5.8% to 1.9%. Only under blending:
//! without it a tail's writes pack four to a port cycle, and a tail that binds the port by
//! its reads (a drawn sliver) is its ending runs' ([`O2Formulas::drawn_tail`]).
//!
//! `T_w = g` when the end token is emitted; what is left, `d - T_w`, is the backlog ahead
//! of the token, carried into the next window. A verbose query's hit words take the port
//! cycles the window left idle, and lengthen `d` by the rest.
//!
//! Reads' stalls: no block behind the rasterizer is faster than its one fragment a cycle,
//! so a stall (a read that comes late, behind the port's writes or a forced cycle) is
//! never made up while fragments flow: the FIFOs keep the entries it filled until a
//! primitive's setup leaves the rasterizer idle. But the stalls do not add up without end:
//! the prefetch asks for a read as its fragment is emitted, and the depth test reaches that
//! fragment as many cycles later as it trails the rasterizer, so a read stalls it only
//! while the trail is shorter than the read's wait and latency, and each stall lengthens
//! the trail. The trail therefore stops at the slowest read's: once the depth test trails
//! the rasterizer by the slowest read's latency and, in a forced stretch, the longest run
//! of forced port cycles a read may wait out, `ρ = ceil(f / (1 - f))` (1 at the O2's `f` =
//! 0.234), the reads come in time. So after a stretch, `d >= g + λ_max + ρ`, with `λ_max`
//! the page miss latency when the stretch missed a page, the page hit latency when it only
//! hit (a ratchet: the trail is kept until setup idles the rasterizer), whether it writes
//! or not. The city's adaptive walk ends its big box queries with the depth test 8 or 9
//! cycles behind (latency 13-15); with `f` = 0 the forest's walk ends them exactly 8
//! behind. (Before, a stretch that wrote stalled its depth test 0.02 cycles for every
//! read, summed over the stretch, and a forced one that read more than 0.3 a fragment
//! 0.085 `f`: over a long drawing primitive the sum filled the FIFO where the machine's
//! trail stops at its slowest read's. Against the cycle level, per query, on the full
//! corpus's O2 runs (1, 4 and 16 engines), 249 queries were more than 2 cycles off and
//! are 145 now, the mean per-query error went from 0.42% to 0.31%, and on the random
//! triangles, whose every query ends a drawing primitive of thousands of fragments, 42
//! queries a run were off by 3 to 7 cycles and 10 are.)
//!
//! Total cycles = `Σ_w T_w` + the last window's tail (the last query's latency, or its
//! drain + 3 when the stream ends without a query end).
//!
//! Query latency (from the `end` token entering the pipe to its records written):
//!
//! ```text
//! drain   = max(d - T_w, e_last + λ_last - T_w)   (e_last: the cycle after the last fragment's
//!                                   emission, λ_last its read latency; 0 when it read nothing new)
//! drain'  = max(0, drain - late) - (3 when the OccU bound the last stretch, to 0 at least)
//! latency = 4 + ceil(port time of ceil(records / (V / 32)) at the debt then) + drain'
//! ```
//!
//! with `late = max(0, r_end - (s_w + T_w))`: in a closed loop the end token enters at its
//! release `r_end`, and the pipe drains while the host holds it (a host-bound window's
//! token finds the pipe empty); in an open loop `r_end = 0`. The last fragment's read
//! drains only what the rasterizer's later work leaves of it: primitives with no fragment
//! after it set up while it comes (on the demo, 61 samples queries took the formulas'
//! 7 cycles where the machine's 5). When the OccU binds, the token leaves the FIFO,
//! crosses the depth pipeline and reaches the OccU while the OccU still works through the
//! backlog ahead of it ([`OCCU_BOUND_TOKEN_OVERLAP_CYCLES`]).
//!
//! With no share (`f` = 0) these are the cycle model's rules summed: on the small corpus at
//! 4 engines every walk's query but one (of 2,786) takes the machine's latency to the
//! cycle, and 97% of the demo's and the random triangles' (`tests/fidelity.rs`). With the
//! O2's share and slack every small-corpus class's p95 latency is exact but the hard
//! cases' (1.23%, behind their clears). (Under the fixed pattern of reserved cycles the
//! port had before, which of a query's last reads and record words met a reserved cycle
//! hung on the cycle they came in, which no count tells: the machine's latencies for one
//! prediction spread by a few cycles, 13 to 17 on the forest's walk where the formulas
//! gave 15, and the 1x1 demo's p95 was 10.5% off.)
//!
//! Followed: the machine's port is in order, and the prefetch issues the depth reads of
//! the `L` fragments after the end token before OccU Control asks for the query's record
//! words. When the next window's first primitive comes while the pipe is still busy (no
//! `wait`, no idle gap), those reads are the next window's first `L` fragments', emitted
//! one a cycle after each primitive's setup, and the records go after the last of them
//! that reads a new word (fragments of a word already read ask the port nothing). Rule 5
//! puts the depth write of the window's fragment `L` before each of them ahead of its read,
//! so the records also wait for the window's last `L` writes, and a write shares a port
//! cycle only with the writes queued right before it: a read between two writes splits
//! them. The formulas run that order on an in-order port (`PortOrder`) from the end token:
//! free once the port is through the window's work but its last writes (`p - t - g`), the
//! window's last `L` fragments writing as its last stretch does (the share of its fragments
//! that write, ready a pace apart up to the depth test's drain; under blending each write
//! from the cycle after its colour read's grant), the next window's reads asked for the
//! cycle after their fragment's emission (`o_k`: the cycles from the end token to fragment
//! `k`'s emission, the setups before it included), then the records' `ceil(records / (V /
//! 32))` cycles; the other clients take the cycles the arbiter gives them (their debt from
//! the window's work on, `f` a granted cycle, one forced cycle where it would pass `σ`):
//!
//! ```text
//! for k in 0..L: write k of the window's last L (when it writes); read of fragment k after the token (when it reads)
//! latency = max(latency, last record grant + 1)
//! ```
//!
//! (without writes, the last read is asked for and granted in `o_k* + 1`, the records from
//! the cycle after). On the full demo at 4 engines on o2 a samples query whose last
//! primitive draws every fragment, followed by a brief query reading 11 of its first 16,
//! took 34 cycles where the formulas, with the reads alone, gave 22; with the writes 27
//! (the machine's port was already a few reads behind at the token, which the stretch's
//! counts do not show); the full corpus's mean latency error on o2 went from 2.09% to 1.77%
//! on the demo and from 2.13% to 1.68% on the 1x1 and 4x4 demos. The formulas follow the
//! fragments after each query's end (`Head`) until `L` have passed,
//! or the pipe drains (a wait, a frame's or another query's end, a primitive
//! released later than the rasterizer is free): the predicted timeline decides whether
//! the next window followed at once ([`crate::levels::predicted_loop`]). Which fragments
//! read comes from the stretches' `first_reads` (the window index keeps them for the 64
//! fragments after a query's end, so `L` is taken at most 64). On the small random
//! triangles (samples queries one after another) the machine's latencies are 15-23 cycles
//! with `f` = 0: taking every `L`-th fragment as a read gave 21 for all of them, this gives
//! 97% of them to the cycle.
//!
//! Queries that end with no work between them: a query's records are asked for `4 +
//! drain` after its token enters, and after a window of no work the in-order port writes
//! them after the records of the query before where those are still being written then
//! (`RecordsWritten`: its last record grant on the timeline and the other clients' debt
//! after it). Its latency is then the port's, its window's last writes being the query
//! before's, which its records went after; the reads of the fragments after its token are
//! taken to find the port's idle cycles before those records (not followed: an
//! approximation). (Without this, 2,000 empty queries in an open loop took 5 cycles,
//! every latency 5, where the machine's records queue up to 2,596 cycles, latencies to
//! 2,465: now 2,595 and 2,465; on the demo, whose brief queries over no fragment follow a
//! query at once, five of them went from 16 cycles to 17 where the machine takes 17 to 21,
//! and the hard cases' query 7 from 17 to 18, the machine's.)
//!
//! In the first latency, the 4 is the empty pipe's path (depth pipeline, OccU, OccU
//! Control, the grant after the last word): with one record group that fits one port
//! cycle, latency is the machine's minimum,
//! [`crate::machines::o2::MIN_QUERY_LATENCY_CYCLES`]. Costs: the functional model plus a
//! few integer operations per fragment.
//!
//! Writes and reads share the port in the order they are claimed: the prefetch claims a
//! fragment's read when it is emitted, `L` fragments ahead of the depth test that claims
//! the writes of the fragments it passes, so a write never shares a cycle with a read
//! (a read takes the whole word) and writes pack to the port's width only between two
//! reads: a stretch's writes take at least `min(max(W, K), R)` cycles. On the 1x1-retiled
//! small demo on o2 with one engine, two samples queries of small drawn triangles took 38
//! and 41 cycles where the formulas, packing every write, gave 21 and 22 (their depth test
//! ended 34 and 32 cycles behind the end token): that run's p95 error went from 42% to 2.6%.
//! Under `blending` (`B` colour reads, one a drawn fragment) the depth test claims a
//! fragment's colour read, 32 bits, then its write, ready only the cycle after the read's
//! grant: the write shares its cycle with the next fragment's colour read and nothing else,
//! so the writes take a cycle each, `min(max(W, K), R + B)`, and a depth read, taking its
//! cycle whole, strands the colour read after it in a cycle of its own, `min(R, B)` more.
//! (Packed with the writes as bits alone, the colour reads left the small hard cases on o2
//! at 4 engines 27% short of the cycle level's cycles and the small demo 1.4%; every class
//! of the small corpus there was then within 0.11%, and is within 0.32% since the depth
//! test runs ahead of the last writes.)
//!
//! The fluid replaced a per-window maximum of the blocks' throughputs with the FIFOs taken
//! half full at every query's end: on the small corpus (o2 and ir2 at 4 engines) the worst
//! p95 latency error went from 69% to 20%.

use super::{service_cycles, NotNan, WindowEnd};
use crate::arch::O2Arch;
use occsim_traces::depth_layout::{DepthAddress, DepthRead, LastRead};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::query::BRIEF_RECORD_ENTRIES;
use occsim_traces::state::RenderState;
use occsim_traces::trace::{
    DenseReadFinder, DenseRuns, DrawnTail, FragmentStretch, FIRST_READS_FRAGMENTS,
};
use occsim_traces::{Fragment, QueryMode, QueryShape, QueryTotals, Span};
use std::collections::VecDeque;

/// Counts of one stretch of work (see the module table): a primitive's fragments, or the
/// events before its first.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StretchCounts {
    pub fragments: u64,
    pub primitives: u64,
    pub occu_cycles: u64,
    pub depth_reads: u64,
    pub page_misses: u64,
    pub depth_writes: u64,
    pub colour_writes: u64,
    pub colour_reads: u64,
    /// Read latency of the stretch's last fragment (0 when it read nothing new).
    pub last_read_latency: u64,
    /// The most cycles a run of dense reads in it leaves the depth test behind the
    /// rasterizer at `1 / (1 - f)` port cycles a read ([`occsim_traces::trace::dense_reads`]),
    /// before the slack the port's other clients allow ([`O2Formulas::dense_read_lag`]).
    pub dense_read_lag: f64,
    /// The runs of reads that end at its last fragment (its last run of fragments between
    /// two other events gave them; [`O2Formulas::ending_runs`]).
    pub ending: DenseRuns,
    /// The fragments that draw one after another up to its last, and their reads
    /// ([`O2Formulas::drawn_tail`]).
    pub drawn_tail: DrawnTail,
}

impl StretchCounts {
    /// Its write buffer's entries: a drawn fragment's colour write travels with its depth
    /// write, so one entry a fragment that writes either.
    fn write_entries(&self) -> u64 {
        self.depth_writes.max(self.colour_writes)
    }
}

/// How long a stretch's work takes the blocks behind the rasterizer.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Downstream {
    /// `max(depth, occu, prefetch)`, in cycles: the blocks the depth test passes fragments
    /// through, its port aside (the port runs on its own clock: see the module docs).
    pub off_port: f64,
    /// The port's cycles: the pipeline's `work` and those the other clients force.
    pub port: f64,
    /// The port cycles the stretch's own transfers take.
    pub work: f64,
    /// The other clients took cycles by force (the port saturated past their slack).
    pub forced: bool,
    /// Fragments the FIFOs hold ahead of the bottleneck: `C1`, and `C2` too when the OccU
    /// binds (behind the depth pipeline).
    pub queued: u64,
    /// The OccU binds.
    pub occu_bound: bool,
}

/// Cycles of the end token's path that overlap the backlog when the OccU binds \[cycles\]:
/// the token leaves the FIFO, crosses the depth pipeline and reaches the OccU while the OccU
/// still works through the fragments ahead of it (measured: with `f` = 0, the lazy-grid
/// walks' multi-tile queries, 2 to 400 OccU cycles a fragment at 1, 4 and 16 engines, take
/// the cycle model's latency exactly with 3, and 3 cycles more without).
const OCCU_BOUND_TOKEN_OVERLAP_CYCLES: f64 = 3.0;

/// The port's other clients' debt after the pipeline took `work` of `span` port cycles from
/// `debt`, their share `f` and slack `σ`: `f` a cycle more, a cycle less each one they took,
/// within `0..=σ` ([`O2Formulas::debt_after`], and the head's port between its grants).
fn clients_debt_after(share: f64, slack: f64, debt: f64, work: f64, span: f64) -> f64 {
    if share == 0.0 {
        return 0.0;
    }
    (debt + work - (1.0 - share) * span).within(0.0, slack)
}

/// The O2 formulas over stretch counts.
pub struct O2Formulas {
    arch: O2Arch,
    /// Port words one clear writes (0: a fast clear).
    clear_words: u64,
    /// `f`, the port's reserved share ([`O2Arch::reserved_port_share`]), and the longest
    /// run of cycles the other clients force ([`Self::longest_reserved_run`]): constants of
    /// the architecture, worked out once instead of at every stretch (each had taken a
    /// division of the display's bit rate).
    reserved_share: f64,
    longest_reserved_run: f64,
    /// `c = 1 / (1 - f)`: port cycles a read takes where the other clients take their
    /// share (worked out once: each stretch had taken two or three divisions for it).
    cycles_per_read: f64,
    /// How far behind their share the other clients may fall (`σ`, port cycles).
    slack: f64,
    /// `L` ([`Self::lookahead`]) and the counts of fragments drawn from it
    /// ([`Self::trailing_fragments`], [`Self::head_fragments`]): constants of the
    /// architecture, each a float's conversion at every stretch before.
    lookahead: f64,
    trailing_fragments: u64,
    head_fragments: u64,
}

impl O2Formulas {
    /// The formulas for `arch` on a `width` x `height` viewport.
    pub fn new(arch: &O2Arch, width: u32, height: u32) -> O2Formulas {
        let clear_words = if arch.clear_writes_memory {
            (width as u64
                * height as u64
                * (arch.depth_bits_per_pixel + arch.colour_bits_per_pixel) as u64)
                .div_ceil(arch.memory_port_bits_per_cycle as u64)
        } else {
            0
        };
        let reserved_share = arch.reserved_port_share();
        let lookahead = arch
            .prefetch_depth_fragments
            .min(arch.fifo_raster_to_depth_entries) as u64;
        O2Formulas {
            arch: arch.clone(),
            clear_words,
            reserved_share,
            longest_reserved_run: (reserved_share / (1.0 - reserved_share)).ceil(),
            cycles_per_read: 1.0 / (1.0 - reserved_share),
            slack: arch.other_clients_slack_cycles.max(1) as f64,
            lookahead: lookahead as f64,
            trailing_fragments: lookahead.min(arch.depth_write_buffer_entries as u64),
            head_fragments: lookahead.min(FIRST_READS_FRAGMENTS),
        }
    }

    /// Lookahead `L`: fragments whose reads may be in flight.
    fn lookahead(&self) -> f64 {
        self.lookahead
    }

    /// OccU cycles per fragment under a query of `tiles` tiles.
    pub fn service_cycles(&self, tiles: usize) -> u64 {
        service_cycles(
            tiles,
            self.arch.occu.engines,
            self.arch.occu.all_tiles_one_cycle,
        )
    }

    /// `1 - f`: the port's share left to the pipeline.
    fn free_share(&self) -> f64 {
        1.0 - self.reserved_share
    }

    /// `runs` of dense reads join stretch `w`: its lag is the most any of them leaves at
    /// `c = 1 / (1 - f)` port cycles a read ([`Self::dense_read_lag`]).
    #[inline]
    fn add_dense_runs(&self, w: &mut StretchCounts, runs: &DenseRuns) {
        if !runs.runs().is_empty() {
            let lag = runs.lag(self.cycles_per_read);
            w.dense_read_lag = w.dense_read_lag.max(lag);
        }
    }

    /// What the runs of reads that end at stretch `w`'s last fragment leave as it ends, the
    /// port's other clients `debt` behind as it starts, its reads with `writes` write
    /// entries beside them. Its counts spread a run over the whole stretch; ending it, the
    /// run leaves the other clients owed and the port behind when the next work comes.
    ///
    /// A read costs the port its own cycle and, in a stretch that draws, the cycle of the
    /// writes it splits off (they share a cycle only when no read comes between them), `a =
    /// 1 + min(1, writes / R)` cycles. A run of `m` fragments and `n` reads keeps the port
    /// busy `a · n` cycles over `max(m, a · n)`, so the clients fall behind by `min(a · n -
    /// (1 - f) · m, f · a · n)` (at least that from no debt: at most `σ`); and the port is
    /// through its last read `max(a · n - m, c · a · n - m - c · (σ - debt))` cycles after the
    /// run's last fragment is emitted (as [`Self::dense_read_lag`], at most `C1`).
    #[inline]
    fn ending_runs(&self, w: &StretchCounts, debt: f64, writes: u64) -> RunEnd {
        let a = 1.0 + (writes as f64 / w.depth_reads.max(1) as f64).min(1.0);
        let mut ending = RunEnd {
            owed: 0.0,
            port_lag: 0.0,
        };
        for run in w.ending.runs() {
            let (n, m) = (a * f64::from(run.reads), f64::from(run.fragments));
            let end = self.run_end(n, m, debt);
            ending.owed = ending.owed.max(end.owed);
            ending.port_lag = ending.port_lag.max(self.queued_lag(end.port_lag));
        }
        ending
    }

    /// What a run of `m` fragments whose transfers keep the port busy `work` cycles leaves
    /// as it ends, the other clients `debt` behind as it starts: they are at least
    /// `min(work - (1 - f) · m, f · work)` behind (within `0..=σ`: at least that from no
    /// debt), and the port is through it `max(work - m, c · work - m - c · (σ - debt))`
    /// cycles after its last fragment's emission (past the slack, each cycle of its work
    /// and the forced ones among them). The one rule of the ending runs of reads and the
    /// drawn tail.
    fn run_end(&self, work: f64, m: f64, debt: f64) -> RunEnd {
        let (f, c) = (self.reserved_share, self.cycles_per_read);
        RunEnd {
            owed: (work - (1.0 - f) * m).min(f * work).within(0.0, self.slack),
            port_lag: (work - m).max(c * work - m - c * (self.slack - debt)),
        }
    }

    /// What a run that lags `lag` cycles at `c` port cycles a read leaves once the slack
    /// the other clients still allow (`σ - debt` of their cycles) is taken off, at most
    /// what the FIFO before the depth test holds ([`Self::dense_read_lag`]).
    fn lag_past_slack(&self, lag: f64, debt: f64) -> f64 {
        let c = self.cycles_per_read;
        self.queued_lag(lag - c * (self.slack - debt))
    }

    /// A lag, none below 0 and no more than the FIFO before the depth test holds (once it is
    /// full the rasterizer waits).
    fn queued_lag(&self, lag: f64) -> f64 {
        lag.within(0.0, self.arch.fifo_raster_to_depth_entries as f64)
    }

    /// The most cycles the dense runs of reads of stretch `w` leave the depth test behind
    /// the rasterizer, the port's other clients `debt` behind as it starts. A run of `n`
    /// reads in `m` fragments takes the port [`Self::port_time`] `= max(n, c (n + debt -
    /// σ))` cycles, so lags `max(n - m, (c n - m) - c (σ - debt))`: never `n - m > 0` (a
    /// read a cycle keeps pace), so the lag at `c` less the slack left, when positive (none
    /// with `f` = 0: `c` = 1). No more than the FIFO before the depth test holds: once it
    /// is full the rasterizer waits for the depth test, so a run leaves at most that many
    /// fragments queued, each a cycle once the run's reads are in.
    fn dense_read_lag(&self, w: &StretchCounts, debt: f64) -> f64 {
        self.lag_past_slack(w.dense_read_lag, debt)
    }

    /// Port cycles for `bits` written, before the other clients' share.
    pub fn port_cycles(&self, bits: u64) -> f64 {
        bits.div_ceil(self.arch.memory_port_bits_per_cycle as u64) as f64
    }

    /// Port words one clear writes (0: a fast clear).
    pub fn clear_work(&self) -> f64 {
        self.clear_words as f64
    }

    /// Cycles the port takes for `work` cycles of the pipeline's transfers in a row, its
    /// other clients `debt` cycles behind ([`crate::blocks::memory_port`]): they take none
    /// until they are `σ` behind, then `f` of the cycles, so `max(work, (work + debt - σ) /
    /// (1 - f))`.
    pub fn port_time(&self, work: f64, debt: f64) -> f64 {
        if self.reserved_share == 0.0 {
            return work;
        }
        work.at_least((work + debt - self.slack) / self.free_share())
    }

    /// The other clients' debt after the port did `work` cycles of the pipeline's over
    /// `span` cycles from `debt`: `f` a cycle more, a cycle less each idle one, within
    /// `0..=σ`.
    pub fn debt_after(&self, debt: f64, work: f64, span: f64) -> f64 {
        clients_debt_after(self.reserved_share, self.slack, debt, work, span)
    }

    /// The other clients' debt after `cycles` idle port cycles from `debt`.
    pub fn debt_after_idle(&self, debt: f64, cycles: f64) -> f64 {
        self.debt_after(debt, 0.0, cycles.at_least(0.0))
    }

    /// The blocks behind the rasterizer on a stretch (see the module docs), the port's
    /// other clients `debt` cycles behind as its transfers start, which the rasterizer asks
    /// for over `asked` cycles (its reads as it emits the fragments).
    pub fn downstream(&self, w: &StretchCounts, debt: f64, asked: f64) -> Downstream {
        let write_bits = self.write_bits(w);
        let a = &self.arch;
        let work = w.depth_reads as f64 + self.write_cycles(w, write_bits);
        let port = self.port_time(work, debt);
        // Spread over the cycles they are asked in, the transfers leave idle cycles that
        // serve the debt: cycles are forced only where the port is through them later.
        let forced = port > work.at_least(asked);
        let depth = w.fragments as f64;
        let occu = w.occu_cycles as f64;
        // `R (λ̄ + 1) / L`, with `R λ̄` the reads' latencies summed: whole cycles, so one
        // division (of an exact sum) where the mean's had two.
        let latencies = w.page_misses * a.page_miss_latency_cycles
            + (w.depth_reads - w.page_misses) * a.page_hit_latency_cycles;
        let prefetch = (latencies + w.depth_reads) as f64 / self.lookahead();
        let off_port = depth.at_least(occu).at_least(prefetch);
        let behind_depth = occu > depth.at_least(port).at_least(prefetch);
        let queued = a.fifo_raster_to_depth_entries
            + if behind_depth {
                a.fifo_depth_to_occu_entries
            } else {
                0
            };
        Downstream {
            off_port,
            port,
            work,
            forced,
            queued: queued as u64,
            occu_bound: behind_depth,
        }
    }

    /// The bits a stretch writes: depth and colour (and under blending the colour it reads,
    /// which travels with them).
    fn write_bits(&self, w: &StretchCounts) -> u64 {
        self.entry_bits(w) + w.colour_reads * self.arch.colour_bits_per_pixel as u64
    }

    /// The bits a stretch's write entries write: depth and colour.
    fn entry_bits(&self, w: &StretchCounts) -> u64 {
        w.depth_writes * self.arch.depth_bits_per_pixel as u64
            + w.colour_writes * self.arch.colour_bits_per_pixel as u64
    }

    /// Port cycles a stretch's writes take (before the reserved share): `write_bits` packed
    /// to the port's width, but at least one cycle for each run of writes between two reads,
    /// and under blending one a write and one for each colour read a depth read strands (see
    /// the module docs), so `max(ceil(bits / V), min(entries, R + B) + min(R, B))`.
    fn write_cycles(&self, w: &StretchCounts, write_bits: u64) -> f64 {
        let packed = write_bits.div_ceil(self.arch.memory_port_bits_per_cycle as u64);
        let runs = w.write_entries().min(w.depth_reads + w.colour_reads);
        packed.max(runs + w.depth_reads.min(w.colour_reads)) as f64
    }

    /// The fragments whose writes follow a stretch's last read: `min(L,
    /// depth_write_buffer_entries)` ([`Self::trailing_write_cycles`]).
    fn trailing_fragments(&self) -> u64 {
        self.trailing_fragments
    }

    /// What stretch `w`'s drawn tail leaves as it ends, the port's other clients `debt`
    /// behind as the stretch starts, when its port traffic outruns its fragments. Its `m`
    /// fragments draw one after another, reading `r` new words (every write, and under
    /// blending every colour read, of its `m`): the port takes `work = r + write cycles` of
    /// them, `c · work` once the other clients' slack is spent, so it is through them
    /// `max(work - m, c · work - m - c · (σ - debt))` cycles after the last fragment's
    /// emission, the depth test taking them at the port's pace, `(m + lag) / m` a fragment.
    /// Where a triangle's drawn fragments come last (its nearer rows in front of what was
    /// drawn, the rest behind), its counts spread them over all its fragments: on the random
    /// triangles under blending, queries whose last triangle ends in 54 to 218 fragments that
    /// draw after a stretch where a quarter did took the machine 63 to 77 cycles where the
    /// formulas, the port far from bound on average, gave 17 to 27.
    ///
    /// Only under blending: without it a tail's writes pack four to a port cycle, and where
    /// its reads bind the port (a drawn sliver), its ending runs of reads take it, with the
    /// writes those reads split ([`Self::ending_runs`]). (Taken there too, the tail moved
    /// the small 1x1 and 4x4 demos' analytic p95 latency from 0.07% to 3.12% off.)
    fn drawn_tail(&self, w: &StretchCounts, debt: f64) -> Option<TailTimes> {
        if w.drawn_tail.fragments == 0 || w.colour_reads == 0 {
            return None;
        }
        let run = self.drawn_tail_counts(w);
        let work = run.depth_reads as f64 + self.write_cycles(&run, self.write_bits(&run));
        let m = run.fragments as f64;
        let c = self.cycles_per_read;
        let end = self.run_end(work, m, debt);
        let forced = c * work - c * (self.slack - debt) > work;
        (end.port_lag > 0.0).then(|| TailTimes {
            fragments: run.fragments,
            port_lag: end.port_lag,
            pace: (m + end.port_lag) / m,
            port_rate: if forced { c } else { 1.0 },
            owed: end.owed,
            counts: run,
        })
    }

    /// Stretch `w`'s drawn tail's counts: each of its fragments writes what `w`'s drawn
    /// ones write.
    fn drawn_tail_counts(&self, w: &StretchCounts) -> StretchCounts {
        let (m, each) = (w.drawn_tail.fragments, |count: u64| u64::from(count > 0));
        StretchCounts {
            fragments: m,
            depth_reads: w.drawn_tail.reads,
            depth_writes: m * each(w.depth_writes),
            colour_writes: m * each(w.colour_writes),
            colour_reads: m * each(w.colour_reads),
            ..StretchCounts::default()
        }
    }

    /// Port cycles the transfers that follow a stretch's last depth read take: the write
    /// entries of its last `L` fragments (rule 5 puts fragment `j`'s write before fragment
    /// `j + L`'s read) and, under blending, their colour reads, at the stretch's shares of
    /// them and its port's rate. With no read among them the writes pack to the port's
    /// width, but a colour read goes before each blended write, which shares its cycle with
    /// the next one's read: `n` blended fragments take `n + 1` cycles. The depth test is
    /// through its last fragment before the port is through these: its write buffer holds
    /// them (`depth_write_buffer_entries` at most).
    fn trailing_write_cycles(&self, w: &StretchCounts, port_rate: f64) -> f64 {
        // In integers, `ceil(bits · held / F / V)` and `ceil(B · held / F)`: a stretch's
        // arithmetic stays off the floating-point rounding calls.
        if w.write_entries() == 0 && w.colour_reads == 0 {
            // Nothing follows the last read (and no division to find so).
            return 0.0;
        }
        let fragments = w.fragments.max(1);
        let held = self.trailing_fragments().min(fragments);
        let port_bits = self.arch.memory_port_bits_per_cycle as u64;
        let packed = (self.entry_bits(w) * held).div_ceil(fragments * port_bits);
        let colour_reads = (w.colour_reads * held).div_ceil(fragments);
        let blended = match colour_reads {
            0 => 0,
            reads => reads + 1,
        };
        packed.max(blended) as f64 * port_rate
    }

    /// The least the depth test trails the rasterizer by after a stretch: its slowest
    /// read's latency and, where the other clients force cycles, their longest run (0 when
    /// it read nothing).
    fn slowest_read_lag(&self, w: &StretchCounts, forced: bool) -> f64 {
        let latency = if w.page_misses > 0 {
            self.arch.page_miss_latency_cycles
        } else if w.depth_reads > 0 {
            self.arch.page_hit_latency_cycles
        } else {
            return 0.0;
        };
        latency as f64
            + if forced {
                self.longest_reserved_run()
            } else {
                0.0
            }
    }

    /// The most port cycles in a row the display refresh and the host force once past their
    /// slack: `f` of the cycles, spread evenly by the debt, `ceil(f / (1 - f))` in a row (1
    /// at the O2's 0.234; 0 with none). A read asked for in the first waits that long.
    fn longest_reserved_run(&self) -> f64 {
        self.longest_reserved_run
    }

    /// Fragments after a query's end token whose depth reads the port may serve before the
    /// query's records: `L`, at most the [`FIRST_READS_FRAGMENTS`] an index marks.
    fn head_fragments(&self) -> u64 {
        self.head_fragments
    }

    /// Latency of a query whose records are `record_words` words, after a window that
    /// drains in `drain` cycles, the port's other clients `debt` behind.
    pub fn latency(&self, record_words: u64, drain: f64, debt: f64) -> f64 {
        4.0 + self.record_cycles(record_words, debt) + drain
    }

    /// Whole cycles the port takes to write `record_words` record words, the other clients
    /// `debt` behind and the cycles they force among them.
    fn record_cycles(&self, record_words: u64, debt: f64) -> f64 {
        let port_cycles = self.record_port_cycles(record_words) as f64;
        self.port_time(port_cycles, debt).ceil()
    }

    /// The port cycles of `record_words` record words, before the other clients'.
    fn record_port_cycles(&self, record_words: u64) -> u64 {
        let words_per_cycle = (self.arch.memory_port_bits_per_cycle / 32) as u64;
        record_words.div_ceil(words_per_cycle)
    }
}

/// The pipe as a fluid: the rasterizer's clock and the cycle the blocks behind it are
/// through the work they were given, from the window's start (see the module docs).
#[derive(Clone, Debug, Default, PartialEq)]
struct Pipe {
    /// `g`.
    raster: f64,
    /// `d`.
    downstream: f64,
    /// `d` at the window's start: the backlog carried into it.
    carried: f64,
    /// The window's port cycles so far (the room verbose hit words find).
    port: f64,
    /// The OccU bound the last stretch.
    occu_bound: bool,
    /// The cycle the last fragment's depth read is ready, from the window's start: its
    /// emission and its read latency (0 when it read nothing new, or before the window).
    last_read_ready: f64,
    /// Fragments emitted so far (in the frame).
    emitted: u64,
    /// The recent stretches the FIFOs may still hold fragments of, oldest first.
    recent: VecDeque<StretchTimes>,
    /// The cycle the port is through the work asked of it so far, from the window's start
    /// (the prefetch asks for a fragment's read when it is emitted, ahead of its depth test).
    port_done: f64,
    /// The last stretch's writes, as counted (divided out into [`LastWrites`] only at a
    /// query's end).
    last_writes: StretchWrites,
    /// The port cycles of its last fragments' writes, which follow its last read
    /// ([`O2Formulas::trailing_write_cycles`]): `port_done` less these is the port through
    /// the work before them.
    trailing: f64,
    /// How far the port's other clients are behind their share, as of `debt_at`
    /// ([`O2Formulas::port_time`]; `debt_at` may lie before the window's start).
    debt: f64,
    debt_at: f64,
}

/// When the blocks behind the rasterizer take a stretch's fragments: its first fragment's
/// number, the cycle they start on the first, and the cycles each takes after it; its last
/// `tail` fragments (a drawn tail that binds the port) each `tail_pace` up to its end.
#[derive(Clone, Copy, Debug, PartialEq)]
struct StretchTimes {
    first: u64,
    fragments: u64,
    begin: f64,
    pace: f64,
    tail: u64,
    tail_pace: f64,
}

impl StretchTimes {
    /// The cycle the blocks behind the rasterizer start its fragment `k`.
    fn started(&self, k: u64) -> f64 {
        let (after, end) = (
            self.first + self.fragments - k,
            self.begin + self.fragments as f64 * self.pace,
        );
        match after <= self.tail {
            true => end - after as f64 * self.tail_pace,
            false => self.begin + (k - self.first) as f64 * self.pace,
        }
    }
}

impl Pipe {
    /// The rasterizer emits the end token: the window's cycles `T_w` and the backlog ahead
    /// of the token.
    fn window_end(&self) -> (f64, f64) {
        (self.raster, (self.downstream - self.raster).at_least(0.0))
    }

    /// Cycles the last fragment's read is still ready after the rasterizer's clock: the
    /// rasterizer's later work (empty primitives' setup) hides that much of its latency.
    fn last_read_wait(&self) -> f64 {
        (self.last_read_ready - self.raster).at_least(0.0)
    }

    /// The cycle the blocks behind the rasterizer start fragment `k`, if a recent stretch
    /// holds it.
    fn started(&self, k: u64) -> Option<f64> {
        // The newest first: the fragment is most often in the latest stretch kept.
        self.recent
            .iter()
            .rev()
            .find(|s| (s.first..s.first + s.fragments).contains(&k))
            .map(|s| s.started(k))
    }

    /// The clocks' origin moves `cycles` later: the blocks behind the rasterizer worked
    /// through that much of their backlog.
    fn shift(&mut self, cycles: f64) {
        self.downstream = (self.downstream - cycles).max(0.0);
        self.port_done = (self.port_done - cycles).max(0.0);
        self.carried = (self.carried - cycles).max(0.0);
        self.last_read_ready = (self.last_read_ready - cycles).max(0.0);
        // Not clamped: the idle cycles since the debt was last settled serve it.
        self.debt_at -= cycles;
        for stretch in &mut self.recent {
            stretch.begin -= cycles;
        }
    }

    /// The next window starts at the end token, `T_w` from this one's start, with the work
    /// left behind it.
    fn restart(&mut self) {
        self.shift(self.raster);
        self.carried = self.downstream;
        self.raster = 0.0;
        self.port = 0.0;
        self.last_read_ready = 0.0;
    }
}

/// Record words a query writes at its end, and the verbose hit words its engines sent,
/// from its result's totals: a brief record a tile, and a verbose query's overflowed
/// buffers a terminator each where they have room for one. Its engines sent each tile's
/// hits up to the buffer's room: a buffer that did not overflow holds them all; one that
/// overflowed holds all but the one the terminator took (`verbose_hits_kept`), so the hits
/// sent are those held and one an overflowed buffer with room.
pub fn query_words(shape: &QueryShape, totals: &QueryTotals) -> (u64, u64) {
    let tiles = totals.tiles as u64;
    let records = tiles * BRIEF_RECORD_ENTRIES as u64;
    if shape.mode != QueryMode::Verbose {
        return (records, 0);
    }
    let room = shape.buffer_entries.saturating_sub(BRIEF_RECORD_ENTRIES) as u64;
    let terminators = if room > 0 {
        totals.overflowed_buffers as u64
    } else {
        0
    };
    (records + terminators, totals.held_hits + terminators)
}

/// The last query's end while the fragments after its end token may hold its records back:
/// the in-order port serves the depth reads of the next `L` of them first, each after the
/// depth write of the fragment `L` before it (rule 5's order: see the module docs, followed).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Head {
    /// The query's latency were nothing to follow it, and its records' port cycles.
    latency: f64,
    record_cycles: u64,
    /// The cycle its end token entered the pipe, on the formulas' timeline.
    entry: f64,
    /// Rasterizer cycles since the end token: primitives' setup and fragments.
    offset: f64,
    /// Fragments since the end token (at most `L`).
    seen: u64,
    /// The window's last `L` fragments' writes, which the port takes between those reads.
    writes: LastWrites,
    /// The in-order port's last grant, from the end token, and the bits it holds.
    port: PortOrder,
}

/// The writes of a window's last `L` fragments, as its last stretch has them: fragment `k`
/// of them (from 0) writes when `floor((k + 1) · share) > floor(k · share)`, `bits` bits,
/// asked for (its depth test passed) in `first_ready + k · pace` cycles from the end token;
/// under blending after a colour read of `colour_read_bits` asked for then (0: none), the
/// write from the cycle after the read's grant.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct LastWrites {
    share: f64,
    bits: u32,
    colour_read_bits: u32,
    first_ready: f64,
    pace: f64,
}

/// A stretch's write entries, the bits they write, the bits of the colour read before each
/// (0: none), its fragments and its pace.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct StretchWrites {
    entries: u64,
    bits: u64,
    colour_read_bits: u32,
    fragments: u64,
    pace: f64,
}

impl StretchWrites {
    /// The writes of a window's last `limit` fragments as this stretch has them, the last
    /// ready `last_ready` cycles from the end token.
    fn last(&self, last_ready: f64, limit: u64) -> LastWrites {
        if self.entries == 0 {
            return LastWrites::default();
        }
        LastWrites {
            share: self.entries as f64 / self.fragments as f64,
            bits: (self.bits / self.entries) as u32,
            colour_read_bits: self.colour_read_bits,
            first_ready: last_ready - limit.saturating_sub(1) as f64 * self.pace,
            pace: self.pace,
        }
    }
}

impl LastWrites {
    /// The ready cycle of fragment `k`'s write, if it writes.
    fn write(&self, k: u64) -> Option<f64> {
        let (k, share) = (k as f64, self.share);
        ((k * share + share).floor() > (k * share).floor())
            .then_some(self.first_ready + k * self.pace)
    }
}

/// An in-order port: each request is granted no sooner than its ready cycle nor before the
/// one asked before it; a write shares its predecessor's cycle when that one was a write
/// with room left and it was ready by then (queued writes pack), a read takes a cycle whole.
/// A write ready before the port is free still takes its cycle after it, though the
/// window's port work counted it: at a query's end the formulas' port is often a few
/// cycles ahead of the machine's (a dense run of reads at the end of a stretch, which its
/// counts do not place), and dropping those writes as counted took the small corpus's
/// analytic mean latency error on o2 from 1.50% to 2.43% on the demo and from 0.93% to
/// 1.02% on the hard cases.
///
/// The port's other clients take their cycles as the machine's arbiter gives them
/// ([`crate::blocks::memory_port`]): every idle one, and one the pipeline asks for when they
/// would otherwise be more than their slack behind. (Granting a cycle a request, the
/// blended writes of the hard cases' full-viewport queries, each a cycle with the next
/// one's colour read, went through the port 1.3 times as fast as the machine's, whose
/// other clients took a cycle in four: their first query's records were available in 48
/// cycles where the machine's took 54.)
#[derive(Clone, Copy, Debug, PartialEq)]
struct PortOrder {
    last_grant: f64,
    bits: u32,
    width: u32,
    /// How far the other clients are behind their share after the last grant, their share
    /// `f` and their slack `σ`.
    debt: f64,
    share: f64,
    slack: f64,
}

impl PortOrder {
    /// The port of `formulas` after its backlog: free from `free`, its other clients `debt`
    /// behind then.
    fn free_from(free: f64, formulas: &O2Formulas, debt: f64) -> PortOrder {
        PortOrder {
            last_grant: free - 1.0,
            bits: formulas.arch.memory_port_bits_per_cycle,
            width: formulas.arch.memory_port_bits_per_cycle,
            debt,
            share: formulas.reserved_share,
            slack: formulas.slack,
        }
    }

    /// A write of `bits` asked for in `ready`: its grant.
    fn write(&mut self, ready: f64, bits: u32) -> f64 {
        if ready <= self.last_grant && self.bits + bits <= self.width {
            self.bits += bits;
        } else {
            self.grant(ready);
            self.bits = bits;
        }
        self.last_grant
    }

    fn read(&mut self, ready: f64) {
        self.grant(ready);
        self.bits = self.width;
    }

    /// A cycle of its own for a request asked for in `ready`: the first at or after it and
    /// after the last grant that the other clients leave the pipeline. The idle cycles
    /// before it serve their debt; then each cycle adds `f` to it, and past `σ` they take
    /// the cycle.
    fn grant(&mut self, ready: f64) {
        let mut cycle = (self.last_grant + 1.0).max(ready);
        if self.share > 0.0 {
            let idle = cycle - self.last_grant - 1.0;
            self.debt = clients_debt_after(self.share, self.slack, self.debt, 0.0, idle);
            while self.debt + self.share > self.slack {
                self.debt = (self.debt + self.share - 1.0).max(0.0);
                cycle += 1.0;
            }
            self.debt += self.share;
        }
        self.last_grant = cycle;
    }
}

/// The in-order port as a query's last record word was granted: that grant, on the
/// formulas' timeline, and how far behind the other clients were after it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct RecordsWritten {
    last_grant: f64,
    debt: f64,
}

impl Head {
    /// The query whose end token entered in `entry`: its records take `record_cycles` port
    /// cycles after the port's backlog at the end token (`port`) and `writes`.
    fn new(
        latency: f64,
        entry: f64,
        record_cycles: u64,
        port: PortOrder,
        writes: LastWrites,
    ) -> Head {
        Head {
            latency,
            record_cycles,
            entry,
            offset: 0.0,
            seen: 0,
            writes,
            port,
        }
    }

    /// The next fragment after the token is emitted `at` cycles after it, reading a new word
    /// when `reads`: the port takes the write of the fragment `L` before it, then its read,
    /// which the prefetch asks for the cycle after its emission.
    fn follow(&mut self, at: f64, reads: bool) {
        self.last_write(self.seen);
        if reads {
            self.port.read(at + 1.0);
        }
        self.seen += 1;
    }

    fn last_write(&mut self, k: u64) {
        let Some(mut ready) = self.writes.write(k) else {
            return;
        };
        if self.writes.colour_read_bits > 0 {
            ready = self.port.write(ready, self.writes.colour_read_bits) + 1.0;
        }
        self.port.write(ready, self.writes.bits);
    }

    /// The query's latency: its records go after the port's last grant, behind the window's
    /// last writes (its depth test runs ahead of them: [`O2Formulas::trailing_write_cycles`])
    /// and the reads of the fragments after the token among them; and the port as the last
    /// record word was granted.
    fn latency(mut self, limit: u64) -> (f64, RecordsWritten) {
        for k in self.seen..limit {
            self.last_write(k);
        }
        for _ in 0..self.record_cycles {
            self.port.read(self.port.last_grant + 1.0);
        }
        // The result is in memory the cycle after its last word's grant; where the formulas'
        // latency is later than the port's, the port idled until then, and the other
        // clients took those cycles.
        let latency = self.latency.max(self.port.last_grant + 1.0);
        let port = &self.port;
        let idle = latency - 1.0 - port.last_grant;
        let written = RecordsWritten {
            last_grant: self.entry + latency - 1.0,
            debt: clients_debt_after(port.share, port.slack, port.debt, 0.0, idle),
        };
        (latency, written)
    }
}

/// A drawn tail that binds the port ([`O2Formulas::drawn_tail`]): its fragments and counts,
/// how far the port is through them after the last one's emission, and the cycles the depth
/// test takes a fragment of them.
struct TailTimes {
    fragments: u64,
    port_lag: f64,
    pace: f64,
    /// Port cycles a cycle of its work takes (`c` where the other clients force theirs),
    /// and how far behind they are at least as it ends.
    port_rate: f64,
    owed: f64,
    counts: StretchCounts,
}

/// What a run of the port's work leaves as it ends ([`O2Formulas::run_end`]; a stretch's
/// ending runs of reads, [`O2Formulas::ending_runs`]).
struct RunEnd {
    /// The port's other clients' debt, at least.
    owed: f64,
    /// Cycles from the last fragment's emission until the port is through its work.
    port_lag: f64,
}

/// The O2 model's counting state: the stretch being counted and the pipe's clocks.
pub(crate) struct O2Bottleneck {
    formulas: O2Formulas,
    address: DepthAddress,
    last_read: LastRead,
    stretch: StretchCounts,
    pipe: Pipe,
    /// OccU cycles per fragment and "occlusion render mode" of the open query.
    open: Option<(u64, bool)>,
    /// The last query's end, while the fragments after it may hold its records back.
    head: Option<Head>,
    /// The last query's latency once its head closed, until taken.
    followed: Option<f64>,
    /// Where the in-order port was once the last query's records were written.
    records: Option<RecordsWritten>,
    /// The dense runs of reads of the fragments counted since the last other event (a
    /// window index's stretch keeps its own).
    dense: DenseReadFinder,
}

impl O2Bottleneck {
    pub(super) fn new(arch: &O2Arch, width: u32, height: u32) -> O2Bottleneck {
        O2Bottleneck {
            formulas: O2Formulas::new(arch, width, height),
            address: DepthAddress::new(&arch.depth_layout(), width),
            last_read: LastRead::new(arch.memory_banks),
            stretch: StretchCounts::default(),
            pipe: Pipe::default(),
            open: None,
            head: None,
            followed: None,
            records: None,
            dense: DenseReadFinder::default(),
        }
    }

    /// `fragments` pass the rasterizer, `first_reads` marking those that read a new word
    /// (bit `k`: fragment `k`): those among the `L` after the last query's end token move its
    /// head on, and the `L`-th closes it.
    fn follow(&mut self, fragments: u64, first_reads: u64) {
        let limit = self.formulas.head_fragments();
        let Some(head) = &mut self.head else {
            return;
        };
        let taken = fragments.min(limit - head.seen);
        for k in 0..taken {
            // Fragment `k` (bit `k`) is emitted `k` cycles after the stretch's first.
            head.follow(head.offset + k as f64, first_reads >> k & 1 == 1);
        }
        head.offset += taken as f64;
        if head.seen == limit {
            self.close_head();
        }
    }

    /// An event other than a fragment: the run of fragments counted one by one or in spans
    /// since the last ends, and its dense runs of reads join the stretch (a window index's
    /// stretch is such a run, and keeps its own).
    #[inline]
    pub(super) fn end_run(&mut self) {
        if self.dense.is_empty() {
            return;
        }
        let runs = self.dense.take();
        self.formulas
            .add_dense_runs(&mut self.stretch, &runs.densest);
        self.stretch.ending = runs.ending;
    }

    /// The last query's records wait for no more reads (`L` fragments followed its end token,
    /// or the pipe drains: a wait, a frame's or another query's end, an idle gap).
    pub(super) fn close_head(&mut self) {
        if let Some(head) = self.head.take() {
            let (latency, written) = head.latency(self.formulas.head_fragments());
            self.followed = Some(latency);
            self.records = Some(written);
        }
    }

    /// The last query's latency, once its head closed.
    pub(super) fn take_followed(&mut self) -> Option<f64> {
        self.followed.take()
    }

    /// The stretch counted so far joins the pipe's clocks (see the module docs).
    fn close_stretch(&mut self) {
        close_stretch(&self.formulas, &mut self.pipe, &self.stretch);
        self.stretch = StretchCounts::default();
    }

    /// A primitive released `release` cycles after the window's start: the rasterizer sets
    /// it up no earlier.
    pub(super) fn primitive(&mut self, release: f64) {
        // One pipe: it takes no primitive before the window starts.
        let release = release.at_least(0.0);
        self.close_stretch();
        if release > self.pipe.raster {
            self.close_head();
        }
        self.pipe.raster = self.pipe.raster.at_least(release);
        self.stretch.primitives = 1;
        if let Some(head) = &mut self.head {
            head.offset += self.formulas.arch.primitive_setup_cycles as f64;
        }
    }

    pub(super) fn begin(&mut self, shape: &QueryShape) {
        let service = self.formulas.service_cycles(shape.tiles);
        self.open = Some((service, shape.mode.is_occlusion_render_mode()));
    }

    /// Passing fragments draw: no occlusion-render-mode query (brief, verbose) is open.
    fn draws(&self) -> bool {
        !self.open.is_some_and(|(_, mode)| mode)
    }

    /// Count one fragment's work (before `functional` applies it).
    #[inline]
    pub(super) fn fragment(&mut self, fragment: Fragment, functional: &FunctionalModel) {
        let (mut stretch, draws) = (FragmentStretch::EMPTY, self.draws());
        stretch.count_fragment(
            fragment,
            functional.state(),
            functional.depth_buffer().get(fragment.x, fragment.y),
            (&self.address, &mut self.last_read),
            draws,
        );
        self.dense.fragments(stretch.depth_reads > 0, 0);
        self.stretch(&stretch, functional.state());
    }

    /// Count a span's fragments (inside the viewport, before `functional` applies it), as
    /// one by one: one read decision a memory word the row run crosses (the words after the
    /// first of a run are the last read's), and its passing fragments counted in one loop.
    pub(super) fn span(&mut self, span: Span, functional: &FunctionalModel) {
        let Some(last) = span.depths.len().checked_sub(1) else {
            return;
        };
        let state = functional.state();
        let end = span.x as u32 + span.depths.len() as u32;
        let mut stretch = FragmentStretch {
            fragments: span.depths.len() as u64,
            depth_reads: 0,
            page_misses: 0,
            passed: 0,
            last_read: DepthRead::SameWord,
            first_reads: 0,
            dense: DenseRuns::NONE,
            ending: DenseRuns::NONE,
            drawn_tail: DrawnTail::NONE,
        };
        let draws = self.draws();
        if !state.depth_test {
            self.dense.fragments(false, last as u64);
            if draws {
                stretch.drawn_tail.fragments = span.depths.len() as u64;
            }
        } else {
            // The fragments from `tail_from` on pass one after another (none where nothing
            // draws).
            let tail = match draws {
                true => functional
                    .depth_buffer()
                    .passing_tail(state.depth_func, span),
                false => 0,
            };
            let tail_from = end - tail as u32;
            stretch.drawn_tail.fragments = tail as u64;
            let last_x = span.x as u32 + last as u32;
            let mut x = span.x as u32;
            while x < end {
                let (word, page) = self.address.locate(x as u16, span.y);
                let read = self.last_read.read(word, page);
                stretch.depth_reads += (read != DepthRead::SameWord) as u64;
                stretch.page_misses += (read == DepthRead::PageMiss) as u64;
                let at = x - span.x as u32;
                if read != DepthRead::SameWord && (at as u64) < FIRST_READS_FRAGMENTS {
                    stretch.first_reads |= 1 << at;
                }
                stretch.drawn_tail.reads += (read != DepthRead::SameWord && x >= tail_from) as u64;
                let next = (x + self.address.pixels_left_in_word(x as u16)).min(end);
                self.dense
                    .fragments(read != DepthRead::SameWord, (next - x - 1) as u64);
                // The last fragment reads anew only when it starts its word's run.
                if x == last_x {
                    stretch.last_read = read;
                }
                x = next;
            }
            if draws {
                stretch.passed = functional
                    .depth_buffer()
                    .count_passing(state.depth_func, span);
            }
        }
        self.stretch(&stretch, state);
    }

    /// Count a stretch of fragments from a trace's window index, as their fragments one by
    /// one would be counted (`state` the render state they were drawn in; the stretch was
    /// counted at this machine's depth layout).
    pub(super) fn stretch(&mut self, stretch: &FragmentStretch, state: &RenderState) {
        let n = stretch.fragments;
        if n == 0 {
            return;
        }
        self.follow(n, stretch.first_reads);
        let draws = self.draws();
        let arch = &self.formulas.arch;
        let w = &mut self.stretch;
        w.fragments += n;
        w.occu_cycles += n * self.open.map_or(1, |(service, _)| service);
        w.last_read_latency = match stretch.last_read {
            DepthRead::SameWord => 0,
            DepthRead::PageHit => arch.page_hit_latency_cycles,
            DepthRead::PageMiss => arch.page_miss_latency_cycles,
        };
        w.depth_reads += stretch.depth_reads;
        w.page_misses += stretch.page_misses;
        self.formulas.add_dense_runs(w, &stretch.dense);
        // A later run of the same stretch ends it (one with no read leaves none).
        w.ending = stretch.ending;
        w.drawn_tail = w.drawn_tail.then(stretch.drawn_tail, n);
        if !draws {
            return;
        }
        // Outside an occlusion render mode: with the depth test off every fragment draws,
        // with it on those that pass.
        let drawn = if state.depth_test { stretch.passed } else { n };
        if state.depth_test && state.depth_mask {
            w.depth_writes += drawn;
        }
        if arch.colour_bits_per_pixel > 0 {
            w.colour_writes += drawn;
            w.colour_reads += arch.blending as u64 * drawn;
        }
    }

    /// A clear: the depth test waits for its words through the port (when clears write
    /// memory), while the rasterizer runs on until the FIFO before the depth test is full.
    pub(super) fn clear(&mut self) {
        self.close_stretch();
        let (formulas, pipe) = (&self.formulas, &mut self.pipe);
        let from = pipe.downstream.max(pipe.raster);
        let debt = formulas.debt_after_idle(pipe.debt, from - pipe.debt_at);
        let work = formulas.clear_work();
        let cycles = formulas.port_time(work, debt);
        pipe.downstream = from + cycles;
        pipe.port_done = pipe.downstream;
        pipe.trailing = 0.0;
        pipe.port += cycles;
        pipe.debt = formulas.debt_after(debt, work, cycles);
        pipe.debt_at = pipe.port_done;
    }

    /// The query `spec` ended with `result`, its window begun at `start` and its end token
    /// released at `release`: the window's cycles and the query's latency.
    pub(super) fn end_query(
        &mut self,
        shape: &QueryShape,
        totals: &QueryTotals,
        start: f64,
        release: f64,
    ) -> WindowEnd {
        self.open = None;
        self.close_stretch();
        let (records, hits) = query_words(shape, totals);
        // Verbose hit words went through the port beside the window's other words: what the
        // port's idle cycles in the window could not take lengthens the drain.
        let pipe = &mut self.pipe;
        // The other clients' debt as the records go: the port idled since it was settled,
        // up to the token's entry at its release and through the backlog ahead of it.
        let records_from = pipe.downstream.max(release - start);
        let debt = self
            .formulas
            .debt_after_idle(pipe.debt, records_from - pipe.debt_at);
        let hit_cycles = self
            .formulas
            .port_time(self.formulas.port_cycles(32 * hits), debt);
        let idle = (pipe.downstream - pipe.carried - pipe.port).max(0.0);
        pipe.downstream += (hit_cycles - idle).max(0.0);
        let (cycles, backlog) = pipe.window_end();
        let drain = backlog.max(pipe.last_read_wait());
        // The port through all but the window's last writes, which the head takes in order,
        // the other clients as far behind then as they were after its work.
        let port_free = pipe.port_done - pipe.trailing;
        let port_debt = self
            .formulas
            .debt_after_idle(pipe.debt, port_free - pipe.debt_at);
        let port_backlog = (port_free - cycles).max(0.0);
        let occu_bound = pipe.occu_bound;
        pipe.restart();
        // The token enters at its release: the pipe drained meanwhile.
        let late = (release - (start + cycles)).max(0.0);
        let port_backlog = (port_backlog - late).max(0.0);
        // The last fragment's write is ready as the depth test is through it.
        let limit = self.formulas.head_fragments();
        let writes = pipe.last_writes.last(backlog - late, limit);
        let mut drain = (drain - late).max(0.0);
        if occu_bound {
            // The token's first steps pass while the OccU works through the backlog.
            drain = (drain - OCCU_BOUND_TOKEN_OVERLAP_CYCLES).max(0.0);
        }
        let latency = self.formulas.latency(records, drain, debt);
        // The port is in order: after a window of no work, the last query's records, still
        // being written when this query's are ready (`4 + drain` after its token enters),
        // go first.
        let entry = start + cycles + late;
        let ready = 4.0 + drain;
        let behind = self.records.filter(|last| {
            cycles == 0.0 && last.last_grant + 1.0 - entry > ready.max(port_backlog)
        });
        // Behind them, the window's last writes are the last query's too, which its records
        // went after.
        let (port, writes) = match behind {
            Some(last) => (
                PortOrder::free_from(last.last_grant + 1.0 - entry, &self.formulas, last.debt),
                LastWrites::default(),
            ),
            None => (
                PortOrder::free_from(port_backlog, &self.formulas, port_debt),
                writes,
            ),
        };
        let record_cycles = self.formulas.record_port_cycles(records);
        let head = Head::new(latency, entry, record_cycles, port, writes);
        if behind.is_none() {
            self.head = Some(head);
            return WindowEnd { cycles, latency };
        }
        // Behind the last query's records its own are asked for before the port is through
        // those, and the reads of the fragments after its token are taken to find the
        // port's idle cycles before them (not followed: an approximation).
        let (latency, written) = head.latency(self.formulas.head_fragments());
        self.records = Some(written);
        WindowEnd { cycles, latency }
    }

    /// The pipe stood idle `cycles` before the window: the blocks behind the rasterizer
    /// worked through that much of the backlog carried into it.
    pub(super) fn idle(&mut self, cycles: f64) {
        self.close_head();
        self.pipe.shift(cycles);
    }

    /// Start the window again with no work (a frame ended inside it).
    pub(super) fn clear_window(&mut self) {
        self.stretch = StretchCounts::default();
        self.pipe = Pipe::default();
    }

    /// The stream ended after a window without a query end: its cycles and the pipe's drain
    /// (+ 3: through the depth pipeline, the OccU and the last write).
    pub(super) fn finish(&self) -> Option<WindowEnd> {
        let mut pipe = self.pipe.clone();
        let mut stretch = self.stretch.clone();
        if !self.dense.is_empty() {
            let runs = self.dense.clone().take();
            self.formulas.add_dense_runs(&mut stretch, &runs.densest);
            stretch.ending = runs.ending;
        }
        close_stretch(&self.formulas, &mut pipe, &stretch);
        // Work since the window began: a primitive, a fragment or a clear.
        let worked = pipe.raster > 0.0 || pipe.downstream > pipe.carried;
        worked.then(|| {
            let (cycles, backlog) = pipe.window_end();
            // The port's last writes trail the depth test: the run ends with the last.
            let port_backlog = pipe.port_done - cycles;
            let latency = (backlog.max(pipe.last_read_wait()) + 3.0).at_least(port_backlog);
            WindowEnd { cycles, latency }
        })
    }
}

/// A stretch's work joins the pipe's clocks: the rasterizer sets up its primitive and emits
/// its fragments a cycle each; the blocks behind take them at the stretch's pace, after the
/// work before and no sooner than they come, and no sooner than the port, on its own clock
/// from their emission, is through their reads; the rasterizer emits fragment `k` only once
/// fragment `k - Q` has left the FIFO (`Q` fragments fit the FIFOs ahead of the bottleneck).
fn close_stretch(formulas: &O2Formulas, pipe: &mut Pipe, stretch: &StretchCounts) {
    let start = pipe.raster + (formulas.arch.primitive_setup_cycles * stretch.primitives) as f64;
    let emitted = start + stretch.fragments as f64;
    pipe.raster = emitted;
    let n = stretch.fragments;
    if n == 0 {
        return;
    }
    // The port takes the stretch's reads as the rasterizer emits them, while the depth test
    // still works through the backlog: a lag already built is slack for them.
    let port_from = pipe.port_done.at_least(start);
    let debt = formulas.debt_after_idle(pipe.debt, port_from - pipe.debt_at);
    let down = formulas.downstream(stretch, debt, emitted - port_from);
    let begin = pipe.downstream.at_least(start);
    pipe.port_done = port_from + down.port;
    // Its transfers spread over the fragments' emission, the idle cycles among them
    // serving the other clients.
    let span = down.port.at_least(emitted - port_from);
    // The port's busy cycles, for the debt: writes that come a cycle apart each take a
    // cycle of their own while the port has room (they pack only once queued).
    let entries = stretch.write_entries() + stretch.colour_reads;
    let busy = down
        .work
        .at_least(((stretch.depth_reads + entries) as f64).at_most(span));
    pipe.debt = formulas.debt_after(debt, busy, span);
    // The runs of reads ending it leave the clients owed and the port behind as it ends.
    let ending = formulas.ending_runs(stretch, debt, entries);
    pipe.debt = pipe.debt.at_least(ending.owed);
    if ending.port_lag > 0.0 {
        pipe.port_done = pipe.port_done.at_least(emitted + ending.port_lag);
    }
    // A drawn tail that binds the port leaves it behind too, and its fragments are what the
    // stretch ends with: the writes after its last read, the FIFO's last departures.
    pipe.debt_at = port_from + span;
    let tail = formulas.drawn_tail(stretch, debt);
    if let Some(tail) = &tail {
        pipe.port_done = pipe.port_done.at_least(emitted + tail.port_lag);
        pipe.debt = pipe.debt.at_least(tail.owed);
        // The port was busy through the tail: the clients are owed that much as it ends.
        pipe.debt_at = pipe.debt_at.at_least(pipe.port_done);
    }
    // The last fragments' writes are the tail's where it holds all of them.
    let last = match &tail {
        Some(tail) if tail.fragments >= formulas.trailing_fragments() => &tail.counts,
        _ => stretch,
    };
    // Its last read's data comes its latency after the port is through: the last
    // fragment's, when it read (in order, the port's last), else a page hit's.
    let last_latency = match stretch.last_read_latency {
        0 => formulas.arch.page_hit_latency_cycles,
        latency => latency,
    };
    // The transfers of its last fragments' writes follow that read on the in-order port,
    // and the depth test runs ahead of them, its write buffer holding them.
    let port_rate = match &tail {
        Some(tail) => tail.port_rate,
        None if down.work > 0.0 => down.port / down.work,
        None => 0.0,
    };
    let trailing = formulas.trailing_write_cycles(last, port_rate);
    pipe.trailing = trailing;
    let read_in = (pipe.port_done - trailing) + last_latency as f64;
    // A dense run of reads inside it leaves the depth test that much behind the fragments'
    // emission, and its last read's data a page hit later.
    let dense_read_lag = formulas.dense_read_lag(stretch, debt);
    let dense_in = match dense_read_lag > 0.0 {
        true => emitted + dense_read_lag + formulas.arch.page_hit_latency_cycles as f64,
        false => 0.0,
    };
    let cycles = (begin + down.off_port).at_least(read_in).at_least(dense_in) - begin;
    let pace = cycles / n as f64;
    pipe.downstream = (begin + cycles).at_least(emitted);
    // The depth test trails the rasterizer by at least its slowest read's latency + 1.
    pipe.downstream = pipe
        .downstream
        .at_least(emitted + formulas.slowest_read_lag(stretch, down.forced));
    pipe.port += down.port;
    pipe.occu_bound = down.occu_bound;
    let tail_pace = tail.as_ref().map_or(pace, |tail| tail.pace);
    pipe.last_writes = StretchWrites {
        entries: last.write_entries(),
        bits: formulas.entry_bits(last),
        colour_read_bits: match last.colour_reads {
            0 => 0,
            _ => formulas.arch.colour_bits_per_pixel,
        },
        fragments: last.fragments,
        pace: tail_pace,
    };
    let times = StretchTimes {
        first: pipe.emitted,
        fragments: n,
        begin,
        pace,
        tail: tail.as_ref().map_or(0, |tail| tail.fragments),
        tail_pace,
    };
    pipe.emitted += n;
    // The last fragment waits for fragment `last - Q` to leave the FIFO: as it starts at the
    // OccU, which takes it from its own FIFO; at the end of its pace before the depth test,
    // which takes it once its read is in.
    let queued = down.queued - (!down.occu_bound) as u64;
    match (pipe.emitted - 1).checked_sub(queued) {
        // Most often in this stretch: the older ones hold no fragment the next may wait for.
        Some(blocking) if blocking >= times.first => {
            pipe.raster = pipe.raster.at_least(times.started(blocking));
            pipe.recent.clear();
        }
        Some(blocking) => {
            if let Some(started) = pipe.started(blocking) {
                pipe.raster = pipe.raster.at_least(started);
            }
            while pipe
                .recent
                .front()
                .is_some_and(|s| s.first + s.fragments <= blocking)
            {
                pipe.recent.pop_front();
            }
        }
        None => {}
    }
    pipe.recent.push_back(times);
    // The last fragment's read is asked for when it is emitted, the cycle before the
    // rasterizer's clock.
    pipe.last_read_ready = if stretch.last_read_latency > 0 {
        pipe.raster + stretch.last_read_latency as f64
    } else {
        0.0
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::Arch;
    use occsim_traces::rng::SplitMix64;
    use occsim_traces::trace::ReadRun;
    use occsim_traces::{DepthFunc, Event, HitList, QueryResult, QuerySpec, Rect, TileResult};

    /// Random row runs (some crossing words and 16-pixel pages, some of one fragment)
    /// under random render state, inside and outside a brief query: the counts after each
    /// span given whole equal those after its fragments one by one.
    #[test]
    fn a_span_counts_as_its_fragments_one_by_one() {
        let mut arch = Arch::builtin("o2").unwrap();
        // Small pages and two banks, so runs cross pages and rows reopen.
        arch.set("framebuffer_tile_width_pixels=16").unwrap();
        arch.set("framebuffer_tile_height_pixels=4").unwrap();
        arch.set("blending=true").unwrap();
        let o2 = arch.o2().unwrap();
        let (width, height) = (64u32, 16u32);
        let mut rng = SplitMix64(7);
        let mut whole = O2Bottleneck::new(&o2, width, height);
        let mut single = O2Bottleneck::new(&o2, width, height);
        let mut functional = FunctionalModel::new(width, height);
        let mut last_reads = 0;
        for step in 0..4000 {
            if rng.below(8) == 0 {
                let event = match rng.below(5) {
                    0 => Event::DepthTest(rng.below(4) != 0),
                    1 => Event::DepthMask(rng.below(2) == 0),
                    2 => Event::DepthFunc(DepthFunc::ALL[rng.below(8) as usize]),
                    3 => Event::Clear,
                    _ => Event::Primitive,
                };
                if event == Event::Clear {
                    whole.clear();
                    single.clear();
                }
                functional.event(&event);
                continue;
            }
            if step % 500 == 0 {
                let spec = QuerySpec {
                    id: step as u32,
                    mode: QueryMode::Brief,
                    buffer_entries: 8,
                    tiles: vec![Rect::new(0, 0, width, height)],
                };
                whole.begin(&spec.shape());
                single.begin(&spec.shape());
            }
            let len = 1 + rng.below(24) as usize;
            let x = rng.below(width as u64 - len as u64 + 1) as u16;
            let y = rng.below(height as u64) as u16;
            let depths: Vec<u32> = (0..len).map(|_| rng.below(1 << 24) as u32).collect();
            let span = Span {
                x,
                y,
                depths: &depths,
            };
            whole.span(span, &functional);
            for fragment in span.fragments() {
                single.fragment(fragment, &functional);
            }
            assert_eq!(whole.stretch, single.stretch, "step {step}");
            last_reads += (whole.stretch.last_read_latency > 0) as u32;
            functional.span(span);
        }
        // The runs did end on a new word, so the last read's latency was compared.
        assert!(last_reads > 100, "{last_reads}");
    }

    /// O2 at 4 engines whose port no refresh or host shares (`f` = 0).
    fn unshared_o2() -> O2Arch {
        unshared_o2_with(&[])
    }

    /// The same with `sets` (`key=value`) besides.
    fn unshared_o2_with(sets: &[&str]) -> O2Arch {
        let mut arch = Arch::builtin("o2").unwrap();
        arch.set("display_width_pixels=0").unwrap();
        arch.set("host_memory_share=0").unwrap();
        arch.set("engines=4").unwrap();
        for set in sets {
            arch.set(set).unwrap();
        }
        let o2 = arch.o2().unwrap();
        assert_eq!(o2.reserved_port_share(), 0.0);
        o2
    }

    /// The O2 with a quarter of its port's cycles reserved (`f` = 1/4, `c` = 4/3; the slack
    /// `σ` 16 and `C1` 16 as built in).
    fn quarter_shared_o2() -> O2Arch {
        let mut arch = Arch::builtin("o2").unwrap();
        arch.set("display_width_pixels=0").unwrap();
        arch.set("host_memory_share=0.25").unwrap();
        let o2 = arch.o2().unwrap();
        assert_eq!(o2.reserved_port_share(), 0.25);
        assert_eq!(o2.other_clients_slack_cycles, 16);
        o2
    }

    /// A stretch of 40 reads ending with 12 fragments that all read, worked by hand at `f`
    /// = 1/4 (`c` = 4/3):
    /// - drawing (40 write entries, one a read): a read takes 2 port cycles, so the run
    ///   keeps the port busy `n` = 24 cycles over `max(12, 24)` = 24; the clients fall
    ///   `min(24 - 3/4 · 12, 1/4 · 24)` = 6 behind; the port is through `max(24 - 12, 4/3 ·
    ///   24 - 12 - 4/3 · (16 - debt))` after the last fragment: 12 at a debt of 4, 20 at 16
    ///   (the FIFO's 16 at most);
    /// - not drawing: `n` = 12, owed `min(12 - 9, 3)` = 3; the port 16 - 12 - 4/3 · (16 -
    ///   debt) behind: none at a debt of 4, 4 at 16;
    /// - no run ends it: nothing.
    #[test]
    fn the_run_ending_a_stretch_leaves_the_clients_owed_and_the_port_behind() {
        let formulas = O2Formulas::new(&quarter_shared_o2(), 640, 480);
        let mut ending = DenseRuns::NONE;
        ending.push(ReadRun {
            reads: 12,
            fragments: 12,
        });
        let stretch = StretchCounts {
            fragments: 100,
            depth_reads: 40,
            ending,
            ..StretchCounts::default()
        };
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9;
        let left = |debt: f64, writes: u64| {
            let ending = formulas.ending_runs(&stretch, debt, writes);
            (ending.owed, ending.port_lag)
        };
        let (owed, lag) = left(4.0, 40);
        assert!(close(owed, 6.0) && close(lag, 12.0), "{owed} {lag}");
        let (owed, lag) = left(16.0, 40);
        assert!(close(owed, 6.0) && close(lag, 16.0), "{owed} {lag}");
        let (owed, lag) = left(4.0, 0);
        assert!(close(owed, 3.0) && close(lag, 0.0), "{owed} {lag}");
        let (owed, lag) = left(16.0, 0);
        assert!(close(owed, 3.0) && close(lag, 4.0), "{owed} {lag}");
        let none = StretchCounts {
            ending: DenseRuns::NONE,
            ..stretch
        };
        let ending = formulas.ending_runs(&none, 16.0, 40);
        assert_eq!((ending.owed, ending.port_lag), (0.0, 0.0));
    }

    /// A verbose query of three tiles with room for 4 hits each (12 entries) whose
    /// fragments pass 2, 9 and 0 times: tile 0 holds its 2 hits; tile 1 overflowed and
    /// holds 3 (the terminator takes the fourth entry); tile 2 none. The engines sent each
    /// tile's hits up to its room, 2 + 4 + 0 = 6 words, and the records are 8 words a tile
    /// and tile 1's terminator, 25. With no room (8 entries) 5 passing fragments overflow a
    /// buffer that holds nothing, not even the terminator: 8 record words, no hit words.
    #[test]
    fn a_verbose_querys_words_are_its_records_terminators_and_hits_sent() {
        let tile = |nohc: u64, held: u16, overflowed: bool| TileResult {
            nohc,
            phc: nohc,
            hits: HitList::from_hits((0..held).map(|x| (x, 0)), 64),
            overflowed,
            ..TileResult::default()
        };
        let query = |buffer_entries: u32, tiles: Vec<TileResult>| {
            let result = QueryResult {
                id: 1,
                mode: QueryMode::Verbose,
                overflowed_buffers: tiles.iter().filter(|t| t.overflowed).count() as u32,
                tiles,
            };
            let shape = QueryShape {
                id: 1,
                mode: QueryMode::Verbose,
                buffer_entries,
                tiles: result.tiles.len(),
            };
            query_words(&shape, &result.totals())
        };
        let three = vec![tile(2, 2, false), tile(9, 3, true), tile(0, 0, false)];
        assert_eq!(query(12, three), (25, 6));
        assert_eq!(query(8, vec![tile(5, 0, true)]), (8, 0));
    }

    fn whole_screen_brief() -> (QueryShape, QueryTotals) {
        let spec = QuerySpec {
            id: 1,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 640, 480)],
        };
        let result = QueryResult {
            id: 1,
            mode: QueryMode::Brief,
            tiles: vec![Default::default()],
            overflowed_buffers: 0,
        };
        (spec.shape(), result.totals())
    }

    /// A brief query's box: one primitive of 800 fragments that reads 100 new words (one a
    /// page miss, the last a page hit) and writes nothing, on an O2 whose port no refresh
    /// or host shares (`f` = 0), at 4 engines. Worked by hand:
    /// - setup 4 cycles, so the fragments are emitted by `g` = 4 + 800 = 804;
    /// - depth 800, OccU 800 (one tile at 4 engines: 1 cycle a fragment), port 100,
    ///   prefetch 100 (2.06 + 1) / 16 = 19.1;
    ///   `d` = max(4 + 800, 804) = 804;
    /// - the slowest read, a page miss of 8 cycles, leaves the depth test 8 behind (no
    ///   reserved cycle to wait for): `d` = 804 + 8 = 812, a backlog of 8 at the end token
    ///   (the FIFO's 16 never bind);
    /// - records: 8 words, one port cycle at 8 words a cycle;
    /// - latency 4 + 1 + max(8, 2) = 13 (the sum 0.02 a read had given a backlog of 2, so
    ///   7), the cycle model's on such queries of the forest's walk.
    #[test]
    fn a_sparse_stretch_leaves_the_depth_test_its_slowest_reads_latency_behind() {
        let (mut formulas, spec, result) = counted_box();
        let end = formulas.end_query(&spec, &result, 0.0, 0.0);
        assert_eq!(end.cycles, 804.0);
        assert_eq!(end.latency, 13.0);
    }

    /// The box's one primitive: 800 fragments, 100 new words read (one a page miss, the
    /// last a page hit), nothing written.
    const BOX: FragmentStretch = FragmentStretch {
        fragments: 800,
        depth_reads: 100,
        page_misses: 1,
        passed: 0,
        last_read: DepthRead::PageHit,
        first_reads: 0,
        dense: DenseRuns::NONE,
        ending: DenseRuns::NONE,
        drawn_tail: DrawnTail::NONE,
    };

    /// The formulas after the box's brief query began and its primitive was counted.
    fn counted_box() -> (O2Bottleneck, QueryShape, QueryTotals) {
        let mut formulas = O2Bottleneck::new(&unshared_o2(), 640, 480);
        let (spec, result) = whole_screen_brief();
        formulas.begin(&spec);
        formulas.primitive(0.0);
        formulas.stretch(&BOX, &RenderState::new(640, 480));
        (formulas, spec, result)
    }

    /// A primitive of 4,000 fragments drawn outside a query (each writing depth and colour,
    /// 64 bits), 1,000 of them reading a new word (page hits, the last fragment's too), on
    /// a port no refresh or host shares (`f` = 0, so no forced cycle). Worked by hand:
    /// - setup 4, emitted by `g` = 4,004; port = 1,000 reads + max(ceil(4,000 · 64 / 256) =
    ///   1,000, min(4,000, 1,000)) = 2,000 cycles, through in 2,004, the last read in
    ///   2,006; the depth test, a fragment a cycle, through in 4,004;
    /// - its reads' stalls stop once it trails by the slowest read's latency, a page hit's
    ///   2: `d` = 4,006, a backlog of 2; the stream ends: latency 2 + 3 = 5.
    ///
    /// (Summing 0.02 cycles a read over the stretch, as the formulas did, gave depth 4,020
    /// and the FIFO's 16 fragments queued at the end: latency 19.)
    #[test]
    fn a_drawing_stretch_leaves_the_depth_test_its_slowest_reads_latency_behind_too() {
        let mut formulas = O2Bottleneck::new(&unshared_o2(), 640, 480);
        formulas.primitive(0.0);
        let drawn = FragmentStretch {
            fragments: 4000,
            depth_reads: 1000,
            page_misses: 0,
            passed: 4000,
            last_read: DepthRead::PageHit,
            first_reads: 0,
            dense: DenseRuns::NONE,
            ending: DenseRuns::NONE,
            // All drawn: 1,000 reads and 1,000 write cycles take the port 2,000 cycles of
            // the 4,000, so the tail leaves it no lag.
            drawn_tail: DrawnTail {
                fragments: 4000,
                reads: 1000,
            },
        };
        formulas.stretch(&drawn, &RenderState::new(640, 480));
        let end = formulas.finish().unwrap();
        assert_eq!((end.cycles, end.latency), (4004.0, 5.0));
    }

    /// A window's last 4 fragments blended, their depth tests a cycle apart from the end
    /// token (`k`), nothing after the token, the port free at it and shared with no one.
    /// Worked by hand: colour read 0 in 0; write 0 (64 bits) from the cycle after, in 1;
    /// colour read 1, asked for in 1, shares that cycle (96 bits); write 1 in 2, with colour
    /// read 2; write 2 in 3, with colour read 3; write 3 in 4; the record in 5, available in
    /// 6. Four blended fragments take the port 4 + 1 cycles, as
    /// `trailing_write_cycles` counts them.
    #[test]
    fn under_blending_each_of_the_last_writes_follows_its_colour_read() {
        let formulas = O2Formulas::new(&unshared_o2_with(&["blending=true"]), 640, 480);
        let writes = LastWrites {
            share: 1.0,
            bits: 64,
            colour_read_bits: 32,
            first_ready: 0.0,
            pace: 1.0,
        };
        let head = Head::new(
            0.0,
            0.0,
            1,
            PortOrder::free_from(0.0, &formulas, 0.0),
            writes,
        );
        assert_eq!(head.latency(4).0, 6.0);
        // Without the colour reads the writes go in 0 to 3 (asked for a cycle apart, none
        // queued to pack with), the record in 4, available in 5.
        let opaque = LastWrites {
            colour_read_bits: 0,
            ..writes
        };
        let head = Head::new(
            0.0,
            0.0,
            1,
            PortOrder::free_from(0.0, &formulas, 0.0),
            opaque,
        );
        assert_eq!(head.latency(4).0, 5.0);
    }

    /// The port's other clients at `f` = 1/4 with a slack of 1, owed nothing, and requests
    /// asked for every cycle from 0: their debt after each granted cycle is 0.25, 0.5, 0.75
    /// and 1 (cycles 0 to 3, none past the slack); in cycle 4 it would be 1.25, so they take
    /// it (debt 0.25), and the request goes in 5 (debt 0.5). After an idle stretch from 6 to
    /// 9 (4 idle cycles serve 0.75 each: debt 0) a request asked for in 10 goes in 10.
    #[test]
    fn the_heads_port_gives_the_other_clients_the_cycles_the_arbiter_does() {
        let mut port = PortOrder {
            last_grant: -1.0,
            bits: 256,
            width: 256,
            debt: 0.0,
            share: 0.25,
            slack: 1.0,
        };
        let grants: Vec<f64> = (0..5)
            .map(|_| {
                port.read(0.0);
                port.last_grant
            })
            .collect();
        assert_eq!(grants, [0.0, 1.0, 2.0, 3.0, 5.0]);
        assert_eq!(port.debt, 0.5);
        port.read(10.0);
        assert_eq!((port.last_grant, port.debt), (10.0, 0.25));
    }

    /// A stretch of 64 fragments, every one drawn and writing 32 bits of depth and 32 of
    /// colour, on a port shared with no one: the transfers after its last read are its last
    /// `min(L, write buffer)` = 16 fragments' writes, a quarter of the stretch's. Opaque,
    /// their 16 · 64 = 1,024 bits pack into 4 cycles of 256; blended, each write waits for its
    /// colour read and shares its cycle with the next one's read: 16 + 1 = 17 cycles.
    #[test]
    fn the_writes_after_a_stretchs_last_read_are_its_last_fragments() {
        let trailing = |sets: &[&str], colour_reads: u64| {
            let formulas = O2Formulas::new(&unshared_o2_with(sets), 640, 480);
            let drawn = StretchCounts {
                fragments: 64,
                depth_reads: 8,
                depth_writes: 64,
                colour_writes: 64,
                colour_reads,
                ..StretchCounts::default()
            };
            let down = formulas.downstream(&drawn, 0.0, 64.0);
            formulas.trailing_write_cycles(&drawn, down.port / down.work)
        };
        assert_eq!(trailing(&[], 0), 4.0);
        assert_eq!(trailing(&["blending=true"], 64), 17.0);
    }

    /// A query of latency 13 (one record cycle) whose window's last 16 fragments each wrote
    /// 64 bits, their writes ready from 2 cycles before the end token a cycle apart (`k - 2`),
    /// then 16 fragments emitted from 4 cycles after it (`4 + k`), the first 4 reading. The
    /// in-order port takes write `k`, then read `k` (asked for in `5 + k`); worked by hand:
    /// - `k` = 0..3: W0 in 0, R0 in 5, W1 in 6, R1 in 7, W2 in 8, R2 in 9, W3 in 10, R3 in 11
    ///   (a read takes its cycle whole, so no write shares one with it);
    /// - `k` = 4..15: no reads; W4 in 12 and W5..W7 (ready 3..5, queued) pack into it to
    ///   the port's 256 bits, W8..W11 in 13, W12..W15 in 14;
    /// - the record in 15, available in 16: latency 16. Without the writes the reads end in
    ///   8 and the record is available in 10, so the query keeps 13 (the model before).
    #[test]
    fn a_querys_records_wait_for_the_windows_last_writes_between_the_next_reads() {
        let writes = LastWrites {
            share: 1.0,
            bits: 64,
            colour_read_bits: 0,
            first_ready: -2.0,
            pace: 1.0,
        };
        let formulas = O2Formulas::new(&unshared_o2(), 640, 480);
        let port = |free: f64| PortOrder::free_from(free, &formulas, 0.0);
        let followed = |writes: LastWrites| {
            let mut head = Head::new(13.0, 0.0, 1, port(0.0), writes);
            for k in 0..16 {
                head.follow(4.0 + k as f64, k < 4);
            }
            head.latency(16).0
        };
        assert_eq!(followed(writes), 16.0);
        assert_eq!(followed(LastWrites::default()), 13.0);
        // A port still 20 cycles behind at the token: every write and read after it.
        let mut head = Head::new(13.0, 0.0, 1, port(20.0), writes);
        head.follow(4.0, true);
        // W0 in 20, R0 in 21, then W1..W4 packed in 22, ..., W13..W15 in 25.
        assert_eq!(head.latency(16).0, 25.0 + 2.0);
    }

    /// The query above (latency 13), then the next window's primitive (setup 4) and its
    /// fragments right after the end token, `L` = 16 of them holding the records back:
    /// - reads at fragments 0, 8 and 10 of 20: fragment 10 is emitted in cycle 4 + 10 after
    ///   the token and leaves in 15, its read is asked for and granted in 15, the record
    ///   word in 16: latency 15 + 1 + 1 = 17, known once fragment 15 passed;
    /// - reads at fragments 3 and 17: fragment 17 comes after the 16, so 4 + 3 + 1 + 1 + 1
    ///   = 10 < 13: the query keeps 13;
    /// - a wait after 5 fragments reading at 2 and 4 drains the pipe: 4 + 4 + 1 + 1 + 1 = 11
    ///   < 13, so 13.
    #[test]
    fn a_querys_records_wait_for_the_reads_of_the_next_l_fragments() {
        let state = RenderState::new(640, 480);
        let followed = |fragments: u64, first_reads: u64, close_after: bool| {
            let (mut formulas, spec, result) = counted_box();
            assert_eq!(formulas.end_query(&spec, &result, 0.0, 0.0).latency, 13.0);
            assert_eq!(formulas.take_followed(), None);
            formulas.primitive(0.0);
            let mut stretch = BOX;
            stretch.fragments = fragments;
            stretch.depth_reads = first_reads.count_ones() as u64;
            stretch.page_misses = 0;
            stretch.first_reads = first_reads;
            formulas.stretch(&stretch, &state);
            if close_after {
                formulas.close_head();
            }
            formulas.take_followed()
        };
        assert_eq!(followed(20, 1 | 1 << 8 | 1 << 10, false), Some(17.0));
        assert_eq!(followed(20, 1 << 3 | 1 << 17, false), Some(13.0));
        // Fewer than L fragments: the head stays open until the pipe drains.
        assert_eq!(followed(5, 1 << 2 | 1 << 4, false), None);
        assert_eq!(followed(5, 1 << 2 | 1 << 4, true), Some(13.0));
    }

    /// The box's query (its depth test 8 cycles behind the end token), then in the next
    /// window a primitive (setup 4) of 10 fragments drawn outside a query, each reading a
    /// new word (page hits) and writing depth and colour, with the token's window restarted:
    /// `d` = 8, the port through the box's reads long before. Worked by hand:
    /// - emitted by `g` = 4 + 10 = 14; port = 10 reads + max(ceil(10 · 64 / 256) = 3,
    ///   min(10, 10)) = 20 cycles; depth 10; OccU 10; prefetch 10 · 3 / 16 = 1.9;
    /// - the port takes the reads from their emission: through in max(0, 4) + 20 = 24, of
    ///   which the writes of the stretch's last 16 fragments (all 10: 640 bits, 3 cycles
    ///   packed) come after its last read, so that read's data comes in 24 - 3 + 2 = 23; the
    ///   depth test, from `b` = max(8, 4) = 8, would be through in 8 + 10 = 18: `d` = 23
    ///   (queued behind the backlog, as the formulas had it, 8 + 20 = 28; through only once
    ///   the port was, 26);
    /// - the stream ends: latency max(`d - g` + 3, the port through in 24 - 14) = 9 + 3 = 12
    ///   (17, then 15, before).
    #[test]
    fn the_port_takes_a_stretchs_reads_while_the_depth_test_works_off_its_backlog() {
        assert_eq!(drawn_after_the_box(DepthRead::PageHit), (14.0, 12.0));
    }

    /// The same, but the last fragment's read, the port's last, is a page miss (8 cycles):
    /// its data comes in 24 - 3 + 8 = 29 (the prefetch asked for it at its emission, in 14,
    /// and the port grants it after the other nine and the writes before it); `d` = 29,
    /// latency 29 - 14 + 3 = 18.
    /// (A page hit's latency after the port, as the formulas had it, gives 15 again: on the
    /// full 1280x1024 demo at 4 engines on o2 a brief query whose last primitive read every
    /// fragment and ended on a page miss took the machine 23 cycles and the formulas 17.)
    #[test]
    fn the_last_read_comes_its_own_latency_after_the_port_is_through() {
        assert_eq!(drawn_after_the_box(DepthRead::PageMiss), (14.0, 18.0));
    }

    /// The box's query, then 10 fragments drawn outside a query, each reading a new word,
    /// the last `last_read` (the others page hits): the stream's end's cycles and latency.
    fn drawn_after_the_box(last_read: DepthRead) -> (f64, f64) {
        let (mut formulas, spec, result) = counted_box();
        formulas.end_query(&spec, &result, 0.0, 0.0);
        formulas.primitive(0.0);
        let drawn = FragmentStretch {
            fragments: 10,
            depth_reads: 10,
            page_misses: (last_read == DepthRead::PageMiss) as u64,
            passed: 10,
            last_read,
            first_reads: 0,
            dense: DenseRuns::NONE,
            ending: DenseRuns::NONE,
            // All drawn: the port through them 10 cycles after the last, as it is already.
            drawn_tail: DrawnTail {
                fragments: 10,
                reads: 10,
            },
        };
        formulas.stretch(&drawn, &RenderState::new(640, 480));
        let end = formulas.finish().unwrap();
        (end.cycles, end.latency)
    }

    /// 100 fragments drawn outside a query, every one writing depth and colour (32 + 32
    /// bits), with 50 new words read, on a port no refresh or host shares. Packed, the
    /// writes fill 6,400 / 256 = 25 cycles; but each run of writes between two reads takes
    /// a cycle of its own, and 100 writes among 50 reads make 50 such runs: port = 50 reads
    /// + max(25, min(100, 50)) = 100 cycles (packing alone gave 75).
    #[test]
    fn writes_pack_to_the_ports_width_only_between_two_reads() {
        let formulas = O2Formulas::new(&unshared_o2(), 640, 480);
        let mut w = StretchCounts {
            fragments: 100,
            depth_reads: 50,
            depth_writes: 100,
            colour_writes: 100,
            ..StretchCounts::default()
        };
        assert_eq!(formulas.downstream(&w, 0.0, 0.0).port, 100.0);
        // With 10 reads the packed 25 cycles bind: 10 + 25.
        w.depth_reads = 10;
        assert_eq!(formulas.downstream(&w, 0.0, 0.0).port, 35.0);
    }

    /// The same 100 fragments under blending, 10 of them reading a new depth word: each
    /// drawn fragment's colour read (32 bits) is granted before its write (depth and colour,
    /// 64 bits), which is ready only the cycle after, so the write shares its cycle with the
    /// next fragment's colour read and no other: 100 cycles of writes, one a fragment. A
    /// depth read takes its cycle whole and strands the colour read after it in a cycle of
    /// its own: 10 more. Port = 10 reads + max(ceil(100 · 96 / 256) = 38,
    /// min(100, 10 + 100) + min(10, 100)) = 10 + 110 = 120 cycles (packing the colour
    /// reads with the writes gave 10 + 38 = 48). On the small hard cases on o2 at 4
    /// engines under blending the cycle level took 121,560 cycles and the formulas 88,579
    /// (27% short); with this, 0.11% off (0.32% since the depth test runs ahead of the last
    /// writes, whose latencies it brought to the machine's).
    #[test]
    fn under_blending_a_fragments_write_waits_for_its_colour_read() {
        let formulas = O2Formulas::new(&unshared_o2_with(&["blending=true"]), 640, 480);
        let w = StretchCounts {
            fragments: 100,
            depth_reads: 10,
            depth_writes: 100,
            colour_writes: 100,
            colour_reads: 100,
            ..StretchCounts::default()
        };
        assert_eq!(formulas.downstream(&w, 0.0, 0.0).port, 120.0);
    }
}
