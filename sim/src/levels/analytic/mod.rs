//! The analytic level: a closed-form bottleneck model of each machine that predicts cycles
//! and query latency from counts alone.
//!
//! The functional model runs on every event, so results stay exact; beside it the machine's
//! formulas count, per *window* (the events from just after one query's end up to the next
//! query's end, see [`crate::levels`]), what each block must do, and at the window's end
//! predict its cycles `T_w` (the slowest block's) and its query's latency:
//! - [`o2`]: rasterizer, depth pipeline, OccU, the in-order memory port and the prefetch;
//! - [`ir`]: every board's Fragment Generator and every Image Engine (depth test, OccU, hit
//!   words), then the two merge stages.
//!
//! Total cycles = `Σ_w T_w` + the last window's tail (the last query's latency, or the pipe's
//! drain when the stream ends without a query end), or the latest query's answer where that
//! is later (an earlier query's merge on the IR), in an open loop; in a closed loop the
//! windows start no earlier than the host and geometry stage release them and frames are
//! timed ([`crate::levels::predicted_loop`]). Costs: the functional model plus a few
//! integer operations per fragment.

pub mod ir;
pub mod o2;

use crate::arch::{Arch, Machine};
use crate::error::SimError;
use crate::levels::functional::FunctionalCore;
use crate::levels::level::{Fidelity, LevelResult};
use crate::levels::predicted_loop::PredictedLoop;
use occsim_traces::golden::FunctionalModel;
use occsim_traces::state::RenderState;
use occsim_traces::trace::{FragmentBand, FragmentStretch, IndexItem, TraceHeader};
use occsim_traces::{Event, Fragment, QueryShape, QueryTotals, Span};

pub use crate::levels::level::WindowEnd;

/// Cycles one fragment occupies an Occlusion Unit of `engines` engines under a query of
/// `tiles` tiles: the tiles are dealt round-robin and each engine tests one a cycle.
pub(crate) fn service_cycles(tiles: usize, engines: usize, all_tiles_one_cycle: bool) -> u64 {
    if all_tiles_one_cycle {
        1
    } else {
        (tiles.div_ceil(engines) as u64).max(1)
    }
}

/// Bounds for the formulas' quantities (clocks, cycle counts, debts), none of which is ever
/// NaN: a comparison each, one `maxsd`/`minsd` on x86_64, where `f64::max` and `min`, which
/// must return the other operand of a NaN, take four instructions, and `clamp` checks its
/// bounds. The O2 formulas run a dependent chain of them per stretch.
pub(crate) trait NotNan {
    /// `self`, or `floor` if that is larger (`f64::max` but for a NaN).
    fn at_least(self, floor: f64) -> f64;
    /// `self`, or `ceiling` if that is smaller (`f64::min` but for a NaN).
    fn at_most(self, ceiling: f64) -> f64;
    /// `self` within `floor..=ceiling` (`floor <= ceiling`).
    fn within(self, floor: f64, ceiling: f64) -> f64;
}

impl NotNan for f64 {
    #[inline(always)]
    fn at_least(self, floor: f64) -> f64 {
        if self > floor {
            self
        } else {
            floor
        }
    }

    #[inline(always)]
    fn at_most(self, ceiling: f64) -> f64 {
        if self < ceiling {
            self
        } else {
            ceiling
        }
    }

    #[inline(always)]
    fn within(self, floor: f64, ceiling: f64) -> f64 {
        debug_assert!(floor <= ceiling);
        self.at_least(floor).at_most(ceiling)
    }
}

/// The formulas of the machine being modelled: they count each window's work as events
/// arrive and predict at its end (shared with the sampled level's extrapolation).
pub(crate) enum Formulas {
    O2(Box<o2::O2Bottleneck>),
    Ir(Box<ir::IrBottleneck>),
}

impl Formulas {
    pub(crate) fn new(arch: &Arch, width: u32, height: u32) -> Result<Formulas, SimError> {
        Ok(match arch.machine() {
            Machine::O2 => {
                Formulas::O2(Box::new(o2::O2Bottleneck::new(&arch.o2()?, width, height)))
            }
            Machine::Ir => Formulas::Ir(Box::new(ir::IrBottleneck::new(&arch.ir()?, width))),
        })
    }

