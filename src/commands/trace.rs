//! `occsim trace gen|info|dump`: make fragment traces and look inside them.

use crate::scene_input::open_scene;
use anyhow::Context;
use occsim_sim::arch::Arch;
use occsim_sweep::output::write_atomically_with;
use occsim_traces::builtin::BuiltinChoices;
use occsim_traces::golden::{EventSink, GoldenModel};
use occsim_traces::raster::RasterProfile;
use occsim_traces::trace::{
    ReadError, TraceHeader, TraceReader, TraceSummary, TraceWriter, WriterOptions,
};
use occsim_traces::words::counted;
use occsim_traces::{Event, QueryResult, QuerySpec};
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(clap::Subcommand)]
pub enum TraceCommand {
    /// Rasterize a scene and write its fragments and golden results as a trace.
    Gen(Box<GenArgs>),
    /// Print a trace's header, counts, features and bytes per fragment.
    Info(InfoArgs),
    /// Print a trace's events, one a line.
    Dump(DumpArgs),
}

/// `trace gen SCENE -o FILE`, or a walkthrough: `trace gen --scene city --driver NAME -o FILE`.
#[derive(clap::Args)]
pub struct GenArgs {
    /// A scene file, or a built-in scene: demo (which takes --width, --height, --frames and
    /// --seed; 1280x1024, 4 frames and seed 1998 unless given), random (--width, --height
    /// and --seed; seed 1 unless given) or hardcases. Leave it out to make a walkthrough of
    /// --scene (city, forest, obj:PATH) driven by --driver instead.
    #[arg(value_name = "SCENE", conflicts_with_all = super::workload_args::WALK_ONLY)]
    pub scene_file: Option<String>,
    /// The trace file to write (written atomically).
    #[arg(short, long, visible_alias = "out")]
    pub output: PathBuf,
    #[command(flatten)]
    pub workload: super::workload_args::WorkloadArgs,
}

