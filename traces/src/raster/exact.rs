//! The `exact` profile: occsim's own rasterizer, exact where llvmpipe rounds.
//!
//! 1. **Clipping** (module `clip`) in clip space, f32: near (z >= -w) and far (z <= w) always,
//!    and a guard band in x/y (|x|, |y| <= g·w, g = 2^17 / side - 2 per axis) only when a
//!    vertex lies outside it. Sutherland-Hodgman, near and far first, the result fanned from
//!    its first vertex (p0, pi, pi+1). An edge's intersection is computed from its endpoints in
//!    a canonical (bitwise) order, so two triangles sharing an edge get bit-identical new
//!    vertices, and the clipped coordinate is set exactly onto its plane.
//! 2. **Window coordinates**, f32: `inv_w = 1 / w`, `n = c · inv_w`, `window = fma(n, side/2,
//!    side/2)` for x and y, and `fma(n_z, 0.5, 0.5)` for z (depth range 0..1).
//! 3. **Snapping** to 8 sub-pixel bits: `X = round_ties_even((x_window - 0.5) · 256)`, the
//!    subtraction in f32.
//! 4. **Setup**: twice the signed area `D` from the snapped vertices; `D == 0` draws nothing;
//!    with `cull_back`, clockwise triangles (`D < 0`, GL window coordinates, y up) are culled;
//!    otherwise clockwise triangles are reoriented. `RasterSink::primitive` is called here.
//! 5. **Coverage**: the shared integer walk ([`super::coverage`]).
//!
//! # Depth
//!
//! Each vertex's window z is quantised to `zq = round(z · (2^24 - 1) · 2^8)` (24-bit unorm
//! with 8 extra fraction bits, ties up, computed exactly from the f32's bits). The plane
//! through the three (X, Y, zq) is evaluated exactly at each pixel centre and rounded to
//! nearest (ties up) unorm24: `depth = round(Z / 2^8)`, clamped to [0, 2^24 - 1]. A vertex at
//! depth exactly 0 or 1 gives 0 or 2^24 - 1 at a pixel centre on it. No f32 rounding enters
//! after snapping, so depth is a function of the snapped triangle alone: a rational oracle
//! (traces/tests/raster_hardcases.rs) checks it.
//!
//! # Integer ranges (viewport sides up to [`MAX_VIEWPORT_SIDE`] = 2^14)
//!
//! The guard band keeps |x/w| <= g = 2^17/side - 2, so |x_window| <= (g + 1)·side/2 <
//! 2^16, and snapped |X|, |Y| < 2^24 + 2^8 (f32 rounding of clipped vertices is far below a
//! pixel). Hence:
//! - twice the area D < 2^51;
//! - zq <= (2^24 - 1)·2^8 < 2^32; plane coefficients |A|, |B| < 2·2^32·2^25 = 2^58;
//!   the numerator 2·(zq0·D + A·dx + B·dy) + 2^8·D < 2^86 is formed in i128 once per row;
//!   per pixel only a quotient (the depth, < 2^24 on covered pixels) and a remainder below
//!   the divisor 2^9·D < 2^60 are stepped, in i64, without division.

use super::coverage::{self, doubled_area, Point, SpanDepths, PIXEL};
use super::{RasterSink, SUBPIXEL_BITS};
use crate::event::{Fragment, DEPTH_ONE};
use crate::state::{RenderState, MAX_VIEWPORT_SIDE};

/// Extra fraction bits of quantised vertex depth below one unorm24 unit.
pub const DEPTH_EXTRA_BITS: u32 = 8;

/// Rasterize one triangle given in clip coordinates under `state`.
pub(super) fn rasterize_triangle(
    state: &RenderState,
    vertices: &[[f32; 4]; 3],
    sink: &mut impl RasterSink,
) {
    debug_assert!(state.width <= MAX_VIEWPORT_SIDE && state.height <= MAX_VIEWPORT_SIDE);
    let guard = clip::GuardBand::for_viewport(state.width, state.height);
    let mut polygon = clip::Polygon::from_triangle(vertices);
    if !polygon.clip(&guard) {
        return;
    }
    let clipped = polygon.vertices();
    let mut window = [None; clip::MAX_VERTICES];
    for (slot, vertex) in window.iter_mut().zip(clipped) {
        *slot = WindowVertex::from_clip(vertex, state);
    }
    let window = &window[..clipped.len()];
    for i in 1..window.len().saturating_sub(1) {
        if let (Some(a), Some(b), Some(c)) = (window[0], window[i], window[i + 1]) {
            rasterize_snapped(state, [a, b, c], sink);
        }
    }
}

