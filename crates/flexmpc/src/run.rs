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
    let (mut csv, csv_path, cols) = start_csv(&scene, out)?;
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
    let seconds = start.elapsed().as_secs_f64();
    let plot = finish(csv, &csv_path, &scene, out, &scene.title, &cols, &table)?;
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

/// Runs a scene's reduced model open loop (`flexmpc simulate --plant rom`): the paper's model
/// (mode set of `[modes]`, else the paper's 2D/3D set) or the exact-joints model, from the
/// scene's initial FE state projected onto it, under the scene's follower loads and joint
/// torques (the modal input columns times their histories), each step one implicit-midpoint
/// step of `[run] dt`. Writes `<out>/timeseries.csv` with the FE run's columns (angles in the
/// FE plant's convention, beam ends rebuilt from the model's fields, energy `½|q1|² + ½|q2|²`;
/// the reaction columns are NaN: the model has none) and the plot. Gravity and dead loads
/// are refused (the modal models carry follower loads only).
pub fn simulate_model(
    scene: Scene,
    out: &Path,
    quiet: bool,
    model: mpc::ModelKind,
) -> Result<RunSummary> {
    use intrinsic_beam::LoadFrame;
    let plant = scene.plant()?;
    if plant.gravity().norm() > 0.0 {
        anyhow::bail!(
            "{}: --plant rom: the reduced models carry no gravity; remove `gravity` or simulate the FE plant",
            scene.file.display()
        );
    }
    // per input: unit load (follower) or unit torque, and its history; the model's inputs are
    // the non-zero loads and the torques (`active`)
    let mut histories: Vec<Box<dyn Fn(f64) -> f64>> = Vec::new();
    let mut active = Vec::new();
    for (k, i) in scene.inputs.iter().enumerate() {
        match &i.kind {
            InputKind::Load { beam, index } => {
                let l = plant.loads(*beam).point[*index].clone();
                if l.frame != LoadFrame::Follower && l.value.norm() > 0.0 {
                    anyhow::bail!(
                        "{}: --plant rom: load `{}` is a dead (global-frame) load; the reduced \
                         models carry follower loads only",
                        scene.file.display(),
                        i.name
                    );
                }
                if l.value.norm() > 0.0 {
                    active.push(k);
                }
                histories.push(Box::new(move |t| l.amplitude.at(t)));
            }
            InputKind::Torque { value, amplitude, .. } => {
                let (v, a) = (*value, amplitude.clone());
                active.push(k);
                histories.push(Box::new(move |t| v * a.at(t)));
            }
        }
    }
    let selection = match &scene.control {
        Some(c) => c.scenario.selection.clone(),
        None => match scene.structure.components() {
            intrinsic_beam::Components::Planar => modal_rom::samples::paper_2d_selection(),
            intrinsic_beam::Components::Spatial => modal_rom::samples::paper_3d_selection(),
        },
    };
    let elastic = scene.control.as_ref().and_then(|c| c.controller.link_elastic_modes);
    let inputs = |structure: &multibody_constraints::Structure, m: &modal_rom::StructureModel| {
        active
            .iter()
            .map(|&k| (&scene.inputs[k], k))
            .map(|(i, _)| match &i.kind {
                InputKind::Load { beam, index } => {
                    let l = &plant.loads(*beam).point[*index];
                    let v = l.value;
                    modal_rom::Input::point(
                        &m.layout,
                        &i.name,
                        *beam,
                        l.node,
                        [v[0], v[1], v[2], v[3], v[4], v[5]],
                    )
                    .map_err(mpc::MpcError::from)
                }
                InputKind::Torque { joint, axis, .. } => {
                    m.joint_torque(structure, &i.name, joint, *axis).map_err(mpc::MpcError::from)
                }
            })
            .collect::<mpc::Result<Vec<_>>>()
    };
    let mut rom = mpc::ModalPlant::new(
        model,
        &scene.structure,
        &selection,
        elastic,
        inputs,
        plant.state(),
        plant.kinematics(),
    )
    .with_context(|| format!("reduced model of {}", scene.file.display()))?;
    let (mut csv, csv_path, cols) = start_csv(&scene, out)?;
    let n_reactions = 6 * scene.structure.joints().iter().filter(|j| j.ground).count();
    let row = |rom: &mpc::ModalPlant, iterations: usize| -> Result<Vec<f64>> {
        let kin = rom.kinematics()?;
        let e = rom.energy();
        let mut r = vec![rom.time(), e, 0.0, e, iterations as f64];
        r.extend(rom.joint_angles(&kin));
        for k in &kin {
            for x in [k.r[0], k.r[k.r.len() - 1]] {
                r.extend_from_slice(&[x.x, x.y, x.z]);
            }
        }
        r.extend(std::iter::repeat_n(f64::NAN, n_reactions));
        for (i, h) in scene.inputs.iter().zip(&histories) {
            r.push(match &i.kind {
                InputKind::Load { beam, index } => {
                    plant.loads(*beam).point[*index].value.norm() * h(rom.time())
                }
                InputKind::Torque { .. } => h(rom.time()),
            });
        }
        Ok(r)
    };
    let mut table = Vec::new();
    let first = row(&rom, 0)?;
    let total0 = first[3];
    csv.write_record(fmt_row(&first))?;
    table.push(first);
    let bar = if quiet { ProgressBar::hidden() } else { ProgressBar::new(scene.steps as u64) };
    let start = std::time::Instant::now();
    let (dt, mut iterations, mut total_end) = (scene.plant_settings.dt, 0, total0);
    for step in 1..=scene.steps {
        let t_mid = rom.time() + 0.5 * dt;
        let u: Vec<f64> = active.iter().map(|&k| histories[k](t_mid)).collect();
        iterations += rom.step(&u, dt).with_context(|| format!("reduced model, step {step}"))?;
        if step % scene.output_every == 0 || step == scene.steps {
            let rw = row(&rom, iterations)?;
            iterations = 0;
            total_end = rw[3];
            csv.write_record(fmt_row(&rw))?;
            table.push(rw);
            bar.set_position(step as u64);
        }
    }
    bar.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    let title = format!("{} ({} model)", scene.title, model.name());
    let plot = finish(csv, &csv_path, &scene, out, &title, &cols, &table)?;
    Ok(RunSummary {
        csv: csv_path,
        plot,
        vtk: None,
        steps: scene.steps,
        seconds,
        total_energy: (total0, total_end),
        velocity_violation: 0.0,
    })
}

