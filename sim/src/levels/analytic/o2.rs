//! The O2-like machine's closed-form bottleneck model: per *window* (the events from just
//! after one query's end to the next query's end, see [`crate::levels`]) a cheap scan
//! counts what each block must do:
//!
//! | count | meaning |
//! |---|---|
//! | `F`, `P` | fragments and primitives |
//! | `S` | OccU cycles: `Σ s` over fragments, `s = ceil(tiles / engines)` under an open query (1 with `all_tiles_one_cycle` or no query) |
//! | `R`, `M` | depth reads (fragments, depth test on, whose memory word differs from the last read's: the prefetch's exact rule) and of them page misses (a different 64 KB page) |
//! | `W` | depth writes (passing fragments with depth test and mask on, outside brief/verbose queries) |
//! | `O` | OccU Control words: verbose hit words `Σ_tiles min(NOHC, entries - 8)` plus records `8 · tiles` (+1 terminator per overflowed buffer with room) |
//! | `K`, `B` | colour writes (passing fragments outside brief/verbose queries, with colour bits) and, under `blending`, as many colour reads |
//! | `Z` | clears (each `ceil(W H (depth_bits + colour_bits) / V)` port words with `clear_writes_memory`) |
//!
//! Throughput of each block over the window, in cycles (`setup` = `primitive_setup_cycles`,
//! `V` = `memory_port_bits_per_cycle`, `L = min(prefetch_depth_fragments,
//! fifo_raster_to_depth_entries)`, `λ̄ = (M · page_miss + (R - M) · page_hit) / R`):
//!
//! ```text
//! raster   = F + setup · P
//! depth    = F
//! occu     = S
//! port     = (R + ceil((W · depth_bits + (K + B) · colour_bits + 32 · O) / V)) / (1 - f)
//! prefetch = R · (λ̄ + 1) / L          (Little's law: L reads in flight, each λ̄ + 1 cycles)
//! clears   = Z · clear_words / (1 - f)   (the depth test waits for a clear's last word)
//! T_w      = max(raster, depth, occu, port, prefetch) + clears
//! ```
//!
//! with `f` the port share the display refresh and the host reserve
//! ([`crate::arch::O2Arch::reserved_port_share`]).
//!
//! Total cycles = `Σ_w T_w` + the last window's tail (the last query's latency, or its
//! drain + 3 when the stream ends without a query end).
//!
//! Query latency (from the `end` token entering the pipe to its records written):
//!
//! ```text
//! β       = max(depth, occu, port, prefetch) / F   (downstream cycles per fragment)
//! backlog = min(F, (C1 + C2) / 2)   (C1, C2: the two FIFOs' entries. No downstream block
//!                                    is faster than the rasterizer's one fragment a cycle,
//!                                    so entries a stall filled stay filled: half full on
//!                                    average, a heuristic)
//! drain   = max(backlog · β, λ_last)  (λ_last: the last fragment's read latency, 0 when
//!                                      it read nothing new)
//! latency = 4 + ceil(ceil(records / (V / 32)) / (1 - f)) + min(drain, ahead)
//! ```
//!
//! with `ahead = max(0, s_w + T_w - r_end)`: in a closed loop the end token enters at its
//! release `r_end`, and only the work the pipe has not finished by then is ahead of it (a
//! host-bound window's token finds the pipe empty); in an open loop `r_end = 0`.
//!
//! Clears with fewer than `L` fragments after them, in this window or earlier ones since the
//! last frame end, also hold the drain: at least their `clear_words / (1 - f)` cycles plus
//! those fragments' (the rasterizer ran past them, up to `L` fragments ahead).
//!
//! The 4 is the empty pipe's path (depth pipeline, OccU, OccU Control, the grant after the
//! last word): with one record group that fits one port cycle, latency is the machine's
//! minimum, [`crate::machines::o2::MIN_QUERY_LATENCY_CYCLES`]. Costs: the functional model plus a
//! few integer operations per fragment.

use super::{service_cycles, WindowEnd};
use crate::arch::O2Arch;
use occsim_traces::depth_layout::{DepthAddress, DepthRead, LastRead};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::query::BRIEF_RECORD_ENTRIES;
use occsim_traces::state::RenderState;
use occsim_traces::trace::FragmentStretch;
use occsim_traces::{Fragment, QueryMode, QueryResult, QuerySpec, Span};

/// Counts of one window (see the module table).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct WindowCounts {
    pub fragments: u64,
    pub primitives: u64,
    pub occu_cycles: u64,
    pub depth_reads: u64,
    pub page_misses: u64,
    pub depth_writes: u64,
    pub occu_words: u64,
    pub colour_writes: u64,
    pub colour_reads: u64,
    pub clears: u64,
    /// Clears with fewer than `L` fragments after them (the rasterizer ran past them, so the
    /// end token waits for their words), and the fragments after the last; carried from
    /// window to window (a frame end drains them).
    pub recent_clears: u64,
    pub fragments_after_clear: u64,
    /// Read latency of the window's last fragment (0 when it read nothing new).
    pub last_read_latency: u64,
}

