//! The built-in parametric scenes, seeded and reproducible.
//!
//! - `city`: a grid of blocks separated by streets; each block holds four buildings with
//!   ledges at every floor, window sills (the detail) and rooftop structures. One building
//!   is one object; the ground is one more. The camera walks down the central avenue.
//! - `forest`: trees (a trunk and stacked cones) on a jittered grid either side of a path,
//!   each tree one object; the ground is one more. The camera walks along the path.

use super::camera::{CameraKeyframe, CameraPath};
use super::{SceneObject, WorkloadScene};
use crate::geometry::{Aabb, SplitMix64};
use glam::Vec3;
use std::f32::consts::TAU;

/// How the city is made. Triangles grow with `blocks^2 * detail`: the defaults give about
/// 150,000; 40 blocks and detail 4 about ten million.
#[derive(Clone, Debug, PartialEq)]
pub struct CityOptions {
    /// Blocks along each side of the square city.
    pub blocks: u32,
    /// Window sills per facade per floor (0: plain buildings).
    pub detail: u32,
    /// Seed of the layout.
    pub seed: u64,
}

impl Default for CityOptions {
    fn default() -> CityOptions {
        CityOptions {
            blocks: 6,
            detail: 2,
            seed: 1998,
        }
    }
}

/// Distance between street centres, metres.
const BLOCK_PITCH: f32 = 70.0;
/// Street width, metres.
const STREET: f32 = 14.0;
/// Storey height, metres.
const STOREY: f32 = 3.5;
/// Eye height above the street, metres.
const EYE_HEIGHT: f32 = 1.7;
/// Most blocks per side and sills per facade per floor the generator accepts (bounds memory:
/// 32 blocks at detail 16 are 24 M triangles, about 0.9 GB; 48 at 16 had been 54 M and 2 GB,
/// and 80 at 2, 870 MB). The command line refuses more; the generator clamps.
pub const MAX_CITY_BLOCKS: u32 = 32;
pub const MAX_CITY_DETAIL: u32 = 16;

fn box_triangles(min: Vec3, max: Vec3) -> Vec<[Vec3; 3]> {
    Aabb { min, max }.triangles()
}

/// A building on the lot [x0, x1] x [z0, z1]: its triangles, and its body and setback
/// storey, the boxes inside its surface.
fn building(rng: &mut SplitMix64, detail: u32, x0: f32, x1: f32, z0: f32, z1: f32) -> SceneObject {
    let floors = rng.range(2.0, 16.0) as u32;
    let height = floors as f32 * STOREY;
    let body = Aabb {
        min: Vec3::new(x0, 0.0, z0),
        max: Vec3::new(x1, height, z1),
    };
    let mut triangles = body.triangles();
    for floor in 1..floors {
        let y = floor as f32 * STOREY;
        // A ledge round the floor, and sills sticking out of each facade.
        triangles.extend(box_triangles(
            Vec3::new(x0 - 0.3, y, z0 - 0.3),
            Vec3::new(x1 + 0.3, y + 0.25, z1 + 0.3),
        ));
        for k in 0..detail {
            let f = (k as f32 + 0.5) / detail as f32;
            let (x, z) = (x0 + (x1 - x0) * f, z0 + (z1 - z0) * f);
            let sill_y = y + 1.0;
            for (min, max) in [
                (
                    Vec3::new(x - 0.8, sill_y, z1),
                    Vec3::new(x + 0.8, sill_y + 0.15, z1 + 0.4),
                ),
                (
                    Vec3::new(x - 0.8, sill_y, z0 - 0.4),
                    Vec3::new(x + 0.8, sill_y + 0.15, z0),
                ),
                (
                    Vec3::new(x1, sill_y, z - 0.8),
                    Vec3::new(x1 + 0.4, sill_y + 0.15, z + 0.8),
                ),
                (
                    Vec3::new(x0 - 0.4, sill_y, z - 0.8),
                    Vec3::new(x0, sill_y + 0.15, z + 0.8),
                ),
            ] {
                triangles.extend(box_triangles(min, max));
            }
        }
    }
    // A setback storey and a rooftop machine room.
    let inset = (x1 - x0).min(z1 - z0) * 0.2;
    let top = height + rng.range(2.0, 6.0);
    let setback = Aabb {
        min: Vec3::new(x0 + inset, height, z0 + inset),
        max: Vec3::new(x1 - inset, top, z1 - inset),
    };
    triangles.extend(setback.triangles());
    triangles.extend(box_triangles(
        Vec3::new(x0 + 2.0 * inset, top, z0 + 2.0 * inset),
        Vec3::new(x0 + 2.8 * inset, top + 2.5, z0 + 2.8 * inset),
    ));
    SceneObject::new(triangles)
        .expect("a building has faces")
        .with_solids(vec![body, setback])
}

/// The `city` scene.
pub fn city(options: &CityOptions) -> WorkloadScene {
    let (objects, camera, _) = city_parts(options);
    WorkloadScene::new("city", objects, camera).expect("a city has buildings")
}

