//! Where a world-space box lands on screen: its pixel rectangle and bounds on the window
//! depth of its fragments, and whether it meets the view frustum at all.

use crate::event::DEPTH_ONE;
use crate::geometry::Aabb;
use crate::state::Rect;
use glam::{Mat4, Vec4};

/// Depth units (of 2^-24) allowed for rounding between our projection of a vertex and the
/// rasterizer's interpolated, quantised depth.
const DEPTH_SLACK: u32 = 8;

/// A box seen by the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum BoxView {
    /// No fragment can reach the viewport.
    Outside,
    /// The box reaches the near plane (or behind the eye): no useful bounds, treat it as
    /// visible. `z_upper` bounds the depth of its fragments from above.
    Near { z_upper: u32 },
    /// The box lies in front of the near plane.
    OnScreen {
        /// Holds every pixel a fragment of the box (or anything inside it) may cover.
        rect: Rect,
        /// No fragment of the box, nor of anything inside it, is nearer than this depth.
        z_lower: u32,
        /// No fragment of the box, nor of anything inside it, is farther than this depth.
        z_upper: u32,
    },
}

/// Window depth (0 to 1) of a clip-space point in front of the eye, as the rasterizer
/// maps it, in 24-bit units (unrounded).
fn window_depth_units(clip: Vec4) -> f64 {
    let ndc = clip.z as f64 / clip.w as f64;
    (ndc + 1.0) * 0.5 * DEPTH_ONE as f64
}

pub(crate) fn project_box(
    bounds: &Aabb,
    view_projection: &Mat4,
    near: f32,
    width: u32,
    height: u32,
) -> BoxView {
    let clips = bounds.corners().map(|c| *view_projection * c.extend(1.0));
    let z_upper = |clips: &[Vec4]| {
        let deepest = clips
            .iter()
            .filter(|c| c.w > 0.0)
            .map(|&c| window_depth_units(c))
            .fold(0.0f64, f64::max);
        ((deepest.ceil() as i64 + DEPTH_SLACK as i64).clamp(0, DEPTH_ONE as i64)) as u32
    };
    // w is the distance in front of the eye; a margin keeps rounding at the plane out.
    if clips.iter().any(|c| c.w < near * 1.001) {
        return BoxView::Near {
            z_upper: z_upper(&clips),
        };
    }
    let (mut x_lo, mut x_hi, mut y_lo, mut y_hi) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    let (mut z_lo, mut z_hi) = (f64::MAX, f64::MIN);
    for clip in clips {
        let w = clip.w as f64;
        let (x, y) = (clip.x as f64 / w, clip.y as f64 / w);
        x_lo = x_lo.min(x);
        x_hi = x_hi.max(x);
        y_lo = y_lo.min(y);
        y_hi = y_hi.max(y);
        let z = window_depth_units(clip);
        z_lo = z_lo.min(z);
        z_hi = z_hi.max(z);
    }
    if z_lo > DEPTH_ONE as f64 {
        return BoxView::Outside;
    }
    // One pixel of slack on each side covers the rasterizer's sub-pixel snapping.
    let to_pixel = |ndc: f64, size: u32| (ndc + 1.0) * 0.5 * size as f64;
    let x0 = (to_pixel(x_lo, width).floor() - 1.0).max(0.0);
    let x1 = (to_pixel(x_hi, width).ceil() + 1.0).min(width as f64);
    let y0 = (to_pixel(y_lo, height).floor() - 1.0).max(0.0);
    let y1 = (to_pixel(y_hi, height).ceil() + 1.0).min(height as f64);
    // Written so that NaN (from absurd coordinates) also counts as off screen.
    if !(x1 > x0 && y1 > y0) {
        return BoxView::Outside;
    }
    BoxView::OnScreen {
        rect: Rect::new(x0 as u32, y0 as u32, (x1 - x0) as u32, (y1 - y0) as u32),
        z_lower: (z_lo.floor() as i64 - DEPTH_SLACK as i64).clamp(0, DEPTH_ONE as i64) as u32,
        z_upper: (z_hi.ceil() as i64 + DEPTH_SLACK as i64).clamp(0, DEPTH_ONE as i64) as u32,
    }
}

