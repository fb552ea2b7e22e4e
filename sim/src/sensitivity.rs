//! Sensitivity bands: how far the headline results move when every parameter we inferred
//! (marked I, [`crate::arch::Mark`]) takes any value in its plausible range.
//!
//! The study is three steps, and this module is their arithmetic; the caller replays (in
//! parallel, in any order) the architectures it hands out:
//! 1. [`Study::one_at_a_time`]: every inferred parameter at the low and at the high end of
//!    its plausible range, the others at their values (an end equal to the value is not
//!    replayed again: it gives the default result);
//! 2. [`Study::corners`]: per headline result, the two corners that move it most, every
//!    parameter at once at the end that pushed the result furthest up (or down) in step 1,
//!    or at its value where neither end moved it that way; corners two results share are
//!    replayed once;
//! 3. [`Study::bands`]: per result the band `low..high` over the default, every single
//!    variation and the corners (so it always holds the default), with the parameters that
//!    move it most first: by swing, `max - min` over the parameter's low end, high end and
//!    the default; ties keep table order. Parameters that do not move a result are left out
//!    of its list.
//!
//! Everything is a function of the replays' results alone, so the bands do not depend on the
//! order or the parallelism the caller replays them in.

use crate::arch::{Arch, ArchError, Mark, Param, Value};
use crate::levels::LevelResult;
use serde::Serialize;

/// The headline results, in the order bands are reported.
pub const METRICS: [Metric; 4] = [
    Metric::Cycles,
    Metric::FrameTime,
    Metric::LatencyP50,
    Metric::LatencyP95,
];

/// One headline result of a replay.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Metric {
    /// The run's cycles.
    #[serde(rename = "cycles")]
    Cycles,
    /// The mean frame time of a closed-loop trace in milliseconds (cycles differ in length
    /// when a clock is varied).
    #[serde(rename = "frame_ms")]
    FrameTime,
    /// Nearest-rank median query latency in cycles.
    #[serde(rename = "latency_p50_cycles")]
    LatencyP50,
    /// Nearest-rank 95th percentile query latency in cycles.
    #[serde(rename = "latency_p95_cycles")]
    LatencyP95,
}

impl Metric {
    pub fn name(self) -> &'static str {
        match self {
            Metric::Cycles => "cycles",
            Metric::FrameTime => "frame_ms",
            Metric::LatencyP50 => "latency_p50_cycles",
            Metric::LatencyP95 => "latency_p95_cycles",
        }
    }

    pub fn unit(self) -> &'static str {
        match self {
            Metric::FrameTime => "ms",
            _ => "cycles",
        }
    }
}

/// A replay's headline results (`None` where the replay has no such result: the frame time
/// of an open-loop trace).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Headlines {
    pub cycles: f64,
    pub frame_ms: Option<f64>,
    /// None without a query.
    pub latency_p50_cycles: Option<f64>,
    pub latency_p95_cycles: Option<f64>,
}

impl Headlines {
    /// The headline results of one replay at a level with time, its clock `clock_mhz`.
    pub fn of(result: &LevelResult, clock_mhz: f64) -> Headlines {
        // The level's own percentiles (none without a query), not a third computation of
        // them (which had given 0).
        let cycles = |figure: Option<u64>| figure.map(|cycles| cycles as f64);
        Headlines {
            cycles: result.total_cycles.unwrap_or(0) as f64,
            frame_ms: result
                .frame_mean_cycles()
                .map(|cycles| cycles / (clock_mhz * 1e3)),
            latency_p50_cycles: cycles(result.latency_p50_cycles),
            latency_p95_cycles: cycles(result.latency_p95_cycles),
        }
    }

    pub fn get(&self, metric: Metric) -> Option<f64> {
        match metric {
            Metric::Cycles => Some(self.cycles),
            Metric::FrameTime => self.frame_ms,
            Metric::LatencyP50 => self.latency_p50_cycles,
            Metric::LatencyP95 => self.latency_p95_cycles,
        }
    }
}

/// Which end of a plausible range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum End {
    Low,
    High,
}

