//! `occsim culling compare`: every culling driver on the same walkthrough, side by side:
//! what each draws, what its queries cost, and (when timing models are supplied) the
//! simulated cycles per frame on each machine.

use super::sensitivity::{CornerBands, Replayer};
use super::workload_args::{parse_workload_flags, write_workload_trace, SceneArgs};
use anyhow::Context;
use occsim_sim::sensitivity::Study;
use occsim_sweep::output::ScratchDir;
use occsim_traces::workloads::compare::{
    compare as compare_drivers, CompareError, CompareReport, DriverReport, FrameCost,
    FrameCycleModel, ModelError,
};
use occsim_traces::workloads::{DriverKind, DriverOptions, GridVariant};
use occsim_traces::Event;
use std::io::Write;

#[derive(clap::Args, Clone, Debug)]
pub struct CompareArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Frames before a query's answer is used by the frustum and hierarchical drivers: 0 or 1
    /// (the grids always read theirs at once).
    #[arg(long, default_value_t = 0)]
    pub query_delay: u32,
    /// Quadtree levels of the hierarchical driver's quadtree variant (0 leaves it out).
    #[arg(long, default_value_t = 2)]
    pub quadtree_levels: u32,
    /// Adaptive thresholds (NOHC/PHC shares) to run the hierarchical driver with, comma
    /// separated; each row shows the pixels lost against the cycles saved.
    #[arg(long, value_delimiter = ',', default_value = "0.05,0.2,0.5")]
    pub adaptive_threshold: Vec<f32>,
    /// Opacity thresholds below 1 to run the hom driver's approximate culling with, comma
    /// separated (the conservative hom row is always there).
    #[arg(long, value_delimiter = ',', default_value = "0.9")]
    pub opacity_threshold: Vec<f32>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    /// A built-in architecture to time every frame on (repeatable, or comma separated; see
    /// `occsim arch list`) [default: o2,ir4 when no --arch-file is given either].
    #[arg(long, value_delimiter = ',', value_name = "NAME")]
    pub arch: Vec<String>,
    /// An architecture file to time every frame on (repeatable; see `occsim arch show`).
    #[arg(long, value_name = "FILE")]
    pub arch_file: Vec<std::path::PathBuf>,
    /// Override one parameter of every machine (repeatable), e.g. --set engines=8.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub set: Vec<String>,
    /// Occlusion engines of every machine (shorthand for --set engines=E).
    #[arg(long, value_name = "E")]
    pub engines: Option<u64>,
    /// Print a sensitivity band beside each frame time: every driver's frames also timed at
    /// the corners a sensitivity study around each machine finds on the hierarchical
    /// driver's walk (see `occsim sensitivity`).
    #[arg(long)]
    pub bands: bool,
    /// Replays run at once while the --bands study looks for its corners.
    #[arg(long, default_value_t = super::sensitivity::default_jobs(), value_parser = super::at_least_one_job)]
    pub jobs: usize,
}

impl CompareArgs {
    /// The machines to time frames on, each with its column's name: the --arch names and
    /// --arch-file stems in order, every --set applied to each.
    pub fn machines(&self) -> anyhow::Result<Vec<(String, occsim_sim::Arch)>> {
        let defaults: Vec<String> = CYCLE_MACHINES.iter().map(|m| m.to_string()).collect();
        let names = if self.arch.is_empty() && self.arch_file.is_empty() {
            &defaults
        } else {
            &self.arch
        };
        let mut machines = Vec::new();
        for name in names {
            let mut arch = super::arch::resolve(name, None, &self.set)
                .with_context(|| format!("--arch {name}"))?;
            super::arch::set_engines(&mut arch, self.engines, &self.set)?;
            machines.push((name.clone(), arch));
        }
        for file in &self.arch_file {
            let mut arch = super::arch::resolve("", Some(file), &self.set)?;
            super::arch::set_engines(&mut arch, self.engines, &self.set)?;
            let name = file.file_stem().map_or(file.display().to_string(), |s| {
                s.to_string_lossy().into_owned()
            });
            machines.push((name, arch));
        }
        // A column a machine: two of one name would print twice and give JSON keys twice.
        let names: Vec<&String> = machines.iter().map(|(name, _)| name).collect();
        if let Some(twice) = super::first_repeated(&names) {
            anyhow::bail!(
                "--arch/--arch-file: {twice} appears twice (each machine is a column, named by its --arch name or its file's stem)"
            );
        }
        Ok(machines)
    }
}

