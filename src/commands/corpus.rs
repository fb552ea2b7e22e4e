//! `occsim fidelity --corpus`: the fidelity ladder on every kind of trace. The corpus is a
//! file of recipes (`examples/fidelity-corpus.toml`, built in): each makes one trace (a
//! built-in scene at a size, or a walkthrough), which runs on every machine and engine count
//! the file names; the errors of every level against the reference are gathered per trace
//! class (the worst run of the class, and every query's latency error pooled) with each
//! level's speed against cycle.

use super::fidelity::{
    distribution, percent, ErrorDistribution, Ladder, LevelRow, ERROR_FLOOR_PERCENT,
};
use super::workload_args::{in_one_line, parse_workload_flags, write_workload_trace, WorkloadArgs};
use anyhow::Context;
use occsim_sim::levels::Fidelity;
use occsim_sim::Arch;
use occsim_sweep::output::ScratchDir;
use occsim_sweep::plot::{LineChart, Scale as PlotScale, Series};
use occsim_traces::builtin::{self, BuiltinChoices};
use occsim_traces::raster::RasterProfile;
use occsim_traces::retile::TileGrid;
use occsim_traces::rng::Fnv1a;
use occsim_traces::trace::TraceReader;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The recipes built in: `examples/fidelity-corpus.toml`.
const BUILT_IN: &str = include_str!("../../examples/fidelity-corpus.toml");

#[derive(clap::Args, Clone, Debug, Default)]
pub struct CorpusArgs {
    /// Run the ladder on the corpus instead of one trace: every recipe of the corpus file, on
    /// every machine and engine count it names; one row per trace class and level.
    #[arg(long)]
    pub corpus: bool,
    /// The recipes [default: the built-in corpus, examples/fidelity-corpus.toml].
    #[arg(long, value_name = "FILE.toml", requires = "corpus")]
    pub corpus_file: Option<PathBuf>,
    /// Make every trace at its `small` size (seconds to minutes) or its `full` size.
    #[arg(
        long,
        value_name = "small|full",
        default_value = "full",
        requires = "corpus"
    )]
    pub scale: Scale,
    /// Keep the traces in DIR, and reuse those already there (a file's name carries a digest
    /// of its recipe and the trace format's version) [default: a scratch directory, removed
    /// afterwards].
    #[arg(long, value_name = "DIR", requires = "corpus")]
    pub traces_dir: Option<PathBuf>,
    /// Run on these built-in machines only (comma separated) instead of the corpus's.
    #[arg(long, value_delimiter = ',', value_name = "NAME", requires = "corpus")]
    pub machines: Vec<String>,
    /// Run only the recipes of these classes (comma separated).
    #[arg(long, value_delimiter = ',', value_name = "CLASS", requires = "corpus")]
    pub classes: Vec<String>,
}

/// Which size a recipe is made at.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Scale {
    Small,
    #[default]
    Full,
}

