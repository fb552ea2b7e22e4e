//! A span given to the functional model at once gives what its fragments give one by one:
//! the same query results (counts, boxes, depth ranges, hit lists and overflow) and the same
//! depth buffer, under every depth function, with depth writes on and off, in every query
//! mode, for one tile, a few tiles (scanned) and many tiles (indexed).

use occsim_traces::golden::FunctionalModel;
use occsim_traces::{DepthFunc, Event, QueryMode, QuerySpec, Rect, Span};
use proptest::prelude::*;

const WIDTH: u32 = 48;
const HEIGHT: u32 = 20;

/// One step of a random stream: a span (x, y, depths) or a state change or query.
#[derive(Clone, Debug)]
enum Step {
    Span {
        x: u16,
        y: u16,
        depths: Vec<u32>,
    },
    Func(DepthFunc),
    Mask(bool),
    Test(bool),
    Query {
        mode: QueryMode,
        tiles: Vec<Rect>,
        entries: u32,
    },
}

fn step() -> impl Strategy<Value = Step> {
    let span = (
        0..WIDTH as u16,
        0..HEIGHT as u16,
        prop::collection::vec(0u32..64, 1..20),
    )
        .prop_map(|(x, y, mut depths)| {
            depths.truncate(WIDTH as usize - x as usize);
            Step::Span { x, y, depths }
        });
    let func = (0u8..8).prop_map(|code| Step::Func(DepthFunc::from_code(code).unwrap()));
    let tile = (0..WIDTH, 0..HEIGHT, 1..WIDTH, 1..HEIGHT)
        .prop_map(|(x, y, w, h)| Rect::new(x, y, w.min(WIDTH - x), h.min(HEIGHT - y)));
    let query = (
        prop::sample::select(vec![
            QueryMode::Samples,
            QueryMode::Any,
            QueryMode::Brief,
            QueryMode::Verbose,
        ]),
        prop::collection::vec(tile, 1..14),
        8u32..24,
    )
        .prop_map(|(mode, tiles, entries)| {
            let tiles = match mode {
                QueryMode::Samples | QueryMode::Any => tiles[..1].to_vec(),
                _ => tiles,
            };
            Step::Query {
                mode,
                tiles,
                entries,
            }
        });
    prop_oneof![
        6 => span,
        1 => func,
        1 => any::<bool>().prop_map(Step::Mask),
        1 => any::<bool>().prop_map(Step::Test),
        2 => query,
    ]
}

/// Replay `steps` on a fresh model, spans whole or fragment by fragment; returns every
/// query's result and the final depths.
fn replay(steps: &[Step], whole_spans: bool) -> (Vec<String>, Vec<u32>) {
    let mut model = FunctionalModel::new(WIDTH, HEIGHT);
    let mut results = Vec::new();
    let mut open = false;
    let mut id = 0;
    let mut apply = |model: &mut FunctionalModel, event: Event| {
        if let Some(result) = model.event(&event) {
            results.push(format!("{result:?}"));
        }
    };
    for step in steps {
        match step {
            Step::Span { x, y, depths } => {
                let span = Span {
                    x: *x,
                    y: *y,
                    depths,
                };
                if whole_spans {
                    model.span(span);
                } else {
                    span.fragments()
                        .for_each(|f| apply(&mut model, Event::Fragment(f)));
                }
            }
            Step::Func(func) => apply(&mut model, Event::DepthFunc(*func)),
            Step::Mask(on) => apply(&mut model, Event::DepthMask(*on)),
            Step::Test(on) => apply(&mut model, Event::DepthTest(*on)),
            Step::Query {
                mode,
                tiles,
                entries,
            } => {
                if open {
                    apply(&mut model, Event::QueryEnd);
                }
                id += 1;
                let spec = QuerySpec {
                    id,
                    mode: *mode,
                    buffer_entries: *entries,
                    tiles: tiles.clone(),
                };
                apply(&mut model, Event::QueryBegin(spec));
                open = true;
            }
        }
    }
    if open {
        apply(&mut model, Event::QueryEnd);
    }
    let depth = model.depth_buffer();
    let depths = (0..HEIGHT as u16)
        .flat_map(|y| (0..WIDTH as u16).map(move |x| (x, y)))
        .map(|(x, y)| depth.get(x, y))
        .collect();
    (results, depths)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn spans_whole_equal_spans_fragment_by_fragment(
        steps in prop::collection::vec(step(), 1..60)
    ) {
        let (whole, whole_depths) = replay(&steps, true);
        let (one_by_one, one_by_one_depths) = replay(&steps, false);
        prop_assert_eq!(whole, one_by_one);
        prop_assert_eq!(whole_depths, one_by_one_depths);
    }
}

#[test]
fn a_span_over_two_tiles_counts_in_each_and_keeps_its_hits_in_order() {
    // Verbose, 2 tiles of 4 columns at x 0..4 and 4..8 on row 0; a span of 6 at x = 1, all
    // passing (buffer cleared to 1.0): tile 0 gets x 1..4, tile 1 gets x 4..7.
    let mut model = FunctionalModel::new(8, 1);
    model.event(&Event::QueryBegin(QuerySpec {
        id: 1,
        mode: QueryMode::Verbose,
        buffer_entries: 64,
        tiles: vec![Rect::new(0, 0, 4, 1), Rect::new(4, 0, 4, 1)],
    }));
    model.span(Span {
        x: 1,
        y: 0,
        depths: &[10, 20, 30, 40, 50, 60],
    });
    let result = model.event(&Event::QueryEnd).unwrap();
    let tiles = &result.tiles;
    assert_eq!((tiles[0].phc, tiles[0].nohc), (3, 3));
    assert_eq!((tiles[0].xmin, tiles[0].xmax), (1, 3));
    assert_eq!((tiles[0].zmin, tiles[0].zmax), (10, 30));
    assert_eq!(tiles[0].hits.listed(), [(1, 0), (2, 0), (3, 0)]);
    assert_eq!((tiles[1].phc, tiles[1].nohc), (3, 3));
    assert_eq!((tiles[1].xmin, tiles[1].xmax), (4, 6));
    assert_eq!(tiles[1].hits.listed(), [(4, 0), (5, 0), (6, 0)]);
}
