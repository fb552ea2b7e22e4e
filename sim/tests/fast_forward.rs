//! Fast-forward ([`occsim_sim::effects`]: `Effects::fast_forward`) changes no report: every
//! built-in trace and seeded random streams, replayed from their traces (so fragments come
//! in spans, as from a file) on the O2 and the InfiniteReality with several engine counts
//! and retiled, give the same report, bit for bit, with `--effects all` (the exact
//! reference, fragment by fragment) and `--effects auto` (fast-forward on).

use occsim_sim::arch::Machine;
use occsim_sim::effects::EffectsChoice;
use occsim_sim::replay::{replay, ReplayOptions};
use occsim_sim::{Arch, Fidelity, LevelResult};
use occsim_traces::builtin::{demo_scene, random_scene, DemoOptions, RandomOptions, HARDCASES};
use occsim_traces::golden::{EventSink, GoldenModel};
use occsim_traces::retile::TileGrid;
use occsim_traces::rng::SplitMix64;
use occsim_traces::scene::{parse_scene, Command};
use occsim_traces::state::DepthFunc;
use occsim_traces::trace::synthetic::{generate, SyntheticScene};
use occsim_traces::trace::{TraceError, TraceHeader, TraceReader, TraceWriter};
use occsim_traces::{Event, QueryMode, QuerySpec, Rect};

/// A scene's trace, its queries answered by the golden model, as `occsim trace gen` writes it.
fn scene_trace(text: &str) -> Vec<u8> {
    let lines = parse_scene(text, "scene").expect("built-in scenes parse");
    let Command::Viewport { width, height } = lines[0].command else {
        panic!("a scene starts with its viewport");
    };
    let mut bytes = Vec::new();
    let header = TraceHeader::new(width, height);
    let mut writer = TraceWriter::new(&mut bytes, &header).expect("header");
    let mut golden = GoldenModel::new(width, height);
    for line in &lines {
        golden.execute(&line.command, &mut writer).unwrap();
    }
    golden.finish(&mut writer).unwrap();
    writer.finish().expect("written");
    bytes
}

/// The cycle level's result of `trace` on `arch` with the effects `choice`, maybe retiled.
fn cycle_result(
    trace: &[u8],
    arch: &Arch,
    effects: EffectsChoice,
    retile: Option<TileGrid>,
) -> LevelResult {
    let options = ReplayOptions {
        effects,
        retile,
        ..ReplayOptions::at(Fidelity::Cycle)
    };
    replay(|| Ok(TraceReader::new(trace)?), arch, options).expect("replays")
}

/// Replays `trace` on `arch` both ways and checks the reports are equal; returns the
/// fragments fast-forwarded.
fn check_equal(name: &str, trace: &[u8], arch: &Arch, retile: Option<TileGrid>) -> u64 {
    let exact = cycle_result(trace, arch, EffectsChoice::All, retile);
    let fast = cycle_result(trace, arch, EffectsChoice::Auto, retile);
    assert_eq!(
        exact.fast_forwarded_fragments,
        Some(0),
        "{name}: all is exact"
    );
    let (exact_report, fast_report) = (exact.report.unwrap(), fast.report.unwrap());
    if let Some(query) = exact_report
        .queries
        .iter()
        .zip(&fast_report.queries)
        .position(|(a, b)| a != b)
    {
        panic!(
            "{name} on {}: query {query} differs:\n  all:  {:?}\n  auto: {:?}",
            exact_report.machine, exact_report.queries[query], fast_report.queries[query]
        );
    }
    assert_eq!(
        exact_report, fast_report,
        "{name} on {}: the reports differ",
        exact_report.machine
    );
    fast.fast_forwarded_fragments.unwrap()
}

fn arch(name: &str, engines: usize) -> Arch {
    let mut arch = Arch::builtin(name).unwrap();
    arch.set(&format!("engines={engines}")).unwrap();
    arch
}

/// Every architecture the small traces are replayed on: both machines, several engine
/// counts (one engine serialises multi-tile queries).
fn archs() -> Vec<Arch> {
    let mut archs = vec![arch("o2", 1), arch("o2", 4), arch("o2", 16)];
    archs.extend([arch("ir1", 1), arch("ir4", 4), arch("ir4", 16)]);
    archs
}

#[test]
fn the_demo_fast_forwards_most_of_its_fragments_with_identical_reports() {
    let trace = scene_trace(&demo_scene(&DemoOptions::default()));
    let fast_forwarded = check_equal("demo", &trace, &arch("o2", 4), None);
    // The demo has 27.3 M fragments; the rule holds for nearly all of them.
    assert!(
        fast_forwarded > 25_000_000,
        "{fast_forwarded} fast-forwarded"
    );
    check_equal("demo", &trace, &arch("ir4", 4), None);
}

