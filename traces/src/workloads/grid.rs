//! The lazy occlusion grid (Hey, Tobler, Purgathofer), z-buffer variant, in query form.
//!
//! The screen is cut into cells (32x32 pixels by default); each cell keeps `zfar`, the
//! farthest depth of its pixels, and whether it is outdated (drawn into since its last
//! refresh). Occlusion hardware reports fragment depths, not stored ones, so a refresh is a
//! *depth probe*: a brief query drawing over the cell a screen-aligned quad at a chosen
//! depth with LEQUAL, which has hits exactly where some stored depth is at least the quad's.
//!
//! A cell keeps two bounds on its stored depths, learned from probes: `upper` (no stored
//! depth exceeds it; drawing only lowers depths, so it holds until the frame's clear) and
//! `lower` (some stored depth reaches it; a draw into the cell voids it: the cell is
//! *outdated*). It also keeps `pending`, the farthest depth of anything drawn into it this
//! frame (from the drawn boxes' projections).
//!
//! A refresh probes a whole cell. At `pending` (when the tested box lies behind all that
//! was drawn into the cell): no hit means every pixel is covered, `zfar <= pending`; a hit
//! means some pixel was never drawn, `zfar` is the clear depth 1.0: one probe gives the
//! paper's refresh, exact up to the drawn boxes' depths. Otherwise the probe sits just in
//! front of the tested box and bounds `zfar` on the side that decides the box.
//!
//! A box whose fragments lie no nearer than `z` is tested as in the paper's figure 3:
//! - every cell meeting its rectangle: hidden where `z > upper`, potentially visible where
//!   the cell is untouched (all depths 1.0);
//! - internal cells (wholly inside the rectangle): potentially visible where `z <= lower`,
//!   else refreshed;
//! - border cells: potentially visible where a pixel was never drawn (`lower` is 1.0, the
//!   paper's `zfar = zmax`), else a probe at `z` over the part of the cell inside the
//!   rectangle decides (the paper's pixel-level query on cell and box).
//!
//! All the probes one box needs go into **one** brief query whose tiles are those cells (or
//! parts), each with its own quad, so one query tests many cells on many engines. Culling
//! is conservative: a box is culled only where its fragments would all fail the depth test.
//!
//! The lazy grid marks the cells under a drawn object outdated; the busy grid refreshes
//! them at once after every draw, at their pending depths.

use super::bvh::NodeContent;
use super::drivers::FrontToBack;
use super::project::{project_box, BoxView, Frustum};
use super::render::{CommandObserver, Renderer};
use super::{DriverKind, DriverOptions, FrameStats, FrameView, WorkloadScene};
use crate::event::DEPTH_ONE;
use crate::golden::EventSink;
use crate::state::Rect;

/// Depth units a probe quad's fragments may land away from the depth asked for (f32 clip
/// coordinates, the viewport transform and quantisation each round).
const PROBE_SLACK: u32 = 3;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Cell {
    /// No stored depth in the cell exceeds this (24-bit units): the paper's zfar, bounded.
    upper: u32,
    /// Some stored depth in the cell reaches this (0: unknown, the cell is outdated).
    lower: u32,
    /// Nothing drawn into the cell this frame lies deeper than this.
    pending: u32,
    /// Drawn into this frame.
    touched: bool,
    /// Drawn into since its last whole-cell probe (the next one is a refresh).
    outdated: bool,
}

const CLEARED: Cell = Cell {
    upper: DEPTH_ONE,
    lower: DEPTH_ONE,
    pending: 0,
    touched: false,
    outdated: false,
};

/// What one cell says about a box.
#[derive(Debug, PartialEq, Eq)]
enum CellVerdict {
    Hidden,
    Visible,
    /// Refresh the whole cell with a probe at this depth.
    Refresh(u32),
    /// Probe this part of the cell (inside the box's rectangle) just in front of the box.
    ProbePart(Rect),
}

/// The screen cut into square cells of `cell` pixels (the last column and row clipped to
/// the viewport): the geometry both grid variants share.
#[derive(Clone, Copy, Debug)]
pub(crate) struct CellLayout {
    /// Cell side in pixels.
    pub(crate) cell: u32,
    pub(crate) columns: u32,
    pub(crate) rows: u32,
    width: u32,
    height: u32,
}

impl CellLayout {
    pub(crate) fn new(cell: u32, width: u32, height: u32) -> CellLayout {
        let cell = cell.max(1);
        CellLayout {
            cell,
            columns: width.div_ceil(cell),
            rows: height.div_ceil(cell),
            width,
            height,
        }
    }

    pub(crate) fn cell_count(&self) -> usize {
        self.columns as usize * self.rows as usize
    }

