//! Closed-loop replay against open-loop replay of the same city walkthrough, in the same run:
//! the hierarchical driver's trace (its geometry batches, host work, waits and frame ends)
//! replayed as it is and with those records stripped, on the O2-like and `ir4` machines.
//! Prints both wall times and the ratio (aim: the closed loop at most 1.2x slower).
//!
//! Run: `cargo bench -p occsim-sim --bench closed_loop`

use occsim_sim::{Arch, MachineModel};
use occsim_traces::raster::RasterProfile;
use occsim_traces::workloads::{city, generate, CityOptions, DriverKind, DriverOptions, Walk};
use occsim_traces::Event;
use std::time::Instant;

const REPEATS: usize = 5;

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
        "city hierarchical walkthrough, 2 frames at 1280x1024: {} events ({} closed-loop records), {fragments} fragments; best of {REPEATS}",
        closed.len(),
        closed.len() - open.len()
    );
    for name in ["o2", "ir4"] {
        let arch = Arch::builtin(name).expect("built-in architecture");
        let open_s = best_of(&arch, &walk, &open);
        let closed_s = best_of(&arch, &walk, &closed);
        println!(
            "{name:<4}: open loop {open_s:.3} s, closed loop {closed_s:.3} s: {:.3}x",
            closed_s / open_s
        );
    }
}

/// The fastest of `REPEATS` replays of `events`, in seconds.
fn best_of(arch: &Arch, walk: &Walk, events: &[Event]) -> f64 {
    (0..REPEATS)
        .map(|_| {
            let start = Instant::now();
            let mut machine = MachineModel::new(arch, walk.width, walk.height).expect("machine");
            for event in events {
                machine
                    .event(event)
                    .expect("replay matches the golden model");
            }
            std::hint::black_box(machine.finish().expect("report"));
            start.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}
