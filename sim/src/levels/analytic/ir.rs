//! The InfiniteReality-like machine's closed-form bottleneck model ([`crate::machines::ir`] states the
//! machine's rules).
//!
//! Counts per window (`B` boards of `N` Image Engines; Image Engine `i = b · N + n`):
//!
//! | count | meaning |
//! |---|---|
//! | `F_bp` | fragments board `b`'s Fragment Generator emits in stretch `p` (its own pixels) |
//! | `P` | primitives (every board sets every one up) |
//! | `D_ip` | `Σ pace` over Image Engine `i`'s fragments of stretch `p`, `pace = max(C, s)`: the depth stage (`C` = `image_engine_cycles_per_fragment`, its initiation interval) and the OccU (`s` = cycles a fragment under the open query, [`super::service_cycles`]) are pipelined, so the slower paces the engine |
//! | `H_i` | hit words: over its passing fragments under a verbose query, the query's tiles holding each |
//!
//! The formulas follow the work stretch by stretch, as a fluid. A *stretch* is a band of a
//! primitive's rows ([`FragmentBand`]: at most [`BAND_ROWS`] rows, cut at every other
//! event, so where a query begins and its pace changes): under the columns interleave,
//! what an Image Engine is given in it is what its columns hold, so a stretch is counted
//! by column (each pixel's owner looked up under the others). A trace's band index holds
//! the bands, so the formulas count them without the fragments. Each board's Fragment Generator has a clock `g_b`, each Image Engine the cycle
//! `d_i` its depth stage is through the work it was given, both carried from stretch to
//! stretch. The generator emits an engine's fragment once the fragment `E` before it
//! (`E` = `image_engine_fifo_entries`) has left the FIFO into the depth stage, so a busy
//! engine holds its generator back only by the work beyond `H`: where the depth stage paces
//! the engine (`pace = C`), `H = (E + 1) · C - 1` cycles (its fragments in flight have left
//! the FIFO); where the OccU does (`s > C`), the depth stage holds its `ceil(L / C)` fragments
//! too (`L` = `image_engine_latency_cycles`), `H = Q · s` with `Q = E + ceil(L / C)`. (With
//! `Q · C` for both, the formulas had every depth-bound query's drain one fragment's pace
//! and a cycle long: 117 cycles where the machine's FIFO-full engines drain in 105 on the
//! city's hierarchical walk on ir2, the random triangles' cycles 2.7% short on ir4, now
//! 0.3% long.) Held back to an engine's last fragment, the generator still emits the `b_i`
//! fragments of its board that follow that one in the stretch. (Without them, a
//! full-viewport query of the hard cases on ir2, whose busiest engine owns the first column
//! of every row, sent its end token 14 cycles early and drained 12 cycles long: latency 160
//! against 148; on the small corpus the grid walks' worst mean latency error went from 3.5%
//! to 0.5%.) An engine still busy with one stretch's fragments takes the next one's after
//! them. At stretch `p`:
//!
//! ```text
//! start_b = max(g_b, r) + setup                   (at a primitive's first stretch: every board sets up every primitive,
//!                                                  no earlier than its release r from the window's start)
//! emit_b  = start_b + F_bp / rate                 (rate = fragment_generator_fragments_per_cycle)
//! d_i     = max(max(d_i, start_b) + D_ip, e_i + pace)   (each engine i of board b it touches;
//!                                                         e_i = emit_b - b_i / rate: its last fragment's
//!                                                         emission, taken as the last row's
//!                                                         first where that came earlier)
//! g_b     = max(emit_b, max_i (d_i - H + b_i / rate))
//! T_w     = max(ceil(max_b g_b), max_i H_i - Q · C)   (hit words drain one 32-bit word a cycle)
//! ```
//!
//! `T_w` counts from the window's start, the end token of the query before; the end token
//! enters when the last generator is through, but holds no board back: a board through
//! sooner takes the next window's work from its own clock, and its primitives from their
//! release by the host (the clocks count on from the first window, each window's start
//! an origin on them). An engine's work left past the window's end (`d_i - T_w`) is
//! carried into the next window, so a long query's backlog is neither lost nor counted
//! twice; where the host leaves the pipe idle before a window (a closed loop), the carried
//! work drains meanwhile. Under the blocks and morton interleaves a board's generator gives
//! an engine a block's share of a row at a time, and a FIFO shorter than that holds it
//! back within the row: there the fragments are followed one engine's run at a time in
//! the order they are emitted ([`IrWindow::close_blocks`]). The old per-primitive
//! maximum (`Σ_p max(generator_p, busiest engine_p - E · C)`) overlapped no primitive with
//! the next and hid only `E · C` of an OccU-bound engine's work: on a lazy-grid walk of the
//! city on ir4, with queries of a hundred tiles and more, it predicted 40% more cycles than
//! the machine (now 2.3% more). Cutting primitives into stretches follows their rows' uneven
//! load (random triangles on ir2: 8.3% fewer cycles than the machine as whole primitives,
//! 2.5% in stretches of 64 fragments). Counted by rows, a stretch costs its columns, not its
//! fragments: the IR's analytic level on the demo on ir4 went from 203 to 112 ms in
//! process decoding the fragments (a band no wider than the units closed in one pass, 96
//! ms; from the band index, 56 ms; its columns closed as vectors, 24 ms; since, in one
//! process, 15.6 ms, and 9.5 in bands of 16 rows read as row bands). Where in a stretch an engine's last fragment
//! came is known only in the last row (a row is one run: a column there has its board's
//! columns right of it after it); an engine whose columns end higher up is taken to be
//! through a pace after the last row's first fragment of its board, a little late.
//!
//! Latency: the end token enters in `t_end` (the predicted cycle the window ends). Image
//! Engine `i`'s partial report is ready in `r_i = t_end + 3 + backlog_i` (3: through its
//! depth stage, its OccU and the report; the machine's idle path), with `backlog_i` the
//! cycles its last fragment's result still needs past `t_end + 3`: `d_i - pace + L + s + 1`
//! (its last fragment entered the depth stage in `d_i - pace`, its result reaches the OccU
//! `L` later, which counts it for `s` cycles and reports the cycle after), less the cycles
//! the token came after the generators were done (in a closed loop whose host releases it
//! late). The two merge stages then run on the
//! `r_i` exactly as the machine runs them, moving the same words (8 a tile from every Image
//! Engine; [`crate::blocks::merge_network::merged_ready`], then the DMA to host memory; the
//! links, the DMA and the host of software merges carried from query to query, a
//! [`crate::blocks::merge_network::MergeState`] as the machine's), and latency = available −
//! `t_end`. A verbose query's hits are counted per Image Engine and tile, each within the
//! tile buffer's room as the machine's Occlusion Unit sends them, and merged within it.
//! (Uncapped, one bucket an engine, the demo at 1280x1024 on ir1 had a verbose query whose
//! buffers overflow predicted a latency of 9,842 cycles where the machine takes 1,554.)

use super::{service_cycles, WindowEnd};
use crate::arch::{Interleave, IrArch};
use crate::blocks::interleave::FramebufferInterleave;
use crate::blocks::merge_network::{MergeState, Partial, ReportShape};
use crate::blocks::occlusion_engine::hit_room;
use crate::error::SimError;
use crate::machines::ir::check_tile_registers;
use occsim_traces::golden::FunctionalModel;
use occsim_traces::trace::{FragmentBand, RowRun};
#[cfg(doc)]
use occsim_traces::trace::{BAND_ROWS, BAND_RUNS};
use occsim_traces::{Fragment, QueryMode, QueryShape, QuerySpec, Rect, Span};
use std::ops::Range;

/// Counts and clocks of one window (see the module docs). Clocks count in slots of
/// `1 / rate` cycles, so that a Fragment Generator's emission is exact whatever the number
/// of fragments a stretch gives it.
#[derive(Clone, Debug)]
pub struct IrWindow {
    pub primitives: u64,
    /// Fragments over the window.
    pub fragments: u64,
    /// `H_i`.
    pub hit_words: Vec<u64>,
    /// Slots a cycle: `fragment_generator_fragments_per_cycle`.
    rate: u64,
    /// `setup`, in slots.
    setup: u64,
    /// `Q`.
    queued: u64,
    /// `E` and `C`.
    fifo: u64,
    interval: u64,
    /// Where the window starts on the clocks below, in slots (every clock counts from the
    /// first window's start, so that a board through before the window starts keeps its
    /// lead).
    origin: u64,
    /// `g_b`: each board's Fragment Generator clock, in slots, after the stretches closed
    /// so far.
    generators: [u64; MAX_BOARDS],
    /// The generators' clocks as the last primitive began or the last window ended, where
    /// reading the fragments and reading a band index agree (a band index closes a band
    /// at once, the fragments a row at a time).
    settled: [u64; MAX_BOARDS],
    /// `B`: boards (the generators' clocks past them stay 0).
    boards: usize,
    /// `d_i`: each Image Engine's clock, in slots: the cycle its depth stage is through the
    /// work it was given; numbered as its dealer numbers the engines
    /// ([`Dealer::index_of_engine`]).
    through: Vec<u64>,
    /// Each Image Engine's share of the current stretch, where it is dealt first (numbered
    /// as `through`).
    shares: Vec<EngineShare>,
    /// The pace of the last fragment counted (`max(C, s)`), in cycles.
    pace: u64,
    /// The current stretch: its fragments, then (as it closes) its `F_bp` and its last
    /// row's fragments on each board.
    band: FragmentBand,
    stretch_board_fragments: [u64; MAX_BOARDS],
    row_board_fragments: [u64; MAX_BOARDS],
    /// The Image Engines the stretch touched, a bit each (numbered as `through`: engine `e`
    /// is bit `e mod 64` of word `e / 64`).
    touched: Vec<u64>,
    /// `N`: Image Engines a board.
    per_board: usize,
    /// How a stretch's fragments are dealt to the Image Engines.
    dealer: Dealer,
    /// The current stretch starts a primitive (its setup counts).
    stretch_sets_up: bool,
}

