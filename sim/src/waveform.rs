//! Waveforms of the `rtl` fidelity: the unit sequencer's, every engine's and OccU
//! Control's registers and wires as a VCD file, for a window of cycles.
//!
//! The window `start..end` is half-open: cycles `start` to `end - 1` are dumped, each at
//! time `cycle * period` with `period` the clock period rounded to whole picoseconds
//! (66.67 MHz: 14999 ps); the file ends with a timestamp at the window's end (or the run's
//! last cycle). Values are those during the cycle: registers before the clock edge that
//! ends it, wires as evaluated in it. Per engine, the tile registers shown are those of the
//! slot tested in the cycle (the slot multiplexer's output). Scopes: `occu` (sequencer),
//! `occu.engine_E`, `occu.control`.
//!
//! Cost: the signals are declared in blocks (the sequencer; the fragment it shows; each
//! engine's wires and counters followed by its shown slot's registers; OccU Control) whose
//! values are handed to the writer as arrays, each compared in one branch-free loop
//! ([`VcdWriter::change_block`]). Whole blocks are skipped where the model says nothing
//! changed since the last dumped cycle (inside the window that is the previous cycle): an
//! engine's slot registers while the slot shown and the engine's `slots_version` (bumped
//! by every latch that touched a slot, every load and unload) are those of the last dump;
//! the fragment wires outside accept cycles; OccU Control while it stays quiet (empty
//! buffer, no record bank, grant or pick). What remains is formatting the changes: on the
//! `rtl` benchmark's whole-run dumps 38-109 bytes per cycle (a timestamp and 3-9 lines), and
//! comparing the signals that may have changed (the sequencer's 8 and, when its shown slot
//! moves, an engine's 21, every cycle). `cargo bench -p occsim-sim --bench rtl` prints the
//! dump's cost against the `rtl` run without it (about 2x; see the README).

use occsim_rtl::bits::bits_for;
use occsim_rtl::occlusion_engine::{EngineWires, OcclusionEngine, TileSlot};
use occsim_rtl::occlusion_unit::{Wires, MAX_TILES};
use occsim_rtl::vcd::{SignalId, VarKind, VcdWriter};
use occsim_rtl::OccuRtl;
use std::io::Write;
use std::ops::Range;

use VarKind::{Reg, Wire};

/// Where and what to dump.
pub struct WaveformOptions {
    /// The VCD's destination (buffer it: every change is one small write).
    pub out: Box<dyn Write + Send>,
    /// Cycles to dump, half-open.
    pub window: Range<u64>,
}

