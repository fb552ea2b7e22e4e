//! `occsim sweep` end to end on a real trace: results do not depend on --jobs or sharding, and
//! bad axes are rejected by name.

mod support;

use std::path::{Path, PathBuf};
use support::cli::{occsim, scratch_dir as scratch, stdout_of};

/// Run `occsim` and require success.
fn ok(args: &[&str]) {
    stdout_of(args);
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

const AXES: [&str; 4] = ["--set", "engines=1,2,3", "--set", "counter_bits=8,32"];

#[test]
fn results_do_not_depend_on_jobs_or_shards() {
    let dir = scratch("det");
    let trace = dir.join("hard.occt");
    ok(&["trace", "gen", "hardcases", "-o", s(&trace)]);
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec!["sweep", s(&trace), "--arch", "o2", "--out", s(out)];
        args.extend(AXES);
        args.extend(extra);
        ok(&args);
    };
    let one = dir.join("one.jsonl");
    let two = dir.join("two.jsonl");
    run(&one, &["--jobs", "1"]);
    run(&two, &["--jobs", "2"]);
    let read = |p: &Path| std::fs::read(p).unwrap();
    assert_eq!(read(&one), read(&two));
    assert_eq!(
        read(&one.with_extension("csv")),
        read(&two.with_extension("csv"))
    );
    assert_eq!(String::from_utf8(read(&one)).unwrap().lines().count(), 6);

    let shards: Vec<PathBuf> = (1..=3)
        .map(|k| dir.join(format!("shard-{k}.jsonl")))
        .collect();
    for (k, shard) in shards.iter().enumerate() {
        run(shard, &["--shard", &format!("{}/3", k + 1)]);
    }
    let merged = dir.join("merged.jsonl");
    let mut args = vec!["sweep", "merge", s(&merged)];
    args.extend(shards.iter().map(|p| s(p)));
    ok(&args);
    assert_eq!(read(&one), read(&merged));
    assert_eq!(
        read(&one.with_extension("csv")),
        read(&merged.with_extension("csv"))
    );

    // A missing shard is reported by the keys of its points.
    let partial = dir.join("partial.jsonl");
    let output = occsim(&["sweep", "merge", s(&partial), s(&shards[0]), s(&shards[1])]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("2 of 6 points are missing"), "{stderr}");
    assert!(stderr.contains("engines=2,counter_bits=8"), "{stderr}");
}

