//! `occsim latency TRACE --arch ... --engines 1,2,4,8,16`: replay a trace once per engine
//! count and tabulate what its queries' latency costs: p50/p95/max in cycles and
//! microseconds, split into drain, local merge and global merge (means, which add up to the
//! mean latency; at the cycle and rtl levels, whose reports split it), total cycles and
//! fragments per cycle. `--plot FILE.svg` draws the table.

use super::arch::ArchSelection;
use super::replay::replay_trace;
use super::sensitivity::{CornerBands, FigureBands, Replayer};
use anyhow::{bail, Context};
use occsim_sim::levels::LevelResult;
use occsim_sim::report::QueryReport;
use occsim_sim::sensitivity::Headlines;
use occsim_sim::Fidelity;
use occsim_sweep::plot::{LineChart, Scale, Series};
use occsim_sweep::{Axis, Grid, Point, Pool};
use occsim_traces::retile::TileGrid;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct LatencyArgs {
    /// The fragment trace (.occt) to replay.
    pub trace: PathBuf,
    #[command(flatten)]
    pub arch: ArchSelection,
    /// Occlusion engines per Occlusion Unit, one replay each (comma-separated).
    #[arg(
        long,
        value_name = "E,E,...",
        value_delimiter = ',',
        default_value = "1,2,4,8,16"
    )]
    pub engines: Vec<u64>,
    /// Replace every brief query's tiles by a G by H grid over the viewport (the golden
    /// results are recomputed), e.g. --retile 8x8.
    #[arg(long, value_name = "GxH")]
    pub retile: Option<TileGrid>,
    /// Level of detail: analytic, sampled:K, cycle or rtl (a level with time; only cycle
    /// and rtl split latency into drain and merges).
    #[arg(long, value_name = "LEVEL", default_value = "cycle")]
    pub fidelity: occsim_sim::Fidelity,
    /// Print the rows as JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Also draw the table as an SVG line chart.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Print a sensitivity band beside each row's figures: the row replayed at the corners
    /// a sensitivity study around the base architecture finds (engines left as the row has
    /// them; see `occsim sensitivity`).
    #[arg(long)]
    pub bands: bool,
    /// Replays run at once.
    #[arg(long, default_value_t = super::sensitivity::default_jobs(), value_parser = super::at_least_one_job)]
    pub jobs: usize,
}

/// One engine count's figures.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct LatencyRow {
    pub engines: u64,
    pub queries: u64,
    pub latency_p50_cycles: u64,
    pub latency_p95_cycles: u64,
    pub latency_max_cycles: u64,
    pub latency_p50_us: f64,
    pub latency_p95_us: f64,
    pub latency_max_us: f64,
    /// Means over the queries; they add up to the mean latency (None below the cycle level,
    /// which predicts latency whole).
    pub drain_mean_cycles: Option<f64>,
    pub local_merge_mean_cycles: Option<f64>,
    pub global_merge_mean_cycles: Option<f64>,
    pub total_cycles: u64,
    pub fragments_per_cycle: f64,
    /// Frames of a closed-loop trace and their mean time (None for an open-loop trace or a
    /// level that does not time frames).
    pub frames: u64,
    pub frame_mean_cycles: Option<f64>,
    pub frames_per_second: Option<f64>,
    /// With `--bands`: each headline figure's band over the study's corners.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bands: Option<FigureBands>,
}