/// How a stretch's fragments are given to their Image Engines ([`IrWindow::close_band`]).
#[derive(Clone, Debug)]
enum Dealer {
    /// Under the columns interleave (`x mod U` to unit `x mod U`), an engine's fragments
    /// are those of its columns: counted a column at a time, the engines numbered by unit
    /// (a stretch's columns are then a run of clocks).
    Columns(Columns),
    /// Under the columns interleave, each pixel's owner looked up: the interleave, and per
    /// unit its board and Image Engine (board-major, as they are numbered). Only where the
    /// vectors do not take the boards, which no machine the architecture check admits has
    /// (1, 2 or 4 boards): the columns path's tests take it as their reference.
    Owners(FramebufferInterleave, Vec<(usize, usize)>),
    /// Under the blocks and morton interleaves, a block's share of a row at a time, in the
    /// order its generator emits them ([`IrWindow::close_blocks`]).
    Blocks(Blocks),
}

/// The blocks and morton interleaves' dealer: the interleave, the owners as
/// [`Dealer::Owners`]'s, and per Image Engine (numbered as the clocks) the slots from its
/// busy run's first emission to its depth stage's start, 1 to `rate` (the stage takes a
/// fragment the cycle after the one it was emitted in; the clocks count from the emission).
#[derive(Clone, Debug)]
struct Blocks {
    interleave: FramebufferInterleave,
    owners: Vec<(usize, usize)>,
    lags: Vec<u64>,
}

impl Dealer {
    /// Where Image Engine `engine` of board `board` (`per_board` a board) is in the
    /// window's clocks: unit `g = e · B + b` for engine `e` of board `b` under the columns
    /// interleave, else `b · N + e` (board-major).
    fn index_of_engine(&self, board: usize, engine: usize, per_board: usize) -> usize {
        match self {
            Dealer::Columns(columns) => (engine << columns.board_shift) | board,
            Dealer::Owners(..) | Dealer::Blocks(..) => board * per_board + engine,
        }
    }
}

/// The columns interleave's shape, and room to count a stretch's fragments a column.
#[derive(Clone, Debug)]
struct Columns {
    /// `log2 B` (the machine has 1, 2 or 4 boards).
    board_shift: u32,
    /// A stretch's runs as steps: `+1` where a run begins, `-1` past its end (the
    /// viewport's width and a vector's, all zero between stretches).
    steps: Vec<i32>,
    /// A stretch's columns from a vector's start on, as [`close_lanes`] takes them: their
    /// heights (in slots), and room for their engines' clocks.
    heights: Vec<u64>,
    clocks: Vec<u64>,
    /// A wide stretch's columns summed into their units (whole vectors).
    unit_slots: Vec<u64>,
    unit_after: Vec<u64>,
}

/// One Image Engine's share of the current stretch.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct EngineShare {
    /// `D_ip`, in slots (non-zero only at `touched`).
    slots: u64,
    /// Its board's fragments in the stretch up to its last one: when that was emitted.
    last: u64,
}

