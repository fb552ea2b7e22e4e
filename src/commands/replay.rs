//! `occsim replay TRACE`: replay a fragment trace on a machine model, check every query's
//! counts against the golden results in the trace, and report the timing.

use super::arch::ArchSelection;
use anyhow::Context;
use occsim_sim::{MachineModel, OccuModel, SimError, WaveformOptions};
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
    #[command(flatten)]
    pub fidelity: FidelityArgs,
}

// ---- fidelity (cycle | rtl) and waveforms ----

/// How the Occlusion Unit and OccU Control are modelled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Fidelity {
    /// Event timestamps per fragment.
    Cycle,
    /// The occsim-rtl register-transfer model, clocked every cycle (same results and cycles).
    Rtl,
}

#[derive(clap::Args)]
pub struct FidelityArgs {
    /// Model fidelity of the Occlusion Unit and OccU Control.
    #[arg(long, value_enum, default_value = "cycle")]
    pub fidelity: Fidelity,
    /// Write the rtl model's registers and wires as a VCD waveform to FILE (needs --fidelity rtl).
    #[arg(long, value_name = "FILE")]
    pub vcd: Option<PathBuf>,
    /// Cycles the waveform covers, START..END (END exclusive; default: the whole run).
    #[arg(long, value_name = "START..END")]
    pub window: Option<String>,
}

/// Parse `START..END` (cycles, END exclusive, END > START).
pub fn parse_window(text: &str) -> anyhow::Result<std::ops::Range<u64>> {
    let usage = "expected START..END in cycles, END exclusive, e.g. 1000..2000";
    let (start, end) = text
        .split_once("..")
        .with_context(|| format!("--window {text:?}: {usage}"))?;
    let number = |part: &str, name: &str| {
        part.trim().parse::<u64>().with_context(|| {
            format!("--window {text:?}: {name} {part:?} is not a cycle number; {usage}")
        })
    };
    let (start, end) = (number(start, "START")?, number(end, "END")?);
    anyhow::ensure!(
        end > start,
        "--window {text:?}: END must be greater than START"
    );
    Ok(start..end)
}

/// Check the flags' combination; the waveform window if a VCD is asked for.
fn waveform_window(args: &FidelityArgs) -> anyhow::Result<Option<std::ops::Range<u64>>> {
    if args.fidelity != Fidelity::Rtl && (args.vcd.is_some() || args.window.is_some()) {
        anyhow::bail!("--vcd and --window need --fidelity rtl");
    }
    match (&args.vcd, &args.window) {
        (None, Some(_)) => anyhow::bail!("--window needs --vcd FILE"),
        (None, None) => Ok(None),
        (Some(_), None) => Ok(Some(0..u64::MAX)),
        (Some(_), Some(window)) => parse_window(window).map(Some),
    }
}

enum VcdChunk {
    Data(Vec<u8>),
    /// The replay succeeded: keep the file.
    Done,
}

/// The waveform's destination: 1 MiB chunks handed to a thread that writes the file
/// atomically ([`crate::output::write_atomically_with`]); if the replay fails, the file is
/// never made.
struct VcdSender {
    chunks: std::sync::mpsc::SyncSender<VcdChunk>,
    buffer: Vec<u8>,
}

impl VcdSender {
    fn send(&mut self) -> std::io::Result<()> {
        let data = std::mem::take(&mut self.buffer);
        self.chunks
            .send(VcdChunk::Data(data))
            .map_err(|_| std::io::Error::new(std::io::ErrorKind::BrokenPipe, "VCD writer stopped"))
    }
}

impl std::io::Write for VcdSender {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.buffer.extend_from_slice(bytes);
        if self.buffer.len() >= 1 << 20 {
            self.send()?;
        }
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.send()
    }
}

/// The OccU model the flags ask for, and the thread writing its waveform (if any).
type VcdThread = (
    std::sync::mpsc::SyncSender<VcdChunk>,
    std::thread::JoinHandle<anyhow::Result<()>>,
);

fn occu_model(args: &FidelityArgs) -> anyhow::Result<(OccuModel, Option<VcdThread>)> {
    let window = waveform_window(args)?;
    Ok(match (args.fidelity, window, &args.vcd) {
        (Fidelity::Cycle, ..) => (OccuModel::Cycle, None),
        (Fidelity::Rtl, Some(window), Some(path)) => {
            let (sender, receiver) = std::sync::mpsc::sync_channel::<VcdChunk>(4);
            let path = path.clone();
            let thread = std::thread::spawn(move || {
                crate::output::write_atomically_with(&path, |file| {
                    use std::io::Write;
                    loop {
                        match receiver.recv() {
                            Ok(VcdChunk::Data(data)) => file.write_all(&data)?,
                            Ok(VcdChunk::Done) => return Ok(()),
                            Err(_) => anyhow::bail!("the replay failed; no waveform written"),
                        }
                    }
                })
                .with_context(|| format!("cannot write the waveform {}", path.display()))
            });
            let out = Box::new(VcdSender {
                chunks: sender.clone(),
                buffer: Vec::with_capacity(1 << 20),
            });
            let waveform = Some(WaveformOptions { out, window });
            (OccuModel::Rtl { waveform }, Some((sender, thread)))
        }
        (Fidelity::Rtl, ..) => (OccuModel::Rtl { waveform: None }, None),
    })
}

/// Keep or drop the waveform file after the replay's `outcome`.
fn close_vcd<T>(vcd: Option<VcdThread>, outcome: anyhow::Result<T>) -> anyhow::Result<T> {
    let Some((sender, thread)) = vcd else {
        return outcome;
    };
    if outcome.is_ok() {
        // The receiver only stops early after a write error, which the join reports.
        let _ = sender.send(VcdChunk::Done);
    }
    drop(sender);
    let written = thread
        .join()
        .map_err(|_| anyhow::anyhow!("the waveform writer panicked"))?;
    let value = outcome?;
    written?;
    Ok(value)
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

/// Feed the whole trace to `machine` and report.
fn replay<R: std::io::Read>(
    reader: &mut TraceReader<R>,
    machine: MachineModel,
    path: &str,
    arch: &occsim_sim::Arch,
) -> anyhow::Result<occsim_sim::Report> {
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
    sink.machine
        .finish()
        .with_context(|| format!("{path}: replay on {}", arch.machine().name()))
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
    let (occu, vcd) = occu_model(&args.fidelity)?;
    let outcome = MachineModel::with_occu_model(&arch, width, height, occu)
        .with_context(|| format!("{path}: cannot replay"))
        .and_then(|machine| replay(&mut reader, machine, &path, &arch));
    let report = close_vcd(vcd, outcome)?;
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
