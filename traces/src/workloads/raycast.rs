//! Ray casting supported by verbose occlusion queries (Bartz, Meissner, Huettner 1998,
//! section 5, "Support for Ray Casting"), in a scene that mixes a volume with polygons.
//!
//! The polygons are drawn first, as occlusion-driven rendering draws them (the
//! `hierarchical` driver). The volume (the scene's middle, see `WorkloadScene::volume`) is
//! cut into `bricks` x `bricks` x `bricks` subdivision entities; each brick in the view
//! frustum is drawn in verbose mode, one tile over its rectangle, with a buffer of
//! `buffer_entries` entries. Its hits are the pixels where the brick's front faces pass the
//! depth test, the pixels whose rays may still meet the brick's content; rays through the
//! others would be wasted. The host casts a ray segment through the brick at each chosen
//! pixel; the rays cast are the pixels some brick chose.
//!
//! Choices the paper leaves open, and what is done here:
//! - An overflowing buffer (its hits beyond the buffer lost, the list ended by -1) is not
//!   an error: the brick's rays go through every pixel of the box of its hits, which the
//!   brief record holds exactly whatever the buffer kept ([`choose_rays`]).
//! - A brick reaching the near plane has no usable front faces: its rays go through the
//!   whole viewport.
//! - Bricks are tested near to far; the order changes no answer (queries do not write the
//!   depth buffer) and the volume's colours are composited on the host, not drawn.
//! - Host costs: each brick a node visit and box test, each ray segment (a brick's chosen
//!   pixel) a host test.

use super::project::{project_box, BoxView, Frustum};
use super::render::{CommandObserver, Renderer};
use super::{DriverOptions, FrameView, WorkloadScene};
use crate::geometry::{to_clip, Aabb};
use crate::golden::{ask_for_viewport_buffer, EventSink, ViewportBufferTooLarge};
use crate::query::TileResult;
use crate::state::Rect;
use glam::Vec3;

/// One bit a pixel: the pixels a ray is cast through this frame.
pub(crate) struct RayMask {
    width: u32,
    bits: Vec<u64>,
}

impl RayMask {
    pub(crate) fn new(width: u32, height: u32) -> RayMask {
        RayMask {
            width,
            bits: vec![0; RayMask::words(width, height)],
        }
    }

    /// A mask for a user's viewport, or the error when the allocator will not give it.
    pub(crate) fn try_new(width: u32, height: u32) -> Result<RayMask, ViewportBufferTooLarge> {
        let words = RayMask::words(width, height);
        ask_for_viewport_buffer::<u64>("ray mask", (width, height), words)?;
        Ok(RayMask::new(width, height))
    }

    fn words(width: u32, height: u32) -> usize {
        (width as usize * height as usize).div_ceil(64)
    }

    /// No pixel with a ray (a new frame's).
    fn clear(&mut self) {
        self.bits.fill(0);
    }

    fn set(&mut self, x: u32, y: u32) {
        let i = y as usize * self.width as usize + x as usize;
        self.bits[i / 64] |= 1 << (i % 64);
    }

    #[cfg(test)]
    pub(crate) fn contains(&self, x: u32, y: u32) -> bool {
        let i = y as usize * self.width as usize + x as usize;
        self.bits[i / 64] & (1 << (i % 64)) != 0
    }

    fn set_rect(&mut self, rect: Rect) {
        for y in rect.y..rect.y + rect.height {
            for x in rect.x..rect.x + rect.width {
                self.set(x, y);
            }
        }
    }

    /// Pixels with a ray.
    pub(crate) fn count(&self) -> u64 {
        self.bits.iter().map(|w| w.count_ones() as u64).sum()
    }
}

/// How a brick's pixels were chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum RayChoice {
    /// No hit: the brick is hidden, no ray.
    Hidden,
    /// Its listed hits, all of them: this many pixels.
    Hits(u64),
    /// Its buffer overflowed: every pixel of the box of its hits, this many.
    HitBox(u64),
    /// No answer to choose by (the brick reaches the near plane): every pixel of this
    /// many it may cover.
    Everywhere(u64),
}