/// The driver configurations the report compares.
fn drivers_to_compare(args: &CompareArgs) -> Vec<DriverOptions> {
    let delayed = |mut options: DriverOptions| {
        options.query_delay_frames = args.query_delay;
        options
    };
    let mut vob = DriverOptions::new(DriverKind::Hierarchical);
    vob.virtual_occlusion_buffer = true;
    let mut list = vec![
        delayed(DriverOptions::new(DriverKind::Frustum)),
        delayed(DriverOptions::new(DriverKind::Hierarchical)),
        delayed(vob),
    ];
    if args.quadtree_levels > 0 {
        let mut quadtree = delayed(DriverOptions::new(DriverKind::Hierarchical));
        quadtree.quadtree_levels = args.quadtree_levels;
        list.push(quadtree);
    }
    list.push(DriverOptions::new(DriverKind::Collision));
    for kind in [DriverKind::LazyGrid, DriverKind::BusyGrid] {
        for variant in GridVariant::ALL {
            let mut grid = DriverOptions::new(kind);
            grid.grid_variant = variant;
            list.push(grid);
        }
    }
    for &threshold in &args.adaptive_threshold {
        let mut adaptive = delayed(DriverOptions::new(DriverKind::Hierarchical));
        adaptive.adaptive_threshold = Some(threshold);
        list.push(adaptive);
    }
    seed_drivers(args, &mut list);
    list
}

/// The drivers of seeds 002 to 004, each conservative, then each approximate variant; the
/// dynamic grid in 3D and 2D; the raycast.
fn seed_drivers(args: &CompareArgs, list: &mut Vec<DriverOptions>) {
    list.push(DriverOptions::new(DriverKind::Hom));
    for &threshold in &args.opacity_threshold {
        let mut approximate = DriverOptions::new(DriverKind::Hom);
        approximate.opacity_threshold = threshold;
        list.push(approximate);
    }
    list.push(DriverOptions::new(DriverKind::LargeOccluders));
    list.push(DriverOptions::new(DriverKind::DynamicGrid));
    let mut flat = DriverOptions::new(DriverKind::DynamicGrid);
    flat.flat_grid = true;
    list.push(flat);
    list.push(DriverOptions::new(DriverKind::Raycast));
}

/// `culling compare` timed on the machines its flags name (with `--bands`, each machine with
/// its corners).
pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    // A driver a threshold: one given twice would be two rows, and two JSON drivers, of one
    // name.
    for (flag, thresholds) in [
        ("--adaptive-threshold", &args.adaptive_threshold),
        ("--opacity-threshold", &args.opacity_threshold),
    ] {
        if let Some(twice) = super::first_repeated(thresholds) {
            anyhow::bail!("{flag}: {twice} is named twice");
        }
    }
    // The conservative hom driver (threshold 1) is a row of its own already.
    if args.opacity_threshold.contains(&1.0) {
        anyhow::bail!(
            "--opacity-threshold 1: the hom row is the conservative threshold already; give approximate ones below 1"
        );
    }
    let machines = args.machines()?;
    let variants = match args.bands {
        true => band_corners(&args, &machines)?,
        false => vec![Vec::new(); machines.len()],
    };
    // One step a frame a machine a driver (on a terminal).
    let steps = drivers_to_compare(&args).len() * args.scene.frames() as usize * machines.len();
    let bar = occsim_sweep::progress::bar(steps as u64, "frames timed");
    bar.set_message("culling compare");
    let mut models: Vec<Box<dyn FrameCycleModel>> = Vec::new();
    for ((name, arch), variants) in machines.into_iter().zip(variants) {
        models.push(Box::new(MachineFrames::new(
            name,
            arch,
            variants,
            bar.clone(),
        )));
    }
    let stdout = std::io::stdout();
    let outcome = run_with(&args, &mut models, &mut stdout.lock());
    bar.finish_and_clear();
    outcome
}

