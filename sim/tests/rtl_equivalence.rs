//! The `rtl` fidelity (the occsim-rtl model clocked every cycle) against the `cycle`
//! fidelity (event timestamps): the whole report, every count, cycle and latency, must be
//! identical, on built-in scenes and on random streams, on the O2 and on the
//! InfiniteReality (every Image Engine's unit the RTL, whose merged results, hit lists in
//! order, must be identical too); and the VCD waveform is well formed.

use occsim_sim::{Arch, MachineBuilder, OccuModel, Report, WaveformOptions};
use occsim_traces::builtin::{demo_scene, DemoOptions, HARDCASES};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{DepthFunc, Event, Fragment, QueryMode, QueryResult, QuerySpec, Rect};
use proptest::prelude::*;
use std::io::Write;
use std::sync::{Arc, Mutex};

fn arch(sets: &[String]) -> Arch {
    let mut arch = Arch::builtin("o2").unwrap();
    for set in sets {
        arch.set(set).unwrap();
    }
    arch
}

fn replay(arch: &Arch, width: u32, height: u32, events: &[Event], occu: OccuModel) -> Report {
    let mut machine = MachineBuilder::new(arch)
        .occu(occu)
        .build(width, height)
        .unwrap();
    for event in events {
        machine.event(event).unwrap();
    }
    machine.finish().unwrap()
}

/// Replay on both fidelities and insist on identical reports.
fn check_equivalent(arch: &Arch, width: u32, height: u32, events: &[Event]) -> Report {
    let cycle = replay(arch, width, height, events, OccuModel::Cycle);
    let rtl = replay(
        arch,
        width,
        height,
        events,
        OccuModel::Rtl { waveform: None },
    );
    assert_eq!(cycle, rtl);
    assert_eq!(cycle.summary.checked_queries, cycle.summary.queries);
    cycle
}

mod support;
use support::scene_events;

#[test]
fn hardcases_scene_is_identical() {
    let (width, height, events) = scene_events(HARDCASES);
    for sets in [
        vec![],
        vec!["engines=1".to_string()],
        vec!["engines=3".into(), "occu_write_buffer_words=1".into()],
        vec!["all_tiles_one_cycle=true".into(), "counter_bits=4".into()],
    ] {
        check_equivalent(&arch(&sets), width, height, &events);
    }
}

/// Two frames of the demo at 160x120: its viewport and events.
fn small_demo() -> (u32, u32, Vec<Event>) {
    let text = demo_scene(&DemoOptions {
        width: 160,
        height: 120,
        frames: 2,
        lots_per_side: 6,
        ..DemoOptions::default()
    });
    scene_events(&text)
}

#[test]
fn small_demo_is_identical() {
    let (width, height, events) = small_demo();
    let report = check_equivalent(&arch(&[]), width, height, &events);
    assert!(report.summary.fragments > 1000);
    check_equivalent(
        &arch(&["engines=2".into(), "occu_write_buffer_words=2".into()]),
        width,
        height,
        &events,
    );
}

const WIDTH: u32 = 40;
const HEIGHT: u32 = 32;

use occsim_traces::rng::SplitMix64;

