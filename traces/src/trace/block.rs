//! The container: file header, block headers, trailer. Byte order is little-endian.

/// The first 8 bytes of every trace (PNG-style: a CR LF and a ^Z catch text-mode mangling).
pub const MAGIC: [u8; 8] = *b"OCCT\r\n\x1a\n";
/// The last 8 bytes of every trace.
pub const END_MAGIC: [u8; 8] = *b"OCCTEND\n";
/// The format version this code writes. Version 2 added the closed loop's records
/// (geometry batches, host work, waits, conditional rendering, frame ends); version 3 stores
/// verbose hit lists as counts, digests and the first hits listed (`HitList`), so a result's
/// size no longer grows with its hits; version 4 may hold window-index blocks
/// ([`crate::trace::index`]), named by the header's `window_index`; version 5 pairs every
/// event block of an indexed trace with a depth-test block ([`crate::trace::depth_tests`]);
/// version 6 gives the index's stretches right after a query end their first reads
/// ([`crate::trace::FragmentStretch::first_reads`]); version 7 gives every stretch its
/// densest runs of reads ([`crate::trace::FragmentStretch::dense`]); version 8 adds the
/// window table's blocks ([`crate::trace::windows`]); version 9 gives every stretch its runs
/// of reads that end at its last fragment ([`crate::trace::FragmentStretch::ending`]), at
/// two dearer read costs as well ([`crate::trace::DENSE_READ_COSTS`]); version 10 adds the
/// band index's blocks beside the window index's ([`crate::trace::bands`]); version 11
/// gives query records the length of their tiles' bytes, and results their totals
/// ([`crate::trace::TraceReader::skim_queries`]); version 12 gives every stretch its drawn
/// tail ([`crate::trace::FragmentStretch::drawn_tail`]); version 13 keeps a primitive's
/// depth plane ([`crate::raster::PlaneDepths`]) where the rasterizer told it, and its spans
/// whose depths the plane gives as plane spans, without their depths; version 14 writes
/// bands of up to 16 rows (8 before: [`crate::trace::BAND_ROWS`]), one run a row as row
/// bands ([`crate::trace::bands`]).
pub const FORMAT_VERSION: u16 = 14;
/// The first version whose indexed traces hold a band index ([`crate::trace::bands`]).
pub const BANDS_VERSION: u16 = 10;
/// The first version whose window index holds every count the O2 formulas take
/// ([`crate::trace::TraceReader::index_has_every_count`]).
pub const INDEX_COUNTS_VERSION: u16 = 12;
/// The first version whose traces hold a window table ([`crate::trace::windows`]).
pub const WINDOW_TABLE_VERSION: u16 = 8;
/// The oldest version this code reads: version-1 traces replay as an open loop.
pub const OLDEST_READABLE_VERSION: u16 = 1;
/// Most bytes of header JSON.
pub const MAX_HEADER_JSON_BYTES: u32 = 64 << 10;
/// Most bytes of one block's event payload before compression.
pub const MAX_BLOCK_BYTES: usize = 1 << 20;
/// Most bytes of one block's payload as stored (zstd's worst-case growth is far below this).
pub const MAX_STORED_BYTES: usize = MAX_BLOCK_BYTES + (64 << 10);
/// Most bytes of summary JSON.
pub const MAX_SUMMARY_JSON_BYTES: usize = 64 << 10;
/// Bytes of the fixed part of the file header: magic, version, flags, JSON length.
pub const FILE_HEADER_FIXED_BYTES: u64 = 16;
/// Bytes of a block header.
pub const BLOCK_HEADER_BYTES: usize = 20;
/// Bytes of the trailer: summary block offset and end magic.
pub const TRAILER_BYTES: usize = 16;

/// Block kinds.
pub(crate) const KIND_EVENTS: u8 = 1;
pub(crate) const KIND_SUMMARY: u8 = 2;
pub(crate) const KIND_INDEX: u8 = 3;
pub(crate) const KIND_DEPTH_TESTS: u8 = 4;
pub(crate) const KIND_WINDOWS: u8 = 5;
pub(crate) const KIND_BANDS: u8 = 6;
/// Payload codecs.
pub(crate) const CODEC_STORED: u8 = 0;
pub(crate) const CODEC_ZSTD: u8 = 1;

