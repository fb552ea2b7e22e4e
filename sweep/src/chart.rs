//! The sweep's plot: one metric against one swept parameter, one series per combination of the
//! other axes' values (named by their canonical key, e.g. `boards=2`).

use crate::error::SweepError;
use crate::grid::Axis;
use crate::plot::{LineChart, Scale, Series};
use crate::record::StoredLine;
use serde_json::Value;

type Result<T, E = SweepError> = std::result::Result<T, E>;

/// Largest / smallest positive x at or above which the x axis is drawn log10 (power-of-two
/// sweeps such as engines=1,2,4,8,16 read better that way).
const LOG_X_RATIO: f64 = 8.0;
/// The same for y: only very wide metric ranges switch to log10.
const LOG_Y_RATIO: f64 = 1000.0;

/// The unit of a metric, from its name's ending (`_cycles`, `_seconds`, `_per_second`, ...).
pub fn metric_unit(metric: &str) -> Option<&'static str> {
    // A band's ends are in their metric's unit (they had been drawn without one).
    let metric = (metric.strip_suffix("_band_low"))
        .or_else(|| metric.strip_suffix("_band_high"))
        .unwrap_or(metric);
    let units = [
        ("frames_per_second", "frames/s"),
        ("fragments_per_cycle", "fragments/cycle"),
        ("_per_second", "/s"),
        ("_cycles", "cycles"),
        ("_seconds", "s"),
        ("_percent", "%"),
        ("_ms", "ms"),
        ("fragments", "fragments"),
        ("queries", "queries"),
    ];
    units
        .iter()
        .find(|(ending, _)| metric.ends_with(ending))
        .map(|(_, unit)| *unit)
}

/// `name (unit)`, or `name` alone when the unit says nothing more.
fn with_unit(name: &str, unit: Option<&str>) -> String {
    match unit {
        Some(unit) if !unit.is_empty() && unit != name && unit != "name" && unit != "bool" => {
            format!("{name} ({unit})")
        }
        _ => name.to_string(),
    }
}

/// The unit a swept parameter's resolved architecture entry carries (`{"key", "value",
/// "unit"}` in the first line's `resolved_arch`, read from its text), if it has one.
fn parameter_unit(lines: &[StoredLine], key: &str) -> Option<String> {
    let first: Value = serde_json::from_str(&lines.first()?.text).ok()?;
    first["resolved_arch"]
        .as_array()?
        .iter()
        .find(|e| e["key"] == key)?
        .get("unit")?
        .as_str()
        .map(str::to_owned)
}

/// Builds the chart of `metric` against axis `x_key` (the last axis when None). The title
/// names the metric and its unit, the x axis, and `subject` (what was swept: the trace and
/// the machine, as the caller words them); each axis label carries its unit.
pub fn metric_chart(
    axes: &[Axis],
    lines: &[StoredLine],
    metric: &str,
    x_key: Option<&str>,
    subject: &str,
) -> Result<LineChart> {
    let (x_axis, x_values) = plot_axis(axes, x_key)?;
    if !lines.iter().any(|s| s.line.metrics.contains_key(metric)) {
        let known: std::collections::BTreeSet<&str> = lines
            .iter()
            .flat_map(|s| s.line.metrics.keys().map(String::as_str))
            .collect();
        return Err(SweepError::NoSuchMetric {
            metric: metric.to_owned(),
            present: known.into_iter().map(str::to_owned).collect(),
        });
    }

    let mut series: Vec<Series> = Vec::new();
    for stored in lines {
        let line = &stored.line;
        let y = match line.metrics.get(metric) {
            None | Some(Value::Null) => continue,
            Some(value) => value.as_f64().ok_or_else(|| SweepError::MetricNotANumber {
                metric: metric.to_owned(),
                key: line.key.clone(),
                value: value.to_string(),
            })?,
        };
        let mut x = None;
        let mut others = Vec::new();
        for pair in line.key.split(',').filter_map(|p| p.split_once('=')) {
            if pair.0 == x_axis.key {
                x = pair.1.parse::<f64>().ok();
            } else {
                others.push(format!("{}={}", pair.0, pair.1));
            }
        }
        let x = x.ok_or_else(|| SweepError::NoNumericX {
            key: line.key.clone(),
            axis: x_axis.key.clone(),
        })?;
        let name = if others.is_empty() {
            metric.to_string()
        } else {
            others.join(",")
        };
        match series.iter_mut().find(|s| s.name == name) {
            Some(s) => s.points.push((x, y)),
            None => series.push(Series {
                name,
                points: vec![(x, y)],
            }),
        }
    }
    let all = |pick: fn(&(f64, f64)) -> f64| {
        series
            .iter()
            .flat_map(|s| s.points.iter().map(pick))
            .collect::<Vec<f64>>()
    };
    let y_label = with_unit(metric, metric_unit(metric));
    let x_label = with_unit(&x_axis.key, parameter_unit(lines, &x_axis.key).as_deref());
    Ok(LineChart {
        title: format!("{y_label} against {}: {subject}", x_axis.key),
        x_label,
        y_label,
        x_scale: pick_scale(&all(|p| p.0), LOG_X_RATIO),
        y_scale: pick_scale(&all(|p| p.1), LOG_Y_RATIO),
        x_ticks: Some(x_values),
        series,
    })
}

/// The axis a chart of `axes` is drawn against, `x_key` else the last, with its values as
/// numbers; refused unless it is swept and every value of it a number. Known before any
/// point runs, so a sweep checks it first (a sweep over `blending=false,true` with `--plot`
/// had run every point, written its results and then failed on the chart).
pub fn plot_axis<'a>(axes: &'a [Axis], x_key: Option<&str>) -> Result<(&'a Axis, Vec<f64>)> {
    let x_axis = match x_key {
        Some(key) => axes
            .iter()
            .find(|a| a.key == key)
            .ok_or_else(|| SweepError::NotSwept {
                key: key.to_owned(),
                swept: axes.iter().map(|a| a.key.clone()).collect(),
            })?,
        None => axes.last().ok_or(SweepError::NothingSwept)?,
    };
    Ok((x_axis, numeric_values(x_axis)?))
}

/// The axis values as numbers (the chart's x ticks), or an error naming a non-numeric one.
fn numeric_values(axis: &Axis) -> Result<Vec<f64>> {
    if let Some(bad) = axis
        .values
        .iter()
        .find(|v| !v.parse::<f64>().is_ok_and(f64::is_finite))
    {
        return Err(SweepError::NonNumericAxis {
            key: axis.key.clone(),
            value: bad.clone(),
        });
    }
    Ok(axis.values.iter().filter_map(|v| v.parse().ok()).collect())
}

/// Log10 when every value is positive and they span at least `ratio`.
fn pick_scale(values: &[f64], ratio: f64) -> Scale {
    let min = values.iter().copied().fold(f64::INFINITY, f64::min);
    let max = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if min > 0.0 && max / min >= ratio {
        Scale::Log10
    } else {
        Scale::Linear
    }
}
