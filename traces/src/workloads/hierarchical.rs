//! Occlusion-driven rendering (Bartz, Meissner, Huettner 1998, section 3): the hierarchy
//! is traversed front to back; each node's box is drawn in brief mode (it never touches
//! the framebuffer) and the node is opened, or its geometry drawn, only when the box has
//! visible pixels.
//!
//! Options:
//! - a quadtree of tiles per query (the paper's figure 1): the box's rectangle as the root
//!   tile plus `levels` levels of quarters. A child whose rectangle lies in finest tiles
//!   without hits is hidden (it sits behind its parent's box) and is culled without a query.
//! - adaptive culling: a node whose box shows fewer than `threshold` of its projected pixels
//!   (NOHC / PHC) is skipped; this loses pixels, the price of fewer draws.
//! - query delay 1: each node's query is issued every frame it is reached, but the decision
//!   uses the answer of the previous frame (drawing when there is none), as applications
//!   hide query latency.

use super::bvh::NodeContent;
use super::drivers::FrontToBack;
use super::project::{project_box, BoxView, Frustum};
use super::render::{CommandObserver, Renderer};
use super::{DriverOptions, FrameView, WorkloadScene};
use crate::geometry::to_clip;
use crate::golden::EventSink;
use crate::state::Rect;

/// The finest quadtree tiles of a parent's query and whether each had hits.
struct ParentTiles {
    rect: Rect,
    tiles: Vec<(Rect, bool)>,
}

impl ParentTiles {
    /// Does `rect` lie inside the parent's rectangle and meet only tiles without hits?
    fn hides(&self, rect: Rect) -> bool {
        rect.intersect(&self.rect) == rect
            && self
                .tiles
                .iter()
                .all(|(tile, hits)| !hits || tile.intersect(&rect).is_empty())
    }
}

pub(crate) struct HierarchicalDriver {
    levels: u32,
    threshold: Option<f32>,
    delay: u32,
    /// The box tests read the framebuffer back instead of the Occlusion Unit's record.
    virtual_occlusion_buffer: bool,
    /// Per node: the frame of its last query and whether its box passed.
    previous: Vec<Option<(u32, bool)>>,
}

impl HierarchicalDriver {
    pub(crate) fn new(options: &DriverOptions, nodes: usize) -> HierarchicalDriver {
        HierarchicalDriver {
            levels: options.quadtree_levels,
            threshold: options.adaptive_threshold,
            delay: options.query_delay_frames,
            virtual_occlusion_buffer: options.virtual_occlusion_buffer,
            previous: vec![None; nodes],
        }
    }

    /// Does a box with these counts pass (have enough visible pixels)?
    fn passes(&self, nohc: u64, phc: u64) -> bool {
        nohc > 0
            && match self.threshold {
                None => true,
                Some(t) => nohc as f64 >= t as f64 * phc as f64,
            }
    }

    pub(crate) fn frame<S: EventSink, O: CommandObserver>(
        &mut self,
        frame: u32,
        scene: &WorkloadScene,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        let bvh = &scene.bvh;
        if bvh.nodes.is_empty() {
            return Ok(());
        }
        let frustum = Frustum::new(&view.view_projection);
        let mut queue: FrontToBack<Option<ParentTiles>> = FrontToBack::new(view.eye);
        queue.push(bvh, 0, None);
        while let Some((index, parent_tiles)) = queue.pop() {
            renderer.visit_node();
            let node = &bvh.nodes[index as usize];
            if !frustum.may_see(&node.bounds) {
                continue;
            }
            let query_box = node.bounds.inflated(scene.box_margin);
            let vp = &view.view_projection;
            let (visible, tiles_for_children) =
                match project_box(&query_box, vp, view.near, view.width, view.height) {
                    BoxView::Outside => continue,
                    BoxView::Near { .. } => (true, None),
                    BoxView::OnScreen { rect, .. } => {
                        if parent_tiles.as_ref().is_some_and(|p| p.hides(rect)) {
                            renderer.stats.culled_by_parent_tiles += 1;
                            continue;
                        }
                        let tiles = quadtree_tiles(rect, self.levels);
                        let finest_first = tiles.len() - finest_count(&tiles, self.levels);
                        let triangles = query_box
                            .triangles()
                            .into_iter()
                            .map(|t| t.map(|p| to_clip(vp, p)));
                        let answer = renderer.brief_query(tiles.clone(), triangles)?;
                        if self.virtual_occlusion_buffer {
                            // The host reads the box's rectangle back and searches it.
                            renderer.read_back(rect.area());
                        }
                        match answer {
                            None => (true, None),
                            Some(result) => {
                                let root = &result.tiles[0];
                                let now = self.passes(root.nohc, root.phc);
                                let visible = self.decide(index, frame, now);
                                let finest =
                                    (self.delay == 0 && self.levels > 0).then(|| ParentTiles {
                                        rect,
                                        tiles: tiles[finest_first..]
                                            .iter()
                                            .zip(&result.tiles[finest_first..])
                                            .map(|(tile, r)| (*tile, r.nohc > 0))
                                            .collect(),
                                    });
                                (visible, finest)
                            }
                        }
                    }
                };
            if !visible {
                continue;
            }
            match node.content {
                NodeContent::Leaf { first, count } => {
                    renderer.draw_leaf(scene, first, count, vp)?;
                }
                NodeContent::Inner { children } => {
                    for child in children {
                        let hint = tiles_for_children.as_ref().map(|p| ParentTiles {
                            rect: p.rect,
                            tiles: p.tiles.clone(),
                        });
                        queue.push(bvh, child, hint);
                    }
                }
            }
        }
        Ok(())
    }

