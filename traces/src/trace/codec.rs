//! The event payload of a block: one tag byte per record, LEB128 varints, zigzag for signed
//! values, and fragments grouped into spans (runs of x+1 on one row) whose positions and
//! depths are coded as residuals from a prediction. All prediction state resets at every
//! block start, so each block decodes on its own.

use super::bands::{FragmentBand, RowRun, BAND_RUNS, ROW_BAND_ROWS};
use super::dense_reads::{DenseRuns, ReadRun, DENSE_READ_COSTS};
use super::header::StreamTally;
use super::index::{
    DrawnTail, FragmentStretch, IndexItem, DENSE_RUNS_FLAG, DRAWN_TAIL_FLAG, ENDING_RUNS_FLAG,
    FIRST_READS_FLAG,
};
use crate::depth_layout::DepthRead;
use crate::event::{Event, Fragment, GeometryBatch, HostWork, Span, DEPTH_ONE};
use crate::golden::EventSink;
use crate::hit_list::{
    listed_hits_per_tile, Hit, HitBounds, HitDigests, HitList, LISTED_HITS_PER_QUERY,
};
use crate::query::{
    QueryMode, QueryResult, QueryShape, QuerySpec, QueryTotals, TileResult, MAX_BUFFER_ENTRIES,
    MAX_TILES,
};
use crate::raster::PlaneDepths;
use crate::state::{DepthFunc, Rect};
use span_depths::span_depths;

mod span_depths;

/// Record tags (the first byte of every record in a payload).
pub(crate) mod tag {
    pub const CLEAR: u8 = 0x01;
    /// Then one byte: the `DepthFunc` code.
    pub const DEPTH_FUNC: u8 = 0x02;
    /// Then one byte, 0 or 1.
    pub const DEPTH_MASK: u8 = 0x03;
    pub const DEPTH_TEST: u8 = 0x04;
    pub const CULL: u8 = 0x05;
    pub const SCISSOR_OFF: u8 = 0x06;
    /// Then x, y, width, height as varints.
    pub const SCISSOR_ON: u8 = 0x07;
    pub const QUERY_BEGIN: u8 = 0x08;
    pub const QUERY_END: u8 = 0x09;
    pub const PRIMITIVE: u8 = 0x0A;
    /// A run of fragments on one row at x, x+1, ...
    pub const SPAN: u8 = 0x0B;
    /// A query result whose verbose tiles store every hit (versions 1 and 2; read only).
    pub const QUERY_RESULT_LISTED: u8 = 0x0C;
    /// Then a varint length and that many bytes of a large event (continued).
    pub const PART: u8 = 0x0D;
    /// As PART, and the large event is complete: its bytes are one QUERY_BEGIN or QUERY_RESULT
    /// record.
    pub const PART_END: u8 = 0x0E;
    /// Then vertices and triangles as varints and a flags byte (bit 0 starts a draw, bit 1
    /// discarded). Version 2 on, as the five below.
    pub const GEOMETRY: u8 = 0x0F;
    /// Then nodes, boxes, decisions and read-back pixels as varints.
    pub const HOST_WORK: u8 = 0x10;
    /// Then the query id as a varint.
    pub const WAIT: u8 = 0x11;
    /// Then the query id as a varint.
    pub const CONDITIONAL_BEGIN: u8 = 0x12;
    pub const CONDITIONAL_END: u8 = 0x13;
    pub const SWAP: u8 = 0x14;
    /// A query result whose verbose tiles store their hit lists as `HitList` holds them:
    /// count, the listed hits, digests, bounds and the last hit. Version 3 on.
    pub const QUERY_RESULT: u8 = 0x15;
    /// In window-index blocks only, in place of fragments: a [`crate::trace::index::FragmentStretch`]'s counts.
    /// Version 4 on.
    pub const STRETCH: u8 = 0x16;
    /// In band-index blocks only, in place of fragments: a [`crate::trace::FragmentBand`]'s
    /// runs. Version 10 on.
    pub const BAND: u8 = 0x17;
    /// As BAND, with a varint mask of its runs that passed their depth test (under a
    /// verbose query). Version 10 on.
    pub const BAND_PASSING: u8 = 0x18;
    /// A query begin whose rectangles' bytes are counted: id, mode, buffer entries and
    /// tile count as QUERY_BEGIN's, then a varint length and that many bytes of rectangles.
    /// Version 11 on, in place of QUERY_BEGIN.
    pub const QUERY_BEGIN_SIZED: u8 = 0x19;
    /// A query result with its totals and its tiles' bytes counted: id, mode, overflowed
    /// buffers and tile count as QUERY_RESULT's, the NOHC, PHC and held hits summed over
    /// the tiles, then a varint length and that many bytes of tile results. Version 11 on,
    /// in place of QUERY_RESULT.
    pub const QUERY_RESULT_TOTALED: u8 = 0x1A;
    /// A primitive's depth plane ([`crate::raster::PlaneDepths`]): `a0`, `dzdx` and `dzdy`
    /// as little-endian f32 bits, then a varint, 0 for rows as they are or the mirror + 1.
    /// Not an event: the plane spans after it in its block take their depths from it.
    /// Version 13 on.
    pub const PLANE: u8 = 0x1B;
    /// A run of fragments on one row whose depths are the block's last plane's at their
    /// pixels: its row and column less the last span's and its length less one, as a
    /// SPAN's, and no depths. Version 13 on.
    pub const PLANE_SPAN: u8 = 0x1C;
    /// In band-index blocks only: a [`crate::trace::FragmentBand`] of one run a row on rows
    /// one after another, none passing: its row count, its first run's `x`, `y` and `len`
    /// as varints, then each next row's `x` and `len` less the row before's as zigzag
    /// varints. Version 14 on.
    pub const ROW_BAND: u8 = 0x1D;
}

/// Most fragments in one span: a row of the widest viewport.
pub(crate) const MAX_SPAN_FRAGMENTS: usize = crate::state::MAX_VIEWPORT_SIDE as usize;
// A span header's one-byte length (below 128) needs no check against the most.
const _: () = assert!(MAX_SPAN_FRAGMENTS >= 128);
/// Most bytes one large event (a query begin or result) may take once its parts are joined.
/// Bounds the reader's memory on hostile input; about 20 million verbose hits.
pub const MAX_EVENT_BYTES: usize = 64 << 20;
/// Most bytes a span of `n` fragments can take: tag, four header varints, n-1 residuals.
pub(crate) fn span_bytes_bound(fragments: usize) -> usize {
    1 + 4 * 10 + fragments.saturating_sub(1) * 10
}

/// Most bytes a plane record and a plane span after it take: tags, the plane's three f32s
/// and mirror varint, the span's three header varints.
pub(crate) const PLANE_AND_SPAN_BYTES: usize = 1 + 12 + 5 + 1 + 3 * 10;

#[inline(always)]
pub(crate) fn put_uv(out: &mut Vec<u8>, mut value: u64) {
    while value >= 0x80 {
        out.push(value as u8 | 0x80);
        value >>= 7;
    }
    out.push(value as u8);
}

#[inline(always)]
pub(crate) fn put_zz(out: &mut Vec<u8>, value: i64) {
    put_uv(out, ((value << 1) ^ (value >> 63)) as u64);
}

#[inline(always)]
fn unzigzag(value: u64) -> i64 {
    (value >> 1) as i64 ^ -((value & 1) as i64)
}

/// A malformed payload: where (in the decoded payload) and what.
#[derive(Debug)]
pub(crate) struct PayloadError {
    pub pos: usize,
    pub reason: String,
}

/// Why draining a payload into a sink stopped.
#[derive(Debug)]
pub(crate) enum DrainError<E> {
    Payload(PayloadError),
    Sink(E),
}

impl<E> From<PayloadError> for DrainError<E> {
    fn from(error: PayloadError) -> DrainError<E> {
        DrainError::Payload(error)
    }
}

#[cold]
fn bad(pos: usize, reason: impl Into<String>) -> PayloadError {
    PayloadError {
        pos,
        reason: reason.into(),
    }
}

/// The error for a `what` of `value` above its `max` at `pos`.
#[cold]
fn exceeds(pos: usize, what: &str, value: u64, max: u64) -> PayloadError {
    bad(pos, format!("{what} {value} exceeds {max}"))
}

