//! A timeline of the cycle-level models: the intervals the blocks are busy, stalled or
//! waiting in, as the event-timestamp models compute them, for a viewer (the command line
//! writes them as Chrome trace-event JSON). The crate does no file IO: slices go to a
//! [`TimelineSink`] the caller supplies.
//!
//! A block reports an interval `start..end` (cycles, half-open) in a state on its track;
//! the recorder keeps one open slice a track and extends it while the next interval of the
//! same state starts where it ends (consecutive cycles in one state are one slice), so
//! memory stays one slice a track whatever the run's length. An interval is clipped to the
//! window and to the end of the track's last slice (no two slices of a track overlap; a
//! block that reports an interval reaching back over one reported before loses that part).
//! Off (no timeline given), the blocks test one `Option` per item: see the replay
//! benchmark's figures in the README.

use std::ops::Range;
use std::sync::{Arc, Mutex};

/// A block's track.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Track {
    /// The host CPU (either machine).
    Host,
    /// The O2's rasterizer (`fragment_input`).
    Rasterizer,
    /// The O2's depth pipeline (prefetch, test, write buffer).
    DepthPipeline,
    /// The O2's Occlusion Unit (all its engines in lockstep): busy while it services a
    /// fragment, from the cycle the fragment starts to the cycle the unit is free again.
    OcclusionUnit,
    /// One Occlusion Engine of the O2's unit: busy the cycles it tests its tiles for each
    /// fragment of a query (one a tile, or one for all with `all_tiles_one_cycle`).
    Engine(u32),
    /// The O2's OccU Control: busy from the cycle a fragment with hits starts in the unit
    /// (or a query's end token leaves the depth pipeline) to the port's grant of the last
    /// hit (or record) word it wrote for it.
    OccuControl,
    /// The O2's memory port, one track a client: the cycles the port granted it.
    MemoryPort(PortLane),
    /// The geometry stage (transform and setup of submitted triangles), busy per batch: on
    /// the O2 the host's own geometry work (lane 0, inside the host's busy time), on the
    /// InfiniteReality each Geometry Engine's lane.
    Geometry(u32),
    /// The IR's stage-one merge of a board's Image Engines' partial reports: from the last
    /// engine's report to the board's merged one.
    LocalMerge(u32),
    /// The IR's stage-two merge of the boards' reports, to the result's availability.
    GlobalMerge,
    /// The IR's Fragment Generator of a board.
    FragmentGenerator(u32),
    /// The IR's Image Engines of a board, aggregated (80 a board are too many tracks): busy
    /// from the cycle after a fragment's emission to the cycle its Image Engine is free
    /// again. Intervals come in fragment order, not in order of start, so an interval that
    /// starts before the end of the track's last slice shows only its part after it: the
    /// track shows when the board's engines work, not how many of them.
    ImageEngines(u32),
}

/// A client of the O2's memory port, as the timeline names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PortLane {
    DepthReads,
    /// Drawn fragments' depth and colour writes (and blends' colour reads).
    DepthWrites,
    OccuControl,
    /// Clears' depth and colour words.
    Clears,
}

/// A query's life on the machine: begun, ended and answered (cycles).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QuerySlice {
    pub id: u32,
    pub mode: occsim_traces::QueryMode,
    pub tiles: usize,
    /// The cycle its `begin` entered the pipe.
    pub begin_cycle: u64,
    /// The cycle its `end` entered the pipe (latency counts from here).
    pub end_cycle: u64,
    /// The cycle its result is available.
    pub available_cycle: u64,
}

/// What a block does in a slice.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum State {
    /// Working: emitting, testing, servicing a fragment, the host's own work.
    Busy,
    /// Ready but held: a full FIFO downstream, or memory data not yet there.
    Stalled,
    /// The host blocked on a query's result.
    WaitingForResult,
    /// The host blocked at a frame's end until the pipeline has drawn it.
    WaitingAtFrameEnd,
}

impl State {
    pub fn name(self) -> &'static str {
        match self {
            State::Busy => "busy",
            State::Stalled => "stalled",
            State::WaitingForResult => "waiting on a result",
            State::WaitingAtFrameEnd => "waiting at frame end",
        }
    }
}

/// A closed slice: `track` was in `state` for cycles `start..end`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Slice {
    pub track: Track,
    pub state: State,
    pub start: u64,
    pub end: u64,
}

