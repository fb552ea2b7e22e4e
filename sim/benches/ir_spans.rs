//! What taking a span whole saves the InfiniteReality-like machine
//! ([`occsim_sim::IrMachine::span`]: the row's depth tests at once, its interleave units
//! stepped along it): the demo's stream (27.3 M fragments, decoded once into memory as a
//! trace's reader hands it on, events and rows of fragments) fed to the cycle-level
//! machine on ir1 and ir4 span by span against fragment by fragment (the machine's path
//! before). Prints each feed's seconds, fragments per second and the ratio; the reports are
//! checked equal.
//!
//! Run: `cargo bench -p occsim-sim --bench ir_spans`

use occsim_sim::{Arch, IrMachine, Report};
use occsim_traces::golden::EventSink;
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::trace::TraceReader;
use occsim_traces::{Event, Span};
use std::convert::Infallible;

#[path = "support/demo.rs"]
mod demo;

use demo::demo_trace;

/// Rounds in which both feeds take their turn; each keeps its fastest run.
const ROUNDS: usize = 3;

/// An event, or a row of fragments as the trace's reader hands it on.
enum Item {
    Event(Event),
    Span { x: u16, y: u16, depths: Vec<u32> },
}

/// Every item of a stream, kept.
#[derive(Default)]
struct Items(Vec<Item>);

impl EventSink for Items {
    type Error = Infallible;

    fn event(&mut self, event: &Event) -> Result<(), Infallible> {
        self.0.push(Item::Event(event.clone()));
        Ok(())
    }

    fn span(&mut self, span: Span) -> Result<(), Infallible> {
        self.0.push(Item::Span {
            x: span.x,
            y: span.y,
            depths: span.depths.to_vec(),
        });
        Ok(())
    }
}

/// The demo's stream as `occsim replay` reads it from `occsim trace gen demo`'s file.
fn demo_items() -> (u32, u32, Vec<Item>) {
    let bytes = demo_trace();
    let mut reader = TraceReader::new(&bytes[..]).expect("a trace");
    let (width, height) = (reader.header().width, reader.header().height);
    let mut items = Items::default();
    reader.read_into(&mut items).expect("reads");
    (width, height, items.0)
}

/// The machine's report of `items`, each span fed whole or its fragments one by one.
fn feed(arch: &Arch, (width, height): (u32, u32), items: &[Item], whole: bool) -> Report {
    let mut machine = IrMachine::new(arch, width, height).expect("an ir machine");
    for item in items {
        match item {
            Item::Event(event) => machine.event(event),
            Item::Span { x, y, depths } => {
                let span = Span {
                    x: *x,
                    y: *y,
                    depths,
                };
                if whole {
                    machine.span(span)
                } else {
                    span.fragments()
                        .try_for_each(|fragment| machine.event(&Event::Fragment(fragment)))
                }
            }
        }
        .expect("replays");
    }
    machine.finish().expect("finishes")
}

fn main() {
    let (width, height, items) = demo_items();
    let fragments: usize = items
        .iter()
        .map(|item| match item {
            Item::Span { depths, .. } => depths.len(),
            Item::Event(Event::Fragment(_)) => 1,
            Item::Event(_) => 0,
        })
        .sum();
    println!(
        "demo, {fragments} fragments, cycle-level machine, fastest of {ROUNDS} interleaved rounds"
    );
    for name in ["ir1", "ir4"] {
        let arch = Arch::builtin(name).expect("built-in architecture");
        let viewport = (width, height);
        let mut jobs: Vec<_> = [false, true]
            .map(|whole| {
                let (arch, items) = (&arch, &items);
                move || feed(arch, viewport, items, whole)
            })
            .into_iter()
            .collect();
        let figures = fastest_of_rounds(ROUNDS, 0.0, &mut jobs);
        let (single, whole) = (&figures[0], &figures[1]);
        assert_eq!(
            single.output, whole.output,
            "{name}: spans changed the report"
        );
        println!(
            "{name:<4} fragment by fragment {:.3} s ({:.1} M fragments/s), spans whole {:.3} s ({:.1} M fragments/s): {:.2}x",
            single.seconds,
            fragments as f64 / single.seconds / 1e6,
            whole.seconds,
            fragments as f64 / whole.seconds / 1e6,
            single.seconds / whole.seconds,
        );
    }
}