impl RayChoice {
    fn rays(self) -> u64 {
        match self {
            RayChoice::Hidden => 0,
            RayChoice::Hits(n) | RayChoice::HitBox(n) | RayChoice::Everywhere(n) => n,
        }
    }
}

/// Mark the pixels to cast rays through for one brick's tile: its hits when its buffer
/// held and listed them all; otherwise (an overflow, the list cut short and ended by -1)
/// every pixel of the box of its hits, which the brief record bounds exactly.
pub(crate) fn choose_rays(tile: &TileResult, rays: &mut RayMask) -> RayChoice {
    if tile.nohc == 0 {
        return RayChoice::Hidden;
    }
    if !tile.overflowed && tile.hits.is_fully_listed() && tile.hits.len() == tile.nohc {
        for &(x, y) in tile.hits.listed() {
            rays.set(x as u32, y as u32);
        }
        return RayChoice::Hits(tile.hits.len());
    }
    let hit_box = Rect::new(
        tile.xmin,
        tile.ymin,
        tile.xmax - tile.xmin + 1,
        tile.ymax - tile.ymin + 1,
    );
    rays.set_rect(hit_box);
    RayChoice::HitBox(hit_box.area())
}

pub(crate) struct RaycastDriver {
    bricks: u32,
    buffer_entries: u32,
    /// The frame's rays, one mask for the walk (made by the caller, where its allocation
    /// can fail with a workload's error).
    rays: RayMask,
}

impl RaycastDriver {
    pub(crate) fn new(options: &DriverOptions, rays: RayMask) -> RaycastDriver {
        RaycastDriver {
            bricks: options.volume_bricks,
            buffer_entries: options.verbose_buffer_entries,
            rays,
        }
    }

