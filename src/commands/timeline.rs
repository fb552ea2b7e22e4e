//! `replay --timeline FILE.json`: the blocks' busy, stall and waiting slices the sim
//! crate's recorder closes ([`occsim_sim::timeline`]), streamed as Chrome trace-event JSON
//! (`{"traceEvents": [...]}`, "X" complete events and "M" metadata naming the tracks) as
//! they come, a slice per query from its begin to its result as each is answered, then a
//! slice per frame from the report. Times are simulated
//! microseconds, cycles / clock MHz; every slice's `args` also give its cycles exactly.
//! The file is written to a temporary beside the target and renamed when the replay
//! succeeds (nothing is left on an error).

use anyhow::Context;
use occsim_sim::timeline::{PortLane, QuerySlice, Slice, TimelineSink, Track};
use occsim_sim::Report;
use occsim_sweep::output::{AtomicFile, Finished};
use std::collections::BTreeSet;
use std::io::{BufWriter, Write};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The `tid` of a track (also its place, top to bottom), and its name.
fn track_id(track: Track) -> (u32, String) {
    match track {
        Track::Host => (1, "host".into()),
        Track::Geometry(g) => (10 + g, format!("geometry {g}")),
        Track::Rasterizer => (100, "rasterizer (fragment_input)".into()),
        Track::DepthPipeline => (101, "depth pipeline".into()),
        Track::OcclusionUnit => (102, "occlusion unit".into()),
        Track::Engine(e) => (200 + e, format!("occlusion engine {e}")),
        Track::OccuControl => (400, "OccU Control".into()),
        Track::MemoryPort(lane) => {
            let (offset, client) = match lane {
                PortLane::DepthReads => (1, "depth reads"),
                PortLane::DepthWrites => (2, "depth writes"),
                PortLane::OccuControl => (3, "OccU Control writes"),
                PortLane::Clears => (4, "clears"),
            };
            (400 + offset, format!("memory port: {client}"))
        }
        Track::FragmentGenerator(b) => (1000 + 10 * b, format!("board {b} fragment generator")),
        Track::ImageEngines(b) => (1001 + 10 * b, format!("board {b} image engines")),
        Track::LocalMerge(b) => (1002 + 10 * b, format!("board {b} merge (stage one)")),
        Track::GlobalMerge => (FRAMES_TID - 1, "global merge (stage two)".into()),
    }
}

/// The frames track's `tid`; query lanes follow it.
const FRAMES_TID: u32 = 9000;
const QUERIES_TID: u32 = 10000;

/// The JSON being streamed.
struct Writer {
    out: BufWriter<std::fs::File>,
    clock_mhz: f64,
    /// Tracks already named.
    named: BTreeSet<u32>,
    /// The first write error (reported at the end).
    error: Option<std::io::Error>,
    /// No event written yet (the next needs no separator).
    first: bool,
    /// Per query lane, the cycle its last query was answered.
    lanes: Vec<u64>,
}

impl Writer {
    fn put(&mut self, event: serde_json::Value) {
        if self.error.is_none() {
            let separator: &[u8] = if self.first { b"" } else { b",\n" };
            self.first = false;
            let outcome = self
                .out
                .write_all(separator)
                .and_then(|()| serde_json::to_writer(&mut self.out, &event).map_err(Into::into));
            if let Err(e) = outcome {
                self.error = Some(e);
            }
        }
    }

    fn name_track(&mut self, tid: u32, name: &str) {
        if self.named.insert(tid) {
            self.put(serde_json::json!({
                "name": "thread_name", "ph": "M", "pid": 1, "tid": tid,
                "args": {"name": name},
            }));
            self.put(serde_json::json!({
                "name": "thread_sort_index", "ph": "M", "pid": 1, "tid": tid,
                "args": {"sort_index": tid},
            }));
        }
    }

    /// An "X" event of cycles `start..end` on `tid`.
    fn complete(&mut self, tid: u32, name: &str, start: u64, end: u64, args: serde_json::Value) {
        let mhz = self.clock_mhz;
        let mut args = args;
        args["start_cycle"] = start.into();
        args["end_cycle"] = end.into();
        self.put(serde_json::json!({
            "name": name, "ph": "X", "pid": 1, "tid": tid,
            "ts": start as f64 / mhz, "dur": (end - start) as f64 / mhz,
            "args": args,
        }));
    }
}

