//! The one main-memory port: `bits_per_cycle` bits per cycle, shared by depth reads, depth
//! writes and OccU Control writes.
//!
//! Rule (what the RTL model must implement): the port is in-order. It grants requests one
//! after another in the machine's request order ([`crate::machines::o2`] defines it), each in the
//! first cycle that is at or after its ready cycle and at or after the previous grant's
//! cycle and in which its bits fit next to the bits already granted in that cycle. A request
//! never splits across cycles.
//!
//! The other clients: the display refresh and the host (the O2's unified memory) need a
//! share `f` of the port's cycles, `f` a cycle, and may fall behind that need by at most
//! `slack` cycles (the display's scan-out FIFO, the host's queued misses). They take every
//! cycle the pipeline leaves idle while they are behind, and a cycle by force when the
//! pipeline's request would leave them more than `slack` behind. Cycle by cycle, with the
//! debt `δ` (cycles of their need not yet served) at 0 from the start:
//!
//! ```text
//! δ' = δ + f
//! the pipeline takes cycle c  when it asks for it and δ' <= slack:  δ = δ'
//! the other clients take c    otherwise:                            δ = max(0, δ' - 1)
//! ```
//!
//! (`f` and `δ` in fixed point, 2^-32 of a cycle, so every run gives the same cycles.) A
//! cycle is *forced* when the pipeline asked for it and lost it. With `f = 0` the port is
//! the plain one.
//!
//! Why a debt and not a fixed pattern of reserved cycles: the pattern's phase runs from
//! cycle 0, so which of a query's last reads meet a reserved cycle hangs on the cycle the
//! query comes in, which nothing local to the query tells; the debt forgets its past in
//! any stretch where the port idles more than `f` of its cycles, as real arbiters with
//! FIFOs do, and a machine started mid-trace (the sampled level) meets the same port as
//! one that ran from the start once it has.
//!
//! In-order service keeps the machine monotone: a request made earlier can never make a
//! later one wait longer (an earlier grant moves an idle cycle later, which serves the debt
//! no less), so speeding up any block never slows a query down.

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
    /// Port cycles the display refresh and the host were served before `end_cycle`, in
    /// whole cycles (their need, `f` a cycle, less what they are still owed).
    pub reserved_cycles: u64,
    /// Cycles the pipeline asked for and the display refresh and the host took by force.
    pub forced_cycles: u64,
}

/// One cycle in the fixed point of the other clients' share and debt.
const CYCLE_UNITS: u64 = 1 << 32;

pub struct MemoryPort {
    bits_per_cycle: u32,
    /// `f`, the other clients' share, in [`CYCLE_UNITS`] a cycle (0: none).
    share_units: u64,
    /// How far they may fall behind, in [`CYCLE_UNITS`].
    slack_units: u64,
    /// `δ`, what they are owed at the start of cycle `settled`, in [`CYCLE_UNITS`].
    debt_units: u64,
    /// The first cycle not yet settled between the pipeline and the other clients.
    settled: u64,
    /// The cycle of the last grant (meaningful once `settled > 0`).
    cycle: u64,
    /// Bits granted so far in `cycle`.
    cycle_bits: u32,
    stats: PortStats,
    /// Where each grant's cycle goes, if anywhere (a lane a client).
    timeline: Option<Timeline>,
}

impl MemoryPort {
    pub fn new(bits_per_cycle: u32) -> MemoryPort {
        MemoryPort::with_other_clients(bits_per_cycle, 0.0, 0)
    }

    /// A port whose other clients need `share` (in `0.0..1.0`) of its cycles and may fall
    /// `slack_cycles` behind (see the module docs).
    pub fn with_other_clients(bits_per_cycle: u32, share: f64, slack_cycles: u32) -> MemoryPort {
        debug_assert!((0.0..1.0).contains(&share));
        MemoryPort {
            bits_per_cycle,
            share_units: (share * CYCLE_UNITS as f64).round() as u64,
            // At least a cycle: with none, every cycle would be owed to them.
            slack_units: slack_cycles.max(1) as u64 * CYCLE_UNITS,
            debt_units: 0,
            settled: 0,
            cycle: 0,
            cycle_bits: 0,
            stats: PortStats::default(),
            timeline: None,
        }
    }

