//! The streaming trace writer: events in, blocks out, one block buffer of memory.

use super::bands::{FragmentBand, RowRun};
use super::block::*;
use super::codec::{
    encode_large_event, encode_plane, encode_plane_span, encode_small_event, encode_span, put_uv,
    span_bytes_bound, tag, SpanPredictor, MAX_EVENT_BYTES, MAX_SPAN_FRAGMENTS,
    PLANE_AND_SPAN_BYTES,
};
use super::depth_tests::DepthTestBits;
use super::header::{BlockCounts, StreamTally, TraceHeader, TraceSummary};
use super::index::{FragmentStretch, WindowIndexer};
use super::windows::{WindowScout, WindowSize};
use super::TraceError;
use crate::depth_layout::DepthLayout;
use crate::event::{Event, Fragment};
use crate::golden::EventSink;
use crate::raster::PlaneDepths;
use std::io::Write;

/// Payload bytes a block holds at most by default: 64 KB, about 60,000 of the demo's
/// fragments as spans of depths (plane spans, a few bytes a row, end a block at
/// [`BLOCK_EVENTS`] first). A reader that starts mid-trace (the sampled level's machines) decodes the
/// block holding its first fragment from the block's start, so smaller blocks waste less;
/// a block decoded whole also stays in a 2-core machine's cache. Measured against 1 MB
/// blocks (`occsim replay T --fidelity sampled:10`, whole process): 256 KB took the demo
/// from 0.22 to 0.13 s. Since the O2's sampled windows simulate 12,288 fragments (warm-up
/// and tail), 64 KB against 256 KB (in one process, best of 10, sampled:10 and sampled:100):
/// the demo 30-31 -> 23-24 ms and 10 -> 7.6 ms, its file 1% smaller; the lazy-grid walk
/// 24 -> 21 ms and 13 ms either way, its file 13% larger (0.88 -> 0.99 MB). 32 KB gave no
/// more and the walk's file 28% larger.
pub const DEFAULT_BLOCK_BYTES: usize = 64 << 10;

/// Events an event block holds at most (a span that would pass it starts the next block):
/// what keeps blocks of plane spans, a few bytes a row, fine-grained for a reader that
/// starts mid-trace (format 13 at 64 KB alone put 800,000 of the demo's fragments in a
/// block). In one process, best of 5: the demo's sampled:10 and sampled:100 on the O2 took
/// 30.0 and 6.4 ms uncapped, 25.3 and 5.3 ms at 2^18 events, 24.1 and 5.3 at 2^17, 23.7 and
/// 5.2 at 2^16 (25.7 and 5.6 from its version-12 trace); each block's zstd tables cost the
/// random triangles' functional replay 667 M instructions uncapped, 670 M, 677 M and 687 M.
pub const BLOCK_EVENTS: usize = 1 << 17;

/// How the writer cuts and compresses blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriterOptions {
    /// Most payload bytes per block before compression, 4096..=`MAX_BLOCK_BYTES`.
    pub block_bytes: usize,
    /// zstd compression level (1..=22). Higher levels find longer matches, so fewer
    /// sequences to decode: the default, 9, against 3 made the demo's trace 25% smaller and
    /// its functional replay 8% sooner, its writing 21% slower (12 saves another 2% of the
    /// replay for twice the writing).
    pub zstd_level: i32,
    /// Write a window index counted at this depth layout ([`crate::trace::index`]).
    pub window_index: Option<DepthLayout>,
}

impl Default for WriterOptions {
    fn default() -> WriterOptions {
        WriterOptions {
            block_bytes: DEFAULT_BLOCK_BYTES,
            zstd_level: 9,
            window_index: None,
        }
    }
}

/// A block being filled, and what the blocks of its kind took so far.
struct OpenBlock {
    kind: u8,
    payload: Vec<u8>,
    /// Items completed in the payload (events; for the index, its items).
    items: u32,
    written: BlockCounts,
}

