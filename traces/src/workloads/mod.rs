//! Walkthrough workloads: parametric scenes, camera paths, and the culling drivers that
//! issue occlusion queries while the golden model answers them.
//!
//! A workload is a scene ([`WorkloadScene`]: objects in world space, a bounding volume
//! hierarchy over them and a default camera path), a walk ([`Walk`]: frames and viewport)
//! and a driver ([`DriverOptions`]): the culling algorithm that decides, frame by frame,
//! which objects to draw. [`generate`] runs the driver; its commands go through the golden
//! model, whose events (the fragment stream a trace records) go to the caller's sink.
//!
//! Every frame's events are self-contained: the frame begins with exactly one `Clear`
//! followed by the whole render state, so a consumer can split a stream into frames at
//! `Clear` events.
//!
//! Drivers (seeds 000 and 001 of the project):
//! - `frustum`: view-frustum culling through the hierarchy; no queries (the baseline).
//! - `hierarchical`: occlusion-driven rendering (Bartz et al. 1998, section 3): the hierarchy
//!   traversed front to back, each node's box drawn in brief mode, geometry drawn only for
//!   leaves whose box has visible pixels.
//! - `lazy-grid`, `busy-grid`: the lazy occlusion grid (Hey et al.), z-buffer variant, in
//!   query form (see `grid.rs`).
//!
//! Drivers of seeds 002 to 004:
//! - `hom`: hierarchical occlusion maps (Zhang et al.), the map read by queries (`hom.rs`).
//! - `large-occluders`: supporting and separating planes of large occluders (Coorg and
//!   Teller), object space on the host, no queries (`large.rs`).
//! - `dynamic-grid`: a regular grid for dynamic scenes (Batagelo and Wu), its potentially
//!   visible set confirmed by brief box queries (`dynamic_grid.rs`); the `traffic` scene's
//!   cars move every frame (`traffic.rs`).
//! - `raycast`: the raycasting support of seed 001 section 5: verbose hit lists of a
//!   volume's bricks choose the pixels rays are cast through (`raycast.rs`).

mod bvh;
mod camera;
mod collision;
pub mod compare;
mod drivers;
mod dynamic_grid;
mod grid;
mod hierarchical;
mod hom;
mod large;
mod obj;
mod occlusion_buffer_grid;
mod oracle;
mod project;
mod raycast;
mod render;
mod scenes;
mod traffic;

pub use camera::{CameraKeyframe, CameraPath};
pub use collision::{collision_oracle, CollisionTest};
pub use obj::{load_obj, ObjOptions};
pub use oracle::full_render_visible_pixels;
pub use render::CommandObserver;
pub use scenes::{
    city, forest, CityOptions, ForestOptions, MAX_CITY_BLOCKS, MAX_CITY_DETAIL, MAX_CONE_SIDES,
    MAX_TREES,
};
pub use traffic::{traffic, TrafficOptions, MAX_CARS_PER_BLOCK};

use crate::geometry::{look_at, perspective_gl, Aabb};
use crate::golden::EventSink;
use crate::hit_list::LISTED_HITS_PER_QUERY;
use crate::query::{BRIEF_RECORD_ENTRIES, MAX_TILES};
use crate::raster::RasterProfile;
use crate::state::MAX_VIEWPORT_SIDE;
use bvh::Bvh;
use glam::{Mat4, Vec3};
use std::borrow::Cow;
use std::time::Duration;
pub(crate) use traffic::Motion;

/// A workload that cannot be made, with what to change.
#[derive(Debug, thiserror::Error)]
pub enum WorkloadError {
    /// An option out of range or not applicable: the option, then what is wrong with it
    /// (the command line names the option by its flag, [`WorkloadOption::name`] otherwise).
    #[error("{} {detail}", option.name())]
    Option {
        option: WorkloadOption,
        detail: String,
    },
    #[error("unknown driver `{0}`: expected one of {names}", names = DriverKind::names())]
    UnknownDriver(String),
    #[error("{file}:{line}: {message}")]
    Obj {
        file: String,
        line: u64,
        message: String,
    },
    /// What the model holds, found once it is read (no one line says it).
    #[error("{file}: {message}")]
    ObjModel { file: String, message: String },
    #[error("{file}: {message}")]
    Camera { file: String, message: String },
    #[error(transparent)]
    ViewportBuffer(#[from] crate::golden::ViewportBufferTooLarge),
}

/// The options of a walkthrough and its driver that can be out of range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WorkloadOption {
    Frames,
    Width,
    Height,
    QueryDelay,
    QuadtreeLevels,
    AdaptiveThreshold,
    GridCellPixels,
    GridVariant,
    CollisionTiles,
    CollisionStep,
    VirtualOcclusionBuffer,
    OcclusionMapCellPixels,
    OpacityThreshold,
    OccluderTriangles,
    GridResolution,
    FlatGrid,
    VolumeBricks,
    VerboseBuffer,
}

