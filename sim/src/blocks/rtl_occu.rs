//! The `rtl` fidelity of an Occlusion Unit and its OccU Control (the O2's one, or one
//! InfiniteReality Image Engine's): the `occsim-rtl` model clocked cycle by cycle, bridged
//! to the event-timestamp rest of the machine.
//!
//! Bridge rules:
//! - a fragment ready in `ready` is offered on the RTL's fragment port from cycle `ready`
//!   on; the RTL's clock runs until it takes the fragment (`o_i`) and until the fragment
//!   leaves (`c_i`), so the next fragment finds the clock at `c_i + 1`;
//! - every word entering the RTL's write buffer in cycle `t` asks the in-order memory port
//!   from `t + 1` (after the previous OccU word's grant); its grant cycle is fed back as the
//!   RTL's `grants` input in that cycle;
//! - the port's request order puts a query's records before the next fragment's depth
//!   write, but the RTL emits them while it already counts later fragments. So at the end
//!   token a copy of OccU Control is clocked ahead over the record phase (records have
//!   priority over hits, so nothing the engines do changes when record words enter): its
//!   words are claimed on the port then, and the real RTL, entering the same words later
//!   cycle by cycle, is checked against those entry cycles;
//! - cycles are skipped in bulk only when no grant falls in them and the RTL proves them
//!   quiet: quiescent (sequencer idle, no record bank: no register changes), or
//!   [`OccuRtl::quiet_cycles`] (only the tile step changes: test steps whose comparators
//!   all miss, drain or idle behind a full write buffer). With a waveform, the latter are
//!   skipped only outside its window, and the window's first cycle and one idle cycle
//!   after any activity are always ticked, so the dump sees every change;
//! - the memory image: hit words are stored per tile as they enter, record words are
//!   decoded into the tile's result, the terminator cuts the hit list at its entry.
//!
//! At an Image Engine of the InfiniteReality ([`ResultPath::PartialReport`]) OccU Control
//! writes hit words only: the end token passes the idle unit between cycles when the
//! bridge handles it ([`RtlOccu::partial_report`]; nothing in the unit depends on the
//! token's cycle, which the Image Engine's rule computes) and the tile registers, read off
//! the partial-report port, go to the merge network with the hit words stored so far.

use crate::arch::{IrArch, O2Arch, OccuArch, OCCU_WORD_BITS};
use crate::blocks::memory_port::{MemoryPort, PortClient};
use crate::blocks::occlusion_unit::OccuStats;
use crate::blocks::waveform::{Waveform, WaveformOptions};
use crate::SimError;
use occsim_rtl::occlusion_unit::Wires;
use occsim_rtl::occu_control::{ControlWires, WordKind};
use occsim_rtl::{
    CycleInputs, CycleOutputs, FragmentPort, OccuParams, OccuRtl, QueryConfig, ResultPath, TileRect,
};
use occsim_traces::query::BRIEF_RECORD_ENTRIES;
use occsim_traces::{Fragment, HitList, QueryMode, QuerySpec, TileResult};
use std::collections::VecDeque;

pub struct RtlOccu {
    rtl: OccuRtl,
    outputs: CycleOutputs,
    wires: Wires,
    /// Grant cycles of the words in the RTL's write buffer, head first.
    grants: VecDeque<u64>,
    /// Record words claimed ahead: (entry cycle, grant cycle), in order.
    claimed_ahead: VecDeque<(u64, u64)>,
    /// Port side: the last OccU grant, words written, distinct grant cycles.
    last_grant: u64,
    words_written: u64,
    grant_cycles: u64,
    /// The open query's hit entries per tile, as written to memory.
    hits: Vec<HitList>,
    /// Hits each tile's result lists (`QuerySpec::listed_hits_per_tile`).
    hit_list_cap: usize,
    /// First cycle the unit is free (`c_last + 1`).
    free: u64,
    /// The last tick changed nothing and left only idle wires.
    last_tick_idle: bool,
    waveform: Option<Waveform>,
}

/// The rtl model's parameters from the Occlusion Unit's (the same group on both machines).
fn rtl_params(occu: &OccuArch, results: ResultPath) -> OccuParams {
    OccuParams {
        engines: occu.engines as u32,
        counter_bits: occu.counter_bits,
        write_buffer_words: occu.occu_write_buffer_words as u32,
        all_tiles_one_cycle: occu.all_tiles_one_cycle,
        results,
    }
}