impl OpenBlock {
    fn new(kind: u8) -> OpenBlock {
        OpenBlock {
            kind,
            payload: Vec::new(),
            items: 0,
            written: BlockCounts::default(),
        }
    }
}

/// The streams a writer fills: the events, the window index, the band index, and the
/// window table.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Lane {
    Events,
    Index,
    Bands,
    Windows,
}

/// The window index being written: its counting state and its open block, and the depth
/// tests' results of the open event block's fragments (and of the span being gathered).
struct IndexLane {
    indexer: Box<WindowIndexer>,
    block: OpenBlock,
    /// The band index's open block ([`crate::trace::bands`]), and the band being gathered.
    bands: OpenBlock,
    band: FragmentBand,
    depth_tests: DepthTestBits,
    span_passed: Vec<bool>,
    depth_test_blocks: BlockCounts,
}

/// Most bytes a small (state) event record takes: a tag and four 5-byte varints.
const SMALL_EVENT_BYTES: usize = 21;
/// Room for a part record's tag and length varint.
const PART_OVERHEAD: usize = 11;

/// Writes a trace to `W` as events arrive. Use it as an [`EventSink`] (the first error is
/// kept and reported by [`TraceWriter::finish`]) or through [`TraceWriter::write_event`].
pub struct TraceWriter<W: Write> {
    out: W,
    /// The header as written, and its JSON's length padded with spaces so that a finished
    /// header with the features used fits in place.
    header: TraceHeader,
    header_json_bytes: usize,
    /// Bytes written so far.
    offset: u64,
    options: WriterOptions,
    compressor: zstd::bulk::Compressor<'static>,
    /// The open event block.
    events: OpenBlock,
    predictor: SpanPredictor,
    /// The span being gathered: its start and its depths.
    span_x: u16,
    span_y: u16,
    span_depths: Vec<u32>,
    max_span: usize,
    /// The depth plane of the primitive being written, where the rasterizer told one
    /// ([`EventSink::depth_plane`]); whether the open event block holds it yet; room for
    /// the depths it gives a span.
    plane: Option<PlaneDepths>,
    plane_in_block: bool,
    plane_depths: Vec<u32>,
    /// Scratch space for a large event's record, and for compressed output.
    large: Vec<u8>,
    stored: Vec<u8>,
    tally: StreamTally,
    width: u32,
    height: u32,
    events_seen: u64,
    index: Option<IndexLane>,
    /// The window table: the windows' rule followed over the events written, and its open
    /// block ([`crate::trace::windows`]).
    windows: WindowScout,
    window_table: OpenBlock,
    failed: bool,
}

/// Room kept in the header JSON (as trailing spaces, which JSON ignores) for the features
/// used, written back by [`TraceWriter::finish_seekable`]: every query mode and depth function
/// and every flag set take under 300 bytes.
const FEATURES_RESERVE_BYTES: usize = 512;

/// The file header's bytes, at this format's version.
fn header_bytes(json: &[u8]) -> Vec<u8> {
    file_header_bytes(FORMAT_VERSION, json)
}

fn write_at(out: &mut impl Write, offset: &mut u64, bytes: &[u8]) -> Result<(), TraceError> {
    out.write_all(bytes).map_err(|io| TraceError::Io {
        offset: *offset,
        io,
    })?;
    *offset += bytes.len() as u64;
    Ok(())
}

impl<W: Write> TraceWriter<W> {
    /// Start a trace: writes the file header at once.
    pub fn new(out: W, header: &TraceHeader) -> Result<TraceWriter<W>, TraceError> {
        TraceWriter::with_options(out, header, WriterOptions::default())
    }

