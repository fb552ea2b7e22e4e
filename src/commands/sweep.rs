//! `occsim sweep`: command-line shape of the architecture sweep and its `merge` subcommand.
//! The machine wiring supplies the evaluator, the key/value validator and the trace digest.

use anyhow::{anyhow, Context, Result};
use occsim_sweep::{
    capped_jobs, kept_points, list_keys, merge_pending, metric_chart, run_sweep, AxisValidator,
    Grid, Joining, Point, PointRecord, Shard, StoredLine, SweepError, SweepOptions,
};
use occsim_traces::words::counted;
use std::num::NonZeroUsize;
use std::path::PathBuf;

/// The command line's model of one point, in anyhow's terms (the engine takes any error).
pub type Evaluator<'a> = &'a (dyn Fn(&Point) -> Result<PointRecord> + Sync);

/// How to split a sweep over a cluster; shown by `occsim sweep --help`.
const CLUSTER_HELP: &str = "\
Results do not depend on --jobs or on sharding. On a cluster, run one shard a task, then merge
(README's recipe). As a Slurm job array script (sbatch it; by hand, bash it, and the 8 shards
run one after another):

    #!/bin/bash
    #SBATCH --array=1-8
    for shard in ${SLURM_ARRAY_TASK_ID:-1 2 3 4 5 6 7 8}; do
        occsim sweep demo.occt --arch o2 --set engines=1,2,4,8,16 --set page_miss_latency_cycles=6,8,10 \\
            --shard $shard/8 --out cluster-$shard.jsonl --resume
    done

When every task has finished:

    occsim sweep merge cluster.jsonl cluster-*.jsonl --plot cluster.svg

--resume makes a rerun of a stopped task continue where it stopped; a shard's file holds only
its own sweep's points, so each sweep's shards need names of their own. A results file is
replaced only with --force.";

/// Run a machine over the cartesian product of parameter values.
#[derive(clap::Args, Debug)]
#[command(
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true,
    after_long_help = CLUSTER_HELP
)]
pub struct SweepArgs {
    #[command(subcommand)]
    pub command: Option<SweepCommand>,
    #[command(flatten)]
    pub run: SweepRunArgs,
}

#[derive(clap::Subcommand, Debug)]
pub enum SweepCommand {
    /// Join shard outputs into one results file, reporting missing points.
    Merge(MergeArgs),
}

/// `occsim sweep TRACE --arch ir --set boards=1,2,4 --set engines=1,2,4,8,16 --out r.jsonl`
#[derive(clap::Args, Debug)]
pub struct SweepRunArgs {
    /// Trace every point runs on.
    #[arg(required = true)]
    pub trace: Option<PathBuf>,
    /// Built-in base architecture (e.g. o2, ir) the swept values override [default: o2].
    #[arg(long, conflicts_with = "arch_file")]
    pub arch: Option<String>,
    /// Base architecture from a TOML file.
    #[arg(long, value_name = "FILE")]
    pub arch_file: Option<PathBuf>,
    /// A swept parameter and its values; repeat for more axes (the first is outermost).
    #[arg(long = "set", value_name = "KEY=V1,V2,...")]
    pub set: Vec<String>,
    /// Worker threads, at least 1 [default: available parallelism]. Results do not depend
    /// on it.
    #[arg(long, value_parser = super::at_least_one_job)]
    pub jobs: Option<usize>,
    /// Run only every N-th point, starting at the K-th (1-based), e.g. for a job array.
    #[arg(long, value_name = "K/N", value_parser = parse_shard)]
    pub shard: Option<Shard>,
    /// Continue an interrupted sweep: keep the points already in --out, run the rest.
    #[arg(long)]
    pub resume: bool,
    /// Replace --out when it already holds results (they are lost once the new sweep's
    /// first point is kept, and their CSV with them); without it a sweep refuses such a
    /// file.
    #[arg(long, conflicts_with = "resume")]
    pub force: bool,
    /// Replace every brief query's tiles by a G by H grid over the viewport (the golden
    /// results are recomputed), so tile counts can be swept too.
    #[arg(long, value_name = "GxH")]
    pub retile: Option<occsim_traces::retile::TileGrid>,
    /// Level of detail of every point: functional, analytic, sampled:K, cycle or rtl.
    #[arg(long, value_name = "LEVEL", default_value = "cycle")]
    pub fidelity: occsim_sim::Fidelity,
    /// Record a sensitivity band beside each point's headline metrics (`*_band_low`,
    /// `*_band_high`): the point replayed at the corners a sensitivity study around the base
    /// architecture finds, the swept parameters left as the point has them.
    #[arg(long)]
    pub bands: bool,
    /// Results file (one JSON line per point); the CSV view is written beside it.
    #[arg(
        short = 'o',
        long,
        value_name = "FILE.jsonl",
        required = true,
        visible_alias = "output"
    )]
    pub out: Option<PathBuf>,
    /// Also print every point's results line (as --out holds them) as one JSON array on
    /// standard output.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub plot: PlotArgs,
}

