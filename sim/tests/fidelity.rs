//! The fidelity ladder and the effects choice on built-in scenes and random streams:
//! exact results at every level, finite predictions, and `--effects all` = automatic.

use occsim_sim::effects::{
    effects_of_features, observe, EffectScan, Effects, EffectsChoice, TraceFacts,
};
use occsim_sim::levels::sampled::QUERIES_PER_SLOWEST;
use occsim_sim::levels::{run_level, Fidelity, LevelResult};
use occsim_sim::{Arch, MachineBuilder, Report};
use occsim_traces::builtin::{demo_scene, random_scene, DemoOptions, RandomOptions, HARDCASES};
use occsim_traces::golden::{EventSink, FunctionalModel};
use occsim_traces::trace::{TraceFeatures, TraceHeader, TraceReader, TraceWriter};
use occsim_traces::{DepthFunc, Event, Fragment, QueryMode, QuerySpec, Rect};
use proptest::prelude::*;

mod support;

/// The events of a scene, with the golden results, and its viewport.
fn scene_events(text: &str) -> (Vec<Event>, u32, u32) {
    let (width, height, events) = support::scene_events(text);
    (events, width, height)
}

fn small_demo() -> (Vec<Event>, u32, u32) {
    scene_events(&demo_scene(&DemoOptions {
        width: 320,
        height: 256,
        frames: 1,
        lots_per_side: 8,
        ..DemoOptions::default()
    }))
}

fn small_random() -> (Vec<Event>, u32, u32) {
    scene_events(&random_scene(&RandomOptions {
        width: 256,
        height: 192,
        triangles: 600,
        queries: 60,
        ..RandomOptions::default()
    }))
}

/// A stream of events and its viewport width and height.
type Stream = (Vec<Event>, u32, u32);

fn builtin_traces() -> Vec<(&'static str, Stream)> {
    vec![
        ("hardcases", scene_events(HARDCASES)),
        ("demo", small_demo()),
        ("random", small_random()),
    ]
}

/// `level` on `arch` over a stream, with the automatic effects choice.
fn run_at(level: &str, arch: &Arch, (events, width, height): &Stream) -> LevelResult {
    run_level(
        level.parse().unwrap(),
        arch,
        *width,
        *height,
        EffectsChoice::Auto,
        events,
    )
    .unwrap()
}

fn replay(arch: &Arch, width: u32, height: u32, effects: Effects, events: &[Event]) -> Report {
    let mut machine = MachineBuilder::new(arch)
        .effects(effects)
        .build(width, height)
        .unwrap();
    for event in events {
        machine.event(event).unwrap();
    }
    machine.finish().unwrap()
}

/// The golden values of every query in the stream, in order (from the stored results).
fn golden_values(events: &[Event]) -> Vec<u64> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::QueryResult(r) => Some(r.value()),
            _ => None,
        })
        .collect()
}

fn archs() -> Vec<Arch> {
    let mut few_engines = Arch::builtin("o2").unwrap();
    few_engines.set("engines=1").unwrap();
    let mut one_cycle = Arch::builtin("o2").unwrap();
    one_cycle.set("all_tiles_one_cycle=true").unwrap();
    let mut ir_one_engine = small_ir();
    ir_one_engine.set("engines=1").unwrap();
    vec![
        Arch::builtin("o2").unwrap(),
        few_engines,
        one_cycle,
        small_ir(),
        ir_one_engine,
    ]
}

/// The InfiniteReality-like machine, small enough for quick tests: 2 boards of 5 Image
/// Engines, 3 engines per Occlusion Unit.
fn small_ir() -> Arch {
    let mut arch = Arch::builtin("ir2").unwrap();
    arch.set("image_engines_per_board=5").unwrap();
    arch.set("engines=3").unwrap();
    arch
}

/// The shortest latency a query can have: O2's empty pipe; the IR's Image Engine path
/// (depth stage, OccU, report) before any merge.
fn minimum_latency(arch: &Arch) -> u64 {
    match arch.machine() {
        occsim_sim::arch::Machine::O2 => 5,
        occsim_sim::arch::Machine::Ir => 3,
    }
}

#[test]
fn every_level_gives_the_golden_values_and_finite_predictions() {
    for arch in [Arch::builtin("o2").unwrap(), small_ir()] {
        every_level_gives_the_golden_values_on(&arch);
    }
}

fn every_level_gives_the_golden_values_on(arch: &Arch) {
    let minimum = minimum_latency(arch);
    for (name, (events, width, height)) in builtin_traces() {
        let golden = golden_values(&events);
        assert!(!golden.is_empty(), "{name} has queries");
        for level in ["functional", "analytic", "sampled:1", "sampled:3", "cycle"] {
            let level: Fidelity = level.parse().unwrap();
            let result = run_level(level, arch, width, height, EffectsChoice::Auto, &events)
                .unwrap_or_else(|e| panic!("{name} at {level}: {e}"));
            let values: Vec<u64> = result.queries.iter().map(|q| q.value).collect();
            assert_eq!(values, golden, "{name} at {level}");
            assert_eq!(result.checked_queries, golden.len() as u64);
            match level {
                Fidelity::Functional => {
                    assert_eq!(result.total_cycles, None);
                    assert!(result.queries.iter().all(|q| q.latency_cycles.is_none()));
                }
                _ => {
                    let total = result.total_cycles.unwrap();
                    assert!(
                        total >= result.fragments,
                        "{name} at {level}: {total} cycles"
                    );
                    assert!(result.latency_mean_cycles.unwrap().is_finite());
                    assert!(result
                        .queries
                        .iter()
                        .all(|q| q.latency_cycles.is_some_and(|l| l >= minimum)));
                }
            }
        }
    }
}

#[test]
fn sampled_every_window_equals_cycle_on_builtin_traces() {
    // sampled:1 runs one machine over the whole stream and measures every window.
    for arch in [Arch::builtin("o2").unwrap(), small_ir()] {
        for (name, (events, width, height)) in builtin_traces() {
            sampled_every_window_equals_cycle_on(&arch, name, &events, width, height);
        }
    }
}

