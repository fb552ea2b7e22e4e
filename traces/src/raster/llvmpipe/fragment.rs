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
    depths: PlaneDepths,
}

impl DepthPlane {
    /// From the window positions in the order llvmpipe hands them to setup.
    pub fn new(window: &[[f32; 3]; 3], framebuffer: Framebuffer, height: u32) -> DepthPlane {
        let PlaneCoefficients { a0, dzdx, dzdy } = PlaneCoefficients::new(window);
        // The framebuffer row is its own inverse mapping of the GL row.
        let mirror = match framebuffer.gl_row(0, height) {
            0 => None,
            last => Some(last as u32),
        };
        DepthPlane {
            depths: PlaneDepths {
                a0,
                dzdx,
                dzdy,
                mirror,
            },
        }
    }

    /// What a sink is told of the plane ([`crate::raster::RasterSink::depth_plane`]).
    pub fn depths(&self) -> PlaneDepths {
        self.depths
    }
}

/// A primitive's depth plane as llvmpipe's fragment shader evaluates it at a pixel
/// ([`Self::depth`]): the f32 coefficients its setup made and how framebuffer rows map to
/// GL rows. Every fragment of a primitive the llvmpipe profile rasterizes has the depth
/// this gives at its pixel, so a trace may keep the plane in place of the depths
/// ([`crate::trace`]'s plane spans), which its reader evaluates again.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneDepths {
    pub a0: f32,
    pub dzdx: f32,
    pub dzdy: f32,
    /// Framebuffer row `y` is GL row `y`, or `mirror - y` where rows run the other way (a
    /// window's framebuffer, `mirror` its height less one).
    pub mirror: Option<u32>,
}

impl PlaneDepths {
    /// The unorm24 depth at pixel `(x, y)` (framebuffer coordinates).
    #[inline(always)]
    pub fn depth(&self, x: u16, y: u16) -> u32 {
        depth(&self.coefficients(), x as f32, self.gl_row(y))
    }

    /// The depths at pixels `x..x + out.len()` of row `y`, into `out`: each what
    /// [`Self::depth`] gives (eight at a time with AVX2 and FMA, the same operations
    /// rounded the same way).
    #[inline]
    pub fn fill(&self, x: u16, y: u16, out: &mut [u32]) {
        #[cfg(target_arch = "x86_64")]
        match avx2::available() {
            // SAFETY: the processor has AVX2 and FMA (just checked).
            avx2::Available::Avx2 => return unsafe { avx2::fill(self, x, y, out) },
            // SAFETY: the processor has AVX2, FMA, AVX-512F and AVX-512VL (just checked).
            avx2::Available::WithMaskRegisters => {
                return unsafe { avx2::fill_mask_registers(self, x, y, out) }
            }
            avx2::Available::No => {}
        }
        self.fill_one_by_one(x, y, out);
    }

    /// [`Self::fill`] a pixel at a time.
    pub(crate) fn fill_one_by_one(&self, x: u16, y: u16, out: &mut [u32]) {
        let (coefficients, row) = (self.coefficients(), self.gl_row(y));
        for (k, depth_out) in out.iter_mut().enumerate() {
            *depth_out = depth(&coefficients, (x as usize + k) as f32, row);
        }
    }

    /// The GL row of framebuffer row `y`, as the shader takes it.
    #[inline(always)]
    fn gl_row(&self, y: u16) -> f32 {
        match self.mirror {
            Some(mirror) => (mirror as i64 - y as i64) as f32,
            None => y as f32,
        }
    }

    #[inline(always)]
    fn coefficients(&self) -> PlaneCoefficients {
        PlaneCoefficients {
            a0: self.a0,
            dzdx: self.dzdx,
            dzdy: self.dzdy,
        }
    }
}

