//! Collision detection with the Occlusion Unit (seed 001, section 5, "Support for Collision
//! Detection"), after each frame's image.
//!
//! The user moves from this frame's eye to the next one's. The screen is cut into the
//! paper's figure 7 areas, three by three (straight, straight-left, up-right, ...); the area
//! holding the heading's vanishing point is the *check area*. A customised view frustum over
//! the check area, from just beyond the near plane to the step's length in view depth (the
//! far plane the step size sets: anything within one step in any direction through the
//! area lies nearer than that), is drawn in brief mode with back-face culling off, its tiles
//! the check area cut into `collision_tiles` x `collision_tiles` (the paper's "subdivided
//! further"). Its side faces pass through the eye and cover no pixel; its near face passes
//! everywhere; its far face fails exactly where the image holds something nearer than the
//! far plane. So a tile collides when NOHC != PHC. A heading more than 90 degrees from the
//! view direction cannot be tested from this image (the paper: stepping backward needs a
//! second pass): the frame records no test.
//!
//! Choices the paper leaves open: the far plane's depth (the step's length, not its
//! component along the view direction, so the test is conservative for sideways steps), the
//! near face's depth (1% beyond the near plane, inside the clip volume), and the step (the
//! distance to the next frame's eye, or `collision_step` metres).

use super::project::Frustum;
use super::render::{CommandObserver, Renderer};
use super::{DriverOptions, FrameView, Walk, WorkloadScene};
use crate::geometry::to_clip;
use crate::golden::EventSink;
use crate::state::Rect;
use glam::{Vec3, Vec4};

/// One frame's collision test: the step tested and each tile with whether it collides.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CollisionTest {
    /// The far plane's view depth, in metres.
    pub step: f32,
    /// The figure 7 area tested: column and row, 0 to 2 (row 0 at the bottom).
    pub area: (u32, u32),
    pub tiles: Vec<(Rect, bool)>,
}

impl CollisionTest {
    pub fn collides(&self) -> bool {
        self.tiles.iter().any(|&(_, hit)| hit)
    }
}

pub(crate) struct CollisionDriver {
    tiles_per_side: u32,
    step: Option<f32>,
}

impl CollisionDriver {
    pub(crate) fn new(options: &DriverOptions) -> CollisionDriver {
        CollisionDriver {
            tiles_per_side: options.collision_tiles.max(1),
            step: options.collision_step,
        }
    }

    /// The collision test after frame `frame`'s image; None when the heading cannot be
    /// tested from it.
    pub(crate) fn test<S: EventSink, O: CommandObserver>(
        &self,
        frame: u32,
        scene: &WorkloadScene,
        walk: &Walk,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) -> Result<Option<CollisionTest>, S::Error> {
        let Some((area, rect, step)) = self.check_area(frame, scene, walk, view) else {
            return Ok(None);
        };
        let tiles = split(rect, self.tiles_per_side);
        let triangles = frustum_faces(view, rect, view.near * 1.01, step);
        renderer.set_culling(false)?;
        let result = renderer.brief_query(tiles.clone(), triangles)?;
        renderer.set_culling(true)?;
        let Some(result) = result else {
            return Ok(None);
        };
        let tiles = tiles
            .into_iter()
            .zip(&result.tiles)
            .map(|(tile, answer)| (tile, answer.nohc != answer.phc))
            .collect();
        Ok(Some(CollisionTest { step, area, tiles }))
    }

    /// The figure 7 area the heading points into, its rectangle and the step's length.
    fn check_area(
        &self,
        frame: u32,
        scene: &WorkloadScene,
        walk: &Walk,
        view: &FrameView,
    ) -> Option<((u32, u32), Rect, f32)> {
        let heading = heading(frame, scene, walk)?;
        let step = self.step.unwrap_or(heading.length());
        if step.is_nan() || step <= view.near * 1.02 {
            return None;
        }
        let vanishing = view.view_projection * (view.eye + heading.normalize()).extend(1.0);
        if vanishing.w <= 0.0 {
            return None;
        }
        let ndc = |v: f32| ((v / vanishing.w + 1.0) * 0.5).clamp(0.0, 0.999_999);
        let (column, row) = (
            (ndc(vanishing.x) * 3.0) as u32,
            (ndc(vanishing.y) * 3.0) as u32,
        );
        let third = |size: u32, i: u32| (size * i / 3, size * (i + 1) / 3);
        let (x0, x1) = third(view.width, column);
        let (y0, y1) = third(view.height, row);
        if x1 <= x0 || y1 <= y0 {
            return None;
        }
        let far = view.near * super::FAR_OVER_NEAR * 0.99;
        Some((
            (column, row),
            Rect::new(x0, y0, x1 - x0, y1 - y0),
            step.min(far),
        ))
    }
}

