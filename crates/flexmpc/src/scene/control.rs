//! `[modes]`, `[controller]`, `[scenario]` and `[sweep]` → the closed-loop setup.

use multibody_constraints::PlantSettings;
use multibody_constraints::Structure;
use serde::de::{value, IntoDeserializer};
use serde::Deserialize;

use super::error::{Ctx, Owner, SceneError};
use super::spec::SceneSpec;
use super::Control;

/// `[modes] count` and `angles`, checked.
pub(super) fn modes_of(ctx: &Ctx<'_>, spec: &SceneSpec) -> Result<(usize, Vec<f64>), SceneError> {
    let Some(m) = &spec.modes else { return Ok((8, Vec::new())) };
    let span = Some(m.span());
    let ms = m.get_ref();
    let count = ms.count.unwrap_or(8);
    if count == 0 {
        return ctx.err(span, "modes.count", "must be at least 1");
    }
    let angles = ms.angles.clone().unwrap_or_default();
    if let Some(a) = angles.iter().find(|a| !a.is_finite()) {
        return ctx.err(span, "modes.angles", format!("angles (deg) must be finite, got {a}"));
    }
    if ms.angles.as_ref().is_some_and(|a| a.is_empty()) {
        return ctx.err(span, "modes.angles", "give at least one angle (deg), e.g. [0, 45, 90]");
    }
    if !angles.is_empty() && !spec.beams.iter().any(|b| b.get_ref().attach.is_some()) {
        return ctx.err(
            span,
            "modes.angles",
            "reference angles need a beam placed by a joint (`attach = { joint = .. }`)",
        );
    }
    Ok((count, angles))
}

/// The controller model's mode set of `[modes]` (exactly one of its four forms).
fn selection_of(ctx: &Ctx<'_>, spec: &SceneSpec) -> Result<modal_rom::ModeSelection, SceneError> {
    use modal_rom::ModeSelection;
    const NEED: &str = "the controller model needs a mode set in [modes]: one of \
                        `selection = \"paper-2d\"|\"paper-3d\"`, `kinds = { rigid = 2, axial = 4, \
                        bending_e2 = 4 }`, `lowest = n` or `indices = [..]`";
    let Some(m) = &spec.modes else {
        let span = spec.scenario.as_ref().map(|s| s.span());
        return ctx.err(span, "modes", NEED);
    };
    let span = Some(m.span());
    let ms = m.get_ref();
    let given =
        [ms.selection.is_some(), ms.kinds.is_some(), ms.lowest.is_some(), ms.indices.is_some()];
    match given.iter().filter(|g| **g).count() {
        0 => return ctx.err(span, "modes.selection", NEED),
        1 => {}
        _ => {
            return ctx.err(
                span,
                "modes.selection",
                "give only one of `selection`, `kinds`, `lowest`, `indices`",
            )
        }
    }
    let selection = match (ms.selection, ms.kinds, ms.lowest, &ms.indices) {
        (Some(p), ..) => p.selection(),
        (_, Some(k), ..) => ModeSelection::ByKind(k),
        (_, _, Some(n), _) => ModeSelection::Lowest(n),
        (.., v) => ModeSelection::Indices(v.clone().unwrap_or_default()),
    };
    // the library's rule (at least one mode); its error names the form = the scene key
    selection.validate().or_else(|e| match e {
        modal_rom::ModalError::Invalid { field, value, reason } => {
            ctx.err(span, format!("modes.{field}"), format!("{reason}, got {value}"))
        }
        e => ctx.err(span, "modes", e.to_string()),
    })?;
    Ok(selection)
}

