//! The InfiniteReality-like machine: `B` Raster Memory boards (1, 2 or 4), each with one
//! Fragment Generator and `N` Image Engines; the framebuffer is interleaved over the `B x N`
//! Image Engines; an Occlusion Unit sits at every Image Engine; a query's partial results
//! are merged in two stages, within each board and then across the boards.
//!
//! ```text
//!             +-> board 0: fragment_generator -> FIFO -> image_engine 0 (depth, OccU) --+
//! primitives -+                              \-> FIFO -> image_engine 1 (depth, OccU) --+- local merge -+
//!             |                               ...                                        |               +- global merge -> report
//!             +-> board 1: ...                                                          ... ------------+
//! ```
//!
//! # Timing rules
//! Cycles count from 0; everything is processed in trace order, each cycle a monotone
//! function of earlier ones.
//! 1. Interleave ([`crate::blocks::interleave`]): each pixel belongs to exactly one board and one
//!    Image Engine on it.
//! 2. Fragment Generators ([`crate::blocks::fragment_generator`]): every board sets up every
//!    primitive (`fragment_generator_setup_cycles`) and emits only its own pixels'
//!    fragments, at most `fragment_generator_fragments_per_cycle` a cycle, in order, blocking
//!    while the target Image Engine's FIFO is full.
//! 3. Image Engines ([`crate::blocks::image_engine`]): each starts a fragment's depth test
//!    every `image_engine_cycles_per_fragment` cycles in a pipelined stage of
//!    `image_engine_latency_cycles`, then its own Occlusion Unit (`engines`
//!    engines, the query's tiles dealt round-robin, one tile per engine per cycle) counts it;
//!    hit words drain through a per-engine write buffer, one word per cycle.
//! 4. Query end: the end token enters every board in `t_end`, the first cycle after every
//!    Fragment Generator has emitted and set up everything before it; each Image Engine's
//!    partial report is ready in `r` (rule in [`crate::blocks::image_engine`]).
//! 5. Stage one merges each board's Image Engines' reports in Image Engine order, stage two
//!    the boards' merged reports in board order ([`crate::blocks::merge_network`]: tree, chain or
//!    software, with the per-hop or per-read latency). Every report moves word by word: 8
//!    words a tile from every Image Engine (and a verbose query's hits), over links of
//!    `local_merge_link_bits_per_cycle` and `global_merge_link_bits_per_cycle`, or read by
//!    the host at `result_read_cycles_per_word` a word in a software merge. After a
//!    hardware stage two the final report goes to host memory by DMA at
//!    `report_dma_bits_per_cycle`; the result is available when it is there. A link and the
//!    DMA carry one report at a time, in order: a query's report waits for an earlier
//!    query's to have crossed ([`crate::blocks::merge_network::MergeState`]). Latency =
//!    available - `t_end` = drain + local + global, with drain = `max r - t_end`, local =
//!    `max_b board_b - max r`, global = available - `max_b board_b` (the DMA included).
//! 6. State changes, `begin` and `clear` take no cycles; every Image Engine sees them (the
//!    depth state is broadcast); a fast clear.
//!
//! # What is compared with the golden model
//! Counters (saturated to `counter_bits`), boxes, z ranges, the number of hits kept, the
//! overflow flags and the overflowed-buffer count exactly. The hit lists are concatenated
//! board by board, Image Engine by Image Engine, so their order differs from the golden
//! (trace-order) list: without overflow the hit multiset must equal the golden one; on
//! overflow the kept hits are a prefix of that concatenation, not of the trace order, so
//! only their number (`room - 1`) and their lying in the tile's box are checked here (the
//! tests check they are true hits of the tile).
//!
//! The functional depth test uses one depth buffer for the whole screen, partitioned by
//! ownership: each pixel is only ever tested by the Image Engine that owns it.
//!
//! # Fidelity
//! Every Image Engine's Occlusion Unit and OccU Control is the event-timestamp model
//! (`cycle`) or the `occsim-rtl` model clocked cycle by cycle (`rtl`,
//! [`MachineBuilder::occu`], [`crate::blocks::rtl_occu`]), with identical reports. An rtl
//! unit is clocked only when its Image Engine has a fragment for it (quiescent cycles are
//! skipped in bulk), so idle Image Engines cost nothing; a waveform (`--vcd`) dumps Image
//! Engine 0 of board 0.

