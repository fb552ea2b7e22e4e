//! Occlusion culling of a dynamic scene on a regular grid (Batagelo and Wu; seed 002), in
//! the 3D extension its section 6 sketches, or its own 2D case (`flat`).
//!
//! The grid's cells are cubes (3D) or columns through the scene's whole height (2D), over
//! the scene's bounds, `resolution` cells along its longer horizontal side. It keeps the
//! paper's matrices: O (opaque cells), H (occluded cells, found lazily and memoised), I
//! (objects spanning each cell, static ones discretised once) and T (temporal bounding
//! volumes), and O_s (static opaque cells, section 4.5). Every frame:
//! 1. Scene discretisation (4.1): moving objects drawn last frame are discretised into O and
//!    I; the others keep or get a temporal bounding volume (TBV) in T, whose validity period
//!    adapts (doubles when one expires unseen, halves when one is revealed).
//! 2. View-frustum traversal (4.2): cells meeting the view frustum in shells of equal chess
//!    distance from the eye's cell, nearest first; a cell not occluded adds the objects of
//!    its I list to the potentially visible set (PVS) and reveals its TBVs (their objects
//!    are discretised at once); the traversal ends at a shell with no cell left visible.
//! 3. Occluder extension (4.3): a visible opaque cell grows, along the two axes across its
//!    direction from the eye, by whole rows of opaque or occluded cells (occluder fusion),
//!    into a rectangle of cells; it is kept when its solid-angle estimate a / |d|^2 (Coorg
//!    and Teller's, with n . v = 1 as the paper takes it) reaches `MIN_SOLID_ANGLE`.
//! 4. Occlusion computation (4.4): a cell is occluded when it lies in the shadow of a kept
//!    occluder.
//!
//! The hardware's part: the PVS, in the order the traversal found it (near to far), is
//! drawn with a brief occlusion query of each object's box first (one tile, its
//! rectangle), so an object the grid could not cull but the depth buffer hides is not
//! drawn; the objects drawn are the PVS the next frame's discretisation uses.
//!
//! Choices where the paper is silent or sketchy, and what is done here:
//! - Discretisation (the paper's fast method, 4.1): an object's footprint on the ground
//!   plane is rasterised with its edges moved out by half a cell's diagonal (the cells it
//!   spans, I) or in by it (the cells wholly inside, O), sampled at cell centres
//!   ([`discretise_polygon`]). Footprints are the object's box (I) and its declared solids
//!   (O, [`SceneObject::solids`]); as every solid here is a vertical prism, the paper's
//!   three orthographic projections reduce to the footprint and the exact height range.
//!   A cell is opaque when the height ranges of the solids whose footprints cover it cover
//!   its own (so in 2D a column is opaque only where solids fill the scene's whole
//!   height: conservative where the flatland assumption does not hold, as in a city).
//! - Shadows (4.4): instead of rasterising a shadow polygon from the eye's cell, a cell is
//!   occluded when the segment from the eye to each of its eight corners passes through
//!   the occluder's box (shrunk by a thousandth of a cell): the set of points an occluder
//!   hides from a point is convex, so its corners decide, and the eye is known exactly.
//! - Traversal (4.2): each shell's cells are enumerated directly rather than walked from
//!   Bresenham seed cells along the line of sight; the order (chess distance) and the early
//!   end are the paper's. Cells are tested against the view frustum's side and far planes
//!   only, so a ray is followed from the eye itself.
//! - TBVs (4.1): spheres (3D) or circles (2D) of the object's box's half-diagonal plus its
//!   speed times the validity period; T holds every cell meeting the sphere's surface (the
//!   paper's empty circle, made exact, so no ray can slip between its cells: its footnote
//!   2). A TBV never comes within the near distance plus a cell's diagonal of the eye: one
//!   that would is made shorter-lived, one that comes so close later is revealed, and an
//!   object whose TBV cannot keep away is discretised instead. The period starts at
//!   `FIRST_PERIOD` frames and stays within 1..=`MAX_PERIOD`; a TBV's radius is at most
//!   `MAX_TBV_CELLS` cells (the paper's cap on TBV size). With the eye outside the grid no
//!   TBV is used.
//! - A revealed object's cells already passed are checked: if one was visible, the object
//!   joins the PVS at once (the paper discretises it for the rest of the traversal only).
//! - Host costs: every cell visited, discretised or tested against an occluder's shadow is
//!   a host test.

use super::project::{project_box, BoxView, Frustum};
use super::render::{CommandObserver, Renderer};
use super::{DriverOptions, FrameView, SceneObject, WorkloadScene};
use crate::geometry::{to_clip, Aabb};
use crate::golden::EventSink;
use glam::{DVec3, Vec3};

/// Least solid-angle estimate (steradians, a / |d|^2) of an occluder worth its shadow.
const MIN_SOLID_ANGLE: f64 = 0.01;
/// A moving object's first TBV validity period, in frames, and the longest.
const FIRST_PERIOD: u32 = 4;
const MAX_PERIOD: u32 = 64;
/// Largest TBV radius, in cells.
const MAX_TBV_CELLS: f32 = 8.0;

/// Cell coordinates: x, y (layer), z.
type Cell = [u32; 3];

/// The regular grid's geometry.
#[derive(Clone, Debug)]
pub(crate) struct Grid {
    origin: Vec3,
    /// Side of a cell in x and z, metres.
    side: f32,
    /// Height of a layer (the side in 3D; the scene's height in 2D).
    layer: f32,
    dims: Cell,
    flat: bool,
}

