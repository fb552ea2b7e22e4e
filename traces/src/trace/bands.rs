//! The band index: a third stream, beside the events and the window index, of everything
//! in the trace but its fragments, each run of fragments between two other events cut into
//! [`FragmentBand`]s: at most [`BAND_ROWS`] rows of runs, as the InfiniteReality-like
//! machine's analytic formulas count them (`occsim_sim::levels::analytic::ir`). A band
//! keeps where its fragments are (each row's runs), not their depths: what an interleave
//! deals to its Image Engines, whatever the interleave and the number of engines, so one
//! index serves every IR architecture. Under a verbose query a band's runs are cut where
//! the depth test's outcome changes and marked passing: the Image Engines' hits are the
//! passing fragments' (a writer's functional model tells it which pass).
//!
//! A band of one run a row on rows one after another, none passing (a primitive's rows:
//! most bands), is a `ROW_BAND count x y len` record (varints: its first run) and then each
//! next row's `x` and `len` less the row before's (zigzag varints, the row one more): a
//! primitive's rows step by a pixel or two, so most take two bytes, read two at a time. (As
//! `BAND` records, three bytes a row, each read on its own, reading the band index was
//! about a third of the IR's analytic level's time on the demo and the lazy-grid walk, by
//! `perf record`.) Any other band record is `BAND count` and then each run as its `x`, `y`
//! and `len` less the run before's (zigzag varints; the first run's relative to 0). Under a
//! verbose query, a band with passing runs is `BAND_PASSING count mask` and its runs, bit
//! `k` of the varint `mask` set when run `k`'s fragments passed their depth test. A band's
//! runs are those a [`FragmentBand::push_run`] would make: a run that continues the one
//! before on its row is part of it, so no run starts where the one before ends on the same
//! row.

use super::codec::{put_uv, put_zz, tag};
use std::ops::Range;

/// Rows a band holds at most: a stretch of the IR formulas, which close one and advance
/// their clocks there. A primitive's rows load its Image Engines unevenly (a narrow row
/// paces the generator at one engine's speed, a wide one at the generator's), which one sum
/// over the whole primitive averages away; a few FIFOs' worth of a narrow primitive's rows,
/// so that the fluid still smooths what the FIFOs do. On the small corpus on ir1, ir2 and
/// ir4 (`occsim fidelity --corpus --scale small --machines ir1,ir2,ir4 --no-rtl`), the
/// worst class's analytic cycles error (the random scene's slivers) was, with today's
/// formulas, 1.3% at 8 rows, 2.0% at 16 and 2.8% at 32 (`BAND_RUNS` raised to 32 for every
/// 32-row figure here); with the fifteenth session's, 0.6% at 4, 1.0% at 8, 1.7% at 16,
/// 5.2% at 64 and 6.3% for whole primitives. The sampled level's worst cycles error was
/// 0.71% at 8 and 16 and 1.21% at 32, its worst p95 latency error 1.9% at 8 and 16 and 5.9%
/// at 32 (the hard cases; its bounds are 1% and 3%). The analytic level on the demo on ir4,
/// from its band index as `BAND` records, took 15.6 ms at 8 rows, 11.8 at 16 and 10.4 at 32
/// (in one process, best of 8; decoding the fragments, 184 ms at 4 rows, 112 at 8 and 90 at
/// 16): 16 holds every bound, at most of the saving. (Closed at 8 rows and more where a
/// row's length is more than twice the first's or less than half, up to 32: no quicker than
/// 16, and the hard cases' sampled cycles 2.4% off.)
pub const BAND_ROWS: usize = 16;

/// Runs a band holds at most (a primitive's rows are one run each; fragments scattered on
/// a row make a run each, and a band of them closes at this many).
pub const BAND_RUNS: usize = 16;

/// Rows a row band holds at most: one run a row, so as many rows as a band holds and no
/// more than its runs.
pub(crate) const ROW_BAND_ROWS: usize = if BAND_ROWS < BAND_RUNS {
    BAND_ROWS
} else {
    BAND_RUNS
};

/// A run of fragments at pixels `x..x + len` of row `y`; under a verbose query, `passes`
/// says they passed their depth test (a run's fragments all pass or all fail: where that
/// changes along a row, a run ends), which tells the Image Engines' hits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RowRun {
    pub x: u16,
    pub y: u16,
    pub len: u32,
    pub passes: bool,
}