/// `occsim sweep merge OUT.jsonl SHARD1.jsonl SHARD2.jsonl ...`, or with the merged file
/// named as `sweep` and `trace gen` name their outputs, `occsim sweep merge -o OUT.jsonl
/// SHARD1.jsonl ...`
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The merged results file (its CSV view is written beside it), then the shard results
    /// files; with -o/--out, the shard results files alone.
    #[arg(required = true, value_name = "FILE.jsonl")]
    pub paths: Vec<PathBuf>,
    /// Merged results file (its CSV view is written beside it), instead of the first path.
    #[arg(
        short = 'o',
        long = "out",
        visible_alias = "output",
        value_name = "FILE.jsonl"
    )]
    pub out: Option<PathBuf>,
    /// Write the merge even if points are missing (they are still listed).
    #[arg(long)]
    pub allow_missing: bool,
    /// Replace the merged results file when it exists; without it a merge refuses to touch an
    /// existing file.
    #[arg(long)]
    pub force: bool,
    #[command(flatten)]
    pub plot: PlotArgs,
}

#[derive(clap::Args, Debug)]
pub struct PlotArgs {
    /// Draw the metric against a swept parameter into this SVG file.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Metric to plot.
    #[arg(long, default_value = "total_cycles", requires = "plot")]
    pub metric: String,
    /// Swept parameter on the x axis [default: the last --set]; the others make the series.
    #[arg(long, value_name = "KEY", requires = "plot")]
    pub plot_x: Option<String>,
}

fn parse_shard(spec: &str) -> std::result::Result<Shard, String> {
    Shard::parse(spec).map_err(|e| format!("{:#}", anyhow::Error::new(e)))
}

/// What to do about results of another sweep found when resuming.
const RESUME_ADVICE: &str =
    "choose another --out, or pass --force instead of --resume to start over in this file";

