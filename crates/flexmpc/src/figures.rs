//! The figures of closed loops and sweeps: snapshots of the deformed structure (paper Figs.
//! 7, 9), the scaled cost per ω0 (Figs. 6, 8) and the inputs per ω0 (Fig. 10), drawn with the
//! generic charts of [`crate::plot`] from the data types of [`crate::results`].

use std::path::Path;

use anyhow::Result;
use mpc::RunResult;
use plotters::prelude::*;

use crate::plot::{color, grid, steps, styled_panels, Axes, Series, Style, StyledChart};

use crate::results::{sweep_kinds, sweep_models, SweepRun};

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

/// Colour of snapshot `k` of `n` within a time window: light blue-grey (first) darkening to
/// navy (last), as the paper's "shade darkening as t increases".
pub fn time_color(k: usize, n: usize) -> RGBColor {
    let f = if n > 1 { k as f64 / (n - 1) as f64 } else { 1.0 };
    let mix = |a: f64, b: f64| (a + (b - a) * f).round() as u8;
    RGBColor(mix(185.0, 10.0), mix(200.0, 25.0), mix(225.0, 95.0))
}

/// The paper's three time windows of the snapshots (Figs. 7, 9): `[0, T/3]`, `[T/3, 2T/3]`,
/// `[2T/3, T]` of the run's last snapshot time `T`; a snapshot on a boundary is in both.
pub fn time_windows(result: &RunResult) -> [(f64, f64); 3] {
    let t = result.snapshots.last().map_or(0.0, |s| s.t);
    [(0.0, t / 3.0), (t / 3.0, 2.0 * t / 3.0), (2.0 * t / 3.0, t)]
}

/// Draws the snapshots of `result` with `t0 ≤ t ≤ t1` in plane `(a, b)` into `area`, shaded
/// by time; the view is the same for every window of a run (the box around all snapshots).
pub fn draw_snapshots<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    result: &RunResult,
    (name, a, b): (&str, usize, usize),
    title: &str,
    (t0, t1): (f64, f64),
) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let eps = 1e-9 * (1.0 + t1.abs());
    let shown: Vec<&mpc::Snapshot> =
        result.snapshots.iter().filter(|s| s.t >= t0 - eps && s.t <= t1 + eps).collect();
    let n = shown.len();
    let axis = ["x (m)", "y (m)", "z (m)"];
    let ((ca, cb), w) = window(result, a, b);
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "{title}, t ∈ [{}, {}] s ({name})",
                crate::plot::short(t0),
                crate::plot::short(t1)
            ),
            ("sans-serif", crate::plot::AXIS_FONT),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(56)
        .build_cartesian_2d((ca - w)..(ca + w), (cb - w)..(cb + w))?;
    chart
        .configure_mesh()
        .x_desc(axis[a])
        .y_desc(axis[b])
        .label_style(("sans-serif", crate::plot::TICK_FONT))
        .axis_desc_style(("sans-serif", crate::plot::AXIS_FONT))
        .x_labels(5)
        .y_labels(5)
        .x_label_formatter(&|v| crate::plot::short(*v))
        .y_label_formatter(&|v| crate::plot::short(*v))
        .draw()?;
    for (k, s) in shown.iter().enumerate() {
        let c = time_color(k, n);
        let width = if k + 1 == n { 3 } else { 2 };
        for beam in &s.positions {
            chart.draw_series(LineSeries::new(
                beam.iter().map(|p| (p[a], p[b])),
                c.stroke_width(width),
            ))?;
        }
    }
    Ok(())
}

