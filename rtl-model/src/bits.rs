//! Fixed-width arithmetic: registers are stored in `u64` and masked to their width.

/// All ones in the low `width` bits (`width` in 1..=64).
#[inline(always)]
pub const fn mask(width: u32) -> u64 {
    u64::MAX >> (64 - width)
}

/// Bits needed to hold the values `0..=max` (at least 1).
pub const fn bits_for(max: u64) -> u32 {
    if max == 0 {
        1
    } else {
        64 - max.leading_zeros()
    }
}

/// A saturating up-counter of `width` bits: `value + 1`, held at all ones.
#[inline(always)]
pub fn saturating_increment(value: u64, width: u32) -> u64 {
    let max = mask(width);
    if value >= max {
        max
    } else {
        value + 1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counters_saturate_at_their_width() {
        assert_eq!(saturating_increment(0, 1), 1);
        assert_eq!(saturating_increment(1, 1), 1);
        assert_eq!(saturating_increment(6, 3), 7);
        assert_eq!(saturating_increment(7, 3), 7);
        assert_eq!(saturating_increment(u64::MAX - 1, 64), u64::MAX);
        assert_eq!(saturating_increment(u64::MAX, 64), u64::MAX);
    }

    #[test]
    fn widths() {
        assert_eq!(mask(1), 1);
        assert_eq!(mask(24), 0xFF_FFFF);
        assert_eq!(mask(64), u64::MAX);
        assert_eq!(bits_for(0), 1);
        assert_eq!(bits_for(1), 1);
        assert_eq!(bits_for(2), 2);
        assert_eq!(bits_for(255), 8);
        assert_eq!(bits_for(256), 9);
    }
}