impl Grid {
    pub(crate) fn new(bounds: &Aabb, resolution: u32, flat: bool) -> Grid {
        let extent = bounds.max - bounds.min;
        let side = extent.x.max(extent.z).max(1e-3) / resolution as f32;
        let count = |length: f32| ((length / side).ceil() as u32).max(1);
        let (layers, layer) = if flat {
            (1, extent.y.max(1e-3))
        } else {
            (count(extent.y), side)
        };
        Grid {
            origin: bounds.min,
            side,
            layer,
            dims: [count(extent.x), layers, count(extent.z)],
            flat,
        }
    }

    fn cells(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    fn columns(&self) -> usize {
        self.dims[0] as usize * self.dims[2] as usize
    }

    fn index(&self, [x, y, z]: Cell) -> usize {
        (y as usize * self.dims[2] as usize + z as usize) * self.dims[0] as usize + x as usize
    }

    fn column(&self, [x, _, z]: Cell) -> usize {
        z as usize * self.dims[0] as usize + x as usize
    }

    fn cell_box(&self, [x, y, z]: Cell) -> Aabb {
        let min = self.origin
            + Vec3::new(
                x as f32 * self.side,
                y as f32 * self.layer,
                z as f32 * self.side,
            );
        Aabb {
            min,
            max: min + Vec3::new(self.side, self.layer, self.side),
        }
    }

    /// The cell holding `p`, clamped into the grid, and whether `p` lies inside it.
    fn locate(&self, p: Vec3) -> (Cell, bool) {
        let local = p - self.origin;
        let steps = [
            local.x / self.side,
            local.y / self.layer,
            local.z / self.side,
        ];
        let mut inside = true;
        let cell = std::array::from_fn(|axis| {
            let step = steps[axis].floor();
            let last = self.dims[axis] - 1;
            if !(step >= 0.0 && step <= last as f32) {
                inside = false;
            }
            step.clamp(0.0, last as f32) as u32
        });
        (cell, inside)
    }

    /// Layers whose height range meets [y0, y1].
    fn layers(&self, y0: f32, y1: f32) -> std::ops::RangeInclusive<u32> {
        if self.flat {
            return 0..=0;
        }
        let (first, _) = self.locate(Vec3::new(self.origin.x, y0, self.origin.z));
        let (last, _) = self.locate(Vec3::new(self.origin.x, y1, self.origin.z));
        first[1]..=last[1]
    }

    /// A cell's diagonal in the metric TBVs use (2D: on the ground plane).
    fn diagonal(&self) -> f32 {
        if self.flat {
            self.side * std::f32::consts::SQRT_2
        } else {
            self.side * 3f32.sqrt()
        }
    }

    /// Distance in the metric TBVs use: on the ground plane in 2D (circles), in space in 3D.
    fn distance(&self, a: Vec3, b: Vec3) -> f32 {
        let d = a - b;
        if self.flat {
            d.x.hypot(d.z)
        } else {
            d.length()
        }
    }

    /// Nearest and farthest distance from `centre` to the cell, in the TBVs' metric.
    fn distance_range(&self, cell: Cell, centre: Vec3) -> (f32, f32) {
        let b = self.cell_box(cell);
        let nearest = centre.clamp(b.min, b.max);
        let farthest = Vec3::select((centre - b.min).cmpgt(b.max - centre), b.min, b.max);
        (
            self.distance(centre, nearest),
            self.distance(centre, farthest),
        )
    }
}

/// Cells on the ground plane (column x, column z) a convex polygon spans and fills.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct Footprint {
    /// Every cell the polygon may touch (an over-estimate).
    pub(crate) spanned: Vec<(u32, u32)>,
    /// Cells wholly inside the polygon (an under-estimate).
    pub(crate) opaque: Vec<(u32, u32)>,
}

/// The paper's fast conservative discretisation (section 4.1, after Wonka et al.): the
/// convex `polygon` (x, z vertices in order, either winding) with every edge moved out
/// (spanned) or in (opaque) along its normal by half a cell's diagonal, `side / sqrt 2`,
/// sampled at the centres of the `columns` x `rows` cells of side `side` from `origin`.
/// A centre within that distance of the polygon has its whole cell touching it; a centre
/// that far inside has its whole cell inside.
pub(crate) fn discretise_polygon(
    polygon: &[(f64, f64)],
    origin: (f64, f64),
    side: f64,
    (columns, rows): (u32, u32),
) -> Footprint {
    let mut footprint = Footprint::default();
    let n = polygon.len();
    if n < 3 {
        return footprint;
    }
    let twice_area: f64 = (0..n)
        .map(|i| {
            let (a, b) = (polygon[i], polygon[(i + 1) % n]);
            a.0 * b.1 - b.0 * a.1
        })
        .sum();
    let winding = if twice_area >= 0.0 { 1.0 } else { -1.0 };
    let epsilon = side / std::f64::consts::SQRT_2;
    // The signed distance of a point inside from the nearest edge line (positive inside).
    let depth = |p: (f64, f64)| {
        (0..n)
            .map(|i| {
                let (a, b) = (polygon[i], polygon[(i + 1) % n]);
                let edge = (b.0 - a.0, b.1 - a.1);
                let length = edge.0.hypot(edge.1);
                let cross = edge.0 * (p.1 - a.1) - edge.1 * (p.0 - a.0);
                if length > 0.0 {
                    winding * cross / length
                } else {
                    f64::INFINITY
                }
            })
            .fold(f64::INFINITY, f64::min)
    };
    let lo = polygon
        .iter()
        .fold((f64::MAX, f64::MAX), |m, p| (m.0.min(p.0), m.1.min(p.1)));
    let hi = polygon
        .iter()
        .fold((f64::MIN, f64::MIN), |m, p| (m.0.max(p.0), m.1.max(p.1)));
    let cells = |low: f64, high: f64, start: f64, count: u32| {
        let first = ((low - epsilon - start) / side).floor().max(0.0);
        let last = ((high + epsilon - start) / side).ceil().min(count as f64);
        first as u32..last.max(first) as u32
    };
    for row in cells(lo.1, hi.1, origin.1, rows) {
        for column in cells(lo.0, hi.0, origin.0, columns) {
            let centre = (
                origin.0 + (column as f64 + 0.5) * side,
                origin.1 + (row as f64 + 0.5) * side,
            );
            let d = depth(centre);
            if d >= -epsilon {
                footprint.spanned.push((column, row));
            }
            if d >= epsilon {
                footprint.opaque.push((column, row));
            }
        }
    }
    footprint
}