/// The driver whose walk the `--bands` study replays: the paper's own (seed 001).
const BAND_REFERENCE_DRIVER: &str = "hierarchical";

/// Per machine, the architectures at the corners of a sensitivity study around it, replayed
/// on the reference driver's walk of the compared scene (written to a scratch directory
/// that is removed afterwards, or when the command is interrupted). One study a machine,
/// not one a driver: the corners are where the inferred parameters push frame time
/// furthest, and every driver's frames are then timed there.
fn band_corners(
    args: &CompareArgs,
    machines: &[(String, occsim_sim::Arch)],
) -> anyhow::Result<Vec<Vec<Corner>>> {
    let scratch = ScratchDir::create("occsim-bands")?;
    let trace = scratch.path().join("reference-walk.occt");
    let mut walk = parse_workload_flags(["--driver", BAND_REFERENCE_DRIVER])?;
    walk.scene = args.scene.clone();
    write_workload_trace(&walk, &trace, |_, _| Ok(()))
        .context("--bands: the sensitivity study's reference walk")?;
    let replayer = Replayer {
        trace: &trace,
        retile: None,
        fidelity: occsim_sim::Fidelity::Cycle,
        jobs: args.jobs,
    };
    machines
        .iter()
        .map(|(name, arch)| {
            let corners = CornerBands::find(&replayer, arch, &[])
                .with_context(|| format!("--bands on {name}"))?;
            corners
                .corners
                .iter()
                .map(|changes| {
                    let said: Vec<String> = (changes.iter())
                        .map(|(key, value)| format!("{key}={value}"))
                        .collect();
                    Ok((said.join(", "), Study::apply(arch, changes)?))
                })
                .collect()
        })
        .collect()
}

/// The machines `culling compare` times every frame on by default.
const CYCLE_MACHINES: [&str; 2] = ["o2", "ir4"];

/// A corner of a machine's sensitivity study: what it changes (`key=value, ...`) and the
/// architecture so changed.
type Corner = (String, occsim_sim::Arch);

/// A sim machine as a per-frame timing model: each frame replays on a fresh machine (frames
/// are self-contained: each begins with a clear and the whole render state), and on a fresh
/// machine for each of its variants (the corners of `--bands`).
struct MachineFrames {
    name: String,
    arch: occsim_sim::Arch,
    variants: Vec<Corner>,
    /// During a frame: the machine, then one a variant.
    machines: Vec<occsim_sim::MachineModel>,
    /// Moves a step each frame timed.
    progress: occsim_sweep::progress::ProgressBar,
}

impl MachineFrames {
    fn new(
        name: String,
        arch: occsim_sim::Arch,
        variants: Vec<Corner>,
        progress: occsim_sweep::progress::ProgressBar,
    ) -> MachineFrames {
        MachineFrames {
            name,
            arch,
            variants,
            machines: Vec::new(),
            progress,
        }
    }
}

/// A machine's failure in a frame, naming the machine.
#[derive(Debug)]
struct FrameError {
    machine: String,
    /// None: the frame ended before it began.
    source: Option<occsim_sim::SimError>,
}

impl std::fmt::Display for FrameError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.source {
            Some(_) => write!(f, "frame on {}", self.machine),
            None => write!(f, "{}: a frame ended before it began", self.machine),
        }
    }
}