/// Up to [`BAND_ROWS`] rows (and [`BAND_RUNS`] runs) of fragments, in the order they came.
/// Two bands are equal when they hold the same runs (what lies past them is room).
#[derive(Clone, Copy, Debug)]
pub struct FragmentBand {
    runs: [RowRun; BAND_RUNS],
    count: u8,
    rows: u8,
    /// The last row's first run.
    last_row: u8,
    /// Its runs' fragments, summed as they come (asked for twice a band when a band index
    /// is read: summed from the runs each time, the IR's analytic level took the demo on
    /// ir4 in 14.87 ms and the lazy-grid walk in 18.79, in one process, best of 9; so,
    /// 14.72 and 18.45).
    fragments: u64,
    /// The least `x` of its runs and the greatest end (`x + len`), kept as they come (asked
    /// for at every band's close: over its runs there, a fifth of the IR formulas' own time
    /// on the demo); `u32::MAX` and 0 while it is empty.
    first_column: u32,
    end_column: u32,
}

impl RowRun {
    /// `len` fragments at `x..` of row `y`, outside a verbose query.
    pub const fn at(x: u16, y: u16, len: u32) -> RowRun {
        RowRun {
            x,
            y,
            len,
            passes: false,
        }
    }
}

/// Where a run goes in a band ([`FragmentBand::place`]).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Place {
    /// Onto the last run, which it continues.
    Joined,
    /// A run of its own on the last run's row.
    SameRow,
    /// A run of its own on a new row.
    NewRow,
}

/// Why [`FragmentBand::try_push`] refuses a run that fits the viewport.
const PAST_ROOM: &str = "a band run that continues the one before, or past 16 runs or 16 rows";
const _: () = assert!(BAND_ROWS == 16 && BAND_RUNS == 16, "PAST_ROOM names them");

impl PartialEq for FragmentBand {
    fn eq(&self, other: &FragmentBand) -> bool {
        self.runs() == other.runs() && (self.rows, self.last_row) == (other.rows, other.last_row)
    }
}

impl Eq for FragmentBand {}

impl Default for FragmentBand {
    fn default() -> FragmentBand {
        FragmentBand::EMPTY
    }
}

impl FragmentBand {
    pub const EMPTY: FragmentBand = FragmentBand {
        runs: [RowRun {
            x: 0,
            y: 0,
            len: 0,
            passes: false,
        }; BAND_RUNS],
        count: 0,
        rows: 0,
        last_row: 0,
        fragments: 0,
        first_column: u32::MAX,
        end_column: 0,
    };

    /// Bytes a band record takes at most: a tag, its count, its passing runs' mask, and
    /// three varints a run.
    pub(crate) const MAX_BYTES: usize = 2 + 3 + BAND_RUNS * 3 * 10;

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Empty it, its room kept as it is (a decoder refills one band record after record).
    pub(crate) fn clear(&mut self) {
        (self.count, self.rows, self.last_row, self.fragments) = (0, 0, 0, 0);
        (self.first_column, self.end_column) = (u32::MAX, 0);
    }

    /// Its runs, in order.
    pub fn runs(&self) -> &[RowRun] {
        &self.runs[..self.count as usize]
    }

    /// The runs of its last row.
    pub fn last_row(&self) -> &[RowRun] {
        &self.runs[self.last_row as usize..self.count as usize]
    }

    /// Bit `k` set when run `k` passes.
    fn passing_mask(&self) -> u16 {
        (self.runs().iter().enumerate()).fold(0, |mask, (k, run)| mask | (run.passes as u16) << k)
    }

    pub fn fragments(&self) -> u64 {
        self.fragments
    }

    /// The columns its runs span: from the least `x` to past the greatest end (`0..0`
    /// while it is empty).
    pub fn columns(&self) -> Range<usize> {
        match self.count {
            0 => 0..0,
            _ => self.first_column as usize..self.end_column as usize,
        }
    }

    /// Take `run`'s columns into its span.
    #[inline(always)]
    fn span_columns(&mut self, run: &RowRun) {
        self.first_column = self.first_column.min(run.x as u32);
        self.end_column = self.end_column.max(run.x as u32 + run.len);
    }

