//! Integration tests of `multibody-constraints`: energy, constraints, statics, frame
//! invariance, topology errors, the stiff double pendulum.

use intrinsic_beam::Section;
use intrinsic_beam::{Beam, Components, LoadFrame, Mesh};
use multibody_constraints::null_space;
use multibody_constraints::samples;
use multibody_constraints::{End, EndRef, Joint, JointKind, Support};
use multibody_constraints::{MultibodyError, Owner, Plant, PlantSettings};
use multibody_constraints::{Placement, Structure, StructureBeam, StructureSettings};
use nalgebra::{Vector3, Vector6};

/// Link 1 at rest, link 2 spinning about the elbow at `rate`: consistent with both hinges.
fn elbow_spin_state(plant: &Plant, rate: f64) -> Vec<f64> {
    let s = plant.structure();
    let mut x = vec![0.0; s.dim()];
    let b = s.beam_index("link2").unwrap();
    let elbow = s.reference()[b].r[0];
    let spin = s.rigid_rotation_state(Vector3::new(0.0, rate, 0.0), elbow);
    let o = s.offset(b);
    let d = s.beams()[b].beam.dim();
    x[o..o + d].copy_from_slice(&spin[o..o + d]);
    x
}

#[test]
fn two_link_2d_energy_and_constraints() {
    let structure = samples::paper_2d(Section::paper_2d().undamped(), 10, 0.0).unwrap();
    let mut plant =
        Plant::new(structure, PlantSettings { dt: 2e-3, ..Default::default() }).unwrap();
    let x = elbow_spin_state(&plant, 4.0);
    plant.set_state(&x).unwrap();
    let e0 = plant.energy();
    let mut max_angle = 0.0f64;
    let mut drift = 0.0f64;
    let mut vv = 0.0f64;
    let mut iters = 0;
    for _ in 0..2000 {
        let r = plant.step().unwrap();
        iters += r.iterations;
        vv = vv.max(r.velocity_violation);
        drift = drift.max((plant.energy() - e0).abs() / e0);
        max_angle = max_angle.max(plant.joint_angles()[0].abs());
    }
    println!(
        "drift {drift:e} vv {vv:e} angle {max_angle} iters/step {} gap {:e}",
        iters as f64 / 2000.0,
        plant.joint_gap()
    );
    assert!(drift < 1e-11);
    assert!(vv < 1e-11);
    assert!(max_angle > 60f64.to_radians());
}

fn stiff_pendulum_error(n: usize, dt: f64, t_end: f64) -> f64 {
    let (t1, t2) = (30f64.to_radians(), 0.0);
    let section = samples::stiff_paper_2d(1e6).unwrap();
    let structure = samples::hanging_two_link(section, n, t1, t2).unwrap();
    let mut plant = Plant::new(structure, PlantSettings { dt, ..Default::default() }).unwrap();
    plant.set_gravity(Vector3::new(0.0, 0.0, -9.81)).unwrap();
    let rod = samples::RodPendulum { m: 1.0, l: 1.0, i_c: 1.0 / 12.0 + 1e-5, g: 9.81 };
    let steps = (t_end / dt).round() as usize;
    let reference = rod.integrate([t1, t2, 0.0, 0.0], dt / 10.0, steps * 10);
    let mut err = 0.0f64;
    let mut iters = 0;
    for s in 1..=steps {
        iters += plant.step().unwrap().iterations;
        let k = plant.kinematics();
        let a1 = samples::pendulum_angle(&k[0].r[0], &k[0].r[n]);
        let a2 = samples::pendulum_angle(&k[1].r[0], &k[1].r[n]);
        let y = reference[s * 10];
        err = err.max((a1 - y[0]).abs()).max((a2 - y[1]).abs());
    }
    println!(
        "n {n} dt {dt}: stiff pendulum max angle error {err:e}, iters/step {}",
        iters as f64 / steps as f64
    );
    err
}