/// Parameters changed from a study's base: `(key, value)` in table order.
pub type Changes = Vec<(&'static str, Value)>;

/// `changes` as `key=value` pairs joined by commas, as `--set` takes them.
pub fn describe_changes(changes: &[(&str, Value)]) -> String {
    changes
        .iter()
        .map(|(key, value)| format!("{key}={value}"))
        .collect::<Vec<_>>()
        .join(",")
}

/// An architecture to replay and what it changes from the study's base.
#[derive(Clone, Debug, PartialEq)]
pub struct Variant {
    pub arch: Arch,
    pub changes: Changes,
}

/// Why a study cannot start.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SensitivityError {
    /// A base value outside its parameter's plausible range: the band would not be a band
    /// around it.
    #[error("parameter '{key}' = {value} lies outside its plausible {}; a band is taken around values inside it", plausible(low, high, *choice))]
    OutsideRange {
        key: &'static str,
        value: String,
        low: String,
        high: String,
        /// A choice's plausible values are the two named, not a range between them.
        choice: bool,
    },
    #[error(transparent)]
    Arch(#[from] ArchError),
    /// A variant the study makes (a parameter at an end of its plausible range, or a
    /// corner of several) is impossible with the rest of the base: the values set leave it
    /// no room.
    #[error(
        "the study's variant {changes} is impossible with the rest of the architecture: {error}"
    )]
    ImpossibleVariant { changes: String, error: ArchError },
    /// The results handed back do not match the variants handed out.
    #[error("{0}")]
    Mismatch(String),
}

/// One parameter's effect on one result.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Swing {
    pub key: &'static str,
    pub low_value: Value,
    pub high_value: Value,
    /// The result with the parameter at its low end and at its high end.
    pub at_low: f64,
    pub at_high: f64,
}

impl Swing {
    fn extent(&self, default: f64) -> f64 {
        let (lo, hi) = span([default, self.at_low, self.at_high]);
        hi - lo
    }
}

/// One headline result's band.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Band {
    pub metric: Metric,
    pub unit: &'static str,
    pub default: f64,
    pub low: f64,
    pub high: f64,
    /// The parameters that move the result, the most first.
    pub parameters: Vec<Swing>,
}

/// A sensitivity study around one architecture.
#[derive(Clone, Debug)]
pub struct Study {
    base: Arch,
    /// The inferred parameters varied, in table order, with their ranges.
    varied: Vec<(&'static Param, Value, Value)>,
}

/// A parameter's plausible values as a message names them: `range 2..6`, or for a choice
/// `choices columns and morton` (blocks, the third, had read as lying inside `columns..morton`).
fn plausible(low: &str, high: &str, choice: bool) -> String {
    match choice {
        true => format!("choices {low} and {high}"),
        false => format!("range {low}..{high}"),
    }
}

fn span<const N: usize>(values: [f64; N]) -> (f64, f64) {
    values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
            (lo.min(v), hi.max(v))
        })
}

impl Study {
    /// A study around `base`, varying every inferred parameter except those named in `fixed`
    /// (a sweep's own axes). Refuses a base value of an inferred parameter outside its
    /// plausible range.
    pub fn new(base: &Arch, fixed: &[&str]) -> Result<Study, SensitivityError> {
        let mut varied = Vec::new();
        for (param, value) in base.entries() {
            let Some((low, high)) = param.plausible() else {
                continue;
            };
            debug_assert_eq!(param.provenance.mark, Mark::I);
            if !param.is_plausible(value) {
                return Err(SensitivityError::OutsideRange {
                    key: param.key,
                    value: value.to_string(),
                    low: low.to_string(),
                    high: high.to_string(),
                    choice: matches!(value, Value::Choice(_)),
                });
            }
            if !fixed.contains(&param.key) {
                varied.push((param, low, high));
            }
        }
        Ok(Study {
            base: base.clone(),
            varied,
        })
    }

    /// The keys varied, in table order.
    pub fn keys(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.varied.iter().map(|(p, _, _)| p.key)
    }