/// A sweep's lines belong to its machine: resuming or merging results made on another
/// base architecture is refused, as another trace's are (a resume with `--arch ir4` had
/// continued a file made with `--arch ir2`, one CSV holding both machines' points).
#[test]
fn results_of_another_machine_are_not_joined() {
    let dir = scratch("machine");
    let trace = dir.join("hard.occt");
    ok(&["trace", "gen", "hardcases", "-o", s(&trace)]);
    let sweep = |arch: &str, out: &Path, extra: &[&str]| -> Vec<String> {
        let args = ["sweep", s(&trace), "--arch", arch, "--set", "engines=1,2"];
        let args = [&args[..], &["--out", s(out)], extra].concat();
        args.into_iter().map(str::to_owned).collect()
    };
    let ok = |args: Vec<String>| ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let occsim = |args: Vec<String>| occsim(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let ir2 = dir.join("ir2.jsonl");
    ok(sweep("ir2", &ir2, &["--shard", "1/2"]));
    let resumed = occsim(sweep("ir4", &ir2, &["--resume", "--shard", "1/2"]));
    assert!(!resumed.status.success());
    let stderr = String::from_utf8_lossy(&resumed.stderr);
    assert!(stderr.contains("on another machine"), "{stderr}");
    // A shard of each machine: the merge refuses the second.
    let ir4 = dir.join("ir4.jsonl");
    ok(sweep("ir4", &ir4, &["--shard", "2/2"]));
    let merged = dir.join("merged.jsonl");
    let merge = occsim(
        ["sweep", "merge", s(&merged), s(&ir2), s(&ir4)]
            .map(str::to_owned)
            .to_vec(),
    );
    assert!(!merge.status.success());
    let stderr = String::from_utf8_lossy(&merge.stderr);
    assert!(stderr.contains("on another machine"), "{stderr}");
    assert!(!merged.exists());
    // The same machine's shards merge.
    let same = dir.join("ir2-rest.jsonl");
    ok(sweep("ir2", &same, &["--shard", "2/2"]));
    ok(["sweep", "merge", s(&merged), s(&ir2), s(&same)]
        .map(str::to_owned)
        .to_vec());
}

/// README's rule: a results file is replaced only with `--force`, by `sweep` (which
/// otherwise continues it with `--resume` or refuses) and by `sweep merge` alike.
#[test]
fn results_files_are_replaced_only_with_force() {
    let dir = scratch("force");
    let trace = dir.join("hard.occt");
    ok(&["trace", "gen", "hardcases", "-o", s(&trace)]);
    let sweep = |out: &Path, set: &str, extra: &[&str]| {
        let mut args = vec!["sweep", s(&trace), "--out", s(out), "--set", set];
        args.extend(extra);
        occsim(&args)
    };
    // An earlier 3-point sweep, then a 2-point one in two shards.
    let earlier = dir.join("sweep.jsonl");
    assert!(sweep(&earlier, "engines=1,2,4", &[]).status.success());
    let before = std::fs::read(&earlier).unwrap();
    let shards: Vec<PathBuf> = (1..=2)
        .map(|k| dir.join(format!("shard-{k}.jsonl")))
        .collect();
    for (k, shard) in shards.iter().enumerate() {
        let shard_flag = format!("{}/2", k + 1);
        assert!(sweep(shard, "engines=1,8", &["--shard", &shard_flag])
            .status
            .success());
    }
    let merge = |extra: &[&str]| {
        let mut args = vec!["sweep", "merge", s(&earlier), s(&shards[0]), s(&shards[1])];
        args.extend(extra);
        occsim(&args)
    };
    let refused = merge(&[]);
    assert!(!refused.status.success());
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(
        stderr.contains("sweep.jsonl already exists; pass --force to replace it"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&earlier).unwrap(), before, "untouched");
    assert!(merge(&["--force"]).status.success());
    let merged = std::fs::read_to_string(&earlier).unwrap();
    assert_eq!(merged.lines().count(), 2, "the 2-point merge replaced it");

    // A fresh sweep over a results file: refused, then replaced with --force.
    let refused = sweep(&earlier, "engines=1,2,4", &[]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success());
    assert!(
        stderr.contains("pass --resume to continue that sweep, or --force to replace it"),
        "{stderr}"
    );
    assert_eq!(std::fs::read_to_string(&earlier).unwrap(), merged);
    assert!(sweep(&earlier, "engines=1,2,4", &["--force"])
        .status
        .success());
    assert_eq!(
        std::fs::read(&earlier).unwrap(),
        before,
        "the same sweep again"
    );

    // A merge into one of its own shards (README: the one output that may name an input):
    // refused without --force; with it, the shard is read whole first and the merge holds
    // its points beside the other shard's.
    let into_shard = |extra: &[&str]| {
        let mut args = vec![
            "sweep",
            "merge",
            s(&shards[0]),
            s(&shards[0]),
            s(&shards[1]),
        ];
        args.extend(extra);
        occsim(&args)
    };
    assert!(!into_shard(&[]).status.success());
    assert!(into_shard(&["--force"]).status.success());
    let merged = std::fs::read_to_string(&shards[0]).unwrap();
    assert_eq!(merged.lines().count(), 2, "both shards' points: {merged}");
}

/// `--json` prints the lines `--out` holds, as one array.
#[test]
fn sweep_json_prints_the_results_lines() {
    let dir = scratch("json");
    let trace = dir.join("hard.occt");
    ok(&["trace", "gen", "hardcases", "-o", s(&trace)]);
    let out = dir.join("r.jsonl");
    let printed = stdout_of(&[
        "sweep",
        s(&trace),
        "--out",
        s(&out),
        "--set",
        "engines=1,2",
        "--json",
    ]);
    let array: Vec<serde_json::Value> = serde_json::from_str(&printed).unwrap();
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(array, lines);
    assert_eq!(array.len(), 2);
    assert_eq!(array[1]["metrics"]["queries"], 28);
}

/// A sweep's chart names the metric with its unit, the swept parameter, the trace, the
/// machine and the level; a merge's names the shards' trace digest and machine.
#[test]
fn sweep_charts_say_what_they_show() {
    let dir = scratch("chart");
    let trace = dir.join("hard.occt");
    ok(&["trace", "gen", "hardcases", "-o", s(&trace)]);
    let (out, svg) = (dir.join("r.jsonl"), dir.join("r.svg"));
    ok(&[
        "sweep",
        s(&trace),
        "--arch",
        "o2",
        "--out",
        s(&out),
        "--set",
        "engines=1,2",
        "--set",
        "page_miss_latency_cycles=4,8",
        "--plot",
        s(&svg),
        "--retile",
        "2x2",
    ]);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(
        text.contains("total_cycles (cycles) against page_miss_latency_cycles: "),
        "{text}"
    );
    assert!(
        text.contains("hard.occt retiled 2x2 on o2, cycle"),
        "{text}"
    );
    assert!(
        text.contains("page_miss_latency_cycles (cycles)"),
        "the x unit: {text}"
    );
    let merged = dir.join("m.jsonl");
    let merged_svg = dir.join("m.svg");
    ok(&[
        "sweep",
        "merge",
        s(&merged),
        s(&out),
        "--plot",
        s(&merged_svg),
    ]);
    let text = std::fs::read_to_string(&merged_svg).unwrap();
    assert!(text.contains("1 shard of trace fnv1a64:"), "{text}");
    assert!(text.contains(" on o2"), "{text}");
    // A merge whose chart cannot be drawn writes none of its outputs (the merge and its CSV
    // had been written before the chart failed): they come into place together or not at all.
    let (unplotted, unplotted_svg) = (dir.join("u.jsonl"), dir.join("u.svg"));
    let output = occsim(&[
        "sweep",
        "merge",
        s(&unplotted),
        s(&out),
        "--plot",
        s(&unplotted_svg),
        "--plot-x",
        "boards",
    ]);
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("boards"), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|entry| entry.unwrap().file_name().into_string().unwrap())
        .filter(|name| name.starts_with("u.") || name.starts_with(".u."))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

#[test]
fn bad_axes_are_rejected_by_name() {
    let dir = scratch("bad");
    let trace = dir.join("hard.occt");
    ok(&["trace", "gen", "hardcases", "-o", s(&trace)]);
    let out = dir.join("x.jsonl");
    for (set, expected) in [
        (
            "enginez=1,2",
            "unknown parameter 'enginez' (did you mean engines?)",
        ),
        ("engines=0", "'engines' = 0"),
        ("counter_bits=wide", "counter_bits"),
        ("engines", "expected key=v1,v2"),
        // One value written two ways would be one point run twice under two keys.
        (
            "engines=4,04",
            "bad --set engines=04: the same value as '4' (4) given before it",
        ),
        (
            "clock_mhz=1e2,100",
            "bad --set clock_mhz=100: the same value as '1e2' (100.0) given before it",
        ),
    ] {
        let output = occsim(&["sweep", s(&trace), "--set", set, "--out", s(&out)]);
        assert!(!output.status.success(), "{set} accepted");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(expected), "{set}: {stderr}");
    }
    // A plot's metric and x axis are checked before any point runs (they had been checked
    // once every point had run), so no results file is made.
    let plot = dir.join("p.svg");
    for (flag, value, expected) in [
        (
            "--metric",
            "nosuch",
            "--metric nosuch: not a metric a sweep records",
        ),
        (
            "--plot-x",
            "boards",
            "--plot-x boards: not a swept parameter (swept: engines)",
        ),
    ] {
        let args = ["sweep", s(&trace), "--set", "engines=1,2", "--out", s(&out)];
        let output = occsim(&[&args[..], &["--plot", s(&plot), flag, value]].concat());
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            !output.status.success() && stderr.contains(expected),
            "{stderr}"
        );
        assert!(!out.exists(), "{flag}: points ran");
    }
    // An x axis of names or flags cannot be drawn: refused before any point runs (a sweep
    // over blending=false,true had run both points and written its results first).
    let args = [
        "sweep",
        s(&trace),
        "--set",
        "blending=false,true",
        "--out",
        s(&out),
    ];
    let output = occsim(&[&args[..], &["--plot", s(&plot)]].concat());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success()
            && stderr.contains("cannot plot against 'blending': value 'false' is not a number"),
        "{stderr}"
    );
    assert!(!out.exists(), "blending: points ran");
    // A chart at the results file's path or its CSV view's is refused before any point runs
    // (it had replaced the results, the run ending with status 0).
    for plot in [out.clone(), out.with_extension("csv")] {
        let args = ["sweep", s(&trace), "--set", "engines=1,2", "--out", s(&out)];
        let output = occsim(&[&args[..], &["--plot", s(&plot)]].concat());
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            !output.status.success() && stderr.contains("two of this command's outputs"),
            "{stderr}"
        );
        assert!(!out.exists(), "{}: points ran", plot.display());
    }
}

