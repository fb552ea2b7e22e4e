//! Engine-level tests: a fake machine whose metrics follow a fixed formula of the point's
//! values (total_cycles = 1000 / (boards * engines) + 10 * boards, tiles = boards * engines).

use super::*;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

const DIGEST: &str = "sha256:0123abcd";

type Result<T, E = BoxError> = std::result::Result<T, E>;

/// An error and its sources, joined by ": " (as anyhow's `{:#}` prints them).
fn chain(error: &dyn std::error::Error) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(cause) = source {
        text.push_str(&format!(": {cause}"));
        source = cause.source();
    }
    text
}

fn accept_all(_: &str, value: &str) -> std::result::Result<String, String> {
    Ok(value.to_owned())
}

fn grid(specs: &[&str]) -> Grid {
    let specs: Vec<String> = specs.iter().map(|s| s.to_string()).collect();
    Grid::parse(&specs, &accept_all).unwrap()
}

/// The 12-point grid most tests sweep.
fn twelve_points() -> Grid {
    grid(&["boards=1,2,4", "engines=1,2,4,8"])
}

fn fake_machine(point: &Point) -> Result<PointRecord> {
    let boards: u64 = point.get("boards").unwrap_or("1").parse()?;
    let engines: u64 = point.get("engines").unwrap_or("1").parse()?;
    let cycles = 1000.0 / (boards * engines) as f64 + 10.0 * boards as f64;
    let mut metrics = BTreeMap::new();
    metrics.insert("total_cycles".to_string(), serde_json::Value::from(cycles));
    metrics.insert(
        "tiles".to_string(),
        serde_json::Value::from(boards * engines),
    );
    Ok(PointRecord {
        resolved_arch: serde_json::json!({"boards": boards, "engines": engines, "clock_mhz": 66.67}),
        metrics,
    })
}

fn options<'a>(grid: &'a Grid, out: &'a Path, jobs: usize) -> SweepOptions<'a> {
    SweepOptions {
        grid,
        shard: None,
        trace_digest: DIGEST,
        out,
        jobs,
        resume: false,
        replace: false,
        show_progress: false,
    }
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap()
}

/// Runs the whole grid with 1 job into `dir/full.jsonl`, the reference for other runs.
fn reference_run(dir: &Path, grid: &Grid) -> (String, String) {
    let out = dir.join("full.jsonl");
    run_sweep(&options(grid, &out, 1), &fake_machine).unwrap();
    (read(&out), read(&dir.join("full.csv")))
}

