//! The `demo` city block: streets of box buildings with ledges, seen by a camera walking down
//! the main street, drawn with occlusion-driven rendering (box test first, draw if visible).

use crate::golden::{Discard, GoldenModel};
use crate::query::{QueryMode, QueryResult, QuerySpec, BRIEF_RECORD_ENTRIES};
use crate::scene::{format_command, Command};
use crate::state::{DepthFunc, Rect};
use glam::{Mat4, Vec3, Vec4};

/// How the demo is made.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Viewport width in pixels.
    pub width: u32,
    /// Viewport height in pixels.
    pub height: u32,
    /// Frames of the walk down the street.
    pub frames: u32,
    /// Seed of the building layout.
    pub seed: u64,
    /// Building lots along each side of the main street.
    pub lots_per_side: u32,
}

impl Default for DemoOptions {
    fn default() -> DemoOptions {
        DemoOptions {
            width: 1280,
            height: 1024,
            frames: 4,
            seed: 1998,
            lots_per_side: 40,
        }
    }
}

/// SplitMix64: a tiny, well-mixed, seedable generator (the layout must be reproducible
/// everywhere, so no platform or crate-version dependent randomness).
pub(crate) struct SplitMix64(pub(crate) u64);

impl SplitMix64 {
    pub(crate) fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [lo, hi).
    pub(crate) fn range(&mut self, lo: f32, hi: f32) -> f32 {
        let unit = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * unit
    }
}

/// An axis-aligned box in world space (metres).
#[derive(Clone, Copy, Debug)]
struct Aabb {
    min: Vec3,
    max: Vec3,
}

impl Aabb {
    fn union(self, other: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min, self.max);
        [
            Vec3::new(a.x, a.y, a.z),
            Vec3::new(b.x, a.y, a.z),
            Vec3::new(a.x, b.y, a.z),
            Vec3::new(b.x, b.y, a.z),
            Vec3::new(a.x, a.y, b.z),
            Vec3::new(b.x, a.y, b.z),
            Vec3::new(a.x, b.y, b.z),
            Vec3::new(b.x, b.y, b.z),
        ]
    }

    /// The twelve triangles of the box, counter-clockwise seen from outside.
    fn triangles(&self) -> Vec<[Vec3; 3]> {
        let c = self.corners();
        let centre = (self.min + self.max) * 0.5;
        // Each face as a quad of corner indices; winding is fixed up below.
        const FACES: [[usize; 4]; 6] = [
            [0, 1, 3, 2],
            [4, 6, 7, 5],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 5, 7, 3],
        ];
        let mut out = Vec::with_capacity(12);
        for face in FACES {
            let [a, b, cc, d] = face.map(|i| c[i]);
            let normal = (b - a).cross(cc - a);
            let outward = (a + cc) * 0.5 - centre;
            let quad = if normal.dot(outward) > 0.0 {
                [a, b, cc, d]
            } else {
                [a, d, cc, b]
            };
            out.push([quad[0], quad[1], quad[2]]);
            out.push([quad[0], quad[2], quad[3]]);
        }
        out
    }
}

/// A building: its parts and their bounding box.
struct Building {
    parts: Vec<Aabb>,
    bounds: Aabb,
}

fn make_building(rng: &mut SplitMix64, x0: f32, x1: f32, z0: f32, z1: f32) -> Building {
    let height = rng.range(6.0, 45.0);
    let body = Aabb {
        min: Vec3::new(x0, 0.0, z0),
        max: Vec3::new(x1, height, z1),
    };
    let mut parts = vec![body];
    // Ledges every floor band protrude a little: detail that a box test never sees.
    let mut y = 3.5;
    while y < height - 1.0 {
        parts.push(Aabb {
            min: Vec3::new(x0 - 0.3, y, z0 - 0.3),
            max: Vec3::new(x1 + 0.3, y + 0.3, z1 + 0.3),
        });
        y += rng.range(3.0, 7.0);
    }
    // A setback storey and a rooftop box.
    let inset = (x1 - x0).min(z1 - z0) * 0.2;
    let top = height + rng.range(2.0, 8.0);
    parts.push(Aabb {
        min: Vec3::new(x0 + inset, height, z0 + inset),
        max: Vec3::new(x1 - inset, top, z1 - inset),
    });
    parts.push(Aabb {
        min: Vec3::new(x0 + 2.0 * inset, top, z0 + 2.0 * inset),
        max: Vec3::new(x0 + 2.5 * inset, top + 2.0, z0 + 2.5 * inset),
    });
    let bounds = parts.iter().copied().reduce(Aabb::union).unwrap_or(body);
    Building { parts, bounds }
}