/// What the formulas predict for one window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowPrediction {
    /// `T_w`: the window's cycles.
    pub cycles: f64,
    /// The pipe's drain after the window's last fragment, in cycles.
    pub drain: f64,
}

/// The O2 formulas over window counts.
pub struct O2Formulas {
    arch: O2Arch,
    /// Port words one clear writes (0: a fast clear).
    clear_words: u64,
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
        O2Formulas {
            arch: arch.clone(),
            clear_words,
        }
    }

    /// Lookahead `L`: fragments whose reads may be in flight.
    fn lookahead(&self) -> f64 {
        self.arch
            .prefetch_depth_fragments
            .min(self.arch.fifo_raster_to_depth_entries) as f64
    }

    /// OccU cycles per fragment under a query of `tiles` tiles.
    pub fn service_cycles(&self, tiles: usize) -> u64 {
        service_cycles(
            tiles,
            self.arch.occu.engines,
            self.arch.occu.all_tiles_one_cycle,
        )
    }

    /// `T_w` and the drain of a window.
    pub fn window(&self, w: &WindowCounts) -> WindowPrediction {
        let a = &self.arch;
        let fragments = w.fragments as f64;
        let raster = fragments + (a.primitive_setup_cycles * w.primitives) as f64;
        let depth = fragments;
        let occu = w.occu_cycles as f64;
        let write_bits = w.depth_writes * a.depth_bits_per_pixel as u64
            + (w.colour_writes + w.colour_reads) * a.colour_bits_per_pixel as u64
            + 32 * w.occu_words;
        let free_share = 1.0 - a.reserved_port_share();
        let port = (w.depth_reads as f64
            + write_bits.div_ceil(a.memory_port_bits_per_cycle as u64) as f64)
            / free_share;
        let clears = (w.clears * self.clear_words) as f64 / free_share;
        let prefetch = if w.depth_reads == 0 {
            0.0
        } else {
            let misses = w.page_misses as f64;
            let reads = w.depth_reads as f64;
            let mean_latency = (misses * a.page_miss_latency_cycles as f64
                + (reads - misses) * a.page_hit_latency_cycles as f64)
                / reads;
            reads * (mean_latency + 1.0) / self.lookahead()
        };
        let downstream = depth.max(occu).max(port).max(prefetch);
        let cycles = raster.max(downstream) + clears;
        // Fragments ahead of the end token: the downstream blocks never run faster than one
        // fragment a cycle, the rasterizer's own rate, so FIFO entries that a stall filled
        // stay filled; we take them half full on average.
        let fifo = (a.fifo_raster_to_depth_entries + a.fifo_depth_to_occu_entries) as f64;
        let backlog = if w.fragments > 0 {
            fragments.min(fifo / 2.0) * (downstream / fragments)
        } else {
            0.0
        };
        // A clear the rasterizer ran past (fewer than L fragments after it) is still being
        // written when the end token enters: the drain waits for its words.
        let behind_clears = if w.recent_clears > 0 {
            (w.recent_clears * self.clear_words) as f64 / free_share
                + w.fragments_after_clear as f64
        } else {
            0.0
        };
        WindowPrediction {
            cycles,
            drain: backlog.max(w.last_read_latency as f64).max(behind_clears),
        }
    }

    /// Latency of a query whose records are `record_words` words, after a window that
    /// drains in `drain` cycles.
    pub fn latency(&self, record_words: u64, drain: f64) -> f64 {
        let words_per_cycle = (self.arch.memory_port_bits_per_cycle / 32) as u64;
        let port_cycles = record_words.div_ceil(words_per_cycle) as f64;
        4.0 + (port_cycles / (1.0 - self.arch.reserved_port_share())).ceil() + drain
    }
}

/// Record words a query writes at its end, and the verbose hit words its engines sent.
pub fn query_words(spec: &QuerySpec, result: &QueryResult) -> (u64, u64) {
    let room = spec.buffer_entries.saturating_sub(BRIEF_RECORD_ENTRIES) as u64;
    let mut records = 0;
    let mut hits = 0;
    for tile in &result.tiles {
        records += BRIEF_RECORD_ENTRIES as u64;
        if spec.mode == QueryMode::Verbose {
            hits += tile.nohc.min(room);
            if tile.overflowed && room > 0 {
                records += 1;
            }
        }
    }
    (records, hits)
}

/// The O2 model's per-window counting state.
pub(crate) struct O2Bottleneck {
    formulas: O2Formulas,
    address: DepthAddress,
    last_read: LastRead,
    window: WindowCounts,
    /// OccU cycles per fragment and "occlusion render mode" of the open query.
    open: Option<(u64, bool)>,
}

impl O2Bottleneck {
    pub(super) fn new(arch: &O2Arch, width: u32, height: u32) -> O2Bottleneck {
        O2Bottleneck {
            formulas: O2Formulas::new(arch, width, height),
            address: DepthAddress::new(&arch.depth_layout(), width),
            last_read: LastRead::new(arch.memory_banks),
            window: WindowCounts::default(),
            open: None,
        }
    }

