//! `[reference]`: commanded joint rotations of a closed loop (reconfiguration), checked by
//! `mpc::JointCommand::validate` and against the structure's joints.
//!
//! ```toml
//! [reference]
//! joints = [
//!   { joint = "elbow", axis = [0.0, 1.0, 0.0], angle_deg = 90.0, ramp_s = 4.0 },
//!   { joint = "root", axis = [0.0, 1.0, 0.0], angle_deg = 45.0, ramp_s = 4.0 },
//! ]
//! ```
//!
//! `axis`: in the joint's first end frame (global for a support); `ramp_s`: time to reach
//! `angle_deg` from 0 along a smooth step (default 0: the target from the start); `start_s`:
//! when the ramp starts (default 0; the angle is 0 before it).

use multibody_constraints::Structure;

use super::error::{Ctx, SceneError};
use super::spec::SceneSpec;

/// The commands of `[reference]` (empty without it) for the controller `model` (the paper
/// model refuses them); errors name `reference.joints[i].<field>`.
pub(super) fn references_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    structure: &Structure,
    model: mpc::ModelKind,
) -> Result<Vec<mpc::JointCommand>, SceneError> {
    let Some(r) = &spec.reference else { return Ok(Vec::new()) };
    let span = Some(r.span());
    if model == mpc::ModelKind::Paper && !r.get_ref().joints.is_empty() {
        return ctx.err(
            span,
            "reference",
            "the paper model cannot follow joint commands (its modes and joint rows are \
             linearised at the reference angle): set [controller] model = \"exact-joints\"",
        );
    }
    let mut out: Vec<mpc::JointCommand> = Vec::new();
    for (i, c) in r.get_ref().joints.iter().enumerate() {
        let at = format!("reference.joints[{i}]");
        let command = mpc::JointCommand {
            joint: c.joint.clone(),
            axis: c.axis,
            angle_deg: c.angle_deg,
            ramp_s: c.ramp_s.unwrap_or(0.0),
            start_s: c.start_s.unwrap_or(0.0),
        };
        if let Err(mpc::MpcError::Invalid { field, value, reason }) = command.validate() {
            return ctx.err(
                span.clone(),
                format!("{at}.{field}"),
                format!("{reason}, got {value}"),
            );
        }
        if structure.joint_index(&c.joint).is_none() {
            let names: Vec<&str> = structure.joints().iter().map(|j| j.name.as_str()).collect();
            return ctx.err(
                span.clone(),
                format!("{at}.joint"),
                format!(
                    "`{}` is not a joint or support (there are: {})",
                    c.joint,
                    names.join(", ")
                ),
            );
        }
        if out.iter().any(|d| d.joint == c.joint) {
            return ctx.err(
                span.clone(),
                format!("{at}.joint"),
                format!("`{}` has a command already", c.joint),
            );
        }
        out.push(command);
    }
    Ok(out)
}
