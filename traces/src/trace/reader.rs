//! The streaming trace reader: blocks in, events out, one block of memory.

use super::block::*;
use super::codec::{BlockDecoder, DecodeContext, DrainError, PayloadError};
use super::header::{BlockCounts, StreamTally, TraceHeader, TraceSummary};
use super::index::IndexItem;
use super::windows::{decode_window_sizes, WindowSize};
use super::{ReadError, TraceError};
use crate::event::Event;
use crate::golden::EventSink;
use std::collections::VecDeque;
use std::io::{Read, Seek, SeekFrom};

/// Reads a trace from `R`, checking every block's checksum and every event's sense.
pub struct TraceReader<R: Read> {
    input: R,
    /// Bytes consumed so far: the file offset of the next byte.
    offset: u64,
    header: TraceHeader,
    decompressor: zstd::bulk::Decompressor<'static>,
    /// The current block's payload as stored, and decompressed.
    stored: Vec<u8>,
    payload: Vec<u8>,
    decoder: BlockDecoder,
    /// The current block's file offset and its claimed event count.
    block_offset: u64,
    block_events: u32,
    in_block: bool,
    tally: StreamTally,
    /// The bytes gathered so far of an event split over blocks.
    assembly: Vec<u8>,
    blocks: u64,
    payload_bytes: u64,
    stored_bytes: u64,
    /// The sum of the event counts the block headers claim.
    claimed_events: u64,
    /// Some blocks were skipped, not decoded: the event tally is incomplete.
    skipped: bool,
    /// The window-index blocks passed so far.
    index: BlockCounts,
    /// The depth-test blocks passed so far.
    depth_tests: BlockCounts,
    /// The window table's blocks passed so far.
    window_table: BlockCounts,
    /// The band index's blocks passed so far.
    bands: BlockCounts,
    /// The block loaded is a window-index or band-index block (read by
    /// [`TraceReader::next_index_item`] or [`TraceReader::for_each_band_item`]).
    in_index_block: bool,
    /// What the reader has read by: its events, its window index or its band index (the
    /// first asked for), and whether it was asked for another since.
    read_by: Option<Wanted>,
    read_by_several: bool,
    /// Index blocks decoded to their end, of the lane read by: all of them, and the tally
    /// has every event but the fragments, and the fragments as the index counts them.
    index_blocks_read: u64,
    summary: Option<TraceSummary>,
    failed: bool,
    /// The file's format version.
    version: u16,
    /// The index lanes' queries are read skimmed ([`TraceReader::skim_queries`]).
    skim_queries: bool,
}

/// Which blocks [`TraceReader::load_block`] decodes.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Wanted {
    Events,
    Index,
    Bands,
    Windows,
    Nothing,
}

impl<R: Read> TraceReader<R> {
    /// Read and check the file header.
    pub fn new(input: R) -> Result<TraceReader<R>, TraceError> {
        let mut reader = TraceReader {
            input,
            offset: 0,
            header: TraceHeader::new(1, 1),
            decompressor: zstd::bulk::Decompressor::new().map_err(|e| TraceError::Decompress {
                offset: 0,
                reason: e.to_string(),
            })?,
            stored: Vec::new(),
            payload: Vec::new(),
            decoder: BlockDecoder::new(),
            block_offset: 0,
            block_events: 0,
            in_block: false,
            tally: StreamTally::new(&TraceHeader::new(1, 1)),
            assembly: Vec::new(),
            blocks: 0,
            payload_bytes: 0,
            stored_bytes: 0,
            claimed_events: 0,
            skipped: false,
            index: BlockCounts::default(),
            depth_tests: BlockCounts::default(),
            window_table: BlockCounts::default(),
            bands: BlockCounts::default(),
            in_index_block: false,
            read_by: None,
            read_by_several: false,
            index_blocks_read: 0,
            summary: None,
            failed: false,
            version: FORMAT_VERSION,
            skim_queries: false,
        };
        reader.header = reader.read_file_header()?;
        reader.tally = StreamTally::new(&reader.header);
        Ok(reader)
    }

    pub fn header(&self) -> &TraceHeader {
        &self.header
    }

    /// The file's format version ([`FORMAT_VERSION`] or an older one it still reads).
    pub fn format_version(&self) -> u16 {
        self.version
    }