fn sampled_every_window_equals_cycle_on(
    arch: &Arch,
    name: &str,
    events: &[Event],
    width: u32,
    height: u32,
) {
    {
        let cycle = run_level(
            Fidelity::Cycle,
            arch,
            width,
            height,
            EffectsChoice::Auto,
            events,
        )
        .unwrap();
        let sampled = run_level(
            Fidelity::Sampled { every: 1 },
            arch,
            width,
            height,
            EffectsChoice::Auto,
            events,
        )
        .unwrap();
        assert_eq!(sampled.total_cycles, cycle.total_cycles, "{name}");
        assert_eq!(sampled.queries, cycle.queries, "{name}");
        let windows = sampled.sampled_windows.unwrap();
        assert_eq!(windows.simulated, windows.total, "{name}");
    }
}

#[test]
fn sampled_windows_are_counted_every_kth_and_the_slowest_predicted_simulated() {
    let arch = Arch::builtin("o2").unwrap();
    let (events, width, height) = small_random();
    let queries = golden_values(&events).len() as u64;
    let level = Fidelity::Sampled { every: 4 };
    let result = run_level(level, &arch, width, height, EffectsChoice::All, &events).unwrap();
    let windows = result.sampled_windows.unwrap();
    // One window per query end, plus the tail after the last (the random scene ends with one).
    assert!(windows.total == queries || windows.total == queries + 1);
    // Besides every 4th window, the windows of the ceil(n / QUERIES_PER_SLOWEST) queries
    // (the top fifteenth) the formulas predict slowest (the analytic level's latencies; of
    // equal ones the earlier); query i ends window i.
    let analytic = run_level(
        Fidelity::Analytic,
        &arch,
        width,
        height,
        EffectsChoice::All,
        &events,
    )
    .unwrap();
    let predicted: Vec<u64> = analytic
        .queries
        .iter()
        .map(|q| q.latency_cycles.unwrap())
        .collect();
    let mut ranked: Vec<usize> = (0..predicted.len()).collect();
    ranked.sort_by_key(|&i| (std::cmp::Reverse(predicted[i]), i));
    let slowest_only = ranked[..predicted.len().div_ceil(QUERIES_PER_SLOWEST)]
        .iter()
        .filter(|&&i| i % 4 != 0)
        .count() as u64;
    assert!(slowest_only > 0, "{predicted:?}");
    assert_eq!(windows.slowest, slowest_only);
    assert_eq!(windows.simulated, windows.total.div_ceil(4) + slowest_only);
}

#[test]
fn one_window_sampled_at_every_level_of_k_equals_cycle() {
    // A stream with a single query and nothing after it is one window: sampled:K simulates
    // it from the same reset state the cycle level starts in.
    let (width, height) = (64, 48);
    let mut golden = FunctionalModel::new(width, height);
    let mut events = vec![Event::Clear, Event::DepthFunc(DepthFunc::Less)];
    for y in 0..40u16 {
        events.push(Event::Primitive);
        for x in 0..60u16 {
            events.push(Event::Fragment(Fragment {
                x,
                y,
                z: 1000 + x as u32,
            }));
        }
    }
    events.push(Event::QueryBegin(QuerySpec {
        id: 7,
        mode: QueryMode::Brief,
        buffer_entries: 8,
        tiles: (0..12).map(|i| Rect::new(i * 5, 0, 5, 48)).collect(),
    }));
    for y in 0..48u16 {
        for x in 0..64u16 {
            events.push(Event::Fragment(Fragment {
                x,
                y,
                z: 900 + y as u32 * 3,
            }));
        }
    }
    events.push(Event::QueryEnd);
    let mut stream = Vec::new();
    for event in events {
        let result = golden.event(&event);
        stream.push(event);
        if let Some(result) = result {
            stream.push(Event::QueryResult(result));
        }
    }
    let arch = Arch::builtin("o2").unwrap();
    let cycle = run_level(
        Fidelity::Cycle,
        &arch,
        width,
        height,
        EffectsChoice::All,
        &stream,
    )
    .unwrap();
    for every in [1, 5] {
        let sampled = run_level(
            Fidelity::Sampled { every },
            &arch,
            width,
            height,
            EffectsChoice::All,
            &stream,
        )
        .unwrap();
        assert_eq!(sampled.total_cycles, cycle.total_cycles);
        assert_eq!(sampled.queries, cycle.queries);
    }
}

/// One samples query over no fragments, on a 16x16 viewport.
fn one_empty_query() -> [Event; 2] {
    let spec = QuerySpec {
        id: 1,
        mode: QueryMode::Samples,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, 16, 16)],
    };
    [Event::QueryBegin(spec), Event::QueryEnd]
}

#[test]
fn analytic_reaches_the_minimum_latency_on_an_idle_pipe() {
    // One samples query over no fragments: the records (8 words) fit one port cycle. The
    // display refresh and the host need f = 0.2343 of the port's cycles but may fall 16
    // behind (other_clients_slack_cycles), so on an idle port they take no cycle the
    // pipeline asks for: the records go in 4, their first chance (end 0, depth 1, OccU 2,
    // ready 3, asking from 4), and are available in 5, the machine's minimum, as without
    // the share.
    let arch = Arch::builtin("o2").unwrap();
    let events = one_empty_query();
    let analytic = run_level(
        Fidelity::Analytic,
        &arch,
        16,
        16,
        EffectsChoice::Auto,
        &events,
    )
    .unwrap();
    let cycle = run_level(Fidelity::Cycle, &arch, 16, 16, EffectsChoice::Auto, &events).unwrap();
    assert_eq!(analytic.queries[0].latency_cycles, Some(5));
    assert_eq!(cycle.queries[0].latency_cycles, Some(5));
    // Without the share, the same.
    let mut free = arch.clone();
    free.set("display_refresh_hz=0").unwrap();
    free.set("host_memory_share=0").unwrap();
    for level in [Fidelity::Analytic, Fidelity::Cycle] {
        let result = run_level(level, &free, 16, 16, EffectsChoice::Auto, &events).unwrap();
        assert_eq!(result.queries[0].latency_cycles, Some(5), "{level}");
    }
}

