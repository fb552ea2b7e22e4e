//! Built-in scenes, so that every command has something to run on a fresh machine.
//!
//! - `demo`: a city block seen from the street over a few frames. Each building's bounding
//!   box is tested in brief mode (a 2x2 quadtree of tiles over its screen rectangle), front to
//!   back, and the building is drawn, inside a `samples` query, only when the box has a
//!   visible pixel. The query answers come from the golden model while the scene is made.
//! - `hardcases`: the rasterizer's hard cases as one scene (see `hardcases.scene`).
//! - `random`: 20,000 random triangles under 2,000 samples queries at 1280x1024, the
//!   benchmark workload.

mod city;
mod random;

pub use city::{demo_scene, DemoOptions};
pub use random::{random_scene, RandomOptions};

/// The names `SCENE` arguments accept besides file paths.
pub const NAMES: [&str; 3] = ["demo", "hardcases", "random"];

/// The hand-written hard-case catalogue.
pub const HARDCASES: &str = include_str!("hardcases.scene");

/// The text of a built-in scene, if `name` is one.
pub fn scene_text(name: &str) -> Option<String> {
    match name {
        "demo" => Some(demo_scene(&DemoOptions::default())),
        "hardcases" => Some(HARDCASES.to_owned()),
        "random" => Some(random_scene(&RandomOptions::default())),
        _ => None,
    }
}
