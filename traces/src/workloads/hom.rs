//! Hierarchical occlusion maps (Zhang, Manocha, Hudson, Hoff; seed 003), with the occlusion
//! map rendered on the machine and read through occlusion queries.
//!
//! Every frame:
//! 1. Occluder selection (section 5.3): from the occluder database (objects big enough and
//!    not flat, chosen once per scene), the objects in the view frustum sorted by the
//!    distance from the eye to their boxes' centres; the nearest are taken while their
//!    triangles stay within the budget L.
//! 2. The occluders are drawn (they are part of the image anyway), then the occlusion map
//!    is read: one brief query per band of map rows (at most 8,192 pixels), whose tiles are the map's pixels (cells
//!    of `cell` x `cell` screen pixels), drawing one screen-aligned quad just in front of the
//!    clear depth with depth writes off. A tile's hits are its pixels no occluder covers, so
//!    its opacity is exactly the covered share of its cell: the box-filtered occlusion map
//!    the paper renders at 256x256 for a 1024x1024 image (4-pixel cells).
//! 3. The pyramid (section 4.1) is built by averaging 2x2 blocks as bilinear texture
//!    filtering at weights one half does, in 8-bit opacity (the framebuffer channel's), down
//!    to at most 4x4 pixels; on the host, each pixel made a host test.
//! 4. The depth estimation buffer (section 5.2.2): 64x64 entries, each the farthest depth of
//!    the occluders whose boxes' screen rectangles meet it (their farthest box vertex).
//! 5. The model's hierarchy is traversed front to back with view-frustum culling; a node is
//!    culled when its box's rectangle passes the depth test (every entry under it nearer
//!    than the box's nearest vertex) and the hierarchical overlap test (section 5.1).
//!
//! Choices the paper leaves open, and what is done here:
//! - Occluder database: an object is in it when its box is not flat (its smallest extent at
//!   least 1/20 of its largest: a ground plane occludes nothing standing on it, and its
//!   rectangle and depth would void the depth estimation buffer) and its diagonal at least
//!   half the median object's. Redundancy is not judged; an object with more triangles than
//!   L can never be chosen (rendering complexity).
//! - The budget L: a sixteenth of the scene's triangles unless given; it is not adapted to
//!   the frame rate (a trace does not know the machine) and the hole-filling feedback of
//!   section 5.3.2 is left out. Selection stops at the first object that does not fit.
//! - Averaging truncates: 255 (opaque) only when all four are 255, so threshold 1.0 stays
//!   conservative (rounding to nearest would make three opaque pixels and one at 254 read
//!   as opaque). At the viewport's right and bottom edges a pyramid pixel averages the
//!   children that exist (its on-screen part).
//! - Opacity thresholds (section 5.4): the finest map's is 1.0; level k's is T^k for the
//!   given T (1: conservative culling), rising with resolution as the paper asks. A pixel
//!   at or above its level's threshold is opaque. The transparency threshold of early
//!   termination is 1/8: a pixel below it ends the test (the occludee is drawn).
//! - The overlap test starts at the finest level whose pixels are at least as large as the
//!   rectangle's longer side.
//! - Host costs: each occluder candidate and each hierarchy node is a node visit and a box
//!   test; each map and pyramid pixel made, each pixel the overlap test reads and each
//!   depth-estimation entry written or read is a host test (charged as a decision).

use super::bvh::NodeContent;
use super::drivers::FrontToBack;
use super::project::{project_box, BoxView, Frustum};
use super::render::{CommandObserver, Renderer};
use super::{DriverOptions, FrameView, WorkloadScene};
use crate::event::DEPTH_ONE;
use crate::golden::EventSink;
use crate::query::MAX_TILES;
use crate::state::Rect;

/// The map's probe quad: just in front of the clear depth by more than a quad's rounding.
const PROBE_DEPTH: u32 = DEPTH_ONE - 8;
/// Map pixels a probe query holds at most: under `MAX_TILES`, and small enough that every
/// machine's tile registers hold the query (ir4's 320 Image Engines each keep every tile
/// of a query; its model allows 4,194,304 tile registers, 320 x 8,192 = 2,621,440).
const MAP_TILES_PER_QUERY: u32 = 8192;
/// Depth estimation buffer entries along each side.
const DEB_SIDE: u32 = 64;
/// The coarsest pyramid level has at most this many pixels along each side.
const TOP_SIDE: u32 = 4;
/// Early termination: a pixel below this opacity (of 255) ends the overlap test.
const TRANSPARENCY: u8 = 32;

