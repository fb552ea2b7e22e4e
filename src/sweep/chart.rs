//! The sweep's plot: one metric against one swept parameter, one series per combination of the
//! other axes' values (named by their canonical key, e.g. `boards=2`).

use super::grid::Axis;
use super::record::StoredLine;
use crate::plot::{LineChart, Scale, Series};
use anyhow::{bail, Context, Result};
use serde_json::Value;

/// Largest / smallest positive x at or above which the x axis is drawn log10 (power-of-two
/// sweeps such as engines=1,2,4,8,16 read better that way).
const LOG_X_RATIO: f64 = 8.0;
/// The same for y: only very wide metric ranges switch to log10.
const LOG_Y_RATIO: f64 = 1000.0;

/// Builds the chart of `metric` against axis `x_key` (the last axis when None).
pub fn metric_chart(
    axes: &[Axis],
    lines: &[StoredLine],
    metric: &str,
    x_key: Option<&str>,
) -> Result<LineChart> {
    let x_axis = match x_key {
        Some(key) => axes.iter().find(|a| a.key == key).with_context(|| {
            format!(
                "cannot plot against '{key}': it is not swept (swept: {})",
                axis_names(axes)
            )
        })?,
        None => axes
            .last()
            .context("cannot plot: no parameter is swept (add --set)")?,
    };
    let x_values = numeric_values(x_axis)?;
    if !lines.iter().any(|s| s.line.metrics.contains_key(metric)) {
        let known: std::collections::BTreeSet<&str> = lines
            .iter()
            .flat_map(|s| s.line.metrics.keys().map(String::as_str))
            .collect();
        let known: Vec<&str> = known.into_iter().collect();
        bail!(
            "no result has metric '{metric}'; metrics present: {}",
            known.join(", ")
        );
    }

    let mut series: Vec<Series> = Vec::new();
    for stored in lines {
        let line = &stored.line;
        let y = match line.metrics.get(metric) {
            None | Some(Value::Null) => continue,
            Some(value) => value.as_f64().with_context(|| {
                format!(
                    "metric '{metric}' of point '{}' is {value}, not a number",
                    line.key
                )
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
        let x = x.with_context(|| format!("point '{}' has no numeric {}", line.key, x_axis.key))?;
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
    Ok(LineChart {
        title: format!("{metric} vs {}", x_axis.key),
        x_label: x_axis.key.clone(),
        y_label: metric.to_string(),
        x_scale: pick_scale(&all(|p| p.0), LOG_X_RATIO),
        y_scale: pick_scale(&all(|p| p.1), LOG_Y_RATIO),
        x_ticks: Some(x_values),
        series,
    })
}

fn axis_names(axes: &[Axis]) -> String {
    let names: Vec<&str> = axes.iter().map(|a| a.key.as_str()).collect();
    names.join(", ")
}

/// The axis values as numbers (the chart's x ticks), or an error naming a non-numeric one.
fn numeric_values(axis: &Axis) -> Result<Vec<f64>> {
    if let Some(bad) = axis
        .values
        .iter()
        .find(|v| !v.parse::<f64>().is_ok_and(f64::is_finite))
    {
        bail!(
            "cannot plot against '{}': value '{bad}' is not a number (choose another --plot-x)",
            axis.key
        );
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
