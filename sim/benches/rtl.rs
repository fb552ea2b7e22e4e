//! The `rtl` fidelity's cost: the O2-like machine with its OccU at `cycle` fidelity, at
//! `rtl` fidelity, and at `rtl` dumping a VCD of the whole run and of a tenth of it, and an
//! FST of the whole run (into sinks that discard them, so disk speed is not measured; the
//! bytes are counted; the FST's sink seeks in a counted length), at 1, 4
//! and 16 engines, on a synthetic stream of about 1.5 M fragments (the replay benchmark's
//! frame, three times); then the InfiniteReality-like `ir4` (320 Image Engines, each unit
//! the RTL) at `cycle` and `rtl`. Prints fragments per second (wall time, the fastest of
//! five runs, the configurations taking turns: the kernel's per-thread CPU time moves at
//! scheduler ticks, too coarse for a 40 ms cycle-level run) and the ratios. Last, the
//! Occlusion Unit's RTL alone on a lazy-grid-like query of 400 tiles, with the tile locator
//! answering the quiet-cycle search and with every slot scanned (what the locator saves).
//!
//! Run: `cargo bench -p occsim-sim --bench rtl`

use occsim_rtl::{
    CycleInputs, CycleOutputs, FragmentPort, OccuParams, OccuRtl, QueryConfig, ResultPath, TileRect,
};
use occsim_sim::{Arch, MachineBuilder, OccuModel, WaveformOptions};
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::Event;
use std::io::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

#[path = "support/stream.rs"]
mod stream;

use stream::{frame, HEIGHT, WIDTH};

const FRAMES: usize = 3;
/// Runs of each configuration, interleaved; the fastest counts (single runs on a shared
/// machine vary by a third).
const REPEATS: usize = 5;

/// A sink that counts the bytes it is given.
struct Counting(Arc<AtomicU64>);