/// unorm24 depth of one pixel at framebuffer column `x`, GL row `row`.
#[inline(always)]
fn depth(plane: &PlaneCoefficients, x: f32, row: f32) -> u32 {
    let z = plane
        .dzdy
        .mul_add(row, flush(plane.dzdx.mul_add(x, plane.a0)));
    let z = sse_max(sse_min(z, 1.0), 0.0);
    convert_nearest_even(z * DEPTH_ONE as f32) as u32
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::PlaneDepths;
    use crate::event::DEPTH_ONE;
    use crate::masked_lanes::{mask_registers_available, MaskMoves, MaskRegisters, MaskedLanes};
    use std::arch::x86_64::*;

    const LANES: usize = 8;

    /// Which of the kernels this processor runs.
    #[derive(Clone, Copy, PartialEq, Eq, Debug)]
    pub enum Available {
        No,
        /// AVX2 and FMA.
        Avx2,
        /// AVX2 and FMA, AVX-512F and AVX-512VL.
        WithMaskRegisters,
    }

    /// Checked once, then a load.
    pub fn available() -> Available {
        static AVAILABLE: std::sync::OnceLock<Available> = std::sync::OnceLock::new();
        *AVAILABLE.get_or_init(|| {
            match (is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma"))
                .then(mask_registers_available)
            {
                None => Available::No,
                Some(false) => Available::Avx2,
                Some(true) => Available::WithMaskRegisters,
            }
        })
    }

    /// [`fill_with`], the last pixels stored through AVX2's masked moves.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn fill(plane: &PlaneDepths, x: u16, y: u16, out: &mut [u32]) {
        // SAFETY: compiled for AVX2 and FMA, all the kernel and its moves need.
        unsafe { fill_with::<MaskMoves>(plane, x, y, out) }
    }

    /// [`fill_with`], the last pixels stored through AVX-512's masked moves.
    #[target_feature(enable = "avx2,fma,avx512f,avx512vl")]
    pub unsafe fn fill_mask_registers(plane: &PlaneDepths, x: u16, y: u16, out: &mut [u32]) {
        // SAFETY: compiled for AVX2, FMA, AVX-512F and AVX-512VL, all the kernel and its
        // moves need.
        unsafe { fill_with::<MaskRegisters>(plane, x, y, out) }
    }

    /// [`PlaneDepths::fill`] eight pixels at a time: `fmadd(dzdx, x, a0)` flushed as FTZ
    /// would (a denormal becomes zero of its sign), `fmadd(dzdy, row, that)`, `minps` with 1
    /// and `maxps` with 0 (a NaN gives the second operand, as `sse_min` and `sse_max`), times
    /// 2^24 - 1 and converted with rounding to nearest even (the default rounding mode,
    /// which nothing in the process changes). The last pixels, fewer than eight, are
    /// computed as a whole vector and stored through a mask, by `M`. Inlined into a
    /// function compiled for AVX2 and FMA and what `M` needs.
    #[inline(always)]
    unsafe fn fill_with<M: MaskedLanes>(plane: &PlaneDepths, x: u16, y: u16, out: &mut [u32]) {
        // SAFETY: the caller's: compiled for AVX2 and FMA.
        let row = unsafe { RowDepths::new(plane, y) };
        let step = _mm256_set1_ps(LANES as f32);
        // Pixel columns as f32, exact (below 2^24).
        let mut columns = _mm256_add_ps(
            _mm256_set1_ps(x as f32),
            _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0),
        );
        let mut chunks = out.chunks_exact_mut(LANES);
        for chunk in &mut chunks {
            // SAFETY: eight u32s in bounds; an unaligned store. Compiled for AVX2 and FMA.
            unsafe { _mm256_storeu_si256(chunk.as_mut_ptr().cast(), row.depths(columns)) };
            columns = _mm256_add_ps(columns, step);
        }
        let rest = chunks.into_remainder();
        if !rest.is_empty() {
            // Lane k holds pixel k of the rest, stored where k is below its length.
            let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let stored = _mm256_cmpgt_epi32(_mm256_set1_epi32(rest.len() as i32), lanes);
            // SAFETY: a masked store writes only the lanes of its mask, the slice's own
            // elements (fewer than eight from its start). Compiled for AVX2 and FMA and
            // what `M` needs.
            unsafe { M::store(rest.as_mut_ptr(), stored, row.depths(columns)) };
        }
    }

    /// A plane's terms for one row, in every lane.
    struct RowDepths {
        a0: __m256,
        dzdx: __m256,
        dzdy: __m256,
        row: __m256,
        scale: __m256,
    }

    impl RowDepths {
        /// # Safety
        /// The processor has AVX.
        #[inline(always)]
        unsafe fn new(plane: &PlaneDepths, y: u16) -> RowDepths {
            RowDepths {
                a0: _mm256_set1_ps(plane.a0),
                dzdx: _mm256_set1_ps(plane.dzdx),
                dzdy: _mm256_set1_ps(plane.dzdy),
                row: _mm256_set1_ps(plane.gl_row(y)),
                scale: _mm256_set1_ps(DEPTH_ONE as f32),
            }
        }

        /// The depths at the pixel columns `columns` (inlined, as every method here, into
        /// a function compiled for the instructions).
        ///
        /// # Safety
        /// The processor has AVX and FMA.
        #[inline(always)]
        unsafe fn depths(&self, columns: __m256) -> __m256i {
            let sign = _mm256_set1_ps(-0.0);
            let partial = _mm256_fmadd_ps(self.dzdx, columns, self.a0);
            // |partial| below the least normal: a denormal (or a zero), kept as its sign.
            let magnitude = _mm256_andnot_ps(sign, partial);
            let smallest = _mm256_set1_ps(f32::MIN_POSITIVE);
            let denormal = _mm256_cmp_ps::<_CMP_LT_OQ>(magnitude, smallest);
            let partial = _mm256_blendv_ps(partial, _mm256_and_ps(partial, sign), denormal);
            let z = _mm256_fmadd_ps(self.dzdy, self.row, partial);
            let z = _mm256_max_ps(_mm256_min_ps(z, _mm256_set1_ps(1.0)), _mm256_setzero_ps());
            _mm256_cvtps_epi32(_mm256_mul_ps(z, self.scale))
        }
    }
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
        let y = py as u16;
        let (coefficients, row) = (self.depths.coefficients(), self.depths.gl_row(y));
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU has FMA, checked just above.
            unsafe { emit_span_fma(&coefficients, row, y, first, last, sink) };
            return;
        }
        emit_span(&coefficients, row, y, first, last, sink);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// A coefficient: mostly an ordinary slope or offset, sometimes a value at an edge of
    /// f32 (a NaN, an infinity, a denormal, the least normal, a huge or a tiny one).
    fn coefficient(random: &mut SplitMix64) -> f32 {
        const EDGES: [f32; 10] = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            1.0e-40,
            -0.0,
            3.0e38,
            1.0e-30,
            0.5,
        ];
        match random.below(8) {
            0 => EDGES[random.below(EDGES.len() as u64) as usize],
            // Random bits: every exponent.
            1 => f32::from_bits(random.next_u64() as u32),
            _ => (random.below(1 << 24) as f32 / (1 << 22) as f32 - 2.0) / 1024.0,
        }
    }

    /// A row's depths filled by a path: `fill` and each vector path this processor has.
    type Fill = fn(&PlaneDepths, u16, u16, &mut [u32]);

    fn fills() -> Vec<(&'static str, Fill)> {
        let mut fills: Vec<(&'static str, Fill)> = vec![("fill", PlaneDepths::fill)];
        #[cfg(target_arch = "x86_64")]
        {
            use avx2::Available;
            let available = avx2::available();
            if available != Available::No {
                // SAFETY: the processor has AVX2 and FMA (just checked).
                fills.push(("AVX2", |p, x, y, out| unsafe { avx2::fill(p, x, y, out) }));
            }
            if available == Available::WithMaskRegisters {
                // SAFETY: the processor has AVX2, FMA, AVX-512F and AVX-512VL (just checked).
                fills.push(("AVX-512 masks", |p, x, y, out| unsafe {
                    avx2::fill_mask_registers(p, x, y, out)
                }));
            }
        }
        fills
    }

    #[test]
    fn a_filled_row_has_each_pixels_depth() {
        // Each vector path the processor has (AVX2 and FMA, with AVX2's masked moves or
        // with AVX-512's) against the pixel-by-pixel definition, over random planes and
        // spans of every length up to five vectors; and `fill`, whichever path it takes.
        let mut random = SplitMix64(2026);
        let mut denormal_partials = 0;
        for case in 0..20_000 {
            let mut plane = PlaneDepths {
                a0: coefficient(&mut random),
                dzdx: coefficient(&mut random),
                dzdy: coefficient(&mut random),
                mirror: random.chance(50).then(|| random.below(70_000) as u32),
            };
            let len = 1 + random.below(40) as usize;
            let x = random.below(65_536 - len as u64) as u16;
            let y = random.below(65_536) as u16;
            if case % 10 == 0 {
                // A partial sum `dzdx · x + a0` that is a denormal (of either sign), which
                // the shader flushes to zero.
                plane.dzdx = if case % 20 == 0 { 1.0e-42 } else { -1.0e-42 };
                plane.a0 = 0.0;
                let partial = plane.dzdx.mul_add(x as f32, plane.a0);
                denormal_partials += partial.is_subnormal() as u32;
            }
            for (path, fill) in fills() {
                let mut filled = vec![u32::MAX; len + 3];
                fill(&plane, x, y, &mut filled[..len]);
                for (k, &depth) in filled[..len].iter().enumerate() {
                    let expected = plane.depth(x + k as u16, y);
                    assert_eq!(
                        depth,
                        expected,
                        "{path}: {plane:?} at ({}, {y})",
                        x as usize + k
                    );
                }
                assert_eq!(
                    filled[len..],
                    [u32::MAX; 3],
                    "{path}: a fill writes past its pixels"
                );
            }
        }
        assert!(
            denormal_partials > 100,
            "{denormal_partials} denormal partial sums tried"
        );
    }

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
