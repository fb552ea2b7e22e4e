//! Fragment input: the rasterizer's output side, with triangle setup.
//!
//! Rules: the rasterizer emits at most one fragment per cycle into the rasterizer-to-depth
//! FIFO. A `Primitive` costs `primitive_setup_cycles` cycles, starting the cycle after the
//! previous fragment was emitted (setup of the next triangle does not overlap the emission
//! of the last one). Fragment `i` is emitted in cycle
//! `a_i = max(free, slot)`, where `free` is the first cycle after the previous emission or
//! setup and `slot` the cycle the FIFO has room ([`crate::blocks::fifo`]); then `free = a_i + 1`.
//! Waiting for `slot` counts as stall.

pub struct FragmentInput {
    setup_cycles: u64,
    /// First cycle the rasterizer can emit or start a setup.
    free: u64,
    pub busy_cycles: u64,
    pub stall_cycles: u64,
    pub fragments: u64,
    pub primitives: u64,
}

impl FragmentInput {
    pub fn new(setup_cycles: u64) -> FragmentInput {
        FragmentInput {
            setup_cycles,
            free: 0,
            busy_cycles: 0,
            stall_cycles: 0,
            fragments: 0,
            primitives: 0,
        }
    }

    /// Nothing can start before `cycle` (the host or the geometry stage has not delivered
    /// it yet); the idle cycles count as neither busy nor stall.
    #[inline]
    pub fn release(&mut self, cycle: u64) {
        self.free = self.free.max(cycle);
    }

    /// A primitive reached setup.
    #[inline]
    pub fn primitive(&mut self) {
        self.free += self.setup_cycles;
        self.busy_cycles += self.setup_cycles;
        self.primitives += 1;
    }

    /// Emit one fragment once the output FIFO has a slot from cycle `slot_free`; returns the
    /// emission cycle.
    #[inline(always)]
    pub fn emit(&mut self, slot_free: u64) -> u64 {
        let cycle = self.free.max(slot_free);
        self.stall_cycles += cycle - self.free;
        self.busy_cycles += 1;
        self.fragments += 1;
        self.free = cycle + 1;
        cycle
    }

    /// Emit `count` fragments in the `count` cycles from the first free one, none waiting for
    /// a FIFO slot (a fast-forward proved it, [`crate::effects`]): what `count` calls of
    /// [`Self::emit`] give.
    #[inline]
    pub fn emit_run(&mut self, count: u64) {
        self.busy_cycles += count;
        self.fragments += count;
        self.free += count;
    }

    /// The first cycle the rasterizer is free: where a token (query end) enters the pipe.
    pub fn free_cycle(&self) -> u64 {
        self.free
    }
}
