//! One occlusion engine: the registers of the tiles dealt to it, one in-tile comparator pair
//! and one tile-sequencing position per cycle, and a queue of the hit words it produced.
//!
//! Registers per tile slot (widths in bits):
//! - tile rectangle `x0`, `y0`, `width`, `height`: 32 each (the query's tile, as given);
//! - `phc`, `nohc`: `counter_bits`, saturating at all ones;
//! - `xmin`, `xmax`, `ymin`, `ymax`, `zmin`, `zmax`: 32 (one record word each; the minima
//!   reset to all ones, the maxima to zero);
//! - `hits_sent`: 25 (verbose hits sent, at most the buffer's hit room < 2^24);
//! - `overflowed`: 1.
//!
//! In-tile comparator: `(x - x0) mod 2^32 < width` and the same for y, one 32-bit subtractor
//! and one comparator per axis (exactly the rectangle test of the functional model, wrap
//! included).

use crate::bits::saturating_increment;
use crate::occu_control::Word;
use std::collections::VecDeque;

/// Width of a tile coordinate register and of a record word, in bits.
pub const WORD_BITS: u32 = 32;
/// Width of a hit-room and hits-sent register, in bits (buffers hold < 2^24 entries).
pub const HIT_COUNT_BITS: u32 = 25;
/// Entries of the brief record: NOHC, PHC, Xmin, Xmax, Ymin, Ymax, Zmin, Zmax.
pub const RECORD_WORDS: u32 = 8;

/// One tile slot's registers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TileSlot {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    pub phc: u64,
    pub nohc: u64,
    pub xmin: u32,
    pub xmax: u32,
    pub ymin: u32,
    pub ymax: u32,
    pub zmin: u32,
    pub zmax: u32,
    pub hits_sent: u32,
    pub overflowed: bool,
}

impl TileSlot {
    pub fn reset(x0: u32, y0: u32, width: u32, height: u32) -> TileSlot {
        TileSlot {
            x0,
            y0,
            width,
            height,
            phc: 0,
            nohc: 0,
            xmin: u32::MAX,
            xmax: 0,
            ymin: u32::MAX,
            ymax: 0,
            zmin: u32::MAX,
            zmax: 0,
            hits_sent: 0,
            overflowed: false,
        }
    }

    /// The in-tile comparators.
    #[inline(always)]
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x.wrapping_sub(self.x0) < self.width && y.wrapping_sub(self.y0) < self.height
    }
}

/// The fragment an engine tests this cycle (wires from the unit sequencer).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FragmentWires {
    pub x: u32,
    pub y: u32,
    pub z: u32,
    pub pass: bool,
}

/// An engine's wires in one cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EngineWires {
    /// A tile is tested this cycle.
    pub testing: bool,
    /// The slot tested (the first one with `all_tiles_one_cycle`).
    pub slot: u32,
    /// Tested slots holding the fragment (the comparators' outputs, summed).
    pub inside: u32,
    /// Non-occlusion hits among them.
    pub hits: u32,
    /// Hit words produced (verbose, within room).
    pub words: u32,
}

#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OcclusionEngine {
    /// This engine's number and the engine count (slot `j` holds tile `j * engines + index`).
    index: u32,
    engines: u32,
    counter_bits: u32,
    pub slots: Vec<TileSlot>,
    verbose: bool,
    /// Hit entries per tile buffer (`buffer_entries - 8`), 25 bits.
    hit_room: u32,
    /// Hit words produced and not yet taken by OccU Control's arbiter.
    pub queue: VecDeque<Word>,
    /// Change tracking (not hardware): bumped by every load and unload, the changes to the
    /// slots that no wire shows, so that a waveform probe which saw the same count knows
    /// only the slots its last cycle's wires latched can have changed. Code that changes
    /// `slots` other than by a latch must bump it too.
    pub loads: u64,
    /// Statistics (not hardware): cycles testing tiles, cycles held by OccU Control.
    pub busy_cycles: u64,
    pub stall_cycles: u64,
}

impl OcclusionEngine {
    pub fn new(index: u32, engines: u32, counter_bits: u32) -> OcclusionEngine {
        OcclusionEngine {
            index,
            engines,
            counter_bits,
            ..OcclusionEngine::default()
        }
    }

    /// Load a query's tiles (configuration write between cycles): every `engines`-th tile
    /// from this engine's index on.
    pub fn load(&mut self, tiles: &[[u32; 4]], verbose: bool, hit_room: u32) {
        self.verbose = verbose;
        self.hit_room = hit_room & crate::bits::mask(HIT_COUNT_BITS) as u32;
        self.slots.clear();
        self.slots.extend(
            tiles
                .iter()
                .skip(self.index as usize)
                .step_by(self.engines as usize)
                .map(|t| TileSlot::reset(t[0], t[1], t[2], t[3])),
        );
        self.queue.clear();
        self.loads += 1;
    }

    /// Tiles held (the tile-sequencing counter's range).
    pub fn tile_count(&self) -> u32 {
        self.slots.len() as u32
    }

    /// Hand the slots over to OccU Control's record bank and return to no tiles.
    pub fn unload(&mut self) -> Vec<TileSlot> {
        self.loads += 1;
        std::mem::take(&mut self.slots)
    }

    /// Slots tested at sequencer step `step` (those a latch at that step may change).
    #[inline(always)]
    pub fn tested(&self, step: u32, all_tiles_one_cycle: bool) -> std::ops::Range<usize> {
        let k = self.slots.len();
        if all_tiles_one_cycle {
            if step == 0 {
                0..k
            } else {
                0..0
            }
        } else if (step as usize) < k {
            step as usize..step as usize + 1
        } else {
            0..0
        }
    }

