//! What every fidelity level speaks: the level's name, and the common result each ends in
//! (the vocabulary below the levels, so none of them depends on another to use it).

use crate::arch::{ArchEntry, Machine, Value};
use crate::effects::Effects;
use crate::report::{latency_figures, Report};
use occsim_traces::words::counted;
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
    /// The query's tiles (1 for a samples or any query). `tile_count` in JSON: at the cycle
    /// and rtl levels a query's `tiles` are its tiles' reports.
    #[serde(rename = "tile_count")]
    pub tiles: usize,
    /// NOHC and PHC summed over the tiles.
    pub nohc: u64,
    pub phc: u64,
    /// Tiles whose verbose buffer overflowed.
    pub overflowed_buffers: u32,
    /// Predicted or simulated latency in cycles; None at the functional level.
    pub latency_cycles: Option<u64>,
}

impl QueryOutcome {
    /// The outcome of the query whose result came to `totals`, `fragments` of them inside it.
    pub(crate) fn of(totals: &occsim_traces::QueryTotals, fragments: u64) -> QueryOutcome {
        QueryOutcome {
            id: totals.id,
            mode: totals.mode,
            fragments,
            value: totals.value(),
            tiles: totals.tiles,
            nohc: totals.nohc,
            phc: totals.phc,
            overflowed_buffers: totals.overflowed_buffers,
            latency_cycles: None,
        }
    }
}

/// Windows the sampled level simulated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct SampledWindows {
    pub simulated: u64,
    /// Of the simulated windows, those simulated only as one of the windows whose queries
    /// the formulas predict slowest ([`crate::levels::sampled::SampledModel::slowest_windows`]),
    /// not as one of every K.
    pub slowest: u64,
    /// Of the simulated windows, those simulated over their last fragments alone, their
    /// heads extrapolated ([`crate::levels::sampled::tail_fragments`]).
    pub tails: u64,
    pub total: u64,
}

/// What a level produced, in the same shape at every level.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LevelResult {
    pub level: Fidelity,
    pub machine: String,
    /// The fully resolved architecture the run used.
    pub arch: Vec<ArchEntry>,
    pub viewport_width: u32,
    pub viewport_height: u32,
    pub fragments: u64,
    pub primitives: u64,
    /// Queries compared with a golden result stored in the stream.
    pub checked_queries: u64,
    /// Predicted (or simulated) cycles of the whole run; None at the functional level.
    pub total_cycles: Option<u64>,
    pub latency_mean_cycles: Option<f64>,
    /// Nearest-rank 50th and 95th percentiles and the largest of the query latencies.
    pub latency_p50_cycles: Option<u64>,
    pub latency_p95_cycles: Option<u64>,
    pub latency_max_cycles: Option<u64>,
    /// The effect models the cycle model built (cycle and sampled levels).
    pub effects: Option<Effects>,
    /// Fragments the cycle model fast-forwarded ([`crate::effects`]; cycle and rtl levels).
    /// Every field is in the JSON at every level (null, false or empty where the level has
    /// none), so that a script reads the same keys whatever the level.
    pub fast_forwarded_fragments: Option<u64>,
    pub sampled_windows: Option<SampledWindows>,
    /// Read from the trace's index (the window index; the band index on the
    /// InfiniteReality-like machine), not its fragments: the query results are the stream's
    /// golden ones, taken, not checked (the analytic and sampled levels).
    pub from_window_index: bool,
    /// The trace's format version when its window index lacks counts this level's formulas
    /// take (before [`occsim_traces::trace::INDEX_COUNTS_VERSION`]), so its fragments were
    /// decoded instead.
    pub older_index: Option<u16>,
    pub queries: Vec<QueryOutcome>,
    /// Each frame's cycles, for a closed-loop stream at a level that times frames (empty
    /// otherwise).
    pub frame_cycles: Vec<u64>,
    /// Frames over the run's time, when frames were timed.
    pub frames_per_second: Option<f64>,
    /// The full cycle-level report (cycle level only).
    #[serde(skip)]
    pub report: Option<Report>,
}

