//! `[modes]`, `[controller]`, `[scenario]` and `[sweep]` → the closed-loop setup.

use multibody_constraints::Plant;

use super::error::{Ctx, SceneError};
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
    use modal_rom::{KindCounts, ModeSelection};
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
    if let Some(p) = &ms.selection {
        return match p.as_str() {
            "paper-2d" => Ok(modal_rom::samples::paper_2d_selection()),
            "paper-3d" => Ok(modal_rom::samples::paper_3d_selection()),
            other => ctx.err(
                span,
                "modes.selection",
                format!("unknown mode set `{other}` (allowed: paper-2d, paper-3d)"),
            ),
        };
    }
    if let Some(k) = ms.kinds {
        let total = k.rigid + k.axial + k.torsion + k.bending_e2 + k.bending_e3 + k.mixed;
        if total == 0 {
            return ctx.err(span, "modes.kinds", "select at least one mode");
        }
        return Ok(ModeSelection::ByKind(KindCounts {
            rigid: k.rigid,
            axial: k.axial,
            torsion: k.torsion,
            bending_e2: k.bending_e2,
            bending_e3: k.bending_e3,
            mixed: k.mixed,
        }));
    }
    if let Some(n) = ms.lowest {
        if n == 0 {
            return ctx.err(span, "modes.lowest", "must be at least 1");
        }
        return Ok(ModeSelection::Lowest(n));
    }
    match &ms.indices {
        Some(v) if !v.is_empty() => Ok(ModeSelection::Indices(v.clone())),
        _ => ctx.err(span, "modes.indices", "give at least one mode index"),
    }
}

/// A positive finite value, or an error naming `field`.
fn positive(
    ctx: &Ctx<'_>,
    span: Option<std::ops::Range<usize>>,
    field: &str,
    v: f64,
) -> Result<f64, SceneError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        ctx.err(span, field, format!("must be finite and > 0, got {v}"))
    }
}

/// A finite value ≥ 0, or an error naming `field`.
fn non_negative(
    ctx: &Ctx<'_>,
    span: Option<std::ops::Range<usize>>,
    field: &str,
    v: f64,
) -> Result<f64, SceneError> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        ctx.err(span, field, format!("must be finite and ≥ 0, got {v}"))
    }
}

/// An optional `[controller]` value in `(0, max]` behind an on/off switch (`retry` /
/// `retry_relaxation`, `joint_limit` / `plan_joint_limit_deg`): `None` when neither is given
/// (keep the default), `Some(None)` when switched off, `Some(Some(v))` for a value; a value
/// given with the switch off is an error naming both.
fn switched(
    ctx: &Ctx<'_>,
    span: Option<std::ops::Range<usize>>,
    (switch, on): (&str, Option<bool>),
    field: &str,
    value: Option<f64>,
    max: f64,
) -> Result<Option<Option<f64>>, SceneError> {
    let key = format!("controller.{field}");
    match (on, value) {
        (Some(false), Some(_)) => {
            ctx.err(span, &key, format!("is unused with `{switch} = false`; remove one of them"))
        }
        (Some(false), None) => Ok(Some(None)),
        (_, Some(v)) if v > 0.0 && v <= max => Ok(Some(Some(v))),
        (_, Some(v)) => ctx.err(span, &key, format!("must be in (0, {max}], got {v}")),
        (_, None) => Ok(None),
    }
}

/// `nmpc` / `lmpc`.
pub fn controller_kind(name: &str) -> Option<mpc::ControllerKind> {
    match name {
        "nmpc" => Some(mpc::ControllerKind::Nmpc),
        "lmpc" => Some(mpc::ControllerKind::Lmpc),
        _ => None,
    }
}

/// `fe` / `rom`.
pub fn plant_kind(name: &str) -> Option<mpc::PlantKind> {
    match name {
        "fe" => Some(mpc::PlantKind::Fe),
        "rom" => Some(mpc::PlantKind::Rom),
        _ => None,
    }
}