impl Write for Counting {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.fetch_add(bytes.len() as u64, Ordering::Relaxed);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A seekable sink that keeps no bytes: it counts the file's length (the furthest byte
/// written) into the shared counter at every write.
struct CountingSeek {
    length: Arc<AtomicU64>,
    position: u64,
}

impl Write for CountingSeek {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.position += bytes.len() as u64;
        self.length.fetch_max(self.position, Ordering::Relaxed);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl std::io::Seek for CountingSeek {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        let length = self.length.load(Ordering::Relaxed);
        self.position = match to {
            std::io::SeekFrom::Start(at) => at,
            std::io::SeekFrom::End(by) => length.saturating_add_signed(by),
            std::io::SeekFrom::Current(by) => self.position.saturating_add_signed(by),
        };
        Ok(self.position)
    }
}

/// How one configuration's OccU model is made, once per run.
type Maker<'a> = &'a dyn Fn() -> OccuModel;

/// Per configuration, the fastest of `REPEATS` interleaved rounds of replays with the OccU
/// model it makes (`occsim_traces::rounds`, the machine's construction included):
/// (fragments per second, report).
fn fastest(arch: &Arch, frame: &[Event], makers: &[Maker]) -> Vec<(f64, occsim_sim::Report)> {
    let mut jobs: Vec<_> = makers
        .iter()
        .map(|make| move || run(arch, frame, make()).1)
        .collect();
    fastest_of_rounds(REPEATS, 0.0, &mut jobs)
        .into_iter()
        .map(|figure| {
            let fragments = figure.output.summary.fragments as f64;
            (fragments / figure.seconds, figure.output)
        })
        .collect()
}

/// The rtl model dumping `window` as VCD into a sink that counts its bytes into `bytes`.
fn dumping(
    window: std::ops::Range<u64>,
    bytes: &Arc<AtomicU64>,
    max_query_tiles: u64,
) -> OccuModel {
    bytes.store(0, Ordering::Relaxed);
    OccuModel::Rtl {
        waveform: Some(WaveformOptions {
            vcd: Some(Box::new(Counting(bytes.clone()))),
            fst: None,
            window,
            max_query_tiles,
        }),
    }
}

/// The rtl model dumping the whole run as FST into a sink that counts its length.
fn dumping_fst(bytes: &Arc<AtomicU64>, max_query_tiles: u64) -> OccuModel {
    bytes.store(0, Ordering::Relaxed);
    OccuModel::Rtl {
        waveform: Some(WaveformOptions {
            vcd: None,
            fst: Some(Box::new(CountingSeek {
                length: bytes.clone(),
                position: 0,
            })),
            window: 0..u64::MAX,
            max_query_tiles,
        }),
    }
}

/// Replay the stream; returns (fragments per second, report).
fn run(arch: &Arch, frame: &[Event], occu: OccuModel) -> (f64, occsim_sim::Report) {
    let mut machine = MachineBuilder::new(arch)
        .occu(occu)
        .build(WIDTH, HEIGHT)
        .expect("machine");
    let start = Instant::now();
    for _ in 0..FRAMES {
        for event in frame {
            machine
                .event(event)
                .expect("replay matches the golden model");
        }
    }
    let report = machine.finish().expect("report");
    let seconds = start.elapsed().as_secs_f64();
    (report.summary.fragments as f64 / seconds, report)
}

/// A brief query of a 20 by 20 grid of 32 by 24 cells over the 640x480 viewport (400 tiles, as a
/// lazy-grid walk's queries hold hundreds), and fragments across the viewport in rows.
fn grid_query() -> (QueryConfig, Vec<FragmentPort>) {
    let (columns, rows) = (20, 20);
    let (cell_width, cell_height) = (WIDTH / columns, HEIGHT / rows);
    let tiles = (0..rows)
        .flat_map(|row| {
            (0..columns).map(move |column| TileRect {
                x: column * cell_width,
                y: row * cell_height,
                width: cell_width,
                height: cell_height,
            })
        })
        .collect();
    let fragments = (0..HEIGHT as u16)
        .step_by(3)
        .flat_map(|y| {
            (0..WIDTH as u16).map(move |x| FragmentPort {
                valid: true,
                x,
                y,
                z: (x as u32 * 7 + y as u32) & 0xFF_FFFF,
                pass: (x + y) % 4 != 0,
            })
        })
        .collect();
    let config = QueryConfig {
        tiles,
        verbose: false,
        hit_room: 0,
    };
    (config, fragments)
}

/// The unit's RTL at `engines` engines through `fragments` under `config`, driven as the
/// bridge drives it (offer a fragment, skip the quiet cycles, tick until it leaves), with the
/// tile locator on or off; returns the cycle it ends in and its busy cycles.
fn occu_alone(
    engines: u32,
    locator: bool,
    config: &QueryConfig,
    fragments: &[FragmentPort],
) -> (u64, u64) {
    let mut rtl = OccuRtl::new(OccuParams {
        engines,
        counter_bits: 32,
        write_buffer_words: 16,
        all_tiles_one_cycle: false,
        results: ResultPath::Records,
    });
    rtl.set_tile_locator(locator);
    rtl.load_query(config);
    let mut out = CycleOutputs::default();
    for &fragment in fragments {
        rtl.step(
            &CycleInputs {
                fragment,
                grants: 0,
            },
            &mut out,
        );
        while !out.left {
            let quiet = rtl.quiet_cycles(1 << 32);
            if quiet > 0 {
                rtl.skip_quiet_cycles(quiet);
            }
            rtl.step(&CycleInputs::default(), &mut out);
        }
    }
    (rtl.cycle, rtl.busy_cycles)
}

fn locator_saving() {
    let (config, fragments) = grid_query();
    for engines in [1, 4, 16] {
        let mut jobs = [true, false].map(|locator| {
            let (config, fragments) = (&config, &fragments);
            move || occu_alone(engines, locator, config, fragments)
        });
        let figures = fastest_of_rounds(REPEATS, 0.2, &mut jobs);
        assert_eq!(
            figures[0].output, figures[1].output,
            "the locator changed a cycle"
        );
        let rate = |seconds: f64| fragments.len() as f64 / seconds / 1e6;
        println!(
            "OccU RTL alone, 400-tile query, engines {engines:>2}: with the tile locator {:.1} M fragments/s, every slot scanned {:.1} M/s ({:.2}x), {} cycles",
            rate(figures[0].seconds),
            rate(figures[1].seconds),
            figures[1].seconds / figures[0].seconds,
            figures[0].output.0,
        );
    }
}

fn main() {
    let frame = frame(42);
    stream::announce(&frame, FRAMES);
    let max_query_tiles = frame
        .iter()
        .map(|event| match event {
            Event::QueryBegin(spec) => spec.tiles.len() as u64,
            _ => 0,
        })
        .max()
        .unwrap_or(0);
    for engines in [1, 4, 16] {
        let mut arch = Arch::builtin("o2").expect("built-in o2");
        arch.set(&format!("engines={engines}")).expect("engines");
        let cycles = run(&arch, &frame, OccuModel::Cycle).1.summary.cycles;
        // A window of a tenth of the run in its middle: what a user dumping the cycles
        // around an event pays.
        let window = cycles * 45 / 100..cycles * 55 / 100;
        let (whole_bytes, window_bytes, fst_bytes) =
            (Arc::default(), Arc::default(), Arc::default());
        let results = fastest(
            &arch,
            &frame,
            &[
                &|| OccuModel::Cycle,
                &|| OccuModel::Rtl { waveform: None },
                &|| dumping(0..u64::MAX, &whole_bytes, max_query_tiles),
                &|| dumping(window.clone(), &window_bytes, max_query_tiles),
                &|| dumping_fst(&fst_bytes, max_query_tiles),
            ],
        );
        let [cycle, rtl, vcd, windowed, fst] = [0, 1, 2, 3, 4].map(|i| results[i].0);
        assert_eq!(results[0].1, results[1].1, "rtl and cycle reports differ");
        let bytes = whole_bytes.load(Ordering::Relaxed);
        let fst_bytes = fst_bytes.load(Ordering::Relaxed);
        println!(
            "engines {engines:>2}: cycle {:.2} M fragments/s, rtl {:.2} M/s ({:.1}x slower), rtl+vcd {:.2} M/s ({:.2}x the rtl run's time; {} MB of VCD over {cycles} cycles, {:.1} B/cycle), a tenth of the run dumped {:.2}x",
            cycle / 1e6,
            rtl / 1e6,
            cycle / rtl,
            vcd / 1e6,
            rtl / vcd,
            bytes / 1_000_000,
            bytes as f64 / cycles as f64,
            rtl / windowed,
        );
        println!(
            "            rtl+fst {:.2} M/s ({:.2}x the rtl run's time, {:.2}x the VCD's; {:.1} MB of FST, {:.2} B/cycle, {:.1}x smaller than the VCD)",
            fst / 1e6,
            rtl / fst,
            vcd / fst,
            fst_bytes as f64 / 1e6,
            fst_bytes as f64 / cycles as f64,
            bytes as f64 / fst_bytes as f64,
        );
    }
    let arch = Arch::builtin("ir4").expect("built-in ir4");
    let results = fastest(
        &arch,
        &frame,
        &[&|| OccuModel::Cycle, &|| OccuModel::Rtl { waveform: None }],
    );
    let (cycle, rtl) = (results[0].0, results[1].0);
    assert_eq!(
        results[0].1, results[1].1,
        "ir4 rtl and cycle reports differ"
    );
    println!(
        "ir4 (320 Image Engines): cycle {:.2} M fragments/s, rtl {:.2} M/s ({:.1}x slower) over {} cycles",
        cycle / 1e6,
        rtl / 1e6,
        cycle / rtl,
        results[0].1.summary.cycles
    );
    locator_saving();
}