    /// The verdict to act on: this frame's answer, or with a delay the previous frame's
    /// (draw when there is none), remembering this frame's for the next.
    fn decide(&mut self, node: u32, frame: u32, now: bool) -> bool {
        if self.delay == 0 {
            return now;
        }
        let slot = &mut self.previous[node as usize];
        let verdict = match *slot {
            Some((asked, passed)) if asked + 1 == frame => passed,
            _ => true,
        };
        *slot = Some((frame, now));
        verdict
    }
}

/// Tiles of `levels` quadtree levels below `rect`: the rectangle itself first, then each
/// level's tiles row by row (a level splits the rectangle into 2^level x 2^level parts;
/// parts narrower than a pixel are left out).
pub(crate) fn quadtree_tiles(rect: Rect, levels: u32) -> Vec<Rect> {
    let mut tiles = vec![rect];
    for level in 1..=levels {
        tiles.extend(level_tiles(rect, level));
    }
    tiles
}

fn level_tiles(rect: Rect, level: u32) -> Vec<Rect> {
    let parts = 1u64 << level;
    let cuts = |start: u32, size: u32| -> Vec<(u32, u32)> {
        (0..parts)
            .map(|i| {
                let a = start as u64 + size as u64 * i / parts;
                let b = start as u64 + size as u64 * (i + 1) / parts;
                (a as u32, (b - a) as u32)
            })
            .filter(|&(_, length)| length > 0)
            .collect()
    };
    let (columns, rows) = (cuts(rect.x, rect.width), cuts(rect.y, rect.height));
    rows.iter()
        .flat_map(|&(y, h)| columns.iter().map(move |&(x, w)| Rect::new(x, y, w, h)))
        .collect()
}

/// How many of `tiles` belong to the finest level.
fn finest_count(tiles: &[Rect], levels: u32) -> usize {
    match levels {
        0 => tiles.len(),
        _ => level_tiles(tiles[0], levels).len(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_quadtree_level_covers_the_rectangle_once() {
        for rect in [
            Rect::new(3, 4, 50, 7),
            Rect::new(0, 0, 1, 9),
            Rect::new(2, 2, 1, 1),
        ] {
            let tiles = quadtree_tiles(rect, 3);
            assert_eq!(tiles[0], rect);
            let mut start = 1;
            for level in 1..=3 {
                let level_tiles = level_tiles(rect, level);
                assert_eq!(&tiles[start..start + level_tiles.len()], &level_tiles[..]);
                start += level_tiles.len();
                let area: u64 = level_tiles.iter().map(Rect::area).sum();
                assert_eq!(area, rect.area(), "level {level} of {rect:?}");
                for t in &level_tiles {
                    assert_eq!(t.intersect(&rect), *t);
                }
            }
            assert_eq!(start, tiles.len());
        }
        assert_eq!(quadtree_tiles(Rect::new(0, 0, 64, 64), 2).len(), 1 + 4 + 16);
        assert_eq!(
            finest_count(&quadtree_tiles(Rect::new(0, 0, 64, 64), 2), 2),
            16
        );
    }

    #[test]
    fn parent_tiles_hide_only_what_lies_in_tiles_without_hits() {
        let parent = ParentTiles {
            rect: Rect::new(0, 0, 20, 20),
            tiles: vec![
                (Rect::new(0, 0, 10, 20), false),
                (Rect::new(10, 0, 10, 20), true),
            ],
        };
        assert!(parent.hides(Rect::new(2, 2, 8, 8)));
        assert!(
            !parent.hides(Rect::new(2, 2, 9, 8)),
            "reaches the tile with hits"
        );
        assert!(
            !parent.hides(Rect::new(2, 2, 8, 30)),
            "reaches outside the parent"
        );
    }
}
