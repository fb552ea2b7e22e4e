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

use crate::state::MAX_VIEWPORT_SIDE;

/// The names `SCENE` arguments accept besides file paths.
pub const NAMES: [&str; 3] = ["demo", "hardcases", "random"];

/// The hand-written hard-case catalogue.
pub const HARDCASES: &str = include_str!("hardcases.scene");

/// The text of a built-in scene, if `name` is one, as it is made by default.
pub fn scene_text(name: &str) -> Option<String> {
    scene_text_with(name, &BuiltinChoices::default()).unwrap_or(None)
}

/// Most frames the demo may be asked for: its scene is written out whole before it is
/// rasterized (a walkthrough's frames stream instead).
pub const MAX_BUILTIN_FRAMES: u32 = 64;

/// What a command line or a corpus recipe may choose of a built-in scene; `None` keeps the
/// scene's own. The demo takes all four, the random triangles a viewport and a seed, the
/// hard cases none (their coordinates are written for their own viewport).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BuiltinChoices {
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub frames: Option<u32>,
    pub seed: Option<u64>,
}

/// Why a built-in scene cannot be made as asked.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum BuiltinError {
    #[error("the built-in {scene} scene has no {choice} to choose{why}")]
    NotAChoice {
        scene: &'static str,
        choice: &'static str,
        why: &'static str,
    },
    #[error("{choice} {value}: expected {range}")]
    OutOfRange {
        choice: &'static str,
        value: u64,
        range: String,
    },
}

impl BuiltinChoices {
    /// Each choice given, by name, beside what it sets.
    pub fn given(&self) -> impl Iterator<Item = (&'static str, u64)> {
        [
            ("width", self.width.map(u64::from)),
            ("height", self.height.map(u64::from)),
            ("frames", self.frames.map(u64::from)),
            ("seed", self.seed),
        ]
        .into_iter()
        .filter_map(|(choice, value)| Some((choice, value?)))
    }

    /// Whether built-in scene `name` (one of [`NAMES`]) takes these choices, each within
    /// its range.
    pub fn check(&self, name: &str) -> Result<(), BuiltinError> {
        let scene = NAMES.iter().copied().find(|known| *known == name);
        for (choice, value) in self.given() {
            let refused = match (scene, choice) {
                (Some("demo"), _) | (Some("random"), "width" | "height" | "seed") => None,
                (Some("random"), _) => Some(" (it is one image)"),
                _ => Some(" (it is one hand-written image, 64x64)"),
            };
            if let (Some(why), Some(scene)) = (refused, scene) {
                return Err(BuiltinError::NotAChoice { scene, choice, why });
            }
            let range = match choice {
                "width" | "height" => 1..=u64::from(MAX_VIEWPORT_SIDE),
                "frames" => 1..=u64::from(MAX_BUILTIN_FRAMES),
                _ => 0..=u64::MAX,
            };
            if !range.contains(&value) {
                let range = format!("{} to {}", range.start(), range.end());
                return Err(BuiltinError::OutOfRange {
                    choice,
                    value,
                    range,
                });
            }
        }
        Ok(())
    }
}

/// The text of built-in scene `name` made as `choices` ask, if `name` is one.
pub fn scene_text_with(
    name: &str,
    choices: &BuiltinChoices,
) -> Result<Option<String>, BuiltinError> {
    if !NAMES.contains(&name) {
        return Ok(None);
    }
    choices.check(name)?;
    Ok(Some(match name {
        "demo" => {
            let defaults = DemoOptions::default();
            demo_scene(&DemoOptions {
                width: choices.width.unwrap_or(defaults.width),
                height: choices.height.unwrap_or(defaults.height),
                frames: choices.frames.unwrap_or(defaults.frames),
                seed: choices.seed.unwrap_or(defaults.seed),
                ..defaults
            })
        }
        "random" => {
            let defaults = RandomOptions::default();
            random_scene(&RandomOptions {
                width: choices.width.unwrap_or(defaults.width),
                height: choices.height.unwrap_or(defaults.height),
                seed: choices.seed.unwrap_or(defaults.seed),
                ..defaults
            })
        }
        _ => HARDCASES.to_owned(),
    }))
}
