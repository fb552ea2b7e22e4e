//! The stream's *windows* and the window table (format version 8 on).
//!
//! A window is the run of events from just after one query's end (and its result) or
//! frame's end to the next: the unit the sampled level simulates or extrapolates
//! (`sim/src/levels/sampled.rs`). A sampled window's machine starts its warm-up a few
//! thousand fragments before the window, so the sampled level must know the windows'
//! sizes ahead of the events it models. [`WindowScout`] is the rule, fed events (or the
//! window index's items) as a model sees them.
//!
//! The writer runs the same scout over the events it writes and keeps each window's size
//! in *window-table blocks* (kind 5), among the event blocks like the index's: one entry a
//! window, in order, as two varints (its fragments, and its fragments before its last
//! record of the closed loop's host or geometry stage), as many entries as the block
//! header's `events`. A reader that wants only the sizes reads those blocks
//! ([`crate::trace::TraceReader::next_window_sizes`]) and decompresses nothing else: on the
//! demo, the sampled level's second reading of the stream was a sixth of sampled:100's
//! instructions (15 of 86 M, decoding the window index again), and over the events, on a
//! trace without an index, a whole second decoding.

use super::block::{
    blocks_in, file_header_bytes, header_json, summary_and_trailer, BLOCK_HEADER_BYTES, KIND_BANDS,
    KIND_SUMMARY, KIND_WINDOWS,
};
use super::codec::{put_uv, Cursor, PayloadError};
use super::header::{TraceHeader, TraceSummary};
use super::index::IndexItem;
use crate::event::Event;
use crate::golden::EventSink;
use crate::Span;
use std::collections::VecDeque;

/// What the scout tells of a window.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WindowSize {
    /// Its fragments.
    pub fragments: u64,
    /// Its fragments before its last record of the closed loop's host or geometry stage
    /// (0 when it has none): from there on the host has nothing to do but wait. (The
    /// sampled level cut a window only where this came before the warm-up, until its
    /// machines took their host up from the formulas' timeline; the table keeps it.)
    pub host_until: u64,
}

impl WindowSize {
    /// Most bytes an entry of the window table takes: two 10-byte varints.
    pub(crate) const MAX_BYTES: usize = 20;

    /// Append this window's entry of the window table.
    pub(crate) fn encode(self, out: &mut Vec<u8>) {
        put_uv(out, self.fragments);
        put_uv(out, self.host_until);
    }
}

/// Decode a window-table block's `count` entries from `payload` onto `into`. Each entry's
/// host work must end within its fragments, and the payload must hold exactly `count`.
pub(crate) fn decode_window_sizes(
    payload: &[u8],
    count: u32,
    into: &mut VecDeque<WindowSize>,
) -> Result<(), PayloadError> {
    let mut cursor = Cursor::new(payload, 0);
    for _ in 0..count {
        let at = cursor.pos();
        let fragments = cursor.uv()?;
        let host_until = cursor.uv()?;
        if host_until > fragments {
            return Err(PayloadError {
                pos: at,
                reason: format!(
                    "a window's host work ends after fragment {host_until} of its {fragments}"
                ),
            });
        }
        into.push_back(WindowSize {
            fragments,
            host_until,
        });
    }
    if !cursor.at_end() {
        return Err(PayloadError {
            pos: cursor.pos(),
            reason: format!("bytes after the block's {count} windows"),
        });
    }
    Ok(())
}

/// Each window's size, found by following the stream (or its window index) as a model sees
/// it: it hands out the sizes of the windows it has seen end, and where their hosts' work
/// ends.
#[derive(Default)]
pub struct WindowScout {
    fragments: u64,
    host_until: u64,
    ended: bool,
    sizes: VecDeque<WindowSize>,
    /// The stream has ended ([`Self::finish`]).
    finished: bool,
}

impl WindowScout {
    /// The sampled level's rule: a window ends after a query's end (and its result) or a
    /// frame's end, before the next event that is not the result.
    fn close_ended(&mut self) {
        if self.ended {
            self.sizes.push_back(WindowSize {
                fragments: self.fragments,
                host_until: self.host_until,
            });
            (self.fragments, self.host_until, self.ended) = (0, 0, false);
        }
    }