    /// Settle cycles from `settled` on: the idle ones before `c` go to the other clients,
    /// then every cycle they take by force. Returns the cycle the pipeline gets.
    #[inline(always)]
    fn grant_from(&mut self, c: u64) -> u64 {
        // An idle cycle takes `1 - f` off the debt, down to 0.
        let idle = c - self.settled;
        let served = idle.saturating_mul(CYCLE_UNITS - self.share_units);
        self.debt_units = self.debt_units.saturating_sub(served);
        let mut c = c;
        loop {
            let owed = self.debt_units + self.share_units;
            if owed <= self.slack_units {
                self.debt_units = owed;
                self.settled = c + 1;
                return c;
            }
            self.debt_units = owed.saturating_sub(CYCLE_UNITS);
            self.stats.forced_cycles += 1;
            c += 1;
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
        let open = self.cycle_bits > 0;
        if !open || ready > self.cycle || self.cycle_bits + bits > self.bits_per_cycle {
            self.close_cycle();
            self.cycle = self.grant_from(ready.max(self.settled));
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
        // Every cycle before `settled` (= `end_cycle`) added `f` to what the other clients
        // need; what they are still owed was not served.
        let need = self.settled as u128 * self.share_units as u128;
        let served = need - self.debt_units as u128;
        self.stats.reserved_cycles = (served / CYCLE_UNITS as u128) as u64;
        self.stats
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_other_clients_take_idle_cycles_and_force_one_when_too_far_behind() {
        // f = 1/4, slack 1 cycle, every request a full word ready at 0. The debt after
        // cycles 0..3 is 1/4, 1/2, 3/4, 1 (never above the slack: the pipeline's); in 4 it
        // would be 5/4, so 4 is forced (debt 1/4); 5..7 take it to 1 again and 8 is forced.
        let mut port = MemoryPort::with_other_clients(256, 0.25, 1);
        let grants: Vec<u64> = (0..9)
            .map(|_| port.claim(0, 256, PortClient::DepthRead))
            .collect();
        assert_eq!(grants, [0, 1, 2, 3, 5, 6, 7, 9, 10]);
        // Debt 3/4 after 10. Idle 11..19 serve it (3/4 a cycle: down to 0), so a request
        // ready in 20 has it (debt 1/4), and smaller words still pack; a full word then
        // goes to 21 (debt 1/2).
        assert_eq!(port.claim(20, 128, PortClient::DepthWrite), 20);
        assert_eq!(port.claim(20, 128, PortClient::DepthWrite), 20);
        assert_eq!(port.claim(20, 256, PortClient::DepthWrite), 21);
        let stats = port.finish();
        assert!(stats.max_bits_in_one_cycle <= 256);
        // Cycles 0..22 need 22/4 = 5.5; 1/2 still owed: 5 served (4 and 8 by force, and
        // the idle cycles 11..19 the 3 = 3/4 + 9/4 owed over them).
        assert_eq!(
            (stats.end_cycle, stats.reserved_cycles, stats.forced_cycles),
            (22, 5, 2)
        );
        assert_eq!(stats.busy_cycles, 11);
        // No share: the plain port.
        let mut plain = MemoryPort::with_other_clients(256, 0.0, 1);
        assert_eq!(plain.claim(3, 256, PortClient::Clear), 3);
        assert_eq!(plain.claim(0, 256, PortClient::Clear), 4);
    }

    #[test]
    fn a_request_that_comes_later_meets_the_same_port_once_the_debt_is_paid() {
        // The port forgets its past: after an idle stretch long enough to serve the debt,
        // a burst takes the same cycles relative to its start whatever came before it.
        let burst = |port: &mut MemoryPort, from: u64| -> Vec<u64> {
            (0..12)
                .map(|_| port.claim(from, 256, PortClient::DepthRead) - from)
                .collect()
        };
        let mut fresh = MemoryPort::with_other_clients(256, 0.3, 2);
        let mut busy = MemoryPort::with_other_clients(256, 0.3, 2);
        for _ in 0..37 {
            busy.claim(0, 256, PortClient::DepthWrite);
        }
        // At most 2 owed; 0.7 paid an idle cycle: 3 idle cycles pay it (100 is plenty).
        let from = busy.last_grant_end() + 100;
        assert_eq!(burst(&mut fresh, 1_000), burst(&mut busy, from));
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
