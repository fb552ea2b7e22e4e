//! The reference rasterizer: clip-space triangles in, fragments out, in a fixed order, with
//! the arithmetic of a chosen [`RasterProfile`].
//!
//! - [`RasterProfile::Llvmpipe`] (the default): Mesa 22.3 llvmpipe's arithmetic bit for bit,
//!   rendering into a framebuffer object, so counts equal what a GL program gets from
//!   llvmpipe (module `llvmpipe`).
//! - [`RasterProfile::LlvmpipeWindow`]: the same into a window-system framebuffer (y
//!   mirrored).
//! - [`RasterProfile::Exact`]: occsim's own rasterizer: a far guard band instead of x/y
//!   clipping, depth exact from the snapped vertices (module `exact`).
//!
//! Every profile snaps window positions to [`SUBPIXEL_BITS`] bits with ties to even and
//! covers pixels by the same exact integer edge functions and fill rule (module
//! `coverage`); they differ in clipping, culling of slivers and depth rounding.
//!
//! # Fragment order
//!
//! Per triangle: rows bottom to top (increasing GL y), left to right within a row.

mod coverage;
mod exact;
mod llvmpipe;

pub use exact::DEPTH_EXTRA_BITS;
pub use llvmpipe::PlaneDepths;

use crate::event::Fragment;
use crate::state::RenderState;
use serde::{Deserialize, Serialize};

/// Which pixel centres on an edge a triangle owns: Direct3D's and Gallium's top-left rule
/// with y down, which in GL window coordinates (y up) owns left and bottom edges.
pub const FILL_RULE: &str = "top-left with y down (left and bottom edges in GL window coordinates)";
/// Sub-pixel bits of snapped window coordinates.
pub const SUBPIXEL_BITS: u32 = 8;

/// The arithmetic the rasterizer follows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum RasterProfile {
    /// Mesa 22.3 llvmpipe into a framebuffer object, bit for bit.
    #[default]
    #[serde(rename = "llvmpipe")]
    Llvmpipe,
    /// Mesa 22.3 llvmpipe into a window-system framebuffer (y mirrored), bit for bit.
    #[serde(rename = "llvmpipe-window")]
    LlvmpipeWindow,
    /// occsim's exact rasterizer: guard band, depth exact from the snapped vertices.
    #[serde(rename = "exact")]
    Exact,
}

impl RasterProfile {
    pub const ALL: [RasterProfile; 3] = [
        RasterProfile::Llvmpipe,
        RasterProfile::LlvmpipeWindow,
        RasterProfile::Exact,
    ];

    pub fn name(self) -> &'static str {
        match self {
            RasterProfile::Llvmpipe => "llvmpipe",
            RasterProfile::LlvmpipeWindow => "llvmpipe-window",
            RasterProfile::Exact => "exact",
        }
    }

    /// What the profile promises, in one line.
    pub fn describe(self) -> &'static str {
        match self {
            RasterProfile::Llvmpipe => {
                "Mesa 22.3 llvmpipe's arithmetic bit for bit, into a framebuffer object"
            }
            RasterProfile::LlvmpipeWindow => {
                "Mesa 22.3 llvmpipe's arithmetic bit for bit, into a window-system framebuffer (y mirrored)"
            }
            RasterProfile::Exact => {
                "occsim's exact rasterizer: guard-band clipping, depth exact from the snapped vertices"
            }
        }
    }

    /// The profile called `name`, or an error naming the profiles there are.
    pub fn from_name(name: &str) -> Result<RasterProfile, String> {
        RasterProfile::ALL
            .into_iter()
            .find(|p| p.name() == name)
            .ok_or_else(|| {
                let names: Vec<&str> = RasterProfile::ALL.iter().map(|p| p.name()).collect();
                format!(
                    "unknown rasterizer profile `{name}`: expected one of {}",
                    names.join(", ")
                )
            })
    }
}

