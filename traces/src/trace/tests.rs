use super::block::{BlockHeader, BLOCK_HEADER_BYTES};
use super::codec::tag;
use super::synthetic::{generate, SyntheticScene};
use super::*;
use crate::event::{Event, Fragment, GeometryBatch, HostWork, DEPTH_ONE};
use crate::golden::{infallible, EventSink};
use crate::hit_list::{listed_hits_per_tile, HitList};
use crate::query::{QueryMode, QueryResult, QuerySpec, TileResult};
use crate::raster::{PlaneDepths, RasterProfile};
use crate::state::{DepthFunc, Rect};
use proptest::prelude::*;
use std::io::Cursor;

const SIDE: u32 = 16384;

fn write(
    header: &TraceHeader,
    options: WriterOptions,
    events: &[Event],
) -> (Vec<u8>, TraceSummary) {
    let mut bytes = Vec::new();
    let mut writer = TraceWriter::with_options(&mut bytes, header, options).unwrap();
    for event in events {
        writer.write_event(event).unwrap();
    }
    let summary = writer.finish().unwrap();
    (bytes, summary)
}

fn write_default(events: &[Event]) -> Vec<u8> {
    write(
        &TraceHeader::new(SIDE, SIDE).with_scene("test"),
        WriterOptions::default(),
        events,
    )
    .0
}

/// A way to read a whole trace: its events and summary.
type ReadPath = fn(&[u8]) -> Result<(Vec<Event>, TraceSummary), TraceError>;

/// Every event through `next_event`, then the summary.
fn read_one_by_one(bytes: &[u8]) -> Result<(Vec<Event>, TraceSummary), TraceError> {
    let mut reader = TraceReader::new(bytes)?;
    let mut events = Vec::new();
    while let Some(event) = reader.next_event()? {
        events.push(event);
    }
    Ok((
        events,
        reader.summary().cloned().expect("summary at the end"),
    ))
}

fn read_bulk(bytes: &[u8]) -> Result<(Vec<Event>, TraceSummary), TraceError> {
    let mut reader = TraceReader::new(bytes)?;
    let mut events = Vec::new();
    let summary = reader
        .read_into(&mut events)
        .map_err(ReadError::into_trace)?;
    Ok((events, summary))
}

fn frag(x: u16, y: u16, z: u32) -> Event {
    Event::Fragment(Fragment { x, y, z })
}

fn grid_tiles(columns: u32, rows: u32, side: u32) -> Vec<Rect> {
    (0..rows)
        .flat_map(|r| (0..columns).map(move |c| Rect::new(c * side, r * side, side, side)))
        .collect()
}

/// A stream holding every event kind with extreme values.
fn every_kind() -> Vec<Event> {
    let mut events = vec![Event::Clear];
    events.extend(DepthFunc::ALL.into_iter().map(Event::DepthFunc));
    for on in [false, true] {
        events.extend([Event::DepthMask(on), Event::DepthTest(on), Event::Cull(on)]);
    }
    events.push(Event::Scissor(Some(Rect::new(0, u32::MAX, u32::MAX, 7))));
    events.push(Event::Scissor(None));
    let tiles = grid_tiles(64, 64, 256);
    events.push(Event::QueryBegin(QuerySpec {
        id: u32::MAX,
        mode: QueryMode::Verbose,
        buffer_entries: 8 + 3,
        tiles: tiles.clone(),
    }));
    events.push(Event::Primitive);
    events.extend([
        frag(0, 0, 0),
        frag(16383, 16383, DEPTH_ONE),
        frag(16383, 0, 0),
        frag(0, 16383, DEPTH_ONE),
    ]);
    events.extend((0..300).map(|i| frag(100 + i, 7, (i as u32 * 5000) % (DEPTH_ONE + 1))));
    events.extend((0..3).map(|i| frag(16381 + i, 9, DEPTH_ONE - i as u32)));
    events.push(Event::Primitive);
    events.push(Event::QueryEnd);
    let mut result_tiles = vec![TileResult::default(); tiles.len()];
    result_tiles[0] = TileResult {
        nohc: u64::MAX,
        phc: 0,
        xmin: 0,
        xmax: u32::MAX,
        ymin: 3,
        ymax: 4,
        zmin: 0,
        zmax: DEPTH_ONE,
        hits: HitList::from_hits([(0, 0), (16383, 16383), (5, 0)], 2),
        overflowed: true,
    };
    result_tiles[4095].hits = HitList::from_hits([(16383, 0)], 1);
    // A list a merge cut short: its digests and last hit unknown.
    result_tiles[7].hits = HitList::from_hits([(1, 2), (3, 4), (5, 6)], 1);
    result_tiles[7].hits.truncate(1);
    events.push(Event::QueryResult(QueryResult {
        id: u32::MAX,
        mode: QueryMode::Verbose,
        tiles: result_tiles,
        overflowed_buffers: 1,
    }));
    events.push(Event::QueryBegin(QuerySpec {
        id: 0,
        mode: QueryMode::Samples,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, SIDE, SIDE)],
    }));
    events.push(frag(1, 1, 1));
    events.push(Event::QueryEnd);
    events.extend([
        Event::Geometry(GeometryBatch {
            vertices: u32::MAX,
            triangles: 0,
            starts_draw: true,
            discarded: false,
        }),
        Event::Geometry(GeometryBatch {
            vertices: 3,
            triangles: 1,
            starts_draw: false,
            discarded: true,
        }),
        Event::HostWork(HostWork {
            nodes: 1,
            boxes: u32::MAX,
            decisions: 7,
            pixels: 640 * 480,
        }),
        Event::Wait(0),
        Event::ConditionalBegin(u32::MAX),
        Event::ConditionalEnd,
        Event::Swap,
    ]);
    events
}

#[test]
fn every_event_kind_round_trips_through_both_read_paths() {
    let events = every_kind();
    let header = TraceHeader::new(SIDE, SIDE).with_scene("every kind");
    for options in [
        WriterOptions::default(),
        WriterOptions {
            block_bytes: 4096,
            zstd_level: 1,
            window_index: None,
        },
    ] {
        let (bytes, written) = write(&header, options, &events);
        let (one_by_one, summary) = read_one_by_one(&bytes).unwrap();
        assert_eq!(one_by_one, events);
        assert_eq!(summary, written);
        let (bulk, summary) = read_bulk(&bytes).unwrap();
        assert_eq!(bulk, events);
        assert_eq!(summary, written);
        assert_eq!(TraceReader::new(&bytes[..]).unwrap().header(), &header);
    }
}

