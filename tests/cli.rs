//! End-to-end tests of the `occsim` command line.

mod support;

use support::cli::{
    hardcases_trace, occsim, scratch_dir, signal_when, stderr_of_failure, stdout_of,
};

/// The hand-worked counts of tests/../traces/src/builtin/hardcases.scene (see its comments).
#[test]
fn count_hardcases_gives_the_hand_worked_counts() {
    let out = stdout_of(&["count", "hardcases"]);
    let counts: std::collections::BTreeMap<u32, u64> = out
        .lines()
        .filter(|line| line.split(' ').count() == 3)
        .map(|line| {
            let words: Vec<&str> = line.split(' ').collect();
            assert_eq!(words.len(), 3, "line `{line}`");
            assert_eq!(words[0], "query");
            (words[1].parse().unwrap(), words[2].parse().unwrap())
        })
        .collect();
    let expected: [(u32, u64); 23] = [
        (1, 4096),
        (2, 0),
        (3, 4096),
        (4, 4096),
        (5, 256),
        (6, 256),
        (7, 0),
        (8, 64),
        (9, 4096),
        (10, 0),
        (11, 1350),
        (12, 0),
        (13, 4096),
        (14, 0),
        (15, 4096),
        (16, 25),
        (17, 0),
        (18, 4096),
        (19, 4096),
        (20, 4096),
        (21, 4096),
        (22, 4096),
        (28, 4096),
    ];
    for (id, count) in expected {
        assert_eq!(counts.get(&id), Some(&count), "query {id}");
    }
    // The other modes print in their own forms (counts from the scene's comments): 23 any
    // sees its 4 pixels; 24-26 are a 2x2 square under buffers of 12, 11 and 8 entries (4
    // hits fit, 2 then -1, none); 27 is the full screen at z 0.5 over a cleared buffer, its
    // whole-screen tile and four quarters passing everywhere.
    for line in [
        "query 23 any 1",
        "query 24 verbose tile 0 nohc 4 phc 4 hits 4",
        "query 25 verbose tile 0 nohc 4 phc 4 hits 2 overflowed",
        "query 26 verbose tile 0 nohc 4 phc 4 hits 0 overflowed",
        "query 27 brief tile 0 nohc 4096 phc 4096",
        "query 27 brief tile 1 nohc 1024 phc 1024",
        "query 27 brief tile 4 nohc 1024 phc 1024",
    ] {
        assert!(out.lines().any(|l| l == line), "no `{line}` in\n{out}");
    }
    for id in [23, 24, 25, 26, 27] {
        assert!(
            !counts.contains_key(&id),
            "query {id} printed as a samples query"
        );
    }
}

#[test]
fn count_json_gives_verbose_buffers_and_tiles() {
    let out = stdout_of(&["count", "hardcases", "--json"]);
    let results: serde_json::Value = serde_json::from_str(&out).unwrap();
    let by_id = |id: u64| {
        results
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["id"] == id)
            .unwrap_or_else(|| panic!("query {id} missing"))
            .clone()
    };
    assert_eq!(by_id(23)["mode"], "any");
    assert_eq!(by_id(23)["tiles"][0]["nohc"], 1);
    // A 2x2-pixel square at window (30..32, 30..32): 4 hits.
    let fits = by_id(24);
    assert_eq!(fits["tiles"][0]["hits"]["count"], 4);
    assert_eq!(
        fits["tiles"][0]["hits"]["listed"].as_array().unwrap().len(),
        4
    );
    assert_eq!(
        fits["tiles"][0]["hits"]["listed"][0],
        serde_json::json!([30, 30])
    );
    assert_eq!(fits["tiles"][0]["overflowed"], false);
    assert_eq!(fits["overflowed_buffers"], 0);
    assert_eq!(fits["tiles"][0]["xmin"], 30);
    assert_eq!(fits["tiles"][0]["xmax"], 31);
    let by_one = by_id(25);
    assert_eq!(by_one["tiles"][0]["hits"]["count"], 2);
    assert_eq!(
        by_one["tiles"][0]["hits"]["listed"]
            .as_array()
            .unwrap()
            .len(),
        2
    );
    assert_eq!(by_one["tiles"][0]["overflowed"], true);
    assert_eq!(by_one["overflowed_buffers"], 1);
    let minimum = by_id(26);
    assert_eq!(minimum["tiles"][0]["hits"]["count"], 0);
    assert_eq!(minimum["tiles"][0]["nohc"], 4);
    assert_eq!(minimum["overflowed_buffers"], 1);
    let brief = by_id(27);
    let tiles = brief["tiles"].as_array().unwrap();
    assert_eq!(tiles.len(), 5);
    assert_eq!(tiles[0]["nohc"], 4096);
    assert_eq!(tiles[0]["phc"], 4096);
    for quadrant in &tiles[1..] {
        assert_eq!(quadrant["nohc"], 1024);
    }
    assert_eq!(
        (tiles[0]["xmin"].clone(), tiles[0]["xmax"].clone()),
        (0.into(), 63.into())
    );
    assert_eq!(
        (tiles[2]["xmin"].clone(), tiles[2]["ymax"].clone()),
        (32.into(), 31.into())
    );
}

#[test]
fn count_matches_a_scene_file_written_by_hand() {
    let dir = scratch_dir("count");
    let path = dir.join("two.scene");
    // A 4x4 viewport; the left half (8 pixels) drawn, then the whole screen behind it.
    std::fs::write(
        &path,
        "viewport 4 4\nbegin 10\ntri -1 -1 0 1  0 -1 0 1  0 1 0 1\ntri -1 -1 0 1  0 1 0 1  -1 1 0 1\nend\n\
         begin 11\ntri -1 -1 0.5 1  1 -1 0.5 1  1 1 0.5 1\ntri -1 -1 0.5 1  1 1 0.5 1  -1 1 0.5 1\nend\n",
    )
    .unwrap();
    assert_eq!(
        stdout_of(&["count", path.to_str().unwrap()]),
        "query 10 8\nquery 11 8\n"
    );
}

