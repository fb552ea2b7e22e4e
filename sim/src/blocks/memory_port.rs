//! The one main-memory port: `bits_per_cycle` bits per cycle, shared by depth reads, depth
//! writes and OccU Control writes.
//!
//! Rule (what the RTL model must implement): the port is in-order. It grants requests one
//! after another in the machine's request order ([`crate::machines::o2`] defines it), each in the
//! first cycle that is at or after its ready cycle and at or after the previous grant's
//! cycle and in which its bits fit next to the bits already granted in that cycle. A request
//! never splits across cycles.
//!
//! Reserved cycles: the clients outside the pixel pipeline (the O2's display refresh and the
//! host) take a share `f` of the port's cycles, whole cycles in a fixed pattern: cycle `c`
//! is theirs when `floor((c + 1) f) > floor(c f)`, so every prefix of `n` cycles holds
//! `floor(n f)` of them, spread evenly. No request is granted in a reserved cycle; it goes
//! to the next free one. With `f = 0` no cycle is reserved.
//!
//! In-order service keeps the machine monotone: a request made earlier can never make a
//! later one wait longer, so speeding up any block never slows a query down.

use crate::timeline::{note, PortLane, State, Timeline, Track};

/// Who asked for port bandwidth (for statistics and the timeline's lanes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortClient {
    DepthRead,
    /// A drawn fragment's depth and colour writes (and a blend's colour read).
    DepthWrite,
    OccuControl,
    /// A clear's depth and colour words.
    Clear,
}

impl PortClient {
    fn lane(self) -> PortLane {
        match self {
            PortClient::DepthRead => PortLane::DepthReads,
            PortClient::DepthWrite => PortLane::DepthWrites,
            PortClient::OccuControl => PortLane::OccuControl,
            PortClient::Clear => PortLane::Clears,
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
    pub clear_transfers: u64,
    /// One past the last cycle with a transfer.
    pub end_cycle: u64,
    /// Cycles before `end_cycle` reserved for the display refresh and the host.
    pub reserved_cycles: u64,
}

pub struct MemoryPort {
    bits_per_cycle: u32,
    /// The share of cycles reserved for clients outside the pipeline (0: none).
    reserved_share: f64,
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
        MemoryPort::with_reserved_share(bits_per_cycle, 0.0)
    }

    /// A port whose cycles are a share `reserved_share` (in `0.0..1.0`) reserved.
    pub fn with_reserved_share(bits_per_cycle: u32, reserved_share: f64) -> MemoryPort {
        debug_assert!((0.0..1.0).contains(&reserved_share));
        let mut port = MemoryPort {
            bits_per_cycle,
            reserved_share,
            cycle: 0,
            cycle_bits: 0,
            stats: PortStats::default(),
            timeline: None,
        };
        port.cycle = port.first_free(0);
        port
    }

    /// Whether cycle `c` belongs to the reserved clients.
    #[inline(always)]
    fn is_reserved(&self, c: u64) -> bool {
        self.reserved_share > 0.0 && self.reserved_before(c + 1) > self.reserved_before(c)
    }

    /// Reserved cycles among `0..n`: `floor(n f)`.
    #[inline(always)]
    fn reserved_before(&self, n: u64) -> u64 {
        // The product is never negative, so the cast's truncation is the floor (without a
        // call to libm's `floor` on every grant).
        (n as f64 * self.reserved_share) as u64
    }

    /// The first cycle at or after `c` that is not reserved.
    #[inline(always)]
    fn first_free(&self, mut c: u64) -> u64 {
        while self.is_reserved(c) {
            c += 1;
        }
        c
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
            self.cycle = self.first_free(ready.max(self.cycle + 1));
        }
        self.cycle_bits += bits;
        self.stats.bits_transferred += bits as u64;
        match client {
            PortClient::DepthRead => self.stats.depth_read_transfers += 1,
            PortClient::DepthWrite => self.stats.depth_write_transfers += 1,
            PortClient::OccuControl => self.stats.occu_transfers += 1,
            PortClient::Clear => self.stats.clear_transfers += 1,
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
        self.stats.reserved_cycles = self.reserved_before(self.stats.end_cycle);
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reserved_cycles_carry_nothing_else_and_spread_evenly() {
        // A quarter reserved: floor((c + 1) / 4) > floor(c / 4) for c = 3, 7, 11, ...
        let mut port = MemoryPort::with_reserved_share(256, 0.25);
        let grants: Vec<u64> = (0..9)
            .map(|_| port.claim(0, 256, PortClient::DepthRead))
            .collect();
        assert_eq!(grants, [0, 1, 2, 4, 5, 6, 8, 9, 10]);
        // Ready in a reserved cycle: the next free one. Smaller words still pack.
        assert_eq!(port.claim(15, 128, PortClient::DepthWrite), 16);
        assert_eq!(port.claim(15, 128, PortClient::DepthWrite), 16);
        let stats = port.finish();
        assert!(stats.max_bits_in_one_cycle <= 256);
        // Cycles 0..17 hold floor(17 / 4) = 4 reserved ones (3, 7, 11, 15).
        assert_eq!((stats.end_cycle, stats.reserved_cycles), (17, 4));
        assert_eq!(stats.busy_cycles + stats.reserved_cycles, 10 + 4);
        // No share: the plain port.
        let mut plain = MemoryPort::with_reserved_share(256, 0.0);
        assert_eq!(plain.claim(3, 256, PortClient::Clear), 3);
        assert_eq!(plain.claim(0, 256, PortClient::Clear), 4);
    }

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
