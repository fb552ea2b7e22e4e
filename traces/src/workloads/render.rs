//! The drivers' side of the graphics API: commands go to the golden model, its events to
//! the caller's sink, and every command is accounted in the frame's statistics.

use super::{FrameStats, FrameTiming, SceneObject, WorkloadScene};
use crate::event::{Event, HostWork, DEPTH_ONE};
use crate::geometry::to_clip;
use crate::golden::{EventSink, GoldenModel};
use crate::query::{QueryMode, QueryResult, QuerySpec, BRIEF_RECORD_ENTRIES};
use crate::raster::PlaneDepths;
use crate::scene::Command;
use crate::state::{DepthFunc, Rect};
use glam::Mat4;
use std::time::{Duration, Instant};

/// Sees every scene command a driver executes, in order, and each frame's statistics as
/// the frame ends.
pub trait CommandObserver {
    fn command(&mut self, command: &Command);

    /// A frame ended with `stats`: whether the walkthrough keeps them (and the frame's
    /// timing) in its [`super::WorkloadStats`]. An observer that takes what it needs here
    /// says no, and the walkthrough's memory stays flat however many frames it runs.
    fn frame(&mut self, _stats: &FrameStats) -> bool {
        true
    }
}

/// Observes nothing.
impl CommandObserver for () {
    #[inline(always)]
    fn command(&mut self, _: &Command) {}
}

/// Keeps every command.
impl CommandObserver for Vec<Command> {
    fn command(&mut self, command: &Command) {
        self.push(command.clone());
    }
}

/// Counts the fragments on their way to the caller's sink.
struct CountingSink<'s, S> {
    inner: &'s mut S,
    fragments: u64,
}

impl<S: EventSink> EventSink for CountingSink<'_, S> {
    type Error = S::Error;
    #[inline(always)]
    fn event(&mut self, event: &Event) -> Result<(), S::Error> {
        if let Event::Fragment(_) = event {
            self.fragments += 1;
        }
        self.inner.event(event)
    }

    #[inline(always)]
    fn depth_plane(&mut self, plane: &PlaneDepths) -> Result<(), S::Error> {
        self.inner.depth_plane(plane)
    }
}

pub(crate) struct Renderer<'s, S, O> {
    golden: GoldenModel,
    sink: CountingSink<'s, S>,
    observer: &'s mut O,
    next_query_id: u32,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) stats: FrameStats,
    golden_time: Duration,
    /// The traversal's work since the last command, sent before the next one.
    host_work: HostWork,
    /// Whether the host reads each answer as soon as its query ends (a blocking `wait`);
    /// false when decisions use an earlier frame's answers.
    waits_for_answers: bool,
}

impl<'s, S: EventSink, O: CommandObserver> Renderer<'s, S, O> {
    /// A renderer drawing through `golden` (made for the walk's viewport by its caller,
    /// where its depth buffer's allocation can fail with a workload's error).
    pub(crate) fn new(golden: GoldenModel, sink: &'s mut S, observer: &'s mut O) -> Self {
        let crate::state::RenderState { width, height, .. } = *golden.state();
        Renderer {
            // Its queries' answers are read as they come, and no draw is conditioned.
            golden: golden.without_conditions(),
            sink: CountingSink {
                inner: sink,
                fragments: 0,
            },
            observer,
            next_query_id: 1,
            width,
            height,
            stats: FrameStats::default(),
            golden_time: Duration::ZERO,
            host_work: HostWork::default(),
            waits_for_answers: true,
        }
    }

    fn execute(&mut self, command: &Command) -> Result<Option<QueryResult>, S::Error> {
        if !self.host_work.is_empty() {
            let work = Command::Host(std::mem::take(&mut self.host_work));
            self.observer.command(&work);
            self.golden.execute(&work, &mut self.sink)?;
        }
        self.observer.command(command);
        self.golden.execute(command, &mut self.sink)
    }

    /// Back-face culling on or off (the frame starts with it on).
    pub(crate) fn set_culling(&mut self, on: bool) -> Result<(), S::Error> {
        self.execute(&Command::Cull(on)).map(|_| ())
    }

    /// The traversal visits a node and tests its box against the view frustum.
    pub(crate) fn visit_node(&mut self) {
        self.stats.nodes_visited += 1;
        self.host_work.nodes = self.host_work.nodes.saturating_add(1);
        self.host_work.boxes = self.host_work.boxes.saturating_add(1);
    }

    /// The host reads `pixels` of the framebuffer back and searches them for changes.
    pub(crate) fn read_back(&mut self, pixels: u64) {
        let pixels = u32::try_from(pixels).unwrap_or(u32::MAX);
        self.host_work.pixels = self.host_work.pixels.saturating_add(pixels);
    }

