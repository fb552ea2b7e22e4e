//! The lazy occlusion grid (Hey, Tobler, Purgathofer), z-buffer variant, in query form.
//!
//! The screen is cut into cells (32x32 pixels by default). The paper keeps per cell the
//! farthest depth of its pixels, refreshed by a pixel-level query when the cell is
//! outdated. Occlusion hardware reports fragment depths, not stored ones, so here a cell
//! keeps two bounds on its stored depths, both learned from *depth probes*: a brief query
//! drawing, over each tile, a screen-aligned quad at a chosen depth with LEQUAL, which has
//! hits in a tile exactly where some stored depth is at least the quad's.
//! - `upper`: no stored depth in the cell exceeds it. Drawing only lowers depths, so it
//!   stays true until the frame's clear.
//! - `lower`: some stored depth in the cell reaches it. Drawing may invalidate it: a draw
//!   into the cell resets it (the cell is *outdated*).
//!
//! A box whose fragments are no nearer than `z` (and whose screen rectangle holds its
//! fragments) is tested cell by cell, as the paper's figure 3:
//! - `z > upper`: hidden in this cell.
//! - the cell is untouched this frame (all depths 1.0): potentially visible at once.
//! - an internal cell (wholly inside the rectangle) with `z <= lower`: potentially visible.
//! - otherwise the cell needs a probe at `z`: the whole cell for an internal cell (its
//!   bounds are refreshed from the answer), the part inside the rectangle for a border cell.
//!
//! All the cells one box needs go into **one** brief query whose tiles are those cells, so
//! one query tests many cells on many engines. The box is potentially visible if a probed
//! tile has a hit. Culling is conservative: a box is culled only where its fragments would
//! all fail the depth test.
//!
//! The lazy grid marks the cells under a drawn object outdated. The busy grid refreshes
//! them at once after every draw with a probe at the object's farthest depth.

use super::bvh::NodeContent;
use super::drivers::FrontToBack;
use super::project::{project_box, BoxView, Frustum};
use super::render::{CommandObserver, Renderer};
use super::{DriverKind, DriverOptions, FrameView, WorkloadScene};
use crate::event::DEPTH_ONE;
use crate::golden::EventSink;
use crate::state::Rect;

/// Depth units a probe quad's fragments may land away from the depth asked for.
const PROBE_SLACK: u32 = 3;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Cell {
    /// No stored depth in the cell exceeds this (24-bit units).
    upper: u32,
    /// Some stored depth in the cell reaches this (0 when unknown).
    lower: u32,
    /// Something was drawn into the cell this frame.
    touched: bool,
}

const CLEARED: Cell = Cell {
    upper: DEPTH_ONE,
    lower: DEPTH_ONE,
    touched: false,
};

pub(crate) struct GridDriver {
    busy: bool,
    /// Cell side in pixels.
    cell: u32,
    columns: u32,
    rows: u32,
    width: u32,
    height: u32,
    cells: Vec<Cell>,
}

impl GridDriver {
    pub(crate) fn new(options: &DriverOptions, width: u32, height: u32) -> GridDriver {
        let cell = options.grid_cell_pixels.max(1);
        let (columns, rows) = (width.div_ceil(cell), height.div_ceil(cell));
        GridDriver {
            busy: options.kind == DriverKind::BusyGrid,
            cell,
            columns,
            rows,
            width,
            height,
            cells: vec![CLEARED; columns as usize * rows as usize],
        }
    }

    fn cell_rect(&self, column: u32, row: u32) -> Rect {
        let (x, y) = (column * self.cell, row * self.cell);
        Rect::new(
            x,
            y,
            self.cell.min(self.width - x),
            self.cell.min(self.height - y),
        )
    }

