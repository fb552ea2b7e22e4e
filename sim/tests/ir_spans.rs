//! The InfiniteReality-like machine takes a span of fragments as it takes the span's
//! fragments one by one ([`IrMachine::span`]: the row's depth tests at once, its
//! interleave units stepped along it): fed the same streams both ways, every interleave,
//! board count and Occlusion Unit fidelity gives the same report, bit for bit, and a span
//! that leaves the viewport the same error.

mod support;

use occsim_sim::{Arch, IrMachine, MachineBuilder, OccuModel, Report, SimError};
use occsim_traces::builtin::{demo_scene, random_scene, DemoOptions, RandomOptions, HARDCASES};
use occsim_traces::rng::SplitMix64;
use occsim_traces::{Event, Fragment, Span};
use support::scene_events;

/// An event, or a run of fragments along a row fed as one span.
enum Item {
    Event(Event),
    Span { x: u16, y: u16, depths: Vec<u32> },
}

/// `events` with each run of fragments that follow one another along a row cut into spans
/// of random lengths from 1 to 700 (wider than ir1's 80 units and ir2's 160, so that some
/// spans wrap past the last unit).
fn spans_of(events: &[Event], seed: u64) -> Vec<Item> {
    let mut rng = SplitMix64(seed);
    let mut items = Vec::new();
    let mut open: Option<(u16, u16, Vec<u32>, usize)> = None;
    for event in events {
        if let Event::Fragment(f) = event {
            if let Some((x, y, depths, cut)) = &mut open {
                if *y == f.y && *x as usize + depths.len() == f.x as usize && depths.len() < *cut {
                    depths.push(f.z);
                    continue;
                }
            }
            if let Some((x, y, depths, _)) = open.take() {
                items.push(Item::Span { x, y, depths });
            }
            let cut = [1, 2, 7, 64, 300, 700][rng.below(6) as usize];
            open = Some((f.x, f.y, vec![f.z], cut));
            continue;
        }
        if let Some((x, y, depths, _)) = open.take() {
            items.push(Item::Span { x, y, depths });
        }
        items.push(Item::Event(event.clone()));
    }
    if let Some((x, y, depths, _)) = open.take() {
        items.push(Item::Span { x, y, depths });
    }
    items
}

fn machine(arch: &Arch, occu: OccuModel, width: u32, height: u32) -> IrMachine {
    MachineBuilder::new(arch)
        .occu(occu)
        .ir(width, height)
        .expect("an ir machine")
}

/// The report of `events` fed one by one.
fn one_by_one(
    arch: &Arch,
    occu: OccuModel,
    (width, height): (u32, u32),
    events: &[Event],
) -> Report {
    let mut machine = machine(arch, occu, width, height);
    for event in events {
        machine.event(event).expect("replays");
    }
    machine.finish().expect("finishes")
}

/// The report of `items`, its spans fed whole.
fn in_spans(arch: &Arch, occu: OccuModel, (width, height): (u32, u32), items: &[Item]) -> Report {
    let mut machine = machine(arch, occu, width, height);
    for item in items {
        match item {
            Item::Event(event) => machine.event(event),
            Item::Span { x, y, depths } => machine.span(Span {
                x: *x,
                y: *y,
                depths,
            }),
        }
        .expect("replays");
    }
    machine.finish().expect("finishes")
}

fn arch(name: &str, interleave: &str) -> Arch {
    let mut arch = Arch::builtin(name).expect("built in");
    arch.set(&format!("interleave={interleave}"))
        .expect("an interleave");
    arch
}

#[test]
fn spans_give_what_their_fragments_one_by_one_give() {
    // The hard cases (every query mode, verbose buffers that overflow, queries of many
    // tiles), a small demo (brief queries over whole objects) and random triangles under
    // samples queries.
    let scenes = [
        ("hardcases", HARDCASES.to_owned()),
        (
            "demo",
            demo_scene(&DemoOptions {
                width: 160,
                height: 120,
                frames: 1,
                lots_per_side: 4,
                ..DemoOptions::default()
            }),
        ),
        (
            "random",
            random_scene(&RandomOptions {
                width: 320,
                height: 240,
                triangles: 300,
                queries: 30,
                ..RandomOptions::default()
            }),
        ),
    ];
    for (seed, (scene, text)) in scenes.iter().enumerate() {
        let (width, height, events) = scene_events(text);
        let items = spans_of(&events, seed as u64);
        let spans = items
            .iter()
            .filter(|item| matches!(item, Item::Span { depths, .. } if depths.len() > 1))
            .count();
        assert!(
            spans > 10,
            "{scene}: only {spans} spans of two fragments or more"
        );
        for name in ["ir1", "ir2", "ir4"] {
            for interleave in ["columns", "blocks", "morton"] {
                let arch = arch(name, interleave);
                let viewport = (width, height);
                let expected = one_by_one(&arch, OccuModel::Cycle, viewport, &events);
                let got = in_spans(&arch, OccuModel::Cycle, viewport, &items);
                assert_eq!(got, expected, "{scene} on {name} ({interleave})");
            }
        }
    }
    // The rtl Occlusion Units take the same fragments.
    let (width, height, events) = scene_events(HARDCASES);
    let items = spans_of(&events, 7);
    let arch = arch("ir2", "columns");
    let rtl = || OccuModel::Rtl { waveform: None };
    assert_eq!(
        in_spans(&arch, rtl(), (width, height), &items),
        one_by_one(&arch, rtl(), (width, height), &events),
        "hardcases on ir2 at the rtl level"
    );
}

#[test]
fn a_span_that_leaves_the_viewport_is_the_error_its_fragment_is() {
    // An 8x2 viewport: a span of three fragments from x = 6 on row 1 has its third at x = 8,
    // outside; fed one by one, that fragment is event 3 (events count from 0: the
    // primitive, then the fragments at 6, 7 and 8), and so it is in the span.
    let arch = Arch::builtin("ir1").expect("built in");
    let depths = [5, 5, 5];
    let fragments: Vec<Event> = (6..9)
        .map(|x| Event::Fragment(Fragment { x, y: 1, z: 5 }))
        .collect();
    let mut single = machine(&arch, OccuModel::Cycle, 8, 2);
    single.event(&Event::Primitive).expect("a primitive");
    let expected = fragments
        .iter()
        .try_for_each(|event| single.event(event))
        .unwrap_err();
    let mut spanned = machine(&arch, OccuModel::Cycle, 8, 2);
    spanned.event(&Event::Primitive).expect("a primitive");
    let got = spanned
        .span(Span {
            x: 6,
            y: 1,
            depths: &depths,
        })
        .unwrap_err();
    assert!(
        matches!(
            got,
            SimError::FragmentOutside {
                event: 3,
                x: 8,
                y: 1,
                ..
            }
        ),
        "{got}"
    );
    assert_eq!(got.to_string(), expected.to_string());
}
