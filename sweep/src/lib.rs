//! The architecture sweep engine: runs a model over the cartesian product of `key=v1,v2,...`
//! axes, in parallel, resumably and shardably; merges shard outputs; draws line charts.
//!
//! Architecture invariants:
//! - this crate knows nothing about the machines: a point is evaluated by a caller-supplied
//!   function, and keys/values are validated by a caller-supplied function;
//! - results do not depend on the job count, on sharding or on resume history: the finished
//!   files for one point set are byte-identical however they were produced;
//! - its error messages name no command-line flag (the binary words its advice itself).
//!
//! Code map: `grid` (axes, points, shards), `record` (JSONL line schema, CSV view), `runner`
//! (parallel evaluation, append, resume), `merge` (joining shard outputs), `chart` (metric vs
//! parameter chart), `plot` (SVG line charts and tornado charts through plotters), `output` (atomic file
//! writes), `error` (what can go wrong).

// The docs explain how the public items work, linking the private items that do it: read
// them with `cargo doc --document-private-items` (CI builds them so, every link checked).
#![allow(rustdoc::private_intra_doc_links)]

mod chart;
mod error;
mod grid;
mod merge;
pub mod output;
pub mod plot;
pub mod progress;
mod record;
mod runner;

pub use chart::{metric_chart, plot_axis};
pub use error::{kept_points, whose_results, BoxError, Joining, SweepError};
pub use grid::{Axis, AxisValidator, Grid, Point, Shard, MAX_GRID_POINTS};
pub use merge::{list_keys, merge_pending, merge_results, MergeReport};
pub use record::{csv_path_for, PointRecord, StoredLine, SweepLine, FORMAT};
pub use runner::{
    capped_jobs, run_sweep, Evaluator, Pool, SweepOptions, SweepOutcome, JOBS_PER_CORE,
};

#[cfg(test)]
mod tests;

/// A fresh, empty directory for one test, removed when dropped (tests run in parallel, so
/// each gets its own).
#[cfg(test)]
pub(crate) fn test_dir(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("occsim-sweep-{name}-"))
        .tempdir()
        .expect("cannot create a test directory")
}
