//! The InfiniteReality-like machine's merged results against the functional golden model, on
//! generated streams, for every interleave and many board, Image Engine and engine counts.

use occsim_sim::{Arch, IrMachine, Report, SimError};
use occsim_traces::golden::FunctionalModel;
use occsim_traces::{DepthFunc, Event, Fragment, QueryMode, QueryResult, QuerySpec, Rect};

const WIDTH: u32 = 40;
const HEIGHT: u32 = 24;

use occsim_traces::rng::SplitMix64;

fn random_tile(rng: &mut SplitMix64) -> Rect {
    let x = rng.below(WIDTH as u64) as u32;
    let y = rng.below(HEIGHT as u64) as u32;
    let w = 1 + rng.below((WIDTH - x) as u64) as u32;
    let h = 1 + rng.below((HEIGHT - y) as u64) as u32;
    Rect::new(x, y, w, h)
}

/// The raw stream (no results): state changes, queries over spans and blocks of fragments at
/// depths with many ties; verbose buffers small enough to overflow often.
fn raw_stream(seed: u64) -> Vec<Event> {
    let mut rng = SplitMix64(seed);
    let mut events = Vec::new();
    for query in 0..(3 + rng.below(5)) {
        match rng.below(5) {
            0 => events.push(Event::Clear),
            1 => events.push(Event::DepthFunc(DepthFunc::ALL[rng.below(8) as usize])),
            2 => events.push(Event::DepthMask(rng.below(4) != 0)),
            3 => events.push(Event::DepthTest(rng.below(5) != 0)),
            _ => {}
        }
        let mode = QueryMode::ALL[rng.below(4) as usize];
        let (tiles, buffer_entries) = match mode {
            QueryMode::Samples | QueryMode::Any => (vec![Rect::new(0, 0, WIDTH, HEIGHT)], 8),
            _ => {
                let tiles = (0..1 + rng.below(20))
                    .map(|_| random_tile(&mut rng))
                    .collect();
                (tiles, 8 + rng.below(40) as u32)
            }
        };
        events.push(Event::QueryBegin(QuerySpec {
            id: query as u32,
            mode,
            buffer_entries,
            tiles,
        }));
        for _ in 0..1 + rng.below(5) {
            events.push(Event::Primitive);
            let (x0, y0) = (
                rng.below(WIDTH as u64) as u16,
                rng.below(HEIGHT as u64) as u16,
            );
            let (w, h) = (1 + rng.below(20) as u16, 1 + rng.below(8) as u16);
            let z = rng.below(6) as u32 * 1000;
            for y in y0..(y0 + h).min(HEIGHT as u16) {
                for x in x0..(x0 + w).min(WIDTH as u16) {
                    events.push(Event::Fragment(Fragment { x, y, z }));
                }
            }
        }
        events.push(Event::QueryEnd);
    }
    events
}

/// `raw` with the golden model's result after every query end.
fn with_golden_results(raw: &[Event]) -> Vec<Event> {
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    let mut events = Vec::new();
    for event in raw {
        events.push(event.clone());
        if let Some(result) = golden.event(event) {
            events.push(Event::QueryResult(result));
        }
    }
    events
}

/// The golden results with verbose buffers big enough for every hit: the true hits.
fn all_hits(raw: &[Event]) -> Vec<QueryResult> {
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    raw.iter()
        .filter_map(|event| match event {
            Event::QueryBegin(spec) => {
                let mut spec = spec.clone();
                spec.buffer_entries = 8 + WIDTH * HEIGHT * 8;
                golden.event(&Event::QueryBegin(spec))
            }
            other => golden.event(other),
        })
        .collect()
}

fn arch(sets: &[String]) -> Arch {
    let mut arch = Arch::builtin("ir4").unwrap();
    for set in sets {
        arch.set(set).unwrap_or_else(|e| panic!("--set {set}: {e}"));
    }
    arch
}

/// Replays `events`, returning the report and every query's merged result.
fn replay(arch: &Arch, events: &[Event]) -> Result<(Report, Vec<QueryResult>), SimError> {
    let mut machine = IrMachine::new(arch, WIDTH, HEIGHT)?;
    let mut results = Vec::new();
    for event in events {
        machine.event(event)?;
        if matches!(event, Event::QueryEnd) {
            results.push(machine.last_result().unwrap().clone());
        }
    }
    Ok((machine.finish()?, results))
}

/// `part` is a sub-multiset of `whole`.
fn is_sub_multiset(part: &[(u16, u16)], whole: &[(u16, u16)]) -> bool {
    let mut whole = whole.to_vec();
    part.iter()
        .all(|hit| match whole.iter().position(|h| h == hit) {
            Some(i) => {
                whole.swap_remove(i);
                true
            }
            None => false,
        })
}

