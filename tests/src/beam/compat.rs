//! Compatibility of the integrated kinematics with the strains (theory.md §2, "Kinematics"):
//! node quaternions and positions are integrated in time node by node (eqs. 7, 10 in `t`);
//! the strains say how neighbouring nodes must sit (eqs. 7, 10 in `s`). These measures compare
//! the two, element by element.

use intrinsic_beam::operators::halves;
use intrinsic_beam::rotation::{quat_conj, quat_mul, quaternion_step, rotation, rotation_angle};
use intrinsic_beam::{Beam, Kinematics};
use nalgebra::Vector3;

/// Per-beam (or worst over beams) compatibility measures of integrated kinematics.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Compatibility {
    /// Largest rotation angle (rad) between `ξ_{e+1}` and `exp(h U(κ + κ0)) ξ_e`.
    pub rotation: f64,
    /// Largest `|r_{e+1} − r_e − h T(ξ_{e+½})(e1 + γ)| / h`, `ξ_{e+½} = exp(h/2 U(κ + κ0)) ξ_e`.
    pub chord: f64,
    /// Largest `1 − cos` of the angle between the element's midpoint axis `T(ξ_{e+½}) e1` and
    /// its chord.
    pub mid_axis_chord: f64,
    /// Largest `1 − cos` of the angle between a node's axis `T(ξ_n) e1` and the chord of an
    /// element it belongs to (contains the geometric `h |κ|/2` turn over half an element).
    pub node_axis_chord: f64,
    /// Largest `|ê2 · chord|` with `ê2` the normalised mean of the two nodes' `T e2` (the
    /// VTK ribbon test's measure).
    pub e2_chord: f64,
    /// Largest shear strain `|(γ2, γ3)|`: what `mid_axis_chord` would be (as an angle) if the
    /// kinematics were compatible.
    pub shear: f64,
    /// Largest `h |κ + κ0|` over the elements (the turn of an element).
    pub turn: f64,
}

impl Compatibility {
    /// The worst of two.
    pub fn max(self, o: Self) -> Self {
        Self {
            rotation: self.rotation.max(o.rotation),
            chord: self.chord.max(o.chord),
            mid_axis_chord: self.mid_axis_chord.max(o.mid_axis_chord),
            node_axis_chord: self.node_axis_chord.max(o.node_axis_chord),
            e2_chord: self.e2_chord.max(o.e2_chord),
            shear: self.shear.max(o.shear),
            turn: self.turn.max(o.turn),
        }
    }
}

/// The measures of `kin` against the strains of `state` on `beam`.
pub fn compatibility(beam: &Beam, state: &[f64], kin: &Kinematics) -> Compatibility {
    let c = &beam.section().compliance;
    let kappa0 = beam.section().kappa0;
    let mut out = Compatibility::default();
    let one_minus_cos = |a: &Vector3<f64>, b: &Vector3<f64>| 1.0 - a.dot(b) / (a.norm() * b.norm());
    for (e, &h) in beam.mesh().lengths().iter().enumerate() {
        let (gamma, kappa) = halves(&(c * beam.x2(state, e)));
        let curv = kappa + kappa0;
        let (xa, xb) = (kin.xi[e], kin.xi[e + 1]);
        let predicted = quaternion_step(&xa, &curv, h);
        out.rotation = out.rotation.max(rotation_angle(&quat_mul(&quat_conj(&predicted), &xb)));
        let t_mid = rotation(&quaternion_step(&xa, &curv, 0.5 * h));
        let chord = kin.r[e + 1] - kin.r[e];
        let strain_chord = t_mid * (Vector3::x() + gamma) * h;
        out.chord = out.chord.max((chord - strain_chord).norm() / h);
        out.mid_axis_chord = out.mid_axis_chord.max(one_minus_cos(&(t_mid * Vector3::x()), &chord));
        for x in [xa, xb] {
            out.node_axis_chord =
                out.node_axis_chord.max(one_minus_cos(&(rotation(&x) * Vector3::x()), &chord));
        }
        let e2 = rotation(&xa) * Vector3::y() + rotation(&xb) * Vector3::y();
        out.e2_chord = out.e2_chord.max((e2.dot(&chord) / (e2.norm() * chord.norm())).abs());
        out.shear = out.shear.max(gamma.yz().norm());
        out.turn = out.turn.max(h * curv.norm());
    }
    out
}

/// Outcome of [`two_link_run`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CompatibilityRun {
    /// Worst measures over both links and the sampled times.
    pub worst: Compatibility,
    /// Tip of link 2 integrated in time.
    pub tip_time: Vector3<f64>,
    /// Tip of link 2 rebuilt in space from the strains (link 1 from its integrated root node,
    /// link 2 from its integrated start quaternion and link 1's rebuilt end).
    pub tip_space: Vector3<f64>,
}

/// The paper's 3D two-link (`paper-3d` section, universal joints, `n` elements per link),
/// launched in the rigid spin `ω0 = (0, 1, 1)` rad/s with follower bending moments
/// `(0, −1.2, −1.4)` at the root and a follower force `(0, −1.25, 1.0)` at the tip held on
/// (the first input of the 3D closed loop at ω0 = 1), `dt` steps to `t_end`; the measures
/// are sampled every `t_end / 10`.
pub fn two_link_run(
    n: usize,
    dt: f64,
    t_end: f64,
) -> multibody_constraints::Result<CompatibilityRun> {
    use intrinsic_beam::{LoadFrame, Loads, Section};
    use multibody_constraints::{samples, Plant, PlantSettings};
    use nalgebra::Vector6;
    let structure = samples::paper_3d(Section::paper_3d(), n, 0.0)?;
    let x = structure.rigid_rotation_state(Vector3::new(0.0, 1.0, 1.0), Vector3::zeros());
    let mut plant = Plant::new(structure, PlantSettings { dt, ..Default::default() })?;
    plant.set_state(&x)?;
    *plant.loads_mut(0) = Loads::none().with_point(
        0,
        LoadFrame::Follower,
        Vector6::new(0.0, 0.0, 0.0, 0.0, -1.2, -1.4),
    );
    *plant.loads_mut(1) = Loads::none().with_point(
        n,
        LoadFrame::Follower,
        Vector6::new(0.0, -1.25, 1.0, 0.0, 0.0, 0.0),
    );
    let steps = (t_end / dt).round() as usize;
    let every = (steps / 10).max(1);
    let mut out = CompatibilityRun::default();
    for s in 1..=steps {
        plant.step()?;
        if s % every == 0 || s == steps {
            for (b, sb) in plant.structure().beams().iter().enumerate() {
                let state = plant.structure().beam_slice(b, plant.state());
                out.worst = out.worst.max(compatibility(&sb.beam, state, &plant.kinematics()[b]));
            }
        }
    }
    let (kin, beams) = (plant.kinematics(), plant.structure().beams());
    let state = |b: usize| plant.structure().beam_slice(b, plant.state());
    let link1 = Kinematics::from_strains(&beams[0].beam, state(0), kin[0].xi[0], kin[0].r[0])?;
    let link2 = Kinematics::from_strains(&beams[1].beam, state(1), kin[1].xi[0], link1.r[n])?;
    out.tip_time = kin[1].r[n];
    out.tip_space = link2.r[n];
    Ok(out)
}
