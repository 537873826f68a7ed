//! Numerical experiments on structures and the constrained plant behind the
//! `multibody-constraints/*` verification cases (`cargo xtask verify multibody-constraints/`),
//! the stress runs and the docs tables.

use std::time::Instant;

use intrinsic_beam::{Amplitude, Beam, Components, LoadFrame, Mesh, PointLoad, Section};
use nalgebra::{Matrix6, Vector3, Vector6};

use multibody_constraints::{
    null_space, samples, End, EndRef, Joint, JointKind, MultibodyError, Owner, Placement, Plant,
    PlantSettings, Result, Structure, StructureBeam, StructureSettings, Support,
};

/// `(t, elbow z, tip z)` samples.
pub type TimeSeries = Vec<(f64, f64, f64)>;

/// A state in which only `beam` moves, rigidly, with angular velocity `omega` (global)
/// about `center` (e.g. the second link spinning about the elbow).
pub fn beam_rigid_rotation(
    structure: &Structure,
    beam: usize,
    omega: Vector3<f64>,
    center: Vector3<f64>,
) -> Vec<f64> {
    let full = structure.rigid_rotation_state(omega, center);
    let mut x = vec![0.0; structure.dim()];
    let (o, d) = (structure.offset(beam), structure.beams()[beam].beam.dim());
    x[o..o + d].copy_from_slice(&full[o..o + d]);
    x
}

/// Outcome of [`two_link_swing`].
#[derive(Clone, Copy, Debug, Default)]
pub struct SwingStudy {
    /// `max |ε_n − ε_0| / ε_0`.
    pub energy_drift: f64,
    /// Largest |elbow angle| (rad).
    pub max_elbow_angle: f64,
    /// Largest compatibility-row violation at a step midpoint.
    pub velocity_violation: f64,
    /// Largest balance-row violation at a step midpoint.
    pub balance_violation: f64,
    /// Largest distance between the joined ends (elbow).
    pub max_gap: f64,
    /// Mean Newton iterations per step.
    pub iterations_per_step: f64,
    /// Wall time (s).
    pub seconds: f64,
}

/// The paper's 2D two-link, undamped and unloaded, link 2 launched spinning about the elbow
/// at `rate` (rad/s) with link 1 at rest (consistent with both hinges): swings with large
/// joint angles. `n` elements per link, `steps` steps of `dt`.
pub fn two_link_swing(n: usize, dt: f64, steps: usize, rate: f64) -> Result<SwingStudy> {
    let structure = samples::paper_2d(Section::paper_2d().undamped(), n, 0.0)?;
    let x = beam_rigid_rotation(
        &structure,
        1,
        Vector3::new(0.0, rate, 0.0),
        structure.reference()[1].r[0],
    );
    let mut plant = Plant::new(structure, PlantSettings { dt, ..Default::default() })?;
    plant.set_state(&x)?;
    let e0 = plant.energy();
    let elbow = plant.structure().joint_index("elbow").expect("sample has an elbow");
    let mut out = SwingStudy::default();
    let start = Instant::now();
    let mut iters = 0;
    for _ in 0..steps {
        let r = plant.step()?;
        iters += r.iterations;
        out.velocity_violation = out.velocity_violation.max(r.velocity_violation);
        out.balance_violation = out.balance_violation.max(r.balance_violation);
        out.energy_drift = out.energy_drift.max((plant.energy() - e0).abs() / e0);
        out.max_elbow_angle = out.max_elbow_angle.max(plant.joint_angles()[elbow].abs());
        out.max_gap = out.max_gap.max(plant.joint_gap());
    }
    out.seconds = start.elapsed().as_secs_f64();
    out.iterations_per_step = iters as f64 / steps.max(1) as f64;
    Ok(out)
}