/// Random state changes, queries of every mode over random tiles and buffer sizes, spans
/// of fragments with many depth ties and fragments outside queries; golden results after
/// every query end.
fn random_stream(seed: u64) -> Vec<Event> {
    let mut rng = SplitMix64(seed);
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    let mut events = Vec::new();
    let mut push = |event: Event, events: &mut Vec<Event>| {
        let result = golden.event(&event);
        events.push(event);
        if let Some(result) = result {
            events.push(Event::QueryResult(result));
        }
    };
    for query in 0..(1 + rng.below(8)) {
        match rng.below(5) {
            0 => push(Event::Clear, &mut events),
            1 => push(
                Event::DepthFunc(DepthFunc::ALL[rng.below(8) as usize]),
                &mut events,
            ),
            2 => push(Event::DepthMask(rng.below(4) != 0), &mut events),
            3 => push(Event::DepthTest(rng.below(5) != 0), &mut events),
            _ => {}
        }
        let mode = QueryMode::ALL[rng.below(4) as usize];
        let (tiles, buffer_entries) = match mode {
            QueryMode::Samples | QueryMode::Any => (vec![Rect::new(0, 0, WIDTH, HEIGHT)], 8),
            _ => {
                let count = 1 + rng.below(40);
                let tiles = (0..count)
                    .map(|_| {
                        let x = rng.below(WIDTH as u64) as u32;
                        let y = rng.below(HEIGHT as u64) as u32;
                        let w = 1 + rng.below((WIDTH - x) as u64) as u32;
                        let h = 1 + rng.below((HEIGHT - y) as u64) as u32;
                        Rect::new(x, y, w, h)
                    })
                    .collect();
                (tiles, 8 + rng.below(10) as u32)
            }
        };
        push(
            Event::QueryBegin(QuerySpec {
                id: query as u32,
                mode,
                buffer_entries,
                tiles,
            }),
            &mut events,
        );
        for _ in 0..rng.below(6) {
            push(Event::Primitive, &mut events);
            let (x0, y) = (
                rng.below(WIDTH as u64) as u16,
                rng.below(HEIGHT as u64) as u16,
            );
            let z = rng.below(6) as u32 * 1000;
            for x in x0..(x0 + 1 + rng.below(30) as u16).min(WIDTH as u16) {
                push(Event::Fragment(Fragment { x, y, z }), &mut events);
            }
        }
        push(Event::QueryEnd, &mut events);
        for _ in 0..rng.below(4) {
            let (x, y) = (
                rng.below(WIDTH as u64) as u16,
                rng.below(HEIGHT as u64) as u16,
            );
            push(Event::Fragment(Fragment { x, y, z: 7 }), &mut events);
        }
    }
    events
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]
    #[test]
    fn random_streams_are_identical(
        seed in 0u64..1_000_000,
        engines in 1u32..=16,
        counter_bits in 1u32..=6,
        buffer_words in 1u32..=12,
        one_cycle in any::<bool>(),
        port_bits in prop::sample::select(vec![32u32, 64, 256]),
        prefetch in 1u32..=4,
    ) {
        // The memory's other clients on, at what a 32-bit port can carry: a 640x480 8-bit
        // display at 60 Hz (7 % of it), colour writes where depth and colour fit a word.
        let colour_bits = if port_bits >= 64 { 32 } else { 0 };
        let arch = arch(&[
            "display_width_pixels=640".to_string(),
            "display_height_pixels=480".to_string(),
            "display_bits_per_pixel=8".to_string(),
            "display_refresh_hz=60".to_string(),
            format!("colour_bits_per_pixel={colour_bits}"),
            format!("blending={}", seed % 2 == 0),
            format!("engines={engines}"),
            format!("counter_bits={counter_bits}"),
            format!("occu_write_buffer_words={buffer_words}"),
            format!("all_tiles_one_cycle={one_cycle}"),
            format!("memory_port_bits_per_cycle={port_bits}"),
            format!("prefetch_depth_fragments={prefetch}"),
        ]);
        check_equivalent(&arch, WIDTH, HEIGHT, &random_stream(seed));
    }
}

/// A `Write` the test can read back after the machine has dropped its copy.
#[derive(Clone, Default)]
struct Shared(Arc<Mutex<Vec<u8>>>);

