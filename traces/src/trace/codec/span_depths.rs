//! A span's depths from its residuals: each depth is the one before, plus the previous
//! span's x slope, plus a zigzag residual. Nearly every residual is one byte, and a span
//! whose residuals all are is decoded as a prefix sum, 16 depths at a time (with SSE2 on
//! x86_64): a running depth makes every fragment wait for the one before, one or two
//! dependent additions each, where the prefix sum waits once per 16.

use super::{bad, unzigzag, Cursor, PayloadError};
use crate::event::DEPTH_ONE;

/// Residuals the one-byte path decodes in one step.
const CHUNK: usize = 16;

/// Decode the depths of a span of `len` fragments whose first depth is `first` into
/// `depths[..len]` (the vector may be left longer: the rest is scratch): each next one is
/// the last + `slope` + a zigzag residual read from `payload` at `pos`. Returns the position
/// after the residuals and the last depth.
#[inline(always)]
pub(super) fn span_depths(
    payload: &[u8],
    pos: usize,
    len: usize,
    first: i64,
    slope: i64,
    depths: &mut Vec<u32>,
) -> Result<(usize, i64), PayloadError> {
    // The one-byte path adds in 32 bits, exact for a first depth in range and a slope of at
    // most 2^24 (what a decoder's predictor holds: see `one_byte_depths`).
    let exact_in_i32 = (0..=DEPTH_ONE as i64).contains(&first) && slope.unsigned_abs() < 1 << 24;
    let end = pos + len - 1;
    // The one-byte path checks its residuals' lengths and its depths' range as it goes; a
    // span it cannot vouch for (a long residual, a depth outside, both rare) is decoded
    // again the general way, which finds and names what is wrong.
    if exact_in_i32
        && end <= payload.len()
        && one_byte_depths(payload, pos, len - 1, first as i32, slope as i32, depths)
    {
        return Ok((end, depths[len - 1] as i64));
    }
    any_residual_depths(payload, pos, len, first, slope, depths)
}

/// [`span_depths`] for residuals of any length (the general path).
#[inline(never)]
fn any_residual_depths(
    payload: &[u8],
    mut pos: usize,
    len: usize,
    first: i64,
    slope: i64,
    depths: &mut Vec<u32>,
) -> Result<(usize, i64), PayloadError> {
    depths.clear();
    depths.push(first as u32);
    let start = pos;
    let mut depth = first;
    // Range checked once at the end (a depth outside 0..=2^24-1 is rare: corruption), so the
    // loop carries only the running depth.
    let mut outside = false;
    for _ in 1..len {
        let residual = match payload.get(pos) {
            Some(&b) if b < 0x80 => {
                pos += 1;
                unzigzag(b as u64)
            }
            _ => {
                let mut c = Cursor::new(payload, pos);
                let value = c.zz()?;
                pos = c.pos;
                value
            }
        };
        depth = depth.wrapping_add(slope).wrapping_add(residual);
        outside |= depth as u64 > DEPTH_ONE as u64;
        depths.push(depth as u32);
    }
    if outside {
        return Err(first_depth_outside(payload, start, len, first, slope));
    }
    Ok((pos, depth))
}

