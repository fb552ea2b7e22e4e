//! The Occlusion Unit's top level: the unit sequencer, `engines` occlusion engines in
//! lockstep and OccU Control, with one input/output port bundle per cycle.
//!
//! Unit sequencer registers: state (2 bits: idle, test, drain), tile step
//! (`bits_for(service - 1)` bits), the latched fragment (x 16, y 16, z 24, pass 1), query
//! open (1), service cycles `s` (17 bits: `max(1, max_e k_e)`, 1 with
//! `all_tiles_one_cycle` or no open query).
//!
//! Per cycle: an idle unit accepts a valid fragment (`accepted`) and tests tile step 0 in
//! the same cycle; step `s - 1` is the done cycle, from which OccU Control may take the
//! engines' hit words (the done cycle's own words through a bypass). The fragment leaves
//! (`left`) in the first cycle from done on in which its last hit word enters the write
//! buffer; the cycles after done are stall cycles. The query's end token passes between
//! cycles ([`OccuRtl::end_token`], only when idle); where the tile registers go then is
//! the unit's [`ResultPath`]: into a record bank whose words (records, terminators) are
//! eligible from the next cycle on and go to memory, or out of the partial-report port
//! ([`OccuRtl::take_partial_report`]) to a merge network, writing no word at all.

use crate::bits::{bits_for, mask};
use crate::occlusion_engine::{
    EngineWires, FragmentWires, OcclusionEngine, TileSlot, HIT_COUNT_BITS,
};
use crate::occu_control::{ControlWires, OccuControl, RecordBank, Word};

/// Largest engine count and tile count the registers are sized for.
pub const MAX_ENGINES: u32 = 1024;
pub const MAX_TILES: u32 = 65536;

/// The unit's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OccuParams {
    /// Occlusion engines, 1..=1024.
    pub engines: u32,
    /// Width of PHC and NOHC in bits, 1..=64.
    pub counter_bits: u32,
    /// OccU Control's write buffer, in words, >= 1.
    pub write_buffer_words: u32,
    /// Every engine tests all its tiles in one cycle (k comparators per engine).
    pub all_tiles_one_cycle: bool,
    /// Where a query's tile registers go at its end token.
    pub results: ResultPath,
}

/// Where the tile registers go at a query's end token.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ResultPath {
    /// OccU Control writes each tile's brief record (and a verbose overflow's terminator)
    /// to the occlusion buffers in memory (the O2: one unit per machine).
    #[default]
    Records,
    /// The tile registers leave through the partial-report port to a merge network; OccU
    /// Control writes only hit words (the InfiniteReality: one unit per Image Engine).
    PartialReport,
}

/// A tile as the query gives it (pixels).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileRect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// A query's configuration, written between cycles.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QueryConfig {
    pub tiles: Vec<TileRect>,
    pub verbose: bool,
    /// Hit entries per buffer (`buffer_entries - 8`, < 2^24).
    pub hit_room: u32,
}

/// The fragment input port (from the depth-to-OccU FIFO).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FragmentPort {
    pub valid: bool,
    pub x: u16,
    pub y: u16,
    /// 24-bit depth.
    pub z: u32,
    /// The depth test's write enable.
    pub pass: bool,
}

/// All inputs of one cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CycleInputs {
    pub fragment: FragmentPort,
    /// Write-buffer head words the memory port grants this cycle.
    pub grants: u32,
}

/// The outputs of one cycle.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CycleOutputs {
    /// The fragment on the input port was taken.
    pub accepted: bool,
    /// The fragment in the unit left it.
    pub left: bool,
    /// Words that entered the write buffer, in order.
    pub entered: Vec<Word>,
}

/// Sequencer states.
pub const IDLE: u8 = 0;
pub const TEST: u8 = 1;
pub const DRAIN: u8 = 2;

/// The unit sequencer's wires.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct UnitWires {
    pub accepting: bool,
    pub testing: bool,
    pub step: u32,
    pub done: bool,
    pub arbitrate: bool,
    pub leave: bool,
    pub fragment: FragmentWires,
}

