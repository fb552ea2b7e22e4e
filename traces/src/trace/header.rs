//! What a trace says about itself: the header (how it was made, written first) and the
//! summary (what it holds, written last), plus the tally both the writer and the reader keep
//! of an event stream to produce and to check the summary.

use crate::depth_layout::DepthLayout;
use crate::event::Event;
use crate::query::{
    QueryMode, QueryResult, QueryShape, QueryTotals, MAX_BUFFER_ENTRIES, MAX_TILES,
};
use crate::raster::RasterProfile;
use crate::state::{DepthFunc, MAX_VIEWPORT_SIDE};
use serde::{Deserialize, Serialize};

/// How a trace was made. Stored as JSON in the file header.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TraceHeader {
    /// Viewport width in pixels; every fragment has x < width.
    pub width: u32,
    /// Viewport height in pixels; every fragment has y < height.
    pub height: u32,
    /// Sub-pixel precision of the rasterizer's vertex snapping, in bits.
    pub subpixel_bits: u32,
    /// Which pixels on a shared edge belong to a triangle.
    pub fill_rule: String,
    /// The rasterizer profile whose arithmetic made the fragments (traces written before it
    /// was recorded were made by the `exact` profile).
    #[serde(default = "profile_of_unmarked_traces")]
    pub raster: RasterProfile,
    /// Encoding of fragment depth.
    pub depth_format: String,
    /// The program that produced the trace, with its version.
    pub generator: String,
    /// The scene the trace was made from (a built-in name or a file name).
    pub scene: String,
    /// The pipeline features the trace exercises. A streaming writer learns them as the
    /// events pass, so a seekable output gets them written back into its header at the end
    /// ([`crate::trace::TraceWriter::finish_seekable`]); otherwise only the summary has them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub features: Option<TraceFeatures>,
    /// The depth layout the window index was counted at, when the trace has one
    /// ([`crate::trace::index`]; set by the writer from
    /// [`crate::trace::WriterOptions::window_index`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window_index: Option<DepthLayout>,
    /// Whether the trace holds a window table (every trace of format version 8 on, unless
    /// made without one: [`crate::trace::windows::without_window_table`]); written only
    /// when false.
    #[serde(default = "holds", skip_serializing_if = "is_held")]
    pub window_table: bool,
}

fn holds() -> bool {
    true
}

fn is_held(held: &bool) -> bool {
    *held
}

impl TraceHeader {
    /// A header for a `width` x `height` viewport with occsim's rasterizer conventions.
    pub fn new(width: u32, height: u32) -> TraceHeader {
        TraceHeader {
            width,
            height,
            subpixel_bits: crate::raster::SUBPIXEL_BITS,
            fill_rule: crate::raster::FILL_RULE.to_owned(),
            raster: RasterProfile::default(),
            depth_format: DEPTH_FORMAT.to_owned(),
            generator: crate::GENERATOR_VERSION.to_owned(),
            scene: String::new(),
            features: None,
            window_index: None,
            window_table: true,
        }
    }

    pub fn with_scene(mut self, scene: impl Into<String>) -> TraceHeader {
        self.scene = scene.into();
        self
    }

    pub fn with_raster(mut self, raster: RasterProfile) -> TraceHeader {
        self.raster = raster;
        self
    }

    pub fn with_generator(mut self, generator: impl Into<String>) -> TraceHeader {
        self.generator = generator.into();
        self
    }

    /// Why this header cannot describe a trace, if it cannot.
    pub(crate) fn problem(&self) -> Option<String> {
        let side = 1..=MAX_VIEWPORT_SIDE;
        if !side.contains(&self.width) || !side.contains(&self.height) {
            return Some(format!(
                "viewport {}x{} outside 1..={MAX_VIEWPORT_SIDE} per side",
                self.width, self.height
            ));
        }
        if self.depth_format != DEPTH_FORMAT {
            // The depths are compared and cleared as 24-bit unsigned normalized values: any
            // other encoding would be read as garbage.
            return Some(format!(
                "depth format {:?}: occsim reads {DEPTH_FORMAT:?} depths only",
                self.depth_format
            ));
        }
        if self.subpixel_bits > MAX_SUBPIXEL_BITS {
            return Some(format!(
                "{} sub-pixel bits: more than {MAX_SUBPIXEL_BITS}, which no rasterizer snaps to",
                self.subpixel_bits
            ));
        }
        self.window_index
            .and_then(|layout| layout.problem())
            .map(|problem| format!("window index layout: {problem}"))
    }
}

