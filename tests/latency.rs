//! End-to-end tests of `occsim latency` and of `--retile`, on the built-in hardcases trace.

mod support;

use support::cli::{hardcases_trace, occsim, stdout_of};

#[test]
fn latency_prints_one_row_per_engine_count_and_plots() {
    let (dir, trace) = hardcases_trace("rows");
    let svg = dir.join("latency.svg");
    let json = stdout_of(&[
        "latency",
        &trace,
        "--arch",
        "ir2",
        "--engines",
        "1,4,16",
        "--json",
        "--plot",
        svg.to_str().unwrap(),
    ]);
    let rows: serde_json::Value = serde_json::from_str(&json).unwrap();
    let rows = rows.as_array().unwrap();
    let engines: Vec<u64> = rows
        .iter()
        .map(|r| r["engines"].as_u64().unwrap())
        .collect();
    assert_eq!(engines, [1, 4, 16]);
    for row in rows {
        // The hardcases scene has 28 queries (its `end` lines).
        assert_eq!(row["queries"], 28);
        let (p50, p95, max) = (
            row["latency_p50_cycles"].as_u64().unwrap(),
            row["latency_p95_cycles"].as_u64().unwrap(),
            row["latency_max_cycles"].as_u64().unwrap(),
        );
        assert!(3 <= p50 && p50 <= p95 && p95 <= max, "{row}");
        // Default ir2: every path through the local tree over 80 Image Engines has at least
        // 5 hops (80, 40, 20, 10, 5, 3, 2, 1 with the odd ones passed up), each of 2 cycles
        // and at least one tile's 8 words over a 32-bit link (8); the global tree over 2
        // boards one hop of 8 cycles and at least 8 words over 64 bits (4), then the DMA of
        // at least 8 words at 16 bits a cycle (16).
        assert!(
            row["local_merge_mean_cycles"].as_f64().unwrap() >= 5.0 * (2.0 + 8.0),
            "{row}"
        );
        assert!(
            row["global_merge_mean_cycles"].as_f64().unwrap() >= 8.0 + 4.0 + 16.0,
            "{row}"
        );
        // 100 MHz: microseconds are cycles / 100.
        assert_eq!(row["latency_max_us"].as_f64().unwrap(), max as f64 / 100.0);
    }
    let svg = std::fs::read_to_string(svg).unwrap();
    assert!(svg.contains("<svg") && svg.contains("latency p95") && svg.contains("global merge"));
}

#[test]
fn with_zero_merge_latencies_the_table_shows_only_drain() {
    let (_dir, trace) = hardcases_trace("zero");
    let text = stdout_of(&[
        "latency",
        &trace,
        "--arch",
        "ir4",
        "--engines",
        "2",
        "--set",
        "local_merge_hop_latency_cycles=0",
        "--set",
        "global_merge_hop_latency_cycles=0",
        "--set",
        "local_merge_link_bits_per_cycle=0",
        "--set",
        "global_merge_link_bits_per_cycle=0",
        "--set",
        "report_dma_bits_per_cycle=0",
    ]);
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
    assert_eq!(header[0], "engines");
    let row: Vec<&str> = lines.next().unwrap().split_whitespace().collect();
    let column = |name: &str| row[header.iter().position(|h| *h == name).unwrap()];
    assert_eq!(row[0], "2");
    assert_eq!(column("local"), "0.0");
    assert_eq!(column("global"), "0.0");
}

#[test]
fn retile_replays_with_recomputed_golden_results() {
    let (_dir, trace) = hardcases_trace("retile");
    for arch in ["o2", "ir1", "ir4"] {
        let json = stdout_of(&[
            "replay", &trace, "--arch", arch, "--retile", "4x3", "--json",
        ]);
        let report: serde_json::Value = serde_json::from_str(&json).unwrap();
        let summary = &report["summary"];
        assert_eq!(summary["checked_queries"], summary["queries"], "{arch}");
        let brief_tiles: Vec<usize> = report["queries"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|q| q["mode"] == "brief")
            .map(|q| q["tiles"].as_array().unwrap().len())
            .collect();
        assert!(
            !brief_tiles.is_empty() && brief_tiles.iter().all(|&n| n == 12),
            "{arch}"
        );
    }
}