/// Every wire of one cycle.
#[derive(Clone, Debug, Default)]
pub struct Wires {
    pub unit: UnitWires,
    pub engines: Vec<EngineWires>,
    pub available: Vec<u32>,
    pub control: ControlWires,
}

#[derive(Clone, Debug)]
pub struct OccuRtl {
    params: OccuParams,
    pub engines: Vec<OcclusionEngine>,
    pub control: OccuControl,
    /// The cycle counter (64 bits): the cycle `step` evaluates next.
    pub cycle: u64,
    pub state: u8,
    pub step: u32,
    pub fragment: FragmentWires,
    pub query_open: bool,
    pub service: u32,
    /// The partial-report port: the tile slots (query order) of the last end token, with
    /// [`ResultPath::PartialReport`], until the merge network takes them.
    partial_report: Vec<TileSlot>,
    wires: Wires,
    /// Statistics (not hardware): cycles testing, cycles held in drain.
    pub busy_cycles: u64,
    pub stall_cycles: u64,
}

impl OccuRtl {
    pub fn new(params: OccuParams) -> OccuRtl {
        assert!(
            (1..=MAX_ENGINES).contains(&params.engines),
            "engines out of range"
        );
        assert!(
            (1..=64).contains(&params.counter_bits),
            "counter_bits out of range"
        );
        assert!(params.write_buffer_words >= 1, "write buffer needs a word");
        let engines = (0..params.engines)
            .map(|e| OcclusionEngine::new(e, params.engines, params.counter_bits))
            .collect();
        OccuRtl {
            params,
            engines,
            control: OccuControl::new(params.write_buffer_words, params.engines),
            cycle: 0,
            state: IDLE,
            step: 0,
            fragment: FragmentWires::default(),
            query_open: false,
            service: 1,
            partial_report: Vec::new(),
            wires: Wires::default(),
            busy_cycles: 0,
            stall_cycles: 0,
        }
    }

    pub fn params(&self) -> OccuParams {
        self.params
    }

    /// Width of the tile step register in bits.
    pub fn step_bits(&self) -> u32 {
        bits_for(MAX_TILES as u64 - 1)
    }

    /// Load a query's tiles (a configuration write between cycles; the unit is idle).
    pub fn load_query(&mut self, config: &QueryConfig) {
        debug_assert_eq!(self.state, IDLE);
        let tiles: Vec<[u32; 4]> = config
            .tiles
            .iter()
            .map(|t| [t.x, t.y, t.width, t.height])
            .collect();
        let room = config.hit_room & mask(HIT_COUNT_BITS) as u32;
        let mut service = 1;
        for engine in &mut self.engines {
            engine.load(&tiles, config.verbose, room);
            let k = engine.tile_count();
            let cycles = if self.params.all_tiles_one_cycle {
                k.min(1)
            } else {
                k
            };
            service = service.max(cycles);
        }
        self.service = service;
        self.query_open = true;
    }

    /// The query's end token passes the unit at the start of the current cycle if the unit
    /// is idle: the tile slots move into a record bank, eligible from the next cycle, or
    /// (with [`ResultPath::PartialReport`]) onto the partial-report port. Returns whether it
    /// passed.
    pub fn end_token(&mut self, verbose: bool, hit_room: u32) -> bool {
        if self.state != IDLE {
            return false;
        }
        let mut unloaded: Vec<_> = self
            .engines
            .iter_mut()
            .map(|e| e.unload().into_iter())
            .collect();
        let total: usize = unloaded.iter().map(|u| u.len()).sum();
        let mut slots = Vec::with_capacity(total);
        let n = unloaded.len();
        for t in 0..total {
            slots.push(unloaded[t % n].next().expect("round-robin dealing"));
        }
        match self.params.results {
            ResultPath::Records => self.control.banks.push_back(RecordBank::new(
                slots,
                verbose,
                hit_room & mask(HIT_COUNT_BITS) as u32,
            )),
            ResultPath::PartialReport => self.partial_report = slots,
        }
        self.query_open = false;
        self.service = 1;
        true
    }

