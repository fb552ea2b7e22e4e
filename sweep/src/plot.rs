//! SVG line charts drawn with plotters: title, axis labels, linear or log10 axes with readable
//! tick labels, named series with distinct colours and markers, and a legend.
//!
//! Both axes are plain f64 ranges: a log10 axis is drawn in log10 units, its ticks placed as
//! explicit key points ([`Ticked`]) and labelled with the values they stand for, so one
//! coordinate type serves every combination of scales and the tick choice stays this
//! module's own.
//!
//! Architecture invariant: the SVG text is a pure function of the chart (no clocks, no hash
//! order, fixed number formatting), so plots are as reproducible as the results they show.

use crate::output::{write_atomically, OutputError};
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
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

/// Why a chart cannot be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("cannot plot '{title}': no points")]
    NoPoints { title: String },
    #[error("cannot plot series '{series}': {axis} = {value} is not a finite number")]
    NotFinite {
        series: String,
        axis: &'static str,
        value: f64,
    },
    #[error(
        "cannot plot series '{series}' on a log10 {axis} axis: {axis} = {value} is not positive"
    )]
    NotPositive {
        series: String,
        axis: &'static str,
        value: f64,
    },
    /// plotters failed to draw (it reports its errors as text).
    #[error("cannot draw the chart: {0}")]
    Draw(String),
    #[error(transparent)]
    Write(#[from] OutputError),
}

