//! `occsim replay TRACE`: replay a fragment trace on a machine model at a fidelity level,
//! check every query's counts against the golden results in the trace, and report; at the
//! rtl level, optionally dump a window of the Occlusion Unit's waveform as VCD, FST or both
//! (on the InfiniteReality-like machine, Image Engine 0 of board 0's unit).

use super::arch::ArchSelection;
use super::fidelity::FidelityArg;
use anyhow::Context;
use occsim_sim::levels::{Fidelity, LevelResult};
use occsim_sim::replay::{max_query_tiles, replay, ReplayError, ReplayOptions};
use occsim_sim::timeline::Timeline;
use occsim_sim::{Arch, WaveformOptions};
use occsim_sweep::output::{commit_together, Finished};
use occsim_traces::retile::TileGrid;
use occsim_traces::trace::TraceReader;
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
    #[command(flatten)]
    pub waveform: WaveformArgs,
}

#[derive(clap::Args)]
pub struct WaveformArgs {
    /// Write the rtl model's registers and wires as a VCD waveform to FILE (needs
    /// --fidelity rtl; on an ir machine, Image Engine 0 of board 0's Occlusion Unit).
    #[arg(long, value_name = "FILE")]
    pub vcd: Option<PathBuf>,
    /// Write the same waveform as FST (GTKWave's compressed format) to FILE (needs
    /// --fidelity rtl; may be given with --vcd).
    #[arg(long, value_name = "FILE")]
    pub fst: Option<PathBuf>,
    /// Write a timeline of the blocks' busy and stall slices, the queries and the frames
    /// as Chrome trace-event JSON to FILE (Perfetto, chrome://tracing; needs --fidelity
    /// cycle or rtl).
    #[arg(long, value_name = "FILE")]
    pub timeline: Option<PathBuf>,
    /// Cycles the waveform (and the timeline) covers, START..END (END exclusive; default: the whole run).
    #[arg(long, value_name = "START..END")]
    pub window: Option<String>,
}

pub fn run(args: ReplayArgs) -> anyhow::Result<()> {
    // Before any output is made: none may replace the trace.
    occsim_sweep::output::note_input(&args.trace);
    check_outputs(&args.waveform)?;
    let mut arch = args.arch.resolve()?;
    super::arch::set_engines(&mut arch, args.engines, &args.arch.set)?;
    let path = args.trace.display().to_string();
    let level = args.level.fidelity;
    let effects = args.level.effects()?;
    let cli_words = |e| in_cli_words(&path, e);
    let (waveform, outputs) = match waveform(&args.waveform, level, || {
        // Every slot a query fills is shown: a retiled brief query has the grid's tiles.
        let grid = args.retile.map_or(0, |g| g.columns as u64 * g.rows as u64);
        let tiles = max_query_tiles(opener(&args.trace), &arch).map_err(cli_words)?;
        Ok(tiles.max(grid))
    })? {
        Some((options, outputs)) => (Some(options), Some(outputs)),
        None => (None, None),
    };
    let timeline = timeline(&args.waveform, level, &arch)?;
    let options = ReplayOptions {
        level,
        effects,
        retile: args.retile,
        waveform,
        timeline: timeline.as_ref().map(|t| t.0.clone()),
        window_index: !args.level.no_index,
        // Every query's tiles' reports only where they are printed.
        tile_reports: args.json,
        ..ReplayOptions::at(level)
    };
    let window = args
        .waveform
        .window
        .as_deref()
        .map(parse_window)
        .transpose()?;
    let outcome = replay(opener_with_progress(&args.trace), &arch, options)
        .map_err(cli_words)
        .and_then(|result| {
            // Checked before any file is kept: a window past the end would dump nothing.
            check_window(window.as_ref(), &result)?;
            Ok(result)
        });
    let (result, mut files) = close_waveform(outputs, outcome)?;
    if let Some((recorder, file)) = timeline {
        recorder.flush();
        let report = result
            .report
            .as_ref()
            .context("the cycle and rtl levels give a report")?;
        files.push(file.finish(report)?);
    }
    // The waveforms and the timeline come into place together, or none of them.
    commit_together(files)?;
    let total = result.total_cycles.unwrap_or(0);
    let covered = window.clone().unwrap_or(0..total);
    let covered = format!(
        "cycles {}..{} of the run's {total}",
        covered.start,
        covered.end.min(total)
    );
    let unit = match arch.machine() {
        occsim_sim::arch::Machine::O2 => "the Occlusion Unit and OccU Control",
        occsim_sim::arch::Machine::Ir => {
            "Image Engine 0 of board 0's Occlusion Unit and OccU Control"
        }
    };
    for (path, format) in [(&args.waveform.vcd, "VCD"), (&args.waveform.fst, "FST")] {
        if let Some(path) = path {
            eprintln!(
                "occsim: wrote {}: {format} waveform of {unit}, {covered}, {}",
                path.display(),
                file_size(path)
            );
        }
    }
    if let Some(path) = &args.waveform.timeline {
        eprintln!(
            "occsim: wrote {}: timeline of {covered}, {}",
            path.display(),
            file_size(path)
        );
        let bytes = std::fs::metadata(path).map_or(0, |m| m.len());
        if bytes > TIMELINE_VIEWER_BYTES && args.waveform.window.is_none() {
            eprintln!(
                "occsim: a trace viewer in a browser (Perfetto, chrome://tracing) may not open a timeline this large; --window START..END writes only those cycles"
            );
        }
    }
    let queries = result.queries.len() as u64;
    // From the window index the results are the golden ones themselves: nothing to check.
    if result.checked_queries < queries && !result.from_window_index {
        eprintln!(
            "occsim: warning: {path}: {} of {} queries have no golden result in the trace; their counts were not checked",
            queries - result.checked_queries,
            queries
        );
    }
    if args.json {
        outln!("{}", result_json(&result)?);
    } else {
        out!("{}", result.to_text(args.queries));
    }
    Ok(())
}