fn make_city(options: &DemoOptions) -> Vec<Building> {
    let mut rng = SplitMix64(options.seed);
    let mut buildings = Vec::new();
    for side in [-1.0f32, 1.0] {
        let mut z = -4.0;
        for _ in 0..options.lots_per_side {
            let depth = rng.range(8.0, 18.0);
            let near_edge = rng.range(7.0, 9.0);
            let far_edge = near_edge + rng.range(10.0, 30.0);
            let (x0, x1) = if side < 0.0 {
                (-far_edge, -near_edge)
            } else {
                (near_edge, far_edge)
            };
            buildings.push(make_building(&mut rng, x0, x1, z - depth, z));
            // Cross streets every few lots open the view sideways.
            z -= depth + if rng.range(0.0, 1.0) < 0.2 { 12.0 } else { 1.0 };
        }
    }
    buildings
}

/// Writes commands as scene text while the golden model answers the queries.
struct Recorder {
    text: String,
    golden: GoldenModel,
    next_query_id: u32,
}

impl Recorder {
    fn emit(&mut self, command: Command) -> Option<QueryResult> {
        self.text += &format_command(&command);
        self.text.push('\n');
        self.golden.execute(&command, &mut Discard)
    }

    fn emit_triangles(&mut self, view_projection: &Mat4, triangles: &[[Vec3; 3]]) {
        for tri in triangles {
            let clip = tri.map(|p| {
                let v: Vec4 = *view_projection * p.extend(1.0);
                [v.x, v.y, v.z, v.w]
            });
            self.emit(Command::Tri(clip));
        }
    }

    fn query(&mut self, mode: QueryMode, buffer_entries: u32, tiles: Vec<Rect>) -> u32 {
        let id = self.next_query_id;
        self.next_query_id += 1;
        self.emit(Command::Begin(QuerySpec {
            id,
            mode,
            buffer_entries,
            tiles,
        }));
        id
    }
}

/// OpenGL's perspective projection (gluPerspective): right-handed eye space, depth to [-1, 1].
fn perspective_gl(fov_y_radians: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    let f = 1.0 / (fov_y_radians * 0.5).tan();
    Mat4::from_cols(
        Vec4::new(f / aspect, 0.0, 0.0, 0.0),
        Vec4::new(0.0, f, 0.0, 0.0),
        Vec4::new(0.0, 0.0, (far + near) / (near - far), -1.0),
        Vec4::new(0.0, 0.0, 2.0 * far * near / (near - far), 0.0),
    )
}

/// OpenGL's viewing transform (gluLookAt).
fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Mat4 {
    let forward = (target - eye).normalize();
    let side = forward.cross(up).normalize();
    let up = side.cross(forward);
    Mat4::from_cols(
        Vec4::new(side.x, up.x, -forward.x, 0.0),
        Vec4::new(side.y, up.y, -forward.y, 0.0),
        Vec4::new(side.z, up.z, -forward.z, 0.0),
        Vec4::new(-side.dot(eye), -up.dot(eye), forward.dot(eye), 1.0),
    )
}

/// The pixel rectangle a box covers on screen: the whole viewport when it reaches behind
/// the near plane, None when it is off screen.
fn screen_rect(bounds: &Aabb, view_projection: &Mat4, width: u32, height: u32) -> Option<Rect> {
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for corner in bounds.corners() {
        let clip = *view_projection * corner.extend(1.0);
        if clip.w <= 0.5 {
            return Some(Rect::new(0, 0, width, height));
        }
        let ndc = clip.truncate() / clip.w;
        lo = lo.min(ndc);
        hi = hi.max(ndc);
    }
    let to_pixels = |ndc: f32, size: u32| ((ndc + 1.0) * 0.5 * size as f32).clamp(0.0, size as f32);
    let (x0, x1) = (
        to_pixels(lo.x, width).floor(),
        to_pixels(hi.x, width).ceil(),
    );
    let (y0, y1) = (
        to_pixels(lo.y, height).floor(),
        to_pixels(hi.y, height).ceil(),
    );
    if x1 <= x0 || y1 <= y0 || lo.z > 1.0 {
        return None;
    }
    Some(Rect::new(
        x0 as u32,
        y0 as u32,
        (x1 - x0) as u32,
        (y1 - y0) as u32,
    ))
}

/// A 2x2 quadtree level over `rect` (fewer tiles when it is one pixel wide or high).
fn quad_tiles(rect: Rect) -> Vec<Rect> {
    let (w0, h0) = (rect.width.div_ceil(2), rect.height.div_ceil(2));
    let mut tiles = Vec::with_capacity(4);
    for (y, h) in [(rect.y, h0), (rect.y + h0, rect.height - h0)] {
        for (x, w) in [(rect.x, w0), (rect.x + w0, rect.width - w0)] {
            if w > 0 && h > 0 {
                tiles.push(Rect::new(x, y, w, h));
            }
        }
    }
    tiles
}

