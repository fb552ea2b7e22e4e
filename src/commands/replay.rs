//! `occsim replay TRACE`: replay a fragment trace on a machine model, check every query's
//! counts against the golden results in the trace, and report the timing.

use super::arch::ArchSelection;
use anyhow::Context;
use occsim_sim::{MachineModel, SimError};
use occsim_traces::golden::EventSink;
use occsim_traces::trace::TraceReader;
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
}

/// Feeds decoded events to the machine and keeps the first error.
struct MachineSink {
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
    let path = args.trace.display().to_string();
    let file =
        std::fs::File::open(&args.trace).with_context(|| format!("cannot open trace {path}"))?;
    let mut reader = TraceReader::new(std::io::BufReader::with_capacity(1 << 20, file))
        .with_context(|| format!("{path}: not a readable occsim trace"))?;
    let (width, height) = (reader.header().width, reader.header().height);
    let machine = MachineModel::new(&arch, width, height)
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
    let report = sink
        .machine
        .finish()
        .with_context(|| format!("{path}: replay on {}", arch.machine().name()))?;
    if report.summary.checked_queries < report.summary.queries {
        eprintln!(
            "occsim: warning: {path}: {} of {} queries have no golden result in the trace; their counts were not checked",
            report.summary.queries - report.summary.checked_queries,
            report.summary.queries
        );
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", report.to_text(args.queries));
    }
    Ok(())
}
