//! The analytic level read from a trace's window index equals the analytic level read from
//! its fragments' spans, which equals it fed fragment by fragment, bit for bit, wherever the
//! index is used; and where the index cannot serve (another depth layout, a retiling) the
//! fragments are read. So for the InfiniteReality-like machine's analytic and sampled
//! levels and the band index.

use occsim_sim::effects::EffectsChoice;
use occsim_sim::levels::sampled::{tail_fragments, warm_up_fragments};
use occsim_sim::levels::{run_level, Fidelity, LevelResult};
use occsim_sim::replay::{replay, ReplayOptions};
use occsim_sim::Arch;
use occsim_traces::builtin::{demo_scene, random_scene, DemoOptions, RandomOptions, HARDCASES};
use occsim_traces::retile::TileGrid;
use occsim_traces::trace::{TraceHeader, TraceReader, TraceWriter, WriterOptions};
use occsim_traces::Event;
use std::io::Cursor;

mod support;

/// A trace file's bytes, as `occsim trace gen` writes them: with the window index at the
/// default O2's depth layout, and the features written back into the header.
fn indexed_trace(width: u32, height: u32, events: &[Event]) -> Vec<u8> {
    indexed_trace_in_blocks(width, height, events, WriterOptions::default().block_bytes)
}

/// As [`indexed_trace`], in blocks of `block_bytes` (4096: a reader that starts mid-trace
/// skips blocks and starts inside them).
fn indexed_trace_in_blocks(
    width: u32,
    height: u32,
    events: &[Event],
    block_bytes: usize,
) -> Vec<u8> {
    let layout = Arch::builtin("o2").unwrap().o2().unwrap().depth_layout();
    let options = WriterOptions {
        block_bytes,
        window_index: Some(layout),
        ..WriterOptions::default()
    };
    let mut file = Cursor::new(Vec::new());
    let header = TraceHeader::new(width, height);
    let mut writer = TraceWriter::with_options(&mut file, &header, options).unwrap();
    for event in events {
        writer.write_event(event).unwrap();
    }
    writer.finish_seekable().unwrap();
    file.into_inner()
}

fn analytic(
    trace: &[u8],
    arch: &Arch,
    window_index: bool,
    retile: Option<TileGrid>,
) -> LevelResult {
    let options = ReplayOptions {
        window_index,
        retile,
        ..ReplayOptions::at(Fidelity::Analytic)
    };
    replay(|| Ok(TraceReader::new(trace)?), arch, options).unwrap()
}

/// The analytic level on `arch` read from the trace's index, from its fragments, and fed
/// its `events` one by one (a viewport of `width` by `height`).
fn analytic_three_ways(
    trace: &[u8],
    (width, height): (u32, u32),
    events: &[Event],
    arch: &Arch,
) -> (LevelResult, LevelResult, LevelResult) {
    let indexed = analytic(trace, arch, true, None);
    let decoded = analytic(trace, arch, false, None);
    let one_by_one = run_level(
        Fidelity::Analytic,
        arch,
        width,
        height,
        EffectsChoice::Auto,
        events,
    )
    .unwrap();
    (indexed, decoded, one_by_one)
}

