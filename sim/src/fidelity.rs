//! The fidelity ladder: one trace replayed at the level of detail the user pays for.
//!
//! | level | what runs | time |
//! |---|---|---|
//! | `functional` | the golden functional model: exact results and counts | none |
//! | `analytic` | functional + the closed-form bottleneck model ([`crate::analytic`]) | predicted |
//! | `sampled:K` | functional on everything, the cycle model on every K-th window ([`crate::sampled`]) | measured on 1/K, extrapolated |
//! | `cycle` | the cycle-level machine model ([`crate::MachineModel`]) | exact |
//! | `rtl` | the cycle-level machine with every Occlusion Unit and OccU Control the bit-accurate RTL ([`crate::rtl_occu`]) | exact |
//!
//! A *window* is the run of events from just after one query's end (and its golden result)
//! up to and including the next query's end and its golden result; the events after the
//! last query end form a final window. Every level consumes events one at a time
//! ([`LevelModel::event`]) and ends in a common [`LevelResult`].

use crate::analytic::AnalyticModel;
use crate::arch::Arch;
use crate::effects::{Effects, EffectsChoice};
use crate::error::SimError;
use crate::golden_check::GoldenCheck;
use crate::machine::MachineModel;
use crate::o2::{check_spec, first_difference};
use crate::occu_stage::OccuModel;
use crate::report::{nearest_rank, Report};
use crate::sampled::SampledModel;
use crate::waveform::WaveformOptions;
use occsim_traces::golden::EventSink;
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{Event, Fragment, QueryMode, QueryResult, Span};
use serde::Serialize;
use std::fmt::Write as _;

/// A level of the ladder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fidelity {
    Functional,
    Analytic,
    /// The cycle model on every `every`-th window (`every` >= 1).
    Sampled {
        every: u32,
    },
    Cycle,
    Rtl,
}

impl Fidelity {
    /// Whether the level builds effect models ([`crate::effects`]): the cycle model and the
    /// sampled level's machines build those the trace's facts (header or scan) call for;
    /// `rtl` builds every model (it has no shortcuts); functional and analytic have none.
    /// Only the first two need the facts.
    pub fn builds_effects(self) -> bool {
        matches!(self, Fidelity::Sampled { .. } | Fidelity::Cycle)
    }
}

impl std::fmt::Display for Fidelity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fidelity::Functional => write!(f, "functional"),
            Fidelity::Analytic => write!(f, "analytic"),
            Fidelity::Sampled { every } => write!(f, "sampled:{every}"),
            Fidelity::Cycle => write!(f, "cycle"),
            Fidelity::Rtl => write!(f, "rtl"),
        }
    }
}

/// A level name that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FidelityParseError {
    #[error("unknown fidelity level '{0}' (functional, analytic, sampled:K, cycle, rtl)")]
    Unknown(String),
    #[error("'{0}': K in sampled:K must be a whole number from 1 to 4294967295")]
    BadEvery(String),
}

impl std::str::FromStr for Fidelity {
    type Err = FidelityParseError;
    fn from_str(text: &str) -> Result<Fidelity, FidelityParseError> {
        match text {
            "functional" => Ok(Fidelity::Functional),
            "analytic" => Ok(Fidelity::Analytic),
            "cycle" => Ok(Fidelity::Cycle),
            "rtl" => Ok(Fidelity::Rtl),
            _ => match text.strip_prefix("sampled:") {
                Some(k) => match k.parse::<u32>() {
                    Ok(every) if every >= 1 => Ok(Fidelity::Sampled { every }),
                    _ => Err(FidelityParseError::BadEvery(text.to_string())),
                },
                None => Err(FidelityParseError::Unknown(text.to_string())),
            },
        }
    }
}

impl Serialize for Fidelity {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

/// One query as a level saw it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct QueryOutcome {
    pub id: u32,
    pub mode: QueryMode,
    pub fragments: u64,
    /// The value a GL program reads ([`QueryResult::value`]).
    pub value: u64,
    /// Predicted or simulated latency in cycles; None at the functional level.
    pub latency_cycles: Option<u64>,
}