/// Okabe-Ito colours (distinguishable with colour blindness), yellow left out: too pale on white.
const COLOURS: [RGBColor; 7] = [
    RGBColor(0x00, 0x72, 0xB2),
    RGBColor(0xD5, 0x5E, 0x00),
    RGBColor(0x00, 0x9E, 0x73),
    RGBColor(0xCC, 0x79, 0xA7),
    RGBColor(0xE6, 0x9F, 0x00),
    RGBColor(0x56, 0xB4, 0xE9),
    RGBColor(0x00, 0x00, 0x00),
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
const PLOT_WIDTH: u32 = 560;
const PLOT_HEIGHT: u32 = 360;
/// Room left of the plot for the y tick labels and the y label.
const LEFT: u32 = 80;
/// Room above the plot for the title.
const TOP: u32 = 50;
/// Room below the plot for the x tick labels and the x label.
const BOTTOM: u32 = 60;
const RIGHT_MARGIN: u32 = 10;
const LEGEND_GAP: i32 = 10;
/// Rough width of one legend character, to size the canvas.
const CHAR_WIDTH: u32 = 7;
const MARKER_RADIUS: i32 = 4;
/// Font sizes as plotters takes them (its SVG backend writes 1/1.24 of them: about 12 and 16 px).
const FONT: f64 = 15.0;
const TITLE_FONT: f64 = 20.0;
const GRID_GREY: RGBColor = RGBColor(0xdd, 0xdd, 0xdd);

impl LineChart {
    /// Renders the chart as an SVG document. Errors on no points, non-finite values, or a
    /// value <= 0 on a log10 axis.
    pub fn to_svg(&self) -> Result<String, PlotError> {
        self.check_values()?;
        let mut x_axis = AxisMap::fit(
            self.x_scale,
            self.series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.0)),
        );
        if let Some(values) = &self.x_ticks {
            x_axis.set_ticks(values);
        }
        let y_axis = AxisMap::fit(
            self.y_scale,
            self.series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| p.1)),
        );
        let longest_name = self
            .series
            .iter()
            .map(|s| s.name.chars().count())
            .max()
            .unwrap_or(0);
        let chart_width = LEFT + PLOT_WIDTH + RIGHT_MARGIN;
        let legend_width = 50 + CHAR_WIDTH * longest_name as u32;
        let size = (chart_width + legend_width, TOP + PLOT_HEIGHT + BOTTOM);

        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
            root.fill(&WHITE).map_err(draw_error)?;
            let (chart_area, legend_area) = root.split_horizontally(chart_width);
            self.draw_chart(&chart_area, &x_axis, &y_axis)?;
            self.draw_legend(&legend_area)?;
            root.present().map_err(draw_error)?;
        }
        Ok(svg)
    }

    /// Renders and writes the chart to `path` atomically.
    pub fn write_svg(&self, path: &Path) -> Result<(), PlotError> {
        let svg = self.to_svg()?;
        Ok(write_atomically(path, svg.as_bytes())?)
    }

    fn check_values(&self) -> Result<(), PlotError> {
        if self.series.iter().all(|s| s.points.is_empty()) {
            return Err(PlotError::NoPoints {
                title: self.title.clone(),
            });
        }
        for series in &self.series {
            for &(x, y) in &series.points {
                for (value, axis, scale) in [(x, "x", self.x_scale), (y, "y", self.y_scale)] {
                    if !value.is_finite() {
                        return Err(PlotError::NotFinite {
                            series: series.name.clone(),
                            axis,
                            value,
                        });
                    }
                    if scale == Scale::Log10 && value <= 0.0 {
                        return Err(PlotError::NotPositive {
                            series: series.name.clone(),
                            axis,
                            value,
                        });
                    }
                }
            }
        }
        Ok(())
    }

    /// Title, axes with their ticks and grid, the plot's frame, and every series.
    fn draw_chart<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        x_axis: &AxisMap,
        y_axis: &AxisMap,
    ) -> Result<(), PlotError> {
        let mut chart = ChartBuilder::on(area)
            .caption(plain(&self.title), ("sans-serif", TITLE_FONT))
            .margin_right(RIGHT_MARGIN)
            .x_label_area_size(BOTTOM)
            .y_label_area_size(LEFT)
            .build_cartesian_2d(x_axis.coordinates(), y_axis.coordinates())
            .map_err(draw_error)?;
        let x_label = |at: &f64| x_axis.label_at(*at);
        let y_label = |at: &f64| y_axis.label_at(*at);
        chart
            .configure_mesh()
            .bold_line_style(GRID_GREY)
            .light_line_style(TRANSPARENT)
            .axis_style(BLACK)
            .label_style(("sans-serif", FONT))
            .axis_desc_style(("sans-serif", FONT))
            .x_label_formatter(&x_label)
            .y_label_formatter(&y_label)
            .x_desc(plain(&self.x_label))
            .y_desc(plain(&self.y_label))
            .draw()
            .map_err(draw_error)?;
        let frame = [(x_axis.low, y_axis.low), (x_axis.high, y_axis.high)];
        chart
            .draw_series(std::iter::once(Rectangle::new(frame, BLACK)))
            .map_err(draw_error)?;
        for (i, series) in self.series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            let mut points: Vec<(f64, f64)> = series
                .points
                .iter()
                .map(|&(x, y)| (x_axis.transform(x), y_axis.transform(y)))
                .collect();
            points.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
            if points.len() > 1 {
                chart
                    .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
                    .map_err(draw_error)?;
            }
            let plot = chart.plotting_area();
            for &at in &points {
                draw_marker(plot, MARKERS[i % MARKERS.len()], at, colour)?;
            }
        }
        Ok(())
    }

    /// One row per series: a stretch of its line with its marker, then its name.
    fn draw_legend<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
    ) -> Result<(), PlotError> {
        let text = TextStyle::from(("sans-serif", FONT).into_font())
            .pos(Pos::new(HPos::Left, VPos::Center));
        for (i, series) in self.series.iter().enumerate() {
            let y = TOP as i32 + 10 + 20 * i as i32;
            let colour = COLOURS[i % COLOURS.len()];
            let (left, right) = (LEGEND_GAP, LEGEND_GAP + 30);
            area.draw(&PathElement::new(
                vec![(left, y), (right, y)],
                colour.stroke_width(2),
            ))
            .map_err(draw_error)?;
            draw_marker(area, MARKERS[i % MARKERS.len()], (left + 15, y), colour)?;
            area.draw(&Text::new(
                plain(&series.name),
                (right + 8, y),
                text.clone(),
            ))
            .map_err(draw_error)?;
        }
        Ok(())
    }
}

/// One bar of a tornado chart: a parameter and the result at each end of its range.
#[derive(Debug, Clone, PartialEq)]
pub struct TornadoBar {
    pub label: String,
    pub at_low: f64,
    pub at_high: f64,
}

