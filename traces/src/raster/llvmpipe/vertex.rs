//! The draw module's vertex stage after the (pass-through) vertex shader: clip mask and
//! viewport transform, as draw_llvm.c generates them (`generate_clipmask`,
//! `generate_viewport`), and the viewport Mesa's state tracker sets.

use super::float::{add, div, flush, fused, mul};
use super::Framebuffer;
use crate::state::RenderState;
use std::cmp::Ordering::Greater;

/// The viewport transform (st_atom_viewport.c, `_mesa_get_viewport_xform`) for viewport
/// 0, 0, width, height and depth range 0..1.
#[derive(Clone, Copy, Debug)]
pub(super) struct Viewport {
    pub scale: [f32; 3],
    pub translate: [f32; 3],
}

impl Viewport {
    pub fn new(state: &RenderState, framebuffer: Framebuffer) -> Viewport {
        let (width, height) = (state.width as f32, state.height as f32);
        let (half_width, half_height) = (0.5 * width, 0.5 * height);
        let (scale_y, translate_y) = match framebuffer {
            Framebuffer::Object => (half_height, half_height),
            // A window-system framebuffer is Y_0_TOP: y is mirrored.
            Framebuffer::Window => (-half_height, height - half_height),
        };
        Viewport {
            scale: [half_width, scale_y, 0.5],
            translate: [half_width, translate_y, 0.5],
        }
    }
}

/// A vertex as the draw module carries it: the clip position (`clip_pos`) and the window
/// position (`data[pos]`: x, y, z; the fourth component, 1/w, is not needed for depth).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Vertex {
    pub clip: [f32; 4],
    pub window: [f32; 3],
}

/// Clip-mask bits, in the order of the clipper's planes (draw_context.c `draw->plane`).
pub(super) const PLANE_COUNT: usize = 6;

/// `generate_clipmask` with x/y clipping (no guard band: a depth buffer is bound) and full-z
/// depth clipping: bit 0 `x > w`, 1 `0 > x + w`, 2 `y > w`, 3 `0 > y + w`, 4 `0 > z + w`,
/// 5 `z > w`. `lp_build_compare` compares unordered (lp_bld_logic.c), so a NaN sets the bit:
/// `a > b` is taken as `!(a <= b)`.
pub(super) fn clip_mask(c: &[f32; 4]) -> u32 {
    let [x, y, z, w] = *c;
    let above = |a: f32, b: f32| matches!(a.partial_cmp(&b), Some(Greater) | None) as u32;
    above(x, w)
        | above(0.0, add(x, w)) << 1
        | above(y, w) << 2
        | above(0.0, add(y, w)) << 3
        | above(0.0, add(z, w)) << 4
        | above(z, w) << 5
}

/// The vertex stage: inputs read as by DAZ, the mask, and `generate_viewport`'s window
/// position: `1/w` by IEEE division, then `fmuladd(c · (1/w), scale, translate)`.
pub(super) fn shade(clip: &[f32; 4], viewport: &Viewport) -> (Vertex, u32) {
    let clip = clip.map(flush);
    let inv_w = div(1.0, clip[3]);
    let window = [0, 1, 2].map(|k| {
        fused(
            mul(clip[k], inv_w),
            viewport.scale[k],
            viewport.translate[k],
        )
    });
    (Vertex { clip, window }, clip_mask(&clip))
}

/// The window position the clipper gives a vertex it makes (draw_pipe_clip.c `interp`, C
/// code: unfused, left to right): `c · (1/w) · scale + translate`.
pub(super) fn window_of_new_vertex(clip: &[f32; 4], viewport: &Viewport) -> [f32; 3] {
    let oow = div(1.0, clip[3]);
    [0, 1, 2].map(|k| {
        add(
            mul(mul(clip[k], oow), viewport.scale[k]),
            viewport.translate[k],
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_mask_bits_follow_the_planes() {
        assert_eq!(clip_mask(&[0.0, 0.0, 0.0, 1.0]), 0);
        assert_eq!(
            clip_mask(&[1.0, -1.0, 1.0, 1.0]),
            0,
            "on the planes is inside"
        );
        assert_eq!(clip_mask(&[1.5, 0.0, 0.0, 1.0]), 0b000001);
        assert_eq!(clip_mask(&[-1.5, 0.0, 0.0, 1.0]), 0b000010);
        assert_eq!(clip_mask(&[0.0, 1.5, 0.0, 1.0]), 0b000100);
        assert_eq!(clip_mask(&[0.0, -1.5, 0.0, 1.0]), 0b001000);
        assert_eq!(clip_mask(&[0.0, 0.0, -1.5, 1.0]), 0b010000);
        assert_eq!(clip_mask(&[0.0, 0.0, 1.5, 1.0]), 0b100000);
        // The clip-space origin with w = 0 is inside every plane.
        assert_eq!(clip_mask(&[0.0, 0.0, 0.0, 0.0]), 0);
        // Unordered compares: a NaN coordinate sets its planes' bits.
        assert_eq!(clip_mask(&[0.0, 0.0, f32::NAN, 1.0]), 0b110000);
    }

    #[test]
    fn window_framebuffers_mirror_y() {
        let state = RenderState::new(64, 32);
        let fbo = Viewport::new(&state, Framebuffer::Object);
        let window = Viewport::new(&state, Framebuffer::Window);
        // y = -0.5 (a quarter up from the bottom): 8 in an FBO, 24 in a window.
        let (v, _) = shade(&[0.0, -0.5, 0.0, 1.0], &fbo);
        assert_eq!(v.window, [32.0, 8.0, 0.5]);
        let (v, _) = shade(&[0.0, -0.5, 0.0, 1.0], &window);
        assert_eq!(v.window, [32.0, 24.0, 0.5]);
    }
}
