//! One Raster Memory board's Fragment Generator: it sets up every primitive (all boards see
//! every primitive) and emits only the fragments of its own board's pixels, at most
//! `fragments_per_cycle` per cycle, in trace order.
//!
//! Rules: a primitive starts in a fresh cycle: its setup occupies `setup_cycles` cycles from
//! the first cycle after the last emission (or after the previous setup). Fragment `i` is
//! emitted in `a_i = max(earliest, slot)`, where `earliest` is the cycle of the previous
//! emission while it has emitted fewer than `fragments_per_cycle` fragments, else the next
//! cycle (and never before the primitive's setup ends), and `slot` is the cycle the target
//! Image Engine's FIFO has room ([`crate::blocks::image_engine`]): the generator blocks, in order,
//! while that FIFO is full.

pub struct FragmentGenerator {
    fragments_per_cycle: u32,
    setup_cycles: u64,
    /// No fragment is emitted before this cycle (the current primitive's setup end).
    start: u64,
    /// The cycle of the last emission and the fragments emitted in it.
    cycle: u64,
    in_cycle: u32,
    pub fragments: u64,
    /// Cycles with at least one emission.
    pub busy_cycles: u64,
    /// Cycles a ready fragment waited for room in its Image Engine's FIFO.
    pub stall_cycles: u64,
}

impl FragmentGenerator {
    pub fn new(fragments_per_cycle: u32, setup_cycles: u64) -> FragmentGenerator {
        FragmentGenerator {
            fragments_per_cycle,
            setup_cycles,
            start: 0,
            cycle: 0,
            in_cycle: 0,
            fragments: 0,
            busy_cycles: 0,
            stall_cycles: 0,
        }
    }

    /// The first cycle after everything emitted and set up so far.
    pub fn free_cycle(&self) -> u64 {
        if self.in_cycle > 0 {
            self.start.max(self.cycle + 1)
        } else {
            self.start.max(self.cycle)
        }
    }

    /// Nothing can start before `cycle` (the geometry stage has not delivered it yet).
    pub fn release(&mut self, cycle: u64) {
        self.start = self.start.max(cycle);
    }

    /// Set up a primitive.
    pub fn primitive(&mut self) {
        self.start = self.free_cycle() + self.setup_cycles;
    }

    /// Emit one fragment whose Image Engine FIFO has room from `slot`; returns the cycle.
    #[inline]
    pub fn emit(&mut self, slot: u64) -> u64 {
        let earliest = if self.in_cycle < self.fragments_per_cycle {
            self.start.max(self.cycle)
        } else {
            self.start.max(self.cycle + 1)
        };
        let emitted = earliest.max(slot);
        if emitted == self.cycle && self.in_cycle > 0 {
            self.in_cycle += 1;
        } else {
            self.stall_cycles += emitted - earliest;
            self.busy_cycles += 1;
            self.cycle = emitted;
            self.in_cycle = 1;
        }
        self.fragments += 1;
        emitted
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emits_up_to_the_rate_per_cycle_after_setup() {
        let mut fg = FragmentGenerator::new(2, 3);
        fg.primitive();
        let cycles: Vec<u64> = (0..5).map(|_| fg.emit(0)).collect();
        assert_eq!(cycles, [3, 3, 4, 4, 5]);
        assert_eq!(fg.free_cycle(), 6);
        fg.primitive();
        assert_eq!(
            fg.emit(0),
            9,
            "a new primitive starts in a fresh cycle after setup"
        );
        assert_eq!(fg.emit(12), 12, "blocked by a full FIFO until cycle 12");
        assert_eq!(fg.stall_cycles, 3);
    }
}
