//! The InfiniteReality-like machine's timing, worked by hand on tiny streams, the latency
//! split, and the rejection of bad parameters.

mod support;

use occsim_sim::arch::{Arch, ArchError, IR_PARAMS};
use occsim_sim::{IrMachine, Report};
use occsim_traces::{Event, Fragment, QueryMode, QuerySpec, Rect};

/// One board of two Image Engines, columns interleave, one fragment per cycle, setup 2,
/// an unpipelined 3-cycle depth stage (interval = latency = 3), one-entry FIFOs, one
/// engine; merge links and the report's DMA
/// unlimited and host reads of report words free (what the words cost is worked out in
/// `merge_latency_grows_with_the_words_moved`).
fn tiny(sets: &[&str]) -> Arch {
    let mut arch = Arch::builtin("ir1").unwrap();
    for set in [
        "image_engines_per_board=2",
        "fragment_generator_fragments_per_cycle=1",
        "fragment_generator_setup_cycles=2",
        "image_engine_cycles_per_fragment=3",
        "image_engine_latency_cycles=3",
        "image_engine_fifo_entries=1",
        "engines=1",
        "local_merge_hop_latency_cycles=5",
        "local_merge_link_bits_per_cycle=0",
        "global_merge_link_bits_per_cycle=0",
        "report_dma_bits_per_cycle=0",
        "result_read_cycles_per_word=0",
    ]
    .iter()
    .chain(sets)
    {
        arch.set(set).unwrap();
    }
    arch
}

fn query(xs: &[u16]) -> Vec<Event> {
    let mut events = vec![
        Event::QueryBegin(QuerySpec {
            id: 1,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 4, 1)],
        }),
        Event::Primitive,
    ];
    events.extend(
        xs.iter()
            .map(|&x| Event::Fragment(Fragment { x, y: 0, z: 9 })),
    );
    events.push(Event::QueryEnd);
    events
}

fn run(arch: &Arch, events: &[Event]) -> Report {
    let mut machine = IrMachine::new(arch, 4, 1).unwrap();
    for event in events {
        machine.event(event).unwrap();
    }
    machine.finish().unwrap()
}

#[test]
fn hand_worked_two_image_engines_and_a_tree() {
    // Setup ends in 2. f0 -> IE0: emitted 2, tested from 3, OccU 6. f1 -> IE1: emitted 3,
    // tested 4, OccU 7. f2 -> IE0: emitted 4 (slot freed in 3), tested max(5, 6) = 6, OccU 9.
    // f3 -> IE1: emitted 5, tested 7, OccU 10. End token t_end = 6.
    // IE0: td = max(7, 9) = 9, to = 10, r = 11. IE1: td = 10, to = 11, r = 12.
    // Tree over 2: max(11, 12) + 5 = 17; one board: the global tree adds no hop.
    let report = run(&tiny(&[]), &query(&[0, 1, 0, 1]));
    let q = &report.queries[0];
    assert_eq!((q.end_cycle, q.available_cycle), (6, 17));
    assert_eq!(
        (q.drain_cycles, q.local_merge_cycles, q.global_merge_cycles),
        (6, Some(5), Some(0))
    );
    assert_eq!(q.latency_cycles, 11);
    assert_eq!(report.summary.cycles, 17);
    assert_eq!(report.queries[0].tiles[0].nohc, 4);
}

#[test]
fn hand_worked_chain_and_software_merges() {
    // Chain: c0 = 11, c1 = max(12, 11 + 5) = 16.
    let chain = run(&tiny(&["local_merge=chain"]), &query(&[0, 1, 0, 1]));
    assert_eq!(chain.queries[0].local_merge_cycles, Some(4));
    // Software global stage: the host reads the one board's report: 17 + 100.
    let software = run(
        &tiny(&[
            "global_merge=software",
            "global_merge_read_latency_cycles=100",
        ]),
        &query(&[0, 1, 0, 1]),
    );
    let q = &software.queries[0];
    assert_eq!((q.global_merge_cycles, q.latency_cycles), (Some(100), 111));
    // Software local stage: the host reads IE0 (ready 11) then IE1 (ready 12): 51, 91.
    let reads = run(
        &tiny(&["local_merge=software", "local_merge_read_latency_cycles=40"]),
        &query(&[0, 1, 0, 1]),
    );
    assert_eq!(reads.queries[0].local_merge_cycles, Some(91 - 12));
}