/// A block's signals: kind, name, width in bits; in declaration order, which is the order
/// of the block's values.
type Declarations<const N: usize> = [(VarKind, &'static str, u32); N];

/// Widths that depend on the unit's parameters, in bits.
struct Widths {
    tiles: u32,
    step: u32,
    counter: u32,
    occupancy: u32,
    pointer: u32,
}

const UNIT_SIGNALS: usize = 8;

fn unit_declarations(w: &Widths) -> Declarations<UNIT_SIGNALS> {
    [
        (Reg, "state", 2),
        (Reg, "tile_step", w.step),
        (Reg, "service_cycles", w.tiles),
        (Reg, "query_open", 1),
        (Wire, "accept", 1),
        (Wire, "testing", 1),
        (Wire, "done", 1),
        (Wire, "leave", 1),
    ]
}

fn unit_values(rtl: &OccuRtl, wires: &Wires) -> [u64; UNIT_SIGNALS] {
    let w = &wires.unit;
    [
        rtl.state as u64,
        rtl.step as u64,
        rtl.service as u64,
        rtl.query_open as u64,
        w.accepting as u64,
        w.testing as u64,
        w.done as u64,
        w.leave as u64,
    ]
}

/// The fragment the sequencer shows (declared right after the unit's other signals).
const FRAGMENT_SIGNALS: usize = 4;

fn fragment_declarations() -> Declarations<FRAGMENT_SIGNALS> {
    [
        (Wire, "fragment_x", 16),
        (Wire, "fragment_y", 16),
        (Wire, "fragment_z", 24),
        (Wire, "fragment_pass", 1),
    ]
}

fn fragment_values(wires: &Wires) -> [u64; FRAGMENT_SIGNALS] {
    let f = &wires.unit.fragment;
    [f.x as u64, f.y as u64, f.z as u64, f.pass as u64]
}

const ENGINE_SIGNALS: usize = 7;

fn engine_declarations(w: &Widths) -> Declarations<ENGINE_SIGNALS> {
    [
        (Wire, "testing", 1),
        (Wire, "slot", w.step),
        (Wire, "inside", w.tiles),
        (Wire, "hits", w.tiles),
        (Wire, "hit_words", w.tiles),
        (Reg, "hit_queue_level", w.tiles),
        (Reg, "tiles", w.tiles),
    ]
}

/// The engine's values into `out` (in place: a block is built where it is compared).
fn engine_values(engine: &OcclusionEngine, w: &EngineWires, out: &mut [u64; ENGINE_SIGNALS]) {
    *out = [
        w.testing as u64,
        w.slot as u64,
        w.inside as u64,
        w.hits as u64,
        w.words as u64,
        engine.queue.len() as u64,
        engine.tile_count() as u64,
    ];
}

const SLOT_SIGNALS: usize = 14;

fn slot_declarations(w: &Widths) -> Declarations<SLOT_SIGNALS> {
    [
        (Reg, "x0", 32),
        (Reg, "y0", 32),
        (Reg, "width", 32),
        (Reg, "height", 32),
        (Reg, "phc", w.counter),
        (Reg, "nohc", w.counter),
        (Reg, "xmin", 32),
        (Reg, "xmax", 32),
        (Reg, "ymin", 32),
        (Reg, "ymax", 32),
        (Reg, "zmin", 32),
        (Reg, "zmax", 32),
        (Reg, "hits_sent", 25),
        (Reg, "overflowed", 1),
    ]
}

fn slot_values(slot: &TileSlot, out: &mut [u64; SLOT_SIGNALS]) {
    *out = [
        slot.x0 as u64,
        slot.y0 as u64,
        slot.width as u64,
        slot.height as u64,
        slot.phc,
        slot.nohc,
        slot.xmin as u64,
        slot.xmax as u64,
        slot.ymin as u64,
        slot.ymax as u64,
        slot.zmin as u64,
        slot.zmax as u64,
        slot.hits_sent as u64,
        slot.overflowed as u64,
    ];
}

const CONTROL_SIGNALS: usize = 12;

fn control_declarations(w: &Widths) -> Declarations<CONTROL_SIGNALS> {
    [
        (Reg, "buffer_level", w.occupancy),
        (Wire, "full", 1),
        (Wire, "empty", 1),
        (Wire, "grants", w.occupancy),
        (Wire, "room", w.occupancy + 1),
        (Wire, "record_words_in", w.occupancy + 1),
        (Wire, "hit_words_in", w.occupancy + 1),
        (Reg, "arbiter_pointer", w.pointer),
        (Reg, "record_banks", 8),
        (Reg, "record_tile", w.tiles),
        (Reg, "record_word", 4),
        (Reg, "overflowed_buffers", w.tiles),
    ]
}

fn control_values(rtl: &OccuRtl, wires: &Wires) -> [u64; CONTROL_SIGNALS] {
    let (control, w) = (&rtl.control, &wires.control);
    let (tile, word) = control
        .banks
        .front()
        .map_or((0, 0), |b| (b.tile_counter(), b.word_counter()));
    [
        control.fifo.len() as u64,
        w.full as u64,
        w.empty as u64,
        w.grants as u64,
        w.room as u64,
        w.record_words as u64,
        w.picks.len() as u64,
        control.pointer as u64,
        control.banks.len() as u64,
        tile as u64,
        word as u64,
        control.last_bank_overflows as u64,
    ]
}

/// Declare a block's signals; returns the first one's id (the others follow it).
fn declare<W: Write, const N: usize>(
    vcd: &mut VcdWriter<W>,
    declarations: Declarations<N>,
) -> SignalId {
    let ids: Vec<SignalId> = declarations
        .iter()
        .map(|&(kind, name, width)| vcd.var(kind, name, width))
        .collect();
    debug_assert!(ids.windows(2).all(|p| p[1].0 == p[0].0 + 1));
    ids[0]
}

struct EngineProbe {
    /// The engine's first signal; its slot's signals follow.
    signals: SignalId,
    /// The slot shown in the last dumped cycle and the engine's `slots_version` then.
    dumped_slot: Option<(u32, u64)>,
}

pub struct Waveform {
    vcd: VcdWriter<Box<dyn Write + Send>>,
    window: Range<u64>,
    period_ps: u64,
    unit: SignalId,
    fragment: SignalId,
    engines: Vec<EngineProbe>,
    control: SignalId,
    /// A cycle was dumped (the skips below compare with the last dumped cycle, which is
    /// the previous evaluated one: inside the window every evaluated cycle is dumped).
    dumped: bool,
    /// OccU Control was quiet in the last dumped cycle.
    control_was_quiet: bool,
}

/// The clock period in whole picoseconds.
pub fn period_ps(clock_mhz: f64) -> u64 {
    ((1e6 / clock_mhz).round() as u64).max(1)
}

impl Waveform {
    pub fn new(options: WaveformOptions, rtl: &OccuRtl, clock_mhz: f64) -> Waveform {
        let mut vcd = VcdWriter::new(options.out, "occsim-rtl");
        let params = rtl.params();
        let widths = Widths {
            tiles: bits_for(MAX_TILES as u64),
            step: rtl.step_bits(),
            counter: params.counter_bits,
            occupancy: rtl.control.occupancy_bits(),
            pointer: rtl.control.pointer_bits(),
        };
        vcd.scope("occu");
        let unit = declare(&mut vcd, unit_declarations(&widths));
        let fragment = declare(&mut vcd, fragment_declarations());
        let engines = (0..params.engines)
            .map(|e| {
                vcd.scope(&format!("engine_{e}"));
                let signals = declare(&mut vcd, engine_declarations(&widths));
                let slot_signals = declare(&mut vcd, slot_declarations(&widths));
                assert_eq!(slot_signals.0, signals.0 + ENGINE_SIGNALS);
                vcd.upscope();
                EngineProbe {
                    signals,
                    dumped_slot: None,
                }
            })
            .collect();
        vcd.scope("control");
        let control = declare(&mut vcd, control_declarations(&widths));
        vcd.upscope();
        vcd.upscope();
        vcd.end_definitions();
        Waveform {
            vcd,
            window: options.window,
            period_ps: period_ps(clock_mhz),
            unit,
            fragment,
            engines,
            control,
            dumped: false,
            control_was_quiet: false,
        }
    }

    #[inline]
    pub fn covers(&self, cycle: u64) -> bool {
        self.window.contains(&cycle)
    }

    pub fn start(&self) -> u64 {
        self.window.start
    }

    /// Record cycle `cycle`: the registers (not yet latched) and the cycle's wires.
    pub fn dump(&mut self, cycle: u64, rtl: &OccuRtl, wires: &Wires) {
        let vcd = &mut self.vcd;
        vcd.set_time(cycle * self.period_ps);
        vcd.change_block(self.unit, &unit_values(rtl, wires));
        // The fragment wires show the port in an accept cycle and the fragment register
        // (latched from the port then) otherwise: they change only in accept cycles.
        if wires.unit.accepting || !self.dumped {
            vcd.change_block(self.fragment, &fragment_values(wires));
        }
        for ((probe, engine), w) in self
            .engines
            .iter_mut()
            .zip(&rtl.engines)
            .zip(&wires.engines)
        {
            // An engine without tiles shows no slot: its slot signals keep their values.
            // A slot shown in the last dumped cycle, unchanged since, needs no compare.
            let slot = engine
                .slots
                .get(w.slot as usize)
                .filter(|_| probe.dumped_slot != Some((w.slot, engine.slots_version)));
            match slot {
                None => {
                    let mut values = [0; ENGINE_SIGNALS];
                    engine_values(engine, w, &mut values);
                    vcd.change_block(probe.signals, &values);
                }
                Some(slot) => {
                    // The slot's signals follow the engine's: one block of both.
                    let mut values = [0; ENGINE_SIGNALS + SLOT_SIGNALS];
                    let (head, rest) = values.split_at_mut(ENGINE_SIGNALS);
                    engine_values(engine, w, head.try_into().expect("the engine's part"));
                    slot_values(slot, rest.try_into().expect("the slot's part"));
                    vcd.change_block(probe.signals, &values);
                    probe.dumped_slot = Some((w.slot, engine.slots_version));
                }
            }
        }
        // Quiet OccU Control: empty write buffer, no record bank, no grant, no pick. Then
        // every one of its signals has its idle value (level 0, empty, room = capacity, no
        // words in, no bank counters), and the arbiter pointer and the overflow count,
        // which change only with a pick or a finishing bank, are those of the last dumped
        // cycle if that was quiet too: nothing to compare.
        let control = &rtl.control;
        let quiet = control.fifo.is_empty()
            && control.banks.is_empty()
            && wires.control.grants == 0
            && wires.control.picks.is_empty();
        if !(quiet && self.control_was_quiet) {
            vcd.change_block(self.control, &control_values(rtl, wires));
        }
        self.control_was_quiet = quiet;
        self.dumped = true;
    }

    /// Close the dump at the window's end or `last_cycle`, whichever is first.
    pub fn finish(mut self, last_cycle: u64) -> std::io::Result<()> {
        let end = self.window.end.min(last_cycle.max(self.window.start));
        self.vcd.end_at(end * self.period_ps);
        self.vcd.finish().map(|_| ())
    }
}