    /// Indices and rectangles of the cells meeting `rect`, row by row.
    fn cells_under(&self, rect: Rect) -> impl Iterator<Item = (usize, Rect)> + '_ {
        let (c0, c1) = (rect.x / self.cell, (rect.x + rect.width - 1) / self.cell);
        let (r0, r1) = (rect.y / self.cell, (rect.y + rect.height - 1) / self.cell);
        (r0..=r1.min(self.rows - 1)).flat_map(move |row| {
            (c0..=c1.min(self.columns - 1)).map(move |column| {
                (
                    (row * self.columns + column) as usize,
                    self.cell_rect(column, row),
                )
            })
        })
    }

    /// Is a box with screen rectangle `rect` and fragments no nearer than `z_lower`
    /// potentially visible? May issue one probe query.
    fn potentially_visible<S: EventSink, O: CommandObserver>(
        &mut self,
        rect: Rect,
        z_lower: u32,
        renderer: &mut Renderer<S, O>,
    ) -> bool {
        // Probes need room below the box's depth for their slack.
        if z_lower <= 2 * PROBE_SLACK + 1 {
            return true;
        }
        let probe_depth = z_lower - PROBE_SLACK - 1;
        let mut internal = Vec::new();
        let mut border = Vec::new();
        for (index, cell_rect) in self.cells_under(rect) {
            let cell = self.cells[index];
            if z_lower > cell.upper {
                continue;
            }
            if !cell.touched {
                return true;
            }
            let part = cell_rect.intersect(&rect);
            if part == cell_rect {
                if z_lower <= cell.lower {
                    return true;
                }
                internal.push((index, cell_rect));
            } else {
                border.push(part);
            }
        }
        if internal.is_empty() && border.is_empty() {
            return false;
        }
        let tiles: Vec<Rect> = internal
            .iter()
            .map(|&(_, r)| r)
            .chain(border.iter().copied())
            .collect();
        let Some(result) = renderer.depth_probe(tiles, probe_depth) else {
            return true;
        };
        renderer.stats.cells_refreshed += internal.len() as u64;
        for (&(index, _), tile) in internal.iter().zip(&result.tiles) {
            self.learn(index, probe_depth, tile.nohc > 0);
        }
        result.tiles.iter().any(|tile| tile.nohc > 0)
    }

    /// Fold a probe's answer for a whole cell into its bounds. Probe fragments lie within
    /// `PROBE_SLACK` of `depth`; a hit means some stored depth is at least the fragment's,
    /// no hit means every stored depth is below it.
    fn learn(&mut self, index: usize, depth: u32, hit: bool) {
        let cell = &mut self.cells[index];
        if hit {
            cell.lower = cell.lower.max(depth - PROBE_SLACK);
        } else {
            cell.upper = cell.upper.min(depth + PROBE_SLACK);
        }
    }

    /// After drawing into `rect` things no farther than `z_upper`: outdate the cells, and
    /// for the busy grid refresh them at once.
    fn after_draw<S: EventSink, O: CommandObserver>(
        &mut self,
        rect: Rect,
        z_upper: u32,
        renderer: &mut Renderer<S, O>,
    ) {
        let under: Vec<(usize, Rect)> = self.cells_under(rect).collect();
        for &(index, _) in &under {
            let cell = &mut self.cells[index];
            cell.touched = true;
            cell.lower = 0;
        }
        if !self.busy {
            return;
        }
        // A probe just behind the object: no hit means the cell is now covered no deeper.
        let probe_depth = z_upper.saturating_add(PROBE_SLACK + 1);
        if probe_depth + PROBE_SLACK >= DEPTH_ONE {
            return;
        }
        let refresh: Vec<(usize, Rect)> = under
            .into_iter()
            .filter(|&(index, _)| self.cells[index].upper > probe_depth + PROBE_SLACK)
            .collect();
        if refresh.is_empty() {
            return;
        }
        let tiles = refresh.iter().map(|&(_, r)| r).collect();
        if let Some(result) = renderer.depth_probe(tiles, probe_depth) {
            renderer.stats.cells_refreshed += refresh.len() as u64;
            for (&(index, _), tile) in refresh.iter().zip(&result.tiles) {
                self.learn(index, probe_depth, tile.nohc > 0);
            }
        }
    }

    /// One frame: the paper's figure 4, front to back through the hierarchy.
    pub(crate) fn frame<S: EventSink, O: CommandObserver>(
        &mut self,
        scene: &WorkloadScene,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) {
        self.cells.fill(CLEARED);
        let bvh = &scene.bvh;
        if bvh.nodes.is_empty() {
            return;
        }
        let viewport = Rect::new(0, 0, self.width, self.height);
        let frustum = Frustum::new(&view.view_projection);
        let vp = &view.view_projection;
        let mut queue = FrontToBack::new(view.eye);
        queue.push(bvh, 0, ());
        while let Some((index, _)) = queue.pop() {
            renderer.stats.nodes_visited += 1;
            let node = &bvh.nodes[index as usize];
            if !frustum.may_see(&node.bounds) {
                continue;
            }
            let query_box = node.bounds.inflated(scene.box_margin);
            let (rect, z_upper) =
                match project_box(&query_box, vp, view.near, view.width, view.height) {
                    BoxView::Outside => continue,
                    BoxView::Near { z_upper } => (viewport, z_upper),
                    BoxView::OnScreen {
                        rect,
                        z_lower,
                        z_upper,
                    } => {
                        if !self.potentially_visible(rect, z_lower, renderer) {
                            continue;
                        }
                        (rect, z_upper)
                    }
                };
            match node.content {
                NodeContent::Leaf { first, count } => {
                    for &object in bvh.leaf_objects(first, count) {
                        renderer.draw_object(object, &scene.objects[object as usize], vp);
                    }
                    self.after_draw(rect, z_upper, renderer);
                }
                NodeContent::Inner { children } => {
                    for child in children {
                        queue.push(bvh, child, ());
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_under_a_rectangle_clip_at_the_viewport() {
        let grid = GridDriver::new(&DriverOptions::new(DriverKind::LazyGrid), 100, 70);
        assert_eq!((grid.columns, grid.rows), (4, 3));
        let under: Vec<(usize, Rect)> = grid.cells_under(Rect::new(60, 30, 40, 40)).collect();
        let indices: Vec<usize> = under.iter().map(|&(i, _)| i).collect();
        assert_eq!(indices, vec![1, 2, 3, 5, 6, 7, 9, 10, 11]);
        assert_eq!(under[2].1, Rect::new(96, 0, 4, 32));
        assert_eq!(under[8].1, Rect::new(96, 64, 4, 6));
    }

    #[test]
    fn probe_answers_tighten_the_bounds() {
        let mut grid = GridDriver::new(&DriverOptions::new(DriverKind::LazyGrid), 64, 64);
        grid.learn(0, 1000, false);
        assert_eq!(grid.cells[0].upper, 1000 + PROBE_SLACK);
        grid.learn(0, 900, true);
        assert_eq!(
            grid.cells[0].lower, DEPTH_ONE,
            "a cleared cell's lower bound stays"
        );
        grid.cells[0].lower = 0;
        grid.learn(0, 900, true);
        assert_eq!(grid.cells[0].lower, 900 - PROBE_SLACK);
    }
}
