//! Generic SVG charts (plotters): curves against time with units on both axes, readable
//! tick labels, and the legend in a column beside the plot, never on the data.

use std::path::Path;

use anyhow::{bail, Result};
use plotters::prelude::*;

/// The unit of a time-series column of `flexmpc simulate` (see [`crate::run::columns`]).
pub fn column_unit(name: &str) -> &'static str {
    let field = name.rsplit('.').next().unwrap_or(name);
    if name.starts_with("angle:") {
        "rad"
    } else if name.starts_with("reaction:") {
        if field.starts_with('m') {
            "N·m"
        } else {
            "N"
        }
    } else if name.starts_with("input:") {
        "N or N·m"
    } else if matches!(name, "energy" | "potential" | "total") {
        "J"
    } else if name == "newton_iterations" {
        "iterations"
    } else if matches!(field, "x" | "y" | "z") {
        "m"
    } else {
        "—"
    }
}

/// The y-axis title of `names`: `angle:elbow (rad)`, or `energy, potential (J)`, or with mixed
/// units each name with its own.
pub fn y_title(names: &[String]) -> String {
    let units: Vec<&str> = names.iter().map(|n| column_unit(n)).collect();
    let joined = names.join(", ");
    if units.windows(2).all(|w| w[0] == w[1]) {
        let u = units.first().copied().unwrap_or("—");
        if joined.chars().count() > 40 {
            format!("value ({u})")
        } else {
            format!("{joined} ({u})")
        }
    } else {
        "value (units in the legend)".into()
    }
}

/// Plots the named columns of `table` against the first column (time) into an SVG file; the
/// y axis and the legend carry the units of the columns.
pub fn time_series(
    path: &Path,
    title: &str,
    columns: &[String],
    table: &[Vec<f64>],
    names: &[String],
) -> Result<()> {
    let mut idx = Vec::new();
    for n in names {
        match columns.iter().position(|c| c == n) {
            Some(i) => idx.push(i),
            None => bail!("plot column `{n}` does not exist (columns: {})", columns.join(", ")),
        }
    }
    let series: Vec<Series> = idx
        .iter()
        .zip(names)
        .map(|(&i, n)| {
            (format!("{n} ({})", column_unit(n)), table.iter().map(|r| (r[0], r[i])).collect())
        })
        .collect();
    let axes = Axes {
        title: title.to_string(),
        x: "t (s)".into(),
        y: y_title(names),
        ..Default::default()
    };
    lines(path, (1000, 500), &axes, &series)
}

/// A named curve `(x, y)`.
pub type Series = (String, Vec<(f64, f64)>);

/// Axis options of [`lines`].
#[derive(Clone, Debug, Default)]
pub struct Axes {
    /// Title.
    pub title: String,
    /// x label.
    pub x: String,
    /// y label.
    pub y: String,
    /// Logarithmic y axis (non-positive values are clipped to the smallest positive one).
    pub log_y: bool,
    /// Dashed horizontal reference lines and their labels (black, then grey).
    pub references: Vec<(f64, String)>,
    /// Draw markers only (no lines).
    pub points: bool,
}

// twelve colours, so that a sweep of ten ω0 draws no two curves alike (the first eight are
// the colours of every figure with at most eight curves)
const PALETTE: [RGBColor; 12] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(0, 0, 0),
    RGBColor(227, 119, 194),
    RGBColor(188, 189, 34),
    RGBColor(127, 127, 127),
    RGBColor(0, 0, 128),
];

/// The `i`-th colour of the plots' palette.
pub fn color(i: usize) -> RGBColor {
    PALETTE[i % PALETTE.len()]
}

/// Colour of the `k`-th reference line: black, then greys.
fn reference_color(k: usize) -> RGBColor {
    [RGBColor(0, 0, 0), RGBColor(130, 130, 130), RGBColor(190, 190, 190)][k % 3]
}

fn range_of(series: &[Series], f: impl Fn(&(f64, f64)) -> f64) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (_, pts) in series {
        for p in pts {
            let v = f(p);
            if v.is_finite() {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        return (lo - 0.5, hi + 0.5);
    }
    (lo, hi)
}

/// How a legend entry is drawn.
#[derive(Clone, Copy)]
enum Mark {
    Line,
    Dashed,
    Dot,
}

/// Font sizes of tick labels, axis titles and chart titles: readable at the size the report
/// shows the figures.
pub const TICK_FONT: u32 = 15;
/// Axis title font size.
pub const AXIS_FONT: u32 = 16;
/// Chart title font size.
pub const TITLE_FONT: u32 = 18;

/// Splits `area` into the plot (left) and, when there are `entries`, a legend column (right)
/// wide enough for the longest label; draws the legend there. Returns the plot area.
pub fn with_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[(String, RGBColor, bool)],
) -> Result<DrawingArea<DB, plotters::coord::Shift>>
where
    DB::ErrorType: 'static,
{
    let marks: Vec<(String, RGBColor, Mark)> = entries
        .iter()
        .map(|(l, c, dashed)| (l.clone(), *c, if *dashed { Mark::Dashed } else { Mark::Line }))
        .collect();
    legend_column(area, &marks)
}

