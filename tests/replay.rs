//! Replays of the built-in scenes on the O2-like machine: counts equal the golden model's at
//! every engine count from 1 to 16, and a trace whose golden answer is wrong fails by name.
//! The demo and `random` are made at 320x256 (a quarter of their side, `random` with a
//! quarter of its triangles and queries): the same kinds of query and tile, a sixteenth of
//! the fragments.

mod support;

use occsim_sim::{Arch, MachineModel};
use occsim_traces::builtin::{demo_scene, random_scene, scene_text, DemoOptions, RandomOptions};
use occsim_traces::golden::{EventSink, GoldenModel};
use occsim_traces::scene::{Command, SceneReader};
use occsim_traces::trace::{TraceHeader, TraceReader, TraceWriter};
use occsim_traces::Event;
use std::process::Command as Process;

/// A built-in scene's trace, in memory (the demo and `random` at 320x256).
fn builtin_trace(name: &str) -> Vec<u8> {
    let text = match name {
        "demo" => demo_scene(&DemoOptions {
            width: 320,
            height: 256,
            ..DemoOptions::default()
        }),
        "random" => random_scene(&RandomOptions {
            width: 320,
            height: 256,
            triangles: 5000,
            queries: 500,
            ..RandomOptions::default()
        }),
        _ => scene_text(name).expect("built-in"),
    };
    let mut lines = SceneReader::new(text.as_bytes(), name);
    let Some(Ok(first)) = lines.next() else {
        panic!("{name}: empty")
    };
    let Command::Viewport { width, height } = first.command else {
        panic!("{name}: no viewport")
    };
    let mut bytes = Vec::new();
    let mut writer =
        TraceWriter::new(&mut bytes, &TraceHeader::new(width, height)).expect("header");
    let mut golden = GoldenModel::new(width, height);
    for line in lines {
        golden
            .execute(&line.expect("parses").command, &mut writer)
            .expect("writes");
    }
    golden.finish(&mut writer).expect("writes");
    writer.finish().expect("written");
    bytes
}

struct Replay {
    machine: MachineModel,
}

impl EventSink for Replay {
    type Error = occsim_sim::SimError;
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        self.machine.event(event)
    }
}

/// Replays on o2 with `engines`; returns (queries, queries checked against golden results).
fn replay(bytes: &[u8], engines: u32) -> (u64, u64) {
    let mut reader = TraceReader::new(bytes).expect("header");
    let mut arch = Arch::builtin("o2").unwrap();
    arch.set_value("engines", &engines.to_string()).unwrap();
    let (w, h) = (reader.header().width, reader.header().height);
    let mut replay = Replay {
        machine: MachineModel::new(&arch, w, h).expect("machine"),
    };
    if let Err(e) = reader.read_into(&mut replay) {
        panic!("engines {engines}: {e}");
    }
    let report = replay.machine.finish().expect("finishes");
    (report.summary.queries, report.summary.checked_queries)
}

