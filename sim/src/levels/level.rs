//! What every fidelity level speaks: the level's name, and the common result each ends in
//! (the vocabulary below the levels, so none of them depends on another to use it).

use crate::effects::Effects;
use crate::report::{nearest_rank, Report};
use occsim_traces::QueryMode;
use serde::Serialize;
use std::fmt::Write as _;

/// A level of the ladder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fidelity {
    Functional,
    Analytic,
    /// The cycle model on every `every`-th window (`every` >= 1).
    Sampled {
        every: u32,
    },
    Cycle,
    Rtl,
}

impl Fidelity {
    /// Whether the level builds effect models ([`crate::effects`]): the cycle model and the
    /// sampled level's machines build those the trace's facts (header or scan) call for;
    /// `rtl` builds every model (it has no shortcuts); functional and analytic have none.
    /// Only the first two need the facts.
    pub fn builds_effects(self) -> bool {
        matches!(self, Fidelity::Sampled { .. } | Fidelity::Cycle)
    }
}

impl std::fmt::Display for Fidelity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Fidelity::Functional => write!(f, "functional"),
            Fidelity::Analytic => write!(f, "analytic"),
            Fidelity::Sampled { every } => write!(f, "sampled:{every}"),
            Fidelity::Cycle => write!(f, "cycle"),
            Fidelity::Rtl => write!(f, "rtl"),
        }
    }
}

/// A level name that does not parse.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FidelityParseError {
    #[error("unknown fidelity level '{0}' (functional, analytic, sampled:K, cycle, rtl)")]
    Unknown(String),
    #[error("'{0}': K in sampled:K must be a whole number from 1 to 4294967295")]
    BadEvery(String),
}

impl std::str::FromStr for Fidelity {
    type Err = FidelityParseError;
    fn from_str(text: &str) -> Result<Fidelity, FidelityParseError> {
        match text {
            "functional" => Ok(Fidelity::Functional),
            "analytic" => Ok(Fidelity::Analytic),
            "cycle" => Ok(Fidelity::Cycle),
            "rtl" => Ok(Fidelity::Rtl),
            _ => match text.strip_prefix("sampled:") {
                Some(k) => match k.parse::<u32>() {
                    Ok(every) if every >= 1 => Ok(Fidelity::Sampled { every }),
                    _ => Err(FidelityParseError::BadEvery(text.to_string())),
                },
                None => Err(FidelityParseError::Unknown(text.to_string())),
            },
        }
    }
}

impl Serialize for Fidelity {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

/// What a level's formulas predict when a window closes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowEnd {
    /// `T_w`: the window's cycles.
    pub cycles: f64,
    /// The latency of the query that closed it (or, for the final window without a query
    /// end, the pipe's drain), in cycles.
    pub latency: f64,
}

/// One query as a level saw it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct QueryOutcome {
    pub id: u32,
    pub mode: QueryMode,
    pub fragments: u64,
    /// The value a GL program reads ([`occsim_traces::QueryResult::value`]).
    pub value: u64,
    /// Predicted or simulated latency in cycles; None at the functional level.
    pub latency_cycles: Option<u64>,
}

/// Windows the sampled level simulated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SampledWindows {
    pub simulated: u64,
    pub total: u64,
}

/// What a level produced, in the same shape at every level.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LevelResult {
    pub level: Fidelity,
    pub machine: String,
    pub fragments: u64,
    pub primitives: u64,
    /// Queries compared with a golden result stored in the stream.
    pub checked_queries: u64,
    /// Predicted (or simulated) cycles of the whole run; None at the functional level.
    pub total_cycles: Option<u64>,
    pub latency_mean_cycles: Option<f64>,
    /// Nearest-rank 95th percentile of the query latencies.
    pub latency_p95_cycles: Option<u64>,
    /// The effect models the cycle model built (cycle and sampled levels).
    pub effects: Option<Effects>,
    pub sampled_windows: Option<SampledWindows>,
    pub queries: Vec<QueryOutcome>,
    /// Each frame's cycles, for a closed-loop stream at a level that times frames (empty
    /// otherwise).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub frame_cycles: Vec<u64>,
    /// Frames over the run's time, when frames were timed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frames_per_second: Option<f64>,
    /// The full cycle-level report (cycle level only).
    #[serde(skip)]
    pub report: Option<Report>,
}