/// Where closed slices go, each once, in no order across tracks (in order along one), and
/// every query, in the order the queries end.
pub trait TimelineSink: Send {
    fn slice(&mut self, slice: Slice);
    fn query(&mut self, query: QuerySlice);
}

struct Recorder {
    sink: Box<dyn TimelineSink>,
    window: Range<u64>,
    /// The open slice of each track that has one.
    open: Vec<Slice>,
}

impl Recorder {
    fn interval(&mut self, track: Track, state: State, start: u64, end: u64) {
        let (start, end) = (start.max(self.window.start), end.min(self.window.end));
        let at = self.open.iter().position(|s| s.track == track);
        let start = at.map_or(start, |i| start.max(self.open[i].end));
        if start >= end {
            return;
        }
        match at {
            Some(i) if self.open[i].state == state && self.open[i].end == start => {
                self.open[i].end = end;
            }
            Some(i) => {
                let closed = std::mem::replace(
                    &mut self.open[i],
                    Slice {
                        track,
                        state,
                        start,
                        end,
                    },
                );
                self.sink.slice(closed);
            }
            None => self.open.push(Slice {
                track,
                state,
                start,
                end,
            }),
        }
    }
}

/// The recorder the blocks share (a clone is a handle on the same one).
#[derive(Clone)]
pub struct Timeline(Arc<Mutex<Recorder>>);

impl Timeline {
    /// Slices of cycles in `window` (half-open) to `sink`.
    pub fn new(sink: Box<dyn TimelineSink>, window: Range<u64>) -> Timeline {
        Timeline(Arc::new(Mutex::new(Recorder {
            sink,
            window,
            open: Vec::new(),
        })))
    }

    /// `track` was in `state` for cycles `start..end`.
    pub fn interval(&self, track: Track, state: State, start: u64, end: u64) {
        if start < end {
            self.lock().interval(track, state, start, end);
        }
    }

    /// A query was answered: to the sink when any of its life lies in the window.
    pub fn query(&self, query: QuerySlice) {
        let mut recorder = self.lock();
        let window = recorder.window.clone();
        if query.begin_cycle < window.end && query.available_cycle >= window.start {
            recorder.sink.query(query);
        }
    }

    /// Close every open slice (at the run's end).
    pub fn flush(&self) {
        let mut recorder = self.lock();
        for slice in std::mem::take(&mut recorder.open) {
            recorder.sink.slice(slice);
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Recorder> {
        // A panic while recording leaves slices that are still well formed.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// `interval` on an optional timeline: what a block calls (nothing when off).
#[inline(always)]
pub fn note(timeline: &Option<Timeline>, track: Track, state: State, start: u64, end: u64) {
    if let Some(timeline) = timeline {
        timeline.interval(track, state, start, end);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Collect(Arc<Mutex<Vec<Slice>>>);
    impl TimelineSink for Collect {
        fn slice(&mut self, slice: Slice) {
            self.0.lock().unwrap().push(slice);
        }
        fn query(&mut self, _: QuerySlice) {}
    }

    #[test]
    fn adjacent_intervals_of_one_state_merge_and_overlaps_are_clipped() {
        let slices = Arc::new(Mutex::new(Vec::new()));
        let timeline = Timeline::new(Box::new(Collect(slices.clone())), 2..100);
        let busy = |s, e| timeline.interval(Track::Rasterizer, State::Busy, s, e);
        busy(0, 3); // clipped to the window: 2..3
        busy(3, 4); // adjacent: 2..4
        busy(3, 6); // overlaps: 4..6, adjacent: 2..6
        timeline.interval(Track::Rasterizer, State::Stalled, 6, 8);
        busy(9, 10); // a gap: a new slice
        timeline.interval(Track::Host, State::Busy, 0, 200); // 2..100
        timeline.flush();
        let mut got = slices.lock().unwrap().clone();
        got.sort_by_key(|s| (s.track, s.start));
        let slice = |track, state, start, end| Slice {
            track,
            state,
            start,
            end,
        };
        assert_eq!(
            got,
            [
                slice(Track::Host, State::Busy, 2, 100),
                slice(Track::Rasterizer, State::Busy, 2, 6),
                slice(Track::Rasterizer, State::Stalled, 6, 8),
                slice(Track::Rasterizer, State::Busy, 9, 10),
            ]
        );
    }
}
