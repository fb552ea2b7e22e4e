//! Hand-worked closed-loop timings: the host and the geometry stage ahead of the pipeline,
//! waits, conditionals and frames, on both machines. Expected cycles are derived in the
//! comments from the rules in `sim/src/machines/closed_loop.rs`,
//! `sim/src/blocks/host.rs` and `sim/src/blocks/geometry.rs`; where an expectation needs
//! the pipeline's own result latency (tested by `o2_timing.rs` and `ir_timing.rs`), it is
//! read from the report's `available_cycle` and the host's part is added by hand.

use occsim_sim::machines::MachineBuilder;
use occsim_sim::{Arch, Report};
use occsim_traces::builtin::{demo_scene, DemoOptions};

mod support;
use occsim_traces::{
    Event, Fragment, GeometryBatch, QueryMode, QueryResult, QuerySpec, Rect, TileResult,
};

fn arch(name: &str, sets: &[&str]) -> Arch {
    let mut arch = Arch::builtin(name).unwrap();
    for set in sets {
        arch.set(set).unwrap();
    }
    arch
}

fn run(arch: &Arch, events: &[Event]) -> Report {
    let mut machine = MachineBuilder::new(arch).build(8, 8).unwrap();
    for event in events {
        machine.event(event).unwrap();
    }
    machine.finish().unwrap()
}

fn batch() -> Event {
    Event::Geometry(GeometryBatch {
        vertices: 3,
        triangles: 1,
        starts_draw: true,
        discarded: false,
    })
}

fn begin(id: u32) -> Event {
    Event::QueryBegin(QuerySpec {
        id,
        mode: QueryMode::Samples,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, 8, 8)],
    })
}

/// A query of one draw of one triangle covering pixel (x, 0), depth test off.
fn query_of_one_draw(id: u32, x: u16) -> Vec<Event> {
    vec![
        begin(id),
        batch(),
        Event::Primitive,
        Event::Fragment(Fragment { x, y: 0, z: 7 }),
        Event::QueryEnd,
    ]
}

/// The O2 with a host at the pipeline's clock (a host cycle is a pipeline cycle), a state
/// change costing 10, a draw 100, a vertex 10, a triangle nothing, notification 8 and a
/// word 1.
fn o2() -> Arch {
    arch(
        "o2",
        &[
            "host_clock_mhz=66.67",
            "host_cycles_per_state_change=10",
            "host_cycles_per_draw=100",
            "geometry_host_cycles_per_vertex=10",
            "geometry_host_cycles_per_triangle=0",
            "result_notify_latency_cycles=8",
            "result_read_cycles_per_word=1",
        ],
    )
}

fn query(report: &Report, id: u32) -> &occsim_sim::report::QueryReport {
    report.queries.iter().find(|q| q.id == id).unwrap()
}

#[test]
fn o2_a_query_a_wait_and_a_dependent_draw() {
    let mut events = vec![Event::DepthTest(false)];
    events.extend(query_of_one_draw(1, 0));
    events.push(Event::Wait(1));
    events.extend(query_of_one_draw(2, 1));
    events.push(Event::Swap);
    let report = run(&o2(), &events);
    // `depth_test 0` and `begin 1` wait (20) for the first closed-loop record, the draw's
    // batch: then the driver's 100 and the geometry, 3 vertices * 10 = 30: the primitive is
    // released at 150; setup 4 cycles (150..=153), the fragment emitted in 154 (the
    // rasterizer free at 155); `end` costs the host 10 more, so the token enters at 160.
    let first = query(&report, 1);
    assert_eq!(first.end_cycle, 160);
    // The wait: the host sees the result 8 after it is available and reads one brief
    // record (8 words, 1 each); then `begin 2` 10, draw 2 130, `end` 10: the token enters
    // when the host issues it, 150 after the wait (the rasterizer is free at 145).
    let host_after_wait = first.available_cycle + 8 + 8;
    let second = query(&report, 2);
    assert_eq!(second.end_cycle, host_after_wait + 150);
    assert!(
        second.end_cycle > first.available_cycle,
        "no draw before the answer"
    );
    // One frame, ending when the pipeline is done with the second query; on the host's
    // timeline: busy 20 + 130 + 10 + 8 + 10 + 130 + 10, waiting from 160 until the result
    // is seen.
    assert_eq!(report.frames.len(), 1);
    let frame = &report.frames[0];
    assert_eq!(frame.cycles, report.summary.cycles);
    assert_eq!(frame.cycles, second.available_cycle);
    assert_eq!(frame.host_busy, 20 + 130 + 10 + 8 + 10 + 130 + 10);
    assert_eq!(frame.geometry_busy, 60);
    assert_eq!(frame.waiting, first.available_cycle + 8 - 160);
    assert_eq!(
        frame.host_busy + frame.waiting + frame.pipe_wait,
        frame.cycles
    );
    // Both primitives' 4 setup cycles and both emissions.
    assert_eq!(frame.pixel_busy, 2 * (4 + 1));
    assert!(report.summary.frames_per_second.is_some());
}

