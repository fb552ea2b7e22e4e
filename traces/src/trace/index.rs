//! The window index: a second stream, beside the events, of everything in the trace but its
//! fragments, each run of fragments between two other events summarised as one
//! [`FragmentStretch`] of the counts the O2-like machine's analytic formulas take from them.
//!
//! A model that predicts from counts (the analytic level) reads the index blocks alone and
//! skips the event blocks without decompressing them, so its cost follows the windows and
//! the primitives, not the fragments. The counts that depend on where depth lives in memory
//! (new words read, page misses) are made for one [`DepthLayout`], the one the header names;
//! a model of another layout decodes the events instead.
//!
//! The writer makes the index as the events pass, with a functional model of its own (so a
//! stretch knows which fragments pass the depth test), and cuts index blocks as it cuts event
//! blocks: one block buffer of memory each, whatever the trace's length. An index block's
//! payload is coded as an event payload ([`super::codec`]), with `STRETCH` records in place
//! of spans: `STRETCH fragments depth_reads page_misses passed last_read [first_reads]
//! [dense_runs]` (four varints and a byte: 0 when the stretch's last fragment read no new
//! word, 1 a page hit, 2 a page miss; plus [`FIRST_READS_FLAG`] when a varint of
//! [`FragmentStretch::first_reads`] follows, from format version 6; plus
//! [`DENSE_RUNS_FLAG`] when its [`FragmentStretch::dense`] runs follow, a varint count and a
//! varint pair (reads, fragments) each, from format version 7; plus [`ENDING_RUNS_FLAG`]
//! when its [`FragmentStretch::ending`] runs follow, coded alike, from format version 9;
//! plus [`DRAWN_TAIL_FLAG`] when its [`FragmentStretch::drawn_tail`] follows, a varint pair
//! (fragments, reads), from format version 12).
//!
//! A stretch keeps its `first_reads` only when it begins fewer than [`FIRST_READS_FRAGMENTS`]
//! fragments after the last query end (else it is written 0): the O2-like machine's in-order
//! port serves the depth reads of the fragments right after a query's end token before the
//! query's records, so its formulas read which of them read a word
//! (`occsim_sim::levels::analytic::o2`), and only there.

use super::bands::FragmentBand;
use super::codec::{put_uv, tag};
use super::dense_reads::{DenseReadFinder, DenseRuns, DENSE_READ_COSTS};
use crate::depth_layout::{DepthAddress, DepthLayout, DepthRead, LastRead};
use crate::event::{Event, Fragment};
use crate::golden::{FunctionalModel, ViewportBufferTooLarge};
use crate::query::{QueryShape, QueryTotals};
use crate::state::RenderState;

/// What a run of fragments between two other events asks of the O2-like machine's blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FragmentStretch {
    /// Fragments (at least one).
    pub fragments: u64,
    /// Fragments with the depth test on whose depth word differs from the last read's.
    pub depth_reads: u64,
    /// Of those, reads whose page is not the open row of its bank.
    pub page_misses: u64,
    /// Fragments with the depth test on that pass it, outside an occlusion-render-mode query
    /// (brief or verbose): those that draw, and write depth when the depth mask is on.
    pub passed: u64,
    /// What the last fragment read: `SameWord` when it read no new word (or tested no depth).
    pub last_read: DepthRead,
    /// Bit `k` set when fragment `k` (`k` < [`FIRST_READS_FRAGMENTS`]) read a new word; in a
    /// trace's index, 0 for a stretch that begins [`FIRST_READS_FRAGMENTS`] fragments or more
    /// after the last query end.
    pub first_reads: u64,
    /// Its densest runs of reads ([`super::dense_reads`]).
    pub dense: DenseRuns,
    /// Its runs of reads that end at its last fragment ([`super::dense_reads::StretchRuns`]).
    pub ending: DenseRuns,
    /// The fragments that draw one after another up to its last ([`DrawnTail`], from format
    /// version 12).
    pub drawn_tail: DrawnTail,
}

/// The fragments at the end of a run that draw, one after another (they pass the depth test,
/// or meet it off, outside an occlusion-render-mode query), and the new words they read.
/// Where a primitive's drawn fragments come together at its end (a triangle's last rows in
/// front, the rest behind), its counts spread them over all its fragments; its drawn tail
/// tells the O2-like machine's formulas that they come last, where under blending their
/// port traffic holds the query's end back (`occsim_sim::levels::analytic::o2`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DrawnTail {
    pub fragments: u64,
    pub reads: u64,
}

impl DrawnTail {
    pub const NONE: DrawnTail = DrawnTail {
        fragments: 0,
        reads: 0,
    };

    /// One more fragment: it draws or not, and reads a new word or not.
    #[inline]
    pub fn push(&mut self, draws: bool, reads: bool) {
        *self = match draws {
            true => DrawnTail {
                fragments: self.fragments + 1,
                reads: self.reads + reads as u64,
            },
            false => DrawnTail::NONE,
        };
    }