/// Reads records from a payload slice, remembering the position for errors.
pub(crate) struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(bytes: &'a [u8], pos: usize) -> Cursor<'a> {
        Cursor { bytes, pos }
    }

    pub(crate) fn at_end(&self) -> bool {
        self.pos >= self.bytes.len()
    }

    pub(crate) fn pos(&self) -> usize {
        self.pos
    }

    fn remaining(&self) -> usize {
        self.bytes.len().saturating_sub(self.pos)
    }

    #[inline(always)]
    fn byte(&mut self) -> Result<u8, PayloadError> {
        match self.bytes.get(self.pos) {
            Some(&b) => {
                self.pos += 1;
                Ok(b)
            }
            None => Err(bad(self.pos, "record runs past the end of the payload")),
        }
    }

    #[inline(always)]
    pub(crate) fn uv(&mut self) -> Result<u64, PayloadError> {
        let first = self.byte()?;
        if first < 0x80 {
            return Ok(first as u64);
        }
        self.uv_long(first)
    }

    #[inline(never)]
    fn uv_long(&mut self, first: u8) -> Result<u64, PayloadError> {
        let start = self.pos - 1;
        if let Some((value, len)) = self.varint_in_word(start) {
            self.pos = start + len;
            return Ok(value);
        }
        let mut value = (first & 0x7f) as u64;
        for shift in (7..64).step_by(7) {
            let b = self.byte()?;
            if shift == 63 && b > 1 {
                return Err(bad(start, "varint overflows 64 bits"));
            }
            value |= ((b & 0x7f) as u64) << shift;
            if b < 0x80 {
                return Ok(value);
            }
        }
        Err(bad(start, "varint longer than 10 bytes"))
    }

    /// The next four bytes if each is a whole varint (below 0x80): a span header's usual
    /// shape, read with one test instead of four.
    #[inline(always)]
    fn four_one_byte_varints(&mut self) -> Option<[u8; 4]> {
        let bytes: [u8; 4] = self.bytes.get(self.pos..self.pos + 4)?.try_into().ok()?;
        if u32::from_le_bytes(bytes) & 0x8080_8080 != 0 {
            return None;
        }
        self.pos += 4;
        Some(bytes)
    }

    /// The next three bytes if each is a whole varint: a plane span's usual header.
    #[inline(always)]
    fn three_one_byte_varints(&mut self) -> Option<[u8; 3]> {
        let bytes: [u8; 3] = self.bytes.get(self.pos..self.pos + 3)?.try_into().ok()?;
        if (bytes[0] | bytes[1] | bytes[2]) & 0x80 != 0 {
            return None;
        }
        self.pos += 3;
        Some(bytes)
    }

    #[inline(always)]
    fn zz(&mut self) -> Result<i64, PayloadError> {
        self.uv().map(unzigzag)
    }

    /// A varint that must be at most `max`.
    #[inline(always)]
    fn uv_max(&mut self, max: u64, what: &str) -> Result<u64, PayloadError> {
        let pos = self.pos;
        let value = self.uv()?;
        if value > max {
            return Err(exceeds(pos, what, value, max));
        }
        Ok(value)
    }

    /// A varint that must fit in 32 bits: a byte below 0x80 is one whole; else it is read
    /// from one word where the payload holds eight bytes from it, else byte by byte (which
    /// also says what is wrong with it). A query's tile bounds are mostly the empty box's
    /// `u32::MAX`, five bytes: byte by byte, the lazy-grid walk's analytic replay (12,912
    /// tiles) spent 6% of its instructions reading them.
    #[inline(always)]
    fn u32(&mut self, what: &str) -> Result<u32, PayloadError> {
        if let Some(&first) = self.bytes.get(self.pos) {
            if first < 0x80 {
                self.pos += 1;
                return Ok(first as u32);
            }
        }
        match self.varint_in_word(self.pos) {
            Some((value, len)) if value <= u32::MAX as u64 => {
                self.pos += len;
                Ok(value as u32)
            }
            _ => self.u32_bytewise(what),
        }
    }

    #[cold]
    #[inline(never)]
    fn u32_bytewise(&mut self, what: &str) -> Result<u32, PayloadError> {
        self.uv_max(u32::MAX as u64, what).map(|v| v as u32)
    }

    /// The varint at `at`, with its length, if the payload holds eight bytes from there and
    /// it ends within them (then it is below `2^56`): one load, its 7-bit groups gathered by
    /// halving steps instead of a byte at a time.
    #[inline(always)]
    fn varint_in_word(&self, at: usize) -> Option<(u64, usize)> {
        let bytes: [u8; 8] = self.bytes.get(at..at + 8)?.try_into().ok()?;
        let word = u64::from_le_bytes(bytes);
        let ends = !word & 0x8080_8080_8080_8080;
        if ends == 0 {
            return None;
        }
        let len = ends.trailing_zeros() as usize / 8 + 1;
        let word = match len {
            8 => word,
            _ => word & ((1u64 << (8 * len)) - 1),
        };
        let x = word & 0x7f7f_7f7f_7f7f_7f7f;
        let x = (x & 0x007f_007f_007f_007f) | ((x & 0x7f00_7f00_7f00_7f00) >> 1);
        let x = (x & 0x0000_3fff_0000_3fff) | ((x & 0x3fff_0000_3fff_0000) >> 2);
        let x = (x & 0x0000_0000_0fff_ffff) | ((x & 0x0fff_ffff_0000_0000) >> 4);
        Some((x, len))
    }

    /// Eight bytes, little-endian.
    fn u64_le(&mut self, what: &str) -> Result<u64, PayloadError> {
        let Some(bytes) = self.bytes.get(self.pos..self.pos + 8) else {
            return Err(bad(
                self.pos,
                format!("{what} runs past the end of the payload"),
            ));
        };
        self.pos += 8;
        Ok(u64::from_le_bytes(bytes.try_into().expect("eight bytes")))
    }

    fn flag(&mut self, what: &str) -> Result<bool, PayloadError> {
        let pos = self.pos;
        match self.byte()? {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(bad(pos, format!("{what} flag {b} is neither 0 nor 1"))),
        }
    }

    /// A flags byte of which only the bits of `known` may be set.
    fn flags(&mut self, known: u8, what: &str) -> Result<u8, PayloadError> {
        let pos = self.pos;
        let flags = self.byte()?;
        if flags & !known != 0 {
            return Err(bad(
                pos,
                format!("{what} flags {flags:#04x} have unknown bits"),
            ));
        }
        Ok(flags)
    }

    fn mode(&mut self) -> Result<QueryMode, PayloadError> {
        let pos = self.pos;
        let code = self.byte()?;
        QueryMode::from_code(code)
            .ok_or_else(|| bad(pos, format!("unknown query mode code {code}")))
    }

    fn take(&mut self, len: usize) -> Result<&'a [u8], PayloadError> {
        if len > self.remaining() {
            return Err(bad(self.pos, "record runs past the end of the payload"));
        }
        let slice = &self.bytes[self.pos..self.pos + len];
        self.pos += len;
        Ok(slice)
    }
}

/// Where the next span starts and how depth changes, predicted from the previous span.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SpanPredictor {
    x: i64,
    y: i64,
    z: i64,
    /// Depth change per pixel step in x (from the previous span), in depth units.
    slope_x: i64,
    /// Depth change per row at fixed x (from the last row-to-row step), in depth units.
    slope_y: i64,
}

const SLOPE_LIMIT: i64 = 1 << 25;

impl SpanPredictor {
    /// The predicted first depth of a span starting `dx`, `dy` from the previous one.
    #[inline(always)]
    fn start_depth(&self, dx: i64, dy: i64) -> i64 {
        (self.z + self.slope_x * dx + self.slope_y * dy).clamp(0, DEPTH_ONE as i64)
    }

    /// A span starts at (x, y, z), `dx`, `dy` from the previous span.
    #[inline(always)]
    fn begin(&mut self, x: i64, y: i64, z: i64, dx: i64, dy: i64) {
        if dy == 1 {
            self.slope_y = (z - (self.z + self.slope_x * dx)).clamp(-SLOPE_LIMIT, SLOPE_LIMIT);
        }
        self.x = x;
        self.y = y;
        self.z = z;
    }

    /// A plane span starts at (x, y): the depths' predictions stay the last depth span's
    /// (a plane span's depths are its plane's; a depth span after it is rare).
    #[inline(always)]
    fn moved(&mut self, x: i64, y: i64) {
        self.x = x;
        self.y = y;
    }

    /// The span that began at depth `first` ended at depth `last` after `len` fragments.
    #[inline(always)]
    fn end(&mut self, first: i64, last: i64, len: usize) {
        if len >= 2 {
            // 32-bit division (the operands fit) is much cheaper than 64-bit on the decode path.
            self.slope_x = ((last - first) as i32).div_euclid(len as i32 - 1) as i64;
        }
    }
}

/// Append a span of fragments at (x0, y), (x0+1, y), ... with depths `depths`.
pub(crate) fn encode_span(
    out: &mut Vec<u8>,
    predictor: &mut SpanPredictor,
    x0: u16,
    y: u16,
    depths: &[u32],
) {
    debug_assert!(!depths.is_empty() && depths.len() <= MAX_SPAN_FRAGMENTS);
    let (x, y) = (x0 as i64, y as i64);
    let (dx, dy) = (x - predictor.x, y - predictor.y);
    let first = depths[0] as i64;
    out.push(tag::SPAN);
    put_zz(out, dy);
    put_zz(out, dx);
    put_uv(out, depths.len() as u64 - 1);
    put_zz(out, first - predictor.start_depth(dx, dy));
    // Each step's depth change is predicted by the previous span's slope: rounding a linear
    // depth leaves residuals in {0, 1} (one bit of entropy), where a second difference
    // would leave {-1, 0, 1}.
    let slope = predictor.slope_x;
    predictor.begin(x, y, first, dx, dy);
    let mut previous = first;
    for &depth in &depths[1..] {
        let depth = depth as i64;
        put_zz(out, depth - previous - slope);
        previous = depth;
    }
    predictor.end(first, previous, depths.len());
}

/// Append a plane record.
pub(crate) fn encode_plane(out: &mut Vec<u8>, plane: &PlaneDepths) {
    out.push(tag::PLANE);
    for value in [plane.a0, plane.dzdx, plane.dzdy] {
        out.extend_from_slice(&value.to_bits().to_le_bytes());
    }
    put_uv(out, plane.mirror.map_or(0, |mirror| mirror as u64 + 1));
}

/// Append a plane span of `len` fragments at (x0, y), (x0+1, y), ...: their depths are the
/// last plane record's.
pub(crate) fn encode_plane_span(
    out: &mut Vec<u8>,
    predictor: &mut SpanPredictor,
    x0: u16,
    y: u16,
    len: usize,
) {
    debug_assert!(len > 0 && len <= MAX_SPAN_FRAGMENTS);
    let (x, y) = (x0 as i64, y as i64);
    out.push(tag::PLANE_SPAN);
    put_zz(out, y - predictor.y);
    put_zz(out, x - predictor.x);
    put_uv(out, len as u64 - 1);
    predictor.moved(x, y);
}