/// The lumped node masses of the FE links converge to the rods' inertia as O(h²), so the
/// angle error of 2×N elements is c/N² (c ≈ 8.4 rad at 30°/0° over 5 s). Check that order
/// with N = 10, 20 and, by Richardson extrapolation of the N = 10/20 errors, that the FE
/// angles converge to the rigid ODE's within 1e-3 rad.
#[test]
fn stiff_links_follow_rigid_double_pendulum() {
    let e10 = stiff_pendulum_error(10, 1e-3, 5.0);
    let e20 = stiff_pendulum_error(20, 1e-3, 5.0);
    let order = (e10 / e20).log2();
    assert!((order - 2.0).abs() < 0.1, "order {order}");
    // The N → ∞ limit of the error: |e20 − (e10 − e20)/3| bounds what is left beyond O(h²).
    let limit = (e20 - (e10 - e20) / 3.0).abs();
    assert!(limit < 1e-3, "extrapolated error {limit}");
}

/// Fig. 2: three beams at a ball joint, moving under gravity. At every step the balance (12)
/// and compatibility (11) rows hold at the midpoint to round-off, and the loads the joint
/// applies on the three ends sum to zero with zero moments.
#[test]
fn ball_joint_three_beams_balance() {
    let structure = samples::ball_joint_3(Section::paper_3d(), 6).unwrap();
    let mut plant =
        Plant::new(structure, PlantSettings { dt: 2e-3, ..Default::default() }).unwrap();
    plant.set_gravity(Vector3::new(0.0, 0.0, -9.81)).unwrap();
    let ball = plant.structure().joint_index("ball").unwrap();
    let b = plant.run_joint_balance(ball, 300).unwrap();
    let (worst_sum, worst_moment, worst_v, scale) =
        (b.force_sum, b.moment, b.velocity_violation, b.load_scale);
    assert!(scale > 1.0, "the joint carries load ({scale})");
    // Balance is a row of the Newton system: round-off of O(1) entries times the load scale.
    assert!(worst_sum < 1e-11 * scale, "force sum {worst_sum} (scale {scale})");
    assert!(worst_moment < 1e-11 * scale, "ball joint moment {worst_moment}");
    assert!(worst_v < 1e-11, "velocity compatibility {worst_v}");
    assert!(plant.joint_gap() < 1e-12, "gap {}", plant.joint_gap());
}

/// L-frame, undamped, with a constant dead load at the elbow: `ε − F·r_elbow` is conserved
/// (exact discrete work of dead loads with midpoint rotations), and the motion is out of plane.
#[test]
fn l_frame_dead_load_energy() {
    let structure = samples::l_frame(Section::paper_3d().undamped(), 8, 1.0).unwrap();
    let mut plant =
        Plant::new(structure, PlantSettings { dt: 5e-3, ..Default::default() }).unwrap();
    let f = Vector3::new(0.0, 0.0, 0.2);
    plant.loads_mut(0).point.push(intrinsic_beam::PointLoad {
        node: 8,
        frame: LoadFrame::Dead,
        value: Vector6::new(f.x, f.y, f.z, 0.0, 0.0, 0.0),
        amplitude: intrinsic_beam::Amplitude::Constant,
    });
    let total = |p: &Plant| p.energy() - f.dot(&p.position(0, 8));
    let e0 = total(&plant);
    let mut drift = 0.0f64;
    let mut zmax = 0.0f64;
    for _ in 0..1000 {
        plant.step().unwrap();
        drift = drift.max((total(&plant) - e0).abs());
        zmax = zmax.max(plant.position(1, 8).z.abs());
    }
    // Elbow static deflection F L³/(3 EI) ≈ 0.067; the dynamic swing reaches about twice that.
    assert!(zmax > 0.05, "tip out-of-plane {zmax}");
    let work = f.norm() * zmax;
    assert!(drift < 1e-10 * work, "energy drift {drift} (work scale {work})");
}