/// `query` with `tiles` one-pixel tiles along the row (tiles past x = 3 see no fragment).
fn query_of_tiles(xs: &[u16], tiles: u32) -> Vec<Event> {
    let mut events = query(xs);
    if let Event::QueryBegin(spec) = &mut events[0] {
        spec.tiles = (0..tiles).map(|x| Rect::new(x.min(3), 0, 1, 1)).collect();
    }
    events
}

#[test]
fn merge_latency_grows_with_the_words_moved() {
    // The stream of `hand_worked_two_image_engines_and_a_tree`: IE0's report ready in 11,
    // IE1's in 12, t_end = 6. A 32-bit local link moves a word a cycle: each report of one
    // tile (8 words) crosses it in 8, so the tree's node is ready in max(11 + 8, 12 + 8) + 5
    // = 25; one board, no global hop; the DMA of the 8 words at 16 bits a cycle takes 16:
    // available 41, latency 35 = drain 6 + local 13 + global 16.
    let links = |width: &str| {
        tiny(&[
            &format!("local_merge_link_bits_per_cycle={width}"),
            "report_dma_bits_per_cycle=16",
        ])
    };
    let report = run(&links("32"), &query(&[0, 1, 0, 1]));
    let q = &report.queries[0];
    assert_eq!((q.end_cycle, q.available_cycle), (6, 41));
    assert_eq!(
        (q.drain_cycles, q.local_merge_cycles, q.global_merge_cycles),
        (6, Some(13), Some(16))
    );
    // More tiles, more words: T tiles are 8 T words, ceil(8 T * 32 / w) cycles a link
    // crossing and 8 T * 32 / 16 for the DMA, on top of what unlimited links give (the
    // drain itself grows with the tiles, one tile a cycle in the one engine).
    for (tiles, width, words_cost) in [
        (1, "32", 8 + 16),
        (4, "32", 32 + 64),
        (4, "64", 16 + 64),
        (16, "128", 32 + 256),
    ] {
        let events = query_of_tiles(&[0, 1, 0, 1], tiles);
        let unlimited = run(&tiny(&[]), &events).queries[0].latency_cycles;
        let moved = run(&links(width), &events).queries[0].latency_cycles;
        assert_eq!(
            moved - unlimited,
            words_cost,
            "{tiles} tiles on {width} bits"
        );
    }
    // Chain: c0 = 11 (no link crossed), c1 = max(12, 11 + 8 + 5) = 24: local 24 - 12 = 12.
    let chain = run(
        &tiny(&["local_merge=chain", "local_merge_link_bits_per_cycle=32"]),
        &query(&[0, 1, 0, 1]),
    );
    assert_eq!(chain.queries[0].local_merge_cycles, Some(12));
    // Software: the host reads each report word by word, 40 + 8 words at 2 cycles = 56:
    // IE0 ready 11 -> 67, IE1 -> 123; local = 123 - 12; the host has it: no DMA.
    let reads = run(
        &tiny(&[
            "local_merge=software",
            "local_merge_read_latency_cycles=40",
            "result_read_cycles_per_word=2",
            "global_merge=software",
            "global_merge_read_latency_cycles=0",
            "report_dma_bits_per_cycle=16",
        ]),
        &query(&[0, 1, 0, 1]),
    );
    let q = &reads.queries[0];
    // The global stage reads the board's merged 8 words too: 0 + 8 * 2 = 16.
    assert_eq!(
        (q.local_merge_cycles, q.global_merge_cycles),
        (Some(123 - 12), Some(16))
    );
    // Two boards of two Image Engines (unit g = x mod 4 is Image Engine g / 2 of board
    // g mod 2), a 64-bit global link: each board's merged 8 words cross it in 4, + 8 of hop
    // latency, then the 16-cycle DMA: global = 4 + 8 + 16 after the later board's merge.
    let two = run(
        &tiny(&[
            "boards=2",
            "global_merge_hop_latency_cycles=8",
            "global_merge_link_bits_per_cycle=64",
            "report_dma_bits_per_cycle=16",
        ]),
        &query(&[0, 1, 0, 1]),
    );
    assert_eq!(two.queries[0].global_merge_cycles, Some(4 + 8 + 16));
}

