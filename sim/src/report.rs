//! The replay report: what a run measured, as data (serde) and as text.

use occsim_traces::words::counted;
use occsim_traces::QueryMode;
use serde::Serialize;
use std::fmt::Write as _;

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Report {
    pub machine: String,
    /// The fully resolved architecture the run used.
    pub arch: Vec<ArchEntry>,
    pub viewport_width: u32,
    pub viewport_height: u32,
    pub summary: Summary,
    pub stages: Vec<StageReport>,
    pub memory_port: PortReport,
    pub engines: Vec<EngineReport>,
    /// Machines of many like units (the InfiniteReality-like one): each kind's busy share as
    /// a distribution over its units, instead of one row per unit.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub units: Vec<UnitSummary>,
    pub queries: Vec<QueryReport>,
    /// Each frame's time, split by where the host's time went ([`crate::machines::closed_loop`]);
    /// empty when the stream has no closed-loop record (a version-1 trace: an open loop).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub frames: Vec<FrameReport>,
}

/// One frame of a closed-loop replay. On the host's timeline `host_busy + waiting +
/// pipe_wait = cycles`; `geometry_busy` (on the O2 a part of `host_busy`) and `pixel_busy`
/// overlap it.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct FrameReport {
    pub frame: u64,
    pub cycles: u64,
    pub seconds: f64,
    /// The host CPU busy: traversal, driver, bus writes, result reads (and on the O2 the
    /// software geometry).
    pub host_busy: u64,
    /// The geometry stage busy (the O2's host transform; the IR's Geometry Engines, summed).
    pub geometry_busy: u64,
    /// The rasterizer (the busiest Fragment Generator) busy.
    pub pixel_busy: u64,
    /// The host blocked on query results: drain, merge, notification.
    pub waiting: u64,
    /// The host blocked at the frame's end until the pipeline finished it.
    pub pipe_wait: u64,
}

/// The busy share of `count` like units (the Image Engines, say): min, mean and max.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct UnitSummary {
    pub name: String,
    pub count: usize,
    pub busy_percent_min: f64,
    pub busy_percent_mean: f64,
    pub busy_percent_max: f64,
}

impl UnitSummary {
    /// The summary of the units' busy cycles out of `cycles`.
    pub fn of(name: &str, busy_cycles: impl Iterator<Item = u64>, cycles: u64) -> UnitSummary {
        let shares: Vec<f64> = busy_cycles.map(|busy| percent(busy, cycles)).collect();
        let count = shares.len();
        UnitSummary {
            name: name.to_string(),
            count,
            busy_percent_min: shares.iter().copied().reduce(f64::min).unwrap_or(0.0),
            busy_percent_mean: if count == 0 {
                0.0
            } else {
                shares.iter().sum::<f64>() / count as f64
            },
            busy_percent_max: shares.iter().copied().reduce(f64::max).unwrap_or(0.0),
        }
    }
}

pub use crate::arch::ArchEntry;

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Summary {
    /// Cycles until every block is idle.
    pub cycles: u64,
    pub simulated_seconds: f64,
    pub fragments: u64,
    pub primitives: u64,
    pub fragments_per_cycle: f64,
    pub queries: u64,
    /// Queries whose result was compared with a golden result in the stream.
    pub checked_queries: u64,
    /// Nearest-rank percentiles of the query latencies (none without a query: null in
    /// JSON, as the level's own figures).
    pub latency_p50_cycles: Option<u64>,
    pub latency_p95_cycles: Option<u64>,
    pub latency_max_cycles: Option<u64>,
    /// Frames over the run's time (closed-loop streams only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_per_second: Option<f64>,
}

/// What a machine's run amounts to, for [`Summary::of`].
pub struct RunTotals<'q> {
    pub cycles: u64,
    pub clock_mhz: f64,
    pub fragments: u64,
    pub primitives: u64,
    pub checked_queries: u64,
    pub queries: &'q [QueryReport],
}

