//! What each fidelity level costs, on four traces encoded in memory as `occsim trace gen`
//! writes them (with the window index) and read by every run as `occsim replay` reads a file:
//! - `synthetic`: three frames of the replay benchmark's scene (about 1.5 M fragments, a
//!   clear and 120 queries of every mode a frame);
//! - `demo`: `occsim trace gen demo` (27 M fragments, 609 queries, 4 frames);
//! - `lazy-grid`: `occsim trace gen --scene city --driver lazy-grid --frames 2` (20 M
//!   fragments, 156 queries of up to hundreds of tiles);
//! - `city-hierarchical`: `occsim trace gen --scene city --driver hierarchical --frames 2`
//!   (31 M fragments, 198 one-tile queries), the third trace the targets name.
//!
//! On the O2 and on ir4: fragments per second per level, as ratios to `cycle`, and the
//! analytic and sampled:10 levels decoding the fragments beside them reading the window
//! index (what the index saves), the O2's analytic level reading the index's queries whole
//! beside it skimming them (what skimming saves), and sampled:10 and sampled:100 on the
//! trace without its window table (what the table saves); then, on the synthetic stream,
//! what the automatic effects choice saves over `--effects all` at the cycle level.
//!
//! Run: `cargo bench -p occsim-sim --bench fidelity` (several minutes: the large traces'
//! rtl runs dominate).

use occsim_sim::arch::Machine;
use occsim_sim::effects::{effects_of_features, observe, Effects};
use occsim_sim::levels::analytic::AnalyticModel;
use occsim_sim::levels::Fidelity;
use occsim_sim::replay::{replay, ReplayOptions};
use occsim_sim::{Arch, MachineBuilder};
use occsim_traces::builtin::{demo_scene, DemoOptions};
use occsim_traces::golden::{EventSink, FunctionalModel, GoldenModel};
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::scene::SceneReader;
use occsim_traces::trace::{TraceHeader, TraceReader, TraceWriter, WriterOptions};
use occsim_traces::workloads::{city, generate, CityOptions, DriverKind, DriverOptions, Walk};
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

type Writer<'a> = TraceWriter<&'a mut std::io::Cursor<Vec<u8>>>;

/// A trace file's bytes, as `occsim trace gen` writes them: the window index at the O2's
/// depth layout, the header's features written back; `fill` writes the events.
fn write_trace(width: u32, height: u32, fill: impl FnOnce(&mut Writer)) -> Vec<u8> {
    let layout = Arch::builtin("o2")
        .expect("o2")
        .o2()
        .expect("o2")
        .depth_layout();
    let options = WriterOptions {
        window_index: Some(layout),
        ..WriterOptions::default()
    };
    let mut file = std::io::Cursor::new(Vec::new());
    let mut writer =
        TraceWriter::with_options(&mut file, &TraceHeader::new(width, height), options)
            .expect("header");
    fill(&mut writer);
    writer.finish_seekable().expect("trace");
    file.into_inner()
}

/// The stream encoded as a trace.
fn encode(events: &[Event]) -> Vec<u8> {
    write_trace(WIDTH, HEIGHT, |writer| {
        for event in events {
            writer.event(event).expect("encodes");
        }
    })
}

/// `occsim trace gen demo`.
fn demo_trace() -> Vec<u8> {
    let options = DemoOptions::default();
    let text = demo_scene(&options);
    write_trace(options.width, options.height, |writer| {
        let mut golden = GoldenModel::new(options.width, options.height);
        for line in SceneReader::new(text.as_bytes(), "demo") {
            golden
                .execute(&line.expect("the demo parses").command, writer)
                .expect("encodes");
        }
        golden.finish(writer).expect("encodes");
    })
}

/// `occsim trace gen --scene city --driver DRIVER --frames 2` (its default 1280x1024).
fn city_walk_trace(driver: DriverKind) -> Vec<u8> {
    let walk = Walk {
        frames: 2,
        width: 1280,
        height: 1024,
        raster: Default::default(),
    };
    let scene = city(&CityOptions {
        seed: 1998,
        ..CityOptions::default()
    });
    write_trace(walk.width, walk.height, |writer| {
        generate(&scene, &DriverOptions::new(driver), &walk, writer).expect("walks");
    })
}

/// The effects the automatic choice builds for `trace` on `arch`: from its header, as
/// `occsim replay` decides for a trace file.
fn effects_from_header(arch: &Arch, trace: &[u8]) -> Effects {
    let reader = TraceReader::new(trace).expect("header");
    effects_of_features(arch, WIDTH, HEIGHT, reader.header().features.as_ref())
        .expect("arch")
        .expect("the header has the facts")
}

/// One run of `level` on `trace` as `occsim replay` makes it: its predicted cycles.
fn run_level(level: Fidelity, arch: &Arch, trace: &[u8], window_index: bool) -> Option<u64> {
    let options = ReplayOptions {
        window_index,
        ..ReplayOptions::at(level)
    };
    replay(|| Ok(TraceReader::new(trace)?), arch, options)
        .expect("replays")
        .total_cycles
}

fn fragments_of(trace: &[u8]) -> f64 {
    let (_, summary) = TraceReader::read_summary(std::io::Cursor::new(trace)).expect("summary");
    summary.fragments as f64
}