    pub fn with_options(
        mut out: W,
        header: &TraceHeader,
        options: WriterOptions,
    ) -> Result<TraceWriter<W>, TraceError> {
        let bad_header = |reason: String| TraceError::BadHeader { offset: 0, reason };
        if !(4096..=MAX_BLOCK_BYTES).contains(&options.block_bytes) {
            return Err(bad_header(format!(
                "block size {} outside 4096..={MAX_BLOCK_BYTES}",
                options.block_bytes
            )));
        }
        let header = TraceHeader {
            window_index: options.window_index,
            // The writer always writes one.
            window_table: true,
            ..header.clone()
        };
        if let Some(problem) = header.problem() {
            return Err(bad_header(problem));
        }
        let mut json = serde_json::to_vec(&header).map_err(|e| bad_header(e.to_string()))?;
        json.resize(json.len() + FEATURES_RESERVE_BYTES, b' ');
        if json.len() > MAX_HEADER_JSON_BYTES as usize {
            return Err(bad_header(format!(
                "header JSON of {} bytes exceeds {MAX_HEADER_JSON_BYTES}",
                json.len()
            )));
        }
        let indexer = match options.window_index {
            Some(layout) => Some(WindowIndexer::new(&layout, header.width, header.height)?),
            None => None,
        };
        let bytes = header_bytes(&json);
        let mut offset = 0;
        write_at(&mut out, &mut offset, &bytes)?;
        let compressor = zstd::bulk::Compressor::new(options.zstd_level)
            .map_err(|e| bad_header(format!("zstd level {}: {e}", options.zstd_level)))?;
        Ok(TraceWriter {
            out,
            index: indexer.map(|indexer| IndexLane {
                indexer: Box::new(indexer),
                block: OpenBlock::new(KIND_INDEX),
                bands: OpenBlock::new(KIND_BANDS),
                band: FragmentBand::EMPTY,
                depth_tests: DepthTestBits::default(),
                span_passed: Vec::new(),
                depth_test_blocks: BlockCounts::default(),
            }),
            header: header.clone(),
            header_json_bytes: json.len(),
            offset,
            options,
            compressor,
            events: OpenBlock::new(KIND_EVENTS),
            predictor: SpanPredictor::default(),
            span_x: 0,
            span_y: 0,
            span_depths: Vec::new(),
            max_span: MAX_SPAN_FRAGMENTS.min((options.block_bytes - span_bytes_bound(1)) / 10),
            plane: None,
            plane_in_block: false,
            plane_depths: Vec::new(),
            large: Vec::new(),
            stored: Vec::new(),
            tally: StreamTally::new(&header),
            width: header.width,
            height: header.height,
            events_seen: 0,
            windows: WindowScout::default(),
            window_table: OpenBlock::new(KIND_WINDOWS),
            failed: false,
        })
    }

    /// Append one event. After an error the writer accepts nothing more.
    pub fn write_event(&mut self, event: &Event) -> Result<(), TraceError> {
        if self.failed {
            return Err(self.invalid("the writer stopped at an earlier error".to_owned()));
        }
        let result = self.append(event);
        self.failed = result.is_err();
        self.events_seen += 1;
        result
    }

    fn invalid(&self, reason: String) -> TraceError {
        TraceError::InvalidEvent {
            event: self.events_seen,
            reason,
        }
    }