#[test]
fn null_space_of_paper_2d_at_three_angles() {
    for deg in [0.0f64, 45.0, 90.0] {
        let s = samples::paper_2d(Section::paper_2d(), 12, deg.to_radians()).unwrap();
        let g = s.constraint_matrix();
        let ns = null_space(&g).unwrap();
        assert_eq!(ns.rank, g.rows);
        assert_eq!(ns.basis.ncols(), s.dim() - g.rows);
        let gd = g.to_dense();
        let gz = &gd * &ns.basis;
        let ztz = ns.basis.transpose() * &ns.basis;
        let mut worst = (0.0f64, 0.0f64);
        for j in 0..gz.ncols() {
            for i in 0..gz.nrows() {
                worst.0 = worst.0.max(gz[(i, j)].abs());
            }
            for i in 0..ztz.nrows() {
                let e = if i == j { 1.0 } else { 0.0 };
                worst.1 = worst.1.max((ztz[(i, j)] - e).abs());
            }
        }
        assert!(worst.0 < 1e-14 && worst.1 < 1e-14, "{deg}°: |GZ| {} |ZᵀZ−I| {}", worst.0, worst.1);
    }
}

fn rod(n: usize) -> Beam {
    Beam::new(Section::paper_3d(), Mesh::uniform(1.0, n).unwrap(), Components::Spatial).unwrap()
}

fn clamp(name: &str, beam: &str, end: End) -> Support {
    Support { name: name.into(), end: EndRef::new(beam, end), kind: JointKind::Weld }
}

#[test]
fn topology_errors() {
    let two = || {
        vec![
            StructureBeam::new("a", rod(2), Placement::origin()),
            StructureBeam::new("b", rod(2), Placement::at([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], 0.0)),
        ]
    };
    let elbow = |ends: Vec<EndRef>, kind| Joint { name: "elbow".into(), ends, kind };
    let ok_ends = vec![EndRef::new("a", End::End), EndRef::new("b", End::Start)];
    let s = StructureSettings::default();
    // unknown beam
    let e = Structure::new(
        two(),
        vec![elbow(
            vec![EndRef::new("a", End::End), EndRef::new("c", End::Start)],
            JointKind::Ball,
        )],
        vec![],
        s,
    )
    .unwrap_err();
    assert!(
        matches!(e, MultibodyError::UnknownBeam { .. }) && e.to_string().contains("`c`"),
        "{e}"
    );
    // unknown end
    let e = End::parse(&Owner::Joint("elbow".into()), "middle").unwrap_err();
    assert!(
        matches!(e, MultibodyError::UnknownEnd { .. }) && e.to_string().contains("middle"),
        "{e}"
    );
    // end used twice (in a joint and a support)
    let e = Structure::new(
        two(),
        vec![elbow(ok_ends.clone(), JointKind::Ball)],
        vec![clamp("root", "a", End::End)],
        s,
    )
    .unwrap_err();
    assert!(
        matches!(e, MultibodyError::EndUsedTwice { .. }) && e.to_string().contains("root"),
        "{e}"
    );
    // end used twice within one joint
    let e = Structure::new(
        two(),
        vec![elbow(vec![EndRef::new("a", End::End), EndRef::new("a", End::End)], JointKind::Ball)],
        vec![],
        s,
    )
    .unwrap_err();
    assert!(matches!(e, MultibodyError::EndUsedTwice { .. }), "{e}");
    // not connected (and allowed when asked)
    let e = Structure::new(two(), vec![], vec![clamp("root", "a", End::Start)], s).unwrap_err();
    assert!(matches!(e, MultibodyError::NotConnected { groups: 2, .. }), "{e}");
    Structure::new(
        two(),
        vec![],
        vec![clamp("root", "a", End::Start)],
        StructureSettings { allow_disconnected: true, ..s },
    )
    .unwrap();
    // zero-length axis
    let e = Structure::new(
        two(),
        vec![elbow(ok_ends.clone(), JointKind::hinge_on_first([0.0, 0.0, 0.0]))],
        vec![],
        s,
    )
    .unwrap_err();
    assert!(matches!(e, MultibodyError::ZeroAxis { .. }) && e.to_string().contains("elbow"), "{e}");
    // too few ends
    let e = Structure::new(
        two(),
        vec![elbow(vec![EndRef::new("a", End::End)], JointKind::Weld)],
        vec![],
        s,
    )
    .unwrap_err();
    assert!(matches!(e, MultibodyError::TooFewEnds { .. }), "{e}");
    // joint ends apart in the reference configuration
    let far = vec![
        StructureBeam::new("a", rod(2), Placement::origin()),
        StructureBeam::new("b", rod(2), Placement::at([1.5, 0.0, 0.0], [0.0, 0.0, 1.0], 0.0)),
    ];
    let e =
        Structure::new(far, vec![elbow(ok_ends.clone(), JointKind::Ball)], vec![], s).unwrap_err();
    assert!(
        matches!(e, MultibodyError::BadPlacement { .. }) && e.to_string().contains("elbow"),
        "{e}"
    );
    // duplicate names
    let e = Structure::new(
        two(),
        vec![elbow(ok_ends.clone(), JointKind::Ball)],
        vec![clamp("elbow", "a", End::Start)],
        s,
    )
    .unwrap_err();
    assert!(matches!(e, MultibodyError::DuplicateName { .. }), "{e}");
    // planar structure with a hinge off e2
    let planar = |n| {
        Beam::new(Section::paper_2d(), Mesh::uniform(1.0, n).unwrap(), Components::Planar).unwrap()
    };
    let e = Structure::new(
        vec![StructureBeam::new("a", planar(2), Placement::origin())],
        vec![],
        vec![Support {
            name: "root".into(),
            end: EndRef::new("a", End::Start),
            kind: JointKind::hinge_global([0.0, 0.0, 1.0]),
        }],
        s,
    )
    .unwrap_err();
    assert!(matches!(e, MultibodyError::NotPlanar { .. }), "{e}");
}