impl IrWindow {
    /// The window of `arch` over a viewport `width` pixels wide.
    pub fn new(arch: &IrArch, width: u32) -> IrWindow {
        let engines = arch.image_engines();
        let rate = arch.fragment_generator_fragments_per_cycle.max(1) as u64;
        IrWindow {
            primitives: 0,
            fragments: 0,
            hit_words: vec![0; engines],
            rate,
            setup: arch.fragment_generator_setup_cycles * rate,
            queued: arch.image_engine_fifo_entries as u64 + arch.image_engine_in_flight() as u64,
            fifo: arch.image_engine_fifo_entries as u64,
            interval: arch.image_engine_cycles_per_fragment,
            origin: 0,
            generators: [0; MAX_BOARDS],
            settled: [0; MAX_BOARDS],
            boards: arch.boards,
            through: vec![0; engines],
            shares: vec![EngineShare::default(); engines],
            pace: arch.image_engine_cycles_per_fragment,
            band: FragmentBand::EMPTY,
            stretch_board_fragments: [0; MAX_BOARDS],
            row_board_fragments: [0; MAX_BOARDS],
            touched: vec![0; engines.div_ceil(64)],
            per_board: arch.image_engines_per_board,
            dealer: if arch.interleave == Interleave::Columns
                && arch.boards.is_power_of_two()
                && arch.boards <= MAX_BOARDS
            {
                Dealer::Columns(Columns {
                    board_shift: arch.boards.trailing_zeros(),
                    // A stretch's columns run from a vector's start (at most `LANES - 1`
                    // before its first) to a vector's end (as many past its last), and a
                    // narrow one spans at most `U` columns.
                    steps: vec![0; width as usize + LANES],
                    heights: vec![0; width as usize + LANES],
                    clocks: vec![0; engines + 2 * LANES],
                    unit_slots: vec![0; engines + LANES],
                    unit_after: vec![0; engines + LANES],
                })
            } else {
                let interleave = FramebufferInterleave::new(arch);
                let owners = owners_of_units(arch, &interleave);
                match arch.interleave {
                    Interleave::Columns => Dealer::Owners(interleave, owners),
                    Interleave::Blocks | Interleave::Morton => Dealer::Blocks(Blocks {
                        interleave,
                        owners,
                        lags: vec![rate; engines],
                    }),
                }
            },
            stretch_sets_up: false,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.primitives == 0 && self.fragments == 0
    }

    /// Start the next window at the end token's cycle `end` (from this window's start),
    /// each engine's work left past `end` carried. Each board takes up where its generator
    /// left off: the token enters the last board to be through, and holds no board back (a
    /// board through sooner emits the next window's fragments as they come, as the
    /// machine's rules have it; with every board started together at `end`, twenty queries
    /// of three random triangles each on ir4 under the blocks interleave, whose boards
    /// share a window's work unevenly, took 111,175 cycles where the machine takes 106,086).
    pub fn restart_at(&mut self, end: u64) {
        self.close_stretch();
        self.settled = self.generators;
        self.primitives = 0;
        self.fragments = 0;
        self.hit_words.fill(0);
        self.idle(end);
    }

    /// `cycles` pass before the window's work starts: the engines' carried work drains.
    pub fn idle(&mut self, cycles: u64) {
        self.origin += cycles * self.rate;
    }

    /// The current stretch's work joins the clocks (see the module docs), board by board:
    /// each engine it touched takes its share after the work before and no sooner than the
    /// stretch starts, and is through no sooner than a pace after its board's generator
    /// emitted its last fragment.
    fn close_stretch(&mut self) {
        if self.band.is_empty() {
            // Read from a band index, every stretch closes so: no band to move out (a
            // band is about 200 bytes, and a stretch closes at every primitive and event).
            self.close_band(&FragmentBand::EMPTY);
            return;
        }
        let band = std::mem::take(&mut self.band);
        self.close_band(&band);
    }

    /// [`Self::close_stretch`] with `band` its fragments.
    fn close_band(&mut self, band: &FragmentBand) {
        if band.is_empty() {
            // No engine is given work: the generators only set the primitive up (a
            // stretch closes at every event, most with no fragments since the last).
            if self.stretch_sets_up {
                for generator in &mut self.generators[..self.boards] {
                    *generator += self.setup;
                }
                self.stretch_sets_up = false;
            }
            return;
        }
        match self.dealer {
            Dealer::Columns(_) => self.close_columns(band),
            Dealer::Owners(..) => self.close_owners(band),
            Dealer::Blocks(..) => self.close_blocks(band),
        }
    }

    /// [`Self::close_band`] where each pixel's owner is looked up: the stretch dealt to
    /// its engines' shares, then each engine it touched closed.
    fn close_owners(&mut self, band: &FragmentBand) {
        self.deal_owners(band);
        let setup = if self.stretch_sets_up { self.setup } else { 0 };
        let pace = self.pace * self.rate;
        let hidden = self.hidden();
        let fragments = &self.stretch_board_fragments;
        let starts: [u64; MAX_BOARDS] = std::array::from_fn(|board| self.generators[board] + setup);
        // An engine's last fragment came no earlier than the last row's first of its board.
        let last_row_starts: [u64; MAX_BOARDS] =
            std::array::from_fn(|board| fragments[board] - self.row_board_fragments[board]);
        let mut latest = [0u64; MAX_BOARDS];
        for (word_index, word) in self.touched.iter_mut().enumerate() {
            let mut bits = std::mem::take(word);
            while bits != 0 {
                let index = word_index * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let board = index / self.per_board;
                let share = std::mem::take(&mut self.shares[index]);
                let clock = &mut self.through[index];
                let start = starts[board];
                let emitted = share.last.max(last_row_starts[board]);
                *clock = ((*clock).max(start) + share.slots).max(start + emitted + pace);
                // Its generator, held back until this engine's last fragment may enter the
                // FIFO, then emits the board's fragments after it.
                let behind = fragments[board] - emitted;
                latest[board] = latest[board].max(*clock + behind);
            }
        }
        for board in 0..self.boards {
            let generator = starts[board] + fragments[board];
            self.generators[board] = generator.max(latest[board].saturating_sub(hidden));
        }
        self.stretch_board_fragments = [0; MAX_BOARDS];
        self.row_board_fragments = [0; MAX_BOARDS];
        self.stretch_sets_up = false;
    }

    /// [`Self::close_stretch`] by columns, where the interleave deals columns: the same
    /// clocks as dealing first and then closing engine by engine where the last row is one
    /// run (a primitive's row is, but under a verbose query, whose passing and failing
    /// fragments make runs of their own: there each engine's last fragment is placed as if
    /// the last row were one run, from its extent, [`close_lanes`]). With the engines numbered
    /// by unit, a stretch no wider than the units is a run of clocks, one column each
    /// (copied out and back where the run passes the last unit); a wider one's columns are
    /// summed into their units first. Either way the engines are then closed as vectors
    /// ([`close_lanes`]). (Column by column, with the engines numbered board-major and a
    /// wide stretch dealt to them first: the demo's band index on ir4 in 31.0 ms against
    /// 23.9, the lazy-grid walk's 33.7 against 28.7, the city's hierarchical walk's 27.2
    /// against 20.5, best of 8 interleaved; before the narrow ones closed in one pass, 52
    /// ms on the lazy walk against 37.)
    fn close_columns(&mut self, band: &FragmentBand) {
        let hidden = self.hidden();
        let Dealer::Columns(columns) = &mut self.dealer else {
            return;
        };
        let Range { start: first, end } = band.columns();
        let units = self.through.len();
        let pace = self.pace * self.rate;
        // The columns from the vector holding the first on, to the vector holding the last.
        let from = first - first % LANES;
        let lanes = (end - from).next_multiple_of(LANES);
        let fragments = columns.heights_in_slots(band, from..from + lanes, pace);
        let mut last_row = [0; MAX_BOARDS];
        for run in band.last_row() {
            add_run_to_boards(&mut last_row, run, columns.board_shift);
        }
        let setup = if self.stretch_sets_up { self.setup } else { 0 };
        let starts: [u64; MAX_BOARDS] = std::array::from_fn(|board| self.generators[board] + setup);
        let terms = BoardTerms {
            board_shift: columns.board_shift,
            starts,
            paced_ends: std::array::from_fn(|board| starts[board] + fragments[board] + pace),
            last_row,
            from,
            row: extent(band.last_row()),
        };
        let heights = &columns.heights[..lanes];
        let latest = if end - first > units {
            columns.close_folded(from, lanes, &mut self.through, &terms)
        } else if from % units + lanes <= units {
            // The columns' engines in order, each once (a column without fragments leaves
            // its clock as it is).
            close_lanes::<false>(
                heights,
                &[],
                &mut self.through[from % units..][..lanes],
                &terms,
            )
        } else {
            let clocks = &mut columns.clocks[..lanes];
            copy_around(&self.through, from, clocks);
            let latest = close_lanes::<false>(heights, &[], clocks, &terms);
            let (columns, dest) = (first - from..end - from, &mut self.through);
            copy_back_around(&clocks[columns], first, dest);
            latest
        };
        for board in 0..self.boards {
            let generator = starts[board] + fragments[board];
            self.generators[board] = generator.max(latest[board].saturating_sub(hidden));
        }
        self.stretch_sets_up = false;
    }

    /// [`Self::close_band`] under the blocks and morton interleaves, where a board's
    /// generator gives an Image Engine a block's share of a row, fragment after fragment,
    /// so that a FIFO of fewer entries than that fills within the row and holds the
    /// generator back while the board's other engines wait for their fragments: the
    /// fragments are followed in the order each board emits them, a run to one engine at a
    /// time, as the machine's rules take them. Fragment `k` of engine `i` may be emitted once
    /// fragment `k - E` has left the FIFO, `E · P` slots before the engine is through fragment
    /// `k - 1`, less the slots `λ_i` from its busy run's first emission to its depth stage's
    /// start (`P` a fragment's pace; `H - P + 1 cycle` for `E · P` where the OccU paces the
    /// engine, `H` as [`Self::hidden`]). So with `h_i = E · P - λ_i`, a run of `r` fragments
    /// to engine `i` is emitted from `first = max(g, d_i - h_i)`, the engine is through it at
    /// `d_i' = max(d_i, first) + r · P`, and the generator is free from `max(first + r,
    /// d_i' - P - h_i + 1)`, the slot after its last fragment's emission: the fragments one
    /// by one, summed. (Dealt as a stretch, as under the columns interleave, the demo on ir4
    /// with the morton interleave and FIFOs of 2 entries took 16.1 M cycles where the
    /// machine takes 28.7 M: the stretch had every engine start at once, where the generator
    /// reaches a block's engine only when the block before it has let it go. Without `λ_i`,
    /// one more slot or one fewer each run: a 256x64 quad on ir1 with blocks 4 pixels wide
    /// and FIFOs of 2 entries took 52,429 or 48,408 cycles, where the machine takes 50,420.)
    fn close_blocks(&mut self, band: &FragmentBand) {
        let setup = if self.stretch_sets_up { self.setup } else { 0 };
        let (rate, pace) = (self.rate, self.pace * self.rate);
        // `E · P`, where the depth stage paces the engine.
        let queued = (self.hidden() + rate).saturating_sub(pace);
        let Dealer::Blocks(blocks) = &mut self.dealer else {
            return;
        };
        let mut generators: [u64; MAX_BOARDS] =
            std::array::from_fn(|board| self.generators[board] + setup);
        let (owners, lags, through) = (&blocks.owners, &mut blocks.lags, &mut self.through);
        for run in band.runs() {
            blocks.interleave.for_each_block_along(
                run.x,
                run.y,
                run.len as usize,
                |unit, count| {
                    let (board, engine) = owners[unit];
                    let generator = &mut generators[board];
                    let (through, lag) = (&mut through[engine], &mut lags[engine]);
                    let first = (*generator).max(through.saturating_sub(queued - *lag));
                    if *through <= first {
                        // Idle: a busy run starts.
                        *lag = rate - first % rate;
                    }
                    *through = (*through).max(first) + count * pace;
                    let last = (*through).saturating_sub(pace + queued - *lag);
                    *generator = (first + count).max(last + 1);
                },
            );
        }
        self.generators[..self.boards].copy_from_slice(&generators[..self.boards]);
        self.stretch_sets_up = false;
    }

    /// Deal `band`'s fragments to their boards and Image Engines, each pixel's owner
    /// looked up: each board's `F_bp` and its last row's fragments, each engine's slots and
    /// last, the engines touched.
    fn deal_owners(&mut self, band: &FragmentBand) {
        let Dealer::Owners(interleave, owners) = &self.dealer else {
            return;
        };
        let slots_a_fragment = self.pace * self.rate;
        let last_row_from = band.runs().len() - band.last_row().len();
        let (boards, rows) = (
            &mut self.stretch_board_fragments,
            &mut self.row_board_fragments,
        );
        for (k, run) in band.runs().iter().enumerate() {
            interleave.for_each_unit_along(run.x, run.y, run.len as usize, |unit| {
                let (board, engine) = owners[unit];
                boards[board] += 1;
                rows[board] += (k >= last_row_from) as u64;
                self.touched[engine / 64] |= 1 << (engine % 64);
                self.shares[engine].slots += slots_a_fragment;
                self.shares[engine].last = boards[board];
            });
        }
    }

    /// A new primitive, released `release` cycles after the window's start (before it where
    /// negative: a board through before the window starts may set it up from its release):
    /// the current stretch's work joins the clocks, and no Fragment Generator sets the
    /// primitive up before its release.
    pub fn primitive(&mut self, release: f64) {
        self.close_stretch();
        self.settled = self.generators;
        let release = (self.origin as f64 + (release * self.rate as f64).ceil()).max(0.0) as u64;
        for generator in &mut self.generators[..self.boards] {
            *generator = (*generator).max(release);
        }
        self.primitives += 1;
        self.stretch_sets_up = true;
    }

    /// The fragments that follow are paced at `pace` cycles (`max(C, s)`).
    #[inline]
    pub fn pace(&mut self, pace: u64) {
        if pace != self.pace {
            // A query began: what came before was paced at the old rate.
            self.close_stretch();
            self.pace = pace;
        }
    }

    /// The fragments of pixels `x..x + len` of row `y` (inside the viewport), at the pace
    /// set: they join the current stretch, which closes first where its band would not
    /// admit them ([`FragmentBand::admits`]: past [`BAND_ROWS`] rows or [`BAND_RUNS`] runs).
    pub fn paced_along(&mut self, (x, y): (u16, u16), len: usize) {
        self.paced_run(RowRun::at(x, y, len as u32));
    }

    /// [`Self::paced_along`] for a run that may pass (under a verbose query).
    pub fn paced_run(&mut self, run: RowRun) {
        if run.len == 0 {
            return;
        }
        if !self.band.admits_run(&run) {
            self.close_stretch();
        }
        self.band.push_run(run);
        self.fragments += run.len as u64;
    }

    /// A band of a trace's band index, at the pace set: one stretch, closed (after any
    /// stretch of runs before it: a model reads a trace one way, so there is none).
    pub fn band(&mut self, band: &FragmentBand) {
        if !self.band.is_empty() {
            self.close_stretch();
        }
        self.fragments += band.fragments();
        self.close_band(band);
    }

    /// Slots a Fragment Generator may run ahead of an engine's work at the current pace (see
    /// the module docs): `(E + 1) · C - 1` cycles where the depth stage paces the engine,
    /// `Q · s` where its OccU does.
    fn hidden(&self) -> u64 {
        let pace = self.pace * self.rate;
        if self.pace > self.interval {
            self.queued * pace
        } else {
            (self.fifo + 1) * pace - self.rate
        }
    }

    /// Each Image Engine's clock (`d_i`), board-major.
    #[cfg(test)]
    fn engine_clocks(&self) -> impl Iterator<Item = u64> + '_ {
        (0..self.boards).flat_map(|board| self.board_clocks(board))
    }