    fn append(&mut self, event: &Event) -> Result<(), TraceError> {
        if let Event::Fragment(f) = event {
            if f.x as u32 >= self.width
                || f.y as u32 >= self.height
                || f.z > crate::event::DEPTH_ONE
            {
                let reason = self.tally.event(event).err().unwrap_or_default();
                return Err(self.invalid(reason));
            }
            self.tally.checked_fragments(1);
            self.windows.fragments(1);
            self.write_ended_windows()?;
            let passed = self.index.as_mut().map(|index| index.indexer.fragment(*f));
            if let Some(passed) = passed {
                self.band_fragment(*f, passed)?;
            }
            let len = self.span_depths.len();
            let continues = len > 0
                && len < self.max_span
                && f.y == self.span_y
                && f.x as usize == self.span_x as usize + len;
            if !continues {
                self.flush_span()?;
                (self.span_x, self.span_y) = (f.x, f.y);
            }
            self.span_depths.push(f.z);
            if let (Some(index), Some(passed)) = (&mut self.index, passed) {
                index.span_passed.push(passed);
            }
            return Ok(());
        }
        self.flush_span()?;
        if *event == Event::Primitive {
            // A new primitive's plane, if any, is told after its event.
            self.plane = None;
        }
        self.tally
            .event(event)
            .map_err(|reason| self.invalid(reason))?;
        self.flush_stretch()?;
        match event {
            Event::QueryBegin(_) | Event::QueryResult(_) => self.append_large(event)?,
            _ => {
                for lane in self.lanes() {
                    self.make_room(lane, SMALL_EVENT_BYTES)?;
                    if let Some(block) = self.open_block(lane) {
                        encode_small_event(&mut block.payload, event);
                        block.items += 1;
                    }
                }
            }
        }
        if let Some(index) = &mut self.index {
            index.indexer.event(event);
        }
        self.windows.event(event);
        self.write_ended_windows()
    }

    /// Into the window table: the windows the events so far have ended.
    fn write_ended_windows(&mut self) -> Result<(), TraceError> {
        while let Some(size) = self.windows.take_ended() {
            self.make_room(Lane::Windows, WindowSize::MAX_BYTES)?;
            size.encode(&mut self.window_table.payload);
            self.window_table.items += 1;
        }
        Ok(())
    }

    /// Into the band being gathered: fragment `f`, passing its depth test or not (marked
    /// under a verbose query); the band goes into the band index first where it would not
    /// admit it.
    fn band_fragment(&mut self, f: Fragment, passed: bool) -> Result<(), TraceError> {
        let Some(index) = &self.index else {
            return Ok(());
        };
        let run = RowRun {
            passes: passed && index.indexer.verbose,
            ..RowRun::at(f.x, f.y, 1)
        };
        if !index.band.admits_run(&run) {
            self.flush_band()?;
        }
        if let Some(index) = &mut self.index {
            index.band.push_run(run);
        }
        Ok(())
    }

    /// Into the band index: the band being gathered, if it holds a fragment.
    fn flush_band(&mut self) -> Result<(), TraceError> {
        let Some(band) = self
            .index
            .as_mut()
            .map(|index| std::mem::take(&mut index.band))
            .filter(|band| !band.is_empty())
        else {
            return Ok(());
        };
        self.make_room(Lane::Bands, FragmentBand::MAX_BYTES)?;
        if let Some(block) = self.open_block(Lane::Bands) {
            band.encode(&mut block.payload);
            block.items += 1;
        }
        Ok(())
    }

    /// Into the index: the stretch of fragments since its last item, if any (and into the
    /// band index, its last band).
    fn flush_stretch(&mut self) -> Result<(), TraceError> {
        self.flush_band()?;
        let Some(stretch) = self
            .index
            .as_mut()
            .and_then(|index| index.indexer.take_stretch())
        else {
            return Ok(());
        };
        self.make_room(Lane::Index, FragmentStretch::MAX_BYTES)?;
        if let Some(block) = self.open_block(Lane::Index) {
            stretch.encode(&mut block.payload);
            block.items += 1;
        }
        Ok(())
    }

    /// The lanes this writer fills.
    fn lanes(&self) -> impl Iterator<Item = Lane> {
        let index = self.index.is_some().then_some([Lane::Index, Lane::Bands]);
        std::iter::once(Lane::Events).chain(index.into_iter().flatten())
    }

    fn open_block(&mut self, lane: Lane) -> Option<&mut OpenBlock> {
        match lane {
            Lane::Events => Some(&mut self.events),
            Lane::Index => self.index.as_mut().map(|index| &mut index.block),
            Lane::Bands => self.index.as_mut().map(|index| &mut index.bands),
            Lane::Windows => Some(&mut self.window_table),
        }
    }