    /// Whether the trace can hold the closed loop's records (draws, host work, waits,
    /// frames): version-1 traces cannot, so they replay as an open loop.
    pub fn has_closed_loop(&self) -> bool {
        self.version >= 2
    }

    /// The summary, once the end of the trace has been reached (and checked).
    pub fn summary(&self) -> Option<&TraceSummary> {
        self.summary.as_ref()
    }

    /// Fill `buf` from the input, or say where the file ended. The bytes are read into the
    /// buffer's spare room, not written first (`resize` had zeroed every block before
    /// reading it: 3% of a `sampled:100` run of the demo, which skips most of its blocks).
    fn fill(
        &mut self,
        buf_len: usize,
        into_stored: bool,
        inside: &'static str,
    ) -> Result<(), TraceError> {
        let buf = if into_stored {
            &mut self.stored
        } else {
            &mut self.payload
        };
        buf.clear();
        buf.reserve_exact(buf_len);
        // `read_to_end` retries an interrupted read and stops at `buf_len` bytes.
        match (&mut self.input).take(buf_len as u64).read_to_end(buf) {
            Ok(got) if got < buf_len => Err(TraceError::Truncated {
                offset: self.offset + got as u64,
                inside,
            }),
            Ok(_) => {
                self.offset += buf_len as u64;
                Ok(())
            }
            Err(io) => Err(TraceError::Io {
                offset: self.offset + buf.len() as u64,
                io,
            }),
        }
    }

    fn read_array<const N: usize>(&mut self, inside: &'static str) -> Result<[u8; N], TraceError> {
        self.fill(N, true, inside)?;
        let mut bytes = [0u8; N];
        bytes.copy_from_slice(&self.stored);
        Ok(bytes)
    }

    fn read_file_header(&mut self) -> Result<TraceHeader, TraceError> {
        let magic: [u8; 8] = self.read_array("the magic number")?;
        if magic != MAGIC {
            return Err(TraceError::BadMagic);
        }
        let fixed: [u8; 8] = self.read_array("the file header")?;
        let version = u16::from_le_bytes([fixed[0], fixed[1]]);
        self.version = version;
        if !(OLDEST_READABLE_VERSION..=FORMAT_VERSION).contains(&version) {
            return Err(TraceError::UnsupportedVersion {
                offset: 8,
                version,
                known: FORMAT_VERSION,
            });
        }
        if fixed[2] != 0 || fixed[3] != 0 {
            let reason = "flags are not zero".to_owned();
            return Err(TraceError::BadHeader { offset: 10, reason });
        }
        let json_len = u32::from_le_bytes([fixed[4], fixed[5], fixed[6], fixed[7]]);
        if json_len > MAX_HEADER_JSON_BYTES {
            let reason = format!("header JSON of {json_len} bytes exceeds {MAX_HEADER_JSON_BYTES}");
            return Err(TraceError::BadHeader { offset: 12, reason });
        }
        self.fill(json_len as usize, false, "the header JSON")?;
        let stored_crc = u32::from_le_bytes(self.read_array("the header checksum")?);
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(&fixed);
        hasher.update(&self.payload);
        let computed = hasher.finalize();
        if computed != stored_crc {
            return Err(TraceError::ChecksumMismatch {
                offset: 8,
                stored: stored_crc,
                computed,
            });
        }
        let json_offset = FILE_HEADER_FIXED_BYTES;
        let header: TraceHeader =
            serde_json::from_slice(&self.payload).map_err(|e| TraceError::BadHeader {
                offset: json_offset,
                reason: e.to_string(),
            })?;
        if let Some(reason) = header.problem() {
            return Err(TraceError::BadHeader {
                offset: json_offset,
                reason,
            });
        }
        Ok(header)
    }

    /// Read the next block header and stored payload, checking the checksum. Returns the
    /// header, the payload being in `self.stored`.
    fn read_block(&mut self) -> Result<BlockHeader, TraceError> {
        self.block_offset = self.offset;
        let bytes: [u8; BLOCK_HEADER_BYTES] = self.read_array("a block header")?;
        let offset = self.block_offset;
        let (header, stored_crc) =
            BlockHeader::parse(&bytes).map_err(|reason| TraceError::BadBlock { offset, reason })?;
        self.fill(header.stored_len as usize, true, "a block")?;
        let computed = header.checksum(&self.stored);
        if computed != stored_crc {
            return Err(TraceError::ChecksumMismatch {
                offset,
                stored: stored_crc,
                computed,
            });
        }
        Ok(header)
    }