/// `trace gen demo` and `trace gen random` take the viewport, the demo its frames and both
/// a seed, as the corpus makes them (they had been ignored without a word: `trace gen demo
/// --width 640` wrote the 1280x1024 demo); a scene file and the hard cases take none, and
/// no built-in scene takes a walkthrough's flags.
#[test]
fn built_in_scenes_take_their_choices_and_refuse_the_rest() {
    use occsim_traces::builtin::{demo_scene, random_scene, DemoOptions, RandomOptions};
    let dir = scratch_dir("choices");
    let path = |name: &str| dir.join(name).to_str().unwrap().to_owned();
    let info = |trace: &str| -> serde_json::Value {
        serde_json::from_str(&stdout_of(&["trace", "info", trace, "--json"])).unwrap()
    };
    // The same scene as the library makes with those options, written out as a file.
    let demo = DemoOptions {
        width: 160,
        height: 128,
        frames: 1,
        seed: 7,
        ..DemoOptions::default()
    };
    let random = RandomOptions {
        width: 96,
        height: 64,
        seed: 5,
        ..RandomOptions::default()
    };
    for (name, flags, text) in [
        (
            "demo",
            &[
                "--width", "160", "--height", "128", "--frames", "1", "--seed", "7",
            ][..],
            demo_scene(&demo),
        ),
        (
            "random",
            &["--width", "96", "--height", "64", "--seed", "5"][..],
            random_scene(&random),
        ),
    ] {
        let chosen = path(&format!("{name}.occt"));
        stdout_of(&[&["trace", "gen", name, "-o", &chosen][..], flags].concat());
        let file = path(&format!("{name}.scene"));
        std::fs::write(&file, text).unwrap();
        let written = path(&format!("{name}-file.occt"));
        stdout_of(&["trace", "gen", &file, "-o", &written]);
        let (chosen, written) = (info(&chosen), info(&written));
        assert_eq!(chosen["summary"], written["summary"], "{name}");
        for side in ["width", "height"] {
            assert_eq!(chosen["header"][side], written["header"][side], "{name}");
        }
    }
    assert_eq!(info(&path("demo.occt"))["header"]["width"], 160);
    assert_eq!(info(&path("random.occt"))["header"]["height"], 64);
    // Refused, each naming what it refuses, with no file written.
    let refused = path("refused.occt");
    let hard_file = path("plain.scene");
    std::fs::write(&hard_file, "viewport 8 8\n").unwrap();
    for (args, says) in [
        (
            &["hardcases", "--width", "64"][..],
            "--width: the built-in hardcases scene has no width",
        ),
        (
            &["random", "--frames", "2"][..],
            "--frames: the built-in random scene has no frames",
        ),
        (
            &["demo", "--frames", "65"][..],
            "--frames 65: expected 1 to 64 (the built-in demo scene)",
        ),
        (
            &["demo", "--height", "0"][..],
            "--height 0: expected 1 to 16384",
        ),
        (
            &[hard_file.as_str(), "--seed", "3"][..],
            "--seed: scene file",
        ),
        (
            &["demo", "--driver", "frustum"][..],
            "cannot be used with '--driver",
        ),
        (
            &["random", "--scene", "forest"][..],
            "cannot be used with '--scene",
        ),
    ] {
        let error = stderr_of_failure(&[&["trace", "gen", "-o", &refused][..], args].concat());
        assert!(error.contains(says), "{args:?}: {error}");
        assert!(!std::path::Path::new(&refused).exists(), "{args:?}");
    }
}

/// A run without a query has no latency to report: `-` in the table and null in JSON at
/// every level with time (they had been 0, as if every query took no time).
#[test]
fn a_trace_without_queries_reports_no_latency() {
    let dir = scratch_dir("no-queries");
    let (scene, trace) = (dir.join("drawn.scene"), dir.join("drawn.occt"));
    std::fs::write(&scene, "viewport 4 4\ntri -1 -1 0 1  1 -1 0 1  1 1 0 1\n").unwrap();
    let trace = trace.to_str().unwrap();
    stdout_of(&["trace", "gen", scene.to_str().unwrap(), "-o", trace]);
    for level in ["analytic", "sampled:10", "cycle", "rtl"] {
        let replay = ["replay", trace, "--fidelity", level];
        let text = stdout_of(&replay);
        assert!(
            text.contains("latency p50 - p95 - max - cycles"),
            "{level}: {text}"
        );
        let json: serde_json::Value =
            serde_json::from_str(&stdout_of(&[&replay[..], &["--json"]].concat())).unwrap();
        for key in ["mean", "p50", "p95", "max"] {
            let field = format!("latency_{key}_cycles");
            assert!(
                json[&field].is_null(),
                "{level}: {field} = {}",
                json[&field]
            );
        }
        // The cycle report's own summary (cycle and rtl) says the same.
        if ["cycle", "rtl"].contains(&level) {
            for key in ["p50", "p95", "max"] {
                let field = format!("/summary/latency_{key}_cycles");
                let value = json.pointer(&field);
                assert!(
                    value.is_some_and(|v| v.is_null()),
                    "{level}: {field} = {value:?}"
                );
            }
        }
    }
    // `latency`, whose rows are latencies, refuses it (it had printed rows of 0).
    let error = stderr_of_failure(&["latency", trace]);
    assert!(error.contains("the trace has no query"), "{error}");
    // `fidelity --plot` draws each level by the error it has, its cycles' (it had drawn no
    // point and failed, every level's latency error being none).
    let chart = dir.join("price.svg");
    stdout_of(&["fidelity", trace, "--plot", chart.to_str().unwrap()]);
    let svg = std::fs::read_to_string(&chart).unwrap();
    assert!(svg.contains("analytic"), "{svg}");
}

#[test]
fn bad_scenes_name_file_and_line_and_exit_non_zero() {
    let dir = scratch_dir("bad");
    let path = dir.join("bad.scene");
    std::fs::write(
        &path,
        "viewport 8 8\nbegin 1\ntri 0 0 0 1 1 0 0 1 0 1 nan 1\nend\n",
    )
    .unwrap();
    let path = path.to_str().unwrap();
    let error = stderr_of_failure(&["count", path]);
    assert!(
        error.contains(&format!("{path}:3: tri coordinate 11 is `nan`")),
        "{error}"
    );
    let error = stderr_of_failure(&["count", "no-such-scene"]);
    assert!(
        error.contains("cannot open scene `no-such-scene`"),
        "{error}"
    );
    assert!(error.contains("demo, hardcases, random"), "{error}");
}

