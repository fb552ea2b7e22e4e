//! The InfiniteReality-like machine's closed-form bottleneck model ([`crate::machines::ir`] states the
//! machine's rules).
//!
//! Counts per window (`B` boards of `N` Image Engines; Image Engine `i = b · N + n`):
//!
//! | count | meaning |
//! |---|---|
//! | `F_b` | fragments board `b`'s Fragment Generator emits (its own pixels) |
//! | `P` | primitives (every board sets every one up) |
//! | `F_i` | fragments Image Engine `i` tests |
//! | `D_i` | `Σ max(C, s)` over its fragments: the depth stage (`C` = `image_engine_cycles_per_fragment`, its initiation interval) and the OccU (`s` = cycles a fragment under the open query, [`super::service_cycles`]) are pipelined, so the slower paces the engine |
//! | `H_i` | hit words: over its passing fragments under a verbose query, the query's tiles holding each |
//!
//! The counts are kept per window and, for the busiest Image Engine, per primitive too
//! (`F_bp`, `D_ip`): a small primitive's fragments land on few Image Engines, and the
//! Fragment Generator, emitting in order, waits for them. An Image Engine's FIFO holds
//! `E · C` cycles of its work (`E` = `image_engine_fifo_entries`) that it does after the
//! generator has moved on, so that much of a primitive's busiest engine is hidden:
//!
//! ```text
//! generator_b    = ceil(F_b / fragment_generator_fragments_per_cycle) + setup · P
//! image_engine_i = max(D_i, H_i)                 (hit words drain one 32-bit word a cycle)
//! T_p            = max(ceil(max_b F_bp / rate) + setup, max_i D_ip - E · C)
//! T_w            = max(max_b generator_b, Σ_p T_p, max_i image_engine_i - E · C)
//! ```
//!
//! Latency: the end token enters in `t_end` (the predicted cycle the window ends, `Σ T_w`).
//! Image Engine `i`'s partial report is ready in `r_i = t_end + 3 + backlog_i` (3: through
//! its depth stage, its OccU and the report; the machine's idle path), with
//!
//! ```text
//! backlog_i = min(D_i, round(E · C · min(1, D_i / T_w)) + L)
//! ```
//!
//! (`L` = `image_engine_latency_cycles`) the work still queued at the end token: the last
//! fragment through the depth stage's latency and the FIFO, as full as the engine was busy
//! over the window (full for a bottleneck engine: with the calibrated Image Engines the
//! demo's bottleneck is the Fragment Generators, and their FIFOs are part full). The two
//! merge stages then run on the `r_i` exactly as the machine runs them, moving the same
//! words (8 a tile from every Image Engine; [`crate::blocks::merge_network::merged_ready`], then
//! the DMA to host memory; the host of software merges is carried from query to query), and
//! latency = available − `t_end`. Hit words per Image Engine are not capped by the verbose
//! buffers' room: a query whose buffers overflow is predicted slower than it is.

use super::{service_cycles, WindowEnd};
use crate::arch::IrArch;
use crate::blocks::interleave::FramebufferInterleave;
use crate::blocks::merge_network::{delivered, merged_ready, Partial, ReportShape};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{Fragment, QueryMode, QuerySpec, Rect};

/// Counts of one window (see the module table).
#[derive(Clone, Debug, PartialEq)]
pub struct IrWindow {
    pub primitives: u64,
    /// `F_b`, per board.
    pub board_fragments: Vec<u64>,
    /// `F_i`, per Image Engine (board-major).
    pub image_engine_fragments: Vec<u64>,
    /// `D_i`.
    pub image_engine_cycles: Vec<u64>,
    /// `H_i`.
    pub hit_words: Vec<u64>,
    /// `Σ_p T_p` over the window's primitives closed so far (see the module docs).
    pub serial_cycles: u64,
    /// The current primitive: its `F_b`, its `D_i` (non-zero only at `touched`), the largest.
    primitive_board_fragments: Vec<u64>,
    primitive_engine_cycles: Vec<u64>,
    touched: Vec<usize>,
    primitive_busiest: u64,
    /// The current primitive was announced (its setup counts).
    primitive_set_up: bool,
}

/// The window's bottleneck: `T_w` and each Image Engine's own cycles.
pub struct IrWindowCycles {
    pub cycles: f64,
    pub image_engines: Vec<f64>,
}