/// The six planes of the view frustum (inside: dot(plane, (p, 1)) >= 0).
pub(crate) struct Frustum {
    planes: [Vec4; 6],
}

impl Frustum {
    pub(crate) fn new(view_projection: &Mat4) -> Frustum {
        let row = |i| view_projection.row(i);
        let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
        Frustum {
            planes: [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r3 + r2, r3 - r2],
        }
    }

    /// The frustum without its near plane: everything ahead of the eye within the side
    /// and far planes, so a ray is followed from the eye itself.
    pub(crate) fn without_near(view_projection: &Mat4) -> Frustum {
        let mut frustum = Frustum::new(view_projection);
        // 0 x + 0 y + 0 z + 1 >= 0 holds everywhere.
        frustum.planes[4] = Vec4::W;
        frustum
    }

    /// False only when the box lies wholly outside one plane (conservative).
    pub(crate) fn may_see(&self, bounds: &Aabb) -> bool {
        self.planes.iter().all(|plane| {
            let normal = plane.truncate();
            // The corner farthest along the plane's normal.
            let corner = glam::Vec3::select(normal.cmpge(glam::Vec3::ZERO), bounds.max, bounds.min);
            normal.dot(corner) + plane.w >= 0.0
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{look_at, perspective_gl};
    use glam::Vec3;

    fn camera() -> Mat4 {
        perspective_gl(90f32.to_radians(), 1.0, 1.0, 100.0)
            * look_at(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y)
    }

    fn cube_at(centre: Vec3, half: f32) -> Aabb {
        Aabb {
            min: centre - Vec3::splat(half),
            max: centre + Vec3::splat(half),
        }
    }

    #[test]
    fn a_box_ahead_projects_to_its_rectangle_and_depth_range() {
        // Face at z = -9 spans x, y in [-1, 1]: with a 90-degree view at distance 9 that is
        // 1/9 of the half-width, 100 * (0.5 +- 0.5/9) pixels: 44.4 to 55.6.
        let view = project_box(
            &cube_at(Vec3::new(0.0, 0.0, -10.0), 1.0),
            &camera(),
            1.0,
            100,
            100,
        );
        let BoxView::OnScreen {
            rect,
            z_lower,
            z_upper,
        } = view
        else {
            panic!("{view:?}")
        };
        assert_eq!(rect, Rect::new(43, 43, 14, 14));
        // Window depth of eye distance d with near 1, far 100: (101 - 200/d) / 99 / 2 + 0.5.
        let depth = |d: f64| ((100.0 + 1.0) / 99.0 - 200.0 / (99.0 * d)) * 0.5 + 0.5;
        let expected_lower = (depth(9.0) * DEPTH_ONE as f64).floor() as u32 - DEPTH_SLACK;
        let expected_upper = (depth(11.0) * DEPTH_ONE as f64).ceil() as u32 + DEPTH_SLACK;
        assert!(
            z_lower.abs_diff(expected_lower) <= 2,
            "{z_lower} {expected_lower}"
        );
        assert!(
            z_upper.abs_diff(expected_upper) <= 2,
            "{z_upper} {expected_upper}"
        );
    }

    #[test]
    fn boxes_behind_beside_and_at_the_eye() {
        let vp = camera();
        let frustum = Frustum::new(&vp);
        let behind = cube_at(Vec3::new(0.0, 0.0, 10.0), 1.0);
        assert!(!frustum.may_see(&behind));
        let beside = cube_at(Vec3::new(50.0, 0.0, -10.0), 1.0);
        assert!(!frustum.may_see(&beside));
        assert_eq!(project_box(&beside, &vp, 1.0, 100, 100), BoxView::Outside);
        let ahead = cube_at(Vec3::new(0.0, 0.0, -10.0), 1.0);
        assert!(frustum.may_see(&ahead));
        let around_eye = cube_at(Vec3::ZERO, 2.0);
        assert!(frustum.may_see(&around_eye));
        assert!(matches!(
            project_box(&around_eye, &vp, 1.0, 100, 100),
            BoxView::Near { .. }
        ));
    }
}
