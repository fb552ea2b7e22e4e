//! Frame time at a level that predicts its pipeline's cycles (the analytic level): the
//! closed loop's host and geometry stage ([`crate::machines::closed_loop`], the same blocks
//! as at the cycle level, so exact) around a pixel pipeline whose windows take the cycles the
//! level predicts.
//!
//! # Rules
//! - Window `w`'s work starts at `s_w = max(e_{w-1}, r_w)`, with `r_w` the release of its
//!   first primitive (the closed loop's rule 3; `e_{w-1}` when it has none), and ends at
//!   `e_w = max(s_w + T_w, r'_w)`, with `r'_w` the release of its last primitive (a pipe
//!   that outruns the geometry stage finishes no earlier than the last primitive arrives;
//!   on a frustum walk of the city at 160x120 on ir1 this took the frame time's error from
//!   20.7% to 0.07%). The releases between hold the formulas' pipe front: a primitive is
//!   set up no earlier than `r_p - s_w` into the window, while the blocks behind work on
//!   (a busy-grid walk of the city draws a large box, then its 600-triangle grid in one
//!   batch the geometry stage takes 100,000 cycles over: the formulas had overlapped the
//!   two, and predicted the window 32% short on ir4). Its query's answer is available at
//!   `max(e_w, r_end) + L_w`, with `r_end`
//!   the release of its end token, and `L_w` the formulas' latency counting only the
//!   backlog still ahead of the token at `r_end`.
//! - A query's latency becomes the formulas' *followed* latency (on the O2, its records
//!   waiting at the in-order port behind the depth reads of the next fragments,
//!   [`crate::levels::analytic::o2`], known once those fragments passed) when the next
//!   window's first primitive comes with no idle gap (`r_{w+1} <= e_w`) and no `wait`,
//!   `begin_conditional` or `swap` before it: only then does the machine emit those
//!   fragments before the records leave ([`PredictedLoop::settle`]).
//! - `wait`, `begin_conditional`: as in the closed loop, against those predicted answers (a
//!   query that never ended counts as answered at 0).
//! - `swap` closes the window it falls in (its work so far predicted as if the stream ended
//!   there, `T` and its drain `D`) and ends the frame when the host has issued it and the
//!   pipe is done: `max(h, e + D, a)`, with `a` the latest answer of the queries so far (on
//!   the IR a many-tile query's merge can outlast the queries after it). The window takes
//!   the wait: the next starts no earlier.
//!
//! With no closed-loop record, every `r_w` is 0 and `e_w = Σ T_w`: the open-loop prediction.

use crate::arch::Arch;
use crate::error::SimError;
use crate::levels::level::WindowEnd;
use crate::machines::closed_loop::{ClosedLoop, PipeState};
use occsim_traces::{Event, QueryTotals};
use std::collections::HashMap;

pub(crate) struct PredictedLoop {
    front: ClosedLoop,
    /// `e` of the last window closed.
    pipe_end: f64,
    /// `s` of the window open, once its first primitive came.
    window_start: Option<f64>,
    /// The release of the open window's last primitive so far.
    last_release: f64,
    /// The last window's latency (or drain).
    tail: f64,
    /// Cycles the pipe stood idle before the window just opened (taken by `take_idle`).
    idle: f64,
    /// Each query's predicted answer: available cycle and record words.
    answers: HashMap<u32, (u64, u64)>,
    /// The last query's id, whose answer a followed latency may still move, and the latest
    /// answer of the queries before it.
    last_answered: Option<u32>,
    latest_settled_answer: u64,
    /// The cycle the last query's end token entered.
    last_token: f64,
    /// The last query's id, until a pause or the next window's first primitive.
    followed: Option<u32>,
    /// The last query's id once the next window's first primitive followed its end token
    /// with no pause, until the formulas give its followed latency ([`Self::settle`]).
    following: Option<u32>,
    /// A latency amended since the caller last asked.
    amended: Option<f64>,
}

impl PredictedLoop {
    pub(crate) fn new(arch: &Arch) -> Result<PredictedLoop, SimError> {
        Ok(PredictedLoop {
            front: crate::machines::closed_loop_of(arch)?,
            pipe_end: 0.0,
            window_start: None,
            last_release: 0.0,
            tail: 0.0,
            idle: 0.0,
            answers: HashMap::new(),
            last_answered: None,
            latest_settled_answer: 0,
            last_token: 0.0,
            followed: None,
            following: None,
            amended: None,
        })
    }