/// The demo scene's text.
pub fn demo_scene(options: &DemoOptions) -> String {
    let (width, height) = (options.width, options.height);
    let city = make_city(options);
    let mut recorder = Recorder {
        text: String::new(),
        golden: GoldenModel::new(width, height),
        next_query_id: 1,
    };
    recorder.text += "# occsim demo: a city block, box-tested front to back in brief mode\n";
    recorder.emit(Command::Viewport { width, height });
    let projection = perspective_gl(60f32.to_radians(), width as f32 / height as f32, 0.5, 800.0);
    let ground = Aabb {
        min: Vec3::new(-200.0, -1.0, -700.0),
        max: Vec3::new(200.0, 0.0, 50.0),
    };
    for frame in 0..options.frames {
        let eye = Vec3::new(1.5, 1.7, -(frame as f32) * 6.0);
        let target = eye + Vec3::new(-0.15 + 0.1 * frame as f32, 0.05, -1.0);
        let view_projection = projection * look_at(eye, target, Vec3::Y);
        recorder.text += &format!("# frame {frame}\n");
        for command in [
            Command::Clear,
            Command::Cull(true),
            Command::DepthFunc(DepthFunc::Less),
            Command::DepthMask(true),
        ] {
            recorder.emit(command);
        }
        recorder.query(
            QueryMode::Samples,
            BRIEF_RECORD_ENTRIES,
            vec![Rect::new(0, 0, width, height)],
        );
        recorder.emit_triangles(&view_projection, &ground.triangles());
        recorder.emit(Command::End);

        let mut order: Vec<usize> = (0..city.len()).collect();
        let distance = |b: &Building| ((b.bounds.min + b.bounds.max) * 0.5 - eye).length_squared();
        order.sort_by(|&a, &b| distance(&city[a]).total_cmp(&distance(&city[b])));
        for (rank, &index) in order.iter().enumerate() {
            let building = &city[index];
            let Some(rect) = screen_rect(&building.bounds, &view_projection, width, height) else {
                continue;
            };
            // Every 16th test is verbose, with a small buffer that the near ones overflow.
            let (mode, buffer) = if rank % 16 == 15 {
                (QueryMode::Verbose, BRIEF_RECORD_ENTRIES + 64)
            } else {
                (QueryMode::Brief, BRIEF_RECORD_ENTRIES)
            };
            recorder.query(mode, buffer, quad_tiles(rect));
            recorder.emit_triangles(&view_projection, &building.bounds.triangles());
            let visible = recorder.emit(Command::End).is_some_and(|r| r.value() > 0);
            if visible {
                recorder.query(
                    QueryMode::Samples,
                    BRIEF_RECORD_ENTRIES,
                    vec![Rect::new(0, 0, width, height)],
                );
                for part in &building.parts {
                    recorder.emit_triangles(&view_projection, &part.triangles());
                }
                recorder.emit(Command::End);
            }
        }
    }
    recorder.text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::parse_scene;

    #[test]
    fn box_triangles_face_outward() {
        let b = Aabb {
            min: Vec3::new(-1.0, -2.0, -3.0),
            max: Vec3::new(1.0, 2.0, 3.0),
        };
        for [a, bb, c] in b.triangles() {
            let normal = (bb - a).cross(c - a);
            let centre_of_triangle = (a + bb + c) / 3.0;
            assert!(
                normal.dot(centre_of_triangle) > 0.0,
                "inward triangle {a} {bb} {c}"
            );
        }
    }

    #[test]
    fn quad_tiles_cover_the_rect_once() {
        for rect in [
            Rect::new(3, 4, 5, 7),
            Rect::new(0, 0, 1, 9),
            Rect::new(2, 2, 1, 1),
        ] {
            let tiles = quad_tiles(rect);
            let area: u64 = tiles.iter().map(Rect::area).sum();
            assert_eq!(area, rect.area());
            for t in &tiles {
                assert_eq!(t.intersect(&rect), *t);
            }
        }
    }

    #[test]
    fn small_demo_parses_and_is_reproducible() {
        let options = DemoOptions {
            width: 160,
            height: 120,
            frames: 2,
            seed: 7,
            lots_per_side: 6,
        };
        let text = demo_scene(&options);
        assert_eq!(text, demo_scene(&options));
        let lines = parse_scene(&text, "demo").unwrap();
        assert!(lines.len() > 100, "{} lines", lines.len());
    }
}