    /// Take the tile slots (query order) the last end token put on the partial-report port
    /// (empty with [`ResultPath::Records`] or when taken already).
    pub fn take_partial_report(&mut self) -> Vec<TileSlot> {
        std::mem::take(&mut self.partial_report)
    }

    /// Nothing can change until a fragment arrives or a grant comes: idle sequencer, no
    /// record bank. (Then skipping cycles in bulk is exact.)
    pub fn quiescent(&self) -> bool {
        self.state == IDLE && self.control.banks.is_empty()
    }

    /// Jump the cycle counter over cycles in which the state is provably static: the unit
    /// must be [`Self::quiescent`] and no grant may fall in the skipped cycles.
    pub fn skip_to(&mut self, cycle: u64) {
        debug_assert!(self.quiescent());
        self.cycle = self.cycle.max(cycle);
    }

    /// One clock cycle: evaluate every wire, then latch every register.
    #[inline]
    pub fn step(&mut self, inputs: &CycleInputs, outputs: &mut CycleOutputs) {
        let mut wires = std::mem::take(&mut self.wires);
        self.eval(inputs, &mut wires);
        self.latch(&wires, outputs);
        self.wires = wires;
    }

    /// Evaluate the combinational logic from the registers and the inputs.
    #[inline]
    pub fn eval(&self, inputs: &CycleInputs, wires: &mut Wires) {
        let port = inputs.fragment;
        let accepting = self.state == IDLE && port.valid;
        let testing = accepting || self.state == TEST;
        let step = if accepting { 0 } else { self.step };
        let fragment = if accepting {
            FragmentWires {
                x: port.x as u32,
                y: port.y as u32,
                z: port.z & mask(24) as u32,
                pass: port.pass,
            }
        } else {
            self.fragment
        };
        let done = testing && step + 1 == self.service;
        let arbitrate = done || self.state == DRAIN;
        let n = self.engines.len();
        wires.engines.resize(n, EngineWires::default());
        wires.available.resize(n, 0);
        let mut offered = 0u64;
        for (e, engine) in self.engines.iter().enumerate() {
            let w = if testing && self.query_open {
                engine.eval(step, self.params.all_tiles_one_cycle, fragment)
            } else {
                EngineWires::default()
            };
            wires.engines[e] = w;
            let available = if arbitrate {
                engine.queue.len() as u32 + w.words
            } else {
                0
            };
            wires.available[e] = available;
            offered += available as u64;
        }
        self.control
            .eval(inputs.grants, &wires.available, &mut wires.control);
        let leave = arbitrate && wires.control.picks.len() as u64 == offered;
        wires.unit = UnitWires {
            accepting,
            testing,
            step,
            done,
            arbitrate,
            leave,
            fragment,
        };
    }