/// A vertex after perspective divide, viewport transform and snapping.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct WindowVertex {
    /// Snapped position.
    at: Point,
    /// Quantised depth: unorm24 with [`DEPTH_EXTRA_BITS`] fraction bits.
    z: i64,
}

impl WindowVertex {
    /// None when the vertex has no finite window position (w <= 0 after clipping).
    fn from_clip(v: &[f32; 4], state: &RenderState) -> Option<WindowVertex> {
        if v[3] <= 0.0 || !v[3].is_finite() {
            return None;
        }
        let inv_w = 1.0f32 / v[3];
        let half_width = state.width as f32 * 0.5;
        let half_height = state.height as f32 * 0.5;
        let x = (v[0] * inv_w).mul_add(half_width, half_width);
        let y = (v[1] * inv_w).mul_add(half_height, half_height);
        let z = (v[2] * inv_w).mul_add(0.5, 0.5);
        if !(x.is_finite() && y.is_finite() && z.is_finite()) {
            return None;
        }
        Some(WindowVertex {
            at: Point {
                x: snap(x),
                y: snap(y),
            },
            z: quantise_depth(z),
        })
    }
}

/// Subtract the pixel-centre offset in f32, scale by 2^8 (exact), round half to even.
fn snap(window: f32) -> i64 {
    ((window - 0.5) * (1 << SUBPIXEL_BITS) as f32).round_ties_even() as i64
}

/// `round(z · (2^24 - 1) · 2^8)` for z clamped to [0, 1], ties up, exactly.
fn quantise_depth(z: f32) -> i64 {
    let full = (DEPTH_ONE as i64) << DEPTH_EXTRA_BITS;
    if z.is_nan() || z <= 0.0 {
        return 0;
    }
    if z >= 1.0 {
        return full;
    }
    let bits = z.to_bits();
    let exponent = ((bits >> 23) & 0xff) as i32;
    let fraction = (bits & 0x7f_ffff) as u128;
    // z = mantissa · 2^-shift exactly.
    let (mantissa, shift) = if exponent == 0 {
        (fraction, 149)
    } else {
        (fraction | 1 << 23, 150 - exponent)
    };
    let product = mantissa * full as u128;
    if shift >= 127 {
        return 0;
    }
    ((product + (1u128 << (shift - 1))) >> shift) as i64
}

mod clip {
    //! Sutherland-Hodgman clipping in clip space against near, far and the x/y guard band.

    /// Most vertices a triangle clipped by six planes can have.
    pub const MAX_VERTICES: usize = 3 + 6;

    /// x/y guard-band factors: a vertex is kept unclipped while |x| <= gx·w, |y| <= gy·w.
    pub struct GuardBand {
        gx: f32,
        gy: f32,
    }

    impl GuardBand {
        /// g = 2^17 / side - 2 keeps window coordinates below 2^16 in magnitude.
        pub fn for_viewport(width: u32, height: u32) -> GuardBand {
            let factor = |side: u32| (131072.0 / side.max(1) as f64 - 2.0) as f32;
            GuardBand {
                gx: factor(width),
                gy: factor(height),
            }
        }
    }

    /// A clip plane: signed distance `a·v`, inside when >= 0.
    type Plane = [f32; 4];

    pub struct Polygon {
        vertices: [[f32; 4]; MAX_VERTICES],
        count: usize,
    }

    impl Polygon {
        pub fn from_triangle(t: &[[f32; 4]; 3]) -> Polygon {
            let mut vertices = [[0.0; 4]; MAX_VERTICES];
            vertices[..3].copy_from_slice(t);
            Polygon { vertices, count: 3 }
        }

        pub fn vertices(&self) -> &[[f32; 4]] {
            &self.vertices[..self.count]
        }

        /// Clip in place; false when nothing is left.
        pub fn clip(&mut self, guard: &GuardBand) -> bool {
            let planes: [Plane; 6] = [
                [0.0, 0.0, 1.0, 1.0],      // near: z + w >= 0
                [0.0, 0.0, -1.0, 1.0],     // far: w - z >= 0
                [1.0, 0.0, 0.0, guard.gx], // x >= -gx·w
                [-1.0, 0.0, 0.0, guard.gx],
                [0.0, 1.0, 0.0, guard.gy],
                [0.0, -1.0, 0.0, guard.gy],
            ];
            for plane in &planes {
                if !self.clip_plane(plane) {
                    return false;
                }
            }
            true
        }