impl Summary {
    /// The summary of a run: rates from the totals, latency percentiles from the queries.
    /// The one definition both machines report.
    pub fn of(run: RunTotals<'_>) -> Summary {
        let mut latencies: Vec<u64> = run.queries.iter().map(|q| q.latency_cycles).collect();
        latencies.sort_unstable();
        let [latency_p50_cycles, latency_p95_cycles, latency_max_cycles] =
            latency_figures(&latencies);
        Summary {
            cycles: run.cycles,
            simulated_seconds: run.cycles as f64 / (run.clock_mhz * 1e6),
            fragments: run.fragments,
            primitives: run.primitives,
            fragments_per_cycle: if run.cycles == 0 {
                0.0
            } else {
                run.fragments as f64 / run.cycles as f64
            },
            queries: run.queries.len() as u64,
            checked_queries: run.checked_queries,
            latency_p50_cycles,
            latency_p95_cycles,
            latency_max_cycles,
            frames_per_second: None,
        }
    }
}

impl Report {
    /// Add the closed loop's frames to a machine's report: the run lasts until `end` (the
    /// host's last cycle, when it outlasts the pipeline), and frames per second follow.
    pub(crate) fn close_loop(&mut self, frames: Vec<FrameReport>, end: u64, clock_mhz: f64) {
        let summary = &mut self.summary;
        if end > summary.cycles {
            summary.cycles = end;
            summary.simulated_seconds = end as f64 / (clock_mhz * 1e6);
            summary.fragments_per_cycle = summary.fragments as f64 / end as f64;
        }
        if !frames.is_empty() && summary.simulated_seconds > 0.0 {
            summary.frames_per_second = Some(frames.len() as f64 / summary.simulated_seconds);
        }
        self.frames = frames;
    }
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct StageReport {
    pub name: String,
    pub busy_cycles: u64,
    /// Cycles a ready item waited for memory data or for room downstream.
    pub stall_cycles: u64,
    /// The part of `stall_cycles` spent waiting for memory data.
    pub memory_stall_cycles: u64,
    pub busy_percent: f64,
    pub stall_percent: f64,
}

/// A machine without a shared memory port (InfiniteReality-like) reports all zeros.
#[derive(Clone, Debug, Default, Serialize, PartialEq)]
pub struct PortReport {
    pub bits_per_cycle: u32,
    pub busy_cycles: u64,
    pub busy_percent: f64,
    pub bits_transferred: u64,
    /// Bits carried over bits the port could have carried in the run.
    pub utilization_percent: f64,
    pub max_bits_in_one_cycle: u32,
    pub depth_read_words: u64,
    pub depth_read_word_hits: u64,
    pub depth_read_page_hits: u64,
    pub depth_read_page_misses: u64,
    pub depth_writes: u64,
    /// Drawn fragments' colour writes, and the colour reads of those that blend.
    pub colour_writes: u64,
    pub colour_reads: u64,
    /// Port words the clears wrote.
    pub clear_words: u64,
    /// Port cycles the display refresh and the host were served (whole cycles).
    pub reserved_cycles: u64,
    /// Of them, cycles they took from the pixel pipeline by force (it had asked for them).
    pub forced_cycles: u64,
    pub occu_words: u64,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EngineReport {
    pub engine: usize,
    pub busy_cycles: u64,
    pub stall_cycles: u64,
    pub busy_percent: f64,
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct QueryReport {
    pub id: u32,
    pub mode: QueryMode,
    /// Cycles from the query's `end` entering the pipe to its records being written
    /// (= drain + local merge + global merge).
    pub latency_cycles: u64,
    /// The part of the latency until the last pixel pipeline holds its partial result (the
    /// whole latency on the O2-like machine).
    pub drain_cycles: u64,
    /// The part spent merging the Image Engines' results within the boards (stage one);
    /// None (null) on a machine without merge stages, the O2-like one.
    pub local_merge_cycles: Option<u64>,
    /// The part spent merging the boards' results (stage two); None as the first.
    pub global_merge_cycles: Option<u64>,
    pub end_cycle: u64,
    pub available_cycle: u64,
    pub fragments: u64,
    pub overflowed_buffers: u32,
    /// Every tile's report, or none where the machine keeps totals only
    /// ([`crate::MachineModel::keep_tile_reports`]).
    pub tiles: Vec<TileReport>,
    /// The tiles' totals, kept either way.
    pub totals: TileTotals,
}

/// A query's tiles summed: what a level's result and the host's read-back take of them.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq, Eq)]
pub struct TileTotals {
    pub tiles: usize,
    pub nohc: u64,
    pub phc: u64,
    /// Hit words written to the tile buffers.
    pub hits_written: u64,
}

/// The latest query `id` among `queries`: the cycle its result is available and the record
/// words the host reads back.
pub(crate) fn latest_answer(queries: &[QueryReport], id: u32) -> Option<(u64, u64)> {
    queries
        .iter()
        .rev()
        .find(|q| q.id == id)
        .map(|q| (q.available_cycle, q.record_words()))
}

impl QueryReport {
    /// The 32-bit words of the query's result records: a brief record a tile and the hits
    /// kept (what the host reads back).
    pub fn record_words(&self) -> u64 {
        let totals = &self.totals;
        totals.tiles as u64 * occsim_traces::query::BRIEF_RECORD_ENTRIES as u64
            + totals.hits_written
    }
}

#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct TileReport {
    pub nohc: u64,
    pub phc: u64,
    pub xmin: u32,
    pub xmax: u32,
    pub ymin: u32,
    pub ymax: u32,
    pub zmin: u32,
    pub zmax: u32,
    pub hits_written: u64,
    pub overflowed: bool,
}

/// `part` as a percentage of `whole` (0 when `whole` is 0).
pub fn percent(part: u64, whole: u64) -> f64 {
    if whole == 0 {
        0.0
    } else {
        100.0 * part as f64 / whole as f64
    }
}

/// The p50 and p95 (nearest rank) and the largest of `sorted` latencies, none of them
/// without one: the one definition of the figures a run's latency is summed up by, its
/// report's summary's and every level's result's.
pub fn latency_figures(sorted: &[u64]) -> [Option<u64>; 3] {
    match sorted.last() {
        None => [None; 3],
        Some(&max) => [
            Some(nearest_rank(sorted, 50)),
            Some(nearest_rank(sorted, 95)),
            Some(max),
        ],
    }
}

/// Nearest-rank percentile of sorted values: the value at rank ceil(p/100 * n).
pub fn nearest_rank(sorted: &[u64], p: u64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    let rank = (p as usize * sorted.len()).div_ceil(100).max(1);
    sorted[rank - 1]
}

/// What the report says of a stream with no closed-loop record.
pub(crate) const OPEN_LOOP_NOTE: &str = "open loop: the stream has no draws, host work, waits or frames (as a version-1 trace, or a scene of bare triangles), so nothing waits for an answer";

/// What the frames table's columns are, at every level.
pub(crate) const FRAMES_LEGEND: &str = "  in pipeline cycles (ms: simulated milliseconds): host busy (traversal, driver, result reads; on the O2 its software geometry too), geometry (the geometry stage busy, summed over its Geometry Engines: several engines can pass the frame's cycles), pixel busy (the rasterizer busy), waiting (the host blocked on answers), pipe wait (the host blocked at the frame's end)";

/// The frames table's heading, at every level.
pub(crate) const FRAMES_HEADING: &str = "frame        cycles         ms    host busy     geometry   pixel busy      waiting    pipe wait";

impl Report {
    /// The blocks' tables: stages, memory port (when the machine has one), units of many
    /// like blocks, engines.
    pub(crate) fn write_blocks(&self, out: &mut String) {
        let _ = writeln!(
            out,
            "\n{:<16} {:>12} {:>7} {:>12} {:>7} {:>12}",
            "stage", "busy", "busy%", "stall", "stall%", "memory stall"
        );
        for s in &self.stages {
            let _ = writeln!(
                out,
                "{:<16} {:>12} {:>6.1}% {:>12} {:>6.1}% {:>12}",
                s.name,
                s.busy_cycles,
                s.busy_percent,
                s.stall_cycles,
                s.stall_percent,
                s.memory_stall_cycles
            );
        }
        let _ = writeln!(
            out,
            "  busy, stall: cycles, summed over a stage's units where it has several; busy%, stall%: \
             of the run's {} cycles, the mean over its units; stall: a ready item waiting for memory \
             data or for room downstream; memory stall: the part of stall waiting for memory data",
            self.summary.cycles
        );
        let p = &self.memory_port;
        if p.bits_per_cycle > 0 {
            self.write_port(out);
        }
        self.write_units(out);
        let _ = writeln!(
            out,
            "\n{:<8} {:>12} {:>7} {:>12}",
            "engine", "busy", "busy%", "stall"
        );
        for e in &self.engines {
            let _ = writeln!(
                out,
                "{:<8} {:>12} {:>6.1}% {:>12}",
                e.engine, e.busy_cycles, e.busy_percent, e.stall_cycles
            );
        }
        let legend = if self.units.is_empty() {
            "engine E of the Occlusion Unit: busy: cycles testing fragments against its tiles; \
             busy%: of the run's cycles; stall: cycles holding a tested fragment with no room downstream"
        } else {
            "engine E of every Image Engine's Occlusion Unit: busy, stall: cycles testing \
             fragments against its tiles and holding a tested fragment with no room downstream, \
             summed over the units; busy%: of the run's cycles, the mean over the units"
        };
        let _ = writeln!(out, "  {legend}");
    }

