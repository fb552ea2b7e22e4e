//! Sensitivity scaling: the study of the demo trace run with 1 and with 2 jobs in the same
//! run; prints each one's wall time against the sum of its replays' wall times (the study's
//! time is its replays': near linear in jobs) and checks the two outputs are identical.
//!
//! `cargo bench --bench sensitivity` (set OCCSIM_SENSITIVITY_ARCH to study another built-in
//! machine, default o2).

use std::path::Path;
use std::process::Command;
use std::time::Instant;

/// Runs occsim; its stdout and stderr.
fn occsim(args: &[&str]) -> (String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_occsim"))
        .args(args)
        .output()
        .expect("occsim runs");
    assert!(
        output.status.success(),
        "occsim {args:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    (
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

fn main() {
    let arch = std::env::var("OCCSIM_SENSITIVITY_ARCH").unwrap_or_else(|_| "o2".to_owned());
    let dir = std::env::temp_dir().join(format!("occsim-bench-sensitivity-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch directory");
    let trace = dir.join("demo.occt");
    let path = |p: &Path| p.to_str().expect("utf-8 path").to_owned();
    occsim(&["trace", "gen", "demo", "-o", &path(&trace)]);
    let mut outputs = Vec::new();
    println!("sensitivity study of the demo trace on {arch}");
    for jobs in ["1", "2"] {
        let start = Instant::now();
        let (stdout, stderr) = occsim(&[
            "sensitivity",
            &path(&trace),
            "--arch",
            &arch,
            "--jobs",
            jobs,
            "--json",
            "--timing",
        ]);
        let wall = start.elapsed().as_secs_f64();
        // "sensitivity: N replays, their wall times summed S s"
        let summed: f64 = stderr
            .split("summed ")
            .nth(1)
            .and_then(|rest| rest.split_whitespace().next())
            .and_then(|s| s.parse().ok())
            .expect("the --timing line");
        let replays = stderr
            .split("sensitivity: ")
            .nth(1)
            .and_then(|rest| rest.split_whitespace().next())
            .unwrap_or("?")
            .to_owned();
        println!(
            "  {jobs} job(s): {wall:7.2} s wall, {replays} replays summing {summed:7.2} s (wall / sum {:.2})",
            wall / summed
        );
        outputs.push(stdout);
    }
    assert_eq!(outputs[0], outputs[1], "the bands depend on --jobs");
    let _ = std::fs::remove_dir_all(&dir);
}