    /// Board `board`'s Image Engines' clocks, in order: evenly spaced as
    /// [`Dealer::index_of_engine`] numbers them (every `B`-th under the columns
    /// interleave, else a run).
    fn board_clocks(&self, board: usize) -> impl Iterator<Item = u64> + '_ {
        let index = |engine| self.dealer.index_of_engine(board, engine, self.per_board);
        let (first, stride) = (index(0), index(1) - index(0));
        self.through[first..]
            .iter()
            .step_by(stride)
            .take(self.per_board)
            .map(|&through| through.saturating_sub(self.origin))
    }

    /// The cycles each board's Fragment Generator was through its work before the last
    /// board's, as the last primitive began or the last window ended: under the blocks and
    /// morton interleaves, where the formulas follow each board fragment by fragment. None
    /// under the columns interleave, where a stretch's close takes each board's holdback
    /// approximately and the boards' clocks drift apart by hundreds of cycles (the sampled
    /// level's machines, started that far apart, measured the demo's windows at 1280x1024
    /// on ir4 4.18% short at sampled:10; started level, 0.16%).
    pub fn board_leads(&self) -> Vec<u64> {
        if !matches!(self.dealer, Dealer::Blocks(_)) {
            return Vec::new();
        }
        let generators = &self.settled[..self.boards];
        let last = generators.iter().copied().max().unwrap_or(0);
        generators
            .iter()
            .map(|&generator| (last - generator) / self.rate)
            .collect()
    }

    /// `T_w`: the window's cycles, the current stretch's work included.
    pub fn cycles(&mut self, arch: &IrArch) -> u64 {
        self.close_stretch();
        let generators = self.generators[..self.boards]
            .iter()
            .copied()
            .max()
            .unwrap_or(0);
        let hits = self.hit_words.iter().copied().max().unwrap_or(0);
        let hidden = self.queued * arch.image_engine_cycles_per_fragment;
        generators
            .saturating_sub(self.origin)
            .div_ceil(self.rate)
            .max(hits.saturating_sub(hidden))
    }

    /// Per Image Engine (board-major), the cycles after `t_end + 3` until its partial
    /// report is ready (see the module docs), for a query of `service` OccU cycles a
    /// fragment: each given to `each`, board by board. (As an iterator chained over the
    /// engines, the demo's query ends on ir4 took 31.7 M instructions of the analytic
    /// level's 262 M; so, 24.6 M.)
    fn for_each_backlog(&self, arch: &IrArch, end: u64, service: u64, mut each: impl FnMut(u64)) {
        let tail = arch.image_engine_latency_cycles + service + 1;
        for board in 0..self.boards {
            let hit_words = &self.hit_words[board * self.per_board..][..self.per_board];
            for (through, &hits) in self.board_clocks(board).zip(hit_words) {
                // An engine given no work (or none left past the last window) has no last
                // fragment to wait for.
                let last_result = if through == 0 {
                    0
                } else {
                    (through.div_ceil(self.rate) + tail).saturating_sub(self.pace)
                };
                let hits_drained = hits + 1;
                each(last_result.max(hits_drained).saturating_sub(end + 3));
            }
        }
    }
}

/// The columns `runs` span, `first..end` (`0..0` for none).
fn extent(runs: &[RowRun]) -> (usize, usize) {
    let first = runs.iter().map(|run| run.x as usize).min().unwrap_or(0);
    let end = runs
        .iter()
        .map(|run| run.x as usize + run.len as usize)
        .max();
    (first, end.unwrap_or(0))
}

/// Step `runs` into `steps`: `+1` at each one's first column, `-1` past its last, so that
/// the sum along the columns is each column's fragments.
fn step_runs(steps: &mut [i32], runs: &[RowRun]) {
    for run in runs {
        steps[run.x as usize] += 1;
        steps[run.x as usize + run.len as usize] -= 1;
    }
}

/// Add a run's fragments to its boards' counts: under the columns interleave pixel `x` is
/// board `x mod B`'s, so each board has `len / B` of them, and the `len mod B` boards from
/// the first pixel's on one more.
fn add_run_to_boards(boards: &mut [u64; MAX_BOARDS], run: &RowRun, shift: u32) {
    let (len, b) = (run.len as usize, 1 << shift);
    for step in 0..b {
        let board = (run.x as usize + step) % b;
        boards[board] += (len / b + usize::from(step < len % b)) as u64;
    }
}

impl Columns {
    /// Close a stretch wider than the units (its `lanes` columns from `from` summed
    /// already, [`Self::heights_in_slots`]): each unit's columns summed into its share, its
    /// last fragment the latest of theirs (the last row's, `terms.row`), then every unit's
    /// clock in `through` closed as [`close_lanes`] closes them, whose per-board latest it
    /// returns.
    fn close_folded(
        &mut self,
        from: usize,
        lanes: usize,
        through: &mut [u64],
        terms: &BoardTerms,
    ) -> [u64; MAX_BOARDS] {
        let units = through.len();
        // Whole vectors: the lanes past the last unit have no work.
        let padded = units.next_multiple_of(LANES);
        let (slots, after) = (
            &mut self.unit_slots[..padded],
            &mut self.unit_after[..padded],
        );
        slots.fill(0);
        after.fill(u64::MAX);
        for (unit, columns) in runs_of_units(from..from + lanes, units) {
            let heights = &self.heights[columns.start - from..columns.end - from];
            for (slots, height) in slots[unit..].iter_mut().zip(heights) {
                *slots += height;
            }
        }
        let (row_first, row_end) = terms.row;
        for (unit, columns) in runs_of_units(row_first..row_end, units) {
            let heights = &self.heights[columns.start - from..columns.end - from];
            for ((after, &height), x) in after[unit..].iter_mut().zip(heights).zip(columns) {
                if height != 0 {
                    *after = (*after).min(((row_end - 1 - x) >> terms.board_shift) as u64);
                }
            }
        }
        let clocks = &mut self.clocks[..padded];
        clocks[..units].copy_from_slice(through);
        let latest = close_lanes::<true>(slots, after, clocks, terms);
        through.copy_from_slice(&clocks[..units]);
        latest
    }

    /// Step `band`'s runs and sum them along `columns` (from a multiple of `B` to one,
    /// holding every run): each column's height in slots (`pace` a fragment) into
    /// `heights` (from its start), `steps` left all zero. Returns each board's fragments.
    fn heights_in_slots(
        &mut self,
        band: &FragmentBand,
        columns: Range<usize>,
        pace: u64,
    ) -> [u64; MAX_BOARDS] {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") && pace < 1 << 32 {
            // SAFETY: the processor has AVX2 (just checked), all the function needs.
            return unsafe { self.heights_in_slots_avx2(band, columns, pace) };
        }
        match self.board_shift {
            0 => self.heights_in_slots_of::<1>(band, columns, pace),
            1 => self.heights_in_slots_of::<2>(band, columns, pace),
            _ => self.heights_in_slots_of::<4>(band, columns, pace),
        }
    }

    /// [`Self::heights_in_slots`] eight columns at a time ([`avx2::heights_in_slots`]; `pace`
    /// below `2^32`). (Column by column, the demo's band index on ir4 took 293 M
    /// instructions, 281 M so.)
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn heights_in_slots_avx2(
        &mut self,
        band: &FragmentBand,
        columns: Range<usize>,
        pace: u64,
    ) -> [u64; MAX_BOARDS] {
        step_runs(&mut self.steps, band.runs());
        // The last run's end may be the columns' (its step is not summed).
        self.steps[columns.end] = 0;
        let heights = &mut self.heights[..columns.len()];
        let boards = (1 << self.board_shift) - 1;
        // SAFETY: this function runs only where the processor has AVX2.
        unsafe { avx2::heights_in_slots(&mut self.steps[columns], heights, pace, boards) }
    }

    /// [`Self::heights_in_slots`] over `B` boards, a group of `B` columns (one a board) at
    /// a time, so that each board's count stays in a register.
    #[inline(always)]
    fn heights_in_slots_of<const B: usize>(
        &mut self,
        band: &FragmentBand,
        columns: Range<usize>,
        pace: u64,
    ) -> [u64; MAX_BOARDS] {
        step_runs(&mut self.steps, band.runs());
        // The last run's end may be the columns' (its step is not summed).
        self.steps[columns.end] = 0;
        let steps = &mut self.steps[columns.clone()];
        let heights = &mut self.heights[..columns.len()];
        let mut fragments = [0u64; MAX_BOARDS];
        let mut height = 0i32;
        for (steps, heights) in steps.chunks_exact_mut(B).zip(heights.chunks_exact_mut(B)) {
            for board in 0..B {
                height += std::mem::take(&mut steps[board]);
                heights[board] = height as u64 * pace;
                fragments[board] += height as u64;
            }
        }
        fragments
    }
}

/// Lanes of [`close_lanes`]' vectors (a multiple of every `B`).
const LANES: usize = 8;

/// What [`close_lanes`] needs of a stretch, in slots: each board's start, a pace after
/// its last fragment's emission (`start + F_bp + pace`) and its last row's fragments; the
/// column of its first lane (a multiple of [`LANES`]) and its last row's columns.
struct BoardTerms {
    board_shift: u32,
    starts: [u64; MAX_BOARDS],
    paced_ends: [u64; MAX_BOARDS],
    last_row: [u64; MAX_BOARDS],
    from: usize,
    row: (usize, usize),
}

/// Close a stretch's engines, lane by lane (lane `k` an engine of board `k mod B`, a whole
/// number of vectors): each engine with work (`slots`, 0 for none) takes it after its work
/// before and no sooner than its board's start, and is through no sooner than a pace after
/// its last fragment's emission, the last row's first of its board where it came earlier.
/// Where its last fragment came is `after` (its board's fragments after it, `u64::MAX`
/// for before the last row) where `FOLDED` (an engine a lane), else the lanes are the
/// columns from `terms.from`, one each, and a column in the last row has its board's
/// columns right of it there after it, `(row_end - 1 - x) / B` (a primitive's row is one
/// run). Returns, per board, the latest of its engines' clocks each with its board's
/// fragments after its last (`d_i + b_i`, 0 for none): how far its generator is held back,
/// but `H`. In AVX2 vectors where the processor has them: the same integers.
fn close_lanes<const FOLDED: bool>(
    slots: &[u64],
    after: &[u64],
    clocks: &mut [u64],
    terms: &BoardTerms,
) -> [u64; MAX_BOARDS] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx512f") {
        // SAFETY: the processor has AVX-512F (just checked), all the function needs.
        return unsafe { avx512::close_lanes::<FOLDED>(slots, after, clocks, terms) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2 (just checked), all the function needs.
        return unsafe { avx2::close_lanes::<FOLDED>(slots, after, clocks, terms) };
    }
    close_lanes_of::<FOLDED>(slots, after, clocks, terms)
}