    /// This tail, then a run of `fragments` fragments whose own tail is `next`: the run's
    /// tail, continued by this one where the whole run draws.
    #[inline]
    pub fn then(self, next: DrawnTail, fragments: u64) -> DrawnTail {
        match next.fragments == fragments {
            true => DrawnTail {
                fragments: self.fragments + next.fragments,
                reads: self.reads + next.reads,
            },
            false => next,
        }
    }
}

/// Fragments of a stretch whose reads [`FragmentStretch::first_reads`] marks, and how far
/// after a query's end a stretch keeps them in an index.
pub const FIRST_READS_FRAGMENTS: u64 = 64;

/// Added to a stretch record's last-read byte when a `first_reads` varint follows.
pub(crate) const FIRST_READS_FLAG: u8 = 4;

/// Added to a stretch record's last-read byte when its dense runs follow.
pub(crate) const DENSE_RUNS_FLAG: u8 = 8;

/// Added to a stretch record's last-read byte when its ending runs follow.
pub(crate) const ENDING_RUNS_FLAG: u8 = 16;

/// Added to a stretch record's last-read byte when its drawn tail follows (two varints:
/// fragments, reads).
pub(crate) const DRAWN_TAIL_FLAG: u8 = 32;

impl FragmentStretch {
    /// No fragment yet.
    pub const EMPTY: FragmentStretch = FragmentStretch {
        fragments: 0,
        depth_reads: 0,
        page_misses: 0,
        passed: 0,
        last_read: DepthRead::SameWord,
        first_reads: 0,
        dense: DenseRuns::NONE,
        ending: DenseRuns::NONE,
        drawn_tail: DrawnTail::NONE,
    };

    /// Count one fragment (inside the viewport) drawn under `state`: its depth read by the
    /// layout's `address` after `last_read`, and whether it passes against the depth
    /// `stored` at its pixel and draws (`draws`: no occlusion-render-mode query is open).
    #[inline]
    pub fn count_fragment(
        &mut self,
        fragment: Fragment,
        state: &RenderState,
        stored: u32,
        depth: (&DepthAddress, &mut LastRead),
        draws: bool,
    ) {
        self.fragments += 1;
        self.last_read = DepthRead::SameWord;
        if !state.depth_test {
            self.drawn_tail.push(draws, false);
            return;
        }
        let (address, last_read) = depth;
        let (word, page) = address.locate(fragment.x, fragment.y);
        let read = last_read.read(word, page);
        self.depth_reads += (read != DepthRead::SameWord) as u64;
        self.page_misses += (read == DepthRead::PageMiss) as u64;
        self.last_read = read;
        if read != DepthRead::SameWord && self.fragments <= FIRST_READS_FRAGMENTS {
            self.first_reads |= 1 << (self.fragments - 1);
        }
        let drawn = draws && state.depth_func.passes(fragment.z, stored);
        self.passed += drawn as u64;
        self.drawn_tail.push(drawn, read != DepthRead::SameWord);
    }

    /// Bytes a stretch record takes at most: a tag, five 10-byte varints, a byte, the dense
    /// and ending runs' counts and pairs, and the drawn tail's two varints.
    pub(crate) const MAX_BYTES: usize = 52 + 2 * (1 + 20 * DENSE_READ_COSTS.len()) + 20;

    pub(crate) fn encode(&self, out: &mut Vec<u8>) {
        out.push(tag::STRETCH);
        put_uv(out, self.fragments);
        put_uv(out, self.depth_reads);
        put_uv(out, self.page_misses);
        put_uv(out, self.passed);
        let last_read = match self.last_read {
            DepthRead::SameWord => 0,
            DepthRead::PageHit => 1,
            DepthRead::PageMiss => 2,
        };
        let (dense, ending) = (self.dense.runs(), self.ending.runs());
        let flags = [
            (self.first_reads != 0, FIRST_READS_FLAG),
            (!dense.is_empty(), DENSE_RUNS_FLAG),
            (!ending.is_empty(), ENDING_RUNS_FLAG),
            (self.drawn_tail.fragments > 0, DRAWN_TAIL_FLAG),
        ]
        .iter()
        .filter(|(present, _)| *present)
        .fold(0, |flags, (_, flag)| flags | flag);
        out.push(last_read | flags);
        if self.first_reads != 0 {
            put_uv(out, self.first_reads);
        }
        for runs in [dense, ending] {
            if !runs.is_empty() {
                put_uv(out, runs.len() as u64);
                for run in runs {
                    put_uv(out, run.reads.into());
                    put_uv(out, run.fragments.into());
                }
            }
        }
        if self.drawn_tail.fragments > 0 {
            put_uv(out, self.drawn_tail.fragments);
            put_uv(out, self.drawn_tail.reads);
        }
    }