    /// Count one fragment, already checked to lie in the viewport, before `functional`
    /// applies it.
    #[inline]
    pub(crate) fn fragment(&mut self, fragment: Fragment, functional: &FunctionalModel) {
        match self {
            Formulas::O2(o2) => o2.fragment(fragment, functional),
            Formulas::Ir(ir) => ir.fragment(fragment, functional),
        }
    }

    /// Count a span's fragments (inside the viewport) before `functional` applies it: the
    /// O2's formulas count it whole, the IR's fragment by fragment.
    pub(crate) fn span(&mut self, span: Span, functional: &FunctionalModel) {
        match self {
            Formulas::O2(o2) => o2.span(span, functional),
            Formulas::Ir(ir) => ir.span(span, functional),
        }
    }

    /// Count a stretch of fragments from a trace's window index. Only the O2 formulas count
    /// from stretches ([`AnalyticModel::reads_window_index`]).
    pub(crate) fn stretch(&mut self, stretch: &FragmentStretch, state: &RenderState) {
        match self {
            Formulas::O2(o2) => o2.stretch(stretch, state),
            Formulas::Ir(_) => unreachable!("the IR formulas count bands"),
        }
    }

    /// Count a band of fragments from a trace's band index. Only the IR formulas count
    /// from bands ([`AnalyticModel::reads_band_index`]).
    pub(crate) fn band(&mut self, band: &FragmentBand) {
        match self {
            Formulas::Ir(ir) => ir.band(band),
            Formulas::O2(_) => unreachable!("the O2 formulas count stretches"),
        }
    }

    /// The pipe stood idle `cycles` before the next window (the host held it): the backlog
    /// carried into it drains meanwhile.
    pub(crate) fn idle(&mut self, cycles: f64) {
        if cycles > 0.0 {
            match self {
                Formulas::O2(o2) => o2.idle(cycles),
                Formulas::Ir(ir) => ir.idle(cycles),
            }
        }
    }

    /// Count the other events that matter to the formulas (primitives, query begins, the
    /// O2's clears). A primitive is set up no earlier than `front` released it: the pipe
    /// front waits for the geometry stage, while the blocks behind it work on.
    /// `index` is the event's in the stream, for errors.
    pub(crate) fn event(
        &mut self,
        event: &Event,
        front: &PredictedLoop,
        index: u64,
    ) -> Result<(), SimError> {
        match (self, event) {
            (formulas, Event::Primitive) => formulas.primitive(front.release_in_window()),
            (Formulas::O2(o2), Event::QueryBegin(spec)) => o2.begin(&spec.shape()),
            (Formulas::O2(o2), Event::Clear) => o2.clear(),
            (Formulas::Ir(ir), Event::QueryBegin(spec)) => ir.begin(spec, index)?,
            _ => {}
        }
        Ok(())
    }

    /// The query `spec` ended with `result`, closing the window that began in the predicted
    /// cycle `start`; its end token entered the pipe no earlier than `release` (the host's
    /// release in a closed loop, 0 in an open one). Work the pipe finished before the token
    /// came is no backlog ahead of it: a host-bound window's query drains an empty pipe.
    /// Before `event`: where it drains the pipe (a wait, a conditional begin, a frame's or
    /// a query's end), the last query's records wait for no more reads. (Not a clear: the
    /// rasterizer runs on behind it, and the records still wait for the next fragments'
    /// reads; on the hard cases a query followed by a clear takes 22 cycles on the machine.)
    pub(crate) fn before_event(&mut self, event: &Event) {
        if !matches!(event, Event::Fragment(_)) {
            self.end_run();
        }
        if let (
            Formulas::O2(o2),
            Event::Wait(_) | Event::ConditionalBegin(_) | Event::Swap | Event::QueryEnd,
        ) = (self, event)
        {
            o2.close_head();
        }
    }

    /// A primitive released `release` cycles after the window's start: the rasterizer sets
    /// it up no earlier.
    #[inline]
    pub(crate) fn primitive(&mut self, release: f64) {
        match self {
            Formulas::O2(o2) => o2.primitive(release),
            Formulas::Ir(ir) => ir.primitive(release),
        }
    }

