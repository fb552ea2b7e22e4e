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
//!
//! Quiet cycles (a simulation shortcut, not hardware): with an empty port and no grant, a
//! cycle in which no latch would change anything but the tile step (a test step short of
//! done whose comparators all miss the fragment; drain or idle while OccU Control can
//! write nothing) is counted ahead by [`OccuRtl::quiet_cycles`] and jumped by
//! [`OccuRtl::skip_quiet_cycles`], leaving the registers ticking would leave.

use crate::bits::{bits_for, mask};
use crate::occlusion_engine::{
    EngineWires, FragmentWires, OcclusionEngine, TileSlot, HIT_COUNT_BITS,
};
use crate::occu_control::{ControlWires, OccuControl, RecordBank, Word};
use crate::tile_locator::TileLocator;

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
    /// Engines whose entries in `engines` and `available` the last eval wrote; the
    /// entries after them hold idle wires already.
    written: usize,
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
    /// Engines holding tiles of the open query: round-robin dealing gives tiles to engines
    /// `0..holding`, so the others test nothing, queue no word and latch nothing, and eval
    /// and latch visit only these (a shortcut of the model, not hardware, like `loads`).
    holding: usize,
    /// Which tiles may hold a pixel, for [`Self::quiet_cycles`] (a shortcut of the model,
    /// not hardware: no register or wire depends on it), and whether queries build it.
    locator: TileLocator,
    use_locator: bool,
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
            holding: 0,
            locator: TileLocator::default(),
            use_locator: true,
            partial_report: Vec::new(),
            wires: Wires::default(),
            busy_cycles: 0,
            stall_cycles: 0,
        }
    }

    pub fn params(&self) -> OccuParams {
        self.params
    }

    /// Whether the queries loaded from now on build a tile locator for the quiet-cycle
    /// search (on by default); off, every engine's slots are scanned, as before the
    /// locator: what the `rtl` benchmark compares. Either way the same cycles are quiet.
    pub fn set_tile_locator(&mut self, on: bool) {
        self.use_locator = on;
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
        self.holding = self.engines.len().min(tiles.len());
        // Only a multi-step search gains from the locator (one step is the accept cycle).
        if service > 1 && self.use_locator {
            self.locator.build(&tiles);
        } else {
            self.locator.clear();
        }
        debug_assert!(self.engines[self.holding..]
            .iter()
            .all(|e| e.tile_count() == 0));
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
        self.holding = 0;
        self.locator.clear();
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

    /// How many cycles from the current one on, at most `limit`, would latch nothing but
    /// the tile step, given an empty fragment port and no grant in any of them (the
    /// caller's promise). Such a cycle is one in which OccU Control stays still
    /// ([`OccuControl::still_without_grants`]) while the sequencer idles, waits in drain
    /// (the fragment's words offered to a full write buffer), or tests a step short of the
    /// done step whose comparators all miss the fragment.
    pub fn quiet_cycles(&self, limit: u64) -> u64 {
        // In drain the engines offer the fragment's words still queued (else it had left).
        let draining = self.state == DRAIN;
        if !self.control.still_without_grants(draining) {
            return 0;
        }
        match self.state {
            TEST => self.missing_test_steps(limit),
            _ => limit,
        }
    }

    /// Test steps from the current one on, at most `limit`, before the done step and before
    /// the first step in which an engine's comparators hold the fragment.
    fn missing_test_steps(&self, limit: u64) -> u64 {
        let before_done = self.service - 1;
        let mut end = (self.step as u64 + limit).min(before_done as u64) as u32;
        if self.query_open && self.locator.is_built() {
            end = self.first_located_holding_step(self.step..end);
        } else if self.query_open {
            // Each engine searches only up to the earliest hit found so far.
            let all = self.params.all_tiles_one_cycle;
            for engine in &self.engines[..self.holding] {
                end = engine.first_holding_step(self.step..end, all, self.fragment);
            }
        }
        end.saturating_sub(self.step) as u64
    }

    /// The first of `steps` in which an engine's comparators hold the fragment (`steps.end`
    /// if none), by the locator's candidates: tile `t` is engine `t mod E`'s slot `t / E`,
    /// tested at step `t / E`, so the first holding tile from `steps.start * E` on gives
    /// the first holding step. Equals every engine's [`OcclusionEngine::first_holding_step`]
    /// (one step a slot).
    fn first_located_holding_step(&self, steps: std::ops::Range<u32>) -> u32 {
        let engines = self.params.engines as u64;
        let f = self.fragment;
        let from = steps.start as u64 * engines;
        let until = steps.end as u64 * engines;
        for t in self.locator.candidates(f.x, f.y, from, until) {
            let slot = &self.engines[(t % engines) as usize].slots[(t / engines) as usize];
            if slot.contains(f.x, f.y) {
                return (t / engines) as u32;
            }
        }
        steps.end
    }

    /// Jump over `n` cycles [`Self::quiet_cycles`] found quiet: the tile step advances as
    /// `n` latches would advance it, and the statistics count the cycles as they would.
    pub fn skip_quiet_cycles(&mut self, n: u64) {
        debug_assert_eq!(self.quiet_cycles(n), n, "only quiet cycles are skipped");
        match self.state {
            TEST => {
                let steps = self.step..self.step + n as u32;
                self.busy_cycles += n;
                if self.query_open {
                    let all = self.params.all_tiles_one_cycle;
                    for engine in &mut self.engines[..self.holding] {
                        engine.busy_cycles += engine.testing_steps(steps.clone(), all);
                    }
                }
                self.step = steps.end;
            }
            DRAIN => {
                self.stall_cycles += n;
                if self.query_open {
                    for engine in &mut self.engines[..self.holding] {
                        engine.stall_cycles += n;
                    }
                }
            }
            _ => {}
        }
        self.cycle += n;
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
        // Engines holding no tile test nothing and offer no word (their queues fill only
        // from their slots): idle their entries, unless they are idle already.
        if wires.written > self.holding {
            wires.engines[self.holding..wires.written].fill(EngineWires::default());
            wires.available[self.holding..wires.written].fill(0);
        }
        wires.written = self.holding;
        let mut offered = 0u64;
        for (e, engine) in self.engines[..self.holding].iter().enumerate() {
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
            for engine in &mut self.engines[..self.holding] {
                engine.latch(u.step, self.params.all_tiles_one_cycle, u.fragment);
            }
        }
        self.control
            .latch(&wires.control, &mut self.engines, &mut outputs.entered);
        self.busy_cycles += u.testing as u64;
        if self.state == DRAIN {
            self.stall_cycles += 1;
            if self.query_open {
                for engine in &mut self.engines[..self.holding] {
                    engine.stall_cycles += 1;
                }
            }
        }
        if self.query_open {
            let holding = self.engines[..self.holding].iter_mut();
            for (engine, w) in holding.zip(&wires.engines) {
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

    /// SplitMix64: a seeded generator (the crate has no dependency to borrow one from).
    struct Rng(u64);

    impl Rng {
        fn below(&mut self, n: u64) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            (z ^ (z >> 31)) % n
        }
    }

    /// Every register and statistic of the two units agree (all but their wire scratch).
    fn assert_same_registers(a: &OccuRtl, b: &OccuRtl) {
        let cycle = a.cycle;
        assert_eq!(a.engines, b.engines, "cycle {cycle}");
        assert_eq!(a.control, b.control, "cycle {cycle}");
        let unit = |u: &OccuRtl| {
            let counters = (u.cycle, u.state, u.step, u.query_open, u.service);
            (counters, u.fragment, u.busy_cycles, u.stall_cycles)
        };
        assert_eq!(unit(a), unit(b), "cycle {cycle}");
        assert_eq!(a.partial_report, b.partial_report, "cycle {cycle}");
    }

    /// A unit and its memory port: a word entering in cycle `t` is granted 0 to 2 cycles
    /// after `t + 1` or the previous grant, whichever is later (several may share a cycle).
    struct Bench {
        rtl: OccuRtl,
        grants: std::collections::VecDeque<u64>,
        last_grant: u64,
        port: Rng,
        out: CycleOutputs,
    }

    impl Bench {
        fn new(params: OccuParams, seed: u64) -> Bench {
            Bench {
                rtl: OccuRtl::new(params),
                grants: Default::default(),
                last_grant: 0,
                port: Rng(seed),
                out: CycleOutputs::default(),
            }
        }

        fn tick(&mut self, fragment: FragmentPort) {
            let t = self.rtl.cycle;
            let mut grants = 0;
            while self.grants.front() == Some(&t) {
                self.grants.pop_front();
                grants += 1;
            }
            self.rtl
                .step(&CycleInputs { fragment, grants }, &mut self.out);
            for _ in 0..self.out.entered.len() {
                self.last_grant = (t + 1).max(self.last_grant) + self.port.below(3);
                self.grants.push_back(self.last_grant);
            }
        }
    }

    /// Cycles skipped as quiet, by the state they were skipped in.
    #[derive(Default)]
    struct Skipped([u64; 3]);

    /// One move of `fast`, in lockstep with `slow`, which only ever ticks: a jump over the
    /// quiet cycles before `limit` and the next grant (each of which `slow` ticks, and
    /// none of which may take, release or write anything), else one tick of both with
    /// `port`. Then every register must agree. Returns whether the fragment left.
    fn lockstep(
        slow: &mut Bench,
        fast: &mut Bench,
        port: FragmentPort,
        limit: u64,
        skipped: &mut Skipped,
    ) -> bool {
        let now = fast.rtl.cycle;
        let until = limit.min(fast.grants.front().copied().unwrap_or(u64::MAX));
        let quiet = if port.valid {
            0
        } else {
            fast.rtl.quiet_cycles(until.saturating_sub(now))
        };
        let left = if quiet > 0 {
            skipped.0[fast.rtl.state as usize] += quiet;
            fast.rtl.skip_quiet_cycles(quiet);
            for _ in 0..quiet {
                slow.tick(port);
                let out = &slow.out;
                assert!(!out.accepted && !out.left && out.entered.is_empty());
            }
            false
        } else {
            slow.tick(port);
            fast.tick(port);
            assert_eq!(slow.out, fast.out);
            fast.out.left
        };
        assert_same_registers(&slow.rtl, &fast.rtl);
        left
    }

    fn random_params(rng: &mut Rng) -> OccuParams {
        OccuParams {
            engines: 1 + rng.below(6) as u32,
            counter_bits: 1 + rng.below(8) as u32,
            write_buffer_words: 1 + rng.below(12) as u32,
            all_tiles_one_cycle: rng.below(6) == 0,
            results: if rng.below(2) == 0 {
                ResultPath::Records
            } else {
                ResultPath::PartialReport
            },
        }
    }

    /// Overlapping tiles, some empty, over a 16 by 16 corner the fragments fall around; or,
    /// one query in four, a grid of 2 by 3 cells over it with a tile that wraps past 2^32
    /// among them (where the tile locator serves the quiet-cycle search).
    fn random_query(rng: &mut Rng) -> QueryConfig {
        let tiles = if rng.below(4) == 0 {
            let mut cells: Vec<TileRect> = (0..6)
                .flat_map(|row| {
                    (0..8).map(move |column| TileRect {
                        x: column * 2,
                        y: row * 3,
                        width: 2,
                        height: 3,
                    })
                })
                .collect();
            let wrapping = TileRect {
                x: u32::MAX - 1,
                y: rng.below(16) as u32,
                width: 4,
                height: 2,
            };
            cells.insert(rng.below(cells.len() as u64) as usize, wrapping);
            cells
        } else {
            (0..1 + rng.below(24))
                .map(|_| TileRect {
                    x: rng.below(16) as u32,
                    y: rng.below(16) as u32,
                    width: rng.below(9) as u32,
                    height: rng.below(9) as u32,
                })
                .collect()
        };
        QueryConfig {
            tiles,
            verbose: rng.below(2) == 0,
            hit_room: rng.below(4) as u32,
        }
    }

    /// The bridge's way of driving the unit, with and without skipping quiet cycles.
    fn run_lockstep(seed: u64, skipped: &mut Skipped) {
        let mut rng = Rng(seed);
        let params = random_params(&mut rng);
        let (mut slow, mut fast) = (Bench::new(params, seed), Bench::new(params, seed));
        let idle = FragmentPort::default();
        for _ in 0..4 {
            let config = random_query(&mut rng);
            slow.rtl.load_query(&config);
            fast.rtl.load_query(&config);
            for _ in 0..rng.below(40) {
                let ready = fast.rtl.cycle + rng.below(6);
                while fast.rtl.cycle < ready {
                    lockstep(&mut slow, &mut fast, idle, ready, skipped);
                }
                let fragment = FragmentPort {
                    valid: true,
                    x: rng.below(20) as u16,
                    y: rng.below(20) as u16,
                    z: rng.below(1 << 24) as u32,
                    pass: rng.below(4) != 0,
                };
                let mut left = lockstep(&mut slow, &mut fast, fragment, 0, skipped);
                assert!(fast.out.accepted);
                while !left {
                    left = lockstep(&mut slow, &mut fast, idle, u64::MAX, skipped);
                }
            }
            let (verbose, room) = (config.verbose, config.hit_room);
            assert!(slow.rtl.end_token(verbose, room) && fast.rtl.end_token(verbose, room));
            let reports = (
                slow.rtl.take_partial_report(),
                fast.rtl.take_partial_report(),
            );
            assert_eq!(reports.0, reports.1);
        }
        while !(fast.rtl.quiescent() && fast.grants.is_empty()) {
            lockstep(&mut slow, &mut fast, idle, u64::MAX, skipped);
        }
    }

    #[test]
    fn skipped_quiet_cycles_latch_what_ticking_them_one_by_one_latches() {
        let mut skipped = Skipped::default();
        for seed in 0..400 {
            run_lockstep(seed, &mut skipped);
        }
        // Every kind of quiet stretch came up: idle behind a full buffer, testing, drain.
        assert!(
            skipped.0.iter().all(|&cycles| cycles > 0),
            "{:?}",
            skipped.0
        );
    }
}
