//! Command-line arguments that choose a walkthrough workload: the scene, its camera path,
//! the walk and the culling driver. Shared by `trace gen` (a workload as a trace) and
//! `culling compare`.

use anyhow::Context;
use occsim_sweep::output::write_atomically_with;
use occsim_traces::builtin::BuiltinChoices;
use occsim_traces::trace::{TraceHeader, TraceSummary};
use occsim_traces::words::counted;
use occsim_traces::workloads::{
    city, forest, generate_observed, load_obj, traffic, CameraPath, CityOptions, CommandObserver,
    DriverKind, DriverOptions, ForestOptions, FrameStats, GenerateError, ObjOptions,
    TrafficOptions, Walk, WorkloadError, WorkloadOption, WorkloadScene, MAX_CARS_PER_BLOCK,
    MAX_CITY_BLOCKS, MAX_CITY_DETAIL, MAX_CONE_SIDES, MAX_TREES,
};
use std::path::Path;

/// The scene, its camera and the walk.
#[derive(clap::Args, Clone, Debug)]
pub struct SceneArgs {
    /// The scene: `city`, `traffic` (the city with cars that move every frame), `forest`,
    /// or `obj:PATH` for a Wavefront OBJ model.
    #[arg(long, default_value = "city")]
    pub scene: String,
    /// Frames of the walkthrough (default 8, at most 1,000,000).
    #[arg(long)]
    pub frames: Option<u32>,
    /// Viewport width in pixels (default 1280).
    #[arg(long)]
    pub width: Option<u32>,
    /// Viewport height in pixels (default 1024).
    #[arg(long)]
    pub height: Option<u32>,
    /// Seed of the city's or forest's layout (default 1998).
    #[arg(long)]
    pub seed: Option<u64>,
    /// City and traffic: blocks along each side (default 6, at most 32; triangles grow with
    /// its square).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=MAX_CITY_BLOCKS as i64))]
    pub blocks: Option<u32>,
    /// Traffic: cars circling each block (default 3, at most 64).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=MAX_CARS_PER_BLOCK as i64))]
    pub cars_per_block: Option<u32>,
    /// Forest: trees in all (default 3000, at most 100,000).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=MAX_TREES as i64))]
    pub trees: Option<u32>,
    /// Detail: window sills per facade per floor (city and traffic, default 2, 0 to 16) or
    /// sides per crown cone (forest, default 10, 3 to 32).
    #[arg(long)]
    pub detail: Option<u32>,
    /// Camera path start X,Y,Z in metres (with --camera-to); replaces the scene's walk.
    #[arg(long, value_parser = parse_point, requires = "camera_to", conflicts_with = "camera_file")]
    pub camera_from: Option<[f32; 3]>,
    /// Camera path end X,Y,Z in metres (with --camera-from).
    #[arg(long, value_parser = parse_point, requires = "camera_from")]
    pub camera_to: Option<[f32; 3]>,
    /// The point X,Y,Z the camera looks at along --camera-from/--camera-to (default: the
    /// scene's centre).
    #[arg(long, value_parser = parse_point, requires = "camera_from")]
    pub camera_target: Option<[f32; 3]>,
    /// A TOML camera path: `[[keyframe]]` tables of `eye` and `target`, spread over the
    /// frames, or walked at `metres_per_frame`.
    #[arg(long)]
    pub camera_file: Option<std::path::PathBuf>,
    #[command(flatten)]
    pub raster: super::raster_args::RasterArgs,
}