    /// The frames of a closed-loop run, or the note that the run was an open loop.
    pub(crate) fn write_frames(&self, out: &mut String) {
        let Some(fps) = self.summary.frames_per_second else {
            let _ = writeln!(out, "{OPEN_LOOP_NOTE}");
            return;
        };
        let _ = writeln!(
            out,
            "\n{}, {fps:.2} frames/s; on the host's timeline busy + waiting + pipe wait = cycles",
            counted(self.frames.len() as u64, "frame", "frames")
        );
        let _ = writeln!(out, "{FRAMES_LEGEND}");
        let _ = writeln!(out, "{FRAMES_HEADING}");
        for f in &self.frames {
            let _ = writeln!(
                out,
                "{:<6} {:>12} {:>10.3} {:>12} {:>12} {:>12} {:>12} {:>12}",
                f.frame,
                f.cycles,
                f.seconds * 1e3,
                f.host_busy,
                f.geometry_busy,
                f.pixel_busy,
                f.waiting,
                f.pipe_wait
            );
        }
    }

    fn write_units(&self, out: &mut String) {
        if self.units.is_empty() {
            return;
        }
        let _ = writeln!(
            out,
            "\n{:<20} {:>6} {:>7} {:>7} {:>7}",
            "units", "count", "min%", "mean%", "max%"
        );
        for u in &self.units {
            let _ = writeln!(
                out,
                "{:<20} {:>6} {:>6.1}% {:>6.1}% {:>6.1}%",
                u.name, u.count, u.busy_percent_min, u.busy_percent_mean, u.busy_percent_max
            );
        }
        let _ = writeln!(
            out,
            "  each unit's busy cycles as % of the run's cycles: the least, the mean and the most busy of count units"
        );
    }

    fn write_port(&self, out: &mut String) {
        let p = &self.memory_port;
        let _ = writeln!(
            out,
            "\nmemory port: {} bits/cycle; busy {} cycles ({:.1}% of the run: cycles it carried the pixel pipeline's bits; the display refresh's and the host's are below), utilization {:.1}% (the pixel pipeline's bits over the bits the port could have carried), max {} bits in a cycle",
            p.bits_per_cycle, p.busy_cycles, p.busy_percent, p.utilization_percent, p.max_bits_in_one_cycle
        );
        let _ = writeln!(
            out,
            "  depth reads {} words ({} word hits, {} page hits, {} page misses), depth writes {}, OccU words {}",
            p.depth_read_words, p.depth_read_word_hits, p.depth_read_page_hits, p.depth_read_page_misses, p.depth_writes, p.occu_words
        );
        if p.colour_writes + p.clear_words + p.reserved_cycles > 0 {
            let _ = writeln!(
                out,
                "  colour writes {} (blend reads {}), clear words {}, cycles served to the display refresh and the host {} ({} taken from the pipeline by force)",
                p.colour_writes, p.colour_reads, p.clear_words, p.reserved_cycles, p.forced_cycles
            );
        }
    }
}