impl IrWindow {
    pub fn new(arch: &IrArch) -> IrWindow {
        let engines = arch.image_engines();
        IrWindow {
            primitives: 0,
            board_fragments: vec![0; arch.boards],
            image_engine_fragments: vec![0; engines],
            image_engine_cycles: vec![0; engines],
            hit_words: vec![0; engines],
            serial_cycles: 0,
            primitive_board_fragments: vec![0; arch.boards],
            primitive_engine_cycles: vec![0; engines],
            touched: Vec::new(),
            primitive_busiest: 0,
            primitive_set_up: false,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.primitives == 0 && self.board_fragments.iter().all(|&f| f == 0)
    }

    pub fn clear(&mut self) {
        self.primitives = 0;
        self.board_fragments.fill(0);
        self.image_engine_fragments.fill(0);
        self.image_engine_cycles.fill(0);
        self.hit_words.fill(0);
        self.serial_cycles = 0;
        self.clear_primitive();
        // The primitive being drawn goes on into the next window, its setup paid in this one.
        self.primitive_set_up = false;
    }

    fn clear_primitive(&mut self) {
        for &engine in &self.touched {
            self.primitive_engine_cycles[engine] = 0;
        }
        self.touched.clear();
        self.primitive_board_fragments.fill(0);
        self.primitive_busiest = 0;
    }

    /// `T_p` of the current primitive: `max(generator_p, max_i D_ip)`.
    fn primitive_cycles(&self, arch: &IrArch) -> u64 {
        let rate = arch.fragment_generator_fragments_per_cycle.max(1) as u64;
        let setup = if self.primitive_set_up {
            arch.fragment_generator_setup_cycles
        } else {
            0
        };
        let emitted = self
            .primitive_board_fragments
            .iter()
            .max()
            .copied()
            .unwrap_or(0);
        let hidden = fifo_hidden_cycles(arch);
        (emitted.div_ceil(rate) + setup).max(self.primitive_busiest.saturating_sub(hidden))
    }

    /// A new primitive: the current one's `T_p` joins the window's serial sum.
    pub fn primitive(&mut self, arch: &IrArch) {
        self.serial_cycles += self.primitive_cycles(arch);
        self.clear_primitive();
        self.primitives += 1;
        self.primitive_set_up = true;
    }

    /// One fragment for Image Engine `engine` of `board`, paced at `pace` cycles (`max(C, s)`).
    #[inline]
    pub fn fragment(&mut self, board: usize, engine: usize, pace: u64) {
        self.board_fragments[board] += 1;
        self.image_engine_fragments[engine] += 1;
        self.image_engine_cycles[engine] += pace;
        self.primitive_board_fragments[board] += 1;
        let cycles = &mut self.primitive_engine_cycles[engine];
        if *cycles == 0 {
            self.touched.push(engine);
        }
        *cycles += pace;
        self.primitive_busiest = self.primitive_busiest.max(*cycles);
    }

    /// `T_w` and every Image Engine's `max(D_i, H_i)`.
    pub fn cycles(&self, arch: &IrArch) -> IrWindowCycles {
        let rate = arch.fragment_generator_fragments_per_cycle.max(1) as u64;
        let setup = arch.fragment_generator_setup_cycles * self.primitives;
        let generators = self
            .board_fragments
            .iter()
            .map(|&f| (f.div_ceil(rate) + setup) as f64)
            .fold(0.0, f64::max);
        let image_engines: Vec<f64> = self
            .image_engine_cycles
            .iter()
            .zip(&self.hit_words)
            .map(|(&depth, &hits)| depth.max(hits) as f64)
            .collect();
        let serial = (self.serial_cycles + self.primitive_cycles(arch)) as f64;
        let busiest = image_engines.iter().copied().fold(0.0, f64::max);
        let cycles = generators
            .max(serial)
            .max(busiest - fifo_hidden_cycles(arch) as f64);
        IrWindowCycles {
            cycles,
            image_engines,
        }
    }
}

/// `E · C`: an Image Engine's work its full FIFO holds, which it does after the Fragment
/// Generator has moved on (and after the end token: it is in the latency).
fn fifo_hidden_cycles(arch: &IrArch) -> u64 {
    arch.image_engine_fifo_entries as u64 * arch.image_engine_cycles_per_fragment
}

/// The open query, as the counts need it.
struct OpenQuery {
    /// `s`: OccU cycles per fragment.
    service: u64,
    /// A verbose query's tiles (hit words), else empty.
    verbose_tiles: Vec<Rect>,
}

/// The IR model's per-window counting state.
pub(crate) struct IrBottleneck {
    arch: IrArch,
    interleave: FramebufferInterleave,
    window: IrWindow,
    open: Option<OpenQuery>,
    /// The host's first free cycle (software merges).
    host: u64,
}

impl IrBottleneck {
    pub(super) fn new(arch: &IrArch) -> IrBottleneck {
        IrBottleneck {
            interleave: FramebufferInterleave::new(arch),
            window: IrWindow::new(arch),
            arch: arch.clone(),
            open: None,
            host: 0,
        }
    }