impl WorkloadOption {
    /// The option's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            WorkloadOption::Frames => "frames",
            WorkloadOption::Width => "width",
            WorkloadOption::Height => "height",
            WorkloadOption::QueryDelay => "query delay",
            WorkloadOption::QuadtreeLevels => "quadtree levels",
            WorkloadOption::AdaptiveThreshold => "adaptive threshold",
            WorkloadOption::GridCellPixels => "grid cell pixels",
            WorkloadOption::GridVariant => "grid variant",
            WorkloadOption::CollisionTiles => "collision tiles",
            WorkloadOption::CollisionStep => "collision step",
            WorkloadOption::VirtualOcclusionBuffer => "virtual occlusion buffer",
            WorkloadOption::OcclusionMapCellPixels => "occlusion map cell pixels",
            WorkloadOption::OpacityThreshold => "opacity threshold",
            WorkloadOption::OccluderTriangles => "occluder triangles",
            WorkloadOption::GridResolution => "grid resolution",
            WorkloadOption::FlatGrid => "flat grid",
            WorkloadOption::VolumeBricks => "volume bricks",
            WorkloadOption::VerboseBuffer => "verbose buffer",
        }
    }
}

/// One object of a scene: its triangles (counter-clockwise seen from outside, world space,
/// metres), their bounding box, and boxes known to lie inside its solid interior.
#[derive(Clone)]
pub(crate) struct SceneObject {
    pub(crate) triangles: Vec<[Vec3; 3]>,
    pub(crate) bounds: Aabb,
    /// Axis-aligned boxes wholly inside the object's closed surface (a building's body, a
    /// car's body): what the dynamic grid may call opaque. Empty when not known.
    pub(crate) solids: Vec<Aabb>,
}

impl SceneObject {
    /// None when there are no triangles.
    pub(crate) fn new(triangles: Vec<[Vec3; 3]>) -> Option<SceneObject> {
        let bounds = Aabb::around(triangles.iter().flatten().copied())?;
        Some(SceneObject {
            triangles,
            bounds,
            solids: Vec::new(),
        })
    }

    /// The object with `solids` (each inside its closed surface) declared.
    pub(crate) fn with_solids(mut self, solids: Vec<Aabb>) -> SceneObject {
        self.solids = solids;
        self
    }
}

/// A scene ready to walk through: objects, their hierarchy and a camera path.
#[derive(Clone)]
pub struct WorkloadScene {
    /// The scene's name, for reports (`city`, `forest`, or the OBJ file).
    pub name: String,
    objects: Vec<SceneObject>,
    bvh: Bvh,
    bounds: Aabb,
    camera: CameraPath,
    /// Vertical field of view in degrees.
    pub fov_y_degrees: f32,
    /// How far query boxes are grown beyond the bounds they test, in metres: keeps a box's
    /// depth in front of its contents' by more than depth rounding, so box tests stay
    /// conservative.
    pub box_margin: f32,
    /// Per object, how it moves (empty for a static scene): the objects hold frame 0.
    motions: Vec<Option<Motion>>,
    /// The volume a ray caster renders among the polygons (the raycast driver).
    volume: Aabb,
}

/// Fraction of the scene's diagonal query boxes grow by (see `box_margin`).
const BOX_MARGIN_PER_DIAGONAL: f32 = 5e-4;
/// Far clip distance over near clip distance (24-bit depth stays fine-grained enough).
const FAR_OVER_NEAR: f32 = 1500.0;

impl WorkloadScene {
    /// None when there is no object.
    pub(crate) fn new(
        name: impl Into<String>,
        objects: Vec<SceneObject>,
        camera: CameraPath,
    ) -> Option<WorkloadScene> {
        let bounds = objects.iter().map(|o| o.bounds).reduce(Aabb::union)?;
        let bvh = Bvh::build(&objects);
        // The volume: the middle of the scene, half its extent along each axis.
        let quarter = (bounds.max - bounds.min) * 0.25;
        Some(WorkloadScene {
            name: name.into(),
            objects,
            bvh,
            bounds,
            camera,
            fov_y_degrees: 60.0,
            box_margin: (bounds.max - bounds.min).length() * BOX_MARGIN_PER_DIAGONAL,
            motions: Vec::new(),
            volume: Aabb {
                min: bounds.centre() - quarter,
                max: bounds.centre() + quarter,
            },
        })
    }

    /// The same scene with objects that move: `motions[i]` for object `i` (None: static).
    /// The objects must hold their frame-0 poses, and every pose must stay inside the
    /// scene's bounds.
    pub(crate) fn with_motions(mut self, motions: Vec<Option<Motion>>) -> WorkloadScene {
        self.motions = motions;
        self
    }

