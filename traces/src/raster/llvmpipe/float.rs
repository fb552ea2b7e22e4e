//! f32 arithmetic as llvmpipe runs it: `draw_vbo` and the rasterizer threads set the SSE
//! control word to flush denormal results to zero (FTZ) and read denormal inputs as zero
//! (DAZ) (`util_fpstate_set_denorms_to_zero`, in draw_pt.c and lp_rast.c). Every operation
//! here flushes its result, and scene inputs go through [`flush`] once, so no denormal ever
//! reaches an operation and DAZ follows from FTZ.

/// A denormal becomes zero of the same sign, as the x86 FTZ bit makes it.
#[inline(always)]
pub(super) fn flush(x: f32) -> f32 {
    if x.is_subnormal() {
        0.0f32.copysign(x)
    } else {
        x
    }
}

#[inline(always)]
pub(super) fn add(a: f32, b: f32) -> f32 {
    flush(a + b)
}

#[inline(always)]
pub(super) fn sub(a: f32, b: f32) -> f32 {
    flush(a - b)
}

#[inline(always)]
pub(super) fn mul(a: f32, b: f32) -> f32 {
    flush(a * b)
}

/// IEEE division (LLVM's `fdiv`, C's `/`): never a reciprocal estimate.
#[inline(always)]
pub(super) fn div(a: f32, b: f32) -> f32 {
    flush(a / b)
}

/// `llvm.fmuladd` as LLVM lowers it on a CPU with FMA: `a · b + c` rounded once.
#[inline(always)]
pub(super) fn fused(a: f32, b: f32, c: f32) -> f32 {
    flush(a.mul_add(b, c))
}

/// `_mm_cvtps_epi32` under the default rounding mode: nearest, ties to even; NaN and values
/// outside the i32 range give the "integer indefinite" 0x8000_0000.
#[inline(always)]
pub(super) fn convert_nearest_even(x: f32) -> i32 {
    if x.is_nan() || !(-2_147_483_648.0..2_147_483_648.0).contains(&x) {
        i32::MIN
    } else {
        x.round_ties_even() as i32
    }
}

/// Mesa's `util_iround` on x86-64 (C code, no x87): `(int)(x + 0.5f)` for x >= 0, `(int)(x -
/// 0.5f)` otherwise: half away from zero, the addition rounded in f32.
#[inline(always)]
pub(super) fn round_half_away(x: f32) -> i32 {
    let shifted = if x >= 0.0 { x + 0.5 } else { x - 0.5 };
    if shifted.is_nan() || !(-2_147_483_648.0..2_147_483_648.0).contains(&shifted) {
        i32::MIN
    } else {
        shifted as i32
    }
}

/// x86 `minps(a, b)`: `a < b ? a : b`, so a NaN in either gives `b`.
#[inline(always)]
pub(super) fn sse_min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// x86 `maxps(a, b)`: `a > b ? a : b`, so a NaN in either gives `b`.
#[inline(always)]
pub(super) fn sse_max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn denormals_flush_to_signed_zero() {
        let tiny = f32::from_bits(1);
        assert_eq!(flush(tiny).to_bits(), 0);
        assert_eq!(flush(-tiny).to_bits(), (-0.0f32).to_bits());
        assert_eq!(flush(f32::MIN_POSITIVE), f32::MIN_POSITIVE);
        // 2^-126 · 0.5 is denormal: flushed.
        assert_eq!(mul(f32::MIN_POSITIVE, 0.5), 0.0);
    }

    #[test]
    fn conversions_round_as_the_hardware_does() {
        assert_eq!(convert_nearest_even(2.5), 2);
        assert_eq!(convert_nearest_even(3.5), 4);
        assert_eq!(convert_nearest_even(-2.5), -2);
        assert_eq!(convert_nearest_even(f32::NAN), i32::MIN);
        assert_eq!(convert_nearest_even(3e9), i32::MIN);
        assert_eq!(round_half_away(2.5), 3);
        assert_eq!(round_half_away(-2.5), -3);
        assert_eq!(round_half_away(2.49), 2);
    }

    #[test]
    fn min_and_max_return_the_second_operand_on_nan() {
        assert_eq!(sse_min(f32::NAN, 1.0), 1.0);
        assert!(sse_min(1.0, f32::NAN).is_nan());
        assert_eq!(sse_max(f32::NAN, 0.0), 0.0);
        assert_eq!(sse_min(0.5, 1.0), 0.5);
        assert_eq!(sse_max(-0.5, 0.0), 0.0);
    }
}
