//! Hand-worked timings of tiny traces on the O2-like machine. Every expected cycle count is
//! derived in the comments from the rules in `sim/src/machines/o2.rs`, not computed by the model.

mod support;

use occsim_sim::machines::o2::MIN_QUERY_LATENCY_CYCLES;
use occsim_sim::{Arch, O2Machine, Report};
use occsim_traces::{Event, Fragment, QueryMode, QuerySpec, Rect};

fn fragment(x: u16, y: u16, z: u32) -> Event {
    Event::Fragment(Fragment { x, y, z })
}

fn query(id: u32, mode: QueryMode, buffer_entries: u32, tiles: Vec<Rect>) -> Event {
    Event::QueryBegin(QuerySpec {
        id,
        mode,
        buffer_entries,
        tiles,
    })
}

fn run(arch: &Arch, events: &[Event]) -> Report {
    let mut machine = O2Machine::new(arch, 64, 64).unwrap();
    for event in events {
        machine.event(event).unwrap();
    }
    machine.finish().unwrap()
}

/// The memory's clients outside rules 1-8 of `machines/o2.rs`, all off: no colour, no
/// clear writes, no display refresh, no host share, one bank.
const CLIENTS_OFF: [&str; 5] = [
    "colour_bits_per_pixel=0",
    "clear_writes_memory=false",
    "display_refresh_hz=0",
    "host_memory_share=0",
    "memory_banks=1",
];

/// The O2 with its pipeline's defaults and the other memory clients off (the tests of
/// those clients turn them on), then `sets`.
fn o2(sets: &[&str]) -> Arch {
    let mut arch = Arch::builtin("o2").unwrap();
    for set in CLIENTS_OFF.iter().chain(sets) {
        arch.set(set).unwrap();
    }
    arch
}

/// The stream of `samples_query_of_three_fragments_in_one_word`.
fn three_fragments() -> Vec<Event> {
    vec![
        query(1, QueryMode::Samples, 8, vec![Rect::new(0, 0, 64, 64)]),
        Event::Primitive,
        fragment(0, 0, 100),
        fragment(1, 0, 100),
        fragment(2, 0, 100),
        Event::QueryEnd,
    ]
}

#[test]
fn a_host_share_takes_idle_cycles_and_forces_only_past_its_slack() {
    // f = 3/4 of the port's cycles for the host, 1 cycle of slack (see memory_port.rs: the
    // debt grows f a granted cycle, falls 1 - f an idle one down to 0, and a cycle is
    // forced when it would pass the slack). As in
    // `samples_query_of_three_fragments_in_one_word`: F0's read asked in 5 (debt 0 after
    // the idle cycles 0..4: 3/4, granted), data 13, tested 13, its write granted 14 (debt
    // 3/4 again after the idle 6..13); F1 tested 14, its write asked in 15: 3/2 > 1, forced
    // (debt 1/2), 16: 5/4, forced (1/4), 17: 1, granted; F2 tested 15, its write (ready 16)
    // packs into 17. End in 7; through depth 16, OccU 17, records ready 18, asking from 19
    // (18 idle: debt 3/4): 19 and 20 forced as 15 and 16 were, granted 21; available 22:
    // latency 15 (13 without the share).
    let report = run(
        &o2(&["host_memory_share=0.75", "other_clients_slack_cycles=1"]),
        &three_fragments(),
    );
    let q = &report.queries[0];
    assert_eq!(
        (q.end_cycle, q.available_cycle, q.latency_cycles),
        (7, 22, 15)
    );
    // The pipeline's grants: 5, 14, 17, 21; 15, 16, 19, 20 forced. Cycles 0..22 need
    // 22 * 3/4 = 16.5, of which 1 (the debt after 21) is still owed: 15 served.
    let port = &report.memory_port;
    assert_eq!(
        (port.busy_cycles, port.forced_cycles, port.reserved_cycles),
        (4, 4, 15)
    );
    // With the default slack (16 cycles) the host never falls that far behind on so idle a
    // port: it takes idle cycles only, and the latency is the one without it.
    let slack = run(&o2(&["host_memory_share=0.75"]), &three_fragments());
    assert_eq!(slack.queries[0].latency_cycles, 13);
    assert_eq!(slack.memory_port.forced_cycles, 0);
}

