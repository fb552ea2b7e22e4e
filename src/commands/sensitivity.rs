//! `occsim sensitivity TRACE --arch A`: every parameter marked I varied over its plausible
//! range (one at a time at both ends, then all at once at the corners that move each result
//! most; the arithmetic is `occsim_sim::sensitivity`), each headline result reported as a
//! band with the parameters that move it most first; `--plot` a tornado chart, `--json` the
//! bands. Replays run in parallel on the sweep engine's pool; the output does not depend on
//! `--jobs`. `latency` and `sweep` take `--bands` through [`CornerBands`].

use super::arch::ArchSelection;
use super::replay::replay_trace;
use anyhow::Context;
use occsim_sim::arch::{Arch, Value};
use occsim_sim::sensitivity::{
    corner_band, describe_changes, Band, Changes, End, Headlines, Metric, SensitivityError, Study,
};
use occsim_sim::Fidelity;
use occsim_sweep::plot::{TornadoBar, TornadoChart, TornadoPanel};
use occsim_sweep::{Axis, Grid, Point, Pool};
use occsim_traces::retile::TileGrid;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(clap::Args)]
pub struct SensitivityArgs {
    /// The fragment trace (.occt) to replay.
    pub trace: PathBuf,
    #[command(flatten)]
    pub arch: ArchSelection,
    /// Occlusion engines of the default point (shorthand for --set engines=E; the study
    /// still varies them over their range).
    #[arg(long, value_name = "E")]
    pub engines: Option<u64>,
    /// Replace every brief query's tiles by a G by H grid over the viewport, e.g. --retile 8x8.
    #[arg(long, value_name = "GxH")]
    pub retile: Option<TileGrid>,
    /// Level of detail: analytic, sampled:K, cycle or rtl (a level with time).
    #[arg(long, value_name = "LEVEL", default_value = "cycle")]
    pub fidelity: Fidelity,
    /// Replays run at once, at most 4 a core and one a variant (the output is the same for
    /// any number).
    #[arg(long, default_value_t = default_jobs(), value_parser = super::at_least_one_job)]
    pub jobs: usize,
    /// Print the bands as JSON: per result `metric`, `default`, `low`, `high` and the
    /// parameters that move it, the most first.
    #[arg(long)]
    pub json: bool,
    /// Also draw a tornado chart of the bands as SVG.
    #[arg(long, value_name = "FILE.svg")]
    pub plot: Option<PathBuf>,
    /// Parameters listed per result in the table and the chart, at least 1 (the JSON lists
    /// all).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u32).range(1..))]
    pub top: u32,
    /// Print to stderr the replays made and the sum of their wall times (for benchmarks;
    /// never part of the results).
    #[arg(long)]
    pub timing: bool,
}

pub fn default_jobs() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from)
}

/// A finished study.
pub struct Outcome {
    pub bands: Vec<Band>,
    /// The distinct corners (changes from the base), for `--bands` elsewhere.
    pub corners: Vec<Changes>,
    pub replays: usize,
    /// Sum of the replays' wall times, in seconds.
    pub replay_seconds: f64,
}

/// How to replay: the trace and the level, shared by every variant.
pub struct Replayer<'a> {
    pub trace: &'a Path,
    pub retile: Option<TileGrid>,
    pub fidelity: Fidelity,
    pub jobs: usize,
}

