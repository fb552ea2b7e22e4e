//! OccU Control: collects the engines' hit words and brief records and writes them to the
//! occlusion buffers in main memory through its write buffer.
//!
//! Rules:
//! - words are 32 bits; they enter the `occu_write_buffer_words` buffer in order, any number
//!   per cycle while there is room ([`crate::blocks::write_buffer`]): word `m` enters in
//!   `e_m = max(ready, e_{m-1}, slot_m)`;
//! - a fragment's hit words are ready when the engines finish it (`o_i + s - 1`); the
//!   fragment leaves the OccU when its last hit word has entered (the engines stall
//!   meanwhile);
//! - at a query's end, when the end token has passed the OccU in cycle `to`, the records are
//!   ready in `to + 1`: per tile in query order, the 8-word brief record, then, for a verbose
//!   buffer that overflowed and has room for at least one hit, the -1 terminator word (it
//!   overwrites the last hit). The query's result is available in the cycle after the last
//!   word's port grant.

use crate::arch::OCCU_WORD_BITS;
use crate::blocks::memory_port::{MemoryPort, PortClient};
use crate::blocks::occlusion_engine::hit_room;
use crate::blocks::write_buffer::WriteBuffer;
use occsim_traces::query::BRIEF_RECORD_ENTRIES;
use occsim_traces::{QueryMode, QuerySpec, TileResult};

pub struct OccuControl {
    buffer: WriteBuffer,
    last_enter: u64,
    pub hit_words: u64,
    pub record_words: u64,
    pub terminator_words: u64,
    pub overflowed_buffers: u64,
}

impl OccuControl {
    pub fn new(buffer_words: usize) -> OccuControl {
        OccuControl {
            buffer: WriteBuffer::new(buffer_words, OCCU_WORD_BITS, PortClient::OccuControl),
            last_enter: 0,
            hit_words: 0,
            record_words: 0,
            terminator_words: 0,
            overflowed_buffers: 0,
        }
    }

    /// Enqueue `count` words ready from `ready`; returns the cycle the last one entered
    /// (`ready` when there are none).
    #[inline]
    fn enqueue(&mut self, count: u64, ready: u64, port: &mut MemoryPort) -> u64 {
        let mut enter = ready;
        for _ in 0..count {
            enter = enter
                .max(self.last_enter)
                .max(self.buffer.slot_free_cycle());
            self.buffer.push(enter, port);
            self.last_enter = enter;
        }
        enter
    }

    /// A fragment's hit words, ready in `ready`; returns the cycle the fragment may leave.
    #[inline]
    pub fn hits(&mut self, count: u32, ready: u64, port: &mut MemoryPort) -> u64 {
        if count == 0 {
            return ready;
        }
        self.hit_words += count as u64;
        self.enqueue(count as u64, ready, port)
    }

    /// Write the query's records from `ready`; trims overflowed hit lists to what the buffer
    /// finally holds. Returns the cycle the result is available and the overflowed buffers.
    pub fn records(
        &mut self,
        spec: &QuerySpec,
        tiles: &mut [TileResult],
        ready: u64,
        port: &mut MemoryPort,
    ) -> (u64, u32) {
        let room = hit_room(spec.buffer_entries);
        let mut overflowed = 0u32;
        let mut last_grant = ready;
        for tile in tiles.iter_mut() {
            let mut words = BRIEF_RECORD_ENTRIES as u64;
            if spec.mode == QueryMode::Verbose && tile.overflowed {
                overflowed += 1;
                if room > 0 {
                    words += 1;
                    self.terminator_words += 1;
                    tile.hits.truncate(room - 1);
                }
            }
            self.record_words += BRIEF_RECORD_ENTRIES as u64;
            self.enqueue(words, ready, port);
            last_grant = self.buffer.last_grant();
        }
        self.overflowed_buffers += overflowed as u64;
        (last_grant + 1, overflowed)
    }

    /// Distinct cycles OccU Control had the port.
    pub fn port_cycles(&self) -> u64 {
        self.buffer.grant_cycles
    }

    /// The port grant of the last word written (0 before any).
    pub fn last_grant(&self) -> u64 {
        self.buffer.last_grant()
    }

    pub fn words_written(&self) -> u64 {
        self.buffer.entries_written
    }
}
