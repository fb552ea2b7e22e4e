//! The sampled level (`sampled:K`): the cycle model on every K-th window, the rest
//! extrapolated.
//!
//! Windows are the runs of events between query ends ([`crate::fidelity`]): a query is the
//! unit whose latency the user asks about, and a frame of the demo holds hundreds of them, so
//! windows sample far more finely than frames would. Window `w` (from 0) is simulated when
//! `w % K == 0`.
//!
//! - Results: the functional model runs on every event, so every query's result is exact
//!   (and checked against the golden results in the stream).
//! - A simulated window starts a fresh O2 machine whose render state and depth buffer are
//!   the functional model's at the window's start (so its depth tests, hence its writes,
//!   hits and counts, are right), with empty FIFOs, an idle port and a cold prefetch (no
//!   last word or page).
//! - A simulated window's cost is the cycle its query's `end` entered the pipe (the next
//!   window's first fragment cannot be emitted earlier); the final window's cost is its
//!   machine's total cycles (it includes the drain). Its query's latency is the machine's.
//! - A skipped window's cost is `r · (F + setup · P)`, with `r` the ratio of measured cycles
//!   to rasterizer work `F + setup · P` summed over the simulated windows (final one
//!   excluded); a skipped query's latency is the mean latency of the simulated queries of
//!   the same mode (of all simulated queries when none has its mode).
//! - Bias: a fresh machine starts with an empty pipe, so it misses the backlog an earlier
//!   window may leave (the real pipe overlaps windows): costs and latencies err low after
//!   a window that ends backlogged; its cold prefetch makes the first read a page miss
//!   (errs high by at most one miss latency per window). `sampled:1` simulates every
//!   window, so its only error is this warm-up; on a stream of one window it equals `cycle`.

use crate::arch::Arch;
use crate::effects::Effects;
use crate::error::SimError;
use crate::fidelity::{FunctionalCore, LevelResult, SampledWindows};
use crate::o2::O2Machine;
use occsim_traces::{Event, QueryMode};

struct Window {
    fragments: u64,
    primitives: u64,
    /// The simulated machine, when this window is sampled.
    machine: Option<O2Machine>,
    /// The window's query ended; it closes before the next event that is not its result.
    query_ended: bool,
}

/// A skipped window, remembered until the extrapolation ratio is known.
struct Skipped {
    work: u64,
    /// The index (in the run's queries) and mode of its query, if it had one.
    query: Option<(usize, QueryMode)>,
}

pub struct SampledModel {
    arch: Arch,
    width: u32,
    height: u32,
    effects: Effects,
    every: u32,
    setup_cycles: u64,
    core: FunctionalCore,
    window: Window,
    windows: u64,
    simulated: u64,
    /// Σ measured cycles and Σ rasterizer work of the simulated, non-final windows.
    measured_cycles: u64,
    measured_work: u64,
    /// Σ cost of the simulated windows (final included).
    simulated_cycles: u64,
    skipped: Vec<Skipped>,
    /// Per query (in order): its latency if simulated.
    latencies: Vec<Option<u64>>,
}

impl SampledModel {
    pub fn new(
        arch: &Arch,
        width: u32,
        height: u32,
        effects: Effects,
        every: u32,
    ) -> Result<SampledModel, SimError> {
        let o2 = arch.o2()?;
        let mut model = SampledModel {
            arch: arch.clone(),
            width,
            height,
            effects,
            every: every.max(1),
            setup_cycles: o2.primitive_setup_cycles,
            core: FunctionalCore::new(width, height)?,
            window: Window {
                fragments: 0,
                primitives: 0,
                machine: None,
                query_ended: false,
            },
            windows: 0,
            simulated: 0,
            measured_cycles: 0,
            measured_work: 0,
            simulated_cycles: 0,
            skipped: Vec::new(),
            latencies: Vec::new(),
        };
        model.window.machine = model.start_machine()?;
        Ok(model)
    }

    /// A warm-started machine when the window about to start is sampled.
    fn start_machine(&self) -> Result<Option<O2Machine>, SimError> {
        if self.windows % self.every as u64 != 0 {
            return Ok(None);
        }
        let mut machine =
            O2Machine::with_effects(&self.arch, self.width, self.height, self.effects)?;
        machine.load_functional_state(
            self.core.functional.state(),
            self.core.functional.depth_buffer(),
        );
        Ok(Some(machine))
    }

