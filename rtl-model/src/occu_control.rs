//! OccU Control: the round-robin arbiter over the engines' hit words, the write buffer (a
//! FIFO of words in front of the memory port) and the record sequencer.
//!
//! Registers: the write buffer (`capacity` words; occupancy `bits_for(capacity)` bits with
//! full/empty wires), the arbiter's pointer (`bits_for(engines - 1)` bits), and a FIFO of
//! record banks: at a query's end token the engines' tile slots move into a bank (double
//! buffering, so the next query counts while the records drain); a bank becomes eligible
//! the cycle after it was loaded. Per bank: tile counter (17 bits), word counter (4 bits),
//! words left (25 bits), overflow counter (17 bits).
//!
//! Per cycle: `room = capacity - occupancy + grants` (a slot granted this cycle is reused
//! this cycle). Record words go first: eligible banks in order, any number per cycle within
//! room; hit words are blocked while any bank has words left after this cycle. Then hit
//! words within the remaining room, one per pick, the arbiter picking the next engine with
//! a word after the last one picked. Per tile a record is 8 words (NOHC, PHC, Xmin, Xmax,
//! Ymin, Ymax, Zmin, Zmax at offsets 0..8), then, for a verbose tile that overflowed and has
//! room for at least one hit, the terminator -1 (32 bits of ones) over its last hit entry.

use crate::bits::bits_for;
use crate::occlusion_engine::{OcclusionEngine, TileSlot, RECORD_WORDS};
use std::collections::VecDeque;

/// What a buffer word holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum WordKind {
    #[default]
    Hit,
    Record,
    Terminator,
}

/// One word for an occlusion buffer: which tile's buffer, at which entry, and its value.
/// (The port moves 32-bit words; `data` is 64 bits wide so that counters up to 64 bits
/// travel in one record word of this model.)
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Word {
    pub tile: u32,
    pub offset: u32,
    pub data: u64,
    pub kind: WordKind,
}

/// The terminator's value: -1 as a 32-bit word.
pub const TERMINATOR: u64 = 0xFFFF_FFFF;

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecordBank {
    slots: Vec<TileSlot>,
    verbose: bool,
    hit_room: u32,
    eligible: bool,
    tile: u32,
    word: u32,
    words_left: u64,
    overflows: u32,
}

impl RecordBank {
    pub fn new(slots: Vec<TileSlot>, verbose: bool, hit_room: u32) -> RecordBank {
        let mut bank = RecordBank {
            slots,
            verbose,
            hit_room,
            eligible: false,
            tile: 0,
            word: 0,
            words_left: 0,
            overflows: 0,
        };
        bank.words_left = (0..bank.slots.len())
            .map(|t| bank.tile_words(t) as u64)
            .sum();
        bank
    }

    fn terminated(&self, tile: usize) -> bool {
        self.verbose && self.slots[tile].overflowed && self.hit_room > 0
    }

    fn tile_words(&self, tile: usize) -> u32 {
        RECORD_WORDS + self.terminated(tile) as u32
    }

    /// The next record word; advances the tile and word counters.
    fn emit(&mut self) -> Word {
        let t = self.tile as usize;
        let s = &self.slots[t];
        let (offset, data, kind) = match self.word {
            0 => (0, s.nohc, WordKind::Record),
            1 => (1, s.phc, WordKind::Record),
            2 => (2, s.xmin as u64, WordKind::Record),
            3 => (3, s.xmax as u64, WordKind::Record),
            4 => (4, s.ymin as u64, WordKind::Record),
            5 => (5, s.ymax as u64, WordKind::Record),
            6 => (6, s.zmin as u64, WordKind::Record),
            7 => (7, s.zmax as u64, WordKind::Record),
            _ => (
                RECORD_WORDS + self.hit_room - 1,
                TERMINATOR,
                WordKind::Terminator,
            ),
        };
        if self.word == 0 && self.verbose && s.overflowed {
            self.overflows += 1;
        }
        self.word += 1;
        if self.word == self.tile_words(t) {
            self.word = 0;
            self.tile += 1;
        }
        self.words_left -= 1;
        Word {
            tile: t as u32,
            offset,
            data,
            kind,
        }
    }

    /// The overflow register of tile `tile` (in query order).
    pub fn overflowed(&self, tile: usize) -> bool {
        self.slots[tile].overflowed
    }

    pub fn tile_counter(&self) -> u32 {
        self.tile
    }

    pub fn word_counter(&self) -> u32 {
        self.word
    }
}