impl std::fmt::Display for RasterProfile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for RasterProfile {
    type Err = String;
    fn from_str(name: &str) -> Result<RasterProfile, String> {
        RasterProfile::from_name(name)
    }
}

/// Receives what the rasterizer produces, in deterministic order.
pub trait RasterSink {
    /// A primitive reached setup (after clipping and culling); its fragments follow.
    fn primitive(&mut self);
    /// A fragment inside the primitive and the raster bounds (viewport cut by scissor).
    fn fragment(&mut self, fragment: Fragment);
    /// The span of the row after the one being emitted: pixels `first..=last` of row `y`.
    /// A sink backed by a large buffer can start fetching it (as the O2's depth prefetch
    /// does); the default ignores it. Never changes what is emitted.
    #[inline(always)]
    fn next_span(&mut self, y: u16, first: u16, last: u16) {
        let _ = (y, first, last);
    }
    /// The primitive just begun has the depths of `plane` at its pixels (the llvmpipe
    /// profile tells it; the others do not): a trace writer keeps the plane in place of
    /// its fragments' depths. The default ignores it. Never changes what is emitted.
    #[inline(always)]
    fn depth_plane(&mut self, plane: PlaneDepths) {
        let _ = plane;
    }
}

/// Draws in, fragments out. A draw is the run of triangles between two other commands (one
/// `glDrawArrays`); llvmpipe's result for a triangle can depend on the rest of its draw, so
/// a profile may hold a few triangles back until [`Rasterizer::end_draw`]. Call `end_draw`
/// before anything that must see the fragments drawn so far.
#[derive(Clone, Debug)]
pub struct Rasterizer {
    profile: RasterProfile,
    llvmpipe: Option<llvmpipe::Draws>,
}

impl Rasterizer {
    pub fn new(profile: RasterProfile) -> Rasterizer {
        let llvmpipe = match profile {
            RasterProfile::Llvmpipe => Some(llvmpipe::Draws::new(llvmpipe::Framebuffer::Object)),
            RasterProfile::LlvmpipeWindow => {
                Some(llvmpipe::Draws::new(llvmpipe::Framebuffer::Window))
            }
            RasterProfile::Exact => None,
        };
        Rasterizer { profile, llvmpipe }
    }

    pub fn profile(&self) -> RasterProfile {
        self.profile
    }

    /// The next triangle of the current draw, in clip coordinates, under `state` (which
    /// stays the same until the draw ends).
    #[inline]
    pub fn triangle(
        &mut self,
        state: &RenderState,
        vertices: &[[f32; 4]; 3],
        sink: &mut impl RasterSink,
    ) {
        match &mut self.llvmpipe {
            Some(draws) => draws.triangle(state, vertices, sink),
            None => exact::rasterize_triangle(state, vertices, sink),
        }
    }

    /// The current draw ends: every triangle given so far has been rasterized on return.
    #[inline]
    pub fn end_draw(&mut self, state: &RenderState, sink: &mut impl RasterSink) {
        if let Some(draws) = &mut self.llvmpipe {
            draws.end_draw(state, sink);
        }
    }
}

/// Rasterize one triangle as a draw of its own.
pub fn rasterize_triangle(
    profile: RasterProfile,
    state: &RenderState,
    vertices: &[[f32; 4]; 3],
    sink: &mut impl RasterSink,
) {
    let mut rasterizer = Rasterizer::new(profile);
    rasterizer.triangle(state, vertices, sink);
    rasterizer.end_draw(state, sink);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_parse_by_name_and_an_unknown_one_lists_them() {
        for profile in RasterProfile::ALL {
            assert_eq!(RasterProfile::from_name(profile.name()), Ok(profile));
        }
        let error = RasterProfile::from_name("softpipe").unwrap_err();
        assert!(error.contains("softpipe"), "{error}");
        assert!(
            error.contains("llvmpipe, llvmpipe-window, exact"),
            "{error}"
        );
    }
}