impl std::error::Error for FrameError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.source.as_ref().map(|e| e as _)
    }
}

impl MachineFrames {
    fn failed(&self, source: Option<occsim_sim::SimError>) -> ModelError {
        Box::new(FrameError {
            machine: self.name.clone(),
            source,
        })
    }
}

impl FrameCycleModel for MachineFrames {
    fn machine(&self) -> String {
        self.name.clone()
    }

    fn variants(&self) -> Vec<String> {
        self.variants.iter().map(|(said, _)| said.clone()).collect()
    }

    fn begin_frame(&mut self, width: u32, height: u32) -> Result<(), ModelError> {
        self.machines = std::iter::once(&self.arch)
            .chain(self.variants.iter().map(|(_, arch)| arch))
            .map(|arch| occsim_sim::MachineModel::new(arch, width, height))
            .collect::<Result<_, _>>()
            .map_err(|e| self.failed(Some(e)))?;
        Ok(())
    }

    fn event(&mut self, event: &Event) -> Result<(), ModelError> {
        for machine in &mut self.machines {
            if let Err(e) = machine.event(event) {
                return Err(self.failed(Some(e)));
            }
        }
        Ok(())
    }

    fn end_frame(&mut self) -> Result<FrameCost, ModelError> {
        if self.machines.is_empty() {
            return Err(self.failed(None));
        }
        let mut reports = Vec::with_capacity(self.machines.len());
        for machine in std::mem::take(&mut self.machines) {
            reports.push(machine.finish().map_err(|e| self.failed(Some(e)))?);
        }
        self.progress.inc(1);
        let report = &reports[0];
        // A driver's frame is one closed-loop frame (it ends in `swap`); its split sums the
        // report's frames should there be more.
        let sum = |f: &dyn Fn(&occsim_sim::report::FrameReport) -> u64| {
            report.frames.iter().map(f).sum::<u64>()
        };
        Ok(FrameCost {
            cycles: report.summary.cycles,
            seconds: report.summary.simulated_seconds,
            host_busy: sum(&|f| f.host_busy),
            geometry_busy: sum(&|f| f.geometry_busy),
            pixel_busy: sum(&|f| f.pixel_busy),
            waiting: sum(&|f| f.waiting),
            pipe_wait: sum(&|f| f.pipe_wait),
            variant_seconds: reports[1..]
                .iter()
                .map(|r| r.summary.simulated_seconds)
                .collect(),
        })
    }
}

/// `culling compare` with the caller's timing models, one cycle column each.
pub fn run_with(
    args: &CompareArgs,
    models: &mut [Box<dyn FrameCycleModel>],
    out: &mut dyn Write,
) -> anyhow::Result<()> {
    let report = compare(args, models)?;
    if args.json {
        serde_json::to_writer_pretty(&mut *out, &report)?;
        writeln!(out)?;
    } else {
        print_table(&report, out)?;
    }
    out.flush()?;
    Ok(())
}

/// Run every driver and gather the report.
pub fn compare(
    args: &CompareArgs,
    models: &mut [Box<dyn FrameCycleModel>],
) -> anyhow::Result<CompareReport> {
    let scene = args.scene.load_scene()?;
    let walk = args.scene.walk();
    let drivers = drivers_to_compare(args);
    compare_drivers(&scene, args.scene.describe(&scene), &walk, &drivers, models).map_err(|e| {
        match e {
            CompareError::Workload(e) => super::workload_args::flagged(e),
            CompareError::Model { driver, source } => anyhow::Error::from_boxed(source)
                .context(format!("timing model on the {driver} driver")),
        }
    })
}

