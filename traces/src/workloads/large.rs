//! Occlusion culling with large occluders (Coorg and Teller; seed 004): object-space tests
//! on the host, no occlusion queries.
//!
//! Every frame:
//! 1. Occluder selection (section 3.1): the occluder polygons are the scene's large convex
//!    faces (two coplanar triangles sharing an edge and forming a convex quad, or a single
//!    triangle, of at least a hundredth of the median object's squared diagonal); those in the view frustum facing the eye are ranked by the area-angle
//!    estimate of their solid angle, -A (N . V) / |D|^2, and the 32 largest kept (the
//!    paper's 32 a direction).
//! 2. The hierarchy (Figure 9) is traversed with the occluder set: a node is culled when
//!    one occluder occludes its box fully (the eye satisfies every supporting plane of the
//!    pair and lies across the occluder's plane from the box); otherwise only the occluders
//!    that may partially occlude it (the eye satisfies every separating plane) go on to its
//!    children; a node no occluder even partially occludes is drawn whole (frustum culling
//!    only below it).
//! 3. Temporal coherence (section 3): the planes of every occluder-node pair are cached
//!    between frames and computed only the first time; a pair not used in a frame leaves
//!    the cache. A node found occluded keeps its occluder: the next frame re-tests that
//!    relation first, and only an event (the eye crossing one of its planes) sends the node
//!    through the full test again.
//!
//! Choices the paper leaves open, and what is done here:
//! - The spatial hierarchy is the scene's bounding volume hierarchy (the paper's kD-tree),
//!   and occluders are chosen every frame rather than from a table precomputed per kD-tree
//!   leaf and discretised view direction; V in the metric is the direction from the eye to
//!   the occluder's centre (what the solid angle depends on), not the view direction, so
//!   walls along a street seen obliquely still rank.
//! - Tangent planes are found by trying every box corner with every occluder edge (the
//!   naive method the paper's table lookup speeds up; the planes are the same).
//! - Only single convex occluders occlude: connected occluders (the shared-edge rule of
//!   Figure 3) and detail objects (section 3.2) are not implemented.
//! - Conservative margins: boxes grow by the scene's box margin, each occluder polygon
//!   shrinks by it towards its centroid, and every plane test needs the eye inside by a
//!   millionth of the scene's size, so rounding and the rasterizer's snapping never cull a
//!   visible pixel.
//! - Host costs: each node a node visit and a box test; each tangent plane computed costs
//!   eight host tests (a corner each), each plane the eye is tested against one.

use super::bvh::NodeContent;
use super::project::Frustum;
use super::render::{CommandObserver, Renderer};
use super::{FrameView, WorkloadScene};
use crate::geometry::Aabb;
use crate::golden::EventSink;
use glam::{DVec3, Vec3};
use std::collections::HashMap;

/// Occluders kept a frame.
const OCCLUDERS: usize = 32;

/// A convex planar occluder polygon (counter-clockwise seen from its front).
#[derive(Clone, Debug)]
pub(crate) struct Polygon {
    vertices: Vec<DVec3>,
    normal: DVec3,
    centre: DVec3,
    area: f64,
}

/// A plane: inside where `normal . p + offset > 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Plane {
    normal: DVec3,
    offset: f64,
}

impl Plane {
    fn through(a: DVec3, b: DVec3, c: DVec3) -> Plane {
        let normal = (b - a).cross(c - a);
        Plane {
            normal,
            offset: -normal.dot(a),
        }
    }

    fn flipped(self) -> Plane {
        Plane {
            normal: -self.normal,
            offset: -self.offset,
        }
    }

    /// Signed distance (scaled by the normal's length).
    fn side(&self, p: DVec3) -> f64 {
        self.normal.dot(p) + self.offset
    }

    /// Is `p` inside by more than `margin` (in distance units)?
    fn holds(&self, p: DVec3, margin: f64) -> bool {
        self.side(p) > margin * self.normal.length()
    }
}

/// The planes of one occluder and one box.
#[derive(Clone, Debug)]
struct Relation {
    /// The occluder's plane oriented away from the box (None: the box meets it).
    across: Option<Plane>,
    /// Supporting planes, oriented towards the occluder (and the box).
    supporting: Vec<Plane>,
    /// Separating planes, oriented towards the occluder.
    separating: Vec<Plane>,
}

/// What an occluder does to a box from the eye.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Occlusion {
    None,
    Partial,
    Full,
}