#[test]
fn drawn_fragments_write_colour_and_blending_reads_it_first() {
    // Colour rides with the depth write: 32 + 32 bits in one entry, the same grants (14, 15,
    // 16) and latency 13 as without colour.
    let colour = run(&o2(&["colour_bits_per_pixel=32"]), &three_fragments());
    assert_eq!(colour.queries[0].latency_cycles, 13);
    assert_eq!(
        (
            colour.memory_port.colour_writes,
            colour.memory_port.colour_reads
        ),
        (3, 0)
    );
    assert_eq!(colour.memory_port.bits_transferred, 256 + 3 * 64 + 8 * 32);
    assert_eq!(colour.memory_port.busy_cycles, 5);
    // Blending: F0 tested 13, its colour read granted 14, its write from 15; F1 tested 14,
    // read packed into 15, write 16; F2 tested 15, read 16, write 17; the records still go
    // in 19: latency 13, one more busy port cycle (5, 14, 15, 16, 17, 19).
    let blend = run(
        &o2(&["colour_bits_per_pixel=32", "blending=true"]),
        &three_fragments(),
    );
    assert_eq!(blend.queries[0].latency_cycles, 13);
    assert_eq!(blend.memory_port.colour_reads, 3);
    assert_eq!(blend.memory_port.busy_cycles, 6);
    // A brief query draws nothing: no colour (nor depth) written.
    let mut brief = three_fragments();
    brief[0] = query(1, QueryMode::Brief, 8, vec![Rect::new(0, 0, 64, 64)]);
    let brief = run(&o2(&["colour_bits_per_pixel=32"]), &brief);
    assert_eq!(
        (
            brief.memory_port.colour_writes,
            brief.memory_port.depth_writes
        ),
        (0, 0)
    );
}

#[test]
fn a_clear_writes_the_viewport_and_the_depth_test_waits_for_it() {
    // 64 x 64 pixels of 32-bit depth and 32-bit colour are 64 * 64 * 64 / 256 = 1024 port
    // words, granted in 0..=1023 (the depth test is free from 0). An empty query after it:
    // the end enters in 0, passes the depth pipeline in 1024, the OccU in 1025; its record
    // is ready in 1026 and granted in 1027: available 1028 (the empty pipe's 5 plus 1023).
    let events = [
        Event::Clear,
        query(1, QueryMode::Samples, 8, vec![Rect::new(0, 0, 64, 64)]),
        Event::QueryEnd,
    ];
    let report = run(
        &o2(&["clear_writes_memory=true", "colour_bits_per_pixel=32"]),
        &events,
    );
    assert_eq!(report.memory_port.clear_words, 1024);
    assert_eq!(report.queries[0].latency_cycles, 1028);
    // A fast clear costs nothing.
    let fast = run(&o2(&[]), &events);
    assert_eq!(fast.queries[0].latency_cycles, MIN_QUERY_LATENCY_CYCLES);
}

#[test]
fn a_read_hits_the_open_row_of_its_bank() {
    // 128-pixel tiles: (0,0) and (8,0) lie in tile 0 (different words), (128,0) in tile 1.
    // One bank: every change of tile is a miss (3 misses). Two banks (tile p in bank p mod
    // 2): tile 0's row stays open in bank 0 while bank 1 reads tile 1: the third read hits.
    let events = [
        Event::Primitive,
        fragment(0, 0, 100),
        fragment(128, 0, 100),
        fragment(8, 0, 100),
    ];
    let reads = |banks: &str| {
        let mut machine = O2Machine::new(&o2(&[banks]), 256, 16).unwrap();
        for event in &events {
            machine.event(event).unwrap();
        }
        let port = machine.finish().unwrap().memory_port;
        (port.depth_read_page_hits, port.depth_read_page_misses)
    };
    assert_eq!(reads("memory_banks=1"), (0, 3));
    assert_eq!(reads("memory_banks=2"), (1, 2));
}

