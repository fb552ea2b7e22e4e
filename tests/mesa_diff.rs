//! Differential check: every query's count from the golden model (our exact rasterizer and
//! depth semantics) must equal Mesa llvmpipe's, on structured and seeded random scenes.
//!
//! Without libEGL the check prints `mesa_diff: SKIPPED: ...` and passes, except when
//! `CI=true`, where a missing Mesa fails it (CI installs Mesa). `OCCSIM_LIBEGL=/nonexistent`
//! shows the skip path.
//!
//! What is kept out of the exact-equality scenes, and why:
//! - Geometry that Mesa clips (a vertex outside -w <= x, y, z <= w): llvmpipe's draw module
//!   clips x/y against the viewport planes (no guard band) and z against near/far with its
//!   own interpolation; the new vertices' float rounding differs from ours (we clip x/y only
//!   beyond a large guard band). Such geometry is tested for our own invariants in
//!   traces/tests/raster_hardcases.rs.
//! - Depth comparisons between different primitives whose vertices snapping moved:
//!   llvmpipe builds its depth plane from the *unsnapped* f32 window positions and
//!   evaluates it in f32; ours is the exact plane through the *snapped* vertices. Near a
//!   crossing of two surfaces the two can order a pixel differently (a seen case: 423 units
//!   of 2^-24 on a steep triangle). So depth-sensitive random scenes put vertices on the
//!   1/256 snapping grid (then only llvmpipe's f32 rounding differs, a few units), and the
//!   scenes with snapping ties (1/512 grid) or arbitrary floats measure coverage only
//!   (depth function `always`).
//! - The window transform: llvmpipe computes `fma(x·(1/w), s, t)` (LLVM fuses
//!   `llvm.fmuladd` on hosts with FMA); we do the same. The float scenes check it.

mod support;

use occsim_traces::golden::{Discard, GoldenModel};
use occsim_traces::scene::{format_command, parse_scene};
use occsim_traces::{Command, QueryMode, SceneLine};
use support::gl_replay::{GlQueryCounts, GlReplay};

/// A live llvmpipe, or None after printing why the check is skipped (failing under CI).
fn mesa_or_skip(width: u32, height: u32) -> Option<GlReplay> {
    match GlReplay::new(width, height) {
        Ok(gl) => Some(gl),
        Err(why) => {
            if std::env::var("CI").is_ok_and(|v| v == "true") {
                panic!("mesa_diff: Mesa is required under CI=true but unavailable: {why}");
            }
            println!("mesa_diff: SKIPPED: {why}");
            None
        }
    }
}

/// The golden model's counts, in the same shape as [`GlQueryCounts`].
fn golden_counts(lines: &[SceneLine]) -> Vec<GlQueryCounts> {
    let (width, height) = match lines.first().map(|l| &l.command) {
        Some(Command::Viewport { width, height }) => (*width, *height),
        _ => panic!("scene must start with viewport"),
    };
    let mut model = GoldenModel::new(width, height);
    let mut counts = Vec::new();
    for line in lines {
        if let Some(result) = model.execute(&line.command, &mut Discard) {
            let per_query = match result.mode {
                QueryMode::Samples | QueryMode::Any => vec![result.value()],
                QueryMode::Brief | QueryMode::Verbose => {
                    result.tiles.iter().map(|t| t.nohc).collect()
                }
            };
            counts.push(GlQueryCounts {
                id: result.id,
                mode: result.mode,
                counts: per_query,
            });
        }
    }
    counts
}

fn scene_text(lines: &[SceneLine]) -> String {
    lines
        .iter()
        .map(|l| format_command(&l.command) + "\n")
        .collect()
}