/// [`close_lanes`] in AVX-512 vectors: a vector is [`LANES`] lanes, and the 64-bit
/// maxima, minima and lane choices AVX2 builds from comparisons are single instructions.
#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{BoardTerms, LANES, MAX_BOARDS};
    use std::arch::x86_64::*;

    /// [`super::close_lanes_of`] a vector of eight lanes at a time (unsigned lanes, as the
    /// plain loop's: an unknown `after`, `u64::MAX`, is past any last row).
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn close_lanes<const FOLDED: bool>(
        slots: &[u64],
        after: &[u64],
        clocks: &mut [u64],
        terms: &BoardTerms,
    ) -> [u64; MAX_BOARDS] {
        let boards = (1 << terms.board_shift) - 1;
        // Every vector starts at a multiple of 8, so lane k is board k mod B in each.
        let in_order = _mm512_setr_epi64(0, 1, 2, 3, 4, 5, 6, 7);
        let board_of_lane = _mm512_and_si512(in_order, _mm512_set1_epi64(boards as i64));
        let of_lane = |terms: &[u64; MAX_BOARDS]| {
            // SAFETY: four u64s.
            let terms = unsafe { _mm256_loadu_si256(terms.as_ptr().cast()) };
            _mm512_permutexvar_epi64(board_of_lane, _mm512_castsi256_si512(terms))
        };
        let (starts, paced_ends, last_row) = (
            of_lane(&terms.starts),
            of_lane(&terms.paced_ends),
            of_lane(&terms.last_row),
        );
        let row_first = _mm512_set1_epi64(terms.row.0 as i64);
        let row_end = _mm512_set1_epi64(terms.row.1 as i64);
        let row_last = _mm512_set1_epi64(terms.row.1 as i64 - 1);
        let shift = _mm_cvtsi32_si128(terms.board_shift as i32);
        let unknown = _mm512_set1_epi64(-1);
        let zero = _mm512_setzero_si512();
        let step = _mm512_set1_epi64(LANES as i64);
        let from = terms.from as i64;
        let mut x = _mm512_add_epi64(_mm512_set1_epi64(from), in_order);
        let mut latest = zero;
        debug_assert!(slots.len() == clocks.len() && slots.len().is_multiple_of(LANES));
        debug_assert!(!FOLDED || after.len() == clocks.len());
        for (chunk, clocks) in clocks.chunks_exact_mut(LANES).enumerate() {
            let lanes = chunk * LANES..chunk * LANES + LANES;
            // SAFETY: every chunk is eight u64s in bounds; unaligned loads and stores.
            let (share, clock) = unsafe {
                (
                    _mm512_loadu_si512(slots[lanes.clone()].as_ptr().cast()),
                    _mm512_loadu_si512(clocks.as_ptr().cast()),
                )
            };
            let after = match FOLDED {
                // SAFETY: as above.
                true => unsafe { _mm512_loadu_si512(after[lanes].as_ptr().cast()) },
                false => {
                    let in_row =
                        _mm512_cmpge_epi64_mask(x, row_first) & _mm512_cmplt_epi64_mask(x, row_end);
                    let after = _mm512_srl_epi64(_mm512_sub_epi64(row_last, x), shift);
                    _mm512_mask_blend_epi64(in_row, unknown, after)
                }
            };
            let behind = _mm512_min_epu64(after, last_row);
            let emitted = _mm512_sub_epi64(paced_ends, behind);
            let done = _mm512_max_epu64(
                _mm512_add_epi64(_mm512_max_epu64(starts, clock), share),
                emitted,
            );
            let touched = _mm512_test_epi64_mask(share, share);
            let clock = _mm512_mask_blend_epi64(touched, clock, done);
            // SAFETY: as the loads.
            unsafe { _mm512_storeu_si512(clocks.as_mut_ptr().cast(), clock) };
            let holds = _mm512_add_epi64(done, behind);
            latest = _mm512_mask_max_epu64(latest, touched, latest, holds);
            x = _mm512_add_epi64(x, step);
        }
        // Each board's latest: the lanes folded in halves down to one a board (lane k of
        // the half is board k's), the lanes past the boards 0.
        let mut width = LANES;
        while width > boards + 1 {
            width /= 2;
            let half = _mm512_set1_epi64(width as i64);
            let other = _mm512_permutexvar_epi64(_mm512_xor_si512(in_order, half), latest);
            latest = _mm512_max_epu64(latest, other);
        }
        let mut boards_latest = [0u64; MAX_BOARDS];
        let latest = _mm512_maskz_mov_epi64((1 << (boards + 1)) - 1, latest);
        // SAFETY: four u64s.
        unsafe {
            _mm256_storeu_si256(
                boards_latest.as_mut_ptr().cast(),
                _mm512_castsi512_si256(latest),
            )
        };
        boards_latest
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{BoardTerms, LANES, MAX_BOARDS};
    use std::arch::x86_64::*;

    /// The larger of each lane's signed 64-bit integers (AVX2 has no instruction for it).
    #[inline(always)]
    unsafe fn max(a: __m256i, b: __m256i) -> __m256i {
        _mm256_blendv_epi8(b, a, _mm256_cmpgt_epi64(a, b))
    }

    /// [`super::Columns::heights_in_slots`] eight columns at a time: `steps` (a whole number
    /// of vectors, from a multiple of `B`; left all zero) summed into each column's height,
    /// times `pace` (below `2^32`), into `heights`; each board's fragments (`boards` = `B -
    /// 1`: lane `k` is board `k & boards`'s). A column's height is at most a band's rows.
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn heights_in_slots(
        steps: &mut [i32],
        heights: &mut [u64],
        pace: u64,
        boards: usize,
    ) -> [u64; MAX_BOARDS] {
        debug_assert!(steps.len() == heights.len() && steps.len().is_multiple_of(LANES));
        let paces = _mm256_set1_epi64x(pace as i64);
        let zero = _mm256_setzero_si256();
        let last = _mm256_set1_epi32(LANES as i32 - 1);
        // The height before the vector, in every lane; each lane's heights summed.
        let (mut before, mut sums) = (zero, zero);
        for (steps, heights) in steps
            .chunks_exact_mut(LANES)
            .zip(heights.chunks_exact_mut(LANES))
        {
            // SAFETY: eight i32s and eight u64s in bounds; unaligned loads and stores.
            let v = unsafe { _mm256_loadu_si256(steps.as_ptr().cast()) };
            unsafe { _mm256_storeu_si256(steps.as_mut_ptr().cast(), zero) };
            // Running sums within each half, then the low half's total into the high half.
            let v = _mm256_add_epi32(v, _mm256_slli_si256::<4>(v));
            let v = _mm256_add_epi32(v, _mm256_slli_si256::<8>(v));
            let low_total = _mm256_shuffle_epi32::<0xFF>(v);
            let v = _mm256_add_epi32(v, _mm256_permute2x128_si256::<0x08>(low_total, low_total));
            let height = _mm256_add_epi32(v, before);
            before = _mm256_permutevar8x32_epi32(height, last);
            sums = _mm256_add_epi32(sums, height);
            let low = _mm256_cvtepi32_epi64(_mm256_castsi256_si128(height));
            let high = _mm256_cvtepi32_epi64(_mm256_extracti128_si256::<1>(height));
            unsafe {
                _mm256_storeu_si256(heights.as_mut_ptr().cast(), _mm256_mul_epu32(low, paces));
                let high_heights = heights[4..].as_mut_ptr().cast();
                _mm256_storeu_si256(high_heights, _mm256_mul_epu32(high, paces));
            }
        }
        let mut lanes = [0i32; LANES];
        // SAFETY: eight i32s.
        unsafe { _mm256_storeu_si256(lanes.as_mut_ptr().cast(), sums) };
        let mut fragments = [0u64; MAX_BOARDS];
        for (lane, sum) in lanes.into_iter().enumerate() {
            fragments[lane & boards] += sum as u64;
        }
        fragments
    }

    /// [`super::close_lanes_of`] in vectors of four lanes (signed lanes: clocks stay far
    /// below `2^62` slots; an unknown `after`, `u64::MAX`, is negative).
    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn close_lanes<const FOLDED: bool>(
        slots: &[u64],
        after: &[u64],
        clocks: &mut [u64],
        terms: &BoardTerms,
    ) -> [u64; MAX_BOARDS] {
        const WIDTH: usize = 4;
        let boards = (1 << terms.board_shift) - 1;
        // Every vector starts at a multiple of 4, so lane k is board k mod B in each.
        let of_lane = |terms: &[u64; MAX_BOARDS]| {
            let lane = |k: usize| terms[k & boards] as i64;
            _mm256_setr_epi64x(lane(0), lane(1), lane(2), lane(3))
        };
        let (starts, paced_ends, last_row) = (
            of_lane(&terms.starts),
            of_lane(&terms.paced_ends),
            of_lane(&terms.last_row),
        );
        let row_before = _mm256_set1_epi64x(terms.row.0 as i64 - 1);
        let row_end = _mm256_set1_epi64x(terms.row.1 as i64);
        let row_last = _mm256_set1_epi64x(terms.row.1 as i64 - 1);
        let shift = _mm_cvtsi32_si128(terms.board_shift as i32);
        let unknown = _mm256_set1_epi64x(-1);
        let zero = _mm256_setzero_si256();
        let step = _mm256_set1_epi64x(WIDTH as i64);
        let from = terms.from as i64;
        let mut x = _mm256_setr_epi64x(from, from + 1, from + 2, from + 3);
        let mut latest = zero;
        debug_assert!(slots.len() == clocks.len() && slots.len().is_multiple_of(LANES));
        debug_assert!(!FOLDED || after.len() == clocks.len());
        for (chunk, clocks) in clocks.chunks_exact_mut(WIDTH).enumerate() {
            let lanes = chunk * WIDTH..chunk * WIDTH + WIDTH;
            // SAFETY: every chunk is four u64s in bounds; unaligned loads and stores.
            let (share, clock) = unsafe {
                (
                    _mm256_loadu_si256(slots[lanes.clone()].as_ptr().cast()),
                    _mm256_loadu_si256(clocks.as_ptr().cast()),
                )
            };
            let after = match FOLDED {
                // SAFETY: as above.
                true => unsafe { _mm256_loadu_si256(after[lanes].as_ptr().cast()) },
                false => {
                    let in_row = _mm256_and_si256(
                        _mm256_cmpgt_epi64(x, row_before),
                        _mm256_cmpgt_epi64(row_end, x),
                    );
                    let after = _mm256_srl_epi64(_mm256_sub_epi64(row_last, x), shift);
                    _mm256_blendv_epi8(unknown, after, in_row)
                }
            };
            // min(after, last row), an unknown one (negative) past any.
            let later = _mm256_or_si256(
                _mm256_cmpgt_epi64(after, last_row),
                _mm256_cmpgt_epi64(zero, after),
            );
            let behind = _mm256_blendv_epi8(after, last_row, later);
            let emitted = _mm256_sub_epi64(paced_ends, behind);
            let done = max(_mm256_add_epi64(max(starts, clock), share), emitted);
            let untouched = _mm256_cmpeq_epi64(share, zero);
            let clock = _mm256_blendv_epi8(done, clock, untouched);
            // SAFETY: as the loads.
            unsafe { _mm256_storeu_si256(clocks.as_mut_ptr().cast(), clock) };
            let holds = _mm256_add_epi64(done, behind);
            latest = max(latest, _mm256_andnot_si256(untouched, holds));
            x = _mm256_add_epi64(x, step);
        }
        let mut lanes = [0u64; WIDTH];
        // SAFETY: four u64s.
        unsafe { _mm256_storeu_si256(lanes.as_mut_ptr().cast(), latest) };
        let mut boards_latest = [0u64; MAX_BOARDS];
        for (lane, latest) in lanes.into_iter().enumerate() {
            boards_latest[lane & boards] = boards_latest[lane & boards].max(latest);
        }
        boards_latest
    }
}

