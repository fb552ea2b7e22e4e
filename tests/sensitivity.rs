//! End-to-end tests of `occsim sensitivity` and of `--bands`, on the built-in hardcases trace.

mod support;

use support::cli::{hardcases_trace, stderr_of_failure, stdout_of};

fn bands(trace: &str, arch: &str, jobs: &str) -> String {
    stdout_of(&[
        "sensitivity",
        trace,
        "--arch",
        arch,
        "--jobs",
        jobs,
        "--json",
    ])
}

#[test]
fn every_band_holds_its_default_and_jobs_do_not_change_the_output() {
    let (dir, trace) = hardcases_trace("bands");
    for arch in ["o2", "ir2"] {
        let one = bands(&trace, arch, "1");
        assert_eq!(
            one,
            bands(&trace, arch, "2"),
            "{arch}: output depends on --jobs"
        );
        let json: serde_json::Value = serde_json::from_str(&one).unwrap();
        let metrics: Vec<&str> = json
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b["metric"].as_str().unwrap())
            .collect();
        // hardcases has a frame end: the frame time is a headline too.
        assert_eq!(
            metrics,
            [
                "cycles",
                "frame_ms",
                "latency_p50_cycles",
                "latency_p95_cycles"
            ],
            "{arch}"
        );
        for band in json.as_array().unwrap() {
            let (low, default, high) = (
                band["low"].as_f64().unwrap(),
                band["default"].as_f64().unwrap(),
                band["high"].as_f64().unwrap(),
            );
            assert!(low <= default && default <= high, "{arch}: {band}");
            let parameters = band["parameters"].as_array().unwrap();
            let extent = |p: &serde_json::Value| {
                let (a, b) = (
                    p["at_low"].as_f64().unwrap(),
                    p["at_high"].as_f64().unwrap(),
                );
                a.max(b).max(default) - a.min(b).min(default)
            };
            // The parameters that move it most come first; every one listed moves it, and no
            // single one moves it beyond the band.
            for pair in parameters.windows(2) {
                assert!(extent(&pair[0]) >= extent(&pair[1]), "{arch}: {band}");
            }
            for p in parameters {
                assert!(extent(p) > 0.0, "{arch}: {p}");
                for at in ["at_low", "at_high"] {
                    let v = p[at].as_f64().unwrap();
                    assert!(low <= v && v <= high, "{arch}: {p}");
                }
            }
        }
    }
    // The cycles of the O2 move with the number of engines (one engine serialises the tiles).
    let json: serde_json::Value = serde_json::from_str(&bands(&trace, "o2", "2")).unwrap();
    let cycles = &json[0];
    assert!(
        cycles["parameters"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p["key"] == "engines"),
        "{cycles}"
    );
    let svg = dir.join("tornado.svg");
    stdout_of(&[
        "sensitivity",
        &trace,
        "--arch",
        "o2",
        "--plot",
        svg.to_str().unwrap(),
    ]);
    let svg = std::fs::read_to_string(svg).unwrap();
    assert!(svg.contains("<svg") && svg.contains("latency p95") && svg.contains("engines 1..16"));
}

/// Values the study cannot take are refused, each error saying whose value it is.
#[test]
fn a_value_the_study_cannot_take_is_refused_and_named() {
    let (_dir, trace) = hardcases_trace("refused");
    let cases = [
        // Legal for a replay (1..=65536), but outside the plausible 6..10 of an inference.
        (
            "page_miss_latency_cycles=40",
            "'page_miss_latency_cycles' = 40 lies outside its plausible range 6..10",
            "bring it within that range, or leave it at its default",
        ),
        // 330 Hz refreshes take 81.1% of the O2's port (sim's sensitivity tests derive
        // it): possible beside the host's default 5%, not beside its high end, 15%.
        (
            "display_refresh_hz=330",
            "the study's variant host_memory_share=0.15 is impossible",
            "bring them back toward their defaults",
        ),
    ];
    for (set, what, advice) in cases {
        let error = stderr_of_failure(&["sensitivity", &trace, "--arch", "o2", "--set", set]);
        assert!(error.contains(what) && error.contains(advice), "{error}");
    }
    // No parameter listed had printed "moved most by" nothing.
    let error = stderr_of_failure(&["sensitivity", &trace, "--top", "0"]);
    assert!(error.contains("'0' for '--top <TOP>'"), "{error}");
}

/// `--engines E` is `--set engines=E`, as on replay, fidelity and latency (it had been an
/// unknown flag here), and given with it, refused.
#[test]
fn engines_is_shorthand_for_setting_them() {
    let (_dir, trace) = hardcases_trace("engines");
    let study = |how: &[&str]| {
        let args = [&["sensitivity", &trace, "--arch", "o2", "--json"][..], how].concat();
        stdout_of(&args)
    };
    let by_flag = study(&["--engines", "2"]);
    assert_eq!(by_flag, study(&["--set", "engines=2"]));
    assert_ne!(by_flag, study(&[]), "the default point is another");
    let twice = stderr_of_failure(&[
        "sensitivity",
        &trace,
        "--engines",
        "2",
        "--set",
        "engines=4",
    ]);
    assert!(twice.contains("give the engine count once"), "{twice}");
}

#[test]
fn latency_and_sweep_print_a_band_that_holds_each_figure() {
    let (dir, trace) = hardcases_trace("figure-bands");
    let json = stdout_of(&[
        "latency",
        &trace,
        "--arch",
        "o2",
        "--engines",
        "1,4",
        "--bands",
        "--json",
    ]);
    let rows: serde_json::Value = serde_json::from_str(&json).unwrap();
    for row in rows.as_array().unwrap() {
        let band = &row["bands"];
        let holds = |name: &str, value: &serde_json::Value| {
            let (low, high) = (
                band[name][0].as_f64().unwrap(),
                band[name][1].as_f64().unwrap(),
            );
            let value = value.as_f64().unwrap();
            assert!(low <= value && value <= high, "{name}: {row}");
        };
        holds("cycles", &row["total_cycles"]);
        holds("latency_p50_cycles", &row["latency_p50_cycles"]);
        holds("latency_p95_cycles", &row["latency_p95_cycles"]);
    }
    // The rows differ in engines, which the bands leave where each row put it (the corners
    // are the same for both): one engine serialises the tiles, so the rows' bands differ.
    let rows = rows.as_array().unwrap();
    assert_ne!(rows[0]["bands"], rows[1]["bands"], "{rows:?}");
    let text = stdout_of(&[
        "latency",
        &trace,
        "--arch",
        "o2",
        "--engines",
        "4",
        "--bands",
    ]);
    assert!(text.contains(" band: cycles "), "{text}");

    let out = dir.join("bands.jsonl");
    stdout_of(&[
        "sweep",
        &trace,
        "--arch",
        "o2",
        "--set",
        "engines=2,4",
        "--bands",
        "--out",
        out.to_str().unwrap(),
    ]);
    let lines = std::fs::read_to_string(&out).unwrap();
    assert_eq!(lines.lines().count(), 2);
    for line in lines.lines() {
        let line: serde_json::Value = serde_json::from_str(line).unwrap();
        let m = &line["metrics"];
        for name in ["total_cycles", "latency_p95_cycles", "latency_p50_cycles"] {
            let (low, value, high) = (
                m[format!("{name}_band_low")].as_f64().unwrap(),
                m[name].as_f64().unwrap(),
                m[format!("{name}_band_high")].as_f64().unwrap(),
            );
            assert!(low <= value && value <= high, "{name}: {m}");
        }
    }
}