/// The fixed header in front of every block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct BlockHeader {
    pub kind: u8,
    pub codec: u8,
    /// Events completed in this block (a large event counts in the block holding its end).
    pub events: u32,
    /// Payload bytes after decompression.
    pub raw_len: u32,
    /// Payload bytes as stored after this header.
    pub stored_len: u32,
}

impl BlockHeader {
    /// The first 16 bytes (everything but the checksum).
    pub(crate) fn fields(&self) -> [u8; 16] {
        let mut bytes = [0u8; 16];
        bytes[0] = self.kind;
        bytes[1] = self.codec;
        // bytes[2..4]: reserved, zero.
        bytes[4..8].copy_from_slice(&self.events.to_le_bytes());
        bytes[8..12].copy_from_slice(&self.raw_len.to_le_bytes());
        bytes[12..16].copy_from_slice(&self.stored_len.to_le_bytes());
        bytes
    }

    /// The CRC32 of the header fields and the stored payload.
    pub(crate) fn checksum(&self, stored: &[u8]) -> u32 {
        let mut hasher = crc32fast::Hasher::new();
        hasher.update(&self.fields());
        hasher.update(stored);
        hasher.finalize()
    }

    /// Parse and sanity-check a block header; the error says what is wrong.
    pub(crate) fn parse(bytes: &[u8; BLOCK_HEADER_BYTES]) -> Result<(BlockHeader, u32), String> {
        let word = |at: usize| {
            u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
        };
        let header = BlockHeader {
            kind: bytes[0],
            codec: bytes[1],
            events: word(4),
            raw_len: word(8),
            stored_len: word(12),
        };
        let (raw, stored) = (header.raw_len as usize, header.stored_len as usize);
        match header.kind {
            KIND_EVENTS | KIND_INDEX | KIND_BANDS if raw == 0 => {
                return Err("empty event block".to_owned())
            }
            KIND_EVENTS | KIND_INDEX | KIND_BANDS | KIND_DEPTH_TESTS | KIND_WINDOWS
                if raw > MAX_BLOCK_BYTES =>
            {
                return Err(format!(
                    "block claims {raw} payload bytes (most {MAX_BLOCK_BYTES})"
                ))
            }
            KIND_SUMMARY if raw > MAX_SUMMARY_JSON_BYTES || header.events != 0 => {
                return Err(format!(
                    "summary block claims {raw} bytes and {} events",
                    header.events
                ))
            }
            KIND_SUMMARY if header.codec != CODEC_STORED => {
                return Err("summary block is compressed".to_owned())
            }
            KIND_DEPTH_TESTS if raw != (header.events as usize).div_ceil(8) => {
                return Err(format!(
                    "depth-test block claims {} results in {raw} bytes",
                    header.events
                ))
            }
            // An entry of the window table takes two bytes at least.
            KIND_WINDOWS if raw == 0 || header.events as usize > raw / 2 => {
                return Err(format!(
                    "window-table block claims {} windows in {raw} bytes",
                    header.events
                ))
            }
            KIND_EVENTS | KIND_SUMMARY | KIND_INDEX | KIND_DEPTH_TESTS | KIND_WINDOWS
            | KIND_BANDS => {}
            kind => return Err(format!("unknown block kind {kind}")),
        }
        if bytes[2] != 0 || bytes[3] != 0 {
            return Err("reserved bytes are not zero".to_owned());
        }
        match header.codec {
            CODEC_STORED if stored != raw => {
                return Err(format!(
                    "uncompressed block stores {stored} bytes for {raw}"
                ))
            }
            CODEC_ZSTD if stored > MAX_STORED_BYTES => {
                return Err(format!(
                    "block claims {stored} stored bytes (most {MAX_STORED_BYTES})"
                ))
            }
            CODEC_STORED | CODEC_ZSTD => {}
            codec => return Err(format!("unknown block codec {codec}")),
        }
        Ok((header, word(16)))
    }
}

