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
    let levels: Vec<String> = lines[2..7].iter().map(|l| level_of(l)).collect();
    assert!(
        lines[7].starts_with("  wall s: seconds on this computer") && lines.len() == 8,
        "the legend closes the table:\n{out}"
    );
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
    // Errors in percent, as the table prints them; the trace and the machine in the title.
    assert!(svg.contains("cycle (error 0, drawn at 0.01%)"), "{svg}");
    assert!(svg.contains("rtl (error 0, drawn at 0.01%)"), "{svg}");
    assert!(svg.contains("error vs rtl (%, the worse of"), "{svg}");
    assert!(svg.contains("hardcases.occt on o2"), "{svg}");
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
    // Same report, different effects and fast-forward lines: hard cases fit one 128x128
    // page, and all takes every fragment one by one.
    let strip = |text: &str| {
        text.lines()
            .filter(|l| !l.starts_with("active effects") && !l.starts_with("fast-forwarded"))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(strip(&automatic), strip(&forced));
    assert!(
        forced.contains("fast-forwarded: 0 of 63404 fragments"),
        "{forced}"
    );
    assert!(!automatic.contains("fast-forwarded: 0 of"), "{automatic}");
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
        analytic
            .starts_with("level analytic, machine o2 (4 engines) at 66.67 MHz, viewport 64x64\n"),
        "{analytic}"
    );
    // `trace gen` writes the window index: the analytic level reads it, not the fragments,
    // and takes the golden results; with --no-index it decodes and checks them.
    assert!(
        analytic.contains("28 queries (their golden results, from the window index)"),
        "{analytic}"
    );
    // The InfiniteReality-like machine's formulas read the band index instead.
    let ir = stdout_of(&["replay", &trace, "--fidelity", "analytic", "--arch", "ir2"]);
    assert!(
        ir.contains("28 queries (their golden results, from the band index)")
            && ir.contains("read from the band index: no fragment decoded"),
        "{ir}"
    );
    let decoded = stdout_of(&["replay", &trace, "--fidelity", "analytic", "--no-index"]);
    assert!(
        decoded.contains("28 queries (28 checked against golden results)"),
        "{decoded}"
    );
    assert_eq!(
        analytic
            .lines()
            .nth(1)
            .map(|l| l.split(", 28 queries").next()),
        decoded
            .lines()
            .nth(1)
            .map(|l| l.split(", 28 queries").next())
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
    // 28 windows, one per query. Every 5th: windows 0, 5, 10, 15, 20 and 25. Besides them
    // the windows of the ceil(28 / 15) = 2 queries the formulas predict slowest, as the
    // analytic level gives their latencies: queries 23 and 24 (2,667 and 2,660 cycles,
    // behind clears), the next 2,651 (query 25); neither is one of every 5th, so 2 more, 8
    // in all.
    assert_eq!(sampled["sampled_windows"]["total"], 28);
    assert_eq!(sampled["sampled_windows"]["simulated"], 8);
    assert_eq!(sampled["sampled_windows"]["slowest"], 2);
    let analytic: serde_json::Value = serde_json::from_str(&stdout_of(&[
        "replay",
        &trace,
        "--fidelity",
        "analytic",
        "--json",
    ]))
    .unwrap();
    let predicted: Vec<u64> = analytic["queries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|q| q["latency_cycles"].as_u64().unwrap())
        .collect();
    assert_eq!([23, 24, 25].map(|q| predicted[q]), [2667, 2660, 2651]);
    let mut descending = predicted.clone();
    descending.sort_unstable_by(|a, b| b.cmp(a));
    assert_eq!(descending[..3], [2667, 2660, 2651], "{predicted:?}");
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
    // An option beside a level it does not apply to (both had been passed over unsaid).
    for (args, says) in [
        (
            &["--fidelity", "cycle", "--no-index"][..],
            "--no-index applies to the analytic and sampled levels",
        ),
        (
            &["--fidelity", "functional", "--effects", "all"],
            "--effects: the functional level has no effect models",
        ),
        (
            &["--fidelity", "analytic", "--effects", "auto"],
            "--effects: the analytic level has no effect models",
        ),
        // The rtl level builds every model: `all` says so (the IR's rtl test gives it),
        // `auto` had been passed over.
        (
            &["--fidelity", "rtl", "--effects", "auto"],
            "--effects: the rtl level builds every effect model (--effects all)",
        ),
    ] {
        let error = support::cli::stderr_of_failure(&[&["replay", &trace][..], args].concat());
        assert!(error.contains(says), "{args:?}: {error}");
    }
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
    let first = "level rtl, machine ir (2 boards, 80 Image Engines a board, 4 engines an Occlusion Unit, interleave columns) at 100 MHz";
    assert!(rtl.starts_with(first), "{rtl}");
    // The IR's busy cycles are sums over many units, its percentages their means: said so.
    for legend in [
        "summed over the units; busy%: of the run's cycles, the mean over the units",
        "the least, the mean and the most busy of count units",
    ] {
        assert!(rtl.contains(legend), "no `{legend}` in\n{rtl}");
    }
    assert_eq!(rtl.replacen("level rtl", "level cycle", 1), run("cycle"));
}

/// Every level prints one shape: the level and the machine first, the same summary line,
/// the same frames and query columns, `-` where the level has no figure.
#[test]
fn every_level_reports_in_one_shape() {
    let (_dir, trace) = hardcases_trace("shape");
    let levels = ["functional", "analytic", "sampled:5", "cycle", "rtl"];
    let mut query_headings = Vec::new();
    for level in levels {
        let text = stdout_of(&["replay", &trace, "--fidelity", level, "--queries"]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines[0],
            format!("level {level}, machine o2 (4 engines) at 66.67 MHz, viewport 64x64")
        );
        let summary = lines[1];
        for part in [
            " cycles (",
            "63404 fragments",
            "fragments/cycle",
            "latency p50 ",
        ] {
            assert!(summary.contains(part), "{level}: {summary}");
        }
        // The analytic and sampled levels read the trace's window index and take its golden
        // results; the sampled level's machines check those of the windows they run.
        let queries = match level {
            "analytic" => "28 queries (their golden results, from the window index)",
            "sampled:5" => "28 queries (their golden results, from the window index; ",
            _ => "28 queries (28 checked against golden results)",
        };
        assert!(summary.contains(queries), "{level}: {summary}");
        if level == "sampled:5" {
            // Windows 0..=28 (28 queries, then the final window): windows 0, 5, ..., 25 are
            // sampled, 4, 9, ..., 24 their warm-ups, so the machines run 11 query windows
            // whole (and may end more inside a cool-down): at least 11 checked, at most 28.
            let checked: u64 = summary
                .split("from the window index; ")
                .nth(1)
                .and_then(|rest| rest.split(' ').next())
                .and_then(|n| n.parse().ok())
                .unwrap_or_else(|| panic!("no checked count: {summary}"));
            assert!((11..=28).contains(&checked), "{summary}");
        }
        let heading = lines
            .iter()
            .find(|l| l.trim_start().starts_with("# ") && l.contains("latency"))
            .unwrap_or_else(|| panic!("{level}: no query table in\n{text}"));
        query_headings.push(heading.to_string());
        // Query 27: five brief tiles (the whole screen and its quarters, hardcases.scene).
        let row = lines
            .iter()
            .find(|l| l.split_whitespace().nth(1) == Some("27"))
            .unwrap();
        let cells: Vec<&str> = row.split_whitespace().collect();
        assert_eq!((cells[2], cells[3]), ("brief", "5"), "{level}: {row}");
        let has_time = level != "functional";
        assert_eq!(cells[4] != "-", has_time, "{level}: latency in {row}");
        let splits_latency = matches!(level, "cycle" | "rtl");
        assert_eq!(cells[5] != "-", splits_latency, "{level}: drain in {row}");
        assert_eq!(
            summary.starts_with("- cycles (- s)"),
            !has_time,
            "{level}: {summary}"
        );
        assert_eq!(
            text.contains("stages, memory port, units, engines: - (the"),
            !splits_latency,
            "{level}"
        );
    }
    assert!(
        query_headings.windows(2).all(|w| w[0] == w[1]),
        "{query_headings:?}"
    );
}

/// The hard cases' largest query has 5 tiles (query 27: the screen and its four quarters),
/// so of 8 engines 3 get none; at 4 or 5 engines every engine gets one.
#[test]
fn the_report_says_when_engines_outnumber_the_tiles() {
    let (_dir, trace) = hardcases_trace("idle-engines");
    for level in ["cycle", "analytic"] {
        let eight = stdout_of(&["replay", &trace, "--engines", "8", "--fidelity", level]);
        assert!(
            eight.contains(
                "note: 8 engines, but no query has more than 5 tiles: 3 engines get no tile"
            ),
            "{level}: {eight}"
        );
        let five = stdout_of(&["replay", &trace, "--engines", "5", "--fidelity", level]);
        assert!(!five.contains("note: "), "{level}: {five}");
    }
}

/// `--retile` and `--engines` as `replay` takes them: the same cycles as `replay` with the
/// same flags, and the table names the retiling.
#[test]
fn fidelity_takes_retile_and_engines_as_replay_does() {
    let (_dir, trace) = hardcases_trace("retile");
    let flags = ["--retile", "4x4", "--engines", "2"];
    let mut args = vec!["fidelity", trace.as_str(), "--no-rtl", "--json"];
    args.extend(flags);
    let rows: serde_json::Value = serde_json::from_str(&stdout_of(&args)).unwrap();
    let mut args = vec!["replay", trace.as_str(), "--json"];
    args.extend(flags);
    let replay: serde_json::Value = serde_json::from_str(&stdout_of(&args)).unwrap();
    assert_eq!(rows[3]["level"], "cycle");
    assert_eq!(rows[3]["total_cycles"], replay["summary"]["cycles"]);
    let plain: serde_json::Value =
        serde_json::from_str(&stdout_of(&["fidelity", &trace, "--no-rtl", "--json"])).unwrap();
    assert_ne!(rows[3]["total_cycles"], plain[3]["total_cycles"]);
    let text = stdout_of(&["fidelity", &trace, "--no-rtl", "--retile", "4x4"]);
    assert!(
        text.starts_with(&format!("{trace} (retiled 4x4) on o2:")),
        "{text}"
    );
    // The architecture as it was named (`ir2`, not the machine's `ir`), with the engines.
    let text = stdout_of(&[
        "fidelity",
        &trace,
        "--no-rtl",
        "--arch",
        "ir2",
        "--engines",
        "2",
    ]);
    assert!(
        text.starts_with(&format!("{trace} on ir2, 2 engines:")),
        "{text}"
    );
    // Every timed level has a distribution of per-query errors, the reference's all 0.
    assert_eq!(rows[3]["query_latency_error"]["max"], 0.0);
    assert!(rows[1]["query_latency_error"]["p95"].as_f64().is_some());
    assert!(
        rows[0]["query_latency_error"].is_null(),
        "functional has no time"
    );
}

/// `--corpus` makes every trace of the recipes it is given, runs the ladder on each machine
/// and engine count, and reports per class and level; its scratch traces are removed.
#[test]
fn fidelity_corpus_reports_every_class_and_level() {
    let dir = support::cli::scratch_dir("corpus");
    let recipes = dir.join("corpus.toml");
    std::fs::write(
        &recipes,
        r#"
machines = ["o2", "ir1"]
engines = [1, 4]

[[trace]]
name = "hc"
class = "hard"
scene = "hardcases"

[[trace]]
name = "rand"
class = "random"
scene = "random"
small = { width = 64, height = 48 }

[[trace]]
name = "rand-big"
class = "random"
scene = "random"
small = { width = 96, height = 64 }

[[trace]]
name = "walk"
class = "walk"
walk = "--scene city --blocks 2 --detail 0 --driver hierarchical --quadtree-levels 1"
small = { width = 64, height = 48, frames = 1 }

[[trace]]
name = "frustum"
class = "frustum"
walk = "--scene city --blocks 2 --detail 0 --driver frustum"
small = { width = 64, height = 48, frames = 1 }
"#,
    )
    .unwrap();
    let scratch = support::cli::scratch_dir("corpus-tmp");
    let chart = dir.join("price.svg");
    let stdout = support::cli::stdout_with_temp_dir(
        &[
            "fidelity",
            "--corpus",
            "--corpus-file",
            recipes.to_str().unwrap(),
            "--scale",
            "small",
            "--no-rtl",
            "--json",
            "--machines",
            "o2",
            "--plot",
            chart.to_str().unwrap(),
        ],
        &scratch,
    );
    // The price of accuracy drawn too (it had been left undrawn, with exit 0): a series a
    // class, the frustum walk's too, which has no query and so no latency error (its line
    // had been left out).
    let svg = std::fs::read_to_string(&chart).expect("--plot with --corpus draws a chart");
    for class in ["hard", "random", "walk", "frustum"] {
        assert!(svg.contains(&format!(">\n{class}\n<")), "no series {class}");
    }
    let rows: serde_json::Value = serde_json::from_slice(&stdout).unwrap();
    let rows = rows.as_array().unwrap();
    // 4 classes x 4 levels; --machines o2 leaves 2 engine counts: a random row holds
    // 2 traces x 2 engine counts.
    assert_eq!(rows.len(), 16, "{rows:?}");
    let classes: Vec<&str> = rows.iter().map(|r| r["class"].as_str().unwrap()).collect();
    assert_eq!(classes[0], "hard");
    assert_eq!(classes[4], "random");
    assert_eq!(classes[8], "walk");
    assert_eq!(classes[12], "frustum");
    assert_eq!(rows[4]["runs"], 4);
    for row in rows {
        assert_eq!(row["results_exact"], true, "{row}");
        if row["level"] == "cycle" {
            assert_eq!(row["cycles_error"], 0.0);
            assert_eq!(row["speed_vs_cycle"], 1.0);
        }
    }
    let left: Vec<_> = std::fs::read_dir(&*scratch).unwrap().collect();
    assert!(left.is_empty(), "scratch traces left: {left:?}");
}

/// A recipe file that says nothing runnable fails naming the file and the recipe.
#[test]
fn a_bad_corpus_file_is_refused_with_its_name() {
    let dir = support::cli::scratch_dir("bad-corpus");
    let recipes = dir.join("bad.toml");
    std::fs::write(
        &recipes,
        "machines = [\"o2\"]\nengines = [1]\n[[trace]]\nname = \"x\"\nclass = \"c\"\n",
    )
    .unwrap();
    let recipes = recipes.to_str().unwrap();
    let error =
        support::cli::stderr_of_failure(&["fidelity", "--corpus", "--corpus-file", recipes]);
    assert!(
        error.contains(recipes)
            && error.contains("trace `x` needs exactly one of `scene` and `walk`"),
        "{error}"
    );
    std::fs::write(
        dir.join("typo.toml"),
        "machines = [\"o2\"]\nengine = [1]\ntrace = []\n",
    )
    .unwrap();
    let typo = dir.join("typo.toml");
    let error = support::cli::stderr_of_failure(&[
        "fidelity",
        "--corpus",
        "--corpus-file",
        typo.to_str().unwrap(),
    ]);
    assert!(
        error.contains("typo.toml") && error.contains("engine"),
        "{error}"
    );
    // A machine or engine count the file names twice would run, and be reported, twice.
    for (lists, expected) in [
        (
            "machines = [\"o2\", \"o2\"]\nengines = [1]",
            "`machines` names `o2` twice",
        ),
        (
            "machines = [\"o2\"]\nengines = [4, 1, 4]",
            "`engines` names 4 twice",
        ),
        // Two names of one machine: `ir` is the InfiniteReality-like machine's defaults,
        // its 4 boards `ir4`'s.
        (
            "machines = [\"ir\", \"ir4\"]\nengines = [1]",
            "`ir` and `ir4` are the same machine",
        ),
    ] {
        let twice = dir.join("twice.toml");
        let recipe = "[[trace]]\nname = \"h\"\nclass = \"h\"\nscene = \"hardcases\"\n";
        std::fs::write(&twice, format!("{lists}\n{recipe}")).unwrap();
        let file = twice.to_str().unwrap();
        let error =
            support::cli::stderr_of_failure(&["fidelity", "--corpus", "--corpus-file", file]);
        assert!(error.contains(file) && error.contains(expected), "{error}");
    }
    // Every --set applies to each machine, and a bad one is named.
    std::fs::write(
        dir.join("one.toml"),
        "machines = [\"o2\"]\nengines = [1]\n[[trace]]\nname = \"h\"\nclass = \"h\"\nscene = \"hardcases\"\n",
    )
    .unwrap();
    let one = dir.join("one.toml");
    for (set, expected) in [
        ("no_such_key=1", "no_such_key"),
        // Each run sets its own engine count: a --set engines= would be overridden unseen.
        (
            "engines=2",
            "--set engines=2: a corpus run sets the engine count of each run",
        ),
    ] {
        let corpus_file = one.to_str().unwrap();
        let args = [
            "fidelity",
            "--corpus",
            "--corpus-file",
            corpus_file,
            "--set",
            set,
        ];
        let error = support::cli::stderr_of_failure(&args);
        assert!(error.contains(expected), "{set}: {error}");
    }
    // A class that is none of the corpus's (a typo beside a good one had been dropped
    // unsaid), a machine, engine count or class named twice (run and reported twice), and
    // --retile, which the corpus run had passed over unsaid: refused before any trace.
    for (flags, expected) in [
        (
            &["--classes", "hardcases,nosuch"][..],
            "no recipe is of class `nosuch` (its classes: demo, retiled-1x1-4x4,",
        ),
        (&["--machines", "o2,o2"], "--machines: `o2` is named twice"),
        (
            &["--machines", "ir2,ir,ir4"],
            "--machines: `ir` and `ir4` are the same machine",
        ),
        (&["--engines", "4,4"], "--engines: `4` is named twice"),
        (
            &["--classes", "random,random"],
            "--classes: `random` is named twice",
        ),
        (&["--retile", "2x2"], "--retile retiles one trace"),
    ] {
        let args = [&["fidelity", "--corpus", "--scale", "small"][..], flags].concat();
        let error = support::cli::stderr_of_failure(&args);
        assert!(error.contains(expected), "{flags:?}: {error}");
    }
    // --engines takes a list with --corpus (the corpus file's counts replaced), one count
    // for one trace.
    let two_counts = support::cli::stdout_of(&[
        "fidelity",
        "--corpus",
        "--corpus-file",
        one.to_str().unwrap(),
        "--engines",
        "1,4",
        "--no-rtl",
    ]);
    assert!(
        two_counts.contains("on o2 with 1, 4 engines"),
        "{two_counts}"
    );
    let line = two_counts.lines().find(|l| l.contains("analytic")).unwrap();
    assert_eq!(
        line.split_whitespace().nth(2),
        Some("2"),
        "two runs: {line}"
    );
    let error = support::cli::stderr_of_failure(&["fidelity", "any.occt", "--engines", "1,4"]);
    assert!(error.contains("one engine count for one trace"), "{error}");
    // One trace's machine, which the corpus run had passed over unsaid, running every
    // machine of the corpus.
    for arch in [
        &["--arch", "ir2"][..],
        &["--arch-file", one.to_str().unwrap()],
    ] {
        let args = [&["fidelity", "--corpus", "--scale", "small"][..], arch].concat();
        let error = support::cli::stderr_of_failure(&args);
        assert!(
            error.contains(
                "--arch and --arch-file choose one trace's machine; with --corpus, --machines"
            ),
            "{arch:?}: {error}"
        );
    }
    let neither = support::cli::stderr_of_failure(&["fidelity"]);
    assert!(
        neither.contains("--corpus") || neither.contains("TRACE"),
        "{neither}"
    );
    // What a file can say but not mean: no machine (the run had printed an empty table and
    // exited 0), a name that is a path out of --traces-dir (its trace had been written
    // there), a side past the viewport's, a built-in scene of 2^32 - 1 frames (its scene
    // text, written whole, had asked for 4.5 GB).
    let hardcases = "[[trace]]\nname = \"h\"\nclass = \"h\"\nscene = \"hardcases\"\n";
    let demo = |size: &str| {
        format!("machines = [\"o2\"]\nengines = [1]\n[[trace]]\nname = \"d\"\nclass = \"d\"\nscene = \"demo\"\nsmall = {{ {size} }}\n")
    };
    for (text, expected) in [
        (
            format!("machines = []\nengines = [1]\n{hardcases}"),
            "`machines` names no machine".to_string(),
        ),
        (
            "machines = [\"o2\"]\nengines = [1]\n[[trace]]\nname = \"../out\"\nclass = \"h\"\nscene = \"hardcases\"\n".to_string(),
            "trace `../out`: a name is letters".to_string(),
        ),
        (
            format!("machines = [\"o2\"]\nengines = [1]\n{hardcases}{}", hardcases.replace("class", "retile = \"1x1\"\nclass")),
            "trace `h` named twice".to_string(),
        ),
        (demo("width = 100000"), "trace `d`: small: width 100000: expected 1 to 16384".to_string()),
        (demo("frames = 4294967295"), "frames 4294967295: expected 1 to 64".to_string()),
        // A size the scene cannot take (the hard cases' had been ignored, the random
        // triangles' frames too), refused as `trace gen` refuses it.
        (
            format!("machines = [\"o2\"]\nengines = [1]\n{hardcases}full = {{ width = 128 }}\n"),
            "trace `h`: full: the built-in hardcases scene has no width".to_string(),
        ),
        // Found only once a run came to them, after the traces before were made, and named
        // without the file (an unknown scene as a Rust debug string, a machine blamed on
        // --machines): refused as the file is read.
        (
            format!("machines = [\"o2\"]\nengines = [0]\n{hardcases}"),
            "`machines` and `engines`: o2 with 0 engines".to_string(),
        ),
        (
            format!("machines = [\"o9\"]\nengines = [1]\n{hardcases}"),
            "machine `o9`: unknown architecture".to_string(),
        ),
        (
            format!("{}{}", demo("width = 64"), hardcases.replace("hardcases", "nosuch")),
            "trace `h`: unknown scene `nosuch`".to_string(),
        ),
        (
            format!("{}[[trace]]\nname = \"w\"\nclass = \"w\"\nwalk = \"--driver nosuch\"\n", demo("width = 64")),
            "trace `w`: walk `--driver nosuch` at the full scale: unknown driver `nosuch`".to_string(),
        ),
        // A flag the walk does not have, in one line (clap's usage of `occsim` had followed).
        (
            format!("{}[[trace]]\nname = \"w\"\nclass = \"w\"\nwalk = \"--bogus 3\"\n", demo("width = 64")),
            "walk `--bogus 3` at the full scale: unexpected argument '--bogus' found; tip:".to_string(),
        ),
        // A walk's options and its size at each scale, checked as the file is read (they had
        // been found only when the trace came to be made, after the traces before it).
        (
            format!("{}[[trace]]\nname = \"w\"\nclass = \"w\"\nwalk = \"--driver frustum --collision-tiles 3\"\n", demo("width = 64")),
            "walk `--driver frustum --collision-tiles 3` at the full scale: --collision-tiles applies to the collision driver only".to_string(),
        ),
        (
            format!("{}[[trace]]\nname = \"w\"\nclass = \"w\"\nwalk = \"--driver frustum\"\nsmall = {{ frames = 2000000 }}\n", demo("width = 64")),
            "at the small scale: --frames 2000000 out of range".to_string(),
        ),
    ] {
        let file = dir.join("meaningless.toml");
        std::fs::write(&file, &text).unwrap();
        let error = support::cli::stderr_of_failure(&[
            "fidelity",
            "--corpus",
            "--scale",
            "small",
            "--corpus-file",
            file.to_str().unwrap(),
        ]);
        assert!(
            error.contains("meaningless.toml") && error.contains(&expected),
            "{text}: {error}"
        );
        assert!(!error.contains("Usage:"), "{text}: {error}");
    }
}

/// `--corpus` interrupted while it works leaves no scratch directory behind.
#[test]
fn an_interrupted_corpus_leaves_no_scratch_behind() {
    use std::os::unix::process::ExitStatusExt;
    let temp = support::cli::scratch_dir("corpus-interrupt");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_occsim"))
        .args(["fidelity", "--corpus", "--scale", "small", "--no-rtl"])
        .env("TMPDIR", &*temp)
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Signal once the scratch directory holds a trace (the first takes well under a second).
    let holds_a_file = || {
        std::fs::read_dir(&*temp)
            .unwrap()
            .flatten()
            .any(|dir| std::fs::read_dir(dir.path()).is_ok_and(|mut files| files.next().is_some()))
    };
    let status = support::cli::signal_when(
        &mut child,
        holds_a_file,
        (60, "no scratch trace appeared"),
        "INT",
    );
    assert_eq!(status.signal(), Some(2), "{status:?}");
    let left: Vec<_> = std::fs::read_dir(&*temp).unwrap().collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// What a killed corpus run can leave is dealt with by the next: a scratch directory of a
/// process that is gone is removed, and a kept trace cut short is made again, not refused.
#[test]
fn a_corpus_run_clears_what_a_killed_one_left() {
    let temp = support::cli::scratch_dir("corpus-leftovers");
    // No process has this id (above Linux's largest, 2^22).
    let stale = temp.join("occsim-corpus-4999999");
    std::fs::create_dir_all(&stale).unwrap();
    std::fs::write(stale.join("demo.occt"), "half a trace").unwrap();
    let kept = temp.join("kept");
    let run = |traces_dir: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_occsim"))
            .args(["fidelity", "--corpus", "--scale", "small", "--no-rtl"])
            .args([
                "--classes",
                "hardcases",
                "--machines",
                "o2",
                "--engines",
                "4",
            ])
            .args(traces_dir)
            .env("TMPDIR", &*temp)
            .output()
            .unwrap()
    };
    let scratch = run(&[]);
    let stderr = String::from_utf8_lossy(&scratch.stderr);
    assert!(scratch.status.success(), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(&*temp).unwrap().flatten().collect();
    assert!(left.is_empty(), "left behind: {left:?}");

    let keeping = ["--traces-dir", kept.to_str().unwrap()];
    let first = run(&keeping);
    assert!(first.status.success());
    let traces: Vec<_> = std::fs::read_dir(&kept).unwrap().flatten().collect();
    assert_eq!(traces.len(), 1, "{traces:?}");
    let trace = traces[0].path();
    let whole = std::fs::read(&trace).unwrap();
    std::fs::write(&trace, &whole[..whole.len() / 2]).unwrap();
    let second = run(&keeping);
    let stderr = String::from_utf8_lossy(&second.stderr);
    assert!(second.status.success(), "{stderr}");
    assert!(
        stderr.contains("making") && stderr.contains("again"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&trace).unwrap(), whole);
}

/// `fidelity --corpus` at the small scale on `machines` with 4 engines, without rtl, `more`
/// arguments added: its rows as JSON.
fn small_corpus_at_4_engines(scratch: &str, machines: &str, more: &[&str]) -> serde_json::Value {
    let temp = support::cli::scratch_dir(scratch);
    let mut args = vec![
        "fidelity",
        "--corpus",
        "--scale",
        "small",
        "--machines",
        machines,
        "--engines",
        "4",
        "--no-rtl",
        "--json",
    ];
    args.extend_from_slice(more);
    let stdout = support::cli::stdout_with_temp_dir(&args, &temp);
    serde_json::from_slice(&stdout).unwrap()
}

/// The fidelity ladder's errors on every class of the built-in corpus (small scale, o2 and
/// ir2 with 4 engines), each bounded. Issue 15's targets are analytic within 5% on cycles
/// and 10% on p95 latency, sampled:K within 1% and 3%. A row marked `target` holds its
/// target; a row marked `today` does not meet it yet and is bounded at the error measured
/// on 2026-12-02 after the fluid formulas (`occsim fidelity --corpus --scale small
/// --machines o2,ir2 --engines 4 --no-rtl`), rounded up by a fifth, so that a model change
/// that makes it worse fails here. Raise a bound only with a reason; lower it when a model
/// gets better.
#[test]
fn the_ladder_errors_stay_within_their_bounds_on_every_class() {
    let rows = small_corpus_at_4_engines("bounds", "o2,ir2", &[]);
    // (class, analytic cycles, analytic p95, sampled:10 cycles, sampled:10 p95), as fractions:
    // 0.05, 0.10, 0.01 and 0.03 are the targets; any other value is today's bound, with the
    // error measured in the comment. (c) raised when the fluids' carried backlog began to drain while the host
    // holds the pipe idle (it had been kept whole, an overestimate the sampled level's cycles
    // felt most: 1.4-3.4% on the walks, now 0.9-1.1%): the p95 of these O2 latencies, 10 to
    // 25 cycles, moved by 2 or 3 cycles. (d) raised when the sampled level's warm-up became
    // the 16,384 fragments before each sampled window, over as many windows as that takes
    // (it had been the window before, however short: an empty one left the machine's host
    // and clears cold, 7.69% on the hard cases' cycles, now 0.74%): the sampled queries'
    // measured latencies moved, and with them the regression's, by one cycle of the 1x1
    // demo's 19 on o2 and four of the adaptive walk's 20. (e) lowered when the formulas
    // began to set a primitive up no earlier than the geometry stage releases it inside a
    // window (they had overlapped a long batch with the work before it): the sampled
    // cycles of the hierarchical, quadtree and adaptive walks went from 1.00-1.06% to
    // 0.03-0.12%, the hierarchical walks' analytic p95 from 18.2% to 15.8%. (f) lowered when
    // an extrapolated query of a cell (its class and the formulas' latency) with at least 10
    // sampled queries began to take its nearest sampled query's spread about the regression
    // (`Donors` in `levels/sampled.rs`): sampled p95 on the random triangles from 8.70% to
    // 0.00%, on the hierarchical walks from 18.2% to 15.8%. (g) changed when the O2 formulas'
    // depth test began to trail by its slowest read's latency in stretches that neither
    // write nor read densely (the 0.02 cycles a read had filled the FIFO on every big box),
    // and a query's records to wait behind the next window's first reads when it follows at
    // once (`levels/analytic/o2.rs`): lowered where that helped (demo analytic 16.7% -> 4.76%,
    // sampled 16.7% -> 4.76%; grids sampled 3.41% -> 1.14%; 1x1/4x4 sampled 5.26% -> 2.96%),
    // raised on the small walks (hierarchical 15.8% -> 36.8% at both levels, adaptive 20.0% ->
    // 30.0%): the p95 of their 30-98 queries rests on the few whose last primitive is a thin
    // sliver, a read every fragment, whose lag the stretch's counts do not show, and the
    // sum had matched it by overestimating every query. At the full scale the same change
    // took the hierarchical walks' analytic p95 from 41.2% to 11.8% and the adaptive walk's
    // from 14.3% to 9.5%, their sampled:10 p95 from 12.0% and 23.8% to 0%. Then writes began
    // to pack to the port's width only between two reads: the demo's analytic p95 went from
    // 4.76% to 8.33% and its sampled p95 to 4.17%; on all engine counts, the 1x1 demo on o2
    // with one engine went from 42% to 2.6%. (h) lowered when a query's records began to
    // wait for the reads of exactly those of the next `L` fragments that read a word (they
    // had waited for all `L`), the port's reserved cycles to make a read wait their longest
    // run (ceil(f / (1 - f)), 1 here) and dense reads to stall the depth test in proportion
    // to them, the token's path to overlap an OccU-bound backlog, and a last fragment's
    // read to drain only what the rasterizer's later setups leave of it: the 1x1 and 4x4
    // demos' analytic p95 15.8% -> 5.91%; raised for their sampled:10 p95, 2.96% -> 5.26%,
    // one cycle of the 1x1 demo's 19 on o2, where the regression on 13 sampled queries
    // lands one cycle above the analytic level's own (now exact) p95. (j) changed when the
    // O2 formulas' port began to run on its own clock from the fragments' emission (a lag
    // already built is slack for a stretch's reads; they had been counted again behind it)
    // and a read-bound fragment to leave the FIFO at the end of its pace: lowered on the
    // walks (hierarchical 36.8% -> 26.3%, adaptive 30.0% -> 20.0%), raised for the 1x1/4x4
    // demos' analytic p95, 5.91% -> 10.53% (21 cycles against 19 for the 1x1 demo at 4
    // engines on o2). At the full scale on o2 at 1, 4 and 16 engines the same change took
    // that class from 16.0% to 8.0% and every class within 9.5%. (k) lowered when the O2
    // formulas began to keep the lag a stretch's densest run of reads leaves (a sliver
    // reading every fragment, which the stretch's summed reads had averaged away;
    // `traces/src/trace/dense_reads.rs`): hierarchical analytic 26.3% -> 5.26% (target),
    // sampled 36.8% -> 15.8%; adaptive analytic 20.0% -> 5.00% (target), sampled 30.0% ->
    // 5.00%; measured 2026-12-04. (l) lowered when the sampled level began to simulate on
    // the O2, besides every K-th window, the windows of the top tenth of the queries the
    // formulas predict slowest (`SampledModel::slowest_windows`): sampled p95 on the demo
    // 4.17% -> 0.23%, the hierarchical walks 15.8% -> 0%, the adaptive walk 5.00% -> 0%;
    // the 1x1/4x4 demos stay at 5.26%, one cycle of 19 that the measured window itself
    // gives (its machine, started mid-trace, meets the port's reserved cycles in another
    // phase); measured 2026-12-04. (m) lowered to the targets when the port's other clients
    // became a debt with a slack (they take the cycles the pipeline leaves idle, and force
    // one only when 16 behind; `blocks/memory_port.rs`) in place of a fixed pattern of
    // reserved cycles whose phase no count or warm-up told: the 1x1/4x4 demos' analytic p95
    // 10.53% -> 0%, sampled 5.26% -> 0%; every class's sampled:10 p95 within 0.62%, its
    // analytic p95 within 1.3% (the hard cases'); measured 2026-12-05.
    #[rustfmt::skip]
    let bounds: [ClassBounds; 10] = [
        ("demo",              0.05,  0.10,  0.01,  0.03),  // every target (l)
        ("retiled-1x1-4x4",   0.05,  0.10,  0.01,  0.03),  // every target (m)
        ("retiled-32x32",     0.05,  0.10,  0.01,  0.03),  // every target
        ("hardcases",         0.05,  0.10,  0.01,  0.03),  // every target (sampled 0.27%)
        ("random",            0.05,  0.10,  0.01,  0.03),  // every target (f)
        ("walk-frustum",      0.05,  0.10,  0.01,  0.03),  // every target
        ("walk-hierarchical", 0.05,  0.10,  0.01,  0.03),  // every target (l)
        ("walk-quadtree",     0.05,  0.10,  0.01,  0.03),  // every target (e)
        ("walk-adaptive",     0.05,  0.10,  0.01,  0.03),  // every target (l)
        ("walk-grids",        0.05,  0.10,  0.01,  0.03),  // every target (g)
    ];
    let over = over_bounds(&rows, &bounds);
    assert!(
        over.is_empty(),
        "errors over their bounds:\n{}",
        over.join("\n")
    );
}

/// (class, analytic cycles, analytic p95, sampled:10 cycles, sampled:10 p95): bounds on a
/// class's errors, as fractions.
type ClassBounds = (&'static str, f64, f64, f64, f64);

/// The errors of `rows` (a corpus run's) over their `bounds`, one line each.
fn over_bounds(rows: &serde_json::Value, bounds: &[ClassBounds]) -> Vec<String> {
    let mut over = Vec::new();
    for &(class, analytic_cycles, analytic_p95, sampled_cycles, sampled_p95) in bounds {
        for (level, metric, bound) in [
            ("analytic", "cycles_error", analytic_cycles),
            ("analytic", "frame_error", analytic_cycles),
            ("analytic", "latency_p95_error", analytic_p95),
            ("sampled:10", "cycles_error", sampled_cycles),
            ("sampled:10", "latency_p95_error", sampled_p95),
        ] {
            let value = class_error(rows, class, level, metric);
            if let Some(value) = value.filter(|&value| value > bound) {
                over.push(format!("{class} {level} {metric}: {value:.4} > {bound}"));
            }
        }
    }
    over
}

/// Under the blocks and morton interleaves, with FIFOs of 2 entries in front of the Image
/// Engines (a block's share of a row, 4 fragments, then fills an engine's FIFO and holds
/// its board's generator back), every class of the small corpus on ir2 at 4 engines is
/// held to issue 15's targets, and on ir4 at 4 engines under blocks with the default FIFOs. The formulas had dealt a stretch to its engines as under
/// the columns interleave, every engine starting at once, and restarted every board
/// together at each query's end (the machine's end token holds no board back): on the demo
/// at 1280x1024 on ir4 with the morton interleave and FIFOs of 2, the analytic level took
/// 16.1 M cycles where the machine takes 28.7 M (43.8% short), sampled:10 22.9 M (20.3%);
/// on the small corpus the hard cases' p95 latency was 25.2% off at both levels. Measured
/// 2026-12-07: every error within 1.2% (the 32x32-retiled demo's analytic cycles under
/// morton), the rest within 0.82%.
#[test]
fn the_ladder_errors_stay_within_the_targets_under_the_blocks_and_morton_interleaves() {
    let dir = support::cli::scratch_dir("interleaves");
    let traces = dir.join("traces");
    let targets: Vec<ClassBounds> = [
        "demo",
        "retiled-1x1-4x4",
        "retiled-32x32",
        "hardcases",
        "random",
        "walk-frustum",
        "walk-hierarchical",
        "walk-quadtree",
        "walk-adaptive",
        "walk-grids",
    ]
    .into_iter()
    .map(|class| (class, 0.05, 0.10, 0.01, 0.03))
    .collect();
    // ir4 with the default FIFOs: its sampled machines, started mid-trace with every board
    // level, had measured windows whose boards the trace had left apart (the hard cases
    // under the blocks interleave: sampled:10 5.83% over on cycles).
    for (machine, interleave, fifo) in [
        ("ir2", "blocks", 2),
        ("ir2", "morton", 2),
        ("ir4", "blocks", 8),
    ] {
        let rows = small_corpus_at_4_engines(
            "interleaves",
            machine,
            &[
                "--traces-dir",
                traces.to_str().unwrap(),
                "--set",
                &format!("interleave={interleave}"),
                "--set",
                &format!("image_engine_fifo_entries={fifo}"),
            ],
        );
        let over = over_bounds(&rows, &targets);
        assert!(
            over.is_empty(),
            "{machine}, {interleave}, FIFOs of {fifo}: errors over their bounds:\n{}",
            over.join("\n")
        );
    }
}

/// `--json` names the run each of a class's worst errors is from, and that run alone
/// (`fidelity TRACE --arch M --engines E`) has that error: the hard cases on o2 and ir2 at
/// 1 and 4 engines, whose analytic errors differ from run to run (the O2's p95 1.23% at one
/// engine, its cycles 0.03% at four, measured 2026-12-06). An error of 0 (the cycle level's
/// against itself) names no run.
#[test]
fn the_corpus_names_the_run_of_each_worst_error() {
    let dir = support::cli::scratch_dir("worst-runs");
    let traces = dir.join("traces");
    let rows = corpus_rows(
        &dir,
        "machines = [\"o2\", \"ir2\"]\nengines = [1, 4]\n[[trace]]\nname = \"h\"\n\
         class = \"h\"\nscene = \"hardcases\"\n",
        &["--traces-dir", traces.to_str().unwrap()],
    );
    let names = level_row(&rows, "cycle")["worst_runs"].as_object().unwrap();
    assert!(names.values().all(|name| name.is_null()), "{rows}");
    let trace = std::fs::read_dir(&traces)
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .find(|path| path.extension().is_some_and(|e| e == "occt"))
        .unwrap();
    let analytic = level_row(&rows, "analytic");
    for metric in ["cycles_error", "latency_p95_error"] {
        let name = analytic["worst_runs"][metric].as_str().unwrap();
        // "h on MACHINE, E engine(s)"
        let (machine, engines) = name
            .strip_prefix("h on ")
            .and_then(|rest| rest.split_once(", "))
            .unwrap_or_else(|| panic!("{name}"));
        let engines = engines.split(' ').next().unwrap();
        let alone = support::cli::stdout_of(&[
            "fidelity",
            trace.to_str().unwrap(),
            "--arch",
            machine,
            "--engines",
            engines,
            "--no-rtl",
            "--json",
        ]);
        let alone: serde_json::Value = serde_json::from_str(&alone).unwrap();
        assert!(analytic[metric].as_f64().unwrap() > 0.0, "{rows}");
        let level = level_row(&alone, "analytic");
        assert_eq!(level[metric], analytic[metric], "{name}: {metric}");
    }
}

/// `fidelity --corpus --json` on the recipes `recipes` (a corpus file's text, written into
/// `dir`, which is also the scratch directory), with `more` flags: its rows.
fn corpus_rows(dir: &std::path::Path, recipes: &str, more: &[&str]) -> serde_json::Value {
    let file = dir.join("recipes.toml");
    std::fs::write(&file, recipes).unwrap();
    let mut args = vec![
        "fidelity",
        "--corpus",
        "--corpus-file",
        file.to_str().unwrap(),
        "--no-rtl",
        "--json",
    ];
    args.extend_from_slice(more);
    serde_json::from_slice(&support::cli::stdout_with_temp_dir(&args, dir)).unwrap()
}

/// The row of `level` in a `fidelity --json` answer (one trace's, or one class's).
fn level_row<'a>(rows: &'a serde_json::Value, level: &str) -> &'a serde_json::Value {
    let mut rows = rows.as_array().unwrap().iter();
    rows.find(|row| row["level"] == level)
        .unwrap_or_else(|| panic!("no {level} row"))
}

/// Whether the small corpus's `class` has queries: all but the frustum walks', whose culling
/// asks none (their latency errors are none: `-` in the table, null in JSON).
fn has_queries(class: &str) -> bool {
    class != "walk-frustum"
}

/// A corpus row's `metric` for `class` at `level`, its counts checked exact; none for a
/// latency where the class's runs have no query (a frustum walk issues none: no latency to
/// be off, where 0 against 0 had been counted exact).
fn class_error(rows: &serde_json::Value, class: &str, level: &str, metric: &str) -> Option<f64> {
    let row = rows
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["class"] == class && r["level"] == level)
        .unwrap_or_else(|| panic!("no {class} {level} row"));
    assert_eq!(row["results_exact"], true, "{class} {level}");
    let value = row[metric].as_f64();
    let none_expected = metric.starts_with("latency") && !has_queries(class);
    assert_eq!(
        value.is_none(),
        none_expected,
        "{class} {level} {metric}: {row}"
    );
    value
}

