//! `occsim replay TRACE`: replay a fragment trace on a machine model, check every query's
//! counts against the golden results in the trace, and report the timing.

use super::arch::ArchSelection;
use anyhow::Context;
use occsim_sim::{Arch, MachineModel, Report, SimError};
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
}

/// Feeds decoded events to the machine and keeps the first error.
pub struct MachineSink {
    machine: MachineModel,
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
    let report = replay_trace(&args.trace, &arch, args.retile)?;
    let path = args.trace.display();
    if report.summary.checked_queries < report.summary.queries {
        eprintln!(
            "occsim: warning: {path}: {} of {} queries have no golden result in the trace; their counts were not checked",
            report.summary.queries - report.summary.checked_queries,
            report.summary.queries
        );
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        out!("{}", report.to_text(args.queries));
    }
    Ok(())
}

/// Replay the trace at `trace` on `arch`, with its brief queries retiled to `retile` when
/// given (the golden results are then recomputed), and return the report. Errors name the
/// trace file. The one replay path `replay`, `sweep` and `latency` share.
pub fn replay_trace(trace: &Path, arch: &Arch, retile: Option<TileGrid>) -> anyhow::Result<Report> {
    let reader = super::trace::open_trace(trace)?;
    replay_reader(reader, &trace.display().to_string(), arch, retile)
}

/// Replay a trace from any reader; `name` names it in errors.
pub fn replay_reader<R: std::io::Read>(
    mut reader: TraceReader<R>,
    name: &str,
    arch: &Arch,
    retile: Option<TileGrid>,
) -> anyhow::Result<Report> {
    let (width, height) = (reader.header().width, reader.header().height);
    let machine =
        MachineModel::new(arch, width, height).with_context(|| format!("{name}: cannot replay"))?;
    let sink = MachineSink {
        machine,
        error: None,
    };
    let on = || format!("{name}: replay on {}", arch.machine().name());
    let sink = match retile {
        None => feed(&mut reader, sink, |s| s, name, on)?,
        Some(grid) => {
            let retile = Retile::new(grid, width, height, sink)
                .with_context(|| format!("{name}: --retile {grid}"))?;
            feed(&mut reader, retile, Retile::inner_mut, name, on)?.into_inner()
        }
    };
    sink.machine.finish().with_context(on)
}

/// Read every event of `reader` into `sink`, stopping at the machine's first error.
fn feed<R: std::io::Read, S: EventSink>(
    reader: &mut TraceReader<R>,
    mut sink: S,
    machine: impl Fn(&mut S) -> &mut MachineSink,
    path: &str,
    on: impl Fn() -> String,
) -> anyhow::Result<S> {
    while reader
        .next_block(&mut sink)
        .with_context(|| format!("{path}: cannot read trace"))?
    {
        if let Some(error) = machine(&mut sink).error.take() {
            return Err(error).with_context(&on);
        }
    }
    if let Some(error) = machine(&mut sink).error.take() {
        return Err(error).with_context(&on);
    }
    Ok(sink)
}