impl LatencyRow {
    fn of(engines: u64, result: &LevelResult, clock_mhz: f64) -> LatencyRow {
        // A part of the queries' latency, their mean: none below the cycle level (no report)
        // and none for a part the machine has not (the O2's merges: `-`, null in JSON).
        let mean = |part: &dyn Fn(&QueryReport) -> Option<u64>| -> Option<f64> {
            let queries = &result.report.as_ref()?.queries;
            let parts: Vec<u64> = queries.iter().map(part).collect::<Option<_>>()?;
            (!parts.is_empty()).then(|| parts.iter().sum::<u64>() as f64 / parts.len() as f64)
        };
        let total_cycles = result.total_cycles.unwrap_or(0);
        let us = |cycles: u64| cycles as f64 / clock_mhz;
        // The level's own figures: a trace without a query, which has none, is refused
        // before any replay.
        let [p50, p95, max] = [
            result.latency_p50_cycles,
            result.latency_p95_cycles,
            result.latency_max_cycles,
        ]
        .map(|figure| figure.unwrap_or_default());
        LatencyRow {
            engines,
            queries: result.queries.len() as u64,
            latency_p50_cycles: p50,
            latency_p95_cycles: p95,
            latency_max_cycles: max,
            latency_p50_us: us(p50),
            latency_p95_us: us(p95),
            latency_max_us: us(max),
            drain_mean_cycles: mean(&|q| Some(q.drain_cycles)),
            local_merge_mean_cycles: mean(&|q| q.local_merge_cycles),
            global_merge_mean_cycles: mean(&|q| q.global_merge_cycles),
            total_cycles,
            fragments_per_cycle: if total_cycles == 0 {
                0.0
            } else {
                result.fragments as f64 / total_cycles as f64
            },
            frames: result.frame_cycles.len() as u64,
            frame_mean_cycles: result.frame_mean_cycles(),
            frames_per_second: result.frames_per_second,
            bands: None,
        }
    }
}

pub fn run(args: LatencyArgs) -> anyhow::Result<()> {
    occsim_sweep::output::note_input(&args.trace);
    super::check_output(args.plot.as_deref(), "--plot")?;
    if args.engines.is_empty() {
        bail!("--engines: give at least one engine count");
    }
    if let Some(set) = super::arch::set_of(&args.arch.set, "engines") {
        // Every row sets its own count: the --set would be overridden without a word.
        bail!("--set {set}: latency replays once per --engines count; give the counts there");
    }
    let (_, summary, _) = super::trace::read_header_and_summary(&args.trace, false)?;
    anyhow::ensure!(
        summary.queries > 0,
        "{}: the trace has no query, so no latency to show (`occsim replay` times its cycles)",
        args.trace.display()
    );
    let base = args.arch.resolve()?;
    anyhow::ensure!(
        args.fidelity != Fidelity::Functional,
        "latency needs a level with time: analytic, sampled:K, cycle or rtl, not functional"
    );
    let clock_mhz = match base.get("clock_mhz") {
        Some(occsim_sim::arch::Value::Float(mhz)) => mhz,
        _ => bail!("the architecture has no clock_mhz"),
    };
    if let Some(twice) = super::first_repeated(&args.engines) {
        bail!("--engines: {twice} appears twice");
    }
    // A sweep over one axis, engines, through the sweep engine's pool (with its progress bar).
    let grid = Grid::from_axes(vec![Axis {
        key: "engines".into(),
        values: args.engines.iter().map(u64::to_string).collect(),
    }])?;
    let replayer = Replayer {
        trace: &args.trace,
        retile: args.retile,
        fidelity: args.fidelity,
        jobs: args.jobs,
    };
    let corners = match args.bands {
        true => Some(CornerBands::find(&replayer, &base, &["engines"])?),
        false => None,
    };
    let pool = Pool {
        grid: &grid,
        jobs: args.jobs,
        show_progress: true,
        failure: &|point: &Point| format!("--engines {}", point.values[0].1),
    };
    let rows = pool.collect(&|point: &Point| {
        let engines = &point.values[0].1;
        let mut arch = base.clone();
        arch.set_value("engines", engines)?;
        let result = replay_trace(&args.trace, &arch, args.retile, args.fidelity)?;
        let mut row = LatencyRow::of(engines.parse()?, &result, clock_mhz);
        if let Some(corners) = &corners {
            let default = Headlines::of(&result, clock_mhz);
            row.bands = Some(corners.at(&replayer, &arch, &default)?);
        }
        Ok(row)
    })?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        out!("{}", table(&rows));
    }
    if let Some(path) = &args.plot {
        chart(&args, &rows)
            .write_svg(path)
            .with_context(|| format!("cannot write plot {}", path.display()))?;
    }
    Ok(())
}