/// One level of the pyramid: `columns` x `rows` pixels of `side` x `side` screen pixels.
#[derive(Clone, Debug, PartialEq)]
struct Level {
    columns: u32,
    rows: u32,
    side: u32,
    opacity: Vec<u8>,
}

impl Level {
    fn at(&self, column: u32, row: u32) -> u8 {
        self.opacity[(row * self.columns + column) as usize]
    }

    /// The pixels (column and row ranges, inclusive) meeting `rect`.
    fn under(&self, rect: Rect) -> (u32, u32, u32, u32) {
        let last =
            |start: u32, length: u32, count: u32| ((start + length - 1) / self.side).min(count - 1);
        (
            (rect.x / self.side).min(self.columns - 1),
            last(rect.x, rect.width, self.columns),
            (rect.y / self.side).min(self.rows - 1),
            last(rect.y, rect.height, self.rows),
        )
    }
}

/// Hierarchical occlusion maps: level 0 the finest.
#[derive(Clone, Debug, PartialEq)]
struct Pyramid {
    levels: Vec<Level>,
}

impl Pyramid {
    /// The pyramid over a finest map of `columns` x `rows` pixels of `cell` screen pixels.
    fn build(columns: u32, rows: u32, cell: u32, finest: Vec<u8>) -> Pyramid {
        let mut levels = vec![Level {
            columns,
            rows,
            side: cell,
            opacity: finest,
        }];
        loop {
            let below = levels.last().expect("level 0");
            if below.columns <= TOP_SIDE && below.rows <= TOP_SIDE {
                break;
            }
            let (columns, rows) = (below.columns.div_ceil(2), below.rows.div_ceil(2));
            let mut opacity = Vec::with_capacity((columns * rows) as usize);
            for row in 0..rows {
                for column in 0..columns {
                    let (mut sum, mut count) = (0u32, 0u32);
                    for (c, r) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let (c, r) = (2 * column + c, 2 * row + r);
                        if c < below.columns && r < below.rows {
                            sum += below.at(c, r) as u32;
                            count += 1;
                        }
                    }
                    opacity.push((sum / count) as u8);
                }
            }
            let side = below.side * 2;
            levels.push(Level {
                columns,
                rows,
                side,
                opacity,
            });
        }
        Pyramid { levels }
    }

    /// Pixels over all levels but the finest (the averaging's work).
    fn averaged_pixels(&self) -> u64 {
        self.levels[1..]
            .iter()
            .map(|l| l.opacity.len() as u64)
            .sum()
    }

    /// Does `rect` lie in the opaque part of the maps, at `thresholds` (one a level)? Counts
    /// the pixels read in `reads`.
    fn covers(&self, rect: Rect, thresholds: &[u8], reads: &mut u64) -> bool {
        let longer = rect.width.max(rect.height);
        let start = self
            .levels
            .iter()
            .position(|l| l.side >= longer)
            .unwrap_or(self.levels.len() - 1);
        let (c0, c1, r0, r1) = self.levels[start].under(rect);
        (r0..=r1).all(|row| {
            (c0..=c1).all(|column| self.pixel_covers(start, column, row, rect, thresholds, reads))
        })
    }

    fn pixel_covers(
        &self,
        level: usize,
        column: u32,
        row: u32,
        rect: Rect,
        thresholds: &[u8],
        reads: &mut u64,
    ) -> bool {
        *reads += 1;
        let opacity = self.levels[level].at(column, row);
        if opacity >= thresholds[level] {
            return true;
        }
        if level == 0 || opacity < TRANSPARENCY {
            return false;
        }
        let finer = &self.levels[level - 1];
        let (c0, c1, r0, r1) = finer.under(rect);
        let (c0, c1) = (c0.max(2 * column), c1.min(2 * column + 1));
        let (r0, r1) = (r0.max(2 * row), r1.min(2 * row + 1));
        (r0..=r1)
            .all(|r| (c0..=c1).all(|c| self.pixel_covers(level - 1, c, r, rect, thresholds, reads)))
    }
}

/// 8-bit opacity thresholds of `levels` levels: 1.0 at the finest, `t`^k at level k, each
/// rounded up (a pixel is opaque at or above it).
fn level_thresholds(t: f32, levels: usize) -> Vec<u8> {
    (0..levels)
        .map(|k| (255.0 * (t as f64).powi(k as i32)).ceil().clamp(0.0, 255.0) as u8)
        .collect()
}

/// The depth estimation buffer: per entry, the farthest depth of the occluders over it.
struct DepthEstimation {
    columns: u32,
    rows: u32,
    /// Entry size in pixels.
    entry_width: u32,
    entry_height: u32,
    farthest: Vec<u32>,
}