#[test]
fn summary_counts_what_the_stream_holds() {
    let (_, summary) = write(
        &TraceHeader::new(SIDE, SIDE),
        WriterOptions::default(),
        &every_kind(),
    );
    // Counted by hand: 18 state and query events before the fragments, 2 primitives, 308
    // fragments, then end, result, begin, end, and 7 closed-loop records.
    assert_eq!(summary.events, 18 + 2 + 308 + 4 + 7);
    // The closed-loop records of `every_kind`: two batches (u32::MAX + 3 vertices, 1
    // triangle, one starting a draw), one wait, one conditional, one frame, one node.
    assert_eq!(
        summary.closed_loop,
        ClosedLoopCounts {
            draws: 1,
            triangles: 1,
            vertices: u32::MAX as u64 + 3,
            discarded_draws: 0,
            waits: 1,
            conditionals: 1,
            frames: 1,
            host_nodes: 1,
        }
    );
    assert_eq!(summary.fragments, 4 + 300 + 3 + 1);
    assert_eq!(summary.primitives, 2);
    assert_eq!(summary.queries, 2);
    assert_eq!(summary.query_results, 1);
    assert_eq!(
        summary.queries_by_mode,
        QueryModeCounts {
            samples: 1,
            any: 0,
            brief: 0,
            verbose: 1
        }
    );
    let features = &summary.features;
    assert_eq!(
        features.query_modes,
        vec![QueryMode::Samples, QueryMode::Verbose]
    );
    assert_eq!(features.depth_funcs, DepthFunc::ALL.to_vec());
    assert!(features.scissor && features.culling && features.clears && features.verbose);
    assert!(features.depth_writes_off && features.depth_test_off && features.query_results);
}

#[test]
fn a_result_larger_than_a_block_travels_in_parts() {
    let tiles = grid_tiles(256, 256, 64);
    let listed = listed_hits_per_tile(tiles.len());
    let results = (0..tiles.len())
        .map(|t| TileResult {
            nohc: 300,
            phc: 300,
            hits: HitList::from_hits(
                (0..256).map(|i| (i * 61 % 16384, i * 17 + (t % 8192) as u16)),
                listed,
            ),
            ..TileResult::default()
        })
        .collect();
    let events = vec![
        Event::QueryBegin(QuerySpec {
            id: 9,
            mode: QueryMode::Verbose,
            buffer_entries: 8 + 256,
            tiles,
        }),
        Event::QueryEnd,
        Event::QueryResult(QueryResult {
            id: 9,
            mode: QueryMode::Verbose,
            tiles: results,
            overflowed_buffers: 0,
        }),
        Event::Primitive,
        frag(3, 4, 5),
    ];
    let (bytes, summary) = write(
        &TraceHeader::new(SIDE, SIDE),
        WriterOptions::default(),
        &events,
    );
    // The result's 65,536 tiles take about 50 bytes each (counters, bounds, one listed hit,
    // two 8-byte digests, the hits' box and last hit): over 3 MiB, so at least three of the
    // 1 MiB blocks.
    assert!(
        summary.blocks >= 3,
        "expected the result to span blocks: {summary:?}"
    );
    assert_eq!(read_one_by_one(&bytes).unwrap().0, events);
    assert_eq!(read_bulk(&bytes).unwrap().0, events);
    // With a window index, whose query records travel in parts too: read skimmed, the
    // begin is its shape and the result its totals.
    let options = WriterOptions {
        window_index: Some(crate::depth_layout::DepthLayout {
            tile_width_pixels: 128,
            tile_height_pixels: 128,
            pixels_per_word: 8,
            banks: 2,
        }),
        ..WriterOptions::default()
    };
    let (indexed, _) = write(&TraceHeader::new(SIDE, SIDE), options, &events);
    let items = index::tests::items_visited(&indexed, true).unwrap();
    let (Event::QueryBegin(spec), Event::QueryResult(result)) = (&events[0], &events[2]) else {
        unreachable!("the events above");
    };
    assert_eq!(items[0], IndexItem::Shape(spec.shape()));
    assert_eq!(items[2], IndexItem::Totals(result.totals()));
    assert_eq!(result.totals().held_hits, 256 * 65536);
}

#[test]
fn same_events_give_the_same_bytes() {
    assert_eq!(write_default(&every_kind()), write_default(&every_kind()));
    let scene = large_triangles(50_000);
    let header = TraceHeader::new(scene.width, scene.height);
    let encode = || {
        let mut out = Vec::new();
        let mut writer = TraceWriter::new(&mut out, &header).unwrap();
        generate(&scene, &mut writer).unwrap();
        writer.finish().unwrap();
        out
    };
    assert_eq!(encode(), encode());
}

#[test]
fn summary_paths_agree_with_a_full_scan() {
    let bytes = write_default(&every_kind());
    let (_, scanned) = read_bulk(&bytes).unwrap();
    let skipped = TraceReader::new(&bytes[..])
        .unwrap()
        .skip_to_summary()
        .unwrap();
    let (header, sought) = TraceReader::read_summary(Cursor::new(&bytes)).unwrap();
    assert_eq!(skipped, scanned);
    assert_eq!(sought, scanned);
    assert_eq!(header.scene, "test");
}

fn first_block_offset(bytes: &[u8]) -> usize {
    super::block::first_block_offset(bytes).expect("a file header")
}

#[test]
fn wrong_magic_is_named() {
    let mut bytes = write_default(&every_kind());
    bytes[0] = b'X';
    let error = TraceReader::new(&bytes[..]).err().unwrap();
    assert!(matches!(error, TraceError::BadMagic), "{error}");
    assert_eq!(
        error.to_string(),
        "byte 0: not an occsim trace (wrong magic number)"
    );
}

#[test]
fn unknown_version_is_named() {
    for version in [0u8, 15] {
        let mut bytes = write_default(&every_kind());
        bytes[8] = version;
        let error = TraceReader::new(&bytes[..]).err().unwrap();
        assert!(
            matches!(
                error,
                TraceError::UnsupportedVersion { offset: 8, version: v, known: 14 } if v == version as u16
            ),
            "{error}"
        );
    }
}

/// `bytes` as a version-1 file: the version field rewritten and the header's CRC with it.
fn as_version_1(bytes: Vec<u8>) -> Vec<u8> {
    as_version(bytes, 1)
}

/// `bytes` as a file of `version`: before version 10, without its band index; before 8,
/// without its window table; the version field rewritten and the header's CRC with it.
pub(crate) fn as_version(bytes: Vec<u8>, version: u8) -> Vec<u8> {
    let bytes = match version < 10 {
        true => windows::without_band_index(&bytes).expect("a whole trace"),
        false => bytes,
    };
    let bytes = match version < 8 {
        true => windows::without_window_table(&bytes).expect("a whole trace"),
        false => bytes,
    };
    with_version_field(bytes, version)
}

/// `bytes` with the version field rewritten to `version` and the header's CRC with it.
fn with_version_field(bytes: Vec<u8>, version: u8) -> Vec<u8> {
    block::with_version_field(&bytes, version.into()).expect("a file header")
}