#[test]
fn analytic_o2_writes_the_records_of_queries_that_end_together_one_after_another() {
    // Brief queries of 4 tiles over no fragments, back to back, in an open loop, on the O2
    // with no share for the port's other clients: every end token enters at cycle 0, and
    // each query's records (4 tiles of 8 words, 4 cycles of a 256-bit port) are ready in 4
    // (end 0, depth 1, OccU 2, ready 3, asking from 4), but the in-order port writes them
    // after the records of the queries before: query k's go in 4 + 4k .. 7 + 4k, its
    // latency 8 + 4k (the formulas had given every one 8: the run 96% short).
    let mut arch = Arch::builtin("o2").unwrap();
    arch.set("display_refresh_hz=0").unwrap();
    arch.set("host_memory_share=0").unwrap();
    let events: Vec<Event> = (0..50)
        .flat_map(|id| {
            let spec = QuerySpec {
                id,
                mode: QueryMode::Brief,
                buffer_entries: 8,
                tiles: vec![
                    Rect::new(0, 0, 8, 8),
                    Rect::new(8, 0, 8, 8),
                    Rect::new(0, 8, 8, 8),
                    Rect::new(8, 8, 8, 8),
                ],
            };
            [Event::QueryBegin(spec), Event::QueryEnd]
        })
        .collect();
    let expected: Vec<u64> = (0..50).map(|k| 8 + 4 * k).collect();
    for level in [Fidelity::Analytic, Fidelity::Cycle] {
        let result = run_level(level, &arch, 16, 16, EffectsChoice::Auto, &events).unwrap();
        let latencies: Vec<u64> = (result.queries.iter())
            .map(|q| q.latency_cycles.unwrap())
            .collect();
        assert_eq!(latencies, expected, "{level}");
    }
}

#[test]
fn every_level_refuses_a_query_past_the_ir_tile_registers() {
    // A brief query of 128 x 128 one-pixel tiles on ir4: 16,384 tiles in each of 320
    // Occlusion Units, 5,242,880 registers, past the model's 4,194,304. The machine had
    // refused it while the analytic level timed it.
    let arch = Arch::builtin("ir4").unwrap();
    let tiles: Vec<Rect> = (0..128 * 128)
        .map(|k| Rect::new(k % 128, k / 128, 1, 1))
        .collect();
    let spec = QuerySpec {
        id: 7,
        mode: QueryMode::Brief,
        buffer_entries: 8,
        tiles,
    };
    let events = [Event::QueryBegin(spec), Event::QueryEnd];
    for level in ["analytic", "sampled:10", "cycle"] {
        let level: Fidelity = level.parse().unwrap();
        let error =
            run_level(level, &arch, 128, 128, EffectsChoice::Auto, &events).expect_err("refused");
        let text = error.to_string();
        assert!(
            text.contains("event 0: query 7 has 16384 tiles") && text.contains("tile registers"),
            "{level}: {text}"
        );
    }
}

#[test]
fn analytic_o2_keeps_the_backlog_its_fifos_hold_at_the_end_token() {
    // o2 without reserved port cycles (f = 0), depth test off, a brief query of 16 tiles
    // (4x4 each) over one primitive of 100 fragments: with 4 engines each fragment takes the
    // OccU s = 4 cycles, so the OccU binds: down = 400, pace 4, and both FIFOs hold
    // fragments ahead of it, Q = 16 + 8 = 24. The primitive is set up from 0 to 4 and its
    // fragments emitted by 104; the OccU takes fragment j in 4 + 4 j and is through in
    // d = 404. The rasterizer emits the last, fragment 99, once fragment 99 - 24 = 75 has
    // left the FIFO, in 4 + 4 * 75 = 304 = T_w: 100 cycles of work are ahead of the end
    // token. No reads, so no last read latency; the records, 16 * 8 = 128 words, take
    // 128 / 8 = 16 port cycles; the OccU binds, so the token's first 3 cycles (out of the
    // FIFO, through the depth pipeline, into the OccU) pass within the backlog: latency
    // 4 + 16 + 100 - 3 = 117, total 304 + 117 = 421.
    let mut arch = Arch::builtin("o2").unwrap();
    arch.set("display_refresh_hz=0").unwrap();
    arch.set("host_memory_share=0").unwrap();
    let tiles = (0..16)
        .map(|t| Rect::new(4 * (t % 4), 4 * (t / 4), 4, 4))
        .collect();
    let spec = QuerySpec {
        id: 1,
        mode: QueryMode::Brief,
        buffer_entries: 8,
        tiles,
    };
    let mut events = vec![
        Event::DepthTest(false),
        Event::QueryBegin(spec),
        Event::Primitive,
    ];
    events.extend((0..100u16).map(|i| {
        Event::Fragment(Fragment {
            x: i % 16,
            y: i / 16,
            z: 7,
        })
    }));
    events.push(Event::QueryEnd);
    let run = |level| run_level(level, &arch, 16, 16, EffectsChoice::Auto, &events).unwrap();
    let analytic = run(Fidelity::Analytic);
    assert_eq!(analytic.queries[0].latency_cycles, Some(117));
    assert_eq!(analytic.total_cycles, Some(421));
    // The machine agrees (the half-full FIFOs of the formulas before the fluid gave a
    // backlog of 12 fragments, 48 cycles, and a latency of 68; without the token's overlap,
    // 120).
    let cycle = run(Fidelity::Cycle);
    assert_eq!(cycle.queries[0].latency_cycles, Some(117));
}