/// The culling driver and its options.
#[derive(clap::Args, Clone, Debug)]
pub struct DriverArgs {
    /// The culling driver: frustum, hierarchical, lazy-grid, busy-grid, collision, hom,
    /// large-occluders, dynamic-grid or raycast.
    #[arg(long, default_value = "hierarchical")]
    pub driver: String,
    /// Frames before a query's answer is used: 0 (at once) or 1 (frustum, hierarchical).
    #[arg(long, default_value_t = 0)]
    pub query_delay: u32,
    /// Hierarchical: quadtree levels of tiles below each box's rectangle (0 to 4).
    #[arg(long, default_value_t = 0)]
    pub quadtree_levels: u32,
    /// Hierarchical: skip nodes whose boxes show less than this share of their pixels
    /// (NOHC/PHC); not conservative.
    #[arg(long)]
    pub adaptive_threshold: Option<f32>,
    /// Grids: cell side in pixels.
    #[arg(long, default_value_t = occsim_traces::workloads::DEFAULT_GRID_CELL_PIXELS)]
    pub grid_cell_pixels: u32,
    /// Grids: what a cell keeps: z-buffer (the farthest depth of its pixels, any
    /// front-to-back order) or occlusion-buffer (whether all its pixels are drawn; boxes are
    /// tested before anything not wholly in front of them is drawn).
    #[arg(long, default_value = "z-buffer")]
    pub variant: String,
    /// Collision: tiles a side the check area is cut into (1 to 16).
    #[arg(long, default_value_t = occsim_traces::workloads::DEFAULT_COLLISION_TILES)]
    pub collision_tiles: u32,
    /// Collision: the step's length in metres, the customised frustum's far plane (default:
    /// the distance to the next frame's eye).
    #[arg(long)]
    pub collision_step: Option<f32>,
    /// Hierarchical: test boxes without the Occlusion Unit, as the paper's software method
    /// did: draw the box, read its rectangle of the framebuffer back and search it.
    #[arg(long)]
    pub virtual_occlusion_buffer: bool,
    /// Hom: side of an occlusion-map pixel in screen pixels (1 to 64).
    #[arg(long, default_value_t = 4)]
    pub occlusion_map_cell_pixels: u32,
    /// Hom: opacity threshold T, level k of the pyramid at T^k; 1 is conservative, below 1
    /// approximate culling.
    #[arg(long, default_value_t = 1.0)]
    pub opacity_threshold: f32,
    /// Hom: the occluders' triangle budget a frame (default: a sixteenth of the scene's).
    #[arg(long)]
    pub occluder_triangles: Option<u64>,
    /// Dynamic grid: cells along the scene's longer horizontal side (4 to 256).
    #[arg(long, default_value_t = occsim_traces::workloads::DEFAULT_GRID_RESOLUTION)]
    pub grid_resolution: u32,
    /// Dynamic grid: the paper's 2D case, columns through the scene's whole height, instead
    /// of its 3D extension's cubes.
    #[arg(long)]
    pub flat_grid: bool,
    /// Raycast: bricks along each side of the volume (1 to 16).
    #[arg(long, default_value_t = occsim_traces::workloads::DEFAULT_VOLUME_BRICKS)]
    pub volume_bricks: u32,
    /// Raycast: entries of each brick's verbose buffer: 8 for the brief record, then one a
    /// hit; a brick with more hits overflows (its rays go through the box of its hits).
    #[arg(long, default_value_t = occsim_traces::workloads::DEFAULT_VERBOSE_BUFFER)]
    pub verbose_buffer: u32,
}

/// Everything `trace gen` needs to make a workload trace.
#[derive(clap::Args, Clone, Debug)]
pub struct WorkloadArgs {
    #[command(flatten)]
    pub scene: SceneArgs,
    #[command(flatten)]
    pub driver: DriverArgs,
}

/// Parse `X,Y,Z`.
fn parse_point(text: &str) -> Result<[f32; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let numbers: Vec<f32> = parts.iter().filter_map(|p| p.parse::<f32>().ok()).collect();
    match numbers[..] {
        [x, y, z] if parts.len() == 3 && numbers.iter().all(|n| n.is_finite()) => Ok([x, y, z]),
        _ => Err(format!(
            "`{text}`: expected three finite numbers X,Y,Z in metres"
        )),
    }
}

/// The flags of a walkthrough alone: a scene file or built-in scene refuses them (each is
/// its clap id, the field's name). The viewport, frames, seed and rasterizer are not among
/// them: a built-in scene takes those it has ([`BuiltinChoices`]).
pub const WALK_ONLY: [&str; 25] = [
    "scene",
    "blocks",
    "cars_per_block",
    "trees",
    "detail",
    "camera_from",
    "camera_to",
    "camera_target",
    "camera_file",
    "driver",
    "query_delay",
    "quadtree_levels",
    "adaptive_threshold",
    "grid_cell_pixels",
    "variant",
    "collision_tiles",
    "collision_step",
    "virtual_occlusion_buffer",
    "occlusion_map_cell_pixels",
    "opacity_threshold",
    "occluder_triangles",
    "grid_resolution",
    "flat_grid",
    "volume_bricks",
    "verbose_buffer",
];