    /// Load the next block of the kind `wanted` for decoding, passing the others (their
    /// checksums checked); with `Wanted::Nothing`, pass one block. Returns false at the
    /// summary (the end).
    fn load_block(&mut self, wanted: Wanted) -> Result<bool, TraceError> {
        if matches!(wanted, Wanted::Events | Wanted::Index | Wanted::Bands) {
            // Noted before the first block, so that a lane with no block at all is known
            // as read (whole) when the summary comes.
            self.read_by_several |= self.read_by.is_some_and(|read_by| read_by != wanted);
            self.read_by.get_or_insert(wanted);
        }
        let header = loop {
            let header = self.read_block()?;
            match header.kind {
                KIND_SUMMARY => {
                    self.finish_at_summary()?;
                    return Ok(false);
                }
                KIND_INDEX => {
                    self.index.add(&header);
                    if wanted == Wanted::Index {
                        break header;
                    }
                }
                KIND_DEPTH_TESTS => self.depth_tests.add(&header),
                KIND_BANDS if self.version < BANDS_VERSION => {
                    return Err(TraceError::BadBlock {
                        offset: self.block_offset,
                        reason: format!(
                            "a band-index block in a version-{} trace (they came in {BANDS_VERSION})",
                            self.version
                        ),
                    })
                }
                KIND_BANDS => {
                    self.bands.add(&header);
                    if wanted == Wanted::Bands {
                        break header;
                    }
                }
                KIND_WINDOWS if self.version < WINDOW_TABLE_VERSION => {
                    return Err(TraceError::BadBlock {
                        offset: self.block_offset,
                        reason: format!(
                            "a window-table block in a version-{} trace (they came in {WINDOW_TABLE_VERSION})",
                            self.version
                        ),
                    })
                }
                KIND_WINDOWS => {
                    self.window_table.add(&header);
                    if wanted == Wanted::Windows {
                        break header;
                    }
                }
                _ => {
                    self.blocks += 1;
                    self.payload_bytes += header.raw_len as u64;
                    self.stored_bytes += header.stored_len as u64;
                    self.claimed_events += header.events as u64;
                    if wanted == Wanted::Events {
                        break header;
                    }
                    self.skipped = true;
                }
            }
            if wanted == Wanted::Nothing {
                return Ok(true);
            }
        };
        self.block_events = header.events;
        self.in_index_block = header.kind == KIND_INDEX || header.kind == KIND_BANDS;
        if header.codec == CODEC_ZSTD {
            let stored = std::mem::take(&mut self.stored);
            let mut payload = std::mem::take(&mut self.payload);
            let result = self.decompress(&header, self.block_offset, &stored, &mut payload);
            (self.stored, self.payload) = (stored, payload);
            result?;
        } else {
            std::mem::swap(&mut self.stored, &mut self.payload);
        }
        self.decoder = BlockDecoder::new();
        self.decoder.in_bands = header.kind == KIND_BANDS;
        self.in_block = true;
        Ok(true)
    }

    /// `stored`, the payload of the block `header` at `offset` as stored, decompressed (or
    /// copied) into `out`.
    pub(crate) fn decompress(
        &mut self,
        header: &BlockHeader,
        offset: u64,
        stored: &[u8],
        out: &mut Vec<u8>,
    ) -> Result<(), TraceError> {
        out.clear();
        if header.codec != CODEC_ZSTD {
            out.extend_from_slice(stored);
            return Ok(());
        }
        out.reserve(header.raw_len as usize);
        match self.decompressor.decompress_to_buffer(stored, out) {
            Ok(n) if n == header.raw_len as usize => Ok(()),
            Ok(n) => {
                let reason = format!("decompressed to {n} bytes, header says {}", header.raw_len);
                Err(TraceError::Decompress { offset, reason })
            }
            Err(e) => {
                let reason = e.to_string();
                Err(TraceError::Decompress { offset, reason })
            }
        }
    }

    /// The payload of the block just read by [`Self::next_raw_block`], decompressed.
    pub(crate) fn decompress_stored(
        &mut self,
        header: &BlockHeader,
        offset: u64,
        out: &mut Vec<u8>,
    ) -> Result<(), TraceError> {
        let stored = std::mem::take(&mut self.stored);
        let result = self.decompress(header, offset, &stored, out);
        self.stored = stored;
        result
    }

