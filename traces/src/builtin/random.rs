//! The `random` scene: many random triangles at random depths under samples queries, the
//! shape of workload the peers' figures were measured on (tens of thousands of triangles,
//! tens of millions of fragments, thousands of queries at 1280x1024).

use crate::geometry::SplitMix64;
use crate::query::{QueryMode, QuerySpec, BRIEF_RECORD_ENTRIES};
use crate::scene::{format_command, Command};
use crate::state::Rect;

/// How the random scene is made.
#[derive(Clone, Debug)]
pub struct RandomOptions {
    /// Viewport width in pixels.
    pub width: u32,
    /// Viewport height in pixels.
    pub height: u32,
    /// Triangles in all.
    pub triangles: u32,
    /// Samples queries, each over an equal share of the triangles.
    pub queries: u32,
    /// Mean triangle area in pixels before clamping at the viewport's edges (approximate:
    /// radii vary from a fifth to twice the mean).
    pub mean_area_pixels: f32,
    pub seed: u64,
}

impl Default for RandomOptions {
    fn default() -> RandomOptions {
        RandomOptions {
            width: 1280,
            height: 1024,
            triangles: 20_000,
            queries: 2_000,
            mean_area_pixels: 1900.0,
            seed: 1,
        }
    }
}

/// The random scene's text. Triangles face front (counter-clockwise) and lie inside the
/// view volume, so every renderer agrees on them without clipping.
pub fn random_scene(options: &RandomOptions) -> String {
    let mut rng = SplitMix64(options.seed);
    let (width, height) = (options.width as f32, options.height as f32);
    let mut text = format!(
        "# occsim random: {} triangles, {} samples queries\n",
        options.triangles, options.queries
    );
    let mut line = |c: Command| {
        text += &format_command(&c);
        text.push('\n');
    };
    line(Command::Viewport {
        width: options.width,
        height: options.height,
    });
    let queries = options.queries.max(1);
    let per_query = options.triangles.div_ceil(queries).max(1);
    // A triangle inscribed in a circle of radius r with these angles covers about 1.3 r^2,
    // and E[U(0.2, 2)^2] = 1.48: so this radius scale gives the mean area asked for.
    let radius_scale = (options.mean_area_pixels / (1.3 * 1.48)).sqrt();
    for query in 0..queries {
        line(Command::Begin(QuerySpec {
            id: query + 1,
            mode: QueryMode::Samples,
            buffer_entries: BRIEF_RECORD_ENTRIES,
            tiles: vec![Rect::new(0, 0, options.width, options.height)],
        }));
        let first = query * per_query;
        for _ in first..(first + per_query).min(options.triangles) {
            let size = radius_scale * rng.range(0.2, 2.0);
            let (cx, cy) = (rng.range(0.0, width), rng.range(0.0, height));
            let mut vertices = [[0f32; 4]; 3];
            for (k, vertex) in vertices.iter_mut().enumerate() {
                // Three points around the centre, counter-clockwise.
                let angle = rng.range(0.0, 1.8) + k as f32 * 2.0944;
                let x = (cx + size * libm::cosf(angle)).clamp(0.0, width);
                let y = (cy + size * libm::sinf(angle)).clamp(0.0, height);
                let z = rng.range(-0.99, 0.99);
                *vertex = [x / width * 2.0 - 1.0, y / height * 2.0 - 1.0, z, 1.0];
            }
            line(Command::Tri(vertices));
        }
        line(Command::End);
    }
    text
}