/// `[controller]` → `mpc::ControllerSettings` and the weights part of `mpc::MpcSettings`.
fn controller_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    mpc_settings: &mut mpc::MpcSettings,
) -> Result<mpc::ControllerSettings, SceneError> {
    use ocp_transcription::IntegratorKind;
    let mut c = mpc::ControllerSettings::default();
    let Some(cs) = &spec.controller else { return Ok(c) };
    let span = Some(cs.span());
    let sp = || span.clone();
    let cs = cs.get_ref();
    if let Some(k) = &cs.kind {
        c.kind = match controller_kind(k) {
            Some(k) => k,
            None => {
                return ctx.err(sp(), "controller.kind", format!("`{k}` (allowed: nmpc, lmpc)"))
            }
        };
    }
    if let Some(v) = cs.real_time_iteration {
        c.real_time_iteration = v;
    }
    if let Some(v) = cs.line_search {
        c.globalisation = if v {
            ocp_transcription::Globalisation::merit()
        } else {
            ocp_transcription::Globalisation::FullStep
        };
    }
    if let Some(n) = cs.max_iterations {
        if n == 0 {
            return ctx.err(sp(), "controller.max_iterations", "must be at least 1");
        }
        c.max_iterations = n;
    }
    if let Some(v) = cs.kkt_tolerance {
        c.kkt_tolerance = positive(ctx, sp(), "controller.kkt_tolerance", v)?;
    }
    if let Some(v) = cs.accept_violation {
        c.accept_violation = positive(ctx, sp(), "controller.accept_violation", v)?;
    }
    if let Some(v) = cs.levenberg_marquardt {
        c.levenberg_marquardt = non_negative(ctx, sp(), "controller.levenberg_marquardt", v)?;
    }
    if let Some(v) = cs.retry_levenberg_marquardt {
        c.retry_levenberg_marquardt =
            non_negative(ctx, sp(), "controller.retry_levenberg_marquardt", v)?;
    }
    if let Some(a) =
        switched(ctx, sp(), ("retry", cs.retry), "retry_relaxation", cs.retry_relaxation, 1.0)?
    {
        c.retry_relaxation = a;
    }
    if let Some(v) = cs.fallback_to_lmpc {
        c.fallback_to_lmpc = v;
    }
    if let Some(d) = switched(
        ctx,
        sp(),
        ("joint_limit", cs.joint_limit),
        "plan_joint_limit_deg",
        cs.plan_joint_limit_deg,
        180.0,
    )? {
        c.plan_joint_limit_deg = d;
    }
    if let Some(i) = &cs.integrator {
        c.integrator.kind = match i.as_str() {
            "lawson-rk4" => IntegratorKind::LawsonRk4,
            "rk4" => IntegratorKind::Rk4,
            "implicit-midpoint" => IntegratorKind::ImplicitMidpoint,
            other => {
                return ctx.err(
                    sp(),
                    "controller.integrator",
                    format!("`{other}` (allowed: lawson-rk4, rk4, implicit-midpoint)"),
                )
            }
        };
    }
    if let Some(n) = cs.substeps {
        if n == 0 {
            return ctx.err(sp(), "controller.substeps", "must be at least 1");
        }
        c.integrator.substeps = n;
    }
    if let Some(w) = &cs.weights {
        let span = Some(w.span());
        let w = w.get_ref();
        let m = mpc_settings;
        for (name, v, slot) in [
            ("kx1", w.kx1, &mut m.kx1),
            ("kx2", w.kx2, &mut m.kx2),
            ("k_dxi", w.k_dxi, &mut m.k_dxi),
            ("k_xi_rigid", w.k_xi_rigid, &mut m.k_xi_rigid),
            ("k_xi_elastic", w.k_xi_elastic, &mut m.k_xi_elastic),
        ] {
            if let Some(v) = v {
                *slot = non_negative(ctx, span.clone(), &format!("controller.weights.{name}"), v)?;
            }
        }
        if let Some(v) = w.ku {
            m.ku = positive(ctx, span.clone(), "controller.weights.ku", v)?;
        }
        if let Some(v) = w.u_max {
            m.u_max = positive(ctx, span.clone(), "controller.weights.u_max", v)?;
        }
    }
    if let Err(e) = c.validate() {
        return ctx.err(sp(), "controller", e.to_string());
    }
    Ok(c)
}