    pub fn event(&mut self, event: &Event) {
        if !matches!(event, Event::QueryResult(_)) {
            self.close_ended();
        }
        match event {
            Event::Fragment(_) => self.fragments += 1,
            Event::QueryEnd | Event::Swap => self.ended = true,
            event if event.is_closed_loop_record() => self.host_until = self.fragments,
            _ => {}
        }
    }

    pub fn fragments(&mut self, count: u64) {
        self.close_ended();
        self.fragments += count;
    }

    pub fn index_item(&mut self, item: &IndexItem) {
        match item {
            IndexItem::Event(event) => self.event(event),
            IndexItem::Stretch(stretch) => self.fragments(stretch.fragments),
            IndexItem::Band(band) => self.fragments(band.fragments()),
            // As their events: a begin closes a window that ended, a result does not.
            IndexItem::Shape(_) => self.close_ended(),
            IndexItem::Totals(_) => {}
        }
    }

    /// The stream ended: the final window's size (unless the scout is finished already).
    pub fn finish(&mut self) {
        if self.finished {
            return;
        }
        self.ended = true;
        self.close_ended();
        self.finished = true;
    }

    /// The oldest window seen end whose size has not been taken.
    pub fn take_ended(&mut self) -> Option<WindowSize> {
        self.sizes.pop_front()
    }

    /// Take the next block of the window table from `read` (which adds its sizes and says
    /// false at the table's end) instead of following the stream: the table holds every
    /// window, the final one too, so at its end the scout is finished.
    pub fn read_table<E>(
        &mut self,
        read: impl FnOnce(&mut VecDeque<WindowSize>) -> Result<bool, E>,
    ) -> Result<bool, E> {
        let more = read(&mut self.sizes)?;
        self.finished |= !more;
        Ok(more)
    }

    /// The next window's size, reading on with `read_on` (which feeds the scout and says
    /// false at the stream's end) until the scout has seen that window end; None after the
    /// last window.
    pub fn next_size<E>(
        &mut self,
        mut read_on: impl FnMut(&mut WindowScout) -> Result<bool, E>,
    ) -> Result<Option<WindowSize>, E> {
        loop {
            if let Some(size) = self.sizes.pop_front() {
                return Ok(Some(size));
            }
            if self.finished {
                return Ok(None);
            }
            if !read_on(self)? {
                self.finish();
            }
        }
    }
}

impl EventSink for WindowScout {
    type Error = std::convert::Infallible;

    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        WindowScout::event(self, event);
        Ok(())
    }

    fn span(&mut self, span: Span) -> Result<(), Self::Error> {
        self.fragments(span.depths.len() as u64);
        Ok(())
    }
}

/// The trace in `bytes` without its window table: its window-table blocks dropped, its
/// summary without them and its header saying so (`window_table: false`, its CRC made
/// again), so a reader finds the windows' sizes as it does in a trace before version 8.
/// For tests and benchmarks of the readings that serve a trace without a table; None when
/// `bytes` is no whole trace of version 8 on.
pub fn without_window_table(bytes: &[u8]) -> Option<Vec<u8>> {
    without_blocks(
        bytes,
        (super::block::WINDOW_TABLE_VERSION, KIND_WINDOWS),
        |header| header.window_table = false,
        |summary| summary.window_table = None,
    )
}

/// The trace in `bytes` without its band index ([`crate::trace::bands`]): its band-index
/// blocks dropped and its summary without them, as a trace before version 10 is. For
/// tests; None when `bytes` is no whole trace of version 10 on.
pub fn without_band_index(bytes: &[u8]) -> Option<Vec<u8>> {
    without_blocks(
        bytes,
        (super::block::BANDS_VERSION, KIND_BANDS),
        |_| {},
        |summary| summary.bands = None,
    )
}

