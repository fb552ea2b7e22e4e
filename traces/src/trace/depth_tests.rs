//! Depth-test blocks: whether each fragment of an indexed trace passed its depth test, one
//! bit a fragment, in a block right after the event block that holds the fragments.
//!
//! A model that starts a machine in the middle of a trace (the sampled level's warm-up)
//! needs the depth buffer there, which only the fragments before it can give. With the
//! results of the depth tests of the fragments it does simulate, it can instead choose, for
//! each pixel the first time it is tested, a depth that gives the recorded result
//! (`occsim-sim`'s consistent depths): no fragment before the warm-up is decoded, and the
//! event blocks wholly before it are not even decompressed ([`TestedFragments`]).
//!
//! Payload: the results in the event block's fragment order, bit `i % 8` of byte `i / 8`
//! for fragment `i` (1: passed; a fragment with the depth test off passes), padded with
//! zeros to a whole byte. The block header's `events` is the event block's fragment count.
//! Writers add these blocks to every trace with a window index (format version 5 on). An
//! event block's payload is at most 1 MiB and every fragment takes at least a byte of it (a
//! span's first its header, each further one a residual), so a depth-test block holds at
//! most 128 KiB, well within a block's limit.

use super::block::{
    BlockHeader, KIND_BANDS, KIND_DEPTH_TESTS, KIND_EVENTS, KIND_INDEX, KIND_WINDOWS,
};
use super::codec::{BlockDecoder, DecodeContext, DrainError};
use super::header::StreamTally;
use super::reader::TraceReader;
use super::{ReadError, TraceError};
use crate::event::{Event, Span};
use crate::golden::EventSink;
use crate::raster::PlaneDepths;
use std::convert::Infallible;
use std::io::Read;

/// The results of one event block's depth tests, as the writer gathers them.
#[derive(Default)]
pub(crate) struct DepthTestBits {
    bytes: Vec<u8>,
    count: u32,
}

impl DepthTestBits {
    pub(crate) fn push(&mut self, passed: bool) {
        let bit = self.count % 8;
        if bit == 0 {
            self.bytes.push(0);
        }
        if let Some(last) = self.bytes.last_mut() {
            *last |= (passed as u8) << bit;
        }
        self.count += 1;
    }

    pub(crate) fn count(&self) -> u32 {
        self.count
    }

    pub(crate) fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// None left, the memory kept.
    pub(crate) fn emptied(mut self) -> DepthTestBits {
        self.bytes.clear();
        self.count = 0;
        self
    }
}

/// Which fragments of a span passed their depth tests: fragment `i` of the span is bit
/// `first + i` of `bits`.
#[derive(Clone, Copy, Debug)]
pub struct DepthTestResults<'a> {
    bits: &'a [u8],
    first: usize,
}

impl<'a> DepthTestResults<'a> {
    /// Results packed as a depth-test block packs them, the span's first at bit `first`.
    pub fn new(bits: &'a [u8], first: usize) -> DepthTestResults<'a> {
        DepthTestResults { bits, first }
    }

    /// Whether fragment `i` of the span passed its depth test.
    #[inline]
    pub fn passed(&self, i: usize) -> bool {
        let bit = self.first + i;
        self.bits[bit / 8] >> (bit % 8) & 1 == 1
    }
}

/// A span's place in the loaded block: its start and where its depths begin.
#[derive(Clone, Copy)]
struct SpanAt {
    x: u16,
    y: u16,
    /// Its first fragment's index in the block.
    first: usize,
}

/// The loaded event block's fragments, gathered from the first one a reader may still ask
/// for: the spans wholly before it (where a reader starts mid-block, most of what it
/// decodes) are counted, their depths neither kept nor, for plane spans, evaluated. (The
/// demo's sampled:100 on the O2 decoded ten spans for each one its machines took; keeping
/// them all took 64.7 M instructions in process, so 59.3 M; sampled:10 320.3 M -> 306.7 M.)
#[derive(Default)]
struct BlockFragments {
    spans: Vec<SpanAt>,
    /// The kept spans' depths, from fragment `kept_from` of the block on.
    depths: Vec<u32>,
    kept_from: usize,
    /// Fragments decoded: the kept spans' and those passed over before them.
    decoded: usize,
    /// Fragments no reader will ask for: a span before it is passed over, while no span
    /// has been kept.
    unread: usize,
}

impl BlockFragments {
    /// Empty it for a new block.
    fn clear(&mut self) {
        self.spans.clear();
        self.depths.clear();
        (self.kept_from, self.decoded, self.unread) = (0, 0, 0);
    }