/// One panel of a tornado chart: a result, its default, and its bars, the widest first.
#[derive(Debug, Clone, PartialEq)]
pub struct TornadoPanel {
    pub title: String,
    pub default: f64,
    /// The band over everything tried (corners included), drawn as a grey strip.
    pub band: (f64, f64),
    pub bars: Vec<TornadoBar>,
}

/// A tornado chart: panels stacked top to bottom, each bar running from the default to the
/// result at the parameter's low end (one colour) and at its high end (another).
#[derive(Debug, Clone, PartialEq)]
pub struct TornadoChart {
    pub title: String,
    pub panels: Vec<TornadoPanel>,
}

/// Room for the parameter names left of a tornado panel.
const TORNADO_LABELS: u32 = 300;
const TORNADO_ROW: u32 = 22;

impl TornadoChart {
    /// Renders the chart as an SVG document; errors on no panels or a non-finite value.
    pub fn to_svg(&self) -> Result<String, PlotError> {
        if self.panels.is_empty() {
            return Err(PlotError::NoPoints {
                title: self.title.clone(),
            });
        }
        for panel in &self.panels {
            let values = panel
                .bars
                .iter()
                .flat_map(|b| [b.at_low, b.at_high])
                .chain([panel.default, panel.band.0, panel.band.1]);
            for value in values {
                if !value.is_finite() {
                    return Err(PlotError::NotFinite {
                        series: panel.title.clone(),
                        axis: "x",
                        value,
                    });
                }
            }
        }
        let heights: Vec<u32> = self
            .panels
            .iter()
            .map(|p| TOP + BOTTOM + TORNADO_ROW * p.bars.len().max(1) as u32)
            .collect();
        let width = TORNADO_LABELS + PLOT_WIDTH + RIGHT_MARGIN + 20;
        let size = (width, TOP + heights.iter().sum::<u32>());
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
            root.fill(&WHITE).map_err(draw_error)?;
            let (title, mut rest) = root.split_vertically(TOP);
            title
                .draw(&Text::new(
                    plain(&self.title),
                    (10, TOP as i32 / 2),
                    TextStyle::from(("sans-serif", TITLE_FONT).into_font())
                        .pos(Pos::new(HPos::Left, VPos::Center)),
                ))
                .map_err(draw_error)?;
            let legend = TextStyle::from(("sans-serif", FONT).into_font())
                .pos(Pos::new(HPos::Left, VPos::Center));
            let x = width as i32 - 330;
            for (i, (colour, what)) in [
                (COLOURS[0], "parameter at the low end"),
                (COLOURS[1], "parameter at the high end"),
            ]
            .into_iter()
            .enumerate()
            {
                let y = 14 + 20 * i as i32;
                title
                    .draw(&Rectangle::new(
                        [(x, y - 6), (x + 24, y + 6)],
                        colour.filled(),
                    ))
                    .map_err(draw_error)?;
                title
                    .draw(&Text::new(what, (x + 32, y), legend.clone()))
                    .map_err(draw_error)?;
            }
            for (panel, height) in self.panels.iter().zip(&heights) {
                let (area, below) = rest.split_vertically(*height);
                draw_tornado_panel(&area, panel)?;
                rest = below;
            }
            root.present().map_err(draw_error)?;
        }
        Ok(svg)
    }

    /// Renders and writes the chart to `path` atomically.
    pub fn write_svg(&self, path: &Path) -> Result<(), PlotError> {
        let svg = self.to_svg()?;
        Ok(write_atomically(path, svg.as_bytes())?)
    }
}