#[test]
fn trace_gen_info_dump_round_trip() {
    let dir = scratch_dir("trace");
    let trace = dir.join("hard.occt");
    let trace = trace.to_str().unwrap();
    let gen = stdout_of(&["trace", "gen", "hardcases", "-o", trace]);
    assert!(gen.starts_with(&format!("wrote {trace}: ")), "{gen}");
    let info = stdout_of(&["trace", "info", trace]);
    assert!(info.contains("viewport    64x64"), "{info}");
    // Written by this build: format version 14 (`traces/src/trace/block.rs`).
    assert!(info.contains("\nformat      version 14\n"), "{info}");
    assert!(
        info.contains("queries     28 (samples 23, any 1, brief 1, verbose 3)"),
        "{info}"
    );
    assert!(
        info.contains("8 sub-pixel bits, unorm24 depth, fill rule top-left with y down"),
        "{info}"
    );
    // --scan reads every block (and says so) and finds what the summary says.
    let scanned = stdout_of(&["trace", "info", trace, "--scan"]);
    let (before, last) = scanned.trim_end().rsplit_once('\n').unwrap();
    assert_eq!(info.trim_end(), before);
    assert!(
        last.starts_with(
            "scanned     every block's checksum checked; the events, the window index"
        ),
        "{scanned}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&stdout_of(&["trace", "info", trace, "--json"])).unwrap();
    assert_eq!(json["header"]["scene"], "hardcases");
    assert_eq!(json["summary"]["queries"], 28);
    assert_eq!(json["scanned"], false);
    assert_eq!(json["format_version"], 14);
    let json: serde_json::Value =
        serde_json::from_str(&stdout_of(&["trace", "info", trace, "--json", "--scan"])).unwrap();
    assert_eq!(
        json["scanned"], true,
        "the JSON says what the table's last line says"
    );
    let dump = stdout_of(&["trace", "dump", trace, "--limit", "3"]);
    let lines: Vec<&str> = dump.lines().collect();
    assert_eq!(lines.len(), 4, "{dump}");
    assert_eq!(lines[1], "begin 1 samples buffer=8 tiles 0,0,64,64");
    // The scene's first draw is two triangles: their geometry batch comes before the
    // first primitive.
    assert_eq!(lines[2], "geometry vertices=6 triangles=2 draw");
    assert_eq!(lines[3], "primitive");
}

#[test]
fn corrupted_traces_fail_with_the_file_and_byte_offset() {
    let dir = scratch_dir("corrupt");
    let trace = dir.join("good.occt");
    stdout_of(&["trace", "gen", "hardcases", "-o", trace.to_str().unwrap()]);
    let bytes = std::fs::read(&trace).unwrap();

    let bad_magic = dir.join("magic.occt");
    let mut b = bytes.clone();
    b[0] ^= 0xff;
    std::fs::write(&bad_magic, &b).unwrap();
    let error = stderr_of_failure(&["trace", "dump", bad_magic.to_str().unwrap()]);
    assert!(error.contains("magic.occt"), "{error}");
    assert!(error.contains("byte 0"), "{error}");

    let flipped = dir.join("flipped.occt");
    let mut b = bytes.clone();
    let middle = b.len() / 2;
    b[middle] ^= 0x10;
    std::fs::write(&flipped, &b).unwrap();
    let error = stderr_of_failure(&["trace", "dump", flipped.to_str().unwrap()]);
    assert!(error.contains("flipped.occt"), "{error}");
    assert!(error.contains("byte "), "{error}");

    let truncated = dir.join("truncated.occt");
    std::fs::write(&truncated, &bytes[..bytes.len() - 5]).unwrap();
    for command in ["dump", "info"] {
        let error = stderr_of_failure(&["trace", command, truncated.to_str().unwrap()]);
        assert!(error.contains("truncated.occt"), "{command}: {error}");
        assert!(error.contains("byte "), "{command}: {error}");
    }
}

#[test]
fn replay_at_rtl_fidelity_matches_cycle_and_writes_a_vcd_window() {
    let dir = scratch_dir("rtl");
    let trace = dir.join("hardcases.occt");
    let vcd = dir.join("waves.vcd");
    let (trace_arg, vcd_arg) = (trace.to_str().unwrap(), vcd.to_str().unwrap());
    stdout_of(&["trace", "gen", "hardcases", "-o", trace_arg]);
    // The rtl level builds every effect model, so compare with the cycle level doing so too.
    let cycle = stdout_of(&["replay", trace_arg, "--json", "--effects", "all"]);
    let output = occsim(&[
        "replay",
        trace_arg,
        "--json",
        "--fidelity",
        "rtl",
        "--vcd",
        vcd_arg,
        "--window",
        "10..200",
    ]);
    assert!(output.status.success());
    let json = |text: &[u8]| -> serde_json::Value { serde_json::from_slice(text).unwrap() };
    let (mut cycle, mut rtl) = (json(cycle.as_bytes()), json(&output.stdout));
    assert_eq!(
        (&cycle["level"], &rtl["level"]),
        (&"cycle".into(), &"rtl".into())
    );
    cycle["level"] = serde_json::Value::Null;
    rtl["level"] = serde_json::Value::Null;
    assert_eq!(cycle, rtl, "the same report but for its level");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains(&format!(
            "occsim: wrote {vcd_arg}: VCD waveform of the Occlusion Unit and OccU Control, cycles 10..200 of the run's {}",
            cycle["summary"]["cycles"]
        )),
        "{stderr}"
    );
    let text = std::fs::read_to_string(&vcd).unwrap();
    assert!(text.starts_with("$version occsim-rtl $end\n$timescale 1ps $end\n"));
    assert!(
        text.contains("$enddefinitions $end\n#149990\n"),
        "the dump starts at cycle 10"
    );
    // Each engine shows its tile slots one by one, as many as the largest query fills: a
    // replay retiled to 8x8 has 64-tile queries, 16 slots on each of the 4 engines.
    stdout_of(&[
        "replay",
        trace_arg,
        "--fidelity",
        "rtl",
        "--vcd",
        vcd_arg,
        "--window",
        "0..10",
        "--retile",
        "8x8",
    ]);
    let text = std::fs::read_to_string(&vcd).unwrap();
    assert_eq!(text.matches("$scope module slot_").count(), 64);
    assert!(text.contains("$scope module slot_15 $end"));
    assert!(!text.contains("$scope module slot_16 $end"));
    // Flags only the rtl fidelity takes, and windows that cannot be read, fail clearly.
    let without_rtl = stderr_of_failure(&["replay", trace_arg, "--vcd", vcd_arg]);
    assert!(without_rtl.contains("--vcd and --fst need --fidelity rtl"));
    for (window, message) in [
        ("5..3", "END must be greater than START"),
        ("1-3", "expected START..END"),
        ("a..9", "START \"a\" is not a cycle number"),
        ("100000..100500", "starts after the run, which has"),
    ] {
        let error = stderr_of_failure(&[
            "replay",
            trace_arg,
            "--fidelity",
            "rtl",
            "--vcd",
            vcd_arg,
            "--window",
            window,
        ]);
        assert!(error.contains(message), "{window}: {error}");
    }
    // A window past the end kept nothing: the VCD is the 0..10 one of the retiled run.
    assert_eq!(std::fs::read_to_string(&vcd).unwrap(), text);
}