    /// `arch` with `changes` applied, each checked as `set` checks it (an impossible
    /// result named by the whole variant, not by the base value it clashes with).
    pub fn apply(arch: &Arch, changes: &[(&'static str, Value)]) -> Result<Arch, SensitivityError> {
        let mut arch = arch.clone();
        for (key, value) in changes {
            arch.set_value(key, &value.to_string()).map_err(|error| {
                SensitivityError::ImpossibleVariant {
                    changes: describe_changes(changes),
                    error,
                }
            })?;
        }
        Ok(arch)
    }

    /// Step 1: every varied parameter at each end of its range that differs from its value,
    /// in table order, low end first.
    pub fn one_at_a_time(&self) -> Result<Vec<(usize, End, Variant)>, SensitivityError> {
        let mut variants = Vec::new();
        for (index, (param, low, high)) in self.varied.iter().enumerate() {
            let value = self.base.get(param.key);
            for (end, at) in [(End::Low, *low), (End::High, *high)] {
                if Some(at) == value {
                    continue;
                }
                let changes = vec![(param.key, at)];
                let arch = Self::apply(&self.base, &changes)?;
                variants.push((index, end, Variant { arch, changes }));
            }
        }
        Ok(variants)
    }

    /// Each varied parameter's result at its low and high end for `metric`, from step 1's
    /// results (`singles` parallel to [`Study::one_at_a_time`]'s variants).
    fn ends(
        &self,
        default: &Headlines,
        singles: &[((usize, End), Headlines)],
        metric: Metric,
    ) -> Vec<(f64, f64)> {
        let d = default.get(metric).unwrap_or(0.0);
        let mut ends = vec![(d, d); self.varied.len()];
        for ((index, end), result) in singles {
            let value = result.get(metric).unwrap_or(0.0);
            match end {
                End::Low => ends[*index].0 = value,
                End::High => ends[*index].1 = value,
            }
        }
        ends
    }

    /// Step 2: the corners of every metric `default` has, each as its changes from the base:
    /// `(metric, towards the high result?, changes)`; the caller replays each distinct set
    /// of changes once ([`Study::apply`]).
    pub fn corners(
        &self,
        default: &Headlines,
        singles: &[((usize, End), Headlines)],
    ) -> Vec<(Metric, End, Changes)> {
        let mut corners = Vec::new();
        for metric in METRICS {
            let Some(d) = default.get(metric) else {
                continue;
            };
            let ends = self.ends(default, singles, metric);
            for towards in [End::Low, End::High] {
                let mut changes = Vec::new();
                for ((param, low, high), &(at_low, at_high)) in self.varied.iter().zip(&ends) {
                    let better = |a: f64, b: f64| match towards {
                        End::High => a > b,
                        End::Low => a < b,
                    };
                    // The end that moves the result furthest this way, if either moves it.
                    let (best, at) = if better(at_high, at_low) {
                        (at_high, *high)
                    } else {
                        (at_low, *low)
                    };
                    if better(best, d) && self.base.get(param.key) != Some(at) {
                        changes.push((param.key, at));
                    }
                }
                corners.push((metric, towards, changes));
            }
        }
        corners
    }

    /// Step 3: the band of every metric `default` has, from step 1's results and the
    /// corners' (`corners` holds each corner's changes and its result).
    pub fn bands(
        &self,
        default: &Headlines,
        singles: &[((usize, End), Headlines)],
        corners: &[(Changes, Headlines)],
    ) -> Vec<Band> {
        let mut bands = Vec::new();
        for metric in METRICS {
            let Some(d) = default.get(metric) else {
                continue;
            };
            let ends = self.ends(default, singles, metric);
            let mut swings: Vec<Swing> = self
                .varied
                .iter()
                .zip(&ends)
                .map(|((param, low, high), &(at_low, at_high))| Swing {
                    key: param.key,
                    low_value: *low,
                    high_value: *high,
                    at_low,
                    at_high,
                })
                .collect();
            let (mut lo, mut hi) = (d, d);
            for v in ends
                .iter()
                .flat_map(|&(a, b)| [a, b])
                .chain(corners.iter().filter_map(|(_, h)| h.get(metric)))
            {
                lo = lo.min(v);
                hi = hi.max(v);
            }
            // Stable: equal swings keep table order.
            swings.sort_by(|a, b| b.extent(d).total_cmp(&a.extent(d)));
            swings.retain(|s| s.extent(d) > 0.0);
            bands.push(Band {
                metric,
                unit: metric.unit(),
                default: d,
                low: lo,
                high: hi,
                parameters: swings,
            });
        }
        bands
    }
}

/// A band around one result from the results of a study's corners only (what `--bands`
/// prints beside a figure): `low..high` over the default and the corners.
pub fn corner_band(
    default: &Headlines,
    corners: &[Headlines],
    metric: Metric,
) -> Option<(f64, f64)> {
    let d = default.get(metric)?;
    Some(
        corners
            .iter()
            .filter_map(|h| h.get(metric))
            .fold((d, d), |(lo, hi), v| (lo.min(v), hi.max(v))),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headlines(cycles: f64, p95: f64) -> Headlines {
        Headlines {
            cycles,
            frame_ms: None,
            latency_p50_cycles: Some(0.0),
            latency_p95_cycles: Some(p95),
        }
    }

    #[test]
    fn a_value_outside_its_plausible_range_is_refused() {
        let mut arch = Arch::builtin("o2").unwrap();
        // Legal (1..=65536) but outside the plausible 2..6.
        arch.set("page_hit_latency_cycles=40").unwrap();
        match Study::new(&arch, &[]) {
            Err(SensitivityError::OutsideRange { key, low, high, .. }) => {
                assert_eq!(
                    (key, low.as_str(), high.as_str()),
                    ("page_hit_latency_cycles", "2", "6")
                )
            }
            other => panic!("{other:?}"),
        }
        // A choice's plausible values are named as two, not a range.
        let mut ir = Arch::builtin("ir4").unwrap();
        ir.set("interleave=blocks").unwrap();
        let error = Study::new(&ir, &[]).unwrap_err().to_string();
        assert!(
            error.contains(
                "'interleave' = \"blocks\" lies outside its plausible choices \"columns\" and \"morton\""
            ),
            "{error}"
        );
        // A sweep's own axis is not varied, but its values are still checked.
        assert!(Study::new(&arch, &["page_hit_latency_cycles"]).is_err());
    }

    #[test]
    fn a_variant_the_base_leaves_no_room_for_is_named_as_the_studys_not_the_users() {
        let mut arch = Arch::builtin("o2").unwrap();
        // Possible on its own: 330 refreshes a second of 1280 x 1024 pixels of 32 bits read
        // 13.84 G bits a second of the port's 256 bits x 66.67 MHz = 17.07 G, 81.1%, and
        // host_memory_share's default 5% keeps the two within the 90% allowed. At
        // host_memory_share's high end, 15%, they reserve 96.1%.
        arch.set("display_refresh_hz=330").unwrap();
        let study = Study::new(&arch, &[]).unwrap();
        match study.one_at_a_time() {
            Err(SensitivityError::ImpossibleVariant { changes, error }) => {
                assert_eq!(changes, "host_memory_share=0.15");
                assert!(matches!(error, ArchError::Impossible(_)), "{error:?}");
            }
            other => panic!("{other:?}"),
        }
    }
    #[test]
    fn every_inferred_parameter_but_the_fixed_ones_is_varied_at_the_ends_that_differ() {
        let arch = Arch::builtin("o2").unwrap();
        let study = Study::new(&arch, &["engines"]).unwrap();
        assert!(!study.keys().any(|k| k == "engines"));
        assert!(study.keys().any(|k| k == "page_hit_latency_cycles"));
        assert!(!study.keys().any(|k| k == "clock_mhz"), "V is not varied");
        let singles = study.one_at_a_time().unwrap();
        // page_hit_latency_cycles = 2 is its low end: only the high end is replayed.
        let hit: Vec<_> = singles
            .iter()
            .filter(|(_, _, v)| v.changes[0].0 == "page_hit_latency_cycles")
            .collect();
        assert_eq!(hit.len(), 1);
        assert_eq!(hit[0].1, End::High);
        assert_eq!(
            hit[0].2.arch.get("page_hit_latency_cycles"),
            Some(Value::Int(6))
        );
    }

    #[test]
    fn bands_hold_the_default_and_order_by_swing() {
        let arch = Arch::builtin("o2").unwrap();
        let study = Study::new(&arch, &[]).unwrap();
        let index = |key: &str| study.keys().position(|k| k == key).unwrap();
        let (a, b) = (
            index("page_miss_latency_cycles"),
            index("prefetch_depth_fragments"),
        );
        let default = headlines(100.0, 10.0);
        // a moves cycles 90..130 (swing 40), b 95..105 (10); neither moves below 90 alone.
        let singles = vec![
            ((a, End::Low), headlines(90.0, 10.0)),
            ((a, End::High), headlines(130.0, 12.0)),
            ((b, End::Low), headlines(105.0, 10.0)),
            ((b, End::High), headlines(95.0, 10.0)),
        ];
        let corners = study.corners(&default, &singles);
        let (_, _, high_cycles) = corners
            .iter()
            .find(|(m, e, _)| *m == Metric::Cycles && *e == End::High)
            .unwrap();
        // Towards more cycles: a at its high end, b at its low end.
        assert_eq!(
            high_cycles,
            &vec![
                ("prefetch_depth_fragments", Value::Int(4)),
                ("page_miss_latency_cycles", Value::Int(10)),
            ]
        );
        let results = vec![
            (high_cycles.clone(), headlines(140.0, 13.0)),
            (vec![], headlines(85.0, 9.0)),
        ];
        let bands = study.bands(&default, &singles, &results);
        let cycles = &bands[0];
        assert_eq!(cycles.metric, Metric::Cycles);
        assert_eq!(
            (cycles.low, cycles.default, cycles.high),
            (85.0, 100.0, 140.0)
        );
        let keys: Vec<&str> = cycles.parameters.iter().map(|s| s.key).collect();
        assert_eq!(
            keys,
            ["page_miss_latency_cycles", "prefetch_depth_fragments"]
        );
        // No frame time in an open-loop trace: three bands, each holding its default.
        assert_eq!(bands.len(), 3);
        for band in &bands {
            assert!(
                band.low <= band.default && band.default <= band.high,
                "{band:?}"
            );
        }
        let p95 = bands
            .iter()
            .find(|b| b.metric == Metric::LatencyP95)
            .unwrap();
        assert_eq!((p95.low, p95.high), (9.0, 13.0));
        assert_eq!(
            corner_band(&default, &[headlines(140.0, 13.0)], Metric::Cycles),
            Some((100.0, 140.0))
        );
    }
}
