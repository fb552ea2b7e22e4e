//! Comparing culling drivers on one walkthrough: what each draws, what its queries cost, the
//! visible pixels it loses against a full render, and (with timing models the caller
//! supplies, such as the sim crate's machines) the simulated cycles per frame on each.

use super::{
    full_render_visible_pixels, generate, DriverOptions, FrameStats, FrameTiming, GenerateError,
    Walk, WorkloadError, WorkloadScene, WorkloadStats,
};
use crate::golden::EventSink;
use crate::Event;
use serde::Serialize;

/// What a timing model can fail with.
pub type ModelError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Why a comparison stopped.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    #[error(transparent)]
    Workload(#[from] WorkloadError),
    #[error("timing model on the {driver} driver")]
    Model {
        driver: String,
        #[source]
        source: ModelError,
    },
}

/// A timing model the caller supplies (the O2 and ir4 machines live in the sim crate): it is
/// fed each frame's events and says how many cycles the frame took on its machine.
///
/// Frames are self-contained: each begins with `Clear` and the whole render state.
pub trait FrameCycleModel {
    /// The machine's name, a column of the report (e.g. `O2`, `ir4`).
    fn machine(&self) -> String;
    /// A new frame of `width` x `height` pixels begins; its events follow.
    fn begin_frame(&mut self, width: u32, height: u32) -> Result<(), ModelError>;
    fn event(&mut self, event: &Event) -> Result<(), ModelError>;
    /// The frame's time for its events since `begin_frame`.
    fn end_frame(&mut self) -> Result<FrameCost, ModelError>;
    /// What each of the machine's variants changes from it (`key=value, ...`), in the
    /// order of [`FrameCost::variant_seconds`]; none without variants.
    fn variants(&self) -> Vec<String> {
        Vec::new()
    }
}

/// What one frame cost on a machine: its cycles and seconds, and where the host's time went
/// (busy, waiting on answers) beside the geometry stage's and the rasterizer's busy cycles.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FrameCost {
    pub cycles: u64,
    pub seconds: f64,
    pub host_busy: u64,
    pub geometry_busy: u64,
    pub pixel_busy: u64,
    pub waiting: u64,
    /// The host idle, the pipe still busy with work it released (`host_busy + waiting +
    /// pipe_wait = cycles`).
    pub pipe_wait: u64,
    /// The frame's seconds on each of the machine's variants a sensitivity band is taken
    /// over (the corners of a study), in the same order every frame; empty without bands.
    pub variant_seconds: Vec<f64>,
}

/// A driver's frames on one machine, as means per frame.
#[derive(Clone, Debug, Serialize)]
pub struct MachineFrameTime {
    pub machine: String,
    pub frames_per_second: f64,
    pub ms_per_frame: f64,
    pub host_busy_cycles: f64,
    pub geometry_busy_cycles: f64,
    pub pixel_busy_cycles: f64,
    pub waiting_cycles: f64,
    pub pipe_wait_cycles: f64,
    /// With variants: the band of `ms_per_frame` over the machine and its variants,
    /// `(low, high)`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ms_per_frame_band: Option<(f64, f64)>,
    /// The mean frame time on each of the machine's variants, in their order (the same
    /// architectures for every driver, so drivers compare variant by variant).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub ms_per_frame_at_variants: Vec<f64>,
    /// What each variant changes from the machine, in the same order (`key=value, ...`), so
    /// that a corner can be run again (the JSON had given its frame time alone).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub variants: Vec<String>,
}

impl MachineFrameTime {
    fn of(machine: String, variants: Vec<String>, frames: &[FrameCost]) -> MachineFrameTime {
        let n = frames.len().max(1) as f64;
        let mean = |f: &dyn Fn(&FrameCost) -> u64| frames.iter().map(f).sum::<u64>() as f64 / n;
        let seconds: f64 = frames.iter().map(|f| f.seconds).sum();
        MachineFrameTime {
            machine,
            frames_per_second: if seconds > 0.0 {
                frames.len() as f64 / seconds
            } else {
                0.0
            },
            ms_per_frame: seconds * 1e3 / n,
            host_busy_cycles: mean(&|f| f.host_busy),
            geometry_busy_cycles: mean(&|f| f.geometry_busy),
            pixel_busy_cycles: mean(&|f| f.pixel_busy),
            waiting_cycles: mean(&|f| f.waiting),
            pipe_wait_cycles: mean(&|f| f.pipe_wait),
            ms_per_frame_band: None,
            ms_per_frame_at_variants: mean_ms_at_variants(frames),
            variants,
        }
        .with_band()
    }