#[test]
fn sweeps_run_at_any_fidelity_and_rtl_agrees_with_cycle() {
    let dir = scratch("levels");
    let trace = dir.join("hard.occt");
    ok(&["trace", "gen", "hardcases", "-o", s(&trace)]);
    let run = |level: &str| {
        let out = dir.join(format!("{level}.jsonl"));
        ok(&[
            "sweep",
            s(&trace),
            "--set",
            "engines=1,4",
            "--fidelity",
            level,
            "--out",
            s(&out),
        ]);
        std::fs::read_to_string(out.with_extension("csv")).unwrap()
    };
    // rtl and cycle: the same cycles, the same CSV.
    assert_eq!(run("cycle"), run("rtl"));
    // The analytic level predicts total cycles, so the column is filled for both points.
    let analytic = run("analytic");
    let lines: Vec<&str> = analytic.lines().collect();
    assert_eq!(lines.len(), 3, "{analytic}");
    let header: Vec<&str> = lines[0].split(',').collect();
    let column = |name: &str| header.iter().position(|&c| c == name).unwrap();
    let (cycles_at, fragments_at) = (column("total_cycles"), column("fragments"));
    for row in &lines[1..] {
        let field = |at: usize| -> u64 { row.split(',').nth(at).unwrap().parse().unwrap() };
        assert!(
            field(cycles_at) > field(fragments_at),
            "at most one fragment a cycle: {row}"
        );
    }
    // The latency table needs a level with time; functional is refused by name.
    let output = occsim(&["latency", s(&trace), "--fidelity", "functional"]);
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("not functional"));
}

/// `trace gen` and `sweep` name their output alike: `-o`, `--output` and `--out` on both
/// (`trace gen -o` beside `sweep --out` had each refused the other's spelling).
#[test]
fn trace_gen_and_sweep_take_the_same_output_flags() {
    let dir = scratch("output-flags");
    for (k, flag) in ["-o", "--output", "--out"].into_iter().enumerate() {
        let trace = dir.join(format!("hard{k}.occt"));
        ok(&["trace", "gen", "hardcases", flag, s(&trace)]);
        assert!(trace.exists(), "trace gen {flag}");
        let results = dir.join(format!("r{k}.jsonl"));
        ok(&["sweep", s(&trace), flag, s(&results), "--set", "engines=1"]);
        assert!(results.exists(), "sweep {flag}");
    }
}
