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
