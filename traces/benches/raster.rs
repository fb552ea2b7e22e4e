//! Rasterizer throughput: fragments per second into a sink that does nothing but count,
//! on large triangles (the span walk) and on small ones (setup cost). Run with
//! `cargo bench -p occsim-traces --bench raster`.

use occsim_traces::raster::{rasterize_triangle, RasterSink};
use occsim_traces::state::RenderState;
use occsim_traces::Fragment;
use std::hint::black_box;
use std::time::Instant;

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

fn measure(name: &str, state: &RenderState, triangles: &[[[f32; 4]; 3]], repeats: u32) {
    let mut sink = Count {
        fragments: 0,
        checksum: 0,
    };
    let start = Instant::now();
    for _ in 0..repeats {
        for triangle in triangles {
            rasterize_triangle(state, black_box(triangle), &mut sink);
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    black_box(sink.checksum);
    let triangles_done = triangles.len() as f64 * repeats as f64;
    println!(
        "{name}: {:.1} M fragments/s, {:.2} M triangles/s ({} fragments in {seconds:.3} s)",
        sink.fragments as f64 / seconds / 1e6,
        triangles_done / seconds / 1e6,
        sink.fragments
    );
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
    measure("huge guard-band-clipped triangle", &state, &huge, 200);
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