/// Append a non-fragment event whose record is small and fixed in shape.
pub(crate) fn encode_small_event(out: &mut Vec<u8>, event: &Event) {
    match event {
        Event::Clear => out.push(tag::CLEAR),
        Event::DepthFunc(f) => out.extend_from_slice(&[tag::DEPTH_FUNC, f.code()]),
        Event::DepthMask(on) => out.extend_from_slice(&[tag::DEPTH_MASK, *on as u8]),
        Event::DepthTest(on) => out.extend_from_slice(&[tag::DEPTH_TEST, *on as u8]),
        Event::Cull(on) => out.extend_from_slice(&[tag::CULL, *on as u8]),
        Event::Scissor(None) => out.push(tag::SCISSOR_OFF),
        Event::Scissor(Some(rect)) => {
            out.push(tag::SCISSOR_ON);
            put_rect(out, rect);
        }
        Event::QueryEnd => out.push(tag::QUERY_END),
        Event::Primitive => out.push(tag::PRIMITIVE),
        Event::Geometry(batch) => {
            out.push(tag::GEOMETRY);
            put_uv(out, batch.vertices as u64);
            put_uv(out, batch.triangles as u64);
            out.push(batch.starts_draw as u8 | (batch.discarded as u8) << 1);
        }
        Event::HostWork(work) => {
            out.push(tag::HOST_WORK);
            for v in [work.nodes, work.boxes, work.decisions, work.pixels] {
                put_uv(out, v as u64);
            }
        }
        Event::Wait(id) => {
            out.push(tag::WAIT);
            put_uv(out, *id as u64);
        }
        Event::ConditionalBegin(id) => {
            out.push(tag::CONDITIONAL_BEGIN);
            put_uv(out, *id as u64);
        }
        Event::ConditionalEnd => out.push(tag::CONDITIONAL_END),
        Event::Swap => out.push(tag::SWAP),
        Event::QueryBegin(_) | Event::QueryResult(_) | Event::Fragment(_) => {
            unreachable!("not a small event: {event:?}")
        }
    }
}

fn put_rect(out: &mut Vec<u8>, rect: &Rect) {
    for v in [rect.x, rect.y, rect.width, rect.height] {
        put_uv(out, v as u64);
    }
}

/// Append a query begin or result record (tag included); it may be large.
pub(crate) fn encode_large_event(out: &mut Vec<u8>, event: &Event) {
    match event {
        Event::QueryBegin(spec) => {
            out.push(tag::QUERY_BEGIN_SIZED);
            put_uv(out, spec.id as u64);
            out.push(spec.mode.code());
            put_uv(out, spec.buffer_entries as u64);
            put_uv(out, spec.tiles.len() as u64);
            put_sized(out, |body| {
                spec.tiles.iter().for_each(|t| put_rect(body, t))
            });
        }
        Event::QueryResult(result) => {
            let totals = result.totals();
            out.push(tag::QUERY_RESULT_TOTALED);
            put_uv(out, result.id as u64);
            out.push(result.mode.code());
            put_uv(out, result.overflowed_buffers as u64);
            put_uv(out, result.tiles.len() as u64);
            for sum in [totals.nohc, totals.phc, totals.held_hits] {
                put_uv(out, sum);
            }
            put_sized(out, |body| {
                result.tiles.iter().for_each(|t| put_tile_result(body, t))
            });
        }
        _ => unreachable!("not a large event: {event:?}"),
    }
}

/// What `put` writes, after its length in bytes (so that a reader may pass over it).
fn put_sized(out: &mut Vec<u8>, put: impl FnOnce(&mut Vec<u8>)) {
    let mut body = Vec::new();
    put(&mut body);
    put_uv(out, body.len() as u64);
    out.extend_from_slice(&body);
}

fn put_tile_result(out: &mut Vec<u8>, tile: &TileResult) {
    put_uv(out, tile.nohc);
    put_uv(out, tile.phc);
    for v in [
        tile.xmin, tile.xmax, tile.ymin, tile.ymax, tile.zmin, tile.zmax,
    ] {
        put_uv(out, v as u64);
    }
    out.push(tile.overflowed as u8);
    put_hit_list(out, &tile.hits);
}

/// Count and listed hits (as deltas); then, for a list that holds any, a flags byte (bit 0
/// digests known, bit 1 last hit known), the two digests as little-endian u64s, the bounds
/// and the last hit.
fn put_hit_list(out: &mut Vec<u8>, hits: &HitList) {
    put_uv(out, hits.len());
    put_uv(out, hits.listed().len() as u64);
    put_hits(out, hits.listed());
    let Some(bounds) = hits.bounds() else {
        return;
    };
    let digests = hits.digests();
    out.push(digests.is_some() as u8 | (hits.last().is_some() as u8) << 1);
    if let Some(d) = digests {
        out.extend_from_slice(&d.in_order.to_le_bytes());
        out.extend_from_slice(&d.as_set.to_le_bytes());
    }
    for v in [bounds.xmin, bounds.xmax, bounds.ymin, bounds.ymax] {
        put_uv(out, v as u64);
    }
    if let Some((x, y)) = hits.last() {
        put_uv(out, x as u64);
        put_uv(out, y as u64);
    }
}

fn put_hits(out: &mut Vec<u8>, hits: &[Hit]) {
    let (mut px, mut py) = (0i64, 0i64);
    for &(x, y) in hits {
        put_zz(out, x as i64 - px);
        put_zz(out, y as i64 - py);
        (px, py) = (x as i64, y as i64);
    }
}

fn geometry_batch(c: &mut Cursor) -> Result<GeometryBatch, PayloadError> {
    let vertices = c.u32("batch vertices")?;
    let triangles = c.u32("batch triangles")?;
    let flags = c.flags(0b11, "geometry")?;
    Ok(GeometryBatch {
        vertices,
        triangles,
        starts_draw: flags & 1 != 0,
        discarded: flags & 2 != 0,
    })
}

fn rect(c: &mut Cursor) -> Result<Rect, PayloadError> {
    Ok(Rect::new(
        c.u32("x")?,
        c.u32("y")?,
        c.u32("width")?,
        c.u32("height")?,
    ))
}

/// Decode a query begin or result record (tag included), which must fill `bytes` exactly:
/// whole, or skimmed when `skim`.
fn decode_large_event(bytes: &[u8], skim: bool) -> Result<QueryRecord, PayloadError> {
    let mut c = Cursor::new(bytes, 0);
    let t = c.byte()?;
    let Some(query) = query_record(&mut c, t, skim)? else {
        return Err(bad(0, format!("multi-block event has tag {t:#04x}")));
    };
    if !c.at_end() {
        return Err(bad(c.pos, "multi-block event has bytes after its end"));
    }
    Ok(query)
}

/// A query begin or result as its reader asked for it.
pub(crate) enum QueryRecord {
    Whole(Event),
    /// A begin, its tiles' rectangles passed over.
    Shape(QueryShape),
    /// A result, its tiles passed over.
    Totals(QueryTotals),
}

/// The query record of tag `t` (read), whole or skimmed; None for another tag. A record
/// from before version 11 has no lengths to pass over, so it is read whole and skimmed
/// after.
#[inline]
fn query_record(c: &mut Cursor, t: u8, skim: bool) -> Result<Option<QueryRecord>, PayloadError> {
    let event = match t {
        tag::QUERY_BEGIN_SIZED => {
            let shape = shape_head(c)?;
            // Every rectangle takes at least 4 bytes.
            let end = body_end(c, shape.tiles, 4, "rectangles")?;
            if skim {
                c.pos = end;
                return Ok(Some(QueryRecord::Shape(shape)));
            }
            let spec = query_spec_tiles(c, shape)?;
            body_read(c, end, "rectangles")?;
            Event::QueryBegin(spec)
        }
        tag::QUERY_RESULT_TOTALED => {
            let start = c.pos - 1;
            let (totals, list_cap) = totals_head(c)?;
            let end = body_end(c, totals.tiles, 10, "tile results")?;
            if skim {
                c.pos = end;
                return Ok(Some(QueryRecord::Totals(totals)));
            }
            let result = query_result_tiles(c, totals, list_cap, HitCoding::Digested)?;
            body_read(c, end, "tile results")?;
            let summed = result.totals();
            if summed != totals {
                return Err(bad(
                    start,
                    format!(
                        "query {}'s result totals {totals:?} are not its tiles' {summed:?}",
                        totals.id
                    ),
                ));
            }
            Event::QueryResult(result)
        }
        tag::QUERY_BEGIN => Event::QueryBegin(query_spec(c)?),
        tag::QUERY_RESULT => Event::QueryResult(query_result(c, HitCoding::Digested)?),
        tag::QUERY_RESULT_LISTED => Event::QueryResult(query_result(c, HitCoding::Listed)?),
        _ => return Ok(None),
    };
    Ok(Some(match (skim, event) {
        (true, Event::QueryBegin(spec)) => QueryRecord::Shape(spec.shape()),
        (true, Event::QueryResult(result)) => QueryRecord::Totals(result.totals()),
        (_, event) => QueryRecord::Whole(event),
    }))
}

/// Where the body of a sized query record ends: its length read and checked to hold
/// `count` items of at least `least` bytes each within the payload.
fn body_end(c: &mut Cursor, count: usize, least: usize, what: &str) -> Result<usize, PayloadError> {
    let pos = c.pos;
    let len = c.uv_max(c.remaining() as u64, "query record length")? as usize;
    if len < count * least {
        return Err(bad(
            pos,
            format!("{count} {what} in {len} bytes (at least {least} each)"),
        ));
    }
    Ok(c.pos + len)
}