#[test]
fn version_1_traces_still_read_and_say_they_have_no_closed_loop() {
    let events: Vec<Event> = every_kind()
        .into_iter()
        .filter(|e| !e.is_closed_loop_record())
        .collect();
    let bytes = as_version_1(write_default(&events));
    let reader = TraceReader::new(&bytes[..]).unwrap();
    assert_eq!(reader.format_version(), 1);
    assert!(!reader.has_closed_loop());
    let current_bytes = write_default(&events);
    let current = TraceReader::new(&current_bytes[..]).unwrap();
    assert_eq!(current.format_version(), FORMAT_VERSION);
    assert!(current.has_closed_loop());
    assert_eq!(read_bulk(&bytes).unwrap().0, events);
}

#[test]
fn a_flipped_byte_in_a_block_fails_its_checksum_at_the_block_offset() {
    let clean = write_default(&every_kind());
    let block = first_block_offset(&clean);
    for flip_at in [block, block + 5, block + BLOCK_HEADER_BYTES + 3] {
        let mut bytes = clean.clone();
        bytes[flip_at] ^= 0x10;
        let error = read_bulk(&bytes).err().unwrap();
        match error {
            TraceError::ChecksumMismatch { offset, .. } | TraceError::BadBlock { offset, .. } => {
                assert_eq!(offset, block as u64, "{error}")
            }
            other => panic!("flip at {flip_at}: {other}"),
        }
    }
    let mut bytes = clean.clone();
    bytes[block + BLOCK_HEADER_BYTES + 3] ^= 0x10;
    let message = read_one_by_one(&bytes).err().unwrap().to_string();
    assert!(
        message.starts_with(&format!("byte {block}: block checksum mismatch")),
        "{message}"
    );
}

#[test]
fn a_block_claiming_the_wrong_event_count_is_caught() {
    let mut bytes = write_default(&[Event::Primitive, frag(1, 2, 3), frag(2, 2, 3)]);
    let block = first_block_offset(&bytes);
    let fields: [u8; BLOCK_HEADER_BYTES] =
        bytes[block..block + BLOCK_HEADER_BYTES].try_into().unwrap();
    let (mut header, _) = BlockHeader::parse(&fields).unwrap();
    header.events += 1;
    let stored =
        &bytes[block + BLOCK_HEADER_BYTES..block + BLOCK_HEADER_BYTES + header.stored_len as usize];
    let crc = header.checksum(stored);
    bytes[block..block + 16].copy_from_slice(&header.fields());
    bytes[block + 16..block + 20].copy_from_slice(&crc.to_le_bytes());
    let error = read_bulk(&bytes).err().unwrap();
    assert!(
        matches!(error, TraceError::Corrupt { offset, .. } if offset == block as u64),
        "{error}"
    );
    assert!(
        error
            .to_string()
            .contains("claims 4 events, the block holds 3"),
        "{error}"
    );
}

#[test]
fn truncation_at_every_offset_is_a_clean_error() {
    let bytes = write_default(&every_kind()[..30]);
    for len in 0..bytes.len() {
        assert!(
            read_one_by_one(&bytes[..len]).is_err(),
            "cut at {len} read fine"
        );
        assert!(read_bulk(&bytes[..len]).is_err(), "cut at {len} read fine");
        let skipped = TraceReader::new(&bytes[..len]).and_then(|mut r| r.skip_to_summary());
        assert!(skipped.is_err(), "cut at {len} read fine");
        // The summary alone (`trace info`): past the header, the error is at the cut, the
        // file too short for a trailer or ending in none (it had named the 16 bytes before
        // the end).
        let summary = TraceReader::read_summary(std::io::Cursor::new(&bytes[..len]));
        let error = summary
            .err()
            .unwrap_or_else(|| panic!("cut at {len} read fine"));
        if TraceReader::new(&bytes[..len]).is_ok() {
            let at_the_cut = match &error {
                TraceError::BadSummary { offset, reason } => {
                    *offset == len as u64 && reason.contains("does not end in a trailer")
                }
                TraceError::Truncated { offset, .. } => *offset == len as u64,
                _ => false,
            };
            assert!(at_the_cut, "cut at {len}: {error}");
        }
    }
    let mut longer = bytes.clone();
    longer.push(0);
    let error = read_bulk(&longer).err().unwrap();
    assert!(matches!(error, TraceError::TrailingData { .. }), "{error}");
}

/// A reader that gives one byte a call and is interrupted before every byte, then fails
/// for good after `fail_after` bytes (if given).
struct Stuttering<'a> {
    bytes: &'a [u8],
    interrupt_next: bool,
    fail_after: Option<usize>,
    given: usize,
}

impl std::io::Read for Stuttering<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        self.interrupt_next = !self.interrupt_next;
        if !self.interrupt_next {
            return Err(std::io::ErrorKind::Interrupted.into());
        }
        if Some(self.given) == self.fail_after {
            return Err(std::io::Error::other("the disk is gone"));
        }
        let Some((&first, rest)) = self.bytes.split_first() else {
            return Ok(0);
        };
        let Some(slot) = buf.first_mut() else {
            return Ok(0);
        };
        *slot = first;
        self.bytes = rest;
        self.given += 1;
        Ok(1)
    }
}

#[test]
fn short_and_interrupted_reads_give_the_same_trace_and_io_errors_name_their_offset() {
    let bytes = write_default(&every_kind());
    let stutter = |fail_after| Stuttering {
        bytes: &bytes,
        interrupt_next: false,
        fail_after,
        given: 0,
    };
    let mut reader = TraceReader::new(stutter(None)).unwrap();
    let mut events = Vec::new();
    let summary = reader
        .read_into(&mut events)
        .map_err(ReadError::into_trace)
        .unwrap();
    assert_eq!((events, summary), read_bulk(&bytes).unwrap());
    // Failing after 100 bytes names byte 100, where the failed read began (in the header or
    // a block: the offset counts from the file's start either way).
    let failed = TraceReader::new(stutter(Some(100))).and_then(|mut reader| {
        reader
            .read_into(&mut Vec::new())
            .map_err(ReadError::into_trace)
    });
    match failed {
        Err(TraceError::Io { offset, .. }) => assert_eq!(offset, 100),
        other => panic!("expected an I/O error at byte 100: {other:?}"),
    }
}

#[test]
fn the_writer_refuses_malformed_streams() {
    let header = TraceHeader::new(64, 32);
    let cases: [(&[Event], &str); 4] = [
        (&[Event::QueryEnd], "query end without begin"),
        (&[frag(64, 0, 0)], "outside the 64x32 viewport"),
        (&[frag(0, 0, DEPTH_ONE + 1)], "24-bit depth"),
        (
            &[Event::QueryResult(QueryResult {
                id: 1,
                mode: QueryMode::Any,
                tiles: vec![],
                overflowed_buffers: 0,
            })],
            "without a query end",
        ),
    ];
    for (events, expected) in cases {
        let mut writer = TraceWriter::new(Vec::new(), &header).unwrap();
        // The first bad event's error comes back from that event.
        let first = events.iter().find_map(|event| writer.event(event).err());
        let error = first.or(writer.finish().err()).unwrap().to_string();
        assert!(error.contains(expected), "{error}");
    }
}