/// A brief query whose one primitive begins with a one-pixel column, a new depth word
/// every fragment, then rows that read one word in 8: the column's reads outrun the port.
fn sliver_then_rows() -> Vec<Event> {
    let spec = QuerySpec {
        id: 1,
        mode: QueryMode::Brief,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, 16, 64)],
    };
    let mut events = vec![
        Event::DepthTest(true),
        Event::QueryBegin(spec),
        Event::Primitive,
    ];
    let column = (0..40u16).map(|y| (0, y));
    let rows = (40..64u16).flat_map(|y| (8..16u16).map(move |x| (x, y)));
    events.extend(
        column
            .chain(rows)
            .map(|(x, y)| Event::Fragment(Fragment { x, y, z: 7 })),
    );
    events.push(Event::QueryEnd);
    events
}

#[test]
fn analytic_o2_keeps_the_lag_a_sliver_of_reads_leaves() {
    // The O2 as built: the display refresh and the host need f = 0.23432 of the port's
    // cycles (1280 * 1024 * 32 * 75 / (256 * 66.67e6) + 0.05) and may fall 16 cycles
    // behind. The column's 40 reads and the first row's (a new word right after it), 41 in
    // a row, leave them 41 f = 9.6 behind: no cycle is forced, the reads keep pace with the
    // rasterizer, and the depth test trails it only by its slowest read (the first, a page
    // miss: 8). Latency 4 + 1 (the record's port cycle) + 8 = 13.
    let events = sliver_then_rows();
    let latencies = |slack: u32| {
        let mut arch = Arch::builtin("o2").unwrap();
        arch.set(&format!("other_clients_slack_cycles={slack}"))
            .unwrap();
        let run = |level| run_level(level, &arch, 16, 64, EffectsChoice::Auto, &events).unwrap();
        [Fidelity::Analytic, Fidelity::Cycle].map(|level| run(level).queries[0].latency_cycles)
    };
    assert_eq!(latencies(16), [Some(13), Some(13)]);
    // With a slack of 1 cycle they take every cycle past it: the 41 reads take
    // max(41, c (41 + 0 - 1)) port cycles, c = 1 / (1 - f) = 1.30603, so the run leaves the
    // depth test 41 c - 41 - c = 11.24 cycles behind the rasterizer, and its last read's
    // data comes a page hit (2) later; the rows after it, 8 fragments and one read each,
    // never let it catch up (no block is faster than the rasterizer's fragment a cycle).
    // Summed over the primitive, 64 reads in 232 fragments would have hidden the lag.
    // Latency ceil(4 + 1 + 11.24 + 2) = 19, the machine's.
    assert_eq!(latencies(1), [Some(19), Some(19)]);
}

#[test]
fn analytic_reaches_the_minimum_latency_on_an_idle_ir() {
    // ir4: a one-tile query over no fragments. Every Image Engine's report (8 words) is
    // ready 3 cycles after the end token; the local tree over 80 Image Engines is
    // ceil(log2 80) = 7 hops, each 8 words over a 32-bit link (8 cycles) and 2 of latency;
    // the global tree over 4 boards 2 hops of 8 words over 64 bits (4) and 8 of latency; the
    // DMA of the final 8 words at 16 bits a cycle 16: 3 + 7 * 10 + 2 * 12 + 16 = 113.
    let arch = Arch::builtin("ir4").unwrap();
    let events = one_empty_query();
    for level in [Fidelity::Analytic, Fidelity::Cycle] {
        let result = run_level(level, &arch, 16, 16, EffectsChoice::Auto, &events).unwrap();
        assert_eq!(result.queries[0].latency_cycles, Some(113), "{level}");
    }
}

#[test]
fn analytic_ir_times_a_lone_fragment_as_the_machine_does() {
    // ir2 on a 160x120 viewport, one primitive of one fragment under a one-tile query. The
    // generators set the primitive up in cycles 0-3 and board 0's emits the fragment in 4:
    // the end token enters in 5. Its Image Engine starts the depth test in 5, the result
    // reaches the OccU 16 later, in 21, which counts it (s = 1); the token passes the depth
    // stage in 21, the OccU in 22, and the report is ready in 23: a drain of 18. The local
    // tree over 80 Image Engines, ceil(log2 80) = 7 hops of 8 words over 32 bits (8) and 2
    // of latency, 70; the global tree over 2 boards, one hop of 8 words over 64 bits (4) and
    // 8 of latency, and the DMA of 8 words at 16 bits a cycle (16), 28. Latency 18 + 70 + 28
    // = 116, total 5 + 116 = 121. The formulas: d = 4 + 11 (one slot a fragment at 2 a
    // cycle, rounded up) = 16, the last result in 16 - 11 + 16 + 1 + 1 = 23: the same. (They
    // once capped the backlog at the window's 5 cycles of work, giving 106.)
    let arch = Arch::builtin("ir2").unwrap();
    let spec = QuerySpec {
        id: 1,
        mode: QueryMode::Samples,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, 160, 120)],
    };
    let events = [
        Event::QueryBegin(spec),
        Event::Primitive,
        Event::Fragment(Fragment { x: 0, y: 0, z: 7 }),
        Event::QueryEnd,
    ];
    for level in [Fidelity::Analytic, Fidelity::Cycle] {
        let result = run_level(level, &arch, 160, 120, EffectsChoice::Auto, &events).unwrap();
        assert_eq!(result.queries[0].latency_cycles, Some(116), "{level}");
        assert_eq!(result.total_cycles, Some(121), "{level}");
    }
}

/// ir1 with 2 Image Engines (columns: even x to 0, odd x to 1) and an unpipelined 45-cycle
/// depth stage (interval = latency = 45), and a one-tile samples query over one primitive
/// of 20 fragments for each column in `columns`, in turn.
fn two_engine_ir_stream(columns: &[u16]) -> (Arch, Vec<Event>) {
    let mut arch = Arch::builtin("ir1").unwrap();
    arch.set("image_engines_per_board=2").unwrap();
    arch.set("image_engine_cycles_per_fragment=45").unwrap();
    arch.set("image_engine_latency_cycles=45").unwrap();
    let spec = QuerySpec {
        id: 1,
        mode: QueryMode::Samples,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, 16, 32)],
    };
    let mut events = vec![Event::QueryBegin(spec)];
    for &x in columns {
        events.push(Event::Primitive);
        events.extend((0..20).map(|y| Event::Fragment(Fragment { x, y, z: 7 })));
    }
    events.push(Event::QueryEnd);
    (arch, events)
}

