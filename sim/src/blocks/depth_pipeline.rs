//! The depth/stencil pipeline: prefetch buffer, depth test, depth write buffer.
//!
//! Rules, for fragment `i` readable from the rasterizer FIFO from cycle `arrive_i`
//! (= emission cycle + 1):
//! - its depth word is fetched by the [`DepthPrefetch`] (data ready in `r_i`);
//! - the test takes one cycle, one fragment per cycle, in order, in cycle
//!   `d_i = max(arrive_i, d_{i-1} + 1, r_i, out_slot, write_slot)`, where `out_slot` is the
//!   cycle the depth-to-OccU FIFO has room and, when the fragment will write depth,
//!   `write_slot` the cycle the depth write buffer has room (the test leaves its result in
//!   both in cycle `d_i`; the OccU can read it from `d_i + 1`);
//! - it writes depth when the depth test is on, the fragment passed, the depth mask is on and
//!   no occlusion render mode (brief, verbose) is active; the write enters the
//!   [`WriteBuffer`] in cycle `d_i` and drains one `depth_bits_per_pixel` transfer;
//! - a drawn fragment (it passed, no occlusion render mode) also writes
//!   `colour_bits_per_pixel` of colour: with its depth write one entry of both; under
//!   `blending` its colour is read first (one port request of the colour bits from `d_i + 1`,
//!   in order), and the entry is written from the cycle after the read's grant (the port is
//!   pipelined: the read's latency overlaps the requests after it);
//! - a clear with `clear_writes_memory` writes every depth and colour word of the viewport,
//!   `ceil(W H (depth_bits + colour_bits) / port_bits)` full port words from the first cycle
//!   the depth test is free, in order, and the depth test resumes after the last one;
//! - the pass signal is the functional depth test ([`DepthBuffer`]) under the current state.
//!
//! Writes and clears leave the banks' open rows as they are: only depth reads open rows.
//!
//! Stall accounting: cycles between `max(arrive_i, d_{i-1} + 1)` and `d_i` count as memory
//! stall while waiting for `r_i`, the rest as back-pressure stall.

use crate::arch::O2Arch;
use crate::blocks::depth_prefetch::DepthPrefetch;
use crate::blocks::memory_port::{MemoryPort, PortClient};
use crate::blocks::write_buffer::WriteBuffer;
use crate::effects::Effects;
use occsim_traces::golden::DepthBuffer;
use occsim_traces::state::RenderState;
use occsim_traces::{Fragment, Span};

pub struct DepthPipeline {
    pub state: RenderState,
    depth: DepthBuffer,
    pub prefetch: DepthPrefetch,
    pub write_buffer: WriteBuffer,
    /// First cycle the depth test is free.
    free: u64,
    pub busy_cycles: u64,
    pub stall_memory_cycles: u64,
    pub stall_backpressure_cycles: u64,
    /// Effect hook: false when a scan proved no fragment can write depth.
    depth_write_traffic: bool,
    depth_bits: u32,
    colour_bits: u32,
    blending: bool,
    /// Port words one clear writes (0: a fast clear).
    clear_words: u64,
    port_bits: u32,
    pub depth_writes: u64,
    pub colour_writes: u64,
    pub colour_reads: u64,
    pub clear_words_written: u64,
}

/// What the depth test decided for one fragment.
#[derive(Clone, Copy, Debug)]
pub struct DepthOutcome {
    /// The cycle of the test.
    pub cycle: u64,
    /// The depth test's write-enable signal (pass).
    pub passed: bool,
}