/// Creates `out` and `<out>/timeseries.csv` with the scene's header row: the writer, its
/// path and the column names.
fn start_csv(
    scene: &Scene,
    out: &Path,
) -> Result<(csv::Writer<std::fs::File>, PathBuf, Vec<String>)> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let csv_path = out.join("timeseries.csv");
    let mut csv = csv::Writer::from_path(&csv_path)
        .with_context(|| format!("creating {}", csv_path.display()))?;
    let cols = columns(scene);
    csv.write_record(&cols)?;
    Ok((csv, csv_path, cols))
}

/// Flushes a run's `timeseries.csv` and writes `<out>/plot.svg` of the scene's `[output] plot`
/// columns (`None` when it names none).
fn finish(
    mut csv: csv::Writer<std::fs::File>,
    csv_path: &Path,
    scene: &Scene,
    out: &Path,
    title: &str,
    cols: &[String],
    table: &[Vec<f64>],
) -> Result<Option<PathBuf>> {
    csv.flush().with_context(|| format!("writing {}", csv_path.display()))?;
    if scene.plot.is_empty() {
        return Ok(None);
    }
    let path = out.join("plot.svg");
    crate::plot::time_series(&path, title, cols, table, &scene.plot)?;
    Ok(Some(path))
}

fn fmt_row(r: &[f64]) -> Vec<String> {
    r.iter().map(|v| format!("{v:.10e}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
        let mut r = csv::Reader::from_path(path).unwrap();
        let cols = r.headers().unwrap().iter().map(String::from).collect();
        let rows = r
            .records()
            .map(|x| x.unwrap().iter().map(|v| v.parse::<f64>().unwrap()).collect())
            .collect();
        (cols, rows)
    }

    /// `simulate --plant rom`: the FE run's columns, and over 1 s of the paper's 2D spin
    /// (ω0 = 1, 2×8 elements) the exact-joints model's root and elbow angles within 1e-2 rad
    /// of the FE plant's (the root turns by 1 rad), its energy within 1e-3 relative.
    #[test]
    fn reduced_model_matches_the_fe_columns_and_angles() {
        let text = include_str!("../../../scenes/paper-2d.toml")
            .replace("elements = 50", "elements = 8")
            .replace("duration = 7.5", "duration = 1.0");
        let file = Path::new("paper-2d.toml");
        let dir = std::env::temp_dir().join(format!("flexmpc-rom-sim-{}", std::process::id()));
        let fe = simulate(crate::scene::load_str(file, &text).unwrap(), &dir.join("fe"), true);
        fe.unwrap();
        let rom = simulate_model(
            crate::scene::load_str(file, &text).unwrap(),
            &dir.join("rom"),
            true,
            mpc::ModelKind::ExactJoints,
        )
        .unwrap();
        let (cf, tf) = table(&dir.join("fe").join("timeseries.csv"));
        let (cr, tr) = table(&rom.csv);
        assert_eq!(cf, cr);
        assert_eq!(tf.len(), tr.len());
        let col = |n: &str| cf.iter().position(|c| c == n).unwrap();
        let (elbow, root, energy) = (col("angle:elbow"), col("angle:root"), col("energy"));
        let mut worst = 0.0f64;
        for (a, b) in tf.iter().zip(&tr) {
            assert!((a[0] - b[0]).abs() < 1e-12);
            worst = worst.max((a[elbow] - b[elbow]).abs()).max((a[root] - b[root]).abs());
            assert!(
                (a[energy] - b[energy]).abs() <= 1e-3 * a[energy],
                "{} vs {}",
                a[energy],
                b[energy]
            );
        }
        let turned = tf.last().unwrap()[root];
        assert!(turned > 0.9, "the root turns by ω0 t = 1 rad, got {turned}");
        assert!(worst < 1e-2, "joint angles of the model vs FE: {worst:e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
