//! The tile locator (a simulation shortcut, not hardware): which of a query's tiles may hold
//! a pixel, so that [`crate::OccuRtl::quiet_cycles`] finds a fragment's next holding test
//! step without running every engine's comparators over every slot.
//!
//! Why: on a query of hundreds of tiles (a lazy-grid walk's cells) a fragment sits in one
//! or two of them, and the search for its holding steps had been a scan of every slot of
//! every engine, two or three times a fragment: most of the `rtl` level's time on such
//! walks.
//!
//! What it holds: a grid of square buckets, `2^shift` pixels a side, over the pixels the
//! tiles reach; each bucket lists, ascending, the tiles whose rectangle meets it. A tile's
//! rectangle is the slot registers' `(x - x0) mod 2^32 < width` (and the same for y)
//! restricted to the 16-bit pixel range; where that wraps, the tile is listed in every
//! bucket along the axis. So a bucket's list is a superset of the tiles that hold any of
//! its pixels, and the caller's comparators decide: the locator only skips tiles that
//! cannot hold the pixel, and every answer equals the full scan's.
//!
//! Memory follows the query: buckets are about four a tile, and a query whose tiles would
//! be listed more than [`MAX_ENTRIES_PER_TILE`] times a tile on average (large overlapping
//! tiles, where the full scan finds a holding slot at once anyway) builds no locator.

/// The pixel range a fragment coordinate spans (16 bits).
const PIXELS: u64 = 1 << 16;
/// Smallest bucket side, as a shift: 8 pixels.
const MIN_SHIFT: u32 = 3;
/// Buckets aimed at per tile.
const BUCKETS_PER_TILE: u64 = 4;
/// Average listings per tile above which no locator is built.
pub const MAX_ENTRIES_PER_TILE: u64 = 32;

/// A superset of the pixels `0..2^16` that `(p - origin) mod 2^32 < size` holds: a range.
fn axis_range(origin: u32, size: u32) -> std::ops::Range<u64> {
    let (origin, size) = (origin as u64, size as u64);
    if origin + size > 1 << 32 {
        // Wraps past 2^32 back to 0: take the whole axis (a superset).
        0..PIXELS
    } else {
        origin.min(PIXELS)..(origin + size).min(PIXELS)
    }
}

#[derive(Clone, Debug, Default)]
pub struct TileLocator {
    /// Bucket side, as a shift.
    shift: u32,
    /// Buckets across and down.
    columns: u64,
    rows: u64,
    /// Bucket `b`'s tiles are `tiles[starts[b]..starts[b + 1]]`, ascending.
    starts: Vec<u32>,
    tiles: Vec<u32>,
    /// A locator was built for the loaded query.
    built: bool,
}

impl TileLocator {
    /// Index a query's tiles (`[x0, y0, width, height]`, in query order). Returns whether a
    /// locator was built (else the caller scans).
    pub fn build(&mut self, rects: &[[u32; 4]]) -> bool {
        self.built = false;
        self.starts.clear();
        self.tiles.clear();
        let ranges: Vec<_> = rects
            .iter()
            .map(|r| (axis_range(r[0], r[2]), axis_range(r[1], r[3])))
            .collect();
        // The extent of the tiles that hold a pixel at all (an empty one is listed nowhere).
        let holding = || {
            ranges
                .iter()
                .filter(|(x, y)| !x.is_empty() && !y.is_empty())
        };
        let width = holding().map(|(x, _)| x.end).max().unwrap_or(0);
        let height = holding().map(|(_, y)| y.end).max().unwrap_or(0);
        if width == 0 || height == 0 {
            return false;
        }
        let target = BUCKETS_PER_TILE * rects.len() as u64;
        let mut shift = MIN_SHIFT;
        while shift < 16 && (width >> shift).max(1) * (height >> shift).max(1) > target {
            shift += 1;
        }
        let buckets = |r: &std::ops::Range<u64>| {
            if r.is_empty() {
                0..0
            } else {
                r.start >> shift..((r.end - 1) >> shift) + 1
            }
        };
        // A tile empty along one axis is listed in no bucket along the other either.
        let listed = |(x, y): &(std::ops::Range<u64>, std::ops::Range<u64>)| {
            if x.is_empty() || y.is_empty() {
                (0..0, 0..0)
            } else {
                (buckets(x), buckets(y))
            }
        };
        let listings: u64 = ranges
            .iter()
            .map(|tile| {
                let (columns, rows) = listed(tile);
                columns.count() as u64 * rows.count() as u64
            })
            .sum();
        if listings > MAX_ENTRIES_PER_TILE * rects.len() as u64 {
            return false;
        }
        self.shift = shift;
        self.columns = ((width - 1) >> shift) + 1;
        self.rows = ((height - 1) >> shift) + 1;
        // Counting sort into the buckets: counts, prefix sums, then a fill in tile order
        // (so every bucket's list ascends).
        let count = (self.columns * self.rows) as usize;
        let mut fill = vec![0u32; count + 1];
        for tile in &ranges {
            let (columns, rows) = listed(tile);
            for row in rows {
                for column in columns.clone() {
                    fill[(row * self.columns + column) as usize + 1] += 1;
                }
            }
        }
        for b in 1..=count {
            fill[b] += fill[b - 1];
        }
        self.starts.extend_from_slice(&fill);
        self.tiles.resize(listings as usize, 0);
        for (t, tile) in ranges.iter().enumerate() {
            let (columns, rows) = listed(tile);
            for row in rows {
                for column in columns.clone() {
                    let b = (row * self.columns + column) as usize;
                    self.tiles[fill[b] as usize] = t as u32;
                    fill[b] += 1;
                }
            }
        }
        self.built = true;
        true
    }