/// `first` and the depths that the `residuals` residuals at `payload[pos..]` give, taken
/// for one byte each, into `depths[..=residuals]`, the vector lengthened if it is too short
/// (what lies past is scratch). Returns whether they are what the span holds: every
/// residual one byte long, every depth in 0..=2^24-1.
///
/// The kernels add in 32 bits, which is exact up to the first depth outside 0..2^24 (all
/// the caller needs: it rejects the span there): that depth follows one inside the range
/// by a step of `slope` (|slope| < 2^24) and a residual (|residual| <= 64), and a chunk's
/// depths are its base plus at most 16 such steps (< 2^29 in size), so no sum forming it
/// leaves the i32 range. Depths after it may wrap; nobody reads them.
#[inline(always)]
fn one_byte_depths(
    payload: &[u8],
    pos: usize,
    residuals: usize,
    first: i32,
    slope: i32,
    depths: &mut Vec<u32>,
) -> bool {
    let chunks = residuals.div_ceil(CHUNK);
    if depths.len() < 1 + chunks * CHUNK {
        depths.resize(1 + chunks * CHUNK, 0);
    }
    depths[0] = first as u32;
    // Whole chunks straight from the payload, the last one's bytes past the residuals
    // included where the payload has them: they only give depths past the span (a chunk's
    // depths depend on its earlier bytes only), and the kernel looks at the first
    // `residuals` alone.
    let direct = chunks.min((payload.len() - pos) / CHUNK) * CHUNK;
    let mut fits = one_byte_chunks(
        &payload[pos..pos + direct],
        residuals.min(direct),
        first,
        slope,
        &mut depths[1..=direct],
    );
    if direct < residuals {
        // Near the payload's end: the last chunk from a copy padded with zeros.
        let mut padded = [0u8; CHUNK];
        padded[..residuals - direct].copy_from_slice(&payload[pos + direct..pos + residuals]);
        let base = depths[direct] as i32;
        let out = &mut depths[1 + direct..][..CHUNK];
        fits &= one_byte_chunks(&padded, residuals - direct, base, slope, out);
    }
    fits
}

/// The depths after `base` that `residuals` (taken for one byte each, a whole number of
/// chunks) give, into `out` (as long). Returns whether the first `count` residuals are each
/// one byte long (below 0x80) and their depths all in 0..=2^24-1; past them, the bytes'
/// depths are scratch and not looked at.
#[inline(always)]
fn one_byte_chunks(residuals: &[u8], count: usize, base: i32, slope: i32, out: &mut [u32]) -> bool {
    debug_assert!(residuals.len().is_multiple_of(CHUNK) && out.len() == residuals.len());
    debug_assert!(count <= residuals.len());
    #[cfg(target_arch = "x86_64")]
    if avx2::available() {
        // SAFETY: the CPU has AVX2, checked just now.
        return unsafe { avx2::one_byte_chunks(residuals, count, base, slope, out) };
    }
    #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
    // SAFETY: the kernel needs SSE2, which the build targets (`target_feature = "sse2"`).
    unsafe {
        sse2::one_byte_chunks(residuals, count, base, slope, out)
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "sse2")))]
    one_byte_chunks_scalar(residuals, count, base, slope, out)
}

/// [`one_byte_chunks`] one depth after the other: the kernel where SSE2 is missing, and the
/// reference the tests hold the SIMD kernels to.
#[cfg_attr(all(target_arch = "x86_64", target_feature = "sse2"), allow(dead_code))]
fn one_byte_chunks_scalar(
    residuals: &[u8],
    count: usize,
    base: i32,
    slope: i32,
    out: &mut [u32],
) -> bool {
    let mut depth = base;
    let mut fits = true;
    for (i, (&byte, out)) in residuals.iter().zip(out).enumerate() {
        depth = depth
            .wrapping_add(slope)
            .wrapping_add(unzigzag(byte as u64) as i32);
        *out = depth as u32;
        if i < count {
            fits &= byte < 0x80 && (0..=DEPTH_ONE as i32).contains(&depth);
        }
    }
    fits
}

#[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
mod sse2 {
    use super::CHUNK;
    use crate::event::DEPTH_ONE;
    use std::arch::x86_64::*;