/// Where the user moves from frame `frame`'s eye: to the next frame's eye (the last frame
/// keeps the step before it). None when the eye does not move.
fn heading(frame: u32, scene: &WorkloadScene, walk: &Walk) -> Option<Vec3> {
    let eye = |f: u32| scene.frame_view(f, walk).eye;
    let step = if frame + 1 < walk.frames {
        eye(frame + 1) - eye(frame)
    } else if frame > 0 {
        eye(frame) - eye(frame - 1)
    } else {
        return None;
    };
    (step.length() > 0.0).then_some(step)
}

/// `rect` cut into `n` x `n` tiles (fewer where it is narrower than `n` pixels).
fn split(rect: Rect, n: u32) -> Vec<Rect> {
    let (columns, rows) = (n.min(rect.width), n.min(rect.height));
    let cut = |start: u32, size: u32, parts: u32, i: u32| {
        (start + size * i / parts, start + size * (i + 1) / parts)
    };
    (0..rows)
        .flat_map(|r| {
            (0..columns).map(move |c| {
                let (x0, x1) = cut(rect.x, rect.width, columns, c);
                let (y0, y1) = cut(rect.y, rect.height, rows, r);
                Rect::new(x0, y0, x1 - x0, y1 - y0)
            })
        })
        .collect()
}

/// The world point at view depth `depth` on the ray through window position (`x`, `y`).
fn point_at_depth(view: &FrameView, x: f32, y: f32, depth: f32) -> Vec3 {
    let ndc_x = 2.0 * x / view.width as f32 - 1.0;
    let ndc_y = 2.0 * y / view.height as f32 - 1.0;
    let inverse = view.view_projection.inverse();
    let on_ray = inverse * Vec4::new(ndc_x, ndc_y, 0.0, 1.0);
    let on_ray = on_ray.truncate() / on_ray.w;
    let w = (view.view_projection * on_ray.extend(1.0)).w;
    view.eye + (on_ray - view.eye) * (depth / w)
}

/// The six faces (twelve triangles, clip coordinates) of the frustum over `rect` between
/// view depths `near` and `far`.
fn frustum_faces(view: &FrameView, rect: Rect, near: f32, far: f32) -> Vec<[[f32; 4]; 3]> {
    let (x0, x1) = (rect.x as f32, (rect.x + rect.width) as f32);
    let (y0, y1) = (rect.y as f32, (rect.y + rect.height) as f32);
    // Corner k: x from bit 0, y from bit 1, depth from bit 2.
    let corner = |k: usize| {
        let x = if k & 1 == 0 { x0 } else { x1 };
        let y = if k & 2 == 0 { y0 } else { y1 };
        let depth = if k & 4 == 0 { near } else { far };
        to_clip(&view.view_projection, point_at_depth(view, x, y, depth))
    };
    let c: Vec<[f32; 4]> = (0..8).map(corner).collect();
    let quads = [
        [0, 1, 3, 2], // near
        [4, 6, 7, 5], // far
        [0, 4, 5, 1], // bottom
        [2, 3, 7, 6], // top
        [0, 2, 6, 4], // left
        [1, 5, 7, 3], // right
    ];
    quads
        .iter()
        .flat_map(|q| [[c[q[0]], c[q[1]], c[q[2]]], [c[q[0]], c[q[2]], c[q[3]]]])
        .collect()
}

/// The geometric oracle of one collision tile, bounding what the query may answer: `surely`
/// when a front-facing scene triangle covers a pixel centre of the tile by at least a pixel's
/// margin nearer than the far plane (by 0.1%), so its depth, or a nearer one's, is stored
/// there; `possibly` when some triangle's part in front of the near plane reaches over the
/// tile (grown by a pixel) nearer than the far plane (by 0.1%). A query that answers
/// "collides" where not possibly, or "free" where surely, is wrong.
pub fn collision_oracle(
    scene: &WorkloadScene,
    frame: u32,
    walk: &Walk,
    tile: Rect,
    step: f32,
) -> (bool, bool) {
    let view = scene.frame_view(frame, walk);
    let frustum = Frustum::new(&view.view_projection);
    let (mut surely, mut possibly) = (false, false);
    for object in &scene.posed(frame).objects {
        if !frustum.may_see(&object.bounds) {
            continue;
        }
        for triangle in &object.triangles {
            let clip = triangle.map(|p| view.view_projection * p.extend(1.0));
            let (s, p) = triangle_against_tile(&view, &clip, tile, step);
            surely |= s;
            possibly |= p;
            if surely {
                return (true, true);
            }
        }
    }
    (surely, possibly)
}

