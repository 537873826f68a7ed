//! `flexmpc modes`: constrained linear modes of a scene's structure (paper §3.2, eqs. 30–32),
//! printed as a table or JSON and drawn in the style of the paper's Figs. 4–5.
//!
//! Two routes compute the same report (`docs/theory.md §4`):
//!
//! - **dense** ([`modal_rom::mode_report`]): the blocks `B1`, `B2`, `D` are dense matrices and
//!   the null space and modes come from dense SVDs; it returns every mode, in `O(n²)` memory
//!   and `O(n³)` time in the number `n` of node unknowns. It is taken for meshes up to
//!   [`DENSE_ROUTE_MAX_N1`] node unknowns (every shipped scene), and it is what `mpc`,
//!   `sweep` and `ocp` build their modal basis with ([`check_size`] guards them).
//! - **sparse** ([`modal_rom::sparse_mode_report`]): the lowest modes only, by shift-invert
//!   Lanczos on the sparse saddle-point pencil factorised once by sparse LU, in memory and
//!   time linear in the mesh. Frequencies agree with the dense route to about `1e-10`
//!   relative, labels and rigid modes are the same, shapes agree up to sign.
//!
//! [`estimate`] predicts the memory and time of both from the mesh before anything is
//! allocated; [`plan`] picks the route and refuses a structure whose sparse estimate is above
//! [`MAX_SPARSE_BYTES`].

use std::io::Write;
use std::path::Path;

use anyhow::{bail, Context, Result};
use modal_rom::{mode_report, sparse_mode_report, BasisSettings, ModeReport, SparseSettings};
use multibody_constraints::Structure;
use plotters::prelude::*;

/// Largest dense memory (bytes) the modal basis may use: 4 GiB. A structure whose
/// [`estimate`] is above it is refused by the commands that need the whole dense basis
/// (`mpc`, `sweep`, `ocp`) before anything is allocated (a mesh of more than about 2,100
/// planar or 1,050 spatial elements in all).
pub const MAX_DENSE_BYTES: f64 = 4.0 * 1024.0 * 1024.0 * 1024.0;

/// Largest memory (bytes) the sparse route of `modes` may use: 4 GiB.
pub const MAX_SPARSE_BYTES: f64 = 4.0 * 1024.0 * 1024.0 * 1024.0;

/// `modes` takes the dense route up to this many node unknowns `n1` (a planar mesh of about
/// 400 elements, a spatial one of about 200; the dense route then takes about a second), the
/// sparse route above.
pub const DENSE_ROUTE_MAX_N1: usize = 1200;

/// Seconds per `n1³` (cubed node unknowns) of the dense modal computation, measured on one
/// core of the development machine (a planar two-link of 2 × 300 elements, `n1 = 1806`, took
/// 3.2 s and 380 MB; 2 × 600 elements, estimated 28 s and 1.3 GB, took 37 s and 1.4 GB on a
/// loaded machine).
const SECONDS_PER_N3: f64 = 6e-10;

/// Bytes per unknown of the saddle-point system (`n1 + n2 + constraint rows`) for the
/// structure, its sparse LU factors, pattern, work vectors and report: measured peak resident
/// memory of `flexmpc modes` on planar two-links of 2 × 5000 and 2 × 50,000 elements is
/// 1.0–1.1 KB per unknown, Krylov basis included (`docs/performance.md`); the estimate adds
/// the Krylov basis at its largest size, so it is an upper bound.
const SPARSE_BYTES_PER_UNKNOWN: f64 = 1000.0;

/// Seconds per unknown of the saddle-point system and Lanczos step of the sparse route on one
/// core (2 × 5000 elements: 0.65 s CPU; 2 × 50,000: 12 s CPU with plots and two shifts, about
/// 280 steps in all).
const SPARSE_SECONDS_PER_UNKNOWN_STEP: f64 = 7e-8;

/// Lanczos steps in all (components and shifts) the time estimate assumes.
const SPARSE_TYPICAL_STEPS: f64 = 300.0;