    /// [`super::one_byte_chunks`]: per chunk, the residuals' prefix sums in 16-bit lanes
    /// (|sum| <= 16 * 128), widened, plus the slope's ramp and the base. The checks ride
    /// along: the bytes' top bits (a long residual's first byte has it) and every depth's
    /// bits ORed, of the first `count` only, tested once at the end.
    #[target_feature(enable = "sse2")]
    pub(super) fn one_byte_chunks(
        residuals: &[u8],
        count: usize,
        base: i32,
        slope: i32,
        out: &mut [u32],
    ) -> bool {
        // Lane k of ramp[j] is slope * (4j + k + 1): the slopes up to depth 4j + k of a chunk.
        let first_four = _mm_setr_epi32(
            slope,
            slope.wrapping_mul(2),
            slope.wrapping_mul(3),
            slope.wrapping_mul(4),
        );
        let four = _mm_set1_epi32(slope.wrapping_mul(4));
        let mut ramp = [first_four; 4];
        for j in 1..4 {
            ramp[j] = _mm_add_epi32(ramp[j - 1], four);
        }
        // Lane k of index[j] is 4j + k: a depth's place in its chunk.
        let mut index = [_mm_setr_epi32(0, 1, 2, 3); 4];
        for j in 1..4 {
            index[j] = _mm_add_epi32(index[j - 1], _mm_set1_epi32(4));
        }
        let mut base = _mm_set1_epi32(base);
        let mut long_residuals = 0u32;
        let mut depth_bits = _mm_setzero_si128();
        for (c, (chunk, out)) in residuals
            .chunks_exact(CHUNK)
            .zip(out.chunks_exact_mut(CHUNK))
            .enumerate()
        {
            // How many of this chunk's residuals are the span's (0..=16).
            let counted = count.saturating_sub(c * CHUNK).min(CHUNK) as u32;
            let bytes = load(chunk.try_into().expect("a chunk"));
            long_residuals |= _mm_movemask_epi8(bytes) as u32 & ((1 << counted) - 1);
            let residuals = unzigzag_bytes(bytes);
            let low = prefix_sums_i16(_mm_srai_epi16::<8>(_mm_unpacklo_epi8(residuals, residuals)));
            let high =
                prefix_sums_i16(_mm_srai_epi16::<8>(_mm_unpackhi_epi8(residuals, residuals)));
            // The high half's sums start from the low half's total (its lane 7 everywhere).
            let high = _mm_add_epi16(
                high,
                _mm_shuffle_epi32::<0xFF>(_mm_shufflehi_epi16::<0xFF>(low)),
            );
            let sums = [
                _mm_srai_epi32::<16>(_mm_unpacklo_epi16(low, low)),
                _mm_srai_epi32::<16>(_mm_unpackhi_epi16(low, low)),
                _mm_srai_epi32::<16>(_mm_unpacklo_epi16(high, high)),
                _mm_srai_epi32::<16>(_mm_unpackhi_epi16(high, high)),
            ];
            let counted = _mm_set1_epi32(counted as i32);
            let mut last = base;
            for (j, (sum, out)) in sums.into_iter().zip(out.chunks_exact_mut(4)).enumerate() {
                last = _mm_add_epi32(base, _mm_add_epi32(ramp[j], sum));
                store(out.try_into().expect("four depths"), last);
                let in_span = _mm_cmpgt_epi32(counted, index[j]);
                depth_bits = _mm_or_si128(depth_bits, _mm_and_si128(last, in_span));
            }
            // The next chunk's base: this one's last depth everywhere.
            base = _mm_shuffle_epi32::<0xFF>(last);
        }
        // A depth in 0..2^24 sets no bit above bit 23; one outside (negative, or too large)
        // does.
        let outside = _mm_and_si128(depth_bits, _mm_set1_epi32(!(DEPTH_ONE as i32)));
        let inside = _mm_movemask_epi8(_mm_cmpeq_epi32(outside, _mm_setzero_si128())) == 0xFFFF;
        long_residuals == 0 && inside
    }

