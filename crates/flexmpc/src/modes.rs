//! `flexmpc modes`: constrained linear modes of a scene's structure (paper §3.2, eqs. 30–32),
//! printed as a table or JSON and drawn in the style of the paper's Figs. 4–5.

use std::path::Path;

use anyhow::{Context, Result};
use modal_rom::{mode_report, BasisSettings, ModeReport};
use multibody_constraints::Structure;
use plotters::prelude::*;

/// The first `n_modes` modes of `structure` (fewer if the structure has fewer).
pub fn report(structure: &Structure, n_modes: usize) -> Result<ModeReport> {
    let settings = BasisSettings::default();
    // Ask for what exists: the basis knows its size only once solved.
    match mode_report(structure, n_modes, &settings) {
        Ok(r) => Ok(r),
        Err(first) => {
            let all = modal_rom::StructureModel::new(structure)?.modes(&settings)?;
            if n_modes > all.n_modes() && all.n_modes() > 0 {
                Ok(modal_rom::report_of(&all, all.n_modes())?)
            } else {
                Err(first.into())
            }
        }
    }
}

/// Prints the frequency table.
pub fn print_table(report: &ModeReport) {
    println!("{:>4}  {:>14}  {:>10}  label", "mode", "ω (rad/s)", "f (Hz)");
    for (i, (w, l)) in report.frequencies_rad_s.iter().zip(&report.labels).enumerate() {
        println!("{:>4}  {:>14.6}  {:>10.5}  {}", i + 1, w, w / std::f64::consts::TAU, l);
    }
}

/// Writes `components.svg` (Fig. 4: each velocity component of each elastic mode along the
/// arc length, beams one after the other) and `shapes.svg` (Fig. 5: translational velocity
/// mode shapes superimposed on the reference configuration, in the e1–e3 plane).
pub fn plot(report: &ModeReport, dir: &Path) -> Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let elastic: Vec<_> = report.shapes.iter().skip(report.n_rigid).collect();
    let shapes = if elastic.is_empty() { report.shapes.iter().collect() } else { elastic };
    let k = shapes
        .first()
        .and_then(|m| m.beams.first())
        .map_or(0, |b| b.phi1.first().map_or(0, Vec::len));
    let names: Vec<&str> =
        if k == 3 { vec!["v1", "v3", "ω2"] } else { vec!["v1", "v2", "v3", "ω1", "ω2", "ω3"] };
    let palette = [RED, BLUE, GREEN, MAGENTA, CYAN, BLACK, RGBColor(200, 120, 0)];

    // Fig. 4: components against the cumulative arc length.
    let fig4 = dir.join("components.svg");
    {
        let root = SVGBackend::new(&fig4, (900, 260 * k.max(1) as u32)).into_drawing_area();
        root.fill(&WHITE)?;
        let panels = root.split_evenly((k.max(1), 1));
        for (c, panel) in panels.iter().enumerate() {
            let mut series: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
            let mut lo = f64::INFINITY;
            let mut hi = f64::NEG_INFINITY;
            let mut s_max: f64 = 0.0;
            for m in &shapes {
                let mut pts = Vec::new();
                let mut offset = 0.0;
                for b in &m.beams {
                    for (s, phi) in b.s.iter().zip(&b.phi1) {
                        let y = phi.get(c).copied().unwrap_or(0.0);
                        lo = lo.min(y);
                        hi = hi.max(y);
                        pts.push((offset + s, y));
                    }
                    offset += b.s.last().copied().unwrap_or(0.0);
                    // a break between beams: discontinuities at joints stay visible
                    pts.push((f64::NAN, f64::NAN));
                }
                s_max = s_max.max(offset);
                series.push((
                    format!("mode {} ({}, {:.3} rad/s)", m.index + 1, m.label, m.frequency_rad_s),
                    pts,
                ));
            }
            if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
                hi = lo + 1.0;
            }
            let pad = 0.05 * (hi - lo);
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("φ_{}", names.get(c).copied().unwrap_or("?")), ("sans-serif", 16))
                .margin(10)
                .x_label_area_size(30)
                .y_label_area_size(55)
                .build_cartesian_2d(0.0..s_max.max(1e-12), (lo - pad)..(hi + pad))?;
            chart.configure_mesh().x_desc("s along the beams").draw()?;
            for (j, (label, pts)) in series.into_iter().enumerate() {
                let color = palette[j % palette.len()];
                for segment in pts.split(|p| p.0.is_nan()) {
                    chart.draw_series(LineSeries::new(
                        segment.iter().copied(),
                        color.stroke_width(2),
                    ))?;
                }
                if c == 0 {
                    chart
                        .draw_series(std::iter::once(PathElement::new(vec![], color)))?
                        .label(label)
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                        });
                }
            }
            if c == 0 {
                chart
                    .configure_series_labels()
                    .background_style(WHITE.mix(0.8))
                    .border_style(BLACK)
                    .draw()?;
            }
        }
        root.present()?;
    }

    // Fig. 5: reference configuration (thick black) plus the global translational velocity.
    let fig5 = dir.join("shapes.svg");
    {
        let n = shapes.len().max(1);
        let root = SVGBackend::new(&fig5, (300 * n as u32, 320)).into_drawing_area();
        root.fill(&WHITE)?;
        let panels = root.split_evenly((1, n));
        for (m, panel) in shapes.iter().zip(panels.iter()) {
            let (mut lo_x, mut hi_x, mut lo_z, mut hi_z) =
                (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
            let vmax = m
                .beams
                .iter()
                .flat_map(|b| b.velocity_global.iter())
                .map(|v| (v[0] * v[0] + v[2] * v[2]).sqrt())
                .fold(0.0_f64, f64::max)
                .max(1e-300);
            let span =
                m.beams.iter().map(|b| b.s.last().copied().unwrap_or(0.0)).sum::<f64>().max(1e-12);
            let scale = 0.25 * span / vmax;
            for b in &m.beams {
                for (r, v) in b.reference.iter().zip(&b.velocity_global) {
                    for (x, z) in [(r[0], r[2]), (r[0] + scale * v[0], r[2] + scale * v[2])] {
                        lo_x = lo_x.min(x);
                        hi_x = hi_x.max(x);
                        lo_z = lo_z.min(z);
                        hi_z = hi_z.max(z);
                    }
                }
            }
            let w = (hi_x - lo_x).max(hi_z - lo_z).max(1e-12) * 0.55;
            let (cx, cz) = (0.5 * (lo_x + hi_x), 0.5 * (lo_z + hi_z));
            let mut chart = ChartBuilder::on(panel)
                .caption(
                    format!("mode {}: {} ({:.3} rad/s)", m.index + 1, m.label, m.frequency_rad_s),
                    ("sans-serif", 13),
                )
                .margin(8)
                .x_label_area_size(20)
                .y_label_area_size(30)
                .build_cartesian_2d((cx - w)..(cx + w), (cz - w)..(cz + w))?;
            chart.configure_mesh().x_desc("x").y_desc("z").draw()?;
            for b in &m.beams {
                chart.draw_series(LineSeries::new(
                    b.reference.iter().map(|r| (r[0], r[2])),
                    BLACK.stroke_width(4),
                ))?;
                chart.draw_series(LineSeries::new(
                    b.reference
                        .iter()
                        .zip(&b.velocity_global)
                        .map(|(r, v)| (r[0] + scale * v[0], r[2] + scale * v[2])),
                    RED.stroke_width(2),
                ))?;
            }
        }
        root.present()?;
    }
    Ok(vec![fig4, fig5])
}
