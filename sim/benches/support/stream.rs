//! The benchmark stream the sim benches share: frames of random rectangles drawn row by row
//! (as spans leave a rasterizer) under samples, 16-tile brief and 4-tile verbose queries,
//! with the golden model's results inserted after every query end.
// Each bench uses a part of it.
#![allow(dead_code)]

use occsim_traces::golden::FunctionalModel;
use occsim_traces::{DepthFunc, Event, Fragment, QueryMode, QuerySpec, Rect};

/// Viewport of the stream, in pixels.
pub const WIDTH: u32 = 640;
pub const HEIGHT: u32 = 480;

use occsim_traces::rng::SplitMix64 as Rng;

/// Rectangles drawn row by row, as spans leave a rasterizer.
pub fn rectangle(rng: &mut Rng, max_side: u64, events: &mut Vec<Event>) {
    let w = 4 + rng.below(max_side) as u32;
    let h = 4 + rng.below(max_side) as u32;
    let x0 = rng.below((WIDTH - w) as u64) as u32;
    let y0 = rng.below((HEIGHT - h) as u64) as u32;
    let z = rng.below(1 << 24) as u32;
    events.push(Event::Primitive);
    for y in y0..y0 + h {
        for x in x0..x0 + w {
            events.push(Event::Fragment(Fragment {
                x: x as u16,
                y: y as u16,
                z,
            }));
        }
    }
}

pub fn grid(columns: u32, rows: u32) -> Vec<Rect> {
    let (w, h) = (WIDTH / columns, HEIGHT / rows);
    (0..rows)
        .flat_map(|r| (0..columns).map(move |c| Rect::new(c * w, r * h, w, h)))
        .collect()
}

/// One frame: occluders drawn plainly, then samples, brief (16-tile grid) and verbose
/// (4-tile) queries over boxes, with the golden results in the stream.
pub fn frame(seed: u64) -> Vec<Event> {
    let mut rng = Rng(seed);
    let mut raw = vec![Event::Clear, Event::DepthFunc(DepthFunc::Less)];
    for _ in 0..60 {
        rectangle(&mut rng, 120, &mut raw);
    }
    for q in 0..120u32 {
        let (mode, tiles, buffer_entries) = match q % 3 {
            0 => (QueryMode::Samples, vec![Rect::new(0, 0, WIDTH, HEIGHT)], 8),
            1 => (QueryMode::Brief, grid(4, 4), 8),
            _ => (QueryMode::Verbose, grid(2, 2), 8 + 64),
        };
        raw.push(Event::QueryBegin(QuerySpec {
            id: q,
            mode,
            buffer_entries,
            tiles,
        }));
        for _ in 0..2 {
            rectangle(&mut rng, 60, &mut raw);
        }
        raw.push(Event::QueryEnd);
    }
    let mut golden = FunctionalModel::new(WIDTH, HEIGHT);
    let mut events = Vec::with_capacity(raw.len() + 128);
    for event in raw {
        let result = golden.event(&event);
        events.push(event);
        if let Some(result) = result {
            events.push(Event::QueryResult(result));
        }
    }
    events
}

/// Nanoseconds this thread has run on a CPU (Linux schedstat), so the rate can be read on
/// a machine shared with other work; None elsewhere.
pub fn thread_cpu_ns() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    text.split_whitespace().next()?.parse().ok()
}

/// Print what a benchmark replays: `frames` copies of `frame`.
pub fn announce(frame: &[Event], frames: usize) {
    let per_frame = frame
        .iter()
        .filter(|e| matches!(e, Event::Fragment(_)))
        .count();
    println!(
        "stream: {} fragments ({frames} frames of {per_frame}), {WIDTH}x{HEIGHT}",
        per_frame * frames
    );
}
