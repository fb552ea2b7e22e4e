//! `occsim replay TRACE`: replay a fragment trace on a machine model at a fidelity level,
//! check every query's counts against the golden results in the trace, and report.

use super::arch::ArchSelection;
use super::fidelity::{effects_of_trace, FidelityArg};
use anyhow::Context;
use occsim_sim::effects::Effects;
use occsim_sim::fidelity::{Fidelity, LevelModel, LevelResult};
use occsim_sim::{Arch, Report, SimError};
use occsim_traces::golden::EventSink;
use occsim_traces::retile::{Retile, TileGrid};
use occsim_traces::trace::TraceReader;
use occsim_traces::Event;
use std::path::{Path, PathBuf};

#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The fragment trace (.occt) to replay.
    pub trace: PathBuf,
    #[command(flatten)]
    pub arch: ArchSelection,
    /// Occlusion engines (shorthand for --set engines=E).
    #[arg(long, value_name = "E")]
    pub engines: Option<u64>,
    /// Print the whole report as JSON.
    #[arg(long)]
    pub json: bool,
    /// Add a table of every query.
    #[arg(long)]
    pub queries: bool,
    /// Replace every brief query's tiles by a G by H grid over the viewport (the golden
    /// results are recomputed), e.g. --retile 8x8.
    #[arg(long, value_name = "GxH")]
    pub retile: Option<TileGrid>,
    #[command(flatten)]
    pub level: FidelityArg,
}

/// Feeds decoded events to the model (at its level) and keeps the first error.
struct LevelSink {
    model: LevelModel,
    error: Option<SimError>,
}

impl EventSink for LevelSink {
    #[inline]
    fn event(&mut self, event: &Event) {
        if self.error.is_none() {
            if let Err(error) = self.model.event(event) {
                self.error = Some(error);
            }
        }
    }
}

/// How to replay: the level, the effect models to build, and an optional retiling.
#[derive(Clone, Copy)]
pub struct ReplayOptions {
    pub level: Fidelity,
    pub effects: Effects,
    pub retile: Option<TileGrid>,
}

impl ReplayOptions {
    /// The cycle level with every effect model: what sweeps and latency reports run.
    pub fn cycle(retile: Option<TileGrid>) -> ReplayOptions {
        ReplayOptions {
            level: Fidelity::Cycle,
            effects: Effects::ALL,
            retile,
        }
    }
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    let mut arch = args.arch.resolve()?;
    if let Some(engines) = args.engines {
        arch.set_value("engines", &engines.to_string())
            .context("--engines")?;
    }
    let path = args.trace.display().to_string();
    // A retiled trace has other queries than the scan would see: build every model then.
    let effects = match args.retile {
        Some(_) => Effects::ALL,
        None => effects_of_trace(args.level.effects, &arch, &args.trace)?,
    };
    let options = ReplayOptions {
        level: args.level.fidelity,
        effects,
        retile: args.retile,
    };
    let mut result = replay_reader(
        super::trace::open_trace(&args.trace)?,
        &path,
        &arch,
        options,
    )?;
    let queries = result.queries.len() as u64;
    if result.checked_queries < queries {
        eprintln!(
            "occsim: warning: {path}: {} of {} queries have no golden result in the trace; their counts were not checked",
            queries - result.checked_queries,
            queries
        );
    }
    let Some(report) = result.report.take() else {
        // Below the cycle level: the level's own summary.
        if args.json {
            outln!("{}", serde_json::to_string_pretty(&result)?);
        } else {
            out!("{}", result.to_text());
        }
        return Ok(());
    };
    if args.json {
        // The cycle report with the effect models that were built.
        let mut json = serde_json::to_value(&report)?;
        json["effects"] = serde_json::to_value(effects)?;
        outln!("{}", serde_json::to_string_pretty(&json)?);
    } else {
        out!("{}", report.to_text(args.queries));
        outln!("active effects: {}", effects.active_names());
    }
    Ok(())
}

/// Replay the trace at `trace` on `arch` at the cycle level (brief queries retiled to
/// `retile` when given) and return the report. The one replay path `sweep`, `latency` and
/// `culling compare` share.
pub fn replay_trace(trace: &Path, arch: &Arch, retile: Option<TileGrid>) -> anyhow::Result<Report> {
    let name = trace.display().to_string();
    let reader = super::trace::open_trace(trace)?;
    let result = replay_reader(reader, &name, arch, ReplayOptions::cycle(retile))?;
    result
        .report
        .with_context(|| format!("{name}: the cycle level gave no report"))
}

/// Replay a trace from any reader; `name` names it in errors.
pub fn replay_reader<R: std::io::Read>(
    mut reader: TraceReader<R>,
    name: &str,
    arch: &Arch,
    options: ReplayOptions,
) -> anyhow::Result<LevelResult> {
    let (width, height) = (reader.header().width, reader.header().height);
    let model = LevelModel::new(options.level, arch, width, height, options.effects)
        .with_context(|| format!("{name}: cannot replay"))?;
    let sink = LevelSink { model, error: None };
    let on = || format!("{name}: replay on {}", arch.machine().name());
    let sink = match options.retile {
        None => feed(&mut reader, sink, |s| s, name, on)?,
        Some(grid) => {
            let retile = Retile::new(grid, width, height, sink)
                .with_context(|| format!("{name}: --retile {grid}"))?;
            feed(&mut reader, retile, Retile::inner_mut, name, on)?.into_inner()
        }
    };
    sink.model.finish(arch).with_context(on)
}

/// Read every event of `reader` into `sink`, stopping at the model's first error.
fn feed<R: std::io::Read, S: EventSink>(
    reader: &mut TraceReader<R>,
    mut sink: S,
    model: impl Fn(&mut S) -> &mut LevelSink,
    path: &str,
    on: impl Fn() -> String,
) -> anyhow::Result<S> {
    while reader
        .next_block(&mut sink)
        .with_context(|| format!("{path}: cannot read trace"))?
    {
        if let Some(error) = model(&mut sink).error.take() {
            return Err(error).with_context(&on);
        }
    }
    if let Some(error) = model(&mut sink).error.take() {
        return Err(error).with_context(&on);
    }
    Ok(sink)
}