impl SceneArgs {
    /// Frames of the walk (8 unless given).
    pub fn frames(&self) -> u32 {
        self.frames.unwrap_or(8)
    }

    /// Seed of the scene's layout (1998 unless given).
    pub fn seed(&self) -> u64 {
        self.seed.unwrap_or(1998)
    }

    pub fn walk(&self) -> Walk {
        Walk {
            frames: self.frames(),
            width: self.width.unwrap_or(1280),
            height: self.height.unwrap_or(1024),
            raster: self.raster.profile,
        }
    }

    /// What a built-in scene is asked for: the viewport, frames and seed given, none
    /// otherwise (each scene keeps its own defaults).
    pub fn builtin_choices(&self) -> BuiltinChoices {
        BuiltinChoices {
            width: self.width,
            height: self.height,
            frames: self.frames,
            seed: self.seed,
        }
    }

    /// Build (or load) the scene and put the camera on its path.
    pub fn load_scene(&self) -> anyhow::Result<WorkloadScene> {
        let name = self.scene.as_str();
        if self.blocks.is_some() && !matches!(name, "city" | "traffic") {
            anyhow::bail!("--blocks applies to the city and traffic scenes only, not `{name}`");
        }
        if self.cars_per_block.is_some() && name != "traffic" {
            anyhow::bail!("--cars-per-block applies to the traffic scene only, not `{name}`");
        }
        if self.trees.is_some() && name != "forest" {
            anyhow::bail!("--trees applies to the forest scene only, not `{name}`");
        }
        if self.detail.is_some() && name.starts_with("obj:") {
            anyhow::bail!("--detail applies to the city and forest scenes, not to OBJ models");
        }
        if let Some(detail) = self.detail {
            let range = match name {
                "forest" => 3..=MAX_CONE_SIDES,
                _ => 0..=MAX_CITY_DETAIL,
            };
            anyhow::ensure!(
                range.contains(&detail),
                "--detail {detail}: the {name} scene takes {} to {}",
                range.start(),
                range.end()
            );
        }
        let city_options = || {
            let defaults = CityOptions::default();
            CityOptions {
                blocks: self.blocks.unwrap_or(defaults.blocks),
                detail: self.detail.unwrap_or(defaults.detail),
                seed: self.seed(),
            }
        };
        let scene = match name {
            "city" => city(&city_options()),
            "traffic" => traffic(&TrafficOptions {
                city: city_options(),
                cars_per_block: self
                    .cars_per_block
                    .unwrap_or(TrafficOptions::default().cars_per_block),
            }),
            "forest" => {
                let defaults = ForestOptions::default();
                forest(&ForestOptions {
                    trees: self.trees.unwrap_or(defaults.trees),
                    detail: self.detail.unwrap_or(defaults.detail),
                    seed: self.seed(),
                })
            }
            other => match other.strip_prefix("obj:") {
                Some(path) => load_obj_file(Path::new(path))?,
                None => anyhow::bail!(
                    "unknown scene `{other}`: expected city, traffic, forest or obj:PATH"
                ),
            },
        };
        match self.camera_path(&scene)? {
            Some(path) => Ok(scene.with_camera(path)),
            None => Ok(scene),
        }
    }

    fn camera_path(&self, scene: &WorkloadScene) -> anyhow::Result<Option<CameraPath>> {
        if let (Some(from), Some(to)) = (self.camera_from, self.camera_to) {
            let target = self.camera_target.unwrap_or(scene.centre());
            let path = CameraPath::line(from, to, target).context("--camera-from/--camera-to")?;
            return Ok(Some(path));
        }
        let Some(file) = &self.camera_file else {
            return Ok(None);
        };
        let text = super::read_settings_file(file, "camera file")?;
        Ok(Some(CameraPath::from_toml(
            &text,
            &file.display().to_string(),
        )?))
    }

    /// A one-line account of the scene and walk, for trace headers and reports.
    pub fn describe(&self, scene: &WorkloadScene) -> String {
        let walk = self.walk();
        format!(
            "{} ({}, {}, seed {}) {} at {}x{}",
            self.scene,
            counted(scene.object_count() as u64, "object", "objects"),
            counted(scene.triangle_count(), "triangle", "triangles"),
            self.seed(),
            counted(walk.frames.into(), "frame", "frames"),
            walk.width,
            walk.height
        )
    }
}

