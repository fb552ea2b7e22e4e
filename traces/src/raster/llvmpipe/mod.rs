//! The `llvmpipe` and `llvmpipe-window` profiles: Mesa 22.3 llvmpipe's arithmetic, bit for
//! bit, from a draw's clip-space triangles to each fragment's 24-bit depth.
//!
//! The path a triangle takes (Mesa's files in brackets; see README's exactness section):
//! 1. **Vertex stage** ([`vertex`]; draw_llvm.c): the clip mask (x, y and z planes: llvmpipe
//!    has no guard band while a depth buffer is bound, lp_state_derived.c) and the window
//!    position `fmuladd(c · (1/w), scale, translate)`.
//! 2. **Segments and the pipeline** (this module; draw_pt_vsplit.c, draw_split_tmp.h,
//!    draw_pt_fetch_shade_pipeline_llvm.c): a draw is shaded in segments of
//!    [`SEGMENT_TRIANGLES`] triangles; when any vertex of a segment has a clip bit, the whole
//!    segment runs the draw pipeline: clipping ([`clipper`]) for triangles with a clip bit,
//!    and, when culling is on, the cull stage (draw_pipe_cull.c: the f32 determinant of the
//!    window positions; zero counts as back-facing) for every triangle. Otherwise the segment
//!    goes straight to setup, where a segment of exactly three triangles whose last is flat in
//!    y takes the nine-vertex path (lp_setup_analysis.c, `lp_setup_analyse_triangles`, meant
//!    for a Windows compositor's window borders): its first two triangles are drawn as one
//!    rectangle if they form one in the expected vertex order, or not at all.
//! 3. **Setup** ([`setup`]; lp_setup_tri.c, lp_state_setup.c): snapping, the fixed-point area
//!    and face culling, then the f32 depth plane from the unsnapped positions.
//! 4. **Coverage** by the shared integer walk, **depth** per pixel ([`fragment`]).
//!
//! A framebuffer object keeps GL's y; a window-system framebuffer (`llvmpipe-window`) is
//! mirrored in y (st_atom_viewport.c), which moves where f32 rounding falls.

mod clipper;
mod float;
mod fragment;
mod setup;
mod vertex;

use super::RasterSink;
use crate::state::RenderState;
pub use fragment::PlaneDepths;
use vertex::{shade, Vertex, Viewport};

/// What llvmpipe renders into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Framebuffer {
    /// A framebuffer object: y up, as GL's window coordinates.
    Object,
    /// A window-system framebuffer (a window or pbuffer): y mirrored.
    Window,
}

/// A triangle after the vertex stage: each vertex with its clip mask, shaded once.
type ShadedTriangle = [(Vertex, u32); 3];

/// Triangles the draw module shades together: `max_vertices` = 4096 vertices for a linear
/// draw (draw_pt_fetch_shade_pipeline_llvm.c), trimmed to whole triangles (4095).
pub(crate) const SEGMENT_TRIANGLES: usize = 4096 / 3;

/// One draw at a time: a draw is the triangles between two other commands. A segment is
/// held back until what it needs of its future is known: with culling, whether any of its
/// vertices is clipped (which puts the whole segment through the cull stage); without, only
/// whether it has exactly three triangles (the nine-vertex path). The rest streams.
#[derive(Clone, Debug)]
pub(super) struct Draws {
    framebuffer: Framebuffer,
    /// Triangles of the current segment held back, shaded.
    held: Vec<ShadedTriangle>,
    /// Triangles of the current segment already drawn (none are held then).
    streamed: usize,
}

impl Draws {
    pub fn new(framebuffer: Framebuffer) -> Draws {
        Draws {
            framebuffer,
            held: Vec::new(),
            streamed: 0,
        }
    }

    /// The next triangle of the current draw.
    pub fn triangle(
        &mut self,
        state: &RenderState,
        vertices: &[[f32; 4]; 3],
        sink: &mut impl RasterSink,
    ) {
        let viewport = Viewport::new(state, self.framebuffer);
        let shaded = vertices.map(|c| shade(&c, &viewport));
        if self.streamed > 0 {
            self.draw_one(state, &shaded, &viewport, None, sink);
            self.streamed += 1;
            if self.streamed == SEGMENT_TRIANGLES {
                self.streamed = 0;
            }
            return;
        }
        self.held.push(shaded);
        if self.held.len() == SEGMENT_TRIANGLES {
            self.flush_segment(state, sink);
        } else if !state.cull_back && self.held.len() > 3 {
            // Past three triangles without culling, nothing depends on the rest.
            let held = std::mem::take(&mut self.held);
            for triangle in &held {
                self.draw_one(state, triangle, &viewport, None, sink);
            }
            self.streamed = held.len();
            self.held = held;
            self.held.clear();
        }
    }