impl LevelResult {
    /// The trace's index a level reads instead of the fragments on this machine
    /// ([`LevelResult::from_window_index`]): the O2's formulas count the window index's
    /// stretches, the InfiniteReality-like machine's the band index's runs.
    fn index_name(&self) -> &'static str {
        if self.machine == Machine::Ir.name() {
            "band index"
        } else {
            "window index"
        }
    }

    /// Set the run's cycles and derive the latency statistics from the queries' latencies
    /// (none without a query: `-` in the table, null in JSON, as for any figure a run has
    /// not; they had been 0).
    pub(crate) fn set_timing(&mut self, total_cycles: u64) {
        self.total_cycles = Some(total_cycles);
        let mut latencies: Vec<u64> = self
            .queries
            .iter()
            .filter_map(|q| q.latency_cycles)
            .collect();
        latencies.sort_unstable();
        [
            self.latency_p50_cycles,
            self.latency_p95_cycles,
            self.latency_max_cycles,
        ] = latency_figures(&latencies);
        self.latency_mean_cycles = (!latencies.is_empty())
            .then(|| latencies.iter().sum::<u64>() as f64 / latencies.len() as f64);
    }

    /// From a cycle-level report (the level is `cycle`; [`crate::LevelModel::finish`] says
    /// `rtl` when it was).
    pub fn from_report(report: Report, effects: Effects) -> LevelResult {
        let queries = report
            .queries
            .iter()
            .map(|q| {
                let nohc = q.totals.nohc;
                QueryOutcome {
                    id: q.id,
                    mode: q.mode,
                    fragments: q.fragments,
                    value: if q.mode == QueryMode::Any {
                        (nohc > 0) as u64
                    } else {
                        nohc
                    },
                    tiles: q.totals.tiles,
                    nohc,
                    phc: q.totals.phc,
                    overflowed_buffers: q.overflowed_buffers,
                    latency_cycles: Some(q.latency_cycles),
                }
            })
            .collect();
        let mut result = LevelResult {
            level: Fidelity::Cycle,
            machine: report.machine.clone(),
            arch: report.arch.clone(),
            viewport_width: report.viewport_width,
            viewport_height: report.viewport_height,
            fragments: report.summary.fragments,
            primitives: report.summary.primitives,
            checked_queries: report.summary.checked_queries,
            total_cycles: None,
            latency_mean_cycles: None,
            latency_p50_cycles: None,
            latency_p95_cycles: None,
            latency_max_cycles: None,
            effects: Some(effects),
            fast_forwarded_fragments: None,
            sampled_windows: None,
            from_window_index: false,
            older_index: None,
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

    /// The readable report, one shape at every level: the level and the machine with its
    /// key parameters; the summary line; the frames; the blocks' tables (cycle and rtl); the
    /// sampled windows and effect models; with `with_queries` a table of every query. What a
    /// level cannot give prints as `-`.
    pub fn to_text(&self, with_queries: bool) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "level {}, machine {}, viewport {}x{}",
            self.level,
            machine_text(&self.machine, &self.arch),
            self.viewport_width,
            self.viewport_height
        );
        let _ = writeln!(out, "{}", self.summary_line());
        if let Some(note) = self.idle_engines_note() {
            let _ = writeln!(out, "{note}");
        }
        match &self.report {
            Some(report) => report.write_frames(&mut out),
            None => self.write_predicted_frames(&mut out),
        }
        match &self.report {
            Some(report) => report.write_blocks(&mut out),
            None => {
                let _ = writeln!(
                    out,
                    "\nstages, memory port, units, engines: - (the {} level models no blocks; the cycle and rtl levels do)",
                    self.level
                );
            }
        }
        if let Some(windows) = self.sampled_windows {
            let _ = writeln!(
                out,
                "sampled windows: {} of {} simulated; of those {}, {} only as one of the slowest predicted and, of either kind, {} over their last fragments alone",
                windows.simulated, windows.total, windows.simulated, windows.slowest, windows.tails
            );
        }
        if let Some(version) = self.older_index {
            let _ = writeln!(
                out,
                "decoded every fragment: the trace's window index (format version {version}) \
                 lacks counts the formulas take from version {} on; `occsim trace gen` makes \
                 the trace anew",
                occsim_traces::trace::INDEX_COUNTS_VERSION
            );
        }
        let index = self.index_name();
        match (self.from_window_index, self.sampled_windows) {
            (false, _) => {}
            (true, None) => {
                let _ = writeln!(
                    out,
                    "read from the {index}: no fragment decoded; query results are the trace's golden ones"
                );
            }
            (true, Some(_)) => {
                let _ = writeln!(
                    out,
                    "read from the {index}: only the simulated windows' fragments decoded, \
                     their machines' depths made consistent with the trace's depth tests; query \
                     results are the trace's golden ones, {} checked by those machines",
                    self.checked_queries
                );
            }
        }
        match self.effects {
            Some(effects) => {
                let _ = writeln!(out, "active effects: {}", effects.active_names());
            }
            None => {
                let _ = writeln!(
                    out,
                    "active effects: - (the {} level builds no effect models)",
                    self.level
                );
            }
        }
        if let Some(fast_forwarded) = self.fast_forwarded_fragments {
            let _ = writeln!(
                out,
                "fast-forwarded: {fast_forwarded} of {} fragments ({:.1}%)",
                self.fragments,
                crate::report::percent(fast_forwarded, self.fragments)
            );
        }
        if with_queries {
            self.write_query_table(&mut out);
        }
        out
    }

    /// The one-line summary: cycles, simulated time, fragments, rate, queries, latency.
    pub fn summary_line(&self) -> String {
        let clock = clock_mhz(&self.arch);
        let dash = |v: Option<u64>| v.map_or("-".to_string(), |v| v.to_string());
        let seconds = match (self.total_cycles, clock) {
            (Some(cycles), Some(mhz)) => format!("{:.6} s", cycles as f64 / (mhz * 1e6)),
            _ => "- s".to_string(),
        };
        let rate = match self.total_cycles {
            Some(cycles) if cycles > 0 => format!("{:.3}", self.fragments as f64 / cycles as f64),
            Some(_) => "0.000".to_string(),
            None => "-".to_string(),
        };
        format!(
            "{} cycles ({seconds}), {} fragments, {rate} fragments/cycle, {} queries ({}), latency p50 {} p95 {} max {} cycles",
            dash(self.total_cycles),
            self.fragments,
            self.queries.len(),
            if self.from_window_index && self.sampled_windows.is_some() {
                format!(
                    "their golden results, from the {}; {} checked by the simulated windows",
                    self.index_name(),
                    self.checked_queries
                )
            } else if self.from_window_index {
                format!("their golden results, from the {}", self.index_name())
            } else {
                format!("{} checked against golden results", self.checked_queries)
            },
            dash(self.latency_p50_cycles),
            dash(self.latency_p95_cycles),
            dash(self.latency_max_cycles),
        )
    }

    /// When the machine has more engines an Occlusion Unit than any query has tiles, the
    /// extra engines get none (tiles are dealt round-robin), so they change nothing.
    pub fn idle_engines_note(&self) -> Option<String> {
        let engines = match arch_value(&self.arch, "engines") {
            Some(Value::Int(engines)) => *engines,
            _ => return None,
        };
        let most = self.queries.iter().map(|q| q.tiles as u64).max()?;
        (engines > most).then(|| {
            let idle = match engines - most {
                1 => "1 engine gets no tile and changes".to_string(),
                idle => format!("{idle} engines get no tile and change"),
            };
            format!(
                "note: {engines} engines, but no query has more than {}: {idle} nothing here",
                counted(most, "tile", "tiles"),
            )
        })
    }

    /// The frames a level without a report timed: their cycles and time; the host's split
    /// is the cycle level's (`-`).
    fn write_predicted_frames(&self, out: &mut String) {
        if self.total_cycles.is_none() {
            let _ = writeln!(out, "\nframes: - (the {} level has no time)", self.level);
            return;
        }
        let Some(fps) = self.frames_per_second else {
            let _ = writeln!(out, "{}", crate::report::OPEN_LOOP_NOTE);
            return;
        };
        let _ = writeln!(
            out,
            "\n{}, {fps:.2} frames/s; host busy, geometry, pixel busy, waiting, pipe wait: - (the cycle and rtl levels split a frame)",
            counted(self.frame_cycles.len() as u64, "frame", "frames")
        );
        let _ = writeln!(out, "{}", crate::report::FRAMES_LEGEND);
        let _ = writeln!(out, "{}", crate::report::FRAMES_HEADING);
        let mhz = clock_mhz(&self.arch).unwrap_or(0.0);
        for (frame, cycles) in self.frame_cycles.iter().enumerate() {
            let ms = if mhz > 0.0 {
                format!("{:.3}", *cycles as f64 / (mhz * 1e3))
            } else {
                "-".to_string()
            };
            let _ = writeln!(
                out,
                "{:<6} {:>12} {:>10} {:>12} {:>12} {:>12} {:>12} {:>12}",
                frame, cycles, ms, "-", "-", "-", "-", "-"
            );
        }
    }

    /// Every query: the same columns at every level (`-` where the level has no figure).
    fn write_query_table(&self, out: &mut String) {
        let _ = writeln!(
            out,
            "\nqueries: latency from the end entering the pipe to the result written, in cycles, \
             = drain (last fragment through every Occlusion Unit) + local merge + global merge (IR); \
             overflow: tiles whose verbose buffer overflowed; nohc, phc: passing and projected \
             fragments summed over the tiles; fragments: inside the query"
        );
        let _ = writeln!(
            out,
            "{:>6} {:>10} {:<8} {:>6} {:>10} {:>8} {:>8} {:>8} {:>9} {:>12} {:>12} {:>10}",
            "#",
            "id",
            "mode",
            "tiles",
            "latency",
            "drain",
            "local",
            "global",
            "overflow",
            "nohc",
            "phc",
            "fragments"
        );
        let reported = self.report.as_ref().map(|r| &r.queries);
        let dash = |v: Option<u64>| v.map_or("-".to_string(), |v| v.to_string());
        for (index, q) in self.queries.iter().enumerate() {
            let split = reported.and_then(|r| r.get(index));
            let _ = writeln!(
                out,
                "{:>6} {:>10} {:<8} {:>6} {:>10} {:>8} {:>8} {:>8} {:>9} {:>12} {:>12} {:>10}",
                index,
                q.id,
                q.mode.name(),
                q.tiles,
                dash(q.latency_cycles),
                dash(split.map(|s| s.drain_cycles)),
                dash(split.and_then(|s| s.local_merge_cycles)),
                dash(split.and_then(|s| s.global_merge_cycles)),
                q.overflowed_buffers,
                q.nohc,
                q.phc,
                q.fragments
            );
        }
    }
}

