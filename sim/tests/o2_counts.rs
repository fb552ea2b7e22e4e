//! The O2-like machine's counts against the functional golden model, on generated event
//! streams, and the properties of its timing that must hold on any stream.

use occsim_sim::machines::o2::MIN_QUERY_LATENCY_CYCLES;
use occsim_sim::{Arch, O2Machine, Report, SimError};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{DepthFunc, Event, Fragment, QueryMode, QuerySpec, Rect};
use proptest::prelude::*;

const WIDTH: u32 = 48;
const HEIGHT: u32 = 40;

use occsim_traces::rng::SplitMix64;

fn random_tile(rng: &mut SplitMix64) -> Rect {
    let x = rng.below(WIDTH as u64) as u32;
    let y = rng.below(HEIGHT as u64) as u32;
    let w = 1 + rng.below((WIDTH - x) as u64) as u32;
    let h = 1 + rng.below((HEIGHT - y) as u64) as u32;
    Rect::new(x, y, w, h)
}

/// A stream of state changes, primitives, fragments and queries, with the golden model's
/// result after every query end. `max_tiles` bounds the tiles of brief/verbose queries.
fn generated_stream(seed: u64, max_tiles: u64) -> Vec<Event> {
    let mut rng = SplitMix64(seed);
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    let mut events = Vec::new();
    let mut push = |event: Event, events: &mut Vec<Event>| {
        if let Some(result) = golden.event(&event) {
            events.push(event);
            events.push(Event::QueryResult(result));
        } else {
            events.push(event);
        }
    };
    for query in 0..(2 + rng.below(6)) {
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
                let count = 1 + rng.below(max_tiles);
                let tiles = (0..count).map(|_| random_tile(&mut rng)).collect();
                (tiles, 8 + rng.below(12) as u32)
            }
        };
        let spec = QuerySpec {
            id: query as u32 * 10,
            mode,
            buffer_entries,
            tiles,
        };
        push(Event::QueryBegin(spec), &mut events);
        for _ in 0..rng.below(6) {
            push(Event::Primitive, &mut events);
            // A span of fragments, as a rasterizer emits them, at depths with many ties.
            let (x0, y) = (
                rng.below(WIDTH as u64) as u16,
                rng.below(HEIGHT as u64) as u16,
            );
            let z = rng.below(8) as u32 * 1000;
            for x in x0..(x0 + 1 + rng.below(24) as u16).min(WIDTH as u16) {
                push(Event::Fragment(Fragment { x, y, z }), &mut events);
            }
        }
        push(Event::QueryEnd, &mut events);
        // Some fragments outside any query.
        for _ in 0..rng.below(3) {
            let (x, y) = (
                rng.below(WIDTH as u64) as u16,
                rng.below(HEIGHT as u64) as u16,
            );
            push(Event::Fragment(Fragment { x, y, z: 7 }), &mut events);
        }
    }
    events
}

fn arch(sets: &[String]) -> Arch {
    let mut arch = Arch::builtin("o2").unwrap();
    for set in sets {
        arch.set(set).unwrap();
    }
    arch
}

fn replay(arch: &Arch, events: &[Event]) -> Result<Report, SimError> {
    let mut machine = O2Machine::new(arch, WIDTH, HEIGHT)?;
    for event in events {
        machine.event(event)?;
    }
    machine.finish()
}

#[test]
fn counts_equal_the_golden_model_at_engine_counts_1_to_16() {
    for seed in 0..40 {
        let events = generated_stream(seed, 24);
        let queries = events
            .iter()
            .filter(|e| matches!(e, Event::QueryEnd))
            .count() as u64;
        for engines in 1..=16 {
            let report = replay(&arch(&[format!("engines={engines}")]), &events)
                .unwrap_or_else(|e| panic!("seed {seed}, {engines} engines: {e}"));
            assert_eq!(report.summary.checked_queries, queries, "seed {seed}");
        }
    }
}

#[test]
fn a_count_differing_from_the_golden_result_names_the_query() {
    let mut events = generated_stream(3, 4);
    let (position, golden_id) = events
        .iter()
        .enumerate()
        .filter_map(|(i, e)| match e {
            Event::QueryResult(r) => Some((i, r.id)),
            _ => None,
        })
        .nth(1)
        .unwrap();
    if let Event::QueryResult(result) = &mut events[position] {
        result.tiles[0].phc += 1;
    }
    match replay(&arch(&[]), &events) {
        Err(SimError::Mismatch {
            id, index, field, ..
        }) => {
            assert_eq!((id, index, field.as_str()), (golden_id, 1, "tile 0 phc"));
        }
        other => panic!("expected a mismatch, got {other:?}"),
    }
}