#[test]
fn csv_view_holds_the_hand_computed_metrics() {
    let temp = test_dir("csv-values");
    let dir = temp.path();
    let g = grid(&["boards=1,2", "engines=1,4"]);
    let out = dir.join("r.jsonl");
    let outcome = run_sweep(&options(&g, &out, 2), &fake_machine).unwrap();
    assert_eq!((outcome.evaluated, outcome.reused), (4, 0));
    assert_eq!(
        read(&dir.join("r.csv")),
        "point,key,boards,engines,tiles,total_cycles\n\
         0,\"boards=1,engines=1\",1,1,1,1010.0\n\
         1,\"boards=1,engines=4\",1,4,4,260.0\n\
         2,\"boards=2,engines=1\",2,1,2,520.0\n\
         3,\"boards=2,engines=4\",2,4,8,145.0\n"
    );
    let jsonl = read(&out);
    let keys: Vec<&str> = jsonl
        .lines()
        .map(|l| &l[..l.find(",\"axes\"").unwrap()])
        .collect();
    assert_eq!(
        keys,
        [
            r#"{"format":"occsim-sweep/2","point":0,"key":"boards=1,engines=1""#,
            r#"{"format":"occsim-sweep/2","point":1,"key":"boards=1,engines=4""#,
            r#"{"format":"occsim-sweep/2","point":2,"key":"boards=2,engines=1""#,
            r#"{"format":"occsim-sweep/2","point":3,"key":"boards=2,engines=4""#,
        ]
    );
    assert!(jsonl.contains(r#""trace_digest":"sha256:0123abcd""#));
    assert!(jsonl.contains(r#""resolved_arch":{"boards":2,"clock_mhz":66.67,"engines":4}"#));
}

#[test]
fn one_and_two_jobs_give_identical_files() {
    let temp = test_dir("jobs");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, csv) = reference_run(dir, &g);
    let out = dir.join("two.jsonl");
    run_sweep(&options(&g, &out, 2), &fake_machine).unwrap();
    assert_eq!(read(&out), jsonl);
    assert_eq!(read(&dir.join("two.csv")), csv);
    assert_eq!(jsonl.lines().count(), 12);
}

fn run_shard(dir: &Path, g: &Grid, number: usize, count: usize) -> PathBuf {
    let out = dir.join(format!("shard{number}.jsonl"));
    let mut o = options(g, &out, 2);
    o.shard = Some(Shard { number, count });
    run_sweep(&o, &fake_machine).unwrap();
    out
}

#[test]
fn three_shards_merged_equal_the_unsharded_run() {
    let temp = test_dir("shards");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, csv) = reference_run(dir, &g);
    let shards: Vec<PathBuf> = (1..=3).rev().map(|k| run_shard(dir, &g, k, 3)).collect();
    assert_eq!(
        read(&shards[0]).lines().count(),
        4,
        "shard 3/3 holds points 2, 5, 8, 11"
    );
    let merged = dir.join("merged.jsonl");
    let report = merge_results(&merged, &shards, false, false).unwrap();
    assert!(report.missing.is_empty());
    assert_eq!(read(&merged), jsonl);
    assert_eq!(read(&dir.join("merged.csv")), csv);
}

#[test]
fn merge_reports_missing_points_then_resume_fills_them() {
    let temp = test_dir("merge-missing");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, _) = reference_run(dir, &g);
    let shards = vec![run_shard(dir, &g, 1, 3), run_shard(dir, &g, 3, 3)];
    let merged = dir.join("merged.jsonl");
    let err = chain(&merge_results(&merged, &shards, false, false).unwrap_err());
    assert!(
        err.starts_with(
            "4 of 12 points are missing from the shards: 'boards=1,engines=2', \
             'boards=2,engines=1', 'boards=2,engines=8', 'boards=4,engines=4'; nothing written"
        ),
        "{err}"
    );
    assert!(!merged.exists());

    // A shard cut inside its last line (interrupted): the point is missing, and the error
    // says which shard lost it (it had listed the point alone).
    let all = [shards.clone(), vec![run_shard(dir, &g, 2, 3)]].concat();
    let text = read(&all[0]);
    let last_line_start = text.trim_end().rfind('\n').unwrap() + 1;
    std::fs::write(&all[0], &text[..last_line_start + 40]).unwrap();
    let err = chain(&merge_results(&merged, &all, false, false).unwrap_err());
    let torn = format!(
        "({} ends in a torn line, its point dropped)",
        all[0].display()
    );
    assert!(
        err.starts_with("1 of 12 points are missing from the shards: '") && err.contains(&torn),
        "{err}"
    );
    std::fs::write(&all[0], text).unwrap();

    let report = merge_results(&merged, &shards, true, false).unwrap();
    assert_eq!(report.missing.len(), 4);
    assert_eq!(read(&merged).lines().count(), 8);

    let evaluated = Mutex::new(Vec::new());
    let counting = |p: &Point| {
        evaluated.lock().unwrap().push(p.index);
        fake_machine(p)
    };
    let mut o = options(&g, &merged, 2);
    o.resume = true;
    run_sweep(&o, &counting).unwrap();
    let mut evaluated = evaluated.into_inner().unwrap();
    evaluated.sort();
    assert_eq!(evaluated, [1, 4, 7, 10]);
    assert_eq!(read(&merged), jsonl);
}

#[test]
fn merge_never_replaces_a_file_unless_told_to() {
    let temp = test_dir("merge-replace");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, _) = reference_run(dir, &g);
    let full = dir.join("full.jsonl");
    // An earlier, different sweep's results where the merge would go.
    let other_grid = grid(&["boards=1,2,4", "engines=1,2,4"]);
    let earlier = dir.join("earlier.jsonl");
    run_sweep(&options(&other_grid, &earlier, 1), &fake_machine).unwrap();
    let before = read(&earlier);
    let shards = vec![run_shard(dir, &g, 1, 2), run_shard(dir, &g, 2, 2)];
    let err = chain(&merge_results(&earlier, &shards, false, false).unwrap_err());
    assert!(
        err.contains("earlier.jsonl already exists; a merge replaces a file only when told to"),
        "{err}"
    );
    assert_eq!(read(&earlier), before, "the earlier results are untouched");
    merge_results(&earlier, &shards, false, true).unwrap();
    assert_eq!(read(&earlier), jsonl);
    // An empty file holds nothing to lose.
    let empty = dir.join("empty.jsonl");
    std::fs::write(&empty, "").unwrap();
    merge_results(&empty, &[full], false, false).unwrap();
    assert_eq!(read(&empty), jsonl);
}