    pub(super) fn primitive(&mut self) {
        self.window.primitives += 1;
    }

    pub(super) fn begin(&mut self, spec: &QuerySpec) {
        let service = self.formulas.service_cycles(spec.tiles.len());
        self.open = Some((service, spec.mode.is_occlusion_render_mode()));
    }

    /// Count one fragment's work (before `functional` applies it).
    #[inline]
    pub(super) fn fragment(&mut self, fragment: Fragment, functional: &FunctionalModel) {
        let mut stretch = FragmentStretch::EMPTY;
        stretch.count_fragment(
            fragment,
            functional.state(),
            functional.depth_buffer().get(fragment.x, fragment.y),
            (&self.address, &mut self.last_read),
            !self.open.is_some_and(|(_, mode)| mode),
        );
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
        };
        if state.depth_test {
            let last_x = span.x as u32 + last as u32;
            let mut x = span.x as u32;
            while x < end {
                let (word, page) = self.address.locate(x as u16, span.y);
                let read = self.last_read.read(word, page);
                stretch.depth_reads += (read != DepthRead::SameWord) as u64;
                stretch.page_misses += (read == DepthRead::PageMiss) as u64;
                let next = (x + self.address.pixels_left_in_word(x as u16)).min(end);
                // The last fragment reads anew only when it starts its word's run.
                if x == last_x {
                    stretch.last_read = read;
                }
                x = next;
            }
            if !self.open.is_some_and(|(_, mode)| mode) {
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
        let lookahead = self.formulas.lookahead() as u64;
        let arch = &self.formulas.arch;
        let w = &mut self.window;
        let n = stretch.fragments;
        w.fragments += n;
        if w.recent_clears > 0 {
            // One by one, the count stops at L, where the clears stop holding the drain.
            w.fragments_after_clear = (w.fragments_after_clear + n).min(lookahead);
            if w.fragments_after_clear >= lookahead {
                w.recent_clears = 0;
            }
        }
        w.occu_cycles += n * self.open.map_or(1, |(service, _)| service);
        w.last_read_latency = match stretch.last_read {
            DepthRead::SameWord => 0,
            DepthRead::PageHit => arch.page_hit_latency_cycles,
            DepthRead::PageMiss => arch.page_miss_latency_cycles,
        };
        w.depth_reads += stretch.depth_reads;
        w.page_misses += stretch.page_misses;
        if self.open.is_some_and(|(_, mode)| mode) {
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

    /// A clear: its words through the port (when clears write memory).
    pub(super) fn clear(&mut self) {
        let w = &mut self.window;
        w.clears += 1;
        if self.formulas.clear_words > 0 {
            w.recent_clears += 1;
            w.fragments_after_clear = 0;
        }
    }

    /// The query `spec` ended with `result`, its window begun at `start` and its end token
    /// released at `release`: the window's cycles and the query's latency.
    pub(super) fn end_query(
        &mut self,
        spec: &QuerySpec,
        result: &QueryResult,
        start: f64,
        release: f64,
    ) -> WindowEnd {
        self.open = None;
        let (records, hits) = query_words(spec, result);
        self.window.occu_words += records + hits;
        let prediction = self.formulas.window(&self.window);
        // The clears the rasterizer ran past stay behind it into the next window.
        self.window = WindowCounts {
            recent_clears: self.window.recent_clears,
            fragments_after_clear: self.window.fragments_after_clear,
            ..WindowCounts::default()
        };
        // What the pipe has still to do when the token comes is all it can wait behind.
        let ahead = (start + prediction.cycles - release).max(0.0);
        WindowEnd {
            cycles: prediction.cycles,
            latency: self.formulas.latency(records, prediction.drain.min(ahead)),
        }
    }

    /// Start the window again with no work (a frame ended inside it).
    pub(super) fn clear_window(&mut self) {
        self.window = WindowCounts::default();
    }

    /// The stream ended after a window without a query end: its cycles and the pipe's drain
    /// (+ 3: through the depth pipeline, the OccU and the last write).
    pub(super) fn finish(&self) -> Option<WindowEnd> {
        let w = &self.window;
        (w.fragments > 0 || w.primitives > 0).then(|| {
            let prediction = self.formulas.window(w);
            WindowEnd {
                cycles: prediction.cycles,
                latency: prediction.drain + 3.0,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::Arch;
    use occsim_traces::rng::SplitMix64;
    use occsim_traces::{DepthFunc, Event, Rect};

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
                whole.begin(&spec);
                single.begin(&spec);
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
            assert_eq!(whole.window, single.window, "step {step}");
            last_reads += (whole.window.last_read_latency > 0) as u32;
            functional.span(span);
        }
        // The runs did end on a new word, so the last read's latency was compared.
        assert!(last_reads > 100, "{last_reads}");
    }
}