/// [`check_equal`] on `trace` as it is and retiled 4x4. The fast-forward rule is the O2's
/// (the InfiniteReality takes every fragment one by one): there it must have held somewhere
/// either way, or the equality proves nothing of it. (Retiled, none had: the retiling
/// adapter passed spans on as their fragments.)
fn check_plain_and_retiled(name: &str, trace: &[u8], arch: &Arch) {
    let grid: TileGrid = "4x4".parse().unwrap();
    let plain = check_equal(name, trace, arch, None);
    let retiled = check_equal(&format!("{name} retiled 4x4"), trace, arch, Some(grid));
    if arch.machine() == Machine::O2 {
        assert!(
            plain > 0 && retiled > 0,
            "{name}: {plain} and {retiled} fast-forwarded"
        );
    }
}

#[test]
fn hardcases_give_identical_reports_on_every_machine_plain_and_retiled() {
    let trace = scene_trace(HARDCASES);
    for arch in archs() {
        check_plain_and_retiled("hardcases", &trace, &arch);
    }
}

#[test]
fn the_random_scene_gives_identical_reports_plain_and_retiled() {
    // 27.8 M fragments and 2,000 queries of every mode: one architecture a machine.
    let trace = scene_trace(&random_scene(&RandomOptions::default()));
    for arch in [arch("o2", 4), arch("ir4", 4)] {
        check_plain_and_retiled("random", &trace, &arch);
    }
}

/// Passes a synthetic stream on to a trace, with queries of every mode (random tiles,
/// verbose buffers that overflow) opened and closed and the depth state changed between
/// its primitives: the rule's every condition meets both of its outcomes.
struct WithQueries<'a> {
    writer: TraceWriter<&'a mut Vec<u8>>,
    random: SplitMix64,
    width: u32,
    height: u32,
    open: bool,
    next_id: u32,
}

impl WithQueries<'_> {
    fn between_primitives(&mut self) -> Result<(), TraceError> {
        if self.open && self.random.chance(40) {
            self.writer.event(&Event::QueryEnd)?;
            self.open = false;
        }
        if self.random.chance(10) {
            let funcs = [DepthFunc::Less, DepthFunc::Lequal, DepthFunc::Always];
            let func = funcs[self.random.below(3) as usize];
            self.writer.event(&Event::DepthFunc(func))?;
        }
        if self.random.chance(8) {
            let on = self.random.chance(70);
            self.writer.event(&Event::DepthMask(on))?;
        }
        if self.random.chance(4) {
            let on = self.random.chance(80);
            self.writer.event(&Event::DepthTest(on))?;
        }
        if self.random.chance(2) {
            self.writer.event(&Event::Clear)?;
        }
        if !self.open && self.random.chance(30) {
            let spec = self.query();
            self.writer.event(&Event::QueryBegin(spec))?;
            self.open = true;
        }
        Ok(())
    }

    fn query(&mut self) -> QuerySpec {
        let tiles = (0..1 + self.random.below(6))
            .map(|_| {
                let x = self.random.below(self.width as u64) as u32;
                let y = self.random.below(self.height as u64) as u32;
                let width = 1 + self.random.below((self.width - x) as u64) as u32;
                let height = 1 + self.random.below((self.height - y) as u64) as u32;
                Rect::new(x, y, width, height)
            })
            .collect();
        self.next_id += 1;
        QuerySpec {
            id: self.next_id,
            mode: QueryMode::ALL[self.random.below(4) as usize],
            buffer_entries: 8 + self.random.below(40) as u32,
            tiles,
        }
    }
}

impl EventSink for WithQueries<'_> {
    type Error = TraceError;
    fn event(&mut self, event: &Event) -> Result<(), TraceError> {
        if *event == Event::Primitive {
            self.between_primitives()?;
        }
        self.writer.event(event)
    }
}

fn synthetic_trace(seed: u64, width: u32, height: u32, max_radius: f64) -> Vec<u8> {
    let scene = SyntheticScene {
        width,
        height,
        min_radius: 2.0,
        max_radius,
        fragments: 200_000,
        seed,
    };
    let mut bytes = Vec::new();
    let header = TraceHeader::new(width, height);
    let mut sink = WithQueries {
        writer: TraceWriter::new(&mut bytes, &header).expect("header"),
        random: SplitMix64(seed ^ 0x5eed),
        width,
        height,
        open: false,
        next_id: 0,
    };
    generate(&scene, &mut sink).expect("generated");
    if sink.open {
        sink.writer.event(&Event::QueryEnd).unwrap();
    }
    sink.writer.finish().expect("written");
    bytes
}

#[test]
fn seeded_random_streams_give_identical_reports() {
    let grid: TileGrid = "4x4".parse().unwrap();
    let mut fast_forwarded = 0;
    for seed in 1..=4 {
        // Small triangles on a viewport of many pages, large ones on a small viewport.
        for (width, height, radius) in [(640, 480, 12.0), (96, 64, 60.0)] {
            let trace = synthetic_trace(seed, width, height, radius);
            let name = format!("synthetic seed {seed} {width}x{height}");
            for arch in archs() {
                fast_forwarded += check_equal(&name, &trace, &arch, None);
            }
            check_equal(&name, &trace, &arch("o2", 4), Some(grid));
        }
    }
    assert!(
        fast_forwarded > 0,
        "the rule never held: the test proves nothing"
    );
}
