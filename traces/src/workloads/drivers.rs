//! The frame loop, the front-to-back traversal queue every driver shares, and the frustum
//! driver (the baseline).

use super::bvh::{Bvh, NodeContent};
use super::collision::CollisionDriver;
use super::dynamic_grid::DynamicGridDriver;
use super::grid::GridDriver;
use super::hierarchical::HierarchicalDriver;
use super::hom::HomDriver;
use super::large::LargeOccluderDriver;
use super::occlusion_buffer_grid::OcclusionBufferGrid;
use super::project::Frustum;
use super::raycast::{RayMask, RaycastDriver};
use super::render::{CommandObserver, Renderer};
use super::{
    DriverKind, DriverOptions, FrameView, GridVariant, Walk, WorkloadScene, WorkloadStats,
};
use crate::golden::EventSink;
use glam::Vec3;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::time::Instant;

/// Hierarchy nodes in front-to-back order of their boxes' distance from the eye; equal
/// distances in node order, so the traversal is reproducible.
pub(crate) struct FrontToBack<T> {
    heap: BinaryHeap<Reverse<(u32, u32, u32)>>,
    /// Payloads the entries refer to by index.
    payloads: Vec<T>,
    eye: Vec3,
}

impl<T> FrontToBack<T> {
    pub(crate) fn new(eye: Vec3) -> FrontToBack<T> {
        FrontToBack {
            heap: BinaryHeap::new(),
            payloads: Vec::new(),
            eye,
        }
    }

    pub(crate) fn push(&mut self, bvh: &Bvh, node: u32, payload: T) {
        // Non-negative floats order as their bit patterns do.
        let distance = bvh.nodes[node as usize].bounds.distance_squared(self.eye);
        self.payloads.push(payload);
        let slot = (self.payloads.len() - 1) as u32;
        self.heap.push(Reverse((distance.to_bits(), node, slot)));
    }

    /// The nearest node and its payload's index.
    pub(crate) fn pop(&mut self) -> Option<(u32, &T)> {
        let Reverse((_, node, slot)) = self.heap.pop()?;
        Some((node, &self.payloads[slot as usize]))
    }
}

/// The drivers' state between frames. A dynamic scene's hierarchy is rebuilt every frame,
/// so there each frame starts afresh (node indices and cached planes would name other
/// boxes); the dynamic grid keeps its own state, made for moving objects.
struct DriverStates {
    hierarchical: HierarchicalDriver,
    grid: GridDriver,
    obuffer_grid: OcclusionBufferGrid,
    collision: CollisionDriver,
    hom: Option<HomDriver>,
    large: Option<LargeOccluderDriver>,
}

impl DriverStates {
    fn new(options: &DriverOptions, scene: &WorkloadScene, walk: &Walk) -> DriverStates {
        DriverStates {
            hierarchical: HierarchicalDriver::new(options, scene.bvh.nodes.len()),
            grid: GridDriver::new(options, walk.width, walk.height),
            obuffer_grid: OcclusionBufferGrid::new(options, walk.width, walk.height),
            collision: CollisionDriver::new(options),
            hom: (options.kind == DriverKind::Hom).then(|| HomDriver::new(options, scene)),
            large: (options.kind == DriverKind::LargeOccluders)
                .then(|| LargeOccluderDriver::new(scene)),
        }
    }
}

/// The buffers of a walk the size of its viewport, each asked of the allocator by the
/// caller ([`crate::golden::ask_for_viewport_buffer`]): the golden model's depths, and the
/// raycast driver's mask.
pub(crate) struct ViewportBuffers {
    pub golden: crate::golden::GoldenModel,
    pub rays: Option<RayMask>,
}

impl ViewportBuffers {
    pub(crate) fn for_walk(
        walk: &Walk,
        kind: DriverKind,
    ) -> Result<ViewportBuffers, crate::golden::ViewportBufferTooLarge> {
        let golden =
            crate::golden::GoldenModel::try_with_profile(walk.width, walk.height, walk.raster)?;
        let rays = match kind {
            DriverKind::Raycast => Some(RayMask::try_new(walk.width, walk.height)?),
            _ => None,
        };
        Ok(ViewportBuffers { golden, rays })
    }
}