/// The depth encoding of every trace: 24-bit unsigned normalized (`DEPTH_ONE` is 1.0).
const DEPTH_FORMAT: &str = "unorm24";

/// Sub-pixel bits a header may claim at most: the fragments do not depend on the figure
/// (it says how they were made, and another rasterizer's trace may claim another), but a
/// rasterizer's snapping keeps at most 16 fraction bits (GL and Vulkan implementations
/// keep 4 to 8; occsim's profiles keep 8), so more is a damaged header.
const MAX_SUBPIXEL_BITS: u32 = 16;

/// Traces from before the header named its profile were rasterized exactly.
fn profile_of_unmarked_traces() -> RasterProfile {
    RasterProfile::Exact
}

/// Which pipeline features a trace exercises (computed from its events).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TraceFeatures {
    /// Query modes begun at least once, in `QueryMode::ALL` order.
    pub query_modes: Vec<QueryMode>,
    /// Depth functions set at least once, in `DepthFunc::ALL` order.
    pub depth_funcs: Vec<DepthFunc>,
    /// A scissor rectangle was enabled.
    pub scissor: bool,
    /// Back-face culling was enabled.
    pub culling: bool,
    /// The depth buffer was cleared.
    pub clears: bool,
    /// Depth writes were disabled (`depthmask off`).
    pub depth_writes_off: bool,
    /// The depth test was disabled.
    pub depth_test_off: bool,
    /// A verbose query was begun.
    pub verbose: bool,
    /// The trace stores the golden model's query results.
    pub query_results: bool,
    /// The most tiles any query has (None in traces written before it was recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_query_tiles: Option<u64>,
    /// Some fragment arrives with the depth test and depth writes on and no brief or verbose
    /// query open, so the trace can write depth (None in traces written before it was
    /// recorded).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_writes: Option<bool>,
}

/// Queries begun, per mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct QueryModeCounts {
    pub samples: u64,
    pub any: u64,
    pub brief: u64,
    pub verbose: u64,
}

impl QueryModeCounts {
    fn count(&mut self, mode: QueryMode) {
        match mode {
            QueryMode::Samples => self.samples += 1,
            QueryMode::Any => self.any += 1,
            QueryMode::Brief => self.brief += 1,
            QueryMode::Verbose => self.verbose += 1,
        }
    }
}

/// What a trace holds. Stored as JSON in the final block; a full scan recomputes and checks it.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TraceSummary {
    /// Events of every kind, fragments included.
    pub events: u64,
    pub fragments: u64,
    pub primitives: u64,
    /// Queries begun.
    pub queries: u64,
    pub queries_by_mode: QueryModeCounts,
    /// `QueryResult` events stored.
    pub query_results: u64,
    /// The closed loop's records (all zero in version-1 traces).
    #[serde(default)]
    pub closed_loop: ClosedLoopCounts,
    pub features: TraceFeatures,
    /// Event blocks (the summary block not counted).
    pub blocks: u64,
    /// Event payload bytes before compression.
    pub payload_bytes: u64,
    /// Event payload bytes as stored (after compression), block headers not counted.
    pub stored_bytes: u64,
    /// The window index's blocks, when the trace has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window_index: Option<BlockCounts>,
    /// The depth-test blocks, one an event block, when the trace has a window index
    /// (version 5 on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth_tests: Option<BlockCounts>,
    /// The window table's blocks (version 8 on, [`crate::trace::windows`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub window_table: Option<BlockCounts>,
    /// The band index's blocks, when the trace has a window index (version 10 on,
    /// [`crate::trace::bands`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bands: Option<BlockCounts>,
}