impl Write for Shared {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(bytes);
        Ok(bytes.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The most tiles one query of `events` has.
fn max_query_tiles(events: &[Event]) -> u64 {
    let tiles = events.iter().map(|event| match event {
        Event::QueryBegin(spec) => spec.tiles.len() as u64,
        _ => 0,
    });
    tiles.max().unwrap_or(0)
}

fn waveform(arch: &Arch, events: &[Event], window: std::ops::Range<u64>) -> (Report, String) {
    let shared = Shared::default();
    let report = replay(
        arch,
        WIDTH,
        HEIGHT,
        events,
        OccuModel::Rtl {
            waveform: Some(WaveformOptions {
                vcd: Some(Box::new(shared.clone())),
                fst: None,
                window,
                max_query_tiles: max_query_tiles(events),
            }),
        },
    );
    let text = String::from_utf8(shared.0.lock().unwrap().clone()).unwrap();
    (report, text)
}

/// The waveform as an independent reader sees it: wellen (the library the Surfer viewer is
/// built on) parses it, and per signal (its full dotted name) gives its (time, value)
/// changes. Also checked: the header occsim writes, increasing timestamps, values that fit
/// their declared widths, and that only changes are written (no value twice in a row).
fn parse_vcd(text: &str) -> std::collections::HashMap<String, Vec<(u64, u64)>> {
    assert!(text.starts_with("$version occsim-rtl $end\n$timescale 1ps $end\n"));
    // A reader keeps a signal's value when it is written again unchanged, so the writer's
    // promise to write only changes is checked on the text itself.
    let (_, body) = text
        .split_once("$enddefinitions $end\n")
        .expect("definitions end");
    let mut last = std::collections::HashMap::new();
    for line in body.lines().filter(|l| !l.starts_with('#')) {
        let (value, code) = match line.strip_prefix('b') {
            Some(rest) => rest.split_once(' ').expect("a vector value and its code"),
            None => line.split_at(1),
        };
        assert_ne!(
            last.insert(code, value),
            Some(value),
            "{code}: only changes"
        );
    }
    let mut wave = wellen::simple::read_from_reader(std::io::Cursor::new(text.as_bytes().to_vec()))
        .expect("wellen reads the VCD");
    let hierarchy = wave.hierarchy();
    let vars: Vec<(String, wellen::SignalRef, u32)> = hierarchy
        .iter_vars()
        .map(|v| {
            (
                v.full_name(hierarchy),
                v.signal_ref(),
                v.length().unwrap_or(1),
            )
        })
        .collect();
    let refs: Vec<wellen::SignalRef> = vars.iter().map(|v| v.1).collect();
    wave.load_signals(&refs);
    let times = wave.time_table().to_vec();
    assert!(times.windows(2).all(|t| t[0] < t[1]), "timestamps increase");
    let mut changes = std::collections::HashMap::new();
    for (name, signal, width) in vars {
        let signal = wave.get_signal(signal).expect("a loaded signal");
        let mut list: Vec<(u64, u64)> = Vec::new();
        for (time, value) in signal.iter_changes() {
            let bits = value.to_bit_string().expect("a bit vector");
            assert!(
                bits.len() as u32 <= width,
                "{name}: value wider than declared"
            );
            let value = u64::from_str_radix(&bits, 2).expect("binary digits only");
            list.push((times[time as usize], value));
        }
        assert!(
            changes.insert(name.clone(), list).is_none(),
            "{name} declared twice"
        );
    }
    changes
}

#[test]
fn waveform_is_well_formed_and_does_not_change_the_report() {
    for seed in 0..20 {
        let events = random_stream(seed);
        let arch = arch(&["engines=3".into(), "occu_write_buffer_words=4".into()]);
        let (report, text) = waveform(&arch, &events, 0..u64::MAX);
        assert_eq!(
            report,
            replay(&arch, WIDTH, HEIGHT, &events, OccuModel::Cycle)
        );
        parse_vcd(&text);
        let (_, windowed) = waveform(&arch, &events, 5..40);
        let changes = parse_vcd(&windowed);
        let period = 14999;
        for (_, list) in changes {
            assert!(list
                .iter()
                .all(|&(t, _)| (5 * period..40 * period).contains(&t)));
        }
    }
}

#[test]
fn hand_worked_waveform() {
    // One brief query, one tile on one engine, two fragments inside it, no primitive
    // setup. Both fragments read the same depth word, so they pass the depth test in
    // consecutive cycles and the unit takes them back to back: `accept` rises in o0 and
    // falls in o0 + 2 (only changes are written). PHC latches at the end of each accept
    // cycle: 1 from o0 + 1 (by o0 + 2 the slot has moved into OccU Control's record bank,
    // so the engine's PHC shows no further change; the report has 2). The end token passes the idle unit at the start
    // of o0 + 2; the 8 record words enter the write buffer in o0 + 3 (eligible the cycle
    // after the token), so its level reads 8 from o0 + 4; they ask the port from o0 + 4,
    // are granted together (8 x 32 bits = one 256-bit port cycle) in o0 + 4, and the result
    // is available in o0 + 5. The level returns to 0 in o0 + 5.
    let events = vec![
        Event::QueryBegin(QuerySpec {
            id: 1,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 4, 4)],
        }),
        Event::Fragment(Fragment { x: 1, y: 1, z: 0 }),
        Event::Fragment(Fragment { x: 2, y: 1, z: 0 }),
        Event::QueryEnd,
    ];
    let arch = arch(&["engines=1".into(), "occu_write_buffer_words=32".into()]);
    let (report, text) = waveform(&arch, &events, 0..1000);
    let changes = parse_vcd(&text);
    let p = 14999;
    let accept = &changes["occu.accept"];
    assert_eq!(accept.len(), 3);
    let o0 = accept[1].0 / p;
    assert_eq!(accept, &[(0, 0), (o0 * p, 1), ((o0 + 2) * p, 0)]);
    assert_eq!(
        changes["occu.engine_0.slot_0.phc"],
        [(0, 0), ((o0 + 1) * p, 1)]
    );
    assert_eq!(
        changes["occu.control.buffer_level"],
        [(0, 0), ((o0 + 4) * p, 8), ((o0 + 5) * p, 0)]
    );
    assert_eq!(
        changes["occu.control.record_words_in"],
        [(0, 0), ((o0 + 3) * p, 8), ((o0 + 4) * p, 0)]
    );
    assert_eq!(
        changes["occu.control.grants"],
        [(0, 0), ((o0 + 4) * p, 8), ((o0 + 5) * p, 0)]
    );
    let query = &report.queries[0];
    assert_eq!(query.available_cycle, o0 + 5);
    assert_eq!(report.queries[0].tiles[0].phc, 2);
}

