//! The lazy occlusion grid's occlusion-buffer variant (Hey, Tobler, Purgathofer, sections
//! 3.1, 4.2 and 5), in query form.
//!
//! The occlusion buffer holds one bit a pixel: drawn (occluded) or free. Each cell keeps
//! whether it is *full* (every pixel drawn) and a state: *completely free* (nothing drawn
//! into it), *partially free* (a pixel-level query found a free pixel) or *outdated* (drawn
//! into since). The hardware's pixel-level query (section 5: are all pixels in an area
//! drawn, i.e. is every stored depth below the clear depth) is a brief query drawing a quad
//! over the area just in front of the clear depth with LEQUAL: it has hits exactly where a
//! pixel was never drawn (or was drawn within the probe's slack of the far plane, which
//! counts as free: conservative).
//!
//! The test of a box with screen rectangle `rect` is the paper's figure 2. Cells that are
//! full are skipped; an internal cell (wholly inside `rect`) that is completely or
//! partially free makes the box visible at once, an outdated one waits for a pixel-level
//! query; a border cell that is completely free makes it visible, a partially free or
//! outdated one waits for a pixel-level query over its part inside `rect`. Then the waiting
//! areas are queried: an internal cell with a free pixel becomes partially free (else
//! full), a border part with a free pixel makes its cell partially free; any free pixel
//! makes the box visible. The paper queries one area after another and stops at the first
//! free one; here **all of them go into one brief query** (a tile each), which costs one
//! query's latency instead of several and learns every internal cell's state at once (a
//! choice the paper leaves open: it ran the queries in software on a read-back z-buffer).
//!
//! A depth-free test is only right if everything drawn lies in front of the boxes tested
//! later: the traversal is figure 6's, with two lists, boxes to test by their nearest depth
//! and tested leaves to draw by their farthest; a leaf is drawn only when its farthest depth
//! is strictly nearer than every box still to test (a child lies inside its parent, so no
//! box tested later is nearer), and its cells become outdated. The busy update queries the
//! cells under a leaf right after drawing it.