        fn clip_plane(&mut self, plane: &Plane) -> bool {
            let distance = |v: &[f32; 4]| {
                plane[0] * v[0] + plane[1] * v[1] + plane[2] * v[2] + plane[3] * v[3]
            };
            // Each vertex's side, decided once (a NaN distance is outside).
            let count = self.count;
            let inside: [bool; MAX_VERTICES] =
                std::array::from_fn(|i| i < count && distance(&self.vertices[i]) >= 0.0);
            if inside[..count].iter().all(|&inside| inside) {
                return true;
            }
            // A convex polygon gains at most one vertex a plane, so six planes leave a
            // triangle at most nine; one that rounding has made crossing a plane more than
            // twice could pass the room, and is dropped as the degenerate thing it is.
            let crosses = |i: usize| inside[i] != inside[(i + 1) % count];
            let kept = (0..count).filter(|&i| inside[i]).count();
            if kept + (0..count).filter(|&i| crosses(i)).count() > MAX_VERTICES {
                return false;
            }
            let mut out = [[0.0f32; 4]; MAX_VERTICES];
            let mut n = 0;
            for (i, &current) in self.vertices[..count].iter().enumerate() {
                if inside[i] {
                    out[n] = current;
                    n += 1;
                }
                if crosses(i) {
                    out[n] = intersect(&current, &self.vertices[(i + 1) % count], plane);
                    n += 1;
                }
            }
            self.vertices = out;
            self.count = n;
            n >= 3
        }
    }

    /// The point where the edge a-b crosses the plane, computed from the endpoints in a
    /// canonical order so the same edge always gives the same bits.
    fn intersect(a: &[f32; 4], b: &[f32; 4], plane: &Plane) -> [f32; 4] {
        let distance =
            |v: &[f32; 4]| plane[0] * v[0] + plane[1] * v[1] + plane[2] * v[2] + plane[3] * v[3];
        let key = |v: &[f32; 4]| v.map(f32::to_bits);
        let (p, q) = if key(a) <= key(b) { (a, b) } else { (b, a) };
        let (dp, dq) = (distance(p), distance(q));
        let t = dp / (dp - dq);
        let mut v = [0.0f32; 4];
        for k in 0..4 {
            v[k] = p[k] + t * (q[k] - p[k]);
        }
        // Put the clipped coordinate exactly on the plane (s·v[axis] + a_w·w = 0): with huge
        // endpoints the interpolation's rounding could otherwise throw it far off.
        if let Some(axis) = (0..3).find(|&k| plane[k] != 0.0) {
            v[axis] = -plane[axis] * plane[3] * v[3];
        }
        v
    }
}

/// Setup and coverage of one snapped triangle.
fn rasterize_snapped(state: &RenderState, mut v: [WindowVertex; 3], sink: &mut impl RasterSink) {
    let area = doubled_area(&v.map(|p| p.at));
    if area == 0 || (area < 0 && state.cull_back) {
        return;
    }
    if area < 0 {
        v.swap(1, 2);
    }
    sink.primitive();
    let plane = DepthPlane::new(&v, area.abs());
    coverage::walk_triangle(state, &v.map(|p| p.at), &plane, sink);
}

/// The depth plane, kept as an exact rational stepped by quotient and remainder.
struct DepthPlane {
    a: i128,
    b: i128,
    origin: Point,
    /// 2^(extra bits + 1) · D: the divisor of the doubled numerator.
    divisor: i64,
    /// zq0 · D · 2 + 2^extra · D: the numerator at the origin (doubled, plus half).
    base: i128,
    /// Per pixel step in x of the numerator, as quotient and remainder by `divisor`.
    step_quotient: i64,
    step_remainder: i64,
}