/// Sampled:100 on the same corpus (o2, ir2 and ir4, 4 engines), held to the targets issue 15
/// sets sampled:K, 1% on cycles and 3% on p95 latency, on every class. The hard cases' p95 on
/// ir2 was 5.91% off (191 cycles where the machine takes 203) while the IR's formulas held a
/// Fragment Generator back only until a backlogged engine's last fragment could enter its
/// FIFO, not through the fragments its board emits after that one: their 28 queries give K =
/// 100 one sampled window, a query of the whole 64x64 viewport whose end token the formulas
/// then sent 14 cycles early (its drain 12 cycles long), and the regression moved every
/// other query by that one query's error. Now 1.19%. On ir4 the random triangles' cycles
/// were 1.18% off (20 sampled windows of 2,000) until the IR's warm-up grew with K past 10
/// (`warm_up_fragments`): 0.75% with 12,288 fragments, 0.71% since the generator hold.
/// Measured 2026-12-06 (`occsim fidelity --corpus --scale small --machines o2,ir2,ir4
/// --engines 4 --sample-every 100 --no-rtl`).
#[test]
fn sampled_100_stays_within_its_bounds_on_every_class() {
    let rows = small_corpus_at_4_engines("bounds-100", "o2,ir2,ir4", &["--sample-every", "100"]);
    // (class, sampled:100 cycles, sampled:100 p95), as fractions: 0.01 and 0.03 are the
    // targets.
    #[rustfmt::skip]
    let classes: [(&str, f64, f64); 10] = [
        ("demo",              0.01,  0.03),
        ("retiled-1x1-4x4",   0.01,  0.03),
        ("retiled-32x32",     0.01,  0.03),
        ("hardcases",         0.01,  0.03),
        ("random",            0.01,  0.03),
        ("walk-frustum",      0.01,  0.03),
        ("walk-hierarchical", 0.01,  0.03),
        ("walk-quadtree",     0.01,  0.03),
        ("walk-adaptive",     0.01,  0.03),
        ("walk-grids",        0.01,  0.03),
    ];
    let mut over = Vec::new();
    for (class, cycles, p95) in classes {
        for (metric, bound) in [("cycles_error", cycles), ("latency_p95_error", p95)] {
            let value = class_error(&rows, class, "sampled:100", metric);
            if let Some(value) = value.filter(|&value| value > bound) {
                over.push(format!(
                    "{class} sampled:100 {metric}: {value:.4} > {bound}"
                ));
            }
        }
    }
    assert!(
        over.is_empty(),
        "errors over their bounds:\n{}",
        over.join("\n")
    );
}

