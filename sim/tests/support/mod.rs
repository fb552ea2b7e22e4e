//! What several of sim's integration tests share.

use occsim_traces::golden::GoldenModel;
use occsim_traces::scene::{parse_scene, Command};
use occsim_traces::Event;

/// A scene's viewport and events with the golden results, as `occsim trace gen` makes them.
pub fn scene_events(text: &str) -> (u32, u32, Vec<Event>) {
    let lines = parse_scene(text, "scene").expect("test scenes parse");
    let Command::Viewport { width, height } = lines[0].command else {
        panic!("a scene starts with its viewport");
    };
    let mut golden = GoldenModel::new(width, height);
    let mut events = Vec::new();
    for line in &lines {
        golden.execute(&line.command, &mut events).unwrap();
    }
    golden.finish(&mut events).unwrap();
    (width, height, events)
}
