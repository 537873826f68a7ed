//! Canonical structures (the paper's §5 two-links, Fig. 2's three-beam ball joint, an L-frame)
//! and the rigid double pendulum of uniform rods used as a reference for very stiff links.
//!
//! Values follow theory.md §9. All builders return validated structures.

use intrinsic_beam::{Beam, Components, Mesh, Section};
use nalgebra::Vector3;

use crate::error::Result;
use crate::joint::{End, EndRef, Joint, JointKind, Support};
use crate::structure::{Placement, Structure, StructureBeam, StructureSettings};

/// The paper's 2D hinged two-link (§5.1–5.2): two straight links of length 1 along global e1
/// (the second turned by `joint_angle` about e2 at the elbow), root hinge to the ground and an
/// elbow hinge, both about e2; planar components. Beams `link1`, `link2`; support `root`;
/// joint `elbow`.
pub fn paper_2d(section: Section, n_elements: usize, joint_angle: f64) -> Result<Structure> {
    hinged_two_link(section, n_elements, joint_angle, Components::Planar)
}

/// [`paper_2d`]'s hinged two-link on either kind of components (on spatial components the
/// hinges about e2 leave the same planar motion possible).
pub fn hinged_two_link(
    section: Section,
    n_elements: usize,
    joint_angle: f64,
    components: Components,
) -> Result<Structure> {
    two_link(
        section,
        n_elements,
        joint_angle,
        components,
        JointKind::hinge_global([0.0, 1.0, 0.0]),
        JointKind::hinge_on_first([0.0, 1.0, 0.0]),
    )
}

/// The paper's 3D two-link (§5.3): as [`paper_2d`] but spatial, with universal (wheel) joints
/// at the root and the elbow.
pub fn paper_3d(section: Section, n_elements: usize, joint_angle: f64) -> Result<Structure> {
    two_link(
        section,
        n_elements,
        joint_angle,
        Components::Spatial,
        JointKind::Universal,
        JointKind::Universal,
    )
}

fn two_link(
    section: Section,
    n_elements: usize,
    joint_angle: f64,
    components: Components,
    root: JointKind,
    elbow: JointKind,
) -> Result<Structure> {
    let beam = Beam::new(section, Mesh::uniform(1.0, n_elements)?, components)?;
    Structure::new(
        vec![
            StructureBeam::new("link1", beam.clone(), Placement::origin()),
            StructureBeam::new(
                "link2",
                beam,
                Placement::Attached {
                    joint: "elbow".into(),
                    axis: [0.0, 1.0, 0.0],
                    angle: joint_angle,
                },
            ),
        ],
        vec![Joint {
            name: "elbow".into(),
            ends: vec![EndRef::new("link1", End::End), EndRef::new("link2", End::Start)],
            kind: elbow,
        }],
        vec![Support { name: "root".into(), end: EndRef::new("link1", End::Start), kind: root }],
        StructureSettings::default(),
    )
}

/// A planar double pendulum of two hinged links of length 1 hanging under gravity along −e3:
/// link 1 at `theta1`, link 2 at `theta2` from the downward vertical (positive towards +e1).
pub fn hanging_two_link(
    section: Section,
    n_elements: usize,
    theta1: f64,
    theta2: f64,
) -> Result<Structure> {
    let beam = Beam::new(section, Mesh::uniform(1.0, n_elements)?, Components::Planar)?;
    // A rotation by φ about e2 turns e1 into (cos φ, 0, −sin φ); hanging at θ needs φ = π/2 − θ.
    let phi = std::f64::consts::FRAC_PI_2 - theta1;
    Structure::new(
        vec![
            StructureBeam::new(
                "link1",
                beam.clone(),
                Placement::at([0.0; 3], [0.0, 1.0, 0.0], phi),
            ),
            StructureBeam::new(
                "link2",
                beam,
                Placement::Attached {
                    joint: "elbow".into(),
                    axis: [0.0, 1.0, 0.0],
                    angle: theta1 - theta2,
                },
            ),
        ],
        vec![Joint {
            name: "elbow".into(),
            ends: vec![EndRef::new("link1", End::End), EndRef::new("link2", End::Start)],
            kind: JointKind::hinge_on_first([0.0, 1.0, 0.0]),
        }],
        vec![Support {
            name: "root".into(),
            end: EndRef::new("link1", End::Start),
            kind: JointKind::hinge_global([0.0, 1.0, 0.0]),
        }],
        StructureSettings::default(),
    )
}