    /// Feed the events the loop acts on (the others pass by); a `swap` needs the open
    /// window's prediction, `cut`, which the caller takes from its formulas.
    /// A query begins, read skimmed: the host issues a command, as [`Self::event`] takes a
    /// whole begin.
    pub(crate) fn query_begin(&mut self) {
        self.front.state_change();
    }

    /// A primitive: released where the host and geometry stage let it go; the first of a
    /// window starts it.
    #[inline]
    pub(crate) fn primitive(&mut self) {
        let release = self.front.primitive_release() as f64;
        self.last_release = release;
        if self.window_start.is_none() {
            self.window_start = Some(self.pipe_end.max(release));
            self.idle = (release - self.pipe_end).max(0.0);
            let followed = self.followed.take();
            if self.idle == 0.0 {
                self.following = followed;
            }
        }
    }

    pub(crate) fn event(&mut self, event: &Event, cut: impl FnOnce() -> Option<WindowEnd>) {
        if matches!(
            event,
            Event::Wait(_) | Event::ConditionalBegin(_) | Event::Swap
        ) {
            // The host stops for an answer or the frame: the pipe drains first.
            self.followed = None;
        }
        match event {
            Event::Geometry(batch) => self.front.geometry(batch),
            Event::HostWork(work) => self.front.host_work(work),
            Event::Primitive => self.primitive(),
            Event::Wait(id) => {
                let (available, words) = self.answers.get(id).copied().unwrap_or((0, 0));
                self.front.wait(available, words);
            }
            Event::ConditionalBegin(id) => {
                let (available, _) = self.answers.get(id).copied().unwrap_or((0, 0));
                self.front.hold_pipe(available);
            }
            Event::Swap => {
                if let Some(end) = cut() {
                    self.close(end);
                }
                let idle = self.idle_cycle();
                self.front.swap(idle);
                // The frame's end waits for the pipe to be through everything: the window
                // the swap closed takes the drain, and the next starts after it.
                self.pipe_end = self.pipe_end.max(idle.idle_cycle as f64);
                self.tail = 0.0;
                self.window_start = None;
            }
            other => self.front.command(other),
        }
    }

    /// The cycles the pipe stood idle, waiting for the host and geometry stage, before the
    /// window the last event opened (0 when it opened none): the formulas' backlog drains
    /// meanwhile.
    pub(crate) fn take_idle(&mut self) -> f64 {
        std::mem::take(&mut self.idle)
    }

    /// The release of the open window's last primitive so far, in cycles from the window's
    /// start: negative where the host released it before the pipe was through the window
    /// before (the window starts at the later of the two).
    pub(crate) fn release_in_window(&self) -> f64 {
        self.last_release - self.window_start()
    }

    /// The host and geometry stage, as at the cycle level.
    pub(crate) fn front(&self) -> &ClosedLoop {
        &self.front
    }

    /// Query `id`'s predicted answer, if it ended: available cycle and record words.
    pub(crate) fn answer(&self, id: u32) -> Option<(u64, u64)> {
        self.answers.get(&id).copied()
    }

    /// The cycle the last query's end token entered the pipe.
    pub(crate) fn last_token(&self) -> f64 {
        self.last_token
    }

    /// `e` of the last window closed.
    pub(crate) fn pipe_end(&self) -> f64 {
        self.pipe_end
    }

    /// Where the host releases the last command it issued (a query's end token) to the pipe.
    pub(crate) fn command_release(&self) -> f64 {
        self.front.command_release() as f64
    }

    /// `s` of the window open (where its work starts).
    pub(crate) fn window_start(&self) -> f64 {
        self.window_start.unwrap_or(self.pipe_end)
    }

    /// Where the open window would end on the timeline were its work `cycles`.
    pub(crate) fn end_if_closed(&self, cycles: f64) -> f64 {
        (self.window_start() + cycles).max(self.last_release)
    }

    fn close(&mut self, end: WindowEnd) {
        self.pipe_end = self.end_if_closed(end.cycles);
        self.tail = end.latency;
        self.window_start = None;
    }

    /// A query ended, closing its window: `end` is the level's prediction.
    pub(crate) fn end_query(&mut self, end: WindowEnd, result: &QueryTotals) {
        self.close(end);
        let words = result.tiles as u64 * occsim_traces::query::BRIEF_RECORD_ENTRIES as u64
            + result.held_hits;
        let token = self.pipe_end.max(self.front.command_release() as f64);
        let available = (token + end.latency).ceil() as u64;
        self.latest_settled_answer = self.latest_answer();
        self.answers.insert(result.id, (available, words));
        self.last_answered = Some(result.id);
        self.last_token = token;
        self.followed = Some(result.id);
        self.following = None;
    }

