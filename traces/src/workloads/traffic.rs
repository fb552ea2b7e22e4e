//! The `traffic` scene: the city with cars that drive round its blocks, every car moving
//! every frame (seed 002's dynamic scene). Deterministic: a car's pose is a function of its
//! seeded loop, speed and phase and of the frame number alone.
//!
//! Each car circles one block in the lane `LANE_OFFSET` metres inside the street's centre
//! line, at a constant speed, turning at the corners: its path is continuous and its speed
//! bounded, which is what a temporal bounding volume needs to hold.

use super::scenes::{city_parts, CityOptions, StreetLayout};
use super::{SceneObject, WorkloadScene};
use crate::geometry::{Aabb, SplitMix64};
use glam::Vec3;

/// How the traffic scene is made.
#[derive(Clone, Debug, PartialEq)]
pub struct TrafficOptions {
    pub city: CityOptions,
    /// Cars circling each block.
    pub cars_per_block: u32,
}

impl Default for TrafficOptions {
    fn default() -> TrafficOptions {
        TrafficOptions {
            city: CityOptions::default(),
            cars_per_block: 3,
        }
    }
}

/// Distance from a street's centre line to the middle of the lane cars drive in, metres:
/// clear of the walk's eye (1.5 m off the avenue's centre) and of the building lots.
const LANE_OFFSET: f32 = 5.0;
// The lane lies in the street, short of the lots (half a metre at least beyond its kerb).
const _: () = assert!(LANE_OFFSET < StreetLayout::STREET_WIDTH * 0.5 + 0.5);

/// Slowest and fastest car, metres per frame (a frame is a tenth of a second: 29 to 50 km/h).
const SPEED_RANGE: (f32, f32) = (0.8, 1.4);
/// Most cars a block (bounds memory).
/// Most cars a block (the command line refuses more; the generator clamps).
pub const MAX_CARS_PER_BLOCK: u32 = 64;

/// A car's surface at rest: centred on the origin in x and z, standing on y = 0, its length
/// along +x. Every part is centred in x and z, so the box of any pose is centred on the car.
fn car_shape() -> (Vec<[Vec3; 3]>, Aabb) {
    let part = |min: Vec3, max: Vec3| Aabb { min, max };
    let body = part(Vec3::new(-2.2, 0.3, -0.9), Vec3::new(2.2, 1.1, 0.9));
    let cabin = part(Vec3::new(-1.2, 1.1, -0.8), Vec3::new(1.2, 1.6, 0.8));
    let mut triangles = body.triangles();
    triangles.extend(cabin.triangles());
    for (x, z) in [(-1.5, -0.75), (-1.5, 0.75), (1.5, -0.75), (1.5, 0.75)] {
        let wheel = part(
            Vec3::new(x - 0.3, 0.0, z - 0.15),
            Vec3::new(x + 0.3, 0.6, z + 0.15),
        );
        triangles.extend(wheel.triangles());
    }
    (triangles, body)
}

/// How one car moves: round the rectangle `min`..`max` (x, z) counter-clockwise seen from
/// above, `speed` metres a frame, starting `phase` metres along it.
#[derive(Clone, Debug)]
pub(crate) struct Motion {
    min: (f32, f32),
    max: (f32, f32),
    /// Metres a frame: no point of the car moves farther than this in a frame.
    pub(crate) speed: f32,
    phase: f32,
    shape: Vec<[Vec3; 3]>,
    solid: Aabb,
}

impl Motion {
    fn perimeter(&self) -> f32 {
        2.0 * ((self.max.0 - self.min.0) + (self.max.1 - self.min.1))
    }

    /// Where the car is at `frame` on its loop, and whether it is heading along z.
    fn place(&self, frame: u32) -> (Vec3, bool) {
        // f64 keeps long walks exact enough; the remainder is the distance along the loop.
        let along = (self.phase as f64 + self.speed as f64 * frame as f64)
            .rem_euclid(self.perimeter() as f64) as f32;
        let (w, d) = (self.max.0 - self.min.0, self.max.1 - self.min.1);
        let (x0, z0, x1, z1) = (self.min.0, self.min.1, self.max.0, self.max.1);
        if along < w {
            (Vec3::new(x0 + along, 0.0, z1), false)
        } else if along < w + d {
            (Vec3::new(x1, 0.0, z1 - (along - w)), true)
        } else if along < 2.0 * w + d {
            (Vec3::new(x1 - (along - w - d), 0.0, z0), false)
        } else {
            (Vec3::new(x0, 0.0, z0 + (along - 2.0 * w - d)), true)
        }
    }

    /// The car as it stands at `frame`.
    pub(crate) fn pose(&self, frame: u32) -> SceneObject {
        let (at, along_z) = self.place(frame);
        // A quarter turn about y (x' = z, z' = -x) keeps the winding counter-clockwise.
        let turn = |p: Vec3| {
            if along_z {
                Vec3::new(p.z, p.y, -p.x)
            } else {
                p
            }
        };
        let moved = |p: Vec3| turn(p) + at;
        let triangles = self.shape.iter().map(|t| t.map(moved)).collect();
        let solid = Aabb::around(self.solid.corners().map(moved)).expect("eight corners");
        SceneObject::new(triangles)
            .expect("a car has faces")
            .with_solids(vec![solid])
    }
}

