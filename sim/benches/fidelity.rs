//! What each fidelity level costs on one trace of about 1.5 million fragments (three frames
//! of the replay benchmark's scene, each with a clear and 120 queries of every mode, encoded
//! as a trace in memory and decoded by every run, as `occsim replay` does from a file), on
//! the O2 and on ir4: fragments per second per level, as ratios to `cycle`; and what the
//! automatic effects choice saves over `--effects all` at the cycle level.
//!
//! Run: `cargo bench -p occsim-sim --bench fidelity`

use occsim_sim::effects::{effects_of_features, observe, Effects};
use occsim_sim::levels::{Fidelity, LevelModel, LevelResult, LevelSink};
use occsim_sim::{Arch, MachineBuilder};
use occsim_traces::golden::{EventSink, FunctionalModel};
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::trace::{TraceHeader, TraceReader, TraceWriter};
use occsim_traces::{Event, QueryMode, QuerySpec, Rect};
use std::time::Instant;

#[path = "support/stream.rs"]
mod stream;

use stream::{frame, HEIGHT, WIDTH};

const FRAMES: u64 = 3;
/// Rounds in which every level takes its turn; a level's fastest run counts, so a slow
/// spell of the shared machine falls on all levels alike.
const REPEATS: usize = 5;
/// In each round a level is repeated until its runs add up to this many seconds, so the
/// fast levels' few-millisecond runs are timed as often as the slow levels' long ones are
/// long.
const MIN_SECONDS: f64 = 0.2;

/// The stream encoded as a trace, as `occsim trace gen` writes a file (the header's
/// features written back).
fn encode(events: &[Event]) -> Vec<u8> {
    let mut file = std::io::Cursor::new(Vec::new());
    let mut writer = TraceWriter::new(&mut file, &TraceHeader::new(WIDTH, HEIGHT)).expect("header");
    for event in events {
        writer.event(event).expect("encodes");
    }
    writer.finish_seekable().expect("trace");
    file.into_inner()
}

/// The effects the automatic choice builds for `trace` on `arch`: from its header, as
/// `occsim replay` decides for a trace file.
fn effects_from_header(arch: &Arch, trace: &[u8]) -> Effects {
    let reader = TraceReader::new(trace).expect("header");
    effects_of_features(arch, WIDTH, HEIGHT, reader.header().features.as_ref())
        .expect("arch")
        .expect("the header has the facts")
}

/// Decode `trace` into the model of `level`, as `occsim replay` does.
fn replay(level: Fidelity, arch: &Arch, trace: &[u8], effects: Effects) -> LevelResult {
    let mut reader = TraceReader::new(trace).expect("header");
    let model = LevelModel::new(level, arch, WIDTH, HEIGHT, effects).expect("model");
    let mut sink = LevelSink::new(model);
    reader.read_into(&mut sink).expect("decodes and replays");
    sink.model.finish(arch).expect("replays")
}

/// One run of `level` (the effects choice included where the level builds effects): its
/// predicted cycles.
fn run_level(level: Fidelity, arch: &Arch, trace: &[u8]) -> Option<u64> {
    let effects = if level.builds_effects() {
        effects_from_header(arch, trace)
    } else {
        Effects::every_model_of(arch.machine())
    };
    replay(level, arch, trace, effects).total_cycles
}

fn main() {
    let events: Vec<Event> = (0..FRAMES).flat_map(|f| frame(42 + f)).collect();
    let fragments = events
        .iter()
        .filter(|e| matches!(e, Event::Fragment(_)))
        .count() as f64;
    println!("stream: {fragments} fragments, {WIDTH}x{HEIGHT}, {FRAMES} frames");
    let trace = encode(&events);
    println!("trace: {} bytes", trace.len());
    let plain = samples_only_without_depth_writes(&events);
    for name in ["o2", "ir4"] {
        let arch = Arch::builtin(name).expect("built-in arch");
        println!("{name}:");
        levels(&arch, &trace, fragments);
        compare_effects(&arch, &events, fragments, "the stream above");
        compare_effects(
            &arch,
            &plain,
            fragments,
            "the stream as samples queries, depth mask off",
        );
    }
}