/// Require equal counts query by query; on failure show the first difference and the scene.
fn assert_same_counts(name: &str, lines: &[SceneLine], gl: &mut GlReplay) {
    let ours = golden_counts(lines);
    let mesa = gl.run(lines);
    assert_eq!(ours.len(), mesa.len(), "{name}: query count differs");
    for (index, (o, m)) in ours.iter().zip(&mesa).enumerate() {
        assert!(
            o == m,
            "{name}: query #{index} (id {}) differs: golden {:?}, Mesa {:?}\nscene to reproduce:\n{}",
            o.id,
            o.counts,
            m.counts,
            scene_text(lines)
        );
    }
}

/// Window coordinate to clip coordinate along a viewport side (exact for sides that are
/// powers of two and window coordinates on a 1/512 grid).
fn clip(window: f64, side: u32) -> f64 {
    let half = side as f64 / 2.0;
    (window - half) / half
}

/// Two counter-clockwise triangles covering the window rectangle [x0, x1] x [y0, y1].
fn rect(x0: f64, x1: f64, y0: f64, y1: f64, z: f64, side: (u32, u32)) -> String {
    let (a, b) = (clip(x0, side.0), clip(x1, side.0));
    let (c, d) = (clip(y0, side.1), clip(y1, side.1));
    format!("tri {a} {c} {z} 1 {b} {c} {z} 1 {b} {d} {z} 1\ntri {a} {c} {z} 1 {b} {d} {z} 1 {a} {d} {z} 1\n")
}

fn scene(text: &str) -> Vec<SceneLine> {
    parse_scene(text, "mesa_diff").unwrap_or_else(|e| panic!("bad test scene: {e}\n{text}"))
}

/// The fill and snapping rules, measured on llvmpipe with hand-derived expectations, and
/// the golden model required to agree: a one-pixel-wide scissored column or row, and a
/// rectangle whose edge passes exactly through the centres in it (8 of them).
fn fill_rule_and_snapping_of_llvmpipe(gl: &mut GlReplay) {
    let s = (8, 8);
    let column = "scissor 2 0 1 8";
    let row = "scissor 0 2 8 1";
    let eps = 1.0 / 512.0;
    let cases = [
        (
            "left edge on centres: owned",
            column,
            rect(2.5, 6.0, 0.3, 7.7, 0.0, s),
            8,
        ),
        (
            "right edge on centres: not owned",
            column,
            rect(0.2, 2.5, 0.3, 7.7, 0.0, s),
            0,
        ),
        (
            "bottom edge on centres: owned",
            row,
            rect(0.3, 7.7, 2.5, 6.0, 0.0, s),
            8,
        ),
        (
            "top edge on centres: not owned",
            row,
            rect(0.3, 7.7, 0.2, 2.5, 0.0, s),
            0,
        ),
        // (2.5 + 1/512 - 0.5) · 256 = 512.5 -> 512 (even): onto the centres.
        (
            "left edge tie rounds to even, onto centres",
            column,
            rect(2.5 + eps, 6.0, 0.3, 7.7, 0.0, s),
            8,
        ),
        // 513.5 -> 514 (even): past the centres.
        (
            "left edge tie rounds to even, past centres",
            column,
            rect(2.5 + 3.0 * eps, 6.0, 0.3, 7.7, 0.0, s),
            0,
        ),
        (
            "bottom edge tie onto centres",
            row,
            rect(0.3, 7.7, 2.5 + eps, 6.0, 0.0, s),
            8,
        ),
        (
            "bottom edge tie past centres",
            row,
            rect(0.3, 7.7, 2.5 + 3.0 * eps, 6.0, 0.0, s),
            0,
        ),
        // 511.5 -> 512: a right edge onto the centres, still not owned.
        (
            "right edge tie onto centres",
            column,
            rect(0.2, 2.5 - eps, 0.3, 7.7, 0.0, s),
            0,
        ),
        // 512.5 -> 512 for a right edge at 2.5 + 1/512: onto the centres, not owned.
        (
            "right edge tie back onto centres",
            column,
            rect(0.2, 2.5 + eps, 0.3, 7.7, 0.0, s),
            0,
        ),
        (
            "right edge just past centres",
            column,
            rect(0.2, 2.5 + 3.0 * eps, 0.3, 7.7, 0.0, s),
            8,
        ),
    ];
    for (name, scissor, tris, expected) in cases {
        let lines = scene(&format!("viewport 8 8\n{scissor}\nbegin 1\n{tris}end\n"));
        let mesa = gl.run(&lines)[0].counts[0];
        let ours = golden_counts(&lines)[0].counts[0];
        assert_eq!(mesa, expected, "Mesa, {name}");
        assert_eq!(ours, expected, "golden model, {name}");
    }
}