    /// The counts' own consistency, as a decoder checks them.
    #[inline]
    pub(crate) fn problem(&self) -> Option<&'static str> {
        if self.fragments == 0 {
            Some("a stretch of no fragments")
        } else if self.depth_reads > self.fragments || self.passed > self.fragments {
            Some("a stretch with more reads or passes than fragments")
        } else if self.page_misses > self.depth_reads {
            Some("a stretch with more page misses than reads")
        } else if self.depth_reads == 0 && self.last_read != DepthRead::SameWord {
            Some("a stretch whose last fragment read a word though none was read")
        } else if self.first_reads.count_ones() as u64 > self.depth_reads
            || self.fragments < FIRST_READS_FRAGMENTS && self.first_reads >> self.fragments != 0
        {
            Some("a stretch whose first reads are more than its reads or past its fragments")
        } else if self
            .dense
            .runs()
            .iter()
            .chain(self.ending.runs())
            .any(|run| {
                u64::from(run.reads) > self.depth_reads
                    || u64::from(run.fragments) > self.fragments
                    || run.reads == 0
            })
        {
            Some("a stretch whose dense run holds no read, or more reads or fragments than it")
        } else if self.drawn_tail.fragments > self.fragments
            || self.drawn_tail.reads > self.drawn_tail.fragments.min(self.depth_reads)
        {
            Some("a stretch whose drawn tail holds more fragments or reads than it")
        } else {
            None
        }
    }
}

/// One item of the index: an event of the trace other than a fragment, or a stretch (in
/// the window index) or a band (in the band index, [`crate::trace::bands`]) of fragments.
#[derive(Clone, Debug, PartialEq)]
pub enum IndexItem {
    Event(Event),
    Stretch(FragmentStretch),
    Band(FragmentBand),
    /// A query's begin, skimmed ([`crate::trace::TraceReader::skim_queries`]).
    Shape(QueryShape),
    /// A query's result, skimmed.
    Totals(QueryTotals),
}

/// The writer's counting state: the functional model (render state, depth buffer, open
/// query) and the depth layout's last read, with the stretch being gathered.
pub(crate) struct WindowIndexer {
    functional: FunctionalModel,
    address: DepthAddress,
    last_read: LastRead,
    /// An occlusion-render-mode query (brief, verbose) is open: nothing draws.
    occlusion_mode: bool,
    /// A verbose query is open: the band index marks the runs that pass.
    pub(crate) verbose: bool,
    stretch: FragmentStretch,
    /// The stretch's dense runs of reads, found as its fragments pass.
    dense: DenseReadFinder,
    /// Fragments since the last query end, as far as [`FIRST_READS_FRAGMENTS`] (there
    /// before the first).
    since_end: u64,
}

impl WindowIndexer {
    pub(crate) fn new(
        layout: &DepthLayout,
        width: u32,
        height: u32,
    ) -> Result<WindowIndexer, ViewportBufferTooLarge> {
        Ok(WindowIndexer {
            functional: FunctionalModel::try_new(width, height)?,
            address: DepthAddress::new(layout, width),
            last_read: LastRead::new(layout.banks),
            occlusion_mode: false,
            verbose: false,
            stretch: FragmentStretch::EMPTY,
            dense: DenseReadFinder::default(),
            since_end: FIRST_READS_FRAGMENTS,
        })
    }

    /// Count a fragment (inside the viewport) and apply it; returns whether it passes the
    /// depth test (as it does when the test is off).
    #[inline]
    pub(crate) fn fragment(&mut self, fragment: Fragment) -> bool {
        let stored = self.functional.depth_buffer().get(fragment.x, fragment.y);
        let state = self.functional.state();
        let passed = !state.depth_test || state.depth_func.passes(fragment.z, stored);
        let reads = self.stretch.depth_reads;
        self.stretch.count_fragment(
            fragment,
            self.functional.state(),
            stored,
            (&self.address, &mut self.last_read),
            !self.occlusion_mode,
        );
        self.dense.fragments(self.stretch.depth_reads > reads, 0);
        self.functional.fragment(fragment);
        passed
    }

    /// The stretch gathered since the last other event, if it holds a fragment.
    pub(crate) fn take_stretch(&mut self) -> Option<FragmentStretch> {
        let mut stretch = std::mem::replace(&mut self.stretch, FragmentStretch::EMPTY);
        let runs = self.dense.take();
        (stretch.dense, stretch.ending) = (runs.densest, runs.ending);
        if self.since_end >= FIRST_READS_FRAGMENTS {
            stretch.first_reads = 0;
        }
        self.since_end = (self.since_end + stretch.fragments).min(FIRST_READS_FRAGMENTS);
        (stretch.fragments > 0).then_some(stretch)
    }

