//! The depth test of a run of fragments of one row fused with the [`RunTally`] its tile
//! keeps: one pass over the depths that tests, writes and reduces. On x86_64 it is written
//! out with SIMD: AVX2, eight fragments a step, where the CPU has it (checked at run time;
//! a run's last fragments through AVX-512's mask registers where it has those too,
//! [`crate::masked_lanes`]), else SSE2, four a step. LLVM vectorises the test or the reduction alone, but not the two
//! fused, and two passes cost a store and a reload of every outcome.

use crate::query::RunTally;
use crate::state::DepthFunc;

/// A depth test of runs whose function and write enable are constants in it.
pub(crate) trait RunKernel: Copy {
    /// Whether a passing fragment writes its depth.
    const WRITES: bool;

    /// Test the fragments at `depths` against the stored depths `stored` (as long),
    /// replace a stored depth by its fragment's where it passed if [`Self::WRITES`], and
    /// tally the run: what testing them one by one and [`RunTally::of`] their outcomes give.
    fn test_and_tally(self, depths: &[u32], stored: &mut [u32]) -> RunTally;
}

/// The instructions a kernel runs in, one this CPU has: only [`KernelIsa::best`] makes one.
#[derive(Clone, Copy, Debug)]
pub(crate) struct KernelIsa(Isa);

impl KernelIsa {
    /// The best instructions this CPU runs.
    pub(crate) fn best() -> KernelIsa {
        KernelIsa(Isa::best())
    }
}

/// The instructions a kernel is written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Isa {
    /// One fragment after the other.
    #[cfg_attr(all(target_arch = "x86_64", target_feature = "sse2"), allow(dead_code))]
    Plain,
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    Sse2,
    /// AVX2 (with POPCNT): only where the CPU has both.
    #[cfg(target_arch = "x86_64")]
    Avx2,
    /// AVX2 with AVX-512's masked moves for a run's last fragments
    /// ([`crate::masked_lanes`]): only where the CPU has all of them.
    #[cfg(target_arch = "x86_64")]
    Avx2MaskRegisters,
}

impl Isa {
    /// What every CPU the build targets runs.
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    const BASELINE: Isa = Isa::Sse2;
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    const BASELINE: Isa = Isa::Plain;

    /// The best this CPU runs.
    fn best() -> Isa {
        #[cfg(target_arch = "x86_64")]
        if avx2::available() {
            return match crate::masked_lanes::mask_registers_available() {
                true => Isa::Avx2MaskRegisters,
                false => Isa::Avx2,
            };
        }
        Isa::BASELINE
    }
}

/// The kernel of the depth function of code `FUNC`, in `isa`.
#[derive(Clone, Copy)]
struct Kernel<const FUNC: u8, const WRITE: bool> {
    isa: Isa,
}

impl<const FUNC: u8, const WRITE: bool> RunKernel for Kernel<FUNC, WRITE> {
    const WRITES: bool = WRITE;