#[test]
fn samples_query_of_three_fragments_in_one_word() {
    // Defaults: setup 4, page miss 8, port 256 bits, 4 engines, one tile.
    // Primitive: setup in cycles 0..=3, rasterizer free at 4.
    // F0: emitted 4, request 5, first read = page miss: granted 5, data 13; tested 13;
    //     depth write granted 14; OccU 14 (s = 1), leaves 14.
    // F1: emitted 5, request 6, same word: data 13; tested max(6, 14, 13) = 14; write 15;
    //     OccU 15.
    // F2: emitted 6, request 7, data 13; tested 15; write 16; OccU 16.
    // End enters at 7 (rasterizer free); through depth max(8, 16) = 16; through OccU
    // max(17, 17) = 17; records ready and entering the buffer in 18; they ask the port
    // from 19; 8 words = 256 bits all granted in 19; available 20.
    // Latency 20 - 7 = 13. Cycles: everything idle at 20.
    let viewport = Rect::new(0, 0, 64, 64);
    let events = [
        query(1, QueryMode::Samples, 8, vec![viewport]),
        Event::Primitive,
        fragment(0, 0, 100),
        fragment(1, 0, 100),
        fragment(2, 0, 100),
        Event::QueryEnd,
    ];
    let report = run(&o2(&[]), &events);
    assert_eq!(report.queries[0].end_cycle, 7);
    assert_eq!(report.queries[0].available_cycle, 20);
    assert_eq!(report.queries[0].latency_cycles, 13);
    assert_eq!(report.summary.cycles, 20);
    assert_eq!(report.memory_port.depth_read_words, 1);
    assert_eq!(report.memory_port.depth_read_word_hits, 2);
    assert_eq!(report.memory_port.depth_writes, 3);
    assert_eq!(report.memory_port.occu_words, 8);
    // Depth test: busy 3; F0 waited 13 - 5 = 8 cycles for memory.
    assert_eq!(report.stages[1].busy_cycles, 3);
    assert_eq!(report.stages[1].stall_cycles, 8);
    assert_eq!(report.queries[0].tiles[0].nohc, 3);
}

#[test]
fn three_tiles_on_two_engines_take_two_cycles_per_fragment() {
    // Depth test off: no reads, no writes. Tiles 0 and 2 on engine 0, tile 1 on engine 1:
    // s = 2. Setup 4 -> rasterizer free at 4.
    // F0: emitted 4, tested 5, OccU 6..=7 (leaves 7).
    // F1: emitted 5, tested 6, OccU starts max(7, 8) = 8, leaves 9.
    // F2: emitted 6, tested 7, OccU 10, leaves 11.
    // End enters at 7; through depth max(8, 8) = 8; through OccU max(9, 12) = 12; records
    // (3 x 8 words) enter 13, granted 8 per cycle in 14, 15, 16; available 17; latency 10.
    let tiles = vec![
        Rect::new(0, 0, 8, 8),
        Rect::new(8, 0, 8, 8),
        Rect::new(0, 8, 8, 8),
    ];
    let events = [
        Event::DepthTest(false),
        query(7, QueryMode::Brief, 8, tiles),
        Event::Primitive,
        fragment(1, 1, 5),
        fragment(9, 1, 5),
        fragment(1, 9, 5),
        Event::QueryEnd,
    ];
    let report = run(&o2(&["engines=2"]), &events);
    let q = &report.queries[0];
    assert_eq!(
        (q.end_cycle, q.available_cycle, q.latency_cycles),
        (7, 17, 10)
    );
    assert_eq!(report.summary.cycles, 17);
    assert_eq!(report.memory_port.busy_cycles, 3);
    assert_eq!(report.engines[0].busy_cycles, 6, "2 tiles x 3 fragments");
    assert_eq!(report.engines[1].busy_cycles, 3);
    assert_eq!(report.stages[2].busy_cycles, 6);
    let phc: Vec<u64> = q.tiles.iter().map(|t| t.phc).collect();
    assert_eq!(phc, [1, 1, 1]);

    // With all tiles in one cycle, s = 1: OccU 6, 7, 8; end through OccU max(9, 9) = 9;
    // records enter 10, granted 11, 12, 13; available 14; latency 7.
    let report = run(&o2(&["engines=2", "all_tiles_one_cycle=true"]), &events);
    assert_eq!(report.queries[0].latency_cycles, 7);
}

#[test]
fn an_empty_query_on_an_idle_pipe_takes_the_pipeline_depth() {
    // End enters at 0; depth 1; OccU 2; records enter 3, granted 4; available 5.
    let events = [
        query(0, QueryMode::Any, 8, vec![Rect::new(0, 0, 64, 64)]),
        Event::QueryEnd,
    ];
    let report = run(&o2(&[]), &events);
    assert_eq!(report.queries[0].latency_cycles, 5);
    assert_eq!(MIN_QUERY_LATENCY_CYCLES, 5);
}