    /// Each byte (below 0x80) unzigzagged: (b >> 1) ^ -(b & 1), as i8.
    #[target_feature(enable = "sse2")]
    pub(super) fn unzigzag_bytes(bytes: __m128i) -> __m128i {
        // (A 16-bit shift: the bit each byte takes from the next is masked off.)
        let half = _mm_and_si128(_mm_srli_epi16::<1>(bytes), _mm_set1_epi8(0x7F));
        let odd = _mm_and_si128(bytes, _mm_set1_epi8(1));
        _mm_xor_si128(half, _mm_sub_epi8(_mm_setzero_si128(), odd))
    }

    /// Inclusive prefix sums of eight i16 lanes (shift and add, three times).
    #[target_feature(enable = "sse2")]
    fn prefix_sums_i16(lanes: __m128i) -> __m128i {
        let lanes = _mm_add_epi16(lanes, _mm_slli_si128::<2>(lanes));
        let lanes = _mm_add_epi16(lanes, _mm_slli_si128::<4>(lanes));
        _mm_add_epi16(lanes, _mm_slli_si128::<8>(lanes))
    }

    #[target_feature(enable = "sse2")]
    pub(super) fn load(bytes: &[u8; CHUNK]) -> __m128i {
        // SAFETY: the reference holds the 16 bytes read; an unaligned load needs no more.
        unsafe { _mm_loadu_si128(bytes.as_ptr().cast()) }
    }

    #[target_feature(enable = "sse2")]
    fn store(out: &mut [u32; 4], lanes: __m128i) {
        // SAFETY: the reference holds the 16 bytes written; an unaligned store needs no more.
        unsafe { _mm_storeu_si128(out.as_mut_ptr().cast(), lanes) }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    // The 16 bytes' load and unzigzag are SSE2's: one definition.
    use super::sse2::{load, unzigzag_bytes};
    use super::CHUNK;
    use crate::event::DEPTH_ONE;
    use std::arch::x86_64::*;

    /// Whether this CPU runs the kernel (a cached flag's load).
    #[inline(always)]
    pub(super) fn available() -> bool {
        is_x86_feature_detected!("avx2")
    }

    /// [`super::one_byte_chunks`] in AVX2: the SSE2 kernel's steps, a chunk's sixteen
    /// residuals widened to 16-bit lanes in one register and its depths in two of eight.
    #[target_feature(enable = "avx2")]
    pub(super) fn one_byte_chunks(
        residuals: &[u8],
        count: usize,
        base: i32,
        slope: i32,
        out: &mut [u32],
    ) -> bool {
        // Lane k of ramp[j] is slope * (8j + k + 1): the slopes up to depth 8j + k of a chunk;
        // lane k of index[j] is 8j + k, a depth's place in its chunk.
        let index = [
            _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7),
            _mm256_setr_epi32(8, 9, 10, 11, 12, 13, 14, 15),
        ];
        let slopes = _mm256_set1_epi32(slope);
        let one = _mm256_set1_epi32(1);
        let ramp = index.map(|index| _mm256_mullo_epi32(slopes, _mm256_add_epi32(index, one)));
        let mut base = _mm256_set1_epi32(base);
        let mut long_residuals = 0u32;
        let mut depth_bits = _mm256_setzero_si256();
        for (c, (chunk, out)) in residuals
            .chunks_exact(CHUNK)
            .zip(out.chunks_exact_mut(CHUNK))
            .enumerate()
        {
            // How many of this chunk's residuals are the span's (0..=16).
            let counted = count.saturating_sub(c * CHUNK).min(CHUNK) as u32;
            let bytes = load(chunk.try_into().expect("a chunk"));
            long_residuals |= _mm_movemask_epi8(bytes) as u32 & ((1 << counted) - 1);
            let sums = prefix_sums_i16(_mm256_cvtepi8_epi16(unzigzag_bytes(bytes)));
            // Each half's sums are its own (byte shifts stay in their 128-bit half): the high
            // half's start from the low half's total, its lane 7.
            let totals = _mm256_shuffle_epi32::<0xFF>(_mm256_shufflehi_epi16::<0xFF>(sums));
            let sums = _mm256_add_epi16(sums, _mm256_permute2x128_si256::<0x08>(totals, totals));
            let sums = [
                _mm256_cvtepi16_epi32(_mm256_castsi256_si128(sums)),
                _mm256_cvtepi16_epi32(_mm256_extracti128_si256::<1>(sums)),
            ];
            let counted = _mm256_set1_epi32(counted as i32);
            let mut last = base;
            for (j, (sum, out)) in sums.into_iter().zip(out.chunks_exact_mut(8)).enumerate() {
                last = _mm256_add_epi32(base, _mm256_add_epi32(ramp[j], sum));
                store(out.try_into().expect("eight depths"), last);
                let in_span = _mm256_cmpgt_epi32(counted, index[j]);
                depth_bits = _mm256_or_si256(depth_bits, _mm256_and_si256(last, in_span));
            }
            // The next chunk's base: this one's last depth everywhere.
            base = _mm256_permutevar8x32_epi32(last, _mm256_set1_epi32(7));
        }
        // A depth in 0..2^24 sets no bit above bit 23; one outside (negative, or too large)
        // does.
        let outside = _mm256_and_si256(depth_bits, _mm256_set1_epi32(!(DEPTH_ONE as i32)));
        long_residuals == 0 && _mm256_testz_si256(outside, outside) == 1
    }

