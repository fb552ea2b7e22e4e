//! World-space helpers shared by the scene generators: a seedable generator, boxes, and the
//! OpenGL camera transforms. glam lives here and in the generators only, never in the
//! rasterizer.

use crate::state::Rect;
use glam::{Mat4, Vec3, Vec4};

pub(crate) use crate::rng::SplitMix64;

/// An axis-aligned box in world space (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Aabb {
    pub(crate) min: Vec3,
    pub(crate) max: Vec3,
}

impl Aabb {
    pub(crate) fn union(self, other: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// The smallest box holding every point (None for no points).
    pub(crate) fn around(points: impl IntoIterator<Item = Vec3>) -> Option<Aabb> {
        points
            .into_iter()
            .map(|p| Aabb { min: p, max: p })
            .reduce(Aabb::union)
    }

    /// The box grown by `margin` metres on every side.
    pub(crate) fn inflated(self, margin: f32) -> Aabb {
        Aabb {
            min: self.min - Vec3::splat(margin),
            max: self.max + Vec3::splat(margin),
        }
    }

    pub(crate) fn centre(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    pub(crate) fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }

    /// Squared distance from `point` to the box (0 inside).
    pub(crate) fn distance_squared(&self, point: Vec3) -> f32 {
        let nearest = point.clamp(self.min, self.max);
        (point - nearest).length_squared()
    }

    /// The twelve triangles of the box, counter-clockwise seen from outside.
    pub(crate) fn triangles(&self) -> Vec<[Vec3; 3]> {
        let c = self.corners();
        let centre = self.centre();
        // Each face as a quad of corner indices; winding is fixed up below.
        const FACES: [[usize; 4]; 6] = [
            [0, 1, 3, 2],
            [4, 6, 7, 5],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 5, 7, 3],
        ];
        let mut out = Vec::with_capacity(12);
        for face in FACES {
            let [a, b, cc, d] = face.map(|i| c[i]);
            let normal = (b - a).cross(cc - a);
            let outward = (a + cc) * 0.5 - centre;
            let quad = if normal.dot(outward) > 0.0 {
                [a, b, cc, d]
            } else {
                [a, d, cc, b]
            };
            out.push([quad[0], quad[1], quad[2]]);
            out.push([quad[0], quad[2], quad[3]]);
        }
        out
    }
}

/// OpenGL's perspective projection (gluPerspective): right-handed eye space, depth to [-1, 1].
pub(crate) fn perspective_gl(fov_y_radians: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    // libm's tanf, not f32::tan: the platform's libm (or the compiler folding a constant
    // with its own) may differ in the last bit, and scenes must be the same everywhere.
    let f = 1.0 / libm::tanf(fov_y_radians * 0.5);
    Mat4::from_cols(
        Vec4::new(f / aspect, 0.0, 0.0, 0.0),
        Vec4::new(0.0, f, 0.0, 0.0),
        Vec4::new(0.0, 0.0, (far + near) / (near - far), -1.0),
        Vec4::new(0.0, 0.0, 2.0 * far * near / (near - far), 0.0),
    )
}

/// OpenGL's viewing transform (gluLookAt).
pub(crate) fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let forward = (target - eye).normalize();
    let side = forward.cross(up).normalize();
    let up = side.cross(forward);
    Mat4::from_cols(
        Vec4::new(side.x, up.x, -forward.x, 0.0),
        Vec4::new(side.y, up.y, -forward.y, 0.0),
        Vec4::new(side.z, up.z, -forward.z, 0.0),
        Vec4::new(-side.dot(eye), -up.dot(eye), forward.dot(eye), 1.0),
    )
}

/// Clip coordinates of a world point.
pub(crate) fn to_clip(view_projection: &Mat4, point: Vec3) -> [f32; 4] {
    let v: Vec4 = *view_projection * point.extend(1.0);
    [v.x, v.y, v.z, v.w]
}

/// The pixel rectangle a box covers on screen: the whole viewport when it reaches behind
/// the near plane, None when it is off screen.
pub(crate) fn screen_rect(
    bounds: &Aabb,
    view_projection: &Mat4,
    width: u32,
    height: u32,
) -> Option<Rect> {
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for corner in bounds.corners() {
        let clip = *view_projection * corner.extend(1.0);
        if clip.w <= 0.5 {
            return Some(Rect::new(0, 0, width, height));
        }
        let ndc = clip.truncate() / clip.w;
        lo = lo.min(ndc);
        hi = hi.max(ndc);
    }
    let to_pixels = |ndc: f32, size: u32| ((ndc + 1.0) * 0.5 * size as f32).clamp(0.0, size as f32);
    let (x0, x1) = (
        to_pixels(lo.x, width).floor(),
        to_pixels(hi.x, width).ceil(),
    );
    let (y0, y1) = (
        to_pixels(lo.y, height).floor(),
        to_pixels(hi.y, height).ceil(),
    );
    if x1 <= x0 || y1 <= y0 || lo.z > 1.0 {
        return None;
    }
    Some(Rect::new(
        x0 as u32,
        y0 as u32,
        (x1 - x0) as u32,
        (y1 - y0) as u32,
    ))
}

/// A 2x2 quadtree level over `rect` (fewer tiles when it is one pixel wide or high).
pub(crate) fn quad_tiles(rect: Rect) -> Vec<Rect> {
    let (w0, h0) = (rect.width.div_ceil(2), rect.height.div_ceil(2));
    let mut tiles = Vec::with_capacity(4);
    for (y, h) in [(rect.y, h0), (rect.y + h0, rect.height - h0)] {
        for (x, w) in [(rect.x, w0), (rect.x + w0, rect.width - w0)] {
            if w > 0 && h > 0 {
                tiles.push(Rect::new(x, y, w, h));
            }
        }
    }
    tiles
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_triangles_face_outward() {
        let b = Aabb {
            min: Vec3::new(-1.0, -2.0, -3.0),
            max: Vec3::new(1.0, 2.0, 3.0),
        };
        for [a, bb, c] in b.triangles() {
            let normal = (bb - a).cross(c - a);
            let centre_of_triangle = (a + bb + c) / 3.0;
            assert!(
                normal.dot(centre_of_triangle) > 0.0,
                "inward triangle {a} {bb} {c}"
            );
        }
    }

    #[test]
    fn quad_tiles_cover_the_rect_once() {
        for rect in [
            Rect::new(3, 4, 5, 7),
            Rect::new(0, 0, 1, 9),
            Rect::new(2, 2, 1, 1),
        ] {
            let tiles = quad_tiles(rect);
            let area: u64 = tiles.iter().map(Rect::area).sum();
            assert_eq!(area, rect.area());
            for t in &tiles {
                assert_eq!(t.intersect(&rect), *t);
            }
        }
    }

    #[test]
    fn distance_to_a_box() {
        let b = Aabb {
            min: Vec3::ZERO,
            max: Vec3::ONE,
        };
        assert_eq!(b.distance_squared(Vec3::splat(0.5)), 0.0);
        assert_eq!(b.distance_squared(Vec3::new(3.0, 0.5, 0.5)), 4.0);
    }
}