fn print_table(report: &CompareReport, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "scene {}; {} triangles, {:.0} visible pixels per frame in the full render",
        report.scene, report.scene_triangles, report.visible_pixels_per_frame
    )?;
    let machines: Vec<String> = report
        .drivers
        .first()
        .map(|d| d.cycles_per_frame.iter().map(|(m, _)| m.clone()).collect())
        .unwrap_or_default();
    write!(
        out,
        "{:<24} {:>7} {:>10} {:>8} {:>9} {:>10} {:>10} {:>9} {:>10}",
        "driver (per frame)",
        "tris %",
        "triangles",
        "queries",
        "tiles",
        "query frag",
        "draw frag",
        "cells",
        "px lost"
    )?;
    for machine in &machines {
        write!(out, " {:>12}", format!("cycles {machine}"))?;
    }
    writeln!(out, " {:>10} {:>10}", "trav ms", "golden ms")?;
    for d in &report.drivers {
        write!(
            out,
            "{:<24} {:>7.2} {:>10.0} {:>8.1} {:>9.1} {:>10.0} {:>10.0} {:>9.1} {:>10.0}",
            d.driver,
            d.triangles_drawn_share * 100.0,
            d.triangles_per_frame,
            d.queries_per_frame,
            d.query_tiles_per_frame,
            d.query_fragments_per_frame,
            d.draw_fragments_per_frame,
            d.cells_refreshed_per_frame,
            d.pixels_lost_per_frame
        )?;
        for (_, cycles) in &d.cycles_per_frame {
            write!(out, " {cycles:>12.0}")?;
        }
        writeln!(
            out,
            " {:>10.2} {:>10.2}",
            d.traversal_ms_per_frame, d.golden_model_ms_per_frame
        )?;
    }
    writeln!(
        out,
        "  means per frame: tris %: the scene's triangles drawn; queries issued and their tiles; \
         query frag: fragments of the queries' boxes (tested, never drawn); draw frag: fragments of \
         the drawn geometry; cells: occlusion-grid cells refreshed (grid drivers); px lost: visible \
         pixels of the full render whose objects were not drawn; cycles M: simulated cycles of a \
         frame on machine M; trav ms, golden ms: wall-clock milliseconds on this computer in the \
         driver's traversal and in the golden model (rasterizing and answering the queries)"
    )?;
    print_rays(report, out)?;
    print_frame_time(report, out)?;
    print_fastest(report, &machines, out)?;
    print_accuracy(report, &machines, out)
}

/// The raycast rows' rays under the table: cast, against a cast through every pixel.
fn print_rays(report: &CompareReport, out: &mut dyn Write) -> std::io::Result<()> {
    for d in report
        .drivers
        .iter()
        .filter(|d| d.rays_full_screen_per_frame > 0.0)
    {
        writeln!(
            out,
            "{}: {:.0} rays cast a frame of {:.0} for the full screen ({:.1}% saved); verbose buffers overflowed a frame: {:.1} (those bricks cast through the box of their hits)",
            d.driver,
            d.rays_cast_per_frame,
            d.rays_full_screen_per_frame,
            100.0 * (1.0 - d.rays_cast_per_frame / d.rays_full_screen_per_frame),
            d.overflowed_buffers_per_frame
        )?;
    }
    Ok(())
}