/// [`close_lanes`]' loop, lane by lane.
fn close_lanes_of<const FOLDED: bool>(
    slots: &[u64],
    after: &[u64],
    clocks: &mut [u64],
    terms: &BoardTerms,
) -> [u64; MAX_BOARDS] {
    let boards = (1 << terms.board_shift) - 1;
    let (row_first, row_end) = terms.row;
    let mut latest = [0u64; MAX_BOARDS];
    for (lane, (&share, clock)) in slots.iter().zip(clocks).enumerate() {
        let board = lane & boards;
        let x = terms.from + lane;
        let after = match FOLDED {
            true => after[lane],
            false if (row_first..row_end).contains(&x) => {
                ((row_end - 1 - x) >> terms.board_shift) as u64
            }
            false => u64::MAX,
        };
        let behind = after.min(terms.last_row[board]);
        let emitted = terms.paced_ends[board] - behind;
        let done = (terms.starts[board].max(*clock) + share).max(emitted);
        if share != 0 {
            *clock = done;
            latest[board] = latest[board].max(done + behind);
        }
    }
    latest
}

/// `columns` as runs of consecutive units (column `x` is unit `x mod units`): each run's
/// first unit and its columns.
fn runs_of_units(
    columns: Range<usize>,
    units: usize,
) -> impl Iterator<Item = (usize, Range<usize>)> {
    let mut start = columns.start;
    std::iter::from_fn(move || {
        (start < columns.end).then(|| {
            let unit = start % units;
            let end = columns.end.min(start + units - unit);
            let run = (unit, start..end);
            start = end;
            run
        })
    })
}

/// Copy the clocks of columns `from..from + out.len()` out of `clocks` (one a unit, column
/// `x` unit `x mod units`) into `out`.
fn copy_around(clocks: &[u64], from: usize, out: &mut [u64]) {
    for (unit, columns) in runs_of_units(from..from + out.len(), clocks.len()) {
        let run = columns.start - from..columns.end - from;
        out[run.clone()].copy_from_slice(&clocks[unit..unit + run.len()]);
    }
}

/// Copy `values`, the clocks of columns `from..from + values.len()` (no more than the
/// units), back into `clocks`.
fn copy_back_around(values: &[u64], from: usize, clocks: &mut [u64]) {
    for (unit, columns) in runs_of_units(from..from + values.len(), clocks.len()) {
        let run = columns.start - from..columns.end - from;
        clocks[unit..unit + run.len()].copy_from_slice(&values[run]);
    }
}

/// Per interleave unit of `arch`, its board and its Image Engine (board-major).
fn owners_of_units(arch: &IrArch, interleave: &FramebufferInterleave) -> Vec<(usize, usize)> {
    (0..arch.image_engines())
        .map(|g| {
            let owner = interleave.owner_of_unit(g);
            (
                owner.board,
                owner.board * arch.image_engines_per_board + owner.image_engine,
            )
        })
        .collect()
}

/// Boards the formulas keep clocks for on the stack (the machine has 1, 2 or 4).
const MAX_BOARDS: usize = 4;

/// The open query, as the counts need it.
struct OpenQuery {
    /// `s`: OccU cycles per fragment.
    service: u64,
    /// A verbose query's tiles (hit words), else empty.
    verbose_tiles: Vec<Rect>,
    /// Hits a tile's buffer holds ([`hit_room`]).
    room: u64,
    /// Hits each Image Engine sent for each tile (engine-major), at most `room` each: an
    /// engine's Occlusion Unit sends a tile's hit while its buffer has room, as the
    /// machine's does ([`crate::blocks::occlusion_engine`]).
    hits_sent: Vec<u64>,
}

/// The IR model's per-window counting state.
pub(crate) struct IrBottleneck {
    arch: IrArch,
    interleave: FramebufferInterleave,
    /// Per interleave unit, its board and its Image Engine (board-major).
    owners: Vec<(usize, usize)>,
    window: IrWindow,
    open: Option<OpenQuery>,
    /// The merge stages' links and DMA, and the host of software merges, as the machine
    /// carries them from query to query.
    merges: MergeState,
    /// Room for each Image Engine's ready cycle at a query's end.
    ready: Vec<u64>,
}

impl IrBottleneck {
    /// The formulas of `arch` over a viewport `width` pixels wide.
    pub(super) fn new(arch: &IrArch, width: u32) -> IrBottleneck {
        let interleave = FramebufferInterleave::new(arch);
        let owners = owners_of_units(arch, &interleave);
        IrBottleneck {
            interleave,
            owners,
            window: IrWindow::new(arch, width),
            arch: arch.clone(),
            open: None,
            merges: MergeState::default(),
            ready: Vec::new(),
        }
    }

    pub(super) fn primitive(&mut self, release: f64) {
        self.window.primitive(release);
    }

    pub(super) fn board_leads(&self) -> Vec<u64> {
        self.window.board_leads()
    }

    pub(super) fn merges(&self) -> &MergeState {
        &self.merges
    }

    /// The query `spec` (event `index`) begins: refused past the tile registers, as the
    /// machine refuses it, before its verbose hits are given room in every Image Engine.
    pub(super) fn begin(&mut self, spec: &QuerySpec, index: u64) -> Result<(), SimError> {
        check_tile_registers(spec, self.arch.image_engines(), index)?;
        self.open = Some(OpenQuery {
            service: service_cycles(
                spec.tiles.len(),
                self.arch.occu.engines,
                self.arch.occu.all_tiles_one_cycle,
            ),
            verbose_tiles: match spec.mode {
                QueryMode::Verbose => spec.tiles.clone(),
                _ => Vec::new(),
            },
            room: hit_room(spec.buffer_entries),
            hits_sent: match spec.mode {
                QueryMode::Verbose => vec![0; self.arch.image_engines() * spec.tiles.len()],
                _ => Vec::new(),
            },
        });
        Ok(())
    }

    /// An Image Engine's cycles a fragment under the open query: `max(C, s)`.
    fn pace(&self) -> u64 {
        let service = self.open.as_ref().map_or(1, |q| q.service);
        service.max(self.arch.image_engine_cycles_per_fragment)
    }

    /// Count a span's work (before `functional` applies it): its fragments' Image Engines,
    /// each pixel's owner stepped along the row and looked up, not divided out; under a
    /// verbose query, each fragment's hit words too (its depth test against the buffer
    /// before the span: a span's pixels are distinct).
    pub(super) fn span(&mut self, span: Span, functional: &FunctionalModel) {
        let pace = self.pace();
        self.window.pace(pace);
        if !self.verbose_open() {
            self.window.paced_along((span.x, span.y), span.depths.len());
            return;
        }
        // Under a verbose query, the span as runs of fragments that pass their depth test
        // or fail it (against the buffer before the span: its pixels are distinct), as the
        // band index keeps them.
        let state = functional.state();
        let mut run = RowRun::at(span.x, span.y, 0);
        for fragment in span.fragments() {
            let stored = functional.depth_buffer().get(fragment.x, fragment.y);
            let passes = !state.depth_test || state.depth_func.passes(fragment.z, stored);
            if passes != run.passes && run.len > 0 {
                self.verbose_run(run);
                run = RowRun::at(fragment.x, span.y, 0);
            }
            run.passes = passes;
            run.len += 1;
        }
        self.verbose_run(run);
    }

    /// A verbose query is open.
    fn verbose_open(&self) -> bool {
        self.open
            .as_ref()
            .is_some_and(|query| !query.verbose_tiles.is_empty())
    }

    /// A run under a verbose query: its work, and its hits if it passes.
    fn verbose_run(&mut self, run: RowRun) {
        self.window.paced_run(run);
        if run.passes {
            self.count_hits(run);
        }
    }

    /// Count a band of a trace's band index: one stretch, and under a verbose query its
    /// passing runs' hits.
    pub(super) fn band(&mut self, band: &FragmentBand) {
        let pace = self.pace();
        self.window.pace(pace);
        self.window.band(band);
        if self.verbose_open() {
            for run in band.runs().iter().filter(|run| run.passes) {
                self.count_hits(*run);
            }
        }
    }

    /// An event other than a fragment comes: the stretch closes (as a band of the index
    /// ends at every such event).
    pub(super) fn close_stretch(&mut self) {
        self.window.close_stretch();
    }

    /// Count one fragment's work (before `functional` applies it): a span of one.
    #[inline]
    pub(super) fn fragment(&mut self, fragment: Fragment, functional: &FunctionalModel) {
        let depths = [fragment.z];
        self.span(
            Span {
                x: fragment.x,
                y: fragment.y,
                depths: &depths,
            },
            functional,
        );
    }