    /// Whether the window index's stretches carry their first reads right after a query
    /// end ([`crate::trace::FragmentStretch::first_reads`], format version 6), their
    /// densest runs of reads ([`crate::trace::FragmentStretch::dense`], version 7) and the
    /// runs that end at their last fragment ([`crate::trace::FragmentStretch::ending`],
    /// version 9): a model that reads them
    /// decodes an older index's fragments instead.
    pub fn index_has_every_count(&self) -> bool {
        self.version >= INDEX_COUNTS_VERSION && self.header.window_index.is_some()
    }

    /// Whether the trace holds a window table ([`crate::trace::windows`]): every trace of
    /// version 8 on whose header does not say otherwise.
    pub fn has_window_table(&self) -> bool {
        self.version >= WINDOW_TABLE_VERSION && self.header.window_table
    }

    /// The sizes of the next block of the window table ([`crate::trace::windows`]), added to
    /// `into` in the stream's order; false once the table has no block left (at the trace's
    /// end). Only the window table's blocks are decompressed (the others' checksums are
    /// checked). A trace before version 8 has no table: false at once.
    pub fn next_window_sizes(
        &mut self,
        into: &mut VecDeque<WindowSize>,
    ) -> Result<bool, TraceError> {
        if self.in_block && !self.at_end() {
            self.failed = true;
            return Err(self.mixed_reading());
        }
        if !self.has_window_table()
            || self.at_end()
            || !self.guarded(|reader| reader.load_block(Wanted::Windows))?
        {
            return Ok(false);
        }
        self.in_block = false;
        if let Err(error) = decode_window_sizes(&self.payload, self.block_events, into) {
            self.failed = true;
            return Err(self.corrupt(error));
        }
        Ok(true)
    }

    /// Whether every event block has a depth-test block after it
    /// ([`crate::trace::depth_tests`]).
    pub fn has_depth_tests(&self) -> bool {
        self.version >= 5 && self.header.window_index.is_some()
    }

    /// The next block but the summary, read and its checksum checked (its payload, as
    /// stored, in `self.stored`), for a reader of blocks of its own
    /// ([`crate::trace::depth_tests::TestedFragments`]); None at the summary, which is
    /// left unread. The reader's own decoding is over: it checks no summary after this.
    pub(crate) fn next_raw_block(&mut self) -> Result<Option<BlockHeader>, TraceError> {
        self.guarded(|reader| {
            reader.skipped = true;
            let header = reader.read_block()?;
            Ok((header.kind != KIND_SUMMARY).then_some(header))
        })
    }

    /// Swap the stored payload of the block just read into `into`.
    pub(crate) fn keep_stored(&mut self, into: &mut Vec<u8>) {
        std::mem::swap(&mut self.stored, into);
    }

    /// The file offset of the block read last.
    pub(crate) fn block_offset(&self) -> u64 {
        self.block_offset
    }

    fn corrupt(&self, error: PayloadError) -> TraceError {
        TraceError::Corrupt {
            offset: self.block_offset,
            payload_offset: error.pos,
            reason: error.reason,
        }
    }

    /// The current block is fully decoded: check its event count.
    fn end_block(&mut self) -> Result<(), TraceError> {
        self.in_block = false;
        self.index_blocks_read += self.in_index_block as u64;
        if self.decoder.events != self.block_events as u64 {
            return Err(TraceError::Corrupt {
                offset: self.block_offset,
                payload_offset: self.payload.len(),
                reason: format!(
                    "block header claims {} events, the block holds {}",
                    self.block_events, self.decoder.events
                ),
            });
        }
        Ok(())
    }

