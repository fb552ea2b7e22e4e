//! Waveforms of the `rtl` fidelity: the unit sequencer's, every engine's and OccU
//! Control's registers and wires as a VCD file, an FST file or both, for a window of
//! cycles. The signal set, the scopes and the skips below are defined once, here; the
//! change detection is `occsim_rtl::wave`'s writer, and VCD and FST are its two encoders
//! (`occsim_rtl::vcd`, `occsim_rtl::fst`), fed the same changes.
//!
//! The window `start..end` is half-open: cycles `start` to `end - 1` are dumped, each at
//! time `cycle * period` with `period` the clock period rounded to whole picoseconds
//! (66.67 MHz: 14999 ps); the file ends with a timestamp at the window's end (or the run's
//! last cycle). Values are those during the cycle: registers before the clock edge that
//! ends it, wires as evaluated in it. Scopes: `occu` (sequencer; its `step` wire is the
//! slot every engine whose `testing` is high tests), `occu.engine_E` (its wires),
//! `occu.engine_E.slot_J` (the registers of tile slot `J`, which holds the query's tile
//! `J * engines + E`), `occu.control`.
//!
//! Tile slots: each engine's register file is shown slot by slot, as many slots as the
//! query with the most tiles fills ([`WaveformOptions::max_query_tiles`]); a slot's signals
//! change when a load writes its tile and when a latch updates its counters, and hold
//! their values while the engine has no query (its registers went to OccU Control at the
//! end token). Slots past the declared ones are not shown.
//!
//! Cost: the signals are declared in blocks (the sequencer; the fragment it shows; each
//! engine's wires; each tile slot; OccU Control) whose values are handed to the writer as
//! arrays, each compared in one branch-free loop ([`WaveWriter::change_block`]). Blocks are
//! compared only where the model can have changed them since the last dumped cycle (inside
//! the window every evaluated cycle is dumped, and cycles skipped between change nothing):
//! a tile slot only if the last dumped cycle's wires latched it (a tested slot holding the
//! fragment) or the engine loaded or unloaded since (its `loads` count); the fragment wires
//! in accept cycles; OccU Control unless it stays quiet (empty buffer, no record bank,
//! grant or pick). What remains is formatting the changes and comparing the sequencer's
//! and the engines' wires every cycle. `cargo bench -p occsim-sim --bench rtl` prints the
//! dump's cost against the `rtl` run without it (see the README).

use occsim_rtl::bits::bits_for;
use occsim_rtl::fst::FstEncoder;
use occsim_rtl::occlusion_engine::{EngineWires, OcclusionEngine, TileSlot};
use occsim_rtl::occlusion_unit::{Wires, MAX_TILES};
use occsim_rtl::vcd::VcdEncoder;
use occsim_rtl::wave::{SignalId, VarKind, WaveEncoder, WaveWriter};
use occsim_rtl::OccuRtl;
use std::io::{Seek, Write};
use std::ops::Range;

use VarKind::{Reg, Wire};

/// A destination that seeks (an FST's header is rewritten at its end).
pub trait WriteSeek: Write + Seek + Send {}
impl<T: Write + Seek + Send> WriteSeek for T {}

/// The encoders a dump feeds: a VCD, an FST, or both.
type Encoders = (
    Option<VcdEncoder<Box<dyn Write + Send>>>,
    Option<FstEncoder<Box<dyn WriteSeek>>>,
);