/// Largest angle error (rad) over `t_end` between the FE double pendulum with links of
/// stiffness × `factor` (2 × `n` elements, step `dt`, gravity 9.81) released at `theta1`,
/// `theta2` from hanging, and the rigid double pendulum of uniform rods
/// ([`samples::RodPendulum`], RK4 at `dt/10`). Angles are those of the links' chords.
pub fn stiff_pendulum_error(
    n: usize,
    dt: f64,
    t_end: f64,
    factor: f64,
    theta1: f64,
    theta2: f64,
) -> Result<f64> {
    let section = samples::stiff_paper_2d(factor)?;
    let rotary = section.mass[(4, 4)];
    let structure = samples::hanging_two_link(section, n, theta1, theta2)?;
    let mut plant = Plant::new(structure, PlantSettings { dt, ..Default::default() })?;
    plant.set_gravity(Vector3::new(0.0, 0.0, -9.81))?;
    // Uniform rods of mass 1 and length 1; the section's rotary inertia adds to i_c.
    let rod = samples::RodPendulum { m: 1.0, l: 1.0, i_c: 1.0 / 12.0 + rotary, g: 9.81 };
    let steps = (t_end / dt).round() as usize;
    let sub = 10;
    let reference = rod.integrate([theta1, theta2, 0.0, 0.0], dt / sub as f64, steps * sub);
    let mut err = 0.0f64;
    for s in 1..=steps {
        plant.step()?;
        let k = plant.kinematics();
        let a1 = samples::pendulum_angle(&k[0].r[0], &k[0].r[n]);
        let a2 = samples::pendulum_angle(&k[1].r[0], &k[1].r[n]);
        let y = reference[s * sub];
        err = err.max((a1 - y[0]).abs()).max((a2 - y[1]).abs());
    }
    Ok(err)
}

/// A rod hanging from a hinge (about e2) under gravity with strong diffusive damping `c`,
/// settled over `t_end`: returns `(vertical reaction / weight − 1, horizontal / weight,
/// |hinge-axis moment|)`.
pub fn hanging_hinge_reaction(n: usize, c: f64, t_end: f64) -> Result<(f64, f64, f64)> {
    let d2 = Matrix6::from_diagonal(&Vector6::repeat(c));
    let section =
        Section::paper_3d().undamped().with_damping(Matrix6::zeros(), Matrix6::zeros(), d2)?;
    let beam = Beam::new(section, Mesh::uniform(1.0, n)?, Components::Spatial)?;
    let structure = Structure::new(
        vec![StructureBeam::new(
            "rod",
            beam,
            Placement::at([0.0; 3], [0.0, 1.0, 0.0], std::f64::consts::FRAC_PI_2),
        )],
        vec![],
        vec![Support {
            name: "hinge".into(),
            end: EndRef::new("rod", End::Start),
            kind: JointKind::hinge_global([0.0, 1.0, 0.0]),
        }],
        StructureSettings::default(),
    )?;
    let dt = 2e-3;
    let mut plant = Plant::new(structure, PlantSettings { dt, ..Default::default() })?;
    let g = 9.81;
    plant.set_gravity(Vector3::new(0.0, 0.0, -g))?;
    for _ in 0..(t_end / dt).round() as usize {
        plant.step()?;
    }
    let r = plant.reactions(0)[0];
    let w = g * plant.structure().mass_per_length(0) * 1.0;
    Ok((r[2] / w - 1.0, (r[0] * r[0] + r[1] * r[1]).sqrt() / w, r[4].abs()))
}

/// Fig. 2's three beams at a ball joint swinging under gravity for `steps` steps (Newton
/// solved to the round-off floor): returns
/// `(max |Σ joint forces on the ends| / load scale, max |joint moment| / load scale,
/// max velocity violation, load scale)`.
pub fn ball_joint_balance(n: usize, steps: usize) -> Result<(f64, f64, f64, f64)> {
    let structure = samples::ball_joint_3(Section::paper_3d(), n)?;
    // Full Newton to the round-off floor, so the balance rows hold to round-off.
    let settings = PlantSettings {
        dt: 2e-3,
        newton_tolerance: 1e-15,
        reuse_jacobian: false,
        ..Default::default()
    };
    let mut plant = Plant::new(structure, settings)?;
    plant.set_gravity(Vector3::new(0.0, 0.0, -9.81))?;
    let ball = plant.structure().joint_index("ball").expect("sample has a ball joint");
    let b = plant.run_joint_balance(ball, steps)?;
    Ok((b.force_sum / b.load_scale, b.moment / b.load_scale, b.velocity_violation, b.load_scale))
}