    /// Close `lane`'s open block if `bytes` more would not fit.
    fn make_room(&mut self, lane: Lane, bytes: usize) -> Result<(), TraceError> {
        let limit = self.options.block_bytes;
        if self
            .open_block(lane)
            .is_some_and(|block| block.payload.len() + bytes > limit)
        {
            self.flush_block(lane)?;
        }
        Ok(())
    }

    fn flush_span(&mut self) -> Result<(), TraceError> {
        if self.span_depths.is_empty() {
            return Ok(());
        }
        if self.events.items as usize + self.span_depths.len() > BLOCK_EVENTS {
            self.flush_block(Lane::Events)?;
        }
        if self.plane_gives_span() {
            self.make_room(Lane::Events, PLANE_AND_SPAN_BYTES)?;
            let (payload, plane) = (&mut self.events.payload, self.plane.as_ref());
            if let Some(plane) = plane.filter(|_| !self.plane_in_block) {
                encode_plane(payload, plane);
                self.plane_in_block = true;
            }
            let len = self.span_depths.len();
            encode_plane_span(payload, &mut self.predictor, self.span_x, self.span_y, len);
        } else {
            self.make_room(Lane::Events, span_bytes_bound(self.span_depths.len()))?;
            encode_span(
                &mut self.events.payload,
                &mut self.predictor,
                self.span_x,
                self.span_y,
                &self.span_depths,
            );
        }
        self.events.items += self.span_depths.len() as u32;
        self.span_depths.clear();
        if let Some(index) = &mut self.index {
            index
                .span_passed
                .drain(..)
                .for_each(|passed| index.depth_tests.push(passed));
        }
        Ok(())
    }

    /// Whether the gathered span's depths are the current plane's at its pixels, as a
    /// reader evaluates them ([`PlaneDepths::fill`]): then the span is written as a plane
    /// span, without them.
    fn plane_gives_span(&mut self) -> bool {
        let Some(plane) = &self.plane else {
            return false;
        };
        let len = self.span_depths.len();
        self.plane_depths.resize(len, 0);
        plane.fill(self.span_x, self.span_y, &mut self.plane_depths);
        self.plane_depths == self.span_depths
    }

    /// The primitive just begun has the depths of `plane` at its pixels: its spans that
    /// have them are written as plane spans. (The span gathered before belongs to the
    /// primitive before: it is written first.)
    pub fn depth_plane(&mut self, plane: &PlaneDepths) -> Result<(), TraceError> {
        if self.failed {
            return Err(self.invalid("the writer stopped at an earlier error".to_owned()));
        }
        let result = self.flush_span();
        self.failed = result.is_err();
        self.plane = Some(*plane);
        self.plane_in_block = false;
        result
    }

    /// A query begin or result, into every lane.
    fn append_large(&mut self, event: &Event) -> Result<(), TraceError> {
        let mut large = std::mem::take(&mut self.large);
        large.clear();
        encode_large_event(&mut large, event);
        let total = large.len();
        let result = if total > MAX_EVENT_BYTES {
            Err(self.invalid(format!("event of {total} bytes exceeds {MAX_EVENT_BYTES}")))
        } else {
            self.lanes()
                .try_for_each(|lane| self.put_large(lane, &large))
        };
        self.large = large;
        result
    }

    /// An encoded large event into `lane`: inline if it fits a block, else in parts over
    /// several blocks.
    fn put_large(&mut self, lane: Lane, large: &[u8]) -> Result<(), TraceError> {
        let (total, limit) = (large.len(), self.options.block_bytes);
        if total <= limit {
            self.make_room(lane, total)?;
        }
        let mut done = 0;
        while let Some(block) = self.open_block(lane) {
            if total <= limit {
                block.payload.extend_from_slice(large);
                block.items += 1;
                break;
            }
            let room = limit.saturating_sub(block.payload.len() + PART_OVERHEAD);
            if room < 256 {
                self.flush_block(lane)?;
                continue;
            }
            let chunk = room.min(total - done);
            let last = done + chunk == total;
            block
                .payload
                .push(if last { tag::PART_END } else { tag::PART });
            put_uv(&mut block.payload, chunk as u64);
            block.payload.extend_from_slice(&large[done..done + chunk]);
            done += chunk;
            if last {
                block.items += 1;
                break;
            }
        }
        Ok(())
    }