    /// The next window's first primitive came with the pipe still busy, so its first
    /// fragments followed the last query's end token at once: the query's records wait
    /// behind their depth reads at the in-order port, and its answer comes `latency` after
    /// the token.
    fn amend_latency(&mut self, id: u32, latency: f64) {
        if let Some((available, _)) = self.answers.get_mut(&id) {
            *available = (self.last_token + latency).ceil() as u64;
        }
        self.tail = latency;
        self.amended = Some(latency);
    }

    /// The last query's latency, if amended since the last call (see `amend_latency`).
    fn take_amended_latency(&mut self) -> Option<f64> {
        self.amended.take()
    }

    /// Once the formulas know the last query's `followed` latency (the fragments after its
    /// end token passed, or a pause drained the pipe), the query takes it if the next window
    /// followed its end token at once; the last of a level's per-query latencies (whole
    /// cycles, rounded up) is then set to it. Called after every item the formulas count,
    /// with what they give (`Formulas::take_followed`).
    #[inline]
    pub(crate) fn settle(&mut self, followed: Option<f64>, latencies: &mut [u64]) {
        // Called after every item: nearly always with nothing to settle.
        if followed.is_some() || self.amended.is_some() {
            self.settle_latency(followed, latencies);
        }
    }

    /// [`Self::settle`] where there is something to settle.
    fn settle_latency(&mut self, followed: Option<f64>, latencies: &mut [u64]) {
        if let Some(latency) = followed {
            if let Some(id) = self.following.take() {
                self.amend_latency(id, latency);
            }
        }
        if let (Some(latency), Some(last)) = (self.take_amended_latency(), latencies.last_mut()) {
            *last = latency.ceil() as u64;
        }
    }

    /// The cycle the last of the queries ended so far is answered.
    fn latest_answer(&self) -> u64 {
        let last = self.last_answered.and_then(|id| self.answers.get(&id));
        last.map_or(0, |&(available, _)| available)
            .max(self.latest_settled_answer)
    }

    /// The cycle the pipe is through everything given it: its last window's work and drain,
    /// and every query's answer (on the IR an earlier query's merge can outlast a later
    /// one's: a 64-tile query of the hard cases retiled 8x8 on ir2 answered at cycle 42,963,
    /// the query after it at 39,384, where the run had ended).
    fn idle_cycle(&self) -> PipeState {
        let drained = (self.pipe_end + self.tail).round() as u64;
        PipeState {
            idle_cycle: drained.max(self.latest_answer()),
            // The level predicts no busy split.
            raster_busy_cycles: 0,
        }
    }

    /// The stream ended (`last`: the final window's prediction): each frame's cycles, and
    /// the cycle the run ends.
    pub(crate) fn finish(mut self, last: Option<WindowEnd>) -> (Vec<u64>, u64) {
        if let Some(end) = last {
            self.close(end);
        }
        let idle = self.idle_cycle();
        let (frames, end) = self.front.finish(idle);
        (frames.iter().map(|f| f.cycles).collect(), end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use occsim_traces::{QueryMode, QueryResult, TileResult};

    /// A query whose end token entered at 0 with a latency of 6, for which the formulas,
    /// once the fragments after it passed, give 23 (`levels::analytic::o2` works such
    /// latencies out). The next window's first primitive follows at once (open loop, every
    /// release 0), so the query takes 23 and its answer comes at 23. A `wait` before that
    /// primitive drains the pipe first: the latency stays 6.
    fn followed(wait_first: bool) -> (Vec<u64>, u64) {
        let arch = Arch::builtin("o2").unwrap();
        let mut frames = PredictedLoop::new(&arch).unwrap();
        let result = QueryResult {
            id: 1,
            mode: QueryMode::Brief,
            tiles: vec![TileResult::default()],
            overflowed_buffers: 0,
        }
        .totals();
        let end = WindowEnd {
            cycles: 0.0,
            latency: 6.0,
        };
        frames.end_query(end, &result);
        let mut latencies = vec![6];
        if wait_first {
            frames.event(&Event::Wait(1), || None);
        }
        frames.event(&Event::Primitive, || None);
        frames.settle(Some(23.0), &mut latencies);
        (latencies, frames.answers[&1].0)
    }

    #[test]
    fn a_query_takes_its_followed_latency_only_when_the_next_window_follows_at_once() {
        assert_eq!(followed(false), (vec![23], 23));
        assert_eq!(followed(true), (vec![6], 6));
    }
}
