//! A small SVG line-chart writer: title, axis labels, linear or log10 axes with readable tick
//! labels, named series with distinct colours and markers, and a legend.
//!
//! Architecture invariant: the SVG text is a pure function of the chart (no clocks, no hash
//! order, fixed number formatting), so plots are as reproducible as the results they show.

use anyhow::{bail, Result};
use std::fmt::Write as _;
use std::path::Path;

/// How an axis maps values to positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Scale {
    Linear,
    /// Decades evenly spaced; every value on the axis must be > 0.
    Log10,
}

/// One named line of (x, y) points; drawn in ascending x.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
}

/// A chart ready to render.
#[derive(Debug, Clone, PartialEq)]
pub struct LineChart {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_scale: Scale,
    pub y_scale: Scale,
    /// Put x ticks exactly at these values (e.g. the swept values 1, 2, 4, 8, 16) instead of
    /// round numbers; values outside the axis range are left out.
    pub x_ticks: Option<Vec<f64>>,
    pub series: Vec<Series>,
}

/// Okabe-Ito colours (distinguishable with colour blindness), yellow left out: too pale on white.
const COLOURS: [&str; 7] = [
    "#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000",
];
/// Marker shapes, cycled at a different period from the colours so that series 0..41 differ.
const MARKERS: [Marker; 6] = [
    Marker::Circle,
    Marker::Square,
    Marker::TriangleUp,
    Marker::Diamond,
    Marker::TriangleDown,
    Marker::Cross,
];

#[derive(Debug, Clone, Copy)]
enum Marker {
    Circle,
    Square,
    TriangleUp,
    Diamond,
    TriangleDown,
    Cross,
}

// Layout in SVG user units (pixels).
const PLOT_WIDTH: f64 = 560.0;
const PLOT_HEIGHT: f64 = 360.0;
const LEFT: f64 = 80.0;
const TOP: f64 = 50.0;
const BOTTOM_MARGIN: f64 = 60.0;
const LEGEND_GAP: f64 = 20.0;
/// Rough width of one legend character at font size 12, to size the canvas.
const CHAR_WIDTH: f64 = 7.0;
const MARKER_RADIUS: f64 = 4.0;

