//! The coverage walk every profile shares: a snapped counter-clockwise triangle in, the
//! covered pixels of each row out, bottom row first, left to right.
//!
//! Snapped positions are *offset* fixed point with [`SUBPIXEL_BITS`] fraction bits: `X =
//! round((x_window - 0.5) · 256)`, so the centre of pixel (px, py) is (256·px, 256·py). All
//! positions are in GL window coordinates (y up); a profile that rasterizes a y-flipped
//! framebuffer maps its rows before it gets here.
//!
//! A pixel is covered when its centre is strictly inside every edge, or exactly on an edge the
//! triangle owns: its **left** edges (interior to the right; for a counter-clockwise triangle
//! the edge runs downward) and its **bottom** horizontal edges (interior above). This is
//! Gallium's top-left rule with y down (`bottom_edge_rule = 0`, as Mesa sets it for
//! framebuffer objects); for a window-system framebuffer Mesa flips y and sets
//! `bottom_edge_rule = 1`, which owns the same edges in GL's coordinates. The edge functions
//! are exact integers, so every profile covers a snapped triangle identically.
//!
//! # Integer ranges
//! Snapped |X|, |Y| < 2^25 (viewport sides up to 2^14, coordinates clipped to well inside
//! 2^16 pixels): edge deltas < 2^26, edge functions at pixel centres < 2^53 (i64).

use super::{RasterSink, SUBPIXEL_BITS};
use crate::state::RenderState;

/// One pixel in fixed-point units.
pub(super) const PIXEL: i64 = 1 << SUBPIXEL_BITS;

/// A snapped vertex position (offset fixed point, GL window coordinates).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Point {
    pub x: i64,
    pub y: i64,
}

/// Twice the signed area; positive when counter-clockwise (y up).
pub(super) fn doubled_area(v: &[Point; 3]) -> i64 {
    (v[1].x - v[0].x) * (v[2].y - v[0].y) - (v[2].x - v[0].x) * (v[1].y - v[0].y)
}

/// Produces the depths of a run of covered pixels.
pub(super) trait SpanDepths {
    /// Send the fragments of pixels `first..=last` of row `py` to `sink`, left to right.
    fn emit(&self, py: i64, first: i64, last: i64, sink: &mut impl RasterSink);
}

/// An edge function `E(P) = dx·(Py - Ya) - dy·(Px - Xa)` of a counter-clockwise triangle:
/// positive inside. `own` is 1 when centres exactly on the edge are covered.
struct Edge {
    dx: i64,
    dy: i64,
    ax: i64,
    ay: i64,
    own: i64,
}

impl Edge {
    fn new(a: &Point, b: &Point) -> Edge {
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        // Left edges run downward; bottom edges run rightward (see the module doc).
        let own = (dy < 0 || (dy == 0 && dx > 0)) as i64;
        Edge {
            dx,
            dy,
            ax: a.x,
            ay: a.y,
            own,
        }
    }

    /// Narrow [first, last] to the pixels of row `py` this edge admits.
    fn clamp_span(&self, py: i64, first: &mut i64, last: &mut i64) {
        // Covered when E + own >= 1, i.e. f0 + step·px >= 0.
        let f0 = self.dx * (py * PIXEL - self.ay) + self.dy * self.ax + self.own - 1;
        let step = -self.dy * PIXEL;
        if step > 0 {
            *first = (*first).max(ceil_div(-f0, step));
        } else if step < 0 {
            *last = (*last).min(f0.div_euclid(-step));
        } else if f0 < 0 {
            *last = *first - 1;
        }
    }
}

pub(super) fn ceil_div(n: i64, d: i64) -> i64 {
    -((-n).div_euclid(d))
}

/// Emit every covered pixel of the counter-clockwise triangle `v` inside the raster bounds
/// (viewport cut by scissor), row by row from the bottom.
pub(super) fn walk_triangle(
    state: &RenderState,
    v: &[Point; 3],
    depths: &impl SpanDepths,
    sink: &mut impl RasterSink,
) {
    let bounds = state.raster_bounds();
    if bounds.is_empty() {
        return;
    }
    let edges = [
        Edge::new(&v[0], &v[1]),
        Edge::new(&v[1], &v[2]),
        Edge::new(&v[2], &v[0]),
    ];
    let (min_y, max_y) = (v.iter().map(|p| p.y).min(), v.iter().map(|p| p.y).max());
    let (min_x, max_x) = (v.iter().map(|p| p.x).min(), v.iter().map(|p| p.x).max());
    let (Some(min_y), Some(max_y), Some(min_x), Some(max_x)) = (min_y, max_y, min_x, max_x) else {
        return;
    };
    let rows = (
        ceil_div(min_y, PIXEL).max(bounds.y as i64),
        max_y
            .div_euclid(PIXEL)
            .min(bounds.y as i64 + bounds.height as i64 - 1),
    );
    let columns = (
        ceil_div(min_x, PIXEL).max(bounds.x as i64),
        max_x
            .div_euclid(PIXEL)
            .min(bounds.x as i64 + bounds.width as i64 - 1),
    );
    let span = |py: i64| {
        let (mut first, mut last) = columns;
        for edge in &edges {
            edge.clamp_span(py, &mut first, &mut last);
        }
        (first, last)
    };
    walk_rows(rows, span, depths, sink);
}

/// Emit the spans `span(py)` of rows `rows.0..=rows.1`, telling the sink of each row one
/// row before its fragments arrive.
pub(super) fn walk_rows(
    rows: (i64, i64),
    span: impl Fn(i64) -> (i64, i64),
    depths: &impl SpanDepths,
    sink: &mut impl RasterSink,
) {
    let (row_first, row_last) = rows;
    if row_first > row_last {
        return;
    }
    let mut current = span(row_first);
    for py in row_first..=row_last {
        let next = if py < row_last { span(py + 1) } else { (1, 0) };
        if next.0 <= next.1 {
            sink.next_span((py + 1) as u16, next.0 as u16, next.1 as u16);
        }
        if current.0 <= current.1 {
            depths.emit(py, current.0, current.1, sink);
        }
        current = next;
    }
}