/// (total cycles, the query's latency) at `level`.
fn cycles_and_latency(level: Fidelity, arch: &Arch, events: &[Event]) -> (u64, u64) {
    let result = run_level(level, arch, 16, 32, EffectsChoice::Auto, events).unwrap();
    (
        result.total_cycles.unwrap(),
        result.queries[0].latency_cycles.unwrap(),
    )
}

#[test]
fn analytic_ir_sees_the_busiest_image_engine() {
    // ir1 with 2 Image Engines (columns: even x to 0, odd x to 1), an unpipelined 45-cycle
    // depth stage, FIFOs of 8: one primitive of 20 fragments, all in column 0, under a
    // one-tile query (s = 1), so pace = 45.
    //
    // The formulas (module docs of `levels::analytic::ir`): start = setup 4, emit = 4 +
    // ceil(20 / 2) = 14; the engine is through its depth stage at d = max(4 + 20 · 45, 14 +
    // 45) = 904; the generator may run (E + 1) C - 1 = 9 * 45 - 1 = 404 cycles ahead of it
    // (a fragment goes once the one 8 before it left the FIFO), so g = max(14, 904 - 404) =
    // 500 = T_w. Its last result: d - 45 + L 45 + s 1 + 1 = 906, so its report is ready in
    // 906; one hop in the local tree (its 8 words over a 32-bit link, 8, and 2 of latency),
    // no global hop for one board, and the DMA of 8 words at 16 bits a cycle, 16: available
    // 932, latency 932 - 500 = 432.
    //
    // The machine (rules of `blocks::image_engine`): fragment k starts its depth test in
    // s_k = 5 + 45 k (emitted from cycle 4, P = 1), so s_19 = 860 and its result is counted
    // in 905; fragment 19 is emitted when fragment 11 leaves the FIFO, in s_11 = 500, so the
    // end token enters in 501. The token passes the depth stage in 905, the OccU in 906, and
    // the report is ready in 907: available 907 + 10 + 16 = 933, latency 432. The formulas'
    // window is 1 cycle short of the machine's, their latency exact (with Q = 8 + ceil(45 /
    // 45) = 9 fragments, 405 cycles, for the generator's lead: 499 and 433).
    let (arch, events) = two_engine_ir_stream(&[0]);
    assert_eq!(
        cycles_and_latency(Fidelity::Analytic, &arch, &events),
        (500 + 432, 432)
    );
    assert_eq!(
        cycles_and_latency(Fidelity::Cycle, &arch, &events),
        (501 + 432, 432)
    );
}

/// The stream of `analytic_ir_sees_the_busiest_image_engine` under a verbose query whose
/// tile buffer holds 10 entries: 8 for the record, room for 2 hits. Engine 0's 20 passing
/// fragments send 2 hits and overflow the buffer, as the machine's Occlusion Unit does, so
/// its report is 8 + 2 words, not 8 + 20: the formulas' latency is the machine's, 432 + 2
/// cycles for the 2 words over the local link and 2 * 2 for the DMA at 16 bits a cycle =
/// 438. Counting every hit, they gave the 18 words more 54 cycles more.
#[test]
fn analytic_ir_caps_each_tiles_hits_at_its_buffers_room() {
    let (arch, mut events) = two_engine_ir_stream(&[0]);
    events[0] = Event::QueryBegin(QuerySpec {
        id: 1,
        mode: QueryMode::Verbose,
        buffer_entries: 10,
        tiles: vec![Rect::new(0, 0, 16, 32)],
    });
    let (_, analytic) = cycles_and_latency(Fidelity::Analytic, &arch, &events);
    let (_, cycle) = cycles_and_latency(Fidelity::Cycle, &arch, &events);
    assert_eq!((analytic, cycle), (438, 438));
}

#[test]
fn analytic_ir_overlaps_one_primitive_with_the_next() {
    // As above, then a second primitive of 20 fragments all in column 1. Engine 0 still has
    // 404 cycles of the first primitive's work when the generator moves on; engine 1 takes
    // the second primitive meanwhile. Summing each primitive's own cycles (500 + 500) would
    // miss that overlap and the backlog the first leaves; the formulas carry both:
    // the second starts at g = 500 + setup 4 = 504 and is emitted by 514; engine 1 is through
    // in d = 504 + 900 = 1404 and holds 404 of it, so T_w = 1000. Its last result: 1404 - 45
    // + 47 = 1406; engine 0's, 906, is long done. Available 1406 + 10 + 16 = 1432, latency
    // 432, total 1432.
    //
    // The machine: the generator is free in 501 and sets the second primitive up until 505;
    // engine 1 starts fragment k in 506 + 45 k, so fragment 19 of it is emitted when
    // fragment 11 leaves the FIFO, in 1001: the token enters in 1002. Fragment 19 starts in
    // 1361 and is counted in 1406; the report is ready in 1408, available 1434, latency 432.
    let (arch, events) = two_engine_ir_stream(&[0, 1]);
    assert_eq!(
        cycles_and_latency(Fidelity::Analytic, &arch, &events),
        (1000 + 432, 432)
    );
    assert_eq!(
        cycles_and_latency(Fidelity::Cycle, &arch, &events),
        (1002 + 432, 432)
    );
}

#[test]
fn effects_forced_and_automatic_give_the_same_report_on_builtin_traces() {
    for (name, (events, width, height)) in builtin_traces() {
        for arch in archs() {
            let automatic = observe(&arch, width, height, &events).unwrap();
            let forced = replay(&arch, width, height, Effects::ALL, &events);
            let chosen = replay(&arch, width, height, automatic, &events);
            assert_eq!(chosen, forced, "{name}: effects {automatic:?}");
        }
    }
}

