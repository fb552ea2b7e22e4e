//! The O2-like machine: one rasterizer and one pixel pipeline with the Occlusion Unit, all
//! clocked at the rendering engine's clock and sharing one main-memory port.
//!
//! ```text
//! fragment_input -> FIFO -> depth_pipeline (prefetch, test, write buffer) -> FIFO
//!   -> occlusion_unit (E engines) -> occu_control -> memory_port
//! ```
//!
//! # Timing rules (the RTL model must match them cycle for cycle)
//! Cycles count from 0. `X_{i-n}` for a fragment before the first reads as 0.
//! 1. Rasterizer ([`crate::blocks::fragment_input`]): a primitive costs `primitive_setup_cycles`;
//!    fragment `i` is emitted in `a_i = max(free, slot)`, one per cycle, where the
//!    raster-to-depth FIFO slot frees when fragment `i - fifo_raster_to_depth_entries`
//!    entered the depth test (same-cycle reuse).
//! 2. Prefetch ([`crate::blocks::depth_prefetch`]): request cycle
//!    `q_i = max(a_i + 1, d_{i-P}, q_{i-1} + 1)`; a fragment whose word is the last word read
//!    reuses that read's data; otherwise one port word is granted in `g >= q_i` and the data
//!    is ready in `g + page_hit_latency_cycles` (same 64 KB tile as the last read) or
//!    `g + page_miss_latency_cycles`. Nothing is read when the depth test is off.
//! 3. Depth test ([`crate::blocks::depth_pipeline`]): `d_i = max(a_i + 1, d_{i-1} + 1, r_i,
//!    o_{i-C2}, w)` with `C2 = fifo_depth_to_occu_entries` and `w` the depth write buffer's
//!    slot when the fragment writes; the write asks the port from `d_i + 1`, in order.
//! 4. Occlusion Unit ([`crate::blocks::occlusion_unit`]): `o_i = max(d_i + 1, c_{i-1} + 1)`, busy
//!    `s = max_e k_e` cycles (1 with `all_tiles_one_cycle` or no open query); its hit words
//!    enter OccU Control's buffer from `o_i + s - 1`; it leaves in `c_i`, the cycle its last
//!    hit word entered (or `o_i + s - 1`).
//! 5. Memory port ([`crate::blocks::memory_port`]): in-order, in this request order. With
//!    `L = min(prefetch_depth_fragments, fifo_raster_to_depth_entries)` (the prefetcher
//!    only sees fragments in the FIFO): first the depth reads of fragments `0..L`; then for
//!    each fragment `j` in trace order: (a) the records of the queries that ended just before
//!    it, (b) its depth write, (c) its OccU hit words, (d) the depth read of fragment
//!    `j + L`; last the records of queries that end after the last fragment. Within one
//!    fragment the engines' hit words go round-robin (engine 0, 1, ...); records go tile by
//!    tile in query order, which is round-robin over the engines too. All OccU words are 32
//!    bits, so their order inside a group never changes a cycle count.
//! 6. Query end: the `end` token enters in `t_end` = the rasterizer's first free cycle and
//!    takes no slot; it passes the depth pipeline in `td = max(t_end + 1, d_last + 1)` and
//!    the OccU in `to = max(td + 1, c_last + 1)`; OccU Control's records are ready in
//!    `to + 1` ([`crate::blocks::occu_control`]); the result is available in the cycle after the
//!    last record word's grant. Latency = available - `t_end`, at least
//!    [`MIN_QUERY_LATENCY_CYCLES`].
//! 7. Closed loop ([`crate::machines::closed_loop`]): when the host or the geometry stage
//!    releases a command or primitive later than the rasterizer's first free cycle, the
//!    rasterizer idles until then, and the items already past it are finished first (their
//!    port requests precede the later fragments' in rule 5's order).
//! 8. State changes and `begin` take no cycles. A `clear` reaches the depth pipeline in order
//!    and, with `clear_writes_memory`, writes the viewport's depth and colour words through
//!    the port from the cycle the depth test is free; the depth test waits for the last
//!    ([`crate::blocks::depth_pipeline`]); without it, it is a free fast clear.
//! 9. The port's other clients ([`crate::blocks::memory_port`]). Arbitration: the display
//!    refresh (`display_*`: W x H x bits x Hz a second over the port's bits a second) and the
//!    host (`host_memory_share`) need a share `f` of the port's whole cycles; they take every
//!    cycle the pipeline leaves idle, and a cycle the pipeline asks for only when they would
//!    otherwise fall more than `other_clients_slack_cycles` behind (a debt, settled cycle by
//!    cycle); the pixel pipeline's requests share the other cycles in rule 5's order, a
//!    drawn fragment's colour write
//!    (`colour_bits_per_pixel`; under `blending` after a colour read) travelling with its
//!    depth write (b), a clear's words where the clear stands. Occlusion render modes draw
//!    nothing, so they write no colour. Depth reads hit the open row of their bank
//!    (`memory_banks`, [`crate::blocks::depth_prefetch`]). Stencil traffic is not modelled.
//!    With colour bits 0, no refresh (a display size or rate of 0), no host share, no clear
//!    writes and one bank, the machine is the one of rules 1-8 before these clients.