impl Scale {
    /// As `--scale` takes it.
    fn name(self) -> &'static str {
        match self {
            Scale::Small => "small",
            Scale::Full => "full",
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CorpusFile {
    machines: Vec<String>,
    engines: Vec<u64>,
    trace: Vec<Recipe>,
    /// The file's name, or the built-in corpus's, for its errors.
    #[serde(skip)]
    source: String,
}

#[derive(Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct Recipe {
    name: String,
    class: String,
    /// A built-in scene: demo, random or hardcases.
    scene: Option<String>,
    /// `trace gen` flags of a walkthrough.
    walk: Option<String>,
    retile: Option<String>,
    #[serde(default)]
    full: Size,
    #[serde(default)]
    small: Size,
}

#[derive(Clone, Copy, Debug, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
struct Size {
    width: Option<u32>,
    height: Option<u32>,
    frames: Option<u32>,
}

impl Size {
    /// As a built-in scene's choices.
    fn choices(&self) -> BuiltinChoices {
        BuiltinChoices {
            width: self.width,
            height: self.height,
            frames: self.frames,
            seed: None,
        }
    }
}

/// One class and level over the corpus.
#[derive(Serialize)]
struct ClassRow {
    class: String,
    level: String,
    /// Traces times machines times engine counts.
    runs: usize,
    /// The worst run's errors.
    cycles_error: Option<f64>,
    latency_error: Option<f64>,
    latency_p95_error: Option<f64>,
    frame_error: Option<f64>,
    /// The run each of those errors is from.
    worst_runs: WorstRuns,
    /// Every query of every run, pooled.
    query_latency_error: Option<ErrorDistribution>,
    /// The cycle level's wall time over this level's, summed over the runs.
    speed_vs_cycle: Option<f64>,
    results_exact: bool,
}

/// The runs a class's worst errors are from, named as the progress bar names them ("demo on
/// o2, 4 engines"): where to look, when a class's error is large, with `occsim fidelity
/// TRACE --arch M --engines E`. None where no run has the error, or every run's is 0.
#[derive(Default, Serialize)]
struct WorstRuns {
    cycles_error: Option<String>,
    latency_error: Option<String>,
    latency_p95_error: Option<String>,
    frame_error: Option<String>,
}

/// One trace on one machine and engine count: its class, its name and every level's row.
struct Run {
    class: String,
    name: String,
    rows: Vec<LevelRow>,
}

impl CorpusFile {
    /// Its recipes' classes, each once, in the order they first come.
    fn classes(&self) -> Vec<&str> {
        first_seen(self.trace.iter().map(|recipe| recipe.class.as_str()))
    }

    fn has_class(&self, class: &str) -> bool {
        self.trace.iter().any(|recipe| recipe.class == class)
    }
}

/// Parse the corpus file (the built-in one without a path), naming the file in errors.
fn load(path: Option<&Path>) -> anyhow::Result<CorpusFile> {
    let (name, text) = match path {
        Some(path) => (
            path.display().to_string(),
            super::read_settings_file(path, "corpus file")?,
        ),
        None => ("the built-in corpus".to_string(), BUILT_IN.to_string()),
    };
    let file: CorpusFile = toml::from_str(&text).with_context(|| name.clone())?;
    anyhow::ensure!(
        !file.machines.is_empty(),
        "{name}: `machines` names no machine"
    );
    anyhow::ensure!(
        !file.engines.is_empty(),
        "{name}: `engines` names no engine count"
    );
    anyhow::ensure!(!file.trace.is_empty(), "{name}: no `[[trace]]` recipe");
    // A run twice would be reported as two runs of its class, as the flags' repeats are.
    if let Some(machine) = super::first_repeated(&file.machines) {
        anyhow::bail!("{name}: `machines` names `{machine}` twice");
    }
    if let Some(engines) = super::first_repeated(&file.engines) {
        anyhow::bail!("{name}: `engines` names {engines} twice");
    }
    for (k, recipe) in file.trace.iter().enumerate() {
        // A recipe's name names its trace's file in --traces-dir: no path in it.
        anyhow::ensure!(
            !recipe.name.is_empty()
                && !recipe.name.starts_with('.')
                && recipe
                    .name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c)),
            "{name}: trace `{}`: a name is letters, digits, `-`, `_` and `.` (not first)",
            recipe.name
        );
        anyhow::ensure!(
            !file.trace[..k]
                .iter()
                .any(|other| other.name == recipe.name),
            "{name}: trace `{}` named twice",
            recipe.name
        );
        anyhow::ensure!(
            recipe.scene.is_some() != recipe.walk.is_some(),
            "{name}: trace `{}` needs exactly one of `scene` and `walk`",
            recipe.name
        );
        if let Some(grid) = &recipe.retile {
            grid.parse::<TileGrid>()
                .map_err(|e| anyhow::anyhow!("{name}: trace `{}`: retile: {e}", recipe.name))?;
        }
        // Before any trace is made: a recipe's scene or walk is known or the file is refused.
        if let Some(scene) = &recipe.scene {
            anyhow::ensure!(
                builtin::NAMES.contains(&scene.as_str()),
                "{name}: trace `{}`: unknown scene `{scene}` ({})",
                recipe.name,
                builtin::NAMES.join(", ")
            );
        }
        // Each scale's trace as it will be made: its size, and a walk's flags and options.
        for scale in [Scale::Full, Scale::Small] {
            let checked = match (&recipe.scene, &recipe.walk) {
                (Some(scene), _) => (recipe.size(scale).choices().check(scene))
                    .map_err(|e| format!("{}: {e}", scale.name())),
                (None, Some(walk)) => recipe
                    .walk_args(scale)
                    .map(|_| ())
                    .map_err(|e| format!("walk `{walk}` at the {} scale: {e}", scale.name())),
                (None, None) => Ok(()),
            };
            checked.map_err(|e| anyhow::anyhow!("{name}: trace `{}`: {e}", recipe.name))?;
        }
    }
    Ok(CorpusFile {
        source: name,
        ..file
    })
}

