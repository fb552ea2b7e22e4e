//! Runs the selected points of a grid in parallel and keeps the results file consistent.
//!
//! Architecture invariants:
//! - each finished point is appended to `FILE.jsonl` as one line at once, so an interrupted run
//!   loses at most the unterminated last line, which a resumed run drops and recomputes;
//! - the finished files (JSONL sorted by point index, CSV view) are written atomically and are
//!   byte-identical whatever job count, shard split or resume history produced them: records
//!   hold no wall-clock time and their text is never re-encoded once written.

use crate::error::{BoxError, Joining, SweepError};
use crate::grid::{Grid, Point, Shard};
use crate::output::{check_writable, commit_together, write_atomically, write_finished};
use crate::record::{
    check_line_belongs, csv_path_for, read_results, render_csv, render_jsonl, Expected,
    PointRecord, StoredLine, SweepLine, FORMAT,
};
use indicatif::ProgressBar;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

type Result<T, E = SweepError> = std::result::Result<T, E>;

/// The caller's model of one point: builds the architecture from the point's values, runs it
/// on the trace, and returns the resolved architecture and metrics, or the caller's own error.
/// Called from many threads.
pub type Evaluator<'a> = &'a (dyn Fn(&Point) -> Result<PointRecord, BoxError> + Sync);

/// What to run and where to put it.
pub struct SweepOptions<'a> {
    pub grid: &'a Grid,
    /// Run only this shard's points (all points when None).
    pub shard: Option<Shard>,
    /// Digest of the trace every point runs on; recorded in every line, checked on resume.
    pub trace_digest: &'a str,
    /// The results file `FILE.jsonl`; the CSV view goes to `FILE.csv`.
    pub out: &'a Path,
    /// Worker threads, >= 1.
    pub jobs: usize,
    /// Continue the existing `out` instead of refusing to touch it.
    pub resume: bool,
    /// Replace an existing `out` (its results are lost) instead of refusing to touch it;
    /// `resume` wins when both are set.
    pub replace: bool,
    /// Draw a progress bar on stderr (it is hidden anyway when stderr is not a terminal).
    pub show_progress: bool,
}

/// What a finished sweep did.
#[derive(Debug)]
pub struct SweepOutcome {
    /// Every selected point's line, in point-index order.
    pub lines: Vec<StoredLine>,
    /// Points evaluated by this run.
    pub evaluated: usize,
    /// Points taken from the existing file (when resuming).
    pub reused: usize,
    /// Whether resuming found and dropped a torn last line.
    pub torn_tail_dropped: bool,
    pub csv: PathBuf,
}

/// Runs the sweep described by `options`, evaluating each point not yet done with `evaluate`.
pub fn run_sweep(options: &SweepOptions<'_>, evaluate: Evaluator<'_>) -> Result<SweepOutcome> {
    let csv = csv_path_for(options.out)?;
    // Both written at the end, after every point: a path that cannot take them is told now.
    check_writable(options.out)?;
    check_writable(&csv)?;
    if options.jobs == 0 {
        return Err(SweepError::NoWorkers);
    }
    let selected = options.grid.selected_indices(options.shard);
    let (mut done, torn_tail_dropped) = load_previous(options, &selected)?;
    let reused = done.len();
    let todo: Vec<usize> = selected
        .iter()
        .copied()
        .filter(|i| !done.contains_key(i))
        .collect();

    let fresh = evaluate_points(options, &todo, reused, evaluate, &csv)?;
    let evaluated = fresh.len();
    done.extend(fresh.into_iter().map(|s| (s.line.point, s)));
    if done.len() != selected.len() {
        return Err(SweepError::Internal(format!(
            "{} of {} points done after the sweep",
            done.len(),
            selected.len()
        )));
    }

    let lines: Vec<StoredLine> = done.into_values().collect();
    let refs: Vec<&StoredLine> = lines.iter().collect();
    // The results in point order and their CSV view, in place together.
    commit_together(vec![
        write_finished(options.out, render_jsonl(&refs).as_bytes())?,
        write_finished(&csv, render_csv(options.grid.axes(), &refs).as_bytes())?,
    ])?;
    Ok(SweepOutcome {
        lines,
        evaluated,
        reused,
        torn_tail_dropped,
        csv,
    })
}

