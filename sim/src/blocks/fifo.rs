//! A FIFO of fixed capacity, as the event-timestamp model sees it: only the cycles at which
//! its entries left matter.
//!
//! Rule: entry `n` may be written in cycle `t` only if entry `n - capacity` has left by
//! cycle `t` (an entry read in cycle `t` frees its slot for a write in the same cycle).
//! So the earliest write cycle of the next entry is the departure cycle of the entry
//! `capacity` places earlier, or 0 while fewer than `capacity` entries have passed.

/// Departure cycles of the last `capacity` entries of a FIFO (or any bounded buffer).
#[derive(Clone, Debug)]
pub struct Fifo {
    capacity: usize,
    /// Ring of departure cycles; its length is a power of two > capacity.
    departures: Vec<u64>,
    mask: usize,
    /// Entries that have left so far.
    count: usize,
}

impl Fifo {
    /// A FIFO of `capacity` entries; `capacity` >= 1.
    pub fn new(capacity: usize) -> Fifo {
        assert!(capacity >= 1, "a FIFO needs at least one entry");
        // Room for the last `2 * capacity` departures: a writer may run up to `capacity`
        // entries ahead of the departures recorded so far (see `slot_free_cycle_for`).
        let size = (2 * capacity + 1).next_power_of_two();
        Fifo {
            capacity,
            departures: vec![0; size],
            mask: size - 1,
            count: 0,
        }
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// The earliest cycle the next entry may be written: when the entry `capacity` places
    /// earlier left.
    #[inline(always)]
    pub fn slot_free_cycle(&self) -> u64 {
        if self.count < self.capacity {
            0
        } else {
            self.departures[(self.count - self.capacity) & self.mask]
        }
    }

    /// The earliest cycle entry `entry` may be written, when the departures recorded so far
    /// may lag behind the writes: entry `entry - capacity` must have departed already, and
    /// `entry` may be at most `capacity` ahead of the departures recorded.
    #[inline(always)]
    pub fn slot_free_cycle_for(&self, entry: usize) -> u64 {
        if entry < self.capacity {
            return 0;
        }
        debug_assert!(
            entry - self.capacity < self.count,
            "entry {entry} waits for an unrecorded departure"
        );
        debug_assert!(entry <= self.count + self.capacity);
        self.departures[(entry - self.capacity) & self.mask]
    }

    /// Record the departure cycle of the next entry, in entry order.
    #[inline(always)]
    pub fn depart(&mut self, cycle: u64) {
        self.departures[self.count & self.mask] = cycle;
        self.count += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_slot_frees_when_the_entry_capacity_places_earlier_leaves() {
        let mut fifo = Fifo::new(2);
        assert_eq!(fifo.slot_free_cycle(), 0);
        fifo.depart(5);
        assert_eq!(fifo.slot_free_cycle(), 0, "one entry gone, two slots");
        fifo.depart(7);
        assert_eq!(
            fifo.slot_free_cycle(),
            5,
            "third entry waits for the first to leave"
        );
        fifo.depart(9);
        assert_eq!(fifo.slot_free_cycle(), 7);
    }

    #[test]
    fn a_writer_ahead_of_the_departures_sees_the_right_entry() {
        let mut fifo = Fifo::new(3);
        for cycle in [10, 20, 30, 40] {
            fifo.depart(cycle);
        }
        // Entries 0..=3 departed; entry 6 waits for entry 3, entry 4 for entry 1.
        assert_eq!(fifo.slot_free_cycle_for(6), 40);
        assert_eq!(fifo.slot_free_cycle_for(4), 20);
        assert_eq!(fifo.slot_free_cycle_for(2), 0);
    }
}
