//! The vocabulary every consumer of a fragment stream speaks: the golden model emits it, the
//! trace format stores it, the timing models replay it.

use crate::query::{QueryResult, QuerySpec};
use crate::state::{DepthFunc, Rect};
use serde::{Deserialize, Serialize};

/// One fragment after rasterization and scissor, before the depth test.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Fragment {
    /// Window x of the pixel (0 at the left).
    pub x: u16,
    /// Window y of the pixel (0 at the bottom, as GL).
    pub y: u16,
    /// Window depth as 24-bit unsigned normalised: k means k / (2^24 - 1).
    pub z: u32,
}

/// A run of fragments on one row, as the rasterizer emits them and traces store them: pixel
/// `(x + i, y)` has depth `depths[i]`. Same as the fragments one by one, in order; no pixel
/// appears twice in a span, which lets a consumer test all its depths before it writes any.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Span<'a> {
    pub x: u16,
    pub y: u16,
    pub depths: &'a [u32],
}

impl<'a> Span<'a> {
    /// The fragments `columns` (indices into the span) as a span of their own.
    #[inline(always)]
    pub fn part(&self, columns: std::ops::Range<usize>) -> Span<'a> {
        Span {
            x: self.x + columns.start as u16,
            y: self.y,
            depths: &self.depths[columns],
        }
    }

    /// The span's fragments, in order.
    pub fn fragments(&self) -> impl Iterator<Item = Fragment> + '_ {
        let (x, y) = (self.x, self.y);
        self.depths.iter().enumerate().map(move |(i, &z)| Fragment {
            x: x.wrapping_add(i as u16),
            y,
            z,
        })
    }
}

/// Largest depth value: 1.0 in 24-bit unsigned normalised form.
pub const DEPTH_ONE: u32 = (1 << 24) - 1;

/// An item of a fragment stream, in pipeline order.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Event {
    /// Depth := 1.0 everywhere (ignores scissor and depth mask).
    Clear,
    DepthFunc(DepthFunc),
    DepthMask(bool),
    DepthTest(bool),
    Cull(bool),
    Scissor(Option<Rect>),
    QueryBegin(QuerySpec),
    /// End of the open query.
    QueryEnd,
    /// A primitive reached triangle setup; its fragments follow.
    Primitive,
    Fragment(Fragment),
    /// The golden model's answer to the query that just ended.
    QueryResult(QueryResult),
    /// Geometry the front end transformed: submitted triangles (those culled or clipped away
    /// included) and their vertices, just before the primitives they produce.
    Geometry(GeometryBatch),
    /// The host's own work between commands: the culling traversal.
    HostWork(HostWork),
    /// The host blocks until query `id`'s result is available (`glGetQueryObject` with
    /// `GL_QUERY_RESULT`, HP_occlusion_test's read, the paper's `glRenderMode(GL_RENDER)`).
    Wait(u32),
    /// `glBeginConditionalRender(id, GL_QUERY_WAIT)`: the pipeline holds what follows until
    /// query `id`'s result is known; the draws are discarded when it passed no fragment.
    ConditionalBegin(u32),
    ConditionalEnd,
    /// The frame ends (`SwapBuffers`).
    Swap,
}

impl Event {
    /// One of the closed loop's records (geometry batches, host work, waits, conditional
    /// rendering, frame ends): what a version-1 trace cannot hold.
    pub fn is_closed_loop_record(&self) -> bool {
        matches!(
            self,
            Event::Geometry(_)
                | Event::HostWork(_)
                | Event::Wait(_)
                | Event::ConditionalBegin(_)
                | Event::ConditionalEnd
                | Event::Swap
        )
    }
}

/// A run of submitted triangles the geometry stage processed. A draw (one `glDrawArrays`)
/// is one or more batches; its first has `starts_draw`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct GeometryBatch {
    pub vertices: u32,
    pub triangles: u32,
    /// The first batch of a draw (the host's per-draw cost is charged here).
    pub starts_draw: bool,
    /// The draw was discarded by conditional rendering: submitted, never rasterized.
    pub discarded: bool,
}

/// The host's culling work between two commands, counted in the traversal's own units.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct HostWork {
    /// Hierarchy nodes (or grid cells) visited.
    pub nodes: u32,
    /// Bounding boxes tested against the view frustum.
    pub boxes: u32,
    /// Visibility decisions taken from query answers.
    pub decisions: u32,
    /// Framebuffer pixels read back and searched for changes (the software occlusion test
    /// of the paper's reference \[10\], a virtual occlusion buffer).
    pub pixels: u32,
}

impl HostWork {
    pub fn is_empty(&self) -> bool {
        *self == HostWork::default()
    }
}
