//! `occsim fidelity TRACE`: what accuracy costs. Runs every level of the fidelity ladder on
//! the same trace and prints, per level, wall time, fragments per second, predicted cycles,
//! query latency and the error against the reference level (the most detailed level that
//! ran: `rtl`, else `cycle`).
//! Also [`FidelityArg`], the `--fidelity`/`--effects` options replay shares (and sweep and
//! latency may add).

use super::arch::ArchSelection;
use super::replay::{in_cli_words, opener};
use super::trace::open_trace;
use anyhow::Context;
use occsim_sim::effects::EffectsChoice;
use occsim_sim::levels::{Fidelity, LevelResult};
use occsim_sim::replay::{replay, ReplayOptions};
use occsim_sim::Arch;
use occsim_sweep::plot::{LineChart, Scale, Series};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `--fidelity LEVEL --effects auto|all`.
#[derive(clap::Args, Clone, Debug)]
pub struct FidelityArg {
    /// Level of detail: functional, analytic, sampled:K (cycle model on every K-th query
    /// window), cycle or rtl.
    #[arg(long, value_name = "LEVEL", default_value = "cycle")]
    pub fidelity: Fidelity,
    /// Effect models: auto (only those the trace can observe: same results and cycles) or
    /// all.
    #[arg(long, value_name = "auto|all", default_value = "auto")]
    pub effects: EffectsChoice,
}

#[derive(clap::Args)]
pub struct FidelityArgs {
    /// The fragment trace (.occt).
    pub trace: PathBuf,
    #[command(flatten)]
    pub arch: ArchSelection,
    /// K of the sampled level: the cycle model runs on every K-th query window.
    #[arg(long, value_name = "K", default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
    pub sample_every: u32,
    /// Effect models of the cycle and sampled levels.
    #[arg(long, value_name = "auto|all", default_value = "auto")]
    pub effects: EffectsChoice,
    /// Leave out the rtl level (slowest): errors are then relative to cycle.
    #[arg(long)]
    pub no_rtl: bool,
    /// Draw error against wall time (log-log) as SVG.
    #[arg(long, value_name = "F.svg")]
    pub plot: Option<PathBuf>,
    /// Print the table as JSON.
    #[arg(long)]
    pub json: bool,
}

/// One row of the table.
#[derive(Serialize)]
struct LevelRow {
    level: String,
    wall_seconds: Option<f64>,
    fragments_per_second: Option<f64>,
    total_cycles: Option<u64>,
    latency_mean_cycles: Option<f64>,
    latency_p95_cycles: Option<u64>,
    /// |predicted - reference| / reference, of the total cycles and the mean latency.
    cycles_error: Option<f64>,
    latency_error: Option<f64>,
    /// The mean frame time of a closed-loop trace, and its error against the reference's.
    frame_mean_cycles: Option<f64>,
    frame_error: Option<f64>,
    /// Every query's value equals the reference level's.
    results_exact: Option<bool>,
    note: Option<String>,
}

/// Replay the trace at `path` at `level`, streaming it from the file (a demo trace holds
/// tens of millions of fragments: too many to hold as events).
pub fn replay_level(
    level: Fidelity,
    arch: &Arch,
    path: &Path,
    effects: EffectsChoice,
) -> anyhow::Result<LevelResult> {
    let name = path.display().to_string();
    let options = ReplayOptions {
        effects,
        ..ReplayOptions::at(level)
    };
    replay(opener(path), arch, options)
        .map_err(|e| in_cli_words(&name, e))
        .with_context(|| format!("{name}: {level}"))
}

/// A level's result and wall seconds: the fastest of repeated runs within about 0.3 s
/// (one run for a large trace). Wall time includes decoding the trace.
fn timed(
    level: Fidelity,
    arch: &Arch,
    path: &Path,
    effects: EffectsChoice,
) -> anyhow::Result<(LevelResult, f64)> {
    let mut best = f64::INFINITY;
    let mut spent = 0.0;
    let mut result = None;
    for _ in 0..20 {
        let start = Instant::now();
        let run = replay_level(level, arch, path, effects)?;
        let seconds = start.elapsed().as_secs_f64();
        best = best.min(seconds);
        spent += seconds;
        result = Some(run);
        if spent > 0.3 {
            break;
        }
    }
    Ok((result.expect("at least one run"), best))
}

fn relative_error(value: Option<f64>, reference: Option<f64>) -> Option<f64> {
    match (value, reference) {
        (Some(v), Some(r)) if r > 0.0 => Some((v - r).abs() / r),
        (Some(v), Some(_)) => Some(if v == 0.0 { 0.0 } else { 1.0 }),
        _ => None,
    }
}

