//! What fast-forward saves ([`occsim_sim::effects`]): the cycle level on the demo (27.3 M
//! fragments, encoded as a trace in memory and decoded by every run, as `occsim replay`
//! does from a file) with `--effects auto` (fast-forward on) against `--effects all` (the
//! exact reference, fragment by fragment), on the O2 and on ir4. Prints each run's seconds,
//! fragments per second, the ratio and the fragments fast-forwarded; the reports are
//! checked equal.
//!
//! Run: `cargo bench -p occsim-sim --bench fast_forward`

use occsim_sim::effects::EffectsChoice;
use occsim_sim::replay::{replay, ReplayOptions};
use occsim_sim::{Arch, Fidelity, LevelResult};
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::trace::TraceReader;

#[path = "support/demo.rs"]
mod demo;

use demo::demo_trace;

/// Rounds in which every run takes its turn; each keeps its fastest, so a slow spell of the
/// shared machine falls on all of them alike.
const ROUNDS: usize = 3;

fn cycle_level(trace: &[u8], arch: &Arch, effects: EffectsChoice) -> LevelResult {
    let options = ReplayOptions {
        effects,
        ..ReplayOptions::at(Fidelity::Cycle)
    };
    replay(|| Ok(TraceReader::new(trace)?), arch, options).expect("replays")
}

fn main() {
    let trace = demo_trace();
    let names = ["o2", "ir4"];
    let archs: Vec<Arch> = names
        .iter()
        .map(|name| Arch::builtin(name).expect("built-in architecture"))
        .collect();
    let choices = [EffectsChoice::All, EffectsChoice::Auto];
    let mut jobs: Vec<_> = archs
        .iter()
        .flat_map(|arch| choices.map(|choice| (arch, choice)))
        .map(|(arch, choice)| {
            let trace = &trace;
            move || cycle_level(trace, arch, choice)
        })
        .collect();
    println!("demo, cycle level, fastest of {ROUNDS} interleaved rounds");
    let figures = fastest_of_rounds(ROUNDS, 0.0, &mut jobs);
    for (name, pair) in names.iter().zip(figures.chunks(2)) {
        let (all, auto) = (&pair[0], &pair[1]);
        assert_eq!(
            all.output.report, auto.output.report,
            "fast-forward changed the report"
        );
        let fragments = all.output.fragments as f64;
        let fast_forwarded = auto.output.fast_forwarded_fragments.unwrap_or(0);
        println!(
            "{:<4} --effects all {:.3} s ({:.1} M fragments/s), auto {:.3} s ({:.1} M fragments/s): {:.2}x; fast-forwarded {} of {} fragments ({:.1}%)",
            name,
            all.seconds,
            fragments / all.seconds / 1e6,
            auto.seconds,
            fragments / auto.seconds / 1e6,
            all.seconds / auto.seconds,
            fast_forwarded,
            all.output.fragments,
            100.0 * fast_forwarded as f64 / fragments
        );
    }
}