    /// The current draw ends (any command but a triangle, or the end of the scene).
    pub fn end_draw(&mut self, state: &RenderState, sink: &mut impl RasterSink) {
        self.flush_segment(state, sink);
        self.streamed = 0;
    }

    /// Draw the held triangles as one segment.
    fn flush_segment(&mut self, state: &RenderState, sink: &mut impl RasterSink) {
        if self.held.is_empty() {
            return;
        }
        let viewport = Viewport::new(state, self.framebuffer);
        let held = std::mem::take(&mut self.held);
        let pipeline = held.iter().flatten().any(|&(_, mask)| mask != 0);
        if !pipeline && held.len() == 3 {
            self.nine_vertices(state, &held, &viewport, sink);
        } else {
            for triangle in &held {
                self.draw_one(state, triangle, &viewport, Some(pipeline), sink);
            }
        }
        self.held = held;
        self.held.clear();
    }

    /// One triangle: clipped if a vertex needs it, culled by the draw module if its segment
    /// runs the pipeline with culling on, then set up. `pipeline` is None where it cannot
    /// matter (culling off).
    fn draw_one(
        &self,
        state: &RenderState,
        shaded: &ShadedTriangle,
        viewport: &Viewport,
        pipeline: Option<bool>,
        sink: &mut impl RasterSink,
    ) {
        let (any, all) = shaded
            .iter()
            .fold((0, u32::MAX), |(any, all), (_, m)| (any | m, all & m));
        let triangle = shaded.map(|(v, _)| v);
        let cull_stage = state.cull_back && pipeline.unwrap_or(false);
        let mut set_up = |t: &[Vertex; 3]| {
            if !(cull_stage && self.culled_by_draw(t)) {
                setup::triangle(state, self.framebuffer, t, sink);
            }
        };
        if any == 0 {
            set_up(&triangle);
        } else if all == 0 {
            clipper::clip_triangle(&triangle, any, viewport, set_up);
        }
    }

    /// draw_pipe_cull.c `cull_tri` for back faces: `det = ex·fy - ey·fx` with e = v0 - v2,
    /// f = v1 - v2 of the window positions; a front face has `det < 0` exactly when
    /// `front_ccw` (set for windows, clear for framebuffer objects); zero is a back face.
    fn culled_by_draw(&self, t: &[Vertex; 3]) -> bool {
        use float::{mul, sub};
        let (v0, v1, v2) = (&t[0].window, &t[1].window, &t[2].window);
        let (ex, ey) = (sub(v0[0], v2[0]), sub(v0[1], v2[1]));
        let (fx, fy) = (sub(v1[0], v2[0]), sub(v1[1], v2[1]));
        let det = sub(mul(ex, fy), mul(ey, fx));
        if det == 0.0 {
            return true;
        }
        let front_ccw = self.framebuffer == Framebuffer::Window;
        (det < 0.0) != front_ccw
    }

    /// `lp_setup_draw_arrays` given exactly nine vertices with none clipped: when the last
    /// triangle's window y are all equal, `lp_setup_analyse_triangles` takes the draw over,
    /// drawing the first two as a rectangle if their vertices are (X0,Y0) (X0,Y1) (X1,Y1) and
    /// (X1,Y0) (X1,Y1) (X0,Y0), and nothing otherwise. Else three ordinary triangles.
    fn nine_vertices(
        &self,
        state: &RenderState,
        held: &[ShadedTriangle],
        viewport: &Viewport,
        sink: &mut impl RasterSink,
    ) {
        let v: Vec<Vertex> = held.iter().flatten().map(|&(v, _)| v).collect();
        let (x, y) = (|i: usize| v[i].window[0], |i: usize| v[i].window[1]);
        if !(y(8) == y(7) && y(8) == y(6)) {
            for triangle in held {
                self.draw_one(state, triangle, viewport, Some(false), sink);
            }
            return;
        }
        let rectangle = x(0) == x(1)
            && x(0) == x(5)
            && x(2) == x(3)
            && x(2) == x(4)
            && y(0) == y(3)
            && y(0) == y(5)
            && y(1) == y(2)
            && y(1) == y(4);
        if rectangle {
            setup::rectangle(state, self.framebuffer, &[v[0], v[1], v[2]], sink);
        }
    }
}
