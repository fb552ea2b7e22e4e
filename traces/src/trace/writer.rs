//! The streaming trace writer: events in, blocks out, one block buffer of memory.

use super::block::*;
use super::codec::{
    encode_large_event, encode_small_event, encode_span, put_uv, span_bytes_bound, tag,
    SpanPredictor, MAX_EVENT_BYTES, MAX_SPAN_FRAGMENTS,
};
use super::header::{StreamTally, TraceHeader, TraceSummary};
use super::TraceError;
use crate::event::Event;
use crate::golden::EventSink;
use std::io::Write;

/// How the writer cuts and compresses blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriterOptions {
    /// Most payload bytes per block before compression, 4096..=`MAX_BLOCK_BYTES`.
    pub block_bytes: usize,
    /// zstd compression level (1..=22); decoding speed hardly depends on it.
    pub zstd_level: i32,
}

impl Default for WriterOptions {
    fn default() -> WriterOptions {
        WriterOptions {
            block_bytes: MAX_BLOCK_BYTES,
            zstd_level: 3,
        }
    }
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
    /// The open block's payload.
    block: Vec<u8>,
    block_events: u32,
    predictor: SpanPredictor,
    /// The span being gathered: its start and its depths.
    span_x: u16,
    span_y: u16,
    span_depths: Vec<u32>,
    max_span: usize,
    /// Scratch space for a large event's record, and for compressed output.
    large: Vec<u8>,
    stored: Vec<u8>,
    tally: StreamTally,
    width: u32,
    height: u32,
    events_seen: u64,
    blocks: u64,
    payload_bytes: u64,
    stored_bytes: u64,
    failed: bool,
}

/// Room kept in the header JSON (as trailing spaces, which JSON ignores) for the features
/// used, written back by [`TraceWriter::finish_seekable`]: every query mode and depth function
/// and every flag set take under 300 bytes.
const FEATURES_RESERVE_BYTES: usize = 512;

/// The file header's bytes: magic, version, flags, JSON length, JSON, CRC of all but magic.
fn header_bytes(json: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(json.len() + 24);
    bytes.extend_from_slice(&MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&0u16.to_le_bytes());
    bytes.extend_from_slice(&(json.len() as u32).to_le_bytes());
    bytes.extend_from_slice(json);
    let crc = crc32fast::hash(&bytes[MAGIC.len()..]);
    bytes.extend_from_slice(&crc.to_le_bytes());
    bytes
}

