//! Loading and storing only some lanes of a 256-bit vector: a run's last fragments, fewer
//! than a vector, in the AVX2 kernels (the depth test, [`crate::depth_run`], and the
//! planes' depths, `raster/llvmpipe/fragment.rs`). AVX2's own masked moves
//! (`vpmaskmovd`) store slowly on AMD's processors; AVX-512's, under a mask register, do
//! not. A kernel is written once over [`MaskedLanes`] and compiled for each, the AVX-512
//! one where the processor has AVX-512F and AVX-512VL ([`mask_registers_available`]).
//! (On this project's machine, an AMD EPYC, the random triangles' functional replay, runs
//! of 27 fragments, went from 54.3 to 47.7 ms of CPU, best of 15, two rounds taking turns.)

use std::arch::x86_64::*;

/// A way to move the lanes of a mask (each lane all ones or zero) between a vector and
/// eight u32s in memory, leaving the others alone. Only called from a function compiled
/// for the instructions it uses, into which it is inlined.
pub(crate) trait MaskedLanes {
    /// The lanes of `mask` of the eight u32s at `at`, the others zero.
    ///
    /// # Safety
    /// The lanes of `mask` are readable; the processor has the instructions.
    unsafe fn load(at: *const u32, mask: __m256i) -> __m256i;

    /// `v`'s lanes of `mask` to the eight u32s at `at`.
    ///
    /// # Safety
    /// The lanes of `mask` are writable; the processor has the instructions.
    unsafe fn store(at: *mut u32, mask: __m256i, v: __m256i);
}

/// AVX2's masked moves.
pub(crate) struct MaskMoves;

/// AVX-512's (AVX-512F and AVX-512VL) moves under a mask register.
pub(crate) struct MaskRegisters;

impl MaskedLanes for MaskMoves {
    #[inline(always)]
    unsafe fn load(at: *const u32, mask: __m256i) -> __m256i {
        // SAFETY: the caller's: the lanes read are readable, the processor has AVX2.
        unsafe { _mm256_maskload_epi32(at.cast(), mask) }
    }

    #[inline(always)]
    unsafe fn store(at: *mut u32, mask: __m256i, v: __m256i) {
        // SAFETY: as `load`'s.
        unsafe { _mm256_maskstore_epi32(at.cast(), mask, v) }
    }
}

impl MaskedLanes for MaskRegisters {
    #[inline(always)]
    unsafe fn load(at: *const u32, mask: __m256i) -> __m256i {
        // SAFETY: the caller's: the lanes read are readable, the processor has AVX-512F
        // and AVX-512VL.
        unsafe { _mm256_maskz_loadu_epi32(lane_bits(mask), at.cast()) }
    }

    #[inline(always)]
    unsafe fn store(at: *mut u32, mask: __m256i, v: __m256i) {
        // SAFETY: as `load`'s.
        unsafe { _mm256_mask_storeu_epi32(at.cast(), lane_bits(mask), v) }
    }
}

/// A mask vector's lanes as bits (lane `k` bit `k`), as a mask register takes them.
#[inline(always)]
unsafe fn lane_bits(mask: __m256i) -> __mmask8 {
    // SAFETY: the caller's processor has AVX.
    unsafe { _mm256_movemask_ps(_mm256_castsi256_ps(mask)) as __mmask8 }
}

/// Whether this processor has what [`MaskRegisters`] needs (checked once, then a load).
#[inline]
pub(crate) fn mask_registers_available() -> bool {
    is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx512vl")
}