#[test]
fn the_scan_switches_effects_off_on_the_builtin_traces() {
    // Hard cases: a 64x64 viewport inside one 128x128 page; no verbose query.
    let arch = Arch::builtin("o2").unwrap();
    let (events, width, height) = scene_events(HARDCASES);
    let effects = observe(&arch, width, height, &events).unwrap();
    assert!(!effects.page_model);
    assert!(effects.depth_write_traffic);
    let (events, width, height) = small_random();
    let effects = observe(&arch, width, height, &events).unwrap();
    assert!(
        !effects.verbose_hit_writes,
        "the random scene has samples queries only"
    );
    assert!(effects.page_model);
}

use occsim_traces::rng::SplitMix64;

/// A random stream over a `width` x `height` viewport with state changes and every mode.
fn random_stream(seed: u64, width: u32, height: u32) -> Vec<Event> {
    let mut rng = SplitMix64(seed);
    let mut golden = FunctionalModel::new(width, height);
    let mut events = Vec::new();
    let mut push = |event: Event, events: &mut Vec<Event>| {
        let result = golden.event(&event);
        events.push(event);
        if let Some(result) = result {
            events.push(Event::QueryResult(result));
        }
    };
    for query in 0..(1 + rng.below(6)) {
        match rng.below(5) {
            0 => push(Event::Clear, &mut events),
            1 => push(
                Event::DepthFunc(DepthFunc::ALL[rng.below(8) as usize]),
                &mut events,
            ),
            2 => push(Event::DepthMask(rng.below(3) == 0), &mut events),
            3 => push(Event::DepthTest(rng.below(4) != 0), &mut events),
            _ => {}
        }
        let in_query = rng.below(4) != 0;
        if in_query {
            let mode = QueryMode::ALL[rng.below(4) as usize];
            let tiles = match mode {
                QueryMode::Samples | QueryMode::Any => vec![Rect::new(0, 0, width, height)],
                _ => (0..1 + rng.below(12))
                    .map(|_| {
                        let x = rng.below(width as u64) as u32;
                        let y = rng.below(height as u64) as u32;
                        Rect::new(
                            x,
                            y,
                            1 + rng.below((width - x) as u64) as u32,
                            1 + rng.below((height - y) as u64) as u32,
                        )
                    })
                    .collect(),
            };
            push(
                Event::QueryBegin(QuerySpec {
                    id: query as u32,
                    mode,
                    buffer_entries: 8 + rng.below(10) as u32,
                    tiles,
                }),
                &mut events,
            );
        }
        for _ in 0..rng.below(5) {
            push(Event::Primitive, &mut events);
            let y = rng.below(height as u64) as u16;
            let x0 = rng.below(width as u64) as u16;
            let z = rng.below(64) as u32 * 1000;
            for x in x0..(x0 + 1 + rng.below(40) as u16).min(width as u16) {
                push(Event::Fragment(Fragment { x, y, z }), &mut events);
            }
        }
        if in_query {
            push(Event::QueryEnd, &mut events);
        }
    }
    events
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn effects_forced_and_automatic_agree_on_random_streams(
        seed in any::<u64>(),
        engines in 1u64..6,
        small_viewport in any::<bool>(),
    ) {
        let (width, height) = if small_viewport { (100, 90) } else { (300, 140) };
        let events = random_stream(seed, width, height);
        let mut arch = if small_viewport { small_ir() } else { Arch::builtin("o2").unwrap() };
        arch.set(&format!("engines={engines}")).unwrap();
        let automatic = observe(&arch, width, height, &events).unwrap();
        let forced = replay(&arch, width, height, Effects::ALL, &events);
        let chosen = replay(&arch, width, height, automatic, &events);
        prop_assert_eq!(chosen, forced);
    }

    #[test]
    fn every_level_counts_exactly_on_random_streams(seed in any::<u64>()) {
        let events = random_stream(seed, 64, 64);
        let arch = Arch::builtin("o2").unwrap();
        let golden = golden_values(&events);
        for arch in [arch.clone(), small_ir()] {
            for level in [Fidelity::Functional, Fidelity::Analytic, Fidelity::Sampled { every: 2 }, Fidelity::Sampled { every: 3 }, Fidelity::Cycle] {
                let result = run_level(level, &arch, 64, 64, EffectsChoice::Auto, &events).unwrap();
                let values: Vec<u64> = result.queries.iter().map(|q| q.value).collect();
                prop_assert_eq!(&values, &golden);
            }
        }
        let cycle = run_level(Fidelity::Cycle, &arch, 64, 64, EffectsChoice::Auto, &events).unwrap();
        let every_window =
            run_level(Fidelity::Sampled { every: 1 }, &arch, 64, 64, EffectsChoice::Auto, &events)
                .unwrap();
        prop_assert_eq!(every_window.total_cycles, cycle.total_cycles);
        prop_assert_eq!(every_window.queries, cycle.queries);
    }
}

/// `events` written as a trace file would be (the header's features written back), and the
/// header's features read back.
fn header_features(events: &[Event], width: u32, height: u32) -> TraceFeatures {
    let mut file = std::io::Cursor::new(Vec::new());
    let mut writer = TraceWriter::new(&mut file, &TraceHeader::new(width, height)).unwrap();
    events.iter().for_each(|event| writer.event(event).unwrap());
    writer.finish_seekable().unwrap();
    let reader = TraceReader::new(&file.get_ref()[..]).unwrap();
    reader.header().features.clone().expect("written back")
}