impl LineChart {
    /// Renders the chart as an SVG document. Errors on no points, non-finite values, or a
    /// value <= 0 on a log10 axis.
    pub fn to_svg(&self) -> Result<String> {
        self.check_values()?;
        let mut x_axis = AxisMap::fit(
            self.x_scale,
            self.series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.0)),
            0.0,
            PLOT_WIDTH,
        );
        if let Some(values) = &self.x_ticks {
            x_axis.set_ticks(values);
        }
        let y_axis = AxisMap::fit(
            self.y_scale,
            self.series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.1)),
            PLOT_HEIGHT,
            0.0,
        );
        let longest_name = self
            .series
            .iter()
            .map(|s| s.name.chars().count())
            .max()
            .unwrap_or(0);
        let legend_width = 50.0 + CHAR_WIDTH * longest_name as f64;
        let width = LEFT + PLOT_WIDTH + LEGEND_GAP + legend_width + 10.0;
        let height = TOP + PLOT_HEIGHT + BOTTOM_MARGIN;

        let mut svg = String::new();
        let _ = writeln!(svg, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
        let _ = writeln!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" font-family="sans-serif" font-size="12">"#,
            w = num(width),
            h = num(height)
        );
        let _ = writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#);
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="28" text-anchor="middle" font-size="16">{}</text>"#,
            num(LEFT + PLOT_WIDTH / 2.0),
            escape(&self.title)
        );
        self.write_axes(&mut svg, &x_axis, &y_axis);
        for (i, series) in self.series.iter().enumerate() {
            write_series(&mut svg, i, series, &x_axis, &y_axis);
        }
        self.write_legend(&mut svg, LEFT + PLOT_WIDTH + LEGEND_GAP);
        svg.push_str("</svg>\n");
        Ok(svg)
    }

    /// Renders and writes the chart to `path` atomically.
    pub fn write_svg(&self, path: &Path) -> Result<()> {
        let svg = self.to_svg()?;
        crate::output::write_atomically(path, svg.as_bytes())
    }

    fn check_values(&self) -> Result<()> {
        if self.series.iter().all(|s| s.points.is_empty()) {
            bail!("cannot plot '{}': no points", self.title);
        }
        for series in &self.series {
            for &(x, y) in &series.points {
                for (value, axis, scale) in [(x, "x", self.x_scale), (y, "y", self.y_scale)] {
                    if !value.is_finite() {
                        bail!(
                            "cannot plot series '{}': {axis} = {value} is not a finite number",
                            series.name
                        );
                    }
                    if scale == Scale::Log10 && value <= 0.0 {
                        bail!(
                            "cannot plot series '{}' on a log10 {axis} axis: {axis} = {value} is not positive",
                            series.name
                        );
                    }
                }
            }
        }
        Ok(())
    }

    fn write_axes(&self, svg: &mut String, x_axis: &AxisMap, y_axis: &AxisMap) {
        let bottom = TOP + PLOT_HEIGHT;
        svg.push_str("<g class=\"grid\" stroke=\"#dddddd\" stroke-width=\"1\">\n");
        for tick in &x_axis.ticks {
            let x = LEFT + x_axis.position(tick.value);
            let _ = writeln!(
                svg,
                r#"<line x1="{x}" y1="{}" x2="{x}" y2="{}"/>"#,
                num(TOP),
                num(bottom),
                x = num(x)
            );
        }
        for tick in &y_axis.ticks {
            let y = TOP + y_axis.position(tick.value);
            let _ = writeln!(
                svg,
                r#"<line x1="{}" y1="{y}" x2="{}" y2="{y}"/>"#,
                num(LEFT),
                num(LEFT + PLOT_WIDTH),
                y = num(y)
            );
        }
        svg.push_str("</g>\n<g class=\"axes\">\n");
        let _ = writeln!(
            svg,
            r#"<rect x="{}" y="{}" width="{}" height="{}" fill="none" stroke="black"/>"#,
            num(LEFT),
            num(TOP),
            num(PLOT_WIDTH),
            num(PLOT_HEIGHT)
        );
        for tick in &x_axis.ticks {
            let x = num(LEFT + x_axis.position(tick.value));
            let _ = writeln!(
                svg,
                r#"<text x="{x}" y="{}" text-anchor="middle">{}</text>"#,
                num(bottom + 18.0),
                escape(&tick.label)
            );
        }
        for tick in &y_axis.ticks {
            let y = num(TOP + y_axis.position(tick.value) + 4.0);
            let _ = writeln!(
                svg,
                r#"<text x="{}" y="{y}" text-anchor="end">{}</text>"#,
                num(LEFT - 6.0),
                escape(&tick.label)
            );
        }
        let _ = writeln!(
            svg,
            r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
            num(LEFT + PLOT_WIDTH / 2.0),
            num(bottom + 45.0),
            escape(&self.x_label)
        );
        let (label_x, label_y) = (num(22.0), num(TOP + PLOT_HEIGHT / 2.0));
        let _ = writeln!(
            svg,
            r#"<text x="{label_x}" y="{label_y}" text-anchor="middle" transform="rotate(-90 {label_x} {label_y})">{}</text>"#,
            escape(&self.y_label)
        );
        svg.push_str("</g>\n");
    }

    fn write_legend(&self, svg: &mut String, left: f64) {
        svg.push_str("<g class=\"legend\">\n");
        for (i, series) in self.series.iter().enumerate() {
            let y = TOP + 10.0 + 20.0 * i as f64;
            let colour = COLOURS[i % COLOURS.len()];
            let _ = writeln!(
                svg,
                r#"<line x1="{}" y1="{y}" x2="{}" y2="{y}" stroke="{colour}" stroke-width="2"/>"#,
                num(left),
                num(left + 30.0),
                y = num(y)
            );
            write_marker(svg, MARKERS[i % MARKERS.len()], left + 15.0, y, colour);
            let _ = writeln!(
                svg,
                r#"<text x="{}" y="{}">{}</text>"#,
                num(left + 38.0),
                num(y + 4.0),
                escape(&series.name)
            );
        }
        svg.push_str("</g>\n");
    }
}