/// Rotating the ball-joint structure, its gravity and global axes by a fixed rotation: the
/// largest difference of intrinsic states (relative to the state scale) and of rotated
/// positions over `steps` steps.
pub fn frame_invariance(steps: usize) -> Result<(f64, f64)> {
    let base = samples::ball_joint_3(Section::paper_3d(), 5)?;
    let (axis, angle, center) = (Vector3::new(0.3, -1.0, 0.7), 1.1, Vector3::new(0.2, 0.1, -0.4));
    let turned = base.rotated(axis, angle, center)?;
    let rot = nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
    let settings = PlantSettings {
        dt: 2e-3,
        newton_tolerance: 1e-15,
        reuse_jacobian: false,
        ..Default::default()
    };
    let mut a = Plant::new(base, settings)?;
    let mut b = Plant::new(turned, settings)?;
    let g = Vector3::new(0.0, 0.0, -9.81);
    a.set_gravity(g)?;
    b.set_gravity(rot * g)?;
    for p in [&mut a, &mut b] {
        p.loads_mut(1).point.push(PointLoad {
            node: 5,
            frame: LoadFrame::Follower,
            value: Vector6::new(0.0, 0.5, 1.0, 0.0, 0.0, 0.1),
            amplitude: Amplitude::Constant,
        });
    }
    let (mut ds, mut scale, mut dp) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..steps {
        a.step()?;
        b.step()?;
        for (x, y) in a.state().iter().zip(b.state()) {
            ds = ds.max((x - y).abs());
            scale = scale.max(x.abs());
        }
        for beam in 0..3 {
            for node in 0..=5 {
                let expect = center + rot * (a.position(beam, node) - center);
                dp = dp.max((b.position(beam, node) - expect).norm());
            }
        }
    }
    Ok((ds / scale.max(1.0), dp))
}

/// The L-frame (`n` elements per beam, paper 3D section, damped unless `undamped`) under a
/// constant dead out-of-plane force `force` at the elbow for `t_end` at step `dt`. Returns
/// the time series `(t, elbow z, tip z)` and, when undamped, the drift of `ε − F·r_elbow`
/// relative to `F · max|z_tip|`.
pub fn l_frame(
    n: usize,
    dt: f64,
    t_end: f64,
    force: f64,
    undamped: bool,
) -> Result<(TimeSeries, f64)> {
    let section = if undamped { Section::paper_3d().undamped() } else { Section::paper_3d() };
    let structure = samples::l_frame(section, n, 1.0)?;
    let mut plant = Plant::new(structure, PlantSettings { dt, ..Default::default() })?;
    let f = Vector3::new(0.0, 0.0, force);
    plant.loads_mut(0).point.push(PointLoad {
        node: n,
        frame: LoadFrame::Dead,
        value: Vector6::new(f.x, f.y, f.z, 0.0, 0.0, 0.0),
        amplitude: Amplitude::Constant,
    });
    let total = |p: &Plant| p.energy() - f.dot(&p.position(0, n));
    let e0 = total(&plant);
    let mut series = vec![(0.0, 0.0, 0.0)];
    let (mut drift, mut zmax) = (0.0f64, 0.0f64);
    for _ in 0..(t_end / dt).round() as usize {
        plant.step()?;
        drift = drift.max((total(&plant) - e0).abs());
        let (ze, zt) = (plant.position(0, n).z, plant.position(1, n).z);
        zmax = zmax.max(zt.abs());
        series.push((plant.time(), ze, zt));
    }
    Ok((series, drift / (force.abs() * zmax).max(1e-300)))
}