/// Every level's rate on `trace` (the encoded `events`), as a ratio to `cycle`.
fn levels(arch: &Arch, trace: &[u8], fragments: f64) {
    let levels = [
        Fidelity::Functional,
        Fidelity::Analytic,
        Fidelity::Sampled { every: 10 },
        Fidelity::Sampled { every: 100 },
        Fidelity::Cycle,
        Fidelity::Rtl,
    ];
    let mut jobs = levels.map(|level| move || run_level(level, arch, trace));
    let timings: Vec<(Fidelity, f64, Option<u64>)> = levels
        .iter()
        .zip(fastest_of_rounds(REPEATS, MIN_SECONDS, &mut jobs))
        .map(|(&level, figure)| (level, figure.seconds, figure.output))
        .collect();
    let cycle_seconds = timings[4].1;
    for (level, seconds, cycles) in &timings {
        println!(
            "  {:<12} {:>8.1} M fragments/s  {:>6.2}x cycle  cycles {}",
            level.to_string(),
            fragments / seconds / 1e6,
            cycle_seconds / seconds,
            cycles.map_or("-".to_string(), |c| c.to_string())
        );
    }
}

/// The stream with every query a one-tile samples query and depth writes off: the effects
/// scan can switch off verbose hits, multi-tile serialisation and depth-write traffic.
fn samples_only_without_depth_writes(events: &[Event]) -> Vec<Event> {
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    golden.event(&Event::DepthMask(false));
    let mut out = vec![Event::DepthMask(false)];
    for event in events {
        let event = match event {
            Event::QueryResult(_) => continue,
            Event::DepthMask(_) => Event::DepthMask(false),
            Event::QueryBegin(spec) => Event::QueryBegin(QuerySpec {
                mode: QueryMode::Samples,
                buffer_entries: 8,
                tiles: vec![Rect::new(0, 0, WIDTH, HEIGHT)],
                ..spec.clone()
            }),
            other => other.clone(),
        };
        let result = golden.event(&event);
        out.push(event);
        if let Some(result) = result {
            out.push(Event::QueryResult(result));
        }
    }
    out
}

fn compare_effects(arch: &Arch, events: &[Event], fragments: f64, name: &str) {
    // Effects: the replay with every model against the replay with the automatic choice,
    // interleaved so both see the same machine load; and what deciding costs: reading a
    // trace file's header, or scanning the events of a trace without the facts in it.
    let scan_start = Instant::now();
    let chosen = observe(arch, WIDTH, HEIGHT, events).expect("scan");
    let scan = scan_start.elapsed().as_secs_f64();
    let trace = encode(events);
    let header_start = Instant::now();
    assert_eq!(effects_from_header(arch, &trace), chosen, "header = scan");
    let header = header_start.elapsed().as_secs_f64();
    let mut jobs = [Effects::ALL, chosen].map(|effects| {
        move || {
            let mut machine = MachineBuilder::new(arch)
                .effects(effects)
                .build(WIDTH, HEIGHT)
                .expect("machine");
            for event in events {
                machine.event(event).expect("replays");
            }
            machine.finish().expect("report");
        }
    });
    let figures = fastest_of_rounds(REPEATS, 0.0, &mut jobs);
    let (all, auto) = (figures[0].seconds, figures[1].seconds);
    println!(
        "  {name}: effects chosen: {}; cycle with all: {:.1} M fragments/s, with the choice: {:.1} M fragments/s ({:+.1}%); deciding from the header: {:.0} us, by a scan: {:.1} ms ({:.1}% of a replay)",
        chosen.active_names(),
        fragments / all / 1e6,
        fragments / auto / 1e6,
        100.0 * (all - auto) / all,
        header * 1e6,
        scan * 1e3,
        100.0 * scan / all
    );
}