use crate::arch::{Arch, IrArch};
use crate::blocks::fragment_generator::FragmentGenerator;
use crate::blocks::image_engine::ImageEngine;
use crate::blocks::interleave::FramebufferInterleave;
use crate::blocks::merge_network::{merge_partial, MergeState, Partial, ReportShape};
use crate::blocks::occlusion_engine::hit_room;
use crate::blocks::occlusion_unit::{OccuStats, SharedLocatedTiles};
use crate::blocks::occu_stage::OccuModel;
use crate::effects::Effects;
use crate::error::check_spec;
use crate::error::SimError;
use crate::golden_check::merged_difference;
use crate::golden_check::GoldenCheck;
use crate::machines::builder::MachineBuilder;
use crate::machines::o2::tile_reports;
use crate::report::{
    percent, ArchEntry, EngineReport, PortReport, QueryReport, Report, RunTotals, StageReport,
    Summary, UnitSummary,
};
use crate::timeline::{note, QuerySlice, State, Timeline, Track};
use occsim_traces::golden::DepthBuffer;
use occsim_traces::state::RenderState;
use occsim_traces::{Event, Fragment, QueryMode, QueryResult, QuerySpec, Span, TileResult};

/// Most tile registers (tiles x Image Engines) one query may load: bounds memory.
pub const MAX_TILE_REGISTERS: usize = 1 << 22;

/// Refuse the query `spec` (event `event`) whose tiles, loaded into each of
/// `image_engines` Occlusion Units, need more than [`MAX_TILE_REGISTERS`]: at every level,
/// so that none times a query the others refuse (the analytic level had timed a 20,480-tile
/// query on ir4 that the machine refuses).
pub fn check_tile_registers(
    spec: &QuerySpec,
    image_engines: usize,
    event: u64,
) -> Result<(), SimError> {
    if spec.tiles.len().saturating_mul(image_engines) <= MAX_TILE_REGISTERS {
        return Ok(());
    }
    Err(SimError::TileRegisters {
        event,
        id: spec.id,
        tiles: spec.tiles.len(),
        image_engines,
        max: MAX_TILE_REGISTERS,
    })
}

struct OpenQuery {
    spec: QuerySpec,
    /// Distinguishes queries, so each Image Engine loads a query's tiles once, lazily.
    generation: u64,
    fragments: u64,
    /// The cycle its begin entered the pipe (the boards' last free cycle).
    begin_cycle: u64,
}

pub struct IrMachine {
    arch: IrArch,
    arch_entries: Vec<ArchEntry>,
    width: u32,
    height: u32,
    interleave: FramebufferInterleave,
    /// Per interleave unit, its board and its Image Engine (board-major), looked up instead
    /// of divided out a fragment.
    owners: Vec<(u32, u32)>,
    /// A span's depth-test results and interleave units (kept for the next span).
    span_passed: Vec<bool>,
    span_units: Vec<usize>,
    generators: Vec<FragmentGenerator>,
    /// Board-major: Image Engine `i` of board `b` is `b * N + i`.
    image_engines: Vec<ImageEngine>,
    /// The open query's located tiles (outlines and locators), built once for every Image
    /// Engine.
    located: SharedLocatedTiles,
    state: RenderState,
    depth: DepthBuffer,
    open: Option<OpenQuery>,
    generation: u64,
    /// The merge stages' links and DMA, and the host of software merges, carried from query
    /// to query ([`MergeState`]: a report crosses a link after the one before it).
    merges: MergeState,
    /// The result of the query that just ended, waiting for the stream's golden result.
    golden: GoldenCheck,
    /// The merged result of the last query that ended (hit lists included).
    last_result: Option<QueryResult>,
    queries: Vec<QueryReport>,
    events: u64,
    primitives: u64,
    last_available: u64,
    /// Where the blocks' intervals go, if anywhere.
    timeline: Option<Timeline>,
    /// Each query's report keeps every tile's, else the tiles' totals only
    /// ([`crate::MachineModel::keep_tile_reports`]).
    tile_reports: bool,
}