#[test]
fn a_full_occu_write_buffer_stalls_the_engines() {
    // Verbose, one tile, room for 255 hits; write buffer of 1 word; depth test off so the
    // port carries only hit words (32 bits each). No setup (0 cycles).
    // F0: emitted 0, tested 1, OccU 2; hit word enters 2 (buffer empty), granted 3.
    // F1: emitted 1, tested 2, OccU 3; its word may enter when word 0 left (3): enters 3,
    //     granted 4. F2: OccU 4, enters 4, granted 5. No stall: one word per cycle keeps up.
    // With 2 hit words per fragment (two overlapping tiles, 2 engines, s = 1):
    // F0: OccU 2; words enter 2 and (after word 0 leaves at 3) 3; leaves 3 (stall 1).
    // F1: tested 2, OccU max(3, 4) = 4; words enter 4 (word 1 left at 4), 5; leaves 5.
    // F2: tested 3, OccU 6; words 6, 7; leaves 7. Stall 1 per fragment: 3.
    let tile = Rect::new(0, 0, 8, 8);
    let events = [
        Event::DepthTest(false),
        query(0, QueryMode::Verbose, 8 + 255, vec![tile, tile]),
        fragment(0, 0, 1),
        fragment(1, 0, 1),
        fragment(2, 0, 1),
        Event::QueryEnd,
    ];
    let arch = o2(&[
        "engines=2",
        "occu_write_buffer_words=1",
        "primitive_setup_cycles=0",
    ]);
    let report = run(&arch, &events);
    assert_eq!(report.stages[2].stall_cycles, 3);
    assert_eq!(report.engines[0].stall_cycles, 3);
    assert_eq!(report.memory_port.occu_words, 6 + 16);
    assert_eq!(report.queries[0].tiles[0].hits_written, 3);
}

#[test]
fn reads_wait_in_order_behind_older_depth_writes() {
    // Prefetch one fragment ahead (L = min(1, 16) = 1), no setup. Three passing, writing
    // fragments in three words of one page: x = 0, 8, 16.
    // Push F0: emitted 0, readable 1; read ready 1 (first: page miss): granted 1, data 9.
    // Push F1 first tests F0: max(1, 9) = 9; its write asks from 10: granted 10; OccU 10.
    //   F1: emitted 1, readable 2; read ready max(2, test of F0 = 9, 1 + 1) = 9, but the port
    //   is in order and cycle 10 holds the write's 32 bits: granted 11; page hit: data 13.
    // Push F2 first tests F1: max(2, 10, 13) = 13 (3 memory-stall cycles); write 14; OccU 14.
    //   F2: emitted 2, read ready max(3, 13, 10) = 13, in order after the write in 14, which
    //   leaves no room: granted 15, data 17.
    // Push End: it enters at 3, the rasterizer's first free cycle.
    // Finish: F2 tested 17, write 18, OccU 18. End through depth max(4, 18) = 18, through
    // OccU max(19, 19) = 19; records enter 20, granted 21; available 22; latency 22 - 3 = 19.
    let events = [
        query(2, QueryMode::Samples, 8, vec![Rect::new(0, 0, 64, 64)]),
        fragment(0, 0, 50),
        fragment(8, 0, 50),
        fragment(16, 0, 50),
        Event::QueryEnd,
    ];
    let arch = o2(&["prefetch_depth_fragments=1", "primitive_setup_cycles=0"]);
    let report = run(&arch, &events);
    let q = &report.queries[0];
    assert_eq!(
        (q.end_cycle, q.available_cycle, q.latency_cycles),
        (3, 22, 19)
    );
    assert_eq!(report.summary.cycles, 22);
    assert_eq!(report.memory_port.depth_read_page_misses, 1);
    assert_eq!(report.memory_port.depth_read_page_hits, 2);
    // Memory stalls: F0 waits 9 - 1 = 8, F1 13 - 10 = 3, F2 17 - 14 = 3.
    assert_eq!(report.stages[1].stall_cycles, 14);
    // Port busy in cycles 1, 10, 11, 14, 15, 18, 21.
    assert_eq!(report.memory_port.busy_cycles, 7);
}