/// A query whose class (mode and OccU cycles a fragment) has no sampled query takes its
/// latency from the sampled queries of its mode by their ratio of measured to predicted
/// latency, below the largest of them. A busy-grid walk of the city at 640x480 on ir1 with
/// one engine has 53 brief queries of 1 to 300 tiles; at sampled:100 its one sampled query
/// is the first, 300 tiles, whose latency the formulas take 283 cycles short (24,616
/// against 24,899: 1.1%). Moved by that error, as before, every other query's latency, 138
/// to 7,303 cycles, was 283 cycles long: its mean latency 20.4% off, every query's own
/// error 71.5% at the median, the p95 3.25% (above sampled:K's 3% target). Scaled by
/// 24,899 / 24,616: 0.50%, 1.2% and 0.19% (measured 2026-12-06 with `occsim fidelity
/// --corpus --corpus-file F --scale small --no-rtl --sample-every 100`, F this test's
/// recipe).
#[test]
fn a_query_with_no_sampled_query_of_its_class_takes_its_modes_ratio_not_its_offset() {
    let dir = support::cli::scratch_dir("other-class");
    let rows = corpus_rows(
        &dir,
        "machines = [\"ir1\"]\nengines = [1]\n[[trace]]\nname = \"busy\"\nclass = \"busy\"\n\
         walk = \"--scene city --driver busy-grid\"\n\
         small = { width = 640, height = 480, frames = 1 }\n",
        &["--scale", "small", "--sample-every", "100"],
    );
    let error = |metric: &str| class_error(&rows, "busy", "sampled:100", metric).unwrap();
    let median = level_row(&rows, "sampled:100")
        .pointer("/query_latency_error/p50")
        .and_then(|p50| p50.as_f64())
        .unwrap();
    assert!(error("latency_error") <= 0.01, "{rows}");
    assert!(error("latency_p95_error") <= 0.03, "{rows}");
    assert!(median <= 0.05, "{rows}");
}