// ---- the InfiniteReality-like machine ----

/// A built-in IR machine (`ir1`, `ir2`, `ir4`) with `sets` applied.
fn ir_arch(name: &str, sets: &[String]) -> Arch {
    let mut arch = Arch::builtin(name).unwrap();
    for set in sets {
        arch.set(set).unwrap_or_else(|e| panic!("--set {set}: {e}"));
    }
    arch
}

/// Replays `events` on the IR machine: the report and every query's merged result.
fn ir_replay(
    arch: &Arch,
    width: u32,
    height: u32,
    events: &[Event],
    occu: OccuModel,
) -> (Report, Vec<QueryResult>) {
    let mut machine = MachineBuilder::new(arch)
        .occu(occu)
        .ir(width, height)
        .unwrap();
    let mut results = Vec::new();
    for event in events {
        machine.event(event).unwrap();
        if matches!(event, Event::QueryEnd) {
            results.push(machine.last_result().unwrap().clone());
        }
    }
    (machine.finish().unwrap(), results)
}

/// Replay on both fidelities of the IR machine and insist on identical reports and merged
/// results (hit lists in the same order); through [`MachineModel`] too.
fn ir_check_equivalent(arch: &Arch, width: u32, height: u32, events: &[Event]) -> Report {
    let (cycle, cycle_results) = ir_replay(arch, width, height, events, OccuModel::Cycle);
    let (rtl, rtl_results) = ir_replay(
        arch,
        width,
        height,
        events,
        OccuModel::Rtl { waveform: None },
    );
    assert_eq!(cycle.machine, "ir");
    assert_eq!(cycle, rtl);
    assert_eq!(cycle_results, rtl_results);
    assert_eq!(cycle.summary.checked_queries, cycle.summary.queries);
    // Through the closed loop (host and geometry ahead of the pipeline) the two agree too.
    assert_eq!(
        replay(
            arch,
            width,
            height,
            events,
            OccuModel::Rtl { waveform: None }
        ),
        replay(arch, width, height, events, OccuModel::Cycle)
    );
    cycle
}

/// IR variants: every built-in board count, few Image Engines per board (so each holds
/// many pixels), fast depth tests (so the OccU and its write buffer are the bottleneck and
/// stall), and `extra`.
fn ir_variants(extra: &[&str]) -> Vec<Arch> {
    let mut archs = Vec::new();
    for name in ["ir1", "ir2", "ir4"] {
        archs.push(ir_arch(name, &[]));
        let mut sets: Vec<String> = vec![
            "image_engines_per_board=3".into(),
            "image_engine_cycles_per_fragment=1".into(),
            "occu_write_buffer_words=2".into(),
        ];
        sets.extend(extra.iter().map(|s| s.to_string()));
        archs.push(ir_arch(name, &sets));
    }
    archs
}