fn large_triangles(fragments: u64) -> SyntheticScene {
    SyntheticScene {
        width: 1920,
        height: 1080,
        min_radius: 60.0,
        max_radius: 300.0,
        fragments,
        seed: 7,
    }
}

fn small_triangles(fragments: u64) -> SyntheticScene {
    SyntheticScene {
        width: 1920,
        height: 1080,
        min_radius: 3.0,
        max_radius: 12.0,
        fragments,
        seed: 11,
    }
}

fn bytes_per_fragment(scene: &SyntheticScene) -> (f64, Vec<u8>) {
    let mut events = Vec::new();
    let fragments = infallible(generate(scene, &mut events));
    let (bytes, summary) = write(
        &TraceHeader::new(scene.width, scene.height),
        WriterOptions::default(),
        &events,
    );
    assert_eq!(summary.fragments, fragments);
    assert_eq!(read_bulk(&bytes).unwrap().0, events);
    // The stream must be honest: depth varies along rows.
    let distinct: std::collections::HashSet<u32> = events
        .iter()
        .filter_map(|e| {
            if let Event::Fragment(f) = e {
                Some(f.z)
            } else {
                None
            }
        })
        .collect();
    assert!(distinct.len() as u64 > fragments / 4, "depths barely vary");
    (bytes.len() as f64 / fragments as f64, bytes)
}

#[test]
fn large_triangles_cost_well_under_a_byte_per_fragment() {
    let (rate, _) = bytes_per_fragment(&large_triangles(400_000));
    assert!(rate <= 0.5, "{rate} bytes per fragment");
}

#[test]
fn small_triangles_cost_at_most_two_bytes_per_fragment() {
    let (rate, _) = bytes_per_fragment(&small_triangles(200_000));
    assert!(rate <= 2.0, "{rate} bytes per fragment");
}

fn read_anything(bytes: &[u8]) {
    let _ = window_table(bytes);
    let _ = read_one_by_one(bytes);
    let _ = read_bulk(bytes);
    let _ = TraceReader::new(bytes).and_then(|mut r| r.skip_to_summary());
    let _ = TraceReader::read_summary(Cursor::new(bytes));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
        read_anything(&bytes);
        let mut with_magic = MAGIC.to_vec();
        with_magic.extend_from_slice(&bytes);
        read_anything(&with_magic);
    }

    #[test]
    fn mutated_traces_never_panic(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut bytes = write(&TraceHeader::new(SIDE, SIDE), WriterOptions { block_bytes: 4096, zstd_level: 1, window_index: None }, &every_kind()).0;
        for (at, value) in flips {
            let at = at.index(bytes.len());
            bytes[at] = value;
        }
        read_anything(&bytes);
        read_anything(&bytes[..cut.index(bytes.len())]);
    }

    #[test]
    fn payload_mutations_with_fixed_checksums_never_panic(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
    ) {
        read_anything(&with_payload_mutations(&flips));
    }

    #[test]
    fn both_read_paths_meet_a_damaged_payload_alike(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
    ) {
        // The bulk path decodes spans whole (checks folded into its SIMD kernels), the other
        // one fragment at a time: the same events and summary, or the same error.
        let bytes = with_payload_mutations(&flips);
        let outcome = |read: ReadPath| read(&bytes).map_err(|error| error.to_string());
        prop_assert_eq!(outcome(read_bulk), outcome(read_one_by_one));
    }
}

/// The trace of [`every_kind`] with its first block's decoded payload changed at `flips`
/// and stored uncompressed with a valid checksum, so the event decoder (not the checksum)
/// meets the damage.
fn with_payload_mutations(flips: &[(prop::sample::Index, u8)]) -> Vec<u8> {
    let options = WriterOptions {
        block_bytes: 4096,
        zstd_level: 1,
        window_index: None,
    };
    let clean = write(&TraceHeader::new(SIDE, SIDE), options, &every_kind()).0;
    with_first_payload(&clean, |payload, _| {
        for (at, value) in flips {
            let at = at.index(payload.len());
            payload[at] = *value;
        }
    })
}

/// `clean` with its first block's decoded payload and event count changed by `change` and
/// stored uncompressed with a valid checksum, so the event decoder (not the checksum) meets
/// the change.
fn with_first_payload(clean: &[u8], change: impl FnOnce(&mut Vec<u8>, &mut u32)) -> Vec<u8> {
    let block = first_block_offset(clean);
    let fields: [u8; BLOCK_HEADER_BYTES] =
        clean[block..block + BLOCK_HEADER_BYTES].try_into().unwrap();
    let (header, _) = BlockHeader::parse(&fields).unwrap();
    let stored_end = block + BLOCK_HEADER_BYTES + header.stored_len as usize;
    let stored = &clean[block + BLOCK_HEADER_BYTES..stored_end];
    let mut payload = if header.codec == 1 {
        zstd::bulk::decompress(stored, MAX_BLOCK_BYTES).unwrap()
    } else {
        stored.to_vec()
    };
    let mut events = header.events;
    change(&mut payload, &mut events);
    let new_header = BlockHeader {
        codec: 0,
        events,
        raw_len: payload.len() as u32,
        stored_len: payload.len() as u32,
        ..header
    };
    let mut bytes = clean[..block].to_vec();
    bytes.extend_from_slice(&new_header.fields());
    bytes.extend_from_slice(&new_header.checksum(&payload).to_le_bytes());
    bytes.extend_from_slice(&payload);
    bytes.extend_from_slice(&clean[stored_end..]);
    bytes
}