#[test]
fn verbose_buffers_that_fit_exactly_overflow_by_one_or_hold_only_the_record() {
    // Three passing fragments in one tile.
    let run = |buffer_entries: u32| {
        let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
        let mut events = vec![Event::QueryBegin(QuerySpec {
            id: 5,
            mode: QueryMode::Verbose,
            buffer_entries,
            tiles: vec![Rect::new(0, 0, 8, 8)],
        })];
        events.extend((0..3).map(|x| Event::Fragment(Fragment { x, y: 0, z: 10 })));
        events.push(Event::QueryEnd);
        for event in &events {
            if let Some(result) = golden.event(event) {
                events.push(Event::QueryResult(result));
                break;
            }
        }
        replay(&arch(&[]), &events).unwrap()
    };
    // 8 + 3 entries: all three hits fit; 3 hit words + the 8-word record.
    let exact = run(11);
    let tile = &exact.queries[0].tiles[0];
    assert_eq!((tile.hits_written, tile.overflowed), (3, false));
    assert_eq!(exact.queries[0].overflowed_buffers, 0);
    assert_eq!(exact.memory_port.occu_words, 11);
    // 8 + 2 entries: one hit too many; two hit words sent, then the -1 terminator replaces
    // the second: 1 hit kept, 2 + 8 + 1 words.
    let over = run(10);
    let tile = &over.queries[0].tiles[0];
    assert_eq!((tile.hits_written, tile.overflowed), (1, true));
    assert_eq!(over.queries[0].overflowed_buffers, 1);
    assert_eq!(over.memory_port.occu_words, 11);
    // 8 entries: room for neither hits nor terminator: just the record, overflowed.
    let minimum = run(8);
    let tile = &minimum.queries[0].tiles[0];
    assert_eq!((tile.hits_written, tile.overflowed), (0, true));
    assert_eq!(minimum.memory_port.occu_words, 8);
}

#[test]
fn counters_saturate_at_a_narrow_width() {
    // Ten passing fragments in a viewport query with 3-bit counters: 7 = 2^3 - 1. The golden
    // model's exact 10 saturates to 7 in the comparison, so the replay passes.
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    let mut events = vec![Event::QueryBegin(QuerySpec {
        id: 1,
        mode: QueryMode::Samples,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, WIDTH, HEIGHT)],
    })];
    events.extend((0..10).map(|x| Event::Fragment(Fragment { x, y: 1, z: 10 })));
    events.push(Event::QueryEnd);
    let result = events.iter().find_map(|e| golden.event(e)).unwrap();
    assert_eq!(result.tiles[0].nohc, 10);
    events.push(Event::QueryResult(result));
    let report = replay(&arch(&["counter_bits=3".into()]), &events).unwrap();
    assert_eq!(
        (
            report.queries[0].tiles[0].nohc,
            report.queries[0].tiles[0].phc
        ),
        (7, 7)
    );
    assert_eq!(report.summary.checked_queries, 1);
    // At 4 bits (max 15) the counters hold 10.
    let report = replay(&arch(&["counter_bits=4".into()]), &events).unwrap();
    assert_eq!(report.queries[0].tiles[0].nohc, 10);
}

#[test]
fn malformed_streams_are_errors_not_panics() {
    let m = || O2Machine::new(&arch(&[]), WIDTH, HEIGHT).unwrap();
    let outside = Event::Fragment(Fragment {
        x: WIDTH as u16,
        y: 0,
        z: 0,
    });
    assert!(matches!(
        m().event(&outside),
        Err(SimError::FragmentOutside { .. })
    ));
    assert!(matches!(
        m().event(&Event::QueryEnd),
        Err(SimError::EndWithoutBegin { .. })
    ));
    let small = Event::QueryBegin(QuerySpec {
        id: 2,
        mode: QueryMode::Verbose,
        buffer_entries: 7,
        tiles: vec![Rect::new(0, 0, 4, 4)],
    });
    assert!(matches!(
        m().event(&small),
        Err(SimError::BufferTooSmall { .. })
    ));
    assert!(O2Machine::new(&arch(&[]), 0, 10).is_err());
}