    /// Feed one event.
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        if self.window.query_ended && !matches!(event, Event::QueryResult(_)) {
            self.close_window(false)?;
            self.window = Window {
                fragments: 0,
                primitives: 0,
                machine: self.start_machine()?,
                query_ended: false,
            };
        }
        match event {
            Event::Fragment(_) => self.window.fragments += 1,
            Event::Primitive => self.window.primitives += 1,
            Event::QueryEnd => self.window.query_ended = true,
            _ => {}
        }
        if let Some(machine) = &mut self.window.machine {
            machine.event(event)?;
        }
        if self.core.event(event)?.is_some() {
            self.latencies.push(None);
        }
        Ok(())
    }

    /// Close the current window: measure it or remember it for extrapolation.
    fn close_window(&mut self, last: bool) -> Result<(), SimError> {
        self.windows += 1;
        let work = self.window.fragments + self.setup_cycles * self.window.primitives;
        let query = self
            .window
            .query_ended
            .then(|| self.latencies.len() - 1)
            .map(|index| (index, self.core_mode(index)));
        match self.window.machine.take() {
            Some(machine) => {
                self.simulated += 1;
                let report = machine.finish()?;
                let ended = report.queries.last();
                if let (Some(q), Some((index, _))) = (ended, query) {
                    self.latencies[index] = Some(q.latency_cycles);
                }
                let cost = match ended {
                    Some(q) if !last => q.end_cycle,
                    _ => report.summary.cycles,
                };
                self.simulated_cycles += cost;
                if !last {
                    self.measured_cycles += cost;
                    self.measured_work += work;
                }
            }
            None => self.skipped.push(Skipped { work, query }),
        }
        Ok(())
    }

    fn core_mode(&self, index: usize) -> QueryMode {
        self.core.query_mode(index)
    }

    pub fn finish(mut self) -> Result<LevelResult, SimError> {
        self.close_window(true)?;
        let ratio = if self.measured_work == 0 {
            1.0
        } else {
            self.measured_cycles as f64 / self.measured_work as f64
        };
        let mean_latency =
            |mode: Option<QueryMode>, latencies: &[Option<u64>], modes: &[QueryMode]| {
                let pick: Vec<u64> = latencies
                    .iter()
                    .zip(modes)
                    .filter(|(_, m)| mode.map_or(true, |mode| **m == mode))
                    .filter_map(|(l, _)| *l)
                    .collect();
                (!pick.is_empty()).then(|| pick.iter().sum::<u64>() as f64 / pick.len() as f64)
            };
        let modes: Vec<QueryMode> = (0..self.latencies.len())
            .map(|index| self.core.query_mode(index))
            .collect();
        let mut total = self.simulated_cycles as f64;
        let last_window = self.windows - 1;
        let skipped_count = self.skipped.len();
        let mut filled = self.latencies.clone();
        for (position, skipped) in self.skipped.iter().enumerate() {
            total += ratio * skipped.work as f64;
            if let Some((index, mode)) = skipped.query {
                let latency = mean_latency(Some(mode), &self.latencies, &modes)
                    .or_else(|| mean_latency(None, &self.latencies, &modes))
                    .unwrap_or(crate::o2::MIN_QUERY_LATENCY_CYCLES as f64);
                filled[index] = Some(latency.round() as u64);
                // The final window's drain: its query's latency.
                if position + 1 == skipped_count && self.skipped_is_last(last_window) {
                    total += latency;
                }
            }
        }
        let windows = SampledWindows {
            simulated: self.simulated,
            total: self.windows,
        };
        let mut result = self.core.finish()?;
        for (query, latency) in result.queries.iter_mut().zip(filled) {
            query.latency_cycles = latency;
        }
        result.level = crate::fidelity::Fidelity::Sampled { every: self.every };
        result.effects = Some(self.effects);
        result.sampled_windows = Some(windows);
        result.set_timing(total.round() as u64);
        Ok(result)
    }

    /// Whether the final window was skipped (then it is the last entry of `skipped`).
    fn skipped_is_last(&self, last_window: u64) -> bool {
        last_window % self.every as u64 != 0
    }
}