impl Relation {
    fn new(polygon: &Polygon, corners: &[DVec3; 8]) -> Relation {
        let n = polygon.vertices.len();
        let own = Plane {
            normal: polygon.normal,
            offset: -polygon.normal.dot(polygon.centre),
        };
        let across = if corners.iter().all(|&c| own.side(c) < 0.0) {
            Some(own)
        } else if corners.iter().all(|&c| own.side(c) > 0.0) {
            Some(own.flipped())
        } else {
            None
        };
        let (mut supporting, mut separating) = (Vec::new(), Vec::new());
        for i in 0..n {
            let (p, q) = (polygon.vertices[i], polygon.vertices[(i + 1) % n]);
            for &c in corners {
                let mut plane = Plane::through(p, q, c);
                if plane.normal.length_squared() == 0.0 {
                    continue;
                }
                // Oriented towards the occluder: its centre inside.
                if plane.side(polygon.centre) < 0.0 {
                    plane = plane.flipped();
                }
                let sides: Vec<f64> = corners.iter().map(|&k| plane.side(k)).collect();
                let tolerance = 1e-9 * plane.normal.length();
                if sides.iter().all(|&s| s >= -tolerance) {
                    supporting.push(plane);
                } else if sides.iter().all(|&s| s <= tolerance) {
                    separating.push(plane);
                }
            }
        }
        Relation {
            across,
            supporting,
            separating,
        }
    }

    /// The occlusion from `eye`, and the planes tested.
    fn test(&self, eye: DVec3, margin: f64, tests: &mut u64) -> Occlusion {
        let Some(across) = self.across else {
            *tests += 1;
            return Occlusion::Partial;
        };
        *tests += 1;
        if !across.holds(eye, margin) {
            // The eye is on the box's side of the occluder's plane (or on it).
            return if across.side(eye) < 0.0 {
                Occlusion::None
            } else {
                Occlusion::Partial
            };
        }
        let all = |planes: &[Plane], tests: &mut u64| {
            planes.iter().all(|plane| {
                *tests += 1;
                plane.holds(eye, margin)
            })
        };
        if !self.supporting.is_empty() && all(&self.supporting, tests) {
            return Occlusion::Full;
        }
        if self.separating.iter().any(|plane| {
            *tests += 1;
            plane.side(eye) < 0.0
        }) {
            return Occlusion::None;
        }
        Occlusion::Partial
    }
}

/// The scene's convex faces as occluder polygons, each shrunk by `margin` towards its
/// centroid.
pub(crate) fn occluder_polygons(scene: &WorkloadScene, margin: f32) -> Vec<Polygon> {
    let mut diagonals: Vec<f32> = scene
        .objects
        .iter()
        .map(|o| (o.bounds.max - o.bounds.min).length())
        .collect();
    diagonals.sort_by(f32::total_cmp);
    let median = diagonals.get(diagonals.len() / 2).copied().unwrap_or(0.0) as f64;
    // Large: at least a tenth of the median object's diagonal squared.
    let least_area = (median / 10.0).powi(2);
    let mut polygons = Vec::new();
    for object in &scene.objects {
        let t = &object.triangles;
        let mut i = 0;
        while i < t.len() {
            let quad = (i + 1 < t.len())
                .then(|| convex_quad(&t[i], &t[i + 1]))
                .flatten();
            let vertices: Vec<Vec3> = match quad {
                Some(quad) => {
                    i += 2;
                    quad.to_vec()
                }
                None => {
                    i += 1;
                    t[i - 1].to_vec()
                }
            };
            if let Some(p) = polygon(&vertices, margin as f64) {
                if p.area >= least_area {
                    polygons.push(p);
                }
            }
        }
    }
    polygons
}

/// Two triangles sharing an edge, coplanar, whose union is a convex quad: the quad, in the
/// triangles' winding.
fn convex_quad(a: &[Vec3; 3], b: &[Vec3; 3]) -> Option<[Vec3; 4]> {
    for i in 0..3 {
        let (p, q, r) = (a[i], a[(i + 1) % 3], a[(i + 2) % 3]);
        // b must hold the edge q -> p (the opposite direction) and a fourth vertex.
        for j in 0..3 {
            if b[j] == q && b[(j + 1) % 3] == p {
                let s = b[(j + 2) % 3];
                let quad = [p, s, q, r];
                let na = (q - p).cross(r - p);
                let nb = (p - q).cross(s - q);
                let coplanar =
                    na.cross(nb).length() <= 1e-5 * na.length() * nb.length() && na.dot(nb) > 0.0;
                let convex = (0..4).all(|k| {
                    let (u, v, w) = (quad[k], quad[(k + 1) % 4], quad[(k + 2) % 4]);
                    (v - u).cross(w - v).dot(na) > 0.0
                });
                return (coplanar && convex).then_some(quad);
            }
        }
    }
    None
}

