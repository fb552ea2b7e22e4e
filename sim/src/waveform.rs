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

use occsim_rtl::bits::bits_for;
use occsim_rtl::occlusion_unit::{Wires, MAX_TILES};
use occsim_rtl::vcd::{SignalId, VarKind, VcdWriter};
use occsim_rtl::OccuRtl;
use std::io::Write;
use std::ops::Range;

/// Where and what to dump.
pub struct WaveformOptions {
    /// The VCD's destination (buffer it: every change is one small write).
    pub out: Box<dyn Write + Send>,
    /// Cycles to dump, half-open.
    pub window: Range<u64>,
}

struct EngineSignals {
    testing: SignalId,
    slot: SignalId,
    inside: SignalId,
    hits: SignalId,
    words: SignalId,
    queue: SignalId,
    tiles: SignalId,
    x0: SignalId,
    y0: SignalId,
    width: SignalId,
    height: SignalId,
    phc: SignalId,
    nohc: SignalId,
    xmin: SignalId,
    xmax: SignalId,
    ymin: SignalId,
    ymax: SignalId,
    zmin: SignalId,
    zmax: SignalId,
    hits_sent: SignalId,
    overflowed: SignalId,
}

struct UnitSignals {
    state: SignalId,
    step: SignalId,
    service: SignalId,
    query_open: SignalId,
    accepting: SignalId,
    testing: SignalId,
    done: SignalId,
    leave: SignalId,
    x: SignalId,
    y: SignalId,
    z: SignalId,
    pass: SignalId,
}

struct ControlSignals {
    occupancy: SignalId,
    full: SignalId,
    empty: SignalId,
    grants: SignalId,
    room: SignalId,
    record_words: SignalId,
    hit_words: SignalId,
    pointer: SignalId,
    banks: SignalId,
    bank_tile: SignalId,
    bank_word: SignalId,
    overflows: SignalId,
}

pub struct Waveform {
    vcd: VcdWriter<Box<dyn Write + Send>>,
    window: Range<u64>,
    period_ps: u64,
    unit: UnitSignals,
    engines: Vec<EngineSignals>,
    control: ControlSignals,
}

/// The clock period in whole picoseconds.
pub fn period_ps(clock_mhz: f64) -> u64 {
    ((1e6 / clock_mhz).round() as u64).max(1)
}