/// Where and what to dump.
pub struct WaveformOptions {
    /// The VCD's destination, if one is wanted (the encoder gathers its lines into large
    /// writes).
    pub vcd: Option<Box<dyn Write + Send>>,
    /// The FST's destination, if one is wanted.
    pub fst: Option<Box<dyn WriteSeek>>,
    /// Cycles to dump, half-open.
    pub window: Range<u64>,
    /// The most tiles one query of the run has (a trace's `max_query_tiles`): each engine
    /// shows `ceil(max_query_tiles / engines)` tile slots (at most `MAX_TILES` in all).
    pub max_query_tiles: u64,
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

impl Widths {
    fn of(rtl: &OccuRtl) -> Widths {
        Widths {
            tiles: bits_for(MAX_TILES as u64),
            step: rtl.step_bits(),
            counter: rtl.params().counter_bits,
            occupancy: rtl.control.occupancy_bits(),
            pointer: rtl.control.pointer_bits(),
        }
    }
}

const UNIT_SIGNALS: usize = 9;

fn unit_declarations(w: &Widths) -> Declarations<UNIT_SIGNALS> {
    [
        (Reg, "state", 2),
        (Reg, "tile_step", w.step),
        (Reg, "service_cycles", w.tiles),
        (Reg, "query_open", 1),
        (Wire, "accept", 1),
        (Wire, "testing", 1),
        // The step every engine tests (its slot `step`, or all slots with
        // `all_tiles_one_cycle`): 0 in an accept cycle, else `tile_step`.
        (Wire, "step", w.step),
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
        w.step as u64,
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

const ENGINE_SIGNALS: usize = 6;

fn engine_declarations(w: &Widths) -> Declarations<ENGINE_SIGNALS> {
    [
        (Wire, "testing", 1),
        (Wire, "inside", w.tiles),
        (Wire, "hits", w.tiles),
        (Wire, "hit_words", w.tiles),
        (Reg, "hit_queue_level", w.tiles),
        (Reg, "tiles", w.tiles),
    ]
}

/// No engine's signals pack to this key (it would need 2^21 - 1 slots).
const NO_KEY: (u64, u64) = (u64::MAX, u64::MAX);
/// No engine loads this many queries.
const NOTHING_DUMPED: u64 = u64::MAX;

/// The engine's signals packed into 128 bits (each wire counts at most `MAX_TILES` slots,
/// 17 bits): equal keys, equal values.
#[inline(always)]
fn engine_key(engine: &OcclusionEngine, w: &EngineWires) -> (u64, u64) {
    const { assert!(MAX_TILES < 1 << 21) };
    let wires = w.testing as u64 | (w.inside as u64) << 1 | (w.hits as u64) << 22;
    let counts = engine.queue.len() as u64 | (engine.tile_count() as u64) << 32;
    (wires | (w.words as u64) << 43, counts)
}

/// The engine's values into `out` (in place: a block is built where it is compared).
fn engine_values(engine: &OcclusionEngine, w: &EngineWires, out: &mut [u64; ENGINE_SIGNALS]) {
    *out = [
        w.testing as u64,
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
fn declare<E: WaveEncoder, const N: usize>(
    vcd: &mut WaveWriter<E>,
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
    /// The engine's wires.
    wires: SignalId,
    /// Slot 0's first signal; slot `j`'s are `SLOT_SIGNALS * j` further.
    slots: SignalId,
    /// Slots declared.
    shown_slots: usize,
    /// The engine's signals in the last dumped cycle ([`engine_key`]; `NO_KEY` before).
    dumped_key: (u64, u64),
    /// The engine's `loads` count in the last dumped cycle (`NOTHING_DUMPED` before).
    dumped_loads: u64,
    /// The slots the last dumped cycle latched (tested, holding its fragment).
    latched: Range<usize>,
}

impl EngineProbe {
    /// Slot `j`'s first signal.
    fn slot(&self, j: usize) -> SignalId {
        SignalId(self.slots.0 + SLOT_SIGNALS * j)
    }

    /// Compare the slots that may have changed since the last dumped cycle: those it
    /// latched, or all of them after a load or an unload; at the first dump, every slot
    /// shown (one not loaded yet shows its reset value, 0).
    fn dump_slots<E: WaveEncoder>(&mut self, vcd: &mut WaveWriter<E>, engine: &OcclusionEngine) {
        let slots = if self.dumped_loads == engine.loads {
            self.latched.clone()
        } else {
            0..self.shown_slots
        };
        for j in slots {
            match engine.slots.get(j) {
                Some(slot) => {
                    let mut values = [0; SLOT_SIGNALS];
                    slot_values(slot, &mut values);
                    vcd.change_block(self.slot(j), &values);
                }
                None if self.dumped_loads == NOTHING_DUMPED => {
                    vcd.change_block(self.slot(j), &[0; SLOT_SIGNALS]);
                }
                None => break,
            }
        }
        self.dumped_loads = engine.loads;
    }
}

pub struct Waveform {
    vcd: WaveWriter<Encoders>,
    window: Range<u64>,
    period_ps: u64,
    unit: SignalId,
    fragment: SignalId,
    engines: Vec<EngineProbe>,
    /// Engines test every slot in one cycle (`all_tiles_one_cycle`).
    all_tiles_one_cycle: bool,
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
        const VERSION: &str = "occsim-rtl";
        let encoders = (
            options.vcd.map(|out| VcdEncoder::new(out, VERSION)),
            options.fst.map(|out| FstEncoder::new(out, VERSION)),
        );
        let mut vcd = WaveWriter::with_encoder(encoders);
        let params = rtl.params();
        let widths = Widths::of(rtl);
        let tiles = options.max_query_tiles.min(MAX_TILES as u64) as usize;
        let engines = params.engines as usize;
        vcd.scope("occu");
        let unit = declare(&mut vcd, unit_declarations(&widths));
        let fragment = declare(&mut vcd, fragment_declarations());
        let engines = (0..engines)
            .map(|e| {
                vcd.scope(&format!("engine_{e}"));
                let wires = declare(&mut vcd, engine_declarations(&widths));
                // Engine `e` holds tiles e, e + engines, ...
                let shown_slots = tiles.saturating_sub(e).div_ceil(engines);
                let slots: Vec<SignalId> = (0..shown_slots)
                    .map(|j| {
                        vcd.scope(&format!("slot_{j}"));
                        let first = declare(&mut vcd, slot_declarations(&widths));
                        vcd.upscope();
                        first
                    })
                    .collect();
                vcd.upscope();
                let probe = EngineProbe {
                    wires,
                    slots: slots.first().copied().unwrap_or(SignalId(0)),
                    shown_slots,
                    dumped_key: NO_KEY,
                    dumped_loads: NOTHING_DUMPED,
                    latched: 0..0,
                };
                debug_assert!((0..shown_slots).all(|j| probe.slot(j) == slots[j]));
                probe
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
            all_tiles_one_cycle: params.all_tiles_one_cycle,
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
            // Most engines' wires and counters stay as they were: one packed compare skips
            // the block.
            let key = engine_key(engine, w);
            if probe.dumped_key != key {
                let mut values = [0; ENGINE_SIGNALS];
                engine_values(engine, w, &mut values);
                vcd.change_block(probe.wires, &values);
                probe.dumped_key = key;
            }
            if probe.dumped_loads != engine.loads || !probe.latched.is_empty() {
                probe.dump_slots(vcd, engine);
            }
            if w.inside > 0 {
                let tested = engine.tested(wires.unit.step, self.all_tiles_one_cycle);
                probe.latched = tested.start..tested.end.min(probe.shown_slots);
            } else if !probe.latched.is_empty() {
                probe.latched = 0..0;
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

#[cfg(test)]
mod tests {
    //! The probe against the model itself: the unit is clocked cycle by cycle here and, at
    //! every dumped cycle, each engine's wires and every loaded slot's registers read off
    //! the model must be the values the VCD holds at that time, whatever the probe's skips.
    use super::*;
    use occsim_rtl::{CycleInputs, CycleOutputs, FragmentPort, OccuParams, QueryConfig};
    use occsim_rtl::{ResultPath, TileRect};
    use std::collections::HashMap;
    use std::sync::{Arc, Mutex};

    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(bytes);
            Ok(bytes.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// A seekable shared buffer, for the FST.
    #[derive(Clone, Default)]
    struct SharedSeek(Arc<Mutex<std::io::Cursor<Vec<u8>>>>);

    impl Write for SharedSeek {
        fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().write(bytes)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Seek for SharedSeek {
        fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
            self.0.lock().unwrap().seek(to)
        }
    }

    /// Full signal name (scopes joined by `.`) -> its (time, value) changes, as wellen (the
    /// reader the Surfer viewer is built on) reads the VCD or FST file `file` (an FST's
    /// signals start undefined, `x`, before their first value: such values are left out).
    fn changes(file: &[u8]) -> HashMap<String, Vec<(u64, u64)>> {
        let bytes = std::io::Cursor::new(file.to_vec());
        let mut wave = wellen::simple::read_from_reader(bytes).expect("wellen reads the VCD");
        let hierarchy = wave.hierarchy();
        let vars: Vec<(String, wellen::SignalRef)> = hierarchy
            .iter_vars()
            .map(|v| (v.full_name(hierarchy), v.signal_ref()))
            .collect();
        let refs: Vec<wellen::SignalRef> = vars.iter().map(|v| v.1).collect();
        wave.load_signals(&refs);
        let times = wave.time_table().to_vec();
        vars.into_iter()
            .map(|(name, signal)| {
                let signal = wave.get_signal(signal).expect("a loaded signal");
                let list = signal
                    .iter_changes()
                    .filter_map(|(time, value)| {
                        let bits = value.to_bit_string().expect("a bit vector");
                        let value = u64::from_str_radix(&bits, 2).ok()?;
                        Some((times[time as usize], value))
                    })
                    .collect();
                (name, list)
            })
            .collect()
    }

    /// Per dumped cycle, the model's value of every checked signal (full name, value).
    type Expected = Vec<(u64, Vec<(String, u64)>)>;

    /// The model's value of every signal in one cycle, each named here with the register or
    /// wire it shows, apart from the dumper's own tables (`unit_values`, `engine_values`,
    /// ...): a signal the dumper wires to another register, or two it swaps, fails here.
    fn expected(rtl: &OccuRtl, wires: &Wires, shown_slots: usize) -> Vec<(String, u64)> {
        let (u, f) = (&wires.unit, &wires.unit.fragment);
        let unit = [
            ("state", rtl.state as u64),
            ("tile_step", rtl.step as u64),
            ("service_cycles", rtl.service as u64),
            ("query_open", rtl.query_open as u64),
            ("accept", u.accepting as u64),
            ("testing", u.testing as u64),
            ("step", u.step as u64),
            ("done", u.done as u64),
            ("leave", u.leave as u64),
            ("fragment_x", f.x as u64),
            ("fragment_y", f.y as u64),
            ("fragment_z", f.z as u64),
            ("fragment_pass", f.pass as u64),
        ];
        let mut out: Vec<(String, u64)> = (unit.iter())
            .map(|&(name, value)| (format!("occu.{name}"), value))
            .collect();
        for (e, (engine, w)) in rtl.engines.iter().zip(&wires.engines).enumerate() {
            let signals = [
                ("testing", w.testing as u64),
                ("inside", w.inside as u64),
                ("hits", w.hits as u64),
                ("hit_words", w.words as u64),
                ("hit_queue_level", engine.queue.len() as u64),
                ("tiles", engine.tile_count() as u64),
            ];
            for (name, value) in signals {
                out.push((format!("occu.engine_{e}.{name}"), value));
            }
            for (j, slot) in engine.slots.iter().enumerate().take(shown_slots) {
                let registers = [
                    ("x0", slot.x0 as u64),
                    ("y0", slot.y0 as u64),
                    ("width", slot.width as u64),
                    ("height", slot.height as u64),
                    ("phc", slot.phc),
                    ("nohc", slot.nohc),
                    ("xmin", slot.xmin as u64),
                    ("xmax", slot.xmax as u64),
                    ("ymin", slot.ymin as u64),
                    ("ymax", slot.ymax as u64),
                    ("zmin", slot.zmin as u64),
                    ("zmax", slot.zmax as u64),
                    ("hits_sent", slot.hits_sent as u64),
                    ("overflowed", slot.overflowed as u64),
                ];
                for (name, value) in registers {
                    out.push((format!("occu.engine_{e}.slot_{j}.{name}"), value));
                }
            }
        }
        let (control, w) = (&rtl.control, &wires.control);
        let (tile, word) =
            (control.banks.front()).map_or((0, 0), |b| (b.tile_counter(), b.word_counter()));
        let control = [
            ("buffer_level", control.fifo.len() as u64),
            ("full", w.full as u64),
            ("empty", w.empty as u64),
            ("grants", w.grants as u64),
            ("room", w.room as u64),
            ("record_words_in", w.record_words as u64),
            ("hit_words_in", w.picks.len() as u64),
            ("arbiter_pointer", control.pointer as u64),
            ("record_banks", control.banks.len() as u64),
            ("record_tile", tile as u64),
            ("record_word", word as u64),
            ("overflowed_buffers", control.last_bank_overflows as u64),
        ];
        for (name, value) in control {
            out.push((format!("occu.control.{name}"), value));
        }
        out
    }

    /// Random queries (1 to `max_tiles` tiles of a 16 x 16 area, brief or verbose) of
    /// random fragments on a unit of `params`, clocked cycle by cycle with every word
    /// granted the cycle after it enters; the VCD and the FST of `window` and, per dumped
    /// cycle, the expected values.
    fn run(
        params: OccuParams,
        max_tiles: u64,
        window: Range<u64>,
        seed: u64,
    ) -> (Vec<u8>, Vec<u8>, Expected) {
        let mut rng = occsim_traces::rng::SplitMix64(seed | 1);
        let mut rtl = OccuRtl::new(params);
        let (shared, shared_fst) = (Shared::default(), SharedSeek::default());
        let options = WaveformOptions {
            vcd: Some(Box::new(shared.clone())),
            fst: Some(Box::new(shared_fst.clone())),
            window,
            max_query_tiles: max_tiles,
        };
        let mut waveform = Waveform::new(options, &rtl, 66.67);
        let shown_slots = max_tiles.div_ceil(params.engines as u64) as usize;
        let (mut wires, mut outputs) = (Wires::default(), CycleOutputs::default());
        let mut expected_by_cycle = Vec::new();
        let mut entered_last = 0;
        let mut clock = |rtl: &mut OccuRtl, fragment: FragmentPort| {
            let inputs = CycleInputs {
                fragment,
                grants: std::mem::take(&mut entered_last),
            };
            rtl.eval(&inputs, &mut wires);
            let cycle = rtl.cycle;
            if waveform.covers(cycle) {
                waveform.dump(cycle, rtl, &wires);
                expected_by_cycle.push((cycle, expected(rtl, &wires, shown_slots)));
            }
            rtl.latch(&wires, &mut outputs);
            entered_last = outputs.entered.len() as u32;
            outputs.accepted
        };
        for _ in 0..6 {
            let tiles = (0..1 + rng.below(max_tiles))
                .map(|_| TileRect {
                    x: rng.below(12) as u32,
                    y: rng.below(12) as u32,
                    width: 1 + rng.below(6) as u32,
                    height: 1 + rng.below(6) as u32,
                })
                .collect();
            let verbose = rng.below(2) == 0;
            let hit_room = rng.below(4) as u32;
            rtl.load_query(&QueryConfig {
                tiles,
                verbose,
                hit_room,
            });
            for _ in 0..rng.below(40) {
                let fragment = FragmentPort {
                    valid: true,
                    x: rng.below(16) as u16,
                    y: rng.below(16) as u16,
                    z: rng.below(1 << 24) as u32,
                    pass: rng.below(3) != 0,
                };
                while !clock(&mut rtl, fragment) {}
                for _ in 0..rng.below(3) {
                    clock(&mut rtl, FragmentPort::default());
                }
            }
            while !rtl.end_token(verbose, hit_room) {
                clock(&mut rtl, FragmentPort::default());
            }
            while !rtl.quiescent() {
                clock(&mut rtl, FragmentPort::default());
            }
        }
        let last = rtl.cycle;
        waveform.finish(last).unwrap();
        let vcd = shared.0.lock().unwrap().clone();
        let fst = shared_fst.0.lock().unwrap().get_ref().clone();
        (vcd, fst, expected_by_cycle)
    }

    /// The value `list` holds at `time`, if any.
    fn at(list: &[(u64, u64)], time: u64) -> Option<u64> {
        let at = list.partition_point(|&(t, _)| t <= time);
        at.checked_sub(1).map(|i| list[i].1)
    }

    fn check(params: OccuParams, max_tiles: u64, window: Range<u64>) {
        let period = period_ps(66.67);
        for seed in 0..30 {
            let (vcd, fst, expected) = run(params, max_tiles, window.clone(), seed);
            let (changes, fst_changes) = (changes(&vcd), changes(&fst));
            assert!(!expected.is_empty());
            // Every signal of the VCD is in the FST, with the VCD's value in every dumped
            // cycle.
            assert_eq!(
                changes.len(),
                fst_changes.len(),
                "signal counts, seed {seed}"
            );
            for (name, list) in &changes {
                let fst_list = &fst_changes[name];
                for &(cycle, _) in &expected {
                    let time = cycle * period;
                    assert_eq!(
                        at(fst_list, time),
                        at(list, time),
                        "{name} in the FST at cycle {cycle}, seed {seed}"
                    );
                }
            }
            // Every signal in the file is one the model's values above name, but a slot no
            // query loaded, which holds its reset value.
            let named: std::collections::BTreeSet<&String> = expected
                .iter()
                .flat_map(|(_, v)| v.iter().map(|(n, _)| n))
                .collect();
            for (name, list) in changes.iter().filter(|(n, _)| !named.contains(n)) {
                assert!(
                    name.contains(".slot_"),
                    "{name} is not checked, seed {seed}"
                );
                assert!(list.iter().all(|&(_, v)| v == 0), "{name}: {list:?}");
            }
            for (cycle, values) in expected {
                for (name, value) in values {
                    let list = &changes[&name];
                    let value_then = at(list, cycle * period);
                    assert!(value_then.is_some(), "{name} has no value at cycle {cycle}");
                    assert_eq!(
                        value_then,
                        Some(value),
                        "{name} at cycle {cycle}, seed {seed}"
                    );
                }
            }
        }
    }

    fn params(engines: u32) -> OccuParams {
        OccuParams {
            engines,
            counter_bits: 32,
            write_buffer_words: 6,
            all_tiles_one_cycle: false,
            results: ResultPath::Records,
        }
    }

    #[test]
    fn every_signal_equals_the_model_in_every_dumped_cycle() {
        check(params(1), 5, 0..u64::MAX);
        check(params(3), 9, 0..u64::MAX);
        check(params(4), 4, 0..u64::MAX);
        check(params(3), 9, 40..90);
        let saturating = OccuParams {
            counter_bits: 3,
            ..params(2)
        };
        check(saturating, 6, 0..u64::MAX);
        let all_at_once = OccuParams {
            all_tiles_one_cycle: true,
            ..params(2)
        };
        check(all_at_once, 7, 0..u64::MAX);
    }
}