use super::bvh::NodeContent;
use super::grid::CellLayout;
use super::project::{project_box, BoxView, Frustum};
use super::render::{CommandObserver, Renderer};
use super::{DriverKind, DriverOptions, FrameView, WorkloadScene};
use crate::event::DEPTH_ONE;
use crate::golden::EventSink;
use crate::state::Rect;
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The depth of the pixel-level query's quad: far enough in front of the clear depth that
/// rounding (the grid's probe slack of 3 units, twice over) never hides a free pixel.
const FREE_PROBE_DEPTH: u32 = DEPTH_ONE - 7;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum CellState {
    CompletelyFree,
    PartiallyFree,
    Outdated,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Cell {
    state: CellState,
    /// Every pixel drawn (learned by a pixel-level query; holds until the frame's clear).
    full: bool,
}

const CLEARED: Cell = Cell {
    state: CellState::CompletelyFree,
    full: false,
};

/// What the test of a box needs after the cells' states alone.
#[derive(Debug, PartialEq, Eq)]
enum Pending {
    /// A cell is free without a query: the box is potentially visible.
    Visible,
    /// No cell is free: the box is hidden.
    Hidden,
    /// Query these areas: outdated internal cells whole, partially free or outdated border
    /// cells' parts inside the box.
    Query(Vec<Area>),
}

#[derive(Debug, PartialEq, Eq)]
struct Area {
    cell: usize,
    rect: Rect,
    /// The cell lies wholly inside the box: the query decides whether it is full.
    internal: bool,
}

pub(crate) struct OcclusionBufferGrid {
    busy: bool,
    layout: CellLayout,
    cells: Vec<Cell>,
}

impl OcclusionBufferGrid {
    pub(crate) fn new(options: &DriverOptions, width: u32, height: u32) -> OcclusionBufferGrid {
        let layout = CellLayout::new(options.grid_cell_pixels, width, height);
        OcclusionBufferGrid {
            busy: options.kind == DriverKind::BusyGrid,
            layout,
            cells: vec![CLEARED; layout.cell_count()],
        }
    }

    /// Figure 2 up to its pixel-level queries.
    fn pending(&self, rect: Rect) -> Pending {
        let mut areas = Vec::new();
        for (index, cell_rect) in self.layout.cells_under(rect) {
            let cell = self.cells[index];
            if cell.full {
                continue;
            }
            let part = cell_rect.intersect(&rect);
            let internal = part == cell_rect;
            match (internal, cell.state) {
                (true, CellState::Outdated) => {}
                (true, _) | (false, CellState::CompletelyFree) => return Pending::Visible,
                (false, _) => {}
            }
            areas.push(Area {
                cell: index,
                rect: part,
                internal,
            });
        }
        if areas.is_empty() {
            Pending::Hidden
        } else {
            Pending::Query(areas)
        }
    }

    /// Is a box over `rect` potentially visible? May issue one pixel-level query.
    fn potentially_visible<S: EventSink, O: CommandObserver>(
        &mut self,
        rect: Rect,
        renderer: &mut Renderer<S, O>,
    ) -> Result<bool, S::Error> {
        let areas = match self.pending(rect) {
            Pending::Visible => return Ok(true),
            Pending::Hidden => return Ok(false),
            Pending::Query(areas) => areas,
        };
        self.query(&areas, renderer)
    }

    /// The pixel-level query of `areas` in one brief query, its answers folded into the
    /// cells; whether any area has a free pixel.
    fn query<S: EventSink, O: CommandObserver>(
        &mut self,
        areas: &[Area],
        renderer: &mut Renderer<S, O>,
    ) -> Result<bool, S::Error> {
        let probes: Vec<(Rect, u32)> = areas.iter().map(|a| (a.rect, FREE_PROBE_DEPTH)).collect();
        let Some(result) = renderer.depth_probe(&probes)? else {
            return Ok(true);
        };
        let mut any_free = false;
        for (area, tile) in areas.iter().zip(&result.tiles) {
            let free = tile.nohc > 0;
            any_free |= free;
            self.learn(area, free, &mut renderer.stats.cells_refreshed);
        }
        Ok(any_free)
    }

    fn learn(&mut self, area: &Area, free: bool, refreshed: &mut u64) {
        let cell = &mut self.cells[area.cell];
        if area.internal && cell.state == CellState::Outdated {
            *refreshed += 1;
        }
        if free {
            cell.state = CellState::PartiallyFree;
        } else if area.internal {
            cell.full = true;
        }
    }

    /// After drawing a leaf over `rect`: its cells are outdated; the busy update queries
    /// them at once.
    fn after_draw<S: EventSink, O: CommandObserver>(
        &mut self,
        rect: Rect,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        let mut areas = Vec::new();
        for (index, cell_rect) in self.layout.cells_under(rect) {
            let cell = &mut self.cells[index];
            if !cell.full {
                cell.state = CellState::Outdated;
                areas.push(Area {
                    cell: index,
                    rect: cell_rect,
                    internal: true,
                });
            }
        }
        if self.busy && !areas.is_empty() {
            self.query(&areas, renderer)?;
        }
        Ok(())
    }

    /// One frame: the paper's figure 6.
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
        let frustum = Frustum::new(&view.view_projection);
        let vp = &view.view_projection;
        let viewport = self.layout.viewport();
        // Where a node lands: its rectangle and depth bounds, None when unseen.
        let place = |node: u32| -> Option<(Rect, u32, u32)> {
            let node = &bvh.nodes[node as usize];
            if !frustum.may_see(&node.bounds) {
                return None;
            }
            let query_box = node.bounds.inflated(scene.box_margin);
            match project_box(&query_box, vp, view.near, view.width, view.height) {
                BoxView::Outside => None,
                BoxView::Near { z_upper } => Some((viewport, 0, z_upper)),
                BoxView::OnScreen {
                    rect,
                    z_lower,
                    z_upper,
                } => Some((rect, z_lower, z_upper)),
            }
        };
        // (nearest depth, node) to test; (farthest depth, node) to draw. `places` holds
        // each queued node's rectangle and farthest depth.
        type Heap = BinaryHeap<Reverse<(u32, u32)>>;
        let (mut to_test, mut to_draw): (Heap, Heap) = (BinaryHeap::new(), BinaryHeap::new());
        let mut places: Vec<Option<(Rect, u32)>> = vec![None; bvh.nodes.len()];
        let enqueue = |node: u32, to_test: &mut Heap, places: &mut [Option<(Rect, u32)>]| {
            if let Some((rect, z_lower, z_upper)) = place(node) {
                places[node as usize] = Some((rect, z_upper));
                to_test.push(Reverse((z_lower, node)));
            }
        };
        enqueue(0, &mut to_test, &mut places);
        loop {
            let draw_next = match (to_test.peek(), to_draw.peek()) {
                (None, None) => break,
                (Some(_), None) => false,
                (None, Some(_)) => true,
                (Some(Reverse((near, _))), Some(Reverse((far, _)))) => far < near,
            };
            if draw_next {
                let Reverse((_, node)) = to_draw.pop().expect("peeked");
                let NodeContent::Leaf { first, count } = bvh.nodes[node as usize].content else {
                    unreachable!("only leaves are drawn");
                };
                renderer.draw_leaf(scene, first, count, vp)?;
                let (rect, _) = places[node as usize].expect("a drawn leaf was placed");
                self.after_draw(rect, renderer)?;
                continue;
            }
            let Reverse((_, node)) = to_test.pop().expect("peeked");
            renderer.visit_node();
            let (rect, z_upper) = places[node as usize].expect("a tested node was placed");
            if !self.potentially_visible(rect, renderer)? {
                continue;
            }
            match bvh.nodes[node as usize].content {
                NodeContent::Leaf { .. } => to_draw.push(Reverse((z_upper, node))),
                NodeContent::Inner { children } => {
                    for child in children {
                        enqueue(child, &mut to_test, &mut places);
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

    fn grid(kind: DriverKind) -> OcclusionBufferGrid {
        OcclusionBufferGrid::new(&DriverOptions::new(kind), 64, 64)
    }

    #[test]
    fn cell_states_decide_as_figure_2() {
        let mut grid = grid(DriverKind::LazyGrid);
        let whole = Rect::new(0, 0, 64, 64);
        let part = Rect::new(10, 10, 40, 40);
        // Nothing drawn: visible without a query.
        assert_eq!(grid.pending(whole), Pending::Visible);
        assert_eq!(grid.pending(part), Pending::Visible);
        // All four cells drawn into: internal ones wait for a query, border parts too.
        grid.cells.fill(Cell {
            state: CellState::Outdated,
            full: false,
        });
        let Pending::Query(areas) = grid.pending(whole) else {
            panic!("a query")
        };
        assert_eq!(areas.len(), 4);
        assert!(areas.iter().all(|a| a.internal));
        let Pending::Query(areas) = grid.pending(part) else {
            panic!("a query")
        };
        // The box 10..50 meets each cell in a 22x22 corner, none wholly inside.
        assert_eq!(areas[0].rect, Rect::new(10, 10, 22, 22));
        assert!(areas.iter().all(|a| !a.internal));
        // A partially free internal cell is visible without a query; as a border cell
        // it needs one.
        grid.cells[0].state = CellState::PartiallyFree;
        assert_eq!(grid.pending(Rect::new(0, 0, 32, 32)), Pending::Visible);
        assert!(matches!(grid.pending(part), Pending::Query(_)));
        // Full cells are skipped: all full, the box is hidden.
        grid.cells.fill(Cell {
            state: CellState::Outdated,
            full: true,
        });
        assert_eq!(grid.pending(whole), Pending::Hidden);
        assert_eq!(grid.pending(part), Pending::Hidden);
    }

    #[test]
    fn query_answers_fill_or_free_the_cells() {
        let mut grid = grid(DriverKind::LazyGrid);
        grid.cells.fill(Cell {
            state: CellState::Outdated,
            full: false,
        });
        let mut refreshed = 0;
        let internal = |cell| Area {
            cell,
            rect: Rect::new(0, 0, 32, 32),
            internal: true,
        };
        grid.learn(&internal(0), false, &mut refreshed);
        grid.learn(&internal(1), true, &mut refreshed);
        let border = Area {
            internal: false,
            ..internal(2)
        };
        grid.learn(&border, false, &mut refreshed);
        assert!(grid.cells[0].full);
        assert_eq!(grid.cells[1].state, CellState::PartiallyFree);
        // A border part without a free pixel says nothing of the rest of its cell.
        assert_eq!(
            grid.cells[2],
            Cell {
                state: CellState::Outdated,
                full: false
            }
        );
        assert_eq!(refreshed, 2, "the two internal cells were refreshed");
    }
}
