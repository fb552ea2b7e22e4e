//! Replaying a trace from Rust: a trace and options in, a level's result out. The command
//! line's `replay`, `fidelity`, `latency`, `sweep` and `demo` are this and their printing.
//!
//! A trace is given as a way to open it (`open`), since choosing the effect models of an old
//! trace, whose header lacks the facts, takes a scan of its events before the replay, and
//! so does sizing a waveform.
//!
//! ```no_run
//! use occsim_sim::replay::{replay, ReplayOptions};
//! use occsim_sim::{Arch, Fidelity};
//! use occsim_traces::trace::TraceReader;
//!
//! let arch = Arch::builtin("ir4")?;
//! let open = || Ok(TraceReader::new(std::io::BufReader::new(std::fs::File::open("demo.occt")?))?);
//! let result = replay(open, &arch, ReplayOptions::at(Fidelity::Cycle))?;
//! println!("{} cycles", result.total_cycles.unwrap_or(0));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::arch::Arch;
use crate::blocks::waveform::WaveformOptions;
use crate::effects::{effects_of_features, EffectScan, Effects, EffectsChoice};
use crate::error::SimError;
use crate::levels::analytic::AnalyticModel;
use crate::levels::sampled::{
    feed_window_sizes, simulates_slowest, tail_fragments, warm_up_fragments, SampledModel,
    WindowScout, WindowSize, WindowSizes,
};
use crate::levels::{Fidelity, LevelModel, LevelResult, LevelSink};
use crate::timeline::Timeline;
use occsim_traces::golden::EventSink;
use occsim_traces::retile::{Retile, RetileError, TileGrid};
use occsim_traces::trace::{IndexItem, ReadError, TestedFragments, TraceError, TraceReader};
use occsim_traces::Event;
use std::collections::BTreeSet;
use std::convert::Infallible;
use std::io::Read;

/// How to replay: the level, the effect models to build, an optional retiling and, at the
/// rtl level, an optional waveform.
pub struct ReplayOptions {
    pub level: Fidelity,
    /// `Auto`: only the effect models the trace can observe (at the levels that build
    /// effects; same results and cycles); `All`: every model.
    pub effects: EffectsChoice,
    /// Replace every brief query's tiles by this grid (golden results recomputed).
    pub retile: Option<TileGrid>,
    pub waveform: Option<WaveformOptions>,
    /// At the cycle and rtl levels, where the blocks' intervals go ([`crate::timeline`]).
    pub timeline: Option<Timeline>,
    /// Read the trace's window index instead of its fragments where the level can
    /// ([`AnalyticModel::reads_window_index`]): the same result, without decoding a fragment.
    pub window_index: bool,
    /// At the sampled level, the fragments before a sampled window its machine runs as a
    /// warm-up (None: the machine's own, [`crate::levels::sampled::warm_up_fragments`]).
    pub warm_up_fragments: Option<u64>,
    /// At the sampled level, the fragments at the end of a long sampled window its machine
    /// simulates (None: the machine's own, [`crate::levels::sampled::tail_fragments`];
    /// `Some(u64::MAX)`: every sampled window whole).
    pub tail_fragments: Option<u64>,
    /// At the cycle and rtl levels, the report keeps every query's tiles' reports (their
    /// bounding boxes and depth ranges): memory that grows with the queries' tiles, so only
    /// where they are wanted (`replay --json`). Else each query's tile totals.
    pub tile_reports: bool,
}

impl ReplayOptions {
    /// `level` with the automatic effects choice, no retiling, no waveform.
    pub fn at(level: Fidelity) -> ReplayOptions {
        ReplayOptions {
            level,
            effects: EffectsChoice::Auto,
            retile: None,
            waveform: None,
            timeline: None,
            window_index: true,
            warm_up_fragments: None,
            tail_fragments: None,
            tile_reports: false,
        }
    }