impl TraceSummary {
    /// Why these counts cannot be one trace's, if they cannot: what a reader of the summary
    /// alone (`trace info`) can check before printing them (a summary claiming 2^40 queries
    /// of which 3 had a mode had been printed as it said).
    pub(crate) fn problem(&self) -> Option<String> {
        let q = &self.queries_by_mode;
        let by_mode = [q.samples, q.any, q.brief, q.verbose]
            .iter()
            .try_fold(0u64, |sum, &n| sum.checked_add(n));
        if by_mode != Some(self.queries) {
            return Some(format!(
                "{} queries, but {} by mode",
                self.queries,
                by_mode.map_or("more than 2^64".to_owned(), |n| n.to_string())
            ));
        }
        if self.query_results > self.queries {
            return Some(format!(
                "{} query results of {} queries",
                self.query_results, self.queries
            ));
        }
        // Every fragment, primitive and query begin is an event of its own.
        let least_events = [self.fragments, self.primitives, self.queries]
            .iter()
            .try_fold(0u64, |sum, &n| sum.checked_add(n));
        if least_events.is_none_or(|least| self.events < least) {
            return Some(format!(
                "{} events, fewer than its {} fragments, {} primitives and {} queries",
                self.events, self.fragments, self.primitives, self.queries
            ));
        }
        let loop_counts = &self.closed_loop;
        (loop_counts.discarded_draws > loop_counts.draws).then(|| {
            format!(
                "{} draws discarded of {}",
                loop_counts.discarded_draws, loop_counts.draws
            )
        })
    }
}

/// Blocks of one kind and their bytes (the summary's `window_index` counts the window
/// index's, [`crate::trace::index`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct BlockCounts {
    pub blocks: u64,
    /// Payload bytes before compression.
    pub payload_bytes: u64,
    /// Payload bytes as stored, block headers not counted.
    pub stored_bytes: u64,
}

impl BlockCounts {
    /// Count one more block.
    pub(crate) fn add(&mut self, header: &super::block::BlockHeader) {
        self.blocks += 1;
        self.payload_bytes += header.raw_len as u64;
        self.stored_bytes += header.stored_len as u64;
    }
}

/// What a trace holds of the closed loop: draws, host work, waits and frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct ClosedLoopCounts {
    /// Draws submitted (discarded ones included).
    pub draws: u64,
    /// Triangles submitted, culled and clipped ones included.
    pub triangles: u64,
    pub vertices: u64,
    /// Draws discarded by conditional rendering.
    pub discarded_draws: u64,
    /// Host waits for a query result.
    pub waits: u64,
    /// Conditional-rendering regions.
    pub conditionals: u64,
    /// Frame ends (`swap`).
    pub frames: u64,
    /// Hierarchy nodes the host traversed.
    pub host_nodes: u64,
}

/// Counts an event stream and checks its structure: fragments inside the viewport, queries
/// begun before they end and not nested, results matching the query that just ended.
#[derive(Clone, Debug)]
pub(crate) struct StreamTally {
    width: u32,
    height: u32,
    open: Option<QueryShape>,
    awaiting_result: Option<QueryShape>,
    summary: TraceSummary,
    /// Bit `code` set when that query mode / depth function was seen.
    mode_bits: u8,
    func_bits: u8,
    /// The render state fragments arrive in, for `depth_writes`: depth test and depth
    /// writes on, and a brief or verbose query (which never writes depth) open.
    depth_test: bool,
    depth_mask: bool,
    occlusion_mode_open: bool,
    depth_writes: bool,
    max_query_tiles: u64,
    conditional_open: bool,
}

/// Hits one tile's buffer of the query `shape` holds at most.
fn hit_room(shape: QueryShape) -> u64 {
    match shape.mode {
        QueryMode::Verbose => (shape.buffer_entries - crate::query::BRIEF_RECORD_ENTRIES) as u64,
        _ => 0,
    }
}

impl StreamTally {
    pub(crate) fn new(header: &TraceHeader) -> StreamTally {
        StreamTally {
            width: header.width,
            height: header.height,
            open: None,
            awaiting_result: None,
            summary: TraceSummary::default(),
            mode_bits: 0,
            func_bits: 0,
            depth_test: true,
            depth_mask: true,
            occlusion_mode_open: false,
            depth_writes: false,
            max_query_tiles: 0,
            conditional_open: false,
        }
    }