#[test]
fn ir_hardcases_scene_is_identical() {
    let (width, height, events) = scene_events(HARDCASES);
    for extra in [
        vec![],
        vec!["engines=1"],
        vec!["engines=2", "interleave=blocks", "block_width_pixels=3"],
        vec!["engines=5", "interleave=morton", "counter_bits=4"],
        vec!["all_tiles_one_cycle=true", "occu_write_buffer_words=1"],
    ] {
        for arch in ir_variants(&extra) {
            ir_check_equivalent(&arch, width, height, &events);
        }
    }
}

#[test]
fn ir_small_demo_is_identical() {
    let (width, height, events) = small_demo();
    for arch in ir_variants(&["engines=2"]) {
        let report = ir_check_equivalent(&arch, width, height, &events);
        assert!(report.summary.fragments > 1000);
    }
}

/// A verbose query whose tiles overflow at every Image Engine, then one that fits, on fast
/// Image Engines with a one-word write buffer: hits stall the engines.
#[test]
fn ir_verbose_overflow_is_identical() {
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    let mut events = Vec::new();
    for (id, buffer_entries) in [(1, 10), (2, 8 + 200)] {
        let raw = [Event::QueryBegin(QuerySpec {
            id,
            mode: QueryMode::Verbose,
            buffer_entries,
            tiles: vec![
                Rect::new(0, 0, WIDTH, HEIGHT),
                Rect::new(2, 2, 9, 5),
                Rect::new(0, 0, 1, 1),
            ],
        })];
        let fragments = (0..6u16).flat_map(|y| (0..12u16).map(move |x| (x, y)));
        for event in raw.into_iter().chain(
            fragments
                .map(|(x, y)| Event::Fragment(Fragment { x, y, z: 100 }))
                .chain([Event::QueryEnd]),
        ) {
            let result = golden.event(&event);
            events.push(event);
            events.extend(result.map(Event::QueryResult));
        }
    }
    for extra in [vec!["engines=1"], vec!["engines=2"], vec!["engines=5"]] {
        for arch in ir_variants(&extra) {
            let mut arch = arch;
            arch.set("occu_write_buffer_words=1").unwrap();
            let report = ir_check_equivalent(&arch, WIDTH, HEIGHT, &events);
            assert!(report.queries[0].overflowed_buffers > 0);
            assert_eq!(report.queries[1].overflowed_buffers, 0);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(150))]
    #[test]
    fn ir_random_streams_are_identical(
        seed in 0u64..1_000_000,
        name in prop::sample::select(vec!["ir1", "ir2", "ir4"]),
        image_engines in 1u32..=5,
        engines in prop::sample::select(vec![1u32, 2, 5, 16]),
        counter_bits in 1u32..=6,
        buffer_words in 1u32..=12,
        one_cycle in any::<bool>(),
        interleave in prop::sample::select(vec!["columns", "blocks", "morton"]),
        cycles_per_fragment in prop::sample::select(vec![1u32, 2, 3, 45]),
        fifo in 1u32..=4,
        per_cycle in 1u32..=3,
        setup in 0u32..=4,
    ) {
        let arch = ir_arch(name, &[
            format!("image_engines_per_board={image_engines}"),
            format!("engines={engines}"),
            format!("counter_bits={counter_bits}"),
            format!("occu_write_buffer_words={buffer_words}"),
            format!("all_tiles_one_cycle={one_cycle}"),
            format!("interleave={interleave}"),
            "block_width_pixels=3".to_string(),
            "block_height_pixels=2".to_string(),
            format!("image_engine_cycles_per_fragment={cycles_per_fragment}"),
            format!("image_engine_fifo_entries={fifo}"),
            format!("fragment_generator_fragments_per_cycle={per_cycle}"),
            format!("fragment_generator_setup_cycles={setup}"),
        ]);
        ir_check_equivalent(&arch, WIDTH, HEIGHT, &random_stream(seed));
    }
}