/// A `[controller]` value behind an on/off switch (`retry` / `retry_relaxation`,
/// `joint_limit` / `plan_joint_limit_deg`): `None` when neither is given (keep the default),
/// `Some(None)` when switched off, `Some(Some(v))` for a value (its range is the library's
/// rule); a value given with the switch off is an error naming both.
fn switched(
    ctx: &Ctx<'_>,
    span: Option<std::ops::Range<usize>>,
    (switch, on): (&str, Option<bool>),
    field: &str,
    value: Option<f64>,
    when_on: Option<f64>,
) -> Result<Option<Option<f64>>, SceneError> {
    match (on, value) {
        (Some(false), Some(_)) => ctx.err(
            span,
            format!("controller.{field}"),
            format!("is unused with `{switch} = false`; remove one of them"),
        ),
        (Some(false), None) => Ok(Some(None)),
        (Some(true), None) => Ok(when_on.map(Some)),
        (_, Some(v)) => Ok(Some(Some(v))),
        (_, None) => Ok(None),
    }
}

/// `nmpc` / `lmpc` (the names of `[controller] kind`).
pub fn controller_kind(name: &str) -> Option<mpc::ControllerKind> {
    mpc::ControllerKind::deserialize(IntoDeserializer::<value::Error>::into_deserializer(name)).ok()
}

/// `paper` / `exact-joints` (the names of `[controller] model`).
pub fn model_kind(name: &str) -> Option<mpc::ModelKind> {
    mpc::ModelKind::deserialize(IntoDeserializer::<value::Error>::into_deserializer(name)).ok()
}

/// `fe` / `rom` (the names of `[scenario] plant`).
pub fn plant_kind(name: &str) -> Option<mpc::PlantKind> {
    mpc::PlantKind::deserialize(IntoDeserializer::<value::Error>::into_deserializer(name)).ok()
}

/// `[controller]` → `mpc::ControllerSettings` (unset keys keep the library's defaults; the
/// library's `validate` checks the values).
fn controller_of(ctx: &Ctx<'_>, spec: &SceneSpec) -> Result<mpc::ControllerSettings, SceneError> {
    let mut c = mpc::ControllerSettings::default();
    let Some(cs) = &spec.controller else { return Ok(c) };
    let span = Some(cs.span());
    let cs = cs.get_ref();
    fn set<T>(slot: &mut T, v: Option<T>) {
        if let Some(v) = v {
            *slot = v;
        }
    }
    set(&mut c.kind, cs.kind);
    set(&mut c.real_time_iteration, cs.real_time_iteration);
    set(
        &mut c.globalisation,
        cs.line_search.map(|on| {
            if on {
                ocp_transcription::Globalisation::merit()
            } else {
                ocp_transcription::Globalisation::FullStep
            }
        }),
    );
    if cs.second_order_correction == Some(true) {
        if cs.line_search == Some(false) {
            return ctx.err(
                span.clone(),
                "controller.second_order_correction",
                "needs the merit line search (line_search = true)",
            );
        }
        c.globalisation = ocp_transcription::Globalisation::merit_soc();
    }
    set(&mut c.max_iterations, cs.max_iterations);
    set(&mut c.first_sample_iterations, cs.first_sample_iterations.map(Some));
    set(&mut c.first_sample_guess, cs.first_sample_guess);
    set(&mut c.first_sample_continuation, cs.first_sample_continuation);
    set(&mut c.first_sample_levenberg_marquardt, cs.first_sample_levenberg_marquardt.map(Some));
    set(&mut c.rollout_intervals, cs.rollout_intervals);
    set(&mut c.kkt_tolerance, cs.kkt_tolerance);
    set(&mut c.accept_violation, cs.accept_violation);
    set(&mut c.levenberg_marquardt, cs.levenberg_marquardt);
    set(&mut c.retry_levenberg_marquardt, cs.retry_levenberg_marquardt);
    set(&mut c.fallback_to_lmpc, cs.fallback_to_lmpc);
    set(
        &mut c.retry_relaxation,
        switched(
            ctx,
            span.clone(),
            ("retry", cs.retry),
            "retry_relaxation",
            cs.retry_relaxation,
            mpc::ControllerSettings::full_sqp().retry_relaxation,
        )?,
    );
    set(
        &mut c.plan_joint_limit_deg,
        switched(
            ctx,
            span.clone(),
            ("joint_limit", cs.joint_limit),
            "plan_joint_limit_deg",
            cs.plan_joint_limit_deg,
            mpc::DEFAULT_PLAN_JOINT_LIMIT,
        )?,
    );
    set(&mut c.model, cs.model);
    if c.model == mpc::ModelKind::ExactJoints
        && cs.joint_limit.is_none()
        && cs.plan_joint_limit_deg.is_none()
    {
        // the joint-angle check reads the paper model's state: off by default
        c.plan_joint_limit_deg = None;
    }
    if c.model == mpc::ModelKind::ExactJoints && cs.fallback_to_lmpc.is_none() {
        // the linear MPC is the model linearised at the reference angle: off by default
        c.fallback_to_lmpc = false;
    }
    set(&mut c.link_elastic_modes, cs.link_elastic_modes.map(Some));
    set(&mut c.integrator.kind, cs.integrator);
    set(&mut c.integrator.substeps, cs.substeps);
    match (cs.tail_from_interval, cs.tail_substeps) {
        (Some(from_interval), Some(substeps)) => {
            c.integrator.tail = Some(ocp_transcription::TailSubsteps { from_interval, substeps });
        }
        (None, None) => {}
        (from, _) => {
            let (key, other) = if from.is_some() {
                ("controller.tail_from_interval", "tail_substeps")
            } else {
                ("controller.tail_substeps", "tail_from_interval")
            };
            return ctx.err(span.clone(), key, format!("needs `{other}` too"));
        }
    }
    set(&mut c.integrator.newton_tolerance, cs.newton_tolerance);
    if cs.newton_tolerance.is_some()
        && c.integrator.kind != ocp_transcription::IntegratorKind::ImplicitMidpoint
    {
        return ctx.err(
            span.clone(),
            "controller.newton_tolerance",
            format!(
                "needs integrator = \"implicit-midpoint\" (the explicit {:?} takes no Newton \
                 iterations)",
                c.integrator.kind
            ),
        );
    }
    set(&mut c.parallel_intervals, cs.parallel_intervals);
    c.validate().or_else(|e| ctx.library(spec, Owner::Controller, e))?;
    Ok(c)
}