/// Windows the sampled level simulated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SampledWindows {
    pub simulated: u64,
    pub total: u64,
}

/// What a level produced, in the same shape at every level.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LevelResult {
    pub level: Fidelity,
    pub machine: String,
    pub fragments: u64,
    pub primitives: u64,
    /// Queries compared with a golden result stored in the stream.
    pub checked_queries: u64,
    /// Predicted (or simulated) cycles of the whole run; None at the functional level.
    pub total_cycles: Option<u64>,
    pub latency_mean_cycles: Option<f64>,
    /// Nearest-rank 95th percentile of the query latencies.
    pub latency_p95_cycles: Option<u64>,
    /// The effect models the cycle model built (cycle and sampled levels).
    pub effects: Option<Effects>,
    pub sampled_windows: Option<SampledWindows>,
    pub queries: Vec<QueryOutcome>,
    /// The full cycle-level report (cycle level only).
    #[serde(skip)]
    pub report: Option<Report>,
}

impl LevelResult {
    /// Set the run's cycles and derive the latency statistics from the queries' latencies.
    pub(crate) fn set_timing(&mut self, total_cycles: u64) {
        self.total_cycles = Some(total_cycles);
        let mut latencies: Vec<u64> = self
            .queries
            .iter()
            .filter_map(|q| q.latency_cycles)
            .collect();
        latencies.sort_unstable();
        self.latency_mean_cycles = Some(if latencies.is_empty() {
            0.0
        } else {
            latencies.iter().sum::<u64>() as f64 / latencies.len() as f64
        });
        self.latency_p95_cycles = Some(nearest_rank(&latencies, 95));
    }

    /// From a cycle-level report.
    fn from_report(report: Report, effects: Effects) -> LevelResult {
        let queries = report
            .queries
            .iter()
            .map(|q| {
                let passed: u64 = q.tiles.iter().map(|t| t.nohc).sum();
                QueryOutcome {
                    id: q.id,
                    mode: q.mode,
                    fragments: q.fragments,
                    value: if q.mode == QueryMode::Any {
                        (passed > 0) as u64
                    } else {
                        passed
                    },
                    latency_cycles: Some(q.latency_cycles),
                }
            })
            .collect();
        let mut result = LevelResult {
            level: Fidelity::Cycle,
            machine: report.machine.clone(),
            fragments: report.summary.fragments,
            primitives: report.summary.primitives,
            checked_queries: report.summary.checked_queries,
            total_cycles: None,
            latency_mean_cycles: None,
            latency_p95_cycles: None,
            effects: Some(effects),
            sampled_windows: None,
            queries,
            report: None,
        };
        result.set_timing(report.summary.cycles);
        result.report = Some(report);
        result
    }

    /// A short text form (what `occsim replay --fidelity` prints below the cycle level).
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "level: {} on {}", self.level, self.machine);
        let _ = writeln!(
            out,
            "fragments: {}  primitives: {}  queries: {} ({} checked against golden results)",
            self.fragments,
            self.primitives,
            self.queries.len(),
            self.checked_queries
        );
        match (
            self.total_cycles,
            self.latency_mean_cycles,
            self.latency_p95_cycles,
        ) {
            (Some(total), Some(mean), Some(p95)) => {
                let _ = writeln!(out, "predicted cycles: {total}");
                let _ = writeln!(out, "query latency: mean {mean:.1}  p95 {p95} cycles");
            }
            _ => {
                let _ = writeln!(
                    out,
                    "predicted cycles: none (the functional level has no time)"
                );
            }
        }
        if let Some(windows) = self.sampled_windows {
            let _ = writeln!(
                out,
                "sampled windows: {} of {} simulated",
                windows.simulated, windows.total
            );
        }
        if let Some(effects) = self.effects {
            let _ = writeln!(out, "active effects: {}", effects.active_names());
        }
        out
    }
}

