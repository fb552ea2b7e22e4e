//! Cycle-level replay rate of the O2-like and the 4-board InfiniteReality-like (`ir4`)
//! machines on a synthetic stream of more than 10 million fragments, built in memory (one frame of about 0.49 M fragments, replayed 22
//! times into the same machine). Prints fragments per second of wall time.
//!
//! Run: `cargo bench -p occsim-sim --bench replay`

use occsim_sim::{Arch, MachineModel};
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::Event;

#[path = "support/stream.rs"]
mod stream;

use stream::{frame, thread_cpu_ns, HEIGHT, WIDTH};

const FRAMES: usize = 22;
/// Rounds in which every configuration takes its turn; each keeps its fastest run.
const ROUNDS: usize = 3;

const CONFIGS: [(&str, u32); 5] = [("o2", 1), ("o2", 4), ("o2", 16), ("ir4", 4), ("ir4", 16)];

fn main() {
    let frame = frame(42);
    stream::announce(&frame, FRAMES);
    println!("fastest of {ROUNDS} interleaved rounds");
    let archs: Vec<Arch> = CONFIGS
        .iter()
        .map(|&(name, engines)| {
            let mut arch = Arch::builtin(name).expect("built-in architecture");
            arch.set(&format!("engines={engines}")).expect("engines");
            arch
        })
        .collect();
    let mut jobs: Vec<_> = archs
        .iter()
        .map(|arch| {
            let frame = &frame;
            move || replay(arch, frame)
        })
        .collect();
    let figures = fastest_of_rounds(ROUNDS, 0.0, &mut jobs);
    for ((name, engines), figure) in CONFIGS.iter().zip(figures) {
        let (report, cpu_seconds) = &figure.output;
        let seconds = figure.seconds;
        let fragments = report.summary.fragments as f64;
        println!(
            "{name:<4} engines {engines:>2}: {:.1} M fragments/s wall ({:.3} s), {:.1} M fragments/s on-CPU (last run), {} cycles, {:.3} fragments/cycle, latency p50 {} p95 {}",
            fragments / seconds / 1e6,
            seconds,
            fragments / cpu_seconds / 1e6,
            report.summary.cycles,
            report.summary.fragments_per_cycle,
            latency_figure(report.summary.latency_p50_cycles),
            latency_figure(report.summary.latency_p95_cycles)
        );
    }
}

/// A latency figure, `-` for none (a run without a query).
fn latency_figure(cycles: Option<u64>) -> String {
    cycles.map_or("-".to_string(), |cycles| cycles.to_string())
}

/// Replay `FRAMES` copies of `frame` on `arch`: the report and the run's on-CPU seconds.
fn replay(arch: &Arch, frame: &[Event]) -> (occsim_sim::Report, f64) {
    let mut machine = MachineModel::new(arch, WIDTH, HEIGHT).expect("machine");
    let start = std::time::Instant::now();
    let cpu_start = thread_cpu_ns();
    for _ in 0..FRAMES {
        for event in frame {
            machine
                .event(event)
                .expect("replay matches the golden model");
        }
    }
    let report = machine.finish().expect("report");
    let cpu_seconds = match (cpu_start, thread_cpu_ns()) {
        (Some(a), Some(b)) => (b - a) as f64 / 1e9,
        _ => start.elapsed().as_secs_f64(),
    };
    (report, cpu_seconds)
}