    /// Does any object move?
    pub fn is_dynamic(&self) -> bool {
        self.motions.iter().any(Option::is_some)
    }

    /// How object `object` moves (None: it stands still).
    pub(crate) fn motion(&self, object: u32) -> Option<&Motion> {
        self.motions.get(object as usize)?.as_ref()
    }

    /// The scene as it stands at `frame`: itself when nothing moves; otherwise every moving
    /// object in its pose of that frame and the hierarchy rebuilt over them.
    pub(crate) fn posed(&self, frame: u32) -> Cow<'_, WorkloadScene> {
        if !self.is_dynamic() {
            return Cow::Borrowed(self);
        }
        let objects: Vec<SceneObject> = self
            .objects
            .iter()
            .zip(&self.motions)
            .map(|(object, motion)| match motion {
                Some(motion) => motion.pose(frame),
                None => object.clone(),
            })
            .collect();
        Cow::Owned(WorkloadScene {
            name: self.name.clone(),
            bvh: Bvh::build(&objects),
            objects,
            bounds: self.bounds,
            camera: self.camera.clone(),
            fov_y_degrees: self.fov_y_degrees,
            box_margin: self.box_margin,
            motions: Vec::new(),
            volume: self.volume,
        })
    }

    /// The same scene walked along another camera path.
    pub fn with_camera(mut self, camera: CameraPath) -> WorkloadScene {
        self.camera = camera;
        self
    }

    pub fn camera(&self) -> &CameraPath {
        &self.camera
    }

    pub fn object_count(&self) -> usize {
        self.objects.len()
    }

    pub fn triangle_count(&self) -> u64 {
        self.objects.iter().map(|o| o.triangles.len() as u64).sum()
    }

    /// Triangles of each object, in object order.
    pub fn object_triangle_counts(&self) -> Vec<u64> {
        self.objects
            .iter()
            .map(|o| o.triangles.len() as u64)
            .collect()
    }

    /// The centre of the scene's bounding box (world space, metres).
    pub fn centre(&self) -> [f32; 3] {
        self.bounds.centre().to_array()
    }

    /// Near and far clip distances for the camera path, in metres: far reaches the scene's
    /// farthest corner from any keyframe.
    fn clip_range(&self) -> (f32, f32) {
        let corners = self.bounds.corners();
        let far = self
            .camera
            .keyframes()
            .iter()
            .flat_map(|k| corners.map(|c| (c - Vec3::from(k.eye)).length()))
            .fold(1.0f32, f32::max)
            * 1.05;
        (far / FAR_OVER_NEAR, far)
    }

    /// The camera of `frame` out of `frames`.
    pub(crate) fn frame_view(&self, frame: u32, walk: &Walk) -> FrameView {
        let (eye, target) = self.camera.eye_and_target(frame, walk.frames);
        let (near, far) = self.clip_range();
        let aspect = walk.width as f32 / walk.height as f32;
        let projection = perspective_gl(self.fov_y_degrees.to_radians(), aspect, near, far);
        let forward = (target - eye).normalize_or(Vec3::NEG_Z);
        // Looking straight up or down: any other up vector will do.
        let up = if forward.cross(Vec3::Y).length_squared() < 1e-6 {
            Vec3::Z
        } else {
            Vec3::Y
        };
        let view_projection = projection * look_at(eye, eye + forward, up);
        FrameView {
            view_projection,
            eye,
            near,
            width: walk.width,
            height: walk.height,
        }
    }
}

/// One frame's camera.
pub(crate) struct FrameView {
    pub(crate) view_projection: Mat4,
    pub(crate) eye: Vec3,
    /// Near clip distance in metres.
    pub(crate) near: f32,
    pub(crate) width: u32,
    pub(crate) height: u32,
}

/// The grids' cell side in pixels, where none is given (the lazy-grid and busy-grid
/// drivers').
pub const DEFAULT_GRID_CELL_PIXELS: u32 = 32;

/// Tiles a side of the collision driver's check area, where none is given.
pub const DEFAULT_COLLISION_TILES: u32 = 2;

/// Most frames a walkthrough may have: an hour at 30 frames a second, ten times over.
/// `culling compare` keeps each frame's statistics for its report (a few hundred bytes a
/// frame and driver), so its memory grows with the frames; a walk of 4 billion frames of a
/// small OBJ model had grown past 900 MB before its first frame was reported.
pub const MAX_WALK_FRAMES: u32 = 1_000_000;

/// The frames and viewport of a walkthrough.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Walk {
    /// Frames along the camera path (at least 1).
    pub frames: u32,
    /// Viewport width in pixels.
    pub width: u32,
    /// Viewport height in pixels.
    pub height: u32,
    /// The rasterizer's arithmetic.
    pub raster: RasterProfile,
}