pub(crate) fn run<S: EventSink, O: CommandObserver>(
    scene: &WorkloadScene,
    options: &DriverOptions,
    walk: &Walk,
    buffers: ViewportBuffers,
    sink: &mut S,
    observer: &mut O,
) -> Result<WorkloadStats, S::Error> {
    let ViewportBuffers { golden, rays } = buffers;
    let mut renderer = Renderer::new(golden, sink, observer);
    renderer.set_waits_for_answers(options.query_delay_frames == 0);
    let mut states = DriverStates::new(options, scene, walk);
    let mut dynamic_grid =
        (options.kind == DriverKind::DynamicGrid).then(|| DynamicGridDriver::new(options, scene));
    let mut raycast = rays.map(|rays| RaycastDriver::new(options, rays));
    let mut stats = WorkloadStats {
        scene_triangles: scene.triangle_count(),
        ..WorkloadStats::default()
    };
    for frame in 0..walk.frames {
        let started = Instant::now();
        let view = scene.frame_view(frame, walk);
        let posed = scene.posed(frame);
        if scene.is_dynamic() && frame > 0 {
            states = DriverStates::new(options, &posed, walk);
        }
        renderer.start_frame()?;
        let s = &mut states;
        match options.kind {
            DriverKind::Frustum => frustum_frame(&posed, &view, &mut renderer)?,
            DriverKind::Hierarchical => {
                s.hierarchical.frame(frame, &posed, &view, &mut renderer)?
            }
            DriverKind::Collision => {
                s.hierarchical.frame(frame, &posed, &view, &mut renderer)?;
                let test = s
                    .collision
                    .test(frame, &posed, walk, &view, &mut renderer)?;
                renderer.stats.collision = test;
            }
            DriverKind::LazyGrid | DriverKind::BusyGrid => match options.grid_variant {
                GridVariant::ZBuffer => s.grid.frame(&posed, &view, &mut renderer)?,
                GridVariant::OcclusionBuffer => {
                    s.obuffer_grid.frame(&posed, &view, &mut renderer)?
                }
            },
            DriverKind::Hom => {
                if let Some(hom) = s.hom.as_mut() {
                    hom.frame(&posed, &view, &mut renderer)?
                }
            }
            DriverKind::LargeOccluders => {
                if let Some(large) = s.large.as_mut() {
                    large.frame(&posed, &view, &mut renderer)?
                }
            }
            DriverKind::DynamicGrid => {
                if let Some(grid) = dynamic_grid.as_mut() {
                    grid.frame(frame, scene, &posed, &view, &mut renderer)?
                }
            }
            DriverKind::Raycast => {
                s.hierarchical.frame(frame, &posed, &view, &mut renderer)?;
                if let Some(raycast) = raycast.as_mut() {
                    raycast.frame(&posed, &view, &mut renderer)?;
                }
            }
        }
        renderer.swap()?;
        let (frame_stats, timing) = renderer.finish_frame(started);
        if renderer.observe_frame(&frame_stats) {
            stats.frames.push(frame_stats);
            stats.timing.push(timing);
        }
    }
    Ok(stats)
}

/// Draw every leaf whose box meets the view frustum, front to back.
fn frustum_frame<S: EventSink, O: CommandObserver>(
    scene: &WorkloadScene,
    view: &FrameView,
    renderer: &mut Renderer<S, O>,
) -> Result<(), S::Error> {
    let bvh = &scene.bvh;
    if bvh.nodes.is_empty() {
        return Ok(());
    }
    let frustum = Frustum::new(&view.view_projection);
    let mut queue = FrontToBack::new(view.eye);
    queue.push(bvh, 0, ());
    while let Some((node, _)) = queue.pop() {
        renderer.visit_node();
        let node = &bvh.nodes[node as usize];
        if !frustum.may_see(&node.bounds) {
            continue;
        }
        match node.content {
            NodeContent::Leaf { first, count } => {
                renderer.draw_leaf(scene, first, count, &view.view_projection)?;
            }
            NodeContent::Inner { children } => {
                for child in children {
                    queue.push(bvh, child, ());
                }
            }
        }
    }
    Ok(())
}