/// `[scenario]`, `[controller]`, `[sweep]` and the mode set → the closed-loop setup on
/// `structure` with the plant settings of `[run]`; every value is checked by the library's
/// `validate` ([`mpc::Scenario::validate`], [`mpc::ControllerSettings::validate`]).
pub(super) fn control_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    structure: &Structure,
    plant: PlantSettings,
    controls: Vec<mpc::ControlInput>,
    name: &str,
) -> Result<Option<Control>, SceneError> {
    let Some(sc) = &spec.scenario else {
        for (what, present, span) in [
            ("controller", spec.controller.is_some(), spec.controller.as_ref().map(|c| c.span())),
            ("sweep", spec.sweep.is_some(), spec.sweep.as_ref().map(|c| c.span())),
            ("reference", spec.reference.is_some(), spec.reference.as_ref().map(|c| c.span())),
        ] {
            if present {
                return ctx.err(
                    span,
                    what,
                    format!("[{what}] needs a [scenario] section (axis, omega0, …)"),
                );
            }
        }
        return Ok(None);
    };
    let span = Some(sc.span());
    let ss = sc.get_ref();
    if spec.gravity.is_some() {
        return ctx.err(
            None,
            "gravity",
            "a scene with [scenario] has no gravity (the closed loop's plant has none)",
        );
    }
    let selection = selection_of(ctx, spec)?;
    let controller = controller_of(ctx, spec)?;
    let cost = spec.controller.as_ref().and_then(|c| c.get_ref().weights.as_ref());
    let m = mpc::MpcSettings {
        timing: ss.timing,
        cost: cost.map_or_else(Default::default, |w| *w.get_ref()),
        ..Default::default()
    };
    let omega0 = ss.omega0.unwrap_or(1.0);
    if !omega0.is_finite() {
        return ctx.err(span, "scenario.omega0", format!("must be finite, got {omega0}"));
    }
    // the first support by default; an unknown name is the library's error
    let root = ss
        .root
        .clone()
        .or_else(|| structure.joints().iter().find(|j| j.ground).map(|j| j.name.clone()));
    let scenario = mpc::Scenario {
        name: name.to_string(),
        structure: structure.clone(),
        inputs: controls,
        selection,
        rom_options: modal_rom::RomOptions::default(),
        omega_direction: ss.axis,
        center: ss.center.unwrap_or([0.0; 3]),
        root: root.unwrap_or_default(),
        duration: ss.duration.unwrap_or(7.5),
        output_interval: ss.output_interval.unwrap_or(0.05),
        snapshot_interval: ss.snapshot_interval.unwrap_or(0.25),
        plant,
        rom_plant_substeps: ss.rom_plant_substeps.unwrap_or(16),
        mpc: m,
        references: super::reference::references_of(ctx, spec, structure, controller.model)?,
    };
    scenario.validate().or_else(|e| ctx.library(spec, Owner::Scenario, e))?;
    let (sweep_omegas, sweep_controllers) = sweep_of(ctx, spec, controller.kind)?;
    Ok(Some(Control {
        scenario,
        controller,
        plant: ss.plant.unwrap_or(mpc::PlantKind::Fe),
        omega0,
        sweep_omegas,
        sweep_controllers,
    }))
}