/// The summary block (stored, holding `json`) at file offset `at`, and the trailer that
/// points at it: the bytes that end every trace.
pub(crate) fn summary_and_trailer(json: &[u8], at: u64) -> Vec<u8> {
    let header = BlockHeader {
        kind: KIND_SUMMARY,
        codec: CODEC_STORED,
        events: 0,
        raw_len: json.len() as u32,
        stored_len: json.len() as u32,
    };
    let mut bytes = Vec::with_capacity(BLOCK_HEADER_BYTES + json.len() + TRAILER_BYTES);
    bytes.extend_from_slice(&header.fields());
    bytes.extend_from_slice(&header.checksum(json).to_le_bytes());
    bytes.extend_from_slice(json);
    bytes.extend_from_slice(&at.to_le_bytes());
    bytes.extend_from_slice(&END_MAGIC);
    bytes
}

/// Where the first block of a whole trace in memory starts: after the magic, version,
/// flags, JSON length, header JSON and its CRC. None when the bytes end before the length.
pub(crate) fn first_block_offset(bytes: &[u8]) -> Option<usize> {
    let json_len = u32::from_le_bytes(bytes.get(12..16)?.try_into().ok()?) as usize;
    Some(16 + json_len + 4)
}

/// A file header's bytes: magic, `version`, flags (0), JSON length, `json`, and the CRC of
/// all but the magic.
pub(crate) fn file_header_bytes(version: u16, json: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(json.len() + FILE_HEADER_FIXED_BYTES as usize + 4);
    bytes.extend_from_slice(&MAGIC);
    bytes.extend_from_slice(&version.to_le_bytes());
    bytes.extend_from_slice(&0u16.to_le_bytes());
    bytes.extend_from_slice(&(json.len() as u32).to_le_bytes());
    bytes.extend_from_slice(json);
    let crc = crc32fast::hash(&bytes[MAGIC.len()..]);
    bytes.extend_from_slice(&crc.to_le_bytes());
    bytes
}

/// A whole trace's header JSON and the offset of its first block; None when `bytes` has no
/// file header.
pub(crate) fn header_json(bytes: &[u8]) -> Option<(&[u8], usize)> {
    let first_block = first_block_offset(bytes)?;
    if bytes.get(..MAGIC.len())? != MAGIC {
        return None;
    }
    let json = bytes.get(FILE_HEADER_FIXED_BYTES as usize..first_block.checked_sub(4)?)?;
    Some((json, first_block))
}

/// The trace in `bytes` with its header's version field rewritten to `version` (its CRC
/// made again): for tests and benchmarks of how older versions read (what the version
/// gates, the reader reads as that version's); None when `bytes` has no file header.
pub fn with_version_field(bytes: &[u8], version: u16) -> Option<Vec<u8>> {
    let (json, first_block) = header_json(bytes)?;
    let mut out = file_header_bytes(version, json);
    out.extend_from_slice(bytes.get(first_block..)?);
    Some(out)
}

/// The blocks of a whole trace in memory, in order: each one's offset and header, until
/// the bytes end or a block header does not parse (a block's payload may run past the end:
/// the caller slices it with `get`).
pub(crate) fn blocks_in(bytes: &[u8]) -> impl Iterator<Item = (usize, BlockHeader)> + '_ {
    let mut at = first_block_offset(bytes).unwrap_or(usize::MAX);
    std::iter::from_fn(move || {
        let fields: [u8; BLOCK_HEADER_BYTES] = bytes
            .get(at..at.checked_add(BLOCK_HEADER_BYTES)?)?
            .try_into()
            .ok()?;
        let (header, _) = BlockHeader::parse(&fields).ok()?;
        let block = (at, header);
        at += BLOCK_HEADER_BYTES + header.stored_len as usize;
        Some(block)
    })
}
