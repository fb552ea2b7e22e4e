//! What can go wrong while replaying a fragment stream.

use crate::arch::ArchError;
use occsim_traces::query::{BRIEF_RECORD_ENTRIES, MAX_TILES};
use occsim_traces::QueryShape;
use thiserror::Error;

#[derive(Debug, Error, PartialEq)]
pub enum SimError {
    #[error(transparent)]
    Arch(#[from] ArchError),
    #[error(transparent)]
    ViewportBuffer(#[from] occsim_traces::golden::ViewportBufferTooLarge),
    #[error("the simulated time reaches {cycles} cycles, past the 2^62 a report can sum: the host's or the geometry stage's costs in pipeline cycles are too large for this trace (their cycles a step times clock_mhz over host_clock_mhz or geometry_engine_clock_mhz)")]
    TimeOverflow { cycles: u64 },
    #[error("viewport {width}x{height}: each side must be in 1..={max}")]
    Viewport { width: u32, height: u32, max: u32 },
    #[error("event {event}: fragment ({x}, {y}) lies outside the {width}x{height} viewport")]
    FragmentOutside {
        event: u64,
        x: u16,
        y: u16,
        width: u32,
        height: u32,
    },
    #[error("event {event}: query {id} begins while query {open_id} is open")]
    NestedQuery { event: u64, id: u32, open_id: u32 },
    #[error("event {event}: the host waits for query {id}'s result, but no query {id} has ended")]
    NoResultToWaitFor { event: u64, id: u32 },
    #[error("event {event}: query end without an open query")]
    EndWithoutBegin { event: u64 },
    #[error("event {event}: golden result for query {id}, but no query just ended")]
    ResultWithoutQuery { event: u64, id: u32 },
    #[error("a query's end is not followed by its golden result (before the next event or the stream's end), which a replay from the window index takes as the query's result")]
    MissingGolden,
    #[error("fragment {fragment} at ({x}, {y}): the trace's depth-test results contradict each other (no depth the pixel could hold gives them all)")]
    InconsistentDepthTests { fragment: u64, x: u16, y: u16 },
    #[error("reading the trace ahead for its windows' sizes: {0}")]
    ReadAhead(String),
    #[error("event {event}: query {id} has {entries}-entry occlusion buffers; the minimum is 8")]
    BufferTooSmall { event: u64, id: u32, entries: u32 },
    #[error("event {event}: query {id} has {count} tiles; allowed 1..={max}")]
    TileCount {
        event: u64,
        id: u32,
        count: usize,
        max: usize,
    },
    #[error("event {event}: query {id} has {tiles} tiles: with {image_engines} Image Engines that is more than the model's {max} tile registers")]
    TileRegisters {
        event: u64,
        id: u32,
        tiles: usize,
        image_engines: usize,
        max: usize,
    },
    #[error("query {id} (query #{index} in the trace): {field} differs: simulated {simulated}, golden {golden}")]
    Mismatch {
        id: u32,
        index: usize,
        field: String,
        simulated: String,
        golden: String,
    },
    #[error("the stream ended with query {id} still open")]
    OpenAtEnd { id: u32 },
    #[error("cannot write the waveform: {0}")]
    Waveform(String),
    #[error("cannot record the timeline: {0}")]
    Timeline(String),
}

/// A machine's viewport must fit the rasterizer's proven range: one check for every model.
pub(crate) fn check_viewport(width: u32, height: u32) -> Result<(), SimError> {
    use occsim_traces::state::MAX_VIEWPORT_SIDE;
    let side = 1..=MAX_VIEWPORT_SIDE;
    if side.contains(&width) && side.contains(&height) {
        Ok(())
    } else {
        Err(SimError::Viewport {
            width,
            height,
            max: MAX_VIEWPORT_SIDE,
        })
    }
}

/// A fragment must lie in the `width` x `height` viewport (`event`: its index in the
/// stream): one check for every model.
#[inline(always)]
pub(crate) fn check_fragment_inside(
    fragment: &occsim_traces::Fragment,
    event: u64,
    width: u32,
    height: u32,
) -> Result<(), SimError> {
    if (fragment.x as u32) < width && (fragment.y as u32) < height {
        return Ok(());
    }
    Err(SimError::FragmentOutside {
        event,
        x: fragment.x,
        y: fragment.y,
        width,
        height,
    })
}

/// Reject a query the hardware cannot take.
pub(crate) fn check_spec(shape: QueryShape, event: u64, open: Option<u32>) -> Result<(), SimError> {
    if let Some(open_id) = open {
        return Err(SimError::NestedQuery {
            event,
            id: shape.id,
            open_id,
        });
    }
    if shape.buffer_entries < BRIEF_RECORD_ENTRIES {
        return Err(SimError::BufferTooSmall {
            event,
            id: shape.id,
            entries: shape.buffer_entries,
        });
    }
    if shape.tiles == 0 || shape.tiles > MAX_TILES {
        return Err(SimError::TileCount {
            event,
            id: shape.id,
            count: shape.tiles,
            max: MAX_TILES,
        });
    }
    Ok(())
}