impl Recipe {
    /// A walk recipe's flags at `scale` (its size appended), parsed and checked as `trace
    /// gen` checks them: the walk's viewport and frames, the driver and its options.
    fn walk_args(&self, scale: Scale) -> Result<WorkloadArgs, String> {
        let walk = self.walk.as_deref().unwrap_or_default();
        let mut flags: Vec<String> = walk.split_whitespace().map(str::to_owned).collect();
        let size = self.size(scale);
        for (flag, value) in [
            ("--width", size.width),
            ("--height", size.height),
            ("--frames", size.frames),
        ] {
            if let Some(value) = value {
                flags.extend([flag.to_owned(), value.to_string()]);
            }
        }
        let args = parse_workload_flags(&flags).map_err(|e| in_one_line(&e))?;
        args.checked().map_err(|e| e.to_string())?;
        Ok(args)
    }

    fn size(&self, scale: Scale) -> Size {
        match scale {
            Scale::Small => self.small,
            Scale::Full => self.full,
        }
    }

    /// The trace's file in `dir`: its name, scale and a digest of the recipe and the trace
    /// format's version, so a changed recipe, or a format that keeps more, makes a new trace.
    fn file_in(&self, dir: &Path, scale: Scale) -> PathBuf {
        let recipe = serde_json::to_string(self).unwrap_or_default();
        let version = occsim_traces::trace::FORMAT_VERSION;
        let digest = Fnv1a::of(format!("{recipe}{scale:?}{version}").as_bytes());
        dir.join(format!("{}-{}-{digest:016x}.occt", self.name, scale.name()))
    }

    /// Make the trace at `output` (atomically).
    fn make(&self, scale: Scale, output: &Path) -> anyhow::Result<()> {
        let size = self.size(scale);
        let context = || format!("corpus trace `{}`", self.name);
        if let Some(walk) = &self.walk {
            let args = (self.walk_args(scale))
                .map_err(|e| anyhow::anyhow!("walk `{walk}`: {e}"))
                .with_context(context)?;
            write_workload_trace(&args, output, |_, _| Ok(())).with_context(context)?;
            return Ok(());
        }
        // `load` refused every other recipe: a scene of its own is a built-in one.
        let scene = self.scene.as_deref().unwrap_or_default();
        super::trace::generate_scene(scene, &size.choices(), RasterProfile::Llvmpipe, output)
            .with_context(context)
            .map(|_| ())
    }
}

/// Where the traces go: the caller's directory, or a scratch one removed when dropped (or
/// when the command is interrupted).
enum TraceDir {
    Kept(PathBuf),
    Scratch(ScratchDir),
}

impl TraceDir {
    fn path(&self) -> &Path {
        match self {
            TraceDir::Kept(path) => path,
            TraceDir::Scratch(scratch) => scratch.path(),
        }
    }
}