/// A box's footprint on the ground plane, counter-clockwise seen from above.
fn ground_rectangle(b: &Aabb) -> [(f64, f64); 4] {
    let (x0, z0, x1, z1) = (
        b.min.x as f64,
        b.min.z as f64,
        b.max.x as f64,
        b.max.z as f64,
    );
    [(x0, z0), (x0, z1), (x1, z1), (x1, z0)]
}

/// Does the segment from `from` to `to` pass through `b`? (The slab test.)
fn segment_meets_box(from: DVec3, to: DVec3, b: &Aabb) -> bool {
    let (min, max) = (b.min.as_dvec3(), b.max.as_dvec3());
    let direction = to - from;
    let (mut enter, mut leave) = (0.0f64, 1.0f64);
    for axis in 0..3 {
        let (o, d) = (from[axis], direction[axis]);
        if d == 0.0 {
            if o < min[axis] || o > max[axis] {
                return false;
            }
            continue;
        }
        let (t0, t1) = ((min[axis] - o) / d, (max[axis] - o) / d);
        enter = enter.max(t0.min(t1));
        leave = leave.min(t0.max(t1));
        if enter > leave {
            return false;
        }
    }
    true
}

/// Is every point of `cell` hidden from `eye` by the convex `occluder`? The points an
/// occluder hides from a point form a convex set, so the cell's corners decide.
pub(crate) fn in_shadow(eye: Vec3, occluder: &Aabb, cell: &Aabb) -> bool {
    let eye = eye.as_dvec3();
    cell.corners()
        .iter()
        .all(|c| segment_meets_box(eye, c.as_dvec3(), occluder))
}

/// Bins a side the screen is cut into to find the occluders that may hide a cell.
const SCREEN_BINS: usize = 16;

/// A box's rectangle on screen in normalised device coordinates (x0, y0, x1, y1); None
/// when a corner is not in front of the eye.
type ScreenRect = Option<[f32; 4]>;

/// The frame's occluders, indexed by where they fall on screen: a cell's points are hidden
/// only along rays through the occluder, so only an occluder whose screen rectangle holds
/// the cell's can hide it.
struct Occluders {
    boxes: Vec<Aabb>,
    rects: Vec<ScreenRect>,
    /// Per bin, the occluders whose rectangles meet it, in order.
    bins: Vec<Vec<u32>>,
    /// Occluders without a rectangle (reaching behind the eye), in order.
    everywhere: Vec<u32>,
    view_projection: glam::Mat4,
}

impl Occluders {
    fn new(view_projection: glam::Mat4) -> Occluders {
        Occluders {
            boxes: Vec::new(),
            rects: Vec::new(),
            bins: vec![Vec::new(); SCREEN_BINS * SCREEN_BINS],
            everywhere: Vec::new(),
            view_projection,
        }
    }

    fn screen_rect(&self, b: &Aabb) -> ScreenRect {
        let mut rect = [f32::MAX, f32::MAX, f32::MIN, f32::MIN];
        for corner in b.corners() {
            let clip = self.view_projection * corner.extend(1.0);
            if clip.w <= 1e-6 {
                return None;
            }
            let (x, y) = (clip.x / clip.w, clip.y / clip.w);
            rect = [
                rect[0].min(x),
                rect[1].min(y),
                rect[2].max(x),
                rect[3].max(y),
            ];
        }
        Some(rect)
    }

    fn bin(ndc: f32) -> usize {
        (((ndc + 1.0) * 0.5 * SCREEN_BINS as f32).floor()).clamp(0.0, SCREEN_BINS as f32 - 1.0)
            as usize
    }

    fn push(&mut self, occluder: Aabb) {
        let index = self.boxes.len() as u32;
        let rect = self.screen_rect(&occluder);
        match rect {
            None => self.everywhere.push(index),
            Some([x0, y0, x1, y1]) => {
                for by in Occluders::bin(y0)..=Occluders::bin(y1) {
                    for bx in Occluders::bin(x0)..=Occluders::bin(x1) {
                        self.bins[by * SCREEN_BINS + bx].push(index);
                    }
                }
            }
        }
        self.boxes.push(occluder);
        self.rects.push(rect);
    }