    /// The summary block is in `self.stored`: parse it, read the trailer, check both.
    fn finish_at_summary(&mut self) -> Result<(), TraceError> {
        let offset = self.block_offset;
        let bad = |reason: String| TraceError::BadSummary { offset, reason };
        let stored = parse_summary(&self.stored, offset)?;
        let trailer: [u8; TRAILER_BYTES] = self.read_array("the trailer")?;
        let pointer = u64::from_le_bytes(trailer[..8].try_into().unwrap_or_default());
        if trailer[8..] != END_MAGIC || pointer != offset {
            return Err(bad("the trailer does not point at the summary".to_owned()));
        }
        let mut extra = [0u8; 1];
        let trailing = loop {
            match self.input.read(&mut extra) {
                Ok(n) => break n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(io) => {
                    return Err(TraceError::Io {
                        offset: self.offset,
                        io,
                    })
                }
            }
        };
        if trailing != 0 {
            return Err(TraceError::TrailingData {
                offset: self.offset,
            });
        }
        let mut found = if self.skipped && self.read_whole_index() {
            if !self.assembly.is_empty() {
                return Err(bad("the trace ends inside a multi-block event".to_owned()));
            }
            // Every count but the events' number, which the block headers claim.
            let mut by_index = self.tally.summary();
            by_index.events = self.claimed_events;
            by_index
        } else if self.skipped {
            let mut partial = stored.clone();
            partial.events = self.claimed_events;
            partial
        } else {
            if !self.assembly.is_empty() {
                return Err(bad("the trace ends inside a multi-block event".to_owned()));
            }
            self.tally.summary()
        };
        // Traces written before these features were recorded do not have them.
        if stored.features.max_query_tiles.is_none() {
            found.features.max_query_tiles = None;
        }
        if stored.features.depth_writes.is_none() {
            found.features.depth_writes = None;
        }
        found.blocks = self.blocks;
        found.payload_bytes = self.payload_bytes;
        found.stored_bytes = self.stored_bytes;
        found.window_index = self.header.window_index.map(|_| self.index);
        found.depth_tests = self.has_depth_tests().then_some(self.depth_tests);
        found.window_table = self.has_window_table().then_some(self.window_table);
        found.bands = self.has_band_index().then_some(self.bands);
        if found != stored || self.claimed_events != stored.events {
            return Err(bad(format!(
                "it disagrees with the trace on {}",
                differing_fields(&stored, &found)
            )));
        }
        if let Some(reason) = features_disagree(&self.header, &stored) {
            return Err(bad(reason));
        }
        self.summary = Some(stored);
        Ok(())
    }

    /// Whether the trace was read by its window index or its band index, every block of it
    /// to its end: then the tally has counted every event the summary counts.
    fn read_whole_index(&self) -> bool {
        // (A trace without the lane has no items: whoever asked reads it otherwise.)
        let passed = match self.read_by {
            Some(Wanted::Index) if self.header.window_index.is_some() => self.index.blocks,
            Some(Wanted::Bands) if self.has_band_index() => self.bands.blocks,
            _ => return false,
        };
        // A lane with no block at all is read whole too: its tally, empty, must then agree
        // with a summary of nothing (an index cut out of a trace whose summary still
        // counts its queries had replayed as zero cycles and zero queries).
        !self.read_by_several && self.index_blocks_read == passed
    }

    /// Run `step`, and stop the reader for good if it fails.
    fn guarded<T>(
        &mut self,
        step: impl FnOnce(&mut Self) -> Result<T, TraceError>,
    ) -> Result<T, TraceError> {
        let result = step(self);
        self.failed |= result.is_err();
        result
    }

    fn at_end(&self) -> bool {
        self.failed || self.summary.is_some()
    }

    /// The next event; None at the end of the trace (or after an error).
    pub fn next_event(&mut self) -> Result<Option<Event>, TraceError> {
        if self.at_end() {
            return Ok(None);
        }
        if self.in_block && self.in_index_block {
            self.failed = true;
            return Err(self.mixed_reading());
        }
        if self.in_block {
            match self.decoder.next_fragment_in_span(&self.payload) {
                Some(Ok(fragment)) => return Ok(Some(Event::Fragment(fragment))),
                Some(Err(e)) => {
                    self.failed = true;
                    return Err(self.corrupt(e));
                }
                None => {}
            }
        }
        self.next_record(Wanted::Events, BlockDecoder::next_event)
    }

    /// The next record `decode` finds in blocks of the kind `wanted`, loading them as the
    /// current one is used up; None at the end of the trace.
    fn next_record<T>(
        &mut self,
        wanted: Wanted,
        decode: impl Fn(&mut BlockDecoder, &[u8], &mut DecodeContext) -> Result<Option<T>, PayloadError>,
    ) -> Result<Option<T>, TraceError> {
        self.guarded(|reader| loop {
            if !reader.in_block {
                if !reader.load_block(wanted)? {
                    return Ok(None);
                }
                continue;
            }
            let skim = reader.skim_queries && wanted != Wanted::Events;
            let mut ctx = checked_context(
                &reader.header,
                &mut reader.tally,
                &mut reader.assembly,
                skim,
            );
            match decode(&mut reader.decoder, &reader.payload, &mut ctx) {
                Ok(Some(record)) => return Ok(Some(record)),
                Ok(None) => reader.end_block()?,
                Err(e) => return Err(reader.corrupt(e)),
            }
        })
    }