    /// Take the next `len` fragments at `(x, y)`: whether their depths are to be kept (at
    /// the end of `depths`, where they go).
    #[inline(always)]
    fn keeps(&mut self, (x, y): (u16, u16), len: usize) -> bool {
        let first = self.decoded;
        self.decoded += len;
        if self.spans.is_empty() {
            if first + len <= self.unread {
                return false;
            }
            self.kept_from = first;
        }
        self.spans.push(SpanAt { x, y, first });
        true
    }

    /// The kept depths of fragments `range` of the block.
    fn depths(&self, range: std::ops::Range<usize>) -> &[u32] {
        &self.depths[range.start - self.kept_from..range.end - self.kept_from]
    }
}

impl EventSink for BlockFragments {
    type Error = Infallible;

    fn event(&mut self, event: &Event) -> Result<(), Infallible> {
        if let Event::Fragment(fragment) = event {
            self.span(Span {
                x: fragment.x,
                y: fragment.y,
                depths: &[fragment.z],
            })?;
        }
        Ok(())
    }

    fn span(&mut self, span: Span) -> Result<(), Infallible> {
        if self.keeps((span.x, span.y), span.depths.len()) {
            self.depths.extend_from_slice(span.depths);
        }
        Ok(())
    }

    #[inline(always)]
    fn plane_span(
        &mut self,
        place: (u16, u16),
        len: usize,
        plane: &PlaneDepths,
        _room: &mut Vec<u32>,
    ) -> Result<(), Infallible> {
        if self.keeps(place, len) {
            let start = self.depths.len();
            self.depths.resize(start + len, 0);
            plane.fill(place.0, place.1, &mut self.depths[start..]);
        }
        Ok(())
    }
}

/// The fragments of an indexed trace with their depth tests' results, handed out in order
/// from any point on: the event blocks before that point are passed undecompressed (their
/// checksums still checked), and the one holding it is decoded for its fragments alone, so
/// a reader can start in the middle of a trace. Memory: one event block's fragments.
///
/// Read the trace's events with another reader: this one checks the fragments' bounds, the
/// blocks' checksums and that every event block has its depth-test block, not the sense of
/// the events between the fragments.
pub struct TestedFragments<R: Read> {
    reader: TraceReader<R>,
    tally: StreamTally,
    /// The event block read, as stored, while its depth-test block is read.
    events_stored: Vec<u8>,
    payload: Vec<u8>,
    block: BlockFragments,
    passed: Vec<u8>,
    /// The loaded block's first fragment in the trace, and its fragments (those of `block`
    /// are its first, decoded as far as they were wanted).
    block_first: u64,
    block_len: u64,
    /// The loaded block's decoder, paused where the fragments wanted so far end, and its
    /// blocks' file offsets (for errors).
    decoder: BlockDecoder,
    assembly: Vec<u8>,
    offsets: (u64, u64),
    /// The first fragment of the blocks not yet read.
    unread_first: u64,
    /// The next fragment to hand out or skip.
    next: u64,
}

impl<R: Read> TestedFragments<R> {
    /// The fragments of `reader`'s trace (freshly opened), which must hold depth-test blocks.
    pub fn new(reader: TraceReader<R>) -> Result<TestedFragments<R>, TraceError> {
        if !reader.has_depth_tests() {
            return Err(TraceError::BadHeader {
                offset: 0,
                reason: "the trace has no depth-test blocks (they come with a window index, \
                         from format version 5)"
                    .to_owned(),
            });
        }
        let tally = StreamTally::new(reader.header());
        Ok(TestedFragments {
            reader,
            tally,
            events_stored: Vec::new(),
            payload: Vec::new(),
            block: BlockFragments::default(),
            passed: Vec::new(),
            block_first: 0,
            block_len: 0,
            decoder: BlockDecoder::new(),
            assembly: Vec::new(),
            offsets: (0, 0),
            unread_first: 0,
            next: 0,
        })
    }

    /// Pass over the next `count` fragments (nothing is read until fragments are taken).
    pub fn skip(&mut self, count: u64) {
        self.next += count;
    }

