//! Running a scene: stepping the plant, writing the CSV time series (through the `csv`
//! crate: a name with a comma or a quote is quoted, never splits a column), progress bar,
//! and with `--vtk` the deformed structure at every output step ([`crate::vtk`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use multibody_constraints::Plant;

use crate::scene::{InputKind, Scene};

/// What a run produced.
pub struct RunSummary {
    /// CSV file written.
    pub csv: PathBuf,
    /// Plot written (if the scene asked for one).
    pub plot: Option<PathBuf>,
    /// VTK collection written (`--vtk`).
    pub vtk: Option<PathBuf>,
    /// Steps taken.
    pub steps: usize,
    /// Wall time (s).
    pub seconds: f64,
    /// `energy + gravity potential` at the start and at the end (equal, to solver tolerance,
    /// for undamped scenes without other inputs).
    pub total_energy: (f64, f64),
    /// Largest velocity-constraint violation at a step midpoint.
    pub velocity_violation: f64,
}

/// Column names of the time series.
pub fn columns(scene: &Scene) -> Vec<String> {
    let s = &scene.structure;
    let mut c = vec![
        "t".to_string(),
        "energy".into(),
        "potential".into(),
        "total".into(),
        "newton_iterations".into(),
    ];
    for j in s.joints() {
        c.push(format!("angle:{}", j.name));
    }
    for b in s.beams() {
        for e in ["start", "end"] {
            for x in ["x", "y", "z"] {
                c.push(format!("{}.{e}.{x}", b.name));
            }
        }
    }
    for j in s.joints().iter().filter(|j| j.ground) {
        for x in ["fx", "fy", "fz", "mx", "my", "mz"] {
            c.push(format!("reaction:{}.{x}", j.name));
        }
    }
    for i in &scene.inputs {
        c.push(format!("input:{}", i.name));
    }
    c
}

fn row(scene: &Scene, p: &Plant, iterations: usize) -> Vec<f64> {
    let s = p.structure();
    let (e, v) = (p.energy(), p.potential_energy());
    let mut r = vec![p.time(), e, v, e + v, iterations as f64];
    r.extend_from_slice(p.joint_angles());
    for (b, sb) in s.beams().iter().enumerate() {
        for n in [0, sb.beam.n_elements()] {
            let x = p.position(b, n);
            r.extend_from_slice(&[x.x, x.y, x.z]);
        }
    }
    for (ji, _) in s.joints().iter().enumerate().filter(|(_, j)| j.ground) {
        r.extend(p.reactions(ji)[0].iter());
    }
    for i in &scene.inputs {
        r.push(match &i.kind {
            InputKind::Load { beam, index } => {
                let l = &p.loads(*beam).point[*index];
                l.value.norm() * l.amplitude.at(p.time())
            }
            InputKind::Torque { value, amplitude, .. } => value * amplitude.at(p.time()),
        });
    }
    r
}

/// Runs a scene and writes `<out>/timeseries.csv` (and `plot.svg` if asked).
pub fn simulate(scene: Scene, out: &Path, quiet: bool) -> Result<RunSummary> {
    simulate_with(scene, out, quiet, false)
}

/// [`simulate`], and with `vtk` also `vtk/simulate-<k>.vtu` per output step and the
/// collection `vtk/simulate.pvd` ([`crate::vtk`]).
pub fn simulate_with(scene: Scene, out: &Path, quiet: bool, vtk: bool) -> Result<RunSummary> {
    let mut plant = scene.plant()?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("timeseries.csv");
    let mut csv = csv::Writer::from_path(&csv_path)
        .with_context(|| format!("creating {}", csv_path.display()))?;
    let cols = columns(&scene);
    csv.write_record(&cols)?;
    let mut table: Vec<Vec<f64>> = Vec::new();
    let mut frames =
        if vtk { Some(crate::vtk::Collection::new(&out.join("vtk"), "simulate")?) } else { None };
    let first = row(&scene, &plant, 0);
    let total0 = first[3];
    csv.write_record(fmt_row(&first))?;
    table.push(first);
    if let Some(c) = &mut frames {
        c.push(&crate::vtk::frame_of_plant(&plant))?;
    }
    let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new(scene.steps as u64) };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {bar:40} {pos}/{len} steps ({eta} left) {msg}",
        )
        .expect("valid template"),
    );
    let start = std::time::Instant::now();
    let mut total_end = total0;
    let mut vv = 0.0f64;
    let mut iterations = 0;
    for step in 1..=scene.steps {
        let t_mid = plant.time() + 0.5 * plant.settings().dt;
        for i in &scene.inputs {
            if let InputKind::Torque { joint, axis, value, amplitude } = &i.kind {
                plant.set_joint_torque(joint, *axis, value * amplitude.at(t_mid))?;
            }
        }
        let r = plant.step().with_context(|| format!("step {step} of {}", scene.file.display()))?;
        iterations += r.iterations;
        vv = vv.max(r.velocity_violation);
        if step % scene.output_every == 0 || step == scene.steps {
            let rw = row(&scene, &plant, iterations);
            iterations = 0;
            total_end = rw[3];
            csv.write_record(fmt_row(&rw))?;
            table.push(rw);
            if let Some(c) = &mut frames {
                c.push(&crate::vtk::frame_of_plant(&plant))?;
            }
            bar.set_position(step as u64);
        }
    }
    bar.finish_and_clear();
    csv.flush().with_context(|| format!("writing {}", csv_path.display()))?;
    let seconds = start.elapsed().as_secs_f64();
    let plot = if scene.plot.is_empty() {
        None
    } else {
        let path = out.join("plot.svg");
        crate::plot::time_series(&path, &scene.title, &cols, &table, &scene.plot)?;
        Some(path)
    };
    let vtk = frames.map(crate::vtk::Collection::finish).transpose()?;
    Ok(RunSummary {
        csv: csv_path,
        plot,
        vtk,
        steps: scene.steps,
        seconds,
        total_energy: (total0, total_end),
        velocity_violation: vv,
    })
}

fn fmt_row(r: &[f64]) -> Vec<String> {
    r.iter().map(|v| format!("{v:.10e}")).collect()
}
