//! The draw module's clipper (draw_pipe_clip.c, `do_clip_tri` and `emit_poly`), step for
//! step: the planes some vertex violates, in the order of their mask bits; distances as
//! `dot4` computes them; each new vertex interpolated from the endpoint the code picks, not
//! forced onto the plane; the polygon emitted as triangles (`p[i-1]`, `p[i]`, `p[0]`) (the
//! provoking vertex last, GL's default).

use super::float::{add, div, mul, sub};
use super::vertex::{window_of_new_vertex, Vertex, Viewport, PLANE_COUNT};

/// `MAX_CLIPPED_VERTICES`: 2 · (6 + PIPE_MAX_CLIP_PLANES) + 1.
const MAX_CLIPPED_VERTICES: usize = 2 * (6 + 8) + 1;

/// `draw->plane[0..6]` (draw_context.c): a vertex is inside plane `p` when `dot4(c, p) >= 0`.
const PLANES: [[f32; 4]; PLANE_COUNT] = [
    [-1.0, 0.0, 0.0, 1.0],
    [1.0, 0.0, 0.0, 1.0],
    [0.0, -1.0, 0.0, 1.0],
    [0.0, 1.0, 0.0, 1.0],
    [0.0, 0.0, 1.0, 1.0],
    [0.0, 0.0, -1.0, 1.0],
];

/// `dot4`: `a0·b0 + a1·b1 + a2·b2 + a3·b3`, summed left to right.
fn distance(c: &[f32; 4], plane: &[f32; 4]) -> f32 {
    add(
        add(
            add(mul(c[0], plane[0]), mul(c[1], plane[1])),
            mul(c[2], plane[2]),
        ),
        mul(c[3], plane[3]),
    )
}

/// `interp`: the clip position `out + t·(in - out)` per component, then the window position.
fn interpolate(t: f32, out: &Vertex, inside: &Vertex, viewport: &Viewport) -> Vertex {
    let clip = [0, 1, 2, 3].map(|k| add(out.clip[k], mul(t, sub(inside.clip[k], out.clip[k]))));
    Vertex {
        clip,
        window: window_of_new_vertex(&clip, viewport),
    }
}

/// Clip a triangle whose vertices' masks OR to `mask` (and AND to 0) and send the triangles
/// of what is left to `emit`. Nothing is emitted when a distance is infinite or NaN (the
/// clipper discards the whole triangle) or when the polygon outgrows the clipper's arrays.
pub(super) fn clip_triangle(
    triangle: &[Vertex; 3],
    mut mask: u32,
    viewport: &Viewport,
    mut emit: impl FnMut(&[Vertex; 3]),
) {
    let mut polygon = [triangle[0]; MAX_CLIPPED_VERTICES + 1];
    polygon[..3].copy_from_slice(triangle);
    let mut n = 3;
    let mut made = 0;
    while mask != 0 && n >= 3 {
        let plane = &PLANES[mask.trailing_zeros() as usize];
        mask &= mask - 1;
        let Some(count) = clip_plane(&mut polygon, n, plane, viewport, &mut made) else {
            return;
        };
        n = count;
    }
    if n >= 3 {
        for i in 2..n {
            emit(&[polygon[i - 1], polygon[i], polygon[0]]);
        }
    }
}