impl Walk {
    /// Its frames and viewport within range (each error names its option).
    pub fn validate(&self) -> Result<(), WorkloadError> {
        if !(1..=MAX_WALK_FRAMES).contains(&self.frames) {
            return Err(WorkloadError::Option {
                option: WorkloadOption::Frames,
                detail: format!(
                    "{} out of range: a walkthrough has 1 to {MAX_WALK_FRAMES} frames",
                    self.frames
                ),
            });
        }
        for (option, side) in [
            (WorkloadOption::Width, self.width),
            (WorkloadOption::Height, self.height),
        ] {
            if side == 0 || side > MAX_VIEWPORT_SIDE {
                return Err(WorkloadError::Option {
                    option,
                    detail: format!(
                        "{side} out of range: expected 1 to {MAX_VIEWPORT_SIDE} pixels"
                    ),
                });
            }
        }
        Ok(())
    }
}

/// The culling algorithm.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DriverKind {
    /// View-frustum culling only.
    Frustum,
    /// Occlusion-driven rendering: a brief box query per hierarchy node.
    Hierarchical,
    /// Lazy occlusion grid, z-buffer variant, refreshed by brief probe queries.
    LazyGrid,
    /// The grid refreshed after every draw.
    BusyGrid,
    /// Occlusion-driven rendering, then a collision test along the heading: a customised
    /// view frustum in brief mode (seed 001, section 5).
    Collision,
    /// Hierarchical occlusion maps (seed 003).
    Hom,
    /// Large occluders' supporting and separating planes (seed 004).
    LargeOccluders,
    /// A regular grid for dynamic scenes (seed 002), its PVS confirmed by box queries.
    DynamicGrid,
    /// Occlusion-driven rendering, then a volume's bricks in verbose mode choose the pixels
    /// rays are cast through (seed 001, section 5).
    Raycast,
}

impl DriverKind {
    pub const ALL: [DriverKind; 9] = [
        DriverKind::Frustum,
        DriverKind::Hierarchical,
        DriverKind::LazyGrid,
        DriverKind::BusyGrid,
        DriverKind::Collision,
        DriverKind::Hom,
        DriverKind::LargeOccluders,
        DriverKind::DynamicGrid,
        DriverKind::Raycast,
    ];

    /// Every driver's name, for messages.
    pub fn names() -> String {
        let names: Vec<&str> = DriverKind::ALL.iter().map(|k| k.name()).collect();
        names.join(", ")
    }

    pub fn name(self) -> &'static str {
        match self {
            DriverKind::Frustum => "frustum",
            DriverKind::Hierarchical => "hierarchical",
            DriverKind::LazyGrid => "lazy-grid",
            DriverKind::BusyGrid => "busy-grid",
            DriverKind::Collision => "collision",
            DriverKind::Hom => "hom",
            DriverKind::LargeOccluders => "large-occluders",
            DriverKind::DynamicGrid => "dynamic-grid",
            DriverKind::Raycast => "raycast",
        }
    }
}

impl std::str::FromStr for DriverKind {
    type Err = WorkloadError;

    fn from_str(name: &str) -> Result<DriverKind, WorkloadError> {
        DriverKind::ALL
            .into_iter()
            .find(|k| k.name() == name)
            .ok_or_else(|| WorkloadError::UnknownDriver(name.to_owned()))
    }
}

/// What a grid cell knows of its pixels (seed 000, sections 3.1 and 3.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GridVariant {
    /// The farthest depth of its pixels, bounded by depth probes: boxes in any
    /// front-to-back order.
    ZBuffer,
    /// Whether its pixels are all drawn (one bit a pixel): boxes tested before anything
    /// not wholly in front of them is drawn.
    OcclusionBuffer,
}

impl GridVariant {
    pub const ALL: [GridVariant; 2] = [GridVariant::ZBuffer, GridVariant::OcclusionBuffer];

    pub fn name(self) -> &'static str {
        match self {
            GridVariant::ZBuffer => "z-buffer",
            GridVariant::OcclusionBuffer => "occlusion-buffer",
        }
    }
}

impl std::str::FromStr for GridVariant {
    type Err = WorkloadError;

    fn from_str(name: &str) -> Result<GridVariant, WorkloadError> {
        GridVariant::ALL
            .into_iter()
            .find(|v| v.name() == name)
            .ok_or_else(|| WorkloadError::Option {
                option: WorkloadOption::GridVariant,
                detail: format!(
                    "`{name}` is not a grid variant: expected z-buffer or occlusion-buffer"
                ),
            })
    }
}

/// Most quadtree levels below a hierarchical query's root tile (4 levels: 341 tiles).
pub const MAX_QUADTREE_LEVELS: u32 = 4;

