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
//! - A skipped window's cost is `r_c · work`, with `work = max(F + setup · P, Σ s)` (the
//!   rasterizer's and the OccU's cycles: `s` = OccU cycles per fragment of the open query)
//!   and `r_c` the ratio of measured cycles to work summed over the simulated (non-final)
//!   windows of its class `c` = (its query's mode, `s`), or over all simulated windows when
//!   none is of its class. A skipped query's latency is the mean latency of the simulated
//!   queries of its class, else of its mode, else of all.
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
    /// OccU cycles: Σ over fragments of the open query's cycles per fragment (1 outside).
    occu_cycles: u64,
    /// OccU cycles per fragment of the open query (None: no query open).
    service: Option<u64>,
    /// The window's class: its query's mode code and OccU cycles per fragment.
    class: Option<(u8, u64)>,
    /// The simulated machine, when this window is sampled.
    machine: Option<O2Machine>,
    /// The window's query ended; it closes before the next event that is not its result.
    query_ended: bool,
}

/// Extrapolation classes: (query mode code, OccU cycles per fragment) of a window's query.
type Class = Option<(u8, u64)>;

impl Window {
    fn empty(machine: Option<O2Machine>) -> Window {
        Window {
            fragments: 0,
            primitives: 0,
            occu_cycles: 0,
            service: None,
            class: None,
            machine,
            query_ended: false,
        }
    }
}

/// A skipped window, remembered until the extrapolation ratio is known.
struct Skipped {
    work: u64,
    class: Class,
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
    engines: u64,
    all_tiles_one_cycle: bool,
    core: FunctionalCore,
    window: Window,
    windows: u64,
    simulated: u64,
    /// Σ measured cycles and Σ work of the simulated, non-final windows, in all and per
    /// class.
    measured_cycles: u64,
    measured_work: u64,
    measured_by_class: std::collections::BTreeMap<Class, (u64, u64)>,
    /// Per class: Σ latency and count of its simulated queries.
    latency_by_class: std::collections::BTreeMap<Class, (u64, u64)>,
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
            engines: o2.engines as u64,
            all_tiles_one_cycle: o2.all_tiles_one_cycle,
            core: FunctionalCore::new(width, height)?,
            window: Window::empty(None),
            windows: 0,
            simulated: 0,
            measured_cycles: 0,
            measured_work: 0,
            measured_by_class: Default::default(),
            latency_by_class: Default::default(),
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
            self.window = Window::empty(self.start_machine()?);
        }
        let window = &mut self.window;
        match event {
            Event::Fragment(_) => {
                window.fragments += 1;
                window.occu_cycles += window.service.unwrap_or(1);
            }
            Event::Primitive => window.primitives += 1,
            Event::QueryBegin(spec) => {
                let service = if self.all_tiles_one_cycle {
                    1
                } else {
                    (spec.tiles.len() as u64).div_ceil(self.engines).max(1)
                };
                window.service = Some(service);
                window.class = Some((spec.mode.code(), service));
            }
            Event::QueryEnd => {
                window.query_ended = true;
                window.service = None;
            }
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
        let raster = self.window.fragments + self.setup_cycles * self.window.primitives;
        let work = raster.max(self.window.occu_cycles);
        let class = self.window.class;
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
                    let entry = self.latency_by_class.entry(class).or_default();
                    entry.0 += q.latency_cycles;
                    entry.1 += 1;
                }
                let cost = match ended {
                    Some(q) if !last => q.end_cycle,
                    _ => report.summary.cycles,
                };
                self.simulated_cycles += cost;
                if !last {
                    self.measured_cycles += cost;
                    self.measured_work += work;
                    let entry = self.measured_by_class.entry(class).or_default();
                    entry.0 += cost;
                    entry.1 += work;
                }
            }
            None => self.skipped.push(Skipped { work, class, query }),
        }
        Ok(())
    }

    fn core_mode(&self, index: usize) -> QueryMode {
        self.core.query_mode(index)
    }

    pub fn finish(mut self) -> Result<LevelResult, SimError> {
        self.close_window(true)?;
        let global_ratio = if self.measured_work == 0 {
            1.0
        } else {
            self.measured_cycles as f64 / self.measured_work as f64
        };
        let ratio = |class: &Class| match self.measured_by_class.get(class) {
            Some(&(cycles, work)) if work > 0 => cycles as f64 / work as f64,
            _ => global_ratio,
        };
        let modes: Vec<QueryMode> = (0..self.latencies.len())
            .map(|index| self.core.query_mode(index))
            .collect();
        // A skipped query's latency: the mean over simulated queries of its class, else of
        // its mode, else of all.
        let mean_of_mode = |mode: Option<QueryMode>| {
            let pick: Vec<u64> = self
                .latencies
                .iter()
                .zip(&modes)
                .filter(|(_, m)| mode.map_or(true, |mode| **m == mode))
                .filter_map(|(l, _)| *l)
                .collect();
            (!pick.is_empty()).then(|| pick.iter().sum::<u64>() as f64 / pick.len() as f64)
        };
        let mut total = self.simulated_cycles as f64;
        let final_skipped = (self.windows - 1) % self.every as u64 != 0;
        let skipped_count = self.skipped.len();
        let mut filled = self.latencies.clone();
        for (position, skipped) in self.skipped.iter().enumerate() {
            total += ratio(&skipped.class) * skipped.work as f64;
            if let Some((index, mode)) = skipped.query {
                let latency = match self.latency_by_class.get(&skipped.class) {
                    Some(&(sum, count)) if count > 0 => Some(sum as f64 / count as f64),
                    _ => None,
                }
                .or_else(|| mean_of_mode(Some(mode)))
                .or_else(|| mean_of_mode(None))
                .unwrap_or(crate::o2::MIN_QUERY_LATENCY_CYCLES as f64);
                filled[index] = Some(latency.round() as u64);
                // The final window's drain: its query's latency.
                if position + 1 == skipped_count && final_skipped {
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
}
