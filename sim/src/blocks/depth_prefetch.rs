//! The depth prefetch buffer: issues depth reads ahead of the depth test to hide memory
//! latency.
//!
//! Memory layout: the depth buffer is stored as framebuffer tiles (pages) of
//! `framebuffer_tile_width_pixels` x `framebuffer_tile_height_pixels` pixels, tiles row by
//! row from the bottom left; inside a tile, pixels row by row, packed into memory words of
//! `memory_port_bits_per_cycle` bits (`pixels_per_word` pixels each).
//!
//! Rules, for fragment `i` that arrived at the depth pipeline in cycle `arrive_i` (its FIFO
//! entry is readable):
//! - every fragment takes one of `prefetch_depth_fragments` slots (P) and frees it in the
//!   cycle it enters the depth test, so the request cycle is
//!   `q_i = max(arrive_i, test_{i-P}, q_{i-1} + 1)` (one request decision per cycle);
//! - with the depth test off nothing is read: the data is ready at once;
//! - if the fragment's word is the word of the last read, it is a hit: its data is ready
//!   when that read's data is;
//! - otherwise one word is read on the port, granted in cycle `g` at or after `q_i`, and
//!   the data is ready in cycle `g + page_hit_latency_cycles` when the word's page is the
//!   open row of its bank (page `p` lies in bank `p mod memory_banks`; each bank keeps the
//!   row of its last read open), `g + page_miss_latency_cycles` otherwise (also for a
//!   bank's first read). With one bank, a hit is a read in the page of the last read.

use crate::arch::O2Arch;
use crate::blocks::fifo::Fifo;
use crate::blocks::memory_port::{MemoryPort, PortClient};
use occsim_traces::depth_layout::{DepthAddress, DepthRead, LastRead};

pub struct DepthPrefetch {
    slots: Fifo,
    last_request: Option<u64>,
    last_read: LastRead,
    last_data_ready: u64,
    page_hit_latency: u64,
    page_miss_latency: u64,
    word_bits: u32,
    address: DepthAddress,
    pub word_hits: u64,
    pub page_hits: u64,
    pub page_misses: u64,
    /// Effect hook: false when the viewport lies in one page, so page 0 is every read's.
    page_model: bool,
}

impl DepthPrefetch {
    /// `page_model` false promises that the viewport lies inside one framebuffer tile.
    pub fn new(arch: &O2Arch, viewport_width: u32, page_model: bool) -> DepthPrefetch {
        DepthPrefetch {
            slots: Fifo::new(arch.prefetch_depth_fragments),
            last_request: None,
            last_read: LastRead::new(arch.memory_banks),
            last_data_ready: 0,
            page_hit_latency: arch.page_hit_latency_cycles,
            page_miss_latency: arch.page_miss_latency_cycles,
            word_bits: arch.memory_port_bits_per_cycle,
            address: DepthAddress::new(&arch.depth_layout(), viewport_width),
            word_hits: 0,
            page_hits: 0,
            page_misses: 0,
            page_model,
        }
    }

    /// Fetch the depth of fragment number `index` at (x, y); returns the cycle its data is
    /// ready.
    #[inline]
    pub fn fetch(
        &mut self,
        index: usize,
        arrive: u64,
        x: u16,
        y: u16,
        read: bool,
        port: &mut MemoryPort,
    ) -> u64 {
        let mut request = arrive.max(self.slots.slot_free_cycle_for(index));
        if let Some(last) = self.last_request {
            request = request.max(last + 1);
        }
        self.fetch_at(request, x, y, read, port)
    }

    /// [`Self::fetch`] of a fragment whose request cycle is known (a fast-forward proved it).
    #[inline]
    pub fn fetch_at(
        &mut self,
        request: u64,
        x: u16,
        y: u16,
        read: bool,
        port: &mut MemoryPort,
    ) -> u64 {
        self.last_request = Some(request);
        if !read {
            return 0;
        }
        let (word, page) = if self.page_model {
            self.address.locate(x, y)
        } else {
            // Effect hook: the whole viewport is page 0.
            self.address.locate_in_first_page(x, y)
        };
        let latency = match self.last_read.read(word, page) {
            DepthRead::SameWord => {
                self.word_hits += 1;
                return self.last_data_ready;
            }
            DepthRead::PageHit => {
                self.page_hits += 1;
                self.page_hit_latency
            }
            DepthRead::PageMiss => {
                self.page_misses += 1;
                self.page_miss_latency
            }
        };
        let grant = port.claim(request, self.word_bits, PortClient::DepthRead);
        self.last_data_ready = grant + latency;
        self.last_data_ready
    }

    /// `count` fetches of fragments in the word of the last read (or with nothing read):
    /// word hits, the last requested in `last_request` (a fast-forward proved their
    /// request cycles).
    #[inline]
    pub fn fetch_word_hits(&mut self, count: u64, last_request: u64, read: bool) {
        if count == 0 {
            return;
        }
        self.last_request = Some(last_request);
        if read {
            self.word_hits += count;
        }
    }

    /// Pixels from x on, along its row, in x's word (x's included): the fetches after x's
    /// that are word hits.
    #[inline]
    pub fn pixels_left_in_word(&self, x: u16) -> u32 {
        self.address.pixels_left_in_word(x)
    }

    /// The cycle of the last request (None before any).
    pub fn last_request(&self) -> Option<u64> {
        self.last_request
    }

    /// The slots: when fragment `index` may be requested at the earliest.
    #[inline]
    pub fn slot_free_cycle_for(&self, index: usize) -> u64 {
        self.slots.slot_free_cycle_for(index)
    }

    pub fn slots(&self) -> usize {
        self.slots.capacity()
    }

    /// `count` fragments entered the depth test in consecutive cycles from `first`.
    #[inline]
    pub fn retire_run(&mut self, first: u64, count: usize) {
        self.slots.depart_run(first, count);
    }

    /// The fragment fetched longest ago entered the depth test in `cycle`.
    #[inline(always)]
    pub fn retire(&mut self, cycle: u64) {
        self.slots.depart(cycle);
    }
}
