//! End-to-end tests of `occsim fidelity` and `occsim replay --fidelity/--effects` on the
//! hard-cases trace.

mod support;

use support::cli::{hardcases_trace, occsim, stdout_of};

#[test]
fn fidelity_prints_every_level_against_cycle_and_plots() {
    let (dir, trace) = hardcases_trace("table");
    let plot = dir.join("price.svg");
    let out = stdout_of(&[
        "fidelity",
        &trace,
        "--arch",
        "o2",
        "--sample-every",
        "3",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    let lines: Vec<&str> = out.lines().collect();
    assert!(lines[0].contains("63404 fragments"), "{out}");
    let level_of = |line: &str| line.split_whitespace().next().unwrap_or("").to_string();
    let levels: Vec<String> = lines[2..].iter().map(|l| level_of(l)).collect();
    assert_eq!(
        levels,
        ["functional", "analytic", "sampled:3", "cycle", "rtl"],
        "{out}"
    );
    assert!(lines[0].contains("errors relative to rtl"), "{out}");
    for line in &lines[2..7] {
        assert!(
            line.ends_with("exact"),
            "every level's results are exact: {line}"
        );
    }
    // cycle and rtl agree to the cycle: both have error 0; functional has no time.
    assert!(lines[5].contains("0.00%      0.00%"), "{out}");
    assert!(lines[6].contains("0.00%      0.00%"), "{out}");
    assert!(lines[2].contains(" - "), "{out}");
    let svg = std::fs::read_to_string(&plot).unwrap();
    assert!(svg.starts_with("<svg") || svg.starts_with("<?xml"), "{svg}");
    assert!(svg.contains("cycle (error 0, drawn at 0.0001)"), "{svg}");
    assert!(svg.contains("rtl (error 0, drawn at 0.0001)"), "{svg}");
    assert!(svg.contains("analytic"));

    let json: serde_json::Value =
        serde_json::from_str(&stdout_of(&["fidelity", &trace, "--json"])).unwrap();
    let rows = json.as_array().unwrap();
    assert_eq!(rows[1]["level"], "analytic");
    assert_eq!(rows[2]["level"], "sampled:10");
    assert_eq!(rows[3]["cycles_error"], 0.0);
    assert_eq!(rows[4]["level"], "rtl");
    assert_eq!(rows[4]["total_cycles"], rows[3]["total_cycles"]);
    // The cycle level's total equals what replay reports.
    let replay: serde_json::Value =
        serde_json::from_str(&stdout_of(&["replay", &trace, "--json"])).unwrap();
    assert_eq!(rows[3]["total_cycles"], replay["summary"]["cycles"]);
}

#[test]
fn replay_reports_its_level_and_the_active_effects() {
    let (_dir, trace) = hardcases_trace("replay");
    let automatic = stdout_of(&["replay", &trace]);
    let forced = stdout_of(&["replay", &trace, "--effects", "all"]);
    // Same report, different effects line: hard cases fit one 128x128 page.
    let strip = |text: &str| {
        text.lines()
            .filter(|l| !l.starts_with("active effects"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(strip(&automatic), strip(&forced));
    assert!(automatic.contains(
        "active effects: verbose_hit_writes, multi_tile_serialisation, depth_write_traffic\n"
    ));
    assert!(forced.contains("page_model"), "{forced}");
    let json: serde_json::Value =
        serde_json::from_str(&stdout_of(&["replay", &trace, "--json"])).unwrap();
    assert_eq!(json["effects"]["page_model"], false);
    assert_eq!(json["effects"]["depth_write_traffic"], true);

    let analytic = stdout_of(&["replay", &trace, "--fidelity", "analytic"]);
    assert!(
        analytic.starts_with("level: analytic on o2\n"),
        "{analytic}"
    );
    assert!(analytic.contains("queries: 28 (28 checked"), "{analytic}");
    let functional = stdout_of(&["replay", &trace, "--fidelity", "functional"]);
    assert!(
        functional.contains("predicted cycles: none"),
        "{functional}"
    );
    let sampled: serde_json::Value = serde_json::from_str(&stdout_of(&[
        "replay",
        &trace,
        "--fidelity",
        "sampled:5",
        "--json",
    ]))
    .unwrap();
    assert_eq!(sampled["level"], "sampled:5");
    assert_eq!(sampled["sampled_windows"]["total"], 28);
    assert_eq!(sampled["sampled_windows"]["simulated"], 6);
}

#[test]
fn bad_levels_fail_clearly() {
    let (_dir, trace) = hardcases_trace("errors");
    let output = occsim(&["replay", &trace, "--fidelity", "sampled:0"]);
    assert!(!output.status.success());
    let error = String::from_utf8_lossy(&output.stderr);
    assert!(
        error.contains("K in sampled:K must be a whole number from 1"),
        "{error}"
    );
    let output = occsim(&["replay", &trace, "--effects", "some"]);
    assert!(!output.status.success());
}

#[test]
fn the_rtl_level_of_the_ir_machine_reports_as_its_cycle_level() {
    let (_dir, trace) = hardcases_trace("irrtl");
    let run = |level: &str| {
        stdout_of(&[
            "replay",
            &trace,
            "--arch",
            "ir2",
            "--fidelity",
            level,
            "--effects",
            "all",
        ])
    };
    let rtl = run("rtl");
    assert!(rtl.contains("machine ir"), "{rtl}");
    assert_eq!(rtl, run("cycle"));
}
