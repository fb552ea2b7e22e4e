//! The one main-memory port: `bits_per_cycle` bits per cycle, shared by depth reads, depth
//! writes and OccU Control writes.
//!
//! Rule (what the RTL model must implement): the port is in-order. It grants requests one
//! after another in the machine's request order ([`crate::machines::o2`] defines it), each in the
//! first cycle that is at or after its ready cycle and at or after the previous grant's
//! cycle and in which its bits fit next to the bits already granted in that cycle. A request
//! never splits across cycles.
//!
//! In-order service keeps the machine monotone: a request made earlier can never make a
//! later one wait longer, so speeding up any block never slows a query down.

use crate::timeline::{note, PortLane, State, Timeline, Track};

/// Who asked for port bandwidth (for statistics and the timeline's lanes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortClient {
    DepthRead,
    DepthWrite,
    OccuControl,
}

impl PortClient {
    fn lane(self) -> PortLane {
        match self {
            PortClient::DepthRead => PortLane::DepthReads,
            PortClient::DepthWrite => PortLane::DepthWrites,
            PortClient::OccuControl => PortLane::OccuControl,
        }
    }
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
    /// The cycle of the last grant.
    cycle: u64,
    /// Bits granted so far in `cycle`.
    cycle_bits: u32,
    stats: PortStats,
    /// Where each grant's cycle goes, if anywhere (a lane a client).
    timeline: Option<Timeline>,
}

impl MemoryPort {
    pub fn new(bits_per_cycle: u32) -> MemoryPort {
        MemoryPort {
            bits_per_cycle,
            cycle: 0,
            cycle_bits: 0,
            stats: PortStats::default(),
            timeline: None,
        }
    }

    /// Report every grant's cycle to `timeline`, on its client's lane.
    pub fn set_timeline(&mut self, timeline: Option<Timeline>) {
        self.timeline = timeline;
    }

    pub fn bits_per_cycle(&self) -> u32 {
        self.bits_per_cycle
    }

    /// Grant the next request in order: `bits` (at most the port width) ready from `ready`.
    /// Returns the cycle of the transfer.
    #[inline]
    pub fn claim(&mut self, ready: u64, bits: u32, client: PortClient) -> u64 {
        debug_assert!(bits <= self.bits_per_cycle);
        if ready > self.cycle || self.cycle_bits + bits > self.bits_per_cycle {
            self.close_cycle();
            self.cycle = ready.max(self.cycle + 1);
        }
        self.cycle_bits += bits;
        self.stats.bits_transferred += bits as u64;
        match client {
            PortClient::DepthRead => self.stats.depth_read_transfers += 1,
            PortClient::DepthWrite => self.stats.depth_write_transfers += 1,
            PortClient::OccuControl => self.stats.occu_transfers += 1,
        }
        let lane = Track::MemoryPort(client.lane());
        note(
            &self.timeline,
            lane,
            State::Busy,
            self.cycle,
            self.cycle + 1,
        );
        self.cycle
    }

    fn close_cycle(&mut self) {
        if self.cycle_bits > 0 {
            self.stats.busy_cycles += 1;
            self.stats.max_bits_in_one_cycle =
                self.stats.max_bits_in_one_cycle.max(self.cycle_bits);
            self.stats.end_cycle = self.cycle + 1;
        }
        self.cycle_bits = 0;
    }

    /// The first cycle after every transfer granted so far.
    pub fn last_grant_end(&self) -> u64 {
        if self.cycle_bits > 0 {
            self.cycle + 1
        } else {
            self.stats.end_cycle
        }
    }

    /// Close the last cycle and return the statistics.
    pub fn finish(mut self) -> PortStats {
        self.close_cycle();
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packs_requests_in_order_and_never_goes_back() {
        let mut port = MemoryPort::new(256);
        assert_eq!(port.claim(3, 32, PortClient::DepthWrite), 3);
        // A full word no longer fits in cycle 3.
        assert_eq!(port.claim(3, 256, PortClient::DepthRead), 4);
        // In order: a request ready in 2 still comes after the grant in 4; cycle 4 is full.
        assert_eq!(port.claim(2, 32, PortClient::OccuControl), 5);
        // Seven more words fill cycle 5; the next goes to 6.
        for _ in 0..7 {
            assert_eq!(port.claim(0, 32, PortClient::OccuControl), 5);
        }
        assert_eq!(port.claim(0, 32, PortClient::OccuControl), 6);
        assert_eq!(port.claim(9, 64, PortClient::DepthWrite), 9);
        let stats = port.finish();
        assert_eq!(stats.busy_cycles, 5);
        assert_eq!(stats.bits_transferred, 32 + 256 + 32 * 9 + 64);
        assert_eq!(stats.max_bits_in_one_cycle, 256);
        assert_eq!(stats.end_cycle, 10);
        assert_eq!(
            (
                stats.depth_read_transfers,
                stats.depth_write_transfers,
                stats.occu_transfers
            ),
            (1, 2, 9)
        );
    }
}