/// Each driver's frame time on each machine: frames per second, and where the frame's time
/// went (the host busy and waiting on answers, the geometry stage and rasterizer busy); with
/// `--bands`, the band of the frame time.
fn print_frame_time(report: &CompareReport, out: &mut dyn Write) -> std::io::Result<()> {
    let banded = report
        .drivers
        .iter()
        .flat_map(|d| &d.frame_time)
        .any(|m| m.ms_per_frame_band.is_some());
    write!(
        out,
        "\n{:<24} {:<8} {:>9} {:>10} {:>12} {:>12} {:>12} {:>12} {:>12}",
        "frame time",
        "machine",
        "frames/s",
        "ms/frame",
        "host busy",
        "waiting",
        "pipe wait",
        "geometry",
        "pixel busy"
    )?;
    writeln!(out, "{}", if banded { "  ms/frame band" } else { "" })?;
    for d in &report.drivers {
        for m in &d.frame_time {
            write!(
                out,
                "{:<24} {:<8} {:>9.2} {:>10.2} {:>12.0} {:>12.0} {:>12.0} {:>12.0} {:>12.0}",
                d.driver,
                m.machine,
                m.frames_per_second,
                m.ms_per_frame,
                m.host_busy_cycles,
                m.waiting_cycles,
                m.pipe_wait_cycles,
                m.geometry_busy_cycles,
                m.pixel_busy_cycles
            )?;
            match m.ms_per_frame_band {
                Some((low, high)) => writeln!(out, "  {low:.2}..{high:.2}")?,
                None => writeln!(out)?,
            }
        }
    }
    writeln!(
        out,
        "  on the simulated machine, per frame: host busy (traversal, driver, result reads), \
         waiting (the host blocked on answers), pipe wait (the host idle, the pipe still busy with \
         the frame's work: host busy + waiting + pipe wait = the frame's cycles), geometry (the \
         geometry stage busy, summed over its \
         Geometry Engines: several engines can pass the frame's cycles), pixel busy \
         (the rasterizer busy), in the machine's pipeline cycles{}",
        if banded {
            "; ms/frame band: the frame time at the corners of a sensitivity study around the \
             machine (found on the hierarchical driver's walk), lowest..highest"
        } else {
            ""
        }
    )?;
    Ok(())
}

/// Per machine, the conservative driver with the shortest frame; with `--bands`, whether it
/// stays the fastest at every corner (the same architectures time every driver, so the
/// drivers compare corner by corner).
fn print_fastest(
    report: &CompareReport,
    machines: &[String],
    out: &mut dyn Write,
) -> std::io::Result<()> {
    let conservative: Vec<&DriverReport> =
        report.drivers.iter().filter(|d| d.conservative).collect();
    for (index, machine) in machines.iter().enumerate() {
        let ms = |d: &DriverReport, variant: Option<usize>| {
            let time = &d.frame_time[index];
            variant.map_or(time.ms_per_frame, |v| time.ms_per_frame_at_variants[v])
        };
        let fastest = |variant| {
            conservative
                .iter()
                .min_by(|a, b| ms(a, variant).total_cmp(&ms(b, variant)))
                .map(|d| d.driver.as_str())
        };
        let Some(winner) = fastest(None) else {
            return Ok(());
        };
        let winner_report = conservative.iter().find(|d| d.driver == winner);
        let winner_ms = winner_report.map_or(0.0, |d| ms(d, None));
        write!(
            out,
            "fastest conservative driver on {machine}: {winner} ({winner_ms:.2} ms/frame)"
        )?;
        let variants =
            winner_report.map_or(0, |d| d.frame_time[index].ms_per_frame_at_variants.len());
        if variants > 0 {
            let others: Vec<&str> = (0..variants)
                .filter_map(|v| fastest(Some(v)))
                .filter(|&d| d != winner)
                .collect();
            write!(
                out,
                ", the fastest at {} of {variants} corners",
                variants - others.len()
            )?;
            if !others.is_empty() {
                let mut names = others.clone();
                names.sort_unstable();
                names.dedup();
                write!(out, " ({} at the others)", names.join(", "))?;
            }
        }
        writeln!(out)?;
    }
    Ok(())
}

/// What accuracy costs: each adaptive row against the conservative hierarchical driver,
/// each approximate hom row against the conservative hom driver.
fn print_accuracy(
    report: &CompareReport,
    machines: &[String],
    out: &mut dyn Write,
) -> std::io::Result<()> {
    let hierarchical =
        |d: &&DriverReport| d.driver == "hierarchical" || d.driver.starts_with("hierarchical/d");
    print_approximate(report, machines, "adaptive", hierarchical, "/t", out)?;
    print_approximate(
        report,
        machines,
        "approximate",
        |d| d.driver == "hom",
        "hom/o",
        out,
    )
}