/// One panel: the band strip, a line at the default, a bar per parameter with its name.
fn draw_tornado_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    panel: &TornadoPanel,
) -> Result<(), PlotError> {
    let values = panel
        .bars
        .iter()
        .flat_map(|b| [b.at_low, b.at_high])
        .chain([panel.default, panel.band.0, panel.band.1]);
    let x_axis = AxisMap::fit(Scale::Linear, values);
    let rows = panel.bars.len().max(1) as f64;
    let y_axis = Ticked {
        range: (0.0..rows).into(),
        ticks: Vec::new(),
    };
    let mut chart = ChartBuilder::on(area)
        .caption(plain(&panel.title), ("sans-serif", FONT * 1.2))
        .margin_right(RIGHT_MARGIN + 20)
        .x_label_area_size(BOTTOM - 20)
        .y_label_area_size(TORNADO_LABELS)
        .build_cartesian_2d(x_axis.coordinates(), y_axis)
        .map_err(draw_error)?;
    let x_label = |at: &f64| x_axis.label_at(*at);
    let names: Vec<String> = panel.bars.iter().map(|b| plain(&b.label)).collect();
    // Rows top to bottom: bar i is centred at rows - i - 1/2.
    let centres: Vec<f64> = (0..panel.bars.len())
        .map(|i| rows - i as f64 - 0.5)
        .collect();
    chart
        .configure_mesh()
        .bold_line_style(GRID_GREY)
        .light_line_style(TRANSPARENT)
        .axis_style(BLACK)
        .label_style(("sans-serif", FONT))
        .x_label_formatter(&x_label)
        .y_labels(0)
        .disable_y_mesh()
        .draw()
        .map_err(draw_error)?;
    let (x_low, x_high) = (x_axis.low, x_axis.high);
    let strip = Rectangle::new(
        [(panel.band.0, 0.0), (panel.band.1, rows)],
        RGBColor(0xee, 0xee, 0xee).filled(),
    );
    chart
        .draw_series(std::iter::once(strip))
        .map_err(draw_error)?;
    let (low_colour, high_colour) = (COLOURS[0], COLOURS[1]);
    for (bar, centre) in panel.bars.iter().zip(&centres) {
        for (at, colour) in [(bar.at_low, low_colour), (bar.at_high, high_colour)] {
            let (from, to) = (panel.default.min(at), panel.default.max(at));
            let rect = Rectangle::new(
                [(from, centre - 0.35), (to, centre + 0.35)],
                colour.mix(0.8).filled(),
            );
            chart
                .draw_series(std::iter::once(rect))
                .map_err(draw_error)?;
        }
    }
    chart
        .draw_series(std::iter::once(PathElement::new(
            vec![(panel.default, 0.0), (panel.default, rows)],
            BLACK.stroke_width(2),
        )))
        .map_err(draw_error)?;
    let frame = [(x_low, 0.0), (x_high, rows)];
    chart
        .draw_series(std::iter::once(Rectangle::new(frame, BLACK)))
        .map_err(draw_error)?;
    // Parameter names, right-aligned against the plot, one a row.
    let text =
        TextStyle::from(("sans-serif", FONT).into_font()).pos(Pos::new(HPos::Right, VPos::Center));
    for (name, centre) in names.iter().zip(&centres) {
        let (x, y) = chart.backend_coord(&(x_low, *centre));
        let (origin_x, origin_y) = area.get_base_pixel();
        area.draw(&Text::new(
            name.clone(),
            (x - origin_x - 6, y - origin_y),
            text.clone(),
        ))
        .map_err(draw_error)?;
    }
    Ok(())
}

/// Draws `marker` centred at `at` (in `area`'s coordinates), filled with `colour`.
fn draw_marker<DB: DrawingBackend, CT: CoordTranslate>(
    area: &DrawingArea<DB, CT>,
    marker: Marker,
    at: CT::From,
    colour: RGBColor,
) -> Result<(), PlotError> {
    let r = MARKER_RADIUS;
    let fill = colour.filled();
    let drawn = match marker {
        Marker::Circle => area.draw(&(EmptyElement::at(at) + Circle::new((0, 0), r, fill))),
        Marker::Square => {
            area.draw(&(EmptyElement::at(at) + Rectangle::new([(-r, -r), (r, r)], fill)))
        }
        Marker::TriangleUp => area.draw(
            &(EmptyElement::at(at)
                + Polygon::new(vec![(0, -r - 1), (r + 1, r), (-r - 1, r)], fill)),
        ),
        Marker::TriangleDown => area.draw(
            &(EmptyElement::at(at)
                + Polygon::new(vec![(0, r + 1), (r + 1, -r), (-r - 1, -r)], fill)),
        ),
        Marker::Diamond => area.draw(
            &(EmptyElement::at(at)
                + Polygon::new(vec![(0, -r - 1), (r + 1, 0), (0, r + 1), (-r - 1, 0)], fill)),
        ),
        Marker::Cross => {
            area.draw(&(EmptyElement::at(at) + Cross::new((0, 0), r, colour.stroke_width(2))))
        }
    };
    drawn.map_err(draw_error)
}

