//! Workload trace generation rate: fragments per second for each culling driver walking the
//! default city, then the frustum and dynamic-grid drivers walking the default traffic scene
//! (its cars moving), beside the plain golden model (what `occsim count` does) replaying the
//! very same frames' commands. The difference is the drivers' own cost: traversal, box
//! projection, grid bookkeeping, making commands. Run with
//! `cargo bench -p occsim-traces --bench workloads` (OCCSIM_BENCH_FRAMES, OCCSIM_BENCH_WIDTH
//! and OCCSIM_BENCH_HEIGHT change the walk; defaults 8 frames at 1280x1024). Each driver's
//! generation and its golden-only replay alternate for OCCSIM_BENCH_ROUNDS rounds (3); the
//! fastest of each is kept, and the ratio of the two rates is the figure to compare.

use occsim_traces::golden::{Discard, EventSink, GoldenModel};
use occsim_traces::raster::RasterProfile;
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::workloads::{
    city, generate, generate_observed, traffic, CityOptions, DriverKind, DriverOptions,
    TrafficOptions, Walk, WorkloadScene,
};
use occsim_traces::{Command, Event};
use std::hint::black_box;
use std::time::Instant;

/// Counts fragments so the event stream cannot be optimised away.
struct CountFragments(u64);

impl EventSink for CountFragments {
    type Error = std::convert::Infallible;
    #[inline(always)]
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        if let Event::Fragment(_) = event {
            self.0 += 1;
        }
        Ok(())
    }
}

fn setting(name: &str, default: u32) -> u32 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let walk = Walk {
        frames: setting("OCCSIM_BENCH_FRAMES", 8),
        width: setting("OCCSIM_BENCH_WIDTH", 1280),
        height: setting("OCCSIM_BENCH_HEIGHT", 1024),
        raster: RasterProfile::default(),
    };
    let rounds = setting("OCCSIM_BENCH_ROUNDS", 3).max(1) as usize;
    let mut drivers: Vec<DriverOptions> = DriverKind::ALL
        .into_iter()
        .map(DriverOptions::new)
        .collect();
    let mut quadtree = DriverOptions::new(DriverKind::Hierarchical);
    quadtree.quadtree_levels = 2;
    drivers.insert(2, quadtree);
    let started = Instant::now();
    let scene = city(&CityOptions::default());
    bench_scene(&scene, started, &walk, &drivers, rounds);
    let started = Instant::now();
    let scene = traffic(&TrafficOptions::default());
    let mut flat = DriverOptions::new(DriverKind::DynamicGrid);
    flat.flat_grid = true;
    let moving = [
        DriverOptions::new(DriverKind::Frustum),
        DriverOptions::new(DriverKind::DynamicGrid),
        flat,
    ];
    bench_scene(&scene, started, &walk, &moving, rounds);
}

/// Each driver's generation rate on `scene` beside the golden model alone on its frames.
fn bench_scene(
    scene: &WorkloadScene,
    started: Instant,
    walk: &Walk,
    drivers: &[DriverOptions],
    rounds: usize,
) {
    println!(
        "{}: {} objects, {} triangles, built in {:.3} s; {} frames at {}x{}",
        scene.name,
        scene.object_count(),
        scene.triangle_count(),
        started.elapsed().as_secs_f64(),
        walk.frames,
        walk.width,
        walk.height
    );
    println!(
        "{:<18} {:>12} {:>14} {:>16} {:>12} {:>12}",
        "driver", "fragments", "generate M/s", "golden only M/s", "gen/golden", "driver share"
    );
    for driver in drivers {
        // The same frames' commands, for the golden model alone.
        let mut commands: Vec<Command> = Vec::new();
        generate_observed(scene, driver, walk, &mut Discard, &mut commands).expect("valid options");
        // Generation (the driver and the golden model, events into a counting sink) and the
        // golden model alone take turns in rounds; each keeps its fastest run.
        let mut generation = || {
            let mut sink = CountFragments(0);
            generate(scene, driver, walk, &mut sink).expect("valid options");
            sink.0
        };
        let mut golden_only = || {
            let mut golden = GoldenModel::new(walk.width, walk.height);
            let mut replay = CountFragments(0);
            for command in &commands {
                black_box(golden.execute(command, &mut replay).unwrap());
            }
            golden.finish(&mut replay).unwrap();
            replay.0
        };
        let jobs: &mut [&mut dyn FnMut() -> u64] = &mut [&mut generation, &mut golden_only];
        let figures = fastest_of_rounds(rounds, 0.0, jobs);
        let (sink, replay) = (
            CountFragments(figures[0].output),
            CountFragments(figures[1].output),
        );
        let (generate_seconds, replay_seconds) = (figures[0].seconds, figures[1].seconds);
        assert_eq!(replay.0, sink.0, "the replay must see the same fragments");
        let fragments = sink.0;
        println!(
            "{:<18} {:>12} {:>14.1} {:>16.1} {:>11.2}x {:>11.1}%",
            driver.label(),
            fragments,
            fragments as f64 / generate_seconds / 1e6,
            fragments as f64 / replay_seconds / 1e6,
            replay_seconds / generate_seconds,
            100.0 * (1.0 - replay_seconds / generate_seconds).max(0.0)
        );
    }
}