/// The `traffic` scene: the city of `options.city` and `cars_per_block` cars round every
/// block, walked as the city is.
pub fn traffic(options: &TrafficOptions) -> WorkloadScene {
    let (mut objects, camera, layout) = city_parts(&options.city);
    let cars = options.cars_per_block.min(MAX_CARS_PER_BLOCK);
    // A generator of its own (the seed mixed with "traffic" in ASCII), so the buildings are
    // the city's with the same seed.
    let mut rng = SplitMix64(options.city.seed ^ 0x0074_7261_6666_6963);
    let mut motions: Vec<Option<Motion>> = vec![None; objects.len()];
    let (shape, solid) = car_shape();
    for j in 0..layout.blocks {
        for i in 0..layout.blocks {
            for _ in 0..cars {
                let motion = block_loop(&layout, i, j, &mut rng, &shape, solid);
                objects.push(motion.pose(0));
                motions.push(Some(motion));
            }
        }
    }
    WorkloadScene::new("traffic", objects, camera)
        .expect("a city has buildings")
        .with_motions(motions)
}

/// A car round block `(i, j)` at a seeded speed and starting point.
fn block_loop(
    layout: &StreetLayout,
    i: u32,
    j: u32,
    rng: &mut SplitMix64,
    shape: &[[Vec3; 3]],
    solid: Aabb,
) -> Motion {
    let pitch = StreetLayout::PITCH;
    let west = layout.west + i as f32 * pitch;
    let north = layout.first_street_z - j as f32 * pitch;
    let mut motion = Motion {
        min: (west + LANE_OFFSET, north - pitch + LANE_OFFSET),
        max: (west + pitch - LANE_OFFSET, north - LANE_OFFSET),
        speed: rng.range(SPEED_RANGE.0, SPEED_RANGE.1),
        phase: 0.0,
        shape: shape.to_vec(),
        solid,
    };
    motion.phase = rng.range(0.0, motion.perimeter());
    motion
}

#[cfg(test)]
mod tests {
    use super::*;

    fn test_loop() -> Motion {
        let (shape, solid) = car_shape();
        Motion {
            min: (0.0, -10.0),
            max: (20.0, 0.0),
            speed: 1.0,
            phase: 0.0,
            shape,
            solid,
        }
    }

    #[test]
    fn a_car_goes_round_its_loop_at_its_speed() {
        let car = test_loop();
        // The loop is 60 m round: 20 along +x at z = 0, 10 along -z at x = 20, and back.
        assert_eq!(car.place(0), (Vec3::new(0.0, 0.0, 0.0), false));
        assert_eq!(car.place(5), (Vec3::new(5.0, 0.0, 0.0), false));
        assert_eq!(car.place(25), (Vec3::new(20.0, 0.0, -5.0), true));
        assert_eq!(car.place(35), (Vec3::new(15.0, 0.0, -10.0), false));
        assert_eq!(car.place(55), (Vec3::new(0.0, 0.0, -5.0), true));
        assert_eq!(car.place(60), car.place(0));
        for frame in 0..130 {
            let step = car.place(frame + 1).0 - car.place(frame).0;
            assert!(step.length() <= car.speed + 1e-4, "frame {frame}: {step}");
        }
    }

    #[test]
    fn a_turned_car_keeps_its_faces_outward_and_its_box_centred() {
        let car = test_loop();
        let turned = car.pose(25);
        let centre = turned.bounds.centre();
        assert!((centre.x - 20.0).abs() < 1e-4 && (centre.z + 5.0).abs() < 1e-4);
        // Turned, the car is long along z.
        let extent = turned.bounds.max - turned.bounds.min;
        assert!(extent.z > extent.x);
        // Each box part is twelve triangles; each faces away from its part's centre.
        for part in turned.triangles.chunks(12) {
            let centre = Aabb::around(part.iter().flatten().copied())
                .unwrap()
                .centre();
            for [a, b, c] in part {
                let normal = (*b - *a).cross(*c - *a);
                let middle = (*a + *b + *c) / 3.0;
                assert!(normal.dot(middle - centre) > 0.0, "inward face at {middle}");
            }
        }
    }

    #[test]
    fn traffic_is_the_city_with_cars() {
        let options = TrafficOptions {
            city: CityOptions {
                blocks: 2,
                detail: 0,
                seed: 4,
            },
            cars_per_block: 2,
        };
        let scene = traffic(&options);
        let city = super::super::city(&options.city);
        assert_eq!(scene.object_count(), city.object_count() + 2 * 2 * 2);
        assert!(scene.is_dynamic() && !city.is_dynamic());
        let (a, b) = (scene.posed(3), scene.posed(3));
        let boxes = |s: &WorkloadScene| s.objects.iter().map(|o| o.bounds).collect::<Vec<_>>();
        assert_eq!(boxes(&a), boxes(&b));
        assert_ne!(boxes(&scene.posed(0)), boxes(&a));
        // Every pose stays inside the scene's bounds.
        for frame in [0, 50, 333] {
            for object in &scene.posed(frame).objects {
                assert_eq!(scene.bounds.union(object.bounds), scene.bounds);
            }
        }
    }
}