/// `[scenario]`, `[controller]`, `[sweep]` and the mode set → the closed-loop setup.
pub(super) fn control_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
    plant: &Plant,
    controls: Vec<mpc::ControlInput>,
    name: &str,
) -> Result<Option<Control>, SceneError> {
    let Some(sc) = &spec.scenario else {
        for (what, present, span) in [
            ("controller", spec.controller.is_some(), spec.controller.as_ref().map(|c| c.span())),
            ("sweep", spec.sweep.is_some(), spec.sweep.as_ref().map(|c| c.span())),
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
    let sp = || span.clone();
    let ss = sc.get_ref();
    if spec.gravity.is_some() {
        return ctx.err(
            None,
            "gravity",
            "a scene with [scenario] has no gravity (the closed loop's plant has none)",
        );
    }
    if controls.is_empty() {
        return ctx.err(
            sp(),
            "scenario",
            "a closed loop needs control inputs: mark [[loads]] or [[torques]] with \
             `control = true`",
        );
    }
    let selection = selection_of(ctx, spec)?;
    let mut m = mpc::MpcSettings::default();
    if let Some(v) = ss.horizon {
        m.horizon = positive(ctx, sp(), "scenario.horizon", v)?;
    }
    if let Some(v) = ss.sampling {
        m.sampling = positive(ctx, sp(), "scenario.sampling", v)?;
        if m.sampling > m.horizon {
            return ctx.err(
                sp(),
                "scenario.sampling",
                format!("τs = {} must not exceed the horizon τp = {}", m.sampling, m.horizon),
            );
        }
    }
    if let Some(n) = ss.intervals {
        if n == 0 {
            return ctx.err(sp(), "scenario.intervals", "must be at least 1");
        }
        m.intervals = n;
    }
    let controller = controller_of(ctx, spec, &mut m)?;
    let omega0 = ss.omega0.unwrap_or(1.0);
    if !omega0.is_finite() {
        return ctx.err(sp(), "scenario.omega0", format!("must be finite, got {omega0}"));
    }
    if ss.axis.iter().any(|v| !v.is_finite()) || ss.axis.iter().all(|v| *v == 0.0) {
        return ctx.err(
            sp(),
            "scenario.axis",
            format!("must be finite and non-zero, got {:?}", ss.axis),
        );
    }
    let center = ss.center.unwrap_or([0.0; 3]);
    if center.iter().any(|v| !v.is_finite()) {
        return ctx.err(sp(), "scenario.center", "entries must be finite");
    }
    let structure = plant.structure().clone();
    let supports: Vec<String> =
        structure.joints().iter().filter(|j| j.ground).map(|j| j.name.clone()).collect();
    let root = match &ss.root {
        Some(r) if supports.contains(r) => r.clone(),
        Some(r) => {
            return ctx.err(
                sp(),
                "scenario.root",
                format!("unknown support `{r}` (supports: {})", supports.join(", ")),
            )
        }
        None => match supports.first() {
            Some(r) => r.clone(),
            None => return ctx.err(sp(), "scenario.root", "the structure has no support"),
        },
    };
    let plant_kind = match ss.plant.as_deref() {
        None => mpc::PlantKind::Fe,
        Some(p) => match plant_kind(p) {
            Some(k) => k,
            None => return ctx.err(sp(), "scenario.plant", format!("`{p}` (allowed: fe, rom)")),
        },
    };
    let duration = positive(ctx, sp(), "scenario.duration", ss.duration.unwrap_or(7.5))?;
    let output_interval =
        positive(ctx, sp(), "scenario.output_interval", ss.output_interval.unwrap_or(0.05))?;
    let snapshot_interval =
        positive(ctx, sp(), "scenario.snapshot_interval", ss.snapshot_interval.unwrap_or(0.25))?;
    let rom_plant_substeps = ss.rom_plant_substeps.unwrap_or(16);
    if rom_plant_substeps == 0 {
        return ctx.err(sp(), "scenario.rom_plant_substeps", "must be at least 1");
    }
    let whole = |a: f64, b: f64| {
        let r = a / b;
        r.round() >= 1.0 && (r - r.round()).abs() <= 1e-9 * r.round()
    };
    let dt = plant.settings().dt;
    for (field, a, b, what) in [
        ("scenario.duration", duration, output_interval, "output_interval"),
        ("scenario.sampling", m.sampling, output_interval, "output_interval"),
        ("scenario.snapshot_interval", snapshot_interval, output_interval, "output_interval"),
        ("scenario.output_interval", output_interval, dt, "[run] dt"),
    ] {
        if !whole(a, b) {
            return ctx.err(
                sp(),
                field,
                format!("{a} s must be a whole multiple (≥ 1) of {what} = {b} s"),
            );
        }
    }
    let scenario = mpc::Scenario {
        name: name.to_string(),
        structure,
        inputs: controls,
        selection,
        rom_options: modal_rom::RomOptions::default(),
        omega_direction: ss.axis,
        center,
        root,
        duration,
        output_interval,
        snapshot_interval,
        plant: *plant.settings(),
        rom_plant_substeps,
        mpc: m,
    };
    if let Err(e) = scenario.validate() {
        return ctx.err(sp(), "scenario", e.to_string());
    }
    let (sweep_omegas, sweep_controllers) = match &spec.sweep {
        None => (Vec::new(), vec![controller.kind]),
        Some(sw) => {
            let span = Some(sw.span());
            let s = sw.get_ref();
            if s.omega0.is_empty() {
                return ctx.err(span, "sweep.omega0", "give at least one ω0 (rad/s)");
            }
            if let Some(w) = s.omega0.iter().find(|w| !w.is_finite()) {
                return ctx.err(span, "sweep.omega0", format!("must be finite, got {w}"));
            }
            let kinds = match &s.controllers {
                None => vec![controller.kind],
                Some(v) if v.is_empty() => {
                    return ctx.err(span, "sweep.controllers", "give at least one of nmpc, lmpc")
                }
                Some(v) => {
                    let mut out = Vec::new();
                    for k in v {
                        match controller_kind(k) {
                            Some(k) => out.push(k),
                            None => {
                                return ctx.err(
                                    span,
                                    "sweep.controllers",
                                    format!("`{k}` (allowed: nmpc, lmpc)"),
                                )
                            }
                        }
                    }
                    out
                }
            };
            (s.omega0.clone(), kinds)
        }
    };
    Ok(Some(Control {
        scenario,
        controller,
        plant: plant_kind,
        omega0,
        sweep_omegas,
        sweep_controllers,
    }))
}