fn triangle_against_tile(
    view: &FrameView,
    clip: &[Vec4; 3],
    tile: Rect,
    step: f32,
) -> (bool, bool) {
    let near = view.near as f64;
    let polygon = clip_to_near(clip, near);
    if polygon.is_empty() {
        return (false, false);
    }
    let pixel = |v: &Vec4| {
        (
            (v.x as f64 / v.w as f64 + 1.0) * 0.5 * view.width as f64,
            (v.y as f64 / v.w as f64 + 1.0) * 0.5 * view.height as f64,
        )
    };
    let points: Vec<(f64, f64)> = polygon.iter().map(pixel).collect();
    let (mut lo_x, mut hi_x, mut lo_y, mut hi_y) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in &points {
        (lo_x, hi_x, lo_y, hi_y) = (lo_x.min(x), hi_x.max(x), lo_y.min(y), hi_y.max(y));
    }
    let nearest = polygon.iter().map(|v| v.w as f64).fold(f64::MAX, f64::min);
    let far = step as f64;
    let (tx0, tx1) = (tile.x as f64 - 1.0, (tile.x + tile.width) as f64 + 1.0);
    let (ty0, ty1) = (tile.y as f64 - 1.0, (tile.y + tile.height) as f64 + 1.0);
    let possibly = nearest < far * 1.001 && lo_x < tx1 && hi_x > tx0 && lo_y < ty1 && hi_y > ty0;
    if !possibly || polygon.len() != 3 || clip.iter().any(|v| (v.w as f64) <= near) {
        return (false, possibly);
    }
    // Whole triangle in front of the near plane: test the tile's pixel centres.
    let [a, b, c] = [points[0], points[1], points[2]];
    let area = (b.0 - a.0) * (c.1 - a.1) - (c.0 - a.0) * (b.1 - a.1);
    if area <= 0.0 {
        // Back-facing (counter-clockwise is front) or degenerate: culled when drawn.
        return (false, true);
    }
    let edge = |p: (f64, f64), q: (f64, f64), x: f64, y: f64| {
        let length = ((q.0 - p.0).powi(2) + (q.1 - p.1).powi(2)).sqrt();
        ((q.0 - p.0) * (y - p.1) - (q.1 - p.1) * (x - p.0)) / length
    };
    let w = [clip[0].w as f64, clip[1].w as f64, clip[2].w as f64];
    let x_range =
        (tile.x.max(lo_x.max(0.0) as u32))..(tile.x + tile.width).min(hi_x.ceil() as u32 + 1);
    let y_range =
        (tile.y.max(lo_y.max(0.0) as u32))..(tile.y + tile.height).min(hi_y.ceil() as u32 + 1);
    for py in y_range {
        for px in x_range.clone() {
            let (x, y) = (px as f64 + 0.5, py as f64 + 0.5);
            let (ea, eb, ec) = (edge(b, c, x, y), edge(c, a, x, y), edge(a, b, x, y));
            if ea < 1.0 || eb < 1.0 || ec < 1.0 {
                continue;
            }
            // Barycentrics in screen space; 1/w interpolates linearly there.
            let (ba, bb) = (ea / (ea + eb + ec), eb / (ea + eb + ec));
            let bc = 1.0 - ba - bb;
            let depth = 1.0 / (ba / w[0] + bb / w[1] + bc / w[2]);
            if depth < far * 0.999 {
                return (true, true);
            }
        }
    }
    (false, true)
}

/// The part of a clip-space triangle with w >= `near` (Sutherland-Hodgman on one plane).
fn clip_to_near(triangle: &[Vec4; 3], near: f64) -> Vec<Vec4> {
    let mut out = Vec::with_capacity(4);
    for i in 0..3 {
        let (p, q) = (triangle[i], triangle[(i + 1) % 3]);
        let (dp, dq) = (p.w as f64 - near, q.w as f64 - near);
        if dp >= 0.0 {
            out.push(p);
        }
        if (dp >= 0.0) != (dq >= 0.0) {
            let t = (dp / (dp - dq)) as f32;
            out.push(p + (q - p) * t);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_check_area_splits_into_tiles_that_cover_it_once() {
        let rect = Rect::new(10, 20, 7, 5);
        let tiles = split(rect, 3);
        assert_eq!(tiles.len(), 9);
        assert_eq!(tiles.iter().map(|t| t.area()).sum::<u64>(), rect.area());
        assert_eq!(tiles[0], Rect::new(10, 20, 2, 1));
        assert_eq!(tiles[8], Rect::new(14, 23, 3, 2));
        // Narrower than the split: one tile a pixel.
        assert_eq!(split(Rect::new(0, 0, 2, 1), 4).len(), 2);
    }

    #[test]
    fn near_clipping_keeps_the_part_in_front() {
        let v = |w: f32| Vec4::new(0.0, 0.0, 0.0, w);
        // One vertex behind w = 1: a quadrilateral, the cut points at w = 1.
        let out = clip_to_near(&[v(0.0), v(2.0), v(3.0)], 1.0);
        assert_eq!(out.len(), 4);
        assert!(out.iter().all(|p| p.w >= 1.0 - 1e-6));
        assert!(clip_to_near(&[v(0.1), v(0.2), v(0.3)], 1.0).is_empty());
    }
}