/// Which computation `modes` runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Route {
    /// Dense SVDs on the whole problem: every mode.
    Dense,
    /// Shift-invert Lanczos on the sparse pencil: the lowest modes.
    Sparse,
}

/// An estimate, from the mesh alone, of what the modal computation costs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveEstimate {
    /// Node unknowns `n1 = k Σ (N_b + 1)` (the velocity block `B1` is `n1 × n1`).
    pub n1: usize,
    /// Element unknowns `n2 = k Σ N_b`.
    pub n2: usize,
    /// Constraint rows (joints and supports).
    pub constraint_rows: usize,
    /// Peak dense memory (bytes): the dense blocks `B1`, damping (`n1²` each), `B2` (`n2²`),
    /// `D`, `Dᵀ` (`n1 n2` each), and eight `nz × nz` work matrices of the SVDs on the
    /// constrained space, `nz = n1 − constraint rows`; 8 bytes per entry.
    pub bytes: f64,
    /// Expected wall time (s) of the dense route on one core: `SECONDS_PER_N3 · n1³`.
    pub seconds: f64,
    /// Peak memory (bytes) of the sparse route: the saddle-point system and its LU factors
    /// (`SPARSE_BYTES_PER_UNKNOWN` per unknown) and the Krylov basis (`n1 × max_steps`
    /// doubles, its largest size).
    pub sparse_bytes: f64,
    /// Expected time (s) of the sparse route on one core, for 300 Lanczos steps in all
    /// (two components, two shifts each).
    pub sparse_seconds: f64,
}

/// Memory and time of the modal basis of `structure`, from its mesh and constraint count.
pub fn estimate(structure: &Structure) -> SolveEstimate {
    let k = structure.k();
    let elements: usize = structure.beams().iter().map(|b| b.beam.n_elements()).sum();
    let n1 = k * (elements + structure.beams().len());
    let n2 = k * elements;
    let constraint_rows = structure.joints().iter().map(|j| j.n_rows).sum::<usize>();
    let nz = n1.saturating_sub(constraint_rows) as f64;
    let (a, b) = (n1 as f64, n2 as f64);
    let bytes = 8.0 * (2.0 * a * a + b * b + 2.0 * a * b + 8.0 * nz * nz);
    let unknowns = a + b + constraint_rows as f64;
    let steps = SparseSettings::default().max_steps as f64;
    SolveEstimate {
        n1,
        n2,
        constraint_rows,
        bytes,
        seconds: SECONDS_PER_N3 * a * a * a,
        sparse_bytes: SPARSE_BYTES_PER_UNKNOWN * unknowns + 8.0 * a * steps,
        sparse_seconds: SPARSE_SECONDS_PER_UNKNOWN_STEP * unknowns * SPARSE_TYPICAL_STEPS,
    }
}

impl SolveEstimate {
    /// The route `modes` takes: dense up to [`DENSE_ROUTE_MAX_N1`] node unknowns.
    pub fn route(&self) -> Route {
        if self.n1 <= DENSE_ROUTE_MAX_N1 && self.bytes <= MAX_DENSE_BYTES {
            Route::Dense
        } else {
            Route::Sparse
        }
    }
}

/// `bytes` as `12.3 GB` / `456 MB`.
pub fn human_bytes(bytes: f64) -> String {
    if bytes >= 1e9 {
        format!("{:.1} GB", bytes / 1e9)
    } else {
        format!("{:.0} MB", bytes / 1e6)
    }
}

/// `s` seconds as `under a second`, `12 s`, `3.4 min`, `5.6 h`.
pub fn human_seconds(s: f64) -> String {
    if s < 1.0 {
        "under a second".into()
    } else if s < 120.0 {
        format!("{s:.0} s")
    } else if s < 7200.0 {
        format!("{:.1} min", s / 60.0)
    } else {
        format!("{:.1} h", s / 3600.0)
    }
}

fn elements(structure: &Structure) -> usize {
    structure.beams().iter().map(|b| b.beam.n_elements()).sum()
}

