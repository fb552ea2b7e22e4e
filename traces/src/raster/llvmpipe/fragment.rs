//! Depth at a pixel as llvmpipe's fragment shader computes it: the plane interpolated with
//! two fused multiply-adds (lp_bld_interp.c, `attribs_update_simple`: `a = fmuladd(dadx,
//! x, a0)`, then `fmuladd(dady, y, a)`, at the pixel's integer framebuffer coordinates),
//! clamped to [0, 1] (`lp_build_clamp`: `max(min(z, 1), 0)` with SSE's NaN rule, so NaN
//! becomes 1), and converted to 24-bit unorm by `z · 16777215` in f32 rounded to nearest even
//! (lp_bld_conv.c, `lp_build_clamped_float_to_unsigned_norm` when the width is the mantissa's
//! plus one, then `lp_build_iround`).
//!
//! The first multiply-add's result is flushed as FTZ would (a denormal there could break a
//! rounding tie in the second); the second's need not be: a denormal z converts to 0 either
//! way. The coefficients come from the flushing setup.

use super::super::coverage::SpanDepths;
use super::super::RasterSink;
use super::float::{convert_nearest_even, flush, sse_max, sse_min};
use super::setup::PlaneCoefficients;
use super::Framebuffer;
use crate::event::{Fragment, DEPTH_ONE};

/// The depth plane of one primitive, with the row mapping of its framebuffer.
pub(super) struct DepthPlane {
    coefficients: PlaneCoefficients,
    framebuffer: Framebuffer,
    height: u32,
}

impl DepthPlane {
    /// From the window positions in the order llvmpipe hands them to setup.
    pub fn new(window: &[[f32; 3]; 3], framebuffer: Framebuffer, height: u32) -> DepthPlane {
        DepthPlane {
            coefficients: PlaneCoefficients::new(window),
            framebuffer,
            height,
        }
    }
}

/// unorm24 depth of one pixel at framebuffer column `x`, row `row`.
#[inline(always)]
fn depth(plane: &PlaneCoefficients, x: f32, row: f32) -> u32 {
    let z = plane
        .dzdy
        .mul_add(row, flush(plane.dzdx.mul_add(x, plane.a0)));
    let z = sse_max(sse_min(z, 1.0), 0.0);
    convert_nearest_even(z * DEPTH_ONE as f32) as u32
}

#[inline(always)]
fn emit_span(
    plane: &PlaneCoefficients,
    row: f32,
    y: u16,
    first: i64,
    last: i64,
    sink: &mut impl RasterSink,
) {
    for px in first..=last {
        sink.fragment(Fragment {
            x: px as u16,
            y,
            z: depth(plane, px as f32, row),
        });
    }
}

/// The span loop compiled for FMA, so `mul_add` is one instruction, not a call.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "fma")]
fn emit_span_fma(
    plane: &PlaneCoefficients,
    row: f32,
    y: u16,
    first: i64,
    last: i64,
    sink: &mut impl RasterSink,
) {
    emit_span(plane, row, y, first, last, sink);
}

impl SpanDepths for DepthPlane {
    #[inline(always)]
    fn emit(&self, py: i64, first: i64, last: i64, sink: &mut impl RasterSink) {
        // The framebuffer row is its own inverse mapping of the GL row.
        let row = self.framebuffer.gl_row(py, self.height) as f32;
        let y = py as u16;
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU has FMA, checked just above.
            unsafe { emit_span_fma(&self.coefficients, row, y, first, last, sink) };
            return;
        }
        emit_span(&self.coefficients, row, y, first, last, sink);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_clamps_and_rounds_as_llvmpipe() {
        let flat = |a0: f32| PlaneCoefficients {
            a0,
            dzdx: 0.0,
            dzdy: 0.0,
        };
        assert_eq!(depth(&flat(0.0), 3.0, 5.0), 0);
        assert_eq!(depth(&flat(-0.25), 3.0, 5.0), 0);
        assert_eq!(depth(&flat(1.0), 3.0, 5.0), DEPTH_ONE);
        assert_eq!(depth(&flat(7.0), 3.0, 5.0), DEPTH_ONE);
        // NaN: min(NaN, 1) is 1.
        assert_eq!(depth(&flat(f32::NAN), 3.0, 5.0), DEPTH_ONE);
        // 0.5 · 16777215 = 8388607.5 exactly in f32; ties to even: 8388608.
        assert_eq!(depth(&flat(0.5), 0.0, 0.0), 8_388_608);
        // a0 + dzdx·x + dzdy·y = 0.25 + 0.125·2 + 0.0625·4 = 0.75; · 16777215 =
        // 12582911.25 -> 12582911.
        let sloped = PlaneCoefficients {
            a0: 0.25,
            dzdx: 0.125,
            dzdy: 0.0625,
        };
        assert_eq!(depth(&sloped, 2.0, 4.0), 12_582_911);
    }
}