    /// Hand the next `count` fragments to `each`, as spans (a span of the trace split where
    /// `count` ends) with their depth tests' results.
    pub fn take<E>(
        &mut self,
        mut count: u64,
        mut each: impl FnMut(Span, DepthTestResults) -> Result<(), E>,
    ) -> Result<(), ReadError<E>> {
        while count > 0 {
            if self.next >= self.block_first + self.block_len {
                self.load_block_holding(self.next)
                    .map_err(ReadError::Trace)?;
            }
            let at = (self.next - self.block_first) as usize;
            let wanted = (at as u64 + count).min(self.block_len) as usize;
            // No fragment before the next is asked for again.
            self.block.unread = at;
            self.decode_to(wanted).map_err(ReadError::Trace)?;
            let spans = &self.block.spans;
            let index = spans.partition_point(|span| span.first <= at) - 1;
            for (i, span) in spans.iter().enumerate().skip(index) {
                let end = spans
                    .get(i + 1)
                    .map_or(self.block.decoded, |next| next.first);
                let start = at.max(span.first);
                let stop = end.min(start + count as usize);
                if start >= stop {
                    break;
                }
                let piece = Span {
                    x: span.x + (start - span.first) as u16,
                    y: span.y,
                    depths: self.block.depths(start..stop),
                };
                let results = DepthTestResults {
                    bits: &self.passed,
                    first: start,
                };
                each(piece, results).map_err(ReadError::Sink)?;
                let taken = (stop - start) as u64;
                count -= taken;
                self.next += taken;
                if count == 0 {
                    break;
                }
            }
        }
        Ok(())
    }

    /// Read on to the event block holding fragment `wanted` and decode it with its results.
    fn load_block_holding(&mut self, wanted: u64) -> Result<(), TraceError> {
        loop {
            let pair = self.next_pair()?;
            let fragments = pair.tests.events as u64;
            let first = self.unread_first;
            self.unread_first += fragments;
            if first + fragments <= wanted {
                continue;
            }
            self.load_pair(pair)?;
            (self.block_first, self.block_len) = (first, fragments);
            return Ok(());
        }
    }

    /// The next event block (its stored payload kept in `events_stored`) and its depth-test
    /// block (its stored payload left in the reader).
    fn next_pair(&mut self) -> Result<Pair, TraceError> {
        let events = loop {
            let Some(header) = self.reader.next_raw_block()? else {
                return Err(TraceError::Truncated {
                    offset: self.reader.block_offset(),
                    inside: "the fragments a model asked for",
                });
            };
            match header.kind {
                KIND_INDEX | KIND_BANDS | KIND_WINDOWS => continue,
                KIND_EVENTS => break header,
                _ => {
                    return Err(TraceError::BadBlock {
                        offset: self.reader.block_offset(),
                        reason: "a depth-test block without its event block".to_owned(),
                    })
                }
            }
        };
        let events_offset = self.reader.block_offset();
        self.reader.keep_stored(&mut self.events_stored);
        match self.reader.next_raw_block()? {
            Some(tests) if tests.kind == KIND_DEPTH_TESTS => Ok(Pair {
                events,
                events_offset,
                tests,
                tests_offset: self.reader.block_offset(),
            }),
            _ => Err(TraceError::BadBlock {
                offset: events_offset,
                reason: "an event block without its depth-test block after it".to_owned(),
            }),
        }
    }

    /// Load the pair just read: the depth-test block's results and the event block's
    /// payload, decompressed; its fragments are decoded as they are wanted ([`Self::decode_to`]).
    fn load_pair(&mut self, pair: Pair) -> Result<(), TraceError> {
        self.reader
            .decompress_stored(&pair.tests, pair.tests_offset, &mut self.passed)?;
        self.reader.decompress(
            &pair.events,
            pair.events_offset,
            &self.events_stored,
            &mut self.payload,
        )?;
        self.block.clear();
        self.decoder = BlockDecoder::new();
        self.assembly.clear();
        self.offsets = (pair.events_offset, pair.tests_offset);
        Ok(())
    }