fn legend_column<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    entries: &[(String, RGBColor, Mark)],
) -> Result<DrawingArea<DB, plotters::coord::Shift>>
where
    DB::ErrorType: 'static,
{
    if entries.is_empty() {
        return Ok(area.clone());
    }
    let (w, _) = area.dim_in_pixel();
    let longest = entries.iter().map(|e| e.0.chars().count()).max().unwrap_or(0) as u32;
    let lw = (longest * 8 + 44).clamp(90, (w as f64 * 0.42) as u32);
    let (plot, legend) = area.split_horizontally(w.saturating_sub(lw));
    let font = ("sans-serif", TICK_FONT).into_font();
    for (k, (label, c, mark)) in entries.iter().enumerate() {
        let y = 40 + 22 * k as i32;
        match mark {
            Mark::Line => {
                legend.draw(&PathElement::new(vec![(6, y), (30, y)], c.stroke_width(2)))?
            }
            Mark::Dashed => {
                for x in [6, 16, 26] {
                    legend.draw(&PathElement::new(vec![(x, y), (x + 6, y)], c.stroke_width(1)))?;
                }
            }
            Mark::Dot => legend.draw(&Circle::new((18, y), 4, c.filled()))?,
        }
        legend.draw(&Text::new(label.clone(), (36, y - 8), font.clone()))?;
    }
    Ok(plot)
}

/// How a curve of [`styled_panels`] is drawn: its colour and whether it is dashed.
#[derive(Clone, Copy, Debug)]
pub struct Style {
    /// Colour.
    pub color: RGBColor,
    /// Dashed (else solid).
    pub dashed: bool,
}

/// One chart of [`styled_panels`]: axes, curves with their styles (one per curve), and the
/// legend entries `(label, style)` (in place of one entry per curve).
pub struct StyledChart {
    /// Axes.
    pub axes: Axes,
    /// Curves.
    pub series: Vec<Series>,
    /// One style per curve.
    pub styles: Vec<Style>,
    /// The legend (reference lines are added after it).
    pub legend: Vec<(String, Style)>,
}

/// Draws `series` into one drawing area, the legend (when there is more than one curve or a
/// reference line) in a column to the right of the plot, never on the data.
fn draw_lines<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    axes: &Axes,
    series: &[Series],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let styles: Vec<Style> =
        (0..series.len()).map(|k| Style { color: color(k), dashed: false }).collect();
    draw_styled(area, axes, series, &styles, None)
}

/// [`draw_lines`] with a style per curve and, when `legend` is given, that legend instead of
/// one entry per curve.
fn draw_styled<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    axes: &Axes,
    series: &[Series],
    styles: &[Style],
    legend: Option<&[(String, Style)]>,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let style =
        |k: usize| styles.get(k).copied().unwrap_or(Style { color: color(k), dashed: false });
    let mark = |s: Style| {
        if axes.points {
            Mark::Dot
        } else if s.dashed {
            Mark::Dashed
        } else {
            Mark::Line
        }
    };
    let mut entries: Vec<(String, RGBColor, Mark)> = Vec::new();
    if let Some(l) = legend {
        entries.extend(l.iter().map(|(name, s)| (name.clone(), s.color, mark(*s))));
    } else if series.iter().any(|(n, _)| !n.is_empty()) || !axes.references.is_empty() {
        for (k, (name, _)) in series.iter().enumerate() {
            entries.push((name.clone(), style(k).color, mark(style(k))));
        }
    }
    if !entries.is_empty() || !axes.references.is_empty() {
        for (k, (r, label)) in axes.references.iter().enumerate() {
            if !axes.log_y || *r > 0.0 {
                entries.push((label.clone(), reference_color(k), Mark::Dashed));
            }
        }
    }
    let titled = area.titled(&axes.title, ("sans-serif", TITLE_FONT))?;
    let plot = legend_column(&titled, &entries)?;
    let area = &plot;
    let (x0, x1) = range_of(series, |p| p.0);
    if axes.log_y {
        let pos: Vec<Series> = series
            .iter()
            .map(|(n, p)| (n.clone(), p.iter().copied().filter(|q| q.1 > 0.0).collect()))
            .collect();
        let (mut lo, mut hi) = range_of(&pos, |p| p.1);
        for &(r, _) in &axes.references {
            if r > 0.0 {
                lo = lo.min(r);
                hi = hi.max(r);
            }
        }
        let (lo, hi) = (lo.max(1e-300) / 1.5, hi.max(1e-300) * 1.5);
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(78)
            .build_cartesian_2d(x0..x1, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .x_desc(axes.x.as_str())
            .y_desc(axes.y.as_str())
            .label_style(("sans-serif", TICK_FONT))
            .axis_desc_style(("sans-serif", AXIS_FONT))
            .x_labels(8)
            .y_labels(6)
            .light_line_style(RGBColor(240, 240, 240))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()?;
        for (k, (_, pts)) in pos.iter().enumerate() {
            curve(&mut chart, pts, style(k))?;
        }
        for (k, (r, _)) in axes.references.iter().enumerate() {
            if *r > 0.0 {
                let c = reference_color(k);
                chart.draw_series(DashedLineSeries::new(
                    [(x0, *r), (x1, *r)],
                    6,
                    4,
                    c.stroke_width(1),
                ))?;
            }
        }
    } else {
        let (mut lo, mut hi) = range_of(series, |p| p.1);
        for &(r, _) in &axes.references {
            lo = lo.min(r);
            hi = hi.max(r);
        }
        let pad = 0.05 * (hi - lo);
        let mut chart = ChartBuilder::on(area)
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(78)
            .build_cartesian_2d(x0..x1, (lo - pad)..(hi + pad))?;
        chart
            .configure_mesh()
            .x_desc(axes.x.as_str())
            .y_desc(axes.y.as_str())
            .label_style(("sans-serif", TICK_FONT))
            .axis_desc_style(("sans-serif", AXIS_FONT))
            .x_labels(8)
            .y_labels(8)
            .y_label_formatter(&|v| short(*v))
            .draw()?;
        for (k, (_, pts)) in series.iter().enumerate() {
            let c = style(k).color;
            if axes.points {
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))?;
            } else {
                curve(&mut chart, pts, style(k))?;
            }
        }
        for (k, (r, _)) in axes.references.iter().enumerate() {
            let c = reference_color(k);
            chart.draw_series(DashedLineSeries::new(
                [(x0, *r), (x1, *r)],
                6,
                4,
                c.stroke_width(1),
            ))?;
        }
    }
    Ok(())
}