/// `[sweep]`'s runs: the `ω0` values (finite, at least one; empty without `[sweep]`) and the
/// controllers (at least one; default `kind`, the `[controller]`'s). The sweep has no settings
/// type in the library ([`mpc::sweep`] takes the values), so its rules live here, once.
fn sweep_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    kind: mpc::ControllerKind,
) -> Result<(Vec<f64>, Vec<mpc::ControllerKind>), SceneError> {
    let Some(sw) = &spec.sweep else { return Ok((Vec::new(), vec![kind])) };
    let span = Some(sw.span());
    let s = sw.get_ref();
    if s.omega0.is_empty() {
        return ctx.err(span, "sweep.omega0", "give at least one ω0 (rad/s)");
    }
    if let Some(w) = s.omega0.iter().find(|w| !w.is_finite()) {
        return ctx.err(span, "sweep.omega0", format!("must be finite, got {w}"));
    }
    let kinds = match &s.controllers {
        None => vec![kind],
        Some(v) if v.is_empty() => {
            return ctx.err(span, "sweep.controllers", "give at least one of nmpc, lmpc")
        }
        Some(v) => v.clone(),
    };
    Ok((s.omega0.clone(), kinds))
}

/// The setup that `mpc`, `sweep` and `ocp` build first ([`mpc::Setup::new`]: the modes, the
/// mode set, the reduced model with the control inputs, the weights); a mode set that the
/// structure's modes cannot fill is an error at the `[modes]` key that asked for it.
pub(super) fn setup_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    control: &Control,
) -> Result<mpc::Setup, SceneError> {
    use modal_rom::ModalError;
    mpc::Setup::new(&control.scenario).or_else(|e| match &e {
        mpc::MpcError::Modal(ModalError::NotEnoughModes { .. } | ModalError::Invalid { .. }) => {
            let m = spec.modes.as_ref();
            let key = m.map_or("modes", |m| {
                let m = m.get_ref();
                match (&m.selection, &m.kinds, &m.lowest) {
                    (Some(_), _, _) => "modes.selection",
                    (_, Some(_), _) => "modes.kinds",
                    (_, _, Some(_)) => "modes.lowest",
                    _ => "modes.indices",
                }
            });
            ctx.err(m.map(|m| m.span()), key, e.to_string())
        }
        _ => ctx.library(spec, Owner::Scenario, e),
    })
}