impl RtlOccu {
    /// The O2's unit: records go to memory.
    pub fn new(arch: &O2Arch, waveform: Option<WaveformOptions>) -> RtlOccu {
        let params = rtl_params(&arch.occu, ResultPath::Records);
        RtlOccu::with_params(params, arch.clock_mhz, waveform)
    }

    /// One InfiniteReality Image Engine's unit: partial reports go to the merge network.
    pub fn for_image_engine(arch: &IrArch, waveform: Option<WaveformOptions>) -> RtlOccu {
        let params = rtl_params(&arch.occu, ResultPath::PartialReport);
        RtlOccu::with_params(params, arch.clock_mhz, waveform)
    }

    /// A unit of `params`, clocked at `clock_mhz` MHz (the waveform's time scale).
    fn with_params(
        params: OccuParams,
        clock_mhz: f64,
        waveform: Option<WaveformOptions>,
    ) -> RtlOccu {
        let rtl = OccuRtl::new(params);
        let waveform = waveform.map(|options| Waveform::new(options, &rtl, clock_mhz));
        RtlOccu {
            rtl,
            outputs: CycleOutputs::default(),
            wires: Wires::default(),
            grants: VecDeque::new(),
            claimed_ahead: VecDeque::new(),
            last_grant: 0,
            words_written: 0,
            grant_cycles: 0,
            hits: Vec::new(),
            hit_list_cap: 0,
            free: 0,
            last_tick_idle: false,
            waveform,
        }
    }

    /// Ask the port for one OccU word that entered the buffer in `enter`.
    fn claim(&mut self, enter: u64, port: &mut MemoryPort) -> u64 {
        let grant = port.claim(
            (enter + 1).max(self.last_grant),
            OCCU_WORD_BITS,
            PortClient::OccuControl,
        );
        if grant != self.last_grant || self.words_written == 0 {
            self.grant_cycles += 1;
        }
        self.last_grant = grant;
        self.words_written += 1;
        grant
    }

    /// Clock the RTL one cycle with `fragment` on its port.
    #[inline]
    fn tick(&mut self, fragment: FragmentPort, port: &mut MemoryPort) {
        let t = self.rtl.cycle;
        let mut grants = 0;
        while self.grants.front() == Some(&t) {
            self.grants.pop_front();
            grants += 1;
        }
        let quiescent = self.rtl.quiescent();
        let inputs = CycleInputs { fragment, grants };
        self.rtl.eval(&inputs, &mut self.wires);
        if let Some(waveform) = self.waveform.as_mut().filter(|w| w.covers(t)) {
            waveform.dump(t, &self.rtl, &self.wires);
        }
        self.rtl.latch(&self.wires, &mut self.outputs);
        self.last_tick_idle = quiescent && !fragment.valid && grants == 0;
        for i in 0..self.outputs.entered.len() {
            let word = self.outputs.entered[i];
            let grant = match word.kind {
                WordKind::Hit => {
                    let hits = &mut self.hits[word.tile as usize];
                    debug_assert_eq!(word.offset, BRIEF_RECORD_ENTRIES + hits.len() as u32);
                    hits.push(
                        (word.data as u16, (word.data >> 16) as u16),
                        self.hit_list_cap,
                    );
                    self.claim(t, port)
                }
                WordKind::Record | WordKind::Terminator => {
                    let (enter, grant) = self
                        .claimed_ahead
                        .pop_front()
                        .expect("every record word was claimed at its end token");
                    assert_eq!(enter, t, "record word entered off its look-ahead cycle");
                    grant
                }
            };
            self.grants.push_back(grant);
        }
    }

    /// Jump over the quiet cycles ahead ([`OccuRtl::quiet_cycles`]) before cycle `target`,
    /// the next grant and any cycle the waveform dumps (its window shows every step).
    /// Returns whether the clock moved.
    fn skip_quiet(&mut self, target: u64) -> bool {
        let now = self.rtl.cycle;
        let mut until = target.min(self.grants.front().copied().unwrap_or(u64::MAX));
        if let Some(waveform) = &self.waveform {
            if waveform.covers(now) {
                return false;
            } else if now < waveform.start() {
                until = until.min(waveform.start());
            }
        }
        let quiet = self.rtl.quiet_cycles(until.saturating_sub(now));
        if quiet == 0 {
            return false;
        }
        self.rtl.skip_quiet_cycles(quiet);
        // Ticking is always exact: let the next one inside a window dump.
        self.last_tick_idle = false;
        true
    }

