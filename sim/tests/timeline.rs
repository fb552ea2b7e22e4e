//! The timeline recorder on a hand-worked stream: the slices the O2's blocks report.

use occsim_sim::timeline::{PortLane, QuerySlice, Slice, State, Timeline, TimelineSink, Track};
use occsim_sim::{Arch, MachineBuilder};
use occsim_traces::{Event, Fragment, QueryMode, QuerySpec, Rect};
use std::sync::{Arc, Mutex};

#[derive(Default)]
struct Collected {
    slices: Vec<Slice>,
    queries: Vec<QuerySlice>,
}

struct Collect(Arc<Mutex<Collected>>);

impl TimelineSink for Collect {
    fn slice(&mut self, slice: Slice) {
        self.0.lock().unwrap().slices.push(slice);
    }
    fn query(&mut self, query: QuerySlice) {
        self.0.lock().unwrap().queries.push(query);
    }
}

#[test]
fn hand_worked_o2_slices() {
    // One brief query, one tile, two fragments reading the same depth word, no primitive
    // setup (no `Primitive` event). The rasterizer emits them in cycles 0 and 1: one busy
    // slice 0..2. Fragment 0 arrives at the depth test in 1; its read is requested in 1,
    // granted in 1 and, the first read (a page miss), ready in 1 + 8 = 9: the depth
    // pipeline is stalled 1..9 and tests in 9; fragment 1 reuses the word and tests in 10:
    // busy 9..11. The Occlusion Unit takes each the cycle after its test, one cycle each
    // (one tile): busy 10..12.
    let mut arch = Arch::builtin("o2").unwrap();
    arch.set("engines=1").unwrap();
    arch.set("page_miss_latency_cycles=8").unwrap();
    let slices = Arc::new(Mutex::new(Collected::default()));
    let timeline = Timeline::new(Box::new(Collect(slices.clone())), 0..u64::MAX);
    let mut machine = MachineBuilder::new(&arch)
        .timeline(timeline.clone())
        .build(16, 16)
        .unwrap();
    let events = [
        Event::QueryBegin(QuerySpec {
            id: 1,
            mode: QueryMode::Brief,
            buffer_entries: 8,
            tiles: vec![Rect::new(0, 0, 4, 4)],
        }),
        Event::Fragment(Fragment { x: 1, y: 1, z: 0 }),
        Event::Fragment(Fragment { x: 2, y: 1, z: 0 }),
        Event::QueryEnd,
    ];
    for event in &events {
        machine.event(event).unwrap();
    }
    machine.finish().unwrap();
    timeline.flush();
    let mut got = slices.lock().unwrap().slices.clone();
    got.sort_by_key(|s| (s.track, s.start));
    let slice = |track, state, start, end| Slice {
        track,
        state,
        start,
        end,
    };
    assert_eq!(
        got,
        [
            slice(Track::Rasterizer, State::Busy, 0, 2),
            slice(Track::DepthPipeline, State::Stalled, 1, 9),
            slice(Track::DepthPipeline, State::Busy, 9, 11),
            slice(Track::OcclusionUnit, State::Busy, 10, 12),
            // The one engine holds the one tile: busy with the unit.
            slice(Track::Engine(0), State::Busy, 10, 12),
            // The end token leaves the depth pipeline in 11 (the pipe free after fragment
            // 1's test in 10); the unit is free in 12, the record's 8 words enter OccU
            // Control's buffer in 13 and go out in one 256-bit port cycle, 14.
            slice(Track::OccuControl, State::Busy, 11, 15),
            // The port: fragment 0's depth read in 1 (fragment 1 reuses the word; a brief
            // query is an occlusion render mode, so passing fragments write no depth), and
            // the record in 14.
            slice(Track::MemoryPort(PortLane::DepthReads), State::Busy, 1, 2),
            slice(
                Track::MemoryPort(PortLane::OccuControl),
                State::Busy,
                14,
                15
            ),
        ]
    );
    // The query: its begin entered the pipe before any fragment (0), its end after the
    // rasterizer emitted both (2); the result is available after the record's grant (15).
    assert_eq!(
        slices.lock().unwrap().queries,
        [QuerySlice {
            id: 1,
            mode: QueryMode::Brief,
            tiles: 1,
            begin_cycle: 0,
            end_cycle: 2,
            available_cycle: 15,
        }]
    );
}