#[test]
fn replay_writes_an_fst_beside_a_vcd_and_nothing_when_the_replay_fails() {
    let dir = scratch_dir("fst");
    let trace = dir.join("hardcases.occt");
    let (vcd, fst) = (dir.join("waves.vcd"), dir.join("waves.fst"));
    let trace_arg = trace.to_str().unwrap();
    stdout_of(&["trace", "gen", "hardcases", "-o", trace_arg]);
    let dump = |trace: &str| {
        vec![
            "replay".to_string(),
            trace.into(),
            "--fidelity".into(),
            "rtl".into(),
            "--vcd".into(),
            vcd.to_str().unwrap().into(),
            "--fst".into(),
            fst.to_str().unwrap().into(),
            "--window".into(),
            "10..200".into(),
        ]
    };
    let args = dump(trace_arg);
    stdout_of(&args.iter().map(String::as_str).collect::<Vec<_>>());
    // An FST begins with its header block: type 0, then its length, 329 bytes, big-endian.
    let bytes = std::fs::read(&fst).unwrap();
    assert_eq!(bytes[..9], [0, 0, 0, 0, 0, 0, 0, 1, 73]);
    assert!(std::fs::metadata(&vcd).unwrap().len() > 0);
    // A trace cut short fails the replay: neither file is made, no temporary is left.
    std::fs::remove_file(&vcd).unwrap();
    std::fs::remove_file(&fst).unwrap();
    let truncated = dir.join("truncated.occt");
    let whole = std::fs::read(&trace).unwrap();
    std::fs::write(&truncated, &whole[..whole.len() - 5]).unwrap();
    let args = dump(truncated.to_str().unwrap());
    stderr_of_failure(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(names, ["hardcases.occt", "truncated.occt"]);
}

#[test]
fn replay_writes_a_timeline_whose_tracks_do_not_overlap() {
    let dir = scratch_dir("timeline");
    let trace = dir.join("hardcases.occt");
    let timeline = dir.join("hc.json");
    let (trace_arg, timeline_arg) = (trace.to_str().unwrap(), timeline.to_str().unwrap());
    stdout_of(&["trace", "gen", "hardcases", "-o", trace_arg]);
    for arch in ["o2", "ir4"] {
        let report = stdout_of(&["replay", trace_arg, "--arch", arch, "--json"]);
        let report: serde_json::Value = serde_json::from_str(&report).unwrap();
        stdout_of(&[
            "replay",
            trace_arg,
            "--arch",
            arch,
            "--timeline",
            timeline_arg,
        ]);
        let text = std::fs::read_to_string(&timeline).unwrap();
        let json: serde_json::Value = serde_json::from_str(&text).expect("the timeline is JSON");
        let events = json["traceEvents"].as_array().unwrap();
        let mhz = if arch == "o2" { 66.67 } else { 100.0 };
        let mut by_track: std::collections::BTreeMap<u64, Vec<(u64, u64)>> = Default::default();
        let mut queries = 0;
        for event in events.iter().filter(|e| e["ph"] == "X") {
            let args = &event["args"];
            let (start, end) = (
                args["start_cycle"].as_u64().unwrap(),
                args["end_cycle"].as_u64().unwrap(),
            );
            assert!(start < end, "{event}");
            // ts and dur are cycles / clock MHz.
            let (ts, dur) = (
                event["ts"].as_f64().unwrap(),
                event["dur"].as_f64().unwrap(),
            );
            assert!((ts - start as f64 / mhz).abs() < 1e-6, "{event}");
            assert!((dur - (end - start) as f64 / mhz).abs() < 1e-6, "{event}");
            by_track
                .entry(event["tid"].as_u64().unwrap())
                .or_default()
                .push((start, end));
            if event["name"].as_str().unwrap().starts_with("query ") {
                // A query's slice runs from its begin to its result; its latency counts
                // from its end token.
                let latency = args["latency_cycles"].as_u64().unwrap();
                let end_token = args["query_end_cycle"].as_u64().unwrap();
                assert!(start <= end_token, "{event}");
                assert_eq!(end - end_token, latency, "{event}");
                let query = &report["queries"][queries];
                assert_eq!(args["id"], query["id"]);
                assert_eq!(latency, query["latency_cycles"].as_u64().unwrap());
                queries += 1;
            }
        }
        assert_eq!(
            queries,
            report["queries"].as_array().unwrap().len(),
            "{arch}"
        );
        let names: Vec<&str> = events
            .iter()
            .filter(|e| e["name"] == "thread_name")
            .map(|e| e["args"]["name"].as_str().unwrap())
            .collect();
        let expected: &[&str] = if arch == "o2" {
            &[
                "host",
                "geometry 0",
                "rasterizer (fragment_input)",
                "depth pipeline",
                "occlusion unit",
                "occlusion engine 0",
                "OccU Control",
                "memory port: depth reads",
                "memory port: depth writes",
                "memory port: OccU Control writes",
                "frames",
            ]
        } else {
            &[
                "host",
                "geometry 0",
                "board 0 fragment generator",
                "board 3 image engines",
                "board 0 merge (stage one)",
                "global merge (stage two)",
                "frames",
            ]
        };
        for name in expected {
            assert!(
                names.contains(name),
                "{arch}: no track `{name}` in {names:?}"
            );
        }
        for (tid, mut slices) in by_track {
            slices.sort();
            for pair in slices.windows(2) {
                assert!(
                    pair[0].1 <= pair[1].0,
                    "{arch}: track {tid} overlaps: {pair:?}"
                );
            }
        }
    }
    let error = stderr_of_failure(&[
        "replay",
        trace_arg,
        "--fidelity",
        "analytic",
        "--timeline",
        timeline_arg,
    ]);
    assert!(
        error.contains("--timeline needs --fidelity cycle or rtl"),
        "{error}"
    );
}

#[test]
fn the_rasterizer_profile_is_chosen_by_name_and_recorded_in_the_trace() {
    let error = stderr_of_failure(&["count", "hardcases", "--raster", "softpipe"]);
    assert!(
        error.contains("unknown rasterizer profile `softpipe`")
            && error.contains("llvmpipe, llvmpipe-window, exact"),
        "{error}"
    );
    // The edge-clipped triangle of issue 11: llvmpipe (and the default) counts 58, the
    // exact profile 57 (Mesa 22.3 measured the 58).
    let dir = scratch_dir("raster-profile");
    let scene = dir.join("edge.scene");
    std::fs::write(
        &scene,
        "viewport 200 150\nclear\nbegin 0\n\
         tri 1.195604 0.4832446 0.5 1  0.8642694 0.4082995 0.5 1  0.7934409 0.3295854 0.5 1\nend\n",
    )
    .unwrap();
    let scene = scene.to_str().unwrap();
    assert_eq!(stdout_of(&["count", scene]), "query 0 58\n");
    assert_eq!(
        stdout_of(&["count", scene, "--raster", "llvmpipe"]),
        "query 0 58\n"
    );
    assert_eq!(
        stdout_of(&["count", scene, "--raster", "exact"]),
        "query 0 57\n"
    );
    for profile in ["llvmpipe", "llvmpipe-window", "exact"] {
        let trace = dir.join(format!("{profile}.occt"));
        let trace = trace.to_str().unwrap();
        stdout_of(&["trace", "gen", scene, "-o", trace, "--raster", profile]);
        let info: serde_json::Value =
            serde_json::from_str(&stdout_of(&["trace", "info", trace, "--json"])).unwrap();
        assert_eq!(info["header"]["raster"], profile, "{info}");
    }
}

#[test]
fn workload_option_errors_name_their_flags() {
    let dir = scratch_dir("workload-flags");
    let out = dir.join("w.occt");
    let out = out.to_str().unwrap();
    let base = [
        "trace", "gen", "--scene", "city", "--blocks", "1", "-o", out,
    ];
    let with = |extra: &[&str]| {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        stderr_of_failure(&args)
    };
    let error = with(&["--frames", "0"]);
    assert!(
        error.contains("--frames 0 out of range: a walkthrough has 1 to 1000000 frames"),
        "{error}"
    );
    // Past the most (a walk of 4 billion frames had grown without end, then aborted).
    let error = with(&["--frames", "1000001"]);
    assert!(error.contains("--frames 1000001 out of range"), "{error}");
    let error = with(&["--driver", "lazy-grid", "--query-delay", "1"]);
    assert!(
        error.contains("--query-delay applies to the frustum"),
        "{error}"
    );
    let error = with(&[
        "--driver",
        "hierarchical",
        "--quadtree-levels",
        "2",
        "--virtual-occlusion-buffer",
    ]);
    assert!(
        error.contains(
            "--virtual-occlusion-buffer applies to the hierarchical driver without quadtree levels"
        ),
        "{error}"
    );
    // A grid's or the collision test's option on another driver (they had been taken and
    // left unused), as --variant and --quadtree-levels are.
    for (flags, says) in [
        (
            &["--driver", "frustum", "--grid-cell-pixels", "8"][..],
            "--grid-cell-pixels applies to the lazy-grid and busy-grid drivers only",
        ),
        (
            &["--driver", "lazy-grid", "--collision-tiles", "3"],
            "--collision-tiles applies to the collision driver only",
        ),
        (
            &["--driver", "frustum", "--collision-step", "5"],
            "--collision-step applies to the collision driver only",
        ),
    ] {
        let error = with(flags);
        assert!(error.contains(says), "{flags:?}: {error}");
    }
    let error = with(&["--driver", "hierarchical", "--quadtree-levels", "9"]);
    assert!(
        error.contains("--quadtree-levels 9 out of range"),
        "{error}"
    );
    let error = with(&[
        "--camera-from",
        "0,0,0",
        "--camera-to",
        "0,0,1",
        "--camera-target",
        "0,0,0",
    ]);
    assert!(error.contains("--camera-from/--camera-to"), "{error}");
    assert!(!std::path::Path::new(out).exists());
}

/// A trace write of a few seconds (the demo over 16 frames, 1 s a 4 frames here), then its
/// output path: long enough that a signal sent once its temporary exists comes before its
/// end.
const LONG_WRITE: [&str; 6] = ["trace", "gen", "demo", "--frames", "16", "-o"];

#[test]
fn an_interrupted_write_leaves_nothing_behind_and_ends_by_its_signal() {
    use std::os::unix::process::ExitStatusExt;
    for (name, number) in [("INT", 2), ("TERM", 15), ("HUP", 1)] {
        let dir = scratch_dir(&format!("interrupt-{name}"));
        let out = dir.join("demo.occt");
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_occsim"))
            .args(LONG_WRITE)
            .arg(out.to_str().unwrap())
            .stdout(std::process::Stdio::null())
            .spawn()
            .unwrap();
        // Signal once the temporary exists, seconds before the write could finish (a
        // finished write would leave the test nothing to check).
        let written = || std::fs::read_dir(&dir).unwrap().count() > 0;
        let status = signal_when(&mut child, written, (20, "no temporary appeared"), name);
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().collect();
        assert_eq!(status.signal(), Some(number), "SIG{name}: {status:?}");
        assert!(left.is_empty(), "SIG{name} left {left:?}");
    }
}

/// Started ignoring SIGHUP (as `nohup` starts it), a run outlives its terminal: the signal
/// stays ignored, and the write finishes.
#[test]
fn a_signal_ignored_at_start_stays_ignored() {
    use std::os::unix::process::CommandExt;
    let dir = scratch_dir("nohup");
    let out = dir.join("demo.occt");
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_occsim"));
    command
        .args(LONG_WRITE)
        .arg(out.to_str().unwrap())
        .stdout(std::process::Stdio::null());
    // SAFETY: between fork and exec the child only sets a signal's disposition, which is
    // async-signal-safe.
    unsafe {
        command.pre_exec(|| {
            libc::signal(libc::SIGHUP, libc::SIG_IGN);
            Ok(())
        });
    }
    let mut child = command.spawn().unwrap();
    // Signal once the temporary exists, while the trace is being written.
    let written = || std::fs::read_dir(&dir).unwrap().count() > 0;
    let status = signal_when(&mut child, written, (20, "no temporary appeared"), "HUP");
    assert!(status.success(), "{status:?}");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|entry| entry.unwrap().file_name())
        .collect();
    assert_eq!(left, ["demo.occt"]);
}

