//! The demo's trace the sim benches share, as `occsim trace gen demo` writes it without its
//! window index (the header's facts written back).

use occsim_traces::builtin::{demo_scene, DemoOptions};
use occsim_traces::golden::GoldenModel;
use occsim_traces::scene::{parse_scene, Command};
use occsim_traces::trace::{TraceHeader, TraceWriter};

/// The demo's trace file, its bytes.
pub fn demo_trace() -> Vec<u8> {
    let lines = parse_scene(&demo_scene(&DemoOptions::default()), "demo").expect("parses");
    let Command::Viewport { width, height } = lines[0].command else {
        panic!("a scene starts with its viewport");
    };
    let mut file = std::io::Cursor::new(Vec::new());
    let mut writer = TraceWriter::new(&mut file, &TraceHeader::new(width, height)).expect("header");
    let mut golden = GoldenModel::new(width, height);
    for line in &lines {
        golden
            .execute(&line.command, &mut writer)
            .expect("the demo renders");
    }
    golden.finish(&mut writer).expect("the demo renders");
    writer.finish_seekable().expect("trace");
    file.into_inner()
}