/// Check a sized record's body was read to its end, no further.
fn body_read(c: &Cursor, end: usize, what: &str) -> Result<(), PayloadError> {
    match c.pos == end {
        true => Ok(()),
        false => Err(bad(
            c.pos,
            format!(
                "{what} end at byte {}, not at {end} as their length says",
                c.pos
            ),
        )),
    }
}

/// A query begin's id, mode, buffer entries and tile count.
fn shape_head(c: &mut Cursor) -> Result<QueryShape, PayloadError> {
    Ok(QueryShape {
        id: c.u32("query id")?,
        mode: c.mode()?,
        buffer_entries: c.u32("buffer entries")?,
        tiles: c.uv_max(MAX_TILES as u64, "tile count")? as usize,
    })
}

/// A result's id, mode, overflowed buffers and tile count, its sums left 0.
fn result_head(c: &mut Cursor) -> Result<QueryTotals, PayloadError> {
    let id = c.u32("query id")?;
    let mode = c.mode()?;
    let overflowed_buffers = c.u32("overflowed buffers")?;
    Ok(QueryTotals {
        id,
        mode,
        tiles: c.uv_max(MAX_TILES as u64, "tile count")? as usize,
        nohc: 0,
        phc: 0,
        held_hits: 0,
        overflowed_buffers,
    })
}

/// A totaled result's head and sums, and the hits its tiles list at most.
fn totals_head(c: &mut Cursor) -> Result<(QueryTotals, usize), PayloadError> {
    let mut totals = result_head(c)?;
    totals.nohc = c.uv()?;
    totals.phc = c.uv()?;
    totals.held_hits = c.uv()?;
    Ok((totals, listed_hits_per_tile(totals.tiles)))
}

fn query_spec(c: &mut Cursor) -> Result<QuerySpec, PayloadError> {
    let shape = shape_head(c)?;
    query_spec_tiles(c, shape)
}

/// The begin of `shape`, its rectangles read.
fn query_spec_tiles(c: &mut Cursor, shape: QueryShape) -> Result<QuerySpec, PayloadError> {
    // Every tile takes at least 4 bytes: no allocation beyond what the payload can hold.
    let mut tiles = Vec::with_capacity(shape.tiles.min(c.remaining() / 4));
    for _ in 0..shape.tiles {
        tiles.push(rect(c)?);
    }
    Ok(QuerySpec {
        id: shape.id,
        mode: shape.mode,
        buffer_entries: shape.buffer_entries,
        tiles,
    })
}

/// A stretch record's runs of reads into `runs` (none unless `present`): a count and a pair
/// each, distinct. (Most stretches have none: that case inlined, the rest out of line.)
#[inline(always)]
fn decode_runs(c: &mut Cursor, present: bool, runs: &mut DenseRuns) -> Result<(), PayloadError> {
    if !runs.runs().is_empty() {
        *runs = DenseRuns::NONE;
    }
    if !present {
        return Ok(());
    }
    decode_present_runs(c, runs)
}

#[inline(never)]
fn decode_present_runs(c: &mut Cursor, runs: &mut DenseRuns) -> Result<(), PayloadError> {
    let pos = c.pos;
    let count = c.uv()?;
    if count == 0 || count > DENSE_READ_COSTS.len() as u64 {
        return Err(bad(pos, format!("a stretch with {count} runs of reads")));
    }
    for _ in 0..count {
        let pos = c.pos;
        let (reads, fragments) = (c.uv()?, c.uv()?);
        let (Ok(reads), Ok(fragments)) = (u32::try_from(reads), u32::try_from(fragments)) else {
            return Err(bad(pos, "a dense run of over 2^32 fragments".to_owned()));
        };
        runs.push(ReadRun { reads, fragments });
    }
    if runs.runs().len() as u64 != count {
        return Err(bad(pos, "a stretch with a dense run twice".to_owned()));
    }
    Ok(())
}

/// A span header's row and column steps and its length, each a varint read the general way
/// (a header's bytes not all one-byte varints).
#[inline(never)]
fn span_steps(c: &mut Cursor) -> Result<(i64, i64, usize), PayloadError> {
    let dy = c.zz()?;
    let dx = c.zz()?;
    let len = c.uv_max(MAX_SPAN_FRAGMENTS as u64 - 1, "span length")? as usize + 1;
    Ok((dy, dx, len))
}

/// A plane record's plane (its tag read).
fn plane_record(c: &mut Cursor) -> Result<PlaneDepths, PayloadError> {
    let mut value = || -> Result<f32, PayloadError> {
        let bytes: [u8; 4] = c.take(4)?.try_into().expect("four bytes");
        Ok(f32::from_bits(u32::from_le_bytes(bytes)))
    };
    let (a0, dzdx, dzdy) = (value()?, value()?, value()?);
    let pos = c.pos;
    let mirror = match c.uv()? {
        0 => None,
        code => Some(u32::try_from(code - 1).map_err(|_| bad(pos, "a plane's mirror past 2^32"))?),
    };
    Ok(PlaneDepths {
        a0,
        dzdx,
        dzdy,
        mirror,
    })
}

/// A band record's runs (its tag, `BAND` or `BAND_PASSING`, read) into `out`, checked to
/// be a band a writer makes in a viewport of `width` by `height`.
fn decode_band(
    c: &mut Cursor,
    (width, height): (u32, u32),
    out: &mut FragmentBand,
) -> Result<(), PayloadError> {
    let start = c.pos - 1;
    let passing_tag = c.bytes[start] == tag::BAND_PASSING;
    let count = c.byte()? as usize;
    if count == 0 || count > BAND_RUNS {
        return Err(bad(
            start,
            format!("a band of {count} runs (1 to {BAND_RUNS})"),
        ));
    }
    let passing = match passing_tag {
        true => c.uv_max((1 << count) - 1, "passing runs' mask")?,
        false => 0,
    };
    if passing_tag && passing == 0 {
        return Err(bad(start, "a band of passing runs with none passing"));
    }
    out.clear();
    let out_of_range = || bad(start, "a band run's x, row or length out of range");
    // Each of a run's x, row and length is below 2^16 (a viewport's side is at most
    // `MAX_VIEWPORT_SIDE`, 16,384) or the band is refused, so a zigzag varint of 2^17 or
    // more (a step of more than 2^16) is out of range whatever came before, and the steps
    // below it cannot overflow an i32. (With saturating i64 sums each converted on its own,
    // the IR's analytic level took the demo in 15.2 ms on ir4 and the lazy-grid walk in
    // 19.4, in one process, best of 7; so, 14.9 and 18.9.)
    let (mut x, mut y, mut len) = (0i32, 0i32, 0i32);
    for k in 0..count {
        let (dx, dy, dlen) = (c.uv()?, c.uv()?, c.uv()?);
        if (dx | dy | dlen) >= 1 << 17 {
            return Err(out_of_range());
        }
        x += unzigzag(dx) as i32;
        y += unzigzag(dy) as i32;
        len += unzigzag(dlen) as i32;
        if (x | y | len) as u32 >= 1 << 16 {
            return Err(out_of_range());
        }
        let passes = passing >> k & 1 == 1;
        let run = RowRun {
            x: x as u16,
            y: y as u16,
            len: len as u32,
            passes,
        };
        out.try_push(run, width, height)
            .map_err(|reason| bad(start, reason))?;
    }
    Ok(())
}

/// A row band's runs (its tag, `ROW_BAND`, read) into `out`, checked as
/// [`decode_band`] checks a band's (but a first run's `x`, row or length past 32 bits, which
/// is refused as that varint, at its own offset): one run a row from its first run's row
/// on, each run's `x` and `len` stepped from the row before's.
fn decode_row_band(
    c: &mut Cursor,
    (width, height): (u32, u32),
    out: &mut FragmentBand,
) -> Result<(), PayloadError> {
    const MAX_ROWS: usize = ROW_BAND_ROWS;
    let start = c.pos - 1;
    let count = c.byte()? as usize;
    if count == 0 || count > MAX_ROWS {
        return Err(bad(
            start,
            format!("a row band of {count} rows (1 to {MAX_ROWS})"),
        ));
    }
    // Each read from one word where it takes more than a byte (the rows' x and y mostly
    // do: by `Cursor::uv`, a call each, 3% of the IR's analytic level on the demo).
    let (x, y, len) = (c.u32("x")?, c.u32("row")?, c.u32("length")?);
    let (x, y, len) = (x as u64, y as u64, len as u64);
    // As in `decode_band`: below 2^16 each, so the steps below cannot overflow an i32.
    if (x | y | len) >= 1 << 16 {
        return Err(bad(start, "a band run's x, row or length out of range"));
    }
    if y as usize + count > height as usize {
        return Err(bad(start, "a band run empty or outside the viewport"));
    }
    // The rows stepped from the first, checked once, after.
    let first = RowRun::at(x as u16, y as u16, len as u32);
    let one_byte_each = (c.bytes.get(c.pos..c.pos + 2 * (count - 1)))
        .filter(|bytes| bytes.iter().fold(0, |all, byte| all | byte) < 0x80);
    let (ored, shortest) = if let Some(bytes) = one_byte_each {
        // The usual band: every step one byte (below 64 pixels), stepped as it is read.
        c.pos += bytes.len();
        let step = |pair: &[u8]| {
            let unzigzag = |byte: u8| unzigzag(byte as u64) as i32;
            (unzigzag(pair[0]), unzigzag(pair[1]))
        };
        out.fill_stepped_rows(first, bytes.chunks_exact(2).map(step))
    } else {
        let mut steps = [(0, 0); MAX_ROWS];
        let steps = &mut steps[..count - 1];
        for step in steps.iter_mut() {
            let (dx, dlen) = (c.uv()?, c.uv()?);
            // As in `decode_band`: a step of 2^16 or more is out of range.
            if (dx | dlen) >= 1 << 17 {
                return Err(bad(start, "a band run's x, row or length out of range"));
            }
            *step = (unzigzag(dx) as i32, unzigzag(dlen) as i32);
        }
        out.fill_stepped_rows(first, steps.iter().copied())
    };
    let error = if ored as u32 >= 1 << 16 {
        "a band run's x, row or length out of range"
    } else if shortest == 0 || out.columns().end as u32 > width {
        "a band run empty or outside the viewport"
    } else {
        return Ok(());
    };
    out.clear();
    Err(bad(start, error))
}