#[test]
fn a_seekable_trace_records_its_features_in_the_header() {
    let events = every_kind();
    let header = TraceHeader::new(SIDE, SIDE).with_scene("kinds");
    let mut file = Cursor::new(Vec::new());
    let mut writer = TraceWriter::new(&mut file, &header).unwrap();
    for event in &events {
        writer.write_event(event).unwrap();
    }
    let summary = writer.finish_seekable().unwrap();
    let bytes = file.into_inner();
    let reader = TraceReader::new(&bytes[..]).unwrap();
    let features = reader
        .header()
        .features
        .clone()
        .expect("features in the header");
    assert_eq!(features, summary.features);
    // every_kind() begins a verbose query and sets a scissor: the header says so.
    assert!(features.verbose && features.scissor, "{features:?}");
    // The rest of the file is what a plain finish writes: the events read back the same.
    let (read, _) = read_bulk(&bytes).unwrap();
    assert_eq!(read, events);
    // Without seeking, the header keeps no features (the summary has them).
    let plain = write_default(&events);
    assert!(TraceReader::new(&plain[..])
        .unwrap()
        .header()
        .features
        .is_none());

    // A header whose features are not the summary's is refused by a reading of the summary
    // alone (`trace info`, which had checked it in its table but not in its JSON, naming no
    // offset) at the summary, as by a reading of the whole trace. The forgery claims one
    // tile more a query.
    let mut forged = reader.header().clone();
    let tiles = forged.features.as_ref().and_then(|f| f.max_query_tiles);
    assert!(tiles.is_some());
    if let Some(features) = &mut forged.features {
        features.max_query_tiles = tiles.map(|t| t + 1);
    }
    // As the writer pads it to the room it kept (it wrote the header before the features).
    let json = |header: &TraceHeader, room: usize| {
        let mut json = serde_json::to_vec(header).unwrap();
        json.resize(room, b' ');
        json
    };
    let room = (0..512)
        .map(|extra| serde_json::to_vec(reader.header()).unwrap().len() + extra)
        .find(|&room| {
            bytes.starts_with(&block::file_header_bytes(
                FORMAT_VERSION,
                &json(reader.header(), room),
            ))
        })
        .expect("the header as the writer wrote it");
    let written = block::file_header_bytes(FORMAT_VERSION, &json(reader.header(), room));
    let mut edited = block::file_header_bytes(FORMAT_VERSION, &json(&forged, room));
    assert_eq!(edited.len(), written.len());
    edited.extend_from_slice(&bytes[written.len()..]);
    let error = TraceReader::read_summary(Cursor::new(&edited[..])).unwrap_err();
    let trailer = &bytes[bytes.len() - 16..];
    let summary_at = u64::from_le_bytes(trailer[..8].try_into().unwrap());
    assert!(
        matches!(&error, TraceError::BadSummary { offset, .. } if *offset == summary_at),
        "{error:?}"
    );
    assert!(
        error.to_string().contains("the header's features disagree"),
        "{error}"
    );
    assert!(read_bulk(&edited).is_err());
}

/// Every window's size as the trace's window table gives it, and the table's blocks.
fn window_table(bytes: &[u8]) -> Result<(Vec<(u64, u64)>, u64), TraceError> {
    let mut reader = TraceReader::new(bytes)?;
    let mut sizes = std::collections::VecDeque::new();
    let mut blocks = 0;
    while reader.next_window_sizes(&mut sizes)? {
        blocks += 1;
    }
    let pairs = sizes.iter().map(|s| (s.fragments, s.host_until)).collect();
    Ok((pairs, blocks))
}

/// Windows of 0 to 4 fragments each, ended by a swap; every third with host work after its
/// first fragment (the host work ends its host's part: `host_until` = 1 when it has a
/// fragment before it, else 0).
fn many_windows(windows: u64) -> Vec<Event> {
    let mut events = Vec::new();
    for w in 0..windows {
        for i in 0..w % 5 {
            events.push(frag(i as u16, (w % 100) as u16, 7));
            if i == 0 && w % 3 == 0 {
                events.push(Event::HostWork(HostWork::default()));
            }
        }
        events.push(Event::Swap);
    }
    events
}

#[test]
fn the_window_table_holds_every_window_the_events_make() {
    // 3,000 windows of 1 to 2 bytes an entry take more than one 4,096-byte block.
    let events = many_windows(3000);
    let options = WriterOptions {
        block_bytes: 4096,
        ..WriterOptions::default()
    };
    let (bytes, summary) = write(&TraceHeader::new(SIDE, SIDE), options, &events);
    let (table, blocks) = window_table(&bytes).unwrap();
    assert!(blocks >= 2, "{blocks} blocks");
    assert_eq!(summary.window_table.map(|t| t.blocks), Some(blocks));
    // The scout over the events read back: the same sizes, a window for each swap (the
    // last closed by the stream's end).
    let mut scout = WindowScout::default();
    let (read, _) = read_bulk(&bytes).unwrap();
    read.iter().for_each(|event| scout.event(event));
    scout.finish();
    let scouted: Vec<(u64, u64)> = std::iter::from_fn(|| scout.take_ended())
        .map(|s| (s.fragments, s.host_until))
        .collect();
    assert_eq!(table, scouted);
    assert_eq!(table.len(), 3000);
    // By hand: window 3 has 3 fragments and host work after the first; window 4 has 4 and
    // none; window 6 has 1, then host work.
    assert_eq!(&table[3..7], [(3, 1), (4, 0), (0, 0), (1, 1)]);
}

/// The offset of the first block of `kind` in a trace.
fn first_block_of_kind(bytes: &[u8], kind: u8) -> usize {
    super::block::blocks_in(bytes)
        .find(|(_, header)| header.kind == kind)
        .map(|(at, _)| at)
        .expect("a block of the kind")
}

