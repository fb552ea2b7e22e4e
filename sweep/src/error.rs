//! What can go wrong in a sweep, a merge or a chart. Every variant names what it is about
//! (the axis spec, the results file and line, the point); none names a command-line flag:
//! the binary words its advice in its own flags.

use crate::output::OutputError;
use std::path::PathBuf;

/// An evaluator's own error (an `anyhow::Error` converts with `.into()` or `?`).
pub type BoxError = Box<dyn std::error::Error + Send + Sync>;

#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// An axis `key=v1,v2,...` that breaks the structural rules.
    #[error("bad axis '{spec}': {why}")]
    BadAxis { spec: String, why: String },
    /// The caller's validator rejected one value of an axis.
    #[error("bad axis value {key}={value}: {why}")]
    RejectedValue {
        key: String,
        value: String,
        why: String,
    },
    #[error("axis '{key}' is given twice; put all its values in one axis")]
    DuplicateAxis { key: String },
    #[error("the sweep has more than {limit} points")]
    TooManyPoints { limit: usize },
    #[error("bad shard '{spec}': {why}")]
    BadShard {
        spec: String,
        why: String,
        #[source]
        source: Option<std::num::ParseIntError>,
    },
    #[error("the worker count must be at least 1")]
    NoWorkers,
    #[error("cannot start the worker threads")]
    Threads(#[source] rayon::ThreadPoolBuildError),
    /// A results file named `.csv`, which its own CSV view would overwrite.
    #[error(
        "the results file {} ends in .csv; use a .jsonl name (the CSV view is written beside it)",
        path.display()
    )]
    CsvResultsName { path: PathBuf },
    /// A fresh sweep would append to a file that holds results already.
    #[error("{} already holds results; resume that sweep, or remove it to start over", path.display())]
    AlreadyHoldsResults { path: PathBuf },
    /// A merge's output exists and holds something: a merge replaces it only when told to.
    #[error("{} already exists; a merge replaces a file only when told to", path.display())]
    MergeWouldReplace { path: PathBuf },
    #[error("cannot read {}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot open {} for appending", path.display())]
    OpenForAppend {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot append to {}", path.display())]
    Append {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The CSV view of results a `--force` run replaces, which would otherwise stand beside
    /// the new sweep's points.
    #[error("cannot remove {}, the view of the results being replaced", path.display())]
    RemoveStaleView {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot repair the torn last line of {}", path.display())]
    RepairTornLine {
        path: PathBuf,
        #[source]
        source: OutputError,
    },
    #[error(transparent)]
    Output(#[from] OutputError),
    #[error("cannot encode a sweep result as JSON")]
    Encode(#[source] serde_json::Error),
    #[error("{}:{line}: not UTF-8 text", path.display())]
    NotUtf8 { path: PathBuf, line: usize },
    #[error(
        "{}:{line}: a line longer than {max} bytes: not a sweep results file",
        path.display()
    )]
    LineTooLong {
        path: PathBuf,
        line: usize,
        max: u64,
    },
    #[error(
        "{}:{line}: the line's digest does not match its content (edited, damaged, or not a sweep result line)",
        path.display()
    )]
    BadDigest { path: PathBuf, line: usize },
    #[error(
        "{}:{line}: ends in a line that is neither a result nor the start of one: not a sweep's results file",
        path.display()
    )]
    NotATornResult { path: PathBuf, line: usize },
    #[error("{}:{line}: not a sweep result line", path.display())]
    NotAResultLine {
        path: PathBuf,
        line: usize,
        #[source]
        source: serde_json::Error,
    },
    #[error("{}:{line}: format '{found}' is not '{}'", path.display(), crate::record::FORMAT)]
    WrongFormat {
        path: PathBuf,
        line: usize,
        found: String,
    },
    /// A results line (at `at`, `FILE:LINE`) made on another trace.
    #[error(
        "{at}: results are for trace digest {found}, but {} has trace digest {expected}: \
         they belong to {}; {}",
        joining.reference(),
        whose_results(found, expected),
        joining.advice()
    )]
    ForeignTrace {
        at: String,
        found: String,
        expected: String,
        joining: Joining,
    },
    /// A results line made for another grid (axes as typed, e.g. `boards=1,2 engines=4`).
    #[error(
        "{at}: results are for the grid '{found}', but {} has the grid '{expected}'; {}",
        joining.reference(),
        joining.advice()
    )]
    ForeignGrid {
        at: String,
        found: String,
        expected: String,
        joining: Joining,
    },
    #[error(
        "{at}: results were made by occsim {found}, this is occsim {this}; versions are not mixed"
    )]
    OtherVersion {
        at: String,
        found: String,
        this: String,
    },
    #[error("{at}: point {point} has key '{key}', which does not match its grid")]
    KeyMismatch {
        at: String,
        point: usize,
        key: String,
    },
    /// A resumed shard's file holds a point of another shard.
    #[error(
        "{at}: point '{key}' is not part of shard {shard}; resume a shard's file as the same shard"
    )]
    NotInShard {
        at: String,
        key: String,
        shard: String,
    },
    #[error("{first} and {second} hold different results for point '{key}'")]
    Conflict {
        first: String,
        second: String,
        key: String,
    },
    #[error("a merge needs at least one shard file to read")]
    NoInputs,
    #[error(
        "no results in {inputs} input file{}; nothing to merge",
        if *inputs == 1 { "" } else { "s" }
    )]
    NothingToMerge { inputs: usize },
    #[error("{at}: bad grid")]
    BadGrid {
        at: String,
        #[source]
        source: Box<SweepError>,
    },
    /// Points of the grid no shard holds (their keys, in point order); `torn`, the shards
    /// whose torn last line was dropped (an interrupted shard: its last point is among them).
    #[error(
        "{} of {total} points are missing from the shards: {}{}; nothing written",
        missing.len(),
        crate::merge::list_keys(missing),
        torn_shards(torn)
    )]
    MissingPoints {
        missing: Vec<String>,
        total: usize,
        torn: Vec<PathBuf>,
    },
    /// A point of a sweep failed; the `kept` points of this sweep finished before it are in
    /// `kept_in` (none: no file was written).
    #[error("point {index} ({key}) failed; {}", kept_points(*kept, kept_in, "for a resumed run"))]
    SweepPointFailed {
        index: usize,
        key: String,
        kept: usize,
        kept_in: PathBuf,
        #[source]
        source: BoxError,
    },
    /// A point of a [`crate::Pool`] failed; `what` is the pool's name for it.
    #[error("{what}")]
    PointFailed {
        index: usize,
        what: String,
        #[source]
        source: BoxError,
    },
    #[error("the model panicked: {message}")]
    Panicked { message: String },
    #[error("a worker thread panicked")]
    Poisoned,
    #[error("internal error: {0}")]
    Internal(String),
    #[error("cannot plot against '{key}': it is not swept (swept: {})", swept.join(", "))]
    NotSwept { key: String, swept: Vec<String> },
    #[error("cannot plot: no parameter is swept")]
    NothingSwept,
    #[error("cannot plot against '{key}': value '{value}' is not a number")]
    NonNumericAxis { key: String, value: String },
    #[error("no result has metric '{metric}'; metrics present: {}", present.join(", "))]
    NoSuchMetric {
        metric: String,
        present: Vec<String>,
    },
    #[error("metric '{metric}' of point '{key}' is {value}, not a number")]
    MetricNotANumber {
        metric: String,
        key: String,
        value: String,
    },
    #[error("point '{key}' has no numeric {axis}")]
    NoNumericX { key: String, axis: String },
}