/// How a driver culls.
#[derive(Clone, Debug, PartialEq)]
pub struct DriverOptions {
    pub kind: DriverKind,
    /// Frames between issuing a query and reading its answer: 0 (at once) or 1 (the next
    /// frame, as applications hide query latency; the first frame draws conservatively).
    /// Frustum and hierarchical only.
    pub query_delay_frames: u32,
    /// Hierarchical: quadtree levels of tiles below the box's whole-rectangle tile (0: one
    /// tile). Children lying wholly in tiles without hits are culled without a query.
    pub quadtree_levels: u32,
    /// Hierarchical: skip a node whose box has NOHC/PHC below this share (0 to 1]: adaptive,
    /// not conservative culling. None: skip only boxes without visible pixels.
    pub adaptive_threshold: Option<f32>,
    /// Grids: side of a grid cell in pixels.
    pub grid_cell_pixels: u32,
    /// Grids: what a cell keeps.
    pub grid_variant: GridVariant,
    /// Collision: the check area is cut into this many tiles a side.
    pub collision_tiles: u32,
    /// Collision: the step's length in metres (None: the distance to the next frame's eye).
    pub collision_step: Option<f32>,
    /// Hierarchical: test boxes the paper's earlier software way (its reference \[10\]): draw
    /// the box, then read the framebuffer back over the box's rectangle and search it for
    /// changed pixels on the host, instead of reading the Occlusion Unit's record.
    pub virtual_occlusion_buffer: bool,
    /// Hom: side of an occlusion-map pixel in screen pixels (the paper's 256x256 map of a
    /// 1024x1024 image: 4).
    pub occlusion_map_cell_pixels: u32,
    /// Hom: the opacity threshold T (level k of the pyramid: T^k); 1 is conservative
    /// culling, below 1 approximate culling.
    pub opacity_threshold: f32,
    /// Hom: the occluders' triangle budget a frame (None: a sixteenth of the scene's).
    pub occluder_triangles: Option<u64>,
    /// Dynamic grid: cells along the scene's longer horizontal side.
    pub dynamic_grid_resolution: u32,
    /// Dynamic grid: the paper's 2D case (columns through the scene's height) instead of
    /// its 3D extension (cubes).
    pub flat_grid: bool,
    /// Raycast: bricks along each side of the volume (its subdivision entities).
    pub volume_bricks: u32,
    /// Raycast: entries of each brick's verbose buffer (8 for the brief record, then one a
    /// hit; an overflowing buffer ends with -1).
    pub verbose_buffer_entries: u32,
}

/// The dynamic grid's default resolution, and its range.
pub const DEFAULT_GRID_RESOLUTION: u32 = 64;
const GRID_RESOLUTION_RANGE: std::ops::RangeInclusive<u32> = 4..=256;
/// The raycast's default bricks a side and verbose buffer (the brief record and 1,024 hits).
pub const DEFAULT_VOLUME_BRICKS: u32 = 4;
pub const DEFAULT_VERBOSE_BUFFER: u32 = BRIEF_RECORD_ENTRIES + 1024;
/// The largest verbose buffer a brick may have: every hit it holds is listed.
const MAX_VERBOSE_BUFFER: u32 = BRIEF_RECORD_ENTRIES + LISTED_HITS_PER_QUERY as u32;

impl DriverOptions {
    /// The driver's defaults: no delay, one tile, no threshold, 32-pixel cells.
    pub fn new(kind: DriverKind) -> DriverOptions {
        DriverOptions {
            kind,
            query_delay_frames: 0,
            quadtree_levels: 0,
            adaptive_threshold: None,
            grid_cell_pixels: DEFAULT_GRID_CELL_PIXELS,
            grid_variant: GridVariant::ZBuffer,
            collision_tiles: DEFAULT_COLLISION_TILES,
            collision_step: None,
            virtual_occlusion_buffer: false,
            occlusion_map_cell_pixels: 4,
            opacity_threshold: 1.0,
            occluder_triangles: None,
            dynamic_grid_resolution: DEFAULT_GRID_RESOLUTION,
            flat_grid: false,
            volume_bricks: DEFAULT_VOLUME_BRICKS,
            verbose_buffer_entries: DEFAULT_VERBOSE_BUFFER,
        }
    }