#[test]
fn o2_a_predicated_draw_holds_the_pipe_but_not_the_host() {
    // A host that costs nothing: only the conditional holds anything.
    let free_host = arch(
        "o2",
        &[
            "host_cycles_per_state_change=0",
            "host_cycles_per_draw=0",
            "geometry_host_cycles_per_vertex=0",
            "geometry_host_cycles_per_triangle=0",
            "result_notify_latency_cycles=8",
        ],
    );
    let mut events = vec![Event::DepthTest(false)];
    events.extend(query_of_one_draw(1, 0));
    events.push(Event::ConditionalBegin(1));
    events.extend(query_of_one_draw(2, 1));
    events.push(Event::ConditionalEnd);
    let report = run(&free_host, &events);
    let first = query(&report, 1);
    // Query 1: setup 0..=3, fragment in 4, end token at 5.
    assert_eq!(first.end_cycle, 5);
    // The second draw enters no earlier than the answer plus the notification: setup from
    // there, emission after 4, end token one later.
    let second = query(&report, 2);
    assert_eq!(second.end_cycle, first.available_cycle + 8 + 4 + 1);
    let frame = &report.frames[0];
    assert_eq!(frame.waiting, 0, "the host never blocked");
    assert_eq!(frame.host_busy, 0);
    // The host issued everything at 0 and blocked at the end for the pipeline.
    assert_eq!(frame.pipe_wait, frame.cycles);
}

#[test]
fn ir_a_query_a_wait_and_a_dependent_draw() {
    // One board, host, Geometry Engines and pipeline all at 100 MHz; no bus cost.
    let ir = arch(
        "ir1",
        &[
            "host_clock_mhz=100",
            "host_cycles_per_state_change=0",
            "host_cycles_per_draw=100",
            "bus_bytes_per_vertex=0",
            "geometry_engine_clock_mhz=100",
            "geometry_engine_cycles_per_vertex=10",
            "geometry_engine_cycles_per_triangle=0",
            "result_notify_latency_cycles=8",
            "result_read_cycles_per_word=1",
        ],
    );
    let mut events = vec![Event::DepthTest(false)];
    events.extend(query_of_one_draw(1, 0));
    events.push(Event::Wait(1));
    events.extend(query_of_one_draw(2, 1));
    let report = run(&ir, &events);
    // Draw 1: host 100, then a Geometry Engine 30 from 100: released at 130; the Fragment
    // Generator sets up 130..=133 and emits in 134, so the end token enters at 135.
    let first = query(&report, 1);
    assert_eq!(first.end_cycle, 135);
    // The wait: +8 notification, 8 words at 1; draw 2: host 100 (the engine then idle),
    // engine 30, setup 4, emission 1.
    let second = query(&report, 2);
    assert_eq!(
        second.end_cycle,
        first.available_cycle + 8 + 8 + 100 + 30 + 4 + 1
    );
    let frame = &report.frames[0];
    assert_eq!(
        frame.host_busy,
        100 + 8 + 100,
        "the engines are not the host"
    );
    assert_eq!(frame.geometry_busy, 60);
    assert_eq!(
        frame.host_busy + frame.waiting + frame.pipe_wait,
        frame.cycles
    );
}

/// A query window of two draws: one triangle covering pixel (0, 0), then one of
/// `vertices` vertices (a long batch for the geometry stage) and `triangles` triangles,
/// each covering all 64 pixels of the 8x8 viewport, depth test off.
fn window_with_a_late_draw(vertices: u32, triangles: u32) -> Vec<Event> {
    let mut events = vec![Event::DepthTest(false), begin(1), batch()];
    events.push(Event::Primitive);
    events.push(Event::Fragment(Fragment { x: 0, y: 0, z: 7 }));
    events.push(Event::Geometry(GeometryBatch {
        vertices,
        triangles,
        starts_draw: true,
        discarded: false,
    }));
    for _ in 0..triangles {
        events.push(Event::Primitive);
        for y in 0..8 {
            for x in 0..8 {
                events.push(Event::Fragment(Fragment { x, y, z: 7 }));
            }
        }
    }
    events.push(Event::QueryEnd);
    events
}