#[test]
fn every_builtin_scene_matches_the_golden_model_at_1_to_16_engines() {
    for name in ["hardcases", "demo", "random"] {
        let bytes = builtin_trace(name);
        let engines: Vec<u32> = (1..=16).collect();
        // Two threads: the machine is single-threaded and the engine counts independent.
        let halves: Vec<Vec<(u64, u64)>> = std::thread::scope(|scope| {
            let handles: Vec<_> = engines
                .chunks(8)
                .map(|chunk| {
                    let bytes = &bytes;
                    scope.spawn(move || chunk.iter().map(|&e| replay(bytes, e)).collect())
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for (queries, checked) in halves.into_iter().flatten() {
            assert!(queries > 0, "{name}: no queries");
            assert_eq!(queries, checked, "{name}: every query checked");
        }
    }
}

#[test]
fn a_wrong_golden_answer_fails_the_replay_naming_the_query() {
    // Rewrite the hardcases trace with query 5's NOHC off by one.
    let good = builtin_trace("hardcases");
    let mut reader = TraceReader::new(&good[..]).unwrap();
    let header = reader.header().clone();
    let mut bytes = Vec::new();
    let mut writer = TraceWriter::new(&mut bytes, &header).unwrap();
    while let Some(mut event) = reader.next_event().unwrap() {
        if let Event::QueryResult(result) = &mut event {
            if result.id == 5 {
                assert_eq!(result.tiles[0].nohc, 256, "the hand-worked count");
                result.tiles[0].nohc = 257;
            }
        }
        writer.write_event(&event).unwrap();
    }
    writer.finish().unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wrong.occt");
    std::fs::write(&path, &bytes).unwrap();
    let output = Process::new(env!("CARGO_BIN_EXE_occsim"))
        .args(["replay", path.to_str().unwrap(), "--arch", "o2"])
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("query 5"), "{stderr}");
    assert!(stderr.contains("257") && stderr.contains("256"), "{stderr}");
}

#[test]
fn replay_json_has_the_documented_fields() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("json.occt");
    let bytes = builtin_trace("hardcases");
    let trace_fragments = TraceReader::new(&bytes[..])
        .unwrap()
        .read_into(&mut occsim_traces::golden::Discard)
        .unwrap()
        .fragments;
    std::fs::write(&path, &bytes).unwrap();
    let output = Process::new(env!("CARGO_BIN_EXE_occsim"))
        .args(["replay", path.to_str().unwrap(), "--engines", "2", "--json"])
        .output()
        .unwrap();
    let _ = std::fs::remove_file(&path);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let queries = report["queries"].as_array().unwrap();
    assert_eq!(queries.len(), 28);
    let q27 = queries.iter().find(|q| q["id"] == 27).unwrap();
    assert_eq!(q27["mode"], "brief");
    assert!(q27["latency_cycles"].as_u64().unwrap() >= 5);
    let tile = &q27["tiles"][1];
    for field in [
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
        assert!(!tile[field].is_null(), "tile field {field} missing: {tile}");
    }
    assert_eq!(tile["nohc"], 1024);
    assert_eq!(
        (tile["xmin"].as_u64(), tile["xmax"].as_u64()),
        (Some(0), Some(31))
    );
    let q25 = queries.iter().find(|q| q["id"] == 25).unwrap();
    assert_eq!(q25["tiles"][0]["overflowed"], true);
    // The machine counted every fragment the trace writer counted.
    assert_eq!(report["summary"]["fragments"], trace_fragments);
}

/// Where `lower` holds a key (in objects, and item by item in arrays), `cycle` holds it
/// too, of the same JSON type (or null at either, or an empty list below the cycle level).
fn assert_keys_held(path: &str, lower: &serde_json::Value, cycle: &serde_json::Value) {
    use serde_json::Value;
    match (lower, cycle) {
        (Value::Null, _) | (_, Value::Null) => {}
        (Value::Object(lower), Value::Object(cycle)) => {
            for (key, value) in lower {
                let held = cycle
                    .get(key)
                    .unwrap_or_else(|| panic!("{path}.{key} missing at the cycle level"));
                assert_keys_held(&format!("{path}.{key}"), value, held);
            }
        }
        // An empty list: the level has none (the functional level times no frame).
        (Value::Array(lower), Value::Array(_)) if lower.is_empty() => {}
        (Value::Array(lower), Value::Array(cycle)) => {
            assert_eq!(lower.len(), cycle.len(), "{path}'s length");
            for (k, (value, held)) in lower.iter().zip(cycle).enumerate() {
                assert_keys_held(&format!("{path}[{k}]"), value, held);
            }
        }
        (Value::Number(_), Value::Number(_))
        | (Value::String(_), Value::String(_))
        | (Value::Bool(_), Value::Bool(_)) => {}
        _ => panic!("{path}: {lower} below the cycle level, {cycle} at it"),
    }
}

#[test]
fn replay_json_reads_the_same_keys_at_every_level() {
    // Made by `trace gen`, with its window and band indexes: the analytic and sampled
    // levels read them, and say so (`from_window_index`).
    let (_dir, path) = support::cli::hardcases_trace("json-keys");
    for arch in ["o2", "ir2"] {
        let json_at = |level: &str| -> serde_json::Value {
            let output = Process::new(env!("CARGO_BIN_EXE_occsim"))
                .args(["replay", &path, "--arch", arch])
                .args(["--fidelity", level, "--json"])
                .output()
                .unwrap();
            assert!(output.status.success(), "{arch} {level}");
            serde_json::from_slice(&output.stdout).unwrap()
        };
        let cycle = json_at("cycle");
        for level in ["functional", "analytic", "sampled:2"] {
            let lower = json_at(level);
            assert_keys_held(&format!("{arch} {level}"), &lower, &cycle);
            let (lower_keys, cycle_keys) = (lower.as_object().unwrap(), cycle.as_object().unwrap());
            for key in ["from_window_index", "frame_cycles", "frames_per_second"] {
                assert!(lower_keys.contains_key(key), "{arch} {level}: {key}");
                assert!(cycle_keys.contains_key(key), "{arch} cycle: {key}");
            }
            let from_index = level != "functional";
            assert_eq!(lower["from_window_index"], from_index, "{arch} {level}");
        }
        assert_eq!(cycle["from_window_index"], false);
        // The run's figures at the top level are the report's.
        let summary = &cycle["summary"];
        assert_eq!(cycle["total_cycles"], summary["cycles"], "{arch}");
        assert_eq!(cycle["latency_p95_cycles"], summary["latency_p95_cycles"]);
        assert_eq!(cycle["fragments"], summary["fragments"]);
        let queries = cycle["queries"].as_array().unwrap();
        for query in queries {
            let tiles = query["tiles"].as_array().unwrap();
            assert_eq!(query["tile_count"], tiles.len(), "{arch}: {query}");
        }
        // Query 1 of the hard cases is a full-screen quad of the 64x64 viewport drawn once:
        // every pixel passes, 64 * 64 = 4096 (its comment in hardcases.scene).
        let first = queries.iter().find(|q| q["id"] == 1).unwrap();
        assert_eq!(
            (&first["value"], &first["nohc"]),
            (&4096.into(), &4096.into())
        );
    }
}
