//! The golden model's closed-loop records: geometry batches that count every submitted
//! triangle before the primitives it produces, and conditional rendering that discards the
//! draws of a query that passed nothing.

use occsim_traces::golden::GoldenModel;
use occsim_traces::raster::RasterProfile;
use occsim_traces::scene::parse_scene;
use occsim_traces::{Event, GeometryBatch};

/// The events the golden model emits for `scene` with `profile`.
fn events_of(scene: &str, profile: RasterProfile) -> Vec<Event> {
    let lines = parse_scene(scene, "t.scene").expect("a valid scene");
    let mut golden = GoldenModel::with_profile(8, 8, profile);
    let mut events = Vec::new();
    for line in &lines {
        golden.execute(&line.command, &mut events).unwrap();
    }
    golden.finish(&mut events).unwrap();
    events
}

fn batches(events: &[Event]) -> Vec<GeometryBatch> {
    events
        .iter()
        .filter_map(|e| match e {
            Event::Geometry(b) => Some(*b),
            _ => None,
        })
        .collect()
}

/// A triangle covering the whole 8x8 viewport at depth `z` (clip z = window 2z-1).
fn cover(z: f32) -> String {
    let c = 2.0 * z - 1.0;
    format!("tri -1 -1 {c} 1  3 -1 {c} 1  -1 3 {c} 1\n")
}

/// The same triangle wound clockwise: back-facing, culled with `cull 1`.
fn cover_back(z: f32) -> String {
    let c = 2.0 * z - 1.0;
    format!("tri -1 -1 {c} 1  -1 3 {c} 1  3 -1 {c} 1\n")
}

#[test]
fn every_submitted_triangle_is_counted_before_its_primitives() {
    for profile in RasterProfile::ALL {
        // One draw of three triangles, the middle one culled: all three were transformed.
        let scene = format!(
            "viewport 8 8\ncull 1\n{}{}{}end_draw\n{}",
            cover(0.5),
            cover_back(0.5),
            cover(0.25),
            cover_back(0.75)
        );
        let events = events_of(&scene, profile);
        let batches = batches(&events);
        let triangles: u32 = batches.iter().map(|b| b.triangles).sum();
        assert_eq!(triangles, 4, "{profile}: {batches:?}");
        assert_eq!(
            batches.iter().filter(|b| b.starts_draw).count(),
            2,
            "{profile}: two draws: {batches:?}"
        );
        assert!(batches.iter().all(|b| b.vertices == 3 * b.triangles));
        // A batch precedes the first primitive; the last draw (culled) ends in a batch of
        // its own with no primitive after it.
        let first_primitive = events.iter().position(|e| *e == Event::Primitive).unwrap();
        assert!(matches!(events[first_primitive - 1], Event::Geometry(_)));
        assert_eq!(
            *events.last().unwrap(),
            Event::Geometry(GeometryBatch {
                vertices: 3,
                triangles: 1,
                starts_draw: true,
                discarded: false
            }),
            "{profile}"
        );
    }
}

#[test]
fn conditional_rendering_discards_the_draws_of_a_query_that_passed_nothing() {
    // Query 1: a triangle behind the cleared-to-near depth passes nothing; query 2: one in
    // front passes all 64 pixels. Then a triangle under each condition.
    let scene = format!(
        "viewport 8 8\n{}begin 1\n{}end\nbegin 2\n{}end\n\
         begin_conditional 1\n{}end_conditional\nbegin 3\n{}end\n\
         begin_conditional 2\nbegin 4 brief\n{}end\nend_conditional\n",
        cover(0.5),
        cover(0.75),
        cover(0.25),
        cover(0.0),
        cover(0.0),
        cover(0.0)
    );
    let events = events_of(&scene, RasterProfile::Llvmpipe);
    let value_of = |id: u32| {
        events
            .iter()
            .find_map(|e| match e {
                Event::QueryResult(r) if r.id == id => Some(r.value()),
                _ => None,
            })
            .unwrap()
    };
    assert_eq!(value_of(1), 0);
    assert_eq!(value_of(2), 64);
    // Under query 1's condition nothing was drawn, so query 3 (drawing at depth 0 after
    // query 2's triangle at 0.25) passes all 64. Under query 2's, query 4's triangle is
    // drawn: projected on all 64 pixels (PHC), passing none (0 is not less than 0).
    assert_eq!(value_of(3), 64);
    assert_eq!(value_of(4), 0);
    let phc_of_4 = events.iter().find_map(|e| match e {
        Event::QueryResult(r) if r.id == 4 => Some(r.tiles[0].phc),
        _ => None,
    });
    assert_eq!(phc_of_4, Some(64));
    let discarded: Vec<GeometryBatch> = batches(&events)
        .into_iter()
        .filter(|b| b.discarded)
        .collect();
    assert_eq!(
        discarded,
        [GeometryBatch {
            vertices: 3,
            triangles: 1,
            starts_draw: true,
            discarded: true
        }]
    );
    let begins: Vec<&Event> = events
        .iter()
        .filter(|e| matches!(e, Event::ConditionalBegin(_) | Event::ConditionalEnd))
        .collect();
    assert_eq!(
        begins,
        [
            &Event::ConditionalBegin(1),
            &Event::ConditionalEnd,
            &Event::ConditionalBegin(2),
            &Event::ConditionalEnd
        ]
    );
}

#[test]
fn waits_host_work_and_swaps_pass_through_in_order() {
    let scene = "viewport 8 8\nbegin 1 any\nend\nhost nodes=5 boxes=2\nwait 1\nswap\n";
    let events = events_of(scene, RasterProfile::Llvmpipe);
    let tail: Vec<&Event> = events
        .iter()
        .skip_while(|e| !matches!(e, Event::QueryResult(_)))
        .skip(1)
        .collect();
    assert_eq!(
        tail,
        [
            &Event::HostWork(occsim_traces::HostWork {
                nodes: 5,
                boxes: 2,
                decisions: 0,
                pixels: 0,
            }),
            &Event::Wait(1),
            &Event::Swap
        ]
    );
}
