//! The framebuffer interleave: which board and which Image Engine own a pixel.
//!
//! With `B` boards of `N` Image Engines there are `U = B x N` units. A pixel maps to a unit
//! `g` by the [`Interleave`] rule; unit `g` is Image Engine `g / B` of board `g mod B`, so
//! neighbouring units sit on different boards and every board gets an equal share of any
//! wide span.

use crate::arch::{Interleave, IrArch};

/// Where a pixel lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelOwner {
    pub board: usize,
    /// The Image Engine's index within its board.
    pub image_engine: usize,
}

#[derive(Clone, Debug)]
pub struct FramebufferInterleave {
    kind: Interleave,
    boards: usize,
    units: u64,
    block_width: u32,
    block_height: u32,
}

impl FramebufferInterleave {
    pub fn new(arch: &IrArch) -> FramebufferInterleave {
        FramebufferInterleave {
            kind: arch.interleave,
            boards: arch.boards,
            units: arch.image_engines() as u64,
            block_width: arch.block_width_pixels,
            block_height: arch.block_height_pixels,
        }
    }

    /// The unit (0..U) owning pixel `(x, y)`.
    #[inline]
    pub fn unit(&self, x: u16, y: u16) -> usize {
        let (x, y) = (x as u32, y as u32);
        let g = match self.kind {
            Interleave::Columns => x as u64 % self.units,
            Interleave::Blocks => {
                let (bx, by) = (x / self.block_width, y / self.block_height);
                (bx as u64 + by as u64) % self.units
            }
            Interleave::Morton => {
                let (bx, by) = (x / self.block_width, y / self.block_height);
                morton(bx, by) % self.units
            }
        };
        g as usize
    }

    /// The units owning pixels `x..x + len` of row `y`, in order: what [`Self::unit`] gives
    /// pixel by pixel, found once a block (a column under `columns`) and stepped along.
    #[inline]
    pub fn for_each_unit_along(&self, x: u16, y: u16, len: usize, mut each: impl FnMut(usize)) {
        let end = x as u32 + len as u32;
        if self.kind == Interleave::Columns {
            let mut g = x as u64 % self.units;
            for _ in 0..len {
                each(g as usize);
                g += 1;
                if g == self.units {
                    g = 0;
                }
            }
            return;
        }
        let mut at = x as u32;
        while at < end {
            let block_end = (at / self.block_width + 1) * self.block_width;
            let g = self.unit(at as u16, y);
            for _ in at..block_end.min(end) {
                each(g);
            }
            at = block_end;
        }
    }

    /// The units owning pixels `x..x + len` of row `y`, in order, as runs: each unit with
    /// the pixels it owns in a row before the next pixel's owner differs (a block's share
    /// of the row under `blocks` and `morton`, one pixel under `columns`).
    #[inline]
    pub fn for_each_block_along(
        &self,
        x: u16,
        y: u16,
        len: usize,
        mut each: impl FnMut(usize, u64),
    ) {
        if self.kind == Interleave::Columns {
            return self.for_each_unit_along(x, y, len, |unit| each(unit, 1));
        }
        let end = x as u32 + len as u32;
        let mut at = x as u32;
        while at < end {
            let block_end = ((at / self.block_width + 1) * self.block_width).min(end);
            each(self.unit(at as u16, y), (block_end - at) as u64);
            at = block_end;
        }
    }

    /// The board and Image Engine owning pixel `(x, y)`.
    #[inline]
    pub fn owner(&self, x: u16, y: u16) -> PixelOwner {
        self.owner_of_unit(self.unit(x, y))
    }

    /// The board and Image Engine of unit `g`.
    #[inline]
    pub fn owner_of_unit(&self, g: usize) -> PixelOwner {
        PixelOwner {
            board: g % self.boards,
            image_engine: g / self.boards,
        }
    }
}

/// Bits of `x` and `y` interleaved, x in the even bits: the Z-order curve number.
fn morton(x: u32, y: u32) -> u64 {
    spread(x) | (spread(y) << 1)
}