impl DepthEstimation {
    fn new(width: u32, height: u32) -> DepthEstimation {
        let (entry_width, entry_height) = (width.div_ceil(DEB_SIDE), height.div_ceil(DEB_SIDE));
        let (columns, rows) = (width.div_ceil(entry_width), height.div_ceil(entry_height));
        DepthEstimation {
            columns,
            rows,
            entry_width,
            entry_height,
            farthest: vec![0; (columns * rows) as usize],
        }
    }

    /// Entries meeting `rect` (non-empty, inside the viewport).
    fn under(&self, rect: Rect) -> impl Iterator<Item = usize> + '_ {
        let c0 = (rect.x / self.entry_width).min(self.columns - 1);
        let c1 = ((rect.x + rect.width - 1) / self.entry_width).min(self.columns - 1);
        let r0 = (rect.y / self.entry_height).min(self.rows - 1);
        let r1 = ((rect.y + rect.height - 1) / self.entry_height).min(self.rows - 1);
        (r0..=r1).flat_map(move |r| (c0..=c1).map(move |c| (r * self.columns + c) as usize))
    }

    /// An occluder whose fragments lie within `rect` (None: anywhere) and no deeper than
    /// `z_upper`. Returns the entries written.
    fn add(&mut self, rect: Option<Rect>, z_upper: u32) -> u64 {
        let indices: Vec<usize> = match rect {
            Some(rect) => self.under(rect).collect(),
            None => (0..self.farthest.len()).collect(),
        };
        for &i in &indices {
            self.farthest[i] = self.farthest[i].max(z_upper);
        }
        indices.len() as u64
    }

    /// Is every entry under `rect` strictly nearer than `z_lower`? Counts entries read.
    fn behind(&self, rect: Rect, z_lower: u32, reads: &mut u64) -> bool {
        self.under(rect).all(|i| {
            *reads += 1;
            self.farthest[i] < z_lower
        })
    }
}

pub(crate) struct HomDriver {
    cell: u32,
    thresholds_t: f32,
    /// The occluder database: object indices.
    database: Vec<u32>,
    budget: u64,
}

impl HomDriver {
    pub(crate) fn new(options: &DriverOptions, scene: &WorkloadScene) -> HomDriver {
        let budget = options
            .occluder_triangles
            .unwrap_or(scene.triangle_count() / 16);
        HomDriver {
            cell: options.occlusion_map_cell_pixels.max(1),
            thresholds_t: options.opacity_threshold,
            database: occluder_database(scene, budget),
            budget,
        }
    }

    pub(crate) fn frame<S: EventSink, O: CommandObserver>(
        &mut self,
        scene: &WorkloadScene,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        let bvh = &scene.bvh;
        if bvh.nodes.is_empty() {
            return Ok(());
        }
        let vp = &view.view_projection;
        let frustum = Frustum::new(vp);
        // 1. Occluder selection.
        let mut candidates: Vec<(u32, u32)> = Vec::new();
        for &object in &self.database {
            renderer.visit_node();
            let bounds = &scene.objects[object as usize].bounds;
            if frustum.may_see(bounds) {
                let distance = (bounds.centre() - view.eye).length();
                candidates.push((distance.to_bits(), object));
            }
        }
        candidates.sort_unstable();
        let mut drawn = vec![false; scene.objects.len()];
        let mut deb = DepthEstimation::new(view.width, view.height);
        let mut occluder_triangles = 0u64;
        let mut occluders = 0;
        for &(_, object) in &candidates {
            let o = &scene.objects[object as usize];
            occluder_triangles += o.triangles.len() as u64;
            if occluder_triangles > self.budget {
                break;
            }
            // 2. The occluder is drawn; 4. its rectangle and depth go into the buffer.
            renderer.draw_object(object, o, vp)?;
            drawn[object as usize] = true;
            occluders += 1;
            let written = match project_box(&o.bounds, vp, view.near, view.width, view.height) {
                BoxView::Outside => 0,
                BoxView::Near { z_upper } => deb.add(None, z_upper),
                BoxView::OnScreen { rect, z_upper, .. } => deb.add(Some(rect), z_upper),
            };
            renderer.host_tests(written);
        }
        // 2. The occlusion map through queries; 3. the pyramid.
        let pyramid = if occluders == 0 {
            None
        } else {
            let finest = self.read_map(renderer)?;
            let pyramid = Pyramid::build(
                view.width.div_ceil(self.cell),
                view.height.div_ceil(self.cell),
                self.cell,
                finest,
            );
            renderer.host_tests(pyramid.levels[0].opacity.len() as u64 + pyramid.averaged_pixels());
            Some(pyramid)
        };
        let thresholds = pyramid
            .as_ref()
            .map(|p| level_thresholds(self.thresholds_t, p.levels.len()))
            .unwrap_or_default();
        // 5. The model's hierarchy against the maps.
        let mut queue = FrontToBack::new(view.eye);
        queue.push(bvh, 0, ());
        while let Some((index, _)) = queue.pop() {
            renderer.visit_node();
            let node = &bvh.nodes[index as usize];
            if !frustum.may_see(&node.bounds) {
                continue;
            }
            let query_box = node.bounds.inflated(scene.box_margin);
            match project_box(&query_box, vp, view.near, view.width, view.height) {
                BoxView::Outside => continue,
                BoxView::Near { .. } => {}
                BoxView::OnScreen { rect, z_lower, .. } => {
                    if let Some(pyramid) = &pyramid {
                        let mut reads = 0;
                        let hidden = deb.behind(rect, z_lower, &mut reads)
                            && pyramid.covers(rect, &thresholds, &mut reads);
                        renderer.host_tests(reads);
                        if hidden {
                            continue;
                        }
                    }
                }
            }
            match node.content {
                NodeContent::Leaf { first, count } => {
                    for &object in bvh.leaf_objects(first, count) {
                        if !drawn[object as usize] {
                            drawn[object as usize] = true;
                            renderer.draw_object(object, &scene.objects[object as usize], vp)?;
                        }
                    }
                }
                NodeContent::Inner { children } => {
                    for child in children {
                        queue.push(bvh, child, ());
                    }
                }
            }
        }
        Ok(())
    }