    /// Fragments arrive (`count` > 0) in the current render state.
    #[inline(always)]
    fn fragments_arrive(&mut self) {
        self.depth_writes |= self.depth_test && self.depth_mask && !self.occlusion_mode_open;
    }

    /// Account `count` fragments already checked to lie inside the viewport.
    #[inline(always)]
    pub(crate) fn checked_fragments(&mut self, count: u64) {
        self.summary.fragments += count;
        self.summary.events += count;
        if count > 0 {
            self.fragments_arrive();
        }
    }

    /// Check and account one event. The error says what is wrong with it.
    pub(crate) fn event(&mut self, event: &Event) -> Result<(), String> {
        let features = &mut self.summary.features;
        match event {
            Event::Fragment(f) => {
                if f.x as u32 >= self.width
                    || f.y as u32 >= self.height
                    || f.z > crate::event::DEPTH_ONE
                {
                    return Err(format!(
                        "fragment ({}, {}, z {}) outside the {}x{} viewport or 24-bit depth",
                        f.x, f.y, f.z, self.width, self.height
                    ));
                }
                self.summary.fragments += 1;
                self.fragments_arrive();
            }
            Event::Primitive => self.summary.primitives += 1,
            Event::Clear => features.clears = true,
            Event::DepthFunc(f) => self.func_bits |= 1 << f.code(),
            Event::DepthMask(on) => {
                features.depth_writes_off |= !on;
                self.depth_mask = *on;
            }
            Event::DepthTest(on) => {
                features.depth_test_off |= !on;
                self.depth_test = *on;
            }
            Event::Cull(on) => features.culling |= on,
            Event::Scissor(rect) => features.scissor |= rect.is_some(),
            Event::QueryBegin(spec) => self.begin(spec.shape())?,
            Event::QueryEnd => match self.open.take() {
                Some(open) => {
                    self.awaiting_result = Some(open);
                    self.occlusion_mode_open = false;
                }
                None => return Err("query end without begin".to_owned()),
            },
            Event::QueryResult(result) => {
                let ended = self.result(&result.totals())?;
                self.check_tiles(ended, result)?;
            }
            Event::Geometry(batch) => {
                let counts = &mut self.summary.closed_loop;
                counts.draws += batch.starts_draw as u64;
                counts.discarded_draws += (batch.starts_draw && batch.discarded) as u64;
                counts.triangles += batch.triangles as u64;
                counts.vertices += batch.vertices as u64;
            }
            Event::HostWork(work) => self.summary.closed_loop.host_nodes += work.nodes as u64,
            Event::Wait(_) => self.summary.closed_loop.waits += 1,
            Event::ConditionalBegin(id) => {
                if self.conditional_open {
                    return Err(format!("conditional on query {id} begins inside another"));
                }
                self.conditional_open = true;
                self.summary.closed_loop.conditionals += 1;
            }
            Event::ConditionalEnd => {
                if !std::mem::replace(&mut self.conditional_open, false) {
                    return Err("conditional end without begin".to_owned());
                }
            }
            Event::Swap => self.summary.closed_loop.frames += 1,
        }
        self.summary.events += 1;
        Ok(())
    }

    /// Check and account a query begin read skimmed, as [`Self::event`] does a whole one.
    pub(crate) fn query_begin(&mut self, shape: QueryShape) -> Result<(), String> {
        self.begin(shape)?;
        self.summary.events += 1;
        Ok(())
    }

    /// Check and account a query result read skimmed, as [`Self::event`] does a whole one
    /// but for its tiles one by one.
    pub(crate) fn query_result(&mut self, totals: &QueryTotals) -> Result<(), String> {
        self.result(totals)?;
        self.summary.events += 1;
        Ok(())
    }

