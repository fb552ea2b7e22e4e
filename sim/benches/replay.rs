//! Cycle-level replay rate of the O2-like and the 4-board InfiniteReality-like (`ir4`)
//! machines on a synthetic stream of more than 10 million fragments, built in memory (one frame of about 0.49 M fragments, replayed 22
//! times into the same machine). Prints fragments per second of wall time.
//!
//! Run: `cargo bench -p occsim-sim --bench replay`

use occsim_sim::{Arch, MachineModel};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{DepthFunc, Event, Fragment, QueryMode, QuerySpec, Rect};
use std::time::Instant;

const WIDTH: u32 = 640;
const HEIGHT: u32 = 480;
const FRAMES: usize = 22;

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
    for (name, engines) in [("o2", 1), ("o2", 4), ("o2", 16), ("ir4", 4), ("ir4", 16)] {
        measure(name, engines, &frame);
    }
}

/// Replay `FRAMES` copies of `frame` on the built-in `name` with `engines` engines and print
/// the rate.
fn measure(name: &str, engines: u32, frame: &[Event]) {
    let mut arch = Arch::builtin(name).expect("built-in architecture");
    arch.set(&format!("engines={engines}")).expect("engines");
    let mut machine = MachineModel::new(&arch, WIDTH, HEIGHT).expect("machine");
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
    let fragments = report.summary.fragments as f64;
    println!(
        "{name:<4} engines {engines:>2}: {:.1} M fragments/s wall ({:.3} s), {:.1} M fragments/s on-CPU, {} cycles, {:.3} fragments/cycle, latency p50 {} p95 {}",
        fragments / seconds / 1e6,
        seconds,
        fragments / cpu_seconds / 1e6,
        report.summary.cycles,
        report.summary.fragments_per_cycle,
        report.summary.latency_p50_cycles,
        report.summary.latency_p95_cycles
    );
}