fn arch_value<'a>(arch: &'a [ArchEntry], key: &str) -> Option<&'a Value> {
    arch.iter().find(|e| e.key == key).map(|e| &e.value)
}

fn clock_mhz(arch: &[ArchEntry]) -> Option<f64> {
    match arch_value(arch, "clock_mhz") {
        Some(Value::Float(mhz)) => Some(*mhz),
        _ => None,
    }
}

/// The machine and its key parameters: `o2 (4 engines) at 66.67 MHz`, `ir (4 boards, 80
/// Image Engines a board, 4 engines an Occlusion Unit, interleave columns) at 100 MHz`.
pub fn machine_text(machine: &str, arch: &[ArchEntry]) -> String {
    let text = |key: &str| match arch_value(arch, key) {
        Some(Value::Choice(name)) => Some(name.to_string()),
        Some(value) => Some(value.to_string()),
        None => None,
    };
    let mut parts = Vec::new();
    if let Some(boards) = text("boards") {
        parts.push(format!("{boards} boards"));
    }
    if let Some(ies) = text("image_engines_per_board") {
        parts.push(format!("{ies} Image Engines a board"));
    }
    if let Some(engines) = text("engines") {
        parts.push(match machine {
            "ir" => format!("{engines} engines an Occlusion Unit"),
            _ => format!("{engines} engines"),
        });
    }
    if let Some(interleave) = text("interleave") {
        match interleave.as_str() {
            "columns" => parts.push("interleave columns".to_string()),
            other => parts.push(format!(
                "interleave {other} of {}x{} pixels",
                text("block_width_pixels").unwrap_or_default(),
                text("block_height_pixels").unwrap_or_default()
            )),
        }
    }
    if let Some(Value::Bool(true)) = arch_value(arch, "all_tiles_one_cycle") {
        parts.push("all tiles in one cycle".to_string());
    }
    let mut out = machine.to_string();
    if !parts.is_empty() {
        let _ = write!(out, " ({})", parts.join(", "));
    }
    if let Some(mhz) = clock_mhz(arch) {
        let _ = write!(out, " at {mhz} MHz");
    }
    out
}