    /// Decode the loaded block's fragments on to at least its first `wanted` (at most all
    /// of them): a window's fragments near a block's start cost no decoding of the rest
    /// (the sampled level's windows, a few thousand fragments each, lie in blocks of tens of
    /// thousands). A block whose last fragment is wanted is decoded to its end, and must
    /// hold as many fragments as its depth-test block has results (fewer, and the blocks
    /// after it would be counted from the wrong fragment); one left part-decoded has its
    /// stored bytes' checksum checked, like the blocks passed over, and may not hold more.
    fn decode_to(&mut self, wanted: usize) -> Result<(), TraceError> {
        if self.block.decoded >= wanted {
            return Ok(());
        }
        let whole = wanted as u64 >= self.block_len;
        let header = self.reader.header();
        let mut ctx = DecodeContext {
            width: header.width,
            height: header.height,
            tally: &mut self.tally,
            assembly: &mut self.assembly,
            unchecked_events: true,
            skim_queries: false,
        };
        let (events_offset, tests_offset) = self.offsets;
        let drained = self
            .decoder
            .drain_until(&self.payload, &mut ctx, &mut self.block, |block| {
                !whole && block.decoded >= wanted
            })
            .map_err(|error| match error {
                DrainError::Payload(error) => TraceError::Corrupt {
                    offset: events_offset,
                    payload_offset: error.pos,
                    reason: error.reason,
                },
                DrainError::Sink(never) => match never {},
            })?;
        // Paused, it holds the `wanted` (fewer than the results' count), and may hold more
        // than that count only if the block holds more fragments than results.
        let decoded = self.block.decoded;
        if decoded as u64 > self.block_len || drained && decoded as u64 != self.block_len {
            return Err(TraceError::BadBlock {
                offset: tests_offset,
                reason: format!(
                    "the depth-test block holds {} results for {decoded} fragments",
                    self.block_len,
                ),
            });
        }
        Ok(())
    }
}

/// An event block and its depth-test block, read, with their file offsets.
struct Pair {
    events: BlockHeader,
    events_offset: u64,
    tests: BlockHeader,
    tests_offset: u64,
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::depth_layout::DepthLayout;
    use crate::event::Fragment;
    use crate::golden::{DepthBuffer, FunctionalModel};
    use crate::query::{QueryMode, QuerySpec};
    use crate::rng::SplitMix64;
    use crate::state::{DepthFunc, Rect};
    use crate::trace::{TraceHeader, TraceWriter, WriterOptions};

    const SIDE: u16 = 24;

    /// A stream of every kind of depth test: functions, the test and the mask switched,
    /// brief queries (whose fragments write nothing), clears, and large query begins split
    /// over blocks; fragments in runs along rows at random depths.
    fn stream(seed: u64) -> Vec<Event> {
        let mut rng = SplitMix64(seed);
        let funcs = [
            DepthFunc::Less,
            DepthFunc::Lequal,
            DepthFunc::Greater,
            DepthFunc::Gequal,
            DepthFunc::Equal,
            DepthFunc::Notequal,
            DepthFunc::Always,
            DepthFunc::Never,
        ];
        let mut events = vec![Event::DepthTest(true)];
        let mut open = false;
        for id in 0..400u32 {
            match rng.below(12) {
                0 => events.push(Event::DepthFunc(rng.pick(&funcs))),
                1 => events.push(Event::DepthTest(rng.chance(80))),
                2 => events.push(Event::DepthMask(rng.chance(80))),
                3 => events.push(Event::Clear),
                4 if !open => {
                    // Up to 600 tiles: a begin of kilobytes, split over 4096-byte blocks.
                    let tiles = (0..1 + rng.below(600)).map(|_| Rect::new(0, 0, 8, 8));
                    events.push(Event::QueryBegin(QuerySpec {
                        id,
                        mode: QueryMode::Brief,
                        buffer_entries: 8,
                        tiles: tiles.collect(),
                    }));
                    open = true;
                }
                5 if open => {
                    events.push(Event::QueryEnd);
                    open = false;
                }
                _ => {
                    events.push(Event::Primitive);
                    let y = rng.below(SIDE as u64) as u16;
                    let x0 = rng.below(SIDE as u64) as u16;
                    let len = 1 + rng.below((SIDE - x0) as u64) as u16;
                    // Few distinct depths, so that equal ones occur.
                    let base = rng.below(8) as u32 * 1000;
                    for x in x0..x0 + len {
                        let z = base + rng.below(3) as u32 * 500;
                        events.push(Event::Fragment(Fragment { x, y, z }));
                    }
                }
            }
        }
        if open {
            events.push(Event::QueryEnd);
        }
        events
    }