    /// Occluders from index `first` on that may hide a box with screen rectangle `rect`.
    fn candidates(&self, first: u32, rect: ScreenRect) -> Box<dyn Iterator<Item = u32> + '_> {
        fn from(list: &[u32], first: u32) -> &[u32] {
            &list[list.partition_point(|&o| o < first)..]
        }
        let Some(r) = rect else {
            return Box::new(first..self.boxes.len() as u32);
        };
        let (cx, cy) = ((r[0] + r[2]) * 0.5, (r[1] + r[3]) * 0.5);
        let bin = &self.bins[Occluders::bin(cy) * SCREEN_BINS + Occluders::bin(cx)];
        let holds = move |o: &u32| match self.rects[*o as usize] {
            None => true,
            Some(h) => h[0] <= r[0] && h[1] <= r[1] && h[2] >= r[2] && h[3] >= r[3],
        };
        Box::new(
            from(bin, first)
                .iter()
                .chain(from(&self.everywhere, first))
                .copied()
                .filter(holds),
        )
    }
}

/// A temporal bounding volume: the object stays within `radius` of `centre` until `expires`.
#[derive(Clone, Debug)]
struct Tbv {
    centre: Vec3,
    radius: f32,
    expires: u32,
    cells: Vec<usize>,
}

/// The grid's per-frame state.
struct FrameState {
    frame: u32,
    eye: Vec3,
    /// The near clip distance plus a cell's diagonal: how close a TBV may come to the eye.
    eye_guard: f32,
    /// TBVs are used only with the eye inside the grid.
    eye_inside: bool,
    opaque: Vec<bool>,
    /// Per cell: occluders it was tested against, `u32::MAX` once found occluded (H).
    shadow_tests: Vec<u32>,
    /// Cells the traversal found visible.
    visible: Vec<bool>,
    occluders: Occluders,
    pvs: Vec<u32>,
    in_pvs: Vec<bool>,
    /// Moving objects' y intervals of solids per column, added this frame.
    column_solids: Vec<(usize, f32, f32)>,
    host_tests: u64,
}

pub(crate) struct DynamicGridDriver {
    grid: Grid,
    /// Per column: the y ranges of static solids covering it.
    static_solids: Vec<Vec<(f32, f32)>>,
    /// O_s.
    static_opaque: Vec<bool>,
    /// I for static objects; moving objects' entries this frame, and the cells they touch.
    static_ids: Vec<Vec<u32>>,
    dynamic_ids: Vec<Vec<u32>>,
    dynamic_touched: Vec<usize>,
    /// T: per cell, the objects whose TBV surface meets it.
    tbv_ids: Vec<Vec<u32>>,
    tbvs: Vec<Option<Tbv>>,
    periods: Vec<u32>,
    /// Objects drawn last frame.
    drawn_last: Vec<bool>,
}

impl DynamicGridDriver {
    pub(crate) fn new(options: &DriverOptions, scene: &WorkloadScene) -> DynamicGridDriver {
        let grid = Grid::new(
            &scene.bounds,
            options.dynamic_grid_resolution,
            options.flat_grid,
        );
        let objects = scene.objects.len();
        let mut driver = DynamicGridDriver {
            static_solids: vec![Vec::new(); grid.columns()],
            static_opaque: vec![false; grid.cells()],
            static_ids: vec![Vec::new(); grid.cells()],
            dynamic_ids: vec![Vec::new(); grid.cells()],
            dynamic_touched: Vec::new(),
            tbv_ids: vec![Vec::new(); grid.cells()],
            tbvs: vec![None; objects],
            periods: vec![FIRST_PERIOD; objects],
            drawn_last: vec![true; objects],
            grid,
        };
        for (index, object) in scene.objects.iter().enumerate() {
            if scene.motion(index as u32).is_some() {
                continue;
            }
            for cell in driver.spanned_cells(object) {
                driver.static_ids[cell].push(index as u32);
            }
            for (column, y0, y1) in driver.solid_columns(object) {
                driver.static_solids[column].push((y0, y1));
            }
        }
        for column in 0..driver.grid.columns() {
            let mut solids = driver.static_solids[column].clone();
            for (cell, opaque) in driver.column_cover(column, &mut solids) {
                driver.static_opaque[cell] = opaque;
            }
        }
        driver
    }

    /// Cells (indices) the object's box spans: its footprint grown, times its layers.
    fn spanned_cells(&self, object: &SceneObject) -> Vec<usize> {
        let g = &self.grid;
        let footprint = discretise_polygon(
            &ground_rectangle(&object.bounds),
            (g.origin.x as f64, g.origin.z as f64),
            g.side as f64,
            (g.dims[0], g.dims[2]),
        );
        let layers = g.layers(object.bounds.min.y, object.bounds.max.y);
        let mut cells = Vec::with_capacity(footprint.spanned.len());
        for y in layers {
            cells.extend(footprint.spanned.iter().map(|&(x, z)| g.index([x, y, z])));
        }
        cells
    }

    /// (column, y0, y1) for every column a solid of the object fills, footprint shrunk.
    fn solid_columns(&self, object: &SceneObject) -> Vec<(usize, f32, f32)> {
        let g = &self.grid;
        let mut columns = Vec::new();
        for solid in &object.solids {
            let footprint = discretise_polygon(
                &ground_rectangle(solid),
                (g.origin.x as f64, g.origin.z as f64),
                g.side as f64,
                (g.dims[0], g.dims[2]),
            );
            for (x, z) in footprint.opaque {
                columns.push((g.column([x, 0, z]), solid.min.y, solid.max.y));
            }
        }
        columns
    }