#[inline]
fn decode_stretch(c: &mut Cursor, out: &mut FragmentStretch) -> Result<(), PayloadError> {
    let start = c.pos - 1;
    // Field by field into `out`: the record is read for every stretch of an index.
    out.fragments = c.uv()?;
    out.depth_reads = c.uv()?;
    out.page_misses = c.uv()?;
    out.passed = c.uv()?;
    let pos = c.pos;
    let code = c.byte()?;
    let flags = FIRST_READS_FLAG | DENSE_RUNS_FLAG | ENDING_RUNS_FLAG | DRAWN_TAIL_FLAG;
    out.last_read = match code & !flags {
        0 => DepthRead::SameWord,
        1 => DepthRead::PageHit,
        2 => DepthRead::PageMiss,
        _ => return Err(bad(pos, format!("unknown last-read code {code}"))),
    };
    out.first_reads = if code & FIRST_READS_FLAG != 0 {
        c.uv()?
    } else {
        0
    };
    decode_runs(c, code & DENSE_RUNS_FLAG != 0, &mut out.dense)?;
    decode_runs(c, code & ENDING_RUNS_FLAG != 0, &mut out.ending)?;
    out.drawn_tail = match code & DRAWN_TAIL_FLAG != 0 {
        true => DrawnTail {
            fragments: c.uv()?,
            reads: c.uv()?,
        },
        false => DrawnTail::NONE,
    };
    match out.problem() {
        Some(problem) => Err(bad(start, problem)),
        None => Ok(()),
    }
}

/// How a query result record stores its hit lists.
#[derive(Clone, Copy)]
enum HitCoding {
    /// Every hit (versions 1 and 2).
    Listed,
    /// As [`put_hit_list`] writes them.
    Digested,
}

/// A result as versions before 11 store it: no totals, no length.
fn query_result(c: &mut Cursor, coding: HitCoding) -> Result<QueryResult, PayloadError> {
    let head = result_head(c)?;
    query_result_tiles(c, head, listed_hits_per_tile(head.tiles), coding)
}

/// The result whose id, mode, overflowed buffers and tile count `head` gives, its tiles
/// read (`list_cap` hits listed in each at most).
fn query_result_tiles(
    c: &mut Cursor,
    head: QueryTotals,
    list_cap: usize,
    coding: HitCoding,
) -> Result<QueryResult, PayloadError> {
    // Every tile result takes at least 10 bytes.
    let mut tiles = Vec::with_capacity(head.tiles.min(c.remaining() / 10));
    for _ in 0..head.tiles {
        push_tile_result(c, coding, list_cap, &mut tiles)?;
    }
    Ok(QueryResult {
        id: head.id,
        mode: head.mode,
        tiles,
        overflowed_buffers: head.overflowed_buffers,
    })
}

/// One tile's result onto `tiles`. Built in place: a tile's result (about 120 bytes) moved
/// out through a `Result` and into the vector cost the lazy-grid walk's analytic replay
/// (12,912 tiles) about 5% of its time.
#[inline(always)]
fn push_tile_result(
    c: &mut Cursor,
    coding: HitCoding,
    list_cap: usize,
    tiles: &mut Vec<TileResult>,
) -> Result<(), PayloadError> {
    let nohc = c.uv()?;
    let phc = c.uv()?;
    let mut bounds = [0u32; 6];
    for v in &mut bounds {
        *v = c.u32("tile bound")?;
    }
    let [xmin, xmax, ymin, ymax, zmin, zmax] = bounds;
    let overflowed = c.flag("overflow")?;
    let hits = match coding {
        HitCoding::Listed => {
            let count = c.uv_max(MAX_BUFFER_ENTRIES as u64, "hit count")? as usize;
            HitList::from_hits(hits(c, count)?, list_cap)
        }
        // A brief tile's list, nearly every list a trace holds: no hits, none listed.
        HitCoding::Digested if c.bytes.get(c.pos..c.pos + 2) == Some(&[0, 0]) => {
            c.pos += 2;
            HitList::default()
        }
        HitCoding::Digested => hit_list(c)?,
    };
    tiles.push(TileResult {
        nohc,
        phc,
        xmin,
        xmax,
        ymin,
        ymax,
        zmin,
        zmax,
        hits,
        overflowed,
    });
    Ok(())
}

fn hit_list(c: &mut Cursor) -> Result<HitList, PayloadError> {
    let start = c.pos;
    let len = c.uv_max(MAX_BUFFER_ENTRIES as u64, "hit count")?;
    let listed_count = c.uv_max(len.min(LISTED_HITS_PER_QUERY as u64), "listed hits")?;
    if len == 0 {
        // A brief tile's list, nearly every list a trace holds: nothing else follows, and
        // nothing is left to check against the count.
        return Ok(HitList::default());
    }
    let listed: Vec<Hit> = hits(c, listed_count as usize)?.collect();
    let flags = c.flags(0b11, "hit list")?;
    let digests = if flags & 1 == 1 {
        Some(HitDigests {
            in_order: c.u64_le("in-order hit digest")?,
            as_set: c.u64_le("hit set digest")?,
        })
    } else {
        None
    };
    let mut coordinate = || c.uv_max(u16::MAX as u64, "hit bound").map(|v| v as u16);
    let bounds = Some(HitBounds {
        xmin: coordinate()?,
        xmax: coordinate()?,
        ymin: coordinate()?,
        ymax: coordinate()?,
    });
    let last = if flags & 2 == 2 {
        Some((coordinate()?, coordinate()?))
    } else {
        None
    };
    HitList::from_parts(len, listed, digests, bounds, last).map_err(|why| bad(start, why))
}

/// `count` hits coded as deltas, checked to lie in 0..=65535.
fn hits<'c>(
    c: &'c mut Cursor,
    count: usize,
) -> Result<impl Iterator<Item = Hit> + 'c, PayloadError> {
    // Every hit takes at least 2 bytes.
    let mut hits = Vec::with_capacity(count.min(c.remaining() / 2));
    let (mut x, mut y) = (0i64, 0i64);
    for _ in 0..count {
        let pos = c.pos;
        x = x.wrapping_add(c.zz()?);
        y = y.wrapping_add(c.zz()?);
        if !(0..=u16::MAX as i64).contains(&x) || !(0..=u16::MAX as i64).contains(&y) {
            return Err(bad(pos, "hit coordinates outside 0..=65535"));
        }
        hits.push((x as u16, y as u16));
    }
    Ok(hits.into_iter())
}

/// A span being handed out one fragment at a time (the `next_event` path).
#[derive(Clone, Copy, Debug, Default)]
struct SpanProgress {
    /// Fragments of the span still to hand out.
    remaining: usize,
    /// A plane span: its depths are [`BlockDecoder::plane`]'s at its pixels.
    plane: bool,
    len: usize,
    x: u16,
    y: u16,
    first: i64,
    depth: i64,
    slope: i64,
}

/// The decoding state of one block's payload.
#[derive(Debug, Default)]
pub(crate) struct BlockDecoder {
    pos: usize,
    predictor: SpanPredictor,
    span: SpanProgress,
    /// Events completed in this block so far.
    pub events: u64,
    /// The depths of the span being handed out whole (at most `MAX_SPAN_FRAGMENTS`, and
    /// scratch past them).
    span_depths: Vec<u32>,
    /// The payload is a band-index block's: bands in place of fragments, not stretches.
    pub in_bands: bool,
    /// The block's last plane record's plane (none before its first).
    plane: Option<PlaneDepths>,
}

/// What the decoder needs beyond the payload: the viewport, the stream checks, and the bytes
/// of a large event split over blocks.
pub(crate) struct DecodeContext<'a> {
    pub width: u32,
    pub height: u32,
    pub tally: &'a mut StreamTally,
    pub assembly: &'a mut Vec<u8>,
    /// Decode the events between the fragments without checking their sense (a reader
    /// that starts mid-stream, for its fragments only): parts of large events are passed
    /// over, and no event reaches the tally.
    pub unchecked_events: bool,
    /// Read queries' begins as their shapes and their results as their totals, their tiles
    /// passed over ([`crate::trace::TraceReader::skim_queries`]; index lanes only).
    pub skim_queries: bool,
}

/// Account an index record's `count` fragments in the tally, as the events they stand for
/// would have been: a trace read by its index is then checked against its summary on every
/// count the events would give but their number (a summary forged to claim 2^40 queries
/// had passed every level that reads an index).
fn tally_fragments(ctx: &mut DecodeContext, count: u64) {
    if !ctx.unchecked_events {
        ctx.tally.checked_fragments(count);
    }
}

/// Why an event reader never meets a skimmed query: only the index lanes' readers skim
/// ([`crate::trace::TraceReader::skim_queries`]).
const EVENTS_WHOLE: &str = "a reader of events reads its queries whole";

/// A decoded record.
enum Record {
    Event(Event),
    /// A query begin, skimmed.
    Shape(QueryShape),
    /// A query result, skimmed.
    Totals(QueryTotals),
    /// A span's header was read; its fragments follow.
    Span,
    /// Part of a large event was stored.
    Part,
    /// A plane record was read: the plane spans after it take their depths from it.
    Plane,
}

impl BlockDecoder {
    pub(crate) fn new() -> BlockDecoder {
        BlockDecoder::default()
    }

