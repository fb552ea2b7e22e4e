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
use occsim_traces::retile::TileGrid;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `--fidelity LEVEL --effects auto|all`.
#[derive(clap::Args, Clone, Debug)]
pub struct FidelityArg {
    /// Level of detail: functional, analytic, sampled:K (cycle model on every K-th query
    /// window, and on the O2 at K up to 15 on the slowest fifteenth the formulas predict),
    /// cycle or rtl.
    #[arg(long, value_name = "LEVEL", default_value = "cycle")]
    pub fidelity: Fidelity,
    /// Effect models of the cycle and sampled levels: auto (only those the trace can
    /// observe: same results and cycles; the default) or all (what the rtl level builds).
    #[arg(long, value_name = "auto|all")]
    pub effects: Option<EffectsChoice>,
    /// At the analytic and sampled levels, decode every fragment even where the trace's
    /// window index (and its depth-test blocks) would do (the same result, slower: for
    /// checking and timing the index).
    #[arg(long)]
    pub no_index: bool,
}

impl FidelityArg {
    /// The effects chosen (auto unless given), or why the level takes no choice: `--effects`
    /// and `--no-index` beside a level they do not apply to had been passed over unsaid.
    pub fn effects(&self) -> anyhow::Result<EffectsChoice> {
        let level = self.fidelity;
        anyhow::ensure!(
            !self.no_index || matches!(level, Fidelity::Analytic | Fidelity::Sampled { .. }),
            "--no-index applies to the analytic and sampled levels, which read the trace's index (the {level} level decodes every fragment)"
        );
        match (level, self.effects) {
            // The rtl level builds every model: `all` is what it does, `auto` it cannot do.
            (Fidelity::Rtl, Some(EffectsChoice::Auto)) => {
                anyhow::bail!("--effects: the rtl level builds every effect model (--effects all)")
            }
            (Fidelity::Functional | Fidelity::Analytic, Some(_)) => anyhow::bail!(
                "--effects: the {level} level has no effect models (the cycle and sampled levels choose theirs)"
            ),
            (_, chosen) => Ok(chosen.unwrap_or(EffectsChoice::Auto)),
        }
    }
}

#[derive(clap::Args)]
pub struct FidelityArgs {
    /// The fragment trace (.occt); leave it out with --corpus.
    #[arg(required_unless_present = "corpus")]
    pub trace: Option<PathBuf>,
    #[command(flatten)]
    pub arch: ArchSelection,
    /// Occlusion engines (shorthand for --set engines=E); with --corpus, the engine counts
    /// to run instead of the corpus's (comma separated).
    #[arg(long, value_name = "E", value_delimiter = ',')]
    pub engines: Vec<u64>,
    /// Replace every brief query's tiles by a G by H grid over the viewport (the golden
    /// results are recomputed), e.g. --retile 8x8.
    #[arg(long, value_name = "GxH")]
    pub retile: Option<TileGrid>,
    #[command(flatten)]
    pub corpus: super::corpus::CorpusArgs,
    /// K of the sampled level: the cycle model runs on every K-th query window (and, on the
    /// O2 at K up to 15, on the slowest fifteenth the formulas predict).
    #[arg(long, value_name = "K", default_value_t = 10, value_parser = clap::value_parser!(u32).range(1..))]
    pub sample_every: u32,
    /// Effect models of the cycle and sampled levels.
    #[arg(long, value_name = "auto|all", default_value = "auto")]
    pub effects: EffectsChoice,
    /// Leave out the rtl level (slowest): errors are then relative to cycle.
    #[arg(long)]
    pub no_rtl: bool,
    /// Draw error against wall time (log-log) as SVG; with --corpus, each class's worst
    /// error against its speed over cycle, a line through its levels.
    #[arg(long, value_name = "F.svg")]
    pub plot: Option<PathBuf>,
    /// Print the table as JSON.
    #[arg(long)]
    pub json: bool,
}