impl IrMachine {
    /// The machine `arch` describes at reset, every effect modelled, the OccUs at the cycle
    /// level: shorthand for [`MachineBuilder::ir`].
    pub fn new(arch: &Arch, width: u32, height: u32) -> Result<IrMachine, SimError> {
        MachineBuilder::new(arch).ir(width, height)
    }

    /// [`Self::finish`], handing the depth buffer's memory back for reuse.
    /// The depth buffer the Image Engines' depth tests read
    /// ([`super::MachineModel::depth_buffer_mut`]).
    pub fn depth_buffer_mut(&mut self) -> &mut DepthBuffer {
        &mut self.depth
    }

    pub fn finish_recycling(mut self) -> Result<(Report, DepthBuffer), SimError> {
        let depth = std::mem::replace(&mut self.depth, DepthBuffer::new(0, 0));
        Ok((self.finish()?, depth))
    }

    /// [`crate::MachineModel::keep_tile_reports`].
    pub(crate) fn keep_tile_reports(&mut self, keep: bool) {
        self.tile_reports = keep;
    }

    /// The one constructor: the blocks of `build`'s architecture, effects and OccU fidelity
    /// for a `width` x `height` viewport, starting from `depth` and, when given, a
    /// functional model's render state (a warm start) instead of the reset state. A
    /// waveform dumps Image Engine 0 of board 0 only.
    pub(crate) fn assemble(
        build: MachineBuilder<'_>,
        width: u32,
        height: u32,
        depth: DepthBuffer,
        state: Option<&RenderState>,
    ) -> Result<IrMachine, SimError> {
        let (arch, effects, occu) = (build.arch, build.effects, build.occu);
        let ir = arch.ir()?;
        let arch_entries = arch.report_entries();
        let interleave = FramebufferInterleave::new(&ir);
        let owners = (0..ir.image_engines())
            .map(|unit| {
                let owner = interleave.owner_of_unit(unit);
                let engine = owner.board * ir.image_engines_per_board + owner.image_engine;
                (owner.board as u32, engine as u32)
            })
            .collect();
        Ok(IrMachine {
            interleave,
            owners,
            span_passed: Vec::new(),
            span_units: Vec::new(),
            generators: (0..ir.boards)
                .map(|_| {
                    FragmentGenerator::new(
                        ir.fragment_generator_fragments_per_cycle,
                        ir.fragment_generator_setup_cycles,
                    )
                })
                .collect(),
            image_engines: image_engines(&ir, occu, effects),
            located: SharedLocatedTiles::default(),
            arch: ir,
            arch_entries,
            width,
            height,
            state: state.copied().unwrap_or(RenderState::new(width, height)),
            depth,
            open: None,
            generation: 0,
            merges: MergeState::default(),
            golden: GoldenCheck::default(),
            last_result: None,
            queries: Vec::new(),
            events: 0,
            primitives: 0,
            last_available: 0,
            timeline: build.timeline,
            tile_reports: true,
        })
    }

    /// Feed one event of the stream.
    #[inline]
    pub fn event(&mut self, event: &Event) -> Result<(), SimError> {
        let index = self.events;
        self.events += 1;
        match event {
            Event::Fragment(f) => return self.fragment(*f, index),
            Event::Primitive => {
                self.primitives += 1;
                self.generators
                    .iter_mut()
                    .for_each(FragmentGenerator::primitive);
            }
            Event::Clear => self.depth.clear(),
            Event::DepthFunc(_)
            | Event::DepthMask(_)
            | Event::DepthTest(_)
            | Event::Cull(_)
            | Event::Scissor(_) => {
                self.state.apply(event);
            }
            Event::QueryBegin(spec) => self.begin(spec, index)?,
            Event::QueryEnd => self.end(index)?,
            Event::QueryResult(golden) => self.check(golden, index)?,
            // The closed loop's records are the front end's ([`crate::machines::closed_loop`]).
            Event::Geometry(_)
            | Event::HostWork(_)
            | Event::Wait(_)
            | Event::ConditionalBegin(_)
            | Event::ConditionalEnd
            | Event::Swap => {}
        }
        Ok(())
    }