/// Run the corpus: every recipe on every machine (each with `sets` applied) and engine count.
pub fn run(
    args: &CorpusArgs,
    ladder: &Ladder,
    engines: &[u64],
    sets: &[String],
    (json, plot): (bool, Option<&Path>),
) -> anyhow::Result<()> {
    anyhow::ensure!(args.corpus, "give a TRACE, or --corpus");
    // Each run sets its own engine count (the corpus's, or --engines).
    if let Some(set) = super::arch::set_of(sets, "engines") {
        anyhow::bail!("--set {set}: a corpus run sets the engine count of each run; use --engines");
    }
    let corpus = load(args.corpus_file.as_deref())?;
    let machines = if args.machines.is_empty() {
        &corpus.machines
    } else {
        &args.machines
    };
    let engine_counts = match engines {
        [] => corpus.engines.clone(),
        given => given.to_vec(),
    };
    // A run twice would be reported as two runs of its class.
    for (flag, repeated) in [
        ("--machines", super::first_repeated(&args.machines).cloned()),
        (
            "--engines",
            super::first_repeated(engines).map(u64::to_string),
        ),
        ("--classes", super::first_repeated(&args.classes).cloned()),
    ] {
        if let Some(repeated) = repeated {
            anyhow::bail!("{flag}: `{repeated}` is named twice");
        }
    }
    if let Some(unknown) = (args.classes.iter()).find(|class| !corpus.has_class(class)) {
        anyhow::bail!(
            "--classes: {}: no recipe is of class `{unknown}` (its classes: {})",
            corpus.source,
            corpus.classes().join(", ")
        );
    }
    // Every run's machine, made before any trace is: a bad name or engine count is refused
    // first, named by where it came from.
    let source = match args.machines.is_empty() {
        true => format!("{}: `machines` and `engines`", corpus.source),
        false => "--machines".to_string(),
    };
    let mut archs = Vec::with_capacity(machines.len() * engine_counts.len());
    for machine in machines {
        for &engines in &engine_counts {
            let arch = machine_with(machine, engines, sets).with_context(|| source.clone())?;
            // Two names of one machine (`ir` is `ir4`) would run every run twice.
            if let Some((other, ..)) = archs.iter().find(|(_, _, made)| *made == arch) {
                anyhow::bail!("{source}: `{other}` and `{machine}` are the same machine");
            }
            archs.push((machine, engines, arch));
        }
    }
    let recipes: Vec<&Recipe> = corpus
        .trace
        .iter()
        .filter(|r| args.classes.is_empty() || args.classes.contains(&r.class))
        .collect();
    let dir = match &args.traces_dir {
        Some(dir) => {
            anyhow::ensure!(
                !dir.exists() || dir.is_dir(),
                "--traces-dir {}: not a directory",
                dir.display()
            );
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            TraceDir::Kept(dir.clone())
        }
        None => TraceDir::Scratch(ScratchDir::create("occsim-corpus")?),
    };
    let mut runs: Vec<Run> = Vec::new();
    let steps = recipes.len() * archs.len();
    let bar = occsim_sweep::progress::bar(steps as u64, "runs");
    for recipe in recipes {
        let trace = recipe.file_in(dir.path(), args.scale);
        let remake = match trace_at(&trace) {
            Kept::Whole => false,
            Kept::Missing => true,
            Kept::Damaged(error) => {
                // Above the bar on a terminal, and said off one too (`println` is not).
                bar.suspend(|| eprintln!("occsim: making {} again: {error}", trace.display()));
                true
            }
        };
        if remake {
            bar.set_message(format!("making {}", recipe.name));
            recipe.make(args.scale, &trace)?;
        }
        let mut ladder = *ladder;
        if let Some(grid) = &recipe.retile {
            ladder.retile = Some(grid.parse().map_err(|e| anyhow::anyhow!("{e}"))?);
        }
        for (machine, engines, arch) in &archs {
            let hidden = occsim_sweep::progress::ProgressBar::hidden();
            let name = run_name(&recipe.name, machine, *engines);
            bar.set_message(name.clone());
            let (rows, _) = ladder
                .run(arch, &trace, &hidden)
                .with_context(|| name.clone())?;
            runs.push(Run {
                class: recipe.class.clone(),
                name,
                rows,
            });
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let rows = by_class(&runs);
    // The table first: a plot that cannot be written after hours of runs loses no result.
    if json {
        outln!("{}", serde_json::to_string_pretty(&rows)?);
    } else {
        out!(
            "{}",
            table(
                &rows,
                machines,
                &engine_counts,
                args.scale,
                ladder.reference()
            )
        );
    }
    if let Some(path) = plot {
        price_of_accuracy(&rows, args.scale, ladder.reference())
            .write_svg(path)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}

/// `--plot` with `--corpus`: per class, each timed level's worst error (the larger of total
/// cycles and p95 latency, the two the bounds hold) against its speed, log-log, a line
/// through the levels from the cheapest to the reference.
fn price_of_accuracy(rows: &[ClassRow], scale: Scale, reference: Fidelity) -> LineChart {
    let mut series: Vec<Series> = Vec::new();
    for row in rows {
        let (Some(speed), Some(cycles)) = (row.speed_vs_cycle, row.cycles_error) else {
            continue;
        };
        // A class without a query (the frustum walks) has no latency to err: its line is
        // drawn by its cycles error (it had been left out).
        let p95 = row.latency_p95_error.unwrap_or(0.0);
        let error = (100.0 * cycles.max(p95)).max(ERROR_FLOOR_PERCENT);
        match series.iter_mut().find(|s| s.name == row.class) {
            Some(class) => class.points.push((speed, error)),
            None => series.push(Series {
                name: row.class.clone(),
                points: vec![(speed, error)],
            }),
        }
    }
    LineChart {
        title: format!(
            "The price of accuracy: the {} corpus, each class's levels (an error of 0 drawn at {ERROR_FLOOR_PERCENT}%)",
            scale.name()
        ),
        x_label: "speed against the cycle level (its wall time over the level's)".to_string(),
        y_label: format!(
            "worst run's error vs {reference} (%, the worse of total cycles and p95 latency)"
        ),
        x_scale: PlotScale::Log10,
        y_scale: PlotScale::Log10,
        x_ticks: None,
        series,
    }
}

/// A corpus trace where it is kept (by `--traces-dir`, or in the scratch directory).
enum Kept {
    /// There with its header, trailer and summary whole: replayed again. (Damage inside a
    /// block is still found by its checksum when a run reads it.)
    Whole,
    Missing,
    /// Cut short or damaged (a copy that stopped, a disk that filled): made anew rather
    /// than failing the corpus.
    Damaged(occsim_traces::trace::TraceError),
}

fn trace_at(path: &Path) -> Kept {
    let Ok(file) = std::fs::File::open(path) else {
        return Kept::Missing;
    };
    match TraceReader::read_summary(std::io::BufReader::new(file)) {
        Ok(_) => Kept::Whole,
        Err(error) => Kept::Damaged(error),
    }
}

/// A built-in machine with `sets` applied and `engines` occlusion engines.
fn machine_with(name: &str, engines: u64, sets: &[String]) -> anyhow::Result<Arch> {
    let mut arch =
        super::arch::resolve(name, None, sets).with_context(|| format!("machine `{name}`"))?;
    arch.set_value("engines", &engines.to_string())
        .with_context(|| format!("{name} with {engines} engines"))?;
    Ok(arch)
}

/// `names`, each once, in the order they first come.
fn first_seen<'a>(names: impl Iterator<Item = &'a str>) -> Vec<&'a str> {
    let mut seen: Vec<&str> = Vec::new();
    for name in names {
        if !seen.contains(&name) {
            seen.push(name);
        }
    }
    seen
}

/// A run's name: `trace on machine, E engines`.
fn run_name(trace: &str, machine: &str, engines: u64) -> String {
    let unit = if engines == 1 { "engine" } else { "engines" };
    format!("{trace} on {machine}, {engines} {unit}")
}

/// Per class (in first-seen order) and level: the worst run's errors and which run each is
/// from, every query's latency error pooled, and the speed against cycle over the runs.
fn by_class(runs: &[Run]) -> Vec<ClassRow> {
    let classes = first_seen(runs.iter().map(|run| run.class.as_str()));
    let mut rows = Vec::new();
    for class in classes {
        let members: Vec<&Run> = runs.iter().filter(|run| run.class == class).collect();
        let cycle_seconds: f64 = members
            .iter()
            .flat_map(|run| run.rows.iter().filter(|r| r.level == "cycle"))
            .filter_map(|r| r.wall_seconds)
            .sum();
        for level in members[0].rows.iter().map(|r| r.level.clone()) {
            let of_level: Vec<(&str, &LevelRow)> = members
                .iter()
                .filter_map(|run| {
                    let row = run.rows.iter().find(|r| r.level == level)?;
                    Some((run.name.as_str(), row))
                })
                .collect();
            // The largest error, as `f64::max` finds it, and its run (the first of equal
            // ones).
            let worst = |f: &dyn Fn(&LevelRow) -> Option<f64>| {
                of_level
                    .iter()
                    .filter_map(|(name, r)| Some((f(r)?, *name)))
                    .fold(None, |worst: Option<(f64, &str)>, (e, name)| match worst {
                        Some((w, _)) if !w.is_nan() && (e.is_nan() || e <= w) => worst,
                        _ => Some((e, name)),
                    })
            };
            let (cycles, latency, p95, frame) = (
                worst(&|r| r.cycles_error),
                worst(&|r| r.latency_error),
                worst(&|r| r.latency_p95_error),
                worst(&|r| r.frame_error),
            );
            // An error of 0 is no run's in particular.
            let name = |w: Option<(f64, &str)>| {
                w.filter(|&(e, _)| e != 0.0)
                    .map(|(_, name)| name.to_string())
            };
            let seconds: f64 = of_level.iter().filter_map(|(_, r)| r.wall_seconds).sum();
            let pooled = of_level
                .iter()
                .flat_map(|(_, r)| r.query_errors.iter().copied())
                .collect();
            rows.push(ClassRow {
                class: class.to_string(),
                level: level.clone(),
                runs: of_level.len(),
                cycles_error: cycles.map(|(e, _)| e),
                latency_error: latency.map(|(e, _)| e),
                latency_p95_error: p95.map(|(e, _)| e),
                frame_error: frame.map(|(e, _)| e),
                worst_runs: WorstRuns {
                    cycles_error: name(cycles),
                    latency_error: name(latency),
                    latency_p95_error: name(p95),
                    frame_error: name(frame),
                },
                query_latency_error: ErrorDistribution::of(pooled),
                speed_vs_cycle: (seconds > 0.0).then(|| cycle_seconds / seconds),
                results_exact: of_level.iter().all(|(_, r)| r.results_exact == Some(true)),
            });
        }
    }
    rows
}

fn table(
    rows: &[ClassRow],
    machines: &[String],
    engines: &[u64],
    scale: Scale,
    reference: Fidelity,
) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let engines: Vec<String> = engines.iter().map(u64::to_string).collect();
    let _ = writeln!(
        out,
        "fidelity corpus ({} scale) on {} with {} engines; errors relative to {reference}",
        scale.name(),
        machines.join(", "),
        engines.join(", "),
    );
    let _ = writeln!(
        out,
        "{:<18} {:<11} {:>5} {:>10} {:>9} {:>9} {:>22} {:>9} {:>9} {:>8}",
        "class",
        "level",
        "runs",
        "cycles err",
        "lat err",
        "p95 err",
        "query err p50/p95/max",
        "frame err",
        "speed",
        "results"
    );
    for row in rows {
        let _ = writeln!(
            out,
            "{:<18} {:<11} {:>5} {:>10} {:>9} {:>9} {:>22} {:>9} {:>9} {:>8}",
            row.class,
            row.level,
            row.runs,
            percent(row.cycles_error),
            percent(row.latency_error),
            percent(row.latency_p95_error),
            distribution(row.query_latency_error),
            percent(row.frame_error),
            row.speed_vs_cycle
                .map_or("-".to_string(), |s| format!("{s:.2}x")),
            if row.results_exact { "exact" } else { "DIFFER" }
        );
    }
    let _ = writeln!(
        out,
        "  runs: traces x machines x engine counts of the class; cycles err, lat err, p95 err, \
         frame err: the worst run's |level - reference| / reference of total cycles, mean and \
         p95 query latency and mean frame cycles; query err: every query's own latency error, \
         pooled over the runs, its p50, p95 and max; speed: the cycle level's wall time over \
         this level's, summed over the runs (decoding the trace included); results: every \
         query's counts equal the reference's in every run"
    );
    out
}
