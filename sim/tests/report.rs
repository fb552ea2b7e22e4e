//! The replay report's text and JSON forms carry what `occsim replay` promises.

use occsim_sim::{Arch, O2Machine};
use occsim_traces::{Event, Fragment, QueryMode, QuerySpec, Rect};

fn report() -> occsim_sim::Report {
    let mut machine = O2Machine::new(&Arch::builtin("o2").unwrap(), 16, 16).unwrap();
    let events = [
        Event::QueryBegin(QuerySpec {
            id: 42,
            mode: QueryMode::Verbose,
            buffer_entries: 9,
            tiles: vec![Rect::new(0, 0, 8, 8), Rect::new(8, 0, 8, 8)],
        }),
        Event::Primitive,
        Event::Fragment(Fragment { x: 1, y: 1, z: 3 }),
        Event::Fragment(Fragment { x: 2, y: 1, z: 3 }),
        Event::QueryEnd,
    ];
    for event in &events {
        machine.event(event).unwrap();
    }
    machine.finish().unwrap()
}

#[test]
fn the_text_starts_with_the_summary_line_and_has_every_table() {
    let report = report();
    let text = report.to_text(true);
    let first = text.lines().next().unwrap();
    assert!(
        first.starts_with(&format!("{} cycles (", report.summary.cycles)),
        "{first}"
    );
    assert!(
        first.contains("2 fragments") && first.contains("latency p50"),
        "{first}"
    );
    for heading in ["stage", "memory port:", "engine", "mode"] {
        assert!(
            text.lines()
                .any(|l| l.trim_start().starts_with(heading) || l.contains(heading)),
            "{heading}"
        );
    }
    assert!(text.lines().any(|l| l.contains("occlusion_unit")));
    assert_eq!(
        text.lines().filter(|l| l.contains("verbose")).count(),
        1,
        "one query row"
    );
    assert!(
        !report.to_text(false).contains("verbose"),
        "no query table without --queries"
    );
}

#[test]
fn the_json_names_every_query_and_tile_field() {
    let value = serde_json::to_value(report()).unwrap();
    let query = &value["queries"][0];
    assert_eq!(query["id"], 42);
    assert_eq!(query["mode"], "verbose");
    assert!(query["latency_cycles"].as_u64().unwrap() >= 5);
    let tile = &query["tiles"][0];
    for key in [
        "nohc",
        "phc",
        "xmin",
        "xmax",
        "ymin",
        "ymax",
        "zmin",
        "zmax",
        "hits_written",
        "overflowed",
    ] {
        assert!(!tile[key].is_null(), "{key}");
    }
    // Room for one hit: two hits overflow; the terminator replaces the one kept.
    assert_eq!(
        (tile["nohc"].as_u64(), tile["hits_written"].as_u64()),
        (Some(2), Some(0))
    );
    assert_eq!(tile["overflowed"], true);
    assert_eq!(query["tiles"][1]["overflowed"], false);
    for key in ["summary", "stages", "memory_port", "engines", "arch"] {
        assert!(!value[key].is_null(), "{key}");
    }
}