    /// An event other than a fragment comes: a run of fragments ends.
    pub(crate) fn end_run(&mut self) {
        match self {
            Formulas::O2(o2) => o2.end_run(),
            // As a band of the band index ends there.
            Formulas::Ir(ir) => ir.close_stretch(),
        }
    }

    /// A query begins, read skimmed: only the O2's formulas read a window index, and they
    /// ask nothing of its tiles but their number.
    pub(crate) fn begin_skimmed(&mut self, shape: &QueryShape) {
        match self {
            Formulas::O2(o2) => o2.begin(shape),
            Formulas::Ir(_) => unreachable!("the IR formulas read whole queries"),
        }
    }

    /// The last query's latency once the fragments after its end token are known (O2: see
    /// [`o2`], followed); None before, and from then on until the next query's end.
    pub(crate) fn take_followed(&mut self) -> Option<f64> {
        match self {
            Formulas::O2(o2) => o2.take_followed(),
            Formulas::Ir(_) => None,
        }
    }

    /// The stream ended: the last query's records wait for no more reads.
    pub(crate) fn close_head(&mut self) {
        if let Formulas::O2(o2) = self {
            o2.close_head();
        }
    }

    pub(crate) fn end_query(
        &mut self,
        shape: &QueryShape,
        totals: &QueryTotals,
        start: f64,
        release: f64,
    ) -> WindowEnd {
        match self {
            Formulas::O2(o2) => o2.end_query(shape, totals, start, release),
            Formulas::Ir(ir) => ir.end_query(shape, start, release),
        }
    }

    /// On the InfiniteReality-like machine, the cycles each board's Fragment Generator is
    /// through its work before the last board's ([`ir::IrWindow::board_leads`]); none on
    /// the O2.
    pub(crate) fn board_leads(&self) -> Vec<u64> {
        match self {
            Formulas::O2(_) => Vec::new(),
            Formulas::Ir(ir) => ir.board_leads(),
        }
    }

    /// On the InfiniteReality-like machine, the merge stages' state the formulas carry
    /// ([`crate::blocks::merge_network::MergeState`]); none on the O2.
    pub(crate) fn merges(&self) -> Option<&crate::blocks::merge_network::MergeState> {
        match self {
            Formulas::O2(_) => None,
            Formulas::Ir(ir) => Some(ir.merges()),
        }
    }

    /// The stream ended: the last window's prediction, if it holds any work.
    pub(crate) fn finish(&self) -> Option<WindowEnd> {
        match self {
            Formulas::O2(o2) => o2.finish(),
            Formulas::Ir(ir) => ir.finish(),
        }
    }

    /// A frame ends inside the window: its prediction so far (as [`Formulas::finish`]), and
    /// the window starts again empty.
    pub(crate) fn cut(&mut self) -> Option<WindowEnd> {
        let end = self.finish();
        match self {
            Formulas::O2(o2) => o2.clear_window(),
            Formulas::Ir(ir) => ir.clear_window(),
        }
        end
    }
}

/// Whether a trace with `header` carries every query's golden result (or has no query),
/// which a level reading an index takes for the results its fragments would give.
fn carries_golden_results(header: &TraceHeader) -> bool {
    header
        .features
        .as_ref()
        .is_some_and(|features| features.query_results || features.query_modes.is_empty())
}

/// The analytic level's model.
pub struct AnalyticModel {
    core: FunctionalCore,
    formulas: Formulas,
    open: Option<QueryShape>,
    /// The windows' times in the closed loop (`Σ T_w` when nothing holds the pipe back).
    frames: PredictedLoop,
    latencies: Vec<u64>,
    clock_mhz: f64,
}

impl AnalyticModel {
    pub fn new(arch: &Arch, width: u32, height: u32) -> Result<AnalyticModel, SimError> {
        AnalyticModel::with_core(arch, width, height, FunctionalCore::new(width, height)?)
    }

