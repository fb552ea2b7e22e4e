//! Encode and decode rates of the `.occt` trace format on synthetic rasterizer-shaped streams
//! (spans of linearly varying depth, rounded to 24 bits), and size and decode rate on the
//! built-in `demo` (1280x1024) and `random` scenes as the real rasterizer makes them. Prints
//! fragments/s and bytes per fragment; no assertions (timings are not tests).
//!
//! Run: `cargo bench -p occsim-traces --bench trace_codec`

use occsim_traces::builtin::scene_text;
use occsim_traces::golden::{infallible, EventSink, GoldenModel};
use occsim_traces::rounds::{fastest_of, fastest_of_rounds};
use occsim_traces::scene::{parse_scene, Command};
use occsim_traces::trace::synthetic::{generate, SyntheticScene};
use occsim_traces::trace::{TraceHeader, TraceReader, TraceWriter, WriterOptions};
use occsim_traces::Event;

/// Fragments per synthetic scene.
const FRAGMENTS: u64 = 12_000_000;
const LEVELS: [i32; 3] = [1, 3, 9];

/// Sums what it sees so the decoder's work cannot be optimised away.
#[derive(Default)]
struct Checksum {
    fragments: u64,
    depth_sum: u64,
}

impl EventSink for Checksum {
    type Error = std::convert::Infallible;
    #[inline(always)]
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        if let Event::Fragment(f) = event {
            self.fragments += 1;
            self.depth_sum = self.depth_sum.wrapping_add(f.z as u64 ^ f.x as u64);
        }
        Ok(())
    }
}

/// Rounds of every measurement (`occsim_traces::rounds`: interleaved where two are compared).
const ROUNDS: usize = 3;

/// The fastest of [`ROUNDS`] runs: (seconds, the last run's output).
fn best_of<T>(run: impl FnMut() -> T) -> (f64, T) {
    let figure = fastest_of(ROUNDS, 0.0, run);
    (figure.seconds, figure.output)
}

fn bench_scene(name: &str, scene: &SyntheticScene) {
    let mut events = Vec::new();
    let fragments = infallible(generate(scene, &mut events));
    let header = TraceHeader::new(scene.width, scene.height).with_scene(name);
    println!("{name}: {fragments} fragments, {} events", events.len());
    for level in LEVELS {
        let options = WriterOptions {
            zstd_level: level,
            ..WriterOptions::default()
        };
        let (encode_s, bytes) = best_of(|| {
            let mut bytes = Vec::new();
            let mut writer =
                TraceWriter::with_options(&mut bytes, &header, options).expect("header");
            for e in &events {
                writer.event(e).expect("encode");
            }
            writer.finish().expect("encode");
            bytes
        });
        // Bulk decoding and event-by-event iteration take turns.
        let mut bulk = || {
            let mut sum = Checksum::default();
            let mut reader = TraceReader::new(&bytes[..]).expect("header");
            reader.read_into(&mut sum).expect("decode");
            sum.fragments
        };
        let mut single = || {
            let reader = TraceReader::new(&bytes[..]).expect("header");
            reader
                .map(|e| e.expect("decode"))
                .filter(|e| matches!(e, Event::Fragment(_)))
                .count() as u64
        };
        let jobs: &mut [&mut dyn FnMut() -> u64] = &mut [&mut bulk, &mut single];
        let figures = fastest_of_rounds(ROUNDS, 0.0, jobs);
        assert_eq!(figures[0].output, fragments);
        assert_eq!(figures[1].output, fragments);
        let (bulk_s, single_s) = (figures[0].seconds, figures[1].seconds);
        let rate = |s: f64| fragments as f64 / s / 1e6;
        println!(
            "  zstd {level}: {:.3} bytes/fragment ({} bytes) | encode {:6.1} M frag/s | decode bulk {:6.1} M frag/s, next_event {:6.1} M frag/s",
            bytes.len() as f64 / fragments as f64,
            bytes.len(),
            rate(encode_s),
            rate(bulk_s),
            rate(single_s),
        );
    }
}

/// Size and bulk decode rate of a built-in scene's trace, written at the default level.
fn bench_builtin(name: &str) {
    let text = scene_text(name).expect("a built-in scene");
    let lines = parse_scene(&text, name).expect("it parses");
    let Command::Viewport { width, height } = lines[0].command else {
        panic!("{name}: no viewport first");
    };
    let mut bytes = Vec::new();
    let header = TraceHeader::new(width, height).with_scene(name);
    let mut writer = TraceWriter::new(&mut bytes, &header).expect("header");
    let mut golden = GoldenModel::new(width, height);
    for line in &lines {
        golden.execute(&line.command, &mut writer).unwrap();
    }
    golden.finish(&mut writer).unwrap();
    let summary = writer.finish().expect("encode");
    let (bulk_s, sum) = best_of(|| {
        let mut sum = Checksum::default();
        let mut reader = TraceReader::new(&bytes[..]).expect("header");
        reader.read_into(&mut sum).expect("decode");
        sum
    });
    assert_eq!(sum.fragments, summary.fragments);
    println!(
        "built-in {name} ({width}x{height}): {} fragments, {:.3} bytes/fragment ({} bytes) | decode bulk {:6.1} M frag/s",
        summary.fragments,
        bytes.len() as f64 / summary.fragments as f64,
        bytes.len(),
        summary.fragments as f64 / bulk_s / 1e6
    );
}

fn main() {
    bench_builtin("demo");
    bench_builtin("random");
    let large = SyntheticScene {
        width: 1920,
        height: 1080,
        min_radius: 60.0,
        max_radius: 300.0,
        fragments: FRAGMENTS,
        seed: 7,
    };
    let small = SyntheticScene {
        min_radius: 3.0,
        max_radius: 12.0,
        seed: 11,
        ..large
    };
    bench_scene("large triangles (radius 60-300 px)", &large);
    bench_scene("small triangles (radius 3-12 px)", &small);
}