/// One row of the table.
#[derive(Clone, Serialize)]
pub struct LevelRow {
    pub level: String,
    pub wall_seconds: Option<f64>,
    pub fragments_per_second: Option<f64>,
    pub total_cycles: Option<u64>,
    pub latency_mean_cycles: Option<f64>,
    pub latency_p95_cycles: Option<u64>,
    /// |predicted - reference| / reference, of the total cycles, the mean latency and the
    /// p95 latency.
    pub cycles_error: Option<f64>,
    pub latency_error: Option<f64>,
    pub latency_p95_error: Option<f64>,
    /// Every query's own latency error, |predicted - reference| / reference (a reference
    /// of 0 counts as 1): the distribution's p50, p95 and max.
    pub query_latency_error: Option<ErrorDistribution>,
    /// The mean frame time of a closed-loop trace, and its error against the reference's.
    pub frame_mean_cycles: Option<f64>,
    pub frame_error: Option<f64>,
    /// Every query's value equals the reference level's.
    pub results_exact: Option<bool>,
    pub note: Option<String>,
    /// Every query's latency error, in order (for the corpus's pooled distribution).
    #[serde(skip)]
    pub query_errors: Vec<f64>,
}

/// Nearest-rank p50 and p95 and the max of a set of relative errors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ErrorDistribution {
    pub p50: f64,
    pub p95: f64,
    pub max: f64,
}

impl ErrorDistribution {
    /// None for an empty set.
    pub fn of(mut errors: Vec<f64>) -> Option<ErrorDistribution> {
        if errors.is_empty() {
            return None;
        }
        errors.sort_by(f64::total_cmp);
        let rank = |p: usize| errors[(errors.len() * p).div_ceil(100).max(1) - 1];
        Some(ErrorDistribution {
            p50: rank(50),
            p95: rank(95),
            max: errors[errors.len() - 1],
        })
    }
}

/// Each query's latency error against the reference's, in order (queries without a
/// latency on either side are left out).
pub fn query_latency_errors(result: &LevelResult, reference: &LevelResult) -> Vec<f64> {
    result
        .queries
        .iter()
        .zip(&reference.queries)
        .filter_map(|(q, r)| {
            let (q, r) = (q.latency_cycles? as f64, r.latency_cycles? as f64);
            Some((q - r).abs() / r.max(1.0))
        })
        .collect()
}

/// Replay the trace at `path` at `level`, streaming it from the file (a demo trace holds
/// tens of millions of fragments: too many to hold as events).
pub fn replay_level(
    level: Fidelity,
    arch: &Arch,
    path: &Path,
    retile: Option<TileGrid>,
    effects: EffectsChoice,
) -> anyhow::Result<LevelResult> {
    let name = path.display().to_string();
    let options = ReplayOptions {
        effects,
        retile,
        ..ReplayOptions::at(level)
    };
    replay(opener(path), arch, options)
        .map_err(|e| in_cli_words(&name, e))
        .with_context(|| level.to_string())
}