    /// A short label for reports, e.g. `hierarchical/q2/t0.05/d1`.
    pub fn label(&self) -> String {
        let mut label = self.kind.name().to_owned();
        if self.quadtree_levels > 0 {
            label += &format!("/q{}", self.quadtree_levels);
        }
        if let Some(t) = self.adaptive_threshold {
            label += &format!("/t{t}");
        }
        if self.virtual_occlusion_buffer {
            label += "/vob";
        }
        if self.query_delay_frames > 0 {
            label += &format!("/d{}", self.query_delay_frames);
        }
        if self.grid_cell_pixels != DEFAULT_GRID_CELL_PIXELS && self.is_grid() {
            label += &format!("/c{}", self.grid_cell_pixels);
        }
        if self.grid_variant == GridVariant::OcclusionBuffer {
            label += "/obuf";
        }
        if self.kind == DriverKind::Hom {
            if self.opacity_threshold < 1.0 {
                label += &format!("/o{}", self.opacity_threshold);
            }
            if self.occlusion_map_cell_pixels != 4 {
                label += &format!("/c{}", self.occlusion_map_cell_pixels);
            }
            if let Some(l) = self.occluder_triangles {
                label += &format!("/l{l}");
            }
        }
        if self.dynamic_grid_resolution != DEFAULT_GRID_RESOLUTION {
            label += &format!("/r{}", self.dynamic_grid_resolution);
        }
        if self.flat_grid {
            label += "/2d";
        }
        if self.volume_bricks != DEFAULT_VOLUME_BRICKS {
            label += &format!("/b{}", self.volume_bricks);
        }
        if self.verbose_buffer_entries != DEFAULT_VERBOSE_BUFFER {
            label += &format!("/v{}", self.verbose_buffer_entries);
        }
        label
    }

    fn is_grid(&self) -> bool {
        matches!(self.kind, DriverKind::LazyGrid | DriverKind::BusyGrid)
    }

    /// Whether the driver draws every object with a visible pixel (tests/workloads.rs
    /// checks the ones that say so): all but an adaptive threshold, a query delay and
    /// hom's approximate culling (an opacity threshold below 1).
    pub fn is_conservative(&self) -> bool {
        self.adaptive_threshold.is_none()
            && self.query_delay_frames == 0
            && self.opacity_threshold >= 1.0
    }

    pub fn validate(&self) -> Result<(), WorkloadError> {
        let fail = |option, detail: String| Err(WorkloadError::Option { option, detail });
        let hierarchical = self.kind == DriverKind::Hierarchical;
        if self.query_delay_frames > 1 {
            return fail(
                WorkloadOption::QueryDelay,
                format!(
                    "{}: expected 0 (read answers at once) or 1 (a frame later)",
                    self.query_delay_frames
                ),
            );
        }
        if self.query_delay_frames > 0 && self.kind == DriverKind::Collision {
            return fail(
                WorkloadOption::QueryDelay,
                "applies to the frustum and hierarchical drivers: a collision must be known before the step".into(),
            );
        }
        if self.query_delay_frames > 0 && self.is_grid() {
            return fail(
                WorkloadOption::QueryDelay,
                format!(
                    "applies to the frustum and hierarchical drivers: the {} driver reads its cell refreshes at once",
                    self.kind.name()
                ),
            );
        }
        if self.quadtree_levels > MAX_QUADTREE_LEVELS {
            return fail(
                WorkloadOption::QuadtreeLevels,
                format!(
                    "{} out of range: expected 0 to {MAX_QUADTREE_LEVELS}",
                    self.quadtree_levels
                ),
            );
        }
        if self.quadtree_levels > 0 && !hierarchical {
            return fail(
                WorkloadOption::QuadtreeLevels,
                "applies to the hierarchical driver only".into(),
            );
        }
        if let Some(t) = self.adaptive_threshold {
            if !(t > 0.0 && t <= 1.0) {
                return fail(
                    WorkloadOption::AdaptiveThreshold,
                    format!("{t} out of range: expected a share above 0 and at most 1"),
                );
            }
            if !hierarchical {
                return fail(
                    WorkloadOption::AdaptiveThreshold,
                    "applies to the hierarchical driver only".into(),
                );
            }
        }
        if self.virtual_occlusion_buffer && (!hierarchical || self.quadtree_levels > 0) {
            return fail(
                WorkloadOption::VirtualOcclusionBuffer,
                "applies to the hierarchical driver without quadtree levels (the host reads the box's whole rectangle)".into(),
            );
        }
        self.validate_seed_drivers()?;
        if !(4..=1024).contains(&self.grid_cell_pixels) {
            return fail(
                WorkloadOption::GridCellPixels,
                format!("{} out of range: expected 4 to 1024", self.grid_cell_pixels),
            );
        }
        if !(1..=16).contains(&self.collision_tiles) {
            return fail(
                WorkloadOption::CollisionTiles,
                format!("{} out of range: expected 1 to 16", self.collision_tiles),
            );
        }
        if let Some(step) = self.collision_step {
            if !(step.is_finite() && step > 0.0) {
                return fail(
                    WorkloadOption::CollisionStep,
                    format!("{step}: expected a length in metres above 0"),
                );
            }
        }
        if (self.grid_variant != GridVariant::ZBuffer
            || self.grid_cell_pixels != DEFAULT_GRID_CELL_PIXELS)
            && !self.is_grid()
        {
            let option = if self.grid_variant != GridVariant::ZBuffer {
                WorkloadOption::GridVariant
            } else {
                WorkloadOption::GridCellPixels
            };
            return fail(
                option,
                "applies to the lazy-grid and busy-grid drivers only".into(),
            );
        }
        let collision = self.kind == DriverKind::Collision;
        if !collision
            && (self.collision_tiles != DEFAULT_COLLISION_TILES || self.collision_step.is_some())
        {
            let option = if self.collision_step.is_some() {
                WorkloadOption::CollisionStep
            } else {
                WorkloadOption::CollisionTiles
            };
            return fail(option, "applies to the collision driver only".into());
        }
        Ok(())
    }
}