    /// The finest occlusion map, row by row: each cell's covered share in 8-bit opacity
    /// (rounded down: 255 only when every pixel is covered).
    fn read_map<S: EventSink, O: CommandObserver>(
        &self,
        renderer: &mut Renderer<S, O>,
    ) -> Result<Vec<u8>, S::Error> {
        let (width, height) = (renderer.width, renderer.height);
        let (columns, rows) = (width.div_ceil(self.cell), height.div_ceil(self.cell));
        let band_rows = (MAP_TILES_PER_QUERY.min(MAX_TILES as u32) / columns).max(1);
        let mut finest = Vec::with_capacity((columns * rows) as usize);
        let mut row = 0;
        while row < rows {
            let last = (row + band_rows).min(rows);
            let y0 = row * self.cell;
            let y1 = (last * self.cell).min(height);
            let band = Rect::new(0, y0, width, y1 - y0);
            let tiles: Vec<Rect> = (row..last)
                .flat_map(|r| {
                    (0..columns).map(move |c| {
                        let (x, y) = (c * self.cell, r * self.cell);
                        Rect::new(x, y, self.cell.min(width - x), self.cell.min(height - y))
                    })
                })
                .collect();
            let areas: Vec<u64> = tiles.iter().map(Rect::area).collect();
            let answer = renderer.band_probe(tiles, band, PROBE_DEPTH)?;
            match answer {
                Some(result) => {
                    for (tile, area) in result.tiles.iter().zip(areas) {
                        let covered = area.saturating_sub(tile.nohc);
                        finest.push((covered * 255 / area.max(1)) as u8);
                    }
                }
                None => finest.extend(std::iter::repeat_n(0, areas.len())),
            }
            row = last;
        }
        Ok(finest)
    }
}