fn total_cycles(level: &str, arch: &Arch, events: &[Event]) -> u64 {
    let level = level.parse().unwrap();
    let choice = occsim_sim::effects::EffectsChoice::Auto;
    let result = occsim_sim::levels::run_level(level, arch, 8, 8, choice, events).unwrap();
    result.total_cycles.unwrap()
}

#[test]
fn the_analytic_level_sets_a_primitive_up_no_earlier_than_its_release_mid_window() {
    let events = window_with_a_late_draw(300, 1);
    let report = run(&o2(), &events);
    // `depth_test 0` and `begin 1` wait (20) for the first batch; draw 1 (100 + 3 * 10)
    // releases its primitive at 150, draw 2 (100 + 300 * 10) at 150 + 3100 = 3250. The
    // rasterizer, long done with the first, sets the second up 3250..=3253 and emits its
    // 64 fragments in 3254..=3317; the token (issued by the host at 3260) enters at 3318.
    assert_eq!(query(&report, 1).end_cycle, 3318);
    // The analytic level's window ends where the token enters, and the query's latency
    // follows: it once overlapped the 4 + 64 cycles with the geometry stage's 3100 and
    // ended the window at the release, 3250.
    let analytic = total_cycles("analytic", &o2(), &events);
    let cycle = report.summary.cycles;
    assert!(analytic >= 3318, "analytic {analytic}");
    assert!(
        analytic.abs_diff(cycle) <= 3,
        "analytic {analytic}, cycle {cycle}"
    );
    // The same on the InfiniteReality-like machine, whose Geometry Engines take the batch:
    // after its release, 50 triangles each give 8 fragments to each of the 8 Image Engines
    // owning the viewport's columns, 50 * 8 * 11 = 4,400 cycles of depth tests. Overlapped
    // with the Geometry Engine's 170,000 cycles they put the window 4,298 cycles short
    // (171,015 against 175,313); set up after the release, the formulas are within a few
    // cycles (4 when this test was written).
    let ir = arch(
        "ir1",
        &["host_cycles_per_draw=100", "bus_bytes_per_vertex=0"],
    );
    let events = window_with_a_late_draw(3000, 50);
    let cycle = run(&ir, &events).summary.cycles;
    let analytic = total_cycles("analytic", &ir, &events);
    assert!(
        analytic.abs_diff(cycle) <= 20,
        "analytic {analytic}, cycle {cycle}"
    );
}

/// The demo scene's events (as `occsim trace gen demo` makes them): with `closed_loop`, its
/// geometry batches but no waits and frame ends; without, none of the closed-loop records.
fn demo_events(closed_loop: bool) -> (u32, u32, Vec<Event>) {
    let text = demo_scene(&DemoOptions {
        width: 160,
        height: 120,
        frames: 2,
        lots_per_side: 6,
        ..DemoOptions::default()
    });
    let (width, height, events) = support::scene_events(&text);
    let keep = |e: &Event| {
        if matches!(e, Event::Wait(_) | Event::Swap) {
            return false;
        }
        closed_loop || !e.is_closed_loop_record()
    };
    (width, height, events.into_iter().filter(keep).collect())
}

