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

fn text(report: &occsim_sim::Report, with_queries: bool) -> String {
    occsim_sim::LevelResult::from_report(report.clone(), occsim_sim::Effects::ALL)
        .to_text(with_queries)
}

#[test]
fn the_text_starts_with_the_level_and_summary_lines_and_has_every_table() {
    let report = report();
    let text = text(&report, true);
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "level cycle, machine o2 (4 engines) at 66.67 MHz, viewport 16x16"
    );
    let summary = lines.next().unwrap();
    assert!(
        summary.starts_with(&format!("{} cycles (", report.summary.cycles)),
        "{summary}"
    );
    assert!(
        summary.contains("2 fragments") && summary.contains("latency p50"),
        "{summary}"
    );
    for heading in ["stage", "memory port:", "engine", "mode"] {
        assert!(
            text.lines()
                .any(|l| l.trim_start().starts_with(heading) || l.contains(heading)),
            "{heading}"
        );
    }
    assert!(text.lines().any(|l| l.contains("occlusion_unit")));
    // Every table says what its columns are, with units.
    for legend in [
        "  busy, stall: cycles, summed over a stage's units where it has several",
        "(the pixel pipeline's bits over the bits the port could have carried)",
        "  engine E of the Occlusion Unit: busy: cycles testing fragments",
        "nohc, phc: passing and projected fragments summed over the tiles",
    ] {
        assert!(text.contains(legend), "no legend `{legend}` in\n{text}");
    }
    let query_rows = |text: &str| {
        text.lines()
            .filter(|l| l.split_whitespace().nth(2) == Some("verbose"))
            .count()
    };
    assert_eq!(query_rows(&text), 1, "one query row");
    assert_eq!(
        query_rows(&self::text(&report, false)),
        0,
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
