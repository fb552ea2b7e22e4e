//! One Image Engine: the FIFO in front of it, its depth test over the pixels it owns, and its
//! own Occlusion Unit with an OccU Control write buffer that drains hit words into the Image
//! Engine's memory, at `cycle` fidelity ([`crate::blocks::occlusion_unit`], [`crate::blocks::occu_control`])
//! or as the clocked RTL ([`crate::blocks::rtl_occu`]), through the [`crate::blocks::occu_stage`] seam.
//!
//! Rules, for the Image Engine's `k`-th fragment, emitted by its board's Fragment Generator
//! in `a_k` (`I = image_engine_cycles_per_fragment`, the initiation interval; `L =
//! image_engine_latency_cycles`; `P = ceil(L / I)` fragments in flight; `F =
//! image_engine_fifo_entries`):
//! - FIFO: the fragment may be emitted once fragment `k - F` left the FIFO (same-cycle reuse);
//! - depth test, pipelined: it starts (and leaves the FIFO) in `s_k = max(a_k + 1, s_{k-1} +
//!   I, o_{k-P})` and its result is ready in `s_k + L`: a fragment enters every `I` cycles,
//!   and the pipeline holds `P` until the Occlusion Unit accepts them (with `I = L`, `P = 1`:
//!   one unpipelined stage of `L` cycles);
//! - Occlusion Unit: it accepts the fragment in `o_k = max(s_k + L, c_{k-1} + 1)`, counts it
//!   for `s` cycles (one tile per engine per cycle) and leaves in `c_k`, later than
//!   `o_k + s - 1` only while the hit-word buffer is full; hit words drain one 32-bit word
//!   per cycle;
//! - query end, the end token entering in `t_end`: it passes the depth stage in
//!   `td = max(t_end + 1, s_last + I, o_last)`, the OccU in `to = max(td + 1,
//!   c_last + 1)`, and the Image Engine's partial report is ready in `r = max(to + 1, g + 1)`
//!   with `g` the grant of its last hit word (0 without hits).

use crate::arch::{IrArch, OCCU_WORD_BITS};
use crate::blocks::fifo::Fifo;
use crate::blocks::memory_port::MemoryPort;
use crate::blocks::occlusion_unit::{OccuStats, SharedLocatedTiles};
use crate::blocks::occu_stage::{OccuModel, OccuStage};
use crate::error::SimError;
use occsim_traces::{Fragment, QuerySpec, TileResult};

pub struct ImageEngine {
    /// Verbose hit words can occur (the effect model is built).
    verbose_hit_writes: bool,
    /// `I`, `L`.
    interval: u64,
    latency: u64,
    /// `o` of the last `P` fragments, by fragment number mod `P`.
    accepted: Vec<u64>,
    /// The next fragment's place in `accepted` (its number mod `P`, stepped rather than
    /// divided out a fragment).
    slot: usize,
    /// `s_last + I`: the first cycle the next fragment may enter.
    next_start: u64,
    /// `o_last`.
    last_accepted: u64,
    fifo: Fifo,
    /// The Occlusion Unit and OccU Control, modelled as the fidelity level says.
    occu: OccuStage,
    /// The Image Engine's memory port for hit words: one 32-bit word per cycle.
    port: MemoryPort,
    /// The query generation the Occlusion Unit is loaded for (loaded at the first fragment).
    loaded_query: u64,
    pub fragments: u64,
    /// Cycles spent on depth tests.
    pub busy_cycles: u64,
}

impl ImageEngine {
    /// An Image Engine whose OccU is modelled as `occu` says; `verbose_hit_writes` is the
    /// effect hook ([`crate::effects`]): off, no query is verbose and OccU Control's hit path
    /// is skipped.
    pub fn new(arch: &IrArch, occu: OccuModel, verbose_hit_writes: bool) -> ImageEngine {
        ImageEngine {
            verbose_hit_writes,
            interval: arch.image_engine_cycles_per_fragment,
            latency: arch.image_engine_latency_cycles,
            accepted: vec![0; arch.image_engine_in_flight()],
            slot: 0,
            next_start: 0,
            last_accepted: 0,
            fifo: Fifo::new(arch.image_engine_fifo_entries),
            occu: OccuStage::for_image_engine(arch, occu),
            port: MemoryPort::new(OCCU_WORD_BITS),
            loaded_query: 0,
            fragments: 0,
            busy_cycles: 0,
        }
    }

    /// The cycle the FIFO has room for the next fragment.
    #[inline]
    pub fn slot_free_cycle(&self) -> u64 {
        self.fifo.slot_free_cycle()
    }

    /// Make sure the Occlusion Unit holds query `generation`'s tiles (`spec`), located
    /// (their outlines and locators) once for all the Image Engines through `shared`.
    #[inline]
    pub fn load(&mut self, generation: u64, spec: &QuerySpec, shared: &mut SharedLocatedTiles) {
        if self.loaded_query != generation {
            self.occu.begin_sharing(spec, shared, generation);
            self.loaded_query = generation;
        }
    }

    /// Time one fragment emitted in `emitted` whose depth test `passed`.
    #[inline]
    pub fn fragment(&mut self, fragment: Fragment, passed: bool, emitted: u64, query_open: bool) {
        let slot = self.slot;
        self.slot = if slot + 1 == self.accepted.len() {
            0
        } else {
            slot + 1
        };
        let start = (emitted + 1).max(self.next_start).max(self.accepted[slot]);
        self.fifo.depart(start);
        self.fragments += 1;
        self.busy_cycles += self.interval;
        let accepted = self.occu.fragment(
            fragment,
            passed,
            start + self.latency,
            query_open,
            &mut self.port,
            self.verbose_hit_writes,
        );
        self.accepted[slot] = accepted;
        self.next_start = start + self.interval;
        self.last_accepted = accepted;
    }

    /// `max(s_last + I, o_last)`: the depth stage is through everything before.
    fn depth_free(&self) -> u64 {
        self.next_start.max(self.last_accepted)
    }

    /// The end token entering in `end_cycle`: the cycle the partial report is ready and the
    /// partial results of query `generation` (`None` when no fragment of it came here).
    pub fn end(
        &mut self,
        end_cycle: u64,
        generation: u64,
        tiles: usize,
    ) -> (u64, Option<Vec<TileResult>>) {
        let through_depth = (end_cycle + 1).max(self.depth_free());
        let through_occu = (through_depth + 1).max(self.occu.free_cycle());
        let ready = (through_occu + 1).max(self.hits_drained());
        let results = (self.loaded_query == generation).then(|| self.occu.partial_report(tiles));
        (ready, results)
    }

    /// The cycle after the last hit word's grant (0 without hits).
    fn hits_drained(&self) -> u64 {
        self.occu.last_grant().map_or(0, |grant| grant + 1)
    }

    /// The first cycle every part of the Image Engine is idle.
    pub fn free_cycle(&self) -> u64 {
        self.depth_free()
            .max(self.occu.free_cycle())
            .max(self.hits_drained())
    }

    /// End of the stream: the Occlusion Unit's statistics (its words are all hit words).
    pub fn finish(&mut self) -> Result<OccuStats, SimError> {
        self.occu.finish()
    }
}