/// OccU Control's wires in one cycle.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ControlWires {
    pub grants: u32,
    pub room: u32,
    pub full: bool,
    pub empty: bool,
    pub record_words: u32,
    /// Engines picked by the arbiter, in order, one per hit word entering.
    pub picks: Vec<u32>,
    /// The arbiter's per-engine pick counts (scratch, reused every cycle).
    taken: Vec<u32>,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OccuControl {
    capacity: u32,
    engines: u32,
    pub fifo: VecDeque<Word>,
    pub banks: VecDeque<RecordBank>,
    /// The arbiter's pointer: the engine it looks at first.
    pub pointer: u32,
    /// Overflowed buffers of the last bank that finished (the glRenderMode return value).
    pub last_bank_overflows: u32,
    /// Statistics (not hardware).
    pub hit_words: u64,
    pub record_words: u64,
    pub terminator_words: u64,
    pub overflowed_buffers: u64,
}

impl OccuControl {
    pub fn new(capacity: u32, engines: u32) -> OccuControl {
        OccuControl {
            capacity,
            engines,
            // A small start: the IR holds one unit per Image Engine (thousands); the FIFO
            // grows to its capacity only if the run fills it.
            fifo: VecDeque::with_capacity(capacity.min(64) as usize),
            banks: VecDeque::new(),
            pointer: 0,
            last_bank_overflows: 0,
            hit_words: 0,
            record_words: 0,
            terminator_words: 0,
            overflowed_buffers: 0,
        }
    }

    pub fn occupancy_bits(&self) -> u32 {
        bits_for(self.capacity as u64)
    }

    pub fn pointer_bits(&self) -> u32 {
        bits_for(self.engines as u64 - 1)
    }

    /// With no grant this cycle, the latch changes nothing: every record bank is eligible
    /// already (a new bank's flag is set by its first latch) and no word can enter, the
    /// write buffer being full or nothing asking for it (no record bank, and no hit word
    /// offered when `hits_offered` is false).
    pub fn still_without_grants(&self, hits_offered: bool) -> bool {
        let full = self.fifo.len() as u32 == self.capacity;
        let nothing_to_write = self.banks.is_empty() && !hits_offered;
        self.banks.iter().all(|bank| bank.eligible) && (full || nothing_to_write)
    }

    /// Evaluate: `grants` head words leave for the port this cycle; `available[e]` hit
    /// words engine `e` offers.
    pub fn eval(&self, grants: u32, available: &[u32], wires: &mut ControlWires) {
        let occupancy = self.fifo.len() as u32;
        debug_assert!(grants <= occupancy);
        let room = self.capacity - occupancy + grants.min(occupancy);
        wires.grants = grants;
        wires.room = room;
        wires.full = occupancy == self.capacity;
        wires.empty = occupancy == 0;
        let mut budget = room as u64;
        let mut records = 0u64;
        let mut blocked = false;
        for bank in &self.banks {
            if !bank.eligible {
                blocked = true;
                break;
            }
            let take = budget.min(bank.words_left);
            records += take;
            budget -= take;
            if bank.words_left > take {
                blocked = true;
                break;
            }
        }
        wires.record_words = records as u32;
        wires.picks.clear();
        if blocked || budget == 0 {
            return;
        }
        self.arbitrate(budget, available, &mut wires.picks, &mut wires.taken);
    }

    /// The round-robin arbiter: up to `budget` picks over the engines' offered words.
    fn arbitrate(
        &self,
        mut budget: u64,
        available: &[u32],
        picks: &mut Vec<u32>,
        taken: &mut Vec<u32>,
    ) {
        let mut left: u64 = available.iter().map(|&a| a as u64).sum();
        if left == 0 {
            return;
        }
        let n = self.engines;
        taken.clear();
        taken.resize(n as usize, 0);
        let mut e = self.pointer;
        while budget > 0 && left > 0 {
            if taken[e as usize] < available[e as usize] {
                taken[e as usize] += 1;
                picks.push(e);
                budget -= 1;
                left -= 1;
            }
            e = if e + 1 == n { 0 } else { e + 1 };
        }
    }