    /// The Fragment Generators can start nothing before `cycle`.
    #[inline]
    pub fn release(&mut self, cycle: u64) {
        self.generators.iter_mut().for_each(|g| g.release(cycle));
    }

    /// The merge stages take up from `merges` (their links still busy with earlier queries'
    /// reports, on this machine's clock).
    pub fn take_merges(&mut self, merges: MergeState) {
        self.merges = merges;
    }

    /// Board `b`'s Fragment Generator can start nothing before `cycle - leads[b]` (a board
    /// without a lead given, before `cycle`).
    pub fn release_boards(&mut self, cycle: u64, leads: &[u64]) {
        for (board, generator) in self.generators.iter_mut().enumerate() {
            let lead = leads.get(board).copied().unwrap_or(0);
            generator.release(cycle.saturating_sub(lead));
        }
    }

    /// The cycle by which every block is idle (everything is timed as it is fed).
    pub fn drain(&mut self) -> Result<u64, SimError> {
        Ok(self.idle_cycle())
    }

    fn idle_cycle(&self) -> u64 {
        self.generators
            .iter()
            .map(FragmentGenerator::free_cycle)
            .chain(self.image_engines.iter().map(ImageEngine::free_cycle))
            .chain([self.last_available])
            .max()
            .unwrap_or(0)
    }

    /// The latest query `id` that has ended: the cycle its result is available and the
    /// record words the host reads.
    pub fn result_available(&mut self, id: u32) -> Result<Option<(u64, u64)>, SimError> {
        Ok(crate::report::latest_answer(&self.queries, id))
    }

    /// The cycle the next event fed would enter the pipe, as a query's end does (when
    /// every Fragment Generator is free).
    pub fn entry_cycle(&self) -> u64 {
        self.generators_free()
    }

    /// Cycles the busiest Fragment Generator has been busy so far.
    pub fn raster_busy_cycles(&self) -> u64 {
        self.generators
            .iter()
            .map(|g| g.busy_cycles)
            .max()
            .unwrap_or(0)
    }

    #[inline]
    fn fragment(&mut self, fragment: Fragment, event: u64) -> Result<(), SimError> {
        crate::error::check_fragment_inside(&fragment, event, self.width, self.height)?;
        let unit = self.interleave.unit(fragment.x, fragment.y);
        let writes_allowed = !self.occlusion_mode();
        let passed = self.depth.test(&self.state, fragment, writes_allowed);
        self.timed_fragment(fragment, unit, passed);
        Ok(())
    }

    /// A span of fragments, as its fragments one by one: its depth tests taken for the row
    /// at once (its pixels are distinct), its interleave units stepped along it (a column
    /// interleave's `x mod U` found once, not divided out a pixel), each fragment then timed
    /// as [`Self::fragment`] times it. (Fragment by fragment, with three integer divisions a
    /// fragment for its owner, the IR's cycle level ran at 22.7 M fragments/s on the demo on
    /// ir4; now 34-36 M/s, 1.20x of the one-by-one path with the owner table,
    /// `cargo bench -p occsim-sim --bench ir_spans`.)
    pub fn span(&mut self, span: Span) -> Result<(), SimError> {
        let inside = span.x as u64 + span.depths.len() as u64 <= self.width as u64
            && (span.y as u32) < self.height;
        if !inside {
            // The fragment outside the viewport is an error the one-by-one path names.
            return span
                .fragments()
                .try_for_each(|fragment| self.event(&Event::Fragment(fragment)));
        }
        self.events += span.depths.len() as u64;
        let writes_allowed = !self.occlusion_mode();
        let mut passed = std::mem::take(&mut self.span_passed);
        self.depth
            .test_span(&self.state, span, writes_allowed, &mut passed);
        let mut units = std::mem::take(&mut self.span_units);
        units.clear();
        self.interleave
            .for_each_unit_along(span.x, span.y, span.depths.len(), |unit| units.push(unit));
        for ((fragment, &passed), &unit) in span.fragments().zip(&passed).zip(&units) {
            self.timed_fragment(fragment, unit, passed);
        }
        self.span_passed = passed;
        self.span_units = units;
        Ok(())
    }