    #[inline(always)]
    fn test_and_tally(self, depths: &[u32], stored: &mut [u32]) -> RunTally {
        assert_eq!(depths.len(), stored.len(), "a stored depth per fragment");
        match self.isa {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Isa::Avx2` reaches a kernel only where the CPU has AVX2 and POPCNT
            // (`Isa::best`, or the tests, which check).
            Isa::Avx2 => unsafe { avx2::test_and_tally::<FUNC, WRITE>(depths, stored) },
            #[cfg(target_arch = "x86_64")]
            // SAFETY: `Isa::Avx2MaskRegisters` reaches a kernel only where the CPU has AVX2,
            // POPCNT, AVX-512F and AVX-512VL (`Isa::best`, or the tests, which check).
            Isa::Avx2MaskRegisters => unsafe {
                avx2::test_and_tally_mask_registers::<FUNC, WRITE>(depths, stored)
            },
            #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
            // SAFETY: the kernel needs SSE2, which the build targets (`target_feature = "sse2"`).
            Isa::Sse2 => unsafe { sse2::test_and_tally::<FUNC, WRITE>(depths, stored) },
            Isa::Plain => plain_kernel::<FUNC, WRITE>(depths, stored),
        }
    }
}

/// Work done with one [`RunKernel`]: its code is made once per kernel, the kernel inlined
/// in it, so a choice of function made once serves every run it tests.
pub(crate) trait WithKernel {
    type Output;
    fn run<K: RunKernel>(self, kernel: K) -> Self::Output;
}

/// `job` done with the kernel of `func` and `write` in `isa`.
#[inline]
pub(crate) fn with_kernel_in<J: WithKernel>(
    KernelIsa(isa): KernelIsa,
    func: DepthFunc,
    write: bool,
    job: J,
) -> J::Output {
    macro_rules! kernel_for {
        ($($func:ident),*) => {
            match (func, write) {
                $(
                    (DepthFunc::$func, false) => {
                        job.run(Kernel::<{ DepthFunc::$func as u8 }, false> { isa })
                    }
                    (DepthFunc::$func, true) => {
                        job.run(Kernel::<{ DepthFunc::$func as u8 }, true> { isa })
                    }
                )*
            }
        };
    }
    kernel_for!(Never, Less, Equal, Lequal, Greater, Notequal, Gequal, Always)
}

/// Test the fragments at `depths` against `stored` (as long) by `func` and replace a stored
/// depth by its fragment's where it passed, counting nothing (where no query is open).
#[inline]
pub(crate) fn test_and_write(func: DepthFunc, depths: &[u32], stored: &mut [u32]) {
    // One loop per function, each a constant in it; a select, not a branch: it vectorises.
    macro_rules! loop_for {
        ($($func:ident),*) => {
            match func {
                $(
                    DepthFunc::$func => {
                        for (&z, s) in depths.iter().zip(stored) {
                            *s = if DepthFunc::$func.passes(z, *s) { z } else { *s };
                        }
                    }
                )*
            }
        };
    }
    loop_for!(Never, Less, Equal, Lequal, Greater, Notequal, Gequal, Always)
}

/// The kernel one fragment after the other, where SSE2 is missing.
#[cfg_attr(all(target_arch = "x86_64", target_feature = "sse2"), allow(dead_code))]
fn plain_kernel<const FUNC: u8, const WRITE: bool>(depths: &[u32], stored: &mut [u32]) -> RunTally {
    let func = DepthFunc::ALL[FUNC as usize];
    let mut tally = RunTally {
        fragments: depths.len() as u32,
        zmin: u32::MAX,
        ..RunTally::default()
    };
    for (i, (&z, s)) in depths.iter().zip(stored).enumerate() {
        if !func.passes(z, *s) {
            continue;
        }
        if WRITE {
            *s = z;
        }
        if tally.passed == 0 {
            tally.first = i as u32;
        }
        tally.passed += 1;
        tally.last = i as u32;
        tally.zmin = tally.zmin.min(z);
        tally.zmax = tally.zmax.max(z);
    }
    tally
}

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
mod sse2 {
    use crate::query::RunTally;
    use crate::state::DepthFunc;
    use std::arch::x86_64::*;

    /// Flips the sign bit: unsigned order becomes SSE2's signed order.
    const BIAS: i32 = i32::MIN;

    /// Fragments whose outcomes one word of bits holds (16 steps of four).
    const BLOCK: usize = 64;

    /// The kernel in SSE2: steps of four, their outcomes gathered as bits a block at a time
    /// (the first and last passing found once a block, not once a step); then the last
    /// fragments, fewer than four. Read-only, those are the last four again with the lanes
    /// already done masked off; writing (or in a run shorter than four), one by one: a load
    /// of stored depths a step has just written in part would wait for the store.
    #[inline]
    #[target_feature(enable = "sse2")]
    pub(super) fn test_and_tally<const FUNC: u8, const WRITE: bool>(
        depths: &[u32],
        stored: &mut [u32],
    ) -> RunTally {
        let len = depths.len();
        let mut tally = Tally::new();
        let whole = len / 4 * 4;
        let every_lane = _mm_set1_epi32(-1);
        for (block, (depths, stored)) in depths[..whole]
            .chunks(BLOCK)
            .zip(stored[..whole].chunks_mut(BLOCK))
            .enumerate()
        {
            let mut passed = 0u64;
            for (step, (z, s)) in depths
                .chunks_exact(4)
                .zip(stored.chunks_exact_mut(4))
                .enumerate()
            {
                let (z, s) = (z.try_into().expect("four"), s.try_into().expect("four"));
                let lanes = tally.step::<FUNC, WRITE>(z, s, every_lane);
                passed |= (lanes as u64) << (step * 4);
            }
            tally.note_passed(block * BLOCK, passed);
        }
        if whole < len && len >= 4 && !WRITE {
            // Lane k of the last four is fragment len - 4 + k; those below `whole` are done.
            let at = len - 4;
            let lanes = _mm_setr_epi32(0, 1, 2, 3);
            let not_done = _mm_cmpgt_epi32(lanes, _mm_set1_epi32((whole - at) as i32 - 1));
            let (z, s) = (depths[at..].try_into().expect("four"), &mut stored[at..]);
            let lanes = tally.step::<FUNC, WRITE>(z, s.try_into().expect("four"), not_done);
            tally.note_passed(at, lanes as u64);
        } else {
            // (Selects, not branches: an outcome is as likely as not.)
            let func = DepthFunc::ALL[FUNC as usize];
            let mut passed = 0u64;
            for (i, (&z, s)) in depths[whole..].iter().zip(&mut stored[whole..]).enumerate() {
                let pass = func.passes(z, *s);
                if WRITE {
                    *s = if pass { z } else { *s };
                }
                tally.one(z, pass);
                passed |= (pass as u64) << i;
            }
            tally.note_passed(whole, passed);
        }
        tally.finish(len)
    }

    /// The running tally: per lane (and for fragments tested one by one) the passing count
    /// and the depth range, the vectors' biased; the first and last passing index.
    struct Tally {
        passed: __m128i,
        zmin: __m128i,
        zmax: __m128i,
        passed_one_by_one: u32,
        zmin_one_by_one: u32,
        zmax_one_by_one: u32,
        first: Option<u32>,
        last: u32,
    }

    impl Tally {
        #[inline]
        #[target_feature(enable = "sse2")]
        fn new() -> Tally {
            Tally {
                passed: _mm_setzero_si128(),
                zmin: _mm_set1_epi32(i32::MAX),
                zmax: _mm_set1_epi32(i32::MIN),
                passed_one_by_one: 0,
                zmin_one_by_one: u32::MAX,
                zmax_one_by_one: 0,
                first: None,
                last: 0,
            }
        }

        /// Test four fragments (depths `z`, stored `s`) in the lanes of `valid`, write where
        /// they passed if `WRITE`, and count them. Returns the passing lanes as bits.
        #[inline]
        #[target_feature(enable = "sse2")]
        fn step<const FUNC: u8, const WRITE: bool>(
            &mut self,
            z: &[u32; 4],
            s: &mut [u32; 4],
            valid: __m128i,
        ) -> u32 {
            let (z, stored) = (load(z), load(s));
            let bias = _mm_set1_epi32(BIAS);
            let biased = _mm_xor_si128(z, bias);
            let pass = _mm_and_si128(passes::<FUNC>(biased, _mm_xor_si128(stored, bias)), valid);
            if WRITE {
                store(s, select(pass, z, stored));
            }
            // A passing lane's mask is -1.
            self.passed = _mm_sub_epi32(self.passed, pass);
            let low = select(pass, biased, _mm_set1_epi32(i32::MAX));
            let high = select(pass, biased, _mm_set1_epi32(i32::MIN));
            self.zmin = select(_mm_cmplt_epi32(low, self.zmin), low, self.zmin);
            self.zmax = select(_mm_cmpgt_epi32(high, self.zmax), high, self.zmax);
            _mm_movemask_ps(_mm_castsi128_ps(pass)) as u32
        }

        /// Count one fragment at depth `z` that passed or not.
        #[inline]
        fn one(&mut self, z: u32, pass: bool) {
            self.passed_one_by_one += pass as u32;
            self.zmin_one_by_one = self.zmin_one_by_one.min(if pass { z } else { u32::MAX });
            self.zmax_one_by_one = self.zmax_one_by_one.max(if pass { z } else { 0 });
        }

        /// Fragments `at + i` passed for the bits `i` set in `passed` (called in order).
        #[inline]
        fn note_passed(&mut self, at: usize, passed: u64) {
            if passed != 0 {
                let at = at as u32;
                self.first.get_or_insert(at + passed.trailing_zeros());
                self.last = at + 63 - passed.leading_zeros();
            }
        }

        /// The lanes folded into the run's tally (`fragments` long).
        #[inline]
        #[target_feature(enable = "sse2")]
        fn finish(self, fragments: usize) -> RunTally {
            let lanes = |v: __m128i| {
                let mut out = [0u32; 4];
                store(&mut out, v);
                out
            };
            let unbias = |v: u32| v ^ BIAS as u32;
            let zmin = lanes(self.zmin).map(unbias).into_iter().min();
            let zmax = lanes(self.zmax).map(unbias).into_iter().max();
            RunTally {
                fragments: fragments as u32,
                passed: lanes(self.passed).into_iter().sum::<u32>() + self.passed_one_by_one,
                zmin: zmin.expect("four lanes").min(self.zmin_one_by_one),
                zmax: zmax.expect("four lanes").max(self.zmax_one_by_one),
                first: self.first.unwrap_or(0),
                last: self.last,
            }
        }
    }

    /// Lanes where a fragment at (biased) depth `z` passes against (biased) `stored` by
    /// the function of code `FUNC`: all ones, else zero.
    #[inline]
    #[target_feature(enable = "sse2")]
    fn passes<const FUNC: u8>(z: __m128i, stored: __m128i) -> __m128i {
        const NEVER: u8 = DepthFunc::Never as u8;
        const LESS: u8 = DepthFunc::Less as u8;
        const EQUAL: u8 = DepthFunc::Equal as u8;
        const LEQUAL: u8 = DepthFunc::Lequal as u8;
        const GREATER: u8 = DepthFunc::Greater as u8;
        const NOTEQUAL: u8 = DepthFunc::Notequal as u8;
        const GEQUAL: u8 = DepthFunc::Gequal as u8;
        let not = |v| _mm_xor_si128(v, _mm_set1_epi32(-1));
        match FUNC {
            NEVER => _mm_setzero_si128(),
            LESS => _mm_cmplt_epi32(z, stored),
            EQUAL => _mm_cmpeq_epi32(z, stored),
            LEQUAL => not(_mm_cmpgt_epi32(z, stored)),
            GREATER => _mm_cmpgt_epi32(z, stored),
            NOTEQUAL => not(_mm_cmpeq_epi32(z, stored)),
            GEQUAL => not(_mm_cmplt_epi32(z, stored)),
            _ => _mm_set1_epi32(-1),
        }
    }

    /// `a` in the lanes of `mask`, `b` in the others.
    #[inline]
    #[target_feature(enable = "sse2")]
    fn select(mask: __m128i, a: __m128i, b: __m128i) -> __m128i {
        _mm_or_si128(_mm_and_si128(mask, a), _mm_andnot_si128(mask, b))
    }

    #[inline]
    #[target_feature(enable = "sse2")]
    fn load(lanes: &[u32; 4]) -> __m128i {
        // SAFETY: the reference holds the 16 bytes read; an unaligned load needs no more.
        unsafe { _mm_loadu_si128(lanes.as_ptr().cast()) }
    }

    #[inline]
    #[target_feature(enable = "sse2")]
    fn store(out: &mut [u32; 4], lanes: __m128i) {
        // SAFETY: the reference holds the 16 bytes written; an unaligned store needs no more.
        unsafe { _mm_storeu_si128(out.as_mut_ptr().cast(), lanes) }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use crate::masked_lanes::{MaskMoves, MaskRegisters, MaskedLanes};
    use crate::query::RunTally;
    use crate::state::DepthFunc;
    use std::arch::x86_64::*;

    /// Fragments a step tests.
    const LANES: usize = 8;
    /// Fragments whose outcomes one word of bits holds (8 steps).
    const BLOCK: usize = 64;

    /// Whether this CPU runs the kernel (each check a cached flag's load).
    #[inline(always)]
    pub(super) fn available() -> bool {
        is_x86_feature_detected!("avx2") && is_x86_feature_detected!("popcnt")
    }

    /// The kernel in AVX2 ([`kernel`]), the last fragments through AVX2's masked moves.
    #[inline]
    #[target_feature(enable = "avx2,popcnt")]
    pub(super) fn test_and_tally<const FUNC: u8, const WRITE: bool>(
        depths: &[u32],
        stored: &mut [u32],
    ) -> RunTally {
        // SAFETY: compiled for AVX2 and POPCNT, all the kernel and its moves need.
        unsafe { kernel::<FUNC, WRITE, MaskMoves>(depths, stored) }
    }

    /// The kernel in AVX2 ([`kernel`]), the last fragments through AVX-512's masked moves.
    #[inline]
    #[target_feature(enable = "avx2,popcnt,avx512f,avx512vl")]
    pub(super) fn test_and_tally_mask_registers<const FUNC: u8, const WRITE: bool>(
        depths: &[u32],
        stored: &mut [u32],
    ) -> RunTally {
        // SAFETY: compiled for AVX2, POPCNT, AVX-512F and AVX-512VL, all the kernel and its
        // moves need.
        unsafe { kernel::<FUNC, WRITE, MaskRegisters>(depths, stored) }
    }

    /// The kernel: steps of eight, their outcomes gathered as bits a block at a time (the
    /// passing count, first and last found once a block); then the last fragments, fewer
    /// than eight, in one step loading (and storing) only their lanes, by `M`. Depths
    /// compare unsigned: AVX2 has unsigned minimum and maximum, and signed comparisons of
    /// depths with their sign bit flipped. Inlined into a function compiled for AVX2 and
    /// POPCNT and what `M` needs.
    #[inline(always)]
    unsafe fn kernel<const FUNC: u8, const WRITE: bool, M: MaskedLanes>(
        depths: &[u32],
        stored: &mut [u32],
    ) -> RunTally {
        let len = depths.len();
        let stored = &mut stored[..len];
        let whole = len / LANES * LANES;
        let mut tally = Tally::new();
        // Steps of eight by index (a run is mostly a block or less: iterators over blocks
        // and their steps cost more than the steps), each block's outcomes gathered in
        // `passed` from bit 0 at `block`.
        let (mut passed, mut block) = (0u64, 0);
        let mut at = 0;
        while at < whole {
            // SAFETY: eight u32s from `at` in both slices (`at + 8 <= whole <= len`, the
            // slices `len` long); unaligned loads and stores.
            let (z, old) = unsafe {
                (
                    _mm256_loadu_si256(depths.as_ptr().add(at).cast()),
                    _mm256_loadu_si256(stored.as_ptr().add(at).cast()),
                )
            };
            let pass = passes::<FUNC>(z, old);
            if WRITE {
                let new = _mm256_blendv_epi8(old, z, pass);
                // SAFETY: as the loads.
                unsafe { _mm256_storeu_si256(stored.as_mut_ptr().add(at).cast(), new) };
            }
            passed |= (tally.add(z, pass) as u64) << (at - block);
            at += LANES;
            if at - block == BLOCK {
                tally.note_passed(block, passed);
                (passed, block) = (0, at);
            }
        }
        if whole < len {
            let (depths, stored) = (&depths[whole..], &mut stored[whole..]);
            // Lane k holds fragment whole + k, for k below the fragments left.
            let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
            let valid = _mm256_cmpgt_epi32(_mm256_set1_epi32(depths.len() as i32), lanes);
            // SAFETY: a masked load reads only the lanes of its mask, here the slices' own
            // elements (fewer than eight from their starts); the others read as zero.
            let (z, old) = unsafe {
                (
                    M::load(depths.as_ptr(), valid),
                    M::load(stored.as_ptr(), valid),
                )
            };
            let pass = _mm256_and_si256(passes::<FUNC>(z, old), valid);
            if WRITE {
                // SAFETY: a masked store writes only the lanes of its mask, passing lanes of
                // `valid`: the slice's own elements.
                unsafe { M::store(stored.as_mut_ptr(), pass, z) };
            }
            // The block holds at most 56 fragments' bits: these fit after them.
            passed |= (tally.add(z, pass) as u64) << (whole - block);
        }
        tally.note_passed(block, passed);
        tally.finish(len)
    }

    /// The running tally: per lane the passing depths' range; the passing count and the
    /// first and last passing index.
    struct Tally {
        zmin: __m256i,
        zmax: __m256i,
        passed: u32,
        first: Option<u32>,
        last: u32,
    }

    impl Tally {
        #[inline]
        #[target_feature(enable = "avx2")]
        fn new() -> Tally {
            Tally {
                zmin: _mm256_set1_epi32(-1),
                zmax: _mm256_setzero_si256(),
                passed: 0,
                first: None,
                last: 0,
            }
        }

        /// Take the depths `z` of the lanes of `pass` into the range. Returns those lanes
        /// as bits.
        #[inline]
        #[target_feature(enable = "avx2")]
        fn add(&mut self, z: __m256i, pass: __m256i) -> u32 {
            // A failing lane stands in as u32::MAX for the minimum and 0 for the maximum.
            let low = _mm256_blendv_epi8(_mm256_set1_epi32(-1), z, pass);
            self.zmin = _mm256_min_epu32(self.zmin, low);
            self.zmax = _mm256_max_epu32(self.zmax, _mm256_and_si256(z, pass));
            _mm256_movemask_ps(_mm256_castsi256_ps(pass)) as u32
        }

        /// Fragments `at + i` passed for the bits `i` set in `passed` (called in order).
        #[inline]
        #[target_feature(enable = "avx2,popcnt")]
        fn note_passed(&mut self, at: usize, passed: u64) {
            if passed != 0 {
                let at = at as u32;
                self.passed += passed.count_ones();
                self.first.get_or_insert(at + passed.trailing_zeros());
                self.last = at + 63 - passed.leading_zeros();
            }
        }

        /// The lanes folded into the run's tally (`fragments` long).
        #[inline]
        #[target_feature(enable = "avx2")]
        fn finish(self, fragments: usize) -> RunTally {
            RunTally {
                fragments: fragments as u32,
                passed: self.passed,
                zmin: fold(self.zmin, |a, b| _mm_min_epu32(a, b)),
                zmax: fold(self.zmax, |a, b| _mm_max_epu32(a, b)),
                first: self.first.unwrap_or(0),
                last: self.last,
            }
        }
    }

    /// The eight lanes of `v` folded into one by `op` (a lane-wise minimum or maximum).
    #[inline]
    #[target_feature(enable = "avx2")]
    fn fold(v: __m256i, op: impl Fn(__m128i, __m128i) -> __m128i) -> u32 {
        let four = op(_mm256_castsi256_si128(v), _mm256_extracti128_si256::<1>(v));
        let two = op(four, _mm_shuffle_epi32::<0b01_00_11_10>(four));
        let one = op(two, _mm_shuffle_epi32::<0b10_11_00_01>(two));
        _mm_cvtsi128_si32(one) as u32
    }

    /// Lanes where a fragment at depth `z` passes against `stored` by the function of code
    /// `FUNC` (unsigned): all ones, else zero.
    #[inline]
    #[target_feature(enable = "avx2")]
    fn passes<const FUNC: u8>(z: __m256i, stored: __m256i) -> __m256i {
        const NEVER: u8 = DepthFunc::Never as u8;
        const LESS: u8 = DepthFunc::Less as u8;
        const EQUAL: u8 = DepthFunc::Equal as u8;
        const LEQUAL: u8 = DepthFunc::Lequal as u8;
        const GREATER: u8 = DepthFunc::Greater as u8;
        const NOTEQUAL: u8 = DepthFunc::Notequal as u8;
        const GEQUAL: u8 = DepthFunc::Gequal as u8;
        // Flipping the sign bit makes unsigned order signed order.
        let bias = |v| _mm256_xor_si256(v, _mm256_set1_epi32(i32::MIN));
        let not = |v| _mm256_xor_si256(v, _mm256_set1_epi32(-1));
        match FUNC {
            NEVER => _mm256_setzero_si256(),
            LESS => _mm256_cmpgt_epi32(bias(stored), bias(z)),
            EQUAL => _mm256_cmpeq_epi32(z, stored),
            // z <= stored exactly where the larger of the two is the stored one.
            LEQUAL => _mm256_cmpeq_epi32(_mm256_max_epu32(z, stored), stored),
            GREATER => _mm256_cmpgt_epi32(bias(z), bias(stored)),
            NOTEQUAL => not(_mm256_cmpeq_epi32(z, stored)),
            GEQUAL => _mm256_cmpeq_epi32(_mm256_max_epu32(z, stored), z),
            _ => _mm256_set1_epi32(-1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// The kernel of `func` and `write` on one run.
    fn test_and_tally(
        func: DepthFunc,
        write: bool,
        depths: &[u32],
        stored: &mut [u32],
    ) -> RunTally {
        test_and_tally_in(Isa::best(), func, write, depths, stored)
    }

    /// The kernel of `func` and `write` in `isa` on one run.
    fn test_and_tally_in(
        isa: Isa,
        func: DepthFunc,
        write: bool,
        depths: &[u32],
        stored: &mut [u32],
    ) -> RunTally {
        struct OneRun<'a>(&'a [u32], &'a mut [u32]);
        impl WithKernel for OneRun<'_> {
            type Output = RunTally;
            fn run<K: RunKernel>(self, kernel: K) -> RunTally {
                kernel.test_and_tally(self.0, self.1)
            }
        }
        with_kernel_in(KernelIsa(isa), func, write, OneRun(depths, stored))
    }

    /// Every kernel's instructions this CPU runs.
    fn isas() -> Vec<Isa> {
        let mut isas = vec![Isa::Plain];
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        isas.push(Isa::Sse2);
        #[cfg(target_arch = "x86_64")]
        if avx2::available() {
            isas.push(Isa::Avx2);
            if crate::masked_lanes::mask_registers_available() {
                isas.push(Isa::Avx2MaskRegisters);
            }
        }
        isas
    }

    /// The plain way: each fragment tested (and written) in turn, then the outcomes tallied.
    fn reference(func: DepthFunc, write: bool, depths: &[u32], stored: &mut [u32]) -> RunTally {
        let passed: Vec<bool> = depths
            .iter()
            .zip(stored.iter_mut())
            .map(|(&z, s)| {
                let pass = func.passes(z, *s);
                if pass && write {
                    *s = z;
                }
                pass
            })
            .collect();
        RunTally::of(depths, &passed)
    }

    #[test]
    fn a_run_is_tested_written_and_tallied() {
        // Less, writing: 5 < 6 passes, 7 < 7 fails, 2 < 9 passes, 8 < 3 fails, 1 < 4 passes
        // (five fragments: a whole step and a last step of one new lane). Passing: indices
        // 0, 2 and 4, depths 5, 2, 1: three passed, z 1..=5, first 0, last 4; the stored
        // depths become 5, 7, 2, 3, 1.
        let depths = [5, 7, 2, 8, 1];
        let mut stored = [6, 7, 9, 3, 4];
        let tally = test_and_tally(DepthFunc::Less, true, &depths, &mut stored);
        let expected = RunTally {
            fragments: 5,
            passed: 3,
            zmin: 1,
            zmax: 5,
            first: 0,
            last: 4,
        };
        assert_eq!(tally, expected);
        assert_eq!(stored, [5, 7, 2, 3, 1]);
        // Greater, not writing, across the sign bit: u32::MAX > 0x8000_0000 passes,
        // 0x7FFF_FFFF > 0x8000_0000 fails (a signed comparison would pass it), 3 > 3 fails:
        // one passed, at index 0, z range u32::MAX..=u32::MAX; nothing written.
        let depths = [u32::MAX, 0x7FFF_FFFF, 3];
        let mut stored = [0x8000_0000, 0x8000_0000, 3];
        let tally = test_and_tally(DepthFunc::Greater, false, &depths, &mut stored);
        let expected = RunTally {
            fragments: 3,
            passed: 1,
            zmin: u32::MAX,
            zmax: u32::MAX,
            first: 0,
            last: 0,
        };
        assert_eq!(tally, expected);
        assert_eq!(stored, [0x8000_0000, 0x8000_0000, 3]);
        // Lequal, not writing, six fragments (a whole step, then the last four again with
        // fragments 2 and 3 masked off): 3 <= 5 passes, 9 <= 5 fails, 4 <= 4 passes,
        // 4 <= 6 passes, 7 <= 7 passes, 2 <= 1 fails. Four passed (fragments 2 and 3
        // counted once), z 3..=7, first 0, last 4.
        let depths = [3, 9, 4, 4, 7, 2];
        let mut stored = [5, 5, 4, 6, 7, 1];
        let tally = test_and_tally(DepthFunc::Lequal, false, &depths, &mut stored);
        let expected = RunTally {
            fragments: 6,
            passed: 4,
            zmin: 3,
            zmax: 7,
            first: 0,
            last: 4,
        };
        assert_eq!(tally, expected);
    }

    #[test]
    fn test_and_tally_match_testing_one_by_one() {
        let mut rng = SplitMix64(0x5eed);
        // Depths from a few values (so equal ones are common), some across the sign bit.
        let values = [0, 1, 2, 0x00FF_FFFF, 0x7FFF_FFFF, 0x8000_0000, u32::MAX];
        let depth = |rng: &mut SplitMix64| match rng.below(3) {
            0 => values[rng.below(values.len() as u64) as usize],
            1 => rng.below(8) as u32,
            _ => rng.next_u64() as u32,
        };
        for round in 0..20_000 {
            let len = rng.below(if round % 4 == 0 { 140 } else { 20 }) as usize;
            let depths: Vec<u32> = (0..len).map(|_| depth(&mut rng)).collect();
            let stored: Vec<u32> = (0..len).map(|_| depth(&mut rng)).collect();
            let func = DepthFunc::ALL[rng.below(8) as usize];
            let write = rng.below(2) == 1;
            let mut plain = stored.clone();
            let expected = reference(func, write, &depths, &mut plain);
            for isa in isas() {
                let mut fused = stored.clone();
                assert_eq!(
                    test_and_tally_in(isa, func, write, &depths, &mut fused),
                    expected,
                    "{isa:?} {func:?} write {write}: {depths:?} against {stored:?}"
                );
                assert_eq!(
                    fused, plain,
                    "{isa:?} {func:?} write {write}: the stored depths"
                );
            }
        }
    }
}