    /// The host makes `tests` comparisons of its own, without a query (occlusion-map pixels,
    /// depth-estimation entries, plane tests), each charged as a decision.
    pub(crate) fn host_tests(&mut self, tests: u64) {
        self.stats.host_tests += tests;
        let tests = u32::try_from(tests).unwrap_or(u32::MAX);
        self.host_work.decisions = self.host_work.decisions.saturating_add(tests);
    }

    /// Decisions use an earlier frame's answers: the host never blocks on a query.
    pub(crate) fn set_waits_for_answers(&mut self, waits: bool) {
        self.waits_for_answers = waits;
    }

    /// The frame ends (`swap`), after the traversal's last work.
    pub(crate) fn swap(&mut self) -> Result<(), S::Error> {
        self.execute(&Command::Swap).map(|_| ())
    }

    /// Clear, then state every frame relies on, so each frame stands alone: back faces
    /// culled (box counts need it), depth test LEQUAL with writes.
    pub(crate) fn start_frame(&mut self) -> Result<(), S::Error> {
        self.stats = FrameStats::default();
        self.golden_time = Duration::ZERO;
        for command in [
            Command::Clear,
            Command::Cull(true),
            Command::DepthTest(true),
            Command::DepthFunc(DepthFunc::Lequal),
            Command::DepthMask(true),
            Command::Scissor(None),
        ] {
            self.execute(&command)?;
        }
        Ok(())
    }

    /// The observer's [`CommandObserver::frame`] on a frame's statistics.
    pub(crate) fn observe_frame(&mut self, stats: &FrameStats) -> bool {
        self.observer.frame(stats)
    }

    /// The frame's statistics and the time spent in the golden model.
    pub(crate) fn finish_frame(&mut self, started: Instant) -> (FrameStats, FrameTiming) {
        let timing = FrameTiming {
            total: started.elapsed(),
            golden_model: self.golden_time,
        };
        (std::mem::take(&mut self.stats), timing)
    }

    /// Draw an object's triangles.
    pub(crate) fn draw_object(
        &mut self,
        index: u32,
        object: &SceneObject,
        view_projection: &Mat4,
    ) -> Result<(), S::Error> {
        let started = Instant::now();
        let fragments_before = self.sink.fragments;
        for triangle in &object.triangles {
            let clip = triangle.map(|p| to_clip(view_projection, p));
            self.execute(&Command::Tri(clip))?;
        }
        // An object is a draw of its own, as an application's glDrawArrays per object.
        self.execute(&Command::EndDraw)?;
        self.stats.draw_fragments += self.sink.fragments - fragments_before;
        self.stats.triangles_drawn += object.triangles.len() as u64;
        self.stats.objects_drawn.push(index);
        self.golden_time += started.elapsed();
        Ok(())
    }

    /// Draw the objects of the hierarchy leaf `first..first + count`, in its order.
    pub(crate) fn draw_leaf(
        &mut self,
        scene: &WorkloadScene,
        first: u32,
        count: u32,
        view_projection: &Mat4,
    ) -> Result<(), S::Error> {
        for &object in scene.bvh.leaf_objects(first, count) {
            self.draw_object(object, &scene.objects[object as usize], view_projection)?;
        }
        Ok(())
    }

    /// One brief occlusion query over `tiles` (non-empty, inside the viewport) drawing
    /// `triangles` (clip coordinates). None only if the golden model gave no answer.
    pub(crate) fn brief_query(
        &mut self,
        tiles: Vec<Rect>,
        triangles: impl IntoIterator<Item = [[f32; 4]; 3]>,
    ) -> Result<Option<QueryResult>, S::Error> {
        self.occlusion_query(QueryMode::Brief, BRIEF_RECORD_ENTRIES, tiles, triangles)
    }

    /// One verbose occlusion query: a brief query whose tiles also list their hits, up to
    /// `buffer_entries` entries a tile (the record's 8 included; -1 ends an overflow).
    pub(crate) fn verbose_query(
        &mut self,
        tiles: Vec<Rect>,
        buffer_entries: u32,
        triangles: impl IntoIterator<Item = [[f32; 4]; 3]>,
    ) -> Result<Option<QueryResult>, S::Error> {
        self.occlusion_query(QueryMode::Verbose, buffer_entries, tiles, triangles)
    }