#[test]
fn a_pipelined_depth_stage_starts_a_fragment_every_interval() {
    // Interval 2, latency 6: 3 fragments in flight. All four to IE0 (even x). f0 emitted 2,
    // starts 3, result 9, accepted 9. f1 emitted 3 (f0 left the one-entry FIFO in 3),
    // starts max(4, 3 + 2) = 5, accepted 11. f2 emitted 5, starts 7, accepted 13. f3
    // emitted 7, starts max(8, 9, o_0 = 9) = 9, accepted 15. t_end = 8; the end passes the
    // depth stage in max(9, 11, 15) = 15, the OccU in 16, the report is ready in 17: drain 9.
    let pipelined = tiny(&[
        "image_engine_cycles_per_fragment=2",
        "image_engine_latency_cycles=6",
        "local_merge_hop_latency_cycles=0",
    ]);
    let report = run(&pipelined, &query(&[0, 2, 0, 2]));
    let q = &report.queries[0];
    assert_eq!((q.end_cycle, q.drain_cycles), (8, 9));
    assert_eq!(report.stages[1].busy_cycles, 4 * 2);
    // Unpipelined at 6 (interval = latency): f0 starts 3, accepted 9; f1 emitted 3, starts
    // 9, accepted 15; f2 emitted 9, starts 15, accepted 21; f3 emitted 15, starts 21,
    // accepted 27. t_end = 16; depth 27, OccU 28, ready 29: drain 13.
    let unpipelined = tiny(&[
        "image_engine_cycles_per_fragment=6",
        "image_engine_latency_cycles=6",
        "local_merge_hop_latency_cycles=0",
    ]);
    let q = &run(&unpipelined, &query(&[0, 2, 0, 2])).queries[0];
    assert_eq!((q.end_cycle, q.drain_cycles), (16, 13));
}

#[test]
fn the_fragment_generator_blocks_on_a_full_image_engine_fifo() {
    // All to IE0: f0 emitted 2, tested 3..5, OccU 6. f1 emitted 3 (f0 left the FIFO in 3),
    // tested 6, OccU 9. f2 waits for f1 to leave the FIFO: emitted 6 (earliest 4: 2 cycles
    // blocked), tested 9, OccU 12. t_end = 7; td = 12, to = 13, r = 14: drain 7.
    let report = run(
        &tiny(&["local_merge_hop_latency_cycles=0"]),
        &query(&[0, 2, 0]),
    );
    let generator = &report.stages[0];
    assert_eq!(generator.name, "frag_generators");
    assert_eq!(generator.stall_cycles, 2);
    let q = &report.queries[0];
    assert_eq!((q.end_cycle, q.drain_cycles, q.latency_cycles), (7, 7, 7));
}

#[test]
fn with_zero_merge_latencies_every_latency_is_its_drain() {
    let mut events = Vec::new();
    for i in 0..6u16 {
        events.extend(query(&[i % 4, (i * 3) % 4, 1, 2, 3, 0, i % 2]));
    }
    for local in ["tree", "chain", "software"] {
        for global in ["tree", "chain", "software"] {
            let mut arch = tiny(&[]);
            for set in [
                format!("local_merge={local}"),
                format!("global_merge={global}"),
                "boards=2".into(),
                "local_merge_hop_latency_cycles=0".into(),
                "local_merge_read_latency_cycles=0".into(),
                "global_merge_hop_latency_cycles=0".into(),
                "global_merge_read_latency_cycles=0".into(),
                // Links and the DMA unlimited, host word reads free (as `tiny` has them):
                // the merge moves its words in no time.
                "local_merge_link_bits_per_cycle=0".into(),
                "global_merge_link_bits_per_cycle=0".into(),
                "report_dma_bits_per_cycle=0".into(),
                "result_read_cycles_per_word=0".into(),
            ] {
                arch.set(&set).unwrap();
            }
            let report = run(&arch, &events);
            assert_eq!(report.queries.len(), 6);
            for q in &report.queries {
                assert_eq!(q.latency_cycles, q.drain_cycles, "{local}/{global}");
                assert_eq!(
                    (q.local_merge_cycles, q.global_merge_cycles),
                    (Some(0), Some(0))
                );
            }
        }
    }
}

