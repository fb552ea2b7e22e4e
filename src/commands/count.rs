//! `occsim count SCENE`: the golden model's answer to every query.

use crate::scene_input::open_scene;
use anyhow::Context;
use occsim_traces::golden::{infallible, Discard, GoldenModel};
use occsim_traces::QueryMode;
use std::io::Write;

#[derive(clap::Args)]
pub struct CountArgs {
    /// A scene file, or a built-in scene: demo, hardcases, random.
    pub scene: String,
    /// Print every query's full result (all modes, every tile) as JSON instead.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub raster: super::raster_args::RasterArgs,
}

/// Prints every query's answer in order: `query ID N` for a samples query, exactly as a GL
/// program printing GL_SAMPLES_PASSED would; `query ID any 0|1` for an any query; and for
/// brief and verbose queries one line a tile, `query ID MODE tile K nohc N phc P`, verbose
/// ones with `hits H` kept (and `overflowed` when the buffer overflowed).
pub fn run(args: CountArgs) -> anyhow::Result<()> {
    let mut scene = open_scene(&args.scene, &Default::default())?;
    let mut golden = GoldenModel::try_with_profile(scene.width, scene.height, args.raster.profile)
        .with_context(|| args.scene.clone())?;
    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    // The JSON array is written result by result, so memory does not grow with the queries.
    let mut results = 0usize;
    if args.json {
        write!(out, "[")?;
    }
    for line in &mut scene.reader {
        let line = line?;
        let Some(result) = infallible(golden.execute(&line.command, &mut Discard)) else {
            continue;
        };
        if args.json {
            // Each result as `to_writer_pretty` would nest it in the array: indented once.
            let pretty = serde_json::to_string_pretty(&result)?;
            let separator = if results == 0 { "\n" } else { ",\n" };
            write!(out, "{separator}  {}", pretty.replace('\n', "\n  "))?;
            results += 1;
            continue;
        }
        match result.mode {
            QueryMode::Samples => writeln!(out, "query {} {}", result.id, result.value())?,
            QueryMode::Any => writeln!(out, "query {} any {}", result.id, result.value())?,
            QueryMode::Brief | QueryMode::Verbose => {
                for (k, tile) in result.tiles.iter().enumerate() {
                    write!(
                        out,
                        "query {} {} tile {k} nohc {} phc {}",
                        result.id,
                        result.mode.name(),
                        tile.nohc,
                        tile.phc
                    )?;
                    if result.mode == QueryMode::Verbose {
                        write!(out, " hits {}", tile.hits.len())?;
                    }
                    if tile.overflowed {
                        write!(out, " overflowed")?;
                    }
                    writeln!(out)?;
                }
            }
        }
    }
    if args.json {
        writeln!(out, "{}]", if results == 0 { "" } else { "\n" })?;
    }
    out.flush()?;
    Ok(())
}