fn draw_error<E: std::error::Error + Send + Sync>(error: DrawingAreaErrorKind<E>) -> PlotError {
    PlotError::Draw(error.to_string())
}

/// Text as it may stand in an SVG document: control characters become spaces (plotters
/// escapes the markup characters itself).
fn plain(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// A plotters axis: a linear f64 range whose key points (grid lines and labels) are exactly
/// `ticks`, with no light lines between them. (plotters' own `WithKeyPoints` over an f64
/// range has no label formatting, so a mesh cannot be drawn on it.)
struct Ticked {
    range: RangedCoordf64,
    ticks: Vec<f64>,
}

impl Ranged for Ticked {
    // Labels come from the mesh's formatter; the default one is never asked.
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.range.map(value, limit)
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            Vec::new()
        } else {
            self.ticks.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.range.range()
    }
}

/// A tick: where it is (in data units) and what it says.
#[derive(Debug, Clone, PartialEq)]
struct Tick {
    value: f64,
    label: String,
}

/// One axis: its range in drawn units (log10 of the value for Log10) and its ticks.
#[derive(Debug)]
struct AxisMap {
    scale: Scale,
    low: f64,
    high: f64,
    ticks: Vec<Tick>,
}

impl AxisMap {
    /// Fits an axis to `values` (finite, and > 0 for Log10: checked by the caller).
    fn fit(scale: Scale, values: impl Iterator<Item = f64>) -> AxisMap {
        let (min, max) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
        let (low, high, ticks) = match scale {
            Scale::Linear => {
                // Ticks at whole steps; the frame a little beyond the data, so no point or
                // line lies on the frame.
                let (low, high, ticks) = linear_ticks(min, max);
                let pad = (high - low) * LINEAR_PAD;
                (low.min(min - pad), high.max(max + pad), ticks)
            }
            Scale::Log10 => log_ticks(min, max),
        };
        AxisMap {
            scale,
            low,
            high,
            ticks,
        }
    }

    /// A value in drawn units.
    fn transform(&self, value: f64) -> f64 {
        match self.scale {
            Scale::Linear => value,
            Scale::Log10 => value.log10(),
        }
    }

    /// The plotters coordinate: the drawn range, with the ticks as its only key points.
    fn coordinates(&self) -> Ticked {
        Ticked {
            range: (self.low..self.high).into(),
            ticks: self.ticks.iter().map(|t| self.transform(t.value)).collect(),
        }
    }