    /// The band of the mean frame time over the machine and each of its variants (each
    /// variant's mean over the frames, not each frame's extremes).
    fn with_band(mut self) -> MachineFrameTime {
        if !self.ms_per_frame_at_variants.is_empty() {
            let mut band = (self.ms_per_frame, self.ms_per_frame);
            for &ms in &self.ms_per_frame_at_variants {
                band = (band.0.min(ms), band.1.max(ms));
            }
            self.ms_per_frame_band = Some(band);
        }
        self
    }
}

/// Each variant's mean frame time in ms over `frames` (every frame names the same variants).
fn mean_ms_at_variants(frames: &[FrameCost]) -> Vec<f64> {
    let variants = frames.first().map_or(0, |f| f.variant_seconds.len());
    let n = frames.len() as f64;
    (0..variants)
        .map(|variant| {
            let seconds: f64 = frames
                .iter()
                .map(|f| f.variant_seconds.get(variant).copied().unwrap_or(f.seconds))
                .sum();
            seconds * 1e3 / n
        })
        .collect()
}

/// Splits the event stream into frames at `Clear` and feeds the timing models.
struct FrameSplitter<'m> {
    models: &'m mut [Box<dyn FrameCycleModel>],
    width: u32,
    height: u32,
    in_frame: bool,
    /// Per model, per frame.
    cycles: Vec<Vec<FrameCost>>,
}

