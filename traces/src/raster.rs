//! The exact reference rasterizer. (Being written: see the rasterizer task.)

use crate::event::Fragment;
use crate::state::RenderState;

/// Receives what the rasterizer produces, in deterministic order.
pub trait RasterSink {
    /// A triangle reached setup (after clipping and culling); its fragments follow.
    fn primitive(&mut self);
    /// A fragment inside the triangle and the raster bounds (viewport cut by scissor).
    fn fragment(&mut self, fragment: Fragment);
}

/// Rasterize one triangle given in clip coordinates under `state`.
pub fn rasterize_triangle(
    state: &RenderState,
    vertices: &[[f32; 4]; 3],
    sink: &mut impl RasterSink,
) {
    let _ = (state, vertices, sink);
}