/// Reads the points already in `out` (when resuming), checks they belong to this sweep and
/// shard, and repairs the file atomically if a torn last line had to be dropped.
fn load_previous(
    options: &SweepOptions<'_>,
    selected: &[usize],
) -> Result<(BTreeMap<usize, StoredLine>, bool)> {
    let out = options.out;
    let mut done = BTreeMap::new();
    let exists_with_content = std::fs::metadata(out).is_ok_and(|m| m.len() > 0);
    if !exists_with_content {
        return Ok((done, false));
    }
    if !options.resume {
        if options.replace {
            // Replaced once the first new point is kept ([`ResultsFile::append`]): until then
            // an interrupted or failing run leaves the old results as they were.
            return Ok((done, false));
        }
        // A file that is no results file says so, rather than be taken for a sweep to
        // resume (a file of notes had been "already holds results").
        read_results(out)?;
        return Err(SweepError::AlreadyHoldsResults {
            path: out.to_path_buf(),
        });
    }
    let file = read_results(out)?;
    let expected = Expected {
        grid: options.grid,
        trace_digest: options.trace_digest,
        joining: Joining::Resume,
    };
    for stored in file.lines {
        check_line_belongs(&stored, &expected)?;
        if selected.binary_search(&stored.line.point).is_err() {
            return Err(SweepError::NotInShard {
                at: stored.origin,
                key: stored.line.key,
                shard: options
                    .shard
                    .map_or("(none)".to_string(), |s| s.to_string()),
            });
        }
        if let Some(earlier) = done.get(&stored.line.point) {
            let earlier: &StoredLine = earlier;
            if earlier.text != stored.text {
                return Err(SweepError::Conflict {
                    first: earlier.origin.clone(),
                    second: stored.origin,
                    key: stored.line.key,
                });
            }
        }
        done.insert(stored.line.point, stored.compact());
    }
    if file.torn_tail_dropped {
        let refs: Vec<&StoredLine> = done.values().collect();
        write_atomically(out, render_jsonl(&refs).as_bytes()).map_err(|source| {
            SweepError::RepairTornLine {
                path: out.to_path_buf(),
                source,
            }
        })?;
    }
    Ok((done, file.torn_tail_dropped))
}

/// The results file a run appends its points to, opened when the first is kept: a run
/// interrupted before it leaves no file (or, replacing, the old one as it was), and a run
/// that replaces old results removes their CSV view with them, so that the two never tell
/// different sweeps.
struct ResultsFile<'a> {
    out: &'a Path,
    csv: &'a Path,
    /// Whether the file's old results go (`--force`) rather than grow (a new or resumed run).
    replace: bool,
    file: Option<std::fs::File>,
}

impl ResultsFile<'_> {
    fn append(&mut self, text: &str) -> Result<()> {
        let file = match &mut self.file {
            Some(file) => file,
            None => self.file.insert(self.open()?),
        };
        file.write_all(format!("{text}\n").as_bytes())
            .and_then(|()| file.flush())
            .map_err(|source| SweepError::Append {
                path: self.out.to_path_buf(),
                source,
            })
    }

    fn open(&self) -> Result<std::fs::File> {
        if self.replace {
            match std::fs::remove_file(self.csv) {
                Err(source) if source.kind() != std::io::ErrorKind::NotFound => {
                    return Err(SweepError::RemoveStaleView {
                        path: self.csv.to_path_buf(),
                        source,
                    })
                }
                _ => {}
            }
        }
        std::fs::OpenOptions::new()
            .create(true)
            .append(!self.replace)
            .write(true)
            .truncate(self.replace)
            .open(self.out)
            .map_err(|source| SweepError::OpenForAppend {
                path: self.out.to_path_buf(),
                source,
            })
    }
}

/// Evaluates `todo` on a pool of `options.jobs` threads, appending each result to the file as
/// soon as it is known. Stops at the first failing point; finished points stay in the file.
fn evaluate_points(
    options: &SweepOptions<'_>,
    todo: &[usize],
    already_done: usize,
    evaluate: Evaluator<'_>,
    csv: &Path,
) -> Result<Vec<StoredLine>> {
    let results = ResultsFile {
        out: options.out,
        csv,
        replace: options.replace && !options.resume,
        file: None,
    };
    let sink = Mutex::new((results, Vec::with_capacity(todo.len())));
    let keep = |point: &Point, record: PointRecord| -> Result<()> {
        let line = line_for(point, options, record);
        let text = line.to_json()?;
        let stored = StoredLine {
            line,
            text,
            origin: String::new(),
        }
        .compact();
        let mut guard = sink.lock().map_err(|_| SweepError::Poisoned)?;
        let (results, lines) = &mut *guard;
        results.append(&stored.text)?;
        lines.push(stored);
        Ok(())
    };
    let pool = Pool {
        grid: options.grid,
        jobs: options.jobs,
        show_progress: options.show_progress,
        failure: &|point: &Point| format!("point {}", point.index),
    };
    pool.run(todo, already_done, evaluate, &keep)
        .map_err(|error| match error {
            SweepError::PointFailed { index, source, .. } => SweepError::SweepPointFailed {
                index,
                key: options
                    .grid
                    .point(index)
                    .map(|p| p.key())
                    .unwrap_or_default(),
                kept: already_done + sink.lock().map_or(0, |guard| guard.1.len()),
                kept_in: options.out.to_path_buf(),
                source,
            },
            other => other,
        })?;
    let (_, lines) = sink.into_inner().map_err(|_| SweepError::Poisoned)?;
    Ok(lines)
}

/// The one way points are evaluated in parallel, by the sweep and by callers with a grid of
/// their own: a pool of `jobs` threads, a progress bar (hidden off a terminal), and a failing
/// or panicking point turned into [`SweepError::PointFailed`] naming it. The first failure
/// stops the run.
/// Worker threads for `requested` jobs: no more than the points to run, nor than
/// [`JOBS_PER_CORE`] a core (more only wait on one another and on memory), and at least one.
pub fn capped_jobs(requested: usize, points: usize, cores: usize) -> usize {
    requested
        .min(points.max(1))
        .min(JOBS_PER_CORE * cores.max(1))
        .max(1)
}