/// A result as `--json` prints it: the level's own result, in its fields' order; at the
/// cycle and rtl levels the machine's report, with its `level`, the effect models that were
/// built and the fragments fast-forwarded, and every key of the level's result it lacks
/// (among them the run's `total_cycles` and each query's `value`), so that a script reads
/// the same keys at every level.
pub fn result_json(result: &LevelResult) -> anyhow::Result<String> {
    Ok(match &result.report {
        Some(report) => {
            let mut json = serde_json::to_value(report)?;
            json["level"] = serde_json::to_value(result.level)?;
            json["effects"] = serde_json::to_value(result.effects)?;
            if let Some(fast_forwarded) = result.fast_forwarded_fragments {
                json["fast_forwarded_fragments"] = fast_forwarded.into();
            }
            add_missing_keys(&mut json, serde_json::to_value(result)?);
            serde_json::to_string_pretty(&json)?
        }
        None => serde_json::to_string_pretty(result)?,
    })
}

/// Add to `json` every key of `more` it lacks: in objects key by key, in arrays of the same
/// length (the queries) item by item; where both hold a value that is neither, `json`'s
/// stands.
fn add_missing_keys(json: &mut serde_json::Value, more: serde_json::Value) {
    use serde_json::Value;
    match (json, more) {
        (Value::Object(json), Value::Object(more)) => {
            for (key, value) in more {
                match json.get_mut(&key) {
                    Some(held) => add_missing_keys(held, value),
                    None => {
                        json.insert(key, value);
                    }
                }
            }
        }
        (Value::Array(json), Value::Array(more)) if json.len() == more.len() => {
            for (held, value) in json.iter_mut().zip(more) {
                add_missing_keys(held, value);
            }
        }
        _ => {}
    }
}

/// A `--window` that starts at or after the run's last cycle would show nothing: an error.
fn check_window(window: Option<&std::ops::Range<u64>>, result: &LevelResult) -> anyhow::Result<()> {
    if let (Some(window), Some(total)) = (window, result.total_cycles) {
        anyhow::ensure!(
            window.start < total,
            "--window {}..{} starts after the run, which has {total} cycles (0..{total}); nothing would be written",
            window.start,
            window.end
        );
    }
    Ok(())
}