#[derive(clap::Args)]
pub struct InfoArgs {
    /// The `.occt` trace file to describe.
    pub trace: PathBuf,
    /// Check every block's checksum, decode the events, the window index, the band index and
    /// the window table, and check the summary against what the blocks hold.
    #[arg(long)]
    pub scan: bool,
    /// Print the header and summary as JSON.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args)]
pub struct DumpArgs {
    /// The `.occt` trace file whose events to print.
    pub trace: PathBuf,
    /// Stop after this many events.
    #[arg(long)]
    pub limit: Option<u64>,
    /// Print `{"header": ..., "events": [...]}` as JSON (each event as serde names it, e.g.
    /// `{"Fragment":{"x":1,"y":2,"z":3}}`, `"Primitive"`), streamed.
    #[arg(long)]
    pub json: bool,
}

pub fn run(command: TraceCommand) -> anyhow::Result<()> {
    match command {
        TraceCommand::Gen(args) => generate(*args),
        TraceCommand::Info(args) => info(args),
        TraceCommand::Dump(args) => dump(args),
    }
}

fn generate(args: GenArgs) -> anyhow::Result<()> {
    // Before the scene is made: the demo's is made by the golden model answering its
    // queries, seconds at a large viewport, which a path that cannot be written had wasted.
    super::check_output(Some(&args.output), "-o")?;
    let (summary, frames) = match &args.scene_file {
        Some(scene_file) => {
            let scene = &args.workload.scene;
            let choices = scene.builtin_choices();
            let summary = generate_scene(scene_file, &choices, scene.raster.profile, &args.output)?;
            (summary, String::new())
        }
        None => {
            let collision = args.workload.is_collision();
            let (summary, frames) = super::workload_args::write_workload_trace(
                &args.workload,
                &args.output,
                |frame, stats| print_frame(frame, stats, collision),
            )?;
            (summary, format!("{}, ", counted(frames, "frame", "frames")))
        }
    };
    let bytes = std::fs::metadata(&args.output)?.len();
    outln!(
        "wrote {}: {frames}{}, {}, {}, {} bytes{}",
        args.output.display(),
        counted(summary.fragments, "fragment", "fragments"),
        counted(summary.primitives, "primitive", "primitives"),
        counted(summary.queries, "query", "queries"),
        bytes,
        bytes_per_fragment(bytes, summary.fragments)
            .map_or(String::new(), |b| format!(" ({b:.3} bytes/fragment)"))
    );
    Ok(())
}

/// A frame's lines, printed as the frame ends: the collision driver's test (the figure 7
/// area, the step and the tiles that collide; `collision` says the walk is that driver's,
/// whose frames without a test say so) and the raycast driver's rays (cast, against a
/// cast through every pixel, and the bricks whose verbose buffers overflowed). Nothing
/// for other drivers.
fn print_frame(
    frame: u64,
    stats: &occsim_traces::workloads::FrameStats,
    collision: bool,
) -> std::io::Result<()> {
    match &stats.collision {
        Some(test) => {
            let hits: Vec<String> = (test.tiles.iter().enumerate())
                .filter(|(_, &(_, hit))| hit)
                .map(|(k, _)| k.to_string())
                .collect();
            outln!(
                "frame {frame}: step {:.2} m into area column {} row {}: {}",
                test.step,
                test.area.0,
                test.area.1,
                if hits.is_empty() {
                    format!("free ({} tiles)", test.tiles.len())
                } else {
                    format!(
                        "collision in tiles {} of {}",
                        hits.join(","),
                        test.tiles.len()
                    )
                }
            );
        }
        None if collision => {
            outln!("frame {frame}: heading not testable from this image (backward or still)")
        }
        None => {}
    }
    if stats.rays_full_screen > 0 {
        outln!(
            "frame {frame}: {} rays cast of {} for the full screen ({:.1}% saved); verbose buffers overflowed: {} (those bricks cast through the box of their hits)",
            stats.rays_cast,
            stats.rays_full_screen,
            100.0 * (1.0 - stats.rays_cast as f64 / stats.rays_full_screen as f64),
            stats.overflowed_buffers
        );
    }
    Ok(())
}

/// The writer of every trace file occsim makes: with a window index counted at the O2's
/// default depth layout, so that the analytic level on the O2 reads no fragment.
pub(crate) fn indexed_writer<W: Write>(
    out: W,
    output: &Path,
    header: &TraceHeader,
) -> anyhow::Result<TraceWriter<W>> {
    let layout = Arch::builtin("o2")?.o2()?.depth_layout();
    let options = WriterOptions {
        window_index: Some(layout),
        ..WriterOptions::default()
    };
    TraceWriter::with_options(out, header, options)
        .with_context(|| format!("{}: cannot write trace", output.display()))
}

/// A scene file or built-in scene (made as `choices` ask) through the rasterizer and golden
/// model into a trace.
pub(crate) fn generate_scene(
    scene_file: &str,
    choices: &BuiltinChoices,
    raster: RasterProfile,
    output: &Path,
) -> anyhow::Result<TraceSummary> {
    let mut scene = open_scene(scene_file, choices)?;
    let header = TraceHeader::new(scene.width, scene.height)
        .with_scene(scene.name.clone())
        .with_raster(raster);
    write_atomically_with(output, |file| {
        let mut writer = indexed_writer(file, output, &header)?;
        let mut golden = GoldenModel::try_with_profile(scene.width, scene.height, raster)
            .with_context(|| scene_file.to_owned())?;
        let cannot_write = || format!("{}: cannot write trace", output.display());
        for line in &mut scene.reader {
            golden
                .execute(&line?.command, &mut writer)
                .with_context(cannot_write)?;
        }
        golden.finish(&mut writer).with_context(cannot_write)?;
        writer
            .finish_seekable()
            .with_context(|| format!("{}: cannot write trace", output.display()))
    })
}

/// The read buffer a trace file is read through: 64 KB, a block's worth. The reader copies
/// each block out into its own buffer, so a larger one only costs fresh pages at every pass
/// (1 MB had the sampled level's passes fault 7 MB in: `replay demo.occt --fidelity
/// sampled:10` 1.08x slower).
pub const TRACE_READ_BUFFER_BYTES: usize = 1 << 16;

/// Refuse a trace that is no regular file (a pipe, a device): every command but `trace
/// dump` reads a trace more than once (the levels' passes) or seeks in it (its summary),
/// and a pipe gives one pass (a second read had found the trace "truncated inside the magic
/// number"; a named FIFO's second open waited for another writer, for ever). A path that is
/// missing is left to the open, a directory to the first read, whose errors say so.
fn check_trace_file(path: &Path) -> anyhow::Result<()> {
    match std::fs::metadata(path) {
        Ok(metadata) if !metadata.is_file() && !metadata.is_dir() => anyhow::bail!(
            "{}: not a regular file (a pipe or a device): occsim reads a trace more than once; write it to a file first",
            path.display()
        ),
        _ => Ok(()),
    }
}

/// The trace file at `path` opened, and noted as an input (no output may replace it), for
/// a command that reads it once, from its start: a pipe will do.
fn open_trace_file_once(path: &Path) -> anyhow::Result<std::fs::File> {
    let file = std::fs::File::open(path)
        .with_context(|| format!("cannot open trace {}", path.display()))?;
    occsim_sweep::output::note_input(path);
    Ok(file)
}

/// [`open_trace_file_once`] for every command that reads a trace more than once or seeks in
/// it ([`check_trace_file`]).
pub fn open_trace_file(path: &Path) -> anyhow::Result<std::fs::File> {
    check_trace_file(path)?;
    open_trace_file_once(path)
}

/// `file`, the trace at `path`, as a reader, naming it in every error.
fn trace_reader(
    path: &Path,
    file: std::fs::File,
) -> anyhow::Result<TraceReader<std::io::BufReader<std::fs::File>>> {
    TraceReader::new(std::io::BufReader::with_capacity(
        TRACE_READ_BUFFER_BYTES,
        file,
    ))
    .with_context(|| format!("{}: not a readable occsim trace", path.display()))
}

/// Open a trace file for reading, naming it in every error ([`check_trace_file`]).
pub fn open_trace(path: &Path) -> anyhow::Result<TraceReader<std::io::BufReader<std::fs::File>>> {
    trace_reader(path, open_trace_file(path)?)
}

/// [`open_trace`] for a command that reads the trace once, from its start (`trace dump`):
/// a pipe will do.
fn open_trace_once(path: &Path) -> anyhow::Result<TraceReader<std::io::BufReader<std::fs::File>>> {
    trace_reader(path, open_trace_file_once(path)?)
}

/// A trace's header, summary and format version, by a seek to the summary (or a full
/// scan).
pub fn read_header_and_summary(
    path: &Path,
    scan: bool,
) -> anyhow::Result<(TraceHeader, TraceSummary, u16)> {
    let context = || format!("{}: cannot read trace", path.display());
    if scan {
        let mut reader = open_trace(path)?;
        let (header, version) = (reader.header().clone(), reader.format_version());
        let summary = reader
            .read_into(&mut occsim_traces::golden::Discard)
            .with_context(context)?;
        scan_indexes(path).with_context(context)?;
        return Ok((header, summary, version));
    }
    let file = open_trace_file(path)?;
    let reader = TraceReader::new(std::io::BufReader::new(file)).with_context(context)?;
    let version = reader.format_version();
    let (header, summary) = reader.into_summary().with_context(context)?;
    Ok((header, summary, version))
}

/// Decode the trace's other lanes, each in a pass of its own: its window index, its band
/// index and its window table, where it has them (a pass by events checks their blocks'
/// checksums alone, and a block that claims an item too many had passed `--scan`).
fn scan_indexes(path: &Path) -> anyhow::Result<()> {
    let mut reader = open_trace(path)?;
    if reader.header().window_index.is_some() {
        reader.for_each_index_item(|_| Ok::<(), std::convert::Infallible>(()))?;
    }
    let mut reader = open_trace(path)?;
    if reader.has_band_index() {
        reader.for_each_band_item(|_| Ok::<(), std::convert::Infallible>(()))?;
    }
    let mut reader = open_trace(path)?;
    let mut sizes = std::collections::VecDeque::new();
    while reader.next_window_sizes(&mut sizes)? {
        sizes.clear();
    }
    Ok(())
}

/// `trace info`'s format line: the version, and what an older one lacks that this build
/// writes.
fn format_version_line(version: u16) -> String {
    use occsim_traces::trace::FORMAT_VERSION;
    match version {
        FORMAT_VERSION => format!("version {version}"),
        _ => format!(
            "version {version} (this build writes {FORMAT_VERSION}; `trace gen` again for \
             every index it keeps)"
        ),
    }
}

fn info(args: InfoArgs) -> anyhow::Result<()> {
    // Which format wrote it, too: an older version's indexes give the IR's analytic and
    // sampled levels a little different figures (version 13's bands hold 8 rows, 14's 16).
    let (header, summary, version) = read_header_and_summary(&args.trace, args.scan)?;
    let bytes = std::fs::metadata(&args.trace)?.len();
    let per_fragment = bytes_per_fragment(bytes, summary.fragments);
    if args.json {
        let value = serde_json::json!({
            "file": args.trace.display().to_string(),
            "bytes": bytes,
            "bytes_per_fragment": per_fragment,
            "format_version": version,
            "header": header,
            "summary": summary,
            // As the table's `scanned` line: every block read and checked, not the summary
            // alone.
            "scanned": args.scan,
        });
        outln!("{}", serde_json::to_string_pretty(&value)?);
        return Ok(());
    }
    // The features used: the summary's (the header's copy, where there is one, was checked
    // to be the same as the summary was read; a --scan checks it against the blocks).
    let f = &summary.features;
    let modes: Vec<&str> = f.query_modes.iter().map(|m| m.name()).collect();
    let funcs: Vec<&str> = f.depth_funcs.iter().map(|m| m.name()).collect();
    let flags: Vec<&str> = [
        (f.scissor, "scissor"),
        (f.culling, "culling"),
        (f.clears, "clears"),
        (f.depth_writes_off, "depth-writes-off"),
        (f.depth_test_off, "depth-test-off"),
        (f.depth_writes == Some(true), "depth-writes"),
        (f.verbose, "verbose"),
        (f.query_results, "golden-results"),
    ]
    .iter()
    .filter(|(on, _)| *on)
    .map(|(_, name)| *name)
    .collect();
    let q = &summary.queries_by_mode;
    outln!("trace       {}", args.trace.display());
    outln!("scene       {}", header.scene);
    outln!("generator   {}", header.generator);
    outln!("format      {}", format_version_line(version));
    outln!("viewport    {}x{}", header.width, header.height);
    outln!(
        "raster      {} profile, {} sub-pixel bits, {} depth, fill rule {}",
        header.raster,
        header.subpixel_bits,
        header.depth_format,
        header.fill_rule
    );
    outln!("fragments   {}", summary.fragments);
    outln!("primitives  {}", summary.primitives);
    outln!(
        "queries     {} (samples {}, any {}, brief {}, verbose {})",
        summary.queries,
        q.samples,
        q.any,
        q.brief,
        q.verbose
    );
    outln!("modes       {}", modes.join(", "));
    outln!("depth funcs {}", funcs.join(", "));
    outln!("features    {}", flags.join(", "));
    if let Some(tiles) = f.max_query_tiles {
        outln!("max tiles   {tiles} in one query");
    }
    outln!(
        "bytes       {bytes} in {} ({} before compression){}",
        counted(summary.blocks, "block", "blocks"),
        summary.payload_bytes,
        bytes_per_fragment(bytes, summary.fragments)
            .map_or(String::new(), |b| format!(", {b:.3} bytes/fragment"))
    );
    match (header.window_index, summary.window_index) {
        (Some(layout), Some(index)) => outln!(
            "index       window index in {}, {} bytes stored ({} before compression), at depth tiles {}x{} pixels, {} pixels a word, {} banks",
            counted(index.blocks, "block", "blocks"),
            index.stored_bytes,
            index.payload_bytes,
            layout.tile_width_pixels,
            layout.tile_height_pixels,
            layout.pixels_per_word,
            layout.banks
        ),
        _ => outln!("index       none (the analytic level decodes the fragments)"),
    }
    match summary.bands {
        Some(bands) => outln!(
            "bands       every run of fragments as bands of rows in {}, {} bytes stored ({} before compression): the IR's analytic and sampled levels read them instead of the fragments",
            counted(bands.blocks, "block", "blocks"),
            bands.stored_bytes,
            bands.payload_bytes
        ),
        None => outln!("bands       none (the IR's analytic level decodes the fragments)"),
    }
    match summary.depth_tests {
        Some(tests) => outln!(
            "depth tests each fragment's result in {}, {} bytes stored ({} before compression): the sampled level starts its machines mid-trace",
            counted(tests.blocks, "block", "blocks"),
            tests.stored_bytes,
            tests.payload_bytes
        ),
        None => outln!("depth tests none (the sampled level decodes every fragment)"),
    }
    match summary.window_table {
        Some(table) => outln!(
            "windows     every window's size in {}, {} bytes stored: the sampled level reads them instead of the trace a second time",
            counted(table.blocks, "block", "blocks"),
            table.stored_bytes
        ),
        None => outln!(
            "windows     no table (the sampled level finds the windows' sizes by reading the trace a second time)"
        ),
    }
    if args.scan {
        outln!("scanned     every block's checksum checked; the events, the window index, the band index and the window table decoded, and the summary checked against them");
    }
    Ok(())
}

/// One event as a line of text.
fn describe(event: &Event) -> String {
    fn tiles(spec: &QuerySpec) -> String {
        let t: Vec<String> = spec
            .tiles
            .iter()
            .map(|t| format!("{},{},{},{}", t.x, t.y, t.width, t.height))
            .collect();
        t.join(" ")
    }
    fn result(r: &QueryResult) -> String {
        let tiles: Vec<String> = r
            .tiles
            .iter()
            .map(|t| {
                format!(
                    "[nohc {} phc {} x {}..{} y {}..{} z {}..{} hits {}{}]",
                    t.nohc,
                    t.phc,
                    t.xmin,
                    t.xmax,
                    t.ymin,
                    t.ymax,
                    t.zmin,
                    t.zmax,
                    t.hits.len(),
                    if t.overflowed { " overflowed" } else { "" }
                )
            })
            .collect();
        format!("result {} {} {}", r.id, r.mode.name(), tiles.join(" "))
    }
    match event {
        Event::Clear => "clear".into(),
        Event::DepthFunc(f) => format!("depth_func {}", f.name()),
        Event::DepthMask(b) => format!("depth_mask {}", *b as u8),
        Event::DepthTest(b) => format!("depth_test {}", *b as u8),
        Event::Cull(b) => format!("cull {}", *b as u8),
        Event::Scissor(None) => "scissor off".into(),
        Event::Scissor(Some(r)) => format!("scissor {} {} {} {}", r.x, r.y, r.width, r.height),
        Event::QueryBegin(q) => format!(
            "begin {} {} buffer={} tiles {}",
            q.id,
            q.mode.name(),
            q.buffer_entries,
            tiles(q)
        ),
        Event::QueryEnd => "end".into(),
        Event::Primitive => "primitive".into(),
        Event::Fragment(f) => format!("fragment {} {} {}", f.x, f.y, f.z),
        Event::QueryResult(r) => result(r),
        Event::Geometry(b) => format!(
            "geometry vertices={} triangles={}{}{}",
            b.vertices,
            b.triangles,
            if b.starts_draw { " draw" } else { "" },
            if b.discarded { " discarded" } else { "" }
        ),
        Event::HostWork(w) => format!(
            "host nodes={} boxes={} decisions={} pixels={}",
            w.nodes, w.boxes, w.decisions, w.pixels
        ),
        Event::Wait(id) => format!("wait {id}"),
        Event::ConditionalBegin(id) => format!("begin_conditional {id}"),
        Event::ConditionalEnd => "end_conditional".into(),
        Event::Swap => "swap".into(),
    }
}

/// Prints events until the limit (the rest of the block then passes unprinted): as text, or
/// as the elements of a JSON array.
struct Printer<W: Write> {
    out: W,
    remaining: u64,
    json: bool,
    printed: u64,
}

impl<W: Write> EventSink for Printer<W> {
    type Error = std::io::Error;