impl DepthPipeline {
    /// The pipeline on a `width` x `height` viewport whose depths are `depth`.
    pub fn new(
        arch: &O2Arch,
        width: u32,
        height: u32,
        effects: Effects,
        depth: DepthBuffer,
    ) -> DepthPipeline {
        DepthPipeline {
            state: RenderState::new(width, height),
            depth,
            prefetch: DepthPrefetch::new(arch, width, effects.page_model),
            write_buffer: WriteBuffer::new(
                arch.depth_write_buffer_entries,
                arch.depth_bits_per_pixel,
                PortClient::DepthWrite,
            ),
            free: 0,
            busy_cycles: 0,
            stall_memory_cycles: 0,
            stall_backpressure_cycles: 0,
            depth_write_traffic: effects.depth_write_traffic,
            depth_bits: arch.depth_bits_per_pixel,
            colour_bits: arch.colour_bits_per_pixel,
            blending: arch.blending,
            clear_words: if arch.clear_writes_memory {
                (width as u64
                    * height as u64
                    * (arch.depth_bits_per_pixel + arch.colour_bits_per_pixel) as u64)
                    .div_ceil(arch.memory_port_bits_per_cycle as u64)
            } else {
                0
            },
            port_bits: arch.memory_port_bits_per_cycle,
            depth_writes: 0,
            colour_writes: 0,
            colour_reads: 0,
            clear_words_written: 0,
        }
    }

    /// Start from a functional model's render state (a sampled window's warm start)
    /// instead of the reset state. Only before the first fragment.
    pub fn load_state(&mut self, state: &RenderState) {
        self.state = *state;
    }

    /// The depth buffer, for a warm start that sets a pixel's depth before its first test
    /// (the sampled level's consistent depths).
    pub fn depth_buffer_mut(&mut self) -> &mut DepthBuffer {
        &mut self.depth
    }

    /// Hand the depth buffer's memory back (for reuse), leaving an empty one.
    pub fn take_depth_buffer(&mut self) -> DepthBuffer {
        std::mem::replace(&mut self.depth, DepthBuffer::new(0, 0))
    }

    /// Depth := 1.0 everywhere; with `clear_writes_memory` its words go through the port
    /// in order from the first cycle the depth test is free, which then waits for the last.
    pub fn clear(&mut self, port: &mut MemoryPort) {
        self.depth.clear();
        if self.clear_words == 0 {
            return;
        }
        let mut last = self.free;
        for _ in 0..self.clear_words {
            last = port.claim(self.free, self.port_bits, PortClient::Clear);
        }
        self.clear_words_written += self.clear_words;
        self.free = self.free.max(last + 1);
    }

    /// Front end: fetch the depth of fragment number `index`, readable from `arrive`; returns the cycle
    /// its data is ready. `read` is whether the depth test is on when the fragment arrives.
    #[inline(always)]
    pub fn fetch(
        &mut self,
        index: usize,
        fragment: Fragment,
        arrive: u64,
        read: bool,
        port: &mut MemoryPort,
    ) -> u64 {
        self.prefetch
            .fetch(index, arrive, fragment.x, fragment.y, read, port)
    }

    /// Back end: test one fragment whose data is ready in `data_ready`. `out_slot` is when the
    /// depth-to-OccU FIFO has room; `occlusion_mode` suppresses depth writes.
    #[inline]
    pub fn test(
        &mut self,
        fragment: Fragment,
        arrive: u64,
        data_ready: u64,
        out_slot: u64,
        occlusion_mode: bool,
        port: &mut MemoryPort,
    ) -> DepthOutcome {
        let passed = self.depth.test(&self.state, fragment, !occlusion_mode);
        let cycle = self.time(passed, arrive, data_ready, out_slot, occlusion_mode, port);
        DepthOutcome { cycle, passed }
    }

    /// The functional depth test of one fragment under the current state, before it is
    /// timed (a fast-forward, [`crate::effects`]).
    #[inline]
    pub fn test_fragment(&mut self, fragment: Fragment, occlusion_mode: bool) -> bool {
        self.depth.test(&self.state, fragment, !occlusion_mode)
    }

    /// The functional depth test of a whole span under the current state, before any of it
    /// is timed: `passed[i]` for its fragment `i` (a fast-forward, [`crate::effects`]).
    #[inline]
    pub fn test_span(&mut self, span: Span, occlusion_mode: bool, passed: &mut Vec<bool>) {
        self.depth
            .test_span(&self.state, span, !occlusion_mode, passed);
    }

