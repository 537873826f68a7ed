//! Loads, joint torques and the initial state of a scene, applied to its plant; the control
//! inputs of a closed loop.

use intrinsic_beam::{Amplitude, LoadFrame, PointLoad};
use multibody_constraints::Plant;
use multibody_constraints::Structure;
use nalgebra::{Vector3, Vector6};

use super::error::{Ctx, SceneError};
use super::names::LoadFrameName;
use super::spec::{AmplitudeSpec, NodeSpec, SceneSpec};
use super::{Input, InputKind};

fn amplitude(
    ctx: &Ctx<'_>,
    span: std::ops::Range<usize>,
    field: &str,
    a: &Option<AmplitudeSpec>,
) -> Result<Amplitude, SceneError> {
    let amp = match a {
        None => Amplitude::Constant,
        Some(AmplitudeSpec { ramp: Some(r), table: None }) => Amplitude::Ramp { duration: *r },
        Some(AmplitudeSpec { ramp: None, table: Some(t) }) => {
            Amplitude::Table(t.iter().map(|p| (p[0], p[1])).collect())
        }
        Some(_) => {
            return ctx.err(
                Some(span),
                field,
                "give exactly one of `ramp = seconds` or `table = [[t, a], …]`",
            )
        }
    };
    if let Err(e) = amp.validate(field) {
        return ctx.err(Some(span), field, e.to_string());
    }
    Ok(amp)
}

/// The scene's loads and torques on `structure`: the inputs (for the CSV and the plant of
/// `simulate`), the control inputs of a closed loop (in the order they appear in the file),
/// and the point loads per beam.
pub(super) fn inputs_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    structure: &Structure,
    beam_names: &[String],
) -> Result<Inputs, SceneError> {
    let ctx = *ctx;
    let mut inputs = Vec::new();
    let mut controls = Vec::new();
    let mut loads: Vec<(usize, PointLoad)> = Vec::new();
    for (i, l) in spec.loads.iter().enumerate() {
        let span = l.span();
        let ls = l.get_ref();
        let f = |x: &str| format!("loads[{i}].{x}");
        let Some(b) = structure.beam_index(&ls.beam) else {
            return ctx.err(
                Some(span),
                f("beam"),
                format!("unknown beam `{}` (beams: {})", ls.beam, beam_names.join(", ")),
            );
        };
        let n_el = structure.beams()[b].beam.n_elements();
        let node = match &ls.node {
            NodeSpec::Index(n) if *n <= n_el => *n,
            NodeSpec::Index(n) => {
                return ctx.err(
                    Some(span),
                    f("node"),
                    format!("node {n} does not exist (beam `{}` has nodes 0..={n_el})", ls.beam),
                )
            }
            NodeSpec::Named(s) if s == "start" => 0,
            NodeSpec::Named(s) if s == "end" => n_el,
            NodeSpec::Named(s) => {
                return ctx.err(
                    Some(span),
                    f("node"),
                    format!("`{s}` (allowed: an index 0..={n_el}, start, end)"),
                )
            }
        };
        let frame = match ls.frame {
            LoadFrameName::Follower => LoadFrame::Follower,
            LoadFrameName::Dead => LoadFrame::Dead,
        };
        let fo = ls.force.unwrap_or([0.0; 3]);
        let mo = ls.moment.unwrap_or([0.0; 3]);
        let mut value = Vector6::new(fo[0], fo[1], fo[2], mo[0], mo[1], mo[2]);
        if value.iter().any(|v| !v.is_finite()) {
            return ctx.err(Some(span), f("force"), "entries must be finite");
        }
        let name = ls.name.clone().unwrap_or_else(|| format!("load{i}"));
        if ls.control {
            if frame != LoadFrame::Follower {
                return ctx.err(
                    Some(span),
                    f("frame"),
                    "a control load (`control = true`) must be `follower`",
                );
            }
            if ls.amplitude.is_some() {
                return ctx.err(
                    Some(span),
                    f("amplitude"),
                    "a control load has no `amplitude` (the controller sets its history)",
                );
            }
            if value.norm() == 0.0 {
                return ctx.err(
                    Some(span),
                    f("force"),
                    "a control load needs a non-zero unit load (`force` and/or `moment`), \
                     e.g. force = [1.0, 0.0, 0.0]",
                );
            }
            controls.push((
                span.start,
                mpc::ControlInput::Follower {
                    name: name.clone(),
                    beam: b,
                    node,
                    load: [value[0], value[1], value[2], value[3], value[4], value[5]],
                },
            ));
            value = Vector6::zeros();
        } else if spec.scenario.is_some() {
            return ctx.err(
                Some(span),
                f("control"),
                "a scene with [scenario] takes only control inputs: set `control = true` \
                 (the load is then a unit load scaled by the controller) or remove the load",
            );
        }
        let amp = amplitude(&ctx, span.clone(), &f("amplitude"), &ls.amplitude)?;
        let index = loads.iter().filter(|(beam, _)| *beam == b).count();
        loads.push((b, PointLoad { node, frame, value, amplitude: amp }));
        inputs.push(Input { name, kind: InputKind::Load { beam: b, index } });
    }
    for (i, t) in spec.torques.iter().enumerate() {
        let span = t.span();
        let ts = t.get_ref();
        let f = |x: &str| format!("torques[{i}].{x}");
        let amp = amplitude(&ctx, span.clone(), &f("amplitude"), &ts.amplitude)?;
        let mut value = ts.value;
        if ts.control {
            if ts.value != 1.0 {
                return ctx.err(
                    Some(span),
                    f("value"),
                    format!(
                        "a control torque's `value` is its unit and must be 1, got {} \
                         (the controller sets the torque)",
                        ts.value
                    ),
                );
            }
            if ts.amplitude.is_some() {
                return ctx.err(
                    Some(span),
                    f("amplitude"),
                    "a control torque has no `amplitude` (the controller sets its history)",
                );
            }
            value = 0.0;
            controls.push((
                span.start,
                mpc::ControlInput::JointTorque {
                    name: format!("torque:{}", ts.joint),
                    joint: ts.joint.clone(),
                    axis: ts.axis,
                },
            ));
        } else if spec.scenario.is_some() {
            return ctx.err(
                Some(span),
                f("control"),
                "a scene with [scenario] takes only control inputs: set `control = true` \
                 (the controller then sets the torque) or remove the torque",
            );
        }
        if !value.is_finite() {
            return ctx.err(Some(span), f("value"), format!("must be finite, got {value}"));
        }
        inputs.push(Input {
            name: format!("torque:{}", ts.joint),
            kind: InputKind::Torque {
                joint: ts.joint.clone(),
                axis: ts.axis,
                value,
                amplitude: amp,
            },
        });
    }
    // control inputs in the order they appear in the file
    controls.sort_by_key(|(at, _)| *at);
    Ok(Inputs { inputs, controls: controls.into_iter().map(|(_, c)| c).collect(), loads })
}

