//! The architecture sweep engine: runs a machine model over the cartesian product of
//! `--set key=v1,v2,...` axes, in parallel, resumably and shardably.
//!
//! Architecture invariants:
//! - this module knows nothing about the machines: a point is evaluated by a caller-supplied
//!   function, and keys/values are validated by a caller-supplied function;
//! - results do not depend on `--jobs`, on sharding or on resume history: the finished files
//!   for one point set are byte-identical however they were produced.
//!
//! Code map: `grid` (axes, points, shards), `record` (JSONL line schema, CSV view), `runner`
//! (parallel evaluation, append, resume), `merge` (joining shard outputs), `chart` (metric vs
//! parameter plot).

mod chart;
mod grid;
mod merge;
mod record;
mod runner;

pub use chart::metric_chart;
pub use grid::{Axis, AxisValidator, Grid, Point, Shard};
pub use merge::{list_keys, merge_results};
pub use record::{PointRecord, StoredLine};
pub use runner::{run_sweep, Evaluator, Pool, SweepOptions};

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
