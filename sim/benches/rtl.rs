//! The `rtl` fidelity's cost: the O2-like machine with its OccU at `cycle` fidelity, at
//! `rtl` fidelity, and at `rtl` dumping a VCD of the whole run (into a buffered sink that
//! discards it, so disk speed is not measured; the bytes are counted), on a synthetic
//! stream of about 1.5 M fragments (the replay benchmark's frame, three times). Prints
//! fragments per second (on-CPU where Linux tells) and the ratios.
//!
//! Run: `cargo bench -p occsim-sim --bench rtl`

use occsim_sim::{Arch, MachineModel, OccuModel, WaveformOptions};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{DepthFunc, Event, Fragment, QueryMode, QuerySpec, Rect};
use std::io::Write;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Instant;

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;
const FRAMES: usize = 3;

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: u64) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) % n
    }
}

/// Rectangles drawn row by row, as spans leave a rasterizer.
fn rectangle(rng: &mut Rng, max_side: u64, events: &mut Vec<Event>) {
    let w = 4 + rng.below(max_side) as u32;
    let h = 4 + rng.below(max_side) as u32;
    let x0 = rng.below((WIDTH - w) as u64) as u32;
    let y0 = rng.below((HEIGHT - h) as u64) as u32;
    let z = rng.below(1 << 24) as u32;
    events.push(Event::Primitive);
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            events.push(Event::Fragment(Fragment {
                x: x as u16,
                y: y as u16,
                z,
            }));
        }
    }
}

fn grid(columns: u32, rows: u32) -> Vec<Rect> {
    let (w, h) = (WIDTH / columns, HEIGHT / rows);
    (0..rows)
        .flat_map(|r| (0..columns).map(move |c| Rect::new(c * w, r * h, w, h)))
        .collect()
}

/// One frame: occluders drawn plainly, then samples, brief (16-tile grid) and verbose
/// (4-tile) queries over boxes, with the golden results in the stream.
fn frame(seed: u64) -> Vec<Event> {
    let mut rng = Rng(seed | 1);
    let mut raw = vec![Event::Clear, Event::DepthFunc(DepthFunc::Less)];
    for _ in 0..60 {
        rectangle(&mut rng, 120, &mut raw);
    }
    for q in 0..120u32 {
        let (mode, tiles, buffer_entries) = match q % 3 {
            0 => (QueryMode::Samples, vec![Rect::new(0, 0, WIDTH, HEIGHT)], 8),
            1 => (QueryMode::Brief, grid(4, 4), 8),
            _ => (QueryMode::Verbose, grid(2, 2), 8 + 64),
        };
        raw.push(Event::QueryBegin(QuerySpec {
            id: q,
            mode,
            buffer_entries,
            tiles,
        }));
        for _ in 0..2 {
            rectangle(&mut rng, 60, &mut raw);
        }
        raw.push(Event::QueryEnd);
    }
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    let mut events = Vec::with_capacity(raw.len() + 128);
    for event in raw {
        let result = golden.event(&event);
        events.push(event);
        if let Some(result) = result {
            events.push(Event::QueryResult(result));
        }
    }
    events
}

/// Nanoseconds this thread has run on a CPU (Linux schedstat), so the rate can be read on
/// a machine shared with other work; None elsewhere.
fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

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

/// Replay the stream; returns (fragments per on-CPU second, cycles, report).
fn run(arch: &Arch, frame: &[Event], occu: OccuModel) -> (f64, occsim_sim::Report) {
    let mut machine = MachineModel::with_occu_model(arch, WIDTH, HEIGHT, occu).expect("machine");
    let start = Instant::now();
    let cpu_start = thread_cpu_ns();
    for _ in 0..FRAMES {
        for event in frame {
            machine
                .event(event)
                .expect("replay matches the golden model");
        }
    }
    let report = machine.finish().expect("report");
    let seconds = start.elapsed().as_secs_f64();
    let cpu_seconds = match (cpu_start, thread_cpu_ns()) {
        (Some(a), Some(b)) => (b - a) as f64 / 1e9,
        _ => seconds,
    };
    (report.summary.fragments as f64 / cpu_seconds, report)
}

fn main() {
    let frame = frame(42);
    let per_frame = frame
        .iter()
        .filter(|e| matches!(e, Event::Fragment(_)))
        .count();
    println!(
        "stream: {} fragments ({} frames of {}), {}x{}",
        per_frame * FRAMES,
        FRAMES,
        per_frame,
        WIDTH,
        HEIGHT
    );
    for engines in [1, 4, 16] {
        let mut arch = Arch::builtin("o2").expect("built-in o2");
        arch.set(&format!("engines={engines}")).expect("engines");
        let (cycle, cycle_report) = run(&arch, &frame, OccuModel::Cycle);
        let (rtl, rtl_report) = run(&arch, &frame, OccuModel::Rtl { waveform: None });
        assert_eq!(cycle_report, rtl_report, "rtl and cycle reports differ");
        let bytes = Arc::new(AtomicU64::new(0));
        let out = Box::new(std::io::BufWriter::with_capacity(
            1 << 20,
            Counting(bytes.clone()),
        ));
        let waveform = Some(WaveformOptions {
            out,
            window: 0..u64::MAX,
        });
        let (vcd, _) = run(&arch, &frame, OccuModel::Rtl { waveform });
        println!(
            "engines {engines:>2}: cycle {:.2} M fragments/s, rtl {:.2} M/s ({:.1}x slower), rtl+vcd {:.2} M/s ({:.1}x slower than rtl; {} MB of VCD over {} cycles)",
            cycle / 1e6,
            rtl / 1e6,
            cycle / rtl,
            vcd / 1e6,
            rtl / vcd,
            bytes.load(Ordering::Relaxed) / 1_000_000,
            cycle_report.summary.cycles
        );
    }
}