/// Figs. 7, 9 style: the snapshots of the deformed structure in the paper's three time windows
/// (columns), one row per plane (`x–z` planar; `x–y` and `x–z` spatial), shaded by time.
pub fn snapshots_svg(result: &RunResult, planar: bool, path: &Path) -> Result<()> {
    let pl = planes(planar);
    let root = SVGBackend::new(path, (3 * 420, 420 * pl.len() as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((pl.len(), 3));
    let every = result.snapshots.get(1).map_or(0.0, |s| s.t);
    let title = format!("every {} s", crate::plot::short(every));
    for (row, plane) in pl.iter().enumerate() {
        for (col, win) in time_windows(result).into_iter().enumerate() {
            draw_snapshots(&areas[row * 3 + col], result, *plane, &title, win)?;
        }
    }
    root.present()?;
    Ok(())
}

/// Figs. 7, 9 style for a sweep: one row per run (controllers outer, ω0 inner), the paper's
/// three time windows as columns, in the first plane of the structure (`x–z` planar, `x–y`
/// spatial; each run's `runs/<controller>-w<ω0>-snapshots.svg` has every plane).
pub fn sweep_snapshots_svg(runs: &[SweepRun], planar: bool, path: &Path) -> Result<()> {
    let rows = runs.len().max(1);
    let root = SVGBackend::new(path, (3 * 340, 340 * rows as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((rows, 3));
    let plane = planes(planar)[0];
    for (row, r) in runs.iter().enumerate() {
        let title = format!("{} ω0 = {}", r.label().to_uppercase(), r.omega0);
        match &r.result {
            Ok(res) => {
                for (col, win) in time_windows(res).into_iter().enumerate() {
                    draw_snapshots(&areas[row * 3 + col], res, plane, &title, win)?;
                }
            }
            Err(_) => {
                areas[row * 3].draw(&Text::new(
                    format!("{title}: failed"),
                    (10, 20),
                    ("sans-serif", crate::plot::AXIS_FONT).into_font(),
                ))?;
            }
        }
    }
    root.present()?;
    Ok(())
}

/// Fig. 6 style: the scaled cost `V(t)/V(0)` (state part) against time, one curve per ω0
/// (one colour each), one panel per controller. With several controller models (a sweep of
/// `--model paper,exact-joints`), the models share the axes of their controller's panel, one
/// line style each (the first model solid, the others dashed), and a last panel plots
/// `V(T)/V(0)` against ω0 per controller and model.
pub fn sweep_cost(path: &Path, name: &str, runs: &[SweepRun]) -> Result<()> {
    let kinds = sweep_kinds(runs);
    let models = sweep_models(runs);
    let mut omegas: Vec<f64> = Vec::new();
    for r in runs {
        if !omegas.contains(&r.omega0) {
            omegas.push(r.omega0);
        }
    }
    let dashed = |m: &mpc::ModelKind| models.iter().position(|x| x == m).unwrap_or(0) > 0;
    let model_legend = |c: RGBColor| -> Vec<(String, Style)> {
        if models.len() < 2 {
            return Vec::new();
        }
        models
            .iter()
            .map(|m| {
                let line = if dashed(m) { "dashed" } else { "solid" };
                (format!("{} model ({line})", m.name()), Style { color: c, dashed: dashed(m) })
            })
            .collect()
    };
    let axes = |title: String| Axes {
        title,
        x: "t (s)".into(),
        y: "V/V(0) (dimensionless)".into(),
        log_y: true,
        references: vec![(0.1, "0.1 (criterion)".into())],
        points: false,
    };
    let mut charts: Vec<StyledChart> = kinds
        .iter()
        .map(|k| {
            let (mut series, mut styles) = (Vec::new(), Vec::new());
            for r in runs.iter().filter(|r| r.controller == *k) {
                let Ok(res) = &r.result else { continue };
                let v0 = res.records.first().map_or(1.0, |x| x.v_state);
                let i = omegas.iter().position(|w| *w == r.omega0).unwrap_or(0);
                series.push((
                    format!("ω0 = {}", r.omega0),
                    res.records.iter().map(|x| (x.t, x.v_state / v0)).collect(),
                ));
                styles.push(Style { color: color(i), dashed: dashed(&r.model) });
            }
            let mut legend: Vec<(String, Style)> = omegas
                .iter()
                .enumerate()
                .map(|(i, w)| (format!("ω0 = {w}"), Style { color: color(i), dashed: false }))
                .collect();
            legend.extend(model_legend(RGBColor(90, 90, 90)));
            let title = if models.len() < 2 {
                format!("{name}: {} — V(t)/V(0)", k.name().to_uppercase())
            } else {
                let m: Vec<&str> = models.iter().map(|m| m.name()).collect();
                format!("{name}: {} ({}) — V(t)/V(0)", k.name().to_uppercase(), m.join(" vs "))
            };
            StyledChart { axes: axes(title), series, styles, legend }
        })
        .collect();
    if models.len() > 1 {
        // the end of each curve against ω0: where each model stops meeting the criterion
        let (mut series, mut styles, mut legend) = (Vec::new(), Vec::new(), Vec::new());
        for (ki, k) in kinds.iter().enumerate() {
            for m in &models {
                let pts: Vec<(f64, f64)> = runs
                    .iter()
                    .filter(|r| r.controller == *k && r.model == *m)
                    .filter_map(|r| {
                        r.result.as_ref().ok().map(|res| (r.omega0, res.summary.v_ratio_final))
                    })
                    .collect();
                if pts.is_empty() {
                    continue;
                }
                let st = Style { color: color(ki), dashed: dashed(m) };
                legend.push((format!("{}, {} model", k.name().to_uppercase(), m.name()), st));
                series.push((String::new(), pts));
                styles.push(st);
            }
        }
        let mut a = axes(format!("{name}: V(T)/V(0) at the end of each run"));
        a.x = "ω0 (rad/s)".into();
        a.y = "V(T)/V(0) (dimensionless)".into();
        charts.push(StyledChart { axes: a, series, styles, legend });
    }
    styled_panels(path, (620 * charts.len().max(1) as u32, 460), &charts)
}

/// Fig. 10 style: the inputs of every run of a sweep against time, the panels of each
/// controller on their own rows (at most three a row), one panel per input, one curve per ω0
/// (each input held for τs).
pub fn sweep_inputs(
    path: &Path,
    name: &str,
    units: &[mpc::ControlInput],
    runs: &[SweepRun],
) -> Result<()> {
    // one group of panels per controller and model
    let mut groups: Vec<(mpc::ControllerKind, mpc::ModelKind)> = Vec::new();
    for r in runs {
        if !groups.contains(&(r.controller, r.model)) {
            groups.push((r.controller, r.model));
        }
    }
    let inputs: Vec<String> = runs
        .iter()
        .find_map(|r| r.result.as_ref().ok())
        .map_or_else(Vec::new, |r| r.input_names.clone());
    // at most three panels a row, so that the figure stays readable at the page's width
    let cols = inputs.len().clamp(1, 3);
    let rows_per_kind = inputs.len().div_ceil(cols).max(1);
    let mut charts: Vec<(Axes, Vec<Series>)> = Vec::new();
    for &(k, m) in &groups {
        while charts.len() % cols != 0 {
            charts.push((Axes::default(), Vec::new()));
        }
        for (i, input) in inputs.iter().enumerate() {
            let series = runs
                .iter()
                .filter(|r| r.controller == k && r.model == m)
                .filter_map(|r| r.result.as_ref().ok())
                .map(|res| {
                    let pts: Vec<(f64, f64)> = res.records.iter().map(|x| (x.t, x.u[i])).collect();
                    (format!("ω0 = {}", res.summary.omega0), steps(&pts))
                })
                .collect();
            charts.push((
                Axes {
                    title: format!(
                        "{name}: {} — {input}",
                        crate::results::label(k, m).to_uppercase()
                    ),
                    x: "t (s)".into(),
                    y: format!("u ({})", units.get(i).map_or("N or N·m", input_unit)),
                    ..Default::default()
                },
                series,
            ));
        }
    }
    let rows = (rows_per_kind * groups.len()).max(1);
    grid(path, (520 * cols as u32, 360 * rows as u32), cols, &charts)
}

/// The unit of a control input: `N·m` for a joint torque or a pure follower moment, `N` for a
/// pure follower force, `N, N·m` for a mixed unit load.
pub fn input_unit(input: &mpc::ControlInput) -> &'static str {
    match input {
        mpc::ControlInput::JointTorque { .. } => "N·m",
        mpc::ControlInput::Follower { load, .. } => {
            let force = load[..3].iter().any(|v| *v != 0.0);
            let moment = load[3..].iter().any(|v| *v != 0.0);
            match (force, moment) {
                (true, false) => "N",
                (false, true) => "N·m",
                _ => "N, N·m",
            }
        }
    }
}

/// The rows of [`strategy_timeline`], bottom to top.
const STRATEGIES: [(mpc::Strategy, &str, RGBColor); 5] = [
    (mpc::Strategy::Qp, "linear MPC (QP)", RGBColor(44, 160, 44)),
    (mpc::Strategy::Sqp, "NMPC (SQP)", RGBColor(31, 119, 180)),
    (mpc::Strategy::Relaxed, "NMPC relaxed retry", RGBColor(255, 127, 14)),
    (mpc::Strategy::Fallback, "NMPC failed (fallback)", RGBColor(214, 39, 40)),
    (mpc::Strategy::Held, "LMPC held", RGBColor(148, 103, 189)),
];

/// Which path produced each sample's control: one bar per sample over `[t, t + τs]` on the row
/// of its strategy (QP, SQP, relaxed retry, failed NMPC: the LMPC plan or, without the LMPC
/// fallback, the NMPC's own iterate applied; held on the LMPC), so that the
/// samples where the NMPC failed or was not tried stand out.
pub fn strategy_timeline(path: &Path, result: &RunResult, sampling: f64) -> Result<()> {
    let root = SVGBackend::new(path, (1000, 300)).into_drawing_area();
    root.fill(&WHITE)?;
    let counts: Vec<usize> = STRATEGIES
        .iter()
        .map(|(k, ..)| result.samples.iter().filter(|s| s.strategy == *k).count())
        .collect();
    let entries: Vec<(String, RGBColor, bool)> = STRATEGIES
        .iter()
        .zip(&counts)
        .map(|((_, name, c), n)| (format!("{name}: {n}"), *c, false))
        .collect();
    let titled = root.titled(
        "which path produced each sample's control",
        ("sans-serif", crate::plot::TITLE_FONT),
    )?;
    let area = crate::plot::with_legend(&titled, &entries)?;
    let t_end = result
        .samples
        .last()
        .map_or(sampling, |s| s.t + sampling)
        .max(result.records.last().map_or(0.0, |r| r.t));
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(150)
        .build_cartesian_2d(0.0..t_end.max(1e-9), -0.5..(STRATEGIES.len() as f64 - 0.5))?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .label_style(("sans-serif", crate::plot::TICK_FONT))
        .axis_desc_style(("sans-serif", crate::plot::AXIS_FONT))
        .x_labels(10)
        .y_labels(STRATEGIES.len())
        .y_label_formatter(&|v| {
            let i = v.round();
            if (v - i).abs() < 1e-6 && i >= 0.0 {
                STRATEGIES.get(i as usize).map_or(String::new(), |s| s.1.to_string())
            } else {
                String::new()
            }
        })
        .disable_y_mesh()
        .draw()?;
    for s in &result.samples {
        if let Some(row) = STRATEGIES.iter().position(|(k, ..)| *k == s.strategy) {
            let c = STRATEGIES[row].2;
            let y = row as f64;
            chart.draw_series(std::iter::once(Rectangle::new(
                [(s.t, y - 0.35), (s.t + sampling, y + 0.35)],
                c.filled(),
            )))?;
        }
    }
    root.present()?;
    Ok(())
}

/// The energy `½(q1ᵀq1 + q2ᵀq2)` (eq. 21) of the plant's projected modal state over time, and
/// the reduced model's prediction of it: from the plant's state at every sample, the model
/// (eq. 29) integrated over the sample interval with the applied inputs (implicit midpoint,
/// four steps per output interval). Where the dashed predictions leave the plant's curve, the
/// model no longer describes the plant. Returns the largest relative energy error of a
/// prediction at the end of its interval (`None` when the states do not fit the model).
pub fn energy_and_prediction(
    path_energy: &Path,
    path_prediction: &Path,
    result: &RunResult,
    rom: &modal_rom::ModalRom,
    sampling: f64,
) -> Result<Option<f64>> {
    let n = rom.n_state();
    let fits = result.records.iter().all(|r| r.q.len() == n && r.u.len() == rom.n_inputs());
    let plant: Vec<(f64, f64)> = if fits {
        result.records.iter().map(|r| (r.t, rom.energy(&r.q))).collect()
    } else {
        Vec::new()
    };
    crate::plot::lines(
        path_energy,
        (1000, 420),
        &Axes {
            title: "energy of the plant's projected modal state, ½(q1ᵀq1 + q2ᵀq2)".into(),
            x: "t (s)".into(),
            y: "energy (J)".into(),
            ..Default::default()
        },
        &[("plant".to_string(), plant.clone())],
    )?;
    let mut predicted: Vec<(f64, f64)> = Vec::new();
    let mut worst: Option<f64> = None;
    if fits && result.records.len() > 1 {
        let dt_out = result.records[1].t - result.records[0].t;
        let per_sample = (sampling / dt_out).round().max(1.0) as usize;
        let substeps = 4;
        for start in (0..result.records.len() - 1).step_by(per_sample) {
            let mut q = result.records[start].q.clone();
            predicted.push((result.records[start].t, rom.energy(&q)));
            let stop = (start + per_sample).min(result.records.len() - 1);
            let mut ok = true;
            for k in start..stop {
                for _ in 0..substeps {
                    if rom
                        .midpoint_step(
                            &mut q,
                            &result.records[k].u,
                            dt_out / substeps as f64,
                            1e-10,
                            30,
                        )
                        .is_err()
                    {
                        ok = false;
                        break;
                    }
                }
                if !ok || q.iter().any(|v| !v.is_finite()) {
                    ok = false;
                    break;
                }
                predicted.push((result.records[k + 1].t, rom.energy(&q)));
            }
            if ok {
                let e_plant = plant[stop].1;
                let e_model = rom.energy(&q);
                let rel = (e_model - e_plant).abs() / e_plant.abs().max(1e-300);
                worst = Some(worst.map_or(rel, |w: f64| w.max(rel)));
            }
            // a break between predictions: each starts again from the plant
            predicted.push((f64::NAN, f64::NAN));
        }
    }
    prediction_chart(path_prediction, &plant, &predicted)?;
    Ok(worst)
}

/// The chart of [`energy_and_prediction`]: plant energy (solid) and the model's predictions
/// over each sample interval (dashed pieces, each from the plant's state).
fn prediction_chart(path: &Path, plant: &[(f64, f64)], predicted: &[(f64, f64)]) -> Result<()> {
    let root = SVGBackend::new(path, (1000, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let blue = crate::plot::color(0);
    let red = crate::plot::color(1);
    let titled = root.titled(
        "reduced model against plant: energy predicted over each sample from the plant's state",
        ("sans-serif", crate::plot::TITLE_FONT),
    )?;
    let area = crate::plot::with_legend(
        &titled,
        &[("plant".into(), blue, false), ("model prediction".into(), red, true)],
    )?;
    let pos = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let (mut lo, mut hi, mut t1) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
    for p in plant.iter().chain(predicted).filter(pos) {
        lo = lo.min(p.1);
        hi = hi.max(p.1);
        t1 = t1.max(p.0);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        area.draw(&Text::new(
            "no modal state to compare",
            (20, 20),
            ("sans-serif", crate::plot::AXIS_FONT).into_font(),
        ))?;
        root.present()?;
        return Ok(());
    }
    let mut chart = ChartBuilder::on(&area)
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(78)
        .build_cartesian_2d(0.0..t1.max(1e-9), {
            let pad = 0.05 * (hi - lo).max(1e-12 * hi.abs().max(1e-300));
            (lo - pad)..(hi + pad)
        })?;
    chart
        .configure_mesh()
        .x_desc("t (s)")
        .y_desc("energy (J)")
        .label_style(("sans-serif", crate::plot::TICK_FONT))
        .axis_desc_style(("sans-serif", crate::plot::AXIS_FONT))
        .x_labels(10)
        .y_labels(8)
        .y_label_formatter(&|v| crate::plot::short(*v))
        .draw()?;
    chart.draw_series(LineSeries::new(
        plant.iter().copied().filter(|p| pos(&p)),
        blue.stroke_width(2),
    ))?;
    for piece in predicted.split(|p| p.0.is_nan()) {
        let pts: Vec<(f64, f64)> = piece.iter().copied().filter(|p| pos(&p)).collect();
        if pts.len() > 1 {
            chart.draw_series(DashedLineSeries::new(pts, 5, 3, red.stroke_width(2)))?;
        }
    }
    root.present()?;
    Ok(())
}
