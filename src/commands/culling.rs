//! `occsim culling compare`: every culling driver on the same walkthrough, side by side:
//! what each draws, what its queries cost, and (when timing models are supplied) the
//! simulated cycles per frame on each machine.

use super::workload_args::SceneArgs;
use anyhow::Context;
use occsim_traces::golden::EventSink;
use occsim_traces::workloads::{
    full_render_visible_pixels, generate, DriverKind, DriverOptions, GenerateError, Walk,
    WorkloadScene, WorkloadStats,
};
use occsim_traces::Event;
use serde::Serialize;
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
    #[arg(long, value_delimiter = ',', default_values_t = [0.05f32, 0.2, 0.5])]
    pub adaptive_threshold: Vec<f32>,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
}

/// A timing model the caller supplies (the O2 and ir4 machines live in the sim crate): it is
/// fed each frame's events and says how many cycles the frame took on its machine.
///
/// Frames are self-contained: each begins with `Clear` and the whole render state.
pub trait FrameCycleModel {
    /// The machine's name, a column of the report (e.g. `O2`, `ir4`).
    fn machine(&self) -> String;
    /// A new frame of `width` x `height` pixels begins; its events follow.
    fn begin_frame(&mut self, width: u32, height: u32) -> anyhow::Result<()>;
    fn event(&mut self, event: &Event) -> anyhow::Result<()>;
    /// Simulated cycles for the frame's events since `begin_frame`.
    fn end_frame(&mut self) -> anyhow::Result<u64>;
}

/// Splits the event stream into frames at `Clear` and feeds the timing models.
struct FrameSplitter<'m> {
    models: &'m mut [Box<dyn FrameCycleModel>],
    width: u32,
    height: u32,
    in_frame: bool,
    /// Per model, per frame.
    cycles: Vec<Vec<u64>>,
}

impl FrameSplitter<'_> {
    fn end_frame(&mut self) -> anyhow::Result<()> {
        if !self.in_frame {
            return Ok(());
        }
        for (model, cycles) in self.models.iter_mut().zip(&mut self.cycles) {
            cycles.push(model.end_frame()?);
        }
        self.in_frame = false;
        Ok(())
    }
}

impl EventSink for FrameSplitter<'_> {
    type Error = anyhow::Error;

    fn event(&mut self, event: &Event) -> anyhow::Result<()> {
        if self.models.is_empty() {
            return Ok(());
        }
        if let Event::Clear = event {
            self.end_frame()?;
            for model in self.models.iter_mut() {
                model.begin_frame(self.width, self.height)?;
            }
            self.in_frame = true;
        }
        for model in self.models.iter_mut() {
            model.event(event)?;
        }
        Ok(())
    }
}

/// One driver's line of the report; per-frame figures are means over the walk.
#[derive(Clone, Debug, Serialize)]
pub struct DriverReport {
    pub driver: String,
    /// Share of the scene's triangles drawn, over all frames.
    pub triangles_drawn_share: f64,
    pub triangles_per_frame: f64,
    pub objects_per_frame: f64,
    pub draw_fragments_per_frame: f64,
    pub queries_per_frame: f64,
    pub query_tiles_per_frame: f64,
    pub query_fragments_per_frame: f64,
    pub cells_refreshed_per_frame: f64,
    /// Visible pixels of the full render whose objects were not drawn, per frame.
    pub pixels_lost_per_frame: f64,
    /// Per machine: simulated cycles per frame.
    pub cycles_per_frame: Vec<(String, f64)>,
    /// Wall time of the traversal (driver logic, not the golden model), ms per frame.
    pub traversal_ms_per_frame: f64,
    /// Wall time inside the golden model, ms per frame.
    pub golden_model_ms_per_frame: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct CompareReport {
    pub scene: String,
    pub frames: u32,
    pub width: u32,
    pub height: u32,
    pub scene_triangles: u64,
    /// Mean visible pixels per frame in the full render.
    pub visible_pixels_per_frame: f64,
    pub drivers: Vec<DriverReport>,
}

/// The driver configurations the report compares.
fn drivers_to_compare(args: &CompareArgs) -> Vec<DriverOptions> {
    let delayed = |mut options: DriverOptions| {
        options.query_delay_frames = args.query_delay;
        options
    };
    let mut list = vec![
        delayed(DriverOptions::new(DriverKind::Frustum)),
        delayed(DriverOptions::new(DriverKind::Hierarchical)),
    ];
    if args.quadtree_levels > 0 {
        let mut quadtree = delayed(DriverOptions::new(DriverKind::Hierarchical));
        quadtree.quadtree_levels = args.quadtree_levels;
        list.push(quadtree);
    }
    list.push(DriverOptions::new(DriverKind::LazyGrid));
    list.push(DriverOptions::new(DriverKind::BusyGrid));
    for &threshold in &args.adaptive_threshold {
        let mut adaptive = delayed(DriverOptions::new(DriverKind::Hierarchical));
        adaptive.adaptive_threshold = Some(threshold);
        list.push(adaptive);
    }
    list
}

/// `culling compare` without timing models: the cycle columns are left out.
pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    let mut models: Vec<Box<dyn FrameCycleModel>> = Vec::new();
    for name in CYCLE_MACHINES {
        // A machine this build does not have is simply left out of the table.
        if let Ok(arch) = occsim_sim::Arch::builtin(name) {
            models.push(Box::new(MachineFrames::new(name, arch)));
        }
    }
    let stdout = std::io::stdout();
    run_with(&args, &mut models, &mut stdout.lock())
}