/// The functional model with the stream checks every level shares: fragments inside the
/// viewport, well-formed queries, results equal to the golden results stored in the stream.
pub struct FunctionalCore {
    pub(crate) functional: FunctionalModel,
    width: u32,
    height: u32,
    events: u64,
    open: Option<u32>,
    open_fragments: u64,
    /// The result of the query that just ended, waiting for the stream's golden result.
    golden: GoldenCheck,
    queries: Vec<QueryOutcome>,
    fragments: u64,
    primitives: u64,
}

impl FunctionalCore {
    pub fn new(width: u32, height: u32) -> Result<FunctionalCore, SimError> {
        crate::error::check_viewport(width, height)?;
        Ok(FunctionalCore {
            functional: FunctionalModel::new(width, height),
            width,
            height,
            events: 0,
            open: None,
            open_fragments: 0,
            golden: GoldenCheck::default(),
            queries: Vec::new(),
            fragments: 0,
            primitives: 0,
        })
    }

    /// Reject a fragment outside the viewport (the next event's index).
    #[inline]
    pub(crate) fn check_fragment(&self, fragment: &Fragment) -> Result<(), SimError> {
        self.check_fragment_at(fragment, self.events)
    }

    /// Reject a fragment outside the viewport, `event` its index in the stream.
    #[inline]
    fn check_fragment_at(&self, fragment: &Fragment, event: u64) -> Result<(), SimError> {
        crate::error::check_fragment_inside(fragment, event, self.width, self.height)
    }

    /// Apply a fragment already checked by [`Self::check_fragment`].
    #[inline]
    pub(crate) fn apply_fragment(&mut self, fragment: Fragment) {
        self.events += 1;
        self.fragments += 1;
        self.open_fragments += 1;
        self.functional.fragment(fragment);
    }

    /// Reject a span with a fragment outside the viewport (naming the first such).
    #[inline]
    pub(crate) fn check_span(&self, span: Span) -> Result<(), SimError> {
        let end = span.x as u32 + span.depths.len() as u32;
        if (span.y as u32) < self.height && end <= self.width {
            return Ok(());
        }
        span.fragments()
            .zip(self.events..)
            .try_for_each(|(fragment, event)| self.check_fragment_at(&fragment, event))
    }

    /// Apply a span already checked by [`Self::check_span`].
    #[inline]
    pub(crate) fn apply_span(&mut self, span: Span) {
        let len = span.depths.len() as u64;
        self.events += len;
        self.fragments += len;
        self.open_fragments += len;
        self.functional.span(span);
    }

    /// A span of fragments at once: the same as its fragments one by one.
    #[inline]
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        self.check_span(span)?;
        self.apply_span(span);
        Ok(())
    }

    /// Apply one event; returns the result of a query that ended with it.
    pub fn event(&mut self, event: &Event) -> Result<Option<QueryResult>, SimError> {
        let index = self.events;
        match event {
            Event::Fragment(fragment) => {
                self.check_fragment(fragment)?;
                self.apply_fragment(*fragment);
                return Ok(None);
            }
            Event::Primitive => self.primitives += 1,
            Event::QueryBegin(spec) => {
                check_spec(spec, index, self.open)?;
                self.open = Some(spec.id);
                self.open_fragments = 0;
            }
            Event::QueryEnd => {
                self.open
                    .take()
                    .ok_or(SimError::EndWithoutBegin { event: index })?;
            }
            Event::QueryResult(golden) => {
                self.events += 1;
                self.golden.check(golden, index, |simulated, golden| {
                    first_difference(simulated, golden, u64::MAX)
                })?;
                return Ok(None);
            }
            _ => {}
        }
        self.events += 1;
        let ended = self.functional.event(event);
        if let Some(result) = &ended {
            self.queries.push(QueryOutcome {
                id: result.id,
                mode: result.mode,
                fragments: self.open_fragments,
                value: result.value(),
                latency_cycles: None,
            });
            self.golden.expect(self.queries.len() - 1, result.clone());
        }
        Ok(ended)
    }

    /// The mode of the `index`-th query that ended.
    pub(crate) fn query_mode(&self, index: usize) -> QueryMode {
        self.queries[index].mode
    }

    /// The result without timing (the functional level's answer).
    pub fn finish(self) -> Result<LevelResult, SimError> {
        if let Some(id) = self.open {
            return Err(SimError::OpenAtEnd { id });
        }
        Ok(LevelResult {
            level: Fidelity::Functional,
            machine: String::new(),
            fragments: self.fragments,
            primitives: self.primitives,
            checked_queries: self.golden.checked(),
            total_cycles: None,
            latency_mean_cycles: None,
            latency_p95_cycles: None,
            effects: None,
            sampled_windows: None,
            queries: self.queries,
            report: None,
        })
    }
}