#[test]
fn the_header_decides_the_effects_as_the_scan_does() {
    for (name, (events, width, height)) in builtin_traces() {
        let features = header_features(&events, width, height);
        for arch in archs() {
            let scanned = observe(&arch, width, height, &events).unwrap();
            let from_header = effects_of_features(&arch, width, height, Some(&features))
                .unwrap()
                .expect("the header has the facts");
            assert_eq!(from_header, scanned, "{name} on {}", arch.machine().name());
        }
    }
    // Without the facts (an older trace), the header decides nothing: scan.
    let older = TraceFeatures::default();
    let arch = Arch::builtin("o2").unwrap();
    assert_eq!(
        effects_of_features(&arch, 64, 64, Some(&older)).unwrap(),
        None
    );
    assert_eq!(effects_of_features(&arch, 64, 64, None).unwrap(), None);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn header_facts_equal_scanned_facts_on_random_streams(seed in any::<u64>()) {
        let events = random_stream(seed, 100, 90);
        let features = header_features(&events, 100, 90);
        let arch = Arch::builtin("o2").unwrap();
        let mut scan = EffectScan::for_arch(&arch, 100, 90).unwrap();
        events.iter().for_each(|event| scan.event(event));
        prop_assert_eq!(TraceFacts::from_features(&features), Some(scan.facts()));
    }
}

/// Three frames of the demo (it waits on every occlusion test and swaps at each frame's end).
fn closed_loop_demo() -> (Vec<Event>, u32, u32) {
    scene_events(&demo_scene(&DemoOptions {
        width: 320,
        height: 256,
        frames: 3,
        lots_per_side: 8,
        ..DemoOptions::default()
    }))
}

#[test]
fn every_timed_level_times_the_frames_of_a_closed_loop_trace() {
    let stream = closed_loop_demo();
    for arch in [Arch::builtin("o2").unwrap(), small_ir()] {
        let name = arch.machine().name();
        let run = |level: &str| run_at(level, &arch, &stream);
        let cycle = run("cycle");
        assert_eq!(cycle.frame_cycles.len(), 3, "{name}");
        // One machine over the whole stream: sampled:1 measures every frame as cycle does.
        assert_eq!(run("sampled:1").frame_cycles, cycle.frame_cycles, "{name}");
        assert_eq!(run("rtl").frame_cycles, cycle.frame_cycles, "{name}");
        for level in ["analytic", "sampled:3"] {
            let result = run(level);
            assert_eq!(result.frame_cycles.len(), 3, "{name} {level}");
            // The frames partition the run.
            let sum: u64 = result.frame_cycles.iter().sum();
            let total = result.total_cycles.unwrap();
            assert!(
                sum.abs_diff(total) <= 3,
                "{name} {level}: {sum} against {total}"
            );
            // The mean frame's error against cycle, bounded at 5% here (`occsim fidelity` shows
            // it on any trace: 0.04% for analytic and 0.00% for sampled:10 on the full demo).
            let error = (result.frame_mean_cycles().unwrap() - cycle.frame_mean_cycles().unwrap())
                .abs()
                / cycle.frame_mean_cycles().unwrap();
            assert!(error < 0.05, "{name} {level}: frame time error {error}");
            assert!(result.frames_per_second.is_some());
        }
        assert!(
            run("functional").frame_cycles.is_empty(),
            "no time, no frames"
        );
    }
}

/// The sampled level's extrapolated query latencies keep the waits the formulas see. On
/// hardcases three of 28 windows are simulated at sampled:10, none of them one of the six
/// queries that wait behind a clear (1,344 to 2,721 cycles at cycle level); a mean over the
/// three sampled queries (about 19 cycles) put the mean latency 96% low on the O2. The
/// regression on the formulas' latency keeps it within 1.7% (o2) and 5.5% (ir4) on the
/// whole `trace gen hardcases` trace (`occsim fidelity hc.occt --no-rtl`); bounded here at 10%.
#[test]
fn sampled_latency_keeps_the_waits_behind_clears() {
    let stream = scene_events(HARDCASES);
    for arch in [Arch::builtin("o2").unwrap(), Arch::builtin("ir4").unwrap()] {
        let name = arch.machine().name();
        let mean_latency = |level: &str| {
            let result = run_at(level, &arch, &stream);
            let latencies: Vec<u64> = result
                .queries
                .iter()
                .map(|q| q.latency_cycles.unwrap())
                .collect();
            latencies.iter().sum::<u64>() as f64 / latencies.len() as f64
        };
        let cycle = mean_latency("cycle");
        let sampled = mean_latency("sampled:10");
        let error = (sampled - cycle).abs() / cycle;
        assert!(
            error < 0.10,
            "{name}: sampled:10 mean latency {sampled} against cycle's {cycle}"
        );
    }
}

/// A query whose end token the host releases long after the pipe finished its fragments
/// drains an empty pipe: the analytic level must not add the window's FIFO backlog or last
/// read to its latency. The triangle's 2,080 fragments take the O2 about 2,100 cycles; the
/// host's 20,000 nodes before `end` take far longer, so the token finds the pipe idle. Its
/// one brief record (8 words, one 256-bit port cycle, rounded up over the port's reserved
/// share to 2) gives the O2's analytic latency 4 + 2 = 6, where the cycle level measures 5;
/// on ir2 both give the Image Engines' and merges' fixed path.
#[test]
fn analytic_latency_of_a_token_the_host_releases_late_has_no_backlog() {
    let stream = scene_events(
        "viewport 64 64\nclear\nbegin 1 brief\n\
         tri -1 -1 0.5 1  1 -1 0.5 1  -1 1 0.5 1\nhost nodes=20000\nend\nwait 1\nswap\n",
    );
    for arch in [Arch::builtin("o2").unwrap(), Arch::builtin("ir2").unwrap()] {
        let name = arch.machine().name();
        let latency = |level: &str| {
            run_at(level, &arch, &stream).queries[0]
                .latency_cycles
                .unwrap()
        };
        let (analytic, cycle) = (latency("analytic"), latency("cycle"));
        assert!(
            analytic.abs_diff(cycle) <= 1,
            "{name}: analytic {analytic} against cycle {cycle}"
        );
    }
}