/// A sweep engine error in the command line's words: where the engine says what happened,
/// this adds the flag that does something about it. Every other error passes unchanged.
pub fn in_cli_words(error: SweepError) -> anyhow::Error {
    match error {
        SweepError::BadAxis { spec, why } => anyhow!("bad --set '{spec}': {why}"),
        SweepError::RejectedValue { key, value, why } => {
            anyhow!("bad --set {key}={value}: {why}")
        }
        SweepError::DuplicateAxis { key } => {
            anyhow!("bad --set: axis '{key}' is given twice; put all its values in one --set")
        }
        SweepError::NoWorkers => anyhow!("--jobs must be at least 1"),
        SweepError::CsvResultsName { path } => anyhow!(
            "--out {} ends in .csv; use a .jsonl name (the CSV view is written beside it)",
            path.display()
        ),
        SweepError::AlreadyHoldsResults { path } => anyhow!(
            "{} already holds results; pass --resume to continue that sweep, or --force to replace it",
            path.display()
        ),
        SweepError::MergeWouldReplace { path } => anyhow!(
            "{} already exists; pass --force to replace it, or merge into another file",
            path.display()
        ),
        SweepError::ForeignTrace {
            at,
            found,
            expected,
            joining: Joining::Resume,
        } => anyhow!(
            "{at}: results are for trace digest {found}, but this sweep has trace digest \
             {expected}: they belong to {}; {RESUME_ADVICE}",
            occsim_sweep::whose_results(&found, &expected)
        ),
        SweepError::ForeignGrid {
            at,
            found,
            expected,
            joining: Joining::Resume,
        } => anyhow!(
            "{at}: results are for the grid '{found}', but this sweep has the grid '{expected}'; \
             {RESUME_ADVICE}"
        ),
        SweepError::NotInShard { at, key, shard } => anyhow!(
            "{at}: point '{key}' is not part of shard {shard}; resume a shard's file with the same --shard"
        ),
        SweepError::SweepPointFailed {
            index,
            key,
            kept,
            kept_in,
            source,
        } => anyhow::Error::from_boxed(source).context(format!(
            "point {index} ({key}) failed; {}",
            kept_points(kept, &kept_in, "(rerun with --resume)")
        )),
        SweepError::NoInputs => anyhow!("sweep merge needs at least one shard file to read"),
        SweepError::BadGrid { at, source } => {
            in_cli_words(*source).context(format!("{at}: bad grid"))
        }
        missing @ SweepError::MissingPoints { .. } => anyhow!(
            "{missing} (pass --allow-missing to write the partial merge, then run the sweep \
             with --resume on it to fill the gaps)"
        ),
        SweepError::NothingSwept => anyhow!("cannot plot: no parameter is swept (add --set)"),
        SweepError::NotSwept { key, swept } => anyhow!(
            "--plot-x {key}: not a swept parameter (swept: {})",
            swept.join(", ")
        ),
        not_numeric @ SweepError::NonNumericAxis { .. } => {
            anyhow!("{not_numeric} (choose another --plot-x)")
        }
        other => anyhow::Error::new(other),
    }
}

/// Runs `occsim sweep` (or `occsim sweep merge`, which needs neither evaluator nor trace).
/// `validate` rejects unknown keys or illegal values of the chosen machine.
pub fn run_with(
    args: &SweepArgs,
    evaluator: Evaluator<'_>,
    trace_digest: &str,
    validate: AxisValidator<'_>,
) -> Result<()> {
    if let Some(SweepCommand::Merge(merge)) = &args.command {
        return run_merge(merge);
    }
    let run = &args.run;
    let out = run.out.as_deref().context("sweep needs --out FILE.jsonl")?;
    let grid = Grid::parse(&run.set, validate).map_err(in_cli_words)?;
    check_plot(&run.plot, &grid, run.bands)?;
    check_outputs_apart(out, &run.plot)?;
    let cores = std::thread::available_parallelism().map_or(1, NonZeroUsize::get);
    let points = grid.selected_indices(run.shard).len();
    if let (0, Some(shard)) = (points, run.shard) {
        // Not an error: a cluster's fixed shard count may pass a small grid's size, and the
        // merge takes the empty file.
        eprintln!(
            "sweep: shard {shard} holds none of the grid's {}: its results file is empty",
            counted(grid.len() as u64, "point", "points")
        );
    }
    let requested = run.jobs.unwrap_or(cores);
    let jobs = capped_jobs(requested, points, cores);
    if jobs < requested && run.jobs.is_some() {
        eprintln!(
            "sweep: --jobs {requested} capped to {jobs} ({points} points to run, {cores} cores)"
        );
    }
    let options = SweepOptions {
        grid: &grid,
        shard: run.shard,
        trace_digest,
        out,
        jobs,
        resume: run.resume,
        replace: run.force,
        show_progress: true,
    };
    let evaluate = |point: &Point| evaluator(point).map_err(Into::into);
    let outcome = run_sweep(&options, &evaluate).map_err(in_cli_words)?;
    if outcome.torn_tail_dropped {
        eprintln!(
            "sweep: dropped a torn last line of {} (recomputed)",
            out.display()
        );
    }
    eprintln!(
        "sweep: {} ({} run, {} resumed) -> {}, {}",
        counted(outcome.lines.len() as u64, "point", "points"),
        outcome.evaluated,
        outcome.reused,
        out.display(),
        outcome.csv.display()
    );
    if run.json {
        let texts: Vec<&str> = outcome.lines.iter().map(|l| l.text.as_str()).collect();
        outln!("[\n{}\n]", texts.join(",\n"));
    }
    let trace = run
        .trace
        .as_deref()
        .map_or("the trace".to_string(), |t| t.display().to_string());
    let arch = super::arch::describe(
        run.arch.as_deref().unwrap_or("o2"),
        run.arch_file.as_deref(),
        &[],
    );
    let retiled = run
        .retile
        .map_or(String::new(), |grid| format!(" retiled {grid}"));
    let subject = format!("{trace}{retiled} on {arch}, {}", run.fidelity);
    // The results file is the sweep's own record, kept point by point (a resumed sweep
    // starts from it): the chart of it follows alone.
    let plot = plot_file(&run.plot, &grid, &outcome.lines, &subject)?;
    occsim_sweep::output::commit_together(plot.into_iter().collect())?;
    report_plot(&run.plot);
    Ok(())
}