impl Waveform {
    pub fn new(options: WaveformOptions, rtl: &OccuRtl, clock_mhz: f64) -> Waveform {
        use VarKind::{Reg, Wire};
        let mut vcd = VcdWriter::new(options.out, "occsim-rtl");
        let params = rtl.params();
        let tile_bits = bits_for(MAX_TILES as u64);
        let step_bits = rtl.step_bits();
        vcd.scope("occu");
        let unit = UnitSignals {
            state: vcd.var(Reg, "state", 2),
            step: vcd.var(Reg, "tile_step", step_bits),
            service: vcd.var(Reg, "service_cycles", tile_bits),
            query_open: vcd.var(Reg, "query_open", 1),
            accepting: vcd.var(Wire, "accept", 1),
            testing: vcd.var(Wire, "testing", 1),
            done: vcd.var(Wire, "done", 1),
            leave: vcd.var(Wire, "leave", 1),
            x: vcd.var(Wire, "fragment_x", 16),
            y: vcd.var(Wire, "fragment_y", 16),
            z: vcd.var(Wire, "fragment_z", 24),
            pass: vcd.var(Wire, "fragment_pass", 1),
        };
        let counter = params.counter_bits;
        let engines = (0..params.engines)
            .map(|e| {
                vcd.scope(&format!("engine_{e}"));
                let s = EngineSignals {
                    testing: vcd.var(Wire, "testing", 1),
                    slot: vcd.var(Wire, "slot", step_bits),
                    inside: vcd.var(Wire, "inside", tile_bits),
                    hits: vcd.var(Wire, "hits", tile_bits),
                    words: vcd.var(Wire, "hit_words", tile_bits),
                    queue: vcd.var(Reg, "hit_queue_level", tile_bits),
                    tiles: vcd.var(Reg, "tiles", tile_bits),
                    x0: vcd.var(Reg, "x0", 32),
                    y0: vcd.var(Reg, "y0", 32),
                    width: vcd.var(Reg, "width", 32),
                    height: vcd.var(Reg, "height", 32),
                    phc: vcd.var(Reg, "phc", counter),
                    nohc: vcd.var(Reg, "nohc", counter),
                    xmin: vcd.var(Reg, "xmin", 32),
                    xmax: vcd.var(Reg, "xmax", 32),
                    ymin: vcd.var(Reg, "ymin", 32),
                    ymax: vcd.var(Reg, "ymax", 32),
                    zmin: vcd.var(Reg, "zmin", 32),
                    zmax: vcd.var(Reg, "zmax", 32),
                    hits_sent: vcd.var(Reg, "hits_sent", 25),
                    overflowed: vcd.var(Reg, "overflowed", 1),
                };
                vcd.upscope();
                s
            })
            .collect();
        vcd.scope("control");
        let occupancy_bits = rtl.control.occupancy_bits();
        let control = ControlSignals {
            occupancy: vcd.var(Reg, "buffer_level", occupancy_bits),
            full: vcd.var(Wire, "full", 1),
            empty: vcd.var(Wire, "empty", 1),
            grants: vcd.var(Wire, "grants", occupancy_bits),
            room: vcd.var(Wire, "room", occupancy_bits + 1),
            record_words: vcd.var(Wire, "record_words_in", occupancy_bits + 1),
            hit_words: vcd.var(Wire, "hit_words_in", occupancy_bits + 1),
            pointer: vcd.var(Reg, "arbiter_pointer", rtl.control.pointer_bits()),
            banks: vcd.var(Reg, "record_banks", 8),
            bank_tile: vcd.var(Reg, "record_tile", tile_bits),
            bank_word: vcd.var(Reg, "record_word", 4),
            overflows: vcd.var(Reg, "overflowed_buffers", tile_bits),
        };
        vcd.upscope();
        vcd.upscope();
        vcd.end_definitions();
        Waveform {
            vcd,
            window: options.window,
            period_ps: period_ps(clock_mhz),
            unit,
            engines,
            control,
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
        let (u, w) = (&self.unit, &wires.unit);
        vcd.change(u.state, rtl.state as u64);
        vcd.change(u.step, rtl.step as u64);
        vcd.change(u.service, rtl.service as u64);
        vcd.change(u.query_open, rtl.query_open as u64);
        vcd.change(u.accepting, w.accepting as u64);
        vcd.change(u.testing, w.testing as u64);
        vcd.change(u.done, w.done as u64);
        vcd.change(u.leave, w.leave as u64);
        vcd.change(u.x, w.fragment.x as u64);
        vcd.change(u.y, w.fragment.y as u64);
        vcd.change(u.z, w.fragment.z as u64);
        vcd.change(u.pass, w.fragment.pass as u64);
        for ((s, engine), ew) in self.engines.iter().zip(&rtl.engines).zip(&wires.engines) {
            vcd.change(s.testing, ew.testing as u64);
            vcd.change(s.slot, ew.slot as u64);
            vcd.change(s.inside, ew.inside as u64);
            vcd.change(s.hits, ew.hits as u64);
            vcd.change(s.words, ew.words as u64);
            vcd.change(s.queue, engine.queue.len() as u64);
            vcd.change(s.tiles, engine.tile_count() as u64);
            if let Some(slot) = engine.slots.get(ew.slot as usize) {
                vcd.change(s.x0, slot.x0 as u64);
                vcd.change(s.y0, slot.y0 as u64);
                vcd.change(s.width, slot.width as u64);
                vcd.change(s.height, slot.height as u64);
                vcd.change(s.phc, slot.phc);
                vcd.change(s.nohc, slot.nohc);
                vcd.change(s.xmin, slot.xmin as u64);
                vcd.change(s.xmax, slot.xmax as u64);
                vcd.change(s.ymin, slot.ymin as u64);
                vcd.change(s.ymax, slot.ymax as u64);
                vcd.change(s.zmin, slot.zmin as u64);
                vcd.change(s.zmax, slot.zmax as u64);
                vcd.change(s.hits_sent, slot.hits_sent as u64);
                vcd.change(s.overflowed, slot.overflowed as u64);
            }
        }
        let (c, cw, control) = (&self.control, &wires.control, &rtl.control);
        vcd.change(c.occupancy, control.fifo.len() as u64);
        vcd.change(c.full, cw.full as u64);
        vcd.change(c.empty, cw.empty as u64);
        vcd.change(c.grants, cw.grants as u64);
        vcd.change(c.room, cw.room as u64);
        vcd.change(c.record_words, cw.record_words as u64);
        vcd.change(c.hit_words, cw.picks.len() as u64);
        vcd.change(c.pointer, control.pointer as u64);
        vcd.change(c.banks, control.banks.len() as u64);
        let (tile, word) = control
            .banks
            .front()
            .map_or((0, 0), |b| (b.tile_counter(), b.word_counter()));
        vcd.change(c.bank_tile, tile as u64);
        vcd.change(c.bank_word, word as u64);
        vcd.change(c.overflows, control.last_bank_overflows as u64);
    }

    /// Close the dump at the window's end or `last_cycle`, whichever is first.
    pub fn finish(mut self, last_cycle: u64) -> std::io::Result<()> {
        let end = self.window.end.min(last_cycle.max(self.window.start));
        self.vcd.end_at(end * self.period_ps);
        self.vcd.finish().map(|_| ())
    }
}