#[test]
fn a_sweep_replaces_its_results_file_only_when_told_to() {
    let temp = test_dir("sweep-replace");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, _) = reference_run(dir, &g);
    let out = dir.join("out.jsonl");
    let other_grid = grid(&["boards=1,2,4", "engines=1,2,4"]);
    run_sweep(&options(&other_grid, &out, 1), &fake_machine).unwrap();
    let before = read(&out);
    let err = chain(&run_sweep(&options(&g, &out, 1), &fake_machine).unwrap_err());
    assert!(err.contains("out.jsonl already holds results"), "{err}");
    assert_eq!(read(&out), before);
    let mut o = options(&g, &out, 2);
    o.replace = true;
    let outcome = run_sweep(&o, &fake_machine).unwrap();
    assert_eq!((outcome.evaluated, outcome.reused), (12, 0));
    assert_eq!(read(&out), jsonl);
}

/// A run that stops early leaves what a reader can trust: no results file where it kept no
/// point, the old results and their CSV whole where it was to replace them and kept none,
/// and, once it kept one, its own points without the old results' CSV beside them.
#[test]
fn a_run_stopped_early_leaves_no_empty_file_and_no_stale_csv() {
    let temp = test_dir("sweep-stopped");
    let dir = temp.path();
    let g = twelve_points();
    let out = dir.join("out.jsonl");
    let csv = dir.join("out.csv");
    let log = Mutex::new(Vec::new());
    assert!(run_sweep(&options(&g, &out, 1), &crashing_machine(&log, 0)).is_err());
    assert!(
        !out.exists(),
        "a run that kept no point made a results file"
    );

    let old_grid = grid(&["boards=1,2,4", "engines=1,2,4"]);
    run_sweep(&options(&old_grid, &out, 1), &fake_machine).unwrap();
    let (old, old_csv) = (read(&out), read(&csv));
    let mut replacing = options(&g, &out, 1);
    replacing.replace = true;
    assert!(run_sweep(&replacing, &crashing_machine(&log, 0)).is_err());
    assert_eq!(
        (read(&out), read(&csv)),
        (old, old_csv),
        "replaced by nothing"
    );

    let log = Mutex::new(Vec::new());
    assert!(run_sweep(&replacing, &crashing_machine(&log, 3)).is_err());
    assert_eq!(read(&out).lines().count(), 3, "the new run's points alone");
    assert!(
        !csv.exists(),
        "the old grid's CSV beside the new grid's points"
    );
    let mut resuming = options(&g, &out, 1);
    resuming.resume = true;
    let outcome = run_sweep(&resuming, &fake_machine).unwrap();
    assert_eq!((outcome.evaluated, outcome.reused), (9, 3));
}

#[test]
fn merge_accepts_identical_duplicates_and_rejects_conflicts() {
    let temp = test_dir("merge-duplicates");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, _) = reference_run(dir, &g);
    let full = dir.join("full.jsonl");
    let shard = run_shard(dir, &g, 2, 3);
    let merged = dir.join("merged.jsonl");
    merge_results(&merged, &[shard.clone(), full.clone()], false, false).unwrap();
    assert_eq!(read(&merged), jsonl);

    // An edit with its digest made good again (an edit without is caught as such: below).
    let altered: String = read(&shard)
        .replacen("\"tiles\":2", "\"tiles\":3", 1)
        .lines()
        .map(|l| {
            crate::record::with_digest(&format!("{}}}", &l[..l.rfind(",\"digest\"").unwrap()]))
                + "\n"
        })
        .collect();
    std::fs::write(&shard, altered).unwrap();
    // (`merged` holds the first merge: replace it.)
    let err = chain(&merge_results(&merged, &[shard, full], false, true).unwrap_err());
    assert!(
        err.contains("hold different results for point 'boards=1,engines=2'"),
        "{err}"
    );
    assert!(err.contains("shard2.jsonl:1 and "), "{err}");
}