    /// Each layer's cell of `column` and whether the union of `solids` (y ranges) covers it.
    fn column_cover(&self, column: usize, solids: &mut [(f32, f32)]) -> Vec<(usize, bool)> {
        solids.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        let (x, z) = (
            (column % self.grid.dims[0] as usize) as u32,
            (column / self.grid.dims[0] as usize) as u32,
        );
        (0..self.grid.dims[1])
            .map(|y| {
                let b = self.grid.cell_box([x, y, z]);
                // Walk the ranges by their starts, extending the span covered from the
                // layer's bottom.
                let mut reach = b.min.y;
                for &(y0, y1) in solids.iter() {
                    if y0 <= reach {
                        reach = reach.max(y1);
                    }
                }
                (self.grid.index([x, y, z]), reach >= b.max.y)
            })
            .collect()
    }

    pub(crate) fn frame<S: EventSink, O: CommandObserver>(
        &mut self,
        frame: u32,
        scene: &WorkloadScene,
        posed: &WorkloadScene,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        let objects = posed.objects.len();
        let (_, eye_inside) = self.grid.locate(view.eye);
        let mut state = FrameState {
            frame,
            eye: view.eye,
            eye_guard: view.near + self.grid.diagonal(),
            eye_inside,
            opaque: self.static_opaque.clone(),
            shadow_tests: vec![0; self.grid.cells()],
            visible: vec![false; self.grid.cells()],
            occluders: Occluders::new(view.view_projection),
            pvs: Vec::new(),
            in_pvs: vec![false; objects],
            column_solids: Vec::new(),
            host_tests: 0,
        };
        for cell in self.dynamic_touched.drain(..) {
            self.dynamic_ids[cell].clear();
        }
        self.discretise_scene(scene, posed, &mut state);
        self.traverse(posed, view, &mut state);
        renderer.host_tests(state.host_tests);
        self.draw(posed, view, &state.pvs, renderer)
    }

    /// Step 1: moving objects into O and I, or into T.
    fn discretise_scene(
        &mut self,
        scene: &WorkloadScene,
        posed: &WorkloadScene,
        state: &mut FrameState,
    ) {
        for index in 0..posed.objects.len() {
            let Some(motion) = scene.motion(index as u32) else {
                continue;
            };
            let object = &posed.objects[index];
            match &self.tbvs[index] {
                Some(tbv)
                    if !state.eye_inside
                        || self.grid.distance(state.eye, tbv.centre)
                            <= tbv.radius + state.eye_guard =>
                {
                    self.remove_tbv(index);
                    self.periods[index] = (self.periods[index] / 2).max(1);
                    self.discretise(index, object, state);
                }
                Some(tbv) if state.frame > tbv.expires => {
                    self.remove_tbv(index);
                    self.periods[index] = (self.periods[index] * 2).min(MAX_PERIOD);
                    self.hide(index, object, motion.speed, state);
                }
                Some(_) => {}
                None if self.drawn_last[index] => {
                    self.discretise(index, object, state);
                }
                None => self.hide(index, object, motion.speed, state),
            }
        }
        self.refresh_columns(state);
    }

    /// Give a hidden moving object a TBV that keeps clear of the eye, or discretise it.
    fn hide(&mut self, index: usize, object: &SceneObject, speed: f32, state: &mut FrameState) {
        let centre = object.bounds.centre();
        let half = self.grid.distance(object.bounds.max, centre);
        let clearance = self.grid.distance(state.eye, centre) - state.eye_guard;
        let limit = clearance.min(MAX_TBV_CELLS * self.grid.side);
        let mut period = self.periods[index];
        while period > 0 && half + speed * period as f32 >= limit {
            period /= 2;
        }
        if period == 0 || !state.eye_inside {
            self.discretise(index, object, state);
            return;
        }
        self.periods[index] = period;
        let radius = half + speed * period as f32;
        let cells = self.sphere_cells(centre, radius);
        state.host_tests += cells.len() as u64;
        for &cell in &cells {
            self.tbv_ids[cell].push(index as u32);
        }
        self.tbvs[index] = Some(Tbv {
            centre,
            radius,
            expires: state.frame + period,
            cells,
        });
    }

    /// Cells meeting the surface of the sphere (3D) or circle (2D).
    fn sphere_cells(&self, centre: Vec3, radius: f32) -> Vec<usize> {
        let g = &self.grid;
        let reach = Vec3::splat(radius);
        let (lo, _) = g.locate(centre - reach);
        let (hi, _) = g.locate(centre + reach);
        let mut cells = Vec::new();
        for y in lo[1]..=hi[1] {
            for z in lo[2]..=hi[2] {
                for x in lo[0]..=hi[0] {
                    let (near, far) = g.distance_range([x, y, z], centre);
                    if near <= radius && radius <= far {
                        cells.push(g.index([x, y, z]));
                    }
                }
            }
        }
        cells
    }

    fn remove_tbv(&mut self, index: usize) {
        if let Some(tbv) = self.tbvs[index].take() {
            for cell in tbv.cells {
                self.tbv_ids[cell].retain(|&o| o as usize != index);
            }
        }
    }

