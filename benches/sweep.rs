//! Sweep scaling: 30 points over the demo trace, run with 1 and with 2 jobs in the same run,
//! taking turns in two rounds (`occsim_traces::rounds`; each keeps its fastest); prints both
//! wall times and the speed-up (aim: near linear), and checks the two result files are
//! identical (results never depend on --jobs).
//!
//! `cargo bench --bench sweep` (set OCCSIM_SWEEP_ARCH to sweep another built-in machine).

use occsim_traces::rounds::fastest_of_rounds;
use std::path::Path;
use std::process::Command;

/// Rounds in which the two job counts take turns (a round is about a minute).
const ROUNDS: usize = 2;

fn occsim(args: &[&str]) {
    let output = Command::new(env!("CARGO_BIN_EXE_occsim"))
        .args(args)
        .output()
        .expect("occsim runs");
    assert!(
        output.status.success(),
        "occsim {args:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
}

fn main() {
    let arch = std::env::var("OCCSIM_SWEEP_ARCH").unwrap_or_else(|_| "o2".to_owned());
    let dir = std::env::temp_dir().join(format!("occsim-bench-sweep-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch directory");
    let trace = dir.join("demo.occt");
    let path = |p: &Path| p.to_str().expect("utf-8 path").to_owned();
    occsim(&["trace", "gen", "demo", "-o", &path(&trace)]);
    let axes = [
        "--set",
        "engines=1,2,3,4,5,6,7,8,12,16",
        "--set",
        "counter_bits=16,24,32",
    ];
    let run = |jobs: &str| {
        let out = dir.join(format!("jobs-{jobs}.jsonl"));
        // Each round replaces the last round's results.
        let mut args = vec![
            "sweep".to_owned(),
            path(&trace),
            "--arch".into(),
            arch.clone(),
            "--jobs".into(),
            jobs.into(),
            "--out".into(),
            path(&out),
            "--force".into(),
        ];
        args.extend(axes.iter().map(|a| a.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        occsim(&args);
    };
    let run = &run;
    let mut jobs = ["1", "2"].map(|jobs| move || run(jobs));
    let times: Vec<f64> = fastest_of_rounds(ROUNDS, 0.0, &mut jobs)
        .iter()
        .map(|f| f.seconds)
        .collect();
    let one = std::fs::read(dir.join("jobs-1.jsonl")).expect("results");
    let two = std::fs::read(dir.join("jobs-2.jsonl")).expect("results");
    assert_eq!(one, two, "results depend on --jobs");
    let points = String::from_utf8_lossy(&one).lines().count();
    println!("sweep of {points} points over the demo trace on {arch}");
    println!("  1 job : {:7.2} s", times[0]);
    println!(
        "  2 jobs: {:7.2} s  (speed-up {:.2}x)",
        times[1],
        times[0] / times[1]
    );
    let _ = std::fs::remove_dir_all(&dir);
}