    fn event(&mut self, event: &Event) -> std::io::Result<()> {
        if self.remaining == 0 {
            return Ok(());
        }
        self.remaining -= 1;
        self.printed += 1;
        if self.json {
            let separator = if self.printed == 1 { "" } else { "," };
            writeln!(self.out, "{separator}{}", serde_json::to_string(event)?)
        } else {
            writeln!(self.out, "{}", describe(event))
        }
    }
}

fn dump(args: DumpArgs) -> anyhow::Result<()> {
    let mut reader = open_trace_once(&args.trace)?;
    let stdout = std::io::stdout();
    let mut printer = Printer {
        out: std::io::BufWriter::new(stdout.lock()),
        remaining: args.limit.unwrap_or(u64::MAX),
        json: args.json,
        printed: 0,
    };
    let header = reader.header().clone();
    if args.json {
        writeln!(
            printer.out,
            "{{\"header\": {},\n\"events\": [",
            serde_json::to_string(&header)?
        )?;
    } else {
        writeln!(
            printer.out,
            "# {} {}x{} from {}",
            header.generator, header.width, header.height, header.scene
        )?;
    }
    while printer.remaining > 0 {
        let more = match reader.next_block(&mut printer) {
            Ok(more) => more,
            Err(ReadError::Sink(e)) => return Err(e.into()),
            Err(ReadError::Trace(e)) => {
                return Err(anyhow::Error::new(e)
                    .context(format!("{}: cannot read trace", args.trace.display())))
            }
        };
        if !more {
            break;
        }
    }
    if args.json {
        writeln!(printer.out, "]}}")?;
    }
    printer.out.flush()?;
    Ok(())
}

/// A trace's bytes a fragment: none for a trace of no fragments.
fn bytes_per_fragment(bytes: u64, fragments: u64) -> Option<f64> {
    (fragments > 0).then(|| bytes as f64 / fragments as f64)
}

/// A trace file's identity for sweep records: FNV-1a (64-bit) over its bytes, and its length.
/// Not cryptographic; it tells one trace from another, which is all resume and merge need.
pub fn trace_digest(path: &Path) -> anyhow::Result<String> {
    use std::io::Read;
    let mut file = open_trace_file(path)?;
    let mut hash = occsim_traces::rng::Fnv1a::default();
    let mut length: u64 = 0;
    let mut buffer = vec![0u8; 1 << 16];
    loop {
        let n = file
            .read(&mut buffer)
            .with_context(|| format!("cannot read trace {}", path.display()))?;
        if n == 0 {
            break;
        }
        length += n as u64;
        hash.bytes(&buffer[..n]);
    }
    Ok(format!("fnv1a64:{:016x}:{length}", hash.0))
}