    /// Where `run` would go: joined to the last run (on its row, from its end, passing
    /// alike), else a run of its own on the last row or a new one, where the band has a
    /// run and, for a new row, a row to spare; `None` where it has not.
    #[inline(always)]
    fn place(&self, run: &RowRun) -> Option<Place> {
        let place = match self.runs().last() {
            Some(last) if last.y == run.y => {
                if last.x as u32 + last.len == run.x as u32 && last.passes == run.passes {
                    return Some(Place::Joined);
                }
                Place::SameRow
            }
            _ => Place::NewRow,
        };
        let rows_full = place == Place::NewRow && self.rows as usize == BAND_ROWS;
        ((self.count as usize) < BAND_RUNS && !rows_full).then_some(place)
    }

    /// Put `run` where [`Self::place`] says it goes.
    #[inline(always)]
    fn put(&mut self, run: RowRun, place: Place) {
        self.span_columns(&run);
        if place == Place::Joined {
            self.runs[self.count as usize - 1].len += run.len;
            self.fragments += run.len as u64;
            return;
        }
        if place == Place::NewRow {
            self.rows += 1;
            self.last_row = self.count;
        }
        self.runs[self.count as usize] = run;
        self.count += 1;
        self.fragments += run.len as u64;
    }

    /// Whether `run` fits: it continues the last run, or the band has a run to spare and,
    /// where the run begins a row, a row to spare.
    pub fn admits_run(&self, run: &RowRun) -> bool {
        self.place(run).is_some()
    }

    /// Add `run` (which it [`Self::admits_run`]).
    pub fn push_run(&mut self, run: RowRun) {
        let place = self.place(&run).expect("a run the band admits");
        self.put(run, place);
    }

    /// [`Self::admits_run`] for a run at `x` of row `y` outside a verbose query.
    pub fn admits(&self, x: u16, y: u16) -> bool {
        self.admits_run(&RowRun::at(x, y, 0))
    }

    /// [`Self::push_run`] for `len` fragments at `x..` of row `y` outside a verbose query.
    pub fn push(&mut self, x: u16, y: u16, len: u32) {
        self.push_run(RowRun::at(x, y, len));
    }