#[test]
fn a_window_table_that_no_stream_makes_is_refused_with_its_offset() {
    let clean = write_default(&many_windows(10));
    let table_at = first_block_of_kind(&clean, 5);
    // A version-7 trace has no window table: its reader says so without reading, and a
    // window-table block in one is an error at the block.
    let old = with_version_field(clean.clone(), 7);
    let mut reader = TraceReader::new(&old[..]).unwrap();
    assert!(!reader.has_window_table());
    assert!(!reader
        .next_window_sizes(&mut std::collections::VecDeque::new())
        .unwrap());
    match read_bulk(&old) {
        Err(TraceError::BadBlock { offset, reason }) => {
            assert_eq!(offset, table_at as u64, "{reason}");
            assert!(reason.contains("version-7"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    // The table's block rewritten, checksum and all, to hold one window whose host work
    // ends after fragment 2 of its 1: refused at the block, its entry at payload byte 0.
    let fields: [u8; BLOCK_HEADER_BYTES] = clean[table_at..table_at + BLOCK_HEADER_BYTES]
        .try_into()
        .unwrap();
    let (header, _) = BlockHeader::parse(&fields).unwrap();
    let payload = [0x01, 0x02];
    let bad = BlockHeader {
        codec: 0,
        events: 1,
        raw_len: 2,
        stored_len: 2,
        ..header
    };
    let end = table_at + BLOCK_HEADER_BYTES + header.stored_len as usize;
    let mut bytes = clean[..table_at].to_vec();
    bytes.extend_from_slice(&bad.fields());
    bytes.extend_from_slice(&bad.checksum(&payload).to_le_bytes());
    bytes.extend_from_slice(&payload);
    bytes.extend_from_slice(&clean[end..]);
    match window_table(&bytes) {
        Err(TraceError::Corrupt {
            offset,
            payload_offset,
            reason,
        }) => {
            assert_eq!((offset, payload_offset), (table_at as u64, 0), "{reason}");
            assert!(reason.contains("host work"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

/// What a rasterizer tells a sink: its events, and before each primitive's fragments the
/// depth plane it told (if any).
#[derive(Default)]
struct Told {
    events: Vec<Event>,
    planes: Vec<(usize, PlaneDepths)>,
}

impl EventSink for Told {
    type Error = std::convert::Infallible;
    fn event(&mut self, event: &Event) -> Result<(), Self::Error> {
        self.events.push(event.clone());
        Ok(())
    }
    fn depth_plane(&mut self, plane: &PlaneDepths) -> Result<(), Self::Error> {
        self.planes.push((self.events.len(), *plane));
        Ok(())
    }
}

/// `scene` (a scene file's text) rasterized by `profile` into `sink`.
fn rasterize<S: EventSink>(scene: &str, profile: RasterProfile, sink: &mut S) -> (u32, u32)
where
    S::Error: std::fmt::Debug,
{
    let lines = crate::scene::parse_scene(scene, "scene").unwrap();
    let crate::scene::Command::Viewport { width, height } = lines[0].command else {
        panic!("no viewport")
    };
    let mut golden = crate::golden::GoldenModel::with_profile(width, height, profile);
    for line in &lines {
        golden.execute(&line.command, sink).unwrap();
    }
    golden.finish(sink).unwrap();
    (width, height)
}

/// A small random scene: 400 triangles, 20 queries.
fn small_random_scene() -> String {
    crate::builtin::random_scene(&crate::builtin::RandomOptions {
        width: 320,
        height: 240,
        triangles: 400,
        queries: 20,
        mean_area_pixels: 600.0,
        seed: 3,
    })
}

#[test]
fn an_llvmpipe_primitives_plane_gives_each_of_its_fragments_depth() {
    // What plane spans rest on: the plane the rasterizer tells a primitive gives every one
    // of its fragments its depth. The exact profile tells none.
    let scenes = [small_random_scene(), crate::builtin::HARDCASES.to_owned()];
    for scene in &scenes {
        for profile in [RasterProfile::Llvmpipe, RasterProfile::LlvmpipeWindow] {
            let mut told = Told::default();
            rasterize(scene, profile, &mut told);
            let (mut plane, mut next, mut checked) = (None, 0, 0);
            for (at, event) in told.events.iter().enumerate() {
                while told.planes.get(next).is_some_and(|&(from, _)| from <= at) {
                    plane = Some(told.planes[next].1);
                    next += 1;
                }
                match event {
                    Event::Primitive => plane = None,
                    Event::Fragment(f) => {
                        let plane = plane.expect("a fragment's primitive told its plane");
                        assert_eq!(plane.depth(f.x, f.y), f.z, "{profile:?} {f:?} {plane:?}");
                        checked += 1;
                    }
                    _ => {}
                }
            }
            assert!(checked > 1000, "{checked} fragments");
        }
        let mut told = Told::default();
        rasterize(scene, RasterProfile::Exact, &mut told);
        assert!(told.planes.is_empty(), "the exact profile told a plane");
    }
}

/// The small random scene's trace, the rasterizer's planes told its writer (blocks of
/// `block_bytes`), and its events.
fn plane_trace(block_bytes: usize) -> (Vec<u8>, Vec<Event>) {
    plane_trace_indexed(block_bytes, None)
}

/// [`plane_trace`] with a window index at `layout` (and so depth-test blocks) where given.
fn plane_trace_indexed(
    block_bytes: usize,
    layout: Option<crate::depth_layout::DepthLayout>,
) -> (Vec<u8>, Vec<Event>) {
    let scene = small_random_scene();
    let mut told = Told::default();
    let (width, height) = rasterize(&scene, RasterProfile::Llvmpipe, &mut told);
    let options = WriterOptions {
        block_bytes,
        zstd_level: 1,
        window_index: layout,
    };
    let mut bytes = Vec::new();
    let mut writer =
        TraceWriter::with_options(&mut bytes, &TraceHeader::new(width, height), options).unwrap();
    rasterize(&scene, RasterProfile::Llvmpipe, &mut writer);
    writer.finish().unwrap();
    (bytes, told.events)
}

/// [`plane_trace`] in blocks of 4 KB with a window index, so with depth-test blocks: what
/// the sampled level's machines read from anywhere.
fn plane_trace_with_depth_tests() -> (Vec<u8>, Vec<Event>) {
    let layout = crate::depth_layout::DepthLayout {
        tile_width_pixels: 32,
        tile_height_pixels: 32,
        pixels_per_word: 8,
        banks: 2,
    };
    plane_trace_indexed(4096, Some(layout))
}

#[test]
fn plane_spans_read_back_by_both_paths_and_shrink_the_trace() {
    for block_bytes in [4096, super::writer::DEFAULT_BLOCK_BYTES] {
        let (bytes, events) = plane_trace(block_bytes);
        for read in [read_bulk as ReadPath, read_one_by_one] {
            assert_eq!(
                read(&bytes).unwrap().0,
                events,
                "blocks of {block_bytes} bytes"
            );
        }
        // The same events told no plane: every span keeps its depths.
        let options = WriterOptions {
            block_bytes,
            zstd_level: 1,
            window_index: None,
        };
        let (without, _) = write(&TraceHeader::new(320, 240), options, &events);
        assert_eq!(read_bulk(&without).unwrap().0, events);
        assert!(
            bytes.len() * 2 < without.len(),
            "with planes {} bytes, without {}",
            bytes.len(),
            without.len()
        );
    }
}

#[test]
fn plane_spans_are_handed_out_from_any_fragment_on_with_their_depth_tests() {
    // A reader that starts mid-block passes over the spans before its start (their depths
    // neither kept nor evaluated): from anywhere, in pieces with gaps, it hands out the
    // fragments a read from the start does, with the same results.
    let (bytes, events) = plane_trace_with_depth_tests();
    let take = |fragments: &mut TestedFragments<&[u8]>, count, got: &mut Vec<(Fragment, bool)>| {
        super::depth_tests::tests::take_into(fragments, count, got).unwrap()
    };
    let fresh = || TestedFragments::new(TraceReader::new(&bytes[..]).unwrap()).unwrap();
    let told: Vec<Fragment> = events
        .iter()
        .filter_map(|event| match event {
            Event::Fragment(f) => Some(*f),
            _ => None,
        })
        .collect();
    let mut whole = Vec::new();
    take(&mut fresh(), told.len() as u64, &mut whole);
    let fragments: Vec<Fragment> = whole.iter().map(|&(f, _)| f).collect();
    assert_eq!(fragments, told);
    assert!(whole.iter().any(|&(_, passed)| passed) && whole.iter().any(|&(_, passed)| !passed));
    let mut rng = crate::rng::SplitMix64(7);
    let all = told.len() as u64;
    for _ in 0..40 {
        let mut fragments = fresh();
        let mut at = rng.below(all);
        fragments.skip(at);
        while at < all {
            let count = (1 + rng.below(500)).min(all - at);
            let mut got = Vec::new();
            take(&mut fragments, count, &mut got);
            assert_eq!(got, whole[at as usize..(at + count) as usize], "from {at}");
            let gap = rng.below(3000).min(all - at - count);
            fragments.skip(gap);
            at += count + gap;
        }
    }
}

#[test]
fn a_span_its_plane_does_not_give_keeps_its_depths() {
    // One plane told; the first and last spans have its depths, the middle one differs at
    // one pixel (a plane the rasterizer got wrong would: the trace stays exact).
    let plane = PlaneDepths {
        a0: 0.25,
        dzdx: 0.001,
        dzdy: -0.0005,
        mirror: Some(99),
    };
    let row = |y: u16, odd: Option<u16>| -> Vec<Event> {
        (10..40u16)
            .map(|x| frag(x, y, plane.depth(x, y) + u32::from(Some(x) == odd)))
            .collect()
    };
    let mut events = vec![Event::Primitive];
    events.extend(row(5, None));
    events.extend(row(6, Some(17)));
    events.extend(row(7, None));
    let mut bytes = Vec::new();
    let mut writer = TraceWriter::new(&mut bytes, &TraceHeader::new(100, 100)).unwrap();
    writer.write_event(&events[0]).unwrap();
    writer.depth_plane(&plane).unwrap();
    for event in &events[1..] {
        writer.write_event(event).unwrap();
    }
    writer.finish().unwrap();
    for read in [read_bulk as ReadPath, read_one_by_one] {
        assert_eq!(read(&bytes).unwrap().0, events);
    }
}

#[test]
fn a_plane_span_before_any_plane_in_its_block_is_named_with_its_offset() {
    // A block whose payload is one plane span of one fragment at (0, 0): tag, dy, dx and
    // length less one, and no plane record before it.
    let bytes = with_first_payload(&plane_trace(4096).0, |payload, events| {
        *payload = vec![tag::PLANE_SPAN, 0, 0, 0];
        *events = 1;
    });
    for read in [read_bulk as ReadPath, read_one_by_one] {
        let error = read(&bytes).unwrap_err().to_string();
        assert!(
            error.contains("a plane span before any plane in its block"),
            "{error}"
        );
        // The block's offset, and the span's tag the payload's first byte.
        let at = format!(
            "byte {}: corrupt block payload at decoded byte 0",
            first_block_offset(&bytes)
        );
        assert!(error.contains(&at), "{error} (expected {at})");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn damaged_plane_payloads_never_panic_and_both_read_paths_agree(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
    ) {
        let bytes = with_first_payload(&plane_trace(4096).0, |payload, _| {
            for (at, value) in &flips {
                let at = at.index(payload.len());
                payload[at] = *value;
            }
        });
        read_anything(&bytes);
        let outcome = |read: ReadPath| read(&bytes).map_err(|error| error.to_string());
        prop_assert_eq!(outcome(read_bulk), outcome(read_one_by_one));
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(100))]

    #[test]
    fn damaged_plane_payloads_read_from_any_fragment_on_never_panic(
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..4),
        from in 0u64..3000,
        count in 1u64..3000,
    ) {
        // The sampled level's reader, which passes over the spans before its start, meets
        // damage in the block it starts in (the first, an event block of about 11,000
        // fragments; a fifth of such damage is an error): fragments or an error, never a
        // panic.
        let clean = plane_trace_with_depth_tests().0;
        let bytes = with_first_payload(&clean, |payload, _| {
            for (at, value) in &flips {
                let at = at.index(payload.len());
                payload[at] = *value;
            }
        });
        if let Ok(mut fragments) = TraceReader::new(&bytes[..]).and_then(TestedFragments::new) {
            fragments.skip(from);
            let _ = fragments.take(count, |_, _| Ok::<(), std::convert::Infallible>(()));
        }
    }
}

#[test]
fn an_event_block_of_plane_spans_holds_at_most_its_events() {
    // Plane spans take a few bytes a row, so 64 KB of them would hold hundreds of thousands
    // of fragments: the writer cuts blocks at BLOCK_EVENTS events too.
    let (bytes, events) = plane_trace(super::writer::DEFAULT_BLOCK_BYTES);
    let counts: Vec<u32> = super::block::blocks_in(&bytes)
        .filter(|(_, header)| header.kind == super::block::KIND_EVENTS)
        .map(|(_, header)| header.events)
        .collect();
    let fragments = events
        .iter()
        .filter(|e| matches!(e, Event::Fragment(_)))
        .count();
    // The scene's fragments need two blocks at least (it has more than BLOCK_EVENTS).
    assert!(
        fragments > super::writer::BLOCK_EVENTS,
        "{fragments} fragments"
    );
    assert!(counts.len() >= 2, "{counts:?}");
    assert!(
        counts
            .iter()
            .all(|&n| n as usize <= super::writer::BLOCK_EVENTS),
        "{counts:?}"
    );
    assert_eq!(
        counts.iter().map(|&n| n as u64).sum::<u64>(),
        events.len() as u64
    );
}

/// `bytes` with its summary's JSON changed by `edit` and its checksum made right again, as
/// a forger would (the summary block is stored, not compressed).
fn with_forged_summary(bytes: &[u8], edit: impl FnOnce(&mut serde_json::Value)) -> Vec<u8> {
    let trailer_at = bytes.len() - block::TRAILER_BYTES;
    let summary_at = u64::from_le_bytes(bytes[trailer_at..trailer_at + 8].try_into().unwrap());
    let at = summary_at as usize;
    let header_bytes: [u8; BLOCK_HEADER_BYTES] =
        bytes[at..at + BLOCK_HEADER_BYTES].try_into().unwrap();
    let (mut header, _) = BlockHeader::parse(&header_bytes).unwrap();
    let json_at = at + BLOCK_HEADER_BYTES;
    let mut summary: serde_json::Value =
        serde_json::from_slice(&bytes[json_at..json_at + header.stored_len as usize]).unwrap();
    edit(&mut summary);
    let json = serde_json::to_vec(&summary).unwrap();
    (header.raw_len, header.stored_len) = (json.len() as u32, json.len() as u32);
    let mut forged = bytes[..at].to_vec();
    forged.extend_from_slice(&header.fields());
    forged.extend_from_slice(&header.checksum(&json).to_le_bytes());
    forged.extend_from_slice(&json);
    forged.extend_from_slice(&(summary_at).to_le_bytes());
    forged.extend_from_slice(&block::END_MAGIC);
    forged
}

/// A summary forged to claim other counts, its checksum made right: a trace read by its
/// window index or by its band index is refused as one read by its events is, naming the
/// count. (The index readers had taken the summary as written: one claiming 2^40 queries
/// passed the analytic and sampled levels.) The stream: a brief query over two primitives
/// of 3 and 2 fragments: 5 fragments, 2 primitives, 1 query.
#[test]
fn a_forged_summary_is_refused_by_every_reading() {
    let frag = |x, y| Event::Fragment(Fragment { x, y, z: 100 });
    let query = QuerySpec {
        id: 1,
        mode: QueryMode::Brief,
        buffer_entries: 8,
        tiles: vec![Rect::new(0, 0, 16, 16)],
    };
    let events = [
        Event::QueryBegin(query),
        Event::Primitive,
        frag(0, 0),
        frag(1, 0),
        frag(2, 0),
        Event::Primitive,
        frag(4, 4),
        frag(4, 5),
        Event::QueryEnd,
    ];
    let bytes = super::index::tests::indexed(&events);
    let truth = read_whole_as("events", &bytes).unwrap();
    assert_eq!(
        (truth.fragments, truth.primitives, truth.queries),
        (5, 2, 1)
    );
    let indexes = ["window index", "window index skimmed", "band index"];
    for reading in indexes {
        assert_eq!(read_whole_as(reading, &bytes).unwrap(), truth, "{reading}");
    }
    let refused = |bytes: &[u8], readings: &[&str], wanted: &str| {
        for &reading in readings {
            let error = read_whole_as(reading, bytes)
                .expect_err(reading)
                .to_string();
            assert!(error.contains(wanted), "{reading}: {error}");
        }
    };
    // Forged consistently (2^40 brief queries, and events enough for them), so that only
    // what was read can refuse them.
    for (field, claim) in [("queries", 1u64 << 40), ("fragments", 6), ("primitives", 3)] {
        let forged = with_forged_summary(&bytes, |summary| {
            summary[field] = claim.into();
            if field == "queries" {
                summary["queries_by_mode"]["brief"] = claim.into();
                summary["events"] = (1u64 << 41).into();
            }
        });
        let wanted = format!("{field} (summary {claim}, trace ");
        refused(&forged, &["events"], &wanted);
        refused(&forged, &indexes, &wanted);
    }
    // Forged carelessly, the summary disagrees with itself: refused whoever reads it, the
    // summary alone too (`trace info`, which had printed 2^40 queries, 1 of them brief).
    let careless = with_forged_summary(&bytes, |summary| summary["queries"] = (1u64 << 40).into());
    let wanted = "1099511627776 queries, but 1 by mode";
    refused(&careless, &["events"], wanted);
    refused(&careless, &indexes, wanted);
    let alone = TraceReader::read_summary(Cursor::new(&careless)).unwrap_err();
    assert!(alone.to_string().contains(wanted), "{alone}");
    // Both indexes cut out, and the summary's count of their blocks made 0: read by either
    // index, nothing is read, and the summary's counts are refused (the trace had replayed
    // as 0 cycles of 0 queries); read by events, the trace is what it says.
    let cut = with_forged_summary(&without_index_blocks(&bytes), |summary| {
        let none = serde_json::json!({"blocks": 0, "payload_bytes": 0, "stored_bytes": 0});
        summary["window_index"] = none.clone();
        summary["bands"] = none;
    });
    assert_eq!(read_whole_as("events", &cut).unwrap().queries, 1);
    refused(&cut, &indexes, "fragments (summary 5, trace 0)");
}

/// `bytes` read whole as `reading` reads them (`events`, `window index`, `window index
/// skimmed`, as the O2's analytic level reads it, or `band index`), to the summary.
fn read_whole_as(reading: &str, bytes: &[u8]) -> Result<TraceSummary, TraceError> {
    let mut reader = TraceReader::new(bytes)?;
    let nothing = |_: &IndexItem| Ok::<(), std::convert::Infallible>(());
    match reading {
        "events" => {
            return reader
                .read_into(&mut Vec::new())
                .map_err(ReadError::into_trace)
        }
        "window index skimmed" => {
            reader.skim_queries();
            reader.for_each_index_item(nothing)
        }
        "window index" => reader.for_each_index_item(nothing),
        _ => reader.for_each_band_item(nothing),
    }
    .map_err(ReadError::into_trace)?;
    reader.skip_to_summary()
}

/// `bytes` without its window-index and band-index blocks (the trailer pointed at the
/// summary again; the summary itself as it was).
fn without_index_blocks(bytes: &[u8]) -> Vec<u8> {
    let mut out = bytes[..block::first_block_offset(bytes).unwrap()].to_vec();
    for (at, header) in block::blocks_in(bytes) {
        let end = at + BLOCK_HEADER_BYTES + header.stored_len as usize;
        if header.kind == block::KIND_SUMMARY {
            let summary_at = out.len() as u64;
            out.extend_from_slice(&bytes[at..end]);
            out.extend_from_slice(&summary_at.to_le_bytes());
            out.extend_from_slice(&block::END_MAGIC);
            return out;
        }
        if header.kind != block::KIND_INDEX && header.kind != block::KIND_BANDS {
            out.extend_from_slice(&bytes[at..end]);
        }
    }
    panic!("no summary block");
}

/// A header whose depth format occsim does not read, or whose sub-pixel bits no rasterizer
/// keeps, is refused at offset 16 (the header JSON), its checksum right: the depths would
/// be read as unorm24 whatever the header said.
#[test]
fn a_header_of_another_depth_format_or_absurd_sub_pixel_bits_is_refused() {
    let header = |edit: &dyn Fn(&mut TraceHeader)| {
        let mut header = TraceHeader::new(16, 16);
        edit(&mut header);
        block::file_header_bytes(FORMAT_VERSION, &serde_json::to_vec(&header).unwrap())
    };
    let read = |bytes: Vec<u8>| TraceReader::new(&bytes[..]).map(|_| ());
    // The header as written reads (the blocks after it are not read yet), and so do 4 and
    // 16 sub-pixel bits, another rasterizer's.
    assert!(read(header(&|_| {})).is_ok());
    assert!(read(header(&|h| h.subpixel_bits = 4)).is_ok());
    assert!(read(header(&|h| h.subpixel_bits = 16)).is_ok());
    for (edit, wanted) in [
        (
            &(|h: &mut TraceHeader| h.depth_format = "float32".to_owned()) as &dyn Fn(&mut _),
            "depth format \"float32\": occsim reads \"unorm24\" depths only",
        ),
        (
            &|h: &mut TraceHeader| h.subpixel_bits = 200,
            "200 sub-pixel bits: more than 16",
        ),
    ] {
        let error = read(header(edit)).unwrap_err();
        assert!(
            matches!(error, TraceError::BadHeader { offset: 16, .. }),
            "{error:?}"
        );
        assert!(error.to_string().contains(wanted), "{error}");
    }
}