/// A scene's name, trace bytes, viewport and events.
type Trace = (&'static str, Vec<u8>, (u32, u32), Vec<Event>);

fn traces() -> Vec<Trace> {
    let scenes = [
        ("hardcases", HARDCASES.to_owned()),
        (
            // Two frames: waits, conditionals and frame ends (the closed loop).
            "demo",
            demo_scene(&DemoOptions {
                width: 320,
                height: 256,
                frames: 2,
                lots_per_side: 8,
                ..DemoOptions::default()
            }),
        ),
        (
            "random",
            random_scene(&RandomOptions {
                width: 256,
                height: 192,
                triangles: 600,
                queries: 60,
                ..RandomOptions::default()
            }),
        ),
    ];
    scenes
        .into_iter()
        .map(|(name, text)| {
            let (width, height, events) = support::scene_events(&text);
            let trace = indexed_trace(width, height, &events);
            (name, trace, (width, height), events)
        })
        .collect()
}

fn o2_with(sets: &[&str]) -> Arch {
    let mut arch = Arch::builtin("o2").unwrap();
    for set in sets {
        arch.set(set).unwrap();
    }
    arch
}

#[test]
fn the_index_gives_the_analytic_result_of_the_fragments_bit_for_bit() {
    let archs = [
        o2_with(&[]),
        o2_with(&["engines=1"]),
        o2_with(&["all_tiles_one_cycle=true"]),
        // Blending, slow pages, no colour, fast clears, a short prefetch: each moves a formula.
        o2_with(&["blending=true", "page_miss_latency_cycles=40"]),
        o2_with(&["colour_bits_per_pixel=0"]),
        o2_with(&["clear_writes_memory=false", "prefetch_depth_fragments=2"]),
    ];
    for (name, trace, (width, height), events) in traces() {
        for arch in &archs {
            let (mut indexed, decoded, one_by_one) =
                analytic_three_ways(&trace, (width, height), &events, arch);
            assert_eq!(
                one_by_one.queries, decoded.queries,
                "{name}: spans and fragments differ"
            );
            assert_eq!(one_by_one.total_cycles, decoded.total_cycles, "{name}");
            assert_eq!(one_by_one.frame_cycles, decoded.frame_cycles, "{name}");
            assert!(indexed.from_window_index, "{name}: the index was not read");
            assert!(!decoded.from_window_index);
            assert!(decoded.checked_queries > 0, "{name}: nothing checked");
            // The index takes the golden results; the fragments' run checked them.
            assert_eq!(indexed.checked_queries, 0);
            indexed.checked_queries = decoded.checked_queries;
            indexed.from_window_index = false;
            assert_eq!(indexed, decoded, "{name} on {:?}", arch.report_entries());
        }
    }
}

#[test]
fn where_the_index_cannot_serve_the_fragments_are_read() {
    let (_, trace, _, _) = traces().remove(0);
    // Another depth layout: its reads and page misses are not the index's.
    for arch in [
        o2_with(&["memory_banks=4"]),
        o2_with(&["framebuffer_tile_width_pixels=64"]),
    ] {
        assert!(!analytic(&trace, &arch, true, None).from_window_index);
    }
    // Retiled queries are not the trace's.
    let grid: TileGrid = "2x2".parse().unwrap();
    assert!(!analytic(&trace, &o2_with(&[]), true, Some(grid)).from_window_index);
}

#[test]
fn an_index_before_version_9_is_decoded_and_the_report_says_why() {
    // A version-8 index keeps no ending runs of reads: the analytic and sampled levels read
    // the fragments, give what decoding gives, and name the version.
    let (_, trace, _, _) = traces().remove(0);
    let without_bands = occsim_traces::trace::windows::without_band_index(&trace).unwrap();
    let old = occsim_traces::trace::with_version_field(&without_bands, 8).unwrap();
    let arch = o2_with(&[]);
    let decoded = analytic(&trace, &arch, false, None);
    let from_old = analytic(&old, &arch, true, None);
    assert!(!from_old.from_window_index);
    assert_eq!(from_old.older_index, Some(8));
    assert_eq!(from_old.total_cycles, decoded.total_cycles);
    let text = from_old.to_text(false);
    assert!(text.contains("window index (format version 8)"), "{text}");
    assert_eq!(sampled(&old, &arch, 3, true).older_index, Some(8));
    // Nothing to say where the index serves, or where no level would read it.
    assert_eq!(analytic(&trace, &arch, true, None).older_index, None);
    assert_eq!(analytic(&old, &arch, false, None).older_index, None);
    let ir = Arch::builtin("ir2").unwrap();
    assert_eq!(analytic(&old, &ir, true, None).older_index, None);
}

fn sampled(trace: &[u8], arch: &Arch, every: u32, window_index: bool) -> LevelResult {
    sampled_warm(
        trace,
        arch,
        every,
        window_index,
        warm_up_fragments(arch.machine(), every),
    )
}

fn sampled_warm(
    trace: &[u8],
    arch: &Arch,
    every: u32,
    window_index: bool,
    warm_up_fragments: u64,
) -> LevelResult {
    sampled_tails(
        trace,
        arch,
        every,
        window_index,
        (warm_up_fragments, tail_fragments(arch.machine())),
    )
}

/// The sampled level with a warm-up and tail of these many fragments.
fn sampled_tails(
    trace: &[u8],
    arch: &Arch,
    every: u32,
    window_index: bool,
    (warm_up_fragments, tail): (u64, u64),
) -> LevelResult {
    let options = ReplayOptions {
        window_index,
        warm_up_fragments: Some(warm_up_fragments),
        tail_fragments: Some(tail),
        ..ReplayOptions::at(Fidelity::Sampled { every })
    };
    replay(|| Ok(TraceReader::new(trace)?), arch, options).unwrap()
}

/// `indexed` and `decoded` agree but for where their results come from.
fn assert_same_but_source(mut indexed: LevelResult, decoded: &LevelResult, what: &str) {
    assert!(indexed.from_window_index, "{what}: the index was not read");
    assert!(!decoded.from_window_index);
    indexed.checked_queries = decoded.checked_queries;
    indexed.from_window_index = false;
    assert_eq!(&indexed, decoded, "{what}");
}

#[test]
fn machines_started_inside_warm_up_windows_agree_from_the_index_and_the_fragments() {
    // A warm-up of 40 fragments starts the machines inside spans, stretches and queries
    // (these traces' windows hold hundreds to thousands of fragments), at clears, and
    // across blocks: both readings still agree bit for bit, and with the in-memory run.
    let arch = o2_with(&[]);
    let mut moved = 0;
    for (name, _, (width, height), events) in traces() {
        let trace = indexed_trace_in_blocks(width, height, &events, 4096);
        for every in [3, 5] {
            let what = format!("{name} at sampled:{every}");
            let indexed = sampled_warm(&trace, &arch, every, true, 40);
            let decoded = sampled_warm(&trace, &arch, every, false, 40);
            assert_same_but_source(indexed, &decoded, &what);
            let whole = sampled_warm(&trace, &arch, every, false, u64::MAX);
            moved += (whole.total_cycles != decoded.total_cycles) as u32;
            // The default warm-up, in memory and from the file.
            let in_memory = sampled_in_memory(&arch, every, (width, height), &events);
            let from_file = sampled(&trace, &arch, every, false);
            assert_eq!(in_memory, from_file, "{what}");
        }
    }
    // Short warm-ups do change what some windows measure: the machines did start late.
    assert!(moved > 0, "no warm-up started inside its window");
}

#[test]
fn the_index_gives_the_sampled_result_of_the_fragments_bit_for_bit() {
    // From the index, the machines read only the simulated windows' fragments, their depth
    // buffers made consistent with the trace's depth tests instead of copied from a
    // functional model that saw every fragment: every count, cycle and latency the same.
    let archs = [
        o2_with(&[]),
        o2_with(&["engines=1", "blending=true"]),
        o2_with(&["clear_writes_memory=false", "prefetch_depth_fragments=2"]),
    ];
    for (name, _, (width, height), events) in traces() {
        let trace = indexed_trace_in_blocks(width, height, &events, 4096);
        for arch in &archs {
            for every in [1, 2, 3, 7] {
                let mut indexed = sampled(&trace, arch, every, true);
                let decoded = sampled(&trace, arch, every, false);
                assert!(indexed.from_window_index, "{name}: the index was not read");
                assert!(!decoded.from_window_index);
                let windows = indexed.sampled_windows.unwrap();
                assert!(windows.simulated > 0 && windows.total > windows.simulated || every == 1);
                // The simulated windows' machines checked their queries' results.
                assert!(indexed.checked_queries > 0, "{name}: nothing checked");
                indexed.checked_queries = decoded.checked_queries;
                indexed.from_window_index = false;
                assert_eq!(
                    indexed,
                    decoded,
                    "{name} at sampled:{every} on {:?}",
                    arch.report_entries()
                );
            }
        }
    }
}

#[test]
fn long_sampled_windows_simulated_over_their_tails_agree_from_the_index_and_the_fragments() {
    // Tails of 100 fragments after warm-ups of 40: the windows of these traces (hundreds
    // to thousands of fragments) are cut, their heads extrapolated, and both readings still
    // agree bit for bit, machines started inside spans and stretches of the heads.
    let arch = o2_with(&[]);
    // Runs whose cut total differs from the whole one's.
    let (mut cut_runs, mut differing) = (0, 0);
    for (name, _, (width, height), events) in traces() {
        let trace = indexed_trace_in_blocks(width, height, &events, 4096);
        for every in [1, 3, 5] {
            let what = format!("{name} at sampled:{every}");
            let indexed = sampled_tails(&trace, &arch, every, true, (40, 100));
            let decoded = sampled_tails(&trace, &arch, every, false, (40, 100));
            let windows = decoded.sampled_windows.unwrap();
            let whole = sampled_tails(&trace, &arch, every, false, (40, u64::MAX));
            if every == 1 {
                // One machine runs the whole stream: nothing to cut, the cycle level's result.
                assert_eq!(windows.tails, 0, "{what}");
                assert_eq!(decoded, whole, "{what}");
            } else {
                assert!(windows.tails > 0, "{what}: no window was cut");
                assert!(windows.tails <= windows.simulated, "{what}");
                assert_eq!(whole.sampled_windows.unwrap().tails, 0, "{what}");
                // The heads were extrapolated, not measured: the totals differ (on one run or
                // more: where the formulas are exact for a head they may not).
                cut_runs += 1;
                differing += usize::from(decoded.total_cycles != whole.total_cycles);
                // Results are the functional model's either way.
                assert_eq!(
                    decoded.queries.iter().map(|q| q.value).collect::<Vec<_>>(),
                    whole.queries.iter().map(|q| q.value).collect::<Vec<_>>(),
                    "{what}"
                );
            }
            assert_same_but_source(indexed, &decoded, &what);
        }
    }
    assert!(
        differing > 0,
        "no cut run's total differs from the whole one's ({cut_runs})"
    );
}

#[test]
fn the_sampled_level_reads_fragments_where_the_index_cannot_serve() {
    let (_, trace, _, _) = traces().remove(0);
    assert!(!sampled(&trace, &o2_with(&["memory_banks=4"]), 3, true).from_window_index);
    assert!(!sampled(&trace, &o2_with(&[]), 3, false).from_window_index);
    // The IR's reads the band index, but not where asked not to.
    let ir = Arch::builtin("ir2").unwrap();
    assert!(sampled(&trace, &ir, 3, true).from_window_index);
    assert!(!sampled(&trace, &ir, 3, false).from_window_index);
}

#[test]
fn windows_simulated_over_their_tails_keep_the_sampled_level_within_its_bounds() {
    // These traces are small (as are the small corpus's, which the bounds test runs); with
    // tails of 2,048 after the default warm-up, the demo's long windows are cut (6 at
    // K = 3, 2 at K = 10), and the sampled level's cycles stay within the 1% the issue
    // asks of it against the cycle level (sampled:1, tested equal to cycle): measured
    // 0.08% at worst. (A warm-up of 512
    // fragments put them 2-9% off, cut or not: the warm-up, not the tail, is what the
    // machine's start needs.)
    let arch = o2_with(&[]);
    let mut tails = 0;
    for (name, trace, _, _) in traces() {
        let tailed = |every| {
            sampled_tails(
                &trace,
                &arch,
                every,
                true,
                (warm_up_fragments(arch.machine(), every), 2048),
            )
        };
        let cycle = tailed(1).total_cycles.unwrap() as f64;
        for every in [3, 10] {
            let cut = tailed(every);
            tails += cut.sampled_windows.unwrap().tails;
            let error = (cut.total_cycles.unwrap() as f64 - cycle).abs() / cycle;
            assert!(error <= 0.01, "{name} at sampled:{every}: {error:.4} > 1%");
        }
    }
    assert!(tails > 0, "no window was cut");
}

#[test]
fn machines_started_mid_stream_take_up_the_hosts_lead() {
    // The demo's closed loop: the host issues a query's draws while the pipe works through
    // the ones before, then waits for a brief query's answer. A machine started inside
    // such a stretch with its host at reset issues again, after its start, the draws the
    // host had issued long before, and holds the pipe for them. Taken up from the
    // predicted timeline, the host keeps its lead. Every other window sampled, each whole
    // (no tails), so that machines start mid-stream often; the run's cycles against the
    // cycle level's, measured: with warm-ups of 256 and 1,024 fragments, 0.42% and 0.46% on
    // the O2 and 0.20% and 0.16% on ir4; with the host at reset, 3.75% and 2.22% on the O2
    // and 10.8% and 10.3% on ir4 (on the full demo on ir4 at sampled:10 with a warm-up of
    // 4,096, 2.6%: seven sampled windows 1,100-3,100 cycles long, their brief box's batch
    // released 2,900 cycles after its query began where it had come 1,100 cycles before).
    let (_, trace, _, _) = traces().remove(1);
    for arch in [o2_with(&[]), Arch::builtin("ir4").unwrap()] {
        let name = arch.machine().name();
        let run = |every, warm_up| sampled_tails(&trace, &arch, every, true, (warm_up, u64::MAX));
        // sampled:1 runs one machine over the whole stream: the cycle level.
        let cycle = run(1, 0).total_cycles.unwrap() as f64;
        for warm_up in [256, 1024] {
            let sampled = run(2, warm_up);
            let error = (sampled.total_cycles.unwrap() as f64 - cycle).abs() / cycle;
            assert!(
                error <= 0.01,
                "{name} warmed up over {warm_up}: {:.2}% off",
                error * 100.0
            );
        }
    }
}

#[test]
fn the_window_table_gives_the_sampled_level_the_sizes_its_scout_finds_without_one() {
    // The same trace without its window table: its sizes are found
    // by reading the window index (the O2) or the events (the fragments' reading, the
    // InfiniteReality-like machine) a second time. Short warm-ups and tails put the
    // windows' sizes to use (where machines start, which windows are cut): every count,
    // cycle and latency the same.
    let archs = [o2_with(&[]), Arch::builtin("ir2").unwrap()];
    for (name, _, (width, height), events) in traces() {
        let table = indexed_trace_in_blocks(width, height, &events, 4096);
        let scouted = occsim_traces::trace::windows::without_window_table(&table).unwrap();
        assert!(!TraceReader::new(&scouted[..]).unwrap().has_window_table());
        for arch in &archs {
            for every in [2, 3, 7] {
                for window_index in [true, false] {
                    let what = format!("{name} at sampled:{every} on {:?}", arch.machine());
                    let run =
                        |trace: &[u8]| sampled_tails(trace, arch, every, window_index, (40, 100));
                    assert_eq!(run(&table), run(&scouted), "{what}");
                }
            }
        }
    }
}

fn ir_with(name: &str, sets: &[&str]) -> Arch {
    let mut arch = Arch::builtin(name).unwrap();
    for set in sets {
        arch.set(set).unwrap();
    }
    arch
}

/// The hard cases with their verbose queries made brief, as [`traces`] gives a trace.
fn brief_hardcases() -> Trace {
    let (width, height, events) = support::scene_events(&HARDCASES.replace(" verbose ", " brief "));
    let trace = indexed_trace(width, height, &events);
    ("hardcases, brief", trace, (width, height), events)
}

#[test]
fn the_band_index_gives_the_ir_analytic_result_of_the_fragments_bit_for_bit() {
    // The hard cases (verbose queries whose buffers overflow: a band marks its runs that
    // pass), the two-frame demo (verbose queries too), the random triangles, and the hard
    // cases with no verbose query. Every board count, the columns interleave on many or
    // few engines (a band wider than the units deals an engine several columns), and the
    // others (each pixel looked up).
    let archs = [
        ir_with("ir1", &[]),
        ir_with("ir2", &["engines=1"]),
        ir_with("ir4", &[]),
        ir_with("ir2", &["image_engines_per_board=3"]),
        ir_with("ir2", &["interleave=morton"]),
        ir_with("ir4", &["interleave=blocks"]),
    ];
    for (name, trace, (width, height), events) in traces().into_iter().chain([brief_hardcases()]) {
        for arch in &archs {
            let what = format!("{name} on {:?}", arch.report_entries());
            let (indexed, decoded, one_by_one) =
                analytic_three_ways(&trace, (width, height), &events, arch);
            assert_eq!(one_by_one.total_cycles, decoded.total_cycles, "{what}");
            assert_eq!(one_by_one.queries, decoded.queries, "{what}");
            assert!(decoded.checked_queries > 0, "{what}: nothing checked");
            assert_eq!(
                indexed.checked_queries, 0,
                "{what}: the golden results taken"
            );
            assert_same_but_source(indexed, &decoded, &what);
        }
    }
}

#[test]
fn the_band_index_gives_the_ir_sampled_result_of_the_fragments_bit_for_bit() {
    // From the band index, the IR's machines read only the simulated windows' fragments
    // (their depths made consistent with the trace's depth tests): every count, cycle and
    // latency as decoding every fragment gives.
    let archs = [
        ir_with("ir2", &[]),
        ir_with("ir4", &["engines=1"]),
        ir_with("ir2", &["interleave=morton"]),
    ];
    let mut scenes = traces();
    scenes.remove(1);
    for (name, _, (width, height), events) in scenes {
        let trace = indexed_trace_in_blocks(width, height, &events, 4096);
        for arch in &archs {
            for every in [1, 2, 3, 7] {
                let mut indexed = sampled(&trace, arch, every, true);
                let decoded = sampled(&trace, arch, every, false);
                let windows = indexed.sampled_windows.unwrap();
                assert!(windows.simulated > 0 && windows.total > windows.simulated || every == 1);
                let what = format!("{name} at sampled:{every} on {:?}", arch.report_entries());
                assert!(indexed.checked_queries > 0, "{what}: nothing checked");
                indexed.checked_queries = decoded.checked_queries;
                assert_same_but_source(indexed, &decoded, &what);
            }
        }
    }
}

#[test]
fn the_ir_analytic_level_decodes_an_older_trace_a_retiled_one_or_where_asked() {
    let (_, trace, _, _) = traces().remove(0);
    let ir = ir_with("ir2", &[]);
    assert!(analytic(&trace, &ir, true, None).from_window_index);
    // A version-9 trace has no band index.
    let old = occsim_traces::trace::with_version_field(
        &occsim_traces::trace::windows::without_band_index(&trace).unwrap(),
        9,
    )
    .unwrap();
    let from_old = analytic(&old, &ir, true, None);
    assert!(!from_old.from_window_index);
    assert_eq!(
        from_old.total_cycles,
        analytic(&trace, &ir, false, None).total_cycles
    );
    // Retiled queries are not the trace's; asked not to, it decodes.
    let grid: TileGrid = "2x2".parse().unwrap();
    assert!(!analytic(&trace, &ir, true, Some(grid)).from_window_index);
    assert!(!analytic(&trace, &ir, false, None).from_window_index);
}

#[test]
fn a_query_without_its_golden_result_is_an_error_at_every_level_that_reads_an_index() {
    // The random triangles with their first query's golden result dropped: read from the
    // window or band index, a query's result is its golden one, so the replay must say
    // the result is missing (the sampled level had closed the query's window with no
    // latency to give it, an index below zero).
    let (_, _, (width, height), mut events) = traces().remove(2);
    let first_result = events
        .iter()
        .position(|event| matches!(event, Event::QueryResult(_)))
        .expect("a query result");
    events.remove(first_result);
    let trace = indexed_trace(width, height, &events);
    for arch in [o2_with(&[]), ir_with("ir2", &[])] {
        for level in [
            Fidelity::Analytic,
            Fidelity::Sampled { every: 2 },
            Fidelity::Sampled { every: 10 },
        ] {
            let options = ReplayOptions::at(level);
            let error = replay(|| Ok(TraceReader::new(&trace[..])?), &arch, options)
                .err()
                .unwrap_or_else(|| panic!("{level} on {:?}: replayed", arch.machine()));
            let mut chain = error.to_string();
            let mut source = std::error::Error::source(&error);
            while let Some(cause) = source {
                chain += &format!(": {cause}");
                source = cause.source();
            }
            assert!(
                chain.contains("is not followed by its golden result"),
                "{level} on {:?}: {chain}",
                arch.machine()
            );
        }
    }
}

/// The sampled level fed `events` one by one, as `run_level` feeds them from memory.
fn sampled_in_memory(
    arch: &Arch,
    every: u32,
    (width, height): (u32, u32),
    events: &[Event],
) -> LevelResult {
    let level = Fidelity::Sampled { every };
    run_level(level, arch, width, height, EffectsChoice::Auto, events).unwrap()
}

#[test]
fn the_sampled_level_fed_event_by_event_equals_it_read_span_by_span() {
    // A machine may start inside a span (a warm-up's first fragment in the middle of a
    // row): where its pipe starts is the formulas' work before that fragment however the
    // fragments come, so a run fed one event at a time is the run read from the file.
    for (name, trace, (width, height), events) in traces() {
        for arch in [o2_with(&[]), ir_with("ir2", &[])] {
            for every in [2, 7] {
                let spans = sampled(&trace, &arch, every, false);
                let one_by_one = sampled_in_memory(&arch, every, (width, height), &events);
                let what = format!("{name} on {:?} at sampled:{every}", arch.machine());
                assert_eq!(spans, one_by_one, "{what}");
            }
        }
    }
}