/// A model replaying a stream at one level.
pub enum LevelModel {
    Functional(Box<FunctionalCore>),
    Analytic(Box<AnalyticModel>),
    Sampled(Box<SampledModel>),
    Cycle(Box<MachineModel>, Effects),
}

impl LevelModel {
    /// The model of `level` for the machine `arch` names on a `width` x `height` viewport,
    /// building only `effects` (cycle and sampled levels).
    pub fn new(
        level: Fidelity,
        arch: &Arch,
        width: u32,
        height: u32,
        effects: Effects,
    ) -> Result<LevelModel, SimError> {
        LevelModel::with_waveform(level, arch, width, height, effects, None)
    }

    /// As [`LevelModel::new`]; at the rtl level, `waveform` dumps the Occlusion Unit's
    /// registers and wires as VCD (other levels have none to dump: an error).
    pub fn with_waveform(
        level: Fidelity,
        arch: &Arch,
        width: u32,
        height: u32,
        effects: Effects,
        waveform: Option<WaveformOptions>,
    ) -> Result<LevelModel, SimError> {
        if waveform.is_some() && level != Fidelity::Rtl {
            return Err(SimError::Waveform(format!(
                "the {level} level has no registers to dump: use the rtl level"
            )));
        }
        Ok(match level {
            Fidelity::Functional => {
                LevelModel::Functional(Box::new(FunctionalCore::new(width, height)?))
            }
            Fidelity::Analytic => {
                LevelModel::Analytic(Box::new(AnalyticModel::new(arch, width, height)?))
            }
            Fidelity::Sampled { every } => LevelModel::Sampled(Box::new(SampledModel::new(
                arch, width, height, effects, every,
            )?)),
            Fidelity::Cycle => LevelModel::Cycle(
                Box::new(MachineModel::with_effects(arch, width, height, effects)?),
                effects,
            ),
            // The Occlusion Unit and OccU Control from the rtl-model crate, clocked every
            // cycle; every effect model is built (the rtl model has no shortcuts).
            Fidelity::Rtl => LevelModel::Cycle(
                Box::new(MachineModel::with_occu_model(
                    arch,
                    width,
                    height,
                    OccuModel::Rtl { waveform },
                )?),
                Effects::every_model_of(arch.machine()),
            ),
        })
    }

    /// Replay one event.
    #[inline]
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        match self {
            LevelModel::Functional(core) => core.event(event).map(|_| ()),
            LevelModel::Analytic(model) => model.event(event),
            LevelModel::Sampled(model) => model.event(event),
            LevelModel::Cycle(machine, _) => machine.event(event),
        }
    }

    /// Replay a span of fragments: the same as its fragments one by one, but the levels
    /// without time take the row at once.
    #[inline]
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        match self {
            LevelModel::Functional(core) => core.span(span),
            LevelModel::Analytic(model) => model.span(span),
            LevelModel::Sampled(model) => model.span(span),
            LevelModel::Cycle(machine, _) => span
                .fragments()
                .try_for_each(|fragment| machine.event(&Event::Fragment(fragment))),
        }
    }

    /// End the replay.
    pub fn finish(self, arch: &Arch) -> Result<LevelResult, SimError> {
        let name = arch.machine().name().to_string();
        let mut result = match self {
            LevelModel::Functional(core) => core.finish()?,
            LevelModel::Analytic(model) => model.finish()?,
            LevelModel::Sampled(model) => model.finish()?,
            LevelModel::Cycle(machine, effects) => {
                LevelResult::from_report(machine.finish()?, effects)
            }
        };
        result.machine = name;
        Ok(result)
    }
}