    /// Compress and write `lane`'s open block; the next event block starts with fresh
    /// prediction state.
    fn flush_block(&mut self, lane: Lane) -> Result<(), TraceError> {
        let Some(block) = self.open_block(lane) else {
            return Ok(());
        };
        if block.payload.is_empty() {
            return Ok(());
        }
        let payload = std::mem::take(&mut block.payload);
        let (kind, items) = (block.kind, std::mem::take(&mut block.items));
        let written = self.write_block(kind, items, &payload)?;
        if lane == Lane::Events {
            self.predictor = SpanPredictor::default();
            self.plane_in_block = false;
            self.flush_depth_tests()?;
        }
        if let Some(block) = self.open_block(lane) {
            block.written.add(&written);
            block.payload = payload;
            block.payload.clear();
        }
        Ok(())
    }

    /// After an event block: the depth tests' results of its fragments, in a block of their
    /// own (so a reader that wants them finds them right after the events they belong to).
    fn flush_depth_tests(&mut self) -> Result<(), TraceError> {
        let Some(index) = &mut self.index else {
            return Ok(());
        };
        let bits = std::mem::take(&mut index.depth_tests);
        let written = self.write_block(KIND_DEPTH_TESTS, bits.count(), bits.bytes())?;
        if let Some(index) = &mut self.index {
            index.depth_test_blocks.add(&written);
            index.depth_tests = bits.emptied();
        }
        Ok(())
    }

    /// Compress (when that saves bytes) and write one block; returns its header.
    fn write_block(
        &mut self,
        kind: u8,
        items: u32,
        payload: &[u8],
    ) -> Result<BlockHeader, TraceError> {
        self.stored.clear();
        self.stored
            .reserve(zstd::zstd_safe::compress_bound(payload.len()));
        let compressed = self
            .compressor
            .compress_to_buffer(payload, &mut self.stored);
        let zstd_wins = compressed.is_ok() && self.stored.len() < payload.len();
        let (codec, stored) = if zstd_wins {
            (CODEC_ZSTD, &self.stored[..])
        } else {
            (CODEC_STORED, payload)
        };
        let header = BlockHeader {
            kind,
            codec,
            events: items,
            raw_len: payload.len() as u32,
            stored_len: stored.len() as u32,
        };
        let crc = header.checksum(stored);
        write_at(&mut self.out, &mut self.offset, &header.fields())?;
        write_at(&mut self.out, &mut self.offset, &crc.to_le_bytes())?;
        write_at(&mut self.out, &mut self.offset, stored)?;
        Ok(header)
    }

    /// End the trace: write the last block, the summary and the trailer, and flush.
    pub fn finish(mut self) -> Result<TraceSummary, TraceError> {
        self.finish_stream()
    }

    /// Write the last block, the summary and the trailer, and flush.
    fn finish_stream(&mut self) -> Result<TraceSummary, TraceError> {
        if self.failed {
            return Err(self.invalid("the writer stopped at an earlier error".to_owned()));
        }
        self.flush_span()?;
        self.flush_stretch()?;
        self.windows.finish();
        self.write_ended_windows()?;
        self.flush_block(Lane::Events)?;
        self.flush_block(Lane::Index)?;
        self.flush_block(Lane::Bands)?;
        self.flush_block(Lane::Windows)?;
        let mut summary = self.tally.summary();
        summary.blocks = self.events.written.blocks;
        summary.payload_bytes = self.events.written.payload_bytes;
        summary.stored_bytes = self.events.written.stored_bytes;
        summary.window_index = self.index.as_ref().map(|index| index.block.written);
        summary.bands = self.index.as_ref().map(|index| index.bands.written);
        summary.depth_tests = self.index.as_ref().map(|index| index.depth_test_blocks);
        summary.window_table = Some(self.window_table.written);
        let json = serde_json::to_vec(&summary).map_err(|e| self.invalid(e.to_string()))?;
        let end = summary_and_trailer(&json, self.offset);
        write_at(&mut self.out, &mut self.offset, &end)?;
        let offset = self.offset;
        self.out
            .flush()
            .map_err(|io| TraceError::Io { offset, io })?;
        Ok(summary)
    }
}