    /// Whether the analytic level of `arch` can replay a trace with `header` from its window
    /// index alone ([`occsim_traces::trace::index`]): the O2 formulas, whose counts a
    /// stretch holds, at the depth layout the index was counted at, on a trace whose header
    /// says it carries golden results (or has no query) to stand for the results fragments
    /// would give. (The IR's formulas count each Image Engine's fragments, which a window
    /// index's stretches do not hold: they read the band index, [`Self::reads_band_index`].)
    pub fn reads_window_index(arch: &Arch, header: &TraceHeader) -> bool {
        let Some(layout) = header.window_index else {
            return false;
        };
        carries_golden_results(header) && arch.o2().is_ok_and(|o2| o2.depth_layout() == layout)
    }

    /// Whether the analytic level of `arch` can replay a trace with `header` from its band
    /// index alone (`has_band_index`, [`occsim_traces::trace::bands`]): the IR formulas,
    /// whose counts a band holds whatever the interleave (under a verbose query, which of
    /// its runs pass), on a trace whose header says it carries golden results (or has no
    /// query) to stand for the results fragments would give.
    pub fn reads_band_index(arch: &Arch, header: &TraceHeader, has_band_index: bool) -> bool {
        has_band_index && carries_golden_results(header) && arch.machine() == Machine::Ir
    }

    /// The model for a replay from the window index (see [`Self::reads_window_index`]):
    /// results are the stream's golden ones.
    pub fn from_window_index(
        arch: &Arch,
        width: u32,
        height: u32,
    ) -> Result<AnalyticModel, SimError> {
        let core = FunctionalCore::trusting_golden(width, height)?;
        AnalyticModel::with_core(arch, width, height, core)
    }

    fn with_core(
        arch: &Arch,
        width: u32,
        height: u32,
        core: FunctionalCore,
    ) -> Result<AnalyticModel, SimError> {
        Ok(AnalyticModel {
            core,
            formulas: Formulas::new(arch, width, height)?,
            open: None,
            frames: PredictedLoop::new(arch)?,
            latencies: Vec::new(),
            clock_mhz: arch.clock_mhz()?,
        })
    }

