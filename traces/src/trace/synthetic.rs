//! Synthetic fragment streams shaped like rasterizer output, for tests and benchmarks of the
//! trace format while no real scene is at hand: random triangles, each a `Primitive` and
//! then its fragments row by row from the bottom, left to right, with depth interpolated
//! linearly over the triangle and rounded to 24 bits, as a rasterizer would produce them.

use crate::event::{Event, Fragment, DEPTH_ONE};
use crate::golden::EventSink;
use crate::rng::SplitMix64;

/// What kind of triangles to draw.
#[derive(Clone, Copy, Debug)]
pub struct SyntheticScene {
    /// Viewport width in pixels.
    pub width: u32,
    /// Viewport height in pixels.
    pub height: u32,
    /// Smallest and largest triangle size: the radius of the vertices around the center, in
    /// pixels.
    pub min_radius: f64,
    pub max_radius: f64,
    /// Stop after the triangle that reaches this many fragments.
    pub fragments: u64,
    /// Seed of the deterministic pseudo-random generator.
    pub seed: u64,
}

/// Send the scene's events to `sink` (a `Clear` first); returns the fragments sent.
pub fn generate<S: EventSink>(scene: &SyntheticScene, sink: &mut S) -> Result<u64, S::Error> {
    let mut random = SplitMix64(scene.seed);
    let mut sent = 0;
    sink.event(&Event::Clear)?;
    while sent < scene.fragments {
        let center = (
            random.range_f64(0.0, scene.width as f64),
            random.range_f64(0.0, scene.height as f64),
        );
        let radius = random.range_f64(scene.min_radius, scene.max_radius);
        let start = random.range_f64(0.0, std::f64::consts::TAU);
        let vertices: [[f64; 3]; 3] = std::array::from_fn(|i| {
            let angle =
                start + i as f64 * std::f64::consts::TAU / 3.0 + random.range_f64(-0.5, 0.5);
            let r = radius * random.range_f64(0.6, 1.0);
            [
                center.0 + r * libm::cos(angle),
                center.1 + r * libm::sin(angle),
                random.range_f64(0.05, 0.95),
            ]
        });
        sent += rasterize(scene, &vertices, sink)?;
    }
    Ok(sent)
}

/// Counter-clockwise triangle (x, y, z) -> fragments at pixel centers inside, bottom row first.
fn rasterize<S: EventSink>(
    scene: &SyntheticScene,
    v: &[[f64; 3]; 3],
    sink: &mut S,
) -> Result<u64, S::Error> {
    let area =
        (v[1][0] - v[0][0]) * (v[2][1] - v[0][1]) - (v[2][0] - v[0][0]) * (v[1][1] - v[0][1]);
    if area.abs() < 1.0 {
        return Ok(0);
    }
    // Edge function of the edge from a to b at p, positive inside for either winding.
    let edge = |a: &[f64; 3], b: &[f64; 3], px: f64, py: f64| {
        ((b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0])) * area.signum()
    };
    let clamp_x = |t: f64| t.clamp(0.0, scene.width as f64 - 1.0) as u32;
    let clamp_y = |t: f64| t.clamp(0.0, scene.height as f64 - 1.0) as u32;
    let (x0, x1) = (
        clamp_x(v.iter().map(|p| p[0]).fold(f64::MAX, f64::min)),
        clamp_x(v.iter().map(|p| p[0]).fold(f64::MIN, f64::max)),
    );
    let (y0, y1) = (
        clamp_y(v.iter().map(|p| p[1]).fold(f64::MAX, f64::min)),
        clamp_y(v.iter().map(|p| p[1]).fold(f64::MIN, f64::max)),
    );
    sink.event(&Event::Primitive)?;
    let mut sent = 0;
    for y in y0..=y1 {
        let py = y as f64 + 0.5;
        for x in x0..=x1 {
            let px = x as f64 + 0.5;
            let w0 = edge(&v[1], &v[2], px, py);
            let w1 = edge(&v[2], &v[0], px, py);
            let w2 = edge(&v[0], &v[1], px, py);
            if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                continue;
            }
            let z = (w0 * v[0][2] + w1 * v[1][2] + w2 * v[2][2]) / area.abs();
            let z = (z * DEPTH_ONE as f64).round().clamp(0.0, DEPTH_ONE as f64) as u32;
            sink.event(&Event::Fragment(Fragment {
                x: x as u16,
                y: y as u16,
                z,
            }))?;
            sent += 1;
        }
    }
    Ok(sent)
}