/// Objects that make good occluders from most viewpoints: boxes not flat, diagonals at
/// least half the median, no more triangles than the budget.
fn occluder_database(scene: &WorkloadScene, budget: u64) -> Vec<u32> {
    let diagonal = |o: &super::SceneObject| (o.bounds.max - o.bounds.min).length();
    let mut diagonals: Vec<f32> = scene.objects.iter().map(diagonal).collect();
    diagonals.sort_by(f32::total_cmp);
    let median = diagonals.get(diagonals.len() / 2).copied().unwrap_or(0.0);
    (0..scene.objects.len() as u32)
        .filter(|&i| {
            let o = &scene.objects[i as usize];
            let extent = o.bounds.max - o.bounds.min;
            extent.min_element() * 20.0 >= extent.max_element()
                && diagonal(o) * 2.0 >= median
                && o.triangles.len() as u64 <= budget
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn averaging_truncates_so_only_four_opaque_pixels_make_an_opaque_one() {
        // 2x2 blocks of a 4x2 map: (255+255+255+254)/4 = 254.75 -> 254, not opaque;
        // (255*4)/4 = 255. A 3x1 map: (255+255)/2 = 255 and the lone 100 stays 100.
        let p = Pyramid::build(4, 2, 4, vec![255, 255, 255, 255, 255, 254, 255, 255]);
        assert_eq!(p.levels.len(), 1, "4x2 is already at most 4x4");
        let p = Pyramid::build(8, 2, 4, [255, 255, 255, 255].repeat(4));
        assert_eq!(p.levels[1].opacity, vec![255; 4]);
        let mut map = vec![255u8; 16];
        map[9] = 254; // column 1 of row 1: the block of level-1 pixel (0, 0)
        let p = Pyramid::build(8, 2, 4, map);
        assert_eq!(p.levels[1].opacity, vec![254, 255, 255, 255]);
        assert_eq!(p.levels[1].side, 8);
        let p = Pyramid::build(5, 1, 4, vec![255, 255, 0, 0, 100]);
        assert_eq!(p.levels[1].opacity, vec![255, 0, 100]);
        assert_eq!(p.averaged_pixels(), 3);
    }

    #[test]
    fn thresholds_rise_with_resolution_and_one_is_conservative() {
        assert_eq!(level_thresholds(1.0, 4), vec![255; 4]);
        // 255 * 0.5 = 127.5 -> 128; 255 * 0.25 = 63.75 -> 64; 255 * 0.125 = 31.9 -> 32.
        assert_eq!(level_thresholds(0.5, 4), vec![255, 128, 64, 32]);
    }

    #[test]
    fn the_overlap_test_descends_to_partly_opaque_pixels() {
        // An 8x8 map of 4-pixel cells (32x32 screen pixels), opaque but for cell (5, 5).
        let mut map = vec![255u8; 64];
        map[5 * 8 + 5] = 0;
        let p = Pyramid::build(8, 8, 4, map);
        // Level 1 pixel (2, 2) averages cells 4-5 x 4-5: 765 / 4 = 191.
        assert_eq!(p.levels[1].at(2, 2), 191);
        let conservative = level_thresholds(1.0, p.levels.len());
        let mut reads = 0;
        // A 6x6 rectangle on cells 0-1: starts at level 1 (8-pixel side), one pixel, opaque.
        assert!(p.covers(Rect::new(1, 1, 6, 6), &conservative, &mut reads));
        assert_eq!(reads, 1);
        // A 6x6 rectangle over cells 4-5 x 4-5 (pixels 17-22) starts at level 1 too: 191 is
        // not opaque, so the test descends and reads (4, 4), (5, 4), (4, 5), then the hole
        // (5, 5): 5 reads, not covered.
        reads = 0;
        assert!(!p.covers(Rect::new(17, 17, 6, 6), &conservative, &mut reads));
        assert_eq!(reads, 5);
        // A 4x4 rectangle in cell (4, 4) starts at level 0 (side 4 >= 4): one read, opaque.
        reads = 0;
        assert!(p.covers(Rect::new(16, 16, 4, 4), &conservative, &mut reads));
        assert_eq!(reads, 1);
        // Approximately, with T = 0.7: level 1's threshold is ceil(255 * 0.7) = ceil(178.5)
        // = 179 <= 191, so the hole is ignored after one read.
        let approximate = level_thresholds(0.7, p.levels.len());
        reads = 0;
        assert!(p.covers(Rect::new(17, 17, 6, 6), &approximate, &mut reads));
        assert_eq!(reads, 1);
    }

    #[test]
    fn the_depth_estimation_buffer_keeps_the_farthest_occluder() {
        // 128x64 pixels: entries of 2x1 pixels, 64x64 of them.
        let mut deb = DepthEstimation::new(128, 64);
        assert_eq!((deb.columns, deb.rows), (64, 64));
        assert_eq!(deb.add(Some(Rect::new(0, 0, 4, 2)), 500), 4);
        assert_eq!(deb.add(Some(Rect::new(2, 0, 4, 1)), 700), 2);
        let mut reads = 0;
        assert!(deb.behind(Rect::new(0, 0, 2, 2), 501, &mut reads));
        assert!(
            !deb.behind(Rect::new(0, 0, 2, 2), 500, &mut reads),
            "equal depth passes LEQUAL"
        );
        assert!(
            !deb.behind(Rect::new(0, 0, 3, 1), 600, &mut reads),
            "meets the 700 entry"
        );
        assert_eq!(deb.add(None, 900), 64 * 64);
        assert!(!deb.behind(Rect::new(100, 50, 3, 3), 800, &mut reads));
    }
}