/// The inputs of a scene ([`inputs_of`]).
pub(super) struct Inputs {
    /// Every load and torque (CSV columns; torque histories).
    pub(super) inputs: Vec<Input>,
    /// The control inputs of a closed loop, in the order of `u`.
    pub(super) controls: Vec<mpc::ControlInput>,
    /// Point loads with their beam index, in file order.
    pub(super) loads: Vec<(usize, PointLoad)>,
}

/// Applies the point loads and the torques' values at `t = 0` to `plant`; an unknown joint
/// or axis of a torque is an error at that torque.
pub(super) fn apply(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    plant: &mut Plant,
    loads: &[(usize, PointLoad)],
    inputs: &[Input],
) -> Result<(), SceneError> {
    for (b, l) in loads {
        plant.loads_mut(*b).point.push(l.clone());
    }
    let torques = inputs.iter().filter_map(|i| match &i.kind {
        InputKind::Torque { joint, axis, value, amplitude } => {
            Some((joint, axis, value, amplitude))
        }
        InputKind::Load { .. } => None,
    });
    for (i, (t, (joint, axis, value, amplitude))) in spec.torques.iter().zip(torques).enumerate() {
        plant
            .set_joint_torque(joint, *axis, value * amplitude.at(0.0))
            .or_else(|e| ctx.err(Some(t.span()), format!("torques[{i}].joint"), e.to_string()))?;
    }
    Ok(())
}

/// Sets the initial state (`[[initial.rigid]]`) and checks that the energies are finite.
pub(super) fn initial_state(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    plant: &mut Plant,
) -> Result<(), SceneError> {
    let ctx = *ctx;
    // Initial state.
    if !spec.initial.rigid.is_empty() {
        let s = plant.structure();
        let mut x = vec![0.0; s.dim()];
        for (i, r) in spec.initial.rigid.iter().enumerate() {
            let rs = r.get_ref();
            let full = s.rigid_rotation_state(
                Vector3::from(rs.omega),
                Vector3::from(rs.center.unwrap_or([0.0; 3])),
            );
            let targets: Vec<usize> = match &rs.beams {
                None => (0..s.beams().len()).collect(),
                Some(names) => {
                    let mut v = Vec::new();
                    for n in names {
                        match s.beam_index(n) {
                            Some(b) => v.push(b),
                            None => {
                                return ctx.err(
                                    Some(r.span()),
                                    format!("initial.rigid[{i}].beams"),
                                    format!("unknown beam `{n}`"),
                                )
                            }
                        }
                    }
                    v
                }
            };
            for b in targets {
                let (o, d) = (s.offset(b), s.beams()[b].beam.dim());
                x[o..o + d].copy_from_slice(&full[o..o + d]);
            }
        }
        plant.set_state(&x).or_else(|e| ctx.err(None, "initial", e.to_string()))?;
    }
    // Finite inputs can still overflow: a rate or a gravity near 1e308 squares to infinity.
    let (kinetic, potential) = (plant.energy(), plant.potential_energy());
    if !kinetic.is_finite() {
        return ctx.err(
            spec.initial.rigid.first().map(|r| r.span()),
            "initial.rigid",
            format!("the initial state's energy is not finite ({kinetic}): rates too large"),
        );
    }
    if !potential.is_finite() {
        return ctx.err(
            None,
            "gravity",
            format!("the potential energy is not finite ({potential}): gravity or loads too large"),
        );
    }
    Ok(())
}