#[test]
fn full_fifos_hold_back_the_rasterizer_and_the_depth_test() {
    // Depth test off (no memory traffic), no setup, raster-to-depth FIFO of 2 (so the
    // prefetcher looks 2 ahead), depth-to-OccU FIFO of 1, three tiles on one engine: s = 3.
    // a_i = max(a_{i-1} + 1, d_{i-2}); d_i = max(a_i + 1, d_{i-1} + 1, o_{i-1});
    // o_i = max(d_i + 1, c_{i-1} + 1); c_i = o_i + 2.
    // F0: a 0, d 1, o 2, c 4.      F1: a 1, d max(2, 2, 2) = 2, o max(3, 5) = 5, c 7.
    // F2: a max(2, 1) = 2, d max(3, 3, 5) = 5, o 8, c 10.
    // F3: a max(3, 2) = 3, d max(4, 6, 8) = 8, o 11, c 13.
    // F4: a max(4, 5) = 5 (1 stall), d max(6, 9, 11) = 11, o 14, c 16.
    // End enters at 6; through depth max(7, 12) = 12; through OccU max(13, 17) = 17; 24
    // record words enter 18, granted 19, 20, 21; available 22; latency 16.
    // Depth back-pressure stall: F2 5 - 3, F3 8 - 6, F4 11 - 9: 6 cycles.
    let tiles = vec![
        Rect::new(0, 0, 8, 8),
        Rect::new(0, 0, 4, 4),
        Rect::new(4, 4, 4, 4),
    ];
    let mut events = vec![
        Event::DepthTest(false),
        query(3, QueryMode::Brief, 8, tiles),
    ];
    events.extend((0..5).map(|x| fragment(x, 0, 1)));
    events.push(Event::QueryEnd);
    let arch = o2(&[
        "engines=1",
        "primitive_setup_cycles=0",
        "fifo_raster_to_depth_entries=2",
        "fifo_depth_to_occu_entries=1",
    ]);
    let report = run(&arch, &events);
    let q = &report.queries[0];
    assert_eq!(
        (q.end_cycle, q.available_cycle, q.latency_cycles),
        (6, 22, 16)
    );
    assert_eq!(report.stages[0].stall_cycles, 1, "rasterizer");
    assert_eq!(report.stages[1].stall_cycles, 6, "depth test");
    assert_eq!(report.stages[2].busy_cycles, 15, "OccU");
    assert_eq!(report.engines[0].busy_cycles, 15);
}

#[test]
fn with_every_new_memory_client_off_the_cycles_are_the_machine_before_them() {
    // The built-in hardcases scene (as `occsim trace gen hardcases` makes it), replayed in
    // the closed loop. Its figures before colour writes, clears, the display refresh, the
    // host share and banks were modelled (commit 8186b99, `occsim replay hc.occt --arch o2
    // --json`): 68751 cycles, one frame of 68751, query latencies summing to 605 with the
    // longest 56, the port busy 16047 cycles.
    let (width, height, events) = support::scene_events(occsim_traces::builtin::HARDCASES);
    let replay = |arch: &Arch| {
        let mut machine = occsim_sim::MachineBuilder::new(arch)
            .build(width, height)
            .unwrap();
        for event in &events {
            machine.event(event).unwrap();
        }
        machine.finish().unwrap()
    };
    let off = replay(&o2(&[]));
    let latencies: Vec<u64> = off.queries.iter().map(|q| q.latency_cycles).collect();
    assert_eq!(off.summary.cycles, 68751);
    assert_eq!(
        off.frames.iter().map(|f| f.cycles).collect::<Vec<_>>(),
        [68751]
    );
    assert_eq!(latencies.iter().sum::<u64>(), 605);
    assert_eq!(latencies.iter().max(), Some(&56));
    assert_eq!(off.memory_port.busy_cycles, 16047);
    // Each client on alone costs time (the defaults have them all on): cycles, or query
    // latency where the host's work hides the pipeline's (this trace is host-bound); colour
    // rides in the depth write's port cycle here, adding bits, not cycles. The display
    // refresh and the host share take only the cycles the pipeline leaves idle until they
    // fall 16 cycles behind (`other_clients_slack_cycles`), which this host-bound trace's
    // port never lets them: they cost it time with a slack of 1 (the host at 0.25: at the
    // O2's 0.05 it would need 20 busy cycles in a row, which this trace's port never has).
    for clients in [
        &["clear_writes_memory=true"][..],
        &["display_refresh_hz=75", "other_clients_slack_cycles=1"],
        &["host_memory_share=0.25", "other_clients_slack_cycles=1"],
    ] {
        let on = replay(&o2(clients));
        let client = clients[0];
        let latency: u64 = on.queries.iter().map(|q| q.latency_cycles).sum();
        assert!(
            on.summary.cycles > 68751 || latency > 605,
            "{client}: {} cycles, latencies {latency}",
            on.summary.cycles
        );
    }
    // With the default slack they do not lengthen the frame (the host's work hides what
    // they take of the pipeline's port time).
    for client in ["display_refresh_hz=75", "host_memory_share=0.05"] {
        let on = replay(&o2(&[client]));
        assert_eq!(on.summary.cycles, 68751, "{client}");
    }
    let colour = replay(&o2(&["colour_bits_per_pixel=32"]));
    assert!(colour.memory_port.colour_writes > 0);
    assert!(colour.memory_port.bits_transferred > off.memory_port.bits_transferred);
    let defaults = replay(&Arch::builtin("o2").unwrap());
    assert!(defaults.summary.cycles > 68751);
}
