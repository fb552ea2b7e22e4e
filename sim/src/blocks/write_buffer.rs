//! A posted-write buffer in front of the memory port (used for depth writes and for OccU
//! Control's records and hits).
//!
//! Rules: an entry may enter in cycle `t` if the entry `capacity` places earlier has been
//! granted the port by cycle `t` (see [`Fifo`]). An entry that entered in cycle `t` asks the
//! port from cycle `t + 1`; entries drain in order, as many in one cycle as fit the port's
//! budget, so an entry is never granted before the one ahead of it. An entry leaves the
//! buffer in its grant cycle.

use crate::blocks::fifo::Fifo;
use crate::blocks::memory_port::{MemoryPort, PortClient};

pub struct WriteBuffer {
    slots: Fifo,
    bits_per_entry: u32,
    client: PortClient,
    last_grant: u64,
    /// Distinct cycles in which this buffer was granted the port.
    pub grant_cycles: u64,
    pub entries_written: u64,
}

impl WriteBuffer {
    pub fn new(capacity: usize, bits_per_entry: u32, client: PortClient) -> WriteBuffer {
        WriteBuffer {
            slots: Fifo::new(capacity),
            bits_per_entry,
            client,
            last_grant: 0,
            grant_cycles: 0,
            entries_written: 0,
        }
    }

    /// The earliest cycle the next entry may enter.
    #[inline(always)]
    pub fn slot_free_cycle(&self) -> u64 {
        self.slots.slot_free_cycle()
    }

    /// The next entry enters in cycle `enter` (not before [`Self::slot_free_cycle`]).
    /// Returns its grant cycle on the port.
    #[inline]
    pub fn push(&mut self, enter: u64, port: &mut MemoryPort) -> u64 {
        self.push_entry(enter, enter + 1, self.bits_per_entry, port)
    }

    /// The next entry, of `bits`, enters in cycle `enter` and may be written from `ready`
    /// (at least `enter + 1`; later when its data comes from a read). Returns its grant.
    #[inline]
    pub fn push_entry(&mut self, enter: u64, ready: u64, bits: u32, port: &mut MemoryPort) -> u64 {
        debug_assert!(enter >= self.slot_free_cycle() && ready > enter);
        let grant = port.claim(ready.max(self.last_grant), bits, self.client);
        if grant != self.last_grant || self.entries_written == 0 {
            self.grant_cycles += 1;
        }
        self.last_grant = grant;
        self.entries_written += 1;
        self.slots.depart(grant);
        grant
    }

    /// The grant cycle of the last entry (0 before any).
    pub fn last_grant(&self) -> u64 {
        self.last_grant
    }
}
