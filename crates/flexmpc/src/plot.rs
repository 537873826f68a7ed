//! SVG plots of time series (plotters).

use std::path::Path;

use anyhow::{bail, Result};
use plotters::prelude::*;

/// Plots the named columns of `table` against the first column (time) into an SVG file.
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
    let t_max = table.last().map(|r| r[0]).unwrap_or(1.0).max(1e-12);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for r in table {
        for &i in &idx {
            lo = lo.min(r[i]);
            hi = hi.max(r[i]);
        }
    }
    if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
        hi = lo + 1.0;
    }
    let pad = 0.05 * (hi - lo);
    let root = SVGBackend::new(path, (900, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_max, (lo - pad)..(hi + pad))?;
    chart.configure_mesh().x_desc("t (s)").y_desc("value").draw()?;
    let palette = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK];
    for (k, &i) in idx.iter().enumerate() {
        let color = palette[k % palette.len()];
        chart
            .draw_series(LineSeries::new(
                table.iter().map(|r| (r[0], r[i])),
                color.stroke_width(2),
            ))?
            .label(names[k].clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    chart.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;
    root.present()?;
    Ok(())
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

const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(0, 0, 0),
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

/// Draws `series` into one drawing area.
fn draw_lines<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    axes: &Axes,
    series: &[Series],
) -> Result<()>
where
    DB::ErrorType: 'static,
{
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
            .caption(&axes.title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(38)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, (lo..hi).log_scale())?;
        chart
            .configure_mesh()
            .x_desc(axes.x.as_str())
            .y_desc(axes.y.as_str())
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()?;
        for (k, (name, pts)) in pos.iter().enumerate() {
            let c = color(k);
            chart
                .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
                .label(name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                });
        }
        for (k, (r, label)) in axes.references.iter().enumerate() {
            if *r > 0.0 {
                let c = reference_color(k);
                chart
                    .draw_series(DashedLineSeries::new(
                        [(x0, *r), (x1, *r)],
                        6,
                        4,
                        c.stroke_width(1),
                    ))?
                    .label(label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
            }
        }
        if series.len() > 1 || !axes.references.is_empty() {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()?;
        }
    } else {
        let (mut lo, mut hi) = range_of(series, |p| p.1);
        for &(r, _) in &axes.references {
            lo = lo.min(r);
            hi = hi.max(r);
        }
        let pad = 0.05 * (hi - lo);
        let mut chart = ChartBuilder::on(area)
            .caption(&axes.title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(38)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, (lo - pad)..(hi + pad))?;
        chart.configure_mesh().x_desc(axes.x.as_str()).y_desc(axes.y.as_str()).draw()?;
        for (k, (name, pts)) in series.iter().enumerate() {
            let c = color(k);
            if axes.points {
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))?
                    .label(name.clone())
                    .legend(move |(x, y)| Circle::new((x + 10, y), 3, c.filled()));
            } else {
                chart
                    .draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))?
                    .label(name.clone())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                    });
            }
        }
        for (k, (r, label)) in axes.references.iter().enumerate() {
            let c = reference_color(k);
            chart
                .draw_series(DashedLineSeries::new([(x0, *r), (x1, *r)], 6, 4, c.stroke_width(1)))?
                .label(label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c));
        }
        if series.len() > 1 || !axes.references.is_empty() {
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()?;
        }
    }
    Ok(())
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

/// Panels on a grid of `cols` columns (`charts` row after row) into an SVG file.
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
        draw_lines(area, axes, series)?;
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
