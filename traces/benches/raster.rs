//! Rasterizer throughput of every profile: fragments per second into a sink that does nothing
//! but count, on large triangles (the span walk) and on small ones (setup cost), each
//! profile's rate also as a ratio to the `exact` profile's in the same run. Each triangle set
//! is one draw a repeat. Run with `cargo bench -p occsim-traces --bench raster`.

use occsim_traces::raster::{RasterProfile, RasterSink, Rasterizer};
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::state::RenderState;
use occsim_traces::Fragment;
use std::hint::black_box;

/// Counts fragments and folds their depths so the work cannot be optimised away.
struct Count {
    fragments: u64,
    checksum: u32,
}

impl RasterSink for Count {
    #[inline(always)]
    fn primitive(&mut self) {}

    #[inline(always)]
    fn fragment(&mut self, fragment: Fragment) {
        self.fragments += 1;
        self.checksum = self.checksum.wrapping_add(fragment.z);
    }
}

/// Fragments per second of `profile` on `triangles`, and the fragments.
/// One run: `repeats` passes over `triangles`; the fragments a pass gives.
fn pass(
    profile: RasterProfile,
    state: &RenderState,
    triangles: &[[[f32; 4]; 3]],
    repeats: u32,
) -> u64 {
    let mut sink = Count {
        fragments: 0,
        checksum: 0,
    };
    let mut rasterizer = Rasterizer::new(profile);
    for _ in 0..repeats {
        for triangle in triangles {
            rasterizer.triangle(state, black_box(triangle), &mut sink);
        }
        rasterizer.end_draw(state, &mut sink);
    }
    black_box(sink.checksum);
    sink.fragments / repeats as u64
}

/// The fastest of three interleaved rounds of each profile (`occsim_traces::rounds`), so a
/// slow spell of the machine falls on all alike: (fragments/s, triangles/s, fragments a
/// pass).
fn measure(name: &str, state: &RenderState, triangles: &[[[f32; 4]; 3]], repeats: u32) {
    println!("{name}:");
    let mut jobs =
        RasterProfile::ALL.map(|profile| move || pass(profile, state, triangles, repeats));
    let figures = fastest_of_rounds(3, 0.0, &mut jobs);
    let triangles_done = triangles.len() as f64 * repeats as f64;
    let best: Vec<(f64, f64, u64)> = figures
        .iter()
        .map(|f| {
            (
                f.output as f64 * repeats as f64 / f.seconds,
                triangles_done / f.seconds,
                f.output,
            )
        })
        .collect();
    let exact = best[2].0;
    for (profile, (fragments, primitives, per_repeat)) in RasterProfile::ALL.into_iter().zip(best) {
        println!(
            "  {:<16} {:>8.1} M fragments/s {:>8.3} M triangles/s {:>6.2}x exact ({per_repeat} fragments a repeat)",
            profile.name(),
            fragments / 1e6,
            primitives / 1e6,
            fragments / exact
        );
    }
}

fn main() {
    let state = RenderState::new(1024, 1024);
    // Two sloped-depth triangles covering the viewport, with a perspective w.
    let large = [
        [
            [-1.0f32, -1.0, -0.9, 1.0],
            [1.0, -1.0, 0.3, 1.0],
            [1.0, 1.0, 0.8, 1.0],
        ],
        [
            [-1.0f32, -1.0, -0.9, 1.0],
            [1.0, 1.0, 0.8, 1.0],
            [-1.0, 1.0, 0.1, 1.0],
        ],
        [
            [-2.0f32, -2.0, 0.5, 2.0],
            [1.9, -1.7, 0.9, 2.0],
            [0.1, 1.95, -0.5, 2.0],
        ],
    ];
    measure("large triangles (1024x1024 viewport)", &state, &large, 200);
    // A huge triangle needing guard-band clipping.
    let huge = [[
        [-1e6f32, -1e6, 0.2, 1.0],
        [3e6, -1e6, 0.2, 1.0],
        [-1e6, 3e6, 0.7, 1.0],
    ]];
    measure("huge triangle, clipped", &state, &huge, 200);
    // Small triangles: about 8 pixels each, setup-dominated.
    let mut small = Vec::new();
    for i in 0..1000 {
        let x = -1.0 + (i % 250) as f32 * 0.008;
        let y = -1.0 + (i / 250) as f32 * 0.4;
        small.push([
            [x, y, 0.1, 1.0],
            [x + 0.008, y, 0.2, 1.0],
            [x, y + 0.008, 0.3, 1.0],
        ]);
    }
    measure("small triangles (~8 pixels)", &state, &small, 2000);
}
