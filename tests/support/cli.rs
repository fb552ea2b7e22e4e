//! Running the `occsim` binary from end-to-end tests.

use std::path::Path;
use std::process::{Command, Output};

/// Run `occsim` with `args`.
pub fn occsim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_occsim"))
        .args(args)
        .output()
        .expect("occsim runs")
}

/// Run `occsim`, require success, return its standard output.
pub fn stdout_of(args: &[&str]) -> String {
    let output = occsim(args);
    assert!(
        output.status.success(),
        "occsim {args:?} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).expect("utf-8 output")
}

/// Run `occsim` with its temporary directory (`TMPDIR`) set to `temp`, require success,
/// return its standard output: for checking what a command leaves in the temporary
/// directory.
pub fn stdout_with_temp_dir(args: &[&str], temp: &Path) -> Vec<u8> {
    let output = Command::new(env!("CARGO_BIN_EXE_occsim"))
        .args(args)
        .env("TMPDIR", temp)
        .output()
        .expect("occsim runs");
    assert!(
        output.status.success(),
        "occsim {args:?} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    output.stdout
}

/// Run `occsim`, require failure, return its standard error.
pub fn stderr_of_failure(args: &[&str]) -> String {
    let output = occsim(args);
    assert!(!output.status.success(), "occsim {args:?} should fail");
    String::from_utf8(output.stderr).expect("utf-8 output")
}

/// A fresh, empty scratch directory for one test, removed when dropped, whether the test
/// passes or panics (a `tempfile::TempDir`; tests run in parallel, processes too).
pub struct Scratch(tempfile::TempDir);

impl std::ops::Deref for Scratch {
    type Target = Path;
    fn deref(&self) -> &Path {
        self.0.path()
    }
}

impl AsRef<Path> for Scratch {
    fn as_ref(&self) -> &Path {
        self.0.path()
    }
}

pub fn scratch_dir(name: &str) -> Scratch {
    Scratch(
        tempfile::Builder::new()
            .prefix(&format!("occsim-test-{name}-"))
            .tempdir()
            .expect("scratch directory"),
    )
}

/// A hardcases trace in a fresh scratch directory: (directory, trace path).
pub fn hardcases_trace(name: &str) -> (Scratch, String) {
    let dir = scratch_dir(name);
    let trace = dir.join("hardcases.occt");
    let trace = trace.to_str().expect("utf-8 path").to_string();
    stdout_of(&["trace", "gen", "hardcases", "-o", &trace]);
    (dir, trace)
}

/// Wait until `ready` says the child is where a test wants to interrupt it (at most
/// `seconds`, failing with `what` past them), then send it signal `name` (`INT`, `HUP`...)
/// and wait for it to end.
pub fn signal_when(
    child: &mut std::process::Child,
    ready: impl Fn() -> bool,
    (seconds, what): (u64, &str),
    name: &str,
) -> std::process::ExitStatus {
    let started = std::time::Instant::now();
    while !ready() {
        assert!(started.elapsed().as_secs() < seconds, "{what}");
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    let sent = std::process::Command::new("kill")
        .args([&format!("-{name}"), &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(sent.success(), "kill -{name}");
    child.wait().expect("the child ends")
}