#[test]
fn an_edited_metric_is_caught_on_resume_and_by_merge() {
    let temp = test_dir("edited-metric");
    let dir = temp.path();
    let g = twelve_points();
    let (_, _) = reference_run(dir, &g);
    let full = dir.join("full.jsonl");
    let shard = run_shard(dir, &g, 2, 3);
    let edited = read(&shard).replacen("\"tiles\":2", "\"tiles\":3", 1);
    std::fs::write(&shard, edited).unwrap();
    let merged = dir.join("merged.jsonl");
    let err = chain(&merge_results(&merged, &[shard.clone(), full], false, false).unwrap_err());
    assert!(
        err.contains("shard2.jsonl:1: the line's digest does not match"),
        "{err}"
    );
    let mut o = options(&g, &shard, 2);
    o.resume = true;
    o.shard = Some(Shard {
        number: 2,
        count: 3,
    });
    let err = chain(&run_sweep(&o, &fake_machine).unwrap_err());
    assert!(
        err.contains("shard2.jsonl:1: the line's digest does not match"),
        "{err}"
    );
}

#[test]
fn merge_rejects_shards_of_another_trace_or_grid() {
    let temp = test_dir("merge-foreign");
    let dir = temp.path();
    let g = twelve_points();
    let shard = run_shard(dir, &g, 1, 2);
    let foreign = dir.join("foreign.jsonl");
    let mut o = options(&g, &foreign, 1);
    o.trace_digest = "sha256:ffff";
    o.shard = Some(Shard {
        number: 2,
        count: 2,
    });
    run_sweep(&o, &fake_machine).unwrap();
    let err = chain(
        &merge_results(
            &dir.join("m.jsonl"),
            &[shard.clone(), foreign],
            false,
            false,
        )
        .unwrap_err(),
    );
    assert!(
        err.contains("foreign.jsonl:1: results are for trace digest sha256:ffff"),
        "{err}"
    );
    assert!(
        err.contains("only shards of one sweep can be merged"),
        "{err}"
    );

    let other_grid = grid(&["boards=1,2,4", "engines=1,2,4"]);
    let other = dir.join("other.jsonl");
    run_sweep(&options(&other_grid, &other, 1), &fake_machine).unwrap();
    let err =
        chain(&merge_results(&dir.join("m.jsonl"), &[shard, other], false, false).unwrap_err());
    assert!(
        err.contains("other.jsonl:1: results are for the grid 'boards=1,2,4 engines=1,2,4'"),
        "{err}"
    );
}

/// Evaluates with the fake machine, recording every successful evaluation in `log`, and
/// fails ("crashes") once `successes_before_crash` have succeeded, whatever the job count.
fn crashing_machine<'a>(
    log: &'a Mutex<Vec<usize>>,
    successes_before_crash: usize,
) -> impl Fn(&Point) -> Result<PointRecord> + Sync + 'a {
    move |p: &Point| {
        let mut log = log.lock().unwrap();
        if log.len() >= successes_before_crash {
            return Err("simulated crash".into());
        }
        log.push(p.index);
        fake_machine(p)
    }
}

fn append_torn_fragment(out: &Path, of_line: &str) {
    let mut torn = read(out);
    torn.push_str(&of_line[..40]);
    std::fs::write(out, torn).unwrap();
}

#[test]
fn interrupted_sweep_resumes_without_losing_or_repeating_points() {
    let temp = test_dir("resume");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, csv) = reference_run(dir, &g);
    let out = dir.join("r.jsonl");
    let mut resuming = options(&g, &out, 2);
    resuming.resume = true;

    // Run 1: the machine crashes after 5 points; every finished point must be in the file.
    let run1 = Mutex::new(Vec::new());
    let err = run_sweep(&options(&g, &out, 2), &crashing_machine(&run1, 5));
    let err = chain(&err.unwrap_err());
    // 5 finished before the crash, whatever the job count (the machine counts them).
    assert!(
        err.contains("failed; the 5 points finished are kept in"),
        "{err}"
    );
    assert!(err.contains("simulated crash"), "{err}");
    let run1 = run1.into_inner().unwrap();
    assert_eq!(run1.len(), 5);
    assert_eq!(
        read(&out).lines().count(),
        run1.len(),
        "every finished point was appended"
    );

    // A kill during an append leaves an unterminated fragment of a line.
    append_torn_fragment(&out, jsonl.lines().nth(5).unwrap());
    let without_resume = run_sweep(&options(&g, &out, 2), &fake_machine).unwrap_err();
    assert!(matches!(
        without_resume,
        SweepError::AlreadyHoldsResults { .. }
    ));
    assert!(without_resume
        .to_string()
        .ends_with("r.jsonl already holds results; resume that sweep, or remove it to start over"));

    // Run 2 drops the fragment, then appends two points and crashes again: the appended lines
    // must not be glued to the fragment.
    let run2 = Mutex::new(Vec::new());
    let mut one_job = options(&g, &out, 1);
    one_job.resume = true;
    assert!(run_sweep(&one_job, &crashing_machine(&run2, 2)).is_err());
    let run2 = run2.into_inner().unwrap();
    assert_eq!(run2.len(), 2);

    // Run 3 finishes the sweep.
    let run3 = Mutex::new(Vec::new());
    let outcome = run_sweep(&resuming, &crashing_machine(&run3, 12)).unwrap();
    assert!(!outcome.torn_tail_dropped);
    assert_eq!(outcome.reused, run1.len() + 2);
    let mut all: Vec<usize> = [run1, run2, run3.into_inner().unwrap()].concat();
    all.sort();
    assert_eq!(
        all,
        (0..12).collect::<Vec<_>>(),
        "each point evaluated exactly once"
    );
    assert_eq!(read(&out), jsonl);
    assert_eq!(read(&dir.join("r.csv")), csv);

    // Resuming a finished sweep evaluates nothing and leaves the files as they are.
    let outcome = run_sweep(&resuming, &|_: &Point| Err("must not run".into())).unwrap();
    assert_eq!((outcome.evaluated, outcome.reused), (0, 12));
    assert_eq!(read(&out), jsonl);
}