    /// A moving object into I and (its solids) O for this frame; its cells.
    fn discretise(
        &mut self,
        index: usize,
        object: &SceneObject,
        state: &mut FrameState,
    ) -> Vec<usize> {
        let cells = self.spanned_cells(object);
        for &cell in &cells {
            self.dynamic_ids[cell].push(index as u32);
            self.dynamic_touched.push(cell);
        }
        state.column_solids.extend(self.solid_columns(object));
        state.host_tests += cells.len() as u64;
        cells
    }

    /// O for the columns moving solids fill: static and moving ranges together.
    fn refresh_columns(&mut self, state: &mut FrameState) {
        let mut moving = std::mem::take(&mut state.column_solids);
        moving.sort_by_key(|&(column, ..)| column);
        for run in moving.chunk_by(|a, b| a.0 == b.0) {
            let column = run[0].0;
            let mut solids = self.static_solids[column].clone();
            solids.extend(run.iter().map(|&(_, y0, y1)| (y0, y1)));
            for (cell, opaque) in self.column_cover(column, &mut solids) {
                state.opaque[cell] |= opaque;
            }
        }
    }

    /// Steps 2 to 4: shells of equal chess distance from the eye's cell, nearest first.
    fn traverse(&mut self, posed: &WorkloadScene, view: &FrameView, state: &mut FrameState) {
        let frustum = Frustum::without_near(&view.view_projection);
        let (eye_cell, _) = self.grid.locate(view.eye);
        let farthest = (0..3)
            .map(|a| eye_cell[a].max(self.grid.dims[a] - 1 - eye_cell[a]))
            .max()
            .unwrap_or(0);
        for k in 0..=farthest {
            let mut any_visible = false;
            for cell in shell(eye_cell, k, self.grid.dims) {
                // The paper's walk from seed cells meets only cells in the frustum.
                if !frustum.may_see(&self.grid.cell_box(cell)) {
                    continue;
                }
                state.host_tests += 1;
                if self.visit(cell, eye_cell, posed, state) {
                    any_visible = true;
                }
            }
            // Every ray from the eye crosses every shell: none visible, nothing beyond is.
            if state.eye_inside && !any_visible {
                break;
            }
        }
    }

    /// Visit a cell in the view frustum; whether it is visible.
    fn visit(
        &mut self,
        cell: Cell,
        eye_cell: Cell,
        posed: &WorkloadScene,
        state: &mut FrameState,
    ) -> bool {
        let index = self.grid.index(cell);
        if self.occluded(cell, state.eye, state) {
            return false;
        }
        state.visible[index] = true;
        for i in 0..self.static_ids[index].len() + self.dynamic_ids[index].len() {
            let object = self.static_ids[index]
                .get(i)
                .copied()
                .unwrap_or_else(|| self.dynamic_ids[index][i - self.static_ids[index].len()]);
            add_to_pvs(object, state);
        }
        for object in std::mem::take(&mut self.tbv_ids[index]) {
            self.reveal(object as usize, posed, state);
        }
        if state.opaque[index] {
            self.extend_occluder(cell, eye_cell, state.eye, state);
        }
        true
    }

    /// A TBV met in a visible cell: its object is discretised now, and joins the PVS at
    /// once if one of its cells was already found visible.
    fn reveal(&mut self, index: usize, posed: &WorkloadScene, state: &mut FrameState) {
        self.remove_tbv(index);
        self.periods[index] = (self.periods[index] / 2).max(1);
        let cells = self.discretise(index, &posed.objects[index], state);
        self.refresh_columns(state);
        if cells.iter().any(|&c| state.visible[c]) {
            add_to_pvs(index as u32, state);
        }
    }

    /// Is the cell occluded by an occluder found so far (H, memoised)?
    fn occluded(&self, cell: Cell, eye: Vec3, state: &mut FrameState) -> bool {
        let index = self.grid.index(cell);
        let tested = state.shadow_tests[index];
        if tested == u32::MAX {
            return true;
        }
        let cell_box = self.grid.cell_box(cell);
        let rect = state.occluders.screen_rect(&cell_box);
        state.host_tests += 1;
        let occluders = &state.occluders;
        let mut tests = 0;
        let hidden = occluders.candidates(tested, rect).any(|o| {
            tests += 1;
            in_shadow(eye, &occluders.boxes[o as usize], &cell_box)
        });
        state.host_tests += tests;
        state.shadow_tests[index] = if hidden {
            u32::MAX
        } else {
            occluders.boxes.len() as u32
        };
        hidden
    }

    /// Grow the visible opaque cell into a rectangle of opaque or occluded cells across its
    /// direction from the eye, and keep it as an occluder if it subtends enough.
    fn extend_occluder(&mut self, cell: Cell, eye_cell: Cell, eye: Vec3, state: &mut FrameState) {
        let offset: [i64; 3] = std::array::from_fn(|a| cell[a] as i64 - eye_cell[a] as i64);
        // The depth axis: the largest offset (x, then z, then y on ties).
        let depth = [0usize, 2, 1]
            .into_iter()
            .max_by_key(|&a| (offset[a].abs(), [2, 0, 1][a]))
            .unwrap_or(0);
        let across: Vec<usize> = [0usize, 2, 1].into_iter().filter(|&a| a != depth).collect();
        let mut lo = cell;
        let mut hi = cell;
        for &axis in &across {
            for step in [-1i64, 1] {
                while self.grow(&mut lo, &mut hi, axis, step, eye, state) {}
            }
        }
        let (a, b) = (self.grid.cell_box(lo), self.grid.cell_box(hi));
        let margin = self.grid.side * 1e-3;
        let occluder = Aabb {
            min: a.min + Vec3::splat(margin),
            max: b.max - Vec3::splat(margin),
        };
        let extent = occluder.max - occluder.min;
        let area = (extent[across[0]] * extent[across[1]]) as f64;
        let distance = (occluder.centre() - eye).length_squared().max(1e-6) as f64;
        if area / distance >= MIN_SOLID_ANGLE {
            state.occluders.push(occluder);
        }
    }