/// One plane of `do_clip_tri`'s loop, in place. None when the clipper gives up on the
/// triangle.
fn clip_plane(
    polygon: &mut [Vertex; MAX_CLIPPED_VERTICES + 1],
    n: usize,
    plane: &[f32; 4],
    viewport: &Viewport,
    made: &mut usize,
) -> Option<usize> {
    let finite = |d: f32| d.is_finite().then_some(d);
    let mut previous = polygon[0];
    let mut dp_previous = finite(distance(&previous.clip, plane))?;
    if n >= MAX_CLIPPED_VERTICES {
        return None;
    }
    polygon[n] = polygon[0];
    let mut out = [polygon[0]; MAX_CLIPPED_VERTICES + 1];
    let mut count = 0;
    for &vertex in &polygon[1..=n] {
        let dp = finite(distance(&vertex.clip, plane))?;
        let different_sign = if dp_previous >= 0.0 {
            if count >= MAX_CLIPPED_VERTICES {
                return None;
            }
            out[count] = previous;
            count += 1;
            dp < 0.0
        } else {
            // `!(dp < 0.0f)` in Mesa; the same for the finite dp that reach here.
            dp >= 0.0
        };
        if different_sign {
            // `tmpnr` bounds the new vertices of the whole triangle.
            if *made > MAX_CLIPPED_VERTICES || count >= MAX_CLIPPED_VERTICES {
                return None;
            }
            *made += 1;
            let denominator = sub(dp, dp_previous);
            out[count] = if dp < 0.0 {
                // Going out: interpolate from the endpoint nearer the plane.
                if -dp < dp_previous {
                    interpolate(div(dp, denominator), &vertex, &previous, viewport)
                } else {
                    interpolate(div(-dp_previous, denominator), &previous, &vertex, viewport)
                }
            } else if -dp_previous < dp {
                // Coming back in.
                interpolate(div(-dp_previous, denominator), &previous, &vertex, viewport)
            } else {
                interpolate(div(dp, denominator), &vertex, &previous, viewport)
            };
            count += 1;
        }
        previous = vertex;
        dp_previous = dp;
    }
    polygon[..count].copy_from_slice(&out[..count]);
    Some(count)
}

#[cfg(test)]
mod tests {
    use super::super::vertex::shade;
    use super::super::Framebuffer;
    use super::*;
    use crate::state::RenderState;

    fn clipped(triangle: [[f32; 4]; 3]) -> Vec<[Vertex; 3]> {
        let viewport = Viewport::new(&RenderState::new(8, 8), Framebuffer::Object);
        let shaded = triangle.map(|c| shade(&c, &viewport));
        let mask = shaded.iter().fold(0, |m, (_, bits)| m | bits);
        let mut out = Vec::new();
        clip_triangle(&shaded.map(|(v, _)| v), mask, &viewport, |t| out.push(*t));
        out
    }

    #[test]
    fn a_corner_cut_by_one_plane_gives_a_quad_emitted_around_its_first_vertex() {
        // Only v1 has x > w. Plane 0's distances w - x: v0 1, v1 -2, v2 1.
        // v0 -> v1 goes out: -dp = 2 is not < dp_prev = 1, so t = -dp_prev / (dp - dp_prev)
        //   = -1 / -3 = 0.33333334 from v0: A = v0 + t·(v1 - v0), x = 0.33333334 · 3 = 1.0
        //   after f32 rounding.
        // v1 -> v2 comes in: -dp_prev = 2 is not < dp = 1, so t = dp / (dp - dp_prev) = 1/3
        //   from v2: B = v2 + t·(v1 - v2) = (1.0, 1 - 0.33333334, 0, 1).
        // The polygon v0 A B v2 is emitted as (A, B, v0) and (B, v2, v0).
        let out = clipped([
            [0.0, 0.0, 0.0, 1.0],
            [3.0, 0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0, 1.0],
        ]);
        let third = 1.0f32 / 3.0;
        let a = [1.0, 0.0, 0.0, 1.0];
        let b = [1.0, 1.0 - third, 0.0, 1.0];
        let clips: Vec<[[f32; 4]; 3]> = out.iter().map(|t| t.map(|v| v.clip)).collect();
        assert_eq!(
            clips,
            vec![
                [a, b, [0.0, 0.0, 0.0, 1.0]],
                [b, [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]]
            ]
        );
        // A's window position: x = 1 · (1/1) · 4 + 4 = 8, y = 4, z = 0.5.
        assert_eq!(out[0][0].window, [8.0, 4.0, 0.5]);
    }

    #[test]
    fn an_infinite_distance_discards_the_triangle() {
        // x + w overflows to infinity on the plane x >= -w.
        let out = clipped([
            [-3e38, 0.0, 0.0, 1.0],
            [3e38, 0.0, 0.0, 3e38],
            [0.0, 1.0, 0.0, 1.0],
        ]);
        assert!(out.is_empty());
    }
}
