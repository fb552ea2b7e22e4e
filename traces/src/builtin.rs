//! Built-in scenes: `demo` and `hardcases`. (Being written.)

/// The names `SCENE` arguments accept besides file paths.
pub const NAMES: [&str; 2] = ["demo", "hardcases"];

/// The text of a built-in scene, if `name` is one.
pub fn scene_text(name: &str) -> Option<String> {
    match name {
        "demo" | "hardcases" => Some("viewport 64 64\n".to_owned()),
        _ => None,
    }
}