/// Where the city's streets run: block `(i, j)` spans x from `west + i * BLOCK_PITCH` and z
/// from `north_of_start - j * BLOCK_PITCH` (towards -z), between street centre lines.
pub(crate) struct StreetLayout {
    pub(crate) blocks: u32,
    /// X of the westmost street's centre line.
    pub(crate) west: f32,
    /// Z of the first street's centre line (the blocks run towards -z from it).
    pub(crate) first_street_z: f32,
}

impl StreetLayout {
    pub(crate) const PITCH: f32 = BLOCK_PITCH;
    pub(crate) const STREET_WIDTH: f32 = STREET;
}

/// The city's objects (buildings, then the ground), its walk and its streets.
pub(crate) fn city_parts(options: &CityOptions) -> (Vec<SceneObject>, CameraPath, StreetLayout) {
    let blocks = options.blocks.clamp(1, MAX_CITY_BLOCKS);
    let detail = options.detail.min(MAX_CITY_DETAIL);
    let mut rng = SplitMix64(options.seed);
    let half = blocks as f32 * BLOCK_PITCH * 0.5;
    let mut objects = Vec::new();
    // Block (i, j) spans x from the street at i * pitch - half; the avenue at x = 0 is a
    // street when the block count is even, and runs beside the middle block when it is odd.
    for j in 0..blocks {
        for i in 0..blocks {
            let bx = i as f32 * BLOCK_PITCH - half + STREET * 0.5;
            let bz = -(j as f32) * BLOCK_PITCH - STREET * 0.5;
            let inner = BLOCK_PITCH - STREET;
            for (lx, lz) in [(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (0.5, 0.5)] {
                let gap = rng.range(0.5, 3.0);
                let x0 = bx + lx * inner + gap;
                let x1 = bx + (lx + 0.5) * inner - gap;
                let z1 = bz - lz * inner - gap;
                let z0 = bz - (lz + 0.5) * inner + gap;
                objects.push(building(&mut rng, detail, x0, x1, z0, z1));
            }
        }
    }
    let length = blocks as f32 * BLOCK_PITCH;
    let ground = Aabb {
        min: Vec3::new(-half - 20.0, -1.0, -length - 20.0),
        max: Vec3::new(half + 20.0, 0.0, 40.0),
    };
    objects.push(
        SceneObject::new(ground.triangles())
            .expect("the ground has faces")
            .with_solids(vec![ground]),
    );
    let avenue_x = if blocks.is_multiple_of(2) {
        0.0
    } else {
        -BLOCK_PITCH * 0.5
    };
    let camera = street_walk(avenue_x, 10.0, -length + 10.0, 50.0, 2.0);
    let layout = StreetLayout {
        blocks,
        west: -half,
        first_street_z: 0.0,
    };
    (objects, camera, layout)
}

/// A walk down the street at `x` from `z_start` to `z_end`, glancing left and right every
/// `sway_every` metres, at `step` metres per frame.
fn street_walk(x: f32, z_start: f32, z_end: f32, sway_every: f32, step: f32) -> CameraPath {
    let length = (z_start - z_end).max(1.0);
    let stops = (length / sway_every).ceil().max(1.0) as u32;
    let keyframes = (0..=stops)
        .map(|k| {
            let z = z_start - length * k as f32 / stops as f32;
            let glance = if k % 2 == 0 { -4.0 } else { 4.0 };
            CameraKeyframe {
                eye: [x + 1.5, EYE_HEIGHT, z],
                target: [x + 1.5 + glance, EYE_HEIGHT + 0.5, z - 20.0],
            }
        })
        .collect();
    CameraPath::new(keyframes, Some(step), "street walk").expect("the walk is well formed")
}

/// How the forest is made. Triangles grow with `trees * detail`.
#[derive(Clone, Debug, PartialEq)]
pub struct ForestOptions {
    /// Trees in all.
    pub trees: u32,
    /// Sides of each crown cone (at least 3).
    pub detail: u32,
    /// Seed of the layout.
    pub seed: u64,
}

impl Default for ForestOptions {
    fn default() -> ForestOptions {
        ForestOptions {
            trees: 3000,
            detail: 10,
            seed: 1998,
        }
    }
}

/// Distance between tree sites, metres.
const TREE_PITCH: f32 = 6.0;
/// Half the width of the path kept clear of trees, metres.
const PATH_HALF_WIDTH: f32 = 3.0;
/// Most trees, and sides a crown cone, the generator accepts (bounds memory: 100,000 trees of
/// 32 sides are about 23 M triangles, 0.9 GB; 1,000,000 of 10 had taken 3.9 GB). The command
/// line refuses more; the generator clamps.
pub const MAX_TREES: u32 = 100_000;
pub const MAX_CONE_SIDES: u32 = 32;

/// A cone of `sides` sides on the base circle (centre, radius) up to `apex`.
fn cone(sides: u32, base: Vec3, radius: f32, apex: Vec3) -> Vec<[Vec3; 3]> {
    let rim: Vec<Vec3> = (0..sides)
        .map(|k| {
            let angle = TAU * k as f32 / sides as f32;
            base + Vec3::new(libm::cosf(angle) * radius, 0.0, -libm::sinf(angle) * radius)
        })
        .collect();
    let mut triangles = Vec::with_capacity(2 * sides as usize);
    for k in 0..sides as usize {
        let (a, b) = (rim[k], rim[(k + 1) % rim.len()]);
        // Counter-clockwise from outside: the rim runs counter-clockwise seen from above.
        triangles.push([a, b, apex]);
        triangles.push([a, base, b]);
    }
    triangles
}

fn tree(rng: &mut SplitMix64, sides: u32, x: f32, z: f32) -> Vec<[Vec3; 3]> {
    let trunk_half = rng.range(0.15, 0.35);
    let trunk_height = rng.range(1.5, 3.5);
    let mut triangles = box_triangles(
        Vec3::new(x - trunk_half, 0.0, z - trunk_half),
        Vec3::new(x + trunk_half, trunk_height, z + trunk_half),
    );
    let mut base = trunk_height;
    let mut radius = rng.range(1.8, 3.2);
    for _ in 0..3 {
        let height = rng.range(2.5, 4.5);
        triangles.extend(cone(
            sides,
            Vec3::new(x, base, z),
            radius,
            Vec3::new(x, base + height, z),
        ));
        base += height * 0.55;
        radius *= 0.7;
    }
    triangles
}

/// The `forest` scene.
pub fn forest(options: &ForestOptions) -> WorkloadScene {
    let trees = options.trees.clamp(1, MAX_TREES);
    let sides = options.detail.clamp(3, MAX_CONE_SIDES);
    let mut rng = SplitMix64(options.seed);
    // A square of sites wide enough for the trees beside the path.
    let per_row = ((trees as f32).sqrt().ceil() as u32).max(2);
    let half_width = per_row as f32 * TREE_PITCH * 0.5 + PATH_HALF_WIDTH;
    let mut objects = Vec::with_capacity(trees as usize + 1);
    let mut planted = 0;
    let mut row = 0;
    while planted < trees {
        for column in 0..per_row {
            if planted == trees {
                break;
            }
            let side = if column % 2 == 0 { -1.0 } else { 1.0 };
            let offset = PATH_HALF_WIDTH + 1.0 + (column / 2) as f32 * TREE_PITCH;
            let x = side * offset + rng.range(0.0, TREE_PITCH * 0.6);
            let z = -(row as f32) * TREE_PITCH - rng.range(0.0, TREE_PITCH * 0.8);
            objects.extend(SceneObject::new(tree(&mut rng, sides, x, z)));
            planted += 1;
        }
        row += 1;
    }
    let length = row as f32 * TREE_PITCH;
    objects.extend(SceneObject::new(box_triangles(
        Vec3::new(-half_width - 10.0, -1.0, -length - 10.0),
        Vec3::new(half_width + 10.0, 0.0, 30.0),
    )));
    let camera = {
        let keyframes = (0..=4)
            .map(|k| {
                let z = 8.0 - (length + 8.0) * k as f32 / 4.0;
                let glance = [-3.0, 2.0, -1.0, 3.0, 0.0][k];
                CameraKeyframe {
                    eye: [0.0, EYE_HEIGHT, z],
                    target: [glance, EYE_HEIGHT + 0.3, z - 15.0],
                }
            })
            .collect();
        CameraPath::new(keyframes, Some(1.5), "forest walk").expect("the walk is well formed")
    };
    WorkloadScene::new("forest", objects, camera).expect("a forest has trees")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outward(triangles: &[[Vec3; 3]], centre: Vec3) {
        for [a, b, c] in triangles {
            let normal = (*b - *a).cross(*c - *a);
            let middle = (*a + *b + *c) / 3.0;
            assert!(
                normal.dot(middle - centre) > 0.0,
                "inward triangle {a} {b} {c}"
            );
        }
    }

    #[test]
    fn cones_face_outward() {
        let base = Vec3::new(1.0, 2.0, 3.0);
        let triangles = cone(7, base, 2.0, base + Vec3::new(0.0, 3.0, 0.0));
        assert_eq!(triangles.len(), 14);
        outward(&triangles, base + Vec3::new(0.0, 0.75, 0.0));
    }

    #[test]
    fn scenes_are_reproducible_and_sized_by_their_options() {
        let small = CityOptions {
            blocks: 2,
            detail: 0,
            seed: 3,
        };
        let a = city(&small);
        let b = city(&small);
        assert_eq!(a.object_triangle_counts(), b.object_triangle_counts());
        assert_eq!(a.object_count(), 2 * 2 * 4 + 1);
        let detailed = city(&CityOptions { detail: 2, ..small });
        assert!(detailed.triangle_count() > a.triangle_count());
        let woods = forest(&ForestOptions {
            trees: 10,
            detail: 5,
            seed: 1,
        });
        assert_eq!(woods.object_count(), 11);
        // A trunk (12) and three cones of 5 sides (10 each).
        assert!(woods.object_triangle_counts()[..10]
            .iter()
            .all(|&n| n == 42));
    }
}