fn spread(v: u32) -> u64 {
    let mut v = v as u64;
    v = (v | (v << 16)) & 0x0000_FFFF_0000_FFFF;
    v = (v | (v << 8)) & 0x00FF_00FF_00FF_00FF;
    v = (v | (v << 4)) & 0x0F0F_0F0F_0F0F_0F0F;
    v = (v | (v << 2)) & 0x3333_3333_3333_3333;
    (v | (v << 1)) & 0x5555_5555_5555_5555
}

#[cfg(test)]
mod tests {
    use super::*;

    fn interleave(kind: Interleave, boards: usize, per_board: usize) -> FramebufferInterleave {
        FramebufferInterleave {
            kind,
            boards,
            units: (boards * per_board) as u64,
            block_width: 2,
            block_height: 2,
        }
    }

    #[test]
    fn units_along_a_row_one_by_one_or_in_runs_are_each_pixels_unit() {
        // Every kind, block sizes that do and do not divide the units, spans starting
        // inside blocks and wrapping past the last unit.
        for kind in [Interleave::Columns, Interleave::Blocks, Interleave::Morton] {
            for (boards, per_board, block_width) in [(2, 3, 2), (4, 5, 3), (1, 1, 1), (4, 80, 4)] {
                let interleave = FramebufferInterleave {
                    block_width,
                    ..interleave(kind, boards, per_board)
                };
                for (x, y, len) in [(0, 0, 17), (5, 3, 700), (1021, 77, 3), (2, 9, 0)] {
                    let mut along = Vec::new();
                    interleave.for_each_unit_along(x, y, len, |g| along.push(g));
                    let each: Vec<usize> =
                        (0..len).map(|i| interleave.unit(x + i as u16, y)).collect();
                    assert_eq!(along, each, "{kind:?} {boards}x{per_board} at ({x}, {y})");
                    // The same units as runs, a block's share of the row each.
                    let mut runs = Vec::new();
                    interleave.for_each_block_along(x, y, len, |g, count| {
                        assert!(count > 0);
                        runs.extend(std::iter::repeat_n(g, count as usize));
                    });
                    assert_eq!(
                        runs, each,
                        "runs: {kind:?} {boards}x{per_board} at ({x}, {y})"
                    );
                }
            }
        }
    }

    #[test]
    fn hand_worked_owners() {
        // 2 boards x 3 Image Engines: unit g -> board g mod 2, Image Engine g / 2.
        let columns = interleave(Interleave::Columns, 2, 3);
        let owner = |i: &FramebufferInterleave, x, y| {
            let o = i.owner(x, y);
            (o.board, o.image_engine)
        };
        assert_eq!(owner(&columns, 0, 9), (0, 0));
        assert_eq!(owner(&columns, 5, 0), (1, 2));
        assert_eq!(owner(&columns, 7, 3), (1, 0), "column 7 = unit 1");
        // Blocks of 2x2: pixel (5, 2) is block (2, 1): unit 3 -> board 1, Image Engine 1.
        let blocks = interleave(Interleave::Blocks, 2, 3);
        assert_eq!(owner(&blocks, 5, 2), (1, 1));
        assert_eq!(owner(&blocks, 4, 3), (1, 1), "same block");
        // Morton of block (2, 1) = 0b0110 = 6 -> unit 0.
        let morton = interleave(Interleave::Morton, 2, 3);
        assert_eq!(owner(&morton, 5, 2), (0, 0));
        assert_eq!(owner(&morton, 3, 1), (1, 0), "block (1, 0): morton 1");
    }

    #[test]
    fn morton_interleaves_bits_x_first() {
        // x = 0b11, y = 0b01 -> y1 x1 y0 x0 = 0 1 1 1.
        assert_eq!(morton(3, 1), 0b0111);
        assert_eq!(morton(0, 2), 0b1000);
        assert_eq!(morton(5, 0), 0b10001);
    }
}