fn polygon(vertices: &[Vec3], margin: f64) -> Option<Polygon> {
    let v: Vec<DVec3> = vertices.iter().map(|p| p.as_dvec3()).collect();
    let centre = v.iter().copied().sum::<DVec3>() / v.len() as f64;
    let mut cross = DVec3::ZERO;
    for k in 1..v.len() - 1 {
        cross += (v[k] - v[0]).cross(v[k + 1] - v[0]);
    }
    let area = cross.length() * 0.5;
    if area == 0.0 {
        return None;
    }
    // Shrink towards the centroid by the margin (at most halfway).
    let shrunk = v
        .iter()
        .map(|&p| {
            let to_centre = centre - p;
            let length = to_centre.length();
            p + to_centre * (margin / length).min(0.5)
        })
        .collect();
    Some(Polygon {
        vertices: shrunk,
        normal: cross / (2.0 * area),
        centre,
        area,
    })
}

pub(crate) struct LargeOccluderDriver {
    polygons: Vec<Polygon>,
    /// (node, polygon) -> the pair's planes, kept while the pair is used.
    cache: HashMap<(u32, u32), Relation>,
    /// Per node: the polygon that occluded it last frame.
    occluded_by: Vec<Option<u32>>,
}

impl LargeOccluderDriver {
    pub(crate) fn new(scene: &WorkloadScene) -> LargeOccluderDriver {
        LargeOccluderDriver {
            polygons: occluder_polygons(scene, scene.box_margin),
            cache: HashMap::new(),
            occluded_by: vec![None; scene.bvh.nodes.len()],
        }
    }