#[test]
fn a_reader_that_stops_early_is_no_failure() {
    let dir = scratch_dir("closed-pipe");
    let trace = dir.join("hc.occt");
    let trace = trace.to_str().unwrap();
    stdout_of(&["trace", "gen", "hardcases", "-o", trace]);
    for args in [
        vec!["latency", trace, "--arch", "o2", "--engines", "1,2"],
        vec!["fidelity", trace, "--arch", "o2", "--no-rtl"],
    ] {
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_occsim"))
            .args(&args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // `| head -0`: the reader closes the pipe before the first line.
        drop(child.stdout.take());
        let output = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(output.status.success(), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    }
}

#[test]
fn a_huge_buffer_costs_the_memory_it_uses_not_its_capacity() {
    // 320 Image Engines with a million-word OccU write buffer each: reserving the buffers'
    // rings up front took about 10 GiB of address space; what the trace uses is megabytes.
    let dir = scratch_dir("huge-buffer");
    let trace = dir.join("hc.occt");
    let trace = trace.to_str().unwrap();
    stdout_of(&["trace", "gen", "hardcases", "-o", trace]);
    let output = occsim_within(
        4_000_000,
        &format!("replay {trace} --arch ir4 --set occu_write_buffer_words=1048576"),
    );
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(String::from_utf8_lossy(&output.stdout).contains("cycles"));
}

/// Run `occsim args` with its address space limited to `kib` KiB; its output.
fn occsim_within(kib: u64, args: &str) -> std::process::Output {
    let command = format!(
        "ulimit -v {kib} && exec {} {args}",
        env!("CARGO_BIN_EXE_occsim")
    );
    std::process::Command::new("sh")
        .args(["-c", &command])
        .output()
        .unwrap()
}

#[test]
fn verbose_hits_cost_memory_by_the_tile_not_by_the_hit() {
    // One 99x99 quad under a verbose query of 16,384 copies of the whole-viewport tile with
    // 16 Mi-entry buffers: 16,384 * 9,801 = 160.6 million hits kept. Held as lists they took
    // 4 bytes or more each (over 640 MB; the result record was also too large to store in a
    // trace); held as `HitList`s each tile costs a few words, so every stage runs in 512 MB
    // of address space.
    let dir = scratch_dir("verbose-memory");
    let scene = dir.join("many-tiles.scene");
    let tiles = vec!["tile=0,0,99,99"; 16384].join(" ");
    std::fs::write(
        &scene,
        format!(
            "viewport 99 99\nclear\nbegin 1 verbose buffer=16777216 {tiles}\n\
             tri -1 -1 0 1  1 -1 0 1  1 1 0 1\ntri -1 -1 0 1  1 1 0 1  -1 1 0 1\nend\n"
        ),
    )
    .unwrap();
    let (scene, trace) = (scene.to_str().unwrap(), dir.join("t.occt"));
    let trace = trace.to_str().unwrap();
    let limit = 512_000;
    for args in [
        format!("count {scene}"),
        format!("trace gen {scene} -o {trace}"),
        format!("replay {trace}"),
        format!("replay {trace} --arch ir1"),
    ] {
        let output = occsim_within(limit, &args);
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "{args}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        if args.starts_with("count") {
            // Every tile holds every pixel: 9,801 hits, all fitting the buffer.
            let last = stdout.lines().last().unwrap();
            assert_eq!(
                last,
                "query 1 verbose tile 16383 nohc 9801 phc 9801 hits 9801"
            );
        } else if args.starts_with("replay") {
            assert!(
                stdout.contains("(1 checked against golden results)"),
                "{stdout}"
            );
        }
    }
}

#[test]
fn a_sweep_asked_for_absurd_jobs_caps_them_and_finishes() {
    let dir = scratch_dir("jobs-cap");
    let trace = dir.join("hc.occt");
    let out = dir.join("s.jsonl");
    stdout_of(&["trace", "gen", "hardcases", "-o", trace.to_str().unwrap()]);
    let output = std::process::Command::new(env!("CARGO_BIN_EXE_occsim"))
        .args([
            "sweep",
            trace.to_str().unwrap(),
            "--arch",
            "o2",
            "--set",
            "engines=1,2",
            "--jobs",
            "100000",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(
        stderr.contains("--jobs 100000 capped to 2 (2 points to run"),
        "{stderr}"
    );
}

#[test]
fn a_waveform_that_cannot_be_created_names_its_path() {
    let dir = scratch_dir("vcd-path");
    let trace = dir.join("hc.occt");
    let trace = trace.to_str().unwrap();
    stdout_of(&["trace", "gen", "hardcases", "-o", trace]);
    let missing = dir.join("no-such-dir").join("x.vcd");
    let error = stderr_of_failure(&[
        "replay",
        trace,
        "--fidelity",
        "rtl",
        "--vcd",
        missing.to_str().unwrap(),
    ]);
    // It said only "VCD writer stopped"; the path is checked before the replay now.
    assert!(
        error.contains(&format!("--vcd: cannot create {}", missing.display())),
        "{error}"
    );
}

/// `trace dump --json`: the header and the events, streamed as one JSON document.
#[test]
fn trace_dump_json_gives_the_header_and_events() {
    let dir = scratch_dir("dump-json");
    let trace = dir.join("hardcases.occt");
    let trace = trace.to_str().unwrap();
    stdout_of(&["trace", "gen", "hardcases", "-o", trace]);
    let dump: serde_json::Value = serde_json::from_str(&stdout_of(&[
        "trace", "dump", trace, "--json", "--limit", "5",
    ]))
    .unwrap();
    assert_eq!(
        (&dump["header"]["width"], &dump["header"]["height"]),
        (&64.into(), &64.into())
    );
    assert_eq!(dump["events"].as_array().unwrap().len(), 5, "{dump}");
    let all: serde_json::Value =
        serde_json::from_str(&stdout_of(&["trace", "dump", trace, "--json"])).unwrap();
    let events = all["events"].as_array().unwrap();
    let count = |name: &str| events.iter().filter(|e| e.get(name).is_some()).count();
    assert_eq!(count("QueryBegin"), 28, "the hard cases' 28 queries");
    assert_eq!(&events[..5], dump["events"].as_array().unwrap().as_slice());
}

/// `demo --json` prints only the replay's JSON, as `replay --json` does.
#[test]
fn demo_json_is_the_replay_report() {
    let out = stdout_of(&["demo", "--json"]);
    let report: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(report["level"], "cycle");
    assert_eq!(report["machine"], "o2");
    assert_eq!(report["viewport_width"], 1280);
    assert!(report["summary"]["frames_per_second"].as_f64().unwrap() > 0.0);
    // Every query's tiles' reports, as `replay --json` gives them (they had been empty).
    for query in report["queries"].as_array().unwrap() {
        let tiles = query["tiles"].as_array().unwrap();
        assert_eq!(
            Some(tiles.len() as u64),
            query["tile_count"].as_u64(),
            "{query}"
        );
    }
}

/// Fast-forward ([`occsim_sim::effects`]) changes no report on a lazy-grid walk, and `replay`
/// says how many fragments it took, in its text and in `--json`.
#[test]
fn replay_fast_forwards_a_lazy_grid_walk_to_the_exact_report() {
    let dir = scratch_dir("fast-forward");
    let trace = dir.join("lazy.occt");
    let trace_arg = trace.to_str().unwrap();
    let walk = ["--scene", "city", "--driver", "lazy-grid", "--frames", "1"];
    stdout_of(&[&["trace", "gen"][..], &walk, &["-o", trace_arg]].concat());
    let json = |text: String| -> serde_json::Value { serde_json::from_str(&text).unwrap() };
    for arch in ["o2", "ir4"] {
        let replay = ["replay", trace_arg, "--arch", arch, "--json", "--effects"];
        let mut all = json(stdout_of(&[&replay[..], &["all"]].concat()));
        let mut auto = json(stdout_of(&[&replay[..], &["auto"]].concat()));
        assert_eq!(all["fast_forwarded_fragments"], 0, "{arch}: all is exact");
        let fast_forwarded = auto["fast_forwarded_fragments"].as_u64().unwrap();
        if arch == "o2" {
            assert!(fast_forwarded > 0, "the rule never held on the walk");
        }
        for report in [&mut all, &mut auto] {
            report["fast_forwarded_fragments"] = serde_json::Value::Null;
            report["effects"] = serde_json::Value::Null;
        }
        assert_eq!(all, auto, "{arch}: fast-forward changed the report");
        let text = stdout_of(&["replay", trace_arg, "--arch", arch]);
        let fragments = &all["summary"]["fragments"];
        assert!(
            text.contains(&format!(
                "fast-forwarded: {fast_forwarded} of {fragments} fragments"
            )),
            "{text}"
        );
    }
}

/// A settings file past 16 MiB (an architecture, a corpus, a camera path: each a few KB) is
/// refused by its size, naming it, before it is read whole (/dev/zero as --arch-file had been
/// read for 2 GB until memory ran out).
#[test]
fn a_settings_file_too_large_to_be_one_is_refused_by_its_size() {
    let (dir, trace) = support::cli::hardcases_trace("large-settings");
    let large = dir.join("large.toml");
    std::fs::File::create(&large)
        .unwrap()
        .set_len((16 << 20) + 1)
        .unwrap();
    let large = large.to_str().unwrap();
    for (args, what) in [
        (
            vec!["replay", &trace, "--arch-file", large],
            "architecture file",
        ),
        (
            vec!["fidelity", "--corpus", "--corpus-file", large],
            "corpus file",
        ),
        (
            vec![
                "trace",
                "gen",
                "--scene",
                "city",
                "--camera-file",
                large,
                "-o",
                "x.occt",
            ],
            "camera file",
        ),
    ] {
        let error = support::cli::stderr_of_failure(&args);
        assert!(
            error.contains(&format!("{large}: larger than 16 MiB (is it the {what}?)")),
            "{args:?}: {error}"
        );
    }
}

/// A parameter set twice is refused, naming both, rather than the last one taken silently
/// (`--set engines=4 --set engines=8` had run 8 engines; `--engines 8 --set engines=2`, 8).
#[test]
fn a_parameter_set_twice_is_refused() {
    let (_dir, trace) = support::cli::hardcases_trace("set-twice");
    let error = stderr_of_failure(&["replay", &trace, "--set", "engines=4", "--set", "engines=8"]);
    assert!(
        error.contains("--set engines=8: engines is set twice (--set engines=4)"),
        "{error}"
    );
    let error = stderr_of_failure(&["replay", &trace, "--engines", "8", "--set", "engines=2"]);
    assert!(
        error.contains("--engines 8 and --set engines=2: give the engine count once"),
        "{error}"
    );
}

/// An output that cannot be written is refused before the work that makes it, named as the
/// user gave it (not by the temporary written beside it).
#[test]
fn an_output_in_a_missing_directory_is_refused_before_the_work() {
    let (dir, trace) = hardcases_trace("missing-output-dir");
    let trace = trace.as_str();
    let missing = dir.join("no-such-dir");
    let at = |name: &str| missing.join(name).to_str().unwrap().to_owned();
    let (svg, jsonl, occt) = (at("x.svg"), at("s.jsonl"), at("x.occt"));
    for (args, said) in [
        (
            vec!["latency", trace, "--plot", &svg],
            format!("--plot: cannot create {svg}"),
        ),
        (
            vec!["fidelity", trace, "--no-rtl", "--plot", &svg],
            format!("--plot: cannot create {svg}"),
        ),
        (
            vec!["sensitivity", trace, "--plot", &svg],
            format!("--plot: cannot create {svg}"),
        ),
        (
            vec!["sweep", trace, "--set", "engines=1,2", "--out", &jsonl],
            format!("cannot create {jsonl}"),
        ),
        (
            vec!["trace", "gen", "hardcases", "-o", &occt],
            format!("cannot create {occt}"),
        ),
    ] {
        // `--plot: ` is the check made at the start; the write at the end said `cannot
        // create` and the temporary's name.
        let error = stderr_of_failure(&args);
        assert!(error.contains(&said), "{args:?}: {error}");
    }
    let directory = dir.to_str().unwrap();
    let error = stderr_of_failure(&["sweep", trace, "--set", "engines=1,2", "--out", directory]);
    assert!(error.contains("not a regular file"), "{error}");
    assert!(!missing.exists());
}

/// `arch list` and `arch show` print JSON for scripts, with the figures their text gives.
#[test]
fn arch_list_and_show_print_json() {
    let list: serde_json::Value =
        serde_json::from_str(&stdout_of(&["arch", "list", "--json"])).unwrap();
    let names: Vec<&str> = (list.as_array().unwrap().iter())
        .map(|arch| arch["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["o2", "ir", "ir1", "ir2", "ir4"], "{list}");
    // ir2: the InfiniteReality-like machine with 2 boards; the O2 has none.
    assert_eq!(list[3]["boards"], 2);
    assert!(list[0]["boards"].is_null());
    let show = stdout_of(&["arch", "show", "ir2", "--set", "engines=2", "--json"]);
    let show: serde_json::Value = serde_json::from_str(&show).unwrap();
    assert_eq!(show["machine"], "ir");
    // Named as `arch list` and a chart's title name it, with the override.
    assert_eq!(show["name"], "ir2 (engines=2)");
    let param = |key: &str| {
        (show["parameters"].as_array().unwrap().iter())
            .find(|p| p["key"] == key)
            .unwrap_or_else(|| panic!("no {key} in {show}"))
            .clone()
    };
    assert_eq!(param("boards")["value"], 2);
    assert_eq!(param("engines")["value"], 2);
    // A built-in beside --arch-file is refused, as elsewhere (the file had been shown and
    // the name passed over).
    let both = stderr_of_failure(&["arch", "show", "ir4", "--arch-file", "my.toml"]);
    assert!(both.contains("cannot be used with"), "{both}");
    // As `arch show` prints it: `clock_mhz = 100.0 # [MHz] ... (I 75.0..150.0: ...)`.
    let clock = param("clock_mhz");
    assert_eq!(
        (&clock["unit"], &clock["provenance"], &clock["plausible"]),
        (
            &"MHz".into(),
            &"I".into(),
            &serde_json::json!([75.0, 150.0])
        )
    );
    assert!(param("boards")["plausible"].is_null());
}

/// A viewport whose depth buffer the process may not have is a clear error naming the scene
/// or the trace, and leaves nothing behind: 16384x16384 depths are 1 GiB, and the commands
/// run under a 600 MB address-space limit (`ulimit -v`; they need about 400 MB for a small
/// scene). `trace gen` had aborted on the allocation and left its temporary file.
#[test]
fn a_viewport_too_large_for_the_memory_limit_is_an_error_that_leaves_nothing() {
    use occsim_traces::trace::{TraceHeader, TraceWriter};
    use occsim_traces::{Event, Fragment};
    let dir = scratch_dir("memory-limit");
    std::fs::write(
        dir.join("huge.scene"),
        "viewport 16384 16384\nclear\nbegin 1\ntri -0.01 -0.01 0.5 1  0.01 -0.01 0.5 1  0 0.01 0.5 1\nend\n",
    )
    .unwrap();
    // A trace at that viewport written here, without an index (whose writer keeps depths).
    let mut trace = std::fs::File::create(dir.join("huge.occt")).unwrap();
    let mut writer = TraceWriter::new(&mut trace, &TraceHeader::new(16384, 16384)).unwrap();
    for event in [
        Event::Primitive,
        Event::Fragment(Fragment { x: 5, y: 7, z: 9 }),
    ] {
        writer.write_event(&event).unwrap();
    }
    writer.finish().unwrap();
    let limited = |args: &[&str]| {
        std::process::Command::new("sh")
            .args(["-c", "ulimit -v 600000 && exec \"$0\" \"$@\""])
            .arg(env!("CARGO_BIN_EXE_occsim"))
            .args(args)
            .current_dir(&dir)
            .output()
            .expect("sh runs")
    };
    let too_large = "the 16384x16384 viewport's depth buffer (1024 MiB) could not be allocated";
    for (args, names) in [
        (
            &["trace", "gen", "huge.scene", "-o", "out.occt"][..],
            "out.occt: cannot write trace",
        ),
        (&["count", "huge.scene"], "huge.scene"),
        (&["replay", "huge.occt"], "huge.occt"),
        (
            &[
                "replay",
                "huge.occt",
                "--arch",
                "ir2",
                "--fidelity",
                "functional",
            ],
            "huge.occt",
        ),
        (
            // A sampled window's machine fails as the other levels' setup does.
            &["replay", "huge.occt", "--fidelity", "sampled:2"],
            "huge.occt: cannot replay:",
        ),
        // The trace named once, after the level that failed.
        (
            &["fidelity", "huge.occt", "--no-rtl"],
            "functional: huge.occt: cannot replay",
        ),
        // A walkthrough's viewport is its flags'.
        (
            &[
                "trace",
                "gen",
                "--scene",
                "city",
                "--blocks",
                "1",
                "--frames",
                "1",
                "--width",
                "16384",
                "--height",
                "16384",
                "-o",
                "walk.occt",
            ],
            "walk.occt: cannot write trace",
        ),
        (
            &[
                "culling", "compare", "--scene", "city", "--blocks", "1", "--frames", "1",
                "--width", "16384", "--height", "16384",
            ],
            "--width 16384 --height 16384",
        ),
    ] {
        let output = limited(args);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains(names) && stderr.contains(too_large),
            "{args:?}: {stderr}"
        );
        assert!(
            stderr.matches("huge.occt").count() <= 1,
            "named twice: {stderr}"
        );
        let mut left: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|entry| entry.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, ["huge.occt", "huge.scene"], "{args:?} left a file");
    }
}

#[test]
fn every_output_path_is_checked_before_the_work() {
    // Each refused before a cycle is simulated or a scene made: the VCD's path had been
    // created only as the rtl replay began to write (seconds on the demo), two outputs at
    // one path found once both were written, and the demo's -o once its scene was made.
    let (dir, trace) = hardcases_trace("outputs-first");
    let at = |name: &str| dir.join(name).to_str().unwrap().to_owned();
    let rtl_replay_failing = |outputs: &[&str]| {
        let mut args = vec!["replay", trace.as_str(), "--fidelity", "rtl"];
        args.extend_from_slice(outputs);
        stderr_of_failure(&args)
    };
    let error = rtl_replay_failing(&["--vcd", &at("no-such-dir/x.vcd")]);
    assert!(error.contains("--vcd: cannot create"), "{error}");
    let both = at("x.vcd");
    let error = rtl_replay_failing(&["--vcd", &both, "--fst", &both]);
    assert!(
        error.contains("--vcd, --fst") && error.contains("two of"),
        "{error}"
    );
    let error = rtl_replay_failing(&["--vcd", &trace]);
    assert!(
        error.contains("--vcd") && error.contains("overwrite its own input"),
        "{error}"
    );
    // Of three outputs, the two that meet are named.
    let error = rtl_replay_failing(&["--vcd", &both, "--fst", &at("y.fst"), "--timeline", &both]);
    assert!(error.contains("--vcd, --timeline:"), "{error}");
    let out = at("no-such-dir/demo.occt");
    let start = std::time::Instant::now();
    let error = stderr_of_failure(&["trace", "gen", "demo", "--frames", "64", "-o", &out]);
    assert!(error.contains("-o: cannot create"), "{error}");
    // Not a benchmark: the 64-frame demo takes a quarter of a minute to make.
    assert!(start.elapsed().as_secs() < 5, "{:?}", start.elapsed());
    let left: Vec<_> = std::fs::read_dir(&*dir).unwrap().collect();
    assert_eq!(left.len(), 1, "{left:?}");
}

/// [`stderr_of_failure`], killing the command and failing if it runs `seconds` (it may
/// wait for ever on a FIFO).
fn stderr_of_failure_within(args: &[&str], seconds: u64) -> String {
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_occsim"))
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed().as_secs() >= seconds {
            child.kill().unwrap();
            panic!("occsim {args:?} still ran after {seconds} s");
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let output = child.wait_with_output().unwrap();
    assert!(!output.status.success(), "occsim {args:?} should fail");
    String::from_utf8(output.stderr).expect("utf-8 output")
}

#[test]
fn a_trace_that_is_no_regular_file_is_refused_at_once() {
    // A pipe gives one pass: a second had found the trace "truncated inside the magic
    // number", and a named FIFO's second open waited for another writer for ever.
    let (dir, trace) = hardcases_trace("pipes");
    let fifo = dir.join("trace.fifo");
    let path = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid C string; mkfifo only makes the node.
    assert_eq!(unsafe { libc::mkfifo(path.as_ptr(), 0o600) }, 0);
    let bytes = std::fs::read(&trace).unwrap();
    let writer = {
        let fifo = fifo.clone();
        // Opening a FIFO for writing waits for a reader; a refused replay may never open
        // it, so the writer opens it without waiting and gives up if no reader came.
        std::thread::spawn(move || {
            use std::io::Write;
            use std::os::unix::fs::OpenOptionsExt;
            for _ in 0..100 {
                let open = std::fs::OpenOptions::new()
                    .write(true)
                    .custom_flags(libc::O_NONBLOCK)
                    .open(&fifo);
                if let Ok(mut file) = open {
                    let _ = file.write_all(&bytes);
                    return;
                }
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        })
    };
    let name = fifo.to_str().unwrap();
    for args in [
        vec!["replay", name],
        vec!["trace", "info", name],
        vec!["fidelity", name, "--no-rtl"],
    ] {
        let error = stderr_of_failure_within(&args, 20);
        assert!(error.contains("not a regular file"), "{args:?}: {error}");
    }
    let error = stderr_of_failure(&["replay", "/dev/null"]);
    assert!(error.contains("/dev/null: not a regular file"), "{error}");
    writer.join().unwrap();
}

/// `bytes` with the first block of `kind` claiming one item more than it holds, its
/// checksum made again: a block only decoding finds wrong.
fn with_a_block_claiming_one_more(bytes: &[u8], kind: u8) -> Vec<u8> {
    // File header: magic (8), version (2), flags (2), JSON length (4), JSON, CRC (4); then
    // blocks of a 20-byte header (kind, codec, 2 reserved, events, raw and stored lengths,
    // CRC of the 16 bytes before it and the stored payload) and the payload.
    let json_len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
    let mut at = 16 + json_len + 4;
    loop {
        let stored = u32::from_le_bytes(bytes[at + 12..at + 16].try_into().unwrap()) as usize;
        if bytes[at] == kind {
            let mut forged = bytes.to_vec();
            let events = u32::from_le_bytes(bytes[at + 4..at + 8].try_into().unwrap());
            forged[at + 4..at + 8].copy_from_slice(&(events + 1).to_le_bytes());
            let mut crc = crc32fast::Hasher::new();
            crc.update(&forged[at..at + 16]);
            crc.update(&forged[at + 20..at + 20 + stored]);
            forged[at + 16..at + 20].copy_from_slice(&crc.finalize().to_le_bytes());
            return forged;
        }
        at += 20 + stored;
    }
}

#[test]
fn trace_info_scan_decodes_every_lane() {
    // A band-index (kind 6) or window-index (kind 3) block that claims an item more than it
    // holds, its checksum valid: `--scan` had read the events alone and said every block's
    // payload was checked.
    let (dir, trace) = hardcases_trace("scan-lanes");
    let clean = std::fs::read(&trace).unwrap();
    stdout_of(&["trace", "info", &trace, "--scan"]);
    for (kind, lane) in [(6u8, "band"), (3, "window index")] {
        let forged = dir.join(format!("forged-{kind}.occt"));
        std::fs::write(&forged, with_a_block_claiming_one_more(&clean, kind)).unwrap();
        let forged = forged.to_str().unwrap();
        // The summary alone does not see it.
        stdout_of(&["trace", "info", forged]);
        let error = stderr_of_failure(&["trace", "info", forged, "--scan"]);
        assert!(error.contains("claims"), "{lane}: {error}");
    }
}