#[test]
fn latency_is_the_sum_of_its_parts() {
    let mut events = Vec::new();
    for i in 0..5u16 {
        events.extend(query(&[i % 4, 3, 2, 1]));
    }
    let report = run(&tiny(&["boards=4", "global_merge=chain"]), &events);
    for q in &report.queries {
        assert_eq!(
            q.latency_cycles,
            q.drain_cycles + q.local_merge_cycles.unwrap() + q.global_merge_cycles.unwrap()
        );
        assert!(q.drain_cycles >= 3, "end token: FIFO, depth stage, OccU");
    }
}

#[test]
fn builtins_differ_only_in_boards() {
    for (name, boards) in [("ir1", 1), ("ir2", 2), ("ir4", 4)] {
        let ir = Arch::builtin(name).unwrap().ir().unwrap();
        assert_eq!(ir.boards, boards);
        assert_eq!(ir.image_engines_per_board, 80);
    }
}

#[test]
fn every_parameter_has_a_unit_and_a_meaning_and_reads_back() {
    for p in IR_PARAMS.iter() {
        assert!(!p.unit.is_empty() && !p.meaning.is_empty(), "{}", p.key);
    }
    let mut arch = Arch::builtin("ir2").unwrap();
    arch.set("interleave=morton").unwrap();
    arch.set("ir.global_merge = software").unwrap();
    let text = arch.to_documented_toml();
    assert!(text.contains("interleave = \"morton\""), "{text}");
    assert_eq!(Arch::from_toml(&text).unwrap(), arch);
}

#[test]
fn bad_set_keys_and_values_are_rejected_clearly() {
    let mut arch = Arch::builtin("ir4").unwrap();
    let err = arch.set("boards=3").unwrap_err();
    assert!(matches!(err, ArchError::Impossible(_)));
    assert_eq!(
        err.to_string(),
        "impossible configuration: boards (3) must be 1, 2 or 4"
    );
    let err = arch.set("interleave=diagonal").unwrap_err();
    assert_eq!(
        err.to_string(),
        "parameter 'interleave' = diagonal: expected one of columns, blocks, morton"
    );
    let err = arch.set("local_merge=bus").unwrap_err();
    assert!(
        err.to_string().contains("one of tree, chain, software"),
        "{err}"
    );
    let err = arch.set("image_engines=8").unwrap_err();
    assert!(matches!(err, ArchError::UnknownKey { .. }));
    assert!(err.to_string().contains("image_engines_per_board"), "{err}");
    let err = arch.set("image_engine_cycles_per_fragment=0").unwrap_err();
    assert!(err.to_string().contains("an integer in 1..="), "{err}");
    assert_eq!(
        arch,
        Arch::builtin("ir4").unwrap(),
        "rejected values leave it unchanged"
    );
    let err = Arch::from_toml("machine = \"ir\"\n[ir]\nboards = 8\n").unwrap_err();
    assert!(err.to_string().contains("line 3"), "{err}");
}

#[test]
fn an_unpipelined_45_cycle_stage_is_the_image_engine_before_calibration() {
    // The built-in hardcases scene on ir4 with interval = latency = 45: the one-stage Image
    // Engine of commit 19fdaf8 (`occsim replay hc.occt --arch ir4`: 78215 cycles, query
    // latency p50 509, max 830); the calibrated defaults (interval 11, latency 16) halve
    // the run, the depth stage no longer the bottleneck.
    let (width, height, events) = support::scene_events(occsim_traces::builtin::HARDCASES);
    let replay = |sets: &[&str]| {
        let mut arch = Arch::builtin("ir4").unwrap();
        for set in sets {
            arch.set(set).unwrap();
        }
        let mut machine = occsim_sim::MachineBuilder::new(&arch)
            .build(width, height)
            .unwrap();
        for event in &events {
            machine.event(event).unwrap();
        }
        machine.finish().unwrap()
    };
    let before = replay(&[
        "image_engine_cycles_per_fragment=45",
        "image_engine_latency_cycles=45",
    ]);
    let s = &before.summary;
    assert_eq!(
        (s.cycles, s.latency_p50_cycles, s.latency_max_cycles),
        (78215, Some(509), Some(830))
    );
    let calibrated = replay(&[]);
    assert!(
        calibrated.summary.cycles < 78215 / 2 + 1000,
        "{}",
        calibrated.summary.cycles
    );
}