/// Every query's available cycle on the generated stream of `seed`, at 1 to 13 engines
/// (the engine count `e` at index `e - 1`), with `sets` applied too.
fn available_by_engines(seed: u64, sets: &[&str]) -> Vec<Vec<u64>> {
    let events = generated_stream(seed, 12);
    (1..=13)
        .map(|engines| {
            let mut all = vec![format!("engines={engines}")];
            all.extend(sets.iter().map(|set| set.to_string()));
            let report = replay(&arch(&all), &events).unwrap();
            report.queries.iter().map(|q| q.available_cycle).collect()
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn more_engines_never_make_a_query_finish_later(seed in any::<u64>()) {
        // With the port's other clients off, more engines only shorten the Occlusion
        // Unit's service: no query's result may come later.
        let alone = ["host_memory_share=0", "display_width_pixels=0"];
        let available = available_by_engines(seed, &alone);
        for (engines, pair) in (2..).zip(available.windows(2)) {
            for (q, (now, before)) in pair[1].iter().zip(&pair[0]).enumerate() {
                prop_assert!(now <= before, "query #{} at {} engines: {} > {}", q, engines, now, before);
            }
        }
    }

    #[test]
    fn more_engines_make_a_query_finish_later_by_less_than_the_other_clients_slack(seed in any::<u64>()) {
        // With the display refresh and the host on (the O2's defaults), the port is not
        // monotone: work done sooner leaves those clients further behind (their debt builds
        // a cycle's share at every busy port cycle and pays off at idle ones), and they
        // take it back from later work. (Seed 14693689128000761447: at 6 engines a verbose
        // query's fragments leave the Occlusion Unit a cycle apart instead of two, its
        // records are through 3 cycles sooner, and the clear after it ends the next
        // query's records a cycle later, 1974 against 1973.) The debt never exceeds the
        // slack `σ` = 16 cycles, and a debt higher by `d` stretches the work after it by
        // at most `d / (1 - f)` port cycles (`port = max(work, (work + debt - σ) / (1 -
        // f))`), `f` the share the two take: 0.184 for the refresh (1280 x 1024 pixels of
        // 32 bits at 75 Hz, 3.15 Gbit/s, over 256 bits at 66 MHz, 16.9 Gbit/s) and 0.05 for
        // the host, 0.234; so no result comes more than 16 / 0.766 = 20.9, at most 20
        // whole cycles later. (Over 20,000 generated streams the most was 8; one stream in
        // about 300 has a result later at all, so the property above, held with these
        // clients on, failed a run of 48 cases now and then.)
        let available = available_by_engines(seed, &[]);
        for (engines, pair) in (2..).zip(available.windows(2)) {
            for (q, (now, before)) in pair[1].iter().zip(&pair[0]).enumerate() {
                prop_assert!(*now <= before + 20, "query #{} at {} engines: {} > {} + 20", q, engines, now, before);
            }
        }
    }

    #[test]
    fn latency_is_never_below_the_pipeline_depth(seed in any::<u64>(), engines in 1usize..9) {
        let report = replay(&arch(&[format!("engines={engines}")]), &generated_stream(seed, 12)).unwrap();
        for q in &report.queries {
            prop_assert!(q.latency_cycles >= MIN_QUERY_LATENCY_CYCLES);
        }
    }

    #[test]
    fn the_port_never_carries_more_than_its_width(seed in any::<u64>(), wide in any::<bool>()) {
        // Every memory client on: colour writes with blending, clears, the display refresh
        // (1280x1024 at 75 Hz: 74 % of a 64-bit port) and the host's share.
        let width = if wide { 256 } else { 64 };
        let sets = [
            format!("memory_port_bits_per_cycle={width}"),
            "occu_write_buffer_words=3".to_string(),
            "depth_write_buffer_entries=2".to_string(),
            "blending=true".to_string(),
        ];
        // A clear first (the depth buffer starts cleared: the golden results stand).
        let mut events = generated_stream(seed, 24);
        events.insert(0, Event::Clear);
        let report = replay(&arch(&sets), &events).unwrap();
        let port = &report.memory_port;
        prop_assert!(port.clear_words > 0 && port.reserved_cycles > 0);
        prop_assert!(port.max_bits_in_one_cycle <= width);
        prop_assert!(port.bits_transferred <= port.busy_cycles * width as u64);
        // Reserved cycles carry nothing of the pipeline's.
        prop_assert!(port.busy_cycles + port.reserved_cycles <= report.summary.cycles);
        prop_assert!(port.busy_cycles <= report.summary.cycles);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn any_buffer_sizes_keep_the_counts_and_the_minimum_latency(
        seed in any::<u64>(),
        raster_fifo in 1usize..5,
        occu_fifo in 1usize..4,
        prefetch in 1usize..20,
        depth_writes in 1usize..4,
        occu_words in 1usize..10,
        engines in 1usize..6,
        setup in 0u64..3,
    ) {
        let sets = [
            format!("fifo_raster_to_depth_entries={raster_fifo}"),
            format!("fifo_depth_to_occu_entries={occu_fifo}"),
            format!("prefetch_depth_fragments={prefetch}"),
            format!("depth_write_buffer_entries={depth_writes}"),
            format!("occu_write_buffer_words={occu_words}"),
            format!("engines={engines}"),
            format!("primitive_setup_cycles={setup}"),
        ];
        let events = generated_stream(seed, 8);
        let report = replay(&arch(&sets), &events).unwrap();
        let queries = events.iter().filter(|e| matches!(e, Event::QueryEnd)).count() as u64;
        prop_assert_eq!(report.summary.checked_queries, queries);
        for q in &report.queries {
            prop_assert!(q.latency_cycles >= MIN_QUERY_LATENCY_CYCLES);
        }
        prop_assert!(report.summary.cycles >= report.summary.fragments);
    }
}
