//! The closed loop around a machine's pixel pipeline: the host ([`crate::blocks::host`]) and
//! the geometry stage ([`crate::blocks::geometry`]) feed it, and the host waits for the
//! answers its decisions need. Frames are timed here.
//!
//! # Timing rules
//! All cycles are pipeline cycles. The host's time `h` starts at 0.
//! 1. `host` work: the host is busy for its nodes, box tests, decisions and read-back
//!    pixels; every state change, clear and query begin or end costs it
//!    `host_cycles_per_state_change` (those before the stream's first closed-loop record are
//!    charged when it comes).
//! 2. A geometry batch: the first of a draw costs the host `host_cycles_per_draw`; then the
//!    geometry stage processes it and releases its primitives at `r` (rules in
//!    [`crate::blocks::geometry`]).
//! 3. The pipeline's input (the O2's rasterizer, every Fragment Generator) can start no
//!    command before the host issued it (`h` when it is fed), no primitive before its
//!    batch's `r`, and nothing before the floor a conditional set (rule 5).
//! 4. `wait Q`: the host blocks until `available(Q) + result_notify_latency_cycles`, then
//!    reads the result's record words (`result_read_cycles_per_word` each, busy). The
//!    pipeline is drained first: nothing fed later can start before the wait ends.
//! 5. `begin_conditional Q`: nothing after it enters the pipeline before `available(Q) +
//!    result_notify_latency_cycles`; the host does not block.
//! 6. `swap`: the frame ends when the host has issued it and the pipeline has finished
//!    everything before it: `end = max(h, idle)`; the host blocks until `end`, and the next
//!    frame starts there. Events after the last swap form a last frame.
//!
//! A stream with none of these records (a version-1 trace) leaves `h` at 0 and the floor at
//! 0, so the pipeline runs exactly as the open loop it was.

use crate::blocks::geometry::Geometry;
use crate::blocks::host::Host;
use crate::report::FrameReport;
use occsim_traces::{Event, GeometryBatch, HostWork};

/// What the front end needs of the pipeline it feeds.
#[derive(Clone, Copy, Debug)]
pub struct PipeState {
    /// The cycle by which every block is idle.
    pub idle_cycle: u64,
    /// Cycles the rasterizer has been busy so far.
    pub raster_busy_cycles: u64,
}

/// Counters at the start of the current frame.
#[derive(Clone, Copy, Default)]
struct FrameStart {
    cycle: u64,
    host_busy: u64,
    geometry_busy: u64,
    waiting: u64,
    pipe_wait: u64,
    raster_busy: u64,
}

pub struct ClosedLoop {
    pub(crate) host: Host,
    geometry: Geometry,
    result_notify_latency_cycles: u64,
    result_read_cycles_per_word: u64,
    clock_mhz: f64,
    /// The current batch's release cycle.
    batch_release: u64,
    /// Nothing enters the pipeline before this cycle (conditionals).
    floor: u64,
    geometry_busy: u64,
    frame: FrameStart,
    frames: Vec<FrameReport>,
    /// Whether any closed-loop record has been seen (frames are reported only then).
    seen: bool,
    /// State changes before the first record, charged when it comes.
    pending_state_changes: u64,
    /// Whether the current frame has had any record since it started.
    frame_open: bool,
}

impl ClosedLoop {
    pub fn new(
        host: Host,
        geometry: Geometry,
        result_notify_latency_cycles: u64,
        result_read_cycles_per_word: u64,
        clock_mhz: f64,
    ) -> ClosedLoop {
        ClosedLoop {
            host,
            geometry,
            result_notify_latency_cycles,
            result_read_cycles_per_word,
            clock_mhz,
            batch_release: 0,
            floor: 0,
            geometry_busy: 0,
            frame: FrameStart::default(),
            frames: Vec::new(),
            seen: false,
            pending_state_changes: 0,
            frame_open: false,
        }
    }

    fn mark(&mut self) {
        if !self.seen {
            self.host
                .state_changes(std::mem::take(&mut self.pending_state_changes));
        }
        self.seen = true;
        self.frame_open = true;
    }

    /// Take up where `other` is (the analytic level's loop at the same point of the
    /// stream) on a timeline `base` cycles later: the host's clock, the geometry stage's
    /// engines and release and the floor, each moved back by `base` (0 where earlier), and
    /// whether a record has come. The frame and the counters stay this loop's.
    ///
    /// Why: a machine started mid-stream has its loop at reset, its host level with its
    /// pipe. Where the host was ahead (it issued the next query's draws while the pipe
    /// worked through the ones before), a host at reset does them again after the start:
    /// on the demo on ir4 with a warm-up of 4,096 fragments, seven sampled windows after
    /// host-bound ones measured 1,100-3,100 cycles long (their brief box's batch released
    /// 2,900 cycles after its query began, where it had come 1,100 cycles before).
    pub fn resume_from(&mut self, other: &ClosedLoop, base: u64) {
        self.host.resume_at(other.host.now().saturating_sub(base));
        self.geometry = other.geometry.moved_back(base);
        self.batch_release = other.batch_release.saturating_sub(base);
        self.floor = other.floor.saturating_sub(base);
        self.seen = other.seen;
        self.pending_state_changes = other.pending_state_changes;
    }

    /// The host's clock: where the last record it issued left it.
    pub fn host_now(&self) -> u64 {
        self.host.now()
    }

    /// A command the driver issues: a state change, clear, or query begin or end costs the
    /// host (counted from the stream's start, but charged only once the stream shows a
    /// closed-loop record, so a stream without one stays the open loop it is).
    pub fn command(&mut self, event: &Event) {
        let is_state_change = matches!(
            event,
            Event::Clear
                | Event::DepthFunc(_)
                | Event::DepthMask(_)
                | Event::DepthTest(_)
                | Event::Cull(_)
                | Event::Scissor(_)
                | Event::QueryBegin(_)
                | Event::QueryEnd
        );
        if is_state_change {
            self.state_change();
        }
    }