fn write_at(out: &mut impl Write, offset: &mut u64, bytes: &[u8]) -> Result<(), TraceError> {
    out.write_all(bytes).map_err(|source| TraceError::Io {
        offset: *offset,
        source,
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
        if let Some(problem) = header.problem() {
            return Err(bad_header(problem));
        }
        if !(4096..=MAX_BLOCK_BYTES).contains(&options.block_bytes) {
            return Err(bad_header(format!(
                "block size {} outside 4096..={MAX_BLOCK_BYTES}",
                options.block_bytes
            )));
        }
        let mut json = serde_json::to_vec(header).map_err(|e| bad_header(e.to_string()))?;
        json.resize(json.len() + FEATURES_RESERVE_BYTES, b' ');
        if json.len() > MAX_HEADER_JSON_BYTES as usize {
            return Err(bad_header(format!(
                "header JSON of {} bytes exceeds {MAX_HEADER_JSON_BYTES}",
                json.len()
            )));
        }
        let bytes = header_bytes(&json);
        let mut offset = 0;
        write_at(&mut out, &mut offset, &bytes)?;
        let compressor = zstd::bulk::Compressor::new(options.zstd_level)
            .map_err(|e| bad_header(format!("zstd level {}: {e}", options.zstd_level)))?;
        Ok(TraceWriter {
            out,
            header: header.clone(),
            header_json_bytes: json.len(),
            offset,
            options,
            compressor,
            block: Vec::with_capacity(options.block_bytes),
            block_events: 0,
            predictor: SpanPredictor::default(),
            span_x: 0,
            span_y: 0,
            span_depths: Vec::new(),
            max_span: MAX_SPAN_FRAGMENTS.min((options.block_bytes - span_bytes_bound(1)) / 10),
            large: Vec::new(),
            stored: Vec::new(),
            tally: StreamTally::new(header),
            width: header.width,
            height: header.height,
            events_seen: 0,
            blocks: 0,
            payload_bytes: 0,
            stored_bytes: 0,
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
            return Ok(());
        }
        self.flush_span()?;
        self.tally
            .event(event)
            .map_err(|reason| self.invalid(reason))?;
        match event {
            Event::QueryBegin(_) | Event::QueryResult(_) => self.append_large(event),
            _ => {
                self.make_room(SMALL_EVENT_BYTES)?;
                encode_small_event(&mut self.block, event);
                self.block_events += 1;
                Ok(())
            }
        }
    }

    /// Close the open block if `bytes` more would not fit.
    fn make_room(&mut self, bytes: usize) -> Result<(), TraceError> {
        if self.block.len() + bytes > self.options.block_bytes {
            self.flush_block()?;
        }
        Ok(())
    }

    fn flush_span(&mut self) -> Result<(), TraceError> {
        if self.span_depths.is_empty() {
            return Ok(());
        }
        self.make_room(span_bytes_bound(self.span_depths.len()))?;
        encode_span(
            &mut self.block,
            &mut self.predictor,
            self.span_x,
            self.span_y,
            &self.span_depths,
        );
        self.block_events += self.span_depths.len() as u32;
        self.span_depths.clear();
        Ok(())
    }

    /// A query begin or result: inline if it fits a block, else in parts over several blocks.
    fn append_large(&mut self, event: &Event) -> Result<(), TraceError> {
        self.large.clear();
        encode_large_event(&mut self.large, event);
        let total = self.large.len();
        if total > MAX_EVENT_BYTES {
            return Err(self.invalid(format!("event of {total} bytes exceeds {MAX_EVENT_BYTES}")));
        }
        if total <= self.options.block_bytes {
            self.make_room(total)?;
            self.block.extend_from_slice(&self.large);
            self.block_events += 1;
            return Ok(());
        }
        let mut done = 0;
        while done < total {
            let room = self
                .options
                .block_bytes
                .saturating_sub(self.block.len() + PART_OVERHEAD);
            if room < 256 {
                self.flush_block()?;
                continue;
            }
            let chunk = room.min(total - done);
            let last = done + chunk == total;
            self.block
                .push(if last { tag::PART_END } else { tag::PART });
            put_uv(&mut self.block, chunk as u64);
            self.block
                .extend_from_slice(&self.large[done..done + chunk]);
            done += chunk;
        }
        self.block_events += 1;
        Ok(())
    }

    /// Compress and write the open block; the next block starts with fresh prediction state.
    fn flush_block(&mut self) -> Result<(), TraceError> {
        if self.block.is_empty() {
            return Ok(());
        }
        self.stored.clear();
        self.stored
            .reserve(zstd::zstd_safe::compress_bound(self.block.len()));
        let compressed = self
            .compressor
            .compress_to_buffer(&self.block, &mut self.stored);
        let zstd_wins = compressed.is_ok() && self.stored.len() < self.block.len();
        let (codec, stored) = if zstd_wins {
            (CODEC_ZSTD, &self.stored)
        } else {
            (CODEC_STORED, &self.block)
        };
        let header = BlockHeader {
            kind: KIND_EVENTS,
            codec,
            events: self.block_events,
            raw_len: self.block.len() as u32,
            stored_len: stored.len() as u32,
        };
        let crc = header.checksum(stored);
        write_at(&mut self.out, &mut self.offset, &header.fields())?;
        write_at(&mut self.out, &mut self.offset, &crc.to_le_bytes())?;
        write_at(&mut self.out, &mut self.offset, stored)?;
        self.blocks += 1;
        self.payload_bytes += self.block.len() as u64;
        self.stored_bytes += stored.len() as u64;
        self.block.clear();
        self.block_events = 0;
        self.predictor = SpanPredictor::default();
        Ok(())
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
        self.flush_block()?;
        let mut summary = self.tally.summary();
        summary.blocks = self.blocks;
        summary.payload_bytes = self.payload_bytes;
        summary.stored_bytes = self.stored_bytes;
        let json = serde_json::to_vec(&summary).map_err(|e| self.invalid(e.to_string()))?;
        let header = BlockHeader {
            kind: KIND_SUMMARY,
            codec: CODEC_STORED,
            events: 0,
            raw_len: json.len() as u32,
            stored_len: json.len() as u32,
        };
        let summary_offset = self.offset;
        let crc = header.checksum(&json);
        write_at(&mut self.out, &mut self.offset, &header.fields())?;
        write_at(&mut self.out, &mut self.offset, &crc.to_le_bytes())?;
        write_at(&mut self.out, &mut self.offset, &json)?;
        write_at(
            &mut self.out,
            &mut self.offset,
            &summary_offset.to_le_bytes(),
        )?;
        write_at(&mut self.out, &mut self.offset, &END_MAGIC)?;
        let offset = self.offset;
        self.out
            .flush()
            .map_err(|source| TraceError::Io { offset, source })?;
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
        let io = |source| TraceError::Io { offset: 0, source };
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