/// At the IR the waveform is Image Engine 0's of board 0: well formed, its unit seen
/// taking fragments, and the report unchanged.
#[test]
fn ir_waveform_dumps_the_first_image_engine() {
    let arch = ir_arch(
        "ir2",
        &[
            "image_engines_per_board=2".into(),
            "image_engine_cycles_per_fragment=1".into(),
            "engines=3".into(),
        ],
    );
    // Image Engine 0 of board 0 owns columns 0, 4, 8, ... (columns interleave over 2 x 2
    // Image Engines); x = 1 goes to board 1.
    let events = vec![
        Event::QueryBegin(QuerySpec {
            id: 1,
            mode: QueryMode::Verbose,
            buffer_entries: 20,
            tiles: vec![Rect::new(0, 0, 8, 4); 4],
        }),
        Event::Fragment(Fragment { x: 0, y: 1, z: 0 }),
        Event::Fragment(Fragment { x: 1, y: 1, z: 0 }),
        Event::Fragment(Fragment { x: 4, y: 1, z: 0 }),
        Event::QueryEnd,
    ];
    let shared = Shared::default();
    let (report, _) = ir_replay(
        &arch,
        WIDTH,
        HEIGHT,
        &events,
        OccuModel::Rtl {
            waveform: Some(WaveformOptions {
                vcd: Some(Box::new(shared.clone())),
                fst: None,
                window: 0..u64::MAX,
                max_query_tiles: max_query_tiles(&events),
            }),
        },
    );
    assert_eq!(
        report,
        ir_replay(&arch, WIDTH, HEIGHT, &events, OccuModel::Cycle).0
    );
    let text = String::from_utf8(shared.0.lock().unwrap().clone()).unwrap();
    let changes = parse_vcd(&text);
    // Two fragments reach Image Engine 0 (x = 0 and x = 4): two acceptances; every
    // fragment passes in all 4 tiles: 3 x 4 hit words over the machine.
    let rises = changes["occu.accept"].iter().filter(|c| c.1 == 1).count();
    assert_eq!(rises, 2);
    assert_eq!(report.memory_port.occu_words, 4 * 3);
}

/// The VCD bytes of random streams on several architectures and windows, pinned by the
/// digest and length the register-file probe produced (its values are checked against the
/// model cycle by cycle by the unit test in `sim/src/blocks/waveform.rs`): optimising the writer or
/// the probe must not change one byte of it. Re-pinned once, when the random streams moved
/// to the one shared generator (SplitMix64) from a copy of xorshift64*.
#[test]
fn waveform_bytes_are_pinned() {
    let configurations: [(&[&str], std::ops::Range<u64>); 5] = [
        (&["engines=1"], 0..u64::MAX),
        (&["engines=3", "occu_write_buffer_words=4"], 0..u64::MAX),
        (
            &["engines=16", "counter_bits=5", "occu_write_buffer_words=2"],
            0..u64::MAX,
        ),
        (
            &["engines=4", "all_tiles_one_cycle=true", "counter_bits=64"],
            0..u64::MAX,
        ),
        (&["engines=2", "occu_write_buffer_words=3"], 17..300),
    ];
    let mut digests = Vec::new();
    for (sets, window) in configurations {
        // The memory's other clients off: the waveforms of the machine before them, byte
        // for byte (with them off its cycles are those of that machine).
        let off = [
            "colour_bits_per_pixel=0",
            "clear_writes_memory=false",
            "display_refresh_hz=0",
            "host_memory_share=0",
            "memory_banks=1",
        ];
        let sets: Vec<String> = off.iter().chain(sets).map(|s| s.to_string()).collect();
        let arch = arch(&sets);
        let mut all = Vec::new();
        for seed in 0..40 {
            let (_, text) = waveform(&arch, &random_stream(seed), window.clone());
            all.extend_from_slice(text.as_bytes());
        }
        digests.push((occsim_traces::rng::Fnv1a::of(&all), all.len()));
    }
    assert_eq!(
        digests,
        [
            (0x6b99_4cc4_04f1_c106, 3031652),
            (0x66b9_c1b9_b028_b736, 1984758),
            (0x34ec_6ed8_49ec_483e, 1835749),
            (0xdb9b_62a5_9be9_8f03, 1259721),
            (0xf320_a143_ab7b_e9d8, 1104493),
        ]
    );
}

/// The reader's checks can fail: a value written twice in a row is caught.
#[test]
#[should_panic(expected = "only changes")]
fn the_vcd_check_catches_a_repeated_value() {
    parse_vcd(
        "$version occsim-rtl $end\n$timescale 1ps $end\n$scope module occu $end\n\
         $var wire 4 ! step $end\n$upscope $end\n$enddefinitions $end\n\
         #0\nb1 !\n#10\nb1 !\n",
    );
}