fn load_obj_file(path: &Path) -> anyhow::Result<WorkloadScene> {
    anyhow::ensure!(
        !path.as_os_str().is_empty(),
        "--scene obj:PATH: give the OBJ model's path after `obj:`"
    );
    let file = std::fs::File::open(path)
        .with_context(|| format!("cannot open OBJ model {}", path.display()))?;
    // A directory opens, and its first read fails as the loader's "read error" on line 1.
    anyhow::ensure!(
        !file.metadata().is_ok_and(|m| m.is_dir()),
        "cannot read OBJ model {}: it is a directory",
        path.display()
    );
    occsim_sweep::output::note_input(path);
    let reader = std::io::BufReader::with_capacity(1 << 16, file);
    Ok(load_obj(
        reader,
        &path.display().to_string(),
        &ObjOptions::default(),
    )?)
}

impl DriverArgs {
    pub fn options(&self) -> anyhow::Result<DriverOptions> {
        let kind: DriverKind = self.driver.parse()?;
        let options = DriverOptions {
            kind,
            query_delay_frames: self.query_delay,
            quadtree_levels: self.quadtree_levels,
            adaptive_threshold: self.adaptive_threshold,
            grid_cell_pixels: self.grid_cell_pixels,
            grid_variant: self.variant.parse().map_err(flagged)?,
            collision_tiles: self.collision_tiles,
            collision_step: self.collision_step,
            virtual_occlusion_buffer: self.virtual_occlusion_buffer,
            occlusion_map_cell_pixels: self.occlusion_map_cell_pixels,
            opacity_threshold: self.opacity_threshold,
            occluder_triangles: self.occluder_triangles,
            dynamic_grid_resolution: self.grid_resolution,
            flat_grid: self.flat_grid,
            volume_bricks: self.volume_bricks,
            verbose_buffer_entries: self.verbose_buffer,
        };
        options.validate().map_err(flagged)?;
        Ok(options)
    }
}

/// A workload error in the command line's words: an option named by its flag.
pub fn flagged(error: WorkloadError) -> anyhow::Error {
    match error {
        WorkloadError::Option { option, detail } => {
            let flag = match option {
                WorkloadOption::Frames => "--frames",
                WorkloadOption::Width => "--width",
                WorkloadOption::Height => "--height",
                WorkloadOption::QueryDelay => "--query-delay",
                WorkloadOption::QuadtreeLevels => "--quadtree-levels",
                WorkloadOption::AdaptiveThreshold => "--adaptive-threshold",
                WorkloadOption::GridCellPixels => "--grid-cell-pixels",
                WorkloadOption::GridVariant => "--variant",
                WorkloadOption::CollisionTiles => "--collision-tiles",
                WorkloadOption::CollisionStep => "--collision-step",
                WorkloadOption::VirtualOcclusionBuffer => "--virtual-occlusion-buffer",
                WorkloadOption::OcclusionMapCellPixels => "--occlusion-map-cell-pixels",
                WorkloadOption::OpacityThreshold => "--opacity-threshold",
                WorkloadOption::OccluderTriangles => "--occluder-triangles",
                WorkloadOption::GridResolution => "--grid-resolution",
                WorkloadOption::FlatGrid => "--flat-grid",
                WorkloadOption::VolumeBricks => "--volume-bricks",
                WorkloadOption::VerboseBuffer => "--verbose-buffer",
            };
            anyhow::anyhow!("{flag} {detail}")
        }
        // The viewport the flags asked for, too large for this process.
        WorkloadError::ViewportBuffer(too_large) => anyhow::anyhow!(
            "--width {} --height {}: {too_large}",
            too_large.width,
            too_large.height
        ),
        other => other.into(),
    }
}

impl WorkloadArgs {
    /// The scene (camera on its path), the driver and the walk these arguments ask for.
    pub fn resolve(&self) -> anyhow::Result<(WorkloadScene, DriverOptions, Walk)> {
        let (driver, walk) = self.checked()?;
        let scene = self.scene.load_scene()?;
        Ok((scene, driver, walk))
    }

    /// The driver and the walk, checked (the walk's viewport and frames, the driver and its
    /// options, each error naming its flag) without building the scene: before the scene is
    /// built and a trace's header takes the viewport, and as a corpus file is read.
    pub fn checked(&self) -> anyhow::Result<(DriverOptions, Walk)> {
        let walk = self.scene.walk();
        walk.validate().map_err(flagged)?;
        Ok((self.driver.options()?, walk))
    }