fn write_series(svg: &mut String, i: usize, series: &Series, x_axis: &AxisMap, y_axis: &AxisMap) {
    let colour = COLOURS[i % COLOURS.len()];
    let mut points = series.points.clone();
    points.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let positions: Vec<(f64, f64)> = points
        .iter()
        .map(|&(x, y)| (LEFT + x_axis.position(x), TOP + y_axis.position(y)))
        .collect();
    let _ = writeln!(
        svg,
        r#"<g class="series" data-name="{}">"#,
        escape(&series.name)
    );
    if positions.len() > 1 {
        let path: Vec<String> = positions
            .iter()
            .map(|&(x, y)| format!("{},{}", num(x), num(y)))
            .collect();
        let _ = writeln!(
            svg,
            r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="2"/>"#,
            path.join(" ")
        );
    }
    for &(x, y) in &positions {
        write_marker(svg, MARKERS[i % MARKERS.len()], x, y, colour);
    }
    svg.push_str("</g>\n");
}

fn write_marker(svg: &mut String, marker: Marker, x: f64, y: f64, colour: &str) {
    let r = MARKER_RADIUS;
    let polygon = |corners: &[(f64, f64)]| -> String {
        let list: Vec<String> = corners
            .iter()
            .map(|&(dx, dy)| format!("{},{}", num(x + dx), num(y + dy)))
            .collect();
        format!(r#"<polygon points="{}" fill="{colour}"/>"#, list.join(" "))
    };
    let element = match marker {
        Marker::Circle => format!(
            r#"<circle cx="{}" cy="{}" r="{}" fill="{colour}"/>"#,
            num(x),
            num(y),
            num(r)
        ),
        Marker::Square => format!(
            r#"<rect x="{}" y="{}" width="{}" height="{}" fill="{colour}"/>"#,
            num(x - r),
            num(y - r),
            num(2.0 * r),
            num(2.0 * r)
        ),
        Marker::TriangleUp => polygon(&[(0.0, -r - 1.0), (r + 1.0, r), (-r - 1.0, r)]),
        Marker::TriangleDown => polygon(&[(0.0, r + 1.0), (r + 1.0, -r), (-r - 1.0, -r)]),
        Marker::Diamond => polygon(&[
            (0.0, -r - 1.0),
            (r + 1.0, 0.0),
            (0.0, r + 1.0),
            (-r - 1.0, 0.0),
        ]),
        Marker::Cross => format!(
            r#"<path d="M{} {} L{} {} M{} {} L{} {}" stroke="{colour}" stroke-width="2"/>"#,
            num(x - r),
            num(y - r),
            num(x + r),
            num(y + r),
            num(x - r),
            num(y + r),
            num(x + r),
            num(y - r)
        ),
    };
    svg.push_str(&element);
    svg.push('\n');
}

/// A tick: where it is (in data units) and what it says.
#[derive(Debug, Clone, PartialEq)]
struct Tick {
    value: f64,
    label: String,
}

/// Maps data values onto [from, to] in SVG units (to < from for the y axis, which grows down).
#[derive(Debug)]
struct AxisMap {
    scale: Scale,
    /// Axis range in transformed units (log10 of the value for Log10).
    low: f64,
    high: f64,
    from: f64,
    to: f64,
    ticks: Vec<Tick>,
}

impl AxisMap {
    /// Fits an axis to `values` (finite, and > 0 for Log10: checked by the caller).
    fn fit(scale: Scale, values: impl Iterator<Item = f64>, from: f64, to: f64) -> AxisMap {
        let (min, max) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        let (low, high, ticks) = match scale {
            Scale::Linear => linear_ticks(min, max),
            Scale::Log10 => log_ticks(min, max),
        };
        AxisMap {
            scale,
            low,
            high,
            from,
            to,
            ticks,
        }
    }

    fn transform(&self, value: f64) -> f64 {
        match self.scale {
            Scale::Linear => value,
            Scale::Log10 => value.log10(),
        }
    }

    fn position(&self, value: f64) -> f64 {
        self.from
            + (self.transform(value) - self.low) / (self.high - self.low) * (self.to - self.from)
    }

    /// Replaces the automatic ticks by `values` that fall inside the axis range.
    fn set_ticks(&mut self, values: &[f64]) {
        let inside = |v: f64| {
            let t = self.transform(v);
            t.is_finite() && t >= self.low - 1e-9 && t <= self.high + 1e-9
        };
        self.ticks = values
            .iter()
            .copied()
            .filter(|&v| inside(v))
            .map(|value| Tick {
                value,
                label: format_general(value),
            })
            .collect();
    }
}

/// Ticks every 1, 2 or 5 x 10^k, about five of them, the range widened to whole ticks.
fn linear_ticks(min: f64, max: f64) -> (f64, f64, Vec<Tick>) {
    let (min, max) = if max > min {
        (min, max)
    } else {
        let pad = if min == 0.0 { 1.0 } else { min.abs() * 0.1 };
        (min - pad, max + pad)
    };
    let rough = (max - min) / 5.0;
    let exponent = rough.log10().floor() as i32;
    let magnitude = 10f64.powi(exponent);
    let mantissa = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .find(|m| m * magnitude >= rough)
        .unwrap_or(10.0);
    let step = mantissa * magnitude;
    // The tolerance keeps a value lying on a tick (up to rounding) from adding one more.
    let first = (min / step + 1e-9).floor() as i64;
    let last = (max / step - 1e-9).ceil() as i64;
    let decimals = if mantissa == 10.0 {
        (-exponent - 1).max(0)
    } else {
        (-exponent).max(0)
    } as usize;
    let ticks = (first..=last)
        .map(|k| {
            let value = k as f64 * step;
            Tick {
                value,
                label: format_tick(value, decimals),
            }
        })
        .collect();
    (first as f64 * step, last as f64 * step, ticks)
}

/// Log ticks over the data range padded by 5% of its span (half a decade each side for a
/// single value): every 1..9 x 10^k on narrow ranges, 1, 2, 5 x 10^k up to 2.5 decades, whole
/// decades beyond (every other or fifth one on very wide ranges). Falls back to the range's
/// ends when no such tick lies inside.
fn log_ticks(min: f64, max: f64) -> (f64, f64, Vec<Tick>) {
    let (low, high) = (min.log10(), max.log10());
    let pad = if high > low { (high - low) * 0.05 } else { 0.5 };
    let (low, high) = (low - pad, high + pad);
    let span = high - low;
    let mantissas: &[f64] = if span <= 0.6 {
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]
    } else if span <= 2.5 {
        &[1.0, 2.0, 5.0]
    } else {
        &[1.0]
    };
    let every = if span > 16.0 {
        5
    } else if span > 8.0 {
        2
    } else {
        1
    };
    let mut ticks = Vec::new();
    for exponent in (low.floor() as i32)..=(high.ceil() as i32) {
        if exponent.rem_euclid(every) != 0 {
            continue;
        }
        for &m in mantissas {
            let value = m * 10f64.powi(exponent);
            let at = value.log10();
            if at < low - 1e-9 || at > high + 1e-9 {
                continue;
            }
            let label = if (-3..6).contains(&exponent) {
                format_tick(value, (-exponent).max(0) as usize)
            } else {
                format!("{m}e{exponent}")
            };
            ticks.push(Tick { value, label });
        }
    }
    if ticks.is_empty() {
        ticks = [min, max]
            .iter()
            .map(|&v| Tick {
                value: v,
                label: format_general(v),
            })
            .collect();
        ticks.dedup();
    }
    (low, high, ticks)
}