    /// A verbose query's hit words for a run of fragments that pass their depth test: one
    /// for each of the query's tiles that holds a fragment, while its Image Engine's buffer
    /// for the tile has room.
    fn count_hits(&mut self, run: RowRun) {
        let Some(query) = &mut self.open else {
            return;
        };
        let tiles = query.verbose_tiles.len();
        let (owners, hit_words) = (&self.owners, &mut self.window.hit_words);
        let y = run.y as u32;
        let mut x = run.x as u32;
        self.interleave
            .for_each_unit_along(run.x, run.y, run.len as usize, |unit| {
                let engine = owners[unit].1;
                let sent = &mut query.hits_sent[engine * tiles..(engine + 1) * tiles];
                for (tile, sent) in query.verbose_tiles.iter().zip(sent) {
                    if tile.contains(x, y) && *sent < query.room {
                        *sent += 1;
                        hit_words[engine] += 1;
                    }
                }
                x += 1;
            });
    }

    /// The query ended; the window that began in cycle `start` closes: its cycles and the
    /// query's latency.
    pub(super) fn end_query(&mut self, shape: &QueryShape, start: f64, release: f64) -> WindowEnd {
        let open = self.open.take();
        let service = open.as_ref().map_or(1, |q| q.service);
        let hits_sent = open.map_or(Vec::new(), |q| q.hits_sent);
        let cycles = self.window.cycles(&self.arch);
        let pipe_done = start + cycles as f64;
        // The end token enters at its release; the Image Engines have worked on through
        // what came after the generators were done, so their backlog is that much shorter.
        let late = (release - pipe_done).max(0.0).round() as u64;
        let end_cycle = pipe_done.max(release).round() as u64;
        let shape = ReportShape {
            tiles: shape.tiles as u64,
            room: match shape.mode {
                QueryMode::Verbose => hit_room(shape.buffer_entries),
                _ => u64::MAX,
            },
        };
        // Each Image Engine's partial report is ready (board-major).
        let mut ready = std::mem::take(&mut self.ready);
        ready.clear();
        self.window
            .for_each_backlog(&self.arch, cycles, service, |backlog| {
                ready.push(end_cycle + 3 + backlog.saturating_sub(late))
            });
        let merged = if hits_sent.is_empty() {
            Partial::brief(self.merged_brief(&mut ready, shape.tiles))
        } else {
            self.merged_with_hits(&ready, &hits_sent, shape)
        };
        self.ready = ready;
        let available = self.merges.deliver(
            &self.arch.global_merge_network(),
            &merged,
            shape,
            self.arch.report_dma_bits_per_cycle,
        );
        self.window.restart_at(cycles);
        let latency = (available - end_cycle) as f64;
        WindowEnd {
            cycles: cycles as f64,
            latency,
        }
    }

    /// The two merge stages' output for reports without hits, each Image Engine's ready in
    /// `ready` (board-major, overwritten).
    fn merged_brief(&mut self, ready: &mut [u64], tiles: u64) -> u64 {
        let local = self.arch.local_merge_network();
        let mut boards = [0; MAX_BOARDS];
        for (board, engines) in ready
            .chunks_mut(self.arch.image_engines_per_board)
            .enumerate()
        {
            boards[board] = self.merges.local_brief(&local, board, engines, tiles);
        }
        let global = self.arch.global_merge_network();
        self.merges
            .global_brief(&global, &mut boards[..self.arch.boards], tiles)
    }

    /// The two merge stages' output for a verbose query's reports: each Image Engine's
    /// ready in `ready` (board-major) with the hits it sent, `hits_sent` (a tile's each).
    fn merged_with_hits(
        &mut self,
        ready: &[u64],
        hits_sent: &[u64],
        shape: ReportShape,
    ) -> Partial {
        let tiles = shape.tiles as usize;
        let reports: Vec<Partial> = ready
            .iter()
            .enumerate()
            .map(|(engine, &ready)| Partial {
                ready,
                hits: hits_sent
                    .get(engine * tiles..(engine + 1) * tiles)
                    .map_or(Vec::new(), <[u64]>::to_vec),
            })
            .collect();
        let local = self.arch.local_merge_network();
        let board_reports: Vec<Partial> = reports
            .chunks(self.arch.image_engines_per_board)
            .enumerate()
            .map(|(board, reports)| self.merges.local(&local, board, reports, shape))
            .collect();
        self.merges
            .global(&self.arch.global_merge_network(), &board_reports, shape)
    }

    /// The pipe stood idle `cycles` before the window: the Image Engines worked through that
    /// much of the backlog carried into it.
    pub(super) fn idle(&mut self, cycles: f64) {
        self.window.idle(cycles.round() as u64);
    }

    /// Start the window again with no work (a frame ended inside it).
    pub(super) fn clear_window(&mut self) {
        let cycles = self.window.cycles(&self.arch);
        self.window.restart_at(cycles);
    }