pub fn run(args: FidelityArgs) -> anyhow::Result<()> {
    let arch = args.arch.resolve()?;
    let path = args.trace.display().to_string();
    let summary = open_trace(&args.trace)?
        .skip_to_summary()
        .with_context(|| format!("{path}: cannot read trace"))?;
    let fragments = summary.fragments as f64;
    let mut levels = vec![
        Fidelity::Functional,
        Fidelity::Analytic,
        Fidelity::Sampled {
            every: args.sample_every,
        },
        Fidelity::Cycle,
    ];
    if !args.no_rtl {
        levels.push(Fidelity::Rtl);
    }
    let mut runs = Vec::new();
    // One step a level (not a bar over bytes: drawing one would be timed with the level).
    let bar = occsim_sweep::progress::bar(levels.len() as u64, "levels");
    for level in levels {
        bar.set_message(format!("fidelity: {level}"));
        runs.push((level, timed(level, &arch, &args.trace, args.effects)?));
        bar.inc(1);
    }
    bar.finish_and_clear();
    // The reference is the most detailed level that ran: rtl, else cycle.
    let (reference_level, (reference, _)) = runs.last().context("no level ran")?;
    let reference_level = *reference_level;
    let reference_values: Vec<u64> = reference.queries.iter().map(|q| q.value).collect();
    let rows: Vec<LevelRow> = runs
        .iter()
        .map(|(level, (result, seconds))| {
            let values: Vec<u64> = result.queries.iter().map(|q| q.value).collect();
            LevelRow {
                level: level.to_string(),
                wall_seconds: Some(*seconds),
                fragments_per_second: Some(fragments / seconds.max(1e-9)),
                total_cycles: result.total_cycles,
                latency_mean_cycles: result.latency_mean_cycles,
                latency_p95_cycles: result.latency_p95_cycles,
                cycles_error: relative_error(
                    result.total_cycles.map(|c| c as f64),
                    reference.total_cycles.map(|c| c as f64),
                ),
                latency_error: relative_error(
                    result.latency_mean_cycles,
                    reference.latency_mean_cycles,
                ),
                frame_mean_cycles: result.frame_mean_cycles(),
                frame_error: relative_error(
                    result.frame_mean_cycles(),
                    reference.frame_mean_cycles(),
                ),
                results_exact: Some(values == reference_values),
                note: (*level == reference_level).then(|| "reference".to_string()),
            }
        })
        .collect();
    if let Some(plot) = &args.plot {
        error_chart(&rows, &path, &args.arch.describe(), reference_level)?
            .write_svg(plot)
            .with_context(|| format!("cannot write {}", plot.display()))?;
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        out!(
            "{}",
            table(&rows, &path, &arch, fragments as u64, reference_level)
        );
    }
    Ok(())
}

fn table(
    rows: &[LevelRow],
    path: &str,
    arch: &Arch,
    fragments: u64,
    reference: Fidelity,
) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{path} on {}: {fragments} fragments; errors relative to {reference}",
        arch.machine().name()
    );
    let _ = writeln!(
        out,
        "{:<12} {:>10} {:>12} {:>13} {:>10} {:>9} {:>10} {:>10} {:>12} {:>10} {:>8}",
        "level",
        "wall s",
        "fragments/s",
        "cycles",
        "mean lat",
        "p95 lat",
        "cycles err",
        "lat err",
        "frame cycles",
        "frame err",
        "results"
    );
    let float =
        |v: Option<f64>, digits: usize| v.map_or("-".to_string(), |v| format!("{v:.digits$}"));
    let int = |v: Option<u64>| v.map_or("-".to_string(), |v| v.to_string());
    let percent = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.2}%", 100.0 * v));
    for row in rows {
        let _ = writeln!(
            out,
            "{:<12} {:>10} {:>12} {:>13} {:>10} {:>9} {:>10} {:>10} {:>12} {:>10} {:>8}",
            row.level,
            float(row.wall_seconds, 4),
            row.fragments_per_second
                .map_or("-".to_string(), |v| format!("{:.3e}", v)),
            int(row.total_cycles),
            float(row.latency_mean_cycles, 1),
            int(row.latency_p95_cycles),
            percent(row.cycles_error),
            percent(row.latency_error),
            float(row.frame_mean_cycles, 0),
            percent(row.frame_error),
            match row.results_exact {
                Some(true) => "exact",
                Some(false) => "DIFFER",
                None => "-",
            }
        );
    }
    let _ = writeln!(
        out,
        "  wall s: seconds on this computer, decoding the trace included; fragments/s: fragments \
         over wall s; cycles: the run's simulated cycles; mean lat, p95 lat: query latency in \
         cycles; frame cycles: the mean frame in cycles; cycles err, lat err, frame err: \
         |level - {reference}| / {reference} of cycles, mean latency and frame cycles; results: \
         every query's counts equal the golden ones (exact); -: the level has no such figure"
    );
    out
}

/// The error drawn for a level whose error is 0 (the reference), so a log axis can show it,
/// in percent as the table prints errors.
const ERROR_FLOOR_PERCENT: f64 = 0.01;

/// Error in percent (the larger of total-cycle and mean-latency error) against wall time,
/// log-log; one single-point series per timed level.
fn error_chart(
    rows: &[LevelRow],
    path: &str,
    arch: &str,
    reference: Fidelity,
) -> anyhow::Result<LineChart> {
    let series = rows
        .iter()
        .filter_map(|row| {
            let seconds = row.wall_seconds?;
            let error = 100.0 * row.cycles_error?.max(row.latency_error?);
            let (y, name) = if error > 0.0 {
                (error, row.level.clone())
            } else {
                (
                    ERROR_FLOOR_PERCENT,
                    format!("{} (error 0, drawn at {ERROR_FLOOR_PERCENT}%)", row.level),
                )
            };
            Some(Series {
                name,
                points: vec![(seconds.max(1e-9), y)],
            })
        })
        .collect();
    Ok(LineChart {
        title: format!(
            "The price of accuracy: {path} on {arch} (functional has no time: not drawn)"
        ),
        x_label: "wall time (s)".to_string(),
        y_label: format!("error vs {reference} (%, the worse of total cycles and mean latency)"),
        x_scale: Scale::Log10,
        y_scale: Scale::Log10,
        x_ticks: None,
        series,
    })
}