    fn occlusion_query(
        &mut self,
        mode: QueryMode,
        buffer_entries: u32,
        tiles: Vec<Rect>,
        triangles: impl IntoIterator<Item = [[f32; 4]; 3]>,
    ) -> Result<Option<QueryResult>, S::Error> {
        let started = Instant::now();
        let fragments_before = self.sink.fragments;
        self.stats.queries += 1;
        self.stats.query_tiles += tiles.len() as u64;
        let id = self.next_query_id;
        self.next_query_id = self.next_query_id.wrapping_add(1);
        self.execute(&Command::Begin(QuerySpec {
            id,
            mode,
            buffer_entries,
            tiles,
        }))?;
        for triangle in triangles {
            self.stats.query_triangles += 1;
            self.execute(&Command::Tri(triangle))?;
        }
        let result = self.execute(&Command::End)?;
        if self.waits_for_answers {
            self.execute(&Command::Wait(id))?;
        }
        // The answer (now, or a later frame's) decides the node's fate.
        self.host_work.decisions = self.host_work.decisions.saturating_add(1);
        self.stats.query_fragments += self.sink.fragments - fragments_before;
        self.golden_time += started.elapsed();
        Ok(result)
    }

    /// A brief query over `tiles` (inside `band`) drawing one screen-aligned quad over `band`
    /// at window depth `depth` with depth writes off: a tile's hits are its pixels whose
    /// stored depth is at least the quad's, and the depth buffer is left as it was.
    pub(crate) fn band_probe(
        &mut self,
        tiles: Vec<Rect>,
        band: Rect,
        depth: u32,
    ) -> Result<Option<QueryResult>, S::Error> {
        self.execute(&Command::DepthMask(false))?;
        let quad = screen_quad(band, depth, self.width, self.height);
        let result = self.brief_query(tiles, quad)?;
        self.execute(&Command::DepthMask(true))?;
        Ok(result)
    }

    /// A brief query drawing, over each tile, a screen-aligned quad at that tile's window
    /// depth (24-bit units, 1 to 2^24 - 2). With LEQUAL a tile has hits exactly where the
    /// stored depth is at least the quad's: the query measures the depth buffer.
    pub(crate) fn depth_probe(
        &mut self,
        tiles: &[(Rect, u32)],
    ) -> Result<Option<QueryResult>, S::Error> {
        let quads: Vec<[[f32; 4]; 3]> = tiles
            .iter()
            .flat_map(|&(tile, depth)| screen_quad(tile, depth, self.width, self.height))
            .collect();
        self.brief_query(tiles.iter().map(|&(tile, _)| tile).collect(), quads)
    }
}

/// Two counter-clockwise triangles covering exactly the pixels of `tile` at window depth
/// `depth` (24-bit units), in clip coordinates with w = 1.
pub(crate) fn screen_quad(tile: Rect, depth: u32, width: u32, height: u32) -> [[[f32; 4]; 3]; 2] {
    let ndc = |pixel: u32, size: u32| (2.0 * pixel as f64 / size as f64 - 1.0) as f32;
    let (x0, x1) = (ndc(tile.x, width), ndc(tile.x + tile.width, width));
    let (y0, y1) = (ndc(tile.y, height), ndc(tile.y + tile.height, height));
    let z = (2.0 * depth as f64 / DEPTH_ONE as f64 - 1.0) as f32;
    let v = |x: f32, y: f32| [x, y, z, 1.0];
    [
        [v(x0, y0), v(x1, y0), v(x1, y1)],
        [v(x0, y0), v(x1, y1), v(x0, y1)],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::golden::{infallible, Discard};

    /// A probe at depth p over a screen filled at depth d: hits everywhere when p is well in
    /// front of d, nowhere when well behind: the slack the grid allows for rounding holds.
    #[test]
    fn depth_probes_see_a_filled_screen_within_their_slack() {
        let slack = 3; // the grid's PROBE_SLACK
        let tile = Rect::new(0, 0, 37, 23);
        for filled in [9u32, 1000, 1 << 20, 12_345_678, DEPTH_ONE - 9] {
            let mut sink = Discard;
            let mut observer = ();
            let mut renderer = Renderer::new(GoldenModel::new(37, 23), &mut sink, &mut observer);
            infallible(renderer.start_frame());
            for triangle in screen_quad(tile, filled, 37, 23) {
                infallible(renderer.execute(&Command::Tri(triangle)));
            }
            let probe = |renderer: &mut Renderer<Discard, ()>, depth: u32| {
                let result = infallible(renderer.depth_probe(&[(tile, depth)])).expect("an answer");
                (result.tiles[0].nohc, result.tiles[0].phc)
            };
            assert_eq!(
                probe(&mut renderer, filled - 2 * slack - 1),
                (tile.area(), tile.area())
            );
            assert_eq!(
                probe(&mut renderer, filled + 2 * slack + 1),
                (0, tile.area())
            );
            // In fact the rounding is tighter: one unit either side decides.
            assert_eq!(
                probe(&mut renderer, filled - 1).0,
                tile.area(),
                "depth {filled}"
            );
            assert_eq!(probe(&mut renderer, filled + 1).0, 0, "depth {filled}");
        }
    }
}