/// Which results a line is checked against, which shapes the mismatch messages.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Joining {
    /// A resumed sweep reading its own file back.
    Resume,
    /// A merge; `first` is where the first result read came from (`FILE:LINE`).
    Merge { first: String },
}

impl Joining {
    /// Who set the expectation.
    pub fn reference(&self) -> String {
        match self {
            Joining::Resume => "this sweep".to_owned(),
            Joining::Merge { first } => format!("{first} (the first result read)"),
        }
    }

    /// What to do about a mismatch.
    pub fn advice(&self) -> &'static str {
        match self {
            Joining::Resume => "choose another results file, or remove this one to start over",
            Joining::Merge { .. } => "only shards of one sweep can be merged",
        }
    }
}

/// What a failed sweep left: its `kept` finished points in `file`, `then` what to do with
/// them, or that none had finished.
pub fn kept_points(kept: usize, file: &std::path::Path, then: &str) -> String {
    match kept {
        0 => "no point had finished".to_string(),
        1 => format!("the 1 point finished is kept in {} {then}", file.display()),
        _ => format!(
            "the {kept} points finished are kept in {} {then}",
            file.display()
        ),
    }
}

/// Whose results a line with trace digest `found` holds, for a sweep of digest `expected`:
/// a digest is the trace's `sha256:HEX`, then what replays it otherwise (`:retile=GxH`,
/// `:fidelity=LEVEL`, `:bands`), so the same hash means the same trace replayed otherwise.
pub fn whose_results(found: &str, expected: &str) -> &'static str {
    fn trace(digest: &str) -> Vec<&str> {
        digest.splitn(3, ':').take(2).collect()
    }
    if trace(found) == trace(expected) {
        "the same trace replayed otherwise (on another machine, or another tile grid, level or band study)"
    } else {
        "another trace"
    }
}

/// `(a.jsonl ends in a torn line, its point dropped)` for the shards `torn`, or nothing.
fn torn_shards(torn: &[PathBuf]) -> String {
    match torn {
        [] => String::new(),
        [one] => format!(
            " ({} ends in a torn line, its point dropped)",
            one.display()
        ),
        many => {
            let names: Vec<String> = many.iter().map(|p| p.display().to_string()).collect();
            format!(
                " ({} end in torn lines, their points dropped)",
                names.join(", ")
            )
        }
    }
}
