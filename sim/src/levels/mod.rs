//! The fidelity ladder: one trace replayed at the level of detail the user pays for.
//!
//! | level | what runs | time |
//! |---|---|---|
//! | `functional` | the golden functional model: exact results and counts | none |
//! | `analytic` | functional + the closed-form bottleneck model ([`crate::levels::analytic`]) | predicted |
//! | `sampled:K` | the analytic formulas on everything, the cycle model on every K-th window (and, on the O2 at K up to 15, the top fifteenth of the queries by predicted latency) and the fragments before it ([`crate::levels::sampled`]); from the window index, only those windows' fragments are read | measured on 1/K (and the slowest), extrapolated |
//! | `cycle` | the cycle-level machine model ([`crate::MachineModel`]) | exact |
//! | `rtl` | the cycle-level machine with every Occlusion Unit and OccU Control the bit-accurate RTL ([`crate::blocks::rtl_occu`]) | exact |
//!
//! A *window* is the run of events from just after one query's end (and its golden result)
//! up to and including the next query's end and its golden result; the events after the
//! last query end form a final window. Every level consumes events one at a time
//! ([`LevelModel::event`]) and ends in a common [`LevelResult`].

pub mod analytic;
pub mod consistent_depths;
pub mod functional;
pub mod level;
mod predicted_loop;
pub mod sampled;

pub use functional::FunctionalCore;
pub use level::{Fidelity, FidelityParseError, LevelResult, QueryOutcome, SampledWindows};

use crate::arch::Arch;
use crate::blocks::host::MAX_SIMULATED_CYCLES;
use crate::blocks::occu_stage::OccuModel;
use crate::blocks::waveform::WaveformOptions;
use crate::effects::{Effects, EffectsChoice};
use crate::error::SimError;
use crate::levels::analytic::AnalyticModel;
use crate::levels::sampled::{feed_window_sizes, SampledModel, WindowScout, WindowSizes};
use crate::machines::{MachineBuilder, MachineModel};
use crate::timeline::Timeline;
use occsim_traces::golden::EventSink;
use occsim_traces::{Event, Span};
use std::collections::BTreeSet;

/// A model replaying a stream at one level.
pub enum LevelModel {
    Functional(Box<FunctionalCore>),
    Analytic(Box<AnalyticModel>),
    Sampled(Box<SampledModel>),
    /// The cycle and rtl levels: the machine model, its effect models and which of the two.
    Cycle(Box<MachineModel>, Effects, Fidelity),
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
        LevelModel::with_outputs(level, arch, width, height, effects, waveform, None)
    }

    /// As [`LevelModel::with_waveform`]; at the cycle and rtl levels, the blocks' intervals
    /// go to `timeline` (other levels have no blocks: an error).
    pub fn with_outputs(
        level: Fidelity,
        arch: &Arch,
        width: u32,
        height: u32,
        effects: Effects,
        waveform: Option<WaveformOptions>,
        timeline: Option<Timeline>,
    ) -> Result<LevelModel, SimError> {
        if timeline.is_some() && !matches!(level, Fidelity::Cycle | Fidelity::Rtl) {
            return Err(SimError::Timeline(format!(
                "the {level} level has no blocks to show: use the cycle or rtl level"
            )));
        }
        let builder = |arch| match &timeline {
            Some(timeline) => MachineBuilder::new(arch).timeline(timeline.clone()),
            None => MachineBuilder::new(arch),
        };
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
                Box::new(builder(arch).effects(effects).build(width, height)?),
                effects,
                Fidelity::Cycle,
            ),
            // The Occlusion Unit and OccU Control from the rtl-model crate, clocked every
            // cycle; every effect model is built (the rtl model has no shortcuts).
            Fidelity::Rtl => LevelModel::Cycle(
                Box::new(
                    builder(arch)
                        .occu(OccuModel::Rtl { waveform })
                        .build(width, height)?,
                ),
                Effects::every_model_of(arch.machine()),
                Fidelity::Rtl,
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
            LevelModel::Cycle(machine, _, _) => machine.event(event),
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
            LevelModel::Cycle(machine, _, _) => machine.span(span),
        }
    }

    /// End the replay.
    pub fn finish(self, arch: &Arch) -> Result<LevelResult, SimError> {
        let name = arch.machine().name().to_string();
        let mut result = match self {
            LevelModel::Functional(core) => core.finish()?,
            LevelModel::Analytic(model) => model.finish()?,
            LevelModel::Sampled(model) => model.finish()?,
            LevelModel::Cycle(machine, effects, level) => {
                let fast_forwarded = machine.fast_forwarded_fragments();
                let mut result = LevelResult::from_report(machine.finish()?, effects);
                result.fast_forwarded_fragments = Some(fast_forwarded);
                result.level = level;
                result
            }
        };
        if let Some(cycles) = result
            .total_cycles
            .filter(|&cycles| cycles >= MAX_SIMULATED_CYCLES)
        {
            return Err(SimError::TimeOverflow { cycles });
        }
        result.machine = name;
        result.arch = arch.report_entries();
        Ok(result)
    }
}