use crate::arch::{Arch, O2Arch};
use crate::blocks::depth_pipeline::DepthPipeline;
use crate::blocks::fifo::Fifo;
use crate::blocks::fragment_input::FragmentInput;
use crate::blocks::memory_port::MemoryPort;
use crate::blocks::occlusion_unit::engine_service_cycles;
use crate::blocks::occu_stage::OccuStage;
use crate::effects::Effects;
use crate::error::{check_spec, SimError};
use crate::golden_check::{first_difference, GoldenCheck};
use crate::machines::builder::MachineBuilder;
use crate::report::{
    percent, ArchEntry, EngineReport, PortReport, QueryReport, Report, RunTotals, StageReport,
    Summary, TileReport, TileTotals,
};
use crate::timeline::{note, QuerySlice, State, Timeline, Track};
use occsim_traces::golden::DepthBuffer;
use occsim_traces::state::RenderState;
use occsim_traces::{Event, Fragment, QueryMode, QueryResult, QuerySpec, Span, TileResult};
use std::collections::VecDeque;

/// The shortest possible query latency: the end token crosses the FIFO into the depth
/// pipeline (1), the depth pipeline (1), the OccU (1), enters OccU Control's buffer (1) and
/// is written (1).
pub const MIN_QUERY_LATENCY_CYCLES: u64 = 5;

struct OpenQuery {
    spec: QuerySpec,
    fragments: u64,
    /// The cycle its begin entered the pipe.
    begin_cycle: u64,
    /// With a timeline: each engine's cycles per fragment.
    engine_cycles: Vec<u64>,
}

/// An item that passed the front end (rasterizer and prefetch) and waits for the back end
/// (depth test, OccU, OccU Control).
enum Pending {
    Fragment {
        fragment: Fragment,
        /// First cycle the depth pipeline can read it from the rasterizer FIFO.
        arrive: u64,
        /// Cycle its depth data is ready.
        data_ready: u64,
        /// Its depth test's outcome, when a fast-forward took the test (and counted the
        /// fragment in the open query's tiles) as the fragment entered ([`O2Machine::span`]).
        tested: Option<bool>,
    },
    /// A query begin that entered the pipe in `entered`.
    QueryBegin { spec: Box<QuerySpec>, entered: u64 },
    /// A query end that entered the pipe in `entered`.
    QueryEnd { entered: u64, event: u64 },
    /// Any other event, applied in order by the back end.
    /// (Boxed: fragments, the common item, stay small.)
    Other { event: Box<Event>, index: u64 },
}

pub struct O2Machine {
    arch: O2Arch,
    arch_entries: Vec<ArchEntry>,
    width: u32,
    height: u32,
    input: FragmentInput,
    raster_to_depth: Fifo,
    depth: DepthPipeline,
    depth_to_occu: Fifo,
    /// The Occlusion Unit and OccU Control, at the chosen fidelity.
    occu: OccuStage,
    port: MemoryPort,
    /// Items between front and back end, at most `lookahead` fragments.
    pending: VecDeque<Pending>,
    pending_fragments: usize,
    /// How many fragments the front end runs ahead of the depth test:
    /// min(prefetch_depth_fragments, fifo_raster_to_depth_entries).
    lookahead: usize,
    /// The depth test enable as the front end sees it (decides whether to read).
    front_depth_test: bool,
    /// Queries begun minus ended, as the front end sees them (for stream errors).
    front_open: Option<u32>,
    open: Option<OpenQuery>,
    /// The result of the query that just ended, waiting for the stream's golden result.
    golden: GoldenCheck,
    queries: Vec<QueryReport>,
    events: u64,
    last_available: u64,
    /// The effect models built ([`crate::effects`]); all of them unless a scan proved some
    /// unobservable.
    effects: Effects,
    /// Where the blocks' intervals go, if anywhere.
    timeline: Option<Timeline>,
    /// Each query's report keeps every tile's, else the tiles' totals only
    /// ([`crate::MachineModel::keep_tile_reports`]).
    tile_reports: bool,
    /// Fragments taken by a fast-forward ([`Self::span`]).
    fast_forwarded: u64,
    /// A fast-forward's scratch (kept to reuse its memory): the fragments the back end tests,
    /// in order (the queued ones it takes, then the span's as they enter), and the span's
    /// depth tests' outcomes.
    span_backs: Vec<Entered>,
    span_passed: Vec<bool>,
}

/// A fragment a fast-forward let in: its times through the front end and its depth test's
/// outcome.
#[derive(Clone, Copy, Debug)]
struct Entered {
    times: FrontTimes,
    passed: bool,
}

/// What holds over a fast-forward's span.
#[derive(Clone, Copy, Debug)]
struct SpanModes {
    occlusion_mode: bool,
    query_open: bool,
    /// A fragment that passes writes depth or colour.
    passing_writes: bool,
}

/// When a fragment is readable from the rasterizer FIFO and its depth data is ready.
#[derive(Clone, Copy, Debug)]
struct FrontTimes {
    arrive: u64,
    data_ready: u64,
}