    /// Run the clock with an empty fragment port up to cycle `target`.
    fn advance_to(&mut self, target: u64, port: &mut MemoryPort) {
        while self.rtl.cycle < target {
            if !self.rtl.quiescent() && self.skip_quiet(target) {
                continue;
            }
            if self.rtl.quiescent() {
                let mut until = target.min(self.grants.front().copied().unwrap_or(u64::MAX));
                if let Some(waveform) = &self.waveform {
                    if waveform.covers(self.rtl.cycle) && !self.last_tick_idle {
                        until = self.rtl.cycle;
                    } else if self.rtl.cycle < waveform.start() {
                        until = until.min(waveform.start());
                    }
                }
                if until > self.rtl.cycle {
                    self.rtl.skip_to(until);
                    continue;
                }
            }
            self.tick(FragmentPort::default(), port);
        }
    }

    pub fn begin(&mut self, spec: &QuerySpec) {
        let tiles = spec
            .tiles
            .iter()
            .map(|t| TileRect {
                x: t.x,
                y: t.y,
                width: t.width,
                height: t.height,
            })
            .collect();
        self.rtl.load_query(&QueryConfig {
            tiles,
            verbose: spec.mode == QueryMode::Verbose,
            hit_room: spec.buffer_entries.saturating_sub(BRIEF_RECORD_ENTRIES),
        });
        self.hits.clear();
        self.hits.resize(spec.tiles.len(), HitList::default());
        self.hit_list_cap = spec.listed_hits_per_tile();
    }

    #[inline]
    pub fn fragment(
        &mut self,
        fragment: Fragment,
        passed: bool,
        ready: u64,
        port: &mut MemoryPort,
    ) -> u64 {
        self.advance_to(ready, port);
        let offered = FragmentPort {
            valid: true,
            x: fragment.x,
            y: fragment.y,
            z: fragment.z,
            pass: passed,
        };
        let start = self.rtl.cycle;
        self.tick(offered, port);
        assert!(self.outputs.accepted, "the unit is idle between fragments");
        while !self.outputs.left {
            // The leaving cycle is never quiet: the skip stops short of it.
            self.skip_quiet(u64::MAX);
            self.tick(FragmentPort::default(), port);
        }
        self.free = self.rtl.cycle;
        start
    }

    pub fn free_cycle(&self) -> u64 {
        self.free
    }

    pub fn end(
        &mut self,
        spec: &QuerySpec,
        through_depth: u64,
        port: &mut MemoryPort,
    ) -> (Vec<TileResult>, u64, u32) {
        let verbose = spec.mode == QueryMode::Verbose;
        let room = spec.buffer_entries.saturating_sub(BRIEF_RECORD_ENTRIES);
        self.advance_to(through_depth + 1, port);
        while !self.rtl.end_token(verbose, room) {
            self.tick(FragmentPort::default(), port);
        }
        let bank = self.rtl.control.banks.back().expect("the bank just loaded");
        let mut tiles: Vec<TileResult> = (0..spec.tiles.len())
            .map(|t| TileResult {
                overflowed: bank.overflowed(t),
                ..TileResult::default()
            })
            .collect();
        let (words, overflowed) = self.look_ahead_records(port);
        for word in words {
            let tile = &mut tiles[word.tile as usize];
            match word.offset {
                0 => tile.nohc = word.data,
                1 => tile.phc = word.data,
                2 => tile.xmin = word.data as u32,
                3 => tile.xmax = word.data as u32,
                4 => tile.ymin = word.data as u32,
                5 => tile.ymax = word.data as u32,
                6 => tile.zmin = word.data as u32,
                7 => tile.zmax = word.data as u32,
                entry => {
                    self.hits[word.tile as usize].truncate((entry - BRIEF_RECORD_ENTRIES) as u64)
                }
            }
        }
        for (tile, hits) in tiles.iter_mut().zip(&mut self.hits) {
            tile.hits = std::mem::take(hits);
        }
        (tiles, self.last_grant + 1, overflowed)
    }