fn table(rows: &[LatencyRow]) -> String {
    let split = |mean: Option<f64>| mean.map_or("-".to_string(), |m| format!("{m:.1}"));
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:>7} {:>7} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>12} {:>8} {:>12} {:>9}",
        "engines",
        "queries",
        "p50",
        "p95",
        "max",
        "p50_us",
        "p95_us",
        "max_us",
        "drain",
        "local",
        "global",
        "cycles",
        "frag/cyc",
        "frame cyc",
        "frames/s"
    );
    for r in rows {
        let _ = writeln!(
            out,
            "{:>7} {:>7} {:>9} {:>9} {:>9} {:>9.3} {:>9.3} {:>9.3} {:>9} {:>9} {:>9} {:>12} {:>8.3} {:>12} {:>9}",
            r.engines,
            r.queries,
            r.latency_p50_cycles,
            r.latency_p95_cycles,
            r.latency_max_cycles,
            r.latency_p50_us,
            r.latency_p95_us,
            r.latency_max_us,
            split(r.drain_mean_cycles),
            split(r.local_merge_mean_cycles),
            split(r.global_merge_mean_cycles),
            r.total_cycles,
            r.fragments_per_cycle,
            r.frame_mean_cycles
                .map_or("-".to_string(), |c| format!("{c:.0}")),
            r.frames_per_second
                .map_or("-".to_string(), |f| format!("{f:.2}"))
        );
        if let Some(bands) = &r.bands {
            let _ = writeln!(out, "{:>7} band: {}", "", bands.text());
        }
    }
    let _ = writeln!(
        out,
        "latency in cycles; drain, local and global are mean cycles per query (they add up to the mean latency; - where the level predicts latency whole, and the O2's local and global: it has no merge); frame cyc is the mean frame time of a closed-loop trace (- for an open loop or a level that does not time frames)"
    );
    if rows.iter().any(|r| r.bands.is_some()) {
        let _ = writeln!(
            out,
            "band: low..high of each figure over the parameters marked I at the corners of their plausible ranges (occsim sensitivity)"
        );
    }
    out
}

fn chart(args: &LatencyArgs, rows: &[LatencyRow]) -> LineChart {
    let series = |name: &str, y: &dyn Fn(&LatencyRow) -> f64| Series {
        name: name.to_string(),
        points: rows.iter().map(|r| (r.engines as f64, y(r))).collect(),
    };
    let arch = args.arch.describe();
    LineChart {
        title: format!("query latency, {} on {arch}", args.trace.display()),
        x_label: "occlusion engines per Occlusion Unit".to_string(),
        y_label: "query latency (cycles)".to_string(),
        x_scale: Scale::Log10,
        y_scale: Scale::Linear,
        x_ticks: Some(rows.iter().map(|r| r.engines as f64).collect()),
        series: [
            series("latency p50", &|r| r.latency_p50_cycles as f64),
            series("latency p95", &|r| r.latency_p95_cycles as f64),
            series("latency max", &|r| r.latency_max_cycles as f64),
        ]
        .into_iter()
        .chain(
            rows.iter()
                .all(|r| r.drain_mean_cycles.is_some())
                .then(|| {
                    [
                        series("drain (mean)", &|r| r.drain_mean_cycles.unwrap_or(0.0)),
                        series("local merge (mean)", &|r| {
                            r.local_merge_mean_cycles.unwrap_or(0.0)
                        }),
                        series("global merge (mean)", &|r| {
                            r.global_merge_mean_cycles.unwrap_or(0.0)
                        }),
                    ]
                })
                .into_iter()
                .flatten(),
        )
        .collect(),
    }
}
