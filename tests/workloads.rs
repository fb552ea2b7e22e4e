//! Walkthrough traces end to end: made by a culling driver, replayed with their golden
//! answers checked; `culling compare` prints every driver with cycles on the machines.

mod support;

use support::cli::stdout_of as occsim;

#[test]
fn every_driver_makes_a_trace_that_replays_against_its_golden_answers() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    for (scene, driver) in [
        ("city", "frustum"),
        ("city", "hierarchical"),
        ("forest", "lazy-grid"),
        ("forest", "busy-grid"),
    ] {
        let trace = dir.join(format!("{scene}-{driver}.occt"));
        let trace = trace.to_str().unwrap();
        let made = occsim(&[
            "trace", "gen", "--scene", scene, "--driver", driver, "--frames", "2", "--width",
            "160", "--height", "128", "-o", trace,
        ]);
        assert!(
            made.starts_with(&format!("wrote {trace}: 2 frames, ")),
            "{made}"
        );
        let replay = occsim(&["replay", trace, "--engines", "3"]);
        assert!(
            replay.contains("checked against golden results"),
            "{replay}"
        );
    }
}

#[test]
fn culling_compare_lists_every_driver_with_o2_and_ir4_cycles() {
    let table = occsim(&[
        "culling", "compare", "--scene", "city", "--frames", "1", "--width", "160", "--height",
        "128",
    ]);
    for driver in [
        "frustum",
        "hierarchical",
        "lazy-grid",
        "busy-grid",
        "hierarchical/t0.2",
    ] {
        assert!(table.contains(driver), "{driver} missing:\n{table}");
    }
    assert!(table.contains("cycles o2"), "{table}");
    assert!(table.contains("cycles ir4"), "{table}");
}