    pub(super) fn primitive(&mut self) {
        self.window.primitive(&self.arch);
    }

    pub(super) fn begin(&mut self, spec: &QuerySpec) {
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
        });
    }

    /// Count one fragment's work (before `functional` applies it).
    #[inline]
    pub(super) fn fragment(&mut self, fragment: Fragment, functional: &FunctionalModel) {
        let owner = self.interleave.owner(fragment.x, fragment.y);
        let engine = owner.board * self.arch.image_engines_per_board + owner.image_engine;
        let service = self.open.as_ref().map_or(1, |q| q.service);
        let pace = service.max(self.arch.image_engine_cycles_per_fragment);
        self.window.fragment(owner.board, engine, pace);
        let Some(query) = &self.open else {
            return;
        };
        if query.verbose_tiles.is_empty() {
            return;
        }
        let state = functional.state();
        let passed = !state.depth_test
            || state.depth_func.passes(
                fragment.z,
                functional.depth_buffer().get(fragment.x, fragment.y),
            );
        if passed {
            let (x, y) = (fragment.x as u32, fragment.y as u32);
            let tiles = query.verbose_tiles.iter().filter(|t| t.contains(x, y));
            self.window.hit_words[engine] += tiles.count() as u64;
        }
    }

    /// The query ended; the window that began in cycle `start` closes: its cycles and the
    /// query's latency.
    pub(super) fn end_query(&mut self, spec: &QuerySpec, start: f64, release: f64) -> WindowEnd {
        self.open = None;
        let bottleneck = self.window.cycles(&self.arch);
        let pipe_done = start + bottleneck.cycles;
        // The end token enters at its release; the pipe's work left by then is all the
        // Image Engines' backlog can hold ahead of it.
        let ahead = (pipe_done - release).max(0.0).round() as u64;
        let end_cycle = pipe_done.max(release).round() as u64;
        let ready: Vec<u64> = self
            .report_delays(ahead)
            .map(|delay| end_cycle + delay)
            .collect();
        // Words as the machine moves them: 8 a tile from every Image Engine, and its hit
        // words as one bucket, not capped by the buffers' room.
        let shape = ReportShape {
            tiles: spec.tiles.len() as u64,
            room: u64::MAX,
        };
        let verbose = spec.mode == QueryMode::Verbose;
        let reports: Vec<Partial> = ready
            .iter()
            .zip(&self.window.hit_words)
            .map(|(&ready, &hits)| Partial {
                ready,
                hits: if verbose { vec![hits] } else { Vec::new() },
            })
            .collect();
        let board_reports: Vec<Partial> = reports
            .chunks(self.arch.image_engines_per_board)
            .map(|board| {
                merged_ready(
                    &self.arch.local_merge_network(),
                    board,
                    shape,
                    &mut self.host,
                )
            })
            .collect();
        let global = self.arch.global_merge_network();
        let merged = merged_ready(&global, &board_reports, shape, &mut self.host);
        let available = delivered(&global, &merged, shape, self.arch.report_dma_bits_per_cycle);
        self.window.clear();
        WindowEnd {
            cycles: bottleneck.cycles,
            latency: (available - end_cycle) as f64,
        }
    }

    /// Per Image Engine, the cycles from the end token to its partial report: `3 + backlog_i`,
    /// the backlog no more than the `ahead` cycles of work left when the token came.
    fn report_delays(&self, ahead: u64) -> impl Iterator<Item = u64> + '_ {
        let fifo = self.arch.image_engine_fifo_entries as f64
            * self.arch.image_engine_cycles_per_fragment as f64;
        let latency = self.arch.image_engine_latency_cycles;
        let window = self.window.cycles(&self.arch).cycles.max(1.0);
        self.window.image_engine_cycles.iter().map(move |&cycles| {
            // The FIFO is as full as the engine is busy over the window.
            let busy = (cycles as f64 / window).min(1.0);
            3 + cycles
                .min((fifo * busy).round() as u64 + latency)
                .min(ahead)
        })
    }

    /// Start the window again with no work (a frame ended inside it).
    pub(super) fn clear_window(&mut self) {
        self.window.clear();
    }

    /// The stream ended after a window without a query end: its cycles and the slowest
    /// Image Engine's drain.
    pub(super) fn finish(&self) -> Option<WindowEnd> {
        if self.window.is_empty() {
            return None;
        }
        let drain = self.report_delays(u64::MAX).max().unwrap_or(3);
        Some(WindowEnd {
            cycles: self.window.cycles(&self.arch).cycles,
            latency: drain as f64,
        })
    }
}