/// Runs `occsim sweep merge`.
pub fn run_merge(args: &MergeArgs) -> Result<()> {
    let (out, shards) = args.out_and_shards();
    check_outputs_apart(out, &args.plot)?;
    let mut report =
        merge_pending(out, shards, args.allow_missing, args.force).map_err(in_cli_words)?;
    let subject = match report.lines.first() {
        Some(first) => format!(
            "{} of trace {} on {}",
            counted(shards.len() as u64, "shard", "shards"),
            first.line.trace_digest,
            machine_of(&first.text)
        ),
        None => "nothing merged".to_string(),
    };
    // The merge, its CSV view and its chart come into place together, or none of them.
    let plot = plot_file(&args.plot, &report.grid, &report.lines, &subject)?;
    report.commit(plot)?;
    for torn in &report.torn_inputs {
        eprintln!(
            "sweep merge: {} ends in a torn line (its point is missing)",
            torn.display()
        );
    }
    if !report.missing.is_empty() {
        eprintln!(
            "sweep merge: {} of {} points missing: {}",
            report.missing.len(),
            report.grid.len(),
            list_keys(&report.missing)
        );
    }
    eprintln!(
        "sweep merge: {} -> {}, {}",
        counted(report.lines.len() as u64, "point", "points"),
        out.display(),
        report.csv.display()
    );
    report_plot(&args.plot);
    Ok(())
}

impl MergeArgs {
    /// The merged file and the shards: `-o`'s and every path, or the first path and the
    /// rest (none, where only the merged file is named: merging nothing is refused).
    fn out_and_shards(&self) -> (&std::path::Path, &[PathBuf]) {
        match &self.out {
            Some(out) => (out, &self.paths),
            // `paths` is required: clap gives at least one.
            None => (&self.paths[0], &self.paths[1..]),
        }
    }
}

/// The machine a results line's resolved architecture is of: the InfiniteReality-like one
/// has boards, the O2-like one not.
fn machine_of(text: &str) -> &'static str {
    let line: serde_json::Value = serde_json::from_str(text).unwrap_or_default();
    let has_boards = line["resolved_arch"]
        .as_array()
        .is_some_and(|entries| entries.iter().any(|e| e["key"] == "boards"));
    if has_boards {
        "ir"
    } else {
        "o2"
    }
}

