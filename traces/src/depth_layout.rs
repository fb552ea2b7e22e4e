//! Where a depth pixel lives in memory: the framebuffer-tiled layout of the O2-like
//! machine's depth buffer, and which reads of it are new words, page hits or page misses.
//!
//! One definition for the two places that need it: the cycle model's depth prefetch (in the
//! sim crate) and the trace writer's window index ([`crate::trace::index`]), which counts a
//! window's depth reads and page misses once, when the trace is made, so the analytic level
//! need not decode fragments.
//!
//! Layout: the depth buffer is stored as framebuffer tiles (pages) of `tile_width_pixels` x
//! `tile_height_pixels` pixels, tiles row by row from the bottom left; inside a tile, pixels
//! row by row, `pixels_per_word` to a memory word. Page `p` lies in bank `p mod banks`; each
//! bank keeps the row of its last read open.

use serde::{Deserialize, Serialize};

/// The layout's parameters (the machine's architecture gives them).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DepthLayout {
    /// Width of one framebuffer tile (one memory page), pixels.
    pub tile_width_pixels: u32,
    /// Height of one framebuffer tile, pixels.
    pub tile_height_pixels: u32,
    /// Depth pixels in one memory word.
    pub pixels_per_word: u32,
    /// Memory banks, each with one open row.
    pub banks: u32,
}

impl DepthLayout {
    /// Why these parameters describe no layout, if they do not.
    pub fn problem(&self) -> Option<String> {
        if self.tile_width_pixels == 0 || self.tile_height_pixels == 0 {
            return Some("framebuffer tiles of zero pixels".to_owned());
        }
        if self.pixels_per_word == 0 || !self.tile_width_pixels.is_multiple_of(self.pixels_per_word)
        {
            return Some(format!(
                "tile width {} is not a multiple of {} pixels a word",
                self.tile_width_pixels, self.pixels_per_word
            ));
        }
        (self.banks == 0).then(|| "zero memory banks".to_owned())
    }
}

/// The word and page of a depth pixel.
#[derive(Clone, Debug)]
pub struct DepthAddress {
    tile_width: Divider,
    tile_height: Divider,
    tiles_per_row: u64,
    pixels_per_word: Divider,
    words_per_tile_row: u64,
    words_per_tile: u64,
}

impl DepthAddress {
    /// The addresses of a `viewport_width` pixels wide viewport (`layout` free of problems).
    pub fn new(layout: &DepthLayout, viewport_width: u32) -> DepthAddress {
        let tile_width = layout.tile_width_pixels;
        let words_per_tile_row = (tile_width / layout.pixels_per_word) as u64;
        DepthAddress {
            tile_width: Divider::new(tile_width),
            tile_height: Divider::new(layout.tile_height_pixels),
            tiles_per_row: viewport_width.div_ceil(tile_width) as u64,
            pixels_per_word: Divider::new(layout.pixels_per_word),
            words_per_tile_row,
            words_per_tile: words_per_tile_row * layout.tile_height_pixels as u64,
        }
    }

    /// `(word, page)` of pixel (x, y).
    #[inline(always)]
    pub fn locate(&self, x: u16, y: u16) -> (u64, u64) {
        let (tile_x, in_tile_x) = self.tile_width.divide(x as u32);
        let (tile_y, in_tile_y) = self.tile_height.divide(y as u32);
        let page = tile_y as u64 * self.tiles_per_row + tile_x as u64;
        (self.word(page, in_tile_x, in_tile_y), page)
    }

    /// Pixels from x on, along its row, in x's word (x's included): a row run changes word
    /// only after them.
    #[inline]
    pub fn pixels_left_in_word(&self, x: u16) -> u32 {
        let (_, in_tile_x) = self.tile_width.divide(x as u32);
        let (_, in_word) = self.pixels_per_word.divide(in_tile_x);
        (self.pixels_per_word.divisor - in_word).min(self.tile_width.divisor - in_tile_x)
    }

    /// `(word, 0)` of pixel (x, y) of a viewport inside one page (page 0): no tile division.
    #[inline(always)]
    pub fn locate_in_first_page(&self, x: u16, y: u16) -> (u64, u64) {
        debug_assert_eq!(self.tile_width.divide(x as u32).0, 0);
        debug_assert_eq!(self.tile_height.divide(y as u32).0, 0);
        (self.word(0, x as u32, y as u32), 0)
    }

    #[inline(always)]
    fn word(&self, page: u64, in_tile_x: u32, in_tile_y: u32) -> u64 {
        page * self.words_per_tile
            + in_tile_y as u64 * self.words_per_tile_row
            + self.pixels_per_word.divide(in_tile_x).0 as u64
    }
}

/// What a depth read of a word costs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthRead {
    /// The word of the last read: no new read.
    SameWord,
    /// A new word in the open row of its bank.
    PageHit,
    /// A new word in another page (or its bank's first read).
    PageMiss,
}

/// The word of the last depth read and the open row (page) of every memory bank: decides
/// [`DepthRead`]. Page `p` lies in bank `p mod banks`; a read opens its page's row in its bank.
#[derive(Clone, Debug)]
pub struct LastRead {
    word: Option<u64>,
    open_rows: Vec<Option<u64>>,
}

impl LastRead {
    /// No read yet, `banks` banks (at least one).
    pub fn new(banks: u32) -> LastRead {
        LastRead {
            word: None,
            open_rows: vec![None; banks.max(1) as usize],
        }
    }

    /// Read `word` of `page`: what it costs (a new read becomes the last one and opens its
    /// page's row).
    #[inline(always)]
    pub fn read(&mut self, word: u64, page: u64) -> DepthRead {
        if self.word == Some(word) {
            return DepthRead::SameWord;
        }
        self.word = Some(word);
        let banks = self.open_rows.len() as u64;
        let bank = match banks {
            1 => 0,
            // A mask when it can be: no division on every read.
            _ if banks.is_power_of_two() => (page & (banks - 1)) as usize,
            _ => (page % banks) as usize,
        };
        let row = &mut self.open_rows[bank];
        let hit = *row == Some(page);
        *row = Some(page);
        if hit {
            DepthRead::PageHit
        } else {
            DepthRead::PageMiss
        }
    }
}

/// Division by a constant that takes a shift when the divisor is a power of two (the usual
/// case: 128-pixel tiles, 8 pixels a word), which keeps divisions off the per-fragment path.
#[derive(Clone, Copy, Debug)]
struct Divider {
    divisor: u32,
    shift: Option<u32>,
}

impl Divider {
    fn new(divisor: u32) -> Divider {
        Divider {
            divisor,
            shift: divisor.is_power_of_two().then(|| divisor.trailing_zeros()),
        }
    }

    /// (quotient, remainder)
    #[inline(always)]
    fn divide(self, value: u32) -> (u32, u32) {
        match self.shift {
            Some(shift) => (value >> shift, value & (self.divisor - 1)),
            None => (value / self.divisor, value % self.divisor),
        }
    }
}
