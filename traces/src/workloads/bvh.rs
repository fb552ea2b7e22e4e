//! A bounding volume hierarchy over a scene's objects: binary, split at the median object
//! along the longest axis of the objects' centres, one object a leaf.

use super::SceneObject;
use crate::geometry::Aabb;

/// What a node holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum NodeContent {
    /// Objects `order[first..first + count]`.
    Leaf { first: u32, count: u32 },
    /// Two child nodes.
    Inner { children: [u32; 2] },
}

#[derive(Clone, Debug)]
pub(crate) struct BvhNode {
    pub(crate) bounds: Aabb,
    pub(crate) content: NodeContent,
}

/// Node 0 is the root.
#[derive(Clone)]
pub(crate) struct Bvh {
    pub(crate) nodes: Vec<BvhNode>,
    /// Object indices, leaf by leaf.
    pub(crate) order: Vec<u32>,
}

/// Objects per leaf at most.
const LEAF_OBJECTS: usize = 1;

impl Bvh {
    pub(crate) fn build(objects: &[SceneObject]) -> Bvh {
        let mut bvh = Bvh {
            nodes: Vec::with_capacity(objects.len() * 2),
            order: (0..objects.len() as u32).collect(),
        };
        if !objects.is_empty() {
            bvh.build_node(objects, 0, objects.len());
        }
        bvh
    }

    /// Build the node over `order[first..end]` and return its index.
    fn build_node(&mut self, objects: &[SceneObject], first: usize, end: usize) -> u32 {
        let members = &mut self.order[first..end];
        let bounds = members
            .iter()
            .map(|&i| objects[i as usize].bounds)
            .reduce(Aabb::union)
            .unwrap_or(objects[0].bounds);
        let index = self.nodes.len() as u32;
        if members.len() <= LEAF_OBJECTS {
            self.nodes.push(BvhNode {
                bounds,
                content: NodeContent::Leaf {
                    first: first as u32,
                    count: members.len() as u32,
                },
            });
            return index;
        }
        let extent = bounds.max - bounds.min;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        // Ties broken by object index: the hierarchy, and so the traversal, is reproducible.
        members.sort_by(|&a, &b| {
            let key = |i: u32| objects[i as usize].bounds.centre()[axis];
            key(a).total_cmp(&key(b)).then(a.cmp(&b))
        });
        self.nodes.push(BvhNode {
            bounds,
            content: NodeContent::Leaf { first: 0, count: 0 },
        });
        let middle = first + (end - first) / 2;
        let left = self.build_node(objects, first, middle);
        let right = self.build_node(objects, middle, end);
        self.nodes[index as usize].content = NodeContent::Inner {
            children: [left, right],
        };
        index
    }

    /// The objects of a leaf.
    pub(crate) fn leaf_objects(&self, first: u32, count: u32) -> &[u32] {
        &self.order[first as usize..(first + count) as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn unit_object_at(x: f32) -> SceneObject {
        SceneObject::new(vec![[
            Vec3::new(x, 0.0, 0.0),
            Vec3::new(x + 1.0, 0.0, 0.0),
            Vec3::new(x, 1.0, 0.0),
        ]])
        .unwrap()
    }

    #[test]
    fn every_object_in_exactly_one_leaf_inside_every_ancestor() {
        let objects: Vec<SceneObject> = (0..13)
            .map(|i| unit_object_at((i * 7 % 13) as f32))
            .collect();
        let bvh = Bvh::build(&objects);
        let mut seen = vec![0; objects.len()];
        let mut stack = vec![(0u32, None::<Aabb>)];
        while let Some((node, parent)) = stack.pop() {
            let n = &bvh.nodes[node as usize];
            if let Some(p) = parent {
                assert_eq!(p.union(n.bounds), p, "child box outside its parent");
            }
            match n.content {
                NodeContent::Leaf { first, count } => {
                    for &o in bvh.leaf_objects(first, count) {
                        seen[o as usize] += 1;
                        assert_eq!(n.bounds.union(objects[o as usize].bounds), n.bounds);
                    }
                }
                NodeContent::Inner { children } => {
                    stack.extend(children.map(|c| (c, Some(n.bounds))));
                }
            }
        }
        assert_eq!(seen, vec![1; objects.len()]);
    }
}