    /// The cycle level with the automatic effects choice (the report every effect model
    /// gives, sooner: fast-forward included): what sweeps, latency and sensitivity reports
    /// run.
    pub fn cycle(retile: Option<TileGrid>) -> ReplayOptions {
        ReplayOptions {
            level: Fidelity::Cycle,
            effects: EffectsChoice::Auto,
            retile,
            waveform: None,
            timeline: None,
            window_index: true,
            warm_up_fragments: None,
            tail_fragments: None,
            tile_reports: false,
        }
    }
}

/// Why a replay failed, by stage (the caller names the trace). Each variant's message names
/// the stage; the cause follows as its source.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The trace could not be opened (the caller's `open` failed).
    #[error(transparent)]
    Open(Box<dyn std::error::Error + Send + Sync + 'static>),
    /// The trace could not be read.
    #[error("cannot read trace")]
    Read(#[source] TraceError),
    /// The level's model could not be built for this architecture and viewport.
    #[error("cannot replay")]
    Setup(#[source] SimError),
    /// The requested retiling does not fit the trace's viewport.
    #[error("retile {grid}")]
    Retile {
        grid: TileGrid,
        #[source]
        source: RetileError,
    },
    /// The model refused the stream (a count differs from the golden one, say).
    #[error("replay on {machine}")]
    Model {
        machine: &'static str,
        #[source]
        source: SimError,
    },
}

impl ReplayError {
    /// The error of `machine`'s model: a buffer of the viewport it could not have (a
    /// sampled window's machine, started mid-stream) is the replay's setup failing, as at
    /// the other levels, not the stream's.
    fn of_model(machine: &'static str, source: SimError) -> ReplayError {
        match source {
            SimError::ViewportBuffer(_) => ReplayError::Setup(source),
            source => ReplayError::Model { machine, source },
        }
    }
}

impl From<std::io::Error> for ReplayError {
    fn from(error: std::io::Error) -> ReplayError {
        ReplayError::Open(Box::new(error))
    }
}

impl From<TraceError> for ReplayError {
    fn from(error: TraceError) -> ReplayError {
        ReplayError::Read(error)
    }
}

/// A way to open the trace, once per pass over it.
pub trait OpenTrace<R: Read>: FnMut() -> Result<TraceReader<R>, ReplayError> {}
impl<R: Read, F: FnMut() -> Result<TraceReader<R>, ReplayError>> OpenTrace<R> for F {}

/// Replay the trace `open` gives on `arch`. A model error stops the replay at once.
pub fn replay<R: Read>(
    mut open: impl OpenTrace<R>,
    arch: &Arch,
    options: ReplayOptions,
) -> Result<LevelResult, ReplayError> {
    let effects = effects_for(
        &mut open,
        options.level,
        options.effects,
        arch,
        options.retile.is_some(),
    )?;
    let mut reader = open()?;
    let (width, height) = (reader.header().width, reader.header().height);
    let model_error = |source| ReplayError::of_model(arch.machine().name(), source);
    let older_index = older_index(&reader, arch, &options);
    if let (Fidelity::Analytic, Some(index)) = (options.level, index_read(&reader, arch, &options))
    {
        let mut model =
            AnalyticModel::from_window_index(arch, width, height).map_err(ReplayError::Setup)?;
        // The O2's formulas ask nothing of a query's tiles but their number; the IR's
        // place a verbose query's tiles.
        if let IndexRead::Window = index {
            reader.skim_queries();
        }
        for_each_item(&mut reader, index, |item| model.index_item(item))
            .map_err(|e| read_error(e, model_error))?;
        return LevelModel::Analytic(Box::new(model))
            .finish(arch)
            .map_err(model_error);
    }
    if let Fidelity::Sampled { every } = options.level {
        // First the formulas alone over the trace, for the windows whose queries they
        // predict slowest; then the model that simulates those and every K-th window.
        let (slowest, reader) = match simulates_slowest(every, arch.machine()) {
            false => (BTreeSet::new(), reader),
            true => {
                let predicting = run_sampled(
                    reader,
                    &mut open,
                    (arch, effects, every),
                    &options,
                    |model| Ok(model.predicting()),
                )?;
                (predicting.slowest_windows().map_err(model_error)?, open()?)
            }
        };
        let tail = options
            .tail_fragments
            .unwrap_or_else(|| tail_fragments(arch.machine()));
        let warm_up = options
            .warm_up_fragments
            .unwrap_or_else(|| warm_up_fragments(arch.machine(), every));
        let model = run_sampled(
            reader,
            &mut open,
            (arch, effects, every),
            &options,
            |model| Ok(model.with_slowest(slowest).with_window_sizes(warm_up, tail)),
        )?;
        let mut result = LevelModel::Sampled(model)
            .finish(arch)
            .map_err(model_error)?;
        result.older_index = older_index;
        return Ok(result);
    }
    let model = LevelModel::with_outputs(
        options.level,
        arch,
        width,
        height,
        effects,
        options.waveform,
        options.timeline,
    )
    .map_err(ReplayError::Setup)?;
    let mut model = model;
    model.keep_tile_reports(options.tile_reports);
    let sink = feed_retiled(
        &mut reader,
        LevelSink::new(model),
        options.retile,
        model_error,
    )?;
    let mut result = sink.model.finish(arch).map_err(model_error)?;
    result.older_index = older_index;
    Ok(result)
}

/// The format version of the trace's window index when the level would have read it but it
/// lacks counts the formulas take ([`TraceReader::index_has_every_count`]), so the fragments
/// are decoded instead: the report says why the replay took longer.
fn older_index<R: Read>(
    reader: &TraceReader<R>,
    arch: &Arch,
    options: &ReplayOptions,
) -> Option<u16> {
    let reads_index = matches!(options.level, Fidelity::Analytic | Fidelity::Sampled { .. })
        && index_wanted(reader, arch, options);
    (reads_index && !reader.index_has_every_count()).then(|| reader.format_version())
}

/// Whether the analytic and sampled levels would read the trace's window index instead of
/// its fragments, as far as the options and the architecture go (what the index holds
/// aside): asked to, its queries not retiled, its depth layout the machine's.
fn index_wanted<R: Read>(reader: &TraceReader<R>, arch: &Arch, options: &ReplayOptions) -> bool {
    options.window_index
        && options.retile.is_none()
        && AnalyticModel::reads_window_index(arch, reader.header())
}

/// Which of a trace's indexes the analytic and sampled levels read instead of its
/// fragments: the IR's formulas the band index, the O2's the window index.
#[derive(Clone, Copy)]
enum IndexRead {
    Window,
    Bands,
}

/// The index the analytic and sampled levels read on `arch`, if one serves: the band
/// index ([`bands_wanted`]), or a window index with every count the formulas take.
fn index_read<R: Read>(
    reader: &TraceReader<R>,
    arch: &Arch,
    options: &ReplayOptions,
) -> Option<IndexRead> {
    if bands_wanted(reader, arch, options) {
        Some(IndexRead::Bands)
    } else if index_wanted(reader, arch, options) && reader.index_has_every_count() {
        Some(IndexRead::Window)
    } else {
        None
    }
}

/// Hand every remaining item of the trace's `index` to `visit`.
fn for_each_item<R: Read, E>(
    reader: &mut TraceReader<R>,
    index: IndexRead,
    visit: impl FnMut(&IndexItem) -> Result<(), E>,
) -> Result<(), ReadError<E>> {
    match index {
        IndexRead::Window => reader.for_each_index_item(visit),
        IndexRead::Bands => reader.for_each_band_item(visit),
    }
}

/// Whether the IR's analytic and sampled levels would read the trace's band index instead
/// of its fragments: asked to, its queries not retiled, and an index the formulas can read
/// ([`AnalyticModel::reads_band_index`]).
fn bands_wanted<R: Read>(reader: &TraceReader<R>, arch: &Arch, options: &ReplayOptions) -> bool {
    options.window_index
        && options.retile.is_none()
        && AnalyticModel::reads_band_index(arch, reader.header(), reader.has_band_index())
}

/// Run the sampled level's model over the trace `reader` reads: from the window index where
/// it can (only the simulated windows' fragments read, by a second reader), else fed the
/// events (retiled when asked); `configure` finishes the model, and its window sizes are read
/// ahead by a reader of their own when it wants them.
fn run_sampled<R: Read>(
    mut reader: TraceReader<R>,
    open: &mut impl OpenTrace<R>,
    (arch, effects, every): (&Arch, Effects, u32),
    options: &ReplayOptions,
    configure: impl FnOnce(SampledModel) -> Result<SampledModel, SimError>,
) -> Result<Box<SampledModel>, ReplayError> {
    let (width, height) = (reader.header().width, reader.header().height);
    let model_error = |source| ReplayError::of_model(arch.machine().name(), source);
    let index = index_read(&reader, arch, options).filter(|_| reader.has_depth_tests());
    if let Some(index) = index {
        let model = SampledModel::from_window_index(arch, width, height, effects, every)
            .and_then(configure)
            .map_err(ReplayError::Setup)?;
        let mut model = Box::new(model);
        let mut fragments = TestedFragments::new(open()?)?;
        let mut sizes = ScoutedSizes::new(open()?);
        let mut feed = |item: &IndexItem| {
            feed_window_sizes(&mut model, &mut sizes).map_err(model_error)?;
            model
                .index_item(item, &mut fragments)
                .map_err(|e| read_error(e, model_error))
        };
        for_each_item(&mut reader, index, &mut feed).map_err(|e| match e {
            ReadError::Trace(e) => ReplayError::Read(e),
            ReadError::Sink(e) => e,
        })?;
        return Ok(model);
    }
    let model = SampledModel::new(arch, width, height, effects, every)
        .and_then(configure)
        .map_err(ReplayError::Setup)?;
    let sink = Scouted {
        model: Box::new(model),
        sizes: ScoutedSizes::new(open()?),
    };
    let sink = feed_retiled(&mut reader, sink, options.retile, model_error)?;
    Ok(sink.model)
}

/// The sampled level's window sizes, found by a reader of their own up to K windows ahead:
/// read from the window table when the trace has one (format version 8 on), else found over
/// the window index when it has one (retiling moves no window's end), else over the events.
struct ScoutedSizes<R: Read> {
    reader: TraceReader<R>,
    scout: WindowScout,
}

impl<R: Read> ScoutedSizes<R> {
    fn new(reader: TraceReader<R>) -> ScoutedSizes<R> {
        ScoutedSizes {
            reader,
            scout: WindowScout::default(),
        }
    }
}

/// Give `scout` the next block of the window table, else feed it the next block of events or
/// of index items; false at the trace's end.
fn read_on<R: Read>(
    reader: &mut TraceReader<R>,
    scout: &mut WindowScout,
) -> Result<bool, TraceError> {
    if reader.has_window_table() {
        return scout.read_table(|sizes| reader.next_window_sizes(sizes));
    }
    if reader.header().window_index.is_none() {
        return reader.next_block(scout).map_err(ReadError::into_trace);
    }
    // A block at a time: its items visited in the decoder, as the model reads them (the
    // scout keeps only the sizes of the block's windows).
    reader
        .visit_index_block(|item| {
            scout.index_item(item);
            Ok::<(), Infallible>(())
        })
        .map_err(ReadError::into_trace)
}

impl<R: Read> WindowSizes for ScoutedSizes<R> {
    fn next_size(&mut self) -> Result<Option<WindowSize>, SimError> {
        let reader = &mut self.reader;
        self.scout
            .next_size(|scout| read_on(reader, scout))
            .map_err(|e| SimError::ReadAhead(e.to_string()))
    }
}

/// A sampled model fed decoded events, with its window sizes read ahead.
struct Scouted<R: Read> {
    model: Box<SampledModel>,
    sizes: ScoutedSizes<R>,
}

impl<R: Read> EventSink for Scouted<R> {
    type Error = SimError;

    fn event(&mut self, event: &Event) -> Result<(), SimError> {
        feed_window_sizes(&mut self.model, &mut self.sizes)?;
        self.model.event(event)
    }

    fn span(&mut self, span: occsim_traces::Span) -> Result<(), SimError> {
        feed_window_sizes(&mut self.model, &mut self.sizes)?;
        self.model.span(span)
    }
}

/// [`feed`], through a retiling of the brief queries to `grid` when one is given.
fn feed_retiled<R: Read, S: EventSink<Error = SimError>>(
    reader: &mut TraceReader<R>,
    sink: S,
    grid: Option<TileGrid>,
    model_error: impl Fn(SimError) -> ReplayError,
) -> Result<S, ReplayError> {
    let Some(grid) = grid else {
        return feed(reader, sink, model_error);
    };
    let (width, height) = (reader.header().width, reader.header().height);
    let retile = Retile::new(grid, width, height, sink)
        .map_err(|source| ReplayError::Retile { grid, source })?;
    Ok(feed(reader, retile, model_error)?.into_inner())
}

/// Read every event of `reader` into `sink`, stopping at the first error of either.
fn feed<R: Read, S: EventSink<Error = SimError>>(
    reader: &mut TraceReader<R>,
    mut sink: S,
    model_error: impl Fn(SimError) -> ReplayError,
) -> Result<S, ReplayError> {
    while reader
        .next_block(&mut sink)
        .map_err(|e| read_error(e, &model_error))?
    {}
    Ok(sink)
}

/// A reading's error as the replay's: the trace's, or the model's (worded by `model_error`).
fn read_error(
    error: ReadError<SimError>,
    model_error: impl Fn(SimError) -> ReplayError,
) -> ReplayError {
    match error {
        ReadError::Trace(e) => ReplayError::Read(e),
        ReadError::Sink(e) => model_error(e),
    }
}

/// The effect models `level` builds for the trace: at the levels that build effects
/// ([`Fidelity::builds_effects`]) with `Auto`, those its header's features show it can
/// observe (or, when the header lacks them, a scan of its events); every model otherwise and
/// on a retiled trace (its queries are not those the trace holds), there with fast-forward
/// under `Auto` still (its rule is checked as the replay goes, [`crate::effects`]).
pub fn effects_for<R: Read>(
    mut open: impl OpenTrace<R>,
    level: Fidelity,
    choice: EffectsChoice,
    arch: &Arch,
    retiled: bool,
) -> Result<Effects, ReplayError> {
    let every_model = Effects::every_model_of(arch.machine());
    if choice == EffectsChoice::All || !level.builds_effects() {
        return Ok(every_model);
    }
    if retiled {
        return Ok(Effects {
            fast_forward: true,
            ..every_model
        });
    }
    let mut reader = open()?;
    let header = reader.header();
    let (width, height) = (header.width, header.height);
    if let Some(effects) = effects_of_features(arch, width, height, header.features.as_ref())
        .map_err(ReplayError::Setup)?
    {
        return Ok(effects);
    }
    Ok(scan(&mut reader, arch)?.finish())
}

/// The most tiles one query of the trace has: from its header's features, or (when the
/// header lacks them) a scan of its events. A waveform shows that many tile slots.
pub fn max_query_tiles<R: Read>(
    mut open: impl OpenTrace<R>,
    arch: &Arch,
) -> Result<u64, ReplayError> {
    let mut reader = open()?;
    if let Some(tiles) = reader
        .header()
        .features
        .as_ref()
        .and_then(|f| f.max_query_tiles)
    {
        return Ok(tiles);
    }
    Ok(scan(&mut reader, arch)?.facts().max_query_tiles)
}

struct ScanSink(EffectScan);

impl EventSink for ScanSink {
    type Error = std::convert::Infallible;
    #[inline]
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        self.0.event(event);
        Ok(())
    }
}

/// Every event of `reader` through the effects scan.
fn scan<R: Read>(reader: &mut TraceReader<R>, arch: &Arch) -> Result<EffectScan, ReplayError> {
    let (width, height) = (reader.header().width, reader.header().height);
    let mut scan = ScanSink(EffectScan::for_arch(arch, width, height).map_err(ReplayError::Setup)?);
    reader
        .read_into(&mut scan)
        .map_err(|e| ReplayError::Read(e.into_trace()))?;
    Ok(scan.0)
}