/// Structured scenes on exact boundaries: tilings, fans, shared diagonals, depth functions,
/// masks, scissor and culling.
fn structured_scenes() -> Vec<(String, String)> {
    let s = (32, 32);
    let mut scenes = Vec::new();

    // Quads tiling the viewport on pixel and half-pixel boundaries: 32·32 exactly.
    for offset in [0.0, 0.5, 0.25, 1.0 / 512.0] {
        let mut text = String::from("viewport 32 32\nbegin 1\n");
        let cuts: Vec<f64> = (0..=4)
            .map(|i| i as f64 * 8.0 + if i == 0 || i == 4 { 0.0 } else { offset })
            .collect();
        for i in 0..4 {
            for j in 0..4 {
                text += &rect(cuts[i], cuts[i + 1], cuts[j], cuts[j + 1], 0.0, s);
            }
        }
        text += "end\n";
        scenes.push((format!("tiling with cuts offset {offset}"), text));
    }

    // A fan around a vertex on a pixel centre and one on a pixel corner.
    for centre in [(16.5, 16.5), (16.0, 16.0), (10.5 + 1.0 / 512.0, 20.25)] {
        let ring = [
            (0.0, 0.0),
            (12.5, 0.0),
            (32.0, 0.0),
            (32.0, 13.5),
            (32.0, 32.0),
            (20.5, 32.0),
            (0.0, 32.0),
            (0.0, 7.5),
        ];
        let (cx, cy) = (clip(centre.0, 32), clip(centre.1, 32));
        let mut text = String::from("viewport 32 32\nbegin 1\n");
        for k in 0..ring.len() {
            let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
            text += &format!(
                "tri {cx} {cy} 0 1 {} {} 0 1 {} {} 0 1\n",
                clip(a.0, 32),
                clip(a.1, 32),
                clip(b.0, 32),
                clip(b.1, 32)
            );
        }
        text += "end\n";
        scenes.push((format!("fan around {centre:?}"), text));
    }

    // Shared diagonals through pixel centres (slope 1 and 1/2), each half queried alone.
    let mut text = String::from("viewport 32 32\n");
    for (id, tri) in [
        "0.5 0.5 2.5 2.5 0.5 2.5",
        "0.5 0.5 2.5 0.5 2.5 2.5",
        "0.5 0.5 30.5 15.5 0.5 15.5",
        "0.5 0.5 30.5 0.5 30.5 15.5",
    ]
    .iter()
    .enumerate()
    {
        let v: Vec<f64> = tri.split(' ').map(|w| w.parse().unwrap()).collect();
        text += &format!(
            "begin {id}\ntri {} {} 0 1 {} {} 0 1 {} {} 0 1\nend\n",
            clip(v[0], 32),
            clip(v[1], 32),
            clip(v[2], 32),
            clip(v[3], 32),
            clip(v[4], 32),
            clip(v[5], 32)
        );
    }
    scenes.push(("shared diagonals".into(), text));

    // Every depth function against the same quad drawn before, and depths 0 and 1.
    let mut text = String::from("viewport 32 32\n");
    let quad = rect(3.5, 20.25, 4.0, 29.5, 0.25, s);
    text += &format!("begin 100\n{quad}end\n");
    for (k, f) in occsim_traces::DepthFunc::ALL.iter().enumerate() {
        text += &format!(
            "depth_func {}\ndepth_mask 0\nbegin {k}\n{quad}end\n",
            f.name()
        );
    }
    text += "depth_mask 1\nclear\ndepth_func less\n";
    text += &format!("begin 200\n{}end\n", rect(0.0, 32.0, 0.0, 32.0, 1.0, s));
    text += &format!(
        "depth_func lequal\nbegin 201\n{}end\n",
        rect(0.0, 32.0, 0.0, 32.0, 1.0, s)
    );
    text += &format!("begin 202\n{}end\n", rect(0.0, 32.0, 0.0, 32.0, -1.0, s));
    text += &format!(
        "depth_func less\nbegin 203\n{}end\n",
        rect(0.0, 32.0, 0.0, 32.0, -1.0, s)
    );
    text += &format!(
        "depth_func gequal\nbegin 204\n{}end\n",
        rect(0.0, 32.0, 0.0, 32.0, -1.0, s)
    );
    scenes.push(("depth functions, depths 0 and 1".into(), text));

    // Masks, depth test off, scissor, culling (a clockwise quad vanishes), brief tiles.
    let mut text = String::from("viewport 32 32\n");
    text += &format!(
        "depth_mask 0\nbegin 1\n{}end\n",
        rect(2.0, 30.0, 2.0, 30.0, 0.0, s)
    );
    text += &format!(
        "depth_mask 1\nbegin 2\n{}end\n",
        rect(2.0, 30.0, 2.0, 30.0, 0.5, s)
    );
    text += &format!(
        "depth_test 0\nbegin 3\n{}end\ndepth_test 1\n",
        rect(0.5, 31.5, 0.5, 31.5, 0.75, s)
    );
    text += &format!(
        "scissor 5 7 11 13\nbegin 4 any\n{}end\nscissor off\n",
        rect(0.0, 32.0, 0.0, 32.0, -0.5, s)
    );
    let clockwise = "tri -1 -1 0 1 -1 1 0 1 1 1 0 1\ntri -1 -1 0 1 1 1 0 1 1 -1 0 1\n";
    text += &format!(
        "cull 1\ndepth_func always\nbegin 5\n{clockwise}end\ncull 0\nbegin 6\n{clockwise}end\n"
    );
    text += &format!(
        "depth_func less\nscissor 3 3 20 20\nbegin 7 brief tile=0,0,16,16 tile=16,0,16,16 tile=0,16,32,16 tile=4,4,3,3\n{}end\n",
        rect(1.5, 29.5, 2.5, 30.5, -0.75, s)
    );
    scenes.push(("masks, scissor, culling, brief tiles".into(), text));
    scenes
}

