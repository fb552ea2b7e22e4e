//! `occsim demo`: the README's first command. Makes the built-in demo's trace in memory
//! (a city block whose buildings' bounding boxes are tested in brief mode front to back, then
//! drawn when visible), replays it on the O2-like machine and prints what the queries cost.

use super::arch::ArchSelection;
use occsim_sim::replay::{replay, ReplayOptions};
use occsim_traces::builtin::{demo_scene, DemoOptions};
use occsim_traces::golden::GoldenModel;
use occsim_traces::scene::SceneReader;
use occsim_traces::trace::{TraceHeader, TraceReader, TraceWriter};

#[derive(clap::Args)]
pub struct DemoArgs {
    #[command(flatten)]
    pub arch: ArchSelection,
    /// Add a table of every query.
    #[arg(long)]
    pub queries: bool,
    /// Print the replay's report as JSON (as `occsim replay --json` does), and nothing else.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub raster: super::raster_args::RasterArgs,
}

pub fn run(args: DemoArgs) -> anyhow::Result<()> {
    let arch = args.arch.resolve()?;
    let options = DemoOptions::default();
    let (width, height) = (options.width, options.height);
    let text = demo_scene(&options);
    let mut trace = Vec::new();
    let raster = args.raster.profile;
    let header = TraceHeader::new(width, height)
        .with_scene("demo")
        .with_raster(raster);
    let mut writer = TraceWriter::new(&mut trace, &header)?;
    let mut golden = GoldenModel::with_profile(width, height, raster);
    let bar = occsim_sweep::progress::bar(text.lines().count() as u64, "scene lines");
    bar.set_message("demo: making the trace");
    for line in SceneReader::new(text.as_bytes(), "demo") {
        golden.execute(&line?.command, &mut writer)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    golden.finish(&mut writer)?;
    let summary = writer.finish()?;
    let line = format!(
        "demo: a city block, {} frames at {width}x{height}: {} fragments, {} primitives, {} queries ({} brief, {} verbose, {} samples); trace {} bytes",
        options.frames,
        summary.fragments,
        summary.primitives,
        summary.queries,
        summary.queries_by_mode.brief,
        summary.queries_by_mode.verbose,
        summary.queries_by_mode.samples,
        trace.len()
    );
    if !args.json {
        outln!("{line}");
    }
    let open = || {
        let bar = occsim_sweep::progress::bytes_bar(trace.len() as u64);
        bar.set_message("demo: replaying");
        let counted = occsim_sweep::progress::Counted {
            inner: &trace[..],
            bar,
        };
        Ok(TraceReader::new(counted)?)
    };
    let options = ReplayOptions {
        // Every query's tiles' reports where they are printed, as `replay --json` gives them.
        tile_reports: args.json,
        ..ReplayOptions::cycle(None)
    };
    let result =
        replay(open, &arch, options).map_err(|e| super::replay::in_cli_words("demo", e))?;
    if args.json {
        outln!("{}", super::replay::result_json(&result)?);
    } else {
        out!("{}", result.to_text(args.queries));
    }
    Ok(())
}