    fn begin(&mut self, shape: QueryShape) -> Result<(), String> {
        if let Some(open) = self.open {
            return Err(format!(
                "query {} begins inside open query {}",
                shape.id, open.id
            ));
        }
        if shape.tiles > MAX_TILES {
            return Err(format!(
                "query {} has {} tiles (most {MAX_TILES})",
                shape.id, shape.tiles
            ));
        }
        if !(crate::query::BRIEF_RECORD_ENTRIES..=MAX_BUFFER_ENTRIES)
            .contains(&shape.buffer_entries)
        {
            return Err(format!(
                "query {} buffer of {} entries",
                shape.id, shape.buffer_entries
            ));
        }
        self.open = Some(shape);
        self.awaiting_result = None;
        self.summary.queries += 1;
        self.summary.queries_by_mode.count(shape.mode);
        self.mode_bits |= 1 << shape.mode.code();
        self.occlusion_mode_open = shape.mode.is_occlusion_render_mode();
        self.max_query_tiles = self.max_query_tiles.max(shape.tiles as u64);
        Ok(())
    }

    /// A result (its totals) after its query's end: checked against the query that ended,
    /// which it returns.
    fn result(&mut self, totals: &QueryTotals) -> Result<QueryShape, String> {
        let Some(ended) = self.awaiting_result.take() else {
            return Err(format!(
                "result of query {} without a query end before it",
                totals.id
            ));
        };
        if totals.id != ended.id || totals.mode != ended.mode || totals.tiles != ended.tiles {
            return Err(format!(
                "result (query {}, {}, {} tiles) does not match the query that ended (query {}, {}, {} tiles)",
                totals.id, totals.mode.name(), totals.tiles, ended.id, ended.mode.name(), ended.tiles
            ));
        }
        let room = hit_room(ended);
        if totals.held_hits > room.saturating_mul(ended.tiles as u64) {
            return Err(format!(
                "query {}'s {} tiles hold {} hits (room for {room} each)",
                ended.id, ended.tiles, totals.held_hits
            ));
        }
        self.summary.query_results += 1;
        Ok(ended)
    }

    /// A whole result's tiles, each checked against the query that ended.
    fn check_tiles(&self, ended: QueryShape, result: &QueryResult) -> Result<(), String> {
        let hit_room = hit_room(ended);
        for (index, tile) in result.tiles.iter().enumerate() {
            if tile.hits.len() > hit_room {
                return Err(format!(
                    "tile {index} of query {} holds {} hits (room for {hit_room})",
                    ended.id,
                    tile.hits.len()
                ));
            }
            if let Some(b) = tile.hits.bounds() {
                if b.xmax as u32 >= self.width || b.ymax as u32 >= self.height {
                    return Err(format!(
                        "tile {index} of query {}: hits up to ({}, {}) outside the viewport",
                        ended.id, b.xmax, b.ymax
                    ));
                }
            }
        }
        Ok(())
    }

    /// The tally so far as a summary (block and byte counts are the caller's business).
    pub(crate) fn summary(&self) -> TraceSummary {
        let mut summary = self.summary.clone();
        summary.features.query_modes = QueryMode::ALL
            .into_iter()
            .filter(|m| self.mode_bits & (1 << m.code()) != 0)
            .collect();
        summary.features.depth_funcs = DepthFunc::ALL
            .into_iter()
            .filter(|f| self.func_bits & (1 << f.code()) != 0)
            .collect();
        summary.features.verbose = self.mode_bits & (1 << QueryMode::Verbose.code()) != 0;
        summary.features.query_results = summary.query_results > 0;
        summary.features.max_query_tiles = Some(self.max_query_tiles);
        summary.features.depth_writes = Some(self.depth_writes);
        summary
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_name_their_profile_and_old_ones_read_as_exact() {
        let header = TraceHeader::new(8, 4).with_raster(RasterProfile::LlvmpipeWindow);
        let json = serde_json::to_string(&header).unwrap();
        assert!(json.contains(r#""raster":"llvmpipe-window""#), "{json}");
        assert_eq!(serde_json::from_str::<TraceHeader>(&json).unwrap(), header);
        // A header from before the field: made by the exact rasterizer.
        let old = json.replace(r#""raster":"llvmpipe-window","#, "");
        assert!(!old.contains("raster"), "{old}");
        let read: TraceHeader = serde_json::from_str(&old).unwrap();
        assert_eq!(read.raster, RasterProfile::Exact);
        assert_eq!(TraceHeader::new(8, 4).raster, RasterProfile::Llvmpipe);
    }
}
