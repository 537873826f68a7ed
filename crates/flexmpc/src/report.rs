//! The offline HTML report of a closed loop: `index.html` (hand-written HTML, no external
//! URLs) next to its SVG figures (plotters, plus one hand-written animated SVG): scene
//! summary, mode table and mode shapes (paper Figs. 4–5), snapshots of the deformed structure
//! in three time windows (Figs. 7, 9), the scaled cost `V(t)/V(0)` (Figs. 6, 8), inputs
//! (Fig. 10), joint angles, which path produced each sample's control, the modal energy and
//! the reduced model's prediction against the plant, solve time per sample against `τs`, and
//! the closed-loop summary.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use mpc::RunResult;

use crate::figures::{planes, snapshots_svg, window};
use crate::plot::{self, Axes, Series};
use crate::scene::{Control, Scene};

/// Escapes `&`, `<`, `>`, `"` and `'` for HTML text and attribute values.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// An animated SVG (SMIL, discrete frames at the snapshot times, real time, looping) of the
/// snapshots, one view per plane.
fn animation_svg(result: &RunResult, planar: bool, path: &Path) -> Result<()> {
    let pl = planes(planar);
    let size = 420.0;
    let n = result.snapshots.len().max(1);
    let frame = result.snapshots.get(1).map_or(0.25, |s| s.t).max(1e-3);
    let dur = frame * n as f64;
    let mut svg = String::new();
    let width = size * pl.len() as f64;
    writeln!(
        svg,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{h}" viewBox="0 0 {width} {h}">"#,
        h = size + 30.0
    )?;
    writeln!(svg, r#"<rect width="100%" height="100%" fill="white"/>"#)?;
    let axis = ["x", "y", "z"];
    for (v, (name, a, b)) in pl.iter().enumerate() {
        let ((ca, cb), w) = window(result, *a, *b);
        let ox = v as f64 * size;
        let map = |p: &[f64; 3]| {
            let x = ox + size * (0.5 + (p[*a] - ca) / (2.0 * w));
            let y = size * (0.5 - (p[*b] - cb) / (2.0 * w)) + 30.0;
            format!("{x:.1},{y:.1}")
        };
        writeln!(
            svg,
            r#"<text x="{x}" y="20" font-family="sans-serif" font-size="14">{name} plane ({} right, {} up)</text>"#,
            axis[*a],
            axis[*b],
            x = ox + 10.0
        )?;
        // faint trace of every snapshot
        for s in &result.snapshots {
            for beam in &s.positions {
                let pts: Vec<String> = beam.iter().map(map).collect();
                writeln!(
                    svg,
                    r##"<polyline points="{}" fill="none" stroke="#ccc" stroke-width="1"/>"##,
                    pts.join(" ")
                )?;
            }
        }
        let n_beams = result.snapshots.first().map_or(0, |s| s.positions.len());
        for bi in 0..n_beams {
            let frames: Vec<String> = result
                .snapshots
                .iter()
                .map(|s| s.positions[bi].iter().map(map).collect::<Vec<_>>().join(" "))
                .collect();
            writeln!(
                svg,
                r#"<polyline points="{first}" fill="none" stroke="{color}" stroke-width="4" stroke-linecap="round"><animate attributeName="points" dur="{dur:.3}s" repeatCount="indefinite" calcMode="discrete" values="{values}"/></polyline>"#,
                first = frames[0],
                color = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"][bi % 4],
                values = frames.join(";")
            )?;
        }
    }
    // time label: one text per frame, visible during its frame
    for (k, s) in result.snapshots.iter().enumerate() {
        let values: Vec<&str> = (0..n).map(|j| if j == k { "1" } else { "0" }).collect();
        writeln!(
            svg,
            r#"<text x="{x}" y="20" font-family="sans-serif" font-size="14" opacity="{o}">t = {t:.2} s<animate attributeName="opacity" dur="{dur:.3}s" repeatCount="indefinite" calcMode="discrete" values="{v}"/></text>"#,
            x = width - 110.0,
            o = if k == 0 { 1 } else { 0 },
            t = s.t,
            v = values.join(";")
        )?;
    }
    writeln!(svg, "</svg>")?;
    std::fs::write(path, svg).with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// The controller's mode set in words: `the lowest 8`, `rigid 2, axial 1, bending 4`,
/// `modes 1, 2, 5 of the table below (scene indices 0, 1, 4, 0-based)`.
pub fn selection_text(sel: &modal_rom::ModeSelection) -> String {
    match sel {
        modal_rom::ModeSelection::Lowest(n) => format!("the lowest {n} (rigid included)"),
        modal_rom::ModeSelection::ByKind(k) => {
            let parts: Vec<String> = [
                ("rigid", k.rigid),
                ("axial", k.axial),
                ("torsion", k.torsion),
                ("bending about e2", k.bending_e2),
                ("bending about e3", k.bending_e3),
                ("mixed", k.mixed),
            ]
            .iter()
            .filter(|(_, n)| *n > 0)
            .map(|(name, n)| format!("{name} {n}"))
            .collect();
            format!("the lowest of each kind: {}", parts.join(", "))
        }
        modal_rom::ModeSelection::Indices(i) => format!(
            "modes {} of the table below (scene indices {}, 0-based)",
            i.iter().map(|m| (m + 1).to_string()).collect::<Vec<_>>().join(", "),
            i.iter().map(|m| m.to_string()).collect::<Vec<_>>().join(", ")
        ),
    }
}

/// The page head and its style sheet (no external resources).
fn head(h: &mut String, title: &str) {
    let _ = writeln!(
        h,
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{}</title>
<style>
body {{ font-family: sans-serif; max-width: 1250px; margin: 1em auto; padding: 0 1em; color: #222; }}
table {{ border-collapse: collapse; margin: 0.5em 0 1em; }}
th, td {{ border: 1px solid #bbb; padding: 3px 8px; text-align: left; }}
th {{ background: #f0f0f0; }}
figure {{ margin: 1em 0; }} img {{ max-width: 100%; border: 1px solid #ddd; }}
figcaption {{ color: #555; font-size: 0.9em; }}
.ok {{ color: #161; font-weight: bold; }} .fail {{ color: #a11; font-weight: bold; }}
</style></head><body>"#,
        esc(title)
    );
}

fn row(html: &mut String, key: &str, value: &str) {
    let _ = writeln!(html, "<tr><th>{}</th><td>{}</td></tr>", esc(key), esc(value));
}

fn figure(html: &mut String, src: &str, caption: &str) {
    let _ = writeln!(
        html,
        r#"<figure><img src="{}" alt="{}"><figcaption>{}</figcaption></figure>"#,
        esc(src),
        esc(caption),
        esc(caption)
    );
}

/// Writes the figures and `index.html` of `result` into `out`; returns the path of
/// `index.html`. Every file written is a pure function of the inputs: no measured time is
/// embedded. With `timings`, the report links to the timing files (`timings.json`,
/// `timings.csv`, `solve_times.svg`, written by [`crate::timings::write_run`]); without, it
/// says they were not recorded.
pub fn write(
    scene: &Scene,
    control: &Control,
    result: &RunResult,
    rom: Option<&modal_rom::ModalRom>,
    out: &Path,
    timings: bool,
) -> Result<PathBuf> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let sc = &control.scenario;
    let structure = &sc.structure;
    let planar = matches!(structure.components(), intrinsic_beam::Components::Planar);
    let t = |f: fn(&mpc::Record) -> f64| result.records.iter().map(f).collect::<Vec<f64>>();
    let times = t(|r| r.t);

    // modes (Figs. 4–5)
    let modes = crate::modes::report(structure, scene.mode_count)
        .and_then(|m| crate::modes::plot(&m, &out.join("modes")).map(|_| m));

    // cost (Fig. 6)
    let v0 = result.records.first().map_or(1.0, |r| r.v_state);
    let cost: Vec<(f64, f64)> = result.records.iter().map(|r| (r.t, r.v_state / v0)).collect();
    plot::lines(
        &out.join("cost.svg"),
        (1000, 420),
        &Axes {
            title: format!("scaled cost V(t)/V(0), ω0 = {}", control.omega0),
            x: "t (s)".into(),
            y: "V/V(0) (dimensionless)".into(),
            log_y: true,
            references: vec![(0.1, "0.1 (criterion)".into())],
            points: false,
        },
        &[(control.controller.kind.name().to_uppercase(), cost)],
    )?;
    // inputs (Fig. 10), one panel per unit
    let mut by_unit: Vec<(&str, Vec<Series>)> = Vec::new();
    for (i, n) in result.input_names.iter().enumerate() {
        let unit = sc.inputs.get(i).map_or("N or N·m", crate::figures::input_unit);
        let pts: Vec<(f64, f64)> = result.records.iter().map(|r| (r.t, r.u[i])).collect();
        match by_unit.iter_mut().find(|(u, _)| *u == unit) {
            Some((_, v)) => v.push((n.clone(), plot::steps(&pts))),
            None => by_unit.push((unit, vec![(n.clone(), plot::steps(&pts))])),
        }
    }
    let charts: Vec<(Axes, Vec<Series>)> = by_unit
        .into_iter()
        .map(|(unit, series)| {
            (
                Axes {
                    title: format!("inputs in {unit} (each held for τs)"),
                    x: "t (s)".into(),
                    y: format!("u ({unit})"),
                    ..Default::default()
                },
                series,
            )
        })
        .collect();
    plot::grid(&out.join("inputs.svg"), (1000, 380 * charts.len().max(1) as u32), 1, &charts)?;
    // which path produced each sample, energy and the model against the plant
    crate::figures::strategy_timeline(&out.join("strategies.svg"), result, sc.mpc.timing.sampling)?;
    let prediction_error = match rom {
        Some(rom) => crate::figures::energy_and_prediction(
            &out.join("energy.svg"),
            &out.join("prediction.svg"),
            result,
            rom,
            sc.mpc.timing.sampling,
        )?,
        None => None,
    };
    // joint angles
    let angles: Vec<Series> = result
        .joint_names
        .iter()
        .enumerate()
        .map(|(j, n)| {
            (
                n.clone(),
                result.records.iter().map(|r| (r.t, r.joint_angles[j].to_degrees())).collect(),
            )
        })
        .collect();
    plot::lines(
        &out.join("angles.svg"),
        (1000, 420),
        &Axes {
            title: "joint angles".into(),
            x: "t (s)".into(),
            y: "angle (deg)".into(),
            ..Default::default()
        },
        &angles,
    )?;
    // snapshots (Fig. 7) and their animation
    snapshots_svg(result, planar, &out.join("snapshots.svg"))?;
    animation_svg(result, planar, &out.join("animation.svg"))?;

    let s = &result.summary;
    let title = format!("flexmpc: {}", scene.name);
    let mut h = String::new();
    head(&mut h, &title);
    let _ = writeln!(h, "<h1>{}</h1>\n<p>{}</p>", esc(&title), esc(scene.description.trim()));
    let _ = writeln!(
        h,
        r#"<p id="figure-status" hidden>figures: script did not run</p>
<p>Files: <a href="timeseries.csv">timeseries.csv</a>, <a href="samples.json">samples.json</a> (per-sample solver log), <a href="summary.json">summary.json</a>, <a href="snapshots.json">snapshots.json</a>{}.</p>"#,
        if timings {
            r#"; measured timings: <a href="timings.json">timings.json</a>, <a href="timings.csv">timings.csv</a>"#
        } else {
            ""
        }
    );

    // closed-loop summary
    let _ = writeln!(h, "<h2>Closed-loop summary</h2><table>");
    let verdict = if s.stabilised {
        r#"<span class="ok">stabilised</span>"#
    } else {
        r#"<span class="fail">not stabilised</span>"#
    };
    let _ = writeln!(
        h,
        "<tr><th>criterion (at the end: rigid rate &lt; 5% of ω0, orientation within 20% of \
         its largest excursion, V/V(0) &lt; 0.1)</th><td>{verdict}</td></tr>"
    );
    for (k, v) in [
        ("controller / plant", format!("{} / {}", s.controller, s.plant)),
        ("reduced model", s.model.clone()),
        (
            "ω0 (rad/s) × axis",
            format!(
                "{} × ({})",
                s.omega0,
                sc.omega_direction.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ")
            ),
        ),
        ("V(T)/V(0)", format!("{:.4e}", s.v_ratio_final)),
        ("largest joint angle between links (deg)", format!("{:.2}", s.max_joint_angle_deg)),
        (
            "orientation error at T / largest excursion (deg)",
            format!("{:.2} / {:.2}", s.orientation_error_deg, s.max_orientation_deg),
        ),
        ("rigid rate at T / at 0", format!("{:.3e}", s.rigid_rate_ratio)),
        (
            "samples: total / failed first attempts / relaxed / failed (fallback) / held / joint limit",
            format!(
                "{} / {} / {} / {} / {} / {}",
                result.samples.len(),
                s.failed_first_attempts,
                s.relaxed_samples,
                s.fallback_samples,
                s.held_samples,
                s.joint_limit_samples
            ),
        ),
        ("time reached (s)", format!("{}", s.t_end)),
        ("stopped early because", s.error.clone().unwrap_or_else(|| "—".into())),
    ] {
        row(&mut h, k, &v);
    }
    let _ = writeln!(h, "</table>");

    // figures of the run
    let (fig_cost, fig_snap) = if planar { ("Fig. 6", "Fig. 7") } else { ("Fig. 8", "Fig. 9") };
    let _ = writeln!(h, "<h2>Cost</h2>");
    figure(
        &mut h,
        "cost.svg",
        &format!("State part of the cost (34), V(t)/V(0), from the projected plant state (paper {fig_cost})."),
    );
    let _ = writeln!(h, "<h2>Snapshots</h2>");
    figure(&mut h, "snapshots.svg", &format!("Deformed structure every snapshot interval in three time windows, shade darkening as t increases (paper {fig_snap})."));
    figure(&mut h, "animation.svg", "Animation of the snapshots (real time, looping).");
    let _ = writeln!(h, "<h2>Inputs and joint angles</h2>");
    figure(
        &mut h,
        "inputs.svg",
        if planar {
            "Control inputs, each held for τs (the paper's Fig. 10 shows them for the 3D case)."
        } else {
            "Control inputs, each held for τs (paper Fig. 10)."
        },
    );
    figure(&mut h, "angles.svg", "Joint angles (supports: the root link's orientation).");
    let _ = writeln!(h, "<h2>Controller</h2>");
    figure(&mut h, "strategies.svg", "Which path produced each sample's control: linear MPC, NMPC, NMPC after a relaxed retry, linear MPC plan after an NMPC failure (fallback) or held on it afterwards.");
    if rom.is_some() {
        figure(&mut h, "energy.svg", "Energy ½(q1ᵀq1 + q2ᵀq2) (21) of the plant's state projected on the controller's modes.");
        figure(
            &mut h,
            "prediction.svg",
            &match prediction_error {
                Some(e) => format!("The controller's reduced model (29) against the plant: from the plant's state at each sample, the model's prediction of the energy over the sample interval with the applied inputs. Largest relative error at the end of an interval: {e:.2e}."),
                None => "The controller's reduced model (29) against the plant: no prediction could be made from the recorded states.".to_string(),
            },
        );
    }
    let _ = writeln!(h, "<h2>Solve time per sample</h2>");
    if timings {
        let _ = writeln!(
            h,
            r#"<p>Measured times: per-sample solve times are CPU time per thread (the solving thread's CPU; with parallel shooting intervals all threads' CPU over the pool size), with each sample's wall time beside them, the loop time is wall-clock (they change from run to run, so they are kept in their own files: <a href="timings.json">timings.json</a> has the median and worst solve time and the loop's wall time, <a href="timings.csv">timings.csv</a> each sample's; every other file of this folder is reproducible).</p>"#
        );
        figure(
            &mut h,
            "solve_times.svg",
            &format!(
                "CPU time per thread of each sample's solve (all attempts) against the sampling time τs = {} s and the {} ms goal.",
                sc.mpc.timing.sampling,
                crate::timings::SOLVE_TIME_GOAL_S * 1e3
            ),
        );
    } else {
        let _ = writeln!(
            h,
            "<p>Timings were not recorded (<code>--no-timings</code>): this folder is a pure \
             function of the inputs.</p>"
        );
    }

    // scene summary
    let _ = writeln!(h, "<h2>Scene</h2><table>");
    row(&mut h, "file", &scene.file.display().to_string());
    row(&mut h, "components", if planar { "planar" } else { "spatial" });
    for b in structure.beams() {
        row(
            &mut h,
            &format!("beam {}", b.name),
            &format!("{} elements, length {}", b.beam.n_elements(), b.beam.mesh().length()),
        );
    }
    for j in structure.joints() {
        row(
            &mut h,
            &format!("{} {}", if j.ground { "support" } else { "joint" }, j.name),
            &format!("{} end(s), {} constraint rows", j.ends.len(), j.n_rows),
        );
    }
    for i in &sc.inputs {
        let what = match i {
            mpc::ControlInput::JointTorque { joint, .. } => format!("torque at `{joint}`"),
            mpc::ControlInput::Follower { beam, node, load, .. } => format!(
                "follower load {:?} at node {node} of `{}`",
                load,
                structure.beams()[*beam].name
            ),
        };
        row(&mut h, &format!("input {}", i.name()), &what);
    }
    let m = &sc.mpc;
    let c = &control.controller;
    for (k, v) in [
        ("controller", c.kind.name().to_string()),
        (
            "solver",
            format!(
                "real-time iteration {}, ≤ {} SQP iterations, KKT {:.0e}, accept defects ≤ {:.0e}, LM {}, retry α {} (LM {}), LMPC fallback {}",
                c.real_time_iteration,
                c.max_iterations,
                c.kkt_tolerance,
                c.accept_violation,
                c.levenberg_marquardt,
                c.retry_relaxation.map_or("off".to_string(), |a| a.to_string()),
                c.retry_levenberg_marquardt,
                c.fallback_to_lmpc
            ),
        ),
        (
            "integrator",
            format!(
                "{}, {} substeps per interval",
                match c.integrator.kind {
                    ocp_transcription::IntegratorKind::Rk4 => "explicit RK4",
                    ocp_transcription::IntegratorKind::ImplicitMidpoint => "implicit midpoint",
                    ocp_transcription::IntegratorKind::LawsonRk4 => "Lawson exponential RK4",
                    _ => "another integrator",
                },
                c.integrator.substeps
            ),
        ),
        (
            "weights (34)–(36)",
            format!(
                "kx1 = {}, kx2 = {}, kΔξ = {}, ku = {}, Kξ rigid = {}, Kξ elastic = {}, |u| ≤ {}{}",
                m.cost.kx1,
                m.cost.kx2,
                m.cost.k_dxi,
                m.cost.ku,
                m.cost.k_xi_rigid,
                m.cost.k_xi_elastic,
                m.cost.u_max,
                if *m == mpc::MpcSettings::default() { " (the paper's)" } else { " (NOT the paper's)" }
            ),
        ),
        ("timing", format!("τp = {} s, τs = {} s, Nc = {}, duration {} s, plant dt = {} s", m.timing.horizon, m.timing.sampling, m.timing.intervals, sc.duration, sc.plant.dt)),
        ("controller modes", selection_text(&sc.selection)),
    ] {
        row(&mut h, k, &v);
    }
    let _ = writeln!(h, "</table>");

    // modes
    let _ = writeln!(h, "<h2>Modes</h2>");
    match &modes {
        Ok(m) => {
            let _ = writeln!(
                h,
                "<p>Constrained modes of the structure at its reference configuration (the first {}, rigid included).</p>\n<table><tr><th>mode</th><th>ω (rad/s)</th><th>f (Hz)</th><th>kind</th></tr>",
                m.frequencies_rad_s.len()
            );
            for (i, (w, l)) in m.frequencies_rad_s.iter().zip(&m.labels).enumerate() {
                let _ = writeln!(
                    h,
                    "<tr><td>{}</td><td>{:.6}</td><td>{:.5}</td><td>{}</td></tr>",
                    i + 1,
                    w,
                    w / std::f64::consts::TAU,
                    esc(l)
                );
            }
            let _ = writeln!(h, "</table>");
            let (f4, f5) = if planar { (" (paper Fig. 4)", " (paper Fig. 5)") } else { ("", "") };
            figure(&mut h, "modes/shapes.svg", &format!("Elastic mode shapes: translational velocity on the reference configuration{f5}."));
            figure(
                &mut h,
                "modes/components.svg",
                &format!("Velocity components of the elastic modes along the beams{f4}."),
            );
        }
        Err(e) => {
            let _ = writeln!(
                h,
                "<p class=\"fail\">modes could not be computed: {}</p>",
                esc(&e.to_string())
            );
        }
    }
    let _ = writeln!(
        h,
        "<p>{} records from t = {} to {} s. Written by flexmpc {}.</p>",
        times.len(),
        times.first().copied().unwrap_or(0.0),
        times.last().copied().unwrap_or(0.0),
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(
        h,
        r#"<script>
window.addEventListener('load', function () {{
  var imgs = document.querySelectorAll('img');
  var ok = 0;
  for (var i = 0; i < imgs.length; i++) {{
    var loaded = imgs[i].complete && imgs[i].naturalWidth > 0;
    imgs[i].setAttribute('data-loaded', loaded ? 'yes' : 'no');
    if (loaded) ok++;
  }}
  var s = document.getElementById('figure-status');
  s.textContent = 'figures: ' + ok + ' of ' + imgs.length + ' loaded';
  s.setAttribute('data-loaded', String(ok));
  s.setAttribute('data-total', String(imgs.length));
}});
</script>
</body></html>"#
    );
    let path = out.join("index.html");
    std::fs::write(&path, h).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

/// Writes the sweep's `index.html` into `out` (next to the figures written by
/// [`crate::control::run_sweep`]): one table row per run and the figures — scaled cost
/// (Figs. 6, 8), snapshots (Figs. 7, 9), inputs (Fig. 10) and, with `timings`, the solve time
/// per sample (linked, no measured number in the page). Returns its path.
pub fn write_sweep(
    scene: &Scene,
    control: &Control,
    runs: &[crate::results::SweepRun],
    out: &Path,
    timings: bool,
) -> Result<PathBuf> {
    let title = format!("flexmpc sweep: {}", scene.name);
    let mut h = String::new();
    head(&mut h, &title);
    let _ = writeln!(h, "<h1>{}</h1>\n<p>{}</p>", esc(&title), esc(scene.description.trim()));
    let _ = writeln!(
        h,
        r#"<p>{} closed loops on the {} plant ({} s each, τs = {} s). Files: <a href="sweep.csv">sweep.csv</a>, <a href="sweep.json">sweep.json</a>, per run <code>runs/&lt;controller&gt;-w&lt;ω0&gt;.csv</code> and <code>-snapshots.svg</code>{}.</p>"#,
        runs.len(),
        control.plant.name(),
        control.scenario.duration,
        control.scenario.mpc.timing.sampling,
        if timings {
            r#"; measured timings: <a href="timings.json">timings.json</a>, <a href="timings.csv">timings.csv</a>"#
        } else {
            ""
        }
    );
    let _ = writeln!(
        h,
        "<h2>Runs</h2><table><tr><th>controller</th><th>ω0 (rad/s)</th><th>stabilised</th>\
         <th>V(T)/V(0)</th><th>largest joint angle (deg)</th><th>orientation error / largest \
         (deg)</th><th>rigid rate ratio</th><th>relaxed / fallback / held samples</th><th>stopped \
         early</th><th>time series</th></tr>"
    );
    for r in runs {
        match &r.result {
            Ok(res) => {
                let s = &res.summary;
                let stem = r.stem();
                let _ = writeln!(
                    h,
                    r#"<tr><td>{}</td><td>{}</td><td class="{}">{}</td><td>{:.3e}</td><td>{:.1}</td><td>{:.2} / {:.1}</td><td>{:.2e}</td><td>{} / {} / {}</td><td>{}</td><td><a href="runs/{stem}.csv">csv</a>, <a href="runs/{stem}-snapshots.svg">snapshots</a></td></tr>"#,
                    esc(&r.label()),
                    s.omega0,
                    if s.stabilised { "ok" } else { "fail" },
                    if s.stabilised { "yes" } else { "no" },
                    s.v_ratio_final,
                    s.max_joint_angle_deg,
                    s.orientation_error_deg,
                    s.max_orientation_deg,
                    s.rigid_rate_ratio,
                    s.relaxed_samples,
                    s.fallback_samples,
                    s.held_samples,
                    esc(&s
                        .error
                        .as_ref()
                        .map_or("—".to_string(), |e| format!("at {} s: {e}", s.t_end))),
                );
            }
            Err(e) => {
                let _ = writeln!(
                    h,
                    r#"<tr><td>{}</td><td>{}</td><td class="fail">failed</td><td colspan="7">{}</td></tr>"#,
                    r.label(),
                    r.omega0,
                    esc(e)
                );
            }
        }
    }
    let _ = writeln!(h, "</table>");
    let _ = writeln!(h, "<h2>Cost</h2>");
    let planar =
        matches!(control.scenario.structure.components(), intrinsic_beam::Components::Planar);
    let (fig_cost, fig_snap) = if planar { ("Fig. 6", "Fig. 7") } else { ("Fig. 8", "Fig. 9") };
    figure(
        &mut h,
        "cost.svg",
        &format!("State part of the cost, V(t)/V(0), per ω0 (paper {fig_cost})."),
    );
    let _ = writeln!(h, "<h2>Snapshots</h2>");
    figure(&mut h, "snapshots.svg", &format!("Deformed structure every snapshot interval in three time windows, shade darkening as t increases, one row per run (paper {fig_snap})."));
    let _ = writeln!(h, "<h2>Inputs</h2>");
    figure(
        &mut h,
        "inputs.svg",
        if planar {
            "Control inputs per ω0, each held for τs (the paper's Fig. 10 shows them for the 3D case)."
        } else {
            "Control inputs per ω0, each held for τs (paper Fig. 10)."
        },
    );
    let _ = writeln!(h, "<h2>Solve time per sample</h2>");
    if timings {
        figure(
            &mut h,
            "solve_times.svg",
            &format!(
                "Measured CPU time per thread of each sample's solve against τs = {} s and the {} ms goal (timings.json, timings.csv).",
                control.scenario.mpc.timing.sampling,
                crate::timings::SOLVE_TIME_GOAL_S * 1e3
            ),
        );
    } else {
        let _ = writeln!(
            h,
            "<p>Timings were not recorded (<code>--no-timings</code>): this folder is a pure \
             function of the inputs.</p>"
        );
    }
    let _ = writeln!(h, "<p>Written by flexmpc {}.</p>\n</body></html>", env!("CARGO_PKG_VERSION"));
    let path = out.join("index.html");
    std::fs::write(&path, h).with_context(|| format!("writing {}", path.display()))?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::esc;

    #[test]
    fn escaping() {
        assert_eq!(esc(r#"<a href="x">&'"#), "&lt;a href=&quot;x&quot;&gt;&amp;&#39;");
        assert_eq!(esc("ω0 = 1"), "ω0 = 1");
    }
}