/// Draws one curve, solid (width 2) or dashed (width 2, 8 px dashes).
fn curve<DB: DrawingBackend, X, Y>(
    chart: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    pts: &[(f64, f64)],
    s: Style,
) -> Result<()>
where
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    if s.dashed {
        chart.draw_series(DashedLineSeries::new(
            pts.iter().copied(),
            8,
            5,
            s.color.stroke_width(2),
        ))?;
    } else {
        chart.draw_series(LineSeries::new(pts.iter().copied(), s.color.stroke_width(2)))?;
    }
    Ok(())
}

/// A tick label: plain for moderate magnitudes, scientific otherwise (never 12 digits).
pub fn short(v: f64) -> String {
    let a = v.abs();
    // a tick at zero computed as a sum of steps: round-off, not a value
    if a < 1e-12 {
        "0".into()
    } else if (1e-3..1e4).contains(&a) {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        format!("{v:.1e}")
    }
}

/// One chart of `series` into an SVG file of `size` pixels.
pub fn lines(path: &Path, size: (u32, u32), axes: &Axes, series: &[Series]) -> Result<()> {
    let root = SVGBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    draw_lines(&root, axes, series)?;
    root.present()?;
    Ok(())
}

/// Panels side by side (one per `(axes, series)`) into an SVG file.
pub fn panels(path: &Path, size: (u32, u32), charts: &[(Axes, Vec<Series>)]) -> Result<()> {
    grid(path, size, charts.len(), charts)
}

/// Panels on a grid of `cols` columns (`charts` row after row) into an SVG file; a chart with
/// an empty title and no series leaves its cell blank.
pub fn grid(
    path: &Path,
    size: (u32, u32),
    cols: usize,
    charts: &[(Axes, Vec<Series>)],
) -> Result<()> {
    let cols = cols.max(1);
    let rows = charts.len().div_ceil(cols).max(1);
    let root = SVGBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((rows, cols));
    for ((axes, series), area) in charts.iter().zip(areas.iter()) {
        // an untitled chart without data is a blank cell of the grid
        if !(axes.title.is_empty() && series.is_empty()) {
            draw_lines(area, axes, series)?;
        }
    }
    root.present()?;
    Ok(())
}

/// Panels side by side, each with its own curve styles and legend ([`StyledChart`]), into
/// an SVG file of `size` pixels.
pub fn styled_panels(path: &Path, size: (u32, u32), charts: &[StyledChart]) -> Result<()> {
    let root = SVGBackend::new(path, size).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((1, charts.len().max(1)));
    for (c, area) in charts.iter().zip(areas.iter()) {
        draw_styled(area, &c.axes, &c.series, &c.styles, Some(&c.legend))?;
    }
    root.present()?;
    Ok(())
}

/// A piecewise-constant signal (value held from each `t` to the next) as a step polyline.
pub fn steps(pts: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(2 * pts.len());
    for (i, &(t, v)) in pts.iter().enumerate() {
        out.push((t, v));
        if let Some(&(t1, _)) = pts.get(i + 1) {
            out.push((t1, v));
        }
    }
    out
}