impl Replayer<'_> {
    /// Every architecture's headline results (in order) and the sum of the replays' times,
    /// on the sweep engine's pool with a progress bar.
    fn run(&self, archs: &[(Arch, String)]) -> anyhow::Result<(Vec<Headlines>, f64)> {
        if archs.is_empty() {
            return Ok((Vec::new(), 0.0));
        }
        let grid = Grid::from_axes(vec![Axis {
            key: "variant".into(),
            values: (0..archs.len()).map(|i| i.to_string()).collect(),
        }])?;
        let describe = |point: &Point| -> String {
            let index: usize = point.values[0].1.parse().unwrap_or(0);
            archs
                .get(index)
                .map_or(String::new(), |(_, what)| what.clone())
        };
        let pool = Pool {
            grid: &grid,
            jobs: self.jobs.max(1),
            show_progress: true,
            failure: &describe,
        };
        let results = pool.collect(&|point: &Point| {
            let index: usize = point.values[0].1.parse()?;
            let arch = &archs[index].0;
            let start = Instant::now();
            let result = replay_trace(self.trace, arch, self.retile, self.fidelity)?;
            let headlines = Headlines::of(&result, arch.clock_mhz()?);
            Ok((headlines, start.elapsed().as_secs_f64()))
        })?;
        let seconds = results.iter().map(|(_, s)| s).sum();
        Ok((results.into_iter().map(|(h, _)| h).collect(), seconds))
    }

    /// The study around `base`, every I parameter but `fixed` varied.
    pub fn study(&self, base: &Arch, fixed: &[&str]) -> anyhow::Result<Outcome> {
        let study = Study::new(base, fixed).map_err(in_cli_words)?;
        let singles = study.one_at_a_time().map_err(in_cli_words)?;
        let mut archs = vec![(base.clone(), "the default".to_string())];
        archs.extend(singles.iter().map(|(_, _, v)| {
            let (key, value) = v.changes[0];
            (v.arch.clone(), format!("--set {key}={value}"))
        }));
        let (results, mut seconds) = self.run(&archs)?;
        let default = results[0];
        let singles: Vec<((usize, End), Headlines)> = singles
            .iter()
            .zip(&results[1..])
            .map(|((index, end, _), h)| ((*index, *end), *h))
            .collect();
        let mut corners: Vec<Changes> = Vec::new();
        for (_, _, changes) in study.corners(&default, &singles) {
            if !changes.is_empty() && !corners.contains(&changes) {
                corners.push(changes);
            }
        }
        let corner_archs = corners
            .iter()
            .map(|changes| {
                let arch = Study::apply(base, changes).map_err(in_cli_words)?;
                Ok((arch, format!("the corner {}", describe_changes(changes))))
            })
            .collect::<anyhow::Result<Vec<_>>>()?;
        let (corner_results, corner_seconds) = self.run(&corner_archs)?;
        seconds += corner_seconds;
        let with_results: Vec<_> = corners.iter().cloned().zip(corner_results).collect();
        Ok(Outcome {
            bands: study.bands(&default, &singles, &with_results),
            replays: archs.len() + corner_archs.len(),
            replay_seconds: seconds,
            corners,
        })
    }
}

fn in_cli_words(error: SensitivityError) -> anyhow::Error {
    let advice = match error {
        SensitivityError::ImpossibleVariant { .. } => {
            "the values you set leave it no room: bring them back toward their defaults"
        }
        // Whether the value came from --set or an architecture file, the range is the fix.
        _ => "bring it within that range, or leave it at its default",
    };
    anyhow::anyhow!("{error} ({advice})")
}

/// `--bands` for a command that replays many architectures (`latency`, `sweep`): one study
/// around the base architecture finds the corners; each figure's band is then its own
/// replay and its replays at those corners (the command's own axes left where it put them).
pub struct CornerBands {
    pub corners: Vec<Changes>,
}

/// One figure's bands: per metric `(low, high)`.
#[derive(Clone, Debug, serde::Serialize, PartialEq)]
pub struct FigureBands {
    pub cycles: (f64, f64),
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame_ms: Option<(f64, f64)>,
    /// None without a query.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latency_p50_cycles: Option<(f64, f64)>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latency_p95_cycles: Option<(f64, f64)>,
}

impl FigureBands {
    pub fn text(&self) -> String {
        let mut out = format!("cycles {:.0}..{:.0}", self.cycles.0, self.cycles.1);
        for (name, band) in [
            ("p50", self.latency_p50_cycles),
            ("p95", self.latency_p95_cycles),
        ] {
            if let Some((lo, hi)) = band {
                let _ = write!(out, ", {name} {lo:.0}..{hi:.0}");
            }
        }
        if let Some((lo, hi)) = self.frame_ms {
            let _ = write!(out, ", frame {lo:.2}..{hi:.2} ms");
        }
        out
    }
}

impl CornerBands {
    /// The corners of the study around `base`, with `fixed` (the command's axes) not varied.
    pub fn find(replayer: &Replayer<'_>, base: &Arch, fixed: &[&str]) -> anyhow::Result<Self> {
        let outcome = replayer
            .study(base, fixed)
            .context("finding the corners for --bands")?;
        Ok(CornerBands {
            corners: outcome.corners,
        })
    }

    /// The bands of the figure replayed on `arch` (whose result is `default`): its replays at
    /// every corner, in order (run one after another: the caller runs figures in parallel).
    pub fn at(
        &self,
        replayer: &Replayer<'_>,
        arch: &Arch,
        default: &Headlines,
    ) -> anyhow::Result<FigureBands> {
        Study::new(arch, &[]).map_err(in_cli_words)?;
        let mut results = Vec::with_capacity(self.corners.len());
        for changes in &self.corners {
            let corner = Study::apply(arch, changes).map_err(in_cli_words)?;
            let result = replay_trace(replayer.trace, &corner, replayer.retile, replayer.fidelity)
                .with_context(|| format!("the corner {}", describe_changes(changes)))?;
            results.push(Headlines::of(&result, corner.clock_mhz()?));
        }
        let band = |metric| corner_band(default, &results, metric);
        Ok(FigureBands {
            cycles: band(Metric::Cycles).unwrap_or_default(),
            frame_ms: band(Metric::FrameTime),
            latency_p50_cycles: band(Metric::LatencyP50),
            latency_p95_cycles: band(Metric::LatencyP95),
        })
    }
}