/// Fig. 2: beam `a` (clamped at its start, along e1) ends at a ball joint where beams `b`
/// (turned 60° about e3) and `c` (turned −50° about e2, out of plane) start; spatial.
pub fn ball_joint_3(section: Section, n_elements: usize) -> Result<Structure> {
    let beam = Beam::new(section, Mesh::uniform(1.0, n_elements)?, Components::Spatial)?;
    Structure::new(
        vec![
            StructureBeam::new("a", beam.clone(), Placement::origin()),
            StructureBeam::new(
                "b",
                beam.clone(),
                Placement::Attached {
                    joint: "ball".into(),
                    axis: [0.0, 0.0, 1.0],
                    angle: 60f64.to_radians(),
                },
            ),
            StructureBeam::new(
                "c",
                beam,
                Placement::Attached {
                    joint: "ball".into(),
                    axis: [0.0, 1.0, 0.0],
                    angle: -50f64.to_radians(),
                },
            ),
        ],
        vec![Joint {
            name: "ball".into(),
            ends: vec![
                EndRef::new("a", End::End),
                EndRef::new("b", End::Start),
                EndRef::new("c", End::Start),
            ],
            kind: JointKind::Ball,
        }],
        vec![Support {
            name: "clamp".into(),
            end: EndRef::new("a", End::Start),
            kind: JointKind::Weld,
        }],
        StructureSettings::default(),
    )
}

/// An L-shaped frame: beam `a` clamped at the origin along e1, beam `b` welded to its end at
/// 90° (turned about e3), both of `length`; spatial. The elbow is `a`'s end node.
pub fn l_frame(section: Section, n_elements: usize, length: f64) -> Result<Structure> {
    let beam = Beam::new(section, Mesh::uniform(length, n_elements)?, Components::Spatial)?;
    Structure::new(
        vec![
            StructureBeam::new("a", beam.clone(), Placement::origin()),
            StructureBeam::new(
                "b",
                beam,
                Placement::Attached {
                    joint: "elbow".into(),
                    axis: [0.0, 0.0, 1.0],
                    angle: std::f64::consts::FRAC_PI_2,
                },
            ),
        ],
        vec![Joint {
            name: "elbow".into(),
            ends: vec![EndRef::new("a", End::End), EndRef::new("b", End::Start)],
            kind: JointKind::Weld,
        }],
        vec![Support {
            name: "clamp".into(),
            end: EndRef::new("a", End::Start),
            kind: JointKind::Weld,
        }],
        StructureSettings::default(),
    )
}

/// A section with the paper's 2D values and every stiffness multiplied by `factor`, undamped.
pub fn stiff_paper_2d(factor: f64) -> Result<Section> {
    let inf = f64::INFINITY;
    Ok(Section::from_diagonals(
        [1.0, 1.0, 1.0, 0.0, 1e-5, 0.0],
        [1000.0 * factor, inf, 1e5 * factor, inf, factor, inf],
    )?)
}

/// Rigid double pendulum of two uniform rods (mass `m`, length `l`, inertia about the centre
/// `i_c` each), hinged at a fixed point and to each other, under gravity `g`; angles from the
/// downward vertical. Lagrange's equations:
///
/// ```text
/// (i_c + 5/4 m l²) θ1'' + ½ m l² cos(θ1−θ2) θ2'' + ½ m l² sin(θ1−θ2) θ2'² + 3/2 m g l sin θ1 = 0
/// ½ m l² cos(θ1−θ2) θ1'' + (i_c + ¼ m l²) θ2'' − ½ m l² sin(θ1−θ2) θ1'² + ½ m g l sin θ2 = 0
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RodPendulum {
    /// Mass of each rod.
    pub m: f64,
    /// Length of each rod.
    pub l: f64,
    /// Inertia of each rod about its centre (`m l²/12` for a thin rod, plus rotary inertia).
    pub i_c: f64,
    /// Gravity acceleration.
    pub g: f64,
}