    /// Forget the loaded query.
    pub fn clear(&mut self) {
        self.built = false;
    }

    /// The side of a bucket, in pixels: the pixels of a row from `x` to the next multiple of
    /// it have the same candidates.
    pub fn bucket_side(&self) -> u32 {
        1 << self.shift
    }

    /// Whether a locator is built for the loaded query.
    pub fn is_built(&self) -> bool {
        self.built
    }

    /// The tiles, ascending from `from` and below `until`, that may hold pixel `(x, y)`:
    /// every tile in that range that holds it is among them.
    #[inline]
    pub fn candidates(
        &self,
        x: u32,
        y: u32,
        from: u64,
        until: u64,
    ) -> impl Iterator<Item = u64> + '_ {
        debug_assert!(self.built);
        let (column, row) = ((x as u64) >> self.shift, (y as u64) >> self.shift);
        let listed: &[u32] = if column < self.columns && row < self.rows {
            let b = (row * self.columns + column) as usize;
            &self.tiles[self.starts[b] as usize..self.starts[b + 1] as usize]
        } else {
            &[]
        };
        let first = listed.partition_point(|&t| (t as u64) < from);
        listed[first..]
            .iter()
            .map(|&t| t as u64)
            .take_while(move |&t| t < until)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn holds(r: &[u32; 4], x: u32, y: u32) -> bool {
        x.wrapping_sub(r[0]) < r[2] && y.wrapping_sub(r[1]) < r[3]
    }

    /// Checks that every tile of `rects` that holds a pixel of the 700 by 500 corner (and
    /// the first few columns and rows) is a candidate for it.
    fn check_candidates(rects: &[[u32; 4]]) {
        let mut locator = TileLocator::default();
        assert!(locator.build(rects));
        for y in (0..500).step_by(3).chain([0, 1, 7, 9]) {
            for x in (0..700).step_by(5).chain([0, 1, 4, 5]) {
                let expected: Vec<u64> = (0..rects.len() as u64)
                    .filter(|&t| holds(&rects[t as usize], x, y))
                    .collect();
                let found: Vec<u64> = locator
                    .candidates(x, y, 0, u64::MAX)
                    .filter(|&t| holds(&rects[t as usize], x, y))
                    .collect();
                assert_eq!(found, expected, "pixel ({x}, {y})");
                // From and until cut the list.
                let (from, until) = (expected.first().copied().unwrap_or(0) + 1, 300);
                let cut: Vec<u64> = locator
                    .candidates(x, y, from, until)
                    .filter(|&t| holds(&rects[t as usize], x, y))
                    .collect();
                let wanted: Vec<u64> = expected
                    .iter()
                    .copied()
                    .filter(|t| (from..until).contains(t))
                    .collect();
                assert_eq!(cut, wanted, "pixel ({x}, {y}) from {from}");
            }
        }
    }

    /// A grid of 20 by 15 cells of 33 by 29 pixels (tiles 0..300).
    fn grid() -> Vec<[u32; 4]> {
        (0..15)
            .flat_map(|j| (0..20).map(move |i| [i * 33, j * 29, 33, 29]))
            .collect()
    }

    /// On a grid of cells with an overlapping rectangle, one beyond the 16-bit pixels and
    /// an empty one, every holding tile is a candidate, at buckets of 16 pixels.
    #[test]
    fn every_holding_tile_is_a_candidate() {
        let mut rects = grid();
        rects.push([100, 100, 300, 200]);
        rects.push([70_000, 0, 10, 10]); // beyond the pixels: holds none
        rects.push([3, 3, 0, 5]); // empty
        check_candidates(&rects);
        let mut locator = TileLocator::default();
        locator.build(&rects);
        // 660 by 435 pixels at about 4 buckets a tile (1,212): 41 by 28 buckets of 16.
        assert_eq!(locator.shift, 4);
    }

    /// Tiles that wrap past 2^32 (the comparators' modular test) are found where they hold.
    #[test]
    fn wrapping_tiles_are_candidates_where_they_hold() {
        let mut rects = grid();
        rects.push([u32::MAX - 4, 7, 10, 3]); // x wraps: holds x 0..5, y 7..10
        rects.push([5, u32::MAX, 1, 2]); // y wraps: holds x 5, y 0
        check_candidates(&rects);
        let mut locator = TileLocator::default();
        locator.build(&rects);
        assert!(locator.candidates(2, 8, 300, 301).eq([300]));
        assert!(locator.candidates(5, 0, 301, u64::MAX).eq([301]));
    }

    /// A query of many large overlapping tiles builds none (the scan finds them at once):
    /// 100 full-screen tiles at about 400 buckets would list each in all of them.
    #[test]
    fn overlapping_large_tiles_build_no_locator() {
        let rects = vec![[0, 0, 1280, 1024]; 100];
        let mut locator = TileLocator::default();
        assert!(!locator.build(&rects));
        assert!(!locator.is_built());
    }
}