impl DriverOptions {
    /// The options of the drivers of seeds 002 to 004.
    fn validate_seed_drivers(&self) -> Result<(), WorkloadError> {
        let fail = |option, detail: String| Err(WorkloadError::Option { option, detail });
        let hom = self.kind == DriverKind::Hom;
        if !(1..=64).contains(&self.occlusion_map_cell_pixels) {
            return fail(
                WorkloadOption::OcclusionMapCellPixels,
                format!(
                    "{} out of range: expected 1 to 64",
                    self.occlusion_map_cell_pixels
                ),
            );
        }
        let t = self.opacity_threshold;
        if !(t > 0.0 && t <= 1.0) {
            return fail(
                WorkloadOption::OpacityThreshold,
                format!("{t} out of range: expected above 0 and at most 1"),
            );
        }
        if !hom && (t < 1.0 || self.occlusion_map_cell_pixels != 4) {
            let option = if t < 1.0 {
                WorkloadOption::OpacityThreshold
            } else {
                WorkloadOption::OcclusionMapCellPixels
            };
            return fail(option, "applies to the hom driver only".into());
        }
        if self.occluder_triangles.is_some() && !hom {
            return fail(
                WorkloadOption::OccluderTriangles,
                "applies to the hom driver only".into(),
            );
        }
        self.validate_dynamic_and_raycast()?;
        if matches!(
            self.kind,
            DriverKind::Hom
                | DriverKind::LargeOccluders
                | DriverKind::DynamicGrid
                | DriverKind::Raycast
        ) && self.query_delay_frames > 0
        {
            return fail(
                WorkloadOption::QueryDelay,
                format!(
                    "applies to the frustum and hierarchical drivers: the {} driver decides at once",
                    self.kind.name()
                ),
            );
        }
        Ok(())
    }
}

impl DriverOptions {
    /// The options of the dynamic-grid and raycast drivers.
    fn validate_dynamic_and_raycast(&self) -> Result<(), WorkloadError> {
        let fail = |option, detail: String| Err(WorkloadError::Option { option, detail });
        let grid = self.kind == DriverKind::DynamicGrid;
        let raycast = self.kind == DriverKind::Raycast;
        let r = self.dynamic_grid_resolution;
        if !GRID_RESOLUTION_RANGE.contains(&r) {
            return fail(
                WorkloadOption::GridResolution,
                format!("{r} out of range: expected 4 to 256 cells"),
            );
        }
        if !grid && (r != DEFAULT_GRID_RESOLUTION || self.flat_grid) {
            let option = if self.flat_grid {
                WorkloadOption::FlatGrid
            } else {
                WorkloadOption::GridResolution
            };
            return fail(option, "applies to the dynamic-grid driver only".into());
        }
        let b = self.volume_bricks;
        if !(1..=16).contains(&b) {
            return fail(
                WorkloadOption::VolumeBricks,
                format!("{b} out of range: expected 1 to 16 a side"),
            );
        }
        let v = self.verbose_buffer_entries;
        if !(BRIEF_RECORD_ENTRIES..=MAX_VERBOSE_BUFFER).contains(&v) {
            return fail(
                WorkloadOption::VerboseBuffer,
                format!(
                    "{v} out of range: expected {BRIEF_RECORD_ENTRIES} (the brief record) to {MAX_VERBOSE_BUFFER} entries"
                ),
            );
        }
        if !raycast && (b != DEFAULT_VOLUME_BRICKS || v != DEFAULT_VERBOSE_BUFFER) {
            let option = if b != DEFAULT_VOLUME_BRICKS {
                WorkloadOption::VolumeBricks
            } else {
                WorkloadOption::VerboseBuffer
            };
            return fail(option, "applies to the raycast driver only".into());
        }
        Ok(())
    }
}