/// With no port cycles reserved for the display refresh and the host (`f` = 0), the O2's
/// analytic formulas are the cycle model's timing rules summed: on the small corpus at 4
/// engines, every class's total cycles within 0.1% (0.04% at most, measured 2026-12-03) but
/// the hard cases' 0.2% (0.19%: after each of their clears the machine's port serves the
/// last window's writes and the prefetch's reads of the fragments queued behind the clear
/// before its words, 4 to 18 cycles the formulas do not place; the 0.02 cycles a read they
/// had summed over every drawing stretch covered them, 0.06%, and put the random triangles'
/// queries 3 to 7 cycles late: `levels/analytic/o2.rs`, reads' stalls) and its p95 latency
/// exact, but the hard cases'
/// (1.82%, their clears' queries); on the walks, the random triangles and the demo, 95% of
/// the queries or more take the cycle model's latency to the cycle. The sampled level,
/// whose measured windows start machines mid-trace, gives every class's p95 latency
/// exactly here, the hard cases' too. All of it holds at the O2's own share, `f` = 0.234,
/// too, since the display refresh and the host became a debt with a slack (they force
/// cycles only where the port saturates past it, and the formulas follow the debt): the
/// hard cases' analytic p95 is 1.23% off there (measured 2026-12-05). Under the fixed
/// pattern of reserved cycles they had before, the sampled level's p95 was a cycle off
/// on the 1x1 and 4x4 demos and the grid walks, and the formulas' on the 1x1 demo two.
#[test]
fn with_or_without_the_ports_other_clients_the_o2_formulas_are_the_cycle_models_timing() {
    let unreserved = [
        "--set",
        "host_memory_share=0",
        "--set",
        "display_width_pixels=0",
    ];
    for (scratch, sets) in [("unreserved", &unreserved[..]), ("o2-share", &[][..])] {
        let rows = small_corpus_at_4_engines(scratch, "o2", sets);
        let analytic: Vec<&serde_json::Value> = rows
            .as_array()
            .unwrap()
            .iter()
            .filter(|row| row["level"] == "analytic")
            .collect();
        assert_eq!(analytic.len(), 10, "{rows}");
        let sampled = rows.as_array().unwrap().iter();
        let sampled: Vec<_> = sampled.filter(|row| row["level"] == "sampled:10").collect();
        assert_eq!(sampled.len(), 10, "{rows}");
        for row in sampled {
            let class = row["class"].as_str().unwrap();
            assert_eq!(
                row["latency_p95_error"].as_f64(),
                has_queries(class).then_some(0.0),
                "{scratch}: {row}"
            );
        }
        for row in analytic {
            let class = row["class"].as_str().unwrap();
            let metric = |key: &str| row.pointer(key).and_then(|v| v.as_f64());
            let cycles_bound = if class == "hardcases" { 0.002 } else { 0.001 };
            assert!(
                metric("/cycles_error").unwrap() <= cycles_bound,
                "{scratch}: {row}"
            );
            if class != "hardcases" {
                let exact = has_queries(class).then_some(0.0);
                assert_eq!(metric("/latency_p95_error"), exact, "{scratch}: {row}");
            }
            if class.starts_with("walk") && class != "walk-frustum"
                || ["random", "demo"].contains(&class)
            {
                assert_eq!(
                    metric("/query_latency_error/p95"),
                    Some(0.0),
                    "{scratch}: {row}"
                );
            }
        }
    }
}

