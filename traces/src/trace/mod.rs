//! The `.occt` binary fragment trace format: a streaming [`TraceWriter`] and [`TraceReader`].
//!
//! # Layout (version 14; all integers little-endian; versions 1, without the closed loop's
//! records, 2, with verbose hits stored one by one, 3, without window-index blocks, 4,
//! without depth-test blocks, 5, without the index's first reads, 6, without its densest
//! runs of reads, 7, without the window table, 8, without the index's ending runs of
//! reads, 9, without the band index, 10, with query records whose tiles a reader cannot
//! pass over, 11, without the index's drawn tails, 12, without plane spans, and 13, with
//! bands of at most 8 rows and no row bands, still read)
//!
//! ```text
//! file header   magic "OCCT\r\n\x1a\n" (8) | version u16 = 14 | flags u16 = 0
//!               | json_len u32 (<= 64 KiB) | header JSON (json_len) | CRC32 u32
//!               (the CRC covers version .. end of JSON)
//! event blocks  block header (20) | stored payload (stored_len), with window-index blocks
//!               (kind 3) among them when the header names a `window_index` layout, and
//!               then each event block followed at once by its depth-test block (kind 4),
//!               and window-table blocks (kind 5) and band-index blocks (kind 6) among them
//! summary block block header (20, kind 2, stored) | summary JSON
//! trailer       summary block offset u64 | "OCCTEND\n" (8)
//!
//! block header  kind u8 (1 events, 2 summary, 3 window index, 4 depth tests, 5 window
//!               table, 6 band index) | codec u8 (0 stored, 1 zstd) | reserved u16 = 0
//!               | events u32 | raw_len u32 (<= 1 MiB) | stored_len u32 | CRC32 u32
//!               (the CRC covers the first 16 header bytes and the stored payload; a
//!               depth-test block's `events` is its event block's fragments, a window-table
//!               block's its windows)
//! ```
//!
//! An event payload is a sequence of records, each a tag byte and fields (varints are
//! LEB128; signed ones zigzag). Fragments travel in spans, runs at x, x+1, ... on one row:
//! `SPAN dy dx (len-1) z0-residual` and then one depth residual per further fragment. The
//! span's start is coded relative to the previous span's; its first depth relative to the
//! previous span's first depth moved along the depth slopes (per x from the previous span,
//! per row from the last row step); each further depth relative to the one before plus the
//! previous span's x slope. A primitive's fragments whose depths its plane gives (the
//! rasterizer's own arithmetic) travel instead as `PLANE a0 dzdx dzdy mirror` once (three
//! f32s and a varint) and then `PLANE_SPAN dy dx (len-1)` records, without depths. All prediction state
//! resets at each block start, so blocks
//! decode independently; only a query begin or result too large for one block is split
//! into `PART` records across consecutive blocks. A query's begin and result records give
//! the length of their tiles' bytes, and a result its totals before them, so that a reader
//! that needs no tile (the O2's analytic level) passes over them
//! ([`TraceReader::skim_queries`]). See `codec.rs` for the record tags,
//! [`index`] for the window index, the stream a model that needs no fragment reads,
//! [`depth_tests`] for the depth tests' results a model starting mid-trace reads, and
//! [`windows`] for the window table, the windows' sizes a sampled model reads ahead, and
//! [`bands`] for the band index, the runs the InfiniteReality-like machine's formulas
//! count.

pub mod bands;
mod block;
mod codec;
pub mod dense_reads;
pub mod depth_tests;
mod error;
mod header;
pub mod index;
mod reader;
pub mod synthetic;
pub mod windows;
mod writer;

#[cfg(test)]
mod tests;

pub use bands::{FragmentBand, RowRun, BAND_ROWS, BAND_RUNS};
pub use block::{
    with_version_field, BANDS_VERSION, BLOCK_HEADER_BYTES, END_MAGIC, FORMAT_VERSION,
    INDEX_COUNTS_VERSION, MAGIC, MAX_BLOCK_BYTES, MAX_HEADER_JSON_BYTES, MAX_STORED_BYTES,
    MAX_SUMMARY_JSON_BYTES, OLDEST_READABLE_VERSION, TRAILER_BYTES,
};
pub use codec::MAX_EVENT_BYTES;
pub use dense_reads::{DenseReadFinder, DenseRuns, ReadRun, StretchRuns, DENSE_READ_COSTS};
pub use depth_tests::{DepthTestResults, TestedFragments};
pub use error::{ReadError, TraceError};
pub use header::{
    BlockCounts, ClosedLoopCounts, QueryModeCounts, TraceFeatures, TraceHeader, TraceSummary,
};
pub use index::{DrawnTail, FragmentStretch, IndexItem, FIRST_READS_FRAGMENTS};
pub use reader::TraceReader;
pub use windows::{WindowScout, WindowSize};
pub use writer::{TraceWriter, WriterOptions};
