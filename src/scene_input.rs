//! Resolving a SCENE argument: a built-in name or a scene file, read as a stream.

use anyhow::Context;
use occsim_traces::builtin::{self, BuiltinChoices, BuiltinError};
use occsim_traces::scene::{Command, SceneReader};
use std::io::{BufRead, BufReader, Cursor, Read};

/// A scene being read: its commands as they come, and its size from the first line.
pub struct SceneInput {
    /// The name errors and trace headers use (the file path or the built-in name).
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub reader: SceneReader<Box<dyn BufRead>>,
}

/// Open SCENE: a built-in name (`demo`, `hardcases`, `random`), made as `choices` ask, or a
/// path to a scene file (which takes no choice: its first line sets its viewport).
/// A progress bar over its bytes is drawn on a terminal while it is read (`count`, `trace gen`).
pub fn open_scene(scene: &str, choices: &BuiltinChoices) -> anyhow::Result<SceneInput> {
    // Named by its flag, as a walkthrough's are.
    let text = builtin::scene_text_with(scene, choices).map_err(|e| match e {
        BuiltinError::OutOfRange { .. } => anyhow::anyhow!("--{e} (the built-in {scene} scene)"),
        BuiltinError::NotAChoice { choice, .. } => anyhow::anyhow!("--{choice}: {e}"),
    })?;
    if let (None, Some((choice, _))) = (&text, choices.given().next()) {
        anyhow::bail!(
            "--{choice}: scene file `{scene}` is made as it is written (--width, --height, --frames and --seed choose a walkthrough's, or the built-in demo's or random scene's)"
        );
    }
    let (input, size): (Box<dyn Read>, u64) = match text {
        Some(text) => {
            let size = text.len() as u64;
            (Box::new(Cursor::new(text.into_bytes())), size)
        }
        None => {
            occsim_sweep::output::note_input(std::path::Path::new(scene));
            let file = std::fs::File::open(scene).with_context(|| {
                format!(
                    "cannot open scene `{scene}` (not a file, and not a built-in scene: {})",
                    builtin::NAMES.join(", ")
                )
            })?;
            let size = file.metadata().map_or(0, |m| m.len());
            (Box::new(file), size)
        }
    };
    let bar = occsim_sweep::progress::bytes_bar(size);
    bar.set_message(format!("scene {scene}"));
    let counted = occsim_sweep::progress::Counted { inner: input, bar };
    let input: Box<dyn BufRead> = Box::new(BufReader::with_capacity(1 << 16, counted));
    let mut reader = SceneReader::new(input, scene);
    // The parser guarantees the first command is the viewport.
    let first = reader.next().transpose()?.map(|line| line.command);
    let Some(Command::Viewport { width, height }) = first else {
        anyhow::bail!("{scene}: expected `viewport W H` first");
    };
    Ok(SceneInput {
        name: scene.to_owned(),
        width,
        height,
        reader,
    })
}