impl FrameSplitter<'_> {
    fn end_frame(&mut self) -> Result<(), ModelError> {
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
    type Error = ModelError;

    fn event(&mut self, event: &Event) -> Result<(), ModelError> {
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
    /// Whether the driver draws every object with a visible pixel by construction.
    pub conservative: bool,
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
    /// Raycast: rays cast, rays a cast through every pixel needs, and bricks whose verbose
    /// buffers overflowed, per frame (0 for other drivers).
    pub rays_cast_per_frame: f64,
    pub rays_full_screen_per_frame: f64,
    pub overflowed_buffers_per_frame: f64,
    /// Per machine: simulated cycles per frame (in JSON an object, machine -> cycles, in
    /// the machines' order).
    #[serde(serialize_with = "pairs_as_object")]
    pub cycles_per_frame: Vec<(String, f64)>,
    /// Per machine: frames per second and the split of a frame's time.
    pub frame_time: Vec<MachineFrameTime>,
    /// Wall time of the traversal (driver logic, not the golden model), ms per frame.
    pub traversal_ms_per_frame: f64,
    /// Wall time inside the golden model, ms per frame.
    pub golden_model_ms_per_frame: f64,
}

/// `[(name, value)]` as a JSON object, in the pairs' order.
fn pairs_as_object<S: serde::Serializer>(
    pairs: &[(String, f64)],
    serializer: S,
) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeMap;
    let mut map = serializer.serialize_map(Some(pairs.len()))?;
    for (name, value) in pairs {
        map.serialize_entry(name, value)?;
    }
    map.end()
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

/// Walk `scene` with each of `drivers` and gather the report; `scene_name` names the scene in
/// it. The full render each driver is judged against is made once per frame.
pub fn compare(
    scene: &WorkloadScene,
    scene_name: String,
    walk: &Walk,
    drivers_to_compare: &[DriverOptions],
    models: &mut [Box<dyn FrameCycleModel>],
) -> Result<CompareReport, CompareError> {
    let full: Vec<Vec<u64>> = (0..walk.frames)
        .map(|frame| full_render_visible_pixels(scene, frame, walk))
        .collect::<Result<_, _>>()?;
    let frames = walk.frames as f64;
    let visible: u64 = full.iter().flatten().sum();
    let mut drivers = Vec::new();
    for options in drivers_to_compare {
        options.validate()?;
        let mut splitter = FrameSplitter {
            cycles: vec![Vec::new(); models.len()],
            models: &mut *models,
            width: walk.width,
            height: walk.height,
            in_frame: false,
        };
        let model_error = |source| CompareError::Model {
            driver: options.label(),
            source,
        };
        let stats = generate(scene, options, walk, &mut splitter).map_err(|e| match e {
            GenerateError::Workload(e) => CompareError::Workload(e),
            GenerateError::Sink(e) => model_error(e),
        })?;
        splitter.end_frame().map_err(model_error)?;
        let names: Vec<String> = splitter.models.iter().map(|m| m.machine()).collect();
        let cycles = names
            .iter()
            .zip(&splitter.cycles)
            .map(|(name, per_frame)| {
                let total: u64 = per_frame.iter().map(|f| f.cycles).sum();
                (name.clone(), total as f64 / frames)
            })
            .collect();
        let mut report = driver_report(options, scene, walk, &stats, &full, cycles);
        let variants = splitter.models.iter().map(|m| m.variants());
        report.frame_time = (names.into_iter().zip(variants))
            .zip(&splitter.cycles)
            .map(|((name, variants), per_frame)| MachineFrameTime::of(name, variants, per_frame))
            .collect();
        drivers.push(report);
    }
    Ok(CompareReport {
        scene: scene_name,
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
    let mean =
        |f: &dyn Fn(&FrameStats) -> u64| stats.frames.iter().map(f).sum::<u64>() as f64 / frames;
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
    let ms = |f: &dyn Fn(&FrameTiming) -> std::time::Duration| {
        stats.timing.iter().map(|t| f(t).as_secs_f64()).sum::<f64>() * 1e3 / frames
    };
    let triangles = mean(&|f| f.triangles_drawn);
    DriverReport {
        driver: options.label(),
        conservative: options.is_conservative(),
        triangles_drawn_share: triangles / scene.triangle_count().max(1) as f64,
        triangles_per_frame: triangles,
        objects_per_frame: mean(&|f| f.objects_drawn.len() as u64),
        draw_fragments_per_frame: mean(&|f| f.draw_fragments),
        queries_per_frame: mean(&|f| f.queries),
        query_tiles_per_frame: mean(&|f| f.query_tiles),
        query_fragments_per_frame: mean(&|f| f.query_fragments),
        cells_refreshed_per_frame: mean(&|f| f.cells_refreshed),
        pixels_lost_per_frame: pixels_lost as f64 / frames,
        rays_cast_per_frame: mean(&|f| f.rays_cast),
        rays_full_screen_per_frame: mean(&|f| f.rays_full_screen),
        overflowed_buffers_per_frame: mean(&|f| f.overflowed_buffers),
        cycles_per_frame,
        frame_time: Vec::new(),
        traversal_ms_per_frame: ms(&|t| t.traversal()),
        golden_model_ms_per_frame: ms(&|t| t.golden_model),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(seconds: f64, variant_seconds: Vec<f64>) -> FrameCost {
        FrameCost {
            seconds,
            variant_seconds,
            ..FrameCost::default()
        }
    }

    #[test]
    fn the_band_is_over_each_variants_mean_not_each_frames_extremes() {
        // Two frames, two variants. Means in ms: machine (10 + 30) / 2 = 20; variant 0
        // (5 + 45) / 2 = 25; variant 1 (20 + 10) / 2 = 15. The band is 15..25, though single
        // frames reach 5 and 45.
        let frames = [
            frame(0.010, vec![0.005, 0.020]),
            frame(0.030, vec![0.045, 0.010]),
        ];
        let time = MachineFrameTime::of("m".into(), Vec::new(), &frames);
        let (low, high) = time.ms_per_frame_band.unwrap();
        assert!(
            (low - 15.0).abs() < 1e-9 && (high - 25.0).abs() < 1e-9,
            "{low}..{high}"
        );
        let at = &time.ms_per_frame_at_variants;
        assert!(
            (at[0] - 25.0).abs() < 1e-9 && (at[1] - 15.0).abs() < 1e-9,
            "{at:?}"
        );
        assert!((time.ms_per_frame - 20.0).abs() < 1e-9);
    }

    #[test]
    fn without_variants_there_is_no_band() {
        let time = MachineFrameTime::of("m".into(), Vec::new(), &[frame(0.010, Vec::new())]);
        assert_eq!(time.ms_per_frame_band, None);
    }
}
