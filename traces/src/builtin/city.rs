//! The `demo` city block: streets of box buildings with ledges, seen by a camera walking down
//! the main street, drawn with occlusion-driven rendering (box test first, draw if visible).

use crate::geometry::{look_at, perspective_gl, quad_tiles, screen_rect, Aabb, SplitMix64};
use crate::golden::{infallible, Discard, GoldenModel};
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
        infallible(self.golden.execute(&command, &mut Discard))
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
            let id = recorder.query(mode, buffer, quad_tiles(rect));
            recorder.emit_triangles(&view_projection, &building.bounds.triangles());
            let visible = recorder.emit(Command::End).is_some_and(|r| r.value() > 0);
            // The host reads the answer before it decides (the closed loop waits for it).
            recorder.emit(Command::Wait(id));
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
        recorder.emit(Command::Swap);
    }
    recorder.text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::parse_scene;

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