/// The [`estimate`] of `structure`, or an error naming the estimate and the cap
/// [`MAX_DENSE_BYTES`] when the dense modal basis (`mpc`, `sweep`, `ocp`) is above the cap.
pub fn check_size(structure: &Structure) -> Result<SolveEstimate> {
    let e = estimate(structure);
    if e.bytes > MAX_DENSE_BYTES {
        bail!(
            "the modal basis of this structure ({} elements, {} node unknowns, {} \
             constraint rows) is a dense computation that would need about {} of memory and \
             {} on one core; the cap is {} (flexmpc::modes::MAX_DENSE_BYTES): use fewer \
             `elements` per beam (the modes converge with a few dozen per link)",
            elements(structure),
            e.n1,
            e.constraint_rows,
            human_bytes(e.bytes),
            human_seconds(e.seconds),
            human_bytes(MAX_DENSE_BYTES)
        );
    }
    Ok(e)
}

/// The [`estimate`] of `structure` and the route `modes` takes, or an error naming the sparse
/// estimate and the cap [`MAX_SPARSE_BYTES`] when even the sparse route is above it.
pub fn plan(structure: &Structure) -> Result<(SolveEstimate, Route)> {
    plan_of(estimate(structure), elements(structure))
}

/// [`plan`] from an estimate and the element count.
pub fn plan_of(e: SolveEstimate, elements: usize) -> Result<(SolveEstimate, Route)> {
    let route = e.route();
    if route == Route::Sparse && e.sparse_bytes > MAX_SPARSE_BYTES {
        bail!(
            "the lowest modes of this structure ({} elements, {} node unknowns, {} constraint \
             rows) need the sparse eigen route, which would need about {} of memory and {} on \
             one core; the cap is {} (flexmpc::modes::MAX_SPARSE_BYTES): use fewer `elements` \
             per beam (the modes converge with a few dozen per link)",
            elements,
            e.n1,
            e.constraint_rows,
            human_bytes(e.sparse_bytes),
            human_seconds(e.sparse_seconds),
            human_bytes(MAX_SPARSE_BYTES)
        );
    }
    Ok((e, route))
}

/// The first `n_modes` modes of `structure` (fewer if the structure has fewer), after
/// [`plan`], without a progress indicator.
pub fn report(structure: &Structure, n_modes: usize) -> Result<ModeReport> {
    report_with_progress(structure, n_modes, false)
}

/// [`report`] with a progress spinner unless `quiet` (shown on a terminal only, for solves
/// expected to take more than a second).
pub fn report_with_progress(
    structure: &Structure,
    n_modes: usize,
    quiet: bool,
) -> Result<ModeReport> {
    let (est, route) = plan(structure)?;
    let (seconds, bytes, what) = match route {
        Route::Dense => (est.seconds, est.bytes, "dense eigenproblem"),
        Route::Sparse => (est.sparse_seconds, est.sparse_bytes, "sparse Lanczos eigenproblem"),
    };
    let bar = crate::progress::progress_bar(
        None,
        quiet || seconds < 1.0,
        &format!(
            "modes: {what} of {} unknowns (about {}, {})",
            est.n1,
            human_seconds(seconds),
            human_bytes(bytes)
        ),
    );
    let settings = BasisSettings::default();
    let r = match route {
        Route::Sparse => {
            sparse_mode_report(structure, n_modes, &settings, &SparseSettings::default())
                .map_err(anyhow::Error::from)
        }
        // Ask for what exists: the basis knows its size only once solved.
        Route::Dense => match mode_report(structure, n_modes, &settings) {
            Ok(r) => Ok(r),
            Err(first) => {
                let all = modal_rom::StructureModel::new(structure)?.modes(&settings)?;
                if n_modes > all.n_modes() && all.n_modes() > 0 {
                    Ok(modal_rom::report_of(&all, all.n_modes())?)
                } else {
                    Err(first.into())
                }
            }
        },
    };
    bar.finish_and_clear();
    r
}