#[test]
fn bad_options_are_rejected_with_a_clear_message() {
    let (_dir, trace) = hardcases_trace("bad");
    let output = occsim(&[
        "latency",
        &trace,
        "--arch",
        "ir4",
        "--set",
        "interleave=diagonal",
    ]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("--set interleave=diagonal")
            && stderr.contains("expected one of columns, blocks, morton"),
        "{stderr}"
    );
    // Each row sets its own engine count: a --set engines= had been overridden unsaid.
    let output = occsim(&["latency", &trace, "--engines", "1", "--set", "engines=8"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success() && stderr.contains("--set engines=8"),
        "{stderr}"
    );
    let output = occsim(&["replay", &trace, "--arch", "ir4", "--retile", "5000x1"]);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success() && stderr.contains("--retile 5000x1"),
        "{stderr}"
    );
}

#[test]
fn the_analytic_and_sampled_levels_give_latency_without_a_split() {
    let (_dir, trace) = hardcases_trace("levels");
    let cycle = stdout_of(&[
        "latency",
        &trace,
        "--arch",
        "o2",
        "--engines",
        "2",
        "--json",
    ]);
    let cycle: serde_json::Value = serde_json::from_str(&cycle).unwrap();
    for level in ["analytic", "sampled:3"] {
        let json = stdout_of(&[
            "latency",
            &trace,
            "--arch",
            "o2",
            "--engines",
            "2",
            "--fidelity",
            level,
            "--json",
        ]);
        let rows: serde_json::Value = serde_json::from_str(&json).unwrap();
        let row = &rows[0];
        assert_eq!(row["queries"], 28, "{level}");
        // The O2's empty pipe costs 5 cycles: no level predicts less.
        assert!(
            row["latency_p50_cycles"].as_u64().unwrap() >= 5,
            "{level}: {row}"
        );
        assert!(row["drain_mean_cycles"].is_null(), "{level}: {row}");
        assert!(row["global_merge_mean_cycles"].is_null(), "{level}: {row}");
        let cycles = row["total_cycles"].as_f64().unwrap();
        let reference = cycle[0]["total_cycles"].as_f64().unwrap();
        assert!(
            (cycles - reference).abs() <= 0.25 * reference,
            "{level}: {cycles} cycles against {reference}"
        );
    }
    assert!(cycle[0]["drain_mean_cycles"].as_f64().is_some());
    let output = occsim(&["latency", &trace, "--fidelity", "functional"]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("latency needs a level with time"),
        "{stderr}"
    );
}

#[test]
fn the_o2_shows_no_merge_stages() {
    // The O2 has one pipe and no merge: its rows and query lines show `-` (null in JSON)
    // for the local and global merges, where they had shown 0.
    let (_dir, trace) = hardcases_trace("o2-merges");
    let json = stdout_of(&[
        "latency",
        &trace,
        "--arch",
        "o2",
        "--engines",
        "4",
        "--json",
    ]);
    let rows: serde_json::Value = serde_json::from_str(&json).unwrap();
    let row = &rows.as_array().unwrap()[0];
    assert!(row["local_merge_mean_cycles"].is_null(), "{row}");
    assert!(row["global_merge_mean_cycles"].is_null(), "{row}");
    assert!(row["drain_mean_cycles"].as_f64().unwrap() > 0.0, "{row}");
    let queries = stdout_of(&["replay", &trace, "--arch", "o2", "--queries"]);
    // index, id, mode, tiles, latency, drain, local, global, ...
    let first = queries
        .lines()
        .find(|line| line.split_whitespace().nth(1) == Some("1"))
        .unwrap();
    let columns: Vec<&str> = first.split_whitespace().collect();
    assert_eq!(&columns[6..8], ["-", "-"], "{first}");
    assert_ne!(columns[5], "-", "{first}");
}
