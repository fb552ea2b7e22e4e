//! Counting rate against Mesa llvmpipe, measured in the same run on the same scene.
//!
//! `cargo bench --bench count_vs_llvmpipe` renders the built-in `random` scene (20,000
//! triangles, about 28 M fragments, 2,000 samples queries at 1280x1024) three ways:
//! - the golden model in process (the work `occsim count` does, without parsing), default
//!   profile (`llvmpipe`),
//! - the `occsim count` command end to end (parsing the scene file and printing included),
//! - llvmpipe on one thread (LP_NUM_THREADS=1), depth only, reading every query's result,
//!
//! and prints each one's fragment rate and the ratios: the fastest of three interleaved rounds
//! each (`occsim_traces::rounds`), so a slow spell of the machine falls on all three alike.

#[path = "../tests/support/mod.rs"]
mod support;

use occsim_traces::builtin::{random_scene, RandomOptions};
use occsim_traces::golden::{infallible, Discard, EventSink, GoldenModel};
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::scene::{parse_scene, SceneLine};
use occsim_traces::{Event, QueryMode};
use std::time::Duration;

const ROUNDS: usize = 3;

struct FragmentCounter(u64);

impl EventSink for FragmentCounter {
    type Error = std::convert::Infallible;
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        self.0 += matches!(event, Event::Fragment(_)) as u64;
        Ok(())
    }
}

/// The golden model over the scene: every samples count, in order.
fn golden_counts(
    lines: &[SceneLine],
    width: u32,
    height: u32,
    sink: &mut impl EventSink<Error = std::convert::Infallible>,
) -> Vec<u64> {
    let mut golden = GoldenModel::new(width, height);
    let counts = lines
        .iter()
        .filter_map(|line| infallible(golden.execute(&line.command, sink)))
        .filter(|r| r.mode == QueryMode::Samples)
        .map(|r| r.value())
        .collect();
    infallible(golden.finish(sink));
    counts
}

fn rate(fragments: u64, time: Duration) -> f64 {
    fragments as f64 / time.as_secs_f64() / 1e6
}

fn main() {
    // llvmpipe reads its thread count when the context is made: one thread, like ours.
    std::env::set_var("LP_NUM_THREADS", "1");
    let options = RandomOptions::default();
    let text = random_scene(&options);
    let lines = parse_scene(&text, "random").expect("the built-in scene parses");
    let (width, height) = (options.width, options.height);

    let mut counter = FragmentCounter(0);
    let expected = golden_counts(&lines, width, height, &mut counter);
    let fragments = counter.0;
    println!(
        "scene: random, {} triangles, {} queries, {}x{}, {fragments} fragments",
        options.triangles, options.queries, width, height
    );

    let scene_file =
        std::env::temp_dir().join(format!("occsim-bench-{}.scene", std::process::id()));
    std::fs::write(&scene_file, &text).expect("temporary scene file");
    let mut golden = || {
        std::hint::black_box(golden_counts(&lines, width, height, &mut Discard));
        Vec::new()
    };
    let mut command = || {
        let output = std::process::Command::new(env!("CARGO_BIN_EXE_occsim"))
            .arg("count")
            .arg(&scene_file)
            .output()
            .expect("occsim count runs");
        assert!(output.status.success(), "occsim count failed");
        assert_eq!(
            String::from_utf8_lossy(&output.stdout).lines().count(),
            expected.len()
        );
        Vec::new()
    };
    let gl = support::gl_replay::GlReplay::new(width, height);
    let renderer = gl
        .as_ref()
        .map(|gl| gl.renderer().to_string())
        .map_err(String::clone);
    let figures = match gl {
        Ok(mut gl) => {
            let mut llvmpipe =
                || -> Vec<u64> { gl.run(&lines).into_iter().map(|q| q.counts[0]).collect() };
            let jobs: &mut [&mut dyn FnMut() -> Vec<u64>] =
                &mut [&mut golden, &mut command, &mut llvmpipe];
            fastest_of_rounds(ROUNDS, 0.0, jobs)
        }
        Err(_) => {
            let jobs: &mut [&mut dyn FnMut() -> Vec<u64>] = &mut [&mut golden, &mut command];
            fastest_of_rounds(ROUNDS, 0.0, jobs)
        }
    };
    let _ = std::fs::remove_file(&scene_file);
    let time = |i: usize| Duration::from_secs_f64(figures[i].seconds);

    println!(
        "{:<34} {:>10} {:>14} {:>12}",
        "counter", "seconds", "M fragments/s", "vs llvmpipe"
    );
    let rows = [
        ("occsim golden model (in process)", time(0)),
        ("occsim count (end to end)", time(1)),
    ];
    match renderer {
        Ok(renderer) => {
            // The default profile is llvmpipe's arithmetic: every count equal, or the
            // comparison means nothing.
            assert_eq!(
                figures[2].output, expected,
                "llvmpipe and occsim count differently"
            );
            println!(
                "llvmpipe agrees exactly on all {} queries ({fragments} fragments)",
                expected.len()
            );
            let gl_time = time(2);
            let name = format!("llvmpipe, 1 thread ({renderer})");
            for (name, time) in rows.iter().copied().chain([(name.as_str(), gl_time)]) {
                println!(
                    "{name:<34} {:>10.3} {:>14.1} {:>11.2}x",
                    time.as_secs_f64(),
                    rate(fragments, time),
                    gl_time.as_secs_f64() / time.as_secs_f64()
                );
            }
        }
        Err(reason) => {
            for (name, time) in &rows {
                println!(
                    "{name:<34} {:>10.3} {:>14.1} {:>12}",
                    time.as_secs_f64(),
                    rate(fragments, *time),
                    "-"
                );
            }
            println!("llvmpipe: SKIPPED ({reason})");
        }
    }
}