    /// The fast path: hand the rest of the current block (or all of the next one) to `sink`.
    /// Returns false at the end of the trace. A sink's error stops the reader, as a trace
    /// error does.
    pub fn next_block<S: EventSink>(&mut self, sink: &mut S) -> Result<bool, ReadError<S::Error>> {
        if self.at_end() {
            return Ok(false);
        }
        if self.in_block && self.in_index_block {
            self.failed = true;
            return Err(ReadError::Trace(self.mixed_reading()));
        }
        let mut sink_error = None;
        let result = self.guarded(|reader| {
            if !reader.in_block && !reader.load_block(Wanted::Events)? {
                return Ok(false);
            }
            let mut ctx = checked_context(
                &reader.header,
                &mut reader.tally,
                &mut reader.assembly,
                false,
            );
            match reader.decoder.drain(&reader.payload, &mut ctx, sink) {
                Ok(()) => {}
                Err(DrainError::Payload(e)) => return Err(reader.corrupt(e)),
                Err(DrainError::Sink(e)) => {
                    sink_error = Some(e);
                    return Ok(false);
                }
            }
            debug_assert!(reader.decoder.is_done(&reader.payload));
            reader.end_block()?;
            Ok(true)
        });
        if let Some(error) = sink_error {
            self.failed = true;
            return Err(ReadError::Sink(error));
        }
        result.map_err(ReadError::Trace)
    }

    /// The next item of the window index, or None at the end of the trace: the trace's
    /// events other than fragments, and in place of its fragments their
    /// [`crate::trace::FragmentStretch`]es, read from the index blocks alone (the event
    /// blocks' checksums are checked, their payloads not decompressed). A trace whose header
    /// names no `window_index` has no items. Read a trace either this way or by events.
    pub fn next_index_item(&mut self) -> Result<Option<IndexItem>, TraceError> {
        if self.at_end() {
            return Ok(None);
        }
        if self.in_block && !self.reading(Wanted::Index) {
            self.failed = true;
            return Err(self.mixed_reading());
        }
        self.next_record(Wanted::Index, BlockDecoder::next_index_item)
    }

    /// Read the index lanes' queries skimmed from here on: each begin as its shape and each
    /// result as its totals ([`IndexItem::Shape`], [`IndexItem::Totals`]), their tiles
    /// passed over unread (a version-11 record says where its tiles end; an older one is
    /// read whole and summed). For a reader that asks nothing of a query's tiles, as the
    /// O2's analytic level: on the lazy-grid walk (156 queries, 12,912 tiles) reading them
    /// had been a tenth of its run. Events are read whole as ever.
    pub fn skim_queries(&mut self) {
        self.skim_queries = true;
    }

    /// Hand every remaining item of the window index to `visit`, block by block: what
    /// [`Self::next_index_item`] gives one call at a time, each item visited inside the
    /// block's decoder instead of crossing the reader's per-call checks and two layers of
    /// results on its way out (the analytic level reads nothing else: on the lazy-grid
    /// walk's 81,000 items its run went from 7.7 to 5.7 ms, with the formulas' reserved
    /// share worked out once). A visitor's error stops the reader, as a trace error does.
    pub fn for_each_index_item<E>(
        &mut self,
        mut visit: impl FnMut(&IndexItem) -> Result<(), E>,
    ) -> Result<(), ReadError<E>> {
        while self.visit_lane_block(Wanted::Index, &mut visit)? {}
        Ok(())
    }

    /// Hand every remaining item of the band index to `visit`, as
    /// [`Self::for_each_index_item`] does the window index's: the events other than
    /// fragments, and in place of the fragments their [`crate::trace::FragmentBand`]s. A
    /// trace without a band index ([`Self::has_band_index`]) has no items. Read a trace
    /// either this way, by its window index, or by events.
    pub fn for_each_band_item<E>(
        &mut self,
        mut visit: impl FnMut(&IndexItem) -> Result<(), E>,
    ) -> Result<(), ReadError<E>> {
        while self.visit_lane_block(Wanted::Bands, &mut visit)? {}
        Ok(())
    }