    /// Whether the walk is the collision driver's (whose frames each print a test).
    pub fn is_collision(&self) -> bool {
        matches!(self.driver.driver.parse(), Ok(DriverKind::Collision))
    }

    /// A one-line account for the trace header's scene field.
    pub fn describe(&self, scene: &WorkloadScene, driver: &DriverOptions) -> String {
        format!("{} driver {}", self.scene.describe(scene), driver.label())
    }
}

/// Workload flags as `trace gen` takes them, parsed from `flags` (no command name): for
/// walks a command makes itself (`fidelity --corpus`, `culling compare --bands`).
pub fn parse_workload_flags<I, T>(flags: I) -> Result<WorkloadArgs, clap::Error>
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    #[derive(clap::Parser)]
    #[command(no_binary_name = true)]
    struct Flags {
        #[command(flatten)]
        workload: WorkloadArgs,
    }
    <Flags as clap::Parser>::try_parse_from(flags).map(|f| f.workload)
}

/// A flag parser's error as one line: its message and tip, without the usage and help lines
/// a command line's error prints (a corpus recipe's `walk` is not a command line, and they
/// named a usage of `occsim` it does not have).
pub fn in_one_line(error: &clap::Error) -> String {
    let text = error.to_string();
    let said = (text.lines().map(str::trim))
        .filter(|line| !line.is_empty() && !line.starts_with("For more information"))
        .take_while(|line| !line.starts_with("Usage:"))
        .map(|line| line.strip_prefix("error: ").unwrap_or(line));
    let mut one = String::new();
    for line in said {
        if !one.is_empty() {
            // A line ending in a colon introduces the next ("not provided: --camera-to").
            one.push_str(if one.ends_with(':') { " " } else { "; " });
        }
        one.push_str(line);
    }
    one
}

/// `trace gen` for a workload: walk the scene with the driver, writing the golden model's
/// events to `output` (atomically). The header's scene field describes the workload.
/// Its frames' statistics go to `each_frame` as they end, frame by frame, and are not kept:
/// memory stays flat however many frames it runs. Returns the trace's summary and the
/// number of frames.
pub fn write_workload_trace(
    args: &WorkloadArgs,
    output: &Path,
    each_frame: impl FnMut(u64, &FrameStats) -> std::io::Result<()>,
) -> anyhow::Result<(TraceSummary, u64)> {
    let (scene, driver, walk) = args.resolve()?;
    let header = TraceHeader::new(walk.width, walk.height)
        .with_scene(args.describe(&scene, &driver))
        .with_raster(walk.raster);
    let mut frames = FrameProgress {
        bar: occsim_sweep::progress::bar(walk.frames as u64, "frames"),
        frames: 0,
        each_frame,
        failed: None,
    };
    frames
        .bar
        .set_message(format!("{} walkthrough", driver.label()));
    let written: anyhow::Result<TraceSummary> = write_atomically_with(output, |file| {
        let mut writer = super::trace::indexed_writer(file, output, &header)?;
        generate_observed(&scene, &driver, &walk, &mut writer, &mut frames).map_err(
            |e| match e {
                GenerateError::Workload(e) => flagged(e),
                GenerateError::Sink(e) => anyhow::Error::new(e)
                    .context(format!("{}: cannot write trace", output.display())),
            },
        )?;
        if let Some(error) = frames.failed.take() {
            // A frame's lines could not be printed: the command fails, and writes nothing.
            return Err(error.into());
        }
        let summary = writer
            .finish_seekable()
            .with_context(|| format!("{}: cannot write trace", output.display()))?;
        Ok(summary)
    });
    frames.bar.finish_and_clear();
    Ok((written?, frames.frames))
}

/// Moves a progress bar a step at each frame's end, and hands each frame's statistics on
/// (keeping none).
struct FrameProgress<F> {
    bar: occsim_sweep::progress::ProgressBar,
    frames: u64,
    each_frame: F,
    /// The first error `each_frame` gave (printing to a closed pipe): it is given no more.
    failed: Option<std::io::Error>,
}

impl<F: FnMut(u64, &FrameStats) -> std::io::Result<()>> CommandObserver for FrameProgress<F> {
    fn command(&mut self, command: &occsim_traces::Command) {
        if let occsim_traces::Command::Swap = command {
            self.bar.inc(1);
        }
    }