    /// All events of the payload handed out (the decoder is at the end of the payload).
    pub(crate) fn is_done(&self, payload: &[u8]) -> bool {
        self.span.remaining == 0 && self.pos >= payload.len()
    }

    /// The next fragment if the decoder is inside a span (the common, cheap case).
    #[inline(always)]
    pub(crate) fn next_fragment_in_span(
        &mut self,
        payload: &[u8],
    ) -> Option<Result<Fragment, PayloadError>> {
        (self.span.remaining > 0).then(|| self.next_span_fragment(payload))
    }

    /// The next event, or None at the end of the payload.
    pub(crate) fn next_event(
        &mut self,
        payload: &[u8],
        ctx: &mut DecodeContext,
    ) -> Result<Option<Event>, PayloadError> {
        loop {
            if self.span.remaining > 0 {
                return self
                    .next_span_fragment(payload)
                    .map(|f| Some(Event::Fragment(f)));
            }
            if self.pos >= payload.len() {
                return Ok(None);
            }
            match self.record(payload, ctx)? {
                Record::Event(event) => return Ok(Some(event)),
                Record::Span | Record::Part | Record::Plane => {}
                Record::Shape(_) | Record::Totals(_) => unreachable!("{EVENTS_WHOLE}"),
            }
        }
    }

    /// The next item of a window-index payload, or None at its end: stretches in place of
    /// spans, which an index block must not hold.
    pub(crate) fn next_index_item(
        &mut self,
        payload: &[u8],
        ctx: &mut DecodeContext,
    ) -> Result<Option<IndexItem>, PayloadError> {
        while let Some(&t) = payload.get(self.pos) {
            if let Some(item) = self.index_record(t, payload, ctx)? {
                return Ok(Some(item));
            }
        }
        Ok(None)
    }

    /// The record at the decoder's position, tagged `t`, of a window-index payload: a
    /// stretch or an event, or None for part of a large event.
    #[inline(always)]
    fn index_record(
        &mut self,
        t: u8,
        payload: &[u8],
        ctx: &mut DecodeContext,
    ) -> Result<Option<IndexItem>, PayloadError> {
        match t {
            tag::STRETCH | tag::BAND | tag::BAND_PASSING | tag::ROW_BAND
                if (t != tag::STRETCH) != self.in_bands =>
            {
                Err(bad(
                    self.pos,
                    match self.in_bands {
                        true => "a stretch in a band-index block",
                        false => "a band in a window-index block",
                    },
                ))
            }
            tag::STRETCH => {
                let mut stretch = FragmentStretch::EMPTY;
                self.stretch_record(payload, ctx, &mut stretch)?;
                Ok(Some(IndexItem::Stretch(stretch)))
            }
            tag::BAND | tag::BAND_PASSING | tag::ROW_BAND => {
                let mut band = FragmentBand::EMPTY;
                self.band_record(payload, ctx, &mut band)?;
                Ok(Some(IndexItem::Band(band)))
            }
            tag::SPAN | tag::PLANE_SPAN | tag::PLANE => {
                Err(bad(self.pos, "a span or a plane in a window-index block"))
            }
            _ => Ok(match self.record(payload, ctx)? {
                Record::Event(event) => Some(IndexItem::Event(event)),
                Record::Shape(shape) => Some(IndexItem::Shape(shape)),
                Record::Totals(totals) => Some(IndexItem::Totals(totals)),
                Record::Span | Record::Part | Record::Plane => None,
            }),
        }
    }

    /// The stretch record at the decoder's position (its tag read), into `out`.
    #[inline]
    fn stretch_record(
        &mut self,
        payload: &[u8],
        ctx: &mut DecodeContext,
        out: &mut FragmentStretch,
    ) -> Result<(), PayloadError> {
        let mut c = Cursor::new(payload, self.pos + 1);
        decode_stretch(&mut c, out)?;
        self.pos = c.pos;
        self.events += 1;
        tally_fragments(ctx, out.fragments);
        Ok(())
    }

    /// The band record at the decoder's position (its tag read), into `out`.
    #[inline]
    fn band_record(
        &mut self,
        payload: &[u8],
        ctx: &mut DecodeContext,
        out: &mut FragmentBand,
    ) -> Result<(), PayloadError> {
        let mut c = Cursor::new(payload, self.pos + 1);
        match payload[self.pos] {
            tag::ROW_BAND => decode_row_band(&mut c, (ctx.width, ctx.height), out)?,
            _ => decode_band(&mut c, (ctx.width, ctx.height), out)?,
        }
        self.pos = c.pos;
        self.events += 1;
        tally_fragments(ctx, out.fragments());
        Ok(())
    }

    /// Hand every remaining item of a window-index payload to `visit`, as
    /// [`Self::next_index_item`] gives them one by one (each borrowed, not returned: no item
    /// is moved out through the layers of a result). Stops at the payload's first error or
    /// the visitor's.
    pub(crate) fn visit_index_items<E>(
        &mut self,
        payload: &[u8],
        ctx: &mut DecodeContext,
        mut visit: impl FnMut(&IndexItem) -> Result<(), E>,
    ) -> Result<(), DrainError<E>> {
        // Stretches, most items, are decoded in place into one item: a stretch's record
        // (80 bytes with its dense runs) moved through the layers of results cost the
        // analytic level about 36 instructions a stretch.
        let mut item = match self.in_bands {
            true => IndexItem::Band(FragmentBand::EMPTY),
            false => IndexItem::Stretch(FragmentStretch::EMPTY),
        };
        while let Some(&t) = payload.get(self.pos) {
            match (t, &mut item) {
                (tag::STRETCH, IndexItem::Stretch(stretch)) => {
                    self.stretch_record(payload, ctx, stretch)?;
                    visit(&item).map_err(DrainError::Sink)?;
                    continue;
                }
                (tag::BAND | tag::BAND_PASSING | tag::ROW_BAND, IndexItem::Band(band)) => {
                    self.band_record(payload, ctx, band)?;
                    visit(&item).map_err(DrainError::Sink)?;
                    continue;
                }
                // Primitives, the next most, skip the general dispatch (a tag alone).
                (tag::PRIMITIVE, _) if ctx.assembly.is_empty() => {
                    const PRIMITIVE: IndexItem = IndexItem::Event(Event::Primitive);
                    if !ctx.unchecked_events {
                        ctx.tally
                            .event(&Event::Primitive)
                            .map_err(|reason| bad(self.pos, reason))?;
                    }
                    self.pos += 1;
                    self.events += 1;
                    visit(&PRIMITIVE).map_err(DrainError::Sink)?;
                    continue;
                }
                _ => {}
            }
            if let Some(other) = self.index_record(t, payload, ctx)? {
                visit(&other).map_err(DrainError::Sink)?;
            }
        }
        Ok(())
    }

    /// Hand every remaining event of the payload to `sink`: the fast path. Stops at the
    /// payload's first error or the sink's.
    pub(crate) fn drain<S: EventSink>(
        &mut self,
        payload: &[u8],
        ctx: &mut DecodeContext,
        sink: &mut S,
    ) -> Result<(), DrainError<S::Error>> {
        self.drain_until(payload, ctx, sink, |_| false).map(|_| ())
    }

    /// [`Self::drain`], pausing before the next record once `enough(sink)` (checked between
    /// records, so a span is handed out whole): returns whether the payload was drained to
    /// its end. A paused decoder resumes where it stopped at the next call, with the same
    /// payload and context. (A reader that wants a block's first fragments alone stops
    /// decoding there.) Inlined, so that [`Self::drain`]'s check of a constant `false`
    /// vanishes: a whole read's loop is the one it was (the lazy-grid walk's functional
    /// replay ran 2-3% slower with it out of line).
    #[inline(always)]
    pub(crate) fn drain_until<S: EventSink>(
        &mut self,
        payload: &[u8],
        ctx: &mut DecodeContext,
        sink: &mut S,
        enough: impl Fn(&S) -> bool,
    ) -> Result<bool, DrainError<S::Error>> {
        while self.span.remaining > 0 {
            let fragment = self.next_span_fragment(payload)?;
            sink.event(&Event::Fragment(fragment))
                .map_err(DrainError::Sink)?;
        }
        // The fragments of the spans taken since the stream checks last heard of any: they
        // hear of them before the next other record (whose render state they arrived in)
        // and at the end.
        let mut unreported = 0;
        while let Some(&t) = payload.get(self.pos) {
            if enough(sink) {
                ctx.tally.checked_fragments(unreported);
                return Ok(false);
            }
            // Spans are most records: skip the general dispatch for them.
            if t == tag::PLANE_SPAN && ctx.assembly.is_empty() {
                unreported += self.plane_spans(payload, ctx, sink, &enough)?;
                continue;
            }
            if t == tag::SPAN && ctx.assembly.is_empty() {
                let mut c = Cursor::new(payload, self.pos + 1);
                let span = self.span_header(&mut c, ctx.width, ctx.height)?;
                self.pos = c.pos;
                unreported += span.len as u64;
                self.drain_span(payload, sink, span)?;
                continue;
            }
            ctx.tally.checked_fragments(std::mem::take(&mut unreported));
            match self.record(payload, ctx)? {
                Record::Event(event) => sink.event(&event).map_err(DrainError::Sink)?,
                Record::Span => self.drain_span(payload, sink, self.span)?,
                Record::Part | Record::Plane => {}
                Record::Shape(_) | Record::Totals(_) => unreachable!("{EVENTS_WHOLE}"),
            }
        }
        ctx.tally.checked_fragments(unreported);
        Ok(true)
    }