/// Under blending (`--set blending=true`: every drawn fragment's colour is read before it is
/// written), the O2's formulas keep every class of the small corpus at 4 engines within
/// issue 15's latency targets, at the analytic level (p95 within 10%) and the sampled:10
/// level (p95 within 3%), and their cycles within 0.4% of the cycle level's.
///
/// Measured on 2026-12-06 (`occsim fidelity --corpus --scale small --machines o2 --engines 4
/// --no-rtl --set blending=true`): p95 at most 1.50% at either level (the hard cases), cycles
/// at most 0.32% (the hard cases' analytic level; the bound is that and a fifth). Before the
/// formulas' depth test ran ahead of the window's last writes (its write buffer holding
/// them) and the head's port gave the other clients their cycles
/// (`levels/analytic/o2.rs`, `trailing_write_cycles` and `PortOrder`), sampled:10's p95 was
/// 12.5% off on the demo, whose slowest windows' formulas were 16 to 31 cycles short (the
/// machine's 55, 104 and 81), and the hard cases' queries 23% off on average on the full
/// corpus; their cycles were 0.11% short, now 0.32%. Before a fragment's write waited for its
/// colour read (`write_cycles`), the hard cases' analytic cycles were 27% short and the
/// demo's 3.6%.
#[test]
fn under_blending_the_o2_formulas_keep_every_classs_cycles_and_p95_latency() {
    let rows = small_corpus_at_4_engines("blending", "o2", &["--set", "blending=true"]);
    let rows = rows.as_array().unwrap();
    let mut checked = 0;
    for row in rows {
        let p95_bound = match row["level"].as_str().unwrap() {
            "analytic" => 0.10,
            "sampled:10" => 0.03,
            _ => continue,
        };
        let cycles = row["cycles_error"].as_f64().unwrap();
        assert!(cycles <= 0.004, "{row}");
        let p95 = row["latency_p95_error"].as_f64();
        let class = row["class"].as_str().unwrap();
        assert_eq!(p95.is_some(), has_queries(class), "{row}");
        assert!(p95.is_none_or(|p95| p95 <= p95_bound), "{row}");
        checked += 1;
    }
    assert_eq!(checked, 20, "{rows:?}");
}