    pub(crate) fn viewport(&self) -> Rect {
        Rect::new(0, 0, self.width, self.height)
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

    /// Indices and rectangles of the cells meeting `rect` (non-empty, inside the viewport),
    /// row by row.
    pub(crate) fn cells_under(&self, rect: Rect) -> impl Iterator<Item = (usize, Rect)> + '_ {
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
}

pub(crate) struct GridDriver {
    busy: bool,
    layout: CellLayout,
    cells: Vec<Cell>,
}

impl GridDriver {
    pub(crate) fn new(options: &DriverOptions, width: u32, height: u32) -> GridDriver {
        let layout = CellLayout::new(options.grid_cell_pixels, width, height);
        GridDriver {
            busy: options.kind == DriverKind::BusyGrid,
            layout,
            cells: vec![CLEARED; layout.cell_count()],
        }
    }

    fn cells_under(&self, rect: Rect) -> impl Iterator<Item = (usize, Rect)> + '_ {
        self.layout.cells_under(rect)
    }

    /// Depth of a probe whose fragments lie just behind everything drawn into a cell with
    /// this pending depth.
    fn behind_pending(pending: u32) -> u64 {
        pending as u64 + PROBE_SLACK as u64 + 1
    }

    fn verdict(&self, cell: &Cell, cell_rect: Rect, rect: Rect, z_lower: u32) -> CellVerdict {
        if z_lower > cell.upper {
            return CellVerdict::Hidden;
        }
        if !cell.touched {
            return CellVerdict::Visible;
        }
        let part = cell_rect.intersect(&rect);
        if part != cell_rect {
            return match cell.lower {
                DEPTH_ONE => CellVerdict::Visible,
                _ => CellVerdict::ProbePart(part),
            };
        }
        if z_lower <= cell.lower {
            return CellVerdict::Visible;
        }
        let behind = GridDriver::behind_pending(cell.pending);
        if behind + (PROBE_SLACK as u64) < z_lower as u64 {
            CellVerdict::Refresh(behind as u32)
        } else {
            CellVerdict::Refresh(z_lower - PROBE_SLACK - 1)
        }
    }

    /// Is a box with screen rectangle `rect` and fragments no nearer than `z_lower`
    /// potentially visible? May issue one probe query.
    fn potentially_visible<S: EventSink, O: CommandObserver>(
        &mut self,
        rect: Rect,
        z_lower: u32,
        renderer: &mut Renderer<S, O>,
    ) -> Result<bool, S::Error> {
        // A probe needs room in front of the box for its slack.
        if z_lower <= 2 * PROBE_SLACK + 1 {
            return Ok(true);
        }
        let mut refreshed = Vec::new();
        let mut probes = Vec::new();
        for (index, cell_rect) in self.cells_under(rect) {
            let cell = self.cells[index];
            match self.verdict(&cell, cell_rect, rect, z_lower) {
                CellVerdict::Hidden => {}
                CellVerdict::Visible => return Ok(true),
                CellVerdict::Refresh(depth) => {
                    refreshed.push((index, depth, probes.len()));
                    probes.push((cell_rect, depth));
                }
                CellVerdict::ProbePart(part) => {
                    probes.push((part, z_lower - PROBE_SLACK - 1));
                }
            }
        }
        if probes.is_empty() {
            return Ok(false);
        }
        let Some(result) = renderer.depth_probe(&probes)? else {
            return Ok(true);
        };
        for (index, depth, tile) in refreshed {
            self.learn(
                index,
                depth,
                result.tiles[tile].nohc > 0,
                &mut renderer.stats,
            );
        }
        Ok(result.tiles.iter().any(|tile| tile.nohc > 0))
    }

    /// Fold a whole-cell probe at `depth` into the cell's bounds. Probe fragments lie within
    /// `PROBE_SLACK` of `depth`: a hit means some stored depth is at least `depth - slack`,
    /// and when that is deeper than all that was drawn, a pixel was never drawn (1.0); no
    /// hit means every stored depth is below `depth + slack`.
    fn learn(&mut self, index: usize, depth: u32, hit: bool, stats: &mut FrameStats) {
        let cell = &mut self.cells[index];
        if cell.outdated {
            stats.cells_refreshed += 1;
            cell.outdated = false;
        }
        if !hit {
            cell.upper = cell.upper.min(depth + PROBE_SLACK);
        } else if depth - PROBE_SLACK > cell.pending {
            cell.lower = DEPTH_ONE;
        } else {
            cell.lower = cell.lower.max(depth - PROBE_SLACK);
        }
    }

    /// After drawing into `rect` things no deeper than `z_upper`: outdate the cells, and
    /// for the busy grid refresh them at once.
    fn after_draw<S: EventSink, O: CommandObserver>(
        &mut self,
        rect: Rect,
        z_upper: u32,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        let under: Vec<(usize, Rect)> = self.cells_under(rect).collect();
        for &(index, _) in &under {
            let cell = &mut self.cells[index];
            cell.touched = true;
            cell.outdated = true;
            cell.lower = 0;
            cell.pending = cell.pending.max(z_upper);
        }
        if !self.busy {
            return Ok(());
        }
        let mut refreshed = Vec::new();
        let mut probes = Vec::new();
        for (index, cell_rect) in under {
            let cell = self.cells[index];
            let depth = GridDriver::behind_pending(cell.pending);
            // A probe that could not lower the bound is not worth a tile.
            if depth + (PROBE_SLACK as u64) < cell.upper as u64 {
                refreshed.push((index, depth as u32));
                probes.push((cell_rect, depth as u32));
            } else {
                self.cells[index].outdated = false;
            }
        }
        if probes.is_empty() {
            return Ok(());
        }
        if let Some(result) = renderer.depth_probe(&probes)? {
            for (&(index, depth), tile) in refreshed.iter().zip(&result.tiles) {
                self.learn(index, depth, tile.nohc > 0, &mut renderer.stats);
            }
        }
        Ok(())
    }