    /// Whether the trace holds a band index ([`crate::trace::bands`]): a window index in a
    /// version-10 trace or later.
    pub fn has_band_index(&self) -> bool {
        self.version >= BANDS_VERSION && self.header.window_index.is_some()
    }

    /// Hand the remaining items of the window index's current block (or of its next, when
    /// none is being read) to `visit`, as [`Self::for_each_index_item`] does; false once
    /// the index has no items left. For a reader that reads ahead of another (the sampled
    /// level's scout): what it gathers stays within one block's items.
    pub fn visit_index_block<E>(
        &mut self,
        visit: impl FnMut(&IndexItem) -> Result<(), E>,
    ) -> Result<bool, ReadError<E>> {
        self.visit_lane_block(Wanted::Index, visit)
    }

    /// [`Self::visit_index_block`] over the blocks of the index `wanted` names.
    fn visit_lane_block<E>(
        &mut self,
        wanted: Wanted,
        mut visit: impl FnMut(&IndexItem) -> Result<(), E>,
    ) -> Result<bool, ReadError<E>> {
        if self.in_block && !self.reading(wanted) && !self.at_end() {
            self.failed = true;
            return Err(ReadError::Trace(self.mixed_reading()));
        }
        if self.at_end() || !self.in_block && !self.guarded(|reader| reader.load_block(wanted))? {
            return Ok(false);
        }
        let mut ctx = checked_context(
            &self.header,
            &mut self.tally,
            &mut self.assembly,
            self.skim_queries,
        );
        match self
            .decoder
            .visit_index_items(&self.payload, &mut ctx, &mut visit)
        {
            Ok(()) => self.guarded(|reader| reader.end_block())?,
            Err(DrainError::Payload(e)) => {
                self.failed = true;
                return Err(ReadError::Trace(self.corrupt(e)));
            }
            Err(DrainError::Sink(e)) => {
                self.failed = true;
                return Err(ReadError::Sink(e));
            }
        }
        Ok(true)
    }

    /// Whether the block loaded is one of the index `wanted` names (the window index's or
    /// the band index's).
    fn reading(&self, wanted: Wanted) -> bool {
        self.in_index_block && self.decoder.in_bands == (wanted == Wanted::Bands)
    }

    fn mixed_reading(&self) -> TraceError {
        TraceError::BadBlock {
            offset: self.block_offset,
            reason:
                "a trace is read by events, by its window index or by its band index, one of them"
                    .to_owned(),
        }
    }

    /// Hand every remaining event to `sink`; returns the (checked) summary.
    pub fn read_into<S: EventSink>(
        &mut self,
        sink: &mut S,
    ) -> Result<TraceSummary, ReadError<S::Error>> {
        while self.next_block(sink)? {}
        self.finished_summary().map_err(ReadError::Trace)
    }

    /// Skip to the end without decoding the remaining blocks (their checksums are still
    /// checked); returns the summary, checked against the block headers.
    pub fn skip_to_summary(&mut self) -> Result<TraceSummary, TraceError> {
        if !self.at_end() {
            self.guarded(|reader| {
                if reader.in_block {
                    reader.in_block = false;
                    reader.skipped = true;
                }
                while reader.load_block(Wanted::Nothing)? {}
                Ok(())
            })?;
        }
        self.finished_summary()
    }

    fn finished_summary(&self) -> Result<TraceSummary, TraceError> {
        self.summary.clone().ok_or_else(|| TraceError::BadSummary {
            offset: self.offset,
            reason: "the reader stopped at an earlier error".to_owned(),
        })
    }
}

/// The decoding context of a reader that checks every event: the viewport of `header`, the
/// stream checks in `tally`, a large event's parts in `assembly`. (A field each, so that the
/// reader's decoder and payload stay free to borrow beside it.)
fn checked_context<'a>(
    header: &TraceHeader,
    tally: &'a mut StreamTally,
    assembly: &'a mut Vec<u8>,
    skim_queries: bool,
) -> DecodeContext<'a> {
    DecodeContext {
        width: header.width,
        height: header.height,
        tally,
        assembly,
        unchecked_events: false,
        skim_queries,
    }
}

