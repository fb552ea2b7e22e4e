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
    /// Ring of departure cycles. It grows with the departures (doubling while none has
    /// wrapped) up to `full_size`, so memory follows use, not capacity.
    departures: Vec<u64>,
    mask: usize,
    /// The ring's final length: a power of two > 2 * capacity.
    full_size: usize,
    /// Entries that have left so far.
    count: usize,
}

/// The ring's first length: enough for the FIFOs of the built-in machines at once.
const FIRST_RING: usize = 64;

impl Fifo {
    /// A FIFO of `capacity` entries; `capacity` >= 1.
    pub fn new(capacity: usize) -> Fifo {
        assert!(capacity >= 1, "a FIFO needs at least one entry");
        // Room for the last `2 * capacity` departures: a writer may run up to `capacity`
        // entries ahead of the departures recorded so far (see `slot_free_cycle_for`).
        let full_size = (2 * capacity + 1).next_power_of_two();
        let size = full_size.min(FIRST_RING);
        Fifo {
            capacity,
            departures: vec![0; size],
            mask: size - 1,
            full_size,
            count: 0,
        }
    }

    /// Ring entries allocated now (what the FIFO's memory follows).
    pub fn allocated_entries(&self) -> usize {
        self.departures.len()
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
        if self.count == self.departures.len() && self.count < self.full_size {
            self.grow();
        }
        self.departures[self.count & self.mask] = cycle;
        self.count += 1;
    }

    /// The earliest cycle the entry `ahead` places after the next may be written, from the
    /// departures recorded so far (`ahead` < capacity).
    #[inline(always)]
    pub fn slot_free_cycle_ahead(&self, ahead: usize) -> u64 {
        debug_assert!(ahead < self.capacity);
        match (self.count + ahead).checked_sub(self.capacity) {
            Some(entry) => self.departures[entry & self.mask],
            None => 0,
        }
    }

    /// Record `count` departures in cycles `first`, `first + 1`, ... (a fast-forward): what
    /// `count` calls of [`Self::depart`] leave in the ring.
    #[inline]
    pub fn depart_run(&mut self, first: u64, count: usize) {
        // Grow first as `depart` would on the way (only before the ring wraps), then write
        // the run's last `capacity` straight into it: a writer reads no departure from
        // further back (see `slot_free_cycle_for`).
        while self.departures.len() < self.full_size && self.count + count > self.departures.len() {
            self.grow();
        }
        let kept = count.min(self.capacity);
        let skipped = count - kept;
        let (start, mask) = (self.count + skipped, self.mask);
        for (n, cycle) in (first + skipped as u64..).take(kept).enumerate() {
            self.departures[(start + n) & mask] = cycle;
        }
        self.count += count;
    }

    /// Double the ring. Called only before any departure wrapped around it, so entry `n`
    /// sits at index `n` and stays there.
    #[cold]
    fn grow(&mut self) {
        let size = (self.departures.len() * 2).min(self.full_size);
        self.departures.resize(size, 0);
        self.mask = size - 1;
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
    fn memory_follows_use_not_capacity() {
        // A FIFO of a million entries that ten entries pass holds a small ring; the ring
        // grows with the departures, and gives the answers a full-sized one would.
        let mut big = Fifo::new(1 << 20);
        assert!(
            big.allocated_entries() <= FIRST_RING,
            "{}",
            big.allocated_entries()
        );
        for cycle in 0..10 {
            big.depart(cycle);
        }
        assert!(big.allocated_entries() <= FIRST_RING);
        for capacity in [1, 3, 40, 100, 1000] {
            let mut fifo = Fifo::new(capacity);
            let departures: Vec<u64> = (0..5000u64).map(|i| i * 3 + i % 7).collect();
            for (n, &cycle) in departures.iter().enumerate() {
                // Entry n waits for entry n - capacity (0 for the first `capacity`).
                let expected = |entry: usize| {
                    if entry < capacity {
                        0
                    } else {
                        departures[entry - capacity]
                    }
                };
                assert_eq!(
                    fifo.slot_free_cycle(),
                    expected(n),
                    "capacity {capacity}, n {n}"
                );
                if n > 0 {
                    // The farthest a writer may run ahead: entry n - 1 + capacity.
                    let ahead = n - 1 + capacity;
                    assert_eq!(fifo.slot_free_cycle_for(ahead), expected(ahead));
                }
                fifo.depart(cycle);
            }
            assert!(fifo.allocated_entries() <= (2 * capacity + 1).next_power_of_two());
        }
    }

    #[test]
    fn a_run_of_departures_leaves_what_they_one_by_one_leave() {
        for (capacity, before, run) in [
            (1, 0, 5),
            (3, 2, 1),
            (16, 10, 200),
            (40, 0, 30),
            (40, 70, 3),
        ] {
            let (mut one_by_one, mut at_once) = (Fifo::new(capacity), Fifo::new(capacity));
            for cycle in 0..before as u64 {
                one_by_one.depart(cycle * 2);
                at_once.depart(cycle * 2);
            }
            for n in 0..run as u64 {
                one_by_one.depart(1000 + n);
            }
            at_once.depart_run(1000, run);
            for ahead in 0..capacity {
                assert_eq!(
                    at_once.slot_free_cycle_ahead(ahead),
                    one_by_one.slot_free_cycle_ahead(ahead),
                    "capacity {capacity}, {before} then {run}, {ahead} ahead"
                );
            }
            assert_eq!(at_once.allocated_entries(), one_by_one.allocated_entries());
        }
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
