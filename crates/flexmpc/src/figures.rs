//! The figures of closed loops and sweeps: snapshots of the deformed structure (paper Figs.
//! 7, 9), the scaled cost per ω0 (Figs. 6, 8) and the inputs per ω0 (Fig. 10), drawn with the
//! generic charts of [`crate::plot`] from the data types of [`crate::results`].

use std::path::Path;

use anyhow::Result;
use mpc::RunResult;
use plotters::prelude::*;

use crate::plot::{grid, panels, steps, Axes, Series};
use crate::results::{sweep_kinds, SweepRun};

/// The planes in which snapshots are drawn: `(name, horizontal axis, vertical axis)`.
pub fn planes(planar: bool) -> Vec<(&'static str, usize, usize)> {
    if planar {
        vec![("x–z", 0, 2)]
    } else {
        vec![("x–y", 0, 1), ("x–z", 0, 2)]
    }
}

/// A square window `(center, half width)` around every snapshot in plane `(a, b)`.
pub fn window(result: &RunResult, a: usize, b: usize) -> ((f64, f64), f64) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for s in &result.snapshots {
        for beam in &s.positions {
            for p in beam {
                for (k, c) in [a, b].into_iter().enumerate() {
                    lo[k] = lo[k].min(p[c]);
                    hi[k] = hi[k].max(p[c]);
                }
            }
        }
    }
    if !lo[0].is_finite() {
        return ((0.0, 0.0), 1.0);
    }
    let w = 0.55 * (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    ((0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])), w)
}

/// Colour of snapshot `k` of `n`: blue (t = 0) to red (end).
pub fn time_color(k: usize, n: usize) -> RGBColor {
    let f = if n > 1 { k as f64 / (n - 1) as f64 } else { 0.0 };
    RGBColor((30.0 + 200.0 * f) as u8, 60, (220.0 - 190.0 * f) as u8)
}

/// Draws every snapshot of `result` in plane `(a, b)` into `area`, coloured by time.
pub fn draw_snapshots<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    result: &RunResult,
    (name, a, b): (&str, usize, usize),
    title: &str,
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let n = result.snapshots.len();
    let axis = ["x", "y", "z"];
    let ((ca, cb), w) = window(result, a, b);
    let mut chart = ChartBuilder::on(area)
        .caption(format!("{title} ({name} plane)"), ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(45)
        .build_cartesian_2d((ca - w)..(ca + w), (cb - w)..(cb + w))?;
    chart.configure_mesh().x_desc(axis[a]).y_desc(axis[b]).draw()?;
    for (k, s) in result.snapshots.iter().enumerate() {
        let c = time_color(k, n);
        let width = if k == 0 || k + 1 == n { 3 } else { 1 };
        for beam in &s.positions {
            chart.draw_series(LineSeries::new(
                beam.iter().map(|p| (p[a], p[b])),
                c.stroke_width(width),
            ))?;
        }
    }
    Ok(())
}

/// Fig. 7 style: every snapshot of the deformed structure, coloured by time, one panel per
/// plane.
pub fn snapshots_svg(result: &RunResult, planar: bool, path: &Path) -> Result<()> {
    let pl = planes(planar);
    let root = SVGBackend::new(path, (560 * pl.len() as u32, 560)).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((1, pl.len()));
    let title = format!(
        "snapshots every {:.2} s, blue → red",
        result.snapshots.get(1).map_or(0.0, |s| s.t)
    );
    for (plane, area) in pl.iter().zip(areas.iter()) {
        draw_snapshots(area, result, *plane, &title)?;
    }
    root.present()?;
    Ok(())
}

/// Figs. 7 and 9 style for a sweep: the snapshots of every run, one row per controller, one
/// panel per ω0, in the first plane of the structure (`x–z` planar, `x–y` spatial; each run's
/// `runs/<controller>-w<ω0>-snapshots.svg` has every plane).
pub fn sweep_snapshots_svg(runs: &[SweepRun], planar: bool, path: &Path) -> Result<()> {
    let kinds = sweep_kinds(runs);
    let cols = runs.len().div_ceil(kinds.len().max(1)).max(1);
    let root = SVGBackend::new(path, (300 * cols as u32, 320 * kinds.len().max(1) as u32))
        .into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((kinds.len().max(1), cols));
    let plane = planes(planar)[0];
    for (row, k) in kinds.iter().enumerate() {
        for (col, r) in runs.iter().filter(|r| r.controller == *k).enumerate() {
            let Some(area) = areas.get(row * cols + col) else { continue };
            let title = format!("{} ω0 = {}", k.name().to_uppercase(), r.omega0);
            match &r.result {
                Ok(res) => draw_snapshots(area, res, plane, &title)?,
                Err(_) => {
                    area.draw(&Text::new(
                        format!("{title}: failed"),
                        (10, 20),
                        ("sans-serif", 14).into_font(),
                    ))?;
                }
            }
        }
    }
    root.present()?;
    Ok(())
}

/// Fig. 6 style: the scaled cost `V(t)/V(0)` (state part) against time, one curve per ω0,
/// one panel per controller.
pub fn sweep_cost(path: &Path, name: &str, runs: &[SweepRun]) -> Result<()> {
    let kinds = sweep_kinds(runs);
    let charts: Vec<(Axes, Vec<Series>)> = kinds
        .iter()
        .map(|k| {
            let series = runs
                .iter()
                .filter(|r| r.controller == *k)
                .filter_map(|r| r.result.as_ref().ok())
                .map(|res| {
                    let v0 = res.records.first().map_or(1.0, |x| x.v_state);
                    (
                        format!("ω0 = {}", res.summary.omega0),
                        res.records.iter().map(|x| (x.t, x.v_state / v0)).collect(),
                    )
                })
                .collect();
            (
                Axes {
                    title: format!("{name}: {} — V(t)/V(0)", k.name().to_uppercase()),
                    x: "t (s)".into(),
                    y: "V/V(0)".into(),
                    log_y: true,
                    references: vec![(0.1, "0.1 (criterion)".into())],
                    points: false,
                },
                series,
            )
        })
        .collect();
    panels(path, (620 * charts.len().max(1) as u32, 460), &charts)
}

/// Fig. 10 style: the inputs of every run of a sweep against time, one row of panels per
/// controller, one panel per input, one curve per ω0 (each input held for τs).
pub fn sweep_inputs(path: &Path, name: &str, runs: &[SweepRun]) -> Result<()> {
    let kinds = sweep_kinds(runs);
    let inputs: Vec<String> = runs
        .iter()
        .find_map(|r| r.result.as_ref().ok())
        .map_or_else(Vec::new, |r| r.input_names.clone());
    let cols = inputs.len().max(1);
    let mut charts: Vec<(Axes, Vec<Series>)> = Vec::new();
    for k in &kinds {
        for (i, input) in inputs.iter().enumerate() {
            let series = runs
                .iter()
                .filter(|r| r.controller == *k)
                .filter_map(|r| r.result.as_ref().ok())
                .map(|res| {
                    let pts: Vec<(f64, f64)> = res.records.iter().map(|x| (x.t, x.u[i])).collect();
                    (format!("ω0 = {}", res.summary.omega0), steps(&pts))
                })
                .collect();
            charts.push((
                Axes {
                    title: format!("{name}: {} — {input}", k.name().to_uppercase()),
                    x: "t (s)".into(),
                    y: "u (N, N·m)".into(),
                    ..Default::default()
                },
                series,
            ));
        }
    }
    grid(path, (420 * cols as u32, 340 * kinds.len().max(1) as u32), cols, &charts)
}