#[test]
fn counts_equal_the_golden_model_for_every_interleave_and_count() {
    for seed in 0..6 {
        let raw = raw_stream(seed);
        let events = with_golden_results(&raw);
        let truth = all_hits(&raw);
        for interleave in ["columns", "blocks", "morton"] {
            for boards in [1, 2, 4] {
                for image_engines in [1, 3, 8] {
                    for engines in [1, 2, 5, 16] {
                        let sets = [
                            format!("interleave={interleave}"),
                            format!("boards={boards}"),
                            format!("image_engines_per_board={image_engines}"),
                            format!("engines={engines}"),
                            "block_width_pixels=3".to_string(),
                            "block_height_pixels=2".to_string(),
                        ];
                        let context = format!("seed {seed}, {sets:?}");
                        let (report, results) = replay(&arch(&sets), &events)
                            .unwrap_or_else(|e| panic!("{context}: {e}"));
                        assert_eq!(
                            report.summary.checked_queries,
                            truth.len() as u64,
                            "{context}"
                        );
                        for (result, truth) in results.iter().zip(&truth) {
                            for (tile, true_tile) in result.tiles.iter().zip(&truth.tiles) {
                                assert!(
                                    is_sub_multiset(tile.hits.listed(), true_tile.hits.listed()),
                                    "{context}: query {} kept a hit that is not a true hit",
                                    result.id
                                );
                            }
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn a_tile_split_across_boards_and_image_engines_is_merged_exactly() {
    // Columns interleave over 2 boards x 3 Image Engines: columns 0..6 of the 6x4 block land
    // on all six Image Engines. Hand-worked expectation: all 24 fragments pass (z 100 < 1.0).
    let tile = Rect::new(1, 1, 5, 3); // x 1..=5, y 1..=3: 15 pixels, 5 units.
    let mut events = vec![Event::QueryBegin(QuerySpec {
        id: 7,
        mode: QueryMode::Verbose,
        buffer_entries: 8 + 64,
        tiles: vec![tile, Rect::new(0, 0, 1, 1)],
    })];
    events.push(Event::Primitive);
    for y in 0..4u16 {
        for x in 0..6u16 {
            events.push(Event::Fragment(Fragment {
                x,
                y,
                z: 100 + x as u32 * 10 + y as u32,
            }));
        }
    }
    events.push(Event::QueryEnd);
    let sets = [
        "boards=2".to_string(),
        "image_engines_per_board=3".to_string(),
    ];
    let (_, results) = replay(&arch(&sets), &events).unwrap();
    let merged = &results[0].tiles[0];
    assert_eq!((merged.nohc, merged.phc), (15, 15));
    assert_eq!(
        (merged.xmin, merged.xmax, merged.ymin, merged.ymax),
        (1, 5, 1, 3)
    );
    assert_eq!((merged.zmin, merged.zmax), (111, 153));
    let mut hits = merged.hits.listed().to_vec();
    hits.sort_unstable();
    let expected: Vec<(u16, u16)> = (1..=5).flat_map(|x| (1..=3).map(move |y| (x, y))).collect();
    assert_eq!(hits, expected);
    assert!(!merged.overflowed);
    // Board 1 owns columns 1, 3, 5; board 0 columns 0, 2, 4: hits come board by board.
    assert_eq!(
        merged.hits.listed()[0],
        (2, 1),
        "board 0's first Image Engine with a hit owns column 2"
    );
    let corner = &results[0].tiles[1];
    assert_eq!(
        (corner.nohc, corner.hits.listed()),
        (1, &[(0u16, 0u16)][..])
    );
}

#[test]
fn overflowed_hit_lists_keep_room_minus_one_true_hits() {
    let mut events = vec![Event::QueryBegin(QuerySpec {
        id: 1,
        mode: QueryMode::Verbose,
        buffer_entries: 8 + 5,
        tiles: vec![Rect::new(0, 0, 8, 1)],
    })];
    events.push(Event::Primitive);
    for x in 0..8u16 {
        events.push(Event::Fragment(Fragment { x, y: 0, z: 5 }));
    }
    events.push(Event::QueryEnd);
    let (report, results) = replay(&arch(&["image_engines_per_board=2".into()]), &events).unwrap();
    let tile = &results[0].tiles[0];
    assert!(tile.overflowed);
    assert_eq!(
        tile.hits.len(),
        4,
        "room 5, one entry taken by the -1 terminator"
    );
    assert!(tile.hits.listed().iter().all(|&(x, y)| x < 8 && y == 0));
    assert_eq!(report.queries[0].overflowed_buffers, 1);
}

#[test]
fn a_wrong_golden_count_is_reported() {
    let raw = raw_stream(2);
    let mut events = with_golden_results(&raw);
    let golden = events
        .iter_mut()
        .find_map(|e| match e {
            Event::QueryResult(r) => Some(r),
            _ => None,
        })
        .unwrap();
    golden.tiles[0].phc += 1;
    let error = replay(&arch(&[]), &events).unwrap_err();
    assert!(
        matches!(error, SimError::Mismatch { ref field, .. } if field.contains("phc")),
        "{error}"
    );
}

#[test]
fn narrow_counters_saturate_after_merging() {
    for seed in 0..4 {
        let events = with_golden_results(&raw_stream(seed));
        for boards in [1, 4] {
            let sets = [
                "counter_bits=3".to_string(),
                format!("boards={boards}"),
                "image_engines_per_board=5".to_string(),
            ];
            let (report, _) = replay(&arch(&sets), &events)
                .unwrap_or_else(|e| panic!("seed {seed}, {sets:?}: {e}"));
            assert!(report
                .queries
                .iter()
                .flat_map(|q| &q.tiles)
                .all(|t| t.nohc <= 7 && t.phc <= 7));
            assert_eq!(report.summary.checked_queries, report.summary.queries);
        }
    }
}