    /// One frame: the paper's figure 4, front to back through the hierarchy.
    pub(crate) fn frame<S: EventSink, O: CommandObserver>(
        &mut self,
        scene: &WorkloadScene,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        self.cells.fill(CLEARED);
        let bvh = &scene.bvh;
        if bvh.nodes.is_empty() {
            return Ok(());
        }
        let viewport = self.layout.viewport();
        let frustum = Frustum::new(&view.view_projection);
        let vp = &view.view_projection;
        let mut queue = FrontToBack::new(view.eye);
        queue.push(bvh, 0, ());
        while let Some((index, _)) = queue.pop() {
            renderer.visit_node();
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
                        if !self.potentially_visible(rect, z_lower, renderer)? {
                            continue;
                        }
                        (rect, z_upper)
                    }
                };
            match node.content {
                NodeContent::Leaf { first, count } => {
                    renderer.draw_leaf(scene, first, count, vp)?;
                    self.after_draw(rect, z_upper, renderer)?;
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
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_under_a_rectangle_clip_at_the_viewport() {
        let grid = GridDriver::new(&DriverOptions::new(DriverKind::LazyGrid), 100, 70);
        assert_eq!((grid.layout.columns, grid.layout.rows), (4, 3));
        let under: Vec<(usize, Rect)> = grid.cells_under(Rect::new(60, 30, 40, 40)).collect();
        let indices: Vec<usize> = under.iter().map(|&(i, _)| i).collect();
        assert_eq!(indices, vec![1, 2, 3, 5, 6, 7, 9, 10, 11]);
        assert_eq!(under[2].1, Rect::new(96, 0, 4, 32));
        assert_eq!(under[8].1, Rect::new(96, 64, 4, 6));
    }

    #[test]
    fn cell_verdicts_follow_figure_3() {
        let grid = GridDriver::new(&DriverOptions::new(DriverKind::LazyGrid), 64, 64);
        let cell_rect = Rect::new(0, 0, 32, 32);
        let whole = Rect::new(0, 0, 64, 64);
        let part = Rect::new(10, 10, 40, 40);
        let verdict = |cell: Cell, rect: Rect, z: u32| grid.verdict(&cell, cell_rect, rect, z);
        assert_eq!(verdict(CLEARED, whole, 5000), CellVerdict::Visible);
        let drawn = Cell {
            upper: DEPTH_ONE,
            lower: 0,
            pending: 1000,
            touched: true,
            outdated: true,
        };
        let behind = 1000 + PROBE_SLACK + 1;
        assert_eq!(
            verdict(drawn, whole, 2000),
            CellVerdict::Refresh(behind),
            "behind all drawn"
        );
        assert_eq!(
            verdict(drawn, whole, 1005),
            CellVerdict::Refresh(1005 - PROBE_SLACK - 1)
        );
        assert_eq!(
            verdict(drawn, part, 2000),
            CellVerdict::ProbePart(Rect::new(10, 10, 22, 22))
        );
        let bounded = Cell {
            upper: 1007,
            ..drawn
        };
        assert_eq!(verdict(bounded, whole, 1008), CellVerdict::Hidden);
        assert_eq!(verdict(bounded, part, 1008), CellVerdict::Hidden);
        let with_gap = Cell {
            lower: DEPTH_ONE,
            ..drawn
        };
        assert_eq!(verdict(with_gap, part, 2000), CellVerdict::Visible);
        assert_eq!(verdict(with_gap, whole, 2000), CellVerdict::Visible);
    }

    #[test]
    fn probe_answers_tighten_the_bounds() {
        let mut grid = GridDriver::new(&DriverOptions::new(DriverKind::LazyGrid), 64, 64);
        let drawn = Cell {
            upper: DEPTH_ONE,
            lower: 0,
            pending: 1000,
            touched: true,
            outdated: true,
        };
        let mut stats = FrameStats::default();
        grid.cells[0] = drawn;
        grid.learn(0, 900, true, &mut stats);
        assert_eq!(grid.cells[0].lower, 900 - PROBE_SLACK);
        grid.learn(0, 1010, true, &mut stats);
        assert_eq!(
            grid.cells[0].lower, DEPTH_ONE,
            "a pixel deeper than all drawn: never drawn"
        );
        assert_eq!(
            stats.cells_refreshed, 1,
            "only the first probe refreshed an outdated cell"
        );
        grid.cells[0] = drawn;
        grid.learn(0, 1010, false, &mut stats);
        assert_eq!(grid.cells[0].upper, 1010 + PROBE_SLACK);
    }
}