    /// Feed one event.
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        match event {
            Event::Fragment(fragment) => {
                // Check the fragment lies in the viewport before reading its depth.
                self.core.check_fragment(fragment)?;
                self.formulas.fragment(*fragment, &self.core.functional);
                self.settle();
                self.core.apply_fragment(*fragment);
                return Ok(());
            }
            Event::Primitive => {
                self.primitive();
                return Ok(());
            }
            // A malformed begin is refused by the core below, before any end.
            Event::QueryBegin(spec) => self.open = Some(spec.shape()),
            _ => {}
        }
        self.formulas.before_event(event);
        self.settle();
        let formulas = &mut self.formulas;
        self.frames.event(event, || formulas.cut());
        self.formulas.idle(self.frames.take_idle());
        self.settle();
        self.formulas
            .event(event, &self.frames, self.core.next_event())?;
        if let Some(totals) = self.core.event(event)? {
            self.end_query(&totals);
        }
        Ok(())
    }

    /// A primitive, as [`Self::event`] takes any other event, its steps called directly: the
    /// run ends, the host and geometry stage release it (the pipe idle until then if it
    /// starts a window), the rasterizer sets it up no earlier. A window index's items are
    /// nearly all primitives and stretches (the lazy-grid walk's 44,584 of each): with a
    /// dispatch on the event at each step, its O2 analytic replay took 4.7-4.8 ms, 4.2 ms
    /// without (best of 30 to 60 in one process; the demo's 2.41 and 2.23 ms).
    #[inline]
    fn primitive(&mut self) {
        self.formulas.end_run();
        self.settle();
        self.frames.primitive();
        self.formulas.idle(self.frames.take_idle());
        self.settle();
        self.formulas.primitive(self.frames.release_in_window());
        self.core.primitive();
    }

    /// A query begin read skimmed, taken as [`Self::event`] takes a whole one (a command, no
    /// fragment: the formulas' run ends, the host issues it, the pipe may idle first).
    fn begin_skimmed(&mut self, shape: &QueryShape) -> Result<(), SimError> {
        self.open = Some(*shape);
        self.formulas.end_run();
        self.settle();
        self.frames.query_begin();
        self.formulas.idle(self.frames.take_idle());
        self.settle();
        self.formulas.begin_skimmed(shape);
        self.core.begin_trusted(*shape)
    }

    /// A query result read skimmed, taken as [`Self::event`] takes a whole one (no command:
    /// the formulas' run ends, and the query that ended takes its result).
    fn result_skimmed(&mut self, totals: &QueryTotals) -> Result<(), SimError> {
        self.formulas.end_run();
        self.settle();
        self.formulas.idle(self.frames.take_idle());
        self.settle();
        let totals = self.core.result_trusted(totals)?;
        self.end_query(&totals);
        Ok(())
    }

    /// The query that began last ended with a result of `totals`: its window closes.
    fn end_query(&mut self, totals: &QueryTotals) {
        let Some(shape) = self.open.take() else {
            return;
        };
        let start = self.frames.window_start();
        let release = self.frames.command_release();
        let end = self.formulas.end_query(&shape, totals, start, release);
        self.frames.end_query(end, totals);
        self.latencies.push(end.latency.ceil() as u64);
    }

    /// One item of a window index: a stretch of fragments counted whole, or an event.
    pub fn index_item(&mut self, item: &IndexItem) -> Result<(), SimError> {
        match item {
            IndexItem::Event(event) => self.event(event),
            IndexItem::Shape(shape) => self.begin_skimmed(shape),
            IndexItem::Totals(totals) => self.result_skimmed(totals),
            IndexItem::Stretch(stretch) => {
                let state = self.core.functional.state();
                self.formulas.stretch(stretch, state);
                self.settle();
                self.core.count_fragments(stretch.fragments);
                Ok(())
            }
            IndexItem::Band(band) => {
                self.formulas.band(band);
                self.settle();
                self.core.count_fragments(band.fragments());
                Ok(())
            }
        }
    }

    /// A span of fragments: the formulas count it (its pixels are distinct, so the depths
    /// they read are those before the span), then the functional model takes it whole.
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        self.core.check_span(span)?;
        self.formulas.span(span, &self.core.functional);
        self.settle();
        self.core.apply_span(span);
        Ok(())
    }

    /// The formulas' followed latency of the last query, if they know it now, to the
    /// predicted timeline and the queries' latencies ([`PredictedLoop::settle`]).
    fn settle(&mut self) {
        let followed = self.formulas.take_followed();
        self.frames.settle(followed, &mut self.latencies);
    }

    pub fn finish(mut self) -> Result<LevelResult, SimError> {
        self.formulas.close_head();
        self.settle();
        let (frame_cycles, total) = self.frames.finish(self.formulas.finish());
        let latencies = std::mem::take(&mut self.latencies);
        let mut result = self.core.finish()?;
        for (query, latency) in result.queries.iter_mut().zip(&latencies) {
            query.latency_cycles = Some(*latency);
        }
        result.level = Fidelity::Analytic;
        result.set_timing(total);
        result.set_frames(frame_cycles, self.clock_mhz);
        Ok(result)
    }
}

#[cfg(test)]
mod tests {
    use super::NotNan;
    use occsim_traces::rng::SplitMix64;

    /// The bounds give what `f64::max`, `min` and `clamp` give on every value the formulas
    /// hold (never NaN): whole and fractional cycles, negative differences, infinities, and
    /// equal operands; so swapping them in changed no report.
    #[test]
    fn the_bounds_are_max_min_and_clamp_on_numbers() {
        let mut rng = SplitMix64(15);
        let mut values = vec![
            0.0,
            1.0,
            -1.0,
            0.5,
            16.0,
            1e12,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for _ in 0..60 {
            let whole = rng.below(2_000) as f64 - 1_000.0;
            values.push(whole);
            values.push(whole / 7.0);
        }
        for &a in &values {
            for &b in &values {
                assert_eq!(a.at_least(b), a.max(b), "at_least({a}, {b})");
                assert_eq!(a.at_most(b), a.min(b), "at_most({a}, {b})");
                if a <= b && a.is_finite() && b.is_finite() {
                    for &x in &values {
                        assert_eq!(x.within(a, b), x.clamp(a, b), "{x}.within({a}, {b})");
                    }
                }
            }
        }
    }
}