/// What one frame cost the driver. Deterministic: equal for equal inputs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameStats {
    /// Scene triangles drawn (sent as geometry, before back-face culling).
    pub triangles_drawn: u64,
    /// Indices of the objects drawn, in drawing order.
    pub objects_drawn: Vec<u32>,
    /// Fragments of drawn geometry.
    pub draw_fragments: u64,
    /// Occlusion queries issued (brief mode).
    pub queries: u64,
    /// Tiles over all queries.
    pub query_tiles: u64,
    /// Triangles drawn inside occlusion queries (boxes, probe quads).
    pub query_triangles: u64,
    /// Fragments drawn inside occlusion queries (each once, however many tiles hold it).
    pub query_fragments: u64,
    /// Grids: outdated cells (drawn into since their last probe) refreshed by a probe.
    pub cells_refreshed: u64,
    /// Hierarchy nodes taken from the traversal queue.
    pub nodes_visited: u64,
    /// Collision: the frame's test (None when its heading could not be tested).
    pub collision: Option<CollisionTest>,
    /// Hierarchical: nodes culled by their parent's quadtree tiles, without a query.
    pub culled_by_parent_tiles: u64,
    /// Comparisons the host makes without a query: occlusion-map pixels and depth-estimation
    /// entries (hom), plane tests (large-occluders), cell marks (dynamic-grid).
    pub host_tests: u64,
    /// Raycast: rays cast (distinct pixels), and the rays a cast through every pixel of the
    /// viewport needs.
    pub rays_cast: u64,
    pub rays_full_screen: u64,
    /// Raycast: bricks whose verbose buffer overflowed (their rays cast through the box of
    /// their hits instead).
    pub overflowed_buffers: u64,
}

/// Wall time of one frame; not deterministic, kept apart from [`FrameStats`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameTiming {
    /// The whole frame: traversal and golden model.
    pub total: Duration,
    /// Inside the golden model (rasterizing, depth testing, counting).
    pub golden_model: Duration,
}

impl FrameTiming {
    /// The traversal itself: the frame less the golden model.
    pub fn traversal(&self) -> Duration {
        self.total.saturating_sub(self.golden_model)
    }
}

/// What a walkthrough cost, frame by frame.
#[derive(Clone, Debug, Default)]
pub struct WorkloadStats {
    pub frames: Vec<FrameStats>,
    pub timing: Vec<FrameTiming>,
    /// Triangles in the whole scene.
    pub scene_triangles: u64,
}

/// Why a walkthrough stopped: its options, or the sink its events went to.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError<E> {
    #[error(transparent)]
    Workload(#[from] WorkloadError),
    #[error(transparent)]
    Sink(E),
}

impl GenerateError<std::convert::Infallible> {
    /// The options' error, when the sink cannot fail.
    pub fn into_workload(self) -> WorkloadError {
        match self {
            GenerateError::Workload(error) => error,
            GenerateError::Sink(never) => match never {},
        }
    }
}

/// Walk `scene` with `driver`, sending the golden model's events to `sink`.
pub fn generate<S: EventSink>(
    scene: &WorkloadScene,
    driver: &DriverOptions,
    walk: &Walk,
    sink: &mut S,
) -> Result<WorkloadStats, GenerateError<S::Error>> {
    generate_observed(scene, driver, walk, sink, &mut ())
}

/// [`generate`], also showing every scene command to `commands` as it is executed (to
/// replay the same frames through `occsim count`, or to write them as scene text).
pub fn generate_observed<S: EventSink>(
    scene: &WorkloadScene,
    driver: &DriverOptions,
    walk: &Walk,
    sink: &mut S,
    commands: &mut impl CommandObserver,
) -> Result<WorkloadStats, GenerateError<S::Error>> {
    walk.validate()?;
    driver.validate()?;
    check_grid_size(driver, walk)?;
    let buffers =
        drivers::ViewportBuffers::for_walk(walk, driver.kind).map_err(WorkloadError::from)?;
    drivers::run(scene, driver, walk, buffers, sink, commands).map_err(GenerateError::Sink)
}

/// One probe query may name every cell, so a grid may hold at most `MAX_TILES` cells.
fn check_grid_size(driver: &DriverOptions, walk: &Walk) -> Result<(), WorkloadError> {
    if !driver.is_grid() {
        return Ok(());
    }
    let side = driver.grid_cell_pixels as u64;
    let (columns, rows) = (
        (walk.width as u64).div_ceil(side),
        (walk.height as u64).div_ceil(side),
    );
    if columns * rows > MAX_TILES as u64 {
        return Err(WorkloadError::Option {
            option: WorkloadOption::GridCellPixels,
            detail: format!(
                "{side} makes a {columns}x{rows} grid, more than {MAX_TILES} cells (the most tiles one query holds): use larger cells"
            ),
        });
    }
    Ok(())
}