/// A draw whose geometry the Geometry Engines release over far longer than its fragments
/// take: the pipe cannot finish before the last primitive arrives. 400 one-pixel triangles
/// in one draw on ir1 cost 1,200 vertices of geometry but 400 fragments; predicted whole from
/// the first primitive's release, the window ended long before the last release and the
/// analytic frame came out short (20.7% on a frustum walk of the city); ending it no
/// earlier than its last primitive's release puts it within 1% of cycle here.
#[test]
fn a_predicted_window_ends_no_earlier_than_its_last_primitive_arrives() {
    let mut scene = String::from("viewport 64 64\nclear\n");
    for k in 0..400 {
        // A pixel-sized triangle round pixel centre (x + 0.5, y + 0.5): clip = 2 p / 64 - 1.
        let (x, y) = ((k % 20) as f32 * 3.0, (k / 20) as f32 * 3.0);
        let clip = |p: f32| 2.0 * p / 64.0 - 1.0;
        scene += &format!(
            "tri {} {} 0.5 1  {} {} 0.5 1  {} {} 0.5 1\n",
            clip(x),
            clip(y),
            clip(x + 1.5),
            clip(y),
            clip(x),
            clip(y + 1.5)
        );
    }
    scene += "swap\n";
    let stream = scene_events(&scene);
    let ir1 = Arch::builtin("ir1").unwrap();
    let frame = |level: &str| run_at(level, &ir1, &stream).frame_cycles[0] as f64;
    let (analytic, cycle) = (frame("analytic"), frame("cycle"));
    assert!(
        (analytic - cycle).abs() / cycle < 0.01,
        "analytic frame {analytic} against cycle's {cycle}"
    );
}

/// A scene of `frames` frames on a 256x256 viewport, each a brief query of 256 tiles (a
/// 16x16 grid of 16x16 tiles) over a small triangle, then a one-tile query over another,
/// then a swap.
fn many_tile_queries_then_swaps(frames: u32) -> String {
    let grid: String = (0..256)
        .map(|k| format!(" tile={},{},16,16", k % 16 * 16, k / 16 * 16))
        .collect();
    let triangle = "tri -1 -1 0 1  -0.9 -1 0 1  -0.9 -0.9 0 1\n";
    let mut scene = String::from("viewport 256 256\n");
    for frame in 0..frames {
        scene += &format!(
            "clear\nbegin {} brief{grid}\n{triangle}end\n",
            2 * frame + 1
        );
        scene += &format!("begin {} brief\n{triangle}end\nswap\n", 2 * frame + 2);
    }
    scene
}

#[test]
fn a_merge_that_outlasts_the_windows_after_it_holds_the_frame_and_the_run_at_every_level() {
    // On ir4 a 256-tile query's report crosses both merge stages: 256 tiles x 8 words from
    // each of 320 Image Engines, some 21,000 cycles (README, Latency), where its window and
    // the one-tile query's after it take a few hundred. The cycle level ends each frame,
    // and the run, when that merge is done; the analytic and sampled levels had ended them
    // at the last query's answer (the one-tile query's, thousands of cycles earlier) or,
    // sampled, at the last window's cost: 4,644 cycles for three such frames at sampled:2,
    // where the machine takes 68,286, and double those at sampled:3 (110,620).
    let stream = scene_events(&many_tile_queries_then_swaps(3));
    let arch = Arch::builtin("ir4").unwrap();
    let cycle = run_at("cycle", &arch, &stream);
    let cycle_total = cycle.total_cycles.unwrap() as f64;
    assert!(cycle_total > 3.0 * 20_000.0, "{cycle_total}");
    let cycle_frames = cycle.frame_cycles.clone();
    assert_eq!(cycle_frames.len(), 3);
    for level in ["analytic", "sampled:2", "sampled:3", "sampled:10"] {
        let result = run_at(level, &arch, &stream);
        let total = result.total_cycles.unwrap() as f64;
        assert!(
            (total - cycle_total).abs() <= 0.01 * cycle_total,
            "{level}: {total} cycles against {cycle_total}"
        );
        let frames = result.frame_cycles;
        assert_eq!(frames.len(), cycle_frames.len(), "{level}");
        for (frame, cycle_frame) in frames.iter().zip(&cycle_frames) {
            let (frame, cycle_frame) = (*frame as f64, *cycle_frame as f64);
            assert!(
                (frame - cycle_frame).abs() <= 0.01 * cycle_frame,
                "{level}: frames {frames:?} against {cycle_frames:?}"
            );
        }
    }
}

#[test]
fn a_query_that_draws_no_primitive_costs_the_sampled_level_what_it_costs_the_machine() {
    // Thirty pairs of queries on a 64x64 viewport: a 16x16 triangle, then the same triangle
    // back-facing under `cull 1` (no primitive reaches the pipe). The culled query's window
    // held only the host's time for its commands; the predicted timeline ended it where
    // the pipe's work had ended and gave that time to the next window, where the machine
    // ends a window at its end token's entry, after the host's time: sampled:2 on o2 was
    // 45.7% short, on ir4 42.0% (the analytic level exact). Every sampled level is held to
    // sampled:K's 1% target.
    let front =
        "tri -0.734375 -0.734375 0.0 1  -0.234375 -0.734375 0.0 1  -0.234375 -0.234375 0.0 1";
    let back =
        "tri -0.734375 -0.734375 0.0 1  -0.234375 -0.234375 0.0 1  -0.234375 -0.734375 0.0 1";
    let mut scene = String::from("viewport 64 64\ncull 1\n");
    for pair in 0..30 {
        scene += &format!("begin {}\n{front}\nend\n", 2 * pair + 1);
        scene += &format!("begin {}\n{back}\nend\n", 2 * pair + 2);
    }
    let stream = scene_events(&scene);
    for arch in ["o2", "ir4"] {
        let arch = Arch::builtin(arch).unwrap();
        let cycle = run_at("cycle", &arch, &stream).total_cycles.unwrap() as f64;
        for level in ["analytic", "sampled:2", "sampled:3", "sampled:10"] {
            let total = run_at(level, &arch, &stream).total_cycles.unwrap() as f64;
            assert!(
                (total - cycle).abs() <= 0.01 * cycle,
                "{} {level}: {total} cycles against {cycle}",
                arch.machine().name()
            );
        }
    }
}