    /// Add `run` as read from a trace in a viewport of `width` by `height`, or say why a
    /// writer's band would not hold it: a run empty or outside the viewport, one that
    /// continues the run before (a writer joins them), one past 16 runs or 16 rows. (Each
    /// question asked once: a band index holds every run of a trace.)
    #[inline]
    pub(crate) fn try_push(
        &mut self,
        run: RowRun,
        width: u32,
        height: u32,
    ) -> Result<(), &'static str> {
        if run.len == 0 || run.x as u32 + run.len > width || run.y as u32 >= height {
            return Err("a band run empty or outside the viewport");
        }
        match self.place(&run) {
            // A writer joins a run that continues the one before.
            Some(Place::Joined) | None => Err(PAST_ROOM),
            Some(place) => {
                self.put(run, place);
                Ok(())
            }
        }
    }

    /// Whether it is one run a row, on rows one after another, none passing: a primitive's
    /// rows, most bands, which a `ROW_BAND` record holds.
    fn is_one_run_a_row(&self) -> bool {
        let runs = self.runs();
        !runs.is_empty()
            && (runs.iter().enumerate())
                .all(|(k, run)| !run.passes && run.y as usize == runs[0].y as usize + k)
    }

    /// Refill it with rows of one run each from `first` on, none passing: each next row's
    /// run is the one before's with its `x` and `len` stepped by `steps`' next pair, on
    /// the row below (at most [`BAND_ROWS`] rows in all). Returns every run's `x` and `len`
    /// ORed (negative, or from 2^16 on, where one is out of range: its runs are then not
    /// what they say) and the least `len`: the caller checks them and [`Self::columns`]'
    /// end against the viewport, and clears it where they fail.
    #[inline(always)]
    pub(crate) fn fill_stepped_rows(
        &mut self,
        first: RowRun,
        steps: impl ExactSizeIterator<Item = (i32, i32)>,
    ) -> (i32, i32) {
        debug_assert!(steps.len() < ROW_BAND_ROWS);
        let (mut x, mut len) = (first.x as i32, first.len as i32);
        let (mut ored, mut shortest) = (x | len, len);
        let (mut least_x, mut greatest_end, mut fragments) = (x, x + len, len as i64);
        self.runs[0] = first;
        // At most the rows a band holds, whatever the caller gives in a release build (the
        // caller checks the count).
        let count = steps.len().min(ROW_BAND_ROWS - 1) as u8 + 1;
        for (k, (dx, dlen)) in steps.take(ROW_BAND_ROWS - 1).enumerate() {
            (x, len) = (x + dx, len + dlen);
            ored |= x | len;
            shortest = shortest.min(len);
            least_x = least_x.min(x);
            greatest_end = greatest_end.max(x + len);
            fragments += len as i64;
            self.runs[k + 1] = RowRun::at(x as u16, first.y.wrapping_add(k as u16 + 1), len as u32);
        }
        (self.count, self.rows, self.last_row) = (count, count, count - 1);
        self.fragments = fragments as u64;
        (self.first_column, self.end_column) = (least_x as u32, greatest_end as u32);
        (ored, shortest)
    }

    pub(crate) fn encode(&self, out: &mut Vec<u8>) {
        let passing = self.passing_mask();
        if self.is_one_run_a_row() {
            let first = self.runs[0];
            out.extend([tag::ROW_BAND, self.count]);
            put_uv(out, first.x as u64);
            put_uv(out, first.y as u64);
            put_uv(out, first.len as u64);
            for pair in self.runs().windows(2) {
                put_zz(out, pair[1].x as i64 - pair[0].x as i64);
                put_zz(out, pair[1].len as i64 - pair[0].len as i64);
            }
            return;
        }
        if passing == 0 {
            out.push(tag::BAND);
            out.push(self.count);
        } else {
            out.push(tag::BAND_PASSING);
            out.push(self.count);
            put_uv(out, passing as u64);
        }
        let mut before = RowRun::default();
        for run in self.runs() {
            put_zz(out, run.x as i64 - before.x as i64);
            put_zz(out, run.y as i64 - before.y as i64);
            put_zz(out, run.len as i64 - before.len as i64);
            before = *run;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::{Event, Fragment};
    use crate::query::{QueryMode, QuerySpec};
    use crate::state::Rect;
    use crate::trace::block::{BlockHeader, CODEC_STORED, KIND_BANDS, KIND_INDEX};
    use crate::trace::index::tests::{indexed, indexed_in};
    use crate::trace::{IndexItem, TraceReader};

    fn band_items(bytes: &[u8]) -> Result<Vec<IndexItem>, crate::trace::TraceError> {
        let mut reader = TraceReader::new(bytes)?;
        let mut items = Vec::new();
        reader
            .for_each_band_item(|item| {
                items.push(item.clone());
                Ok::<(), ()>(())
            })
            .map_err(|e| match e {
                crate::trace::ReadError::Trace(e) => e,
                crate::trace::ReadError::Sink(()) => unreachable!(),
            })?;
        Ok(items)
    }

    fn frag(x: u16, y: u16) -> Event {
        Event::Fragment(Fragment { x, y, z: 100 })
    }

    #[test]
    fn the_band_index_holds_the_events_and_each_run_of_fragments_in_bands() {
        // A primitive of eighteen rows (x 2..5 on rows 0..17: 3 fragments each), then a
        // query begin, then two scattered fragments on row 20: a band of rows 0..15, one of
        // rows 16 and 17 (cut at the seventeenth row), then the event, then a band of two
        // runs.
        let mut events = vec![Event::Primitive];
        for y in 0..18 {
            events.extend((2..5).map(|x| frag(x, y)));
        }
        let begin = Event::QueryBegin(QuerySpec {
            id: 1,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 16, 16)],
        });
        events.push(begin.clone());
        events.extend([frag(1, 20), frag(9, 20), Event::QueryEnd]);
        // Under a verbose query (the depth test off: every fragment passes), its runs are
        // marked passing.
        let verbose = Event::QueryBegin(QuerySpec {
            id: 2,
            mode: QueryMode::Verbose,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 16, 16)],
        });
        events.extend([verbose.clone(), frag(3, 22), frag(4, 22), Event::QueryEnd]);
        let items = band_items(&indexed_in(&events, 32, 32)).unwrap();
        let band = |runs: &[(u16, u16, u32)]| {
            let mut band = FragmentBand::EMPTY;
            for &(x, y, len) in runs {
                band.push(x, y, len);
            }
            IndexItem::Band(band)
        };
        let rows = |range: std::ops::Range<u16>| range.map(|y| (2, y, 3)).collect::<Vec<_>>();
        assert_eq!(
            items,
            [
                IndexItem::Event(Event::Primitive),
                band(&rows(0..16)),
                band(&rows(16..18)),
                IndexItem::Event(begin),
                band(&[(1, 20, 1), (9, 20, 1)]),
                IndexItem::Event(Event::QueryEnd),
                IndexItem::Event(verbose),
                IndexItem::Band({
                    let mut passing = FragmentBand::EMPTY;
                    passing.push_run(RowRun {
                        passes: true,
                        ..RowRun::at(3, 22, 2)
                    });
                    passing
                }),
                IndexItem::Event(Event::QueryEnd),
            ]
        );
        // Each band read back knows its fragments: 16 rows of 3, 2 rows of 3, 2 scattered,
        // 2 passing.
        let fragments: Vec<u64> = (items.iter())
            .filter_map(|item| match item {
                IndexItem::Band(band) => Some(band.fragments()),
                _ => None,
            })
            .collect();
        assert_eq!(fragments, [48, 6, 2, 2]);
    }

    #[test]
    fn a_reader_inside_the_window_index_refuses_the_band_index() {
        let bytes = indexed(&[Event::Primitive, frag(0, 0), Event::Primitive, frag(1, 1)]);
        let mut reader = TraceReader::new(&bytes[..]).unwrap();
        // One item in: the reader is inside a window-index block.
        assert_eq!(
            reader.next_index_item().unwrap(),
            Some(IndexItem::Event(Event::Primitive))
        );
        let error = reader
            .for_each_band_item(|_| Ok::<(), ()>(()))
            .err()
            .map(|e| format!("{e:?}"))
            .unwrap();
        assert!(error.contains("one of them"), "{error}");
    }

    /// `bytes` with a stored block of `kind` holding `payload` put ahead of every other
    /// block; returns the bytes and the block's offset.
    fn with_block_first(mut bytes: Vec<u8>, kind: u8, payload: &[u8]) -> (Vec<u8>, usize) {
        let block = BlockHeader {
            kind,
            codec: CODEC_STORED,
            events: 1,
            raw_len: payload.len() as u32,
            stored_len: payload.len() as u32,
        };
        let (_, at) = crate::trace::block::header_json(&bytes).unwrap();
        let mut inserted = block.fields().to_vec();
        inserted.extend_from_slice(&block.checksum(payload).to_le_bytes());
        inserted.extend_from_slice(payload);
        bytes.splice(at..at, inserted);
        (bytes, at)
    }

    /// `clean` with a stored window-index block of `payload`, a band record, put first:
    /// reading its window index refuses the band, at that block's offset.
    fn assert_refused_in_the_window_index(clean: &[u8], payload: &[u8]) {
        let (wrong, at) = with_block_first(clean.to_vec(), KIND_INDEX, payload);
        let mut reader = TraceReader::new(&wrong[..]).unwrap();
        let error = reader
            .for_each_index_item(|_| Ok::<(), std::convert::Infallible>(()))
            .err()
            .map(|e| e.into_trace().to_string())
            .unwrap();
        let place = format!("byte {at}: corrupt block payload at decoded byte 0");
        assert!(error.contains("a band in a window-index block"), "{error}");
        assert!(error.starts_with(&place), "{error}");
    }

    #[test]
    fn a_band_no_writer_makes_or_in_the_wrong_index_is_refused_with_its_offset() {
        let clean = indexed(&[Event::Primitive, frag(0, 0)]);
        let mut two_runs = FragmentBand::EMPTY;
        two_runs.push(0, 0, 1);
        two_runs.push(4, 0, 2);
        let mut payload = Vec::new();
        two_runs.encode(&mut payload);
        // Right as a band-index block; a band in a window-index block is refused.
        let (good, _) = with_block_first(clean.clone(), KIND_BANDS, &payload);
        assert!(
            band_items(&good).is_err(),
            "the summary counts one band block fewer"
        );
        assert_refused_in_the_window_index(&clean, &payload);
        // Runs no writer makes: past the viewport (16 wide), continuing the run before, or
        // at an x, row or length no viewport has (below 0 or from 2^16 on: in one step of
        // 70,000, or in one of 65,530 from row 15).
        for (runs, why) in [
            (&[(10i64, 0i64, 7i64)][..], "outside the viewport"),
            (&[(0, 0, 2), (2, 0, 1)][..], "continues the one before"),
            (&[(0, 0, 1)][..], "with none passing"),
            (&[(-1, 0, 1)][..], "out of range"),
            (&[(0, 70_000, 1)][..], "out of range"),
            (&[(0, 15, 1), (0, 65_545, 1)][..], "out of range"),
            (&[(0, 0, 70_000)][..], "out of range"),
        ] {
            let mut payload = vec![tag::BAND, runs.len() as u8];
            if why == "with none passing" {
                // A passing band's mask of no run.
                payload = vec![tag::BAND_PASSING, 1, 0];
            }
            let mut before = (0i64, 0i64, 0i64);
            for &(x, y, len) in runs {
                for (value, was) in [(x, before.0), (y, before.1), (len, before.2)] {
                    crate::trace::codec::put_zz(&mut payload, value - was);
                }
                before = (x, y, len);
            }
            let (bad, at) = with_block_first(clean.clone(), KIND_BANDS, &payload);
            let error = band_items(&bad).unwrap_err().to_string();
            let place = format!("byte {at}: corrupt block payload at decoded byte 0");
            assert!(error.contains(why) && error.starts_with(&place), "{error}");
        }
    }

    #[test]
    fn a_primitive_s_rows_are_a_row_band_of_two_bytes_a_row_read_back_as_written() {
        // Rows 3..6 at (x 2, len 3), (1, 5), (1, 4): the first run as varints, then each
        // row's x and len less the row before's as zigzag varints (-1 is 1, 2 is 4, 0 is 0).
        let mut band = FragmentBand::EMPTY;
        for (x, y, len) in [(2, 3, 3), (1, 4, 5), (1, 5, 4)] {
            band.push(x, y, len);
        }
        let mut bytes = Vec::new();
        band.encode(&mut bytes);
        assert_eq!(bytes, [tag::ROW_BAND, 3, 2, 3, 3, 1, 4, 0, 1]);
        // Written by a trace writer and read back: those rows (each step one byte, read on
        // the quick path), then a second primitive whose rows step by 100 pixels and more
        // (x 0, 100, 0, 150: 200, 199 and 300 zigzagged, two bytes each; lengths 7, 7, 30,
        // 1: 0, 46 and 57), read on the slower path.
        let rows = [(2, 3, 3), (1, 4, 5), (1, 5, 4)];
        let far = [(0, 10, 7), (100, 11, 7), (0, 12, 30), (150, 13, 1)];
        let mut far_band = FragmentBand::EMPTY;
        for &(x, y, len) in &far {
            far_band.push(x, y, len);
        }
        let mut far_bytes = Vec::new();
        far_band.encode(&mut far_bytes);
        let far_steps = [0xC8, 0x01, 0, 0xC7, 0x01, 46, 0xAC, 0x02, 57];
        assert_eq!(
            far_bytes,
            [&[tag::ROW_BAND, 4, 0, 10, 7][..], &far_steps].concat()
        );
        let mut events = vec![Event::Primitive];
        for (k, primitive) in [&rows[..], &far].into_iter().enumerate() {
            if k > 0 {
                events.push(Event::Primitive);
            }
            for &(x, y, len) in primitive {
                events.extend((x..x + len as u16).map(|x| frag(x, y)));
            }
        }
        let items = band_items(&indexed_in(&events, 256, 32)).unwrap();
        let bands: Vec<&FragmentBand> = (items.iter())
            .filter_map(|item| match item {
                IndexItem::Band(band) => Some(band),
                _ => None,
            })
            .collect();
        assert_eq!(bands, [&band, &far_band]);
        // What equality does not compare: 3 + 5 + 4 fragments over columns 1..6, and 7 + 7
        // + 30 + 1 over columns 0..151.
        let counted = |band: &FragmentBand| (band.fragments(), band.columns(), band.rows);
        assert_eq!(counted(bands[0]), (12, 1..6, 3));
        assert_eq!(counted(bands[1]), (45, 0..151, 4));
        assert_eq!(bands[1].last_row(), [RowRun::at(150, 13, 1)]);
    }

    #[test]
    fn a_row_band_no_writer_makes_is_refused_with_its_offset() {
        let clean = indexed(&[Event::Primitive, frag(0, 0)]);
        // In a viewport of 16 by 16; each payload a ROW_BAND record, refused at the
        // record's tag (decoded byte 0) or, for a varint, at its own first byte.
        for (payload, why, at_byte) in [
            (&[0u8][..], "a row band of 0 rows", 0),
            (&[17, 0, 0, 1][..], "a row band of 17 rows", 0),
            // Rows 14..17, past the bottom row.
            (&[3, 0, 14, 1, 0, 0, 0, 0][..], "outside the viewport", 0),
            // A second row of length 0 (1 less 1), then one past the right edge.
            (&[2, 0, 0, 1, 0, 1][..], "empty or outside", 0),
            (&[2, 10, 0, 6, 0, 2][..], "empty or outside", 0),
            // x 0 less 1; then x 0 less 1 and back by 1 (refused though the last row is
            // in range); then a step of 2^16 (zigzag 2^17: three bytes).
            (&[2, 0, 0, 1, 1, 0][..], "out of range", 0),
            (&[3, 0, 0, 1, 1, 0, 2, 0][..], "out of range", 0),
            (&[2, 0, 0, 1, 0x80, 0x80, 0x08, 0][..], "out of range", 0),
            // A first run from 2^16 on, and one past 32 bits (2^32: five bytes, at byte 2).
            (&[1, 0x80, 0x80, 0x04, 0, 1][..], "out of range", 0),
            (&[1, 0x80, 0x80, 0x80, 0x80, 0x10, 0, 1][..], "exceeds", 2),
            // Cut short: the second row's length step, byte 6, is missing.
            (&[3, 0, 0, 1, 0][..], "past the end", 6),
        ] {
            let payload = [&[tag::ROW_BAND][..], payload].concat();
            let (bad, at) = with_block_first(clean.clone(), KIND_BANDS, &payload);
            let error = band_items(&bad).unwrap_err().to_string();
            let expected = format!("byte {at}: corrupt block payload at decoded byte {at_byte}");
            assert!(
                error.contains(why) && error.contains(&expected),
                "{why}: {error}"
            );
        }
        // A row band in a window-index block is refused as any band there.
        let payload = [tag::ROW_BAND, 1, 0, 0, 1];
        assert_refused_in_the_window_index(&clean, &payload);
    }

    #[test]
    fn a_band_s_columns_and_fragments_are_its_runs_whatever_way_it_grew() {
        // Random bands grown as a writer grows them (pieces that join, several runs a row,
        // rows that step left and right), and the same runs as row bands where they are one
        // a row: the kept span and count must be what the runs themselves give.
        let mut rng = crate::rng::SplitMix64(21);
        for case in 0..2_000 {
            let mut band = FragmentBand::EMPTY;
            let mut y = rng.below(100) as u16;
            // Every other case a primitive's rows: one run a row, each on the next.
            let one_a_row = case % 2 == 0;
            'grow: for k in 0..1 + rng.below(40) {
                let (x, len) = (rng.below(300) as u16, 1 + rng.below(40) as u32);
                match if one_a_row {
                    1 + u64::from(k == 0)
                } else {
                    rng.below(4)
                } {
                    // A piece that continues the last run, where there is one.
                    0 => {
                        if let Some(last) = band.runs().last().copied() {
                            let piece = RowRun::at(last.x + last.len as u16, last.y, len);
                            if band.admits_run(&piece) {
                                band.push_run(piece);
                            }
                            continue;
                        }
                    }
                    // A run on the next row.
                    1 if !band.is_empty() => y += 1,
                    _ => {}
                }
                let run = RowRun::at(x, y, len);
                let last_end = (band.runs().last())
                    .filter(|last| last.y == run.y)
                    .map_or(0, |last| last.x as u32 + last.len + 1);
                let run = RowRun::at(run.x.max(last_end as u16), run.y, run.len);
                if !band.admits_run(&run) {
                    break 'grow;
                }
                band.push_run(run);
            }
            let runs = band.runs();
            let least = runs.iter().map(|run| run.x as usize).min();
            let end = runs
                .iter()
                .map(|run| run.x as usize + run.len as usize)
                .max();
            let span = least.map_or(0..0, |least| least..end.unwrap());
            let fragments: u64 = runs.iter().map(|run| run.len as u64).sum();
            assert_eq!(
                (band.columns(), band.fragments()),
                (span.clone(), fragments),
                "case {case}"
            );
            if band.is_one_run_a_row() {
                let steps: Vec<(i32, i32)> = (runs.windows(2))
                    .map(|pair| {
                        let step = |a: u32, b: u32| b as i32 - a as i32;
                        (
                            step(pair[0].x as u32, pair[1].x as u32),
                            step(pair[0].len, pair[1].len),
                        )
                    })
                    .collect();
                let mut stepped = FragmentBand::EMPTY;
                let (ored, shortest) = stepped.fill_stepped_rows(runs[0], steps.iter().copied());
                assert_eq!(stepped, band, "case {case}");
                assert_eq!((stepped.columns(), stepped.fragments()), (span, fragments));
                assert!(ored < 1 << 16 && shortest > 0, "case {case}");
            }
        }
    }

    #[test]
    fn a_band_takes_sixteen_rows_and_sixteen_runs_and_joins_a_row_s_pieces() {
        let mut band = FragmentBand::EMPTY;
        // Rows 10..26, one run each, the first fed in two pieces that join.
        band.push(4, 10, 3);
        assert!(band.admits(7, 10));
        band.push(7, 10, 2);
        assert_eq!(band.runs(), [RowRun::at(4, 10, 5)]);
        for y in 11..25 {
            assert!(band.admits(0, y));
            band.push(0, y, 1);
        }
        // The sixteenth row fits, then holds the band's last run: a run on a seventeenth
        // row does not fit, nor another on the sixteenth (sixteen runs). (With as many runs
        // as rows, a band's sixteen runs end it before its rows can: `rows_full` in `place`
        // binds only were BAND_RUNS raised.)
        band.push(1, 25, 2);
        assert!(!band.admits(0, 26));
        assert!(!band.admits(5, 25));
        assert!(band.admits(3, 25), "continues the last run");
        assert_eq!(band.last_row(), [RowRun::at(1, 25, 2)]);
        // 5 + 14 + 2 fragments over columns 0..9 (the first row's 4..9).
        assert_eq!(band.fragments(), 21);
        assert_eq!(band.columns(), 0..9);
        // Eight rows of two runs: sixteen runs, so no ninth row.
        let mut two_a_row = FragmentBand::EMPTY;
        for y in 0..8 {
            two_a_row.push(0, y, 1);
            two_a_row.push(4, y, 2);
        }
        assert!(!two_a_row.admits(0, 8));
        assert_eq!((two_a_row.last_row().len(), two_a_row.columns()), (2, 0..6));
        // Scattered fragments on one row: sixteen runs, then no more.
        let mut scattered = FragmentBand::EMPTY;
        for k in 0..16 {
            assert!(scattered.admits(2 * k, 0));
            scattered.push(2 * k, 0, 1);
        }
        assert!(!scattered.admits(40, 0));
        assert!(scattered.admits(31, 0), "continues the last run");
        assert_eq!(FragmentBand::EMPTY.columns(), 0..0);
    }

    #[test]
    fn runs_that_no_band_makes_are_refused() {
        let run = |x, y, len| RowRun::at(x, y, len);
        // A viewport of 16 by 32.
        let read = |runs: &[RowRun]| {
            let mut band = FragmentBand::EMPTY;
            runs.iter().try_for_each(|&r| band.try_push(r, 16, 32))
        };
        assert_eq!(read(&[run(0, 0, 2), run(5, 0, 1)]), Ok(()));
        assert!(read(&[run(0, 0, 0)]).is_err());
        // Past the viewport's right edge (10 + 7 > 16) and its bottom row.
        assert!(read(&[run(10, 0, 7)]).is_err());
        assert!(read(&[run(0, 32, 1)]).is_err());
        // Continues the run before: a writer would have joined them.
        assert!(read(&[run(0, 0, 2), run(2, 0, 1)]).is_err());
        let sixteen_rows: Vec<RowRun> = (0..16).map(|y| run(0, y, 1)).collect();
        assert_eq!(read(&sixteen_rows), Ok(()));
        let seventeen_rows: Vec<RowRun> = (0..17).map(|y| run(0, y, 1)).collect();
        assert!(read(&seventeen_rows).is_err());
        let seventeen_runs: Vec<RowRun> = (0..17).map(|k| run(2 * k % 16, k / 8, 1)).collect();
        assert!(read(&seventeen_runs).is_err());
    }
}