/// A seekable `Write` the test can read back (an FST is rewritten at its header).
#[derive(Clone, Default)]
struct SharedSeek(Arc<Mutex<std::io::Cursor<Vec<u8>>>>);

impl Write for SharedSeek {
    fn write(&mut self, bytes: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().write(bytes)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl std::io::Seek for SharedSeek {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        self.0.lock().unwrap().seek(to)
    }
}

/// Per signal (full dotted name), its (time, value) changes as wellen reads the waveform
/// file `bytes` (VCD or FST); values with an `x` (an FST's signals before their first
/// value) are left out.
fn read_wave(bytes: &[u8]) -> std::collections::HashMap<String, Vec<(u64, u64)>> {
    let mut wave = wellen::simple::read_from_reader(std::io::Cursor::new(bytes.to_vec()))
        .expect("wellen reads the waveform");
    let hierarchy = wave.hierarchy();
    let vars: Vec<(String, wellen::SignalRef)> = hierarchy
        .iter_vars()
        .map(|v| (v.full_name(hierarchy), v.signal_ref()))
        .collect();
    let refs: Vec<wellen::SignalRef> = vars.iter().map(|v| v.1).collect();
    wave.load_signals(&refs);
    let times = wave.time_table().to_vec();
    vars.into_iter()
        .map(|(name, signal)| {
            let signal = wave.get_signal(signal).expect("a loaded signal");
            let list = signal
                .iter_changes()
                .filter_map(|(time, value)| {
                    let bits = value.to_bit_string()?;
                    Some((times[time as usize], u64::from_str_radix(&bits, 2).ok()?))
                })
                .collect();
            (name, list)
        })
        .collect()
}

/// The value `changes` holds at `time`, if any.
fn value_at(changes: &[(u64, u64)], time: u64) -> Option<u64> {
    let at = changes.partition_point(|&(t, _)| t <= time);
    at.checked_sub(1).map(|i| changes[i].1)
}

/// The FST holds the VCD's signals with the VCD's values in every dumped cycle, on the
/// built-in hard cases, for the whole run and a window; dumping both does not change the
/// report.
#[test]
fn fst_equals_vcd_in_every_dumped_cycle() {
    let (width, height, events) = scene_events(HARDCASES);
    let arch = arch(&["engines=3".into()]);
    let cycle_report = replay(&arch, width, height, &events, OccuModel::Cycle);
    let cycles = cycle_report.summary.cycles;
    for window in [0..u64::MAX, 1000..1500] {
        let (vcd, fst) = (Shared::default(), SharedSeek::default());
        let report = replay(
            &arch,
            width,
            height,
            &events,
            OccuModel::Rtl {
                waveform: Some(WaveformOptions {
                    vcd: Some(Box::new(vcd.clone())),
                    fst: Some(Box::new(fst.clone())),
                    window: window.clone(),
                    max_query_tiles: max_query_tiles(&events),
                }),
            },
        );
        assert_eq!(report, cycle_report);
        let vcd_text = String::from_utf8(vcd.0.lock().unwrap().clone()).unwrap();
        let from_vcd = parse_vcd(&vcd_text);
        let from_fst = read_wave(fst.0.lock().unwrap().get_ref());
        assert_eq!(
            from_vcd.keys().collect::<std::collections::BTreeSet<_>>(),
            from_fst.keys().collect(),
            "the same signals"
        );
        // The hard cases run past the window's end, so the window is dumped whole.
        assert!(cycles > 1500, "{cycles} cycles");
        let period = 14999; // 66.67 MHz, in whole picoseconds
        let dumped = window.start..window.end.min(cycles);
        let mut compared = 0;
        for (name, list) in &from_vcd {
            for cycle in dumped.clone() {
                let time = cycle * period;
                let value = value_at(list, time);
                assert!(value.is_some(), "{name} has a value at cycle {cycle}");
                assert_eq!(value_at(&from_fst[name], time), value, "{name} at {cycle}");
                compared += 1;
            }
        }
        assert!(compared > 0);
    }
}