    /// Read one record; a span's header only sets up `self.span`.
    fn record(&mut self, payload: &[u8], ctx: &mut DecodeContext) -> Result<Record, PayloadError> {
        let mut c = Cursor::new(payload, self.pos);
        let start = c.pos;
        let t = c.byte()?;
        if !ctx.assembly.is_empty() && t != tag::PART && t != tag::PART_END {
            return Err(bad(start, "record inside an unfinished multi-block event"));
        }
        if ctx.unchecked_events && (t == tag::PART || t == tag::PART_END) {
            let len = c.uv_max(MAX_EVENT_BYTES as u64, "part length")? as usize;
            c.take(len)?;
            self.pos = c.pos;
            self.events += (t == tag::PART_END) as u64;
            return Ok(Record::Part);
        }
        let event = match t {
            tag::SPAN | tag::PLANE_SPAN => {
                self.span = match t {
                    tag::SPAN => self.span_header(&mut c, ctx.width, ctx.height)?,
                    _ => self.plane_span_header(&mut c, ctx.width, ctx.height)?,
                };
                ctx.tally.checked_fragments(self.span.len as u64);
                self.pos = c.pos;
                return Ok(Record::Span);
            }
            tag::PLANE => {
                self.plane = Some(plane_record(&mut c)?);
                self.pos = c.pos;
                return Ok(Record::Plane);
            }
            tag::PART | tag::PART_END => {
                let len = c.uv_max(MAX_EVENT_BYTES as u64, "part length")? as usize;
                let bytes = c.take(len)?;
                if ctx.assembly.len() + len > MAX_EVENT_BYTES {
                    return Err(bad(
                        start,
                        format!("multi-block event exceeds {MAX_EVENT_BYTES} bytes"),
                    ));
                }
                ctx.assembly.extend_from_slice(bytes);
                self.pos = c.pos;
                if t == tag::PART {
                    return Ok(Record::Part);
                }
                let query = decode_large_event(ctx.assembly, ctx.skim_queries).map_err(|e| {
                    bad(
                        start,
                        format!("in multi-block event at its byte {}: {}", e.pos, e.reason),
                    )
                })?;
                ctx.assembly.clear();
                return self.query_read(query, start, c.pos, ctx);
            }
            tag::CLEAR => Event::Clear,
            tag::DEPTH_FUNC => {
                let pos = c.pos;
                let code = c.byte()?;
                Event::DepthFunc(
                    DepthFunc::from_code(code)
                        .ok_or_else(|| bad(pos, format!("unknown depth function code {code}")))?,
                )
            }
            tag::DEPTH_MASK => Event::DepthMask(c.flag("depth mask")?),
            tag::DEPTH_TEST => Event::DepthTest(c.flag("depth test")?),
            tag::CULL => Event::Cull(c.flag("cull")?),
            tag::SCISSOR_OFF => Event::Scissor(None),
            tag::SCISSOR_ON => Event::Scissor(Some(rect(&mut c)?)),
            tag::QUERY_END => Event::QueryEnd,
            tag::PRIMITIVE => Event::Primitive,
            tag::GEOMETRY => Event::Geometry(geometry_batch(&mut c)?),
            tag::HOST_WORK => Event::HostWork(HostWork {
                nodes: c.u32("host nodes")?,
                boxes: c.u32("host boxes")?,
                decisions: c.u32("host decisions")?,
                pixels: c.u32("host read-back pixels")?,
            }),
            tag::WAIT => Event::Wait(c.u32("waited query id")?),
            tag::CONDITIONAL_BEGIN => Event::ConditionalBegin(c.u32("conditional query id")?),
            tag::CONDITIONAL_END => Event::ConditionalEnd,
            tag::SWAP => Event::Swap,
            // The query records' tags, which `query_record` alone knows, or none.
            t => {
                return match query_record(&mut c, t, ctx.skim_queries)? {
                    Some(query) => self.query_read(query, start, c.pos, ctx),
                    None => Err(bad(start, format!("unknown record tag {t:#04x}"))),
                }
            }
        };
        if !ctx.unchecked_events {
            ctx.tally
                .event(&event)
                .map_err(|reason| bad(start, reason))?;
        }
        self.pos = c.pos;
        self.events += 1;
        Ok(Record::Event(event))
    }

    /// A query record read from `start` to `end`: checked by the stream checks, whole or
    /// skimmed.
    fn query_read(
        &mut self,
        query: QueryRecord,
        start: usize,
        end: usize,
        ctx: &mut DecodeContext,
    ) -> Result<Record, PayloadError> {
        if !ctx.unchecked_events {
            match &query {
                QueryRecord::Whole(event) => ctx.tally.event(event),
                QueryRecord::Shape(shape) => ctx.tally.query_begin(*shape),
                QueryRecord::Totals(totals) => ctx.tally.query_result(totals),
            }
            .map_err(|reason| bad(start, reason))?;
        }
        self.pos = end;
        self.events += 1;
        Ok(match query {
            QueryRecord::Whole(event) => Record::Event(event),
            QueryRecord::Shape(shape) => Record::Shape(shape),
            QueryRecord::Totals(totals) => Record::Totals(totals),
        })
    }

    /// Read a span header, check the span lies in a `width` x `height` viewport, and
    /// return it (the stream checks are the caller's to tell).
    #[inline(always)]
    fn span_header(
        &mut self,
        c: &mut Cursor,
        width: u32,
        height: u32,
    ) -> Result<SpanProgress, PayloadError> {
        let start = c.pos - 1;
        // The first depth's residual, and where it is, once read.
        let mut first_residual = None;
        let (dy, dx, len) = match c.four_one_byte_varints() {
            Some([dy, dx, more, residual]) => {
                // (A one-byte length, below 128, is within MAX_SPAN_FRAGMENTS.)
                first_residual = Some((c.pos - 1, unzigzag(residual as u64)));
                let (dy, dx) = (unzigzag(dy as u64), unzigzag(dx as u64));
                (dy, dx, more as usize + 1)
            }
            None => span_steps(c)?,
        };
        let (x, y) = self.span_start(start, (dy, dx, len), (width, height))?;
        let p = &mut self.predictor;
        let (residual_pos, residual) = match first_residual {
            Some(read) => read,
            None => (c.pos, c.zz()?),
        };
        let first = p.start_depth(dx, dy).wrapping_add(residual);
        if !(0..=DEPTH_ONE as i64).contains(&first) {
            return Err(bad(
                residual_pos,
                format!("depth {first} outside 0..=2^24-1"),
            ));
        }
        let slope = p.slope_x;
        p.begin(x, y, first, dx, dy);
        self.events += len as u64;
        Ok(SpanProgress {
            remaining: len,
            plane: false,
            len,
            x: x as u16,
            y: y as u16,
            first,
            depth: first,
            slope,
        })
    }

    /// Where a span `dx` columns and `dy` rows from the last one starts, checked to lie
    /// whole (`len` fragments) in a `width` x `height` viewport (its header at `start`).
    #[inline(always)]
    fn span_start(
        &self,
        start: usize,
        (dy, dx, len): (i64, i64, usize),
        (width, height): (u32, u32),
    ) -> Result<(i64, i64), PayloadError> {
        let p = &self.predictor;
        let (x, y) = (p.x.wrapping_add(dx), p.y.wrapping_add(dy));
        if x < 0 || y < 0 || x + len as i64 > width as i64 || y >= height as i64 {
            return Err(bad(
                start,
                format!(
                    "span of {len} fragments at ({x}, {y}) outside the {width}x{height} viewport"
                ),
            ));
        }
        Ok((x, y))
    }

    /// Read a plane span's header, check the span lies in a `width` x `height` viewport
    /// and that a plane came before it in its block, and return it.
    #[inline(always)]
    fn plane_span_header(
        &mut self,
        c: &mut Cursor,
        width: u32,
        height: u32,
    ) -> Result<SpanProgress, PayloadError> {
        let (x, y, len) = self.plane_span_place(c, width, height)?;
        Ok(SpanProgress {
            remaining: len,
            plane: true,
            len,
            x,
            y,
            ..SpanProgress::default()
        })
    }

    /// A plane span's place (its header read and checked as [`Self::plane_span_header`]
    /// says): its first pixel and length.
    #[inline(always)]
    fn plane_span_place(
        &mut self,
        c: &mut Cursor,
        width: u32,
        height: u32,
    ) -> Result<(u16, u16, usize), PayloadError> {
        let start = c.pos - 1;
        let (dy, dx, len) = match c.three_one_byte_varints() {
            Some([dy, dx, more]) => (unzigzag(dy as u64), unzigzag(dx as u64), more as usize + 1),
            None => span_steps(c)?,
        };
        let (x, y) = self.span_start(start, (dy, dx, len), (width, height))?;
        if self.plane.is_none() {
            return Err(bad(start, "a plane span before any plane in its block"));
        }
        self.predictor.moved(x, y);
        self.events += len as u64;
        Ok((x as u16, y as u16, len))
    }

    /// The plane spans from the decoder's position on (a primitive's rows), each to `sink`
    /// whole, until another record or `enough(sink)`: as [`Self::drain_span`] would take
    /// them one by one, in a loop of their own. Returns their fragments.
    #[inline(always)]
    fn plane_spans<S: EventSink>(
        &mut self,
        payload: &[u8],
        ctx: &DecodeContext,
        sink: &mut S,
        enough: &impl Fn(&S) -> bool,
    ) -> Result<u64, DrainError<S::Error>> {
        let mut fragments = 0;
        while payload.get(self.pos) == Some(&tag::PLANE_SPAN) && !enough(sink) {
            let mut c = Cursor::new(payload, self.pos + 1);
            let (x, y, len) = self.plane_span_place(&mut c, ctx.width, ctx.height)?;
            self.pos = c.pos;
            fragments += len as u64;
            self.plane_span(sink, (x, y), len)?;
        }
        Ok(fragments)
    }

