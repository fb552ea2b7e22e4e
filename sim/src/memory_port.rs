//! The one main-memory port: `bits_per_cycle` bits per cycle, shared by depth reads, depth
//! writes and OccU Control writes.
//!
//! Arbitration rule (what the RTL model must implement): every cycle the port looks at the
//! requests that are ready, oldest first, and grants each one whose bits still fit into
//! what is left of the cycle's budget; a request that does not fit waits for a later cycle
//! while younger requests that fit go ahead. Age is trace order: the fragment (or query
//! end) that caused the request; within one fragment, depth read before depth write before
//! OccU words. A request never splits across cycles.
//!
//! The model keeps a calendar of bits used per cycle. Requests are claimed in age order and
//! each takes the first cycle at or after its ready cycle with room, which is exactly what
//! the oldest-first arbiter grants, because no request's ready cycle depends on a younger one.

use std::collections::VecDeque;

/// Who asked for port bandwidth (for statistics).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortClient {
    DepthRead,
    DepthWrite,
    OccuControl,
}

/// Port statistics.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PortStats {
    /// Cycles in which the port carried at least one transfer.
    pub busy_cycles: u64,
    pub bits_transferred: u64,
    /// The most bits carried in any one cycle.
    pub max_bits_in_one_cycle: u32,
    pub depth_read_transfers: u64,
    pub depth_write_transfers: u64,
    pub occu_transfers: u64,
    /// One past the last cycle with a transfer.
    pub end_cycle: u64,
}

pub struct MemoryPort {
    bits_per_cycle: u32,
    /// Cycle of `used[0]`; every cycle before it is closed.
    base: u64,
    /// Bits granted per cycle from `base` on.
    used: VecDeque<u32>,
    stats: PortStats,
}

impl MemoryPort {
    pub fn new(bits_per_cycle: u32) -> MemoryPort {
        MemoryPort {
            bits_per_cycle,
            base: 0,
            used: VecDeque::new(),
            stats: PortStats::default(),
        }
    }

    pub fn bits_per_cycle(&self) -> u32 {
        self.bits_per_cycle
    }

    /// Grant `bits` (at most the port width) in the first cycle at or after `ready` with room.
    /// Returns the cycle of the transfer.
    #[inline]
    pub fn claim(&mut self, ready: u64, bits: u32, client: PortClient) -> u64 {
        debug_assert!(bits <= self.bits_per_cycle);
        let mut cycle = ready.max(self.base);
        loop {
            let index = (cycle - self.base) as usize;
            if index >= self.used.len() {
                self.used.resize(index + 1, 0);
            }
            let slot = &mut self.used[index];
            if *slot + bits <= self.bits_per_cycle {
                *slot += bits;
                break;
            }
            cycle += 1;
        }
        self.stats.bits_transferred += bits as u64;
        self.stats.end_cycle = self.stats.end_cycle.max(cycle + 1);
        match client {
            PortClient::DepthRead => self.stats.depth_read_transfers += 1,
            PortClient::DepthWrite => self.stats.depth_write_transfers += 1,
            PortClient::OccuControl => self.stats.occu_transfers += 1,
        }
        cycle
    }

    /// Promise that no request will be ready before `cycle`: earlier cycles are closed and
    /// folded into the statistics (keeps the calendar short).
    #[inline]
    pub fn close_before(&mut self, cycle: u64) {
        while self.base < cycle {
            match self.used.pop_front() {
                Some(bits) => self.account(bits),
                None => {
                    self.base = cycle;
                    return;
                }
            }
            self.base += 1;
        }
    }

    fn account(&mut self, bits: u32) {
        if bits > 0 {
            self.stats.busy_cycles += 1;
            self.stats.max_bits_in_one_cycle = self.stats.max_bits_in_one_cycle.max(bits);
        }
    }

    /// Close every cycle and return the statistics.
    pub fn finish(mut self) -> PortStats {
        while let Some(bits) = self.used.pop_front() {
            self.account(bits);
        }
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packs_small_requests_and_lets_younger_ones_fit_where_older_do_not() {
        let mut port = MemoryPort::new(256);
        assert_eq!(port.claim(3, 32, PortClient::DepthWrite), 3);
        // A full word no longer fits in cycle 3.
        assert_eq!(port.claim(3, 256, PortClient::DepthRead), 4);
        // Seven more 32-bit words fill cycle 3; the eighth goes to 5 (4 is full).
        for _ in 0..7 {
            assert_eq!(port.claim(3, 32, PortClient::OccuControl), 3);
        }
        assert_eq!(port.claim(3, 32, PortClient::OccuControl), 5);
        let stats = port.finish();
        assert_eq!(stats.busy_cycles, 3);
        assert_eq!(stats.bits_transferred, 256 * 2 + 32);
        assert_eq!(stats.max_bits_in_one_cycle, 256);
        assert_eq!(stats.end_cycle, 6);
    }

    #[test]
    fn closed_cycles_are_not_granted() {
        let mut port = MemoryPort::new(256);
        port.close_before(10);
        assert_eq!(port.claim(2, 256, PortClient::DepthRead), 10);
    }
}