fn main() {
    let events: Vec<Event> = (0..FRAMES).flat_map(|f| frame(42 + f)).collect();
    let traces = [
        ("synthetic", encode(&events), REPEATS),
        // The large traces take seconds a run at the cycle level and more at rtl: fewer
        // rounds, but three, so that one slow spell of a shared machine does not set a
        // ratio (with one round, the lazy walk's cycle level ran at 22 M fragments/s in
        // one run and 35 M/s in the next, its analytic level 66x and 122x of it).
        ("demo", demo_trace(), 3),
        ("lazy-grid", city_walk_trace(DriverKind::LazyGrid), 3),
        (
            "city-hierarchical",
            city_walk_trace(DriverKind::Hierarchical),
            3,
        ),
    ];
    for (name, trace, rounds) in &traces {
        println!(
            "{name}: {} fragments, {} bytes",
            fragments_of(trace),
            trace.len()
        );
        for arch in ["o2", "ir4"] {
            println!("  {arch}:");
            levels(&Arch::builtin(arch).expect("built-in arch"), trace, *rounds);
        }
    }
    let fragments = events
        .iter()
        .filter(|e| matches!(e, Event::Fragment(_)))
        .count() as f64;
    let plain = samples_only_without_depth_writes(&events);
    for name in ["o2", "ir4"] {
        let arch = Arch::builtin(name).expect("built-in arch");
        println!("effects on {name}:");
        compare_effects(&arch, &events, fragments, "the synthetic stream");
        compare_effects(
            &arch,
            &plain,
            fragments,
            "the stream as samples queries, depth mask off",
        );
    }
}

/// How a level reads the trace.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Reading {
    /// As `occsim replay` reads it: the window index and the window table where they serve.
    AsWritten,
    /// Decoding every fragment (`--no-index`): what the index saves.
    Decode,
    /// The trace without its window table: what the table saves the
    /// sampled level (its windows' sizes found by reading the trace a second time).
    NoTable,
    /// The window index with its queries read whole, each tile decoded, where `occsim
    /// replay` skims them (`TraceReader::skim_queries`): what skimming saves the O2's
    /// analytic level.
    WholeQueries,
}

/// One run of the analytic level from the window index with its queries read whole (see
/// [`Reading::WholeQueries`]): its predicted cycles.
fn analytic_reading_whole_queries(arch: &Arch, trace: &[u8]) -> Option<u64> {
    let mut reader = TraceReader::new(trace).expect("header");
    let (width, height) = (reader.header().width, reader.header().height);
    let mut model = AnalyticModel::from_window_index(arch, width, height).expect("model");
    reader
        .for_each_index_item(|item| model.index_item(item))
        .expect("reads");
    model.finish().expect("finishes").total_cycles
}

/// Every level's rate on `trace`, as a ratio to `cycle`; the analytic and sampled levels
/// also decoding the fragments (`/decode`) beside reading the window index, and the sampled
/// level on the trace without its window table (`/no-table`).
fn levels(arch: &Arch, trace: &[u8], rounds: usize) {
    let fragments = fragments_of(trace);
    let no_table =
        occsim_traces::trace::windows::without_window_table(trace).expect("a whole trace");
    let mut levels = vec![
        (Fidelity::Functional, Reading::AsWritten),
        (Fidelity::Analytic, Reading::AsWritten),
        (Fidelity::Analytic, Reading::Decode),
        (Fidelity::Sampled { every: 10 }, Reading::AsWritten),
        (Fidelity::Sampled { every: 10 }, Reading::Decode),
        (Fidelity::Sampled { every: 10 }, Reading::NoTable),
        (Fidelity::Sampled { every: 100 }, Reading::AsWritten),
        (Fidelity::Sampled { every: 100 }, Reading::NoTable),
        (Fidelity::Cycle, Reading::AsWritten),
        (Fidelity::Rtl, Reading::AsWritten),
    ];
    // The IR's formulas read the band index's queries whole (they place a verbose query's
    // tiles), so only the O2's analytic level has a skimming to weigh.
    if arch.machine() == Machine::O2 {
        levels.insert(2, (Fidelity::Analytic, Reading::WholeQueries));
    }
    let no_table = &no_table;
    let mut jobs: Vec<_> = levels
        .iter()
        .map(|&(level, reading)| {
            move || match reading {
                Reading::AsWritten => run_level(level, arch, trace, true),
                Reading::Decode => run_level(level, arch, trace, false),
                Reading::NoTable => run_level(level, arch, no_table, true),
                Reading::WholeQueries => analytic_reading_whole_queries(arch, trace),
            }
        })
        .collect();
    let figures = fastest_of_rounds(rounds, MIN_SECONDS, &mut jobs);
    let cycle = levels
        .iter()
        .position(|&(level, _)| level == Fidelity::Cycle);
    let cycle_seconds = figures[cycle.expect("cycle is among the levels")].seconds;
    for ((level, reading), figure) in levels.iter().zip(&figures) {
        let name = match reading {
            Reading::AsWritten => level.to_string(),
            Reading::Decode => format!("{level}/decode"),
            Reading::NoTable => format!("{level}/no-table"),
            Reading::WholeQueries => format!("{level}/whole-queries"),
        };
        println!(
            "    {name:<22} {:>9.1} M fragments/s  {:>8.2}x cycle  cycles {}",
            fragments / figure.seconds / 1e6,
            cycle_seconds / figure.seconds,
            figure.output.map_or("-".to_string(), |c| c.to_string())
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