/// A timeline larger than this many bytes gets a hint to narrow it: I, plausible 100 MB..2 GB;
/// browser trace viewers hold the whole JSON in memory, and Perfetto's in-browser limit is
/// about 2 GB (a demo frame's whole timeline is 765 MB).
const TIMELINE_VIEWER_BYTES: u64 = 256 << 20;

/// `1234 bytes`, or `?` bytes when the file cannot be read.
fn file_size(path: &Path) -> String {
    std::fs::metadata(path).map_or("? bytes".to_string(), |m| format!("{} bytes", m.len()))
}

/// Replay the trace at `trace` on `arch` at `level`, every effect model built, its brief
/// queries retiled to `retile` when given. The one replay path `sweep`, `latency` and the
/// `fidelity` table share.
pub fn replay_trace(
    trace: &Path,
    arch: &Arch,
    retile: Option<TileGrid>,
    level: Fidelity,
) -> anyhow::Result<LevelResult> {
    let options = ReplayOptions {
        level,
        ..ReplayOptions::cycle(retile)
    };
    replay(opener(trace), arch, options).map_err(|e| in_cli_words(&trace.display().to_string(), e))
}

/// The trace file at `path`, opened afresh for each pass the library makes over it.
pub fn opener(
    path: &Path,
) -> impl FnMut() -> Result<TraceReader<std::io::BufReader<std::fs::File>>, ReplayError> + '_ {
    move || super::trace::open_trace(path).map_err(|e| ReplayError::Open(e.into()))
}

/// As [`opener`], with a progress bar over the bytes of each pass (on a terminal).
fn opener_with_progress(
    path: &Path,
) -> impl FnMut() -> Result<
    TraceReader<occsim_sweep::progress::Counted<std::io::BufReader<std::fs::File>>>,
    ReplayError,
> + '_ {
    let size = std::fs::metadata(path).map_or(0, |m| m.len());
    let mut passes = 0;
    move || {
        passes += 1;
        let file = super::trace::open_trace_file(path).map_err(|e| ReplayError::Open(e.into()))?;
        let bar = occsim_sweep::progress::bytes_bar(size);
        let name = path
            .file_name()
            .unwrap_or(path.as_os_str())
            .to_string_lossy();
        bar.set_message(format!("{name} pass {passes}"));
        let counted = occsim_sweep::progress::Counted {
            inner: std::io::BufReader::with_capacity(super::trace::TRACE_READ_BUFFER_BYTES, file),
            bar,
        };
        TraceReader::new(counted)
            .with_context(|| format!("{}: not a readable occsim trace", path.display()))
            .map_err(|e| ReplayError::Open(e.into()))
    }
}

/// A replay error in the command line's words, naming the trace `name` and the flag a
/// stage comes from.
pub fn in_cli_words(name: &str, error: ReplayError) -> anyhow::Error {
    match error {
        ReplayError::Open(error) => anyhow::Error::from_boxed(error),
        ReplayError::Retile { grid, source } => {
            anyhow::Error::new(source).context(format!("{name}: --retile {grid}"))
        }
        other => anyhow::Error::new(other).context(name.to_owned()),
    }
}

// ---- waveforms (rtl level) ----

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

/// The timeline the flags ask for: the recorder to hand the machine and the file it
/// streams into.
fn timeline(
    args: &WaveformArgs,
    level: Fidelity,
    arch: &Arch,
) -> anyhow::Result<Option<(Timeline, super::timeline::TimelineFile)>> {
    let Some(path) = &args.timeline else {
        if args.window.is_some() && args.vcd.is_none() && args.fst.is_none() {
            anyhow::bail!("--window needs --vcd, --fst or --timeline");
        }
        return Ok(None);
    };
    if !matches!(level, Fidelity::Cycle | Fidelity::Rtl) {
        anyhow::bail!("--timeline needs --fidelity cycle or rtl");
    }
    let window = match &args.window {
        Some(window) => parse_window(window)?,
        None => 0..u64::MAX,
    };
    let clock_mhz = arch.clock_mhz()?;
    let machine = arch.machine().name();
    let (file, sink) =
        super::timeline::TimelineFile::create(path, machine, clock_mhz, window.clone())?;
    Ok(Some((Timeline::new(sink, window), file)))
}