    /// The label of the tick drawn at `at` (drawn units): the nearest tick's.
    fn label_at(&self, at: f64) -> String {
        self.ticks
            .iter()
            .min_by(|a, b| {
                let distance = |t: &Tick| (self.transform(t.value) - at).abs();
                distance(a).total_cmp(&distance(b))
            })
            .map(|t| t.label.clone())
            .unwrap_or_default()
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

/// The share of a linear axis's span left between the data and the frame.
const LINEAR_PAD: f64 = 0.04;

/// The fewest ticks a log axis shows when finer steps can give them.
const MIN_LOG_TICKS: usize = 4;

/// Ticks every 1, 2 or 5 x 10^k, about five of them, the range widened to whole ticks.
fn linear_ticks(min: f64, max: f64) -> (f64, f64, Vec<Tick>) {
    linear_ticks_about(min, max, 5.0)
}

/// As [`linear_ticks`], about `count` of them.
fn linear_ticks_about(min: f64, max: f64, count: f64) -> (f64, f64, Vec<Tick>) {
    let (min, max) = if max > min {
        (min, max)
    } else {
        let pad = if min == 0.0 { 1.0 } else { min.abs() * 0.1 };
        (min - pad, max + pad)
    };
    let rough = (max - min) / count;
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
/// single value): whole decades (every other or fifth one on very wide ranges), or, when
/// that gives fewer than [`MIN_LOG_TICKS`], 1, 2, 5 x 10^k, then every 1..9 x 10^k, then
/// round linear steps; the range's ends when nothing else lies inside.
fn log_ticks(min: f64, max: f64) -> (f64, f64, Vec<Tick>) {
    let (low, high) = (min.log10(), max.log10());
    let pad = if high > low { (high - low) * 0.05 } else { 0.5 };
    let (low, high) = (low - pad, high + pad);
    let span = high - low;
    let every = if span > 16.0 {
        5
    } else if span > 8.0 {
        2
    } else {
        1
    };
    let inside = |value: f64| {
        let at = value.log10();
        at >= low - 1e-9 && at <= high + 1e-9
    };
    let decade_ticks = |mantissas: &[f64]| {
        let mut ticks = Vec::new();
        for exponent in (low.floor() as i32)..=(high.ceil() as i32) {
            if exponent.rem_euclid(every) != 0 {
                continue;
            }
            for &m in mantissas {
                let value = m * 10f64.powi(exponent);
                if !inside(value) {
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
        ticks
    };
    let mut ticks = Vec::new();
    for mantissas in [
        &[1.0][..],
        &[1.0, 2.0, 5.0],
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ] {
        ticks = decade_ticks(mantissas);
        if ticks.len() >= MIN_LOG_TICKS {
            break;
        }
    }
    if ticks.len() < MIN_LOG_TICKS {
        let (_, _, linear) = linear_ticks_about(10f64.powf(low), 10f64.powf(high), 8.0);
        let linear: Vec<Tick> = linear
            .into_iter()
            .filter(|t| t.value > 0.0 && inside(t.value))
            .collect();
        if linear.len() > ticks.len() {
            ticks = linear;
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
        assert!(
            !text.chars().any(|c| c.is_control() && c != '\n'),
            "control character in {text:?}"
        );
    }

    /// Every `<text>` element: its opening tag and its (still escaped) content, trimmed.
    fn texts(svg: &str) -> Vec<(&str, &str)> {
        svg.split("<text ")
            .skip(1)
            .map(|piece| {
                let tag_end = piece.find('>').expect("a text tag ends");
                let content = &piece[tag_end + 1..piece.find("</text>").expect("closed")];
                (&piece[..tag_end], content.trim())
            })
            .collect()
    }

    fn contents<'a>(texts: &[(&'a str, &'a str)]) -> Vec<&'a str> {
        texts.iter().map(|(_, content)| *content).collect()
    }

    #[test]
    fn svg_is_well_formed_and_names_every_series() {
        let c = chart(
            Scale::Linear,
            Scale::Linear,
            vec![
                series("boards=1", &[(1.0, 10.0), (2.0, 6.0), (4.0, 4.5)]),
                series("boards=2 \"fast\"\t<", &[(1.0, 5.0), (4.0, 2.0)]),
            ],
        );
        let svg = c.to_svg().unwrap();
        assert_well_formed(&svg);
        assert!(svg.starts_with("<svg"));
        let texts = texts(&svg);
        let contents = contents(&texts);
        assert!(contents.contains(&"boards=1"), "{contents:?}");
        assert!(
            contents.contains(&"boards=2 &quot;fast&quot; &lt;"),
            "{contents:?}"
        );
        assert!(
            contents.contains(&"p50 &amp; p95 &lt;latency&gt;"),
            "{contents:?}"
        );
        assert!(contents.contains(&"engines") && contents.contains(&"cycles"));
        // Each series in its Okabe-Ito colour, a line in the plot and one in its legend row,
        // and a marker of its own shape at each point and in the legend: circles, squares.
        for colour in ["#0072B2", "#D55E00"] {
            let line = format!("<polyline fill=\"none\" opacity=\"1\" stroke=\"{colour}\"");
            assert_eq!(svg.matches(&line).count(), 2, "{colour}");
        }
        assert_eq!(svg.matches("<circle").count(), 3 + 1);
        let squares = svg
            .split("<rect ")
            .skip(1)
            .filter(|rect| rect[..rect.find("/>").unwrap()].contains("fill=\"#D55E00\""))
            .count();
        assert_eq!(squares, 2 + 1);
        assert_eq!(c.to_svg().unwrap(), svg, "rendering is deterministic");
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
        let err = chart(Scale::Linear, Scale::Linear, vec![series("a", &[])])
            .to_svg()
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "cannot plot 'p50 & p95 <latency>': no points"
        );
        let nan = chart(
            Scale::Linear,
            Scale::Linear,
            vec![series("a", &[(1.0, f64::NAN)])],
        );
        assert_eq!(
            nan.to_svg().unwrap_err().to_string(),
            "cannot plot series 'a': y = NaN is not a finite number"
        );
    }

    /// The numeric labels of the texts anchored `anchor` (x ticks are centred, y ticks
    /// right-aligned; the title and axis labels are not numbers).
    fn tick_labels<'a>(texts: &[(&'a str, &'a str)], anchor: &str) -> Vec<&'a str> {
        let anchor = format!("text-anchor=\"{anchor}\"");
        texts
            .iter()
            .filter(|(tag, text)| tag.contains(&anchor) && text.parse::<f64>().is_ok())
            .map(|(_, text)| *text)
            .collect()
    }

    #[test]
    fn every_scale_combination_draws_the_ticks_it_chose() {
        let points = [(1.0, 2.0), (10.0, 200.0), (100.0, 20.0)];
        let labels = |scale, values: [f64; 3]| -> Vec<String> {
            let axis = AxisMap::fit(scale, values.into_iter());
            axis.ticks.into_iter().map(|t| t.label).collect()
        };
        for x_scale in [Scale::Linear, Scale::Log10] {
            for y_scale in [Scale::Linear, Scale::Log10] {
                let svg = chart(x_scale, y_scale, vec![series("a", &points)])
                    .to_svg()
                    .unwrap();
                assert_well_formed(&svg);
                let texts = texts(&svg);
                let (x, y) = (tick_labels(&texts, "middle"), tick_labels(&texts, "end"));
                assert_eq!(x, labels(x_scale, [1.0, 10.0, 100.0]), "{x_scale:?}");
                assert_eq!(y, labels(y_scale, [2.0, 200.0, 20.0]), "{y_scale:?}");
                assert!(x.len() >= 3 && y.len() >= 3, "{x:?} {y:?}");
            }
        }
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
        // Narrower than the 1..9 steps: round linear steps, placed on the log axis.
        assert_eq!(labels(1.1, 1.3), ["1.10", "1.15", "1.20", "1.25", "1.30"]);
        // The demo sweep's cycles, 3.16e7 to 6.40e7 (0.31 decades): 1..9 x 10^7 gives only
        // 4e7, 5e7, 6e7; steps of 5e6 give seven.
        assert_eq!(
            labels(3.16e7, 6.40e7),
            ["3.5e7", "4e7", "4.5e7", "5e7", "5.5e7", "6e7", "6.5e7"]
        );
    }

    #[test]
    fn linear_axes_keep_the_data_off_the_frame() {
        // Ticks 0..10 cover data 0..10 exactly; the frame stands 4% of the span outside.
        let axis = AxisMap::fit(Scale::Linear, [0.0, 10.0].into_iter());
        assert!((axis.low + 0.4).abs() < 1e-9 && (axis.high - 10.4).abs() < 1e-9);
        // Data inside whole ticks keeps the ticks' range.
        let axis = AxisMap::fit(Scale::Linear, [0.5, 9.5].into_iter());
        assert_eq!((axis.low, axis.high), (0.0, 10.0));
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
        assert_eq!(
            tick_labels(&texts(&svg), "middle"),
            ["1", "2", "4", "8", "16"]
        );
    }

    #[test]
    fn log_axes_are_padded_by_a_twentieth_of_their_span() {
        // Two decades padded by 0.1 decade each side.
        let axis = AxisMap::fit(Scale::Log10, [1.0, 100.0].into_iter());
        assert!((axis.low + 0.1).abs() < 1e-9 && (axis.high - 2.1).abs() < 1e-9);
        assert_eq!(axis.transform(10.0), 1.0);
        assert_eq!(axis.label_at(1.0), "10");
        assert_eq!(axis.label_at(1.02), "10", "the nearest tick's label");
    }
}