    /// The timing of the depth test of a fragment whose functional test `passed` (the rules
    /// above): returns the cycle of the test.
    #[inline]
    pub fn time(
        &mut self,
        passed: bool,
        arrive: u64,
        data_ready: u64,
        out_slot: u64,
        occlusion_mode: bool,
        port: &mut MemoryPort,
    ) -> u64 {
        let (writes, draws) = self.port_writes(passed, occlusion_mode);
        let in_order = arrive.max(self.free);
        let after_memory = in_order.max(data_ready);
        let mut cycle = after_memory.max(out_slot);
        if writes || draws {
            cycle = cycle.max(self.write_buffer.slot_free_cycle());
            self.write_entry(cycle, writes, draws, port);
        }
        self.stall_memory_cycles += after_memory - in_order;
        self.stall_backpressure_cycles += cycle - after_memory;
        self.busy_cycles += 1;
        self.free = cycle + 1;
        self.prefetch.retire(cycle);
        cycle
    }

    /// The write-buffer entry of a fragment tested in `cycle` that `writes` depth or `draws`
    /// colour (under `blending` after its colour read), and its port requests.
    #[inline]
    fn write_entry(&mut self, cycle: u64, writes: bool, draws: bool, port: &mut MemoryPort) {
        let bits =
            if writes { self.depth_bits } else { 0 } + if draws { self.colour_bits } else { 0 };
        let mut ready = cycle + 1;
        self.depth_writes += writes as u64;
        if draws {
            self.colour_writes += 1;
            if self.blending {
                self.colour_reads += 1;
                let read = port.claim(ready, self.colour_bits, PortClient::DepthWrite);
                ready = read + 1;
            }
        }
        self.write_buffer.push_entry(cycle, ready, bits, port);
    }

    /// Whether a fragment that passes writes depth or colour (under the current state).
    pub fn writes_if_passed(&self, occlusion_mode: bool) -> bool {
        let (writes, draws) = self.port_writes(true, occlusion_mode);
        writes || draws
    }

    /// In a lockstep run ([`crate::effects`]), the writes of a fragment whose test `passed`
    /// and that is tested in `cycle` with nothing else waited for: false, and nothing
    /// written, when it would wait for a write-buffer slot (the run stops before it).
    #[inline]
    pub fn write_in_lockstep(
        &mut self,
        passed: bool,
        occlusion_mode: bool,
        cycle: u64,
        port: &mut MemoryPort,
    ) -> bool {
        let (writes, draws) = self.port_writes(passed, occlusion_mode);
        if !(writes || draws) {
            return true;
        }
        if self.write_buffer.slot_free_cycle() > cycle {
            return false;
        }
        self.write_entry(cycle, writes, draws, port);
        true
    }

    /// Whether a fragment whose test `passed` writes depth and whether it draws colour
    /// (either is an entry of the write buffer and a port request).
    #[inline(always)]
    fn port_writes(&self, passed: bool, occlusion_mode: bool) -> (bool, bool) {
        let state = &self.state;
        let writes = if self.depth_write_traffic {
            passed && state.depth_test && state.depth_mask && !occlusion_mode
        } else {
            debug_assert!(
                !(state.depth_test && state.depth_mask && !occlusion_mode),
                "depth_write_traffic off, yet a fragment may write"
            );
            false
        };
        let draws = passed && !occlusion_mode && self.colour_bits > 0;
        (writes, draws)
    }

    /// Time `count` fragments tested in consecutive cycles from the first free one, none
    /// waiting, their writes made by [`Self::write_in_lockstep`] (a fast-forward proved it,
    /// [`crate::effects`]): what `count` calls of [`Self::time`] give. Returns the first
    /// one's cycle.
    #[inline]
    pub fn time_run(&mut self, count: usize) -> u64 {
        let first = self.free;
        self.busy_cycles += count as u64;
        self.free += count as u64;
        self.prefetch.retire_run(first, count);
        first
    }

    /// First cycle the depth test is free.
    pub fn free_cycle(&self) -> u64 {
        self.free
    }
}