    /// The volume's bricks, near to far from `eye` (ties in brick order).
    fn bricks(&self, volume: &Aabb, eye: Vec3) -> Vec<Aabb> {
        let n = self.bricks;
        let size = (volume.max - volume.min) / n as f32;
        let mut bricks: Vec<(u32, usize, Aabb)> = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let min = volume.min + size * Vec3::new(i as f32, j as f32, k as f32);
                    let brick = Aabb {
                        min,
                        max: min + size,
                    };
                    let distance = brick.distance_squared(eye).to_bits();
                    bricks.push((distance, bricks.len(), brick));
                }
            }
        }
        bricks.sort_by_key(|&(distance, index, _)| (distance, index));
        bricks.into_iter().map(|(.., brick)| brick).collect()
    }

    /// After the polygons: each brick in verbose mode, and the rays its hits choose.
    pub(crate) fn frame<S: EventSink, O: CommandObserver>(
        &mut self,
        scene: &WorkloadScene,
        view: &FrameView,
        renderer: &mut Renderer<S, O>,
    ) -> Result<(), S::Error> {
        let frustum = Frustum::new(&view.view_projection);
        let vp = &view.view_projection;
        let bricks = self.bricks(&scene.volume, view.eye);
        let rays = &mut self.rays;
        rays.clear();
        let (mut segments, mut overflows) = (0u64, 0u64);
        for brick in bricks {
            renderer.visit_node();
            if !frustum.may_see(&brick) {
                continue;
            }
            let query_box = brick.inflated(scene.box_margin);
            let choice = match project_box(&query_box, vp, view.near, view.width, view.height) {
                BoxView::Outside => RayChoice::Hidden,
                BoxView::Near { .. } => {
                    let screen = Rect::new(0, 0, view.width, view.height);
                    rays.set_rect(screen);
                    RayChoice::Everywhere(screen.area())
                }
                BoxView::OnScreen { rect, .. } => {
                    let triangles = query_box
                        .triangles()
                        .into_iter()
                        .map(|t| t.map(|p| to_clip(vp, p)));
                    match renderer.verbose_query(vec![rect], self.buffer_entries, triangles)? {
                        Some(answer) => choose_rays(&answer.tiles[0], rays),
                        // No answer to read: every pixel of the rectangle may see the brick.
                        None => {
                            rays.set_rect(rect);
                            RayChoice::Everywhere(rect.area())
                        }
                    }
                }
            };
            segments += choice.rays();
            overflows += matches!(choice, RayChoice::HitBox(_)) as u64;
        }
        renderer.host_tests(segments);
        renderer.stats.rays_cast = rays.count();
        renderer.stats.rays_full_screen = view.width as u64 * view.height as u64;
        renderer.stats.overflowed_buffers = overflows;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::golden::{infallible, Discard};
    use crate::workloads::render::screen_quad;

    /// An 8 x 8 screen. A wall at depth 1/4 covers columns 0..4 (x < 4); a brick's face at
    /// depth 1/2 covers columns 2..6 of rows 0..2. The face passes only where the wall is
    /// not: columns 4 and 5 of rows 0 and 1, the four pixels (4,0) (5,0) (4,1) (5,1).
    fn brick_behind_a_wall(buffer_entries: u32) -> TileResult {
        let mut sink = Discard;
        let mut observer = ();
        let golden = crate::golden::GoldenModel::new(8, 8);
        let mut renderer = Renderer::new(golden, &mut sink, &mut observer);
        infallible(renderer.start_frame());
        let quarter = crate::event::DEPTH_ONE / 4;
        // The wall as an object whose world coordinates are its clip coordinates (w = 1),
        // drawn through the identity transform.
        let wall = screen_quad(Rect::new(0, 0, 4, 8), quarter, 8, 8)
            .map(|t| t.map(|[x, y, z, _]| Vec3::new(x, y, z)))
            .to_vec();
        let wall = super::super::SceneObject::new(wall).expect("two triangles");
        infallible(renderer.draw_object(0, &wall, &glam::Mat4::IDENTITY));
        let face = Rect::new(2, 0, 4, 2);
        let answer = infallible(renderer.verbose_query(
            vec![face],
            buffer_entries,
            screen_quad(face, 2 * quarter, 8, 8),
        ))
        .expect("an answer");
        answer.tiles[0].clone()
    }

    #[test]
    fn a_brick_casts_rays_through_its_hits_only() {
        // Room for all four hits: 8 record entries + 4.
        let tile = brick_behind_a_wall(12);
        let mut rays = RayMask::new(8, 8);
        assert_eq!(choose_rays(&tile, &mut rays), RayChoice::Hits(4));
        let chosen: Vec<(u32, u32)> = (0..8)
            .flat_map(|y| (0..8).map(move |x| (x, y)))
            .filter(|&(x, y)| rays.contains(x, y))
            .collect();
        assert_eq!(chosen, vec![(4, 0), (5, 0), (4, 1), (5, 1)]);
    }

    #[test]
    fn an_overflowing_buffer_casts_through_the_box_of_its_hits() {
        // Room for two entries: one hit and the -1 terminator; the record's box still
        // spans x 4..5, y 0..1, so the same four pixels are cast, by the box.
        let tile = brick_behind_a_wall(10);
        assert!(tile.overflowed);
        assert_eq!(tile.hits.len(), 1);
        let mut rays = RayMask::new(8, 8);
        assert_eq!(choose_rays(&tile, &mut rays), RayChoice::HitBox(4));
        assert_eq!(rays.count(), 4);
        assert!(rays.contains(4, 0) && rays.contains(5, 1) && !rays.contains(3, 0));
    }

    #[test]
    fn a_hidden_brick_casts_nothing() {
        let tile = TileResult::default();
        let mut rays = RayMask::new(8, 8);
        assert_eq!(choose_rays(&tile, &mut rays), RayChoice::Hidden);
        assert_eq!(rays.count(), 0);
    }
}