    /// Move the rectangle's side along `axis` one cell in direction `step` if the whole new
    /// row is opaque or occluded.
    fn grow(
        &self,
        lo: &mut Cell,
        hi: &mut Cell,
        axis: usize,
        step: i64,
        eye: Vec3,
        state: &mut FrameState,
    ) -> bool {
        let edge = if step < 0 {
            lo[axis] as i64 - 1
        } else {
            hi[axis] as i64 + 1
        };
        if edge < 0 || edge >= self.grid.dims[axis] as i64 {
            return false;
        }
        let mut row_lo = *lo;
        let mut row_hi = *hi;
        row_lo[axis] = edge as u32;
        row_hi[axis] = edge as u32;
        for y in row_lo[1]..=row_hi[1] {
            for z in row_lo[2]..=row_hi[2] {
                for x in row_lo[0]..=row_hi[0] {
                    let c = [x, y, z];
                    if !state.opaque[self.grid.index(c)] && !self.occluded(c, eye, state) {
                        return false;
                    }
                }
            }
        }
        if step < 0 {
            lo[axis] = edge as u32;
        } else {
            hi[axis] = edge as u32;
        }
        true
    }

    /// Draw the PVS near to far, each object after a brief query of its box.
    fn draw<S: EventSink, O: CommandObserver>(
        &mut self,
        posed: &WorkloadScene,
        view: &FrameView,
        pvs: &[u32],
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        self.drawn_last.fill(false);
        let vp = &view.view_projection;
        for &index in pvs {
            let object = &posed.objects[index as usize];
            let query_box = object.bounds.inflated(posed.box_margin);
            let visible = match project_box(&query_box, vp, view.near, view.width, view.height) {
                BoxView::Outside => false,
                BoxView::Near { .. } => true,
                BoxView::OnScreen { rect, .. } => {
                    let triangles = query_box
                        .triangles()
                        .into_iter()
                        .map(|t| t.map(|p| to_clip(vp, p)));
                    renderer
                        .brief_query(vec![rect], triangles)?
                        .is_none_or(|answer| answer.tiles[0].nohc > 0)
                }
            };
            if visible {
                renderer.draw_object(index, object, vp)?;
                self.drawn_last[index as usize] = true;
            }
        }
        Ok(())
    }
}

fn add_to_pvs(object: u32, state: &mut FrameState) {
    if !state.in_pvs[object as usize] {
        state.in_pvs[object as usize] = true;
        state.pvs.push(object);
    }
}