    /// A plane span (its place read, so its block's plane known) to `sink`, its depths
    /// evaluated in the span room unless the sink takes them otherwise
    /// ([`EventSink::plane_span`]).
    #[inline(always)]
    fn plane_span<S: EventSink>(
        &mut self,
        sink: &mut S,
        place: (u16, u16),
        len: usize,
    ) -> Result<(), DrainError<S::Error>> {
        let plane = self
            .plane
            .as_ref()
            .expect("a plane span's place found its plane");
        sink.plane_span(place, len, plane, &mut self.span_depths)
            .map_err(DrainError::Sink)
    }

    /// One fragment of the current span (slow path, state kept in `self.span`).
    fn next_span_fragment(&mut self, payload: &[u8]) -> Result<Fragment, PayloadError> {
        let span = &mut self.span;
        if span.plane {
            let x = span.x + (span.len - span.remaining) as u16;
            span.remaining -= 1;
            let plane = self.plane.expect("a plane span's header found its plane");
            return Ok(Fragment {
                x,
                y: span.y,
                z: plane.depth(x, span.y),
            });
        }
        if span.remaining < span.len {
            let mut c = Cursor::new(payload, self.pos);
            let pos = c.pos;
            span.depth = span.depth.wrapping_add(span.slope).wrapping_add(c.zz()?);
            if !(0..=DEPTH_ONE as i64).contains(&span.depth) {
                return Err(bad(pos, format!("depth {} outside 0..=2^24-1", span.depth)));
            }
            self.pos = c.pos;
            span.x += 1;
        }
        span.remaining -= 1;
        if span.remaining == 0 {
            self.predictor.end(span.first, span.depth, span.len);
        }
        Ok(Fragment {
            x: span.x,
            y: span.y,
            z: span.depth as u32,
        })
    }

    /// All fragments of `span`, whose header was just read (fast path).
    #[inline(always)]
    fn drain_span<S: EventSink>(
        &mut self,
        payload: &[u8],
        sink: &mut S,
        span: SpanProgress,
    ) -> Result<(), DrainError<S::Error>> {
        let SpanProgress {
            len,
            x,
            y,
            first,
            slope,
            plane,
            ..
        } = span;
        if plane {
            self.plane_span(sink, (x, y), len)?;
            self.span.remaining = 0;
            return Ok(());
        }
        let (pos, depth) =
            span_depths(payload, self.pos, len, first, slope, &mut self.span_depths)?;
        let depths = &self.span_depths[..len];
        sink.span(Span { x, y, depths }).map_err(DrainError::Sink)?;
        self.pos = pos;
        // (A span from `record` was set up in `self.span`; one from the fast path was not.)
        self.span.remaining = 0;
        self.predictor.end(first, depth, len);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn varints_of_every_length_read_back_and_bad_ones_name_their_offset() {
        // Hand-worked: 150 = 0b1_0010110 -> [0x96, 0x01]; 300 = 0b10_0101100 -> [0xac, 0x02].
        for (bytes, value) in [(vec![0x96, 0x01], 150), (vec![0xac, 0x02], 300)] {
            for padding in [0, 8] {
                let mut padded = bytes.clone();
                padded.resize(bytes.len() + padding, 0);
                let mut c = Cursor::new(&padded, 0);
                assert_eq!(c.uv().unwrap(), value, "{bytes:x?} padded by {padding}");
                assert_eq!(c.pos(), bytes.len());
            }
        }
        // Every length from 1 to 10 bytes at its edges (2^(7k) - 1 and 2^(7k)), at the
        // payload's end and with bytes after it.
        let mut values = vec![0, 1, 127, u64::MAX];
        for k in 1..10 {
            values.extend([
                (1u64 << (7 * k)) - 1,
                1u64 << (7 * k),
                (1u64 << (7 * k)) + 77,
            ]);
        }
        for value in values {
            let mut bytes = Vec::new();
            put_uv(&mut bytes, value);
            let len = bytes.len();
            // Padded by 8, a varint of up to 8 bytes is read from one word: bytes after
            // it of every bit set must not leak into it.
            for (padding, pad) in [(0, 0x80), (1, 0x80), (8, 0x80), (8, 0xff), (8, 0x7f)] {
                let mut padded = bytes.clone();
                padded.resize(len + padding, pad);
                let mut c = Cursor::new(&padded, 0);
                assert_eq!(c.uv().unwrap(), value, "{value} padded by {padding}");
                assert_eq!(c.pos(), len, "{value} padded by {padding}");
                let mut c = Cursor::new(&padded, 0);
                match u32::try_from(value) {
                    Ok(small) => {
                        assert_eq!(c.u32("bound").unwrap(), small, "{value}");
                        assert_eq!(c.pos(), len, "{value} padded by {padding}");
                    }
                    Err(_) => {
                        let error = c.u32("bound").unwrap_err();
                        assert_eq!(error.pos, 0, "{}", error.reason);
                        assert!(error.reason.contains("bound"), "{}", error.reason);
                    }
                }
            }
        }
        // Cut short, the error names the offset of the byte that is missing (two
        // continuation bytes: the third, at 2); too long, where the varint began.
        let error = Cursor::new(&[0xff, 0xff], 0).uv().unwrap_err();
        assert_eq!(error.pos, 2, "{}", error.reason);
        let eleven = [0xffu8; 11];
        let error = Cursor::new(&eleven, 0).uv().unwrap_err();
        assert_eq!(error.pos, 0, "{}", error.reason);
        assert!(error.reason.contains("overflows"), "{}", error.reason);
    }

    /// A result record as version 11 writes it: tag, id 7, mode brief, 0 overflowed
    /// buffers, 1 tile, then NOHC 3, PHC 4 and 0 held hits summed, then the tile's bytes.
    /// Read whole, its totals must be its tiles'; skimmed, they are taken as they are.
    #[test]
    fn a_result_whose_totals_are_not_its_tiles_is_refused_where_read_whole() {
        let result = QueryResult {
            id: 7,
            mode: QueryMode::Brief,
            tiles: vec![TileResult {
                nohc: 3,
                phc: 4,
                ..TileResult::default()
            }],
            overflowed_buffers: 0,
        };
        let mut record = Vec::new();
        encode_large_event(&mut record, &Event::QueryResult(result.clone()));
        assert_eq!(
            record[..8],
            [
                tag::QUERY_RESULT_TOTALED,
                7,
                QueryMode::Brief.code(),
                0,
                1,
                3,
                4,
                0
            ]
        );
        let whole = |record: &[u8]| match decode_large_event(record, false) {
            Ok(QueryRecord::Whole(Event::QueryResult(result))) => Ok(result),
            Ok(_) => panic!("not a whole result"),
            Err(e) => Err(e),
        };
        let skimmed = |record: &[u8]| match decode_large_event(record, true) {
            Ok(QueryRecord::Totals(totals)) => totals,
            _ => panic!("not totals"),
        };
        assert_eq!(whole(&record).unwrap(), result);
        assert_eq!(skimmed(&record), result.totals());
        // NOHC 3 -> 2: read whole, refused at the record's first byte, naming the query.
        record[5] = 2;
        let error = whole(&record).unwrap_err();
        assert_eq!(error.pos, 0);
        assert!(
            error.reason.contains("query 7's result totals"),
            "{}",
            error.reason
        );
        assert_eq!(skimmed(&record).nohc, 2);
        // A length past the record's end is refused either way.
        record[8] = 0x7f;
        for skim in [false, true] {
            let error = decode_large_event(&record, skim).err().expect("refused");
            assert!(
                error.reason.contains("query record length"),
                "{}",
                error.reason
            );
        }
    }

    #[test]
    fn a_version_2_result_with_every_hit_listed_reads_as_a_hit_list() {
        // The record as versions 1 and 2 wrote it: tag, id 7, mode verbose, 0 overflowed
        // buffers, 1 tile; nohc 3, phc 4, six bounds, not overflowed; 3 hits as zigzag
        // deltas from (0, 0): (2, 1) -> +2 +1, (5, 1) -> +3 0, (4, 2) -> -1 +1.
        let mut record = vec![tag::QUERY_RESULT_LISTED, 7, QueryMode::Verbose.code(), 0, 1];
        record.extend([3, 4, 2, 5, 1, 2, 9, 9, 0, 3]);
        record.extend([4, 2, 6, 0, 1, 2]);
        let QueryRecord::Whole(Event::QueryResult(result)) =
            decode_large_event(&record, false).unwrap()
        else {
            panic!("not a result");
        };
        let hits = [(2, 1), (5, 1), (4, 2)];
        assert_eq!(
            result.tiles[0].hits,
            HitList::from_hits(hits, LISTED_HITS_PER_QUERY)
        );
        assert_eq!(result.tiles[0].hits.listed(), hits);
    }

    #[test]
    fn hit_lists_round_trip_and_contradicting_parts_name_their_offset() {
        let mut cut = HitList::from_hits([(1, 2), (3, 4), (5, 6)], 2);
        cut.truncate(1);
        for list in [
            HitList::default(),
            HitList::from_hits([(9, 9)], 0),
            HitList::from_hits([(65535, 0), (0, 65535), (7, 7)], 2),
            cut,
        ] {
            let mut bytes = Vec::new();
            put_hit_list(&mut bytes, &list);
            let mut c = Cursor::new(&bytes, 0);
            assert_eq!(hit_list(&mut c).unwrap(), list);
            assert!(c.at_end());
        }
        // Two hits listed of one held.
        let bytes = [1, 2, 0, 0, 2, 2];
        let error = hit_list(&mut Cursor::new(&bytes, 0)).unwrap_err();
        assert_eq!(error.pos, 1, "{}", error.reason);
        assert!(
            error.reason.contains("listed hits 2 exceeds 1"),
            "{}",
            error.reason
        );
    }
}