/// The waveforms and the timeline, each checked before the replay that makes them (a
/// missing directory, a device, the trace itself) and at paths of their own: the VCD's had
/// been created only as the replay began to write it, two outputs at one path found only
/// once both were written.
fn check_outputs(args: &WaveformArgs) -> anyhow::Result<()> {
    let flags = [
        (&args.vcd, "--vcd"),
        (&args.fst, "--fst"),
        (&args.timeline, "--timeline"),
    ];
    let given: Vec<(&std::path::Path, &str)> = (flags.iter())
        .filter_map(|(path, flag)| path.as_deref().map(|path| (path, *flag)))
        .collect();
    for (path, flag) in &given {
        super::check_output(Some(path), flag)?;
    }
    // Pair by pair, so that an error names the two flags that meet.
    for (k, (first, first_flag)) in given.iter().enumerate() {
        for (second, second_flag) in &given[k + 1..] {
            occsim_sweep::output::check_distinct(&[first, second])
                .with_context(|| format!("{first_flag}, {second_flag}"))?;
        }
    }
    Ok(())
}

/// Check the flags' combination; the waveform window if a VCD is asked for.
fn waveform_window(
    args: &WaveformArgs,
    level: Fidelity,
) -> anyhow::Result<Option<std::ops::Range<u64>>> {
    let dumps = args.vcd.is_some() || args.fst.is_some();
    if level != Fidelity::Rtl && dumps {
        anyhow::bail!("--vcd and --fst need --fidelity rtl");
    }
    match (dumps, &args.window) {
        (false, _) => Ok(None),
        (true, None) => Ok(Some(0..u64::MAX)),
        (true, Some(window)) => parse_window(window).map(Some),
    }
}

enum VcdChunk {
    Data(Vec<u8>),
    /// The replay succeeded: keep the file.
    Done,
    /// The replay failed, or never ran: drop the file (sent, not left to the channel's
    /// closing, since the model may still hold a sender).
    Stopped,
}

/// The waveform's destination: 1 MiB chunks handed to a thread that writes the file
/// atomically ([`occsim_sweep::output::write_atomically_with`]); if the replay fails, the file is
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

/// The channel to the thread writing a VCD, and the thread. Dropped before the replay is
/// through (an error on the way), it tells the thread to stop and waits for it, so that
/// its unfinished file is removed: returned at once, the process had exited before the
/// thread could remove it, leaving its temporary behind.
struct VcdThread {
    sender: std::sync::mpsc::SyncSender<VcdChunk>,
    thread: Option<std::thread::JoinHandle<anyhow::Result<Finished>>>,
}

impl VcdThread {
    /// End the thread with `last` (`Done` keeps the file, `Stopped` drops it) and take its
    /// outcome.
    fn end(&mut self, last: VcdChunk) -> anyhow::Result<anyhow::Result<Finished>> {
        // The receiver only stops early after a write error, which the join reports.
        let _ = self.sender.send(last);
        let thread = self
            .thread
            .take()
            .context("the waveform writer ended twice")?;
        thread
            .join()
            .map_err(|_| anyhow::anyhow!("the waveform writer panicked"))
    }
}

impl Drop for VcdThread {
    fn drop(&mut self) {
        if self.thread.is_some() {
            let _ = self.end(VcdChunk::Stopped);
        }
    }
}

/// Where a waveform goes: the thread writing the VCD, the FST's file (written by the model
/// through a handle, kept only when the replay succeeds) and its path.
struct WaveformOutputs {
    vcd: Option<VcdThread>,
    fst: Option<(occsim_sweep::output::AtomicFile, PathBuf)>,
}