    /// Latch: granted words leave, record and hit words enter (`entered`, in order).
    pub fn latch(
        &mut self,
        wires: &ControlWires,
        engines: &mut [OcclusionEngine],
        entered: &mut Vec<Word>,
    ) {
        for _ in 0..wires.grants {
            self.fifo.pop_front();
        }
        for _ in 0..wires.record_words {
            let bank = self
                .banks
                .front_mut()
                .expect("record words come from a bank");
            let word = bank.emit();
            match word.kind {
                WordKind::Terminator => self.terminator_words += 1,
                _ => self.record_words += 1,
            }
            self.fifo.push_back(word);
            entered.push(word);
            if bank.words_left == 0 {
                let done = self.banks.pop_front().expect("front bank");
                self.last_bank_overflows = done.overflows;
                self.overflowed_buffers += done.overflows as u64;
            }
        }
        for &e in &wires.picks {
            let word = engines[e as usize]
                .queue
                .pop_front()
                .expect("the arbiter picks engines with words");
            self.hit_words += 1;
            self.fifo.push_back(word);
            entered.push(word);
            self.pointer = if e + 1 == self.engines { 0 } else { e + 1 };
        }
        for bank in &mut self.banks {
            bank.eligible = true;
        }
        // An empty bank (no tiles cannot happen; kept total) finishes at once.
        while self
            .banks
            .front()
            .is_some_and(|b| b.eligible && b.words_left == 0)
        {
            let done = self.banks.pop_front().expect("front bank");
            self.last_bank_overflows = done.overflows;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arbiter_is_fair_when_every_engine_asks() {
        let control = OccuControl::new(64, 4);
        let (mut picks, mut taken) = (Vec::new(), Vec::new());
        control.arbitrate(10, &[5, 5, 5, 5], &mut picks, &mut taken);
        assert_eq!(picks, [0, 1, 2, 3, 0, 1, 2, 3, 0, 1]);
        picks.clear();
        control.arbitrate(10, &[0, 3, 0, 1], &mut picks, &mut taken);
        assert_eq!(picks, [1, 3, 1, 1]);
    }

    #[test]
    fn pointer_moves_past_the_last_pick() {
        let mut control = OccuControl::new(64, 3);
        let mut engines: Vec<_> = (0..3).map(|e| OcclusionEngine::new(e, 3, 8)).collect();
        for engine in &mut engines {
            engine.queue.push_back(Word::default());
            engine.queue.push_back(Word::default());
        }
        let mut wires = ControlWires::default();
        let mut entered = Vec::new();
        // Room for two words only.
        control.capacity = 2;
        control.eval(0, &[2, 2, 2], &mut wires);
        assert_eq!(wires.picks, [0, 1]);
        control.latch(&wires, &mut engines, &mut entered);
        assert_eq!(control.pointer, 2);
        assert!(!wires.full);
        control.eval(1, &[1, 1, 2], &mut wires);
        assert_eq!(wires.picks, [2]);
        assert!(wires.full);
    }

    fn slot(overflowed: bool) -> TileSlot {
        let mut s = TileSlot::reset(0, 0, 4, 4);
        s.nohc = 3;
        s.phc = 5;
        s.overflowed = overflowed;
        s
    }

    fn drain(bank: RecordBank) -> (Vec<Word>, u32) {
        let mut control = OccuControl::new(100, 1);
        control.banks.push_back(bank);
        let mut engines = vec![OcclusionEngine::new(0, 1, 8)];
        let mut wires = ControlWires::default();
        let mut entered = Vec::new();
        // Loaded this cycle: nothing before the next.
        control.eval(0, &[0], &mut wires);
        assert_eq!(wires.record_words, 0);
        control.latch(&wires, &mut engines, &mut entered);
        control.eval(0, &[0], &mut wires);
        control.latch(&wires, &mut engines, &mut entered);
        assert!(control.banks.is_empty());
        (entered, control.last_bank_overflows)
    }

    #[test]
    fn terminator_only_for_overflowed_verbose_tiles_with_hit_room() {
        let (words, overflows) = drain(RecordBank::new(vec![slot(false), slot(true)], true, 4));
        assert_eq!(words.len(), 8 + 9);
        assert_eq!(overflows, 1);
        let last = words[16];
        assert_eq!(
            (last.tile, last.offset, last.data, last.kind),
            (1, 11, TERMINATOR, WordKind::Terminator)
        );
        assert_eq!((words[8].tile, words[8].data, words[9].data), (1, 3, 5));
        assert_eq!(words[10].data, u32::MAX as u64);
        // No hit room: overflowed, counted, but no terminator.
        let (words, overflows) = drain(RecordBank::new(vec![slot(true)], true, 0));
        assert_eq!((words.len(), overflows), (8, 1));
        // Brief mode never terminates.
        let (words, overflows) = drain(RecordBank::new(vec![slot(true)], false, 4));
        assert_eq!((words.len(), overflows), (8, 0));
    }
}