fn print_approximate(
    report: &CompareReport,
    machines: &[String],
    what: &str,
    is_exact: impl Fn(&&DriverReport) -> bool,
    marker: &str,
    out: &mut dyn Write,
) -> std::io::Result<()> {
    let Some(exact) = report.drivers.iter().find(is_exact) else {
        return Ok(());
    };
    let adaptive: Vec<&DriverReport> = report
        .drivers
        .iter()
        .filter(|d| d.driver.contains(marker))
        .collect();
    if adaptive.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "\n{what} culling against {} (per frame):",
        exact.driver
    )?;
    write!(
        out,
        "{:<24} {:>10} {:>9} {:>15}",
        "driver", "px lost", "% lost", "triangles saved"
    )?;
    for machine in machines {
        write!(out, " {:>16}", format!("cycles saved {machine}"))?;
    }
    writeln!(out)?;
    for d in adaptive {
        write!(
            out,
            "{:<24} {:>10.0} {:>9.3} {:>15.0}",
            d.driver,
            d.pixels_lost_per_frame,
            100.0 * d.pixels_lost_per_frame / report.visible_pixels_per_frame.max(1.0),
            exact.triangles_per_frame - d.triangles_per_frame
        )?;
        for ((_, saved_from), (_, now)) in exact.cycles_per_frame.iter().zip(&d.cycles_per_frame) {
            write!(out, " {:>16.0}", saved_from - now)?;
        }
        writeln!(out)?;
    }
    writeln!(
        out,
        "  px lost: visible pixels not drawn, and as % of the visible pixels; triangles and \
         simulated cycles a frame saved against {}",
        exact.driver
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        compare: CompareArgs,
    }

    fn args(extra: &[&str]) -> CompareArgs {
        let base = [
            "occsim", "--scene", "city", "--blocks", "2", "--detail", "0", "--frames", "2",
            "--width", "80", "--height", "60",
        ];
        Cli::try_parse_from(base.iter().chain(extra))
            .unwrap()
            .compare
    }

    /// A stand-in machine: one cycle per fragment, counted from the stream it is fed.
    struct FragmentCounter {
        fragments: u64,
        frames_begun: u32,
    }

    impl FrameCycleModel for FragmentCounter {
        fn machine(&self) -> String {
            "frag".into()
        }
        fn begin_frame(&mut self, _: u32, _: u32) -> Result<(), ModelError> {
            self.fragments = 0;
            self.frames_begun += 1;
            Ok(())
        }
        fn event(&mut self, event: &Event) -> Result<(), ModelError> {
            if let Event::Fragment(_) = event {
                self.fragments += 1;
            }
            Ok(())
        }
        fn end_frame(&mut self) -> Result<FrameCost, ModelError> {
            Ok(FrameCost {
                cycles: self.fragments,
                seconds: self.fragments as f64 * 1e-6,
                ..FrameCost::default()
            })
        }
    }

    #[test]
    fn the_report_has_every_driver_and_the_supplied_machine() {
        let mut models: Vec<Box<dyn FrameCycleModel>> = vec![Box::new(FragmentCounter {
            fragments: 0,
            frames_begun: 0,
        })];
        let report = compare(&args(&["--adaptive-threshold", "0.3"]), &mut models).unwrap();
        let names: Vec<&str> = report.drivers.iter().map(|d| d.driver.as_str()).collect();
        assert_eq!(
            names,
            [
                "frustum",
                "hierarchical",
                "hierarchical/vob",
                "hierarchical/q2",
                "collision",
                "lazy-grid",
                "lazy-grid/obuf",
                "busy-grid",
                "busy-grid/obuf",
                "hierarchical/t0.3",
                "hom",
                "hom/o0.9",
                "large-occluders",
                "dynamic-grid",
                "dynamic-grid/2d",
                "raycast"
            ]
        );
        for d in &report.drivers {
            // The stand-in's cycles are the fragments it saw; the driver counted its own.
            let fragments = d.draw_fragments_per_frame + d.query_fragments_per_frame;
            assert_eq!(
                d.cycles_per_frame,
                vec![("frag".to_owned(), fragments)],
                "{}",
                d.driver
            );
            let approximate = d.driver.contains("/t") || d.driver.starts_with("hom/o");
            assert_eq!(d.conservative, !approximate, "{}", d.driver);
            if d.conservative {
                assert_eq!(d.pixels_lost_per_frame, 0.0, "{} is conservative", d.driver);
            }
        }
        let mut text = Vec::new();
        print_table(&report, &mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.contains("cycles frag"), "{text}");
        // The stand-in's frame time: a microsecond a fragment.
        for d in &report.drivers {
            let fragments = d.draw_fragments_per_frame + d.query_fragments_per_frame;
            let ms = d.frame_time[0].ms_per_frame;
            assert!((ms - fragments * 1e-3).abs() < 1e-9, "{}: {ms}", d.driver);
        }
        assert!(text.contains("frames/s"), "{text}");
        assert!(text.contains("cycles saved frag"), "{text}");
        assert!(text.contains("approximate culling against hom"), "{text}");
        let raycast = report.drivers.last().unwrap();
        assert!(raycast.rays_cast_per_frame > 0.0);
        assert!(raycast.rays_cast_per_frame < raycast.rays_full_screen_per_frame);
        assert!(text.contains("raycast: "), "{text}");
        assert!(text.contains("rays cast a frame of"), "{text}");
    }

    /// A machine's variants are timed on the same frames: a variant equal to the machine
    /// gives its frame time exactly, a slower host a longer one, and the band spans both.
    #[test]
    fn variants_time_the_same_frames_as_the_machine() {
        let o2 = crate::commands::arch::resolve("o2", None, &[]).unwrap();
        let mut slow_host = o2.clone();
        // The default is 80 host cycles a vertex (I 40..200); every driver draws vertices.
        slow_host
            .set_value("geometry_host_cycles_per_vertex", "200")
            .unwrap();
        let machine = MachineFrames::new(
            "o2".into(),
            o2.clone(),
            vec![
                (String::new(), o2),
                ("geometry_host_cycles_per_vertex=200".into(), slow_host),
            ],
            occsim_sweep::progress::ProgressBar::hidden(),
        );
        let mut models: Vec<Box<dyn FrameCycleModel>> = vec![Box::new(machine)];
        let report = compare(
            &args(&["--quadtree-levels", "0", "--adaptive-threshold", "0.2"]),
            &mut models,
        )
        .unwrap();
        for d in &report.drivers {
            let time = &d.frame_time[0];
            let at = &time.ms_per_frame_at_variants;
            assert_eq!(at[0], time.ms_per_frame, "{}", d.driver);
            assert!(at[1] > time.ms_per_frame, "{}: {at:?}", d.driver);
            assert_eq!(time.ms_per_frame_band, Some((at[0], at[1])), "{}", d.driver);
            assert_eq!(time.variants[1], "geometry_host_cycles_per_vertex=200");
        }
    }

    #[test]
    fn json_output_parses() {
        let mut out = Vec::new();
        run_with(
            &args(&[
                "--json",
                "--adaptive-threshold",
                "0.5",
                "--quadtree-levels",
                "0",
            ]),
            &mut [],
            &mut out,
        )
        .unwrap();
        let value: serde_json::Value = serde_json::from_slice(&out).unwrap();
        // frustum, hierarchical, hierarchical/vob, collision, the two grids in both
        // variants, one adaptive threshold, hom, hom/o0.9, large-occluders, the dynamic grid
        // in 3D and 2D, and raycast.
        assert_eq!(value["drivers"].as_array().unwrap().len(), 15);
        assert_eq!(value["frames"], 2);
    }
}