    /// The first of the sequencer steps `steps` whose tested slots hold the fragment
    /// (`steps.end` if none): the steps before it latch nothing in this engine.
    #[inline]
    pub fn first_holding_step(
        &self,
        steps: std::ops::Range<u32>,
        all_tiles_one_cycle: bool,
        f: FragmentWires,
    ) -> u32 {
        let holds = |slot: &TileSlot| slot.contains(f.x, f.y);
        if all_tiles_one_cycle {
            let at_zero = steps.contains(&0) && self.slots.iter().any(holds);
            return if at_zero { 0 } else { steps.end };
        }
        let tested = steps.start as usize..(steps.end as usize).min(self.slots.len());
        if tested.is_empty() {
            return steps.end;
        }
        self.slots[tested]
            .iter()
            .position(holds)
            .map_or(steps.end, |j| steps.start + j as u32)
    }

    /// Of the sequencer steps `steps`, those in which this engine tests a slot (each a
    /// busy cycle).
    pub fn testing_steps(&self, steps: std::ops::Range<u32>, all_tiles_one_cycle: bool) -> u64 {
        let k = self.tile_count();
        if all_tiles_one_cycle {
            (steps.contains(&0) && k > 0) as u64
        } else {
            steps.end.min(k).saturating_sub(steps.start) as u64
        }
    }

    /// Evaluate: the comparators' and hit logic's wires for step `step`.
    #[inline]
    pub fn eval(&self, step: u32, all_tiles_one_cycle: bool, f: FragmentWires) -> EngineWires {
        let range = self.tested(step, all_tiles_one_cycle);
        let mut wires = EngineWires {
            testing: !range.is_empty(),
            slot: range.start as u32,
            ..EngineWires::default()
        };
        for slot in &self.slots[range] {
            if slot.contains(f.x, f.y) {
                wires.inside += 1;
                if f.pass {
                    wires.hits += 1;
                    if self.verbose && slot.hits_sent < self.hit_room {
                        wires.words += 1;
                    }
                }
            }
        }
        wires
    }

    /// Latch the tested slots' registers and queue the hit words (same step as `eval`).
    #[inline]
    pub fn latch(&mut self, step: u32, all_tiles_one_cycle: bool, f: FragmentWires) {
        let range = self.tested(step, all_tiles_one_cycle);
        let counter_bits = self.counter_bits;
        let (index, engines) = (self.index, self.engines);
        for j in range {
            let slot = &mut self.slots[j];
            if !slot.contains(f.x, f.y) {
                continue;
            }
            slot.phc = saturating_increment(slot.phc, counter_bits);
            if !f.pass {
                continue;
            }
            slot.nohc = saturating_increment(slot.nohc, counter_bits);
            slot.xmin = slot.xmin.min(f.x);
            slot.xmax = slot.xmax.max(f.x);
            slot.ymin = slot.ymin.min(f.y);
            slot.ymax = slot.ymax.max(f.y);
            slot.zmin = slot.zmin.min(f.z);
            slot.zmax = slot.zmax.max(f.z);
            if self.verbose {
                if slot.hits_sent < self.hit_room {
                    self.queue.push_back(Word {
                        tile: j as u32 * engines + index,
                        offset: RECORD_WORDS + slot.hits_sent,
                        data: (f.x & 0xFFFF) as u64 | ((f.y & 0xFFFF) as u64) << 16,
                        kind: crate::occu_control::WordKind::Hit,
                    });
                    slot.hits_sent += 1;
                } else {
                    slot.overflowed = true;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fragment(x: u32, y: u32, pass: bool) -> FragmentWires {
        FragmentWires { x, y, z: 7, pass }
    }

    #[test]
    fn comparator_edges_are_half_open() {
        let slot = TileSlot::reset(10, 20, 5, 3);
        assert!(slot.contains(10, 20));
        assert!(slot.contains(14, 22));
        assert!(!slot.contains(15, 22));
        assert!(!slot.contains(14, 23));
        assert!(!slot.contains(9, 20));
        assert!(!slot.contains(10, 19));
        // An empty tile holds nothing; a tile wrapping past 2^32 holds the small coordinates
        // (the functional model's wrapping rectangle test).
        assert!(!TileSlot::reset(3, 3, 0, 1).contains(3, 3));
        assert!(TileSlot::reset(u32::MAX, 0, 2, 1).contains(0, 0));
    }

    #[test]
    fn sequencer_tests_one_slot_per_step_and_counts_saturate() {
        // Engine 1 of 2 holds tiles 1 and 3 of four; 2-bit counters.
        let tiles = [[0, 0, 4, 4], [0, 0, 2, 2], [0, 0, 1, 1], [1, 1, 1, 1]];
        let mut engine = OcclusionEngine::new(1, 2, 2);
        engine.load(&tiles, true, 2);
        assert_eq!(engine.tile_count(), 2);
        for _ in 0..5 {
            for step in 0..2 {
                let f = fragment(1, 1, true);
                let w = engine.eval(step, false, f);
                assert!(w.testing);
                assert_eq!(w.slot, step);
                engine.latch(step, false, f);
            }
        }
        assert!(!engine.eval(2, false, fragment(1, 1, true)).testing);
        let s = &engine.slots;
        assert_eq!((s[0].phc, s[0].nohc, s[1].phc), (3, 3, 3));
        assert_eq!((s[0].hits_sent, s[0].overflowed), (2, true));
        let words: Vec<_> = engine.queue.iter().map(|w| (w.tile, w.offset)).collect();
        assert_eq!(words, [(1, 8), (3, 8), (1, 9), (3, 9)]);
        assert_eq!(engine.queue[0].data, 1 | 1 << 16);
    }
}