    /// Latch every register from the wires.
    #[inline]
    pub fn latch(&mut self, wires: &Wires, outputs: &mut CycleOutputs) {
        let u = wires.unit;
        outputs.accepted = u.accepting;
        outputs.left = u.leave;
        outputs.entered.clear();
        if u.testing && self.query_open {
            for engine in &mut self.engines {
                engine.latch(u.step, self.params.all_tiles_one_cycle, u.fragment);
            }
        }
        self.control
            .latch(&wires.control, &mut self.engines, &mut outputs.entered);
        self.busy_cycles += u.testing as u64;
        if self.state == DRAIN {
            self.stall_cycles += 1;
            if self.query_open {
                for engine in &mut self.engines {
                    engine.stall_cycles += (engine.tile_count() > 0) as u64;
                }
            }
        }
        if self.query_open {
            for (engine, w) in self.engines.iter_mut().zip(&wires.engines) {
                engine.busy_cycles += w.testing as u64;
            }
        }
        if u.accepting {
            self.fragment = u.fragment;
        }
        (self.state, self.step) = if u.leave {
            (IDLE, 0)
        } else if u.done || self.state == DRAIN {
            (DRAIN, 0)
        } else if u.testing {
            (TEST, u.step + 1)
        } else {
            (IDLE, 0)
        };
        self.cycle += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(engines: u32, buffer: u32) -> OccuRtl {
        OccuRtl::new(OccuParams {
            engines,
            counter_bits: 32,
            write_buffer_words: buffer,
            all_tiles_one_cycle: false,
            results: ResultPath::Records,
        })
    }

    fn fragment(x: u16, y: u16) -> CycleInputs {
        CycleInputs {
            fragment: FragmentPort {
                valid: true,
                x,
                y,
                z: 5,
                pass: true,
            },
            grants: 0,
        }
    }

    #[test]
    fn a_fragment_takes_max_k_cycles_and_hit_words_enter_in_the_done_cycle() {
        // 3 tiles on 2 engines: engine 0 holds two, so s = 2.
        let mut rtl = unit(2, 8);
        let tile = TileRect {
            x: 0,
            y: 0,
            width: 4,
            height: 4,
        };
        rtl.load_query(&QueryConfig {
            tiles: vec![tile; 3],
            verbose: true,
            hit_room: 4,
        });
        let mut out = CycleOutputs::default();
        rtl.step(&fragment(1, 1), &mut out);
        assert!(out.accepted && !out.left && out.entered.is_empty());
        rtl.step(&CycleInputs::default(), &mut out);
        assert!(out.left);
        let tiles: Vec<_> = out.entered.iter().map(|w| w.tile).collect();
        // Engine 0's two words (tiles 0, 2) and engine 1's (tile 1), round-robin.
        assert_eq!(tiles, [0, 1, 2]);
        assert_eq!((rtl.busy_cycles, rtl.stall_cycles), (2, 0));
        // A full buffer holds the next fragment in drain until grants free slots.
        rtl.step(&fragment(2, 2), &mut out);
        rtl.step(&CycleInputs::default(), &mut out);
        assert_eq!(out.entered.len(), 3);
        rtl.step(&fragment(3, 3), &mut out);
        rtl.step(&CycleInputs::default(), &mut out);
        assert_eq!((out.entered.len(), out.left), (2, false));
        rtl.step(
            &CycleInputs {
                grants: 1,
                ..CycleInputs::default()
            },
            &mut out,
        );
        assert_eq!((out.entered.len(), out.left), (1, true));
        assert_eq!(rtl.stall_cycles, 1);
        assert!(rtl.end_token(true, 4));
        assert!(!rtl.quiescent());
    }

    #[test]
    fn a_partial_report_unit_hands_its_tiles_out_and_writes_no_record() {
        let mut rtl = OccuRtl::new(OccuParams {
            results: ResultPath::PartialReport,
            ..unit(2, 8).params()
        });
        let tile = TileRect {
            x: 0,
            y: 0,
            width: 4,
            height: 4,
        };
        let far = TileRect { x: 8, ..tile };
        rtl.load_query(&QueryConfig {
            tiles: vec![tile, far, tile],
            verbose: true,
            hit_room: 1,
        });
        let mut out = CycleOutputs::default();
        for (x, y) in [(1, 1), (2, 3)] {
            rtl.step(&fragment(x, y), &mut out);
            while !out.left {
                rtl.step(&CycleInputs::default(), &mut out);
            }
        }
        assert!(rtl.end_token(true, 1));
        assert!(rtl.quiescent(), "no record bank");
        let slots = rtl.take_partial_report();
        let counts: Vec<_> = slots.iter().map(|s| (s.x0, s.phc, s.nohc)).collect();
        assert_eq!(counts, [(0, 2, 2), (8, 0, 0), (0, 2, 2)]);
        assert_eq!((slots[0].xmin, slots[0].xmax, slots[0].ymax), (1, 2, 3));
        assert!(slots[0].overflowed && slots[2].overflowed && !slots[1].overflowed);
        assert!(rtl.take_partial_report().is_empty());
        // Only the two hit words (one per tile, room 1) ever entered the write buffer.
        rtl.step(&CycleInputs::default(), &mut out);
        assert!(out.entered.is_empty());
        assert_eq!((rtl.control.hit_words, rtl.control.record_words), (2, 0));
    }
}
