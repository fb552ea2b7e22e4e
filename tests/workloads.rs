//! Walkthrough traces end to end: made by a culling driver, replayed with their golden
//! answers checked; `culling compare` prints every driver with cycles on the machines.

mod support;

use support::cli::{stderr_of_failure, stdout_of, stdout_of as occsim};

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
    assert!(
        table.contains("query frag: fragments of the queries' boxes")
            && table.contains("trav ms, golden ms: wall-clock milliseconds"),
        "every column explained:\n{table}"
    );
}

/// `--arch` and `--set` choose the machines as on `replay`: one column each, every --set
/// applied to each; a machine's failure names it.
#[test]
fn culling_compare_takes_arch_and_set() {
    let walk = [
        "culling",
        "compare",
        "--scene",
        "city",
        "--frames",
        "1",
        "--width",
        "96",
        "--height",
        "64",
        "--adaptive-threshold",
        "0.2",
        "--quadtree-levels",
        "0",
    ];
    let run = |extra: &[&str]| {
        let mut args = walk.to_vec();
        args.extend(extra);
        stdout_of(&args)
    };
    let cycles_of = |table: &str, column: usize| -> f64 {
        let row = table
            .lines()
            .find(|l| l.starts_with("lazy-grid "))
            .unwrap_or_else(|| panic!("no lazy-grid row in\n{table}"));
        // The cycle columns follow the nine count columns (driver, tris %, ..., px lost).
        row.split_whitespace()
            .nth(9 + column)
            .unwrap()
            .parse()
            .unwrap()
    };
    let one = run(&["--arch", "o2"]);
    assert!(
        one.contains("cycles o2") && !one.contains("cycles ir4"),
        "{one}"
    );
    let two = run(&["--arch", "ir2,o2", "--set", "engines=1"]);
    assert!(
        two.contains("cycles ir2") && two.contains("cycles o2"),
        "{two}"
    );
    assert!(
        two.find("cycles ir2") < two.find("cycles o2"),
        "columns in --arch order: {two}"
    );
    // The lazy grid's queries have many tiles (the outdated cells a box covers); one engine
    // tests them one after another, four share them.
    assert!(cycles_of(&two, 1) > cycles_of(&one, 0), "{one}\n{two}");
    // A threshold twice would be two rows (and two JSON drivers) of one name.
    for flag in ["--adaptive-threshold", "--opacity-threshold"] {
        let twice = stderr_of_failure(&[&walk[..], &[flag, "0.5,0.5"]].concat());
        assert!(
            twice.contains(&format!("{flag}: 0.5 is named twice")),
            "{twice}"
        );
    }
    // Threshold 1 is the hom row itself: two rows of one name.
    let again = stderr_of_failure(&[&walk[..], &["--opacity-threshold", "0.9,1"]].concat());
    assert!(
        again.contains("--opacity-threshold 1: the hom row"),
        "{again}"
    );
    let wrong = stderr_of_failure(&[&walk[..], &["--arch", "o2", "--set", "boards=2"]].concat());
    assert!(
        wrong.contains("--arch o2") && wrong.contains("boards"),
        "{wrong}"
    );
    // `--engines E` is `--set engines=E` for every machine, as on replay.
    let by_flag = run(&["--arch", "ir2,o2", "--engines", "1"]);
    for column in 0..2 {
        assert_eq!(
            cycles_of(&by_flag, column),
            cycles_of(&two, column),
            "{by_flag}"
        );
    }
    // A machine named twice would be two columns of one name, and JSON keys given twice.
    let twice = stderr_of_failure(&[&walk[..], &["--arch", "o2,o2"]].concat());
    assert!(twice.contains("o2 appears twice"), "{twice}");
}

/// `--bands`: every frame time gets a band that holds it, over corners that are the same for
/// every driver; the scratch trace the study replays is gone afterwards.
#[test]
fn culling_compare_bands_hold_every_frame_time_and_leave_nothing_behind() {
    let scratch = tempfile::tempdir().unwrap();
    let stdout = support::cli::stdout_with_temp_dir(
        &[
            "culling",
            "compare",
            "--scene",
            "city",
            "--blocks",
            "2",
            "--detail",
            "0",
            "--frames",
            "2",
            "--width",
            "80",
            "--height",
            "60",
            "--quadtree-levels",
            "0",
            "--adaptive-threshold",
            "0.2",
            "--arch",
            "o2",
            "--bands",
            "--json",
            "--jobs",
            "2",
        ],
        scratch.path(),
    );
    let report: serde_json::Value = serde_json::from_slice(&stdout).unwrap();
    let o2: serde_json::Value =
        serde_json::from_str(&support::cli::stdout_of(&["arch", "show", "o2", "--json"])).unwrap();
    let clock_mhz = (o2["parameters"].as_array().unwrap().iter())
        .find(|p| p["key"] == "clock_mhz")
        .and_then(|p| p["value"].as_f64())
        .unwrap();
    let mut corners = None;
    for driver in report["drivers"].as_array().unwrap() {
        let time = &driver["frame_time"][0];
        let ms = time["ms_per_frame"].as_f64().unwrap();
        let low = time["ms_per_frame_band"][0].as_f64().unwrap();
        let high = time["ms_per_frame_band"][1].as_f64().unwrap();
        assert!(low <= ms && ms <= high && low < high, "{driver}");
        // The split sums to the frame: host busy + waiting + pipe wait cycles are the
        // frame's: its ms at the O2's clock (means over 2 frames).
        let cycles = |key: &str| time[key].as_f64().unwrap();
        let split =
            cycles("host_busy_cycles") + cycles("waiting_cycles") + cycles("pipe_wait_cycles");
        let frame = ms * clock_mhz * 1e3;
        assert!(
            (split - frame).abs() < 1.0,
            "{split} against {frame}: {driver}"
        );
        let at = time["ms_per_frame_at_variants"].as_array().unwrap().len();
        assert_eq!(
            *corners.get_or_insert(at),
            at,
            "the same corners for every driver"
        );
        // Each corner says what it changes, so that it can be run again with --set (the
        // JSON had given its frame time alone).
        let variants = time["variants"].as_array().unwrap();
        assert_eq!(variants.len(), at, "{time}");
        for corner in variants {
            let corner = corner.as_str().unwrap();
            let first = corner.split(", ").next().unwrap();
            let (key, _) = first.split_once('=').unwrap();
            let known = (o2["parameters"].as_array().unwrap().iter()).any(|p| p["key"] == key);
            assert!(known, "{corner}: `{key}` is no o2 parameter");
        }
    }
    assert!(
        corners.unwrap() >= 2,
        "a study finds at least a low and a high corner"
    );
    let left: Vec<_> = std::fs::read_dir(scratch.path()).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}