/// Runs `occsim sweep` on the machine models: every point replays the trace on the base
/// architecture with the point's values set.
pub fn run(args: SweepArgs) -> Result<()> {
    if let Some(SweepCommand::Merge(merge)) = &args.command {
        return run_merge(merge);
    }
    let trace = args.run.trace.clone().context("sweep needs a TRACE")?;
    occsim_sweep::output::note_input(&trace);
    let base = super::arch::resolve(
        args.run.arch.as_deref().unwrap_or("o2"),
        args.run.arch_file.as_deref(),
        &[],
    )?;
    // A retiled trace asks other questions: it is another input as far as results go.
    let mut digest = super::trace::trace_digest(&trace)?;
    if let Some(grid) = args.run.retile {
        digest += &format!(":retile={grid}");
    }
    // So do other levels: a resumed sweep must not mix their figures.
    let level = args.run.fidelity;
    if level != occsim_sim::Fidelity::Cycle {
        digest += &format!(":fidelity={level}");
    }
    if args.run.bands {
        digest += ":bands";
    }
    // And so does another machine under the grid's values: a resumed sweep or a merge had
    // taken lines made on ir2 into one on ir4, or on an arch file's machine into the
    // built-in's, under one CSV.
    let machine = serde_json::to_string(&base.report_entries())?;
    let machine = occsim_traces::rng::Fnv1a::of(machine.as_bytes());
    digest += &format!(":arch={machine:016x}");
    let validate = |key: &str, value: &str| {
        let mut arch = base.clone();
        arch.set_value(key, value).map_err(|e| e.to_string())?;
        Ok(arch
            .get(key)
            .map_or_else(|| value.to_owned(), |read| read.to_string()))
    };
    let replayer = super::sensitivity::Replayer {
        trace: &trace,
        retile: args.run.retile,
        fidelity: level,
        jobs: args
            .run
            .jobs
            .unwrap_or_else(super::sensitivity::default_jobs),
    };
    let corners = match args.run.bands {
        true => {
            let axes: Vec<&str> = args
                .run
                .set
                .iter()
                .map(|spec| {
                    spec.split_once('=')
                        .map_or(spec.as_str(), |(k, _)| k.trim())
                })
                .collect();
            Some(super::sensitivity::CornerBands::find(
                &replayer, &base, &axes,
            )?)
        }
        false => None,
    };
    let evaluate = |point: &Point| -> Result<PointRecord> {
        let mut arch = base.clone();
        for (key, value) in &point.values {
            arch.set_value(key, value)
                .with_context(|| format!("{key}={value}"))?;
        }
        let result = super::replay::replay_trace(&trace, &arch, args.run.retile, level)?;
        let mut metrics = point_metrics(&result);
        if let Some(corners) = &corners {
            let default = occsim_sim::sensitivity::Headlines::of(&result, arch.clock_mhz()?);
            let bands = corners.at(&replayer, &arch, &default)?;
            for (name, band) in [
                ("total_cycles", Some(bands.cycles)),
                ("frame_ms", bands.frame_ms),
                ("latency_p50_cycles", bands.latency_p50_cycles),
                ("latency_p95_cycles", bands.latency_p95_cycles),
            ] {
                if let Some((low, high)) = band {
                    metrics.insert(format!("{name}_band_low"), serde_json::json!(low));
                    metrics.insert(format!("{name}_band_high"), serde_json::json!(high));
                }
            }
        }
        Ok(PointRecord {
            resolved_arch: serde_json::to_value(arch.report_entries())?,
            metrics,
        })
    };
    run_with(&args, &evaluate, &digest, &validate)
}

/// Every metric a sweep records for a point at the cycle level ([`point_metrics`]; the levels
/// below record fewer), each with `_band_low` and `_band_high` under `--bands`.
const METRICS: [&str; 11] = [
    "fragments",
    "queries",
    "total_cycles",
    "latency_mean_cycles",
    "latency_p95_cycles",
    "frame_mean_cycles",
    "frames_per_second",
    "simulated_seconds",
    "fragments_per_cycle",
    "latency_p50_cycles",
    "latency_max_cycles",
];

/// The results file, its CSV view and the chart each at its own path (a chart at the
/// results' path had replaced them, the run saying it had written both).
fn check_outputs_apart(out: &std::path::Path, plot: &PlotArgs) -> Result<()> {
    let csv = occsim_sweep::csv_path_for(out).map_err(in_cli_words)?;
    let mut outputs = vec![out, csv.as_path()];
    outputs.extend(plot.plot.as_deref());
    occsim_sweep::output::check_distinct(&outputs).map_err(|error| match error {
        two @ occsim_sweep::output::OutputError::TwoOutputsOnePath { .. } => {
            anyhow::Error::new(two)
                .context("the results file, its CSV view (beside it, .csv) and --plot")
        }
        // One path's own fault (an input, a device): the error names it.
        other => anyhow::Error::new(other),
    })
}