    fn frame(&mut self, stats: &FrameStats) -> bool {
        if self.failed.is_none() {
            self.failed = (self.each_frame)(self.frames, stats).err();
        }
        self.frames += 1;
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        workload: WorkloadArgs,
    }

    fn parse(args: &[&str]) -> Result<WorkloadArgs, String> {
        let argv = std::iter::once("occsim").chain(args.iter().copied());
        Cli::try_parse_from(argv)
            .map(|cli| cli.workload)
            .map_err(|e| e.to_string())
    }

    fn resolve_error(args: &[&str]) -> String {
        match parse(args).map(|a| a.resolve()) {
            Ok(Ok(_)) => String::new(),
            Ok(Err(error)) => format!("{error:#}"),
            Err(error) => error,
        }
    }

    /// Every flag a walkthrough takes is in [`WALK_ONLY`] but those a built-in scene takes
    /// too, so that a flag added later is refused beside a SCENE, not passed over.
    #[test]
    fn walk_only_names_every_walkthrough_flag_a_scene_does_not_take() {
        use clap::Args;
        let command = WorkloadArgs::augment_args(clap::Command::new("walk"));
        let shared = ["frames", "width", "height", "seed", "profile"];
        let ids: Vec<String> = (command.get_arguments())
            .map(|arg| arg.get_id().to_string())
            .collect();
        for id in &ids {
            let walk_only = WALK_ONLY.contains(&id.as_str());
            assert_eq!(walk_only, !shared.contains(&id.as_str()), "{id}");
        }
        assert_eq!(WALK_ONLY.len() + shared.len(), ids.len(), "{ids:?}");
    }

    #[test]
    fn a_flag_error_reads_in_one_line() {
        let said = |flags: &[&str]| in_one_line(&parse_workload_flags(flags).err().unwrap());
        assert_eq!(
            said(&["--bogus"]),
            "unexpected argument '--bogus' found; tip: a similar argument exists: '--blocks'"
        );
        let digit = said(&["--frames", "x"]);
        assert_eq!(
            digit,
            "invalid value 'x' for '--frames <FRAMES>': invalid digit found in string"
        );
        let missing = said(&["--camera-from", "1,2,3"]);
        assert!(
            missing.ends_with("were not provided: --camera-to <CAMERA_TO>"),
            "{missing}"
        );
    }

    #[test]
    fn flags_become_options() {
        let args = parse(&[
            "--scene",
            "forest",
            "--trees",
            "20",
            "--detail",
            "4",
            "--driver",
            "lazy-grid",
            "--grid-cell-pixels",
            "16",
            "--frames",
            "3",
            "--width",
            "64",
            "--height",
            "48",
            "--camera-from",
            "0,2,10",
            "--camera-to",
            "0,2,-10",
            "--camera-target",
            "0,0,-50",
        ])
        .unwrap();
        let (scene, driver, walk) = args.resolve().unwrap();
        assert_eq!(scene.object_count(), 21);
        assert_eq!(driver.kind, DriverKind::LazyGrid);
        assert_eq!(driver.grid_cell_pixels, 16);
        assert_eq!(
            walk,
            Walk {
                frames: 3,
                width: 64,
                height: 48,
                raster: occsim_traces::raster::RasterProfile::Llvmpipe,
            }
        );
        assert_eq!(scene.camera().keyframes()[1].eye, [0.0, 2.0, -10.0]);
        assert_eq!(scene.camera().keyframes()[0].target, [0.0, 0.0, -50.0]);
    }