impl O2Machine {
    /// The machine `arch` describes at reset, every effect modelled, the OccU at the cycle
    /// level: shorthand for [`MachineBuilder::o2`].
    pub fn new(arch: &Arch, width: u32, height: u32) -> Result<O2Machine, SimError> {
        MachineBuilder::new(arch).o2(width, height)
    }

    /// [`Self::finish`], handing the depth buffer's memory back for reuse.
    /// The depth buffer the depth test reads ([`super::MachineModel::depth_buffer_mut`]).
    pub fn depth_buffer_mut(&mut self) -> &mut DepthBuffer {
        self.depth.depth_buffer_mut()
    }

    pub fn finish_recycling(mut self) -> Result<(Report, DepthBuffer), SimError> {
        // The fragments still pending are tested first: they need the buffer.
        while self.front_open.is_none() && !self.pending.is_empty() {
            self.back_one()?;
        }
        let depth = self.depth.take_depth_buffer();
        Ok((self.finish()?, depth))
    }

    /// [`crate::MachineModel::keep_tile_reports`].
    pub(crate) fn keep_tile_reports(&mut self, keep: bool) {
        self.tile_reports = keep;
    }

    /// The one constructor: the blocks of `build`'s architecture, effects and OccU fidelity
    /// for a `width` x `height` viewport, starting from `depth` and, when given, a
    /// functional model's render state (a warm start) instead of the reset state.
    pub(crate) fn assemble(
        build: MachineBuilder<'_>,
        width: u32,
        height: u32,
        depth: DepthBuffer,
        state: Option<&RenderState>,
    ) -> Result<O2Machine, SimError> {
        let (arch, effects, model) = (build.arch, build.effects, build.occu);
        let o2 = arch.o2()?;
        let arch_entries = arch.report_entries();
        let mut machine = O2Machine {
            arch: o2.clone(),
            input: FragmentInput::new(o2.primitive_setup_cycles),
            raster_to_depth: Fifo::new(o2.fifo_raster_to_depth_entries),
            depth: DepthPipeline::new(&o2, width, height, effects, depth),
            depth_to_occu: Fifo::new(o2.fifo_depth_to_occu_entries),
            occu: OccuStage::new(&o2, model),
            port: MemoryPort::with_other_clients(
                o2.memory_port_bits_per_cycle,
                o2.reserved_port_share(),
                o2.other_clients_slack_cycles,
            ),
            arch_entries,
            width,
            height,
            pending: VecDeque::new(),
            pending_fragments: 0,
            lookahead: o2
                .prefetch_depth_fragments
                .min(o2.fifo_raster_to_depth_entries),
            front_depth_test: true,
            front_open: None,
            open: None,
            golden: GoldenCheck::default(),
            queries: Vec::new(),
            events: 0,
            last_available: 0,
            effects,
            timeline: build.timeline,
            tile_reports: true,
            fast_forwarded: 0,
            span_backs: Vec::new(),
            span_passed: Vec::new(),
        };
        machine.port.set_timeline(machine.timeline.clone());
        if let Some(state) = state {
            machine.depth.load_state(state);
            machine.front_depth_test = state.depth_test;
        }
        Ok(machine)
    }