    /// The driver issues a state change, a clear, or a query begin or end ([`Self::command`]).
    pub fn state_change(&mut self) {
        if self.seen {
            self.host.state_changes(1);
        } else {
            self.pending_state_changes += 1;
        }
    }

    pub fn clock_mhz(&self) -> f64 {
        self.clock_mhz
    }

    /// Where a command the host has just issued may enter the pipeline.
    #[inline]
    pub fn command_release(&self) -> u64 {
        self.host.now().max(self.floor)
    }

    /// Where the next primitive may enter the pipeline.
    #[inline]
    pub fn primitive_release(&self) -> u64 {
        self.command_release().max(self.batch_release)
    }

    pub fn host_work(&mut self, work: &HostWork) {
        self.mark();
        self.host.work(work);
    }

    pub fn geometry(&mut self, batch: &GeometryBatch) {
        self.mark();
        if batch.starts_draw {
            self.host.draw();
        }
        let (release, busy) = self.geometry.batch(batch, &mut self.host);
        self.batch_release = release;
        self.geometry_busy += busy;
    }

    /// `wait`: the result of the awaited query is available in `available`, `words` long.
    pub fn wait(&mut self, available: u64, words: u64) {
        self.mark();
        self.host
            .wait_for_result(available + self.result_notify_latency_cycles);
        self.host
            .spend(words.saturating_mul(self.result_read_cycles_per_word));
    }

    /// `begin_conditional`: the predicate's result is available in `available`.
    pub fn hold_pipe(&mut self, available: u64) {
        self.mark();
        self.floor = self
            .floor
            .max(available + self.result_notify_latency_cycles);
    }

    /// `swap`: the frame's end, given the pipeline after everything before it.
    pub fn swap(&mut self, pipe: PipeState) {
        self.mark();
        self.end_frame(pipe);
    }

    fn end_frame(&mut self, pipe: PipeState) {
        self.host.wait_for_pipe(pipe.idle_cycle);
        let end = self.host.now();
        let start = self.frame;
        let cycles = end - start.cycle;
        self.frames.push(FrameReport {
            frame: self.frames.len() as u64,
            cycles,
            seconds: cycles as f64 / (self.clock_mhz * 1e6),
            host_busy: self.host.busy_cycles - start.host_busy,
            geometry_busy: self.geometry_busy - start.geometry_busy,
            pixel_busy: pipe.raster_busy_cycles - start.raster_busy,
            waiting: self.host.waiting_cycles - start.waiting,
            pipe_wait: self.host.pipe_wait_cycles - start.pipe_wait,
        });
        self.frame = FrameStart {
            cycle: end,
            host_busy: self.host.busy_cycles,
            geometry_busy: self.geometry_busy,
            waiting: self.host.waiting_cycles,
            pipe_wait: self.host.pipe_wait_cycles,
            raster_busy: pipe.raster_busy_cycles,
        };
        self.frame_open = false;
    }

    /// The end of the stream: the frames (none when the stream had no closed-loop record)
    /// and the cycle the run ends.
    pub fn finish(mut self, pipe: PipeState) -> (Vec<FrameReport>, u64) {
        if self.seen && self.frame_open {
            self.end_frame(pipe);
        }
        let end = self.host.now().max(pipe.idle_cycle);
        (self.frames, end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::arch::Arch;
    use crate::machines::closed_loop_of;
    use occsim_traces::GeometryBatch;

    fn batch(vertices: u32) -> GeometryBatch {
        GeometryBatch {
            vertices,
            triangles: vertices / 3,
            starts_draw: true,
            discarded: false,
        }
    }

    /// A loop resumed from another on a timeline `base` cycles later releases every later
    /// command and primitive `base` cycles sooner, as long as the host's clock is not
    /// earlier than `base`; with `base` past every clock, the loop is at reset.
    #[test]
    fn a_resumed_loop_releases_what_the_loop_it_took_up_releases_base_cycles_sooner() {
        let arch = Arch::builtin("ir4").unwrap();
        let mut original = closed_loop_of(&arch).unwrap();
        // The host runs ahead: three batches, the geometry engines busy with them.
        for vertices in [3_000, 600, 36] {
            original.command(&Event::Clear);
            original.geometry(&batch(vertices));
            original.command(&Event::QueryEnd);
        }
        let host = original.host_now();
        let release = original.primitive_release();
        assert!(release > host, "the geometry stage holds the last batch");
        // Base at the host's clock: what the original holds before it (the fourth geometry
        // engine, idle at 0) the host's clock outweighs in both loops.
        let mut resumed = closed_loop_of(&arch).unwrap();
        resumed.resume_from(&original, host);
        assert_eq!(resumed.host_now(), 0);
        assert_eq!(resumed.primitive_release(), release - host);
        for vertices in [36, 1_200, 36] {
            for lp in [&mut original, &mut resumed] {
                lp.command(&Event::Clear);
                lp.geometry(&batch(vertices));
            }
            assert_eq!(resumed.host_now() + host, original.host_now());
            assert_eq!(
                resumed.primitive_release() + host,
                original.primitive_release()
            );
        }
        // Base past every clock: a loop at reset but for having seen records.
        let mut late = closed_loop_of(&arch).unwrap();
        late.resume_from(&original, u64::MAX);
        assert_eq!((late.host_now(), late.primitive_release()), (0, 0));
        assert!(late.seen);
    }
}