    #[test]
    fn a_workload_trace_holds_the_walk() {
        let args = parse(&[
            "--scene",
            "city",
            "--blocks",
            "2",
            "--detail",
            "0",
            "--driver",
            "lazy-grid",
            "--frames",
            "2",
            "--width",
            "64",
            "--height",
            "48",
        ])
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("walk.occt");
        let mut frames = Vec::new();
        let (summary, count) = write_workload_trace(&args, &path, |_, stats| {
            frames.push(stats.clone());
            Ok(())
        })
        .unwrap();
        assert_eq!((count, frames.len()), (2, 2));
        let fragments: u64 = frames
            .iter()
            .map(|f| f.draw_fragments + f.query_fragments)
            .sum();
        assert_eq!(summary.fragments, fragments);
        let queries: u64 = frames.iter().map(|f| f.queries).sum();
        assert_eq!(summary.queries, queries);
        let mut reader = super::super::trace::open_trace(&path).unwrap();
        assert!(
            reader.header().scene.contains("driver lazy-grid"),
            "{}",
            reader.header().scene
        );
        let read = reader
            .read_into(&mut occsim_traces::golden::Discard)
            .unwrap();
        assert_eq!(read.fragments, fragments);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_flags_are_refused_clearly() {
        assert!(resolve_error(&["--driver", "magic"]).contains("unknown driver `magic`"));
        assert!(resolve_error(&["--scene", "moon"]).contains("unknown scene `moon`"));
        // The walk's frames and viewport, before the scene is built and a trace's header
        // takes the viewport (whose error had named neither flag nor file).
        let frames = resolve_error(&["--frames", "0"]);
        assert!(frames.contains("--frames 0"), "{frames}");
        let wide = resolve_error(&["--width", "65535"]);
        assert!(wide.contains("--width 65535 out of range"), "{wide}");
        let flat = resolve_error(&["--height", "0"]);
        assert!(flat.contains("--height 0 out of range"), "{flat}");
        assert!(resolve_error(&["--camera-from", "1,2"]).contains("expected three finite numbers"));
        assert!(resolve_error(&["--camera-from", "1,2,3"]).contains("--camera-to"));
        let missing = resolve_error(&["--scene", "obj:/no/such/model.obj"]);
        assert!(
            missing.contains("cannot open OBJ model /no/such/model.obj"),
            "{missing}"
        );
        let nothing = resolve_error(&["--scene", "obj:"]);
        assert!(nothing.contains("give the OBJ model's path"), "{nothing}");
        let directory = resolve_error(&["--scene", "obj:/"]);
        assert!(directory.contains("/: it is a directory"), "{directory}");
        let camera = resolve_error(&["--camera-file", "/no/such/walk.toml"]);
        assert!(
            camera.contains("cannot open camera file /no/such/walk.toml"),
            "{camera}"
        );
        // Sizes past what memory holds are refused, not clamped (--blocks 201 had become 200
        // and taken 3.1 GB; --trees 1000000, under the old 4,000,000, 3.9 GB).
        for (flags, expected) in [
            (
                &["--scene", "city", "--blocks", "33"][..],
                "33 is not in 1..=32",
            ),
            (
                &["--scene", "city", "--blocks", "0"][..],
                "0 is not in 1..=32",
            ),
            (
                &["--scene", "forest", "--trees", "100001"][..],
                "not in 1..=100000",
            ),
            (
                &["--scene", "traffic", "--cars-per-block", "65"][..],
                "not in 0..=64",
            ),
            (
                &["--scene", "forest", "--detail", "300"][..],
                "the forest scene takes 3 to 32",
            ),
            (
                &["--scene", "city", "--detail", "17"][..],
                "the city scene takes 0 to 16",
            ),
        ] {
            let error = resolve_error(flags);
            assert!(error.contains(expected), "{flags:?}: {error}");
        }
        let misplaced = resolve_error(&["--scene", "forest", "--blocks", "3"]);
        assert!(
            misplaced.contains("--blocks applies to the city"),
            "{misplaced}"
        );
        let delayed = resolve_error(&["--driver", "busy-grid", "--query-delay", "1"]);
        assert!(delayed.contains("--query-delay applies to"), "{delayed}");
        let cars = resolve_error(&["--scene", "city", "--cars-per-block", "2"]);
        assert!(
            cars.contains("--cars-per-block applies to the traffic"),
            "{cars}"
        );
        let flat = resolve_error(&["--driver", "hom", "--flat-grid"]);
        assert!(
            flat.contains("--flat-grid applies to the dynamic-grid"),
            "{flat}"
        );
        let coarse = resolve_error(&["--driver", "dynamic-grid", "--grid-resolution", "1"]);
        assert!(
            coarse.contains("--grid-resolution 1 out of range"),
            "{coarse}"
        );
        let buffer = resolve_error(&["--driver", "raycast", "--verbose-buffer", "7"]);
        assert!(
            buffer.contains("--verbose-buffer 7 out of range"),
            "{buffer}"
        );
        let bricks = resolve_error(&["--driver", "hierarchical", "--volume-bricks", "2"]);
        assert!(
            bricks.contains("--volume-bricks applies to the raycast"),
            "{bricks}"
        );
    }
}