    /// Whether the open query renders in an occlusion mode (no depth writes).
    fn occlusion_mode(&self) -> bool {
        self.open
            .as_ref()
            .is_some_and(|q| q.spec.mode.is_occlusion_render_mode())
    }

    /// Time a fragment of interleave unit `unit` whose depth test `passed`: its board's
    /// Fragment Generator emits it once its Image Engine's FIFO has room, and the Image
    /// Engine takes it.
    #[inline(always)]
    fn timed_fragment(&mut self, fragment: Fragment, unit: usize, passed: bool) {
        let (board, engine) = self.owners[unit];
        let (board, engine) = (board as usize, engine as usize);
        let engine = &mut self.image_engines[engine];
        // Where the generator was free, for the timeline's stall slice alone.
        let free = self
            .timeline
            .is_some()
            .then(|| self.generators[board].free_cycle());
        let emitted = self.generators[board].emit(engine.slot_free_cycle());
        if let Some(query) = &mut self.open {
            engine.load(query.generation, &query.spec, &mut self.located);
            query.fragments += 1;
        }
        engine.fragment(fragment, passed, emitted, self.open.is_some());
        if let Some(free) = free {
            let (t, board) = (&self.timeline, board as u32);
            let generator = Track::FragmentGenerator(board);
            note(t, generator, State::Stalled, free, emitted);
            note(t, generator, State::Busy, emitted, emitted + 1);
            // The board's Image Engines together: busy while one of them services a
            // fragment (as reported in fragment order, see `Track::ImageEngines`).
            let service_end = engine.free_cycle();
            note(
                t,
                Track::ImageEngines(board),
                State::Busy,
                emitted + 1,
                service_end,
            );
        }
    }

    fn begin(&mut self, spec: &QuerySpec, event: u64) -> Result<(), SimError> {
        check_spec(spec.shape(), event, self.open.as_ref().map(|q| q.spec.id))?;
        check_tile_registers(spec, self.image_engines.len(), event)?;
        self.generation += 1;
        self.open = Some(OpenQuery {
            spec: spec.clone(),
            generation: self.generation,
            fragments: 0,
            begin_cycle: self.generators_free(),
        });
        Ok(())
    }

    /// The last cycle a board's Fragment Generator is busy: where a command enters the pipe.
    fn generators_free(&self) -> u64 {
        self.generators
            .iter()
            .map(FragmentGenerator::free_cycle)
            .max()
            .unwrap_or(0)
    }