    /// Each fragment's depth test by a depth buffer of the test's own.
    fn results_of(events: &[Event]) -> Vec<(Fragment, bool)> {
        let mut state_keeper = FunctionalModel::new(SIDE as u32, SIDE as u32);
        let mut depth = DepthBuffer::new(SIDE as u32, SIDE as u32);
        let mut occlusion_mode = false;
        let mut results = Vec::new();
        for event in events {
            match event {
                Event::Fragment(f) => {
                    let passed = depth.test(state_keeper.state(), *f, !occlusion_mode);
                    results.push((*f, passed));
                    continue;
                }
                Event::Clear => depth.clear(),
                Event::QueryBegin(spec) => occlusion_mode = spec.mode.is_occlusion_render_mode(),
                Event::QueryEnd => occlusion_mode = false,
                _ => {}
            }
            state_keeper.event(event);
        }
        results
    }

    fn written(events: &[Event]) -> Vec<u8> {
        let options = WriterOptions {
            block_bytes: 4096,
            zstd_level: 1,
            window_index: Some(DepthLayout {
                tile_width_pixels: 8,
                tile_height_pixels: 8,
                pixels_per_word: 2,
                banks: 2,
            }),
        };
        let header = TraceHeader::new(SIDE as u32, SIDE as u32);
        let mut bytes = Vec::new();
        let mut writer = TraceWriter::with_options(&mut bytes, &header, options).unwrap();
        events.iter().for_each(|e| writer.write_event(e).unwrap());
        writer.finish().unwrap();
        bytes
    }

    /// The next `count` fragments of `fragments`, each with its result, onto `got`.
    pub(crate) fn take_into(
        fragments: &mut TestedFragments<&[u8]>,
        count: u64,
        got: &mut Vec<(Fragment, bool)>,
    ) -> Result<(), TraceError> {
        fragments
            .take(count, |span, results| {
                got.extend(
                    span.fragments()
                        .enumerate()
                        .map(|(i, f)| (f, results.passed(i))),
                );
                Ok::<(), Infallible>(())
            })
            .map_err(ReadError::into_trace)
    }

    /// Fragments `from..from + count` by a fresh reader that skips to `from`.
    fn read(bytes: &[u8], from: u64, count: u64) -> Result<Vec<(Fragment, bool)>, TraceError> {
        let mut fragments = TestedFragments::new(TraceReader::new(bytes)?)?;
        fragments.skip(from);
        let mut read = Vec::new();
        take_into(&mut fragments, count, &mut read)?;
        Ok(read)
    }

    #[test]
    fn the_results_are_each_fragments_depth_test_from_any_fragment_on() {
        for seed in 0..4 {
            let events = stream(seed);
            let expected = results_of(&events);
            let bytes = written(&events);
            let mut reader = TraceReader::new(&bytes[..]).unwrap();
            let summary = reader.read_into(&mut crate::golden::Discard).unwrap();
            let tests = summary
                .depth_tests
                .expect("an indexed trace has depth tests");
            assert!(summary.blocks > 3, "several blocks: {summary:?}");
            assert_eq!(tests.blocks, summary.blocks, "one for each event block");
            let all = expected.len() as u64;
            assert_eq!(read(&bytes, 0, all).unwrap(), expected);
            // From the middle of blocks, and in pieces that split spans, with gaps skipped.
            let mut rng = SplitMix64(seed + 100);
            for _ in 0..20 {
                let from = rng.below(all);
                let count = rng.below(all - from + 1);
                let got = read(&bytes, from, count).unwrap();
                assert_eq!(got, expected[from as usize..(from + count) as usize]);
            }
            let mut fragments =
                TestedFragments::new(TraceReader::new(&bytes[..]).unwrap()).unwrap();
            let mut at = 0;
            while at < all {
                let (gap, count) = (rng.below(300).min(all - at), rng.below(40));
                fragments.skip(gap);
                at += gap;
                let count = count.min(all - at);
                let mut got = Vec::new();
                take_into(&mut fragments, count, &mut got).unwrap();
                assert_eq!(got, expected[at as usize..(at + count) as usize]);
                at += count;
            }
            // Past the last fragment is a clean error.
            assert!(read(&bytes, all, 1).is_err());
        }
    }

