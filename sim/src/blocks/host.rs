//! The host CPU: the culling traversal and the GL driver (and, on the O2, the software
//! geometry, [`crate::blocks::geometry`]) on one timeline, counted in pipeline cycles.
//!
//! Rules: the host does one thing at a time, in trace order. Work of `n` units at `c` host
//! cycles each costs `round(n * c * pipeline_mhz / host_mhz)` pipeline cycles of busy time.
//! The host blocks (time passes, nothing is done) while it waits for a query's result and,
//! at a frame's end, for the pipeline to finish the frame. Busy, waiting and pipe-wait
//! cycles sum to the host's time.

use crate::timeline::{note, State, Timeline, Track};
use occsim_traces::HostWork;

/// Host costs per unit of work, in pipeline cycles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HostCosts {
    pub node: f64,
    pub box_test: f64,
    pub decision: f64,
    pub draw: f64,
    pub readback_pixel: f64,
    pub state_change: f64,
}

impl HostCosts {
    /// Costs given in host cycles (per node, box test, decision, draw, read-back pixel and
    /// state change), on a host at `host_mhz` feeding a pipeline at `pipe_mhz`.
    pub fn from_host_cycles(host_mhz: f64, pipe_mhz: f64, cycles: [u64; 6]) -> HostCosts {
        let scale = pipe_mhz / host_mhz;
        let [node, box_test, decision, draw, readback_pixel, state_change] =
            cycles.map(|c| c as f64 * scale);
        HostCosts {
            node,
            box_test,
            decision,
            draw,
            readback_pixel,
            state_change,
        }
    }
}

/// The most cycles a simulated clock may reach (2^62): the host's clock stops there, and a
/// replay whose time reaches it is refused ([`crate::SimError::TimeOverflow`]) rather than
/// reported, its sums past the range of a cycle count. Only parameters at the far ends of
/// their ranges together get there (a host clock of 0.001 MHz against a pipe of 20 GHz, 2^24
/// host cycles a vertex).
pub const MAX_SIMULATED_CYCLES: u64 = 1 << 62;

/// `units` at `each` pipeline cycles, rounded to whole cycles (at most
/// [`MAX_SIMULATED_CYCLES`]).
pub fn cost(units: u64, each: f64) -> u64 {
    ((units as f64 * each).round() as u64).min(MAX_SIMULATED_CYCLES)
}

pub struct Host {
    costs: HostCosts,
    /// The first cycle the host is free.
    now: u64,
    pub busy_cycles: u64,
    /// Cycles blocked on query results.
    pub waiting_cycles: u64,
    /// Cycles blocked at frame ends on the pipeline.
    pub pipe_wait_cycles: u64,
    /// Where the host's busy and waiting intervals go, if anywhere.
    pub timeline: Option<Timeline>,
}

impl Host {
    pub fn new(costs: HostCosts) -> Host {
        Host {
            costs,
            now: 0,
            busy_cycles: 0,
            waiting_cycles: 0,
            pipe_wait_cycles: 0,
            timeline: None,
        }
    }

    pub fn now(&self) -> u64 {
        self.now
    }

    /// Take up at `now` (a machine started mid-stream takes its host's clock from the
    /// analytic level's; the counters stay the machine's own).
    pub fn resume_at(&mut self, now: u64) {
        self.now = now;
    }

    /// Spend `cycles` busy.
    pub fn spend(&mut self, cycles: u64) {
        note(
            &self.timeline,
            Track::Host,
            State::Busy,
            self.now,
            self.now.saturating_add(cycles),
        );
        self.now = self.now.saturating_add(cycles).min(MAX_SIMULATED_CYCLES);
        self.busy_cycles = self.busy_cycles.saturating_add(cycles);
    }

    /// The traversal's work.
    pub fn work(&mut self, work: &HostWork) {
        let c = self.costs;
        self.spend(
            cost(work.nodes as u64, c.node)
                + cost(work.boxes as u64, c.box_test)
                + cost(work.decisions as u64, c.decision)
                + cost(work.pixels as u64, c.readback_pixel),
        );
    }

    /// The driver's work for one draw call.
    pub fn draw(&mut self) {
        self.spend(cost(1, self.costs.draw));
    }

    /// The driver's work for `count` state changes (clears, query begins and ends).
    pub fn state_changes(&mut self, count: u64) {
        self.spend(cost(count, self.costs.state_change));
    }

    /// Block until `cycle` for a query result.
    pub fn wait_for_result(&mut self, cycle: u64) {
        if cycle > self.now {
            let waiting = State::WaitingForResult;
            note(&self.timeline, Track::Host, waiting, self.now, cycle);
            self.waiting_cycles += cycle - self.now;
            self.now = cycle;
        }
    }

    /// Block until `cycle` for the pipeline to finish a frame.
    pub fn wait_for_pipe(&mut self, cycle: u64) {
        if cycle > self.now {
            let waiting = State::WaitingAtFrameEnd;
            note(&self.timeline, Track::Host, waiting, self.now, cycle);
            self.pipe_wait_cycles += cycle - self.now;
            self.now = cycle;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn costs_scale_by_the_clock_ratio_and_round() {
        // A 200 MHz host feeding a 100 MHz pipeline: a host cycle is half a pipeline cycle.
        let costs = HostCosts::from_host_cycles(200.0, 100.0, [3, 10, 1, 1000, 4, 0]);
        let mut host = Host::new(costs);
        // 5 nodes * 1.5 = 7.5 -> 8; 2 boxes * 5 = 10; 3 decisions * 0.5 = 1.5 -> 2; 5
        // pixels * 2 = 10.
        host.work(&HostWork {
            nodes: 5,
            boxes: 2,
            decisions: 3,
            pixels: 5,
        });
        assert_eq!(host.now(), 30);
        host.draw();
        assert_eq!(host.now(), 530);
        host.wait_for_result(500);
        assert_eq!(
            (host.now(), host.waiting_cycles),
            (530, 0),
            "no wait into the past"
        );
        host.wait_for_result(600);
        host.wait_for_pipe(650);
        assert_eq!(
            (host.busy_cycles, host.waiting_cycles, host.pipe_wait_cycles),
            (530, 70, 50)
        );
        assert_eq!(
            host.busy_cycles + host.waiting_cycles + host.pipe_wait_cycles,
            host.now()
        );
    }
}