/// Writes the frequency table to `w`.
pub fn print_table(w: &mut impl Write, report: &ModeReport) -> std::io::Result<()> {
    writeln!(w, "{:>4}  {:>14}  {:>10}  label", "mode", "ω (rad/s)", "f (Hz)")?;
    for (i, (f, l)) in report.frequencies_rad_s.iter().zip(&report.labels).enumerate() {
        writeln!(w, "{:>4}  {:>14.6}  {:>10.5}  {}", i + 1, f, f / std::f64::consts::TAU, l)?;
    }
    Ok(())
}

/// Writes `components.svg` (Fig. 4: each velocity component of each elastic mode along the
/// arc length, beams one after the other) and `shapes.svg` (Fig. 5: translational velocity
/// mode shapes superimposed on the reference configuration, in the e1–e3 plane; spatial
/// structures also in the e1–e2 plane).
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
        let root = SVGBackend::new(&fig4, (1100, 280 * k.max(1) as u32)).into_drawing_area();
        root.fill(&WHITE)?;
        let entries: Vec<(String, RGBColor, bool)> = shapes
            .iter()
            .enumerate()
            .map(|(j, m)| {
                (
                    format!("mode {} ({}, {:.3} rad/s)", m.index + 1, m.label, m.frequency_rad_s),
                    palette[j % palette.len()],
                    false,
                )
            })
            .collect();
        let plot_area = crate::plot::with_legend(&root, &entries)?;
        let panels = plot_area.split_evenly((k.max(1), 1));
        for (c, panel) in panels.iter().enumerate() {
            let mut series: Vec<Vec<(f64, f64)>> = Vec::new();
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
                series.push(pts);
            }
            if hi.partial_cmp(&lo) != Some(std::cmp::Ordering::Greater) {
                hi = lo + 1.0;
            }
            let pad = 0.05 * (hi - lo);
            let name = names.get(c).copied().unwrap_or("?");
            let mut chart = ChartBuilder::on(panel)
                .caption(format!("φ_{name}"), ("sans-serif", crate::plot::AXIS_FONT))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(70)
                .build_cartesian_2d(0.0..s_max.max(1e-12), (lo - pad)..(hi + pad))?;
            chart
                .configure_mesh()
                .x_desc("s along the beams (m)")
                .y_desc(format!("φ_{name} (B1-normalised)"))
                .label_style(("sans-serif", crate::plot::TICK_FONT))
                .axis_desc_style(("sans-serif", crate::plot::TICK_FONT))
                .x_labels(8)
                .y_labels(5)
                .y_label_formatter(&|v| crate::plot::short(*v))
                .draw()?;
            for (j, pts) in series.into_iter().enumerate() {
                let color = palette[j % palette.len()];
                for segment in pts.split(|p| p.0.is_nan()) {
                    chart.draw_series(LineSeries::new(
                        segment.iter().copied(),
                        color.stroke_width(2),
                    ))?;
                }
            }
        }
        root.present()?;
    }

    // Fig. 5: reference configuration (thick black) plus the global translational velocity,
    // in the x–z plane (planar) or in the x–y and x–z planes (spatial, one row each).
    let fig5 = dir.join("shapes.svg");
    {
        let n = shapes.len().max(1);
        let planes: &[(usize, usize)] = if k == 3 { &[(0, 2)] } else { &[(0, 1), (0, 2)] };
        let root =
            SVGBackend::new(&fig5, (300 * n as u32, 320 * planes.len() as u32)).into_drawing_area();
        root.fill(&WHITE)?;
        let panels = root.split_evenly((planes.len(), n));
        let axis = ["x (m)", "y (m)", "z (m)"];
        for (row, &(a, b)) in planes.iter().enumerate() {
            for (col, m) in shapes.iter().enumerate() {
                let panel = &panels[row * n + col];
                let vmax = m
                    .beams
                    .iter()
                    .flat_map(|b| b.velocity_global.iter())
                    .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
                    .fold(0.0_f64, f64::max)
                    .max(1e-300);
                let span = m
                    .beams
                    .iter()
                    .map(|b| b.s.last().copied().unwrap_or(0.0))
                    .sum::<f64>()
                    .max(1e-12);
                let scale = 0.25 * span / vmax;
                let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
                for bm in &m.beams {
                    for (r, v) in bm.reference.iter().zip(&bm.velocity_global) {
                        for p in [(r[a], r[b]), (r[a] + scale * v[a], r[b] + scale * v[b])] {
                            lo = [lo[0].min(p.0), lo[1].min(p.1)];
                            hi = [hi[0].max(p.0), hi[1].max(p.1)];
                        }
                    }
                }
                let w = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-12) * 0.55;
                let (cx, cz) = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]));
                let mut chart = ChartBuilder::on(panel)
                    .caption(
                        format!(
                            "mode {}: {} ({:.3} rad/s)",
                            m.index + 1,
                            m.label,
                            m.frequency_rad_s
                        ),
                        ("sans-serif", 13),
                    )
                    .margin(8)
                    .x_label_area_size(36)
                    .y_label_area_size(50)
                    .build_cartesian_2d((cx - w)..(cx + w), (cz - w)..(cz + w))?;
                chart
                    .configure_mesh()
                    .x_desc(axis[a])
                    .y_desc(axis[b])
                    .label_style(("sans-serif", 13))
                    .x_labels(4)
                    .y_labels(4)
                    .x_label_formatter(&|v| crate::plot::short(*v))
                    .y_label_formatter(&|v| crate::plot::short(*v))
                    .draw()?;
                for bm in &m.beams {
                    chart.draw_series(LineSeries::new(
                        bm.reference.iter().map(|r| (r[a], r[b])),
                        BLACK.stroke_width(4),
                    ))?;
                    chart.draw_series(LineSeries::new(
                        bm.reference
                            .iter()
                            .zip(&bm.velocity_global)
                            .map(|(r, v)| (r[a] + scale * v[a], r[b] + scale * v[b])),
                        RED.stroke_width(2),
                    ))?;
                }
            }
        }
        root.present()?;
    }
    Ok(vec![fig4, fig5])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planar(elements: usize, beams: usize) -> SolveEstimate {
        let k = 3;
        let n1 = k * (elements + beams);
        let n2 = k * elements;
        let (a, b, r) = (n1 as f64, n2 as f64, 4.0);
        SolveEstimate {
            n1,
            n2,
            constraint_rows: 4,
            bytes: 8.0 * (2.0 * a * a + b * b + 2.0 * a * b + 8.0 * (a - r) * (a - r)),
            seconds: SECONDS_PER_N3 * a * a * a,
            sparse_bytes: SPARSE_BYTES_PER_UNKNOWN * (a + b + r)
                + 8.0 * a * SparseSettings::default().max_steps as f64,
            sparse_seconds: SPARSE_SECONDS_PER_UNKNOWN_STEP * (a + b + r) * SPARSE_TYPICAL_STEPS,
        }
    }

    /// Shipped meshes stay on the dense route; large ones take the sparse route; a mesh
    /// beyond even the sparse cap is refused with the estimate and the cap in the message.
    #[test]
    fn routes_and_refusal() {
        assert_eq!(planar(100, 2).route(), Route::Dense);
        assert_eq!(planar(4000, 2).route(), Route::Sparse);
        let (e, route) = plan_of(planar(200_000, 2), 200_000).unwrap();
        assert_eq!(route, Route::Sparse);
        assert!(e.sparse_bytes < MAX_SPARSE_BYTES && e.bytes > 1e12);
        let err = plan_of(planar(2_000_000, 20), 2_000_000).unwrap_err().to_string();
        assert!(err.contains("2000000 elements"), "{err}");
        assert!(err.contains("the cap is 4.3 GB"), "{err}");
        assert!(err.contains("MAX_SPARSE_BYTES"), "{err}");
    }
}
