//! Closed-loop replay against open-loop replay of the same city walkthrough, in the same run:
//! the hierarchical driver's trace (its geometry batches, host work, waits and frame ends)
//! replayed as it is and with those records stripped, on the O2-like and `ir4` machines.
//! Prints both wall times and the ratio (aim: the closed loop at most 1.2x slower).
//!
//! Run: `cargo bench -p occsim-sim --bench closed_loop`

use occsim_sim::{Arch, MachineModel};
use occsim_traces::raster::RasterProfile;
use occsim_traces::rounds::fastest_of_rounds;
use occsim_traces::workloads::{city, generate, CityOptions, DriverKind, DriverOptions, Walk};
use occsim_traces::Event;

/// Rounds in which the open and the closed loop take turns; each keeps its fastest run.
const ROUNDS: usize = 5;

fn main() {
    let scene = city(&CityOptions::default());
    let walk = Walk {
        frames: 2,
        width: 1280,
        height: 1024,
        raster: RasterProfile::default(),
    };
    let mut closed: Vec<Event> = Vec::new();
    generate(
        &scene,
        &DriverOptions::new(DriverKind::Hierarchical),
        &walk,
        &mut closed,
    )
    .expect("the walkthrough generates");
    let open: Vec<Event> = closed
        .iter()
        .filter(|e| !e.is_closed_loop_record())
        .cloned()
        .collect();
    let fragments = closed
        .iter()
        .filter(|e| matches!(e, Event::Fragment(_)))
        .count();
    println!(
        "city hierarchical walkthrough, 2 frames at 1280x1024: {} events ({} closed-loop records), {fragments} fragments; fastest of {ROUNDS} interleaved rounds",
        closed.len(),
        closed.len() - open.len()
    );
    for name in ["o2", "ir4"] {
        let arch = Arch::builtin(name).expect("built-in architecture");
        let (arch, walk) = (&arch, &walk);
        let mut jobs = [&open, &closed].map(|events| move || replay(arch, walk, events));
        let figures = fastest_of_rounds(ROUNDS, 0.0, &mut jobs);
        let (open_s, closed_s) = (figures[0].seconds, figures[1].seconds);
        println!(
            "{name:<4}: open loop {open_s:.3} s, closed loop {closed_s:.3} s: {:.3}x",
            closed_s / open_s
        );
    }
}

/// One replay of `events` on a fresh machine.
fn replay(arch: &Arch, walk: &Walk, events: &[Event]) {
    let mut machine = MachineModel::new(arch, walk.width, walk.height).expect("machine");
    for event in events {
        machine
            .event(event)
            .expect("replay matches the golden model");
    }
    std::hint::black_box(machine.finish().expect("report"));
}