impl LevelResult {
    /// Set the run's cycles and derive the latency statistics from the queries' latencies.
    pub(crate) fn set_timing(&mut self, total_cycles: u64) {
        self.total_cycles = Some(total_cycles);
        let mut latencies: Vec<u64> = self
            .queries
            .iter()
            .filter_map(|q| q.latency_cycles)
            .collect();
        latencies.sort_unstable();
        self.latency_mean_cycles = Some(if latencies.is_empty() {
            0.0
        } else {
            latencies.iter().sum::<u64>() as f64 / latencies.len() as f64
        });
        self.latency_p95_cycles = Some(nearest_rank(&latencies, 95));
    }

    /// From a cycle-level report.
    pub(crate) fn from_report(report: Report, effects: Effects) -> LevelResult {
        let queries = report
            .queries
            .iter()
            .map(|q| {
                let passed: u64 = q.tiles.iter().map(|t| t.nohc).sum();
                QueryOutcome {
                    id: q.id,
                    mode: q.mode,
                    fragments: q.fragments,
                    value: if q.mode == QueryMode::Any {
                        (passed > 0) as u64
                    } else {
                        passed
                    },
                    latency_cycles: Some(q.latency_cycles),
                }
            })
            .collect();
        let mut result = LevelResult {
            level: Fidelity::Cycle,
            machine: report.machine.clone(),
            fragments: report.summary.fragments,
            primitives: report.summary.primitives,
            checked_queries: report.summary.checked_queries,
            total_cycles: None,
            latency_mean_cycles: None,
            latency_p95_cycles: None,
            effects: Some(effects),
            sampled_windows: None,
            queries,
            frame_cycles: report.frames.iter().map(|f| f.cycles).collect(),
            frames_per_second: report.summary.frames_per_second,
            report: None,
        };
        result.set_timing(report.summary.cycles);
        result.report = Some(report);
        result
    }

    /// Record the frames' cycles and the rate they give over the run (set_timing first).
    pub(crate) fn set_frames(&mut self, frame_cycles: Vec<u64>, clock_mhz: f64) {
        let total = self.total_cycles.unwrap_or(0);
        self.frames_per_second = (!frame_cycles.is_empty() && total > 0)
            .then(|| frame_cycles.len() as f64 / (total as f64 / (clock_mhz * 1e6)));
        self.frame_cycles = frame_cycles;
    }

    /// The mean frame time in cycles, when frames were timed.
    pub fn frame_mean_cycles(&self) -> Option<f64> {
        (!self.frame_cycles.is_empty())
            .then(|| self.frame_cycles.iter().sum::<u64>() as f64 / self.frame_cycles.len() as f64)
    }

    /// A short text form (what `occsim replay --fidelity` prints below the cycle level).
    pub fn to_text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "level: {} on {}", self.level, self.machine);
        let _ = writeln!(
            out,
            "fragments: {}  primitives: {}  queries: {} ({} checked against golden results)",
            self.fragments,
            self.primitives,
            self.queries.len(),
            self.checked_queries
        );
        match (
            self.total_cycles,
            self.latency_mean_cycles,
            self.latency_p95_cycles,
        ) {
            (Some(total), Some(mean), Some(p95)) => {
                let _ = writeln!(out, "predicted cycles: {total}");
                let _ = writeln!(out, "query latency: mean {mean:.1}  p95 {p95} cycles");
            }
            _ => {
                let _ = writeln!(
                    out,
                    "predicted cycles: none (the functional level has no time)"
                );
            }
        }
        if let Some(windows) = self.sampled_windows {
            let _ = writeln!(
                out,
                "sampled windows: {} of {} simulated",
                windows.simulated, windows.total
            );
        }
        if let Some(effects) = self.effects {
            let _ = writeln!(out, "active effects: {}", effects.active_names());
        }
        out
    }
}