impl DepthPlane {
    fn new(v: &[WindowVertex; 3], area: i64) -> DepthPlane {
        let (x1, y1, z1) = (
            v[1].at.x - v[0].at.x,
            v[1].at.y - v[0].at.y,
            v[1].z - v[0].z,
        );
        let (x2, y2, z2) = (
            v[2].at.x - v[0].at.x,
            v[2].at.y - v[0].at.y,
            v[2].z - v[0].z,
        );
        let a = z1 as i128 * y2 as i128 - z2 as i128 * y1 as i128;
        let b = z2 as i128 * x1 as i128 - z1 as i128 * x2 as i128;
        let d = area as i128;
        let divisor = (d << (DEPTH_EXTRA_BITS + 1)) as i64;
        let base = 2 * v[0].z as i128 * d + (d << DEPTH_EXTRA_BITS);
        let step = 2 * a * PIXEL as i128;
        DepthPlane {
            a,
            b,
            origin: v[0].at,
            divisor,
            base,
            step_quotient: step.div_euclid(divisor as i128) as i64,
            step_remainder: step.rem_euclid(divisor as i128) as i64,
        }
    }

    /// Quotient (the rounded depth) and remainder at the centre of pixel (px, py).
    fn at(&self, px: i64, py: i64) -> (i64, i64) {
        let dx = (px * PIXEL - self.origin.x) as i128;
        let dy = (py * PIXEL - self.origin.y) as i128;
        let numerator = self.base + 2 * (self.a * dx + self.b * dy);
        let divisor = self.divisor as i128;
        (
            numerator.div_euclid(divisor) as i64,
            numerator.rem_euclid(divisor) as i64,
        )
    }
}

impl SpanDepths for DepthPlane {
    #[inline(always)]
    fn emit(&self, py: i64, first: i64, last: i64, sink: &mut impl RasterSink) {
        let (mut depth, mut remainder) = self.at(first, py);
        let (step_q, step_r, divisor) = (self.step_quotient, self.step_remainder, self.divisor);
        let y = py as u16;
        for px in first..=last {
            sink.fragment(Fragment {
                x: px as u16,
                y,
                z: depth.clamp(0, DEPTH_ONE as i64) as u32,
            });
            depth += step_q;
            remainder += step_r;
            if remainder >= divisor {
                remainder -= divisor;
                depth += 1;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::clip::{GuardBand, Polygon};
    use super::*;

    #[test]
    fn a_triangle_that_rounding_makes_cross_a_plane_too_often_is_dropped_not_a_panic() {
        // Found by feeding extreme finite coordinates to the rasterizer (scene line `tri
        // -8e-22 0 0 -6e-25  1e37 0 1 1  -1 1 1 1e28` in a 256x256 viewport): its clipped
        // points, put on one plane, fall on both sides of the next as rounded, so the
        // polygon crosses a plane more than twice and would need a tenth vertex.
        let triangle = [
            [-8e-22, 0.0, 0.0, -6e-25],
            [1e37, 0.0, 1.0, 1.0],
            [-1.0, 1.0, 1.0, 1e28],
        ];
        assert!(!Polygon::from_triangle(&triangle).clip(&GuardBand::for_viewport(256, 256)));
        struct Count(u64);
        impl RasterSink for Count {
            fn primitive(&mut self) {}
            fn fragment(&mut self, _: Fragment) {
                self.0 += 1;
            }
        }
        let mut count = Count(0);
        rasterize_triangle(&RenderState::new(256, 256), &triangle, &mut count);
        assert_eq!(count.0, 0, "dropped");
    }

    #[test]
    fn snap_subtracts_the_centre_offset_and_rounds_ties_to_even() {
        assert_eq!(snap(0.5), 0);
        assert_eq!(snap(2.5 + 1.0 / 512.0), 512); // 512.5 -> 512
        assert_eq!(snap(2.5 + 3.0 / 512.0), 514); // 513.5 -> 514
        assert_eq!(snap(2.5 - 1.0 / 512.0), 512); // 511.5 -> 512
        assert_eq!(snap(-1.0), -384);
    }

    #[test]
    fn depth_quantisation_is_exact_at_the_ends_and_halfway() {
        assert_eq!(quantise_depth(0.0), 0);
        assert_eq!(quantise_depth(-0.5), 0);
        assert_eq!(quantise_depth(1.0), (DEPTH_ONE as i64) << 8);
        // 0.5 · (2^24 - 1) · 2^8 = 2^31 - 2^7 exactly.
        assert_eq!(quantise_depth(0.5), (1i64 << 31) - (1 << 7));
        // The smallest subnormal rounds to 0.
        assert_eq!(quantise_depth(f32::from_bits(1)), 0);
    }
}
