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
        let size = (capacity + 1).next_power_of_two();
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
}