    /// Inclusive prefix sums of each 128-bit half's eight i16 lanes (shift and add, three
    /// times).
    #[target_feature(enable = "avx2")]
    fn prefix_sums_i16(lanes: __m256i) -> __m256i {
        let lanes = _mm256_add_epi16(lanes, _mm256_slli_si256::<2>(lanes));
        let lanes = _mm256_add_epi16(lanes, _mm256_slli_si256::<4>(lanes));
        _mm256_add_epi16(lanes, _mm256_slli_si256::<8>(lanes))
    }

    #[target_feature(enable = "avx2")]
    fn store(out: &mut [u32; 8], lanes: __m256i) {
        // SAFETY: the reference holds the 32 bytes written; an unaligned store needs no more.
        unsafe { _mm256_storeu_si256(out.as_mut_ptr().cast(), lanes) }
    }
}

/// The error for the first depth of a span outside 0..=2^24-1 (the span is known to hold
/// one and its residuals to decode).
#[cold]
fn first_depth_outside(
    payload: &[u8],
    mut pos: usize,
    len: usize,
    first: i64,
    slope: i64,
) -> PayloadError {
    let mut depth = first;
    for _ in 1..len {
        let mut c = Cursor::new(payload, pos);
        let Ok(residual) = c.zz() else {
            break;
        };
        pos = c.pos;
        depth = depth.wrapping_add(slope).wrapping_add(residual);
        if !(0..=DEPTH_ONE as i64).contains(&depth) {
            return bad(pos - 1, format!("depth {depth} outside 0..=2^24-1"));
        }
    }
    bad(pos, "depth outside 0..=2^24-1")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::trace::codec::put_zz;

    /// The depths of a span and the position after it, decoded the plain way: one zigzag
    /// varint after the other, in 64 bits, each depth checked as it comes.
    fn reference(
        payload: &[u8],
        pos: usize,
        len: usize,
        first: i64,
        slope: i64,
    ) -> Result<(Vec<u32>, usize), usize> {
        let mut c = Cursor::new(payload, pos);
        let mut depths = vec![first as u32];
        let mut depth = first;
        for _ in 1..len {
            depth += slope + c.zz().map_err(|e| e.pos)?;
            if !(0..=DEPTH_ONE as i64).contains(&depth) {
                // Named by the residual's last byte.
                return Err(c.pos - 1);
            }
            depths.push(depth as u32);
        }
        Ok((depths, c.pos))
    }

    fn decode(payload: &[u8], len: usize, first: i64, slope: i64) -> Result<Vec<u32>, usize> {
        let mut depths = Vec::new();
        let (pos, last) =
            span_depths(payload, 0, len, first, slope, &mut depths).map_err(|e| e.pos)?;
        assert_eq!(pos, payload.len(), "the position after the residuals");
        assert_eq!(last, depths[len - 1] as i64, "the last depth");
        Ok(depths[..len].to_vec())
    }

    #[test]
    fn span_depths_follow_slope_and_residuals() {
        // Residuals +1, -2 (zigzag 2, 3), then +64 as two bytes (zigzag 128: 0x80 0x01).
        let payload = [2, 3, 0x80, 0x01];
        assert_eq!(decode(&payload, 4, 100, 10), Ok(vec![100, 111, 119, 193]));
        // All one-byte residuals (the fast path).
        assert_eq!(decode(&payload[..2], 3, 100, 10), Ok(vec![100, 111, 119]));
    }

    #[test]
    fn one_byte_runs_cross_chunks_and_halves() {
        // 17 residuals +1 (zigzag 2) at slope 10 from 100: depth k is 100 + 11k, the last
        // one alone in a padded chunk.
        let expected: Vec<u32> = (0..18).map(|k| 100 + 11 * k).collect();
        assert_eq!(decode(&[2; 17], 18, 100, 10), Ok(expected));
        // Eight residuals -2 (zigzag 3), then eight -1 (zigzag 1) at slope 0 from 1000: the
        // high half of the chunk starts from the low half's total, 1000 - 16 = 984.
        let mut payload = [3u8; 16];
        payload[8..].fill(1);
        let expected: Vec<u32> = (0..=8)
            .map(|k| 1000 - 2 * k)
            .chain((1..=8).map(|k| 984 - k))
            .collect();
        assert_eq!(decode(&payload, 17, 1000, 0), Ok(expected));
        // A negative slope with residuals -64 (zigzag 127), the most negative one byte holds.
        let expected: Vec<u32> = (0..40).map(|k| 5_000_000 - 1064 * k).collect();
        assert_eq!(decode(&[127; 39], 40, 5_000_000, -1000), Ok(expected));
    }

    #[test]
    fn a_depth_outside_the_range_names_its_residual() {
        let top = DEPTH_ONE as i64 - 1;
        // Residuals +1, +1, 0: the second leaves the range, its byte at offset 1.
        let mut depths = Vec::new();
        let error = span_depths(&[2, 2, 0], 0, 4, top, 0, &mut depths).unwrap_err();
        assert_eq!(error.pos, 1);
        assert!(
            error.reason.contains("depth 16777216 outside"),
            "{}",
            error.reason
        );
        // The same with a two-byte residual first (the general path): offset 2.
        let slow = [0x80, 0x00, 2, 2];
        let error = span_depths(&slow, 0, 4, top, 0, &mut depths).unwrap_err();
        assert_eq!(error.pos, 3);
        // Below zero.
        let error = span_depths(&[3], 0, 2, 0, 0, &mut depths).unwrap_err();
        assert_eq!(error.pos, 0);
        assert!(
            error.reason.contains("depth -2 outside"),
            "{}",
            error.reason
        );
        // Out in a later chunk, from depth 21 on (top - 20000 + 1000 * 21 > top + 1): the
        // first one out is named, by its residual at offset 20.
        let error = span_depths(&[0; 40], 0, 41, top - 20 * 1000, 1000, &mut depths).unwrap_err();
        assert_eq!(error.pos, 20);
    }

    type Kernel = fn(&[u8], usize, i32, i32, &mut [u32]) -> bool;

    /// Every SIMD kernel this CPU runs, by name.
    fn simd_kernels() -> Vec<(&'static str, Kernel)> {
        #[allow(unused_mut)]
        let mut kernels: Vec<(&'static str, Kernel)> = Vec::new();
        #[cfg(all(target_arch = "x86_64", target_feature = "sse2"))]
        kernels.push(("sse2", |residuals, count, base, slope, out| {
            // SAFETY: the build targets SSE2.
            unsafe { sse2::one_byte_chunks(residuals, count, base, slope, out) }
        }));
        #[cfg(target_arch = "x86_64")]
        if avx2::available() {
            kernels.push(("avx2", |residuals, count, base, slope, out| {
                // SAFETY: the CPU has AVX2, checked above.
                unsafe { avx2::one_byte_chunks(residuals, count, base, slope, out) }
            }));
        }
        kernels
    }

    #[test]
    fn the_simd_kernels_are_the_scalar_one() {
        let mut rng = SplitMix64(17);
        for case in 0..20_000 {
            let chunks = 1 + rng.below(5) as usize;
            // Now and then a long residual's byte (0x80 and up), in the span or past it.
            let long_bytes = rng.below(4) == 0;
            let residuals: Vec<u8> = (0..CHUNK * chunks)
                .map(|_| match long_bytes && rng.below(20) == 0 {
                    true => 0x80 + rng.below(0x80) as u8,
                    false => rng.below(0x80) as u8,
                })
                .collect();
            let count = rng.below(residuals.len() as u64 + 1) as usize;
            // Bases near an end of the range now and then, so depths leave it.
            let base = match rng.below(4) {
                0 => rng.below(2000) as i32,
                1 => DEPTH_ONE as i32 - rng.below(2000) as i32,
                _ => rng.below(1 << 24) as i32,
            };
            let slope = match rng.below(3) {
                0 => rng.below(41) as i32 - 20,
                _ => rng.below(1 << 25) as i32 - (1 << 24) + 1,
            };
            let mut plain = vec![0; residuals.len()];
            let plain_fits = one_byte_chunks_scalar(&residuals, count, base, slope, &mut plain);
            for (kernel, one_byte_chunks) in simd_kernels() {
                let mut fast = vec![0; residuals.len()];
                let fits = one_byte_chunks(&residuals, count, base, slope, &mut fast);
                let context =
                    format!("{kernel} case {case}: base {base} slope {slope} count {count}");
                assert_eq!(fits, plain_fits, "{context}: whether the span fits");
                if residuals.iter().all(|&b| b < 0x80) {
                    assert_eq!(fast, plain, "{context}: {residuals:?}");
                }
            }
        }
    }

    #[test]
    fn span_depths_match_a_plain_decoder() {
        let mut rng = SplitMix64(5);
        let mut depths = Vec::new();
        for case in 0..20_000 {
            let len = 1 + rng.below(70) as usize;
            // Depths near an end of the range now and then, to leave it.
            let first = match rng.below(4) {
                0 => rng.below(100) as i64,
                1 => DEPTH_ONE as i64 - rng.below(100) as i64,
                _ => rng.below(1 << 24) as i64,
            };
            let slope = match rng.below(3) {
                0 => rng.below(5) as i64 - 2,
                1 => rng.below(1 << 25) as i64 - (1 << 24) + 1,
                // Beyond what a predictor holds: the general path.
                _ => rng.below(1 << 30) as i64 - (1 << 29),
            };
            let mut payload = Vec::new();
            for _ in 1..len {
                let residual = match rng.below(50) {
                    0 => rng.below(1 << 20) as i64 - (1 << 19),
                    _ => rng.below(128) as i64 - 64,
                };
                put_zz(&mut payload, residual);
            }
            // Bytes after the span, which the decoder must not take for residuals.
            payload.extend([0x55, 0xFF]);
            let expected = reference(&payload, 0, len, first, slope);
            let got = span_depths(&payload, 0, len, first, slope, &mut depths)
                .map(|(pos, last)| {
                    assert_eq!(last, depths[len - 1] as i64, "case {case}");
                    (depths[..len].to_vec(), pos)
                })
                .map_err(|e| e.pos);
            assert_eq!(got, expected, "case {case}: first {first} slope {slope}");
        }
    }
}
