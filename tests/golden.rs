//! Golden files: what `count` and `replay` print as JSON (the O2-like machine and ir4, at the
//! cycle and analytic levels) on the built-in `hardcases` scene, and a short VCD of its rtl
//! replay, kept in `tests/golden/` and compared exactly. A change to a model shows as a diff of these files in review.
//!
//! Regenerate on purpose, and say why in the commit:
//! `OCCSIM_BLESS=1 cargo test --release --test golden`.

mod support;

use std::path::{Path, PathBuf};
use support::cli::{scratch_dir, stdout_of};

fn golden_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden")
}

/// Compare `actual` with the golden file `name`, or write it under `OCCSIM_BLESS`.
fn check(name: &str, actual: &str) {
    let path = golden_dir().join(name);
    if std::env::var_os("OCCSIM_BLESS").is_some() {
        std::fs::create_dir_all(golden_dir()).expect("tests/golden");
        std::fs::write(&path, actual).expect("a golden file");
        return;
    }
    let expected = std::fs::read_to_string(&path).unwrap_or_else(|_| {
        panic!(
            "{} is missing: run OCCSIM_BLESS=1 cargo test --release --test golden",
            path.display()
        )
    });
    if expected != actual {
        let line = expected
            .lines()
            .zip(actual.lines())
            .position(|(e, a)| e != a)
            .unwrap_or(expected.lines().count().min(actual.lines().count()));
        panic!(
            "{name} differs from tests/golden/{name} at line {}:\n  golden: {}\n  now:    {}\n\
             (OCCSIM_BLESS=1 regenerates it if the change is meant)",
            line + 1,
            expected.lines().nth(line).unwrap_or("<end>"),
            actual.lines().nth(line).unwrap_or("<end>")
        );
    }
}

#[test]
fn counts_match_their_golden_files() {
    check(
        "count-hardcases.json",
        &stdout_of(&["count", "hardcases", "--json"]),
    );
}

#[test]
fn replay_reports_match_their_golden_files() {
    let dir = scratch_dir("golden-replay");
    let trace = dir.join("hardcases.occt");
    let trace = trace.to_str().expect("a UTF-8 path");
    stdout_of(&["trace", "gen", "hardcases", "-o", trace]);
    for arch in ["o2", "ir4"] {
        for level in ["cycle", "analytic"] {
            let report = stdout_of(&[
                "replay",
                trace,
                "--arch",
                arch,
                "--fidelity",
                level,
                "--json",
            ]);
            check(&format!("replay-hardcases-{arch}-{level}.json"), &report);
        }
    }
}

#[test]
fn a_short_waveform_matches_its_golden_file() {
    let dir = scratch_dir("golden-vcd");
    let trace = dir.join("hardcases.occt");
    let vcd = dir.join("window.vcd");
    let (trace, vcd_path) = (
        trace.to_str().expect("a UTF-8 path"),
        vcd.to_str().expect("a UTF-8 path"),
    );
    stdout_of(&["trace", "gen", "hardcases", "-o", trace]);
    stdout_of(&[
        "replay",
        trace,
        "--arch",
        "o2",
        "--engines",
        "2",
        "--fidelity",
        "rtl",
        "--vcd",
        vcd_path,
        // The host delivers the first triangle at about cycle 1,007 (driver 2,000 and
        // geometry 6 x 80 + 2 x 120 host cycles at 180 MHz, on a 66.67 MHz pipeline).
        "--window",
        "1000..1400",
    ]);
    let text = std::fs::read_to_string(&vcd).expect("the VCD was written");
    check("o2-rtl-hardcases-1000-1400.vcd", &text);
}