impl LevelModel {
    /// Whether the cycle and rtl levels' report keeps every query's tiles (by default), or
    /// their totals only ([`crate::MachineModel::keep_tile_reports`]; the other levels report
    /// totals only either way).
    pub fn keep_tile_reports(&mut self, keep: bool) {
        if let LevelModel::Cycle(machine, ..) = self {
            machine.keep_tile_reports(keep);
        }
    }
}

/// Feeds a stream's events and spans to a [`LevelModel`]: how a decoded trace reaches a
/// model. The model's first error stops the stream.
pub struct LevelSink {
    pub model: LevelModel,
}

impl LevelSink {
    pub fn new(model: LevelModel) -> LevelSink {
        LevelSink { model }
    }
}

impl EventSink for LevelSink {
    type Error = SimError;

    #[inline]
    fn event(&mut self, event: &Event) -> Result<(), SimError> {
        self.model.event(event)
    }

    #[inline]
    fn span(&mut self, span: Span) -> Result<(), SimError> {
        self.model.span(span)
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
    if let Fidelity::Sampled { every } = level {
        // As a replay runs it: the formulas alone first, for the windows whose queries they
        // predict slowest; then the model, its window sizes found ahead.
        let slowest = match sampled::simulates_slowest(every, arch.machine()) {
            false => BTreeSet::new(),
            true => {
                let mut predicting =
                    SampledModel::new(arch, width, height, effects, every)?.predicting();
                for event in events {
                    predicting.event(event)?;
                }
                predicting.slowest_windows()?
            }
        };
        let mut model = SampledModel::new(arch, width, height, effects, every)?
            .with_slowest(slowest)
            .with_window_sizes(
                sampled::warm_up_fragments(arch.machine(), every),
                sampled::tail_fragments(arch.machine()),
            );
        let mut sizes = SliceSizes {
            events: events.iter(),
            scout: WindowScout::default(),
        };
        for event in events {
            feed_window_sizes(&mut model, &mut sizes)?;
            model.event(event)?;
        }
        return LevelModel::Sampled(Box::new(model)).finish(arch);
    }
    let mut model = LevelModel::new(level, arch, width, height, effects)?;
    for event in events {
        model.event(event)?;
    }
    model.finish(arch)
}

/// The window sizes of a stream in memory, found ahead by a scout of their own.
struct SliceSizes<'a> {
    events: std::slice::Iter<'a, Event>,
    scout: WindowScout,
}

impl WindowSizes for SliceSizes<'_> {
    fn next_size(&mut self) -> Result<Option<sampled::WindowSize>, SimError> {
        let events = &mut self.events;
        self.scout.next_size(|scout| {
            let event = events.next();
            event.inspect(|event| scout.event(event));
            Ok(event.is_some())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occsim_traces::Fragment;

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