    /// Apply an event other than a fragment (after its stretch was taken).
    pub(crate) fn event(&mut self, event: &Event) {
        debug_assert_eq!(self.stretch.fragments, 0);
        match event {
            Event::QueryBegin(spec) => {
                self.occlusion_mode = spec.mode.is_occlusion_render_mode();
                self.verbose = spec.mode == crate::query::QueryMode::Verbose;
            }
            Event::QueryEnd => {
                self.occlusion_mode = false;
                self.verbose = false;
                self.since_end = 0;
            }
            _ => {}
        }
        self.functional.event(event);
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::event::DEPTH_ONE;
    use crate::hit_list::HitList;
    use crate::query::{QueryMode, QueryResult, QuerySpec, TileResult};
    use crate::state::Rect;
    use crate::trace::{TraceError, TraceHeader, TraceReader, TraceWriter, WriterOptions};

    /// Tiles of 8x8 pixels, 4 pixels a word, one bank.
    const LAYOUT: DepthLayout = DepthLayout {
        tile_width_pixels: 8,
        tile_height_pixels: 8,
        pixels_per_word: 4,
        banks: 1,
    };

    fn frag(x: u16, y: u16, z: u32) -> Event {
        Event::Fragment(Fragment { x, y, z })
    }

    fn brief(id: u32) -> Event {
        Event::QueryBegin(QuerySpec {
            id,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 16, 16)],
        })
    }

    /// `events` as a 16x16 trace with a window index (and so a band index) at `LAYOUT`.
    pub(in crate::trace) fn indexed(events: &[Event]) -> Vec<u8> {
        indexed_in(events, 16, 16)
    }

    /// [`indexed`] in a viewport of `width` by `height`.
    pub(in crate::trace) fn indexed_in(events: &[Event], width: u32, height: u32) -> Vec<u8> {
        let options = WriterOptions {
            window_index: Some(LAYOUT),
            ..WriterOptions::default()
        };
        let mut bytes = Vec::new();
        let mut writer =
            TraceWriter::with_options(&mut bytes, &TraceHeader::new(width, height), options)
                .unwrap();
        for event in events {
            writer.write_event(event).unwrap();
        }
        writer.finish().unwrap();
        bytes
    }

    /// The trace's index items, read one call at a time; read too by a visitor
    /// ([`TraceReader::for_each_index_item`]) and a block at a time
    /// ([`TraceReader::visit_index_block`]), which must give the same items or the same
    /// error.
    fn index_of(bytes: &[u8]) -> Result<Vec<IndexItem>, TraceError> {
        let one_by_one = items_one_by_one(bytes, false);
        let visited = items_visited(bytes, false);
        // Block by block (as the sampled level's scout reads), each block begun by one item
        // read alone: the visit takes up the rest of that block.
        let by_blocks = TraceReader::new(bytes).and_then(|mut reader| {
            let mut items = Vec::new();
            while let Some(item) = reader.next_index_item()? {
                items.push(item);
                reader
                    .visit_index_block(|item| {
                        items.push(item.clone());
                        Ok::<(), std::convert::Infallible>(())
                    })
                    .map_err(crate::trace::ReadError::into_trace)?;
            }
            Ok(items)
        });
        // Skimmed, one by one and visited: each query's begin its shape and its result its
        // totals, the rest as read whole (or the same error: the tiles passed over are still
        // under their block's checksum).
        let skimmed_one_by_one = items_one_by_one(bytes, true);
        let skimmed_visited = items_visited(bytes, true);
        let said = |reading: &Result<Vec<IndexItem>, TraceError>| match reading {
            Ok(items) => Ok(items.clone()),
            Err(e) => Err(e.to_string()),
        };
        let skimmed = said(&one_by_one).map(|items| {
            items
                .into_iter()
                .map(|item| match item {
                    IndexItem::Event(Event::QueryBegin(spec)) => IndexItem::Shape(spec.shape()),
                    IndexItem::Event(Event::QueryResult(result)) => {
                        IndexItem::Totals(result.totals())
                    }
                    item => item,
                })
                .collect::<Vec<_>>()
        });
        for (a, b) in [
            (said(&one_by_one), said(&visited)),
            (said(&one_by_one), said(&by_blocks)),
            (skimmed.clone(), said(&skimmed_one_by_one)),
            (skimmed, said(&skimmed_visited)),
        ] {
            assert!(a == b, "the readings disagree: {a:?} against {b:?}");
        }
        one_by_one
    }

    /// A verbose query whose first tile's buffer overflows, in a window index: read
    /// skimmed (by `index_of`, one by one and visited), its begin is its shape and its
    /// result its totals, the rest as read whole.
    #[test]
    fn a_skimmed_query_is_its_shape_and_its_results_totals() {
        let spec = QuerySpec {
            id: 3,
            mode: QueryMode::Verbose,
            // Room for 2 hits.
            buffer_entries: 10,
            tiles: vec![Rect::new(0, 0, 8, 16), Rect::new(8, 0, 8, 16)],
        };
        // Three fragments pass in tile 0 into the cleared buffer: more than its room, so it
        // overflowed and holds one hit (the terminator took the last entry); tile 1 none.
        let mut first = TileResult::default();
        for x in 0..3 {
            first.record(x, 0, 100, true);
        }
        first.hits = HitList::from_hits([(0, 0)], 64);
        first.overflowed = true;
        let result = QueryResult {
            id: 3,
            mode: QueryMode::Verbose,
            tiles: vec![first, TileResult::default()],
            overflowed_buffers: 1,
        };
        let mut events = vec![Event::QueryBegin(spec.clone()), Event::Primitive];
        events.extend((0..3).map(|x| frag(x, 0, 100)));
        events.extend([Event::QueryEnd, Event::QueryResult(result.clone())]);
        let items = index_of(&indexed(&events)).unwrap();
        assert!(items.contains(&IndexItem::Event(Event::QueryBegin(spec.clone()))));
        assert!(items.contains(&IndexItem::Event(Event::QueryResult(result.clone()))));
        let totals = QueryTotals {
            id: 3,
            mode: QueryMode::Verbose,
            tiles: 2,
            nohc: 3,
            phc: 3,
            held_hits: 1,
            overflowed_buffers: 1,
        };
        assert_eq!(result.totals(), totals);
        let shape = QueryShape {
            id: 3,
            mode: QueryMode::Verbose,
            buffer_entries: 10,
            tiles: 2,
        };
        assert_eq!(spec.shape(), shape);
    }

    /// The index items of `bytes`, read one call at a time (skimmed when `skim`).
    fn items_one_by_one(bytes: &[u8], skim: bool) -> Result<Vec<IndexItem>, TraceError> {
        let mut reader = TraceReader::new(bytes)?;
        if skim {
            reader.skim_queries();
        }
        let mut items = Vec::new();
        while let Some(item) = reader.next_index_item()? {
            items.push(item);
        }
        Ok(items)
    }

    /// The index items of `bytes`, visited block by block (skimmed when `skim`).
    pub(in crate::trace) fn items_visited(
        bytes: &[u8],
        skim: bool,
    ) -> Result<Vec<IndexItem>, TraceError> {
        let mut reader = TraceReader::new(bytes)?;
        if skim {
            reader.skim_queries();
        }
        let mut items = Vec::new();
        reader
            .for_each_index_item(|item| {
                items.push(item.clone());
                Ok::<(), std::convert::Infallible>(())
            })
            .map_err(crate::trace::ReadError::into_trace)?;
        Ok(items)
    }

    /// A visitor's error stops the reading at its item and the reader for good.
    #[test]
    fn a_visitors_error_stops_the_index_reading() {
        let (events, _) = worked_example();
        let bytes = indexed(&events);
        let mut reader = TraceReader::new(&bytes[..]).unwrap();
        let mut seen = 0;
        let stopped = reader.for_each_index_item(|_| {
            seen += 1;
            if seen == 3 {
                Err("enough")
            } else {
                Ok(())
            }
        });
        assert!(matches!(
            stopped,
            Err(crate::trace::ReadError::Sink("enough"))
        ));
        assert_eq!(seen, 3);
        assert!(
            reader.next_index_item().unwrap().is_none(),
            "stopped for good"
        );
    }

    /// A stream and its index worked by hand.
    fn worked_example() -> (Vec<Event>, Vec<IndexItem>) {
        let mut events = vec![Event::DepthTest(true), Event::Primitive];
        // Row 0, x = 0..8 at depth 100 into the cleared buffer: all pass. Words x / 4: two
        // reads (x = 0, 4); both in page 0, the first a miss (the bank's first read), the
        // second a hit. The last fragment (x = 7) shares x = 4's word: no new read.
        events.extend((0..8).map(|x| frag(x, 0, 100)));
        // Under a brief query (nothing draws): x = 8, 9 of row 0 lie in page 1, one word:
        // one read, a miss (the one bank's open row was page 0); the last read nothing new.
        events.push(brief(7));
        events.extend([frag(8, 0, 100), frag(9, 0, 100)]);
        events.push(Event::QueryEnd);
        // The depth test off: one fragment, no read; then on again, (0, 0) at 200 fails
        // against the 100 stored (LESS) and re-reads word 0 of page 0, after page 1's word:
        // a miss, the last fragment's own read. Both begin fewer than 64 fragments after
        // the query's end, so they keep their first reads: none, then fragment 0's.
        // Drawn tails: the first stretch's 8 fragments all draw, reading 2 words; nothing
        // draws under the brief query; the one fragment with the test off draws, reading
        // nothing; the last fails.
        events.extend([
            Event::DepthTest(false),
            frag(3, 1, 5),
            Event::DepthTest(true),
        ]);
        events.push(frag(0, 0, 200));
        let stretch =
            |fragments, depth_reads, page_misses, passed, last_read, first_reads| FragmentStretch {
                fragments,
                depth_reads,
                page_misses,
                passed,
                last_read,
                first_reads,
                dense: DenseRuns::NONE,
                ending: DenseRuns::NONE,
                drawn_tail: DrawnTail::NONE,
            };
        let drawn = |stretch: FragmentStretch, fragments, reads| FragmentStretch {
            drawn_tail: DrawnTail { fragments, reads },
            ..stretch
        };
        let index = vec![
            IndexItem::Event(Event::DepthTest(true)),
            IndexItem::Event(Event::Primitive),
            IndexItem::Stretch(drawn(stretch(8, 2, 1, 8, DepthRead::SameWord, 0), 8, 2)),
            IndexItem::Event(brief(7)),
            IndexItem::Stretch(stretch(2, 1, 1, 0, DepthRead::SameWord, 0)),
            IndexItem::Event(Event::QueryEnd),
            IndexItem::Event(Event::DepthTest(false)),
            IndexItem::Stretch(drawn(stretch(1, 0, 0, 0, DepthRead::SameWord, 0), 1, 0)),
            IndexItem::Event(Event::DepthTest(true)),
            IndexItem::Stretch(stretch(1, 1, 1, 0, DepthRead::PageMiss, 1)),
        ];
        (events, index)
    }

    #[test]
    fn the_index_holds_the_events_and_the_worked_stretches() {
        let (events, index) = worked_example();
        let bytes = indexed(&events);
        assert_eq!(index_of(&bytes).unwrap(), index);
        let reader = TraceReader::new(&bytes[..]).unwrap();
        assert_eq!(reader.header().window_index, Some(LAYOUT));
    }

    /// After a query's end, one primitive's 62 fragments (rows 0 to 3 of the 16-pixel
    /// viewport in order, a new word every 4 pixels: reads at 0, 4, ..., 60), then
    /// another's 6 (x = 0..6 of row 5: reads at 0 and 4) beginning 62 fragments after the
    /// end, then a third's 4 (row 6) beginning 68 after it: the first two keep their first
    /// reads, the third is written without (0), though it read at its fragment 0.
    #[test]
    fn only_stretches_beginning_within_64_fragments_of_a_query_end_keep_their_first_reads() {
        let mut events = vec![Event::DepthTest(true), brief(1), Event::QueryEnd];
        events.push(Event::Primitive);
        events.extend((0..62).map(|k| frag(k % 16, k / 16, 100)));
        for row in [5, 6] {
            events.push(Event::Primitive);
            events.extend((0..if row == 5 { 6 } else { 4 }).map(|x| frag(x, row, 100)));
        }
        let first_reads: Vec<u64> = index_of(&indexed(&events))
            .unwrap()
            .into_iter()
            .filter_map(|item| match item {
                IndexItem::Stretch(stretch) => Some(stretch.first_reads),
                _ => None,
            })
            .collect();
        let every_fourth = (0..62).step_by(4).fold(0u64, |mask, k| mask | 1 << k);
        assert_eq!(first_reads, vec![every_fourth, 1 | 1 << 4, 0]);
    }

    /// A stretch's first reads name fragments it has and reads it made: a decoder refuses
    /// a mask past its 2 fragments (bit 2) or with more bits (2) than its reads (1).
    #[test]
    fn first_reads_past_the_fragments_or_beyond_the_reads_are_a_problem() {
        let stretch = |first_reads| FragmentStretch {
            fragments: 2,
            depth_reads: 1,
            page_misses: 0,
            passed: 0,
            last_read: DepthRead::PageHit,
            first_reads,
            dense: DenseRuns::NONE,
            ending: DenseRuns::NONE,
            drawn_tail: DrawnTail::NONE,
        };
        assert_eq!(stretch(0b10).problem(), None);
        let problem =
            Some("a stretch whose first reads are more than its reads or past its fragments");
        assert_eq!(stretch(0b100).problem(), problem);
        assert_eq!(stretch(0b11).problem(), problem);
    }

    /// A drawn tail is what follows the last fragment that did not draw: pushed one by one,
    /// "D.DDd" (D draws and reads, d draws without reading, . does not draw) leaves the
    /// last three, two of them reading; a run of 4 that all draw continues it, one that
    /// does not replaces it with its own.
    #[test]
    fn a_drawn_tail_is_the_fragments_after_the_last_that_did_not_draw() {
        let mut tail = DrawnTail::NONE;
        for c in "D.DDd".chars() {
            tail.push(c != '.', c == 'D');
        }
        assert_eq!(
            tail,
            DrawnTail {
                fragments: 3,
                reads: 2
            }
        );
        let whole = DrawnTail {
            fragments: 4,
            reads: 1,
        };
        assert_eq!(
            tail.then(whole, 4),
            DrawnTail {
                fragments: 7,
                reads: 3
            }
        );
        let part = DrawnTail {
            fragments: 2,
            reads: 0,
        };
        assert_eq!(tail.then(part, 4), part);
        assert_eq!(tail.then(DrawnTail::NONE, 4), DrawnTail::NONE);
    }

    /// A drawn tail longer than its stretch, or with more reads than its fragments or the
    /// stretch's reads, is refused as the decoder checks a record.
    #[test]
    fn a_drawn_tail_beyond_its_stretch_is_a_problem() {
        let stretch = |fragments, reads| FragmentStretch {
            fragments: 10,
            depth_reads: 4,
            page_misses: 0,
            passed: 6,
            last_read: DepthRead::PageHit,
            first_reads: 0,
            dense: DenseRuns::NONE,
            ending: DenseRuns::NONE,
            drawn_tail: DrawnTail { fragments, reads },
        };
        assert_eq!(stretch(6, 4).problem(), None);
        let problem = Some("a stretch whose drawn tail holds more fragments or reads than it");
        for (fragments, reads) in [(11, 0), (6, 5), (2, 3)] {
            assert_eq!(stretch(fragments, reads).problem(), problem);
        }
    }

    /// A run, densest or ending, with no read or more reads or fragments than its stretch
    /// is refused as the decoder checks a record.
    #[test]
    fn runs_of_reads_beyond_their_stretch_are_a_problem() {
        let runs = |reads, fragments| {
            let mut runs = DenseRuns::NONE;
            runs.push(crate::trace::ReadRun { reads, fragments });
            runs
        };
        let stretch = FragmentStretch {
            fragments: 10,
            depth_reads: 4,
            page_misses: 0,
            passed: 0,
            last_read: DepthRead::PageHit,
            first_reads: 0,
            dense: runs(4, 10),
            ending: runs(2, 3),
            drawn_tail: DrawnTail {
                fragments: 3,
                reads: 2,
            },
        };
        assert_eq!(stretch.problem(), None);
        let problem =
            Some("a stretch whose dense run holds no read, or more reads or fragments than it");
        for bad in [runs(5, 10), runs(4, 11), runs(0, 3)] {
            let dense = FragmentStretch {
                dense: bad,
                ..stretch
            };
            let ending = FragmentStretch {
                ending: bad,
                ..stretch
            };
            assert_eq!(dense.problem(), problem);
            assert_eq!(ending.problem(), problem);
        }
    }

    /// A version-11 index keeps no drawn tails, a version-8 one no ending runs, a
    /// version-6 one no dense runs and a version-5 one no first reads: their readers say
    /// so, and models decode the fragments instead.
    #[test]
    fn an_index_before_version_12_lacks_counts() {
        let (events, _) = worked_example();
        let bytes = indexed(&events);
        assert!(TraceReader::new(&bytes[..])
            .unwrap()
            .index_has_every_count());
        for version in [5, 6, 7, 8, 9, 10, 11] {
            let old = crate::trace::tests::as_version(bytes.clone(), version);
            let reader = TraceReader::new(&old[..]).unwrap();
            assert!(reader.has_depth_tests());
            assert!(!reader.index_has_every_count(), "version {version}");
        }
    }

    /// A stretch of sparse reads with a sliver inside: the index keeps the sliver's run.
    #[test]
    fn the_index_keeps_a_stretchs_densest_run_of_reads() {
        // Depth words are 4 pixels wide (LAYOUT): along row 0, x = 0..16 reads every 4th
        // fragment; then x = 0 down rows 1..=9 reads every fragment (a one-pixel column,
        // a new word each); then x = 4..16 of row 10, a read every 4th, its first (x = 4,
        // a new word) right after the column: 10 reads in a row. At 4/3 they leave
        // 10 · 4/3 - 10 = 3.3 cycles (with x = 12's read of row 0, 3 fragments before,
        // 4/3 - 4 less; with x = 8's of row 10, 4/3 - 4 less), at 3/2 5; at 5/4 2.5 and 9/8
        // 1.25, under the three cycles kept. The same run at both costs: kept once.
        let mut events = vec![Event::DepthTest(true), Event::Primitive];
        events.extend((0..16).map(|x| frag(x, 0, 100)));
        events.extend((1..10).map(|y| frag(0, y, 100)));
        events.extend((4..16).map(|x| frag(x, 10, 100)));
        let items = index_of(&indexed(&events)).unwrap();
        let Some(IndexItem::Stretch(stretch)) = items.last() else {
            panic!("the fragments end the index: {items:?}");
        };
        let column = crate::trace::ReadRun {
            reads: 10,
            fragments: 10,
        };
        assert_eq!(stretch.dense.runs(), &[column]);
        assert_eq!(stretch.depth_reads, 4 + 9 + 3);
        // The run ending the stretch: at 3/1 (weights +2, -1) the column's 9 reads score 18,
        // row 10 adds +2 at each of its 3 reads and -1 at each of its other 9 fragments,
        // 15 at its end; at 5/2 (+3, -2) 27 + 9 - 18 = 18, 9 cycles. Both from the column's
        // top: 12 reads in 21 fragments. At 3/2 (+1, -2) row 10's first "...R" takes the
        // column's 10 down to 0 and the next "..." below: none.
        let ending = crate::trace::ReadRun {
            reads: 12,
            fragments: 21,
        };
        assert_eq!(stretch.ending.runs(), &[ending]);
        assert_eq!(stretch.ending.lag(3.0), 15.0);
    }

    #[test]
    fn an_indexed_trace_reads_by_events_as_one_without_an_index() {
        let (events, _) = worked_example();
        let mut read = Vec::new();
        let bytes = indexed(&events);
        let mut reader = TraceReader::new(&bytes[..]).unwrap();
        let summary = reader.read_into(&mut read).unwrap();
        assert_eq!(read, events);
        let index = summary.window_index.expect("the summary counts the index");
        assert_eq!(index.blocks, 1);
        assert_eq!(summary.blocks, 1);
    }

    #[test]
    fn a_trace_without_an_index_has_no_items() {
        let (events, _) = worked_example();
        let mut bytes = Vec::new();
        let mut writer = TraceWriter::new(&mut bytes, &TraceHeader::new(16, 16)).unwrap();
        events.iter().for_each(|e| writer.write_event(e).unwrap());
        writer.finish().unwrap();
        assert_eq!(index_of(&bytes).unwrap(), vec![]);
    }

    #[test]
    fn index_blocks_are_cut_like_event_blocks_and_stay_in_order() {
        // 4096-byte blocks: 3000 primitives of one fragment each need several index blocks.
        let mut events = vec![Event::DepthTest(true)];
        for i in 0..3000u32 {
            events.push(Event::Primitive);
            events.push(frag((i % 16) as u16, (i / 16 % 16) as u16, DEPTH_ONE - i));
        }
        let options = WriterOptions {
            block_bytes: 4096,
            zstd_level: 1,
            window_index: Some(LAYOUT),
        };
        let mut bytes = Vec::new();
        let mut writer =
            TraceWriter::with_options(&mut bytes, &TraceHeader::new(16, 16), options).unwrap();
        events.iter().for_each(|e| writer.write_event(e).unwrap());
        let summary = writer.finish().unwrap();
        assert!(summary.window_index.unwrap().blocks > 1, "{summary:?}");
        let items = index_of(&bytes).unwrap();
        // Every primitive is followed by its one fragment's stretch.
        assert_eq!(items.len(), 1 + 2 * 3000);
        assert!(items[1..]
            .chunks(2)
            .all(|pair| pair[0] == IndexItem::Event(Event::Primitive)
                && matches!(pair[1], IndexItem::Stretch(s) if s.fragments == 1)));
    }

    #[test]
    fn a_corrupt_stretch_is_refused_with_its_offset() {
        let (events, _) = worked_example();
        let mut bytes = indexed(&events);
        // Make the index block's payload stored (not compressed) to edit it: rewrite with a
        // stretch whose misses exceed its reads, and fix the block checksum.
        let bad = FragmentStretch {
            fragments: 2,
            depth_reads: 1,
            page_misses: 2,
            passed: 0,
            last_read: DepthRead::SameWord,
            first_reads: 0,
            dense: DenseRuns::NONE,
            ending: DenseRuns::NONE,
            drawn_tail: DrawnTail::NONE,
        };
        assert_eq!(
            bad.problem(),
            Some("a stretch with more page misses than reads")
        );
        let mut payload = Vec::new();
        bad.encode(&mut payload);
        let block = crate::trace::block::BlockHeader {
            kind: crate::trace::block::KIND_INDEX,
            codec: crate::trace::block::CODEC_STORED,
            events: 1,
            raw_len: payload.len() as u32,
            stored_len: payload.len() as u32,
        };
        // Put the bad block right after the file header, ahead of every other block.
        let at = first_block_offset(&bytes);
        let mut inserted = block.fields().to_vec();
        inserted.extend_from_slice(&block.checksum(&payload).to_le_bytes());
        inserted.extend_from_slice(&payload);
        bytes.splice(at..at, inserted);
        let error = index_of(&bytes).unwrap_err().to_string();
        assert!(
            error.contains("more page misses than reads") && error.contains(&at.to_string()),
            "{error}"
        );
    }

    #[test]
    fn a_truncated_or_flipped_indexed_trace_is_a_clean_error_by_either_reading() {
        let (events, _) = worked_example();
        let bytes = indexed(&events);
        for len in 0..bytes.len() {
            assert!(index_of(&bytes[..len]).is_err(), "cut at {len} read fine");
            let mut read = Vec::new();
            let by_events = TraceReader::new(&bytes[..len]).and_then(|mut reader| {
                reader
                    .read_into(&mut read)
                    .map_err(crate::trace::ReadError::into_trace)
            });
            assert!(by_events.is_err(), "cut at {len} read fine");
        }
        // A flipped bit anywhere after the file header: a checksum or a field names it.
        for at in first_block_offset(&bytes)..bytes.len() {
            let mut flipped = bytes.clone();
            flipped[at] ^= 0x10;
            assert!(index_of(&flipped).is_err(), "a flip at {at} read fine");
        }
    }

    fn first_block_offset(bytes: &[u8]) -> usize {
        crate::trace::block::first_block_offset(bytes).expect("a file header")
    }
}