impl RodPendulum {
    /// `[θ1', θ2', θ1'', θ2'']` at state `y = [θ1, θ2, θ1', θ2']`.
    pub fn rate(&self, y: &[f64; 4]) -> [f64; 4] {
        let (m, l, ic, g) = (self.m, self.l, self.i_c, self.g);
        let d = y[0] - y[1];
        let a11 = ic + 1.25 * m * l * l;
        let a22 = ic + 0.25 * m * l * l;
        let a12 = 0.5 * m * l * l * d.cos();
        let b1 = -0.5 * m * l * l * d.sin() * y[3] * y[3] - 1.5 * m * g * l * y[0].sin();
        let b2 = 0.5 * m * l * l * d.sin() * y[2] * y[2] - 0.5 * m * g * l * y[1].sin();
        let det = a11 * a22 - a12 * a12;
        [y[2], y[3], (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det]
    }

    /// Classical RK4 from `y0` with `steps` equal steps of `dt`; returns the states at every
    /// step (including `y0`).
    pub fn integrate(&self, y0: [f64; 4], dt: f64, steps: usize) -> Vec<[f64; 4]> {
        let mut out = Vec::with_capacity(steps + 1);
        let mut y = y0;
        out.push(y);
        let add = |y: &[f64; 4], k: &[f64; 4], s: f64| {
            [y[0] + s * k[0], y[1] + s * k[1], y[2] + s * k[2], y[3] + s * k[3]]
        };
        for _ in 0..steps {
            let k1 = self.rate(&y);
            let k2 = self.rate(&add(&y, &k1, 0.5 * dt));
            let k3 = self.rate(&add(&y, &k2, 0.5 * dt));
            let k4 = self.rate(&add(&y, &k3, dt));
            for i in 0..4 {
                y[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
            out.push(y);
        }
        out
    }

    /// Total energy (kinetic + potential, zero at the hanging pivot level).
    pub fn energy(&self, y: &[f64; 4]) -> f64 {
        let (m, l, ic, g) = (self.m, self.l, self.i_c, self.g);
        let d = y[0] - y[1];
        let t = 0.5 * (ic + 1.25 * m * l * l) * y[2] * y[2]
            + 0.5 * (ic + 0.25 * m * l * l) * y[3] * y[3]
            + 0.5 * m * l * l * d.cos() * y[2] * y[3];
        let v = -1.5 * m * g * l * y[0].cos() - 0.5 * m * g * l * y[1].cos();
        t + v
    }
}

/// The angle from the downward vertical (−e3, positive towards +e1) of the chord from `a` to `b`.
pub fn pendulum_angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = b - a;
    d.x.atan2(-d.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pendulum_conserves_energy_and_small_oscillation_frequency() {
        let p = RodPendulum { m: 1.0, l: 1.0, i_c: 1.0 / 12.0, g: 9.81 };
        let traj = p.integrate([0.5, -0.3, 0.0, 0.0], 1e-3, 5000);
        let e0 = p.energy(&traj[0]);
        let drift = traj.iter().map(|y| (p.energy(y) - e0).abs()).fold(0.0, f64::max);
        // RK4 at dt = 1e-3: local error O(dt^5) on a smooth ODE, so the energy wanders ~1e-10.
        assert!(drift < 1e-8 * e0.abs(), "drift {drift}");
        // Linearised modes: det(K − ω² M) = 0 with M = [[4/3, 1/2], [1/2, 1/3]] (i_c = 1/12),
        // K = g diag(3/2, 1/2). Start on the slow mode at amplitude 1e-3: after a quarter
        // period both angles pass zero (nonlinear corrections are O(amplitude²) relative).
        let g = 9.81;
        let (m11, m12, m22, k11, k22): (f64, f64, f64, f64, f64) =
            (4.0 / 3.0, 0.5, 1.0 / 3.0, 1.5 * g, 0.5 * g);
        let (a, b, c) = (m11 * m22 - m12 * m12, -(m11 * k22 + m22 * k11), k11 * k22);
        let w2 = (-b - (b * b - 4.0 * a * c).sqrt()) / (2.0 * a);
        let v2 = (k11 - w2 * m11) / (w2 * m12);
        let amp = 1e-3;
        let quarter = std::f64::consts::FRAC_PI_2 / w2.sqrt();
        let steps = 20_000;
        let end = p.integrate([amp, amp * v2, 0.0, 0.0], quarter / steps as f64, steps)[steps];
        assert!(end[0].abs() < 1e-8 && end[1].abs() < 1e-8 * v2.abs().max(1.0), "{end:?}");
    }
}