/// Bad topologies and joint data: how many of the listed mistakes are rejected with the
/// expected error kind (returns `(rejected, tried)`).
pub fn topology_errors() -> (usize, usize) {
    let rod = |n| {
        Beam::new(Section::paper_3d(), Mesh::uniform(1.0, n).expect("mesh"), Components::Spatial)
            .expect("beam")
    };
    let two = || {
        vec![
            StructureBeam::new("a", rod(2), Placement::origin()),
            StructureBeam::new("b", rod(2), Placement::at([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.0)),
        ]
    };
    let joint = |ends: Vec<EndRef>, kind| Joint { name: "elbow".into(), ends, kind };
    let clamp = |name: &str, beam: &str, end| Support {
        name: name.into(),
        end: EndRef::new(beam, end),
        kind: JointKind::Weld,
    };
    let ok = vec![EndRef::new("a", End::End), EndRef::new("b", End::Start)];
    let s = StructureSettings::default();
    type Expect = fn(&MultibodyError) -> bool;
    let tries: Vec<(Result<Structure>, Expect)> = vec![
        (
            Structure::new(
                two(),
                vec![joint(
                    vec![EndRef::new("a", End::End), EndRef::new("x", End::Start)],
                    JointKind::Ball,
                )],
                vec![],
                s,
            ),
            |e| matches!(e, MultibodyError::UnknownBeam { .. }),
        ),
        (End::parse(&Owner::Joint("elbow".into()), "middle").map(|_| unreachable!()), |e| {
            matches!(e, MultibodyError::UnknownEnd { .. })
        }),
        (
            Structure::new(
                two(),
                vec![joint(ok.clone(), JointKind::Ball)],
                vec![clamp("root", "a", End::End)],
                s,
            ),
            |e| matches!(e, MultibodyError::EndUsedTwice { .. }),
        ),
        (Structure::new(two(), vec![], vec![clamp("root", "a", End::Start)], s), |e| {
            matches!(e, MultibodyError::NotConnected { .. })
        }),
        (
            Structure::new(
                two(),
                vec![joint(ok.clone(), JointKind::hinge_on_first([0.0; 3]))],
                vec![],
                s,
            ),
            |e| matches!(e, MultibodyError::ZeroAxis { .. }),
        ),
        (
            Structure::new(
                two(),
                vec![joint(vec![EndRef::new("a", End::End)], JointKind::Weld)],
                vec![],
                s,
            ),
            |e| matches!(e, MultibodyError::TooFewEnds { .. }),
        ),
        (
            Structure::new(
                two(),
                vec![joint(ok.clone(), JointKind::Ball)],
                vec![clamp("elbow", "a", End::Start)],
                s,
            ),
            |e| matches!(e, MultibodyError::DuplicateName { .. }),
        ),
        (
            {
                let inf = f64::INFINITY;
                Section::from_diagonals([1.0; 6], [inf, 1e5, 1e5, 0.05, 1.0, 2.0])
                    .map_err(MultibodyError::from)
                    .and_then(|sec| {
                        let beam = Beam::new(sec, Mesh::uniform(1.0, 4)?, Components::Spatial)?;
                        let st = Structure::new(
                            vec![StructureBeam::new("bar", beam, Placement::origin())],
                            vec![],
                            vec![clamp("left", "bar", End::Start), clamp("right", "bar", End::End)],
                            s,
                        )?;
                        Plant::new(st.clone(), PlantSettings::default()).map(|_| st)
                    })
            },
            |e| matches!(e, MultibodyError::RedundantConstraints { .. }),
        ),
    ];
    let tried = tries.len();
    let rejected = tries.into_iter().filter(|(r, ok)| matches!(r, Err(e) if ok(e))).count();
    (rejected, tried)
}

/// `(max |G Z|, max |ZᵀZ − I|, null-space dimension)` for the paper's 2D two-link at a
/// reference joint angle (rad).
pub fn null_space_quality(n: usize, joint_angle: f64) -> Result<(f64, f64, usize)> {
    let s = samples::paper_2d(Section::paper_2d(), n, joint_angle)?;
    let g = s.constraint_matrix();
    let ns = null_space(&g)?;
    let gz = g.to_dense() * &ns.basis;
    let ztz = ns.basis.transpose() * &ns.basis;
    let (mut a, mut b) = (0.0f64, 0.0f64);
    for j in 0..gz.ncols() {
        for i in 0..gz.nrows() {
            a = a.max(gz[(i, j)].abs());
        }
        for i in 0..ztz.nrows() {
            b = b.max((ztz[(i, j)] - if i == j { 1.0 } else { 0.0 }).abs());
        }
    }
    Ok((a, b, ns.basis.ncols()))
}