/// The machines `culling compare` times every frame on.
const CYCLE_MACHINES: [&str; 2] = ["o2", "ir4"];

/// A sim machine as a per-frame timing model: each frame replays on a fresh machine (frames
/// are self-contained: each begins with a clear and the whole render state).
struct MachineFrames {
    name: &'static str,
    arch: occsim_sim::Arch,
    machine: Option<occsim_sim::MachineModel>,
}

impl MachineFrames {
    fn new(name: &'static str, arch: occsim_sim::Arch) -> MachineFrames {
        MachineFrames {
            name,
            arch,
            machine: None,
        }
    }
}

impl FrameCycleModel for MachineFrames {
    fn machine(&self) -> String {
        self.name.to_owned()
    }

    fn begin_frame(&mut self, width: u32, height: u32) -> anyhow::Result<()> {
        let machine = occsim_sim::MachineModel::new(&self.arch, width, height)
            .with_context(|| format!("frame on {}", self.name))?;
        self.machine = Some(machine);
        Ok(())
    }

    fn event(&mut self, event: &Event) -> anyhow::Result<()> {
        if let Some(machine) = &mut self.machine {
            machine
                .event(event)
                .with_context(|| format!("frame on {}", self.name))?;
        }
        Ok(())
    }

    fn end_frame(&mut self) -> anyhow::Result<u64> {
        let machine = self
            .machine
            .take()
            .ok_or_else(|| anyhow::anyhow!("{}: a frame ended before it began", self.name))?;
        Ok(machine.finish()?.summary.cycles)
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
    let full: Vec<Vec<u64>> = (0..walk.frames)
        .map(|frame| full_render_visible_pixels(&scene, frame, &walk))
        .collect::<Result<_, _>>()
        .map_err(super::workload_args::flagged)?;
    let frames = walk.frames as f64;
    let visible: u64 = full.iter().flatten().sum();
    let mut drivers = Vec::new();
    for options in drivers_to_compare(args) {
        options.validate().map_err(super::workload_args::flagged)?;
        let mut splitter = FrameSplitter {
            cycles: vec![Vec::new(); models.len()],
            models: &mut *models,
            width: walk.width,
            height: walk.height,
            in_frame: false,
        };
        let on_driver = || format!("timing model on the {} driver", options.label());
        let stats = generate(&scene, &options, &walk, &mut splitter).map_err(|e| match e {
            GenerateError::Workload(e) => super::workload_args::flagged(e),
            GenerateError::Sink(e) => e.context(on_driver()),
        })?;
        splitter.end_frame().with_context(on_driver)?;
        let names: Vec<String> = splitter.models.iter().map(|m| m.machine()).collect();
        let cycles = names
            .into_iter()
            .zip(&splitter.cycles)
            .map(|(name, per_frame)| (name, per_frame.iter().sum::<u64>() as f64 / frames))
            .collect();
        drivers.push(driver_report(
            &options, &scene, &walk, &stats, &full, cycles,
        ));
    }
    Ok(CompareReport {
        scene: args.scene.describe(&scene),
        frames: walk.frames,
        width: walk.width,
        height: walk.height,
        scene_triangles: scene.triangle_count(),
        visible_pixels_per_frame: visible as f64 / frames,
        drivers,
    })
}

fn driver_report(
    options: &DriverOptions,
    scene: &WorkloadScene,
    walk: &Walk,
    stats: &WorkloadStats,
    full: &[Vec<u64>],
    cycles_per_frame: Vec<(String, f64)>,
) -> DriverReport {
    let frames = walk.frames as f64;
    let mean = |f: &dyn Fn(&occsim_traces::workloads::FrameStats) -> u64| {
        stats.frames.iter().map(f).sum::<u64>() as f64 / frames
    };
    let mut pixels_lost = 0u64;
    for (frame, visible) in stats.frames.iter().zip(full) {
        let mut drawn = vec![false; visible.len()];
        for &object in &frame.objects_drawn {
            drawn[object as usize] = true;
        }
        pixels_lost += visible
            .iter()
            .zip(&drawn)
            .filter(|(_, &d)| !d)
            .map(|(&p, _)| p)
            .sum::<u64>();
    }
    let ms = |f: &dyn Fn(&occsim_traces::workloads::FrameTiming) -> std::time::Duration| {
        stats.timing.iter().map(|t| f(t).as_secs_f64()).sum::<f64>() * 1e3 / frames
    };
    let triangles = mean(&|f| f.triangles_drawn);
    DriverReport {
        driver: options.label(),
        triangles_drawn_share: triangles / scene.triangle_count().max(1) as f64,
        triangles_per_frame: triangles,
        objects_per_frame: mean(&|f| f.objects_drawn.len() as u64),
        draw_fragments_per_frame: mean(&|f| f.draw_fragments),
        queries_per_frame: mean(&|f| f.queries),
        query_tiles_per_frame: mean(&|f| f.query_tiles),
        query_fragments_per_frame: mean(&|f| f.query_fragments),
        cells_refreshed_per_frame: mean(&|f| f.cells_refreshed),
        pixels_lost_per_frame: pixels_lost as f64 / frames,
        cycles_per_frame,
        traversal_ms_per_frame: ms(&|t| t.traversal()),
        golden_model_ms_per_frame: ms(&|t| t.golden_model),
    }
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
    print_accuracy(report, &machines, out)
}

/// What accuracy costs: each adaptive row against the conservative hierarchical driver.
fn print_accuracy(
    report: &CompareReport,
    machines: &[String],
    out: &mut dyn Write,
) -> std::io::Result<()> {
    let Some(exact) = report
        .drivers
        .iter()
        .find(|d| d.driver == "hierarchical" || d.driver.starts_with("hierarchical/d"))
    else {
        return Ok(());
    };
    let adaptive: Vec<&DriverReport> = report
        .drivers
        .iter()
        .filter(|d| d.driver.contains("/t"))
        .collect();
    if adaptive.is_empty() {
        return Ok(());
    }
    writeln!(
        out,
        "\nadaptive culling against {} (per frame):",
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
        fn begin_frame(&mut self, _: u32, _: u32) -> anyhow::Result<()> {
            self.fragments = 0;
            self.frames_begun += 1;
            Ok(())
        }
        fn event(&mut self, event: &Event) -> anyhow::Result<()> {
            if let Event::Fragment(_) = event {
                self.fragments += 1;
            }
            Ok(())
        }
        fn end_frame(&mut self) -> anyhow::Result<u64> {
            Ok(self.fragments)
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
                "hierarchical/q2",
                "lazy-grid",
                "busy-grid",
                "hierarchical/t0.3"
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
            if !d.driver.contains("/t") {
                assert_eq!(d.pixels_lost_per_frame, 0.0, "{} is conservative", d.driver);
            }
        }
        let mut text = Vec::new();
        print_table(&report, &mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.contains("cycles frag"), "{text}");
        assert!(text.contains("cycles saved frag"), "{text}");
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
        assert_eq!(value["drivers"].as_array().unwrap().len(), 5);
        assert_eq!(value["frames"], 2);
    }
}
