//! llvmpipe's triangle setup (lp_setup_tri.c): snapping, the fixed-point area and its sign,
//! face culling and the vertex order handed to the generated setup function
//! (lp_state_setup.c), which computes the depth plane in f32 from the *unsnapped* window
//! positions. Also the rectangle path (lp_setup_rect.c) the nine-vertex quirk takes.

use super::super::coverage::{self, doubled_area, Point, PIXEL};
use super::super::RasterSink;
use super::float::{add, convert_nearest_even, div, mul, round_half_away, sub};
use super::fragment::DepthPlane;
use super::vertex::Vertex;
use super::Framebuffer;
use crate::state::RenderState;

/// `pixel_offset` with `half_pixel_center` (GL): window positions are snapped after
/// subtracting it.
const PIXEL_OFFSET: f32 = 0.5;
/// `FIXED_ONE`: 2^8 sub-pixel steps.
const FIXED_ONE: f32 = PIXEL as f32;

impl Framebuffer {
    /// The sign of llvmpipe's fixed-point area for a front face: its area is positive for
    /// triangles clockwise in Gallium's y-down window coordinates. Mesa's state tracker makes
    /// GL's counter-clockwise front faces `front_ccw = 0` in a (y-up) framebuffer object and
    /// `front_ccw = 1` in a (mirrored) window.
    fn front_area_sign(self) -> i64 {
        match self {
            Framebuffer::Object => -1,
            Framebuffer::Window => 1,
        }
    }

    /// `bottom_edge_rule`: 0 for framebuffer objects, 1 for windows (st_atom_rasterizer.c).
    fn bottom_edge_rule(self) -> i32 {
        match self {
            Framebuffer::Object => 0,
            Framebuffer::Window => 1,
        }
    }

    /// The GL row (y up) of framebuffer row `row` of a viewport `height` rows high.
    pub(super) fn gl_row(self, row: i64, height: u32) -> i64 {
        match self {
            Framebuffer::Object => row,
            Framebuffer::Window => height as i64 - 1 - row,
        }
    }
}

/// `calc_fixed_position`'s snap: `_mm_cvtps_epi32((v - 0.5) · 256)`.
fn snap(window: f32) -> i32 {
    convert_nearest_even(mul(sub(window, PIXEL_OFFSET), FIXED_ONE))
}

/// `triangle_both`, `triangle_cw` and `triangle_ccw` with `do_triangle_ccw`: draw `v` unless
/// its fixed-point area is zero or, with culling, of a back face.
pub(super) fn triangle(
    state: &RenderState,
    framebuffer: Framebuffer,
    v: &[Vertex; 3],
    sink: &mut impl RasterSink,
) {
    // A vertex at the clip-space origin with w = 0 has a NaN window position, which
    // llvmpipe snaps to the integer indefinite and rasterizes as garbage; we draw nothing.
    if v.iter()
        .any(|v| !(v.window[0].is_finite() && v.window[1].is_finite()))
    {
        return;
    }
    let x = v.map(|v| snap(v.window[0]));
    let y = v.map(|v| snap(v.window[1]));
    let (dx01, dy01) = (x[0].wrapping_sub(x[1]), y[0].wrapping_sub(y[1]));
    let (dx20, dy20) = (x[2].wrapping_sub(x[0]), y[2].wrapping_sub(y[0]));
    let area = (dx01 as i64 * dy20 as i64).wrapping_sub(dx20 as i64 * dy01 as i64);
    let sign = area.signum();
    if sign == 0 || (state.cull_back && sign != framebuffer.front_area_sign()) {
        return;
    }
    // A negative area is drawn as (v1, v0, v2) (the provoking vertex stays last).
    let order = if sign > 0 { [0, 1, 2] } else { [1, 0, 2] };
    sink.primitive();
    let plane = DepthPlane::new(&order.map(|i| v[i].window), framebuffer, state.height);
    sink.depth_plane(plane.depths());
    let mut points = [0, 1, 2].map(|i| Point {
        x: x[i] as i64,
        y: gl_fixed_y(y[i], framebuffer, state.height),
    });
    if doubled_area(&points) < 0 {
        points.swap(1, 2);
    }
    coverage::walk_triangle(state, &points, &plane, sink);
}

/// A snapped y in GL's y-up fixed point: framebuffer row r's centre is at 256·r, and row r
/// of a window is GL row height - 1 - r.
fn gl_fixed_y(y: i32, framebuffer: Framebuffer, height: u32) -> i64 {
    match framebuffer {
        Framebuffer::Object => y as i64,
        Framebuffer::Window => (height as i64 - 1) * PIXEL - y as i64,
    }
}