/// Why the header's copy of the features is not the summary's (a replay may have trusted
/// it, say to choose its effect models), or none: a header without them agrees.
fn features_disagree(header: &TraceHeader, summary: &TraceSummary) -> Option<String> {
    header
        .features
        .as_ref()
        .is_some_and(|features| *features != summary.features)
        .then(|| "the header's features disagree with the trace's summary".to_owned())
}

impl<R: Read + Seek> TraceReader<R> {
    /// Read the header and the summary only, seeking to the summary through the trailer.
    pub fn read_summary(input: R) -> Result<(TraceHeader, TraceSummary), TraceError> {
        TraceReader::new(input)?.into_summary()
    }

    /// [`Self::read_summary`] from a reader just opened (its header read), for a caller
    /// that asks it something first, such as [`Self::format_version`].
    pub fn into_summary(self) -> Result<(TraceHeader, TraceSummary), TraceError> {
        let mut reader = self;
        let header_end = reader.offset;
        let io = |offset: u64| move |io| TraceError::Io { offset, io };
        let end = reader
            .input
            .seek(SeekFrom::End(0))
            .map_err(io(header_end))?;
        let minimum = header_end + (BLOCK_HEADER_BYTES + TRAILER_BYTES) as u64;
        if end < minimum {
            return Err(TraceError::Truncated {
                offset: end,
                inside: "the trailer",
            });
        }
        let trailer_at = end - TRAILER_BYTES as u64;
        reader
            .input
            .seek(SeekFrom::Start(trailer_at))
            .map_err(io(trailer_at))?;
        reader.offset = trailer_at;
        let trailer: [u8; TRAILER_BYTES] = reader.read_array("the trailer")?;
        let summary_at = u64::from_le_bytes(trailer[..8].try_into().unwrap_or_default());
        if trailer[8..] != END_MAGIC {
            // Read from its start, such a file ends inside a block or its trailer: what
            // is known here is only that its last bytes are no trailer.
            return Err(TraceError::BadSummary {
                offset: end,
                reason: "the file does not end in a trailer (cut short, or never finished)"
                    .to_owned(),
            });
        }
        if summary_at < header_end || summary_at > trailer_at - BLOCK_HEADER_BYTES as u64 {
            let reason = "the trailer does not point at a summary".to_owned();
            return Err(TraceError::BadSummary {
                offset: trailer_at,
                reason,
            });
        }
        reader
            .input
            .seek(SeekFrom::Start(summary_at))
            .map_err(io(summary_at))?;
        reader.offset = summary_at;
        let block = reader.read_block()?;
        if block.kind != KIND_SUMMARY {
            let reason = "the trailer points at an event block".to_owned();
            return Err(TraceError::BadSummary {
                offset: summary_at,
                reason,
            });
        }
        let summary = parse_summary(&reader.stored, summary_at)?;
        if let Some(reason) = features_disagree(&reader.header, &summary) {
            return Err(TraceError::BadSummary {
                offset: summary_at,
                reason,
            });
        }
        Ok((reader.header, summary))
    }
}

impl<R: Read> Iterator for TraceReader<R> {
    type Item = Result<Event, TraceError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_event().transpose()
    }
}

/// The summary block's JSON at file offset `offset`, its counts checked against each other.
fn parse_summary(json: &[u8], offset: u64) -> Result<TraceSummary, TraceError> {
    let bad = |reason: String| TraceError::BadSummary { offset, reason };
    let summary: TraceSummary = serde_json::from_slice(json).map_err(|e| bad(e.to_string()))?;
    match summary.problem() {
        Some(problem) => Err(bad(problem)),
        None => Ok(summary),
    }
}

/// The top-level fields on which two summaries differ, for error messages.
fn differing_fields(a: &TraceSummary, b: &TraceSummary) -> String {
    let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) =
        (serde_json::to_value(a), serde_json::to_value(b))
    else {
        return "its contents".to_owned();
    };
    let fields: Vec<String> = a
        .iter()
        .filter(|(key, value)| b.get(*key) != Some(value))
        .map(|(key, value)| {
            format!(
                "{key} (summary {value}, trace {})",
                b.get(key).cloned().unwrap_or_default()
            )
        })
        .collect();
    if fields.is_empty() {
        "the event count".to_owned()
    } else {
        fields.join(", ")
    }
}