    /// The stream ended after a window without a query end: its cycles and the slowest
    /// Image Engine's drain.
    pub(super) fn finish(&self) -> Option<WindowEnd> {
        if self.window.is_empty() {
            return None;
        }
        let mut window = self.window.clone();
        let cycles = window.cycles(&self.arch);
        let service = self.open.as_ref().map_or(1, |q| q.service);
        let mut slowest = 0;
        window.for_each_backlog(&self.arch, cycles, service, |backlog| {
            slowest = slowest.max(backlog)
        });
        let drain = 3 + slowest;
        Some(WindowEnd {
            cycles: cycles as f64,
            latency: drain as f64,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::Arch;
    use occsim_traces::rng::SplitMix64;

    /// An `ir` architecture with `boards` boards of `per_board` Image Engines and the
    /// columns interleave.
    fn columns_arch(boards: usize, per_board: usize) -> IrArch {
        let mut arch = Arch::builtin("ir").unwrap();
        arch.set_value("boards", &boards.to_string()).unwrap();
        arch.set_value("image_engines_per_board", &per_board.to_string())
            .unwrap();
        arch.ir().unwrap()
    }

    /// The dealer that looks each pixel's owner up, for `arch` (whose interleave deals
    /// columns: the window's own dealer counts them a column at a time).
    fn looked_up(arch: &IrArch) -> Dealer {
        let interleave = FramebufferInterleave::new(arch);
        let owners = owners_of_units(arch, &interleave);
        Dealer::Owners(interleave, owners)
    }

    /// A window of `arch` over a viewport `width` pixels wide with each dealer: by columns
    /// (`true`) and looking each owner up.
    fn both_dealers(arch: &IrArch, width: u32) -> [(bool, IrWindow); 2] {
        let by_columns = IrWindow::new(arch, width);
        let mut looking_up = by_columns.clone();
        looking_up.dealer = looked_up(arch);
        [(true, by_columns), (false, looking_up)]
    }

    #[test]
    fn an_engine_whose_last_fragment_came_before_the_last_row_is_timed_from_that_row() {
        // One board of two Image Engines (U = 2: column x to engine x mod 2), the ir
        // defaults: 2 fragments a cycle (a slot is half a cycle), setup 4 cycles = 8 slots,
        // C = 11 cycles = 22 slots a fragment. A primitive released at 0 starts at slot 8.
        // Row 0 has pixels 1 and 2 (fragments 1 and 2: engines 1 and 0), row 1 pixel 0
        // (fragment 3: engine 0); the last row starts after fragment 2.
        // Engine 1: one fragment, its last (fragment 1) before the last row, so counted at
        // fragment 2: through = max(8 + 22, 8 + 2 + 22) = 32 (31 if fragment 1 counted).
        // Engine 0: two fragments, its last fragment 3: max(8 + 44, 8 + 3 + 22) = 52.
        let arch = columns_arch(1, 2);
        for (by_columns, mut window) in both_dealers(&arch, 4) {
            window.primitive(0.0);
            window.paced_along((1, 0), 2);
            window.paced_along((0, 1), 1);
            window.close_stretch();
            assert_eq!(
                window.engine_clocks().collect::<Vec<_>>(),
                [52, 32],
                "by columns: {by_columns}"
            );
        }
    }

    #[test]
    fn a_primitive_without_fragments_still_takes_its_setup() {
        // Two boards, the ir defaults: setup 4 cycles = 8 slots (2 fragments a cycle).
        // Two primitives with no fragments, then one of a single fragment at pixel 0
        // (board 0): board 0's generator is through the setups at slot 24 and emits the
        // fragment in slot 25, 13 cycles (ceil(25 / 2)); with no setup for the empty
        // ones, 5 (ceil(9 / 2)). Its engine is through at 24 + 1 + 22 = 47 slots.
        let arch = columns_arch(2, 2);
        for (by_columns, mut window) in both_dealers(&arch, 4) {
            window.primitive(0.0);
            window.primitive(0.0);
            let mut band = FragmentBand::EMPTY;
            window.band(&band);
            window.primitive(0.0);
            band.push(0, 0, 1);
            window.band(&band);
            assert_eq!(window.cycles(&arch), 13, "by columns: {by_columns}");
            assert_eq!(
                window.engine_clocks().collect::<Vec<_>>(),
                [47, 0, 0, 0],
                "by columns: {by_columns}"
            );
        }
    }

    #[test]
    fn a_generator_held_by_a_backlogged_engine_still_emits_the_fragments_after_its_last() {
        // One board of eight Image Engines (U = 8: column x to engine x), 2 fragments a
        // cycle (a slot is half a cycle), setup 8 slots, C = 22 slots, a FIFO of E = 2:
        // the generator may run H = (E + 1) · C - 1 = 3 · 11 - 1 = 32 cycles (64 slots)
        // ahead of an engine's work. Rows 0 to 6 hold pixel 0 alone (engine 0), row 7 pixels 0 to 7
        // (one fragment an engine): 15 fragments, the primitive's setup from slot 0.
        // Engine 0: eight fragments, through at 8 + 8 · 22 = 184; its last fragment (the
        // last row's first) enters its FIFO no sooner than 184 - 64 = 120, and the 7
        // fragments after it leave the generator one a slot after it: 127 (held only to
        // engine 0's own last fragment, 120). Every other engine has one fragment, through
        // by 8 + 15 + 22 = 45 at the latest. The window: ceil(127 / 2) = 64 cycles.
        let mut arch = columns_arch(1, 8);
        arch.image_engine_fifo_entries = 2;
        for (by_columns, mut window) in both_dealers(&arch, 8) {
            window.primitive(0.0);
            for y in 0..7 {
                window.paced_along((0, y), 1);
            }
            window.paced_along((0, 7), 8);
            window.close_stretch();
            assert_eq!(window.generators[0], 127, "by columns: {by_columns}");
            assert_eq!(window.cycles(&arch), 64, "by columns: {by_columns}");
        }
    }

    #[test]
    fn under_the_blocks_interleave_a_full_fifo_holds_the_generator_within_the_row() {
        // One board of two Image Engines, blocks 4 pixels wide (pixels 0-3 to engine 0, 4-7
        // to engine 1), a FIFO of F = 2, 2 fragments a cycle (a slot is half a cycle),
        // setup 4 cycles, C = 11 cycles. One row of 8 pixels, the machine's rules by hand
        // (cycles; a fragment emitted in a may start its depth test in a + 1 and once
        // fragment k - F has started, s_k = max(a_k + 1, s_{k-1} + 11)):
        // engine 0: a = 4, 4 (two a cycle), then 5 (once s_0 = 5), then 16 (once s_1 = 16);
        // engine 1: a = 16 (the cycle's second), 17, 17, then 28 (once its s_1 = 28).
        // So the generator is free from slot 2 · 28 + 1 = 57 (the cycle's second slot) and
        // the end token enters in cycle 29.
        let mut arch = columns_arch(1, 2);
        arch.interleave = Interleave::Blocks;
        arch.block_width_pixels = 4;
        arch.image_engine_fifo_entries = 2;
        let mut window = IrWindow::new(&arch, 8);
        assert!(matches!(window.dealer, Dealer::Blocks(_)));
        window.primitive(0.0);
        window.paced_along((0, 0), 8);
        window.close_stretch();
        assert_eq!(window.generators[0], 57);
        assert_eq!(window.cycles(&arch), 29);
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn the_vector_close_gives_the_clocks_the_lane_by_lane_close_gives() {
        // Random stretches (work with gaps, clocks before and after the boards' starts,
        // last rows anywhere among the columns, or an engine's last fragment given, 1, 2
        // and 4 boards): the AVX2 close, the AVX-512 one where the processor has it and
        // the plain one must leave the same clocks and give the same latest, by columns
        // and by units alike.
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("skipped: this processor has no AVX2 (the plain close is the reference)");
            return;
        }
        let mut rng = SplitMix64(7);
        for case in 0..4_000 {
            let board_shift = rng.below(3) as u32;
            let lanes = LANES * (1 + rng.below(6) as usize);
            let from = LANES * rng.below(40) as usize;
            let slots: Vec<u64> = (0..lanes)
                .map(|_| [0, 0, 22, 44, 176, 600][rng.below(6) as usize])
                .collect();
            let after: Vec<u64> = (0..lanes)
                .map(|_| [u64::MAX, 0, 3, 50][rng.below(4) as usize])
                .collect();
            let clocks: Vec<u64> = (0..lanes).map(|_| rng.below(3_000)).collect();
            let starts: [u64; MAX_BOARDS] = std::array::from_fn(|_| rng.below(2_000));
            let last_row: [u64; MAX_BOARDS] = std::array::from_fn(|_| rng.below(40));
            let row_first = from + rng.below(lanes as u64) as usize;
            let row_end = row_first + rng.below((from + lanes - row_first) as u64 + 1) as usize;
            let terms = BoardTerms {
                board_shift,
                starts,
                paced_ends: std::array::from_fn(|b| starts[b] + last_row[b] + rng.below(90) + 22),
                last_row,
                from,
                row: (row_first, row_end),
            };
            let clocks_before = clocks.clone();
            let (mut plain, mut vector) = (clocks.clone(), clocks);
            let (expected, got) = match case % 2 == 0 {
                true => (
                    close_lanes_of::<true>(&slots, &after, &mut plain, &terms),
                    // SAFETY: the processor has AVX2 (checked above).
                    unsafe { avx2::close_lanes::<true>(&slots, &after, &mut vector, &terms) },
                ),
                false => (
                    close_lanes_of::<false>(&slots, &[], &mut plain, &terms),
                    // SAFETY: as above.
                    unsafe { avx2::close_lanes::<false>(&slots, &[], &mut vector, &terms) },
                ),
            };
            assert_eq!(got, expected, "case {case}");
            assert_eq!(vector, plain, "case {case}");
            if std::arch::is_x86_feature_detected!("avx512f") {
                let mut wide = clocks_before.clone();
                // SAFETY: the processor has AVX-512F (just checked).
                let got = unsafe {
                    match case % 2 == 0 {
                        true => avx512::close_lanes::<true>(&slots, &after, &mut wide, &terms),
                        false => avx512::close_lanes::<false>(&slots, &[], &mut wide, &terms),
                    }
                };
                assert_eq!(got, expected, "case {case}, AVX-512");
                assert_eq!(wide, plain, "case {case}, AVX-512");
            }
        }
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn the_vector_heights_are_the_column_by_column_heights() {
        // Random bands (up to 16 rows of up to 16 runs, some rows scattered, some columns
        // shared by several rows, 1, 2 and 4 boards): summed eight columns at a time, each
        // column's height in slots, each board's fragments and the steps left zero must be
        // what the plain sum gives.
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("skipped: this processor has no AVX2 (the plain sum is the reference)");
            return;
        }
        let mut rng = SplitMix64(11);
        let width = 640;
        for case in 0..3_000 {
            let board_shift = rng.below(3) as u32;
            let mut band = FragmentBand::EMPTY;
            for y in 0..1 + rng.below(16) as u16 {
                let mut x = rng.below(200) as u16;
                while x < width - 40 && band.admits(x, y) && rng.below(3) > 0 {
                    let len = 1 + rng.below(30) as u32;
                    band.push(x, y, len);
                    x += len as u16 + 1 + rng.below(5) as u16;
                }
            }
            if band.is_empty() {
                continue;
            }
            let (first, end) = extent(band.runs());
            let from = first - first % LANES;
            let columns = from..from + (end - from).next_multiple_of(LANES);
            let pace = [1, 11, 22, 176][rng.below(4) as usize];
            let plain = Columns {
                board_shift,
                steps: vec![0; width as usize + LANES],
                heights: vec![0; width as usize + LANES],
                clocks: Vec::new(),
                unit_slots: Vec::new(),
                unit_after: Vec::new(),
            };
            let (mut plain, mut vector) = (plain.clone(), plain);
            let expected = match board_shift {
                0 => plain.heights_in_slots_of::<1>(&band, columns.clone(), pace),
                1 => plain.heights_in_slots_of::<2>(&band, columns.clone(), pace),
                _ => plain.heights_in_slots_of::<4>(&band, columns.clone(), pace),
            };
            // SAFETY: the processor has AVX2 (checked above).
            let got = unsafe { vector.heights_in_slots_avx2(&band, columns.clone(), pace) };
            assert_eq!(got, expected, "case {case}");
            let lanes = columns.len();
            assert_eq!(
                vector.heights[..lanes],
                plain.heights[..lanes],
                "case {case}"
            );
            assert!(vector.steps.iter().all(|&step| step == 0), "case {case}");
            assert_eq!(
                expected.iter().sum::<u64>(),
                band.fragments(),
                "case {case}: every fragment counted once"
            );
        }
    }

    #[test]
    fn the_columns_path_counts_what_looking_each_owner_up_counts() {
        // Random rows of one run each (narrow ones that come back to the same engines
        // within a stretch when several rows make one, wide ones that wrap past the last
        // unit, some fed in two pieces), paces and primitives, fed to a window that counts
        // columns and to one that looks every pixel's owner up: every engine's clock and
        // every generator's must agree after every close, and the windows' cycles at the
        // end.
        for (boards, per_board) in [(4, 80), (2, 80), (1, 80), (4, 3), (2, 1), (1, 1)] {
            let arch = columns_arch(boards, per_board);
            let mut columns = IrWindow::new(&arch, 2048);
            let mut looked_up = IrWindow::new(&arch, 2048);
            assert!(matches!(columns.dealer, Dealer::Columns(_)));
            looked_up.dealer = self::looked_up(&arch);
            let mut rng = SplitMix64(boards as u64 * 1000 + per_board as u64);
            let mut y = 0u16;
            for step in 0..4_000 {
                match rng.below(20) {
                    0 => {
                        let release = rng.below(50) as f64;
                        columns.primitive(release);
                        looked_up.primitive(release);
                    }
                    1 => {
                        let pace = [11, 11, 24, 300][rng.below(4) as usize];
                        columns.pace(pace);
                        looked_up.pace(pace);
                    }
                    2 => {
                        let end = columns.cycles(&arch);
                        assert_eq!(end, looked_up.cycles(&arch), "step {step}");
                        columns.restart_at(end);
                        looked_up.restart_at(end);
                    }
                    _ => {
                        let x = rng.below(1280) as u16;
                        let len = [1, 3, 7, 40, 200, 700][rng.below(6) as usize];
                        let len = len.min(2048 - x as usize);
                        // The next row, as a primitive's come.
                        y = (y + 1) % 1024;
                        let split = rng.below(len as u64 + 1) as usize;
                        for (x, len) in [(x, split), (x + split as u16, len - split)] {
                            columns.paced_along((x, y), len);
                            looked_up.paced_along((x, y), len);
                        }
                    }
                }
                if rng.below(4) > 0 {
                    // Several rows to a stretch.
                    continue;
                }
                columns.close_stretch();
                looked_up.close_stretch();
                assert_eq!(
                    columns.engine_clocks().collect::<Vec<_>>(),
                    looked_up.engine_clocks().collect::<Vec<_>>(),
                    "step {step}"
                );
                assert_eq!(columns.generators, looked_up.generators, "step {step}");
                assert_eq!(columns.fragments, looked_up.fragments, "step {step}");
            }
        }
    }
}