    pub(crate) fn frame<S: EventSink, O: CommandObserver>(
        &mut self,
        scene: &WorkloadScene,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        let bvh = &scene.bvh;
        if bvh.nodes.is_empty() {
            return Ok(());
        }
        let vp = &view.view_projection;
        let frustum = Frustum::new(vp);
        let eye = view.eye.as_dvec3();
        let size = (scene.bounds.max - scene.bounds.min).length() as f64;
        let margin = 1e-6 * size;
        // 1. The occluders: the largest area-angles among the faces in view facing the eye.
        let mut ranked: Vec<(f64, u32)> = Vec::new();
        for (i, p) in self.polygons.iter().enumerate() {
            let d = p.centre - eye;
            let facing = -p.normal.dot(d.normalize_or_zero());
            if facing <= 0.0 {
                continue;
            }
            let metric = p.area * facing / d.length_squared().max(1e-12);
            ranked.push((metric, i as u32));
        }
        renderer.host_tests(self.polygons.len() as u64);
        ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let mut occluders: Vec<u32> = Vec::new();
        for &(_, i) in &ranked {
            if occluders.len() == OCCLUDERS {
                break;
            }
            let p = &self.polygons[i as usize];
            let bounds = Aabb::around(p.vertices.iter().map(|v| v.as_vec3()));
            if bounds.is_some_and(|b| frustum.may_see(&b)) {
                occluders.push(i);
            }
        }
        // 2. The hierarchy against them.
        let mut used: HashMap<(u32, u32), Relation> = HashMap::new();
        let mut tests = 0u64;
        let mut stack: Vec<(u32, Vec<u32>)> = vec![(0, occluders)];
        while let Some((index, set)) = stack.pop() {
            renderer.visit_node();
            let node = &bvh.nodes[index as usize];
            if !frustum.may_see(&node.bounds) {
                continue;
            }
            let corners = node
                .bounds
                .inflated(scene.box_margin)
                .corners()
                .map(|c| c.as_dvec3());
            let mut partial = Vec::new();
            let mut hidden = false;
            // The last frame's occluder first: only an event sends the node on.
            let mut order = set.clone();
            if let Some(last) = self.occluded_by[index as usize] {
                if let Some(k) = order.iter().position(|&i| i == last) {
                    order.swap(0, k);
                }
            }
            for &i in &order {
                let key = (index, i);
                let relation = match used.remove(&key).or_else(|| self.cache.remove(&key)) {
                    Some(relation) => relation,
                    None => {
                        let relation = Relation::new(&self.polygons[i as usize], &corners);
                        // Every tangent plane tried: a corner test each, 8 corners.
                        let tried = self.polygons[i as usize].vertices.len() as u64 * 8;
                        tests += tried * 8;
                        relation
                    }
                };
                let occlusion = relation.test(eye, margin, &mut tests);
                used.insert(key, relation);
                match occlusion {
                    Occlusion::Full => {
                        hidden = true;
                        self.occluded_by[index as usize] = Some(i);
                        break;
                    }
                    Occlusion::Partial => partial.push(i),
                    Occlusion::None => {}
                }
            }
            if hidden {
                continue;
            }
            self.occluded_by[index as usize] = None;
            match node.content {
                NodeContent::Leaf { first, count } => {
                    renderer.draw_leaf(scene, first, count, vp)?;
                }
                NodeContent::Inner { children } => {
                    // Front to back: the nearer child last on the stack.
                    let distance = |c: u32| bvh.nodes[c as usize].bounds.distance_squared(view.eye);
                    let [a, b] = children;
                    let (near, far) = if distance(b) < distance(a) {
                        (b, a)
                    } else {
                        (a, b)
                    };
                    stack.push((far, partial.clone()));
                    stack.push((near, partial));
                }
            }
        }
        renderer.host_tests(tests);
        // Pairs not used this frame leave the cache.
        self.cache = used;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_box_at(z: f64) -> [DVec3; 8] {
        let b = Aabb {
            min: Vec3::new(-1.0, -1.0, z as f32 - 1.0),
            max: Vec3::new(1.0, 1.0, z as f32 + 1.0),
        };
        b.corners().map(|c| c.as_dvec3())
    }

    /// A 4x4 square wall in the plane z = 0 facing +z.
    fn wall(half: f32) -> Polygon {
        let v = [
            Vec3::new(-half, -half, 0.0),
            Vec3::new(half, -half, 0.0),
            Vec3::new(half, half, 0.0),
            Vec3::new(-half, half, 0.0),
        ];
        polygon(&v, 0.0).unwrap()
    }

    #[test]
    fn a_box_straight_behind_a_wall_is_fully_occluded_only_from_in_front() {
        // The wall spans x, y in [-2, 2] at z = 0; the box [-1, 1]^2 x [-6, -4] behind it.
        // From (0, 0, 10) the box's silhouette (half-width 1 at distance 14) subtends less
        // than the wall's (half-width 2 at 10): full. From (30, 0, 10) the line of sight to
        // the box passes beside the wall: none. From behind the box: the eye is on the
        // box's side of the wall's plane: none.
        let relation = Relation::new(&wall(2.0), &unit_box_at(-5.0));
        assert!(relation.across.is_some());
        let mut tests = 0;
        assert_eq!(
            relation.test(DVec3::new(0.0, 0.0, 10.0), 1e-9, &mut tests),
            Occlusion::Full
        );
        assert_eq!(
            relation.test(DVec3::new(30.0, 0.0, 10.0), 1e-9, &mut tests),
            Occlusion::None
        );
        assert_eq!(
            relation.test(DVec3::new(0.0, 0.0, -20.0), 1e-9, &mut tests),
            Occlusion::None
        );
        // From (4, 0, 10): the ray to the box's far corner (1, *, -6) crosses z = 0 at
        // x = 4 - 3 * 10 / 16 = 2.125, beyond the wall's edge at 2: partly visible.
        assert_eq!(
            relation.test(DVec3::new(4.0, 0.0, 10.0), 1e-9, &mut tests),
            Occlusion::Partial
        );
        // From (3, 0, 10): the ray to (1, *, -6) crosses at 3 - 2 * 10 / 16 = 1.75 and the
        // ray to (-1, *, -4) at 3 - 4 * 10 / 14 = 0.14, both inside: full again.
        assert_eq!(
            relation.test(DVec3::new(3.0, 0.0, 10.0), 1e-9, &mut tests),
            Occlusion::Full
        );
        assert!(tests > 0);
    }

    #[test]
    fn two_triangles_of_a_box_face_make_one_convex_quad() {
        let b = Aabb {
            min: Vec3::ZERO,
            max: Vec3::new(2.0, 3.0, 4.0),
        };
        let t = b.triangles();
        let quad = convex_quad(&t[0], &t[1]).expect("a face");
        let p = polygon(&quad, 0.0).unwrap();
        // Faces of the box are 2x3, 2x4 or 3x4.
        assert!([6.0, 8.0, 12.0].contains(&p.area), "{}", p.area);
        // Triangles of different faces do not pair.
        assert!(convex_quad(&t[1], &t[2]).is_none());
    }
}
