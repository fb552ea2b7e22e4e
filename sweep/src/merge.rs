//! Joining shard outputs into one results file.
//!
//! The shards must come from the same sweep: every line repeats the axes and trace digest, and
//! the first line read sets the expectation. A point found in several inputs must have the same
//! text everywhere (results are deterministic, so a difference means a real conflict).

use crate::error::{Joining, SweepError};
use crate::grid::Grid;
use crate::output::{commit_together, write_finished, Finished, OutputError};
use crate::record::{
    check_line_belongs, csv_path_for, read_results, render_csv, render_jsonl, Expected, StoredLine,
};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

type Result<T, E = SweepError> = std::result::Result<T, E>;

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
    /// The results file and its CSV view, written and flushed, not yet in place
    /// ([`MergeReport::commit`]).
    written: Vec<Finished>,
}

impl MergeReport {
    /// Rename the merged results, their CSV view and the command's `other` outputs (a
    /// chart of them) into place together ([`commit_together`]): an interrupted merge
    /// leaves none of them.
    pub fn commit(&mut self, other: impl IntoIterator<Item = Finished>) -> Result<(), OutputError> {
        let mut files = std::mem::take(&mut self.written);
        files.extend(other);
        commit_together(files)
    }
}

/// Merges `inputs` into `out` (and its CSV view). Missing points are an error listing them
/// unless `allow_missing`; then the partial result is written and the report lists them (an
/// unsharded resumed sweep on `out` can fill them in). An `out` that already holds anything
/// is an error unless `replace`: a merge never silently replaces results. (The inputs are
/// read before `out` is written, so `out` may be one of them.)
pub fn merge_results(
    out: &Path,
    inputs: &[PathBuf],
    allow_missing: bool,
    replace: bool,
) -> Result<MergeReport> {
    let mut report = merge_pending(out, inputs, allow_missing, replace)?;
    report.commit([])?;
    Ok(report)
}

/// [`merge_results`], its outputs written beside their paths, to be renamed into place with
/// the command's others by [`MergeReport::commit`] (dropped uncommitted, they are removed).
pub fn merge_pending(
    out: &Path,
    inputs: &[PathBuf],
    allow_missing: bool,
    replace: bool,
) -> Result<MergeReport> {
    let csv = csv_path_for(out)?;
    if inputs.is_empty() {
        return Err(SweepError::NoInputs);
    }
    if !replace && std::fs::metadata(out).is_ok_and(|m| m.len() > 0) {
        return Err(SweepError::MergeWouldReplace {
            path: out.to_path_buf(),
        });
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
    let first = stored.first().ok_or(SweepError::NothingToMerge {
        inputs: inputs.len(),
    })?;
    let grid = Grid::from_axes(first.line.axes.clone()).map_err(|e| SweepError::BadGrid {
        at: first.origin.clone(),
        source: Box::new(e),
    })?;
    let trace_digest = first.line.trace_digest.clone();
    let expected = Expected {
        grid: &grid,
        trace_digest: &trace_digest,
        joining: Joining::Merge {
            first: first.origin.clone(),
        },
    };

    let mut by_point: BTreeMap<usize, StoredLine> = BTreeMap::new();
    for line in stored {
        check_line_belongs(&line, &expected)?;
        if let Some(earlier) = by_point.get(&line.line.point) {
            if earlier.text != line.text {
                return Err(SweepError::Conflict {
                    first: earlier.origin.clone(),
                    second: line.origin,
                    key: line.line.key,
                });
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
        return Err(SweepError::MissingPoints {
            missing,
            total: grid.len(),
            torn: torn_inputs,
        });
    }

    let lines: Vec<StoredLine> = by_point.into_values().collect();
    let refs: Vec<&StoredLine> = lines.iter().collect();
    let written = vec![
        write_finished(out, render_jsonl(&refs).as_bytes())?,
        write_finished(&csv, render_csv(grid.axes(), &refs).as_bytes())?,
    ];
    Ok(MergeReport {
        lines,
        grid,
        missing,
        torn_inputs,
        csv,
        written,
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