/// Most worker threads a core: points are CPU-bound, so beyond a few a core they only queue.
pub const JOBS_PER_CORE: usize = 4;

pub struct Pool<'g> {
    pub grid: &'g Grid,
    pub jobs: usize,
    pub show_progress: bool,
    /// What a failing point (an error or a panic) is called in the error, e.g. `point 3`.
    pub failure: &'g (dyn Fn(&Point) -> String + Sync),
}

impl Pool<'_> {
    /// Evaluate the points at `indices` and hand each result to `keep` as it comes (in no
    /// particular order); `already_done` points count as finished on the bar.
    pub fn run<T>(
        &self,
        indices: &[usize],
        already_done: usize,
        evaluate: &(dyn Fn(&Point) -> Result<T, BoxError> + Sync),
        keep: &(dyn Fn(&Point, T) -> Result<()> + Sync),
    ) -> Result<()> {
        let bar = progress_bar(
            self.show_progress,
            indices.len() + already_done,
            already_done,
        );
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(capped_jobs(self.jobs, indices.len(), cores))
            .build()
            .map_err(SweepError::Threads)?;
        let run_one = |index: &usize| -> Result<()> {
            let point = self
                .grid
                .point(*index)
                .ok_or_else(|| SweepError::Internal(format!("point {index} outside the grid")))?;
            // A panicking model becomes an error naming its point; the other points stay.
            let outcome =
                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| evaluate(&point)))
                    .unwrap_or_else(|payload| {
                        Err(SweepError::Panicked {
                            message: panic_text(&payload),
                        }
                        .into())
                    });
            let value = outcome.map_err(|source| SweepError::PointFailed {
                index: point.index,
                what: (self.failure)(&point),
                source,
            })?;
            keep(&point, value)?;
            bar.inc(1);
            Ok(())
        };
        let outcome = pool.install(|| indices.par_iter().try_for_each(run_one));
        bar.finish_and_clear();
        outcome
    }

    /// Evaluate every point of the grid; the results in point order.
    pub fn collect<T: Send>(
        &self,
        evaluate: &(dyn Fn(&Point) -> Result<T, BoxError> + Sync),
    ) -> Result<Vec<T>> {
        let results = Mutex::new(Vec::new());
        let indices: Vec<usize> = (0..self.grid.len()).collect();
        self.run(&indices, 0, evaluate, &|point, value| {
            results
                .lock()
                .map_err(|_| SweepError::Poisoned)?
                .push((point.index, value));
            Ok(())
        })?;
        let mut results = results.into_inner().map_err(|_| SweepError::Poisoned)?;
        results.sort_by_key(|(index, _)| *index);
        Ok(results.into_iter().map(|(_, value)| value).collect())
    }
}

fn panic_text(payload: &Box<dyn std::any::Any + Send>) -> String {
    if let Some(text) = payload.downcast_ref::<&str>() {
        text.to_string()
    } else if let Some(text) = payload.downcast_ref::<String>() {
        text.clone()
    } else {
        "(no message)".to_string()
    }
}

fn line_for(point: &Point, options: &SweepOptions<'_>, record: PointRecord) -> SweepLine {
    SweepLine {
        format: FORMAT.to_string(),
        point: point.index,
        key: point.key(),
        axes: options.grid.axes().to_vec(),
        trace_digest: options.trace_digest.to_string(),
        tool_version: env!("CARGO_PKG_VERSION").to_string(),
        resolved_arch: record.resolved_arch,
        metrics: record.metrics,
    }
}

fn progress_bar(wanted: bool, total: usize, position: usize) -> ProgressBar {
    if !wanted {
        return ProgressBar::hidden();
    }
    let bar = crate::progress::bar(total as u64, "points");
    bar.set_position(position as u64);
    bar
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::Axis;

    #[test]
    fn a_pool_asked_for_more_jobs_than_any_machine_has_threads_runs_on_a_few() {
        // --jobs 18446744073709551615 on `sensitivity` had asked rayon for as many threads
        // and failed after 20 s ("cannot start the worker threads"); the pool takes at most
        // JOBS_PER_CORE a core and no more than its points.
        let grid = Grid::from_axes(vec![Axis {
            key: "k".into(),
            values: (0..5).map(|i| i.to_string()).collect(),
        }])
        .unwrap();
        let pool = Pool {
            grid: &grid,
            jobs: usize::MAX,
            show_progress: false,
            failure: &|point: &Point| format!("point {}", point.index),
        };
        let values = pool
            .collect(&|point: &Point| Ok(point.index * 2))
            .expect("runs");
        assert_eq!(values, vec![0, 2, 4, 6, 8]);
        assert_eq!(capped_jobs(usize::MAX, 5, 64), 5);
        assert_eq!(capped_jobs(usize::MAX, 1_000, 2), 2 * JOBS_PER_CORE);
        assert_eq!(capped_jobs(0, 10, 2), 1);
    }
}