/// splitmix64: a small deterministic generator, so scenes depend on the seed alone.
struct Random(u64);

impl Random {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }

    fn chance(&mut self, percent: u64) -> bool {
        self.below(100) < percent
    }
}

/// A random scene inside the viewport (no clipping by Mesa), coordinates on the exact grid.
/// What a random scene exercises.
#[derive(Clone, Copy, PartialEq, Debug)]
enum SceneKind {
    /// Vertices on the 1/256 snapping grid (snapped = unsnapped, so llvmpipe's depth plane,
    /// built from unsnapped positions, is ours up to its f32 rounding): every depth function.
    DepthOnSnapGrid,
    /// Vertices on the 1/512 grid, half of them on snapping ties; depth function `always`,
    /// so counts measure coverage (the depth planes differ by the snapping).
    CoverageOnTies,
    /// Arbitrary f32 clip coordinates and w inside the view volume; coverage only.
    CoverageFloat,
}

fn random_scene(seed: u64, width: u32, height: u32, kind: SceneKind) -> String {
    let mut rng = Random(seed);
    let mut text = format!("viewport {width} {height}\n");
    if kind != SceneKind::DepthOnSnapGrid {
        text += "depth_func always\n";
    }
    for query in 0..12 {
        if rng.chance(20) {
            text += "clear\n";
        }
        if rng.chance(50) && kind == SceneKind::DepthOnSnapGrid {
            let f = occsim_traces::DepthFunc::ALL[rng.below(8) as usize];
            text += &format!("depth_func {}\n", f.name());
        }
        if rng.chance(30) {
            text += &format!("depth_mask {}\n", rng.below(2));
        }
        if rng.chance(10) {
            text += &format!("depth_test {}\n", (rng.below(4) != 0) as u8);
        }
        if rng.chance(30) {
            text += &format!("cull {}\n", rng.below(2));
        }
        if rng.chance(30) {
            let (x, y) = (rng.below(width as u64), rng.below(height as u64));
            let (w, h) = (
                rng.below(width as u64 - x + 1),
                rng.below(height as u64 - y + 1),
            );
            text += &format!("scissor {x} {y} {w} {h}\n");
        } else if rng.chance(30) {
            text += "scissor off\n";
        }
        let mode = QueryMode::ALL[rng.below(4) as usize];
        text += &format!("begin {query} {}", mode.name());
        if mode.is_occlusion_render_mode() {
            for _ in 0..1 + rng.below(3) {
                let (x, y) = (rng.below(width as u64), rng.below(height as u64));
                let w = 1 + rng.below(width as u64 - x);
                let h = 1 + rng.below(height as u64 - y);
                text += &format!(" tile={x},{y},{w},{h}");
            }
        }
        text += "\n";
        for _ in 0..1 + rng.below(6) {
            text += "tri";
            for _ in 0..3 {
                if kind != SceneKind::CoverageFloat {
                    // w a power of two keeps x·(1/w) exact.
                    let w = [0.5, 1.0, 2.0, 4.0][rng.below(4) as usize];
                    let grid = if kind == SceneKind::DepthOnSnapGrid {
                        256
                    } else {
                        512
                    };
                    let xw = rng.below(width as u64 * grid + 1) as f64 / grid as f64;
                    let yw = rng.below(height as u64 * grid + 1) as f64 / grid as f64;
                    let z = (rng.below(2049) as f64 - 1024.0) / 1024.0;
                    text += &format!(
                        "  {} {} {} {w}",
                        clip(xw, width) * w,
                        clip(yw, height) * w,
                        z * w
                    );
                } else {
                    // Arbitrary f32 clip coordinates inside the view volume.
                    let unit =
                        |rng: &mut Random| (rng.below(1 << 24) as f32 / (1 << 23) as f32) - 1.0;
                    let w = 0.25 + rng.below(1 << 20) as f32 / (1 << 18) as f32;
                    let (x, y, z) = (unit(&mut rng) * w, unit(&mut rng) * w, unit(&mut rng) * w);
                    text += &format!("  {x:?} {y:?} {z:?} {w:?}");
                }
            }
            text += "\n";
        }
        text += "end\n";
    }
    text
}

#[test]
fn golden_model_matches_mesa_llvmpipe() {
    let Some(mut gl8) = mesa_or_skip(8, 8) else {
        return;
    };
    let renderer = gl8.renderer();
    assert!(renderer.contains("llvmpipe"), "not llvmpipe: {renderer}");
    fill_rule_and_snapping_of_llvmpipe(&mut gl8);
    drop(gl8);

    let mut gl = GlReplay::new(32, 32).expect("second context");
    for (name, text) in structured_scenes() {
        assert_same_counts(&name, &scene(&text), &mut gl);
    }
    drop(gl);

    let (width, height) = (64, 32);
    let mut gl = GlReplay::new(width, height).expect("third context");
    for kind in [
        SceneKind::DepthOnSnapGrid,
        SceneKind::CoverageOnTies,
        SceneKind::CoverageFloat,
    ] {
        for seed in 0..150 {
            let text = random_scene(seed, width, height, kind);
            let name = format!("random scene {kind:?}, seed {seed}");
            assert_same_counts(&name, &scene(&text), &mut gl);
        }
    }
}