/// The trace in `bytes` (of version `since` on) without its blocks of `kind`, its header
/// and summary edited to match.
fn without_blocks(
    bytes: &[u8],
    (since, kind): (u16, u8),
    edit_header: impl Fn(&mut TraceHeader),
    edit_summary: impl Fn(&mut TraceSummary),
) -> Option<Vec<u8>> {
    let (json, _) = header_json(bytes)?;
    let version = u16::from_le_bytes(bytes.get(8..10)?.try_into().ok()?);
    if version < since {
        return None;
    }
    let mut header: TraceHeader = serde_json::from_slice(json).ok()?;
    edit_header(&mut header);
    let mut out = file_header_bytes(version, &serde_json::to_vec(&header).ok()?);
    for (at, header) in blocks_in(bytes) {
        let end = at + BLOCK_HEADER_BYTES + header.stored_len as usize;
        match header.kind {
            dropped if dropped == kind => {}
            KIND_SUMMARY => {
                let stored = bytes.get(at + BLOCK_HEADER_BYTES..end)?;
                let mut summary: TraceSummary = serde_json::from_slice(stored).ok()?;
                edit_summary(&mut summary);
                let json = serde_json::to_vec(&summary).ok()?;
                let at = out.len() as u64;
                out.extend_from_slice(&summary_and_trailer(&json, at));
                return Some(out);
            }
            _ => out.extend_from_slice(bytes.get(at..end)?),
        }
    }
    // The blocks ended before the summary.
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::HostWork;
    use crate::Fragment;

    #[test]
    fn the_scout_tells_each_windows_size_and_where_its_host_work_ends() {
        let mut scout = WindowScout::default();
        let fragment = Event::Fragment(Fragment { x: 0, y: 0, z: 0 });
        // Window 0: 3 fragments, host work after the 2nd; window 1: host work before any
        // fragment, then 4; window 2 (the last, cut by the stream's end): 1, no host work.
        let host = Event::HostWork(HostWork::default());
        for event in [
            &fragment,
            &fragment,
            &host,
            &fragment,
            &Event::QueryEnd,
            &host,
        ] {
            scout.event(event);
        }
        scout.fragments(4);
        scout.event(&Event::Swap);
        scout.event(&fragment);
        scout.finish();
        let sizes: Vec<_> = std::iter::from_fn(|| scout.next_size(|_| Ok::<_, ()>(false)).unwrap())
            .map(|size| (size.fragments, size.host_until))
            .collect();
        assert_eq!(sizes, [(3, 2), (4, 0), (1, 0)]);
    }

    #[test]
    fn a_window_table_block_decodes_its_entries_and_refuses_what_no_window_is() {
        // (300, 2) takes 3 bytes: 300 = 0b10_0101100 -> 0xAC 0x02, then 0x02; (0, 0) two.
        let mut payload = Vec::new();
        for (fragments, host_until) in [(300, 2), (0, 0)] {
            WindowSize {
                fragments,
                host_until,
            }
            .encode(&mut payload);
        }
        assert_eq!(payload, [0xAC, 0x02, 0x02, 0x00, 0x00]);
        let mut sizes = VecDeque::new();
        decode_window_sizes(&payload, 2, &mut sizes).unwrap();
        let pairs: Vec<_> = sizes.iter().map(|s| (s.fragments, s.host_until)).collect();
        assert_eq!(pairs, [(300, 2), (0, 0)]);
        // One entry too few claimed: bytes are left over, at byte 3.
        let extra = decode_window_sizes(&payload, 1, &mut VecDeque::new()).unwrap_err();
        assert_eq!(extra.pos, 3, "{}", extra.reason);
        // One too many: the third entry runs past the end, at byte 5.
        let short = decode_window_sizes(&payload, 3, &mut VecDeque::new()).unwrap_err();
        assert_eq!(short.pos, 5, "{}", short.reason);
        // Host work ending after the window's fragments: the entry at byte 0.
        let late = decode_window_sizes(&[0x01, 0x02], 1, &mut VecDeque::new()).unwrap_err();
        assert_eq!(late.pos, 0);
        assert!(late.reason.contains("host work"), "{}", late.reason);
    }
}