/// A value as short as it can be read: up to four decimals, trailing zeros removed.
fn format_general(value: f64) -> String {
    let text = format_tick(value, 4);
    if text.contains('.') && !text.contains('e') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// A tick label with `decimals` digits after the point, or e-notation for very large or very
/// small magnitudes (trailing zeros of the mantissa removed).
fn format_tick(value: f64, decimals: usize) -> String {
    let magnitude = value.abs();
    if magnitude != 0.0 && !(1e-3..1e6).contains(&magnitude) {
        let text = format!("{value:.3e}");
        let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        return format!("{mantissa}e{exponent}");
    }
    let text = format!("{value:.decimals$}");
    // Zero reads best bare (no "-0", no "0.0000").
    if text
        .trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        return "0".to_string();
    }
    text
}

/// Coordinates with two decimals: deterministic and short.
fn num(v: f64) -> String {
    let text = format!("{v:.2}");
    let text = text.trim_end_matches('0').trim_end_matches('.');
    if text == "-0" {
        "0".to_string()
    } else {
        text.to_string()
    }
}

/// Escapes text for element content and attribute values.
fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart(x_scale: Scale, y_scale: Scale, series: Vec<Series>) -> LineChart {
        LineChart {
            title: "p50 & p95 <latency>".into(),
            x_label: "engines".into(),
            y_label: "cycles".into(),
            x_scale,
            y_scale,
            x_ticks: None,
            series,
        }
    }

    fn series(name: &str, points: &[(f64, f64)]) -> Series {
        Series {
            name: name.into(),
            points: points.to_vec(),
        }
    }

    /// Checks that tags nest and close properly and that text holds no raw '<' or bare '&'.
    fn assert_well_formed(svg: &str) {
        let mut open: Vec<String> = Vec::new();
        let mut rest = svg;
        while let Some(start) = rest.find('<') {
            assert_text_is_escaped(&rest[..start]);
            let end = rest[start..].find('>').expect("unclosed tag") + start;
            let tag = &rest[start + 1..end];
            rest = &rest[end + 1..];
            if tag.starts_with('?') {
                assert!(tag.ends_with('?'), "bad declaration <{tag}>");
            } else if let Some(name) = tag.strip_prefix('/') {
                assert_eq!(open.pop().as_deref(), Some(name), "mismatched </{name}>");
            } else if !tag.ends_with('/') {
                let name = tag.split_whitespace().next().expect("empty tag");
                open.push(name.to_string());
            }
            assert_eq!(
                tag.matches('"').count() % 2,
                0,
                "unbalanced quotes in <{tag}>"
            );
        }
        assert_text_is_escaped(rest);
        assert!(open.is_empty(), "unclosed elements {open:?}");
    }

    fn assert_text_is_escaped(text: &str) {
        for (i, _) in text.match_indices('&') {
            let entity = &text[i..text[i..].find(';').map_or(text.len(), |e| i + e + 1)];
            assert!(
                ["&amp;", "&lt;", "&gt;", "&quot;", "&apos;"].contains(&entity),
                "bare & in {text:?}"
            );
        }
    }

    #[test]
    fn svg_is_well_formed_and_names_every_series() {
        let c = chart(
            Scale::Linear,
            Scale::Linear,
            vec![
                series("boards=1", &[(1.0, 10.0), (2.0, 6.0), (4.0, 4.5)]),
                series("boards=2 \"fast\"", &[(1.0, 5.0), (4.0, 2.0)]),
            ],
        );
        let svg = c.to_svg().unwrap();
        assert_well_formed(&svg);
        assert!(svg.starts_with("<?xml"));
        assert!(svg.contains(">boards=1</text>"));
        assert!(svg.contains(">boards=2 &quot;fast&quot;</text>"));
        assert!(svg.contains(">p50 &amp; p95 &lt;latency&gt;</text>"));
        assert_eq!(svg.matches("<polyline").count(), 2);
        assert_eq!(svg, c.to_svg().unwrap(), "rendering is deterministic");
    }

    #[test]
    fn log_axes_reject_non_positive_values() {
        let zero_x = chart(
            Scale::Log10,
            Scale::Linear,
            vec![series("a", &[(0.0, 1.0)])],
        );
        let err = zero_x.to_svg().unwrap_err().to_string();
        assert_eq!(
            err,
            "cannot plot series 'a' on a log10 x axis: x = 0 is not positive"
        );
        let negative_y = chart(
            Scale::Linear,
            Scale::Log10,
            vec![series("b", &[(1.0, -2.0)])],
        );
        let err = negative_y.to_svg().unwrap_err().to_string();
        assert_eq!(
            err,
            "cannot plot series 'b' on a log10 y axis: y = -2 is not positive"
        );
    }

    #[test]
    fn empty_and_non_finite_charts_are_rejected() {
        assert!(chart(Scale::Linear, Scale::Linear, vec![series("a", &[])])
            .to_svg()
            .is_err());
        let nan = chart(
            Scale::Linear,
            Scale::Linear,
            vec![series("a", &[(1.0, f64::NAN)])],
        );
        assert!(nan
            .to_svg()
            .unwrap_err()
            .to_string()
            .contains("not a finite number"));
    }

    #[test]
    fn linear_ticks_are_round_numbers_covering_the_data() {
        let labels = |min, max| -> Vec<String> {
            linear_ticks(min, max)
                .2
                .into_iter()
                .map(|t| t.label)
                .collect()
        };
        assert_eq!(labels(0.0, 10.0), ["0", "2", "4", "6", "8", "10"]);
        assert_eq!(labels(0.1, 0.3), ["0.10", "0.15", "0.20", "0.25", "0.30"]);
        assert_eq!(labels(3.0, 3.0), ["2.6", "2.8", "3.0", "3.2", "3.4"]);
        assert_eq!(labels(0.0, 3e6), ["0", "1e6", "2e6", "3e6"]);
        assert_eq!(
            labels(-0.0004, 0.0),
            ["-4e-4", "-3e-4", "-2e-4", "-1e-4", "0"]
        );
    }

    #[test]
    fn log_ticks_label_decades_readably() {
        let labels = |min, max| -> Vec<String> {
            log_ticks(min, max).2.into_iter().map(|t| t.label).collect()
        };
        assert_eq!(labels(1.0, 16.0), ["1", "2", "5", "10"]);
        assert_eq!(labels(3.0, 7.0), ["3", "4", "5", "6", "7"]);
        assert_eq!(
            labels(0.002, 3000.0),
            ["0.001", "0.01", "0.1", "1", "10", "100", "1000"]
        );
        assert_eq!(labels(1e-8, 1.0), ["1e-8", "1e-6", "1e-4", "0.01", "1"]);
        assert_eq!(
            labels(1.0, 1e10),
            ["1", "100", "10000", "1e6", "1e8", "1e10"]
        );
        assert_eq!(labels(1.1, 1.3), ["1.1", "1.3"]);
    }

    #[test]
    fn explicit_x_ticks_replace_round_numbers() {
        let mut c = chart(
            Scale::Log10,
            Scale::Linear,
            vec![series("a", &[(1.0, 3.0), (16.0, 1.0)])],
        );
        c.x_ticks = Some(vec![1.0, 2.0, 4.0, 8.0, 16.0, 1000.0]);
        let svg = c.to_svg().unwrap();
        let x_labels: Vec<&str> = svg
            .lines()
            .filter(|l| l.contains("text-anchor=\"middle\">") && l.contains("y=\"428\""))
            .map(|l| &l[l.find('>').unwrap() + 1..l.find("</").unwrap()])
            .collect();
        assert_eq!(x_labels, ["1", "2", "4", "8", "16"]);
    }

    #[test]
    fn points_map_inside_the_plot_area() {
        // Two decades padded by 0.1 decade each side: 2.2 decades over 220 units.
        let axis = AxisMap::fit(Scale::Log10, [1.0, 100.0].into_iter(), 0.0, 220.0);
        for (value, expected) in [(1.0, 10.0), (10.0, 110.0), (100.0, 210.0)] {
            assert!((axis.position(value) - expected).abs() < 1e-9, "{value}");
        }
    }
}