#[test]
fn torn_line_is_reported_when_resuming() {
    let temp = test_dir("resume-torn");
    let dir = temp.path();
    let g = twelve_points();
    let (jsonl, _) = reference_run(dir, &g);
    let out = dir.join("r.jsonl");
    let first_four: String = jsonl.lines().take(4).map(|l| format!("{l}\n")).collect();
    std::fs::write(&out, first_four).unwrap();
    append_torn_fragment(&out, jsonl.lines().nth(4).unwrap());
    let mut o = options(&g, &out, 2);
    o.resume = true;
    let outcome = run_sweep(&o, &fake_machine).unwrap();
    assert!(outcome.torn_tail_dropped);
    assert_eq!((outcome.evaluated, outcome.reused), (8, 4));
    assert_eq!(read(&out), jsonl);
}

#[test]
fn resume_refuses_results_of_another_trace_or_shard() {
    let temp = test_dir("resume-foreign");
    let dir = temp.path();
    let g = twelve_points();
    let out = run_shard(dir, &g, 1, 3);

    let mut o = options(&g, &out, 1);
    o.resume = true;
    o.shard = Some(Shard {
        number: 1,
        count: 3,
    });
    o.trace_digest = "sha256:other";
    let err = chain(&run_sweep(&o, &fake_machine).unwrap_err());
    assert!(
        err.contains("shard1.jsonl:1: results are for trace digest sha256:0123abcd"),
        "{err}"
    );
    assert!(err.contains("belong to another trace"), "{err}");
    // The same trace at another level: the digest's hash is the same.
    o.trace_digest = "sha256:0123abcd:fidelity=analytic";
    let err = chain(&run_sweep(&o, &fake_machine).unwrap_err());
    assert!(
        err.contains(
            "belong to the same trace replayed otherwise (on another machine, or another tile grid, level or band study)"
        ),
        "{err}"
    );

    o.trace_digest = DIGEST;
    o.shard = Some(Shard {
        number: 2,
        count: 3,
    });
    let err = chain(&run_sweep(&o, &fake_machine).unwrap_err());
    assert!(
        err.contains("point 'boards=1,engines=1' is not part of shard 2/3"),
        "{err}"
    );
}

#[test]
fn metrics_get_their_units_from_their_names() {
    for (metric, unit) in [
        ("total_cycles", Some("cycles")),
        ("latency_p95_cycles", Some("cycles")),
        ("frames_per_second", Some("frames/s")),
        ("fragments_per_cycle", Some("fragments/cycle")),
        ("simulated_seconds", Some("s")),
        ("queries", Some("queries")),
        ("frame_ms", Some("ms")),
        ("total_cycles_band_high", Some("cycles")),
        ("frame_ms_band_low", Some("ms")),
        ("tiles", None),
    ] {
        assert_eq!(crate::chart::metric_unit(metric), unit, "{metric}");
    }
}

