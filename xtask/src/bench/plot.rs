//! Log-log SVG charts of the bench studies (plotters): one line with markers per series,
//! optional point labels, optional horizontal whiskers (e.g. median → worst solve time).

use anyhow::{bail, Result};
use plotters::prelude::*;
use std::path::Path;

/// One series of points.
#[derive(Clone, Debug, Default)]
pub(crate) struct Series {
    /// Legend text.
    pub label: String,
    /// `(x, y)`; points that are not positive and finite are left out (log axes).
    pub points: Vec<(f64, f64)>,
    /// Text next to each point (empty: none).
    pub point_labels: Vec<String>,
    /// Right end of a horizontal whisker per point (empty: none).
    pub whisker_to: Vec<f64>,
    /// Draw the connecting line (false: markers only).
    pub line: bool,
    /// Palette index (default: the series' position), to share a colour between series.
    pub color: Option<usize>,
}

impl Series {
    /// A connected series.
    pub fn line(label: impl Into<String>) -> Self {
        Self { label: label.into(), line: true, ..Self::default() }
    }

    /// Adds a point with a label.
    pub fn add(&mut self, x: f64, y: f64, text: impl Into<String>) {
        self.points.push((x, y));
        self.point_labels.push(text.into());
    }
}

/// A log-log chart.
#[derive(Clone, Debug)]
pub(crate) struct Chart {
    /// File suffix (`<study>-<key>.svg`).
    pub key: &'static str,
    /// Caption.
    pub title: String,
    /// x axis description with unit.
    pub x_label: String,
    /// y axis description with unit.
    pub y_label: String,
    /// Series.
    pub series: Vec<Series>,
    /// Where the legend goes.
    pub legend: Legend,
}

/// Legend placement (inside the plot area).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Legend {
    /// Upper right corner.
    #[default]
    UpperRight,
    /// Lower left corner.
    LowerLeft,
    /// Upper left corner.
    UpperLeft,
}

fn ok(p: &(f64, f64)) -> bool {
    p.0.is_finite() && p.1.is_finite() && p.0 > 0.0 && p.1 > 0.0
}

/// A padded log range around `lo..hi`, at least one decade wide (so that a power of ten
/// carries a tick label).
fn log_range(lo: f64, hi: f64) -> (f64, f64) {
    let (mut a, mut b) = (lo.log10(), hi.log10());
    if b - a < 1.0 {
        let widen = 0.5 * (1.0 - (b - a));
        a -= widen;
        b += widen;
    }
    let pad = 0.06 * (b - a);
    (10f64.powf(a - pad), 10f64.powf(b + pad))
}

fn tick(v: &f64) -> String {
    let e = v.log10();
    if (e - e.round()).abs() < 1e-9 {
        format!("1e{}", e.round() as i32)
    } else {
        format!("{v:.1e}")
    }
}

impl Chart {
    /// A chart without series.
    pub fn new(
        key: &'static str,
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        Self {
            key,
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            legend: Legend::UpperRight,
        }
    }

    /// Renders the chart to an SVG file.
    pub fn draw(&self, path: &Path) -> Result<()> {
        let pts: Vec<(f64, f64)> = self
            .series
            .iter()
            .flat_map(|s| {
                let w = s.whisker_to.iter().zip(&s.points).map(|(&x, p)| (x, p.1));
                s.points.iter().copied().chain(w)
            })
            .filter(ok)
            .collect();
        if pts.is_empty() {
            bail!("chart `{}` has no positive finite point", self.key);
        }
        let fold = |f: fn(&(f64, f64)) -> f64, init: f64, g: fn(f64, f64) -> f64| {
            pts.iter().map(f).fold(init, g)
        };
        let (x0, x1) = log_range(
            fold(|p| p.0, f64::INFINITY, f64::min),
            fold(|p| p.0, f64::NEG_INFINITY, f64::max),
        );
        let (y0, y1) = log_range(
            fold(|p| p.1, f64::INFINITY, f64::min),
            fold(|p| p.1, f64::NEG_INFINITY, f64::max),
        );
        let root = SVGBackend::new(path, (960, 620)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(&self.title, ("sans-serif", 20))
            .margin(18)
            .x_label_area_size(50)
            .y_label_area_size(80)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())?;
        chart
            .configure_mesh()
            .x_desc(&self.x_label)
            .y_desc(&self.y_label)
            .x_label_formatter(&tick)
            .y_label_formatter(&tick)
            .label_style(("sans-serif", 14))
            .axis_desc_style(("sans-serif", 16))
            .draw()?;
        for (k, s) in self.series.iter().enumerate() {
            let color = flexmpc::plot::color(s.color.unwrap_or(k));
            let good: Vec<usize> = (0..s.points.len()).filter(|&i| ok(&s.points[i])).collect();
            if good.is_empty() {
                continue;
            }
            let style = color.stroke_width(2);
            let marker = k % 3;
            let font = ("sans-serif", 11).into_font().color(&color);
            let at = |i: usize| {
                let text = s.point_labels.get(i).cloned().unwrap_or_default();
                (EmptyElement::at(s.points[i]), Text::new(text, (6, -14), font.clone()))
            };
            let anno = match marker {
                0 => chart.draw_series(good.iter().map(|&i| {
                    let (e, t) = at(i);
                    e + Circle::new((0, 0), 4, color.filled()) + t
                }))?,
                1 => chart.draw_series(good.iter().map(|&i| {
                    let (e, t) = at(i);
                    e + TriangleMarker::new((0, 0), 5, color.filled()) + t
                }))?,
                _ => chart.draw_series(good.iter().map(|&i| {
                    let (e, t) = at(i);
                    e + Cross::new((0, 0), 4, style) + t
                }))?,
            };
            if !s.line {
                anno.label(s.label.clone())
                    .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
            }
            if s.line {
                chart
                    .draw_series(LineSeries::new(good.iter().map(|&i| s.points[i]), style))?
                    .label(s.label.clone())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
            }
            for &i in &good {
                let Some(&xw) = s.whisker_to.get(i) else { continue };
                let p = s.points[i];
                if xw.is_finite() && xw > 0.0 {
                    chart.draw_series(std::iter::once(PathElement::new(
                        vec![p, (xw, p.1)],
                        color.stroke_width(1),
                    )))?;
                    chart.draw_series(std::iter::once(
                        EmptyElement::at((xw, p.1))
                            + PathElement::new(vec![(0, -5), (0, 5)], color.stroke_width(1)),
                    ))?;
                }
            }
        }
        chart
            .configure_series_labels()
            .position(match self.legend {
                Legend::UpperRight => SeriesLabelPosition::UpperRight,
                Legend::LowerLeft => SeriesLabelPosition::LowerLeft,
                Legend::UpperLeft => SeriesLabelPosition::UpperLeft,
            })
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .draw()?;
        root.present()?;
        Ok(())
    }
}