/// A plot's metric and x axis checked before any point runs (they had been checked after
/// every point had).
fn check_plot(plot: &PlotArgs, grid: &Grid, bands: bool) -> Result<()> {
    if plot.plot.is_none() {
        return Ok(());
    }
    super::check_output(plot.plot.as_deref(), "--plot")?;
    let metric = plot.metric.as_str();
    let base = metric
        .strip_suffix("_band_low")
        .or_else(|| metric.strip_suffix("_band_high"))
        .filter(|_| bands)
        .unwrap_or(metric);
    anyhow::ensure!(
        METRICS.contains(&base),
        "--metric {metric}: not a metric a sweep records (one of {})",
        METRICS.join(", ")
    );
    occsim_sweep::plot_axis(grid.axes(), plot.plot_x.as_deref()).map_err(in_cli_words)?;
    Ok(())
}

/// The metrics a sweep records for one point (no wall times: results must not depend on the
/// machine the sweep ran on). Levels below cycle predict fewer of them.
fn point_metrics(
    result: &occsim_sim::LevelResult,
) -> std::collections::BTreeMap<String, serde_json::Value> {
    let mut metrics: std::collections::BTreeMap<String, serde_json::Value> = [
        ("fragments", serde_json::json!(result.fragments)),
        ("queries", serde_json::json!(result.queries.len())),
        ("total_cycles", serde_json::json!(result.total_cycles)),
        (
            "latency_mean_cycles",
            serde_json::json!(result.latency_mean_cycles),
        ),
        (
            "latency_p95_cycles",
            serde_json::json!(result.latency_p95_cycles),
        ),
        (
            "frame_mean_cycles",
            serde_json::json!(result.frame_mean_cycles()),
        ),
        (
            "frames_per_second",
            serde_json::json!(result.frames_per_second),
        ),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_owned(), v))
    .collect();
    if let Some(report) = &result.report {
        let s = &report.summary;
        for (key, value) in [
            ("simulated_seconds", serde_json::json!(s.simulated_seconds)),
            (
                "fragments_per_cycle",
                serde_json::json!(s.fragments_per_cycle),
            ),
            (
                "latency_p50_cycles",
                serde_json::json!(s.latency_p50_cycles),
            ),
            (
                "latency_max_cycles",
                serde_json::json!(s.latency_max_cycles),
            ),
        ] {
            metrics.insert(key.to_owned(), value);
        }
    }
    metrics
}

/// The chart `args` asks for, drawn and written beside its path, to be renamed into place
/// with the command's other outputs.
fn plot_file(
    args: &PlotArgs,
    grid: &Grid,
    lines: &[StoredLine],
    subject: &str,
) -> Result<Option<occsim_sweep::output::Finished>> {
    let Some(path) = args.plot.as_deref() else {
        return Ok(None);
    };
    let chart = metric_chart(
        grid.axes(),
        lines,
        &args.metric,
        args.plot_x.as_deref(),
        subject,
    )
    .map_err(in_cli_words)?;
    let svg = chart.to_svg()?;
    Ok(Some(occsim_sweep::output::write_finished(
        path,
        svg.as_bytes(),
    )?))
}