/// The waveform the flags ask for (rtl level only), and where it goes; `max_query_tiles`
/// finds how many tile slots to show.
fn waveform(
    args: &WaveformArgs,
    level: Fidelity,
    max_query_tiles: impl FnOnce() -> anyhow::Result<u64>,
) -> anyhow::Result<Option<(WaveformOptions, WaveformOutputs)>> {
    let Some(window) = waveform_window(args, level)? else {
        return Ok(None);
    };
    let max_query_tiles = max_query_tiles()?;
    let (vcd_out, vcd) = match &args.vcd {
        Some(path) => {
            let (out, thread) = vcd_thread(path.clone());
            (Some(out), Some(thread))
        }
        None => (None, None),
    };
    let (fst_out, fst) = match &args.fst {
        Some(path) => {
            let cannot = || format!("cannot write the waveform {}", path.display());
            let file = occsim_sweep::output::AtomicFile::create(path).with_context(cannot)?;
            let handle = file.handle().with_context(cannot)?;
            let out: Box<dyn occsim_sim::WriteSeek> =
                Box::new(std::io::BufWriter::with_capacity(1 << 20, handle));
            (Some(out), Some((file, path.clone())))
        }
        None => (None, None),
    };
    let options = WaveformOptions {
        vcd: vcd_out,
        fst: fst_out,
        window,
        max_query_tiles,
    };
    Ok(Some((options, WaveformOutputs { vcd, fst })))
}

/// The VCD's destination: a writer handing chunks to a thread that writes `path`.
fn vcd_thread(path: PathBuf) -> (Box<dyn std::io::Write + Send>, VcdThread) {
    let (sender, receiver) = std::sync::mpsc::sync_channel::<VcdChunk>(4);
    let thread = std::thread::spawn(move || {
        let written = occsim_sweep::output::write_finished_with(&path, |file| {
            use std::io::Write;
            loop {
                match receiver.recv() {
                    Ok(VcdChunk::Data(data)) => file.write_all(&data)?,
                    Ok(VcdChunk::Done) => return Ok(()),
                    Ok(VcdChunk::Stopped) | Err(_) => {
                        return Err(anyhow::Error::new(ReplayStopped))
                    }
                }
            }
        });
        written
            .map(|((), file)| file)
            .with_context(|| format!("cannot write the waveform {}", path.display()))
    });
    let out = Box::new(VcdSender {
        chunks: sender.clone(),
        buffer: Vec::with_capacity(1 << 20),
    });
    let thread = VcdThread {
        sender,
        thread: Some(thread),
    };
    (out, thread)
}

/// The replay stopped before the waveform was complete (its own error says why).
#[derive(Debug)]
struct ReplayStopped;

impl std::fmt::Display for ReplayStopped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("the replay failed; no waveform written")
    }
}

impl std::error::Error for ReplayStopped {}

/// Keep or drop the waveform files after the replay's `outcome`: kept, written whole beside
/// their paths, to be renamed into place with the replay's other outputs.
fn close_waveform<T>(
    outputs: Option<WaveformOutputs>,
    outcome: anyhow::Result<T>,
) -> anyhow::Result<(T, Vec<Finished>)> {
    let Some(WaveformOutputs { vcd, fst }) = outputs else {
        return outcome.map(|value| (value, Vec::new()));
    };
    let (value, vcd) = close_vcd(vcd, outcome)?;
    let mut files: Vec<Finished> = vcd.into_iter().collect();
    if let Some((file, path)) = fst {
        // The model finished (and flushed) the FST; an error dropped the file.
        let finished = file
            .finish()
            .with_context(|| format!("cannot write the waveform {}", path.display()))?;
        files.push(finished);
    }
    Ok((value, files))
}

/// Keep or drop the VCD file after the replay's `outcome`. When the writer failed (it
/// could not create or write the file), its error, which names the file, is the one to
/// report: the replay only saw the writer stop.
fn close_vcd<T>(
    vcd: Option<VcdThread>,
    outcome: anyhow::Result<T>,
) -> anyhow::Result<(T, Option<Finished>)> {
    let Some(mut vcd) = vcd else {
        return outcome.map(|value| (value, None));
    };
    let written = vcd.end(match outcome {
        Ok(_) => VcdChunk::Done,
        Err(_) => VcdChunk::Stopped,
    })?;
    match (outcome, written) {
        (Ok(value), Ok(file)) => Ok((value, Some(file))),
        (Err(replay), Err(writer)) if writer.chain().any(|c| c.is::<ReplayStopped>()) => {
            Err(replay)
        }
        (_, Err(writer)) => Err(writer),
        (Err(replay), Ok(_)) => Err(replay),
    }
}