    #[test]
    fn a_block_is_decoded_only_as_far_as_its_fragments_are_wanted() {
        // Ten fragments from the start of the first block that holds more than 100: the
        // decoder stops at the span that holds the tenth (spans here are at most SIDE = 24
        // fragments long), not at the block's end; taking the rest decodes on from there
        // and gives every result as a whole read does.
        let events = stream(5);
        let expected = results_of(&events);
        let bytes = written(&events);
        let mut fragments = TestedFragments::new(TraceReader::new(&bytes[..]).unwrap()).unwrap();
        let mut got = Vec::new();
        let mut take = |fragments: &mut TestedFragments<&[u8]>, count| {
            take_into(fragments, count, &mut got).unwrap()
        };
        take(&mut fragments, 1);
        while fragments.block_len <= 100 {
            let rest = fragments.block_first + fragments.block_len - fragments.next;
            take(&mut fragments, rest + 1);
        }
        let start = fragments.next;
        take(&mut fragments, 9);
        let decoded = fragments.block.decoded as u64;
        let wanted = start + 9 - fragments.block_first;
        assert!(
            decoded >= wanted && decoded < wanted + SIDE as u64,
            "{decoded} for {wanted}"
        );
        assert!(decoded < fragments.block_len);
        let rest = expected.len() as u64 - fragments.next;
        take(&mut fragments, rest);
        assert_eq!(got, expected);
    }

    #[test]
    fn a_depth_test_block_that_counts_fewer_results_than_its_fragments_is_an_error() {
        // The first depth-test block whose count is not one past a multiple of 8 counts one
        // fragment less (its payload, ceil(count / 8) bytes, the same), its checksum made
        // again: every block's bytes check, but its event block holds one fragment more
        // than it has results. Reading every fragment must fail there, naming that
        // block's offset, not hand the next blocks' fragments out one place off.
        use crate::trace::block::{blocks_in, BLOCK_HEADER_BYTES};
        let events = stream(6);
        let all = results_of(&events).len() as u64;
        let mut bytes = written(&events);
        let (at, mut header) = blocks_in(&bytes)
            .find(|(_, h)| h.kind == KIND_DEPTH_TESTS && h.events % 8 != 1)
            .expect("a depth-test block to shorten");
        header.events -= 1;
        let stored = at + BLOCK_HEADER_BYTES..at + BLOCK_HEADER_BYTES + header.stored_len as usize;
        let checksum = header.checksum(&bytes[stored]);
        bytes[at..at + 16].copy_from_slice(&header.fields());
        bytes[at + 16..at + 20].copy_from_slice(&checksum.to_le_bytes());
        let error = read(&bytes, 0, all).unwrap_err().to_string();
        assert!(
            error.contains("results for") && error.contains(&at.to_string()),
            "{error}"
        );
    }

    #[test]
    fn a_trace_without_an_index_has_no_depth_tests() {
        let events = stream(7);
        let mut bytes = Vec::new();
        let header = TraceHeader::new(SIDE as u32, SIDE as u32);
        let mut writer = TraceWriter::new(&mut bytes, &header).unwrap();
        events.iter().for_each(|e| writer.write_event(e).unwrap());
        let summary = writer.finish().unwrap();
        assert_eq!(summary.depth_tests, None);
        let error = TestedFragments::new(TraceReader::new(&bytes[..]).unwrap()).err();
        assert!(error.is_some_and(|e| e.to_string().contains("no depth-test blocks")));
    }

    /// Where the last depth-test block ends: walk the blocks from the file header's end.
    fn end_of_last_depth_tests(bytes: &[u8]) -> usize {
        crate::trace::block::blocks_in(bytes)
            .filter(|(_, header)| header.kind == KIND_DEPTH_TESTS)
            .map(|(at, header)| at + crate::trace::BLOCK_HEADER_BYTES + header.stored_len as usize)
            .last()
            .unwrap_or(0)
    }

    #[test]
    fn a_truncated_or_flipped_trace_is_a_clean_error() {
        let events = stream(3);
        let all = results_of(&events).len() as u64;
        let bytes = written(&events);
        // Every cut before the end of the last depth-test block loses fragments.
        let needed = end_of_last_depth_tests(&bytes);
        for len in 0..needed {
            assert!(
                read(&bytes[..len], 0, all).is_err(),
                "cut at {len} read fine"
            );
        }
        // A flipped bit in any block fails its checksum, or a field names it.
        let mut flips = 0;
        for at in (bytes.len() / 3..bytes.len() - 100).step_by(5) {
            let mut flipped = bytes.clone();
            flipped[at] ^= 0x04;
            match read(&flipped, 0, all) {
                Err(_) => flips += 1,
                Ok(got) => assert_eq!(got, results_of(&events), "a flip at {at} read wrong"),
            }
        }
        assert!(flips > 0);
    }
}