#[test]
fn sweep_chart_has_one_series_per_other_axis_combination() {
    let temp = test_dir("chart");
    let dir = temp.path();
    let g = grid(&["boards=1,2", "engines=1,4"]);
    let out = dir.join("r.jsonl");
    let outcome = run_sweep(&options(&g, &out, 1), &fake_machine).unwrap();
    let chart = metric_chart(
        g.axes(),
        &outcome.lines,
        "total_cycles",
        None,
        "t.occt on ir",
    )
    .unwrap();
    assert_eq!(chart.x_label, "engines");
    assert_eq!(chart.y_label, "total_cycles (cycles)");
    assert_eq!(
        chart.title,
        "total_cycles (cycles) against engines: t.occt on ir"
    );
    let series: Vec<(&str, &[(f64, f64)])> = chart
        .series
        .iter()
        .map(|s| (s.name.as_str(), s.points.as_slice()))
        .collect();
    assert_eq!(
        series,
        [
            ("boards=1", &[(1.0, 1010.0), (4.0, 260.0)][..]),
            ("boards=2", &[(1.0, 520.0), (4.0, 145.0)][..]),
        ]
    );
    let err = metric_chart(g.axes(), &outcome.lines, "wall_seconds", None, "").unwrap_err();
    assert_eq!(
        err.to_string(),
        "no result has metric 'wall_seconds'; metrics present: tiles, total_cycles"
    );
    let err = metric_chart(g.axes(), &outcome.lines, "tiles", Some("memory"), "").unwrap_err();
    assert_eq!(
        err.to_string(),
        "cannot plot against 'memory': it is not swept (swept: boards, engines)"
    );
}

#[test]
fn a_panicking_model_is_an_error_naming_the_point() {
    let temp = test_dir("panic");
    let dir = temp.path();
    let g = grid(&["engines=1,2,3"]);
    let out = dir.join("r.jsonl");
    let panicky = |p: &Point| -> Result<PointRecord> {
        if p.index == 1 {
            panic!("engine count {} unsupported", p.key());
        }
        fake_machine(p)
    };
    let err = chain(&run_sweep(&options(&g, &out, 1), &panicky).unwrap_err());
    assert!(err.contains("point 1 (engines=2) failed"), "{err}");
    assert!(
        err.contains("the model panicked: engine count engines=2 unsupported"),
        "{err}"
    );
}

#[test]
fn a_results_file_without_newlines_is_refused_at_its_first_megabyte() {
    // A file of 3 MB and no newline (as /dev/zero would give, which was read whole until
    // memory ran out): refused as a line past MAX_LINE_BYTES, naming the file and line 1.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("not-results.jsonl");
    std::fs::write(&path, vec![b'x'; 3 << 20]).unwrap();
    let error = crate::record::read_results(&path).expect_err("refused");
    let text = error.to_string();
    assert!(
        text.contains("not-results.jsonl:1") && text.contains("longer than 1048576 bytes"),
        "{text}"
    );
}

#[test]
fn an_unterminated_line_that_starts_no_result_is_no_torn_line() {
    // A note without a newline, given to --resume as the results file, had been dropped as
    // a torn line and the file replaced: now refused, naming it, and left as it was.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("notes.txt");
    std::fs::write(&path, "my precious notes").unwrap();
    let error = crate::record::read_results(&path).expect_err("refused");
    let text = error.to_string();
    assert!(
        text.contains("notes.txt:1") && text.contains("not a sweep's results file"),
        "{text}"
    );
    assert_eq!(read(&path), "my precious notes");
    // The start of a result line, cut anywhere (an interrupted append), is a torn line.
    for cut in [1, 5, 30] {
        let start = format!("{{\"format\":\"{}\",\"point\":3,", crate::record::FORMAT);
        std::fs::write(&path, &start[..cut]).unwrap();
        let file = crate::record::read_results(&path).unwrap();
        assert!(
            file.torn_tail_dropped && file.lines.is_empty(),
            "cut at {cut}"
        );
    }
}

#[test]
fn a_file_that_holds_no_results_is_not_taken_for_a_sweep_to_resume() {
    // A fresh sweep whose --out is a file of notes: refused as what it is, not as "already
    // holds results; resume that sweep", and left as it was.
    let temp = test_dir("notes");
    let g = twelve_points();
    let out = temp.path().join("notes.txt");
    std::fs::write(&out, "my precious notes\nsecond line\n").unwrap();
    let error = run_sweep(&options(&g, &out, 1), &fake_machine)
        .expect_err("refused")
        .to_string();
    assert!(
        error.contains("notes.txt:1") && !error.contains("already holds results"),
        "{error}"
    );
    assert_eq!(read(&out), "my precious notes\nsecond line\n");
}
