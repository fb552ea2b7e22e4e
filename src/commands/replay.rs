//! `occsim replay TRACE`: replay a fragment trace on a machine model, check every query's
//! counts against the golden results in the trace, and report the timing.

use super::arch::ArchSelection;
use super::fidelity::{effects_of_trace, FidelityArg};
use anyhow::Context;
use occsim_sim::fidelity::{Fidelity, LevelModel};
use occsim_sim::SimError;
use occsim_traces::golden::EventSink;
use occsim_traces::Event;
use std::path::PathBuf;

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
    #[command(flatten)]
    pub level: FidelityArg,
}

/// Feeds decoded events to the machine (at the chosen level) and keeps the first error.
struct MachineSink {
    machine: LevelModel,
    error: Option<SimError>,
}

impl EventSink for MachineSink {
    #[inline]
    fn event(&mut self, event: &Event) {
        if self.error.is_none() {
            if let Err(error) = self.machine.event(event) {
                self.error = Some(error);
            }
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
    let effects = effects_of_trace(args.level.effects, &arch, &args.trace)?;
    let mut reader = super::fidelity::open_trace(&args.trace)?;
    let (width, height) = (reader.header().width, reader.header().height);
    let machine = LevelModel::new(args.level.fidelity, &arch, width, height, effects)
        .with_context(|| format!("{path}: cannot replay"))?;
    let mut sink = MachineSink {
        machine,
        error: None,
    };
    while reader
        .next_block(&mut sink)
        .with_context(|| format!("{path}: cannot read trace"))?
    {
        if let Some(error) = sink.error.take() {
            return Err(error)
                .with_context(|| format!("{path}: replay on {}", arch.machine().name()));
        }
    }
    reader
        .read_into(&mut sink)
        .with_context(|| format!("{path}: cannot read trace"))?;
    if let Some(error) = sink.error.take() {
        return Err(error).with_context(|| format!("{path}: replay on {}", arch.machine().name()));
    }
    let mut result = sink
        .machine
        .finish(&arch)
        .with_context(|| format!("{path}: replay on {}", arch.machine().name()))?;
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
            println!("{}", serde_json::to_string_pretty(&result)?);
        } else {
            print!("{}", result.to_text());
        }
        return Ok(());
    };
    debug_assert_eq!(args.level.fidelity, Fidelity::Cycle);
    if args.json {
        // The cycle report with the effect models that were built.
        let mut json = serde_json::to_value(&report)?;
        json["effects"] = serde_json::to_value(effects)?;
        println!("{}", serde_json::to_string_pretty(&json)?);
    } else {
        print!("{}", report.to_text(args.queries));
        println!("active effects: {}", effects.active_names());
    }
    Ok(())
}