pub fn run(args: SensitivityArgs) -> anyhow::Result<()> {
    occsim_sweep::output::note_input(&args.trace);
    super::check_output(args.plot.as_deref(), "--plot")?;
    anyhow::ensure!(
        args.fidelity != Fidelity::Functional,
        "sensitivity needs a level with time: analytic, sampled:K, cycle or rtl, not functional"
    );
    let (base, arch_name) = args.arch.resolve_with_engines(args.engines)?;
    let replayer = Replayer {
        trace: &args.trace,
        retile: args.retile,
        fidelity: args.fidelity,
        jobs: args.jobs,
    };
    let outcome = replayer.study(&base, &[])?;
    if args.timing {
        eprintln!(
            "sensitivity: {} replays, their wall times summed {:.3} s",
            outcome.replays, outcome.replay_seconds
        );
    }
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&outcome.bands)?);
    } else {
        out!("{}", table(&outcome, args.top as usize));
    }
    if let Some(path) = &args.plot {
        // As the user named the machine, its --set and --engines too (the title had given
        // the built-in's name alone).
        tornado(
            &outcome.bands,
            args.top as usize,
            &format!("{} on {arch_name}", args.trace.display()),
        )
        .write_svg(path)
        .with_context(|| format!("cannot write plot {}", path.display()))?;
    }
    Ok(())
}

fn number(value: f64, unit: &str) -> String {
    if unit == "ms" {
        format!("{value:.3}")
    } else {
        format!("{value:.0}")
    }
}

fn table(outcome: &Outcome, top: usize) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "{:<20} {:>12} {:>12} {:>12} {:>9}  moved most by (result at the low end / high end)",
        "result", "low", "default", "high", "spread"
    );
    for band in &outcome.bands {
        let unit = band.unit;
        let spread = if band.default == 0.0 {
            "-".to_string()
        } else {
            format!(
                "{:+.1}%/{:+.1}%",
                percent(band.low, band.default),
                percent(band.high, band.default)
            )
        };
        let movers: Vec<String> = band
            .parameters
            .iter()
            .take(top)
            .map(|s| {
                format!(
                    "{} {}..{} ({} / {})",
                    s.key,
                    plain(s.low_value),
                    plain(s.high_value),
                    number(s.at_low, unit),
                    number(s.at_high, unit)
                )
            })
            .collect();
        let _ = writeln!(
            out,
            "{:<20} {:>12} {:>12} {:>12} {:>9}  {}",
            format!("{} ({unit})", short(band.metric)),
            number(band.low, unit),
            number(band.default, unit),
            number(band.high, unit),
            spread,
            if movers.is_empty() {
                "nothing".to_string()
            } else {
                movers.join(", ")
            }
        );
    }
    let _ = writeln!(
        out,
        "{} replays: the default, every parameter marked I at each end of its plausible range, and {} corners (`occsim arch show` gives the ranges)",
        outcome.replays,
        outcome.corners.len()
    );
    out
}

fn percent(value: f64, of: f64) -> f64 {
    (value / of - 1.0) * 100.0
}

fn plain(value: Value) -> String {
    match value {
        Value::Choice(name) => name.to_string(),
        other => other.to_string(),
    }
}

fn short(metric: Metric) -> &'static str {
    match metric {
        Metric::Cycles => "cycles",
        Metric::FrameTime => "frame time",
        Metric::LatencyP50 => "latency p50",
        Metric::LatencyP95 => "latency p95",
    }
}

fn tornado(bands: &[Band], top: usize, what: &str) -> TornadoChart {
    TornadoChart {
        title: format!("sensitivity bands, {what}"),
        panels: bands
            .iter()
            .map(|band| TornadoPanel {
                title: format!(
                    "{} ({}): default {}, band {}..{}",
                    short(band.metric),
                    band.unit,
                    number(band.default, band.unit),
                    number(band.low, band.unit),
                    number(band.high, band.unit)
                ),
                default: band.default,
                band: (band.low, band.high),
                bars: band
                    .parameters
                    .iter()
                    .take(top)
                    .map(|s| TornadoBar {
                        label: format!("{} {}..{}", s.key, plain(s.low_value), plain(s.high_value)),
                        at_low: s.at_low,
                        at_high: s.at_high,
                    })
                    .collect(),
            })
            .collect(),
    }
}