/// Say where the chart went, once it is there.
fn report_plot(args: &PlotArgs) {
    if let Some(path) = &args.plot {
        eprintln!("sweep: plot -> {}", path.display());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[test]
    fn the_metrics_a_plot_may_name_are_those_a_cycle_point_records() {
        // METRICS (checked before a sweep runs) and point_metrics (what a point records)
        // must agree: a cycle replay of the hard cases gives every key, and only those.
        let lines = occsim_traces::scene::parse_scene(occsim_traces::builtin::HARDCASES, "h")
            .expect("parses");
        let mut trace = Vec::new();
        let header = occsim_traces::trace::TraceHeader::new(64, 64);
        let mut writer = occsim_traces::trace::TraceWriter::new(&mut trace, &header).unwrap();
        let mut golden = occsim_traces::golden::GoldenModel::new(64, 64);
        for line in &lines {
            golden.execute(&line.command, &mut writer).unwrap();
        }
        golden.finish(&mut writer).unwrap();
        writer.finish().unwrap();
        let open = || Ok(occsim_traces::trace::TraceReader::new(&trace[..])?);
        let arch = occsim_sim::Arch::builtin("o2").unwrap();
        let options = occsim_sim::replay::ReplayOptions::cycle(None);
        let result = occsim_sim::replay::replay(open, &arch, options).unwrap();
        let recorded: Vec<String> = point_metrics(&result).into_keys().collect();
        let mut known: Vec<String> = METRICS.iter().map(|m| m.to_string()).collect();
        known.sort();
        assert_eq!(recorded, known);
    }

    #[derive(clap::Parser, Debug)]
    struct Cli {
        #[command(subcommand)]
        command: Top,
    }

    #[derive(clap::Subcommand, Debug)]
    enum Top {
        Sweep(SweepArgs),
    }

    fn parse(args: &[&str]) -> Result<SweepArgs, clap::Error> {
        let argv = ["occsim", "sweep"].iter().chain(args);
        Cli::try_parse_from(argv).map(|cli| match cli.command {
            Top::Sweep(s) => s,
        })
    }

    #[test]
    fn run_form_parses_repeated_sets_and_shard() {
        let args = parse(&[
            "t.trace",
            "--arch",
            "ir",
            "--set",
            "boards=1,2",
            "--set",
            "engines=1,4",
            "--jobs",
            "2",
            "--shard",
            "2/3",
            "--out",
            "r.jsonl",
            "--plot",
            "r.svg",
        ])
        .unwrap();
        assert!(args.command.is_none());
        assert_eq!(args.run.set, ["boards=1,2", "engines=1,4"]);
        assert_eq!(
            args.run.shard,
            Some(Shard {
                number: 2,
                count: 3
            })
        );
        assert_eq!(args.run.plot.metric, "total_cycles");
    }

    #[test]
    fn merge_form_parses_without_trace_or_out_flag() {
        let args = parse(&[
            "merge",
            "all.jsonl",
            "a.jsonl",
            "b.jsonl",
            "--allow-missing",
        ])
        .unwrap();
        let Some(SweepCommand::Merge(merge)) = args.command else {
            panic!("expected merge, got {args:?}");
        };
        let shards = [PathBuf::from("a.jsonl"), PathBuf::from("b.jsonl")];
        assert_eq!(
            merge.out_and_shards(),
            (std::path::Path::new("all.jsonl"), &shards[..])
        );
        assert!(merge.allow_missing);
        // The merged file named as sweep's and trace gen's outputs are, by any of their flags.
        for flag in ["-o", "--out", "--output"] {
            let args = parse(&["merge", "a.jsonl", flag, "all.jsonl", "b.jsonl"]).unwrap();
            let Some(SweepCommand::Merge(merge)) = args.command else {
                panic!("expected merge, got {args:?}");
            };
            assert_eq!(
                merge.out_and_shards(),
                (std::path::Path::new("all.jsonl"), &shards[..]),
                "{flag}"
            );
        }
    }

    #[test]
    fn bad_shard_and_missing_out_are_rejected() {
        let err = parse(&["t.trace", "--out", "r.jsonl", "--shard", "4/3"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("K must be between 1 and N=3"), "{err}");
        let err = parse(&["t.trace"]).unwrap_err().to_string();
        assert!(err.contains("--out"), "{err}");
        let err = parse(&["t.trace", "--out", "r.jsonl", "--jobs", "0"])
            .unwrap_err()
            .to_string();
        assert!(err.contains("--jobs"), "{err}");
    }

    #[test]
    fn engine_errors_get_the_command_line_flags_back() {
        let words = |error: SweepError| format!("{:#}", in_cli_words(error));
        let path = PathBuf::from("r.jsonl");
        assert_eq!(
            words(SweepError::AlreadyHoldsResults { path: path.clone() }),
            "r.jsonl already holds results; pass --resume to continue that sweep, or --force to replace it"
        );
        assert_eq!(
            words(SweepError::MergeWouldReplace { path: path.clone() }),
            "r.jsonl already exists; pass --force to replace it, or merge into another file"
        );
        assert_eq!(
            words(SweepError::ForeignGrid {
                at: "r.jsonl:1".into(),
                found: "engines=1,2".into(),
                expected: "engines=4".into(),
                joining: Joining::Resume,
            }),
            "r.jsonl:1: results are for the grid 'engines=1,2', but this sweep has the grid \
             'engines=4'; choose another --out, or pass --force instead of --resume to start \
             over in this file"
        );
        assert_eq!(
            words(SweepError::SweepPointFailed {
                index: 3,
                key: "engines=8".into(),
                kept: 2,
                kept_in: path.clone(),
                source: anyhow::anyhow!("cause").context("context").into(),
            }),
            "point 3 (engines=8) failed; the 2 points finished are kept in r.jsonl \
             (rerun with --resume): context: cause"
        );
        assert_eq!(
            words(SweepError::SweepPointFailed {
                index: 0,
                key: "engines=1".into(),
                kept: 0,
                kept_in: path,
                source: anyhow::anyhow!("cause").into(),
            }),
            "point 0 (engines=1) failed; no point had finished: cause"
        );
        assert_eq!(
            words(SweepError::BadGrid {
                at: "s.jsonl:1".into(),
                source: Box::new(SweepError::BadAxis {
                    spec: "a=".into(),
                    why: "no values after 'a='".into(),
                }),
            }),
            "s.jsonl:1: bad grid: bad --set 'a=': no values after 'a='"
        );
        assert_eq!(
            words(SweepError::NonNumericAxis {
                key: "merge".into(),
                value: "tree".into(),
            }),
            "cannot plot against 'merge': value 'tree' is not a number (choose another --plot-x)"
        );
        // A merge's mismatch names no flag: it passes as the engine says it.
        let merge = SweepError::ForeignTrace {
            at: "b.jsonl:1".into(),
            found: "d2".into(),
            expected: "d1".into(),
            joining: Joining::Merge {
                first: "a.jsonl:1".into(),
            },
        };
        let engine_words = merge.to_string();
        assert_eq!(words(merge), engine_words);
    }

    #[test]
    fn run_with_rejects_keys_the_machine_does_not_know() {
        let args = parse(&["t.trace", "--out", "unused.jsonl", "--set", "engnies=1,2"]).unwrap();
        let machine_keys = |key: &str, value: &str| -> std::result::Result<String, String> {
            match key {
                "boards" | "engines" => Ok(value.to_owned()),
                _ => Err(format!(
                    "unknown parameter '{key}' (known: boards, engines)"
                )),
            }
        };
        let never = |_: &Point| -> Result<PointRecord> { anyhow::bail!("no point may run") };
        let err = run_with(&args, &never, "d", &machine_keys)
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "bad --set engnies=1: unknown parameter 'engnies' (known: boards, engines)"
        );
    }

    #[test]
    fn jobs_are_at_least_one() {
        use crate::commands::at_least_one_job;
        assert_eq!(at_least_one_job("0"), Err("give at least 1".to_string()));
        assert_eq!(at_least_one_job("3"), Ok(3));
        let error = parse(&["t.occt", "--out", "r.jsonl", "--jobs", "0"])
            .err()
            .unwrap();
        assert!(
            error
                .to_string()
                .contains("'0' for '--jobs <JOBS>': give at least 1"),
            "{error}"
        );
    }

    #[test]
    fn jobs_are_capped_by_the_points_and_the_cores() {
        assert_eq!(capped_jobs(100_000, 30, 2), 8, "4 a core");
        assert_eq!(capped_jobs(100_000, 5, 2), 5, "no more than the points");
        assert_eq!(capped_jobs(3, 30, 2), 3, "a sane request stands");
        assert_eq!(capped_jobs(4, 0, 2), 1, "an empty shard still gets one");
    }
}