impl<W: Write + std::io::Seek> TraceWriter<W> {
    /// [`TraceWriter::finish`], then write the features used back into the file header, so
    /// that the header alone says how the trace was made and what it exercises.
    pub fn finish_seekable(mut self) -> Result<TraceSummary, TraceError> {
        let summary = self.finish_stream()?;
        let mut header = self.header.clone();
        header.features = Some(summary.features.clone());
        let io = |io| TraceError::Io { offset: 0, io };
        let mut json = serde_json::to_vec(&header).map_err(|e| TraceError::BadHeader {
            offset: 0,
            reason: e.to_string(),
        })?;
        if json.len() > self.header_json_bytes {
            return Err(TraceError::BadHeader {
                offset: 0,
                reason: format!(
                    "the finished header needs {} bytes, {} were kept",
                    json.len(),
                    self.header_json_bytes
                ),
            });
        }
        json.resize(self.header_json_bytes, b' ');
        let end = self.out.stream_position().map_err(io)?;
        self.out.seek(std::io::SeekFrom::Start(0)).map_err(io)?;
        self.out.write_all(&header_bytes(&json)).map_err(io)?;
        self.out.seek(std::io::SeekFrom::Start(end)).map_err(io)?;
        self.out.flush().map_err(io)?;
        Ok(summary)
    }
}

impl<W: Write> EventSink for TraceWriter<W> {
    type Error = TraceError;
    #[inline]
    fn event(&mut self, event: &Event) -> Result<(), TraceError> {
        self.write_event(event)
    }

    fn depth_plane(&mut self, plane: &PlaneDepths) -> Result<(), TraceError> {
        TraceWriter::depth_plane(self, plane)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::Fragment;
    use crate::trace::TraceReader;

    #[test]
    fn a_header_whose_features_lie_is_refused_at_the_end() {
        let header = TraceHeader::new(8, 8);
        let mut file = std::io::Cursor::new(Vec::new());
        let mut writer = TraceWriter::new(&mut file, &header).unwrap();
        writer
            .event(&Event::Fragment(Fragment { x: 1, y: 1, z: 5 }))
            .unwrap();
        writer.finish_seekable().unwrap();
        let mut bytes = file.into_inner();
        let honest = TraceReader::new(&bytes[..]).unwrap().header().clone();
        assert_eq!(
            honest.features.as_ref().and_then(|f| f.depth_writes),
            Some(true),
            "a fragment with the depth test and writes on"
        );
        // The same header saying no fragment can write depth, in the same room, checksummed.
        let mut lying = honest.clone();
        lying.features.as_mut().unwrap().depth_writes = Some(false);
        let json_bytes = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        let mut json = serde_json::to_vec(&lying).unwrap();
        json.resize(json_bytes, b' ');
        let patched = header_bytes(&json);
        bytes[..patched.len()].copy_from_slice(&patched);
        let mut reader = TraceReader::new(&bytes[..]).unwrap();
        assert_eq!(
            reader.header().features.as_ref().unwrap().depth_writes,
            Some(false)
        );
        let error = reader.read_into(&mut crate::golden::Discard).unwrap_err();
        assert!(
            error.to_string().contains("header's features disagree"),
            "{error}"
        );
    }
}