/// The issue's own walkthrough, a lazy-grid walk of the city over 2 frames at 1280x1024 (20
/// M fragments, queries of 380 to 484 tiles), on ir4: sampled:10 within the 1% target of
/// the cycle level. Its largest windows' classes (one a tile count) have no sampled window
/// and take the pooled calibration, whose largest sample is a 484-tile query's tail of
/// 65,440 fragments measuring 0.959 of the formulas' cycles. When only windows of 65,536
/// fragments or more counted as long (a tail is cut at an event, a few fragments short),
/// that rate was not carried past it, and the run came out 2.05% long; it is 0.12% short.
#[test]
fn sampled_stays_within_one_percent_on_the_issues_lazy_grid_walk_on_ir4() {
    let dir = support::cli::scratch_dir("lazy-grid");
    let trace = dir.as_ref().join("lazy.occt");
    let trace = trace.to_str().unwrap();
    let walk = ["--scene", "city", "--driver", "lazy-grid", "--frames", "2"];
    stdout_of(&[&["trace", "gen"][..], &walk, &["-o", trace]].concat());
    let cycles = |level: &str, key: &str| -> f64 {
        let args = [
            "replay",
            trace,
            "--arch",
            "ir4",
            "--fidelity",
            level,
            "--json",
        ];
        let report: serde_json::Value = serde_json::from_str(&stdout_of(&args)).unwrap();
        report.pointer(key).and_then(|v| v.as_f64()).unwrap()
    };
    let reference = cycles("cycle", "/summary/cycles");
    let sampled = cycles("sampled:10", "/total_cycles");
    let error = (sampled - reference).abs() / reference;
    assert!(
        error <= 0.01,
        "sampled:10 {sampled}, cycle {reference}: {error:.4}"
    );
}