#[test]
fn with_a_free_host_and_no_waits_frame_time_is_the_open_loop_cycle_count() {
    let (width, height, closed) = demo_events(true);
    let (_, _, open) = demo_events(false);
    assert!(closed.len() > open.len(), "the demo has geometry batches");
    for name in ["o2", "ir4"] {
        let free = arch(
            name,
            &[
                "host_cycles_per_state_change=0",
                "host_cycles_per_draw=0",
                "host_cycles_per_node=0",
                "host_cycles_per_box_test=0",
                "host_cycles_per_decision=0",
            ],
        );
        let free = match name {
            "o2" => {
                let mut a = free;
                a.set("geometry_host_cycles_per_vertex=0").unwrap();
                a.set("geometry_host_cycles_per_triangle=0").unwrap();
                a
            }
            _ => {
                let mut a = free;
                a.set("geometry_engine_cycles_per_vertex=0").unwrap();
                a.set("geometry_engine_cycles_per_triangle=0").unwrap();
                a.set("bus_bytes_per_vertex=0").unwrap();
                a
            }
        };
        let replay = |events: &[Event]| {
            let mut machine = MachineBuilder::new(&free).build(width, height).unwrap();
            for event in events {
                machine.event(event).unwrap();
            }
            machine.finish().unwrap()
        };
        let (closed, open) = (replay(&closed), replay(&open));
        assert!(open.frames.is_empty(), "{name}: no records, no frames");
        assert!(
            occsim_sim::LevelResult::from_report(open.clone(), occsim_sim::Effects::ALL)
                .to_text(false)
                .contains("open loop: the stream has no draws"),
            "{name}: the report says it was an open loop"
        );
        assert!(
            occsim_sim::LevelResult::from_report(closed.clone(), occsim_sim::Effects::ALL)
                .to_text(false)
                .contains("\n1 frame, "),
            "{name}"
        );
        assert_eq!(closed.frames.len(), 1, "{name}");
        assert_eq!(closed.frames[0].cycles, open.summary.cycles, "{name}");
        assert_eq!(closed.summary.cycles, open.summary.cycles, "{name}");
        assert_eq!(closed.queries, open.queries, "{name}");
    }
}

#[test]
fn more_engines_never_lengthen_a_frame_of_blocking_multi_tile_queries() {
    // Eight brief queries of 16 tiles over a 64x64 screen, each read back before the next
    // draw: the Occlusion Unit's tile loop is on the critical path.
    let tiles: Vec<Rect> = (0..16)
        .map(|i| Rect::new((i % 4) * 16, (i / 4) * 16, 16, 16))
        .collect();
    let mut events = Vec::new();
    for id in 0..8u32 {
        events.push(Event::QueryBegin(QuerySpec {
            id,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: tiles.clone(),
        }));
        events.push(batch());
        events.push(Event::Primitive);
        for x in 0..64u16 {
            events.push(Event::Fragment(Fragment {
                x,
                y: (id * 8) as u16,
                z: 100 + id,
            }));
        }
        events.push(Event::QueryEnd);
        events.push(Event::Wait(id));
    }
    events.push(Event::Swap);
    for name in ["o2", "ir4"] {
        let mut previous = u64::MAX;
        for engines in [1, 2, 4, 8, 16] {
            let a = arch(name, &[&format!("engines={engines}")]);
            let mut machine = MachineBuilder::new(&a).build(64, 64).unwrap();
            for event in &events {
                machine.event(event).unwrap();
            }
            let report = machine.finish().unwrap();
            assert_eq!(report.frames.len(), 1);
            assert!(
                report.frames[0].cycles <= previous,
                "{name}, {engines} engines: {} > {previous}",
                report.frames[0].cycles
            );
            previous = report.frames[0].cycles;
        }
    }
}

#[test]
fn a_wait_for_a_query_that_never_ended_is_an_error_naming_the_event() {
    let mut machine = MachineBuilder::new(&o2()).build(8, 8).unwrap();
    let error = machine.event(&Event::Wait(9)).unwrap_err().to_string();
    assert_eq!(
        error,
        "event 0: the host waits for query 9's result, but no query 9 has ended"
    );
}

#[test]
fn every_level_refuses_a_wait_for_a_query_that_never_ended() {
    use occsim_sim::levels::{run_level, Fidelity};
    let events = [
        Event::DepthTest(false),
        begin(1),
        Event::QueryEnd,
        Event::Wait(9),
    ];
    for level in ["functional", "analytic", "sampled:2", "cycle", "rtl"] {
        let level: Fidelity = level.parse().unwrap();
        let error = run_level(
            level,
            &o2(),
            8,
            8,
            occsim_sim::effects::EffectsChoice::Auto,
            &events,
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            error, "event 3: the host waits for query 9's result, but no query 9 has ended",
            "{level}"
        );
    }
}

#[test]
fn golden_results_still_check_in_the_closed_loop() {
    // A wrong golden result is caught as in the open loop.
    let mut events = vec![Event::DepthTest(false)];
    events.extend(query_of_one_draw(1, 0));
    events.push(Event::QueryResult(QueryResult {
        id: 1,
        mode: QueryMode::Samples,
        tiles: vec![TileResult {
            nohc: 2,
            ..TileResult::default()
        }],
        overflowed_buffers: 0,
    }));
    let mut machine = MachineBuilder::new(&o2()).build(8, 8).unwrap();
    let outcome = events.iter().try_for_each(|e| machine.event(e));
    assert!(outcome.is_err() || machine.finish().is_err());
}