/// The cells at chess distance exactly `k` from `centre`, inside `dims`, in a fixed order.
fn shell(centre: Cell, k: u32, dims: Cell) -> impl Iterator<Item = Cell> {
    let span = move |axis: usize| {
        let lo = centre[axis].saturating_sub(k);
        let hi = (centre[axis] + k).min(dims[axis] - 1);
        lo..=hi
    };
    let at = move |axis: usize, v: u32| v.abs_diff(centre[axis]);
    span(1).flat_map(move |y| {
        span(2).flat_map(move |z| {
            let on_face = at(1, y).max(at(2, z)) == k;
            let xs: Vec<u32> = if on_face {
                span(0).collect()
            } else {
                [centre[0].checked_sub(k), Some(centre[0] + k)]
                    .into_iter()
                    .flatten()
                    .filter(|&x| x < dims[0])
                    .collect::<std::collections::BTreeSet<u32>>()
                    .into_iter()
                    .collect()
            };
            xs.into_iter().map(move |x| [x, y, z])
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rectangle [0.5, 3.2] x [0.4, 2.9] on cells of side 1 from the origin, 6 x 5 cells.
    /// Half a diagonal is 0.7071. Grown: x in [-0.207, 3.907] takes centres 0.5 to 3.5
    /// (columns 0 to 3); z in [-0.307, 3.607] takes rows 0 to 3 (row 3's centre, 3.5, is
    /// inside the grown edge though the rectangle stops at 2.9: the method over-estimates).
    /// Shrunk: x in [1.207, 2.493] takes centre 1.5 only (column 2, wholly inside at [2, 3],
    /// is missed: it under-estimates); z in [1.107, 2.193] takes row 1.
    #[test]
    fn a_rectangle_is_discretised_by_moving_its_edges_half_a_diagonal() {
        let rectangle = [(0.5, 0.4), (3.2, 0.4), (3.2, 2.9), (0.5, 2.9)];
        let footprint = discretise_polygon(&rectangle, (0.0, 0.0), 1.0, (6, 5));
        let mut spanned = Vec::new();
        for z in 0..4 {
            for x in 0..4 {
                spanned.push((x, z));
            }
        }
        assert_eq!(footprint.spanned, spanned);
        assert_eq!(footprint.opaque, vec![(1, 1)]);
        // The other winding gives the same cells.
        let mut reversed = rectangle;
        reversed.reverse();
        assert_eq!(
            discretise_polygon(&reversed, (0.0, 0.0), 1.0, (6, 5)),
            footprint
        );
    }

    /// A diamond |x - 2| + |z - 2| <= 2.4 on cells of side 1 from (-1, -1), 6 x 6 cells. Its
    /// edges have normals (+-1, +-1)/sqrt 2, so moving them by 1/sqrt 2 changes the bound by
    /// 1: grown |x-2| + |z-2| <= 3.4, shrunk <= 1.4. Centres sit at -0.5 .. 4.5, so for
    /// columns (and rows) 0 to 5, |c - 2| is 2.5, 1.5, 0.5, 0.5, 1.5, 2.5.
    #[test]
    fn a_diamond_is_discretised_along_its_slanted_edges() {
        let diamond = [(2.0, -0.4), (4.4, 2.0), (2.0, 4.4), (-0.4, 2.0)];
        let footprint = discretise_polygon(&diamond, (-1.0, -1.0), 1.0, (6, 6));
        // Row by row (z), the columns whose |x-2| + |z-2| <= 3.4:
        // rows 0 and 5 (2.5): columns with 0.5 -> 2, 3;
        // rows 1 and 4 (1.5): columns with <= 1.5 -> 1, 2, 3, 4;
        // rows 2 and 3 (0.5): every column (2.5 + 0.5 = 3) -> 0 to 5.
        let rows: [&[u32]; 6] = [
            &[2, 3],
            &[1, 2, 3, 4],
            &[0, 1, 2, 3, 4, 5],
            &[0, 1, 2, 3, 4, 5],
            &[1, 2, 3, 4],
            &[2, 3],
        ];
        let spanned: Vec<(u32, u32)> = rows
            .iter()
            .enumerate()
            .flat_map(|(z, columns)| columns.iter().map(move |&x| (x, z as u32)))
            .collect();
        assert_eq!(footprint.spanned, spanned);
        assert_eq!(footprint.opaque, vec![(2, 2), (3, 2), (2, 3), (3, 3)]);
    }

    #[test]
    fn cells_outside_the_grid_are_left_out() {
        // A square beyond the grid's far corner touches nothing; one over its edge is cut.
        let far = [(10.0, 10.0), (12.0, 10.0), (12.0, 12.0), (10.0, 12.0)];
        assert_eq!(
            discretise_polygon(&far, (0.0, 0.0), 1.0, (4, 4)),
            Footprint::default()
        );
        let edge = [(3.2, 3.2), (5.0, 3.2), (5.0, 5.0), (3.2, 5.0)];
        let cut = discretise_polygon(&edge, (0.0, 0.0), 1.0, (4, 4));
        // Grown from 3.2 - 0.707 = 2.49: centres 2.5 and 3.5 -> columns and rows 2, 3.
        assert_eq!(cut.spanned, vec![(2, 2), (3, 2), (2, 3), (3, 3)]);
        assert!(cut.opaque.is_empty());
    }

    /// An occluder box [4, 6] x [-1, 1] x [-1, 1] seen from the origin; a ray to (x, y, z)
    /// enters it at x = 4 where its height is 4y/x. The unit cube at x 8..9, |y|, |z| <= 0.5
    /// is hidden (every corner's ray enters at |y|, |z| <= 0.25). Raised to y 1.5..2.5 it
    /// straddles the shadow's edge: corner (9, 1.5, -0.5) enters at y 0.67 (hidden), corner
    /// (8, 2.5, 0.5) at y 1.25 and stays above 1 (not): not occluded.
    #[test]
    fn a_cell_is_in_shadow_only_when_all_its_corners_are() {
        let occluder = Aabb {
            min: Vec3::new(4.0, -1.0, -1.0),
            max: Vec3::new(6.0, 1.0, 1.0),
        };
        let hidden = Aabb {
            min: Vec3::new(8.0, -0.5, -0.5),
            max: Vec3::new(9.0, 0.5, 0.5),
        };
        assert!(in_shadow(Vec3::ZERO, &occluder, &hidden));
        let raised = Aabb {
            min: Vec3::new(8.0, 1.5, -0.5),
            max: Vec3::new(9.0, 2.5, 0.5),
        };
        assert!(!in_shadow(Vec3::ZERO, &occluder, &raised));
        // In front of the occluder nothing is hidden.
        let before = Aabb {
            min: Vec3::new(1.0, -0.5, -0.5),
            max: Vec3::new(2.0, 0.5, 0.5),
        };
        assert!(!in_shadow(Vec3::ZERO, &occluder, &before));
    }

    /// Shells of a 5 x 1 x 5 grid around (2, 0, 2): 1 cell, then the 8 around it, then the
    /// 16 of the border; every cell exactly once.
    #[test]
    fn shells_hold_the_cells_at_each_chess_distance() {
        let dims = [5, 1, 5];
        let sizes: Vec<usize> = (0..3).map(|k| shell([2, 0, 2], k, dims).count()).collect();
        assert_eq!(sizes, vec![1, 8, 16]);
        let mut all: Vec<Cell> = (0..3).flat_map(|k| shell([2, 0, 2], k, dims)).collect();
        all.sort();
        all.dedup();
        assert_eq!(all.len(), 25);
        // From a corner, shell 1 is the three neighbours inside the grid.
        assert_eq!(shell([0, 0, 0], 1, dims).count(), 3);
    }
}