/// Feeds a stream's events and spans to a [`LevelModel`] and keeps its first error: how a
/// decoded trace reaches a model.
pub struct LevelSink {
    pub model: LevelModel,
    pub error: Option<SimError>,
}

impl LevelSink {
    pub fn new(model: LevelModel) -> LevelSink {
        LevelSink { model, error: None }
    }

    fn keep(&mut self, result: Result<(), SimError>) {
        if let Err(error) = result {
            self.error = Some(error);
        }
    }
}

impl EventSink for LevelSink {
    #[inline]
    fn event(&mut self, event: &Event) {
        if self.error.is_none() {
            let result = self.model.event(event);
            self.keep(result);
        }
    }

    #[inline]
    fn span(&mut self, span: Span) {
        if self.error.is_none() {
            let result = self.model.span(span);
            self.keep(result);
        }
    }
}

/// The effects to build for `events` on `arch`: every one, or those a scan finds observable.
pub fn choose_effects(
    choice: EffectsChoice,
    arch: &Arch,
    width: u32,
    height: u32,
    events: &[Event],
) -> Result<Effects, SimError> {
    Ok(match choice {
        EffectsChoice::All => Effects::every_model_of(arch.machine()),
        EffectsChoice::Auto => crate::effects::observe(arch, width, height, events)?,
    })
}

/// Replay `events` at `level` (effects chosen by `choice`) and return the level's result.
pub fn run_level(
    level: Fidelity,
    arch: &Arch,
    width: u32,
    height: u32,
    choice: EffectsChoice,
    events: &[Event],
) -> Result<LevelResult, SimError> {
    let effects = if level.builds_effects() {
        choose_effects(choice, arch, width, height, events)?
    } else {
        Effects::every_model_of(arch.machine())
    };
    let mut model = LevelModel::new(level, arch, width, height, effects)?;
    for event in events {
        model.event(event)?;
    }
    model.finish(arch)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_parse_and_print_back() {
        for text in [
            "functional",
            "analytic",
            "sampled:1",
            "sampled:10",
            "cycle",
            "rtl",
        ] {
            let level: Fidelity = text.parse().unwrap();
            assert_eq!(level.to_string(), text);
        }
        assert_eq!(
            "sampled:7".parse::<Fidelity>(),
            Ok(Fidelity::Sampled { every: 7 })
        );
    }

    #[test]
    fn bad_levels_say_what_is_allowed() {
        for bad in [
            "sampled:0",
            "sampled:",
            "sampled:-3",
            "sampled:x",
            "sampled:99999999999",
        ] {
            let error = bad.parse::<Fidelity>().unwrap_err();
            assert_eq!(error, FidelityParseError::BadEvery(bad.to_string()));
            assert!(error.to_string().contains("from 1"), "{error}");
        }
        let error = "exact".parse::<Fidelity>().unwrap_err();
        assert!(error
            .to_string()
            .contains("functional, analytic, sampled:K, cycle, rtl"));
        assert!("Cycle".parse::<Fidelity>().is_err(), "names are lower case");
    }

    #[test]
    fn every_level_runs_on_every_machine() {
        let levels = ["functional", "analytic", "sampled:3", "cycle", "rtl"];
        for (name, level) in ["o2", "ir1", "ir4"]
            .into_iter()
            .flat_map(|name| levels.map(|level| (name, level)))
        {
            let arch = Arch::builtin(name).unwrap();
            let level: Fidelity = level.parse().unwrap();
            let mut model = LevelModel::new(level, &arch, 8, 8, Effects::ALL).unwrap();
            model
                .event(&Event::Fragment(Fragment { x: 3, y: 5, z: 9 }))
                .unwrap();
            let result = model.finish(&arch).unwrap();
            assert_eq!(result.machine, arch.machine().name(), "{name} {level}");
            assert_eq!(result.fragments, 1, "{name} {level}");
            assert_eq!(
                result.total_cycles.is_some_and(|c| c > 0),
                level != Fidelity::Functional,
                "{name} {level}"
            );
        }
    }
}