    /// Feed one event of the stream.
    #[inline]
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        let index = self.events;
        self.events += 1;
        match event {
            Event::Fragment(f) => return self.front_fragment(*f, index),
            Event::Primitive => {
                let free = self.input.free_cycle();
                self.input.primitive();
                let setup_end = self.input.free_cycle();
                note(
                    &self.timeline,
                    Track::Rasterizer,
                    State::Busy,
                    free,
                    setup_end,
                );
            }
            Event::DepthTest(on) => {
                self.front_depth_test = *on;
                self.pending.push_back(Pending::Other {
                    event: Box::new(event.clone()),
                    index,
                });
            }
            Event::QueryBegin(spec) => {
                check_spec(spec.shape(), index, self.front_open)?;
                self.front_open = Some(spec.id);
                self.pending.push_back(Pending::QueryBegin {
                    spec: Box::new(spec.clone()),
                    entered: self.input.free_cycle(),
                });
            }
            Event::QueryEnd => {
                if self.front_open.take().is_none() {
                    return Err(SimError::EndWithoutBegin { event: index });
                }
                let entered = self.input.free_cycle();
                self.pending.push_back(Pending::QueryEnd {
                    entered,
                    event: index,
                });
            }
            // The closed loop's records are the front end's ([`crate::machines::closed_loop`]).
            Event::Geometry(_)
            | Event::HostWork(_)
            | Event::Wait(_)
            | Event::ConditionalBegin(_)
            | Event::ConditionalEnd
            | Event::Swap => {}
            _ => self.pending.push_back(Pending::Other {
                event: Box::new(event.clone()),
                index,
            }),
        }
        Ok(())
    }

    /// Front end: emit the fragment and issue its depth read, once the back end has tested
    /// the fragment `lookahead` places earlier (which frees its FIFO and prefetch slots).
    #[inline]
    fn front_fragment(&mut self, fragment: Fragment, event: u64) -> Result<(), SimError> {
        crate::error::check_fragment_inside(&fragment, event, self.width, self.height)?;
        while self.pending_fragments >= self.lookahead {
            self.back_one()?;
        }
        let free = self.input.free_cycle();
        let FrontTimes { arrive, data_ready } = self.front_times(fragment);
        if self.timeline.is_some() {
            let (t, emitted) = (&self.timeline, arrive - 1);
            note(t, Track::Rasterizer, State::Stalled, free, emitted);
            note(t, Track::Rasterizer, State::Busy, emitted, emitted + 1);
        }
        self.pending.push_back(Pending::Fragment {
            fragment,
            arrive,
            data_ready,
            tested: None,
        });
        self.pending_fragments += 1;
        Ok(())
    }

    /// Emit the next fragment and issue its depth read (rules 1 and 2).
    #[inline(always)]
    fn front_times(&mut self, fragment: Fragment) -> FrontTimes {
        // The back end lags up to `lookahead` fragments behind: address the FIFO and the
        // prefetch slots by this fragment's number, not by the departures recorded so far.
        let index = self.input.fragments as usize;
        let emitted = self
            .input
            .emit(self.raster_to_depth.slot_free_cycle_for(index));
        let arrive = emitted + 1;
        let data_ready = self.depth.fetch(
            index,
            fragment,
            arrive,
            self.front_depth_test,
            &mut self.port,
        );
        FrontTimes { arrive, data_ready }
    }

    /// A span of fragments: fast-forwarded where the rule of [`crate::effects`] allows it,
    /// otherwise fed one by one.
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        if self.may_fast_forward(span) {
            self.fast_forward(span);
            return Ok(());
        }
        span.fragments()
            .try_for_each(|fragment| self.event(&Event::Fragment(fragment)))
    }

    /// The fast-forward rule's conditions ([`crate::effects`]): allowed, nothing records
    /// the blocks' intervals, the Occlusion Unit is the event-timestamp one, the lookahead
    /// window holds fragments only (no state change or query boundary between them), no
    /// verbose query is open and the span lies inside the viewport (a fragment outside it is
    /// an error the fragment-by-fragment path reports).
    fn may_fast_forward(&mut self, span: Span) -> bool {
        self.effects.fast_forward
            && self.timeline.is_none()
            && self.pending.len() == self.pending_fragments
            && !self
                .open
                .as_ref()
                .is_some_and(|q| q.spec.mode == QueryMode::Verbose)
            && span.x as u64 + span.depths.len() as u64 <= self.width as u64
            && (span.y as u32) < self.height
            && self.occu.cycle_unit().is_some()
    }

    /// Replay a span the way its fragments one by one would, in bulk: each unit of work is
    /// the back end's oldest fragment then the front end's next, as one by one; the
    /// depth tests and the Occlusion Unit's counts are taken for the whole span at once.
    fn fast_forward(&mut self, span: Span) {
        let n = span.depths.len();
        self.events += n as u64;
        self.fast_forwarded += n as u64;
        let occlusion_mode = self
            .open
            .as_ref()
            .is_some_and(|q| q.spec.mode.is_occlusion_render_mode());
        let modes = SpanModes {
            occlusion_mode,
            query_open: self.open.is_some(),
            passing_writes: self.depth.writes_if_passed(occlusion_mode),
        };
        // Unit k tests a fragment once `lookahead` wait: from unit `first_back` on. The
        // queued ones go first, then the span's own first `own`; the rest stay queued.
        let queued = self.pending_fragments;
        let first_back = self.lookahead.saturating_sub(queued);
        let backs = n.saturating_sub(first_back);
        let from_queue = backs.min(queued);
        let own = backs - from_queue;
        self.test_all(span, occlusion_mode, modes.query_open);
        self.take_queued(from_queue);
        let mut k = 0;
        while k < n {
            if k >= first_back {
                let units = self.run_lockstep(span, k, k - first_back, modes);
                if units > 0 {
                    k += units;
                    continue;
                }
                let entered = self.span_backs[k - first_back];
                self.time_back(
                    entered.times,
                    entered.passed,
                    occlusion_mode,
                    modes.query_open,
                );
            }
            let x = span.x.wrapping_add(k as u16);
            let times = self.front_times(Fragment {
                x,
                y: span.y,
                z: span.depths[k],
            });
            let passed = self.span_passed[k];
            self.span_backs.push(Entered { times, passed });
            k += 1;
        }
        for (fragment, entered) in span
            .fragments()
            .zip(&self.span_backs[from_queue..])
            .skip(own)
        {
            self.pending.push_back(Pending::Fragment {
                fragment,
                arrive: entered.times.arrive,
                data_ready: entered.times.data_ready,
                tested: Some(entered.passed),
            });
        }
        self.pending_fragments = queued - from_queue + (n - own);
        if let Some(query) = &mut self.open {
            query.fragments += backs as u64;
        }
    }

    /// The first `count` queued fragments, taken from the queue to be tested first.
    fn take_queued(&mut self, count: usize) {
        self.span_backs.clear();
        for _ in 0..count {
            let Some(Pending::Fragment {
                arrive,
                data_ready,
                tested: Some(passed),
                ..
            }) = self.pending.pop_front()
            else {
                unreachable!("the fast-forward rule: the lookahead window holds fragments only");
            };
            let times = FrontTimes { arrive, data_ready };
            self.span_backs.push(Entered { times, passed });
        }
    }

    /// Run units from unit `k` of a fast-forward (whose back end tests its `back`-th
    /// fragment) in lockstep, the rule of [`crate::effects`]: every block takes one fragment
    /// a cycle and nothing waits; the port requests (the tested fragment's writes, then the
    /// entering one's depth read) are made in their order, exactly. Returns the units run
    /// (0 when the rule does not hold for the first).
    ///
    /// The departures the run's FIFO slots depend on were recorded before it (checked here
    /// first) or are the run's own, in closed form (a bound on the run's start); each unit's
    /// tested fragment is checked before any of the unit's requests is made, so the run
    /// stops with every block's state that of the units run.
    fn run_lockstep(&mut self, span: Span, k: usize, back: usize, modes: SpanModes) -> usize {
        let occu_free = match self.occu.cycle_unit() {
            Some(unit) if unit.service_cycles() == 1 => unit.free_cycle(),
            _ => return 0,
        };
        // Unit u emits in a + u, tests in d + u, requests its depth in q + u.
        let (a, d) = (self.input.free_cycle(), self.depth.free_cycle());
        let q = self
            .depth
            .prefetch
            .last_request()
            .map_or(a + 1, |last| (a + 1).max(last + 1));
        let most = self.lockstep_bound(span.depths.len() - k, a, d, q, occu_free);
        let read = self.front_depth_test;
        let mut units = 0;
        // A word at a time: its first fragment's fetch (a depth read unless it is the last
        // read's word), its others' word hits, which request nothing of the port.
        while units < most {
            let x = span.x.wrapping_add((k + units) as u16);
            let word = match read {
                true => self.depth.prefetch.pixels_left_in_word(x) as usize,
                false => most,
            };
            // A unit tests the fragment that entered `lookahead` units before it: at most
            // that many units' fragments can enter before the first is tested.
            let word = word.min(most - units).min(self.lookahead);
            if !self.lockstep_back(back + units, d + units as u64, modes) {
                break;
            }
            let port = &mut self.port;
            let data_ready = self
                .depth
                .prefetch
                .fetch_at(q + units as u64, x, span.y, read, port);
            let taken = (units + 1..units + word)
                .find(|&unit| !self.lockstep_back(back + unit, d + unit as u64, modes))
                .unwrap_or(units + word)
                - units;
            let last_request = q + (units + taken) as u64 - 1;
            self.depth
                .prefetch
                .fetch_word_hits(taken as u64 - 1, last_request, read);
            let passed = &self.span_passed[k + units..k + units + taken];
            self.span_backs
                .extend(passed.iter().enumerate().map(|(i, &passed)| Entered {
                    times: FrontTimes {
                        arrive: a + (units + i) as u64 + 1,
                        data_ready,
                    },
                    passed,
                }));
            units += taken;
            if taken < word {
                break;
            }
        }
        self.advance_lockstep(units, modes.query_open);
        units
    }

    /// Advance the blocks over the `units` of a lockstep run, one fragment a cycle each, in
    /// closed form: what its units one by one give.
    fn advance_lockstep(&mut self, units: usize, query_open: bool) {
        if units == 0 {
            return;
        }
        self.input.emit_run(units as u64);
        let tested = self.depth.time_run(units);
        self.raster_to_depth.depart_run(tested, units);
        let Some(unit) = self.occu.cycle_unit() else {
            unreachable!("the fast-forward rule: the cycle-level Occlusion Unit");
        };
        let start = unit.time_run_without_hits(tested + 1, units as u64, query_open);
        self.depth_to_occu.depart_run(start, units);
    }

    /// The back end's `back`-th fragment of a fast-forward in a lockstep run, tested in
    /// `cycle`: false, with nothing changed, unless it is readable with its depth data by
    /// then and has a write-buffer slot if it writes; true once its writes are made.
    #[inline(always)]
    fn lockstep_back(&mut self, back: usize, cycle: u64, modes: SpanModes) -> bool {
        let Entered { times, passed } = self.span_backs[back];
        if times.arrive > cycle || times.data_ready > cycle {
            return false;
        }
        !(passed && modes.passing_writes)
            || self
                .depth
                .write_in_lockstep(passed, modes.occlusion_mode, cycle, &mut self.port)
    }

    /// The most units (of `most`) a lockstep run from emission cycle `a`, test cycle `d` and
    /// request cycle `q` may take before a FIFO slot could make a block wait: the slots of
    /// its first units come from departures recorded before it, the later ones from the
    /// run's own, `capacity - lookahead` units (the depth-to-OccU FIFO: its capacity) back.
    fn lockstep_bound(&self, most: usize, a: u64, d: u64, q: u64, occu_free: u64) -> usize {
        let index = self.input.fragments as usize;
        let within = |units: usize, recorded: usize, slot: &dyn Fn(usize) -> u64, ok: u64| {
            let first_late = (0..units.min(recorded)).find(|&u| slot(u) > ok + u as u64);
            first_late.unwrap_or(units)
        };
        // Depth-to-OccU slots: the run's own OccU starts are max(d + 1, occu_free) + u.
        let c2 = self.depth_to_occu.capacity();
        let mut units = within(
            most,
            c2,
            &|u| self.depth_to_occu.slot_free_cycle_ahead(u),
            d,
        );
        if units > c2 && occu_free > d + c2 as u64 {
            units = c2;
        }
        // Rasterizer FIFO and prefetch slots: the run's own tests are in d + u.
        let c = self.raster_to_depth.capacity() - self.lookahead;
        let raster = |u: usize| self.raster_to_depth.slot_free_cycle_for(index + u);
        units = within(units, c, &raster, a);
        if units > c && d > a + c as u64 {
            units = c;
        }
        let p = self.depth.prefetch.slots() - self.lookahead;
        let prefetch = |u: usize| self.depth.prefetch.slot_free_cycle_for(index + u);
        units = within(units, p, &prefetch, q);
        if units > p && d > q + p as u64 {
            units = p;
        }
        units
    }

    /// A fast-forward's depth tests and counts, all as the span enters: first the queued
    /// fragments' not yet taken (they come earlier and may touch the same pixels), one by
    /// one, then the span's at once. With no state change or query boundary queued, each
    /// is tested under the state and counted in the query it would meet one by one.
    fn test_all(&mut self, span: Span, occlusion_mode: bool, query_open: bool) {
        for item in &mut self.pending {
            let Pending::Fragment {
                fragment, tested, ..
            } = item
            else {
                unreachable!("the fast-forward rule: the lookahead window holds fragments only");
            };
            if tested.is_none() {
                let passed = self.depth.test_fragment(*fragment, occlusion_mode);
                if let (true, Some(unit)) = (query_open, self.occu.cycle_unit()) {
                    let hit_words = unit.count(*fragment, passed);
                    debug_assert_eq!(hit_words, 0, "no verbose query is open");
                }
                *tested = Some(passed);
            }
        }
        self.depth
            .test_span(span, occlusion_mode, &mut self.span_passed);
        if let (true, Some(unit)) = (query_open, self.occu.cycle_unit()) {
            unit.count_span(span, &self.span_passed);
        }
    }

    /// The back end's timing of a fragment already tested and counted (rules 3 and 4
    /// without hit words).
    #[inline(always)]
    fn time_back(
        &mut self,
        times: FrontTimes,
        passed: bool,
        occlusion_mode: bool,
        query_open: bool,
    ) {
        let out_slot = self.depth_to_occu.slot_free_cycle();
        let cycle = self.depth.time(
            passed,
            times.arrive,
            times.data_ready,
            out_slot,
            occlusion_mode,
            &mut self.port,
        );
        self.raster_to_depth.depart(cycle);
        let Some(unit) = self.occu.cycle_unit() else {
            unreachable!("the fast-forward rule: the cycle-level Occlusion Unit");
        };
        let start = unit.time_without_hits(cycle + 1, query_open);
        self.depth_to_occu.depart(start);
    }

    /// Fragments fast-forwarded so far.
    pub fn fast_forwarded_fragments(&self) -> u64 {
        self.fast_forwarded
    }

    /// Back end: process the oldest pending item.
    fn back_one(&mut self) -> Result<(), SimError> {
        match self.pending.pop_front() {
            Some(Pending::Fragment {
                fragment,
                arrive,
                data_ready,
                tested,
            }) => {
                self.pending_fragments -= 1;
                let times = FrontTimes { arrive, data_ready };
                match tested {
                    None => self.back_fragment(fragment, times),
                    Some(passed) => self.back_tested(times, passed),
                }
            }
            Some(Pending::QueryBegin { spec, entered }) => self.begin(&spec, entered),
            Some(Pending::QueryEnd { entered, event }) => self.end(entered, event)?,
            Some(Pending::Other { event, index }) => self.back_event(&event, index)?,
            None => {}
        }
        Ok(())
    }

    fn back_event(&mut self, event: &Event, index: u64) -> Result<(), SimError> {
        if self.depth.state.apply(event) {
            return Ok(());
        }
        match event {
            Event::Clear => self.depth.clear(&mut self.port),
            Event::QueryResult(golden) => return self.check(golden, index),
            _ => {}
        }
        Ok(())
    }

    /// A fragment a fast-forward tested and counted as it entered, tested now: timed only.
    fn back_tested(&mut self, times: FrontTimes, passed: bool) {
        let occlusion_mode = self
            .open
            .as_ref()
            .is_some_and(|q| q.spec.mode.is_occlusion_render_mode());
        let query_open = self.open.is_some();
        self.time_back(times, passed, occlusion_mode, query_open);
        if let Some(query) = &mut self.open {
            query.fragments += 1;
        }
    }

    #[inline]
    fn back_fragment(&mut self, fragment: Fragment, times: FrontTimes) {
        let FrontTimes { arrive, data_ready } = times;
        let query_open = self.open.is_some();
        let occlusion_mode = self
            .open
            .as_ref()
            .is_some_and(|q| q.spec.mode.is_occlusion_render_mode());
        let out_slot = self.depth_to_occu.slot_free_cycle();
        let tested = self.depth.test(
            fragment,
            arrive,
            data_ready,
            out_slot,
            occlusion_mode,
            &mut self.port,
        );
        self.raster_to_depth.depart(tested.cycle);
        if self.timeline.is_some() {
            let (t, cycle) = (&self.timeline, tested.cycle);
            note(t, Track::DepthPipeline, State::Stalled, arrive, cycle);
            note(t, Track::DepthPipeline, State::Busy, cycle, cycle + 1);
        }
        let granted_before = self.occu.last_grant();
        let start = self.occu.fragment(
            fragment,
            tested.passed,
            tested.cycle + 1,
            query_open,
            &mut self.port,
            self.effects.verbose_hit_writes,
        );
        self.depth_to_occu.depart(start);
        if self.timeline.is_some() {
            self.note_occu(start, granted_before);
        }
        if let Some(query) = &mut self.open {
            query.fragments += 1;
        }
    }

    /// The timeline's Occlusion Unit, engine and OccU Control slices of a fragment that
    /// started in the unit in `start` (OccU Control's last grant was `granted_before`).
    fn note_occu(&self, start: u64, granted_before: Option<u64>) {
        let t = &self.timeline;
        note(
            t,
            Track::OcclusionUnit,
            State::Busy,
            start,
            self.occu.free_cycle(),
        );
        if let Some(query) = &self.open {
            for (e, &cycles) in query.engine_cycles.iter().enumerate() {
                note(
                    t,
                    Track::Engine(e as u32),
                    State::Busy,
                    start,
                    start + cycles,
                );
            }
        }
        self.note_occu_control(start, granted_before);
    }

    /// OccU Control busy from `from` to the grant of its last word, if it wrote any since
    /// `granted_before`.
    fn note_occu_control(&self, from: u64, granted_before: Option<u64>) {
        match self.occu.last_grant() {
            Some(last) if Some(last) != granted_before => {
                note(
                    &self.timeline,
                    Track::OccuControl,
                    State::Busy,
                    from,
                    last + 1,
                );
            }
            _ => {}
        }
    }

    fn begin(&mut self, spec: &QuerySpec, begin_cycle: u64) {
        self.occu.begin(spec);
        let engine_cycles = match self.timeline {
            Some(_) => engine_service_cycles(
                spec.tiles.len(),
                self.arch.occu.engines,
                self.arch.occu.all_tiles_one_cycle,
            ),
            None => Vec::new(),
        };
        self.open = Some(OpenQuery {
            spec: spec.clone(),
            fragments: 0,
            begin_cycle,
            engine_cycles,
        });
    }

    /// The back end reaches a query end that entered the pipe in `end_cycle`.
    fn end(&mut self, end_cycle: u64, event: u64) -> Result<(), SimError> {
        let query = self
            .open
            .take()
            .ok_or(SimError::EndWithoutBegin { event })?;
        let through_depth = (end_cycle + 1).max(self.depth.free_cycle());
        let granted_before = self.occu.last_grant();
        let (tiles, available, overflowed_buffers) =
            self.occu.end(&query.spec, through_depth, &mut self.port);
        if let Some(timeline) = &self.timeline {
            self.note_occu_control(through_depth, granted_before);
            timeline.query(QuerySlice {
                id: query.spec.id,
                mode: query.spec.mode,
                tiles: query.spec.tiles.len(),
                begin_cycle: query.begin_cycle,
                end_cycle,
                available_cycle: available,
            });
        }
        self.last_available = self.last_available.max(available);
        let (tile_reports, totals) = tile_reports(&tiles, self.tile_reports);
        self.queries.push(QueryReport {
            id: query.spec.id,
            mode: query.spec.mode,
            latency_cycles: available - end_cycle,
            drain_cycles: available - end_cycle,
            local_merge_cycles: None,
            global_merge_cycles: None,
            end_cycle,
            available_cycle: available,
            fragments: query.fragments,
            overflowed_buffers,
            tiles: tile_reports,
            totals,
        });
        let result = QueryResult {
            id: query.spec.id,
            mode: query.spec.mode,
            tiles,
            overflowed_buffers,
        };
        self.golden.expect(self.queries.len() - 1, result);
        Ok(())
    }

    fn check(&mut self, golden: &QueryResult, event: u64) -> Result<(), SimError> {
        let counter_max = self.arch.counter_max();
        self.golden.check(golden, event, |simulated, golden| {
            first_difference(simulated, golden, counter_max)
        })
    }

    /// The rasterizer can start nothing before `cycle`. When that leaves it idle, the back
    /// end first finishes what it holds, so the memory port sees those requests before the
    /// later fragments' reads (its order is the order of time across an idle gap).
    #[inline]
    pub fn release(&mut self, cycle: u64) -> Result<(), SimError> {
        if cycle > self.input.free_cycle() {
            self.drain()?;
        }
        self.input.release(cycle);
        Ok(())
    }

    /// Everything fed so far, through the back end: the cycle by which every block is idle.
    pub fn drain(&mut self) -> Result<u64, SimError> {
        while !self.pending.is_empty() {
            self.back_one()?;
        }
        Ok(self.total_cycles().max(self.port.last_grant_end()))
    }

    /// The latest query `id` that has ended: the cycle its result is available and the
    /// record words the host reads. Drains the pipeline (nothing fed later can start
    /// before the result is read).
    pub fn result_available(&mut self, id: u32) -> Result<Option<(u64, u64)>, SimError> {
        self.drain()?;
        Ok(crate::report::latest_answer(&self.queries, id))
    }

    /// The cycle the next event fed would enter the pipe, as a query's end does (before
    /// any release by the host).
    pub fn entry_cycle(&self) -> u64 {
        self.input.free_cycle()
    }

    /// Cycles the rasterizer has been busy so far.
    pub fn raster_busy_cycles(&self) -> u64 {
        self.input.busy_cycles
    }

    /// The effect models this machine builds.
    pub fn effects(&self) -> Effects {
        self.effects
    }

    /// The cycle by which every block is idle.
    fn total_cycles(&self) -> u64 {
        self.input
            .free_cycle()
            .max(self.depth.free_cycle())
            .max(self.occu.free_cycle())
            .max(self.last_available)
    }

    /// End of the stream: the report.
    pub fn finish(mut self) -> Result<Report, SimError> {
        if let Some(id) = self.front_open {
            return Err(SimError::OpenAtEnd { id });
        }
        while !self.pending.is_empty() {
            self.back_one()?;
        }
        let cycles_before_port = self.total_cycles();
        let prefetch = &self.depth.prefetch;
        let (word_hits, page_hits, page_misses) =
            (prefetch.word_hits, prefetch.page_hits, prefetch.page_misses);
        let depth_writes = self.depth.depth_writes;
        let occu = self.occu.finish()?;
        let occu_words = occu.words_written;
        let occu_port_cycles = occu.port_cycles;
        let port_width = self.port.bits_per_cycle();
        let port = self.port.finish();
        let cycles = cycles_before_port.max(port.end_cycle);
        let stage = |name: &str, busy: u64, stall: u64, memory_stall: u64| StageReport {
            name: name.to_string(),
            busy_cycles: busy,
            stall_cycles: stall,
            memory_stall_cycles: memory_stall,
            busy_percent: percent(busy, cycles),
            stall_percent: percent(stall, cycles),
        };
        let depth = &self.depth;
        let stages = vec![
            stage(
                "fragment_input",
                self.input.busy_cycles,
                self.input.stall_cycles,
                0,
            ),
            stage(
                "depth_test",
                depth.busy_cycles,
                depth.stall_memory_cycles + depth.stall_backpressure_cycles,
                depth.stall_memory_cycles,
            ),
            stage("occlusion_unit", occu.busy_cycles, occu.stall_cycles, 0),
            stage("occu_control", occu_port_cycles, 0, 0),
        ];
        let engines = occu
            .engines
            .iter()
            .enumerate()
            .map(|(engine, &(busy_cycles, stall_cycles))| EngineReport {
                engine,
                busy_cycles,
                stall_cycles,
                busy_percent: percent(busy_cycles, cycles),
            })
            .collect();
        let summary = Summary::of(RunTotals {
            cycles,
            clock_mhz: self.arch.clock_mhz,
            fragments: self.input.fragments,
            primitives: self.input.primitives,
            checked_queries: self.golden.checked(),
            queries: &self.queries,
        });
        Ok(Report {
            machine: "o2".to_string(),
            arch: self.arch_entries,
            viewport_width: self.width,
            viewport_height: self.height,
            summary,
            stages,
            memory_port: PortReport {
                bits_per_cycle: port_width,
                busy_cycles: port.busy_cycles,
                busy_percent: percent(port.busy_cycles, cycles),
                bits_transferred: port.bits_transferred,
                utilization_percent: percent(
                    port.bits_transferred,
                    cycles.saturating_mul(port_width as u64),
                ),
                max_bits_in_one_cycle: port.max_bits_in_one_cycle,
                depth_read_words: port.depth_read_transfers,
                depth_read_word_hits: word_hits,
                depth_read_page_hits: page_hits,
                depth_read_page_misses: page_misses,
                depth_writes,
                colour_writes: depth.colour_writes,
                colour_reads: depth.colour_reads,
                clear_words: depth.clear_words_written,
                reserved_cycles: port.reserved_cycles,
                forced_cycles: port.forced_cycles,
                occu_words,
            },
            engines,
            units: Vec::new(),
            queries: self.queries,
            frames: Vec::new(),
        })
    }
}

/// A query's tiles as its report keeps them: every tile's report where `each` (else none),
/// and their totals.
pub(crate) fn tile_reports(tiles: &[TileResult], each: bool) -> (Vec<TileReport>, TileTotals) {
    let totals = TileTotals {
        tiles: tiles.len(),
        nohc: tiles.iter().map(|tile| tile.nohc).sum(),
        phc: tiles.iter().map(|tile| tile.phc).sum(),
        hits_written: tiles.iter().map(|tile| tile.hits.len()).sum(),
    };
    let reports = match each {
        true => tiles.iter().map(tile_report).collect(),
        false => Vec::new(),
    };
    (reports, totals)
}

fn tile_report(tile: &TileResult) -> TileReport {
    TileReport {
        nohc: tile.nohc,
        phc: tile.phc,
        xmin: tile.xmin,
        xmax: tile.xmax,
        ymin: tile.ymin,
        ymax: tile.ymax,
        zmin: tile.zmin,
        zmax: tile.zmax,
        hits_written: tile.hits.len(),
        overflowed: tile.overflowed,
    }
}
