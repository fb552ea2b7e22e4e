//! `occsim sweep merge OUT SHARD...`: joins shard outputs into one results file.
//!
//! The shards must come from the same sweep: every line repeats the axes and trace digest, and
//! the first line read sets the expectation. A point found in several inputs must have the same
//! text everywhere (results are deterministic, so a difference means a real conflict).

use crate::output::write_atomically;
use super::grid::Grid;
use super::record::{
    check_line_belongs, csv_path_for, read_results, render_csv, render_jsonl, Expected, StoredLine,
};
use anyhow::{bail, Context, Result};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// How many missing keys an error message lists before summarising the rest.
const MISSING_KEYS_SHOWN: usize = 20;

/// What a merge found.
#[derive(Debug)]
pub struct MergeReport {
    /// Every merged line, in point-index order.
    pub lines: Vec<StoredLine>,
    pub grid: Grid,
    /// Keys of the grid's points that no input holds, in point-index order.
    pub missing: Vec<String>,
    /// Inputs whose unterminated last line was dropped (an interrupted shard).
    pub torn_inputs: Vec<PathBuf>,
    pub csv: PathBuf,
}

/// Merges `inputs` into `out` (and its CSV view). Missing points are an error listing them
/// unless `allow_missing`; then the partial result is written and the report lists them (an
/// unsharded `--resume` on `out` can fill them in).
pub fn merge_results(out: &Path, inputs: &[PathBuf], allow_missing: bool) -> Result<MergeReport> {
    let csv = csv_path_for(out)?;
    if inputs.is_empty() {
        bail!("sweep merge needs at least one shard file to read");
    }
    let mut stored = Vec::new();
    let mut torn_inputs = Vec::new();
    for input in inputs {
        let file = read_results(input)?;
        if file.torn_tail_dropped {
            torn_inputs.push(input.clone());
        }
        stored.extend(file.lines);
    }
    let first = stored.first().with_context(|| {
        format!(
            "no results in {} input files; nothing to merge",
            inputs.len()
        )
    })?;
    let grid = Grid::from_axes(first.line.axes.clone())
        .with_context(|| format!("{}: bad grid", first.origin))?;
    let trace_digest = first.line.trace_digest.clone();
    let reference = format!("{} (the first result read)", first.origin);
    let expected = Expected {
        grid: &grid,
        trace_digest: &trace_digest,
        reference: &reference,
        advice: "only shards of one sweep can be merged",
    };

    let mut by_point: BTreeMap<usize, StoredLine> = BTreeMap::new();
    for line in stored {
        check_line_belongs(&line, &expected)?;
        if let Some(earlier) = by_point.get(&line.line.point) {
            if earlier.text != line.text {
                bail!(
                    "{} and {} hold different results for point '{}'",
                    earlier.origin,
                    line.origin,
                    line.line.key
                );
            }
            continue;
        }
        by_point.insert(line.line.point, line.compact());
    }

    let missing: Vec<String> = (0..grid.len())
        .filter(|i| !by_point.contains_key(i))
        .filter_map(|i| grid.point(i).map(|p| p.key()))
        .collect();
    if !missing.is_empty() && !allow_missing {
        bail!(
            "{} of {} points are missing from the shards: {}; nothing written \
             (pass --allow-missing to write the partial merge, then run the sweep with --resume \
             on it to fill the gaps)",
            missing.len(),
            grid.len(),
            list_keys(&missing)
        );
    }

    let lines: Vec<StoredLine> = by_point.into_values().collect();
    let refs: Vec<&StoredLine> = lines.iter().collect();
    write_atomically(out, render_jsonl(&refs).as_bytes())?;
    write_atomically(&csv, render_csv(grid.axes(), &refs).as_bytes())?;
    Ok(MergeReport {
        lines,
        grid,
        missing,
        torn_inputs,
        csv,
    })
}

/// `'a=1', 'a=2' and 3 more`.
pub fn list_keys(keys: &[String]) -> String {
    let shown: Vec<String> = keys
        .iter()
        .take(MISSING_KEYS_SHOWN)
        .map(|k| format!("'{k}'"))
        .collect();
    let mut text = shown.join(", ");
    if keys.len() > MISSING_KEYS_SHOWN {
        text.push_str(&format!(" and {} more", keys.len() - MISSING_KEYS_SHOWN));
    }
    text
}