    /// The end token of the loaded query (the unit is idle: its last fragment left), at an
    /// Image Engine ([`ResultPath::PartialReport`]): the tiles' partial results, in query
    /// order, with the hit words written so far.
    pub fn partial_report(&mut self) -> Vec<TileResult> {
        // With the partial-report path the token's mode and room feed no record bank.
        let passed = self.rtl.end_token(false, 0);
        assert!(passed, "the unit is idle between fragments");
        let slots = self.rtl.take_partial_report();
        debug_assert_eq!(slots.len(), self.hits.len());
        slots
            .into_iter()
            .zip(self.hits.iter_mut())
            .map(|(slot, hits)| TileResult {
                nohc: slot.nohc,
                phc: slot.phc,
                xmin: slot.xmin,
                xmax: slot.xmax,
                ymin: slot.ymin,
                ymax: slot.ymax,
                zmin: slot.zmin,
                zmax: slot.zmax,
                hits: std::mem::take(hits),
                overflowed: slot.overflowed,
            })
            .collect()
    }

    /// The port grant of the last word written (`None` before any).
    pub fn last_grant(&self) -> Option<u64> {
        (self.words_written > 0).then_some(self.last_grant)
    }

    /// Clock a copy of OccU Control (engines offering nothing) until every record bank has
    /// entered the write buffer; claim the new words on the port. Returns the last bank's
    /// words and its overflow count.
    fn look_ahead_records(&mut self, port: &mut MemoryPort) -> (Vec<occsim_rtl::Word>, u32) {
        let mut control = self.rtl.control.clone();
        let mut grants = self.grants.clone();
        let nothing = vec![0; self.rtl.engines.len()];
        let mut wires = ControlWires::default();
        let mut entered = Vec::new();
        let mut words = Vec::new();
        // Words of earlier banks not yet entered in the real RTL were claimed before.
        let earlier = self.claimed_ahead.len();
        let mut already = 0;
        let mut t = self.rtl.cycle;
        while !control.banks.is_empty() {
            let mut granted = 0;
            while grants.front() == Some(&t) {
                grants.pop_front();
                granted += 1;
            }
            if granted == 0 && control.still_without_grants(false) {
                // A full write buffer: nothing enters before its next grant.
                t = *grants
                    .front()
                    .expect("a full write buffer's words await grants");
                continue;
            }
            control.eval(granted, &nothing, &mut wires);
            entered.clear();
            control.latch(&wires, &mut [], &mut entered);
            for &word in &entered {
                let grant = if already < earlier {
                    already += 1;
                    self.claimed_ahead[already - 1].1
                } else {
                    let grant = self.claim(t, port);
                    self.claimed_ahead.push_back((t, grant));
                    words.push(word);
                    grant
                };
                grants.push_back(grant);
            }
            t += 1;
        }
        (words, control.last_bank_overflows)
    }

    /// Drain the RTL (so its waveform shows the last records leave) and report.
    pub fn finish(&mut self) -> Result<OccuStats, SimError> {
        let mut scratch = MemoryPort::new(OCCU_WORD_BITS);
        while !(self.rtl.quiescent() && self.grants.is_empty()) {
            // No word is claimed here: records were claimed ahead and no query is open.
            if !self.skip_quiet(u64::MAX) {
                self.tick(FragmentPort::default(), &mut scratch);
            }
        }
        // One idle cycle more, so that the waveform shows the state the run ends in.
        if self
            .waveform
            .as_ref()
            .is_some_and(|w| w.covers(self.rtl.cycle))
            && !self.last_tick_idle
        {
            self.tick(FragmentPort::default(), &mut scratch);
        }
        if let Some(waveform) = self.waveform.take() {
            waveform
                .finish(self.rtl.cycle)
                .map_err(|e| SimError::Waveform(e.to_string()))?;
        }
        Ok(OccuStats {
            busy_cycles: self.rtl.busy_cycles,
            stall_cycles: self.rtl.stall_cycles,
            engines: self
                .rtl
                .engines
                .iter()
                .map(|e| (e.busy_cycles, e.stall_cycles))
                .collect(),
            words_written: self.words_written,
            port_cycles: self.grant_cycles,
        })
    }
}