/// A beam rigid in extension clamped at both ends: its axial velocity is fixed twice (the
/// rigid element rows telescope to `v1_N − v1_0 = 0`, and both clamps state `v1 = 0`), so the
/// step system is singular; the error names both supports.
#[test]
fn redundant_constraints_are_found_by_rank() {
    let inf = f64::INFINITY;
    let section = Section::from_diagonals([1.0; 6], [inf, 1e5, 1e5, 0.05, 1.0, 2.0]).unwrap();
    let beam = Beam::new(section, Mesh::uniform(1.0, 4).unwrap(), Components::Spatial).unwrap();
    let structure = Structure::new(
        vec![StructureBeam::new("bar", beam, Placement::origin())],
        vec![],
        vec![clamp("left", "bar", End::Start), clamp("right", "bar", End::End)],
        StructureSettings::default(),
    )
    .unwrap();
    let e = Plant::new(structure, PlantSettings::default()).err().expect("redundant");
    let text = e.to_string();
    assert!(matches!(e, MultibodyError::RedundantConstraints { deficiency: 1, .. }), "{text}");
    assert!(text.contains("left") && text.contains("right"), "{text}");
}

/// The planar two-link (3 components) and the same structure on spatial components (paper 2D
/// section: out-of-plane directions rigid or massless; hinges about e2) follow the same
/// trajectory.
#[test]
fn planar_and_spatial_two_links_agree() {
    let run = |components: Components| {
        let structure = samples::hinged_two_link(Section::paper_2d(), 8, 0.4, components).unwrap();
        let x = structure.rigid_rotation_state(Vector3::new(0.0, 1.5, 0.0), Vector3::zeros());
        let settings = PlantSettings { dt: 2e-3, newton_tolerance: 1e-14, ..Default::default() };
        let mut plant = Plant::new(structure, settings).unwrap();
        plant.set_state(&x).unwrap();
        plant.set_joint_torque("root", None, 0.3).unwrap();
        for _ in 0..500 {
            plant.step().unwrap();
        }
        (plant.position(1, 8), plant.joint_angles().to_vec(), plant.energy())
    };
    let (pp, ap, ep) = run(Components::Planar);
    let (ps, as_, es) = run(Components::Spatial);
    // Same equations on the active components; differences are Newton tolerance and round-off.
    assert!((pp - ps).norm() < 1e-10, "tip {pp} vs {ps}");
    for (a, b) in ap.iter().zip(&as_) {
        assert!((a - b).abs() < 1e-10, "angles {ap:?} vs {as_:?}");
    }
    assert!((ep - es).abs() < 1e-10 * ep, "energy {ep} vs {es}");
}