/// `lp_rect_cw` (`try_rect_cw`): the axis-aligned rectangle spanned by `v`, every pixel of
/// its rounded bounding box shaded with the plane through `v`, unless it is clockwise.
pub(super) fn rectangle(
    state: &RenderState,
    framebuffer: Framebuffer,
    v: &[Vertex; 3],
    sink: &mut impl RasterSink,
) {
    // `subpixel_snap` in lp_setup_rect.c is `util_iround(FIXED_ONE · (v - pixel_offset))`.
    let x = v.map(|v| round_half_away(mul(FIXED_ONE, sub(v.window[0], PIXEL_OFFSET))));
    let y = v.map(|v| round_half_away(mul(FIXED_ONE, sub(v.window[1], PIXEL_OFFSET))));
    if (x[2] < x[1]) ^ (y[0] < y[2]) {
        return;
    }
    sink.primitive();
    let adj = framebuffer.bottom_edge_rule();
    let low = |m: i32, extra: i32| m.wrapping_add(PIXEL as i32 - 1 + extra) >> 8;
    let (min_x, max_x) = (x.iter().min(), x.iter().max());
    let (min_y, max_y) = (y.iter().min(), y.iter().max());
    let (Some(&min_x), Some(&max_x), Some(&min_y), Some(&max_y)) = (min_x, max_x, min_y, max_y)
    else {
        return;
    };
    let columns = (low(min_x, 0) as i64, low(max_x, 0) as i64 - 1);
    let rows = (low(min_y, adj) as i64, low(max_y, adj) as i64 - 1);
    let (a, b) = (
        framebuffer.gl_row(rows.0, state.height),
        framebuffer.gl_row(rows.1, state.height),
    );
    let bounds = state.raster_bounds();
    let gl_rows = (
        a.min(b).max(bounds.y as i64),
        a.max(b).min(bounds.y as i64 + bounds.height as i64 - 1),
    );
    let span = (
        columns.0.max(bounds.x as i64),
        columns.1.min(bounds.x as i64 + bounds.width as i64 - 1),
    );
    let plane = DepthPlane::new(&v.map(|v| v.window), framebuffer, state.height);
    sink.depth_plane(plane.depths());
    coverage::walk_rows(gl_rows, |_| span, &plane, sink);
}

/// The generated setup function's depth plane (lp_state_setup.c, `init_args` and
/// `calc_coef4`), each step one f32 operation, unfused, in this order.
pub(super) struct PlaneCoefficients {
    pub a0: f32,
    pub dzdx: f32,
    pub dzdy: f32,
}

impl PlaneCoefficients {
    pub fn new(p: &[[f32; 3]; 3]) -> PlaneCoefficients {
        let x0_center = sub(p[0][0], PIXEL_OFFSET);
        let y0_center = sub(p[0][1], PIXEL_OFFSET);
        let (dx01, dy01) = (sub(p[0][0], p[1][0]), sub(p[0][1], p[1][1]));
        let (dx20, dy20) = (sub(p[2][0], p[0][0]), sub(p[2][1], p[0][1]));
        let e = mul(dx01, dy20);
        let f = mul(dy01, dx20);
        let ooa = div(1.0, sub(e, f));
        let (dx20_ooa, dy20_ooa) = (mul(dx20, ooa), mul(dy20, ooa));
        let (dx01_ooa, dy01_ooa) = (mul(dx01, ooa), mul(dy01, ooa));
        let dz01 = sub(p[0][2], p[1][2]);
        let dz20 = sub(p[2][2], p[0][2]);
        let dzdx = sub(mul(dz01, dy20_ooa), mul(dz20, dy01_ooa));
        let dzdy = sub(mul(dz20, dx01_ooa), mul(dz01, dx20_ooa));
        let a0 = sub(p[0][2], add(mul(dzdx, x0_center), mul(dzdy, y0_center)));
        PlaneCoefficients { a0, dzdx, dzdy }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plane_of_a_right_triangle_by_hand() {
        // Window positions (0.5, 0.5, 0), (4.5, 0.5, 1), (0.5, 2.5, 0.5), exact in f32:
        // dx01 = -4, dy01 = 0, dx20 = 0, dy20 = 2, e = -8, f = 0, ooa = -1/8;
        // dzdx = dz01·dy20·ooa - dz20·dy01·ooa = (-1)(2)(-1/8) - 0 = 0.25;
        // dzdy = dz20·dx01·ooa - dz01·dx20·ooa = (0.5)(-4)(-1/8) - 0 = 0.25;
        // a0 = z0 - (0.25·0 + 0.25·0) = 0 (x0 - 0.5 = y0 - 0.5 = 0).
        let plane = PlaneCoefficients::new(&[[0.5, 0.5, 0.0], [4.5, 0.5, 1.0], [0.5, 2.5, 0.5]]);
        assert_eq!((plane.a0, plane.dzdx, plane.dzdy), (0.0, 0.25, 0.25));
    }

    #[test]
    fn snapping_rounds_ties_to_even_after_the_offset() {
        assert_eq!(snap(0.5), 0);
        assert_eq!(snap(2.5 + 1.0 / 512.0), 512); // 512.5 -> 512
        assert_eq!(snap(2.5 + 3.0 / 512.0), 514); // 513.5 -> 514
        assert_eq!(snap(-1.0), -384);
    }
}