    fn end(&mut self, event: u64) -> Result<(), SimError> {
        let query = self
            .open
            .take()
            .ok_or(SimError::EndWithoutBegin { event })?;
        let spec = &query.spec;
        let end_cycle = self.generators_free();
        let counter_max = self.arch.counter_max();
        let room = match spec.mode {
            QueryMode::Verbose => hit_room(spec.buffer_entries) as usize,
            _ => usize::MAX,
        };
        let per_board = self.arch.image_engines_per_board;
        let mut tiles = vec![TileResult::default(); spec.tiles.len()];
        let mut board_reports = Vec::with_capacity(self.generators.len());
        let mut last_drained = end_cycle;
        let shape = ReportShape {
            tiles: spec.tiles.len() as u64,
            room: room as u64,
        };
        let verbose = spec.mode == QueryMode::Verbose;
        for (board, engines) in self.image_engines.chunks_mut(per_board).enumerate() {
            let mut reports = Vec::with_capacity(per_board);
            for engine in engines {
                let (r, partial) = engine.end(end_cycle, query.generation, spec.tiles.len());
                // Every Image Engine sends a record a tile; a verbose one its hits too (one
                // per passing fragment, up to the room).
                let hits = match (&partial, verbose) {
                    (Some(partial), true) => {
                        partial.iter().map(|t| t.nohc.min(shape.room)).collect()
                    }
                    _ => Vec::new(),
                };
                reports.push(Partial { ready: r, hits });
                if let Some(partial) = partial {
                    merge_partial(&mut tiles, &partial, counter_max, room);
                }
            }
            let board_drained = reports.iter().map(|p| p.ready).max().unwrap_or(0);
            last_drained = last_drained.max(board_drained);
            let local = self.arch.local_merge_network();
            let merged = self.merges.local(&local, board, &reports, shape);
            let lane = Track::LocalMerge(board_reports.len() as u32);
            note(
                &self.timeline,
                lane,
                State::Busy,
                board_drained,
                merged.ready,
            );
            board_reports.push(merged);
        }
        let boards_merged = board_reports
            .iter()
            .map(|p| p.ready)
            .max()
            .unwrap_or(last_drained);
        let global = self.arch.global_merge_network();
        let merged = self.merges.global(&global, &board_reports, shape);
        let available =
            self.merges
                .deliver(&global, &merged, shape, self.arch.report_dma_bits_per_cycle);
        let overflowed_buffers = finish_verbose(spec, &mut tiles);
        self.last_available = self.last_available.max(available);
        if let Some(timeline) = &self.timeline {
            let global = Track::GlobalMerge;
            timeline.interval(global, State::Busy, boards_merged, available);
            timeline.query(QuerySlice {
                id: spec.id,
                mode: spec.mode,
                tiles: spec.tiles.len(),
                begin_cycle: query.begin_cycle,
                end_cycle,
                available_cycle: available,
            });
        }
        let (tile_reports, totals) = tile_reports(&tiles, self.tile_reports);
        self.queries.push(QueryReport {
            id: spec.id,
            mode: spec.mode,
            latency_cycles: available - end_cycle,
            drain_cycles: last_drained - end_cycle,
            local_merge_cycles: Some(boards_merged - last_drained),
            global_merge_cycles: Some(available - boards_merged),
            end_cycle,
            available_cycle: available,
            fragments: query.fragments,
            overflowed_buffers,
            tiles: tile_reports,
            totals,
        });
        let result = QueryResult {
            id: spec.id,
            mode: spec.mode,
            tiles,
            overflowed_buffers,
        };
        self.last_result = Some(result.clone());
        self.golden.expect(self.queries.len() - 1, result);
        Ok(())
    }

    /// The merged result of the last query that ended, hit lists included.
    pub fn last_result(&self) -> Option<&QueryResult> {
        self.last_result.as_ref()
    }

    fn check(&mut self, golden: &QueryResult, event: u64) -> Result<(), SimError> {
        let counter_max = self.arch.counter_max();
        self.golden.check(golden, event, |simulated, golden| {
            merged_difference(simulated, golden, counter_max)
        })
    }