/// The sink the sim's recorder closes slices into (a handle on the shared writer).
struct Sink(Arc<Mutex<Writer>>);

impl TimelineSink for Sink {
    fn slice(&mut self, slice: Slice) {
        let mut writer = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let (tid, name) = track_id(slice.track);
        writer.name_track(tid, &name);
        let state = slice.state.name();
        let args = serde_json::json!({});
        writer.complete(tid, state, slice.start, slice.end, args);
    }

    /// A query's slice from its begin to its result, on lanes `queries N`: the first lane
    /// free at its begin, so none overlap.
    fn query(&mut self, query: QuerySlice) {
        let mut writer = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let (start, end) = (query.begin_cycle, query.available_cycle);
        let lane = match writer.lanes.iter().position(|&free| free <= start) {
            Some(lane) => lane,
            None => {
                writer.lanes.push(0);
                writer.lanes.len() - 1
            }
        };
        writer.lanes[lane] = end;
        let tid = QUERIES_TID + lane as u32;
        writer.name_track(tid, &format!("queries {lane}"));
        let name = format!("query {} {}", query.id, query.mode.name());
        let latency = query.available_cycle - query.end_cycle;
        let args = serde_json::json!({
            "id": query.id,
            "mode": query.mode.name(),
            "tiles": query.tiles,
            "query_end_cycle": query.end_cycle,
            "latency_cycles": latency,
            "latency_us": latency as f64 / writer.clock_mhz,
        });
        writer.complete(tid, &name, start, end, args);
    }
}

/// A timeline file being written: its writer, shared with the sink, and the file.
pub struct TimelineFile {
    writer: Arc<Mutex<Writer>>,
    file: AtomicFile,
    path: PathBuf,
    window: Range<u64>,
}

impl TimelineFile {
    /// Start `path` for a run on `machine` at `clock_mhz`; the sink to hand the recorder.
    pub fn create(
        path: &Path,
        machine: &str,
        clock_mhz: f64,
        window: Range<u64>,
    ) -> anyhow::Result<(TimelineFile, Box<dyn TimelineSink>)> {
        let cannot = || format!("cannot write the timeline {}", path.display());
        let file = AtomicFile::create(path).with_context(cannot)?;
        let mut out = BufWriter::with_capacity(1 << 20, file.handle().with_context(cannot)?);
        out.write_all(b"{\"displayTimeUnit\": \"ns\", \"traceEvents\": [\n")
            .with_context(cannot)?;
        let mut writer = Writer {
            out,
            clock_mhz,
            named: BTreeSet::new(),
            error: None,
            first: true,
            lanes: Vec::new(),
        };
        writer.put(serde_json::json!({
            "name": "process_name", "ph": "M", "pid": 1, "tid": 0,
            "args": {"name": format!("occsim {machine} at {clock_mhz} MHz")},
        }));
        let writer = Arc::new(Mutex::new(writer));
        let sink = Box::new(Sink(writer.clone()));
        let timeline = TimelineFile {
            writer,
            file,
            path: path.to_path_buf(),
            window,
        };
        Ok((timeline, sink))
    }

    /// After a successful replay: a slice per frame, then the file is closed, to be renamed
    /// into place with the replay's other outputs.
    pub fn finish(self, report: &Report) -> anyhow::Result<Finished> {
        let cannot = || format!("cannot write the timeline {}", self.path.display());
        let mut writer = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        let window = self.window.clone();
        let inside = |start: u64, end: u64| start < window.end && end > window.start;
        let mut start = 0;
        for frame in &report.frames {
            let end = start + frame.cycles;
            if inside(start, end) {
                writer.name_track(FRAMES_TID, "frames");
                let args = serde_json::json!({
                    "frame": frame.frame,
                    "host_busy_cycles": frame.host_busy,
                    "waiting_cycles": frame.waiting,
                    "pipe_wait_cycles": frame.pipe_wait,
                });
                let name = format!("frame {}", frame.frame);
                writer.complete(FRAMES_TID, &name, start, end, args);
            }
            start = end;
        }
        if let Some(e) = writer.error.take() {
            return Err(anyhow::Error::new(e).context(cannot()));
        }
        let out = &mut writer.out;
        out.write_all(b"\n]}\n")
            .and_then(|()| out.flush())
            .with_context(cannot)?;
        drop(writer);
        self.file.finish().with_context(cannot)
    }
}