/// A level's result and wall seconds: the fastest of repeated runs within about 0.3 s
/// (one run for a large trace). Wall time includes decoding the trace.
fn timed(
    level: Fidelity,
    arch: &Arch,
    path: &Path,
    retile: Option<TileGrid>,
    effects: EffectsChoice,
) -> anyhow::Result<(LevelResult, f64)> {
    let mut best = f64::INFINITY;
    let mut spent = 0.0;
    let mut result = None;
    for _ in 0..20 {
        let start = Instant::now();
        let run = replay_level(level, arch, path, retile, effects)?;
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

/// How to run the ladder on one trace.
#[derive(Clone, Copy)]
pub struct Ladder {
    pub sample_every: u32,
    pub effects: EffectsChoice,
    pub retile: Option<TileGrid>,
    pub rtl: bool,
}

impl Ladder {
    /// The levels, cheapest first; the last is the reference.
    fn levels(&self) -> Vec<Fidelity> {
        let mut levels = vec![
            Fidelity::Functional,
            Fidelity::Analytic,
            Fidelity::Sampled {
                every: self.sample_every,
            },
            Fidelity::Cycle,
        ];
        if self.rtl {
            levels.push(Fidelity::Rtl);
        }
        levels
    }

    /// The level the others' errors are against: the most detailed that runs.
    pub fn reference(&self) -> Fidelity {
        if self.rtl {
            Fidelity::Rtl
        } else {
            Fidelity::Cycle
        }
    }

    /// Every level on the trace at `path`, timed, with its errors against the reference
    /// level, in the table's rows; and the trace's fragments.
    pub fn run(
        &self,
        arch: &Arch,
        path: &Path,
        progress: &occsim_sweep::progress::ProgressBar,
    ) -> anyhow::Result<(Vec<LevelRow>, u64)> {
        let name = path.display().to_string();
        let summary = open_trace(path)?
            .skip_to_summary()
            .with_context(|| format!("{name}: cannot read trace"))?;
        let fragments = summary.fragments as f64;
        let mut runs = Vec::new();
        for level in self.levels() {
            progress.set_message(format!("fidelity: {level}"));
            runs.push((level, timed(level, arch, path, self.retile, self.effects)?));
            progress.inc(1);
        }
        let reference_level = self.reference();
        let (_, (reference, _)) = runs
            .iter()
            .find(|(level, _)| *level == reference_level)
            .context("the reference level did not run")?;
        let rows = runs
            .iter()
            .map(|(level, (result, seconds))| {
                let mut row = compare_with(result, reference, *seconds, fragments);
                row.level = level.to_string();
                row.note = (*level == reference_level).then(|| "reference".to_string());
                row
            })
            .collect();
        Ok((rows, summary.fragments))
    }
}

/// A level's row: its figures and errors against the reference's.
fn compare_with(
    result: &LevelResult,
    reference: &LevelResult,
    seconds: f64,
    fragments: f64,
) -> LevelRow {
    let values: Vec<u64> = result.queries.iter().map(|q| q.value).collect();
    let reference_values: Vec<u64> = reference.queries.iter().map(|q| q.value).collect();
    let timed = result.total_cycles.is_some();
    let query_errors = match timed {
        true => query_latency_errors(result, reference),
        false => Vec::new(),
    };
    LevelRow {
        level: String::new(),
        wall_seconds: Some(seconds),
        fragments_per_second: Some(fragments / seconds.max(1e-9)),
        total_cycles: result.total_cycles,
        latency_mean_cycles: result.latency_mean_cycles,
        latency_p95_cycles: result.latency_p95_cycles,
        cycles_error: relative_error(
            result.total_cycles.map(|c| c as f64),
            reference.total_cycles.map(|c| c as f64),
        ),
        latency_error: relative_error(result.latency_mean_cycles, reference.latency_mean_cycles),
        latency_p95_error: relative_error(
            result.latency_p95_cycles.map(|c| c as f64),
            reference.latency_p95_cycles.map(|c| c as f64),
        ),
        query_latency_error: ErrorDistribution::of(query_errors.clone()),
        frame_mean_cycles: result.frame_mean_cycles(),
        frame_error: relative_error(result.frame_mean_cycles(), reference.frame_mean_cycles()),
        results_exact: Some(values == reference_values),
        note: None,
        query_errors,
    }
}

pub fn run(args: FidelityArgs) -> anyhow::Result<()> {
    if let Some(trace) = &args.trace {
        occsim_sweep::output::note_input(trace);
    }
    super::check_output(args.plot.as_deref(), "--plot")?;
    let ladder = Ladder {
        sample_every: args.sample_every,
        effects: args.effects,
        retile: args.retile,
        rtl: !args.no_rtl,
    };
    let Some(trace) = &args.trace else {
        // The corpus names its machines; --arch would have been passed over unsaid.
        let (arch, file) = (&args.arch.arch, &args.arch.arch_file);
        anyhow::ensure!(
            arch == super::arch::DEFAULT_ARCH && file.is_none(),
            "--arch and --arch-file choose one trace's machine; with --corpus, --machines {arch} runs the corpus on built-in machines of your choice"
        );
        // The corpus's recipes retile their own traces (its `retile` classes).
        anyhow::ensure!(
            args.retile.is_none(),
            "--retile retiles one trace; with --corpus, the corpus's recipes name their grids (`retile = \"GxH\"`, the retiled classes)"
        );
        return super::corpus::run(
            &args.corpus,
            &ladder,
            &args.engines,
            &args.arch.set,
            (args.json, args.plot.as_deref()),
        );
    };
    anyhow::ensure!(!args.corpus.corpus, "give a TRACE or --corpus, not both");
    // As the user named it (`ir4`, not the machine's `ir`), with the engine count given.
    let engines = match args.engines[..] {
        [] => None,
        [engines] => Some(engines),
        _ => anyhow::bail!("--engines: one engine count for one trace (a list is for --corpus)"),
    };
    let (arch, arch_name) = args.arch.resolve_with_engines(engines)?;
    let path = trace.display().to_string();
    // One step a level (not a bar over bytes: drawing one would be timed with the level).
    let bar = occsim_sweep::progress::bar(ladder.levels().len() as u64, "levels");
    let (rows, fragments) = ladder.run(&arch, trace, &bar)?;
    bar.finish_and_clear();
    let reference_level = ladder.reference();
    let what = match args.retile {
        Some(grid) => format!("{path} (retiled {grid})"),
        None => path.clone(),
    };
    if let Some(plot) = &args.plot {
        error_chart(&rows, &what, &arch_name, reference_level)?
            .write_svg(plot)
            .with_context(|| format!("cannot write {}", plot.display()))?;
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        out!(
            "{}",
            table(&rows, &what, &arch_name, fragments, reference_level)
        );
    }
    Ok(())
}

fn table(rows: &[LevelRow], path: &str, arch: &str, fragments: u64, reference: Fidelity) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{path} on {arch}: {fragments} fragments; errors relative to {reference}"
    );
    let _ = writeln!(
        out,
        "{:<12} {:>10} {:>12} {:>13} {:>10} {:>9} {:>10} {:>10} {:>9} {:>22} {:>12} {:>10} {:>8}",
        "level",
        "wall s",
        "fragments/s",
        "cycles",
        "mean lat",
        "p95 lat",
        "cycles err",
        "lat err",
        "p95 err",
        "query err p50/p95/max",
        "frame cycles",
        "frame err",
        "results"
    );
    let float =
        |v: Option<f64>, digits: usize| v.map_or("-".to_string(), |v| format!("{v:.digits$}"));
    let int = |v: Option<u64>| v.map_or("-".to_string(), |v| v.to_string());
    for row in rows {
        let _ = writeln!(
            out,
            "{:<12} {:>10} {:>12} {:>13} {:>10} {:>9} {:>10} {:>10} {:>9} {:>22} {:>12} {:>10} {:>8}",
            row.level,
            float(row.wall_seconds, 4),
            row.fragments_per_second
                .map_or("-".to_string(), |v| format!("{:.3e}", v)),
            int(row.total_cycles),
            float(row.latency_mean_cycles, 1),
            int(row.latency_p95_cycles),
            percent(row.cycles_error),
            percent(row.latency_error),
            percent(row.latency_p95_error),
            distribution(row.query_latency_error),
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
         cycles; frame cycles: the mean frame in cycles; cycles err, lat err, p95 err, frame \
         err: |level - {reference}| / {reference} of cycles, mean latency, p95 latency and frame \
         cycles; query err: each query's own latency error, its p50, p95 and max; results: \
         every query's counts equal the golden ones (exact); -: the level has no such figure"
    );
    out
}

/// A fraction in percent with two decimals, or `-`.
pub fn percent(fraction: Option<f64>) -> String {
    fraction.map_or("-".to_string(), |v| format!("{:.2}%", 100.0 * v))
}

/// `p50/p95/max` in percent, or `-`.
pub fn distribution(errors: Option<ErrorDistribution>) -> String {
    errors.map_or("-".to_string(), |e| {
        format!(
            "{:.1}/{:.1}/{:.1}%",
            100.0 * e.p50,
            100.0 * e.p95,
            100.0 * e.max
        )
    })
}

/// The error drawn for a level whose error is 0 (the reference), so a log axis can show it,
/// in percent as the table prints errors.
pub(super) const ERROR_FLOOR_PERCENT: f64 = 0.01;

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
            // A run without a query has a cycles error and no latency to err: it is drawn
            // by the one it has (it had been left out, and the chart with it).
            let error = 100.0 * row.cycles_error?.max(row.latency_error.unwrap_or(0.0));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_distribution_is_nearest_rank() {
        // Sorted: 0.1, 0.2, 0.3, 0.5. p50: rank ceil(4 * 0.50) = 2, so 0.2; p95: rank
        // ceil(4 * 0.95) = 4, so 0.5; max 0.5.
        let errors = ErrorDistribution::of(vec![0.3, 0.1, 0.5, 0.2]).unwrap();
        assert_eq!(
            errors,
            ErrorDistribution {
                p50: 0.2,
                p95: 0.5,
                max: 0.5
            }
        );
        assert_eq!(ErrorDistribution::of(Vec::new()), None);
        assert_eq!(distribution(Some(errors)), "20.0/50.0/50.0%");
    }
}