    /// End of the stream: the report.
    pub fn finish(mut self) -> Result<Report, SimError> {
        if let Some(query) = &self.open {
            return Err(SimError::OpenAtEnd { id: query.spec.id });
        }
        let cycles = self.idle_cycle();
        let fragments: u64 = self.generators.iter().map(|g| g.fragments).sum();
        let occu = self
            .image_engines
            .iter_mut()
            .map(ImageEngine::finish)
            .collect::<Result<Vec<OccuStats>, SimError>>()?;
        let engines = self.engine_reports(&occu, cycles);
        let sum_occu = |f: &dyn Fn(&OccuStats) -> u64| occu.iter().map(f).sum::<u64>();
        let stage = |name: &str, busy: u64, stall: u64, units: usize| StageReport {
            name: name.to_string(),
            busy_cycles: busy,
            stall_cycles: stall,
            memory_stall_cycles: 0,
            busy_percent: percent(busy, cycles.saturating_mul(units as u64)),
            stall_percent: percent(stall, cycles.saturating_mul(units as u64)),
        };
        let ies = self.image_engines.len();
        let stages = vec![
            stage(
                "frag_generators",
                self.generators.iter().map(|g| g.busy_cycles).sum(),
                self.generators.iter().map(|g| g.stall_cycles).sum(),
                self.generators.len(),
            ),
            stage(
                "image_engines",
                self.image_engines.iter().map(|e| e.busy_cycles).sum(),
                0,
                ies,
            ),
            stage(
                "occlusion_units",
                sum_occu(&|o| o.busy_cycles),
                sum_occu(&|o| o.stall_cycles),
                ies,
            ),
        ];
        let units = vec![
            UnitSummary::of(
                "fragment_generator",
                self.generators.iter().map(|g| g.busy_cycles),
                cycles,
            ),
            UnitSummary::of(
                "image_engine",
                self.image_engines.iter().map(|e| e.busy_cycles),
                cycles,
            ),
            UnitSummary::of("occlusion_unit", occu.iter().map(|o| o.busy_cycles), cycles),
        ];
        let summary = Summary::of(RunTotals {
            cycles,
            clock_mhz: self.arch.clock_mhz,
            fragments,
            primitives: self.primitives,
            checked_queries: self.golden.checked(),
            queries: &self.queries,
        });
        Ok(Report {
            machine: "ir".to_string(),
            arch: self.arch_entries,
            viewport_width: self.width,
            viewport_height: self.height,
            summary,
            stages,
            memory_port: PortReport {
                occu_words: sum_occu(&|o| o.words_written),
                ..PortReport::default()
            },
            engines,
            units,
            queries: self.queries,
            frames: Vec::new(),
        })
    }

    /// Engine `e`'s statistics summed over every Image Engine's Occlusion Unit; busy percent
    /// of all those engines' cycles.
    fn engine_reports(&self, occu: &[OccuStats], cycles: u64) -> Vec<EngineReport> {
        (0..self.arch.occu.engines)
            .map(|e| {
                let busy = occu.iter().map(|o| o.engines[e].0).sum();
                let stall = occu.iter().map(|o| o.engines[e].1).sum();
                EngineReport {
                    engine: e,
                    busy_cycles: busy,
                    stall_cycles: stall,
                    busy_percent: percent(busy, cycles.saturating_mul(occu.len() as u64)),
                }
            })
            .collect()
    }
}

/// Every Image Engine, board-major, its Occlusion Unit modelled as `occu` says; a
/// waveform goes to the first one (Image Engine 0 of board 0).
fn image_engines(arch: &IrArch, occu: OccuModel, effects: Effects) -> Vec<ImageEngine> {
    let (rtl, mut waveform) = match occu {
        OccuModel::Cycle => (false, None),
        OccuModel::Rtl { waveform } => (true, waveform),
    };
    (0..arch.image_engines())
        .map(|_| {
            let model = if rtl {
                OccuModel::Rtl {
                    waveform: waveform.take(),
                }
            } else {
                OccuModel::Cycle
            };
            ImageEngine::new(arch, model, effects.verbose_hit_writes)
        })
        .collect()
}

/// Verbose buffers that overflowed end with the -1 terminator over their last hit (when they
/// have room for one): keep `room - 1` hits. Returns the overflowed buffers.
fn finish_verbose(spec: &QuerySpec, tiles: &mut [TileResult]) -> u32 {
    if spec.mode != QueryMode::Verbose {
        return 0;
    }
    let room = hit_room(spec.buffer_entries) as usize;
    let mut overflowed = 0;
    for tile in tiles.iter_mut().filter(|t| t.overflowed) {
        overflowed += 1;
        tile.hits.truncate(room.saturating_sub(1) as u64);
    }
    overflowed
}
