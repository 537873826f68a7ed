//! Sections, beams, joints and supports of a scene → [`Structure`].

use intrinsic_beam::rotation::axis_angle;
use intrinsic_beam::{Beam, Components, Mesh, Section};
use multibody_constraints::{End, EndRef, Frame, Freedom, Joint, JointKind, Owner, Support};
use multibody_constraints::{Placement, Structure, StructureBeam, StructureSettings};
use nalgebra::{Matrix6, Vector3, Vector6};
use toml::Spanned;

use super::error::{entry_of, Ctx, SceneError};
use super::names::{FreedomName, JointKindName, SectionPreset};
use super::spec::{JointSpec, SceneSpec, SectionSpec};

/// Largest mesh a scene may ask for, per beam: beyond it a step system needs gigabytes, and
/// no run of this library needs it (frequencies converge at second order, docs/intrinsic-beam.md).
pub const MAX_ELEMENTS_PER_BEAM: usize = 100_000;

fn section_of(
    ctx: &Ctx<'_>,
    name: &str,
    spec: &Spanned<SectionSpec>,
) -> Result<Section, SceneError> {
    let span = Some(spec.span());
    let s = spec.get_ref();
    let field = |f: &str| format!("sections.{name}.{f}");
    let mut section = match (&s.preset, &s.mass, &s.stiffness) {
        (Some(p), None, None) => match p {
            SectionPreset::Paper2d => Section::paper_2d(),
            SectionPreset::Paper3d => Section::paper_3d(),
        },
        (None, Some(m), Some(k)) => {
            let f = s.stiffness_factor.unwrap_or(1.0);
            let k = k.map(|x| x * f);
            match Section::from_diagonals(*m, k) {
                Ok(sec) => sec,
                Err(e) => return ctx.err(span, field("mass/stiffness"), e.to_string()),
            }
        }
        (Some(_), _, _) => {
            return ctx.err(
                span,
                field("preset"),
                "give either `preset` or `mass` and `stiffness`, not both",
            )
        }
        _ => return ctx.err(
            span,
            field("mass"),
            "give `preset` (paper-2d, paper-3d) or both `mass` and `stiffness` (6 entries each)",
        ),
    };
    if s.preset.is_some() {
        if let Some(f) = s.stiffness_factor {
            if !(f.is_finite() && f > 0.0) {
                return ctx.err(
                    span,
                    field("stiffness_factor"),
                    format!("must be positive, got {f}"),
                );
            }
            section.compliance /= f;
        }
    }
    if s.undamped {
        section = section.undamped();
    }
    if let Some(d2) = s.d2 {
        let d = Matrix6::from_diagonal(&Vector6::from(d2));
        section = match section.clone().with_damping(section.d0, section.d1, d) {
            Ok(x) => x,
            Err(e) => return ctx.err(span, field("d2"), e.to_string()),
        };
    }
    if let Some(k0) = s.kappa0 {
        section = match section.with_kappa0(Vector3::from(k0)) {
            Ok(x) => x,
            Err(e) => return ctx.err(span, field("kappa0"), e.to_string()),
        };
    }
    Ok(section)
}

fn parse_end(
    ctx: &Ctx<'_>,
    span: std::ops::Range<usize>,
    field: &str,
    text: &str,
    beams: &[String],
) -> Result<EndRef, SceneError> {
    let Some((b, e)) = text.split_once(':') else {
        return ctx.err(
            Some(span),
            field,
            format!("`{text}` is not of the form \"beam:start\" or \"beam:end\""),
        );
    };
    if !beams.iter().any(|x| x == b) {
        return ctx.err(
            Some(span),
            field,
            format!("unknown beam `{b}` (beams: {})", beams.join(", ")),
        );
    }
    let end = match End::parse(&Owner::Input(field.to_string()), e) {
        Ok(end) => end,
        Err(_) => {
            return ctx.err(Some(span), field, format!("unknown end `{e}` (allowed: start, end)"))
        }
    };
    Ok(EndRef::new(b, end))
}

fn parse_frame(
    ctx: &Ctx<'_>,
    span: std::ops::Range<usize>,
    field: &str,
    text: &str,
) -> Result<Frame, SceneError> {
    match text {
        "global" => Ok(Frame::Global),
        "each-end" => Ok(Frame::EachEnd),
        t if t.starts_with("end-") => match t[4..].parse::<usize>() {
            Ok(i) => Ok(Frame::End(i)),
            Err(_) => ctx.err(
                Some(span),
                field,
                format!("bad frame `{t}` (allowed: global, each-end, end-N)"),
            ),
        },
        t => ctx.err(
            Some(span),
            field,
            format!("unknown frame `{t}` (allowed: global, each-end, end-N)"),
        ),
    }
}

fn joint_kind(
    ctx: &Ctx<'_>,
    spec: &Spanned<JointSpec>,
    field: &str,
    support: bool,
) -> Result<JointKind, SceneError> {
    let span = spec.span();
    let j = spec.get_ref();
    let default_frame = if support { "global" } else { "end-0" };
    let frame = parse_frame(
        ctx,
        span.clone(),
        &format!("{field}.frame"),
        j.frame.as_deref().unwrap_or(default_frame),
    )?;
    let freedoms = |f: &Option<[FreedomName; 3]>, name: &str| -> Result<[Freedom; 3], SceneError> {
        let Some(f) = f else {
            return ctx.err(
                Some(span.clone()),
                format!("{field}.{name}"),
                "a custom joint needs 3 entries, each `rigid` or `free`",
            );
        };
        Ok(f.map(|x| match x {
            FreedomName::Rigid => Freedom::Rigid,
            FreedomName::Free => Freedom::Free,
        }))
    };
    Ok(match j.kind {
        JointKindName::Weld => JointKind::Weld,
        JointKindName::Ball => JointKind::Ball,
        JointKindName::Universal => JointKind::Universal,
        JointKindName::Hinge => {
            let Some(axis) = j.axis else {
                return ctx.err(
                    Some(span),
                    format!("{field}.axis"),
                    "a hinge needs `axis = [x, y, z]`",
                );
            };
            JointKind::Hinge { axis, frame }
        }
        JointKindName::Custom => {
            let rf = match &j.rotation_frame {
                Some(t) => parse_frame(ctx, span.clone(), &format!("{field}.rotation_frame"), t)?,
                None => frame,
            };
            JointKind::Custom {
                translation: freedoms(&j.translation, "translation")?,
                translation_frame: frame,
                rotation: freedoms(&j.rotation, "rotation")?,
                rotation_frame: rf,
                axes: j.axes,
            }
        }
    })
}

/// The structure of a scene (sections, beams, joints, supports) and its beam names.
pub(super) fn structure_of(
    ctx: &Ctx<'_>,
    spec: &SceneSpec,
) -> Result<(Structure, Vec<String>), SceneError> {
    let ctx = *ctx;
    let components = Components::from(spec.components);
    let mut sections = std::collections::BTreeMap::new();
    for (name, s) in &spec.sections {
        sections.insert(name.clone(), section_of(&ctx, name, s)?);
    }
    let beam_names: Vec<String> = spec.beams.iter().map(|b| b.get_ref().name.clone()).collect();
    let mut beams = Vec::new();
    for (i, b) in spec.beams.iter().enumerate() {
        let span = Some(b.span());
        let bs = b.get_ref();
        let f = |x: &str| format!("beams[{i}].{x}");
        let Some(section) = sections.get(&bs.section) else {
            let known: Vec<&str> = sections.keys().map(String::as_str).collect();
            return ctx.err(
                span,
                f("section"),
                format!("unknown section `{}` (sections: {})", bs.section, known.join(", ")),
            );
        };
        if !(bs.length.is_finite() && bs.length > 0.0) {
            return ctx.err(span, f("length"), format!("must be positive, got {}", bs.length));
        }
        if bs.elements == 0 {
            return ctx.err(span, f("elements"), "must be at least 1");
        }
        if bs.elements > MAX_ELEMENTS_PER_BEAM {
            return ctx.err(
                span,
                f("elements"),
                format!(
                    "at most {MAX_ELEMENTS_PER_BEAM} per beam (its step system would need gigabytes), got {}",
                    bs.elements
                ),
            );
        }
        let mesh = Mesh::uniform(bs.length, bs.elements)
            .or_else(|e| ctx.err(span.clone(), f("length"), e.to_string()))?;
        let beam = Beam::new(section.clone(), mesh, components)
            .or_else(|e| ctx.err(span.clone(), f("section"), e.to_string()))?;
        let placement = match (&bs.attach, bs.origin, bs.rotation) {
            (Some(a), None, None) => Placement::Attached {
                joint: a.joint.clone(),
                axis: a.axis,
                angle: a.angle_deg.to_radians(),
            },
            (None, o, r) => {
                let o = o.unwrap_or([0.0; 3]);
                if let Some(r) = &r {
                    let n = Vector3::from(r.axis).norm();
                    if !(n.is_finite() && n > 0.0 && r.angle_deg.is_finite()) {
                        return ctx.err(
                            span,
                            f("rotation"),
                            format!(
                                "axis must be finite and non-zero and angle_deg finite, got axis {:?}, angle_deg {}",
                                r.axis, r.angle_deg
                            ),
                        );
                    }
                }
                let q = r
                    .map(|r| axis_angle(&Vector3::from(r.axis), r.angle_deg.to_radians()))
                    .unwrap_or(nalgebra::Vector4::new(1.0, 0.0, 0.0, 0.0));
                Placement::At { origin: Vector3::from(o), quaternion: q }
            }
            _ => {
                return ctx.err(
                    span,
                    f("attach"),
                    "give either `attach` or `origin`/`rotation`, not both",
                )
            }
        };
        beams.push(StructureBeam::new(bs.name.clone(), beam, placement));
    }
    let mut joints = Vec::new();
    for (i, j) in spec.joints.iter().enumerate() {
        let field = format!("joints[{i}]");
        let js = j.get_ref();
        let Some(ends) = &js.ends else {
            return ctx.err(
                Some(j.span()),
                format!("{field}.ends"),
                "a joint needs `ends = [\"beam:end\", \"beam:start\", …]`",
            );
        };
        if js.end.is_some() {
            return ctx.err(
                Some(j.span()),
                format!("{field}.end"),
                "a joint takes `ends` (a list); `end` is for supports",
            );
        }
        let ends = ends
            .iter()
            .map(|e| parse_end(&ctx, j.span(), &format!("{field}.ends"), e, &beam_names))
            .collect::<Result<Vec<_>, _>>()?;
        joints.push(Joint {
            name: js.name.clone(),
            ends,
            kind: joint_kind(&ctx, j, &field, false)?,
        });
    }
    let mut supports = Vec::new();
    for (i, s) in spec.supports.iter().enumerate() {
        let field = format!("supports[{i}]");
        let ss = s.get_ref();
        let Some(end) = &ss.end else {
            return ctx.err(
                Some(s.span()),
                format!("{field}.end"),
                "a support needs `end = \"beam:start\"`",
            );
        };
        if ss.ends.is_some() {
            return ctx.err(
                Some(s.span()),
                format!("{field}.ends"),
                "a support takes one `end`; `ends` is for joints",
            );
        }
        let end = parse_end(&ctx, s.span(), &format!("{field}.end"), end, &beam_names)?;
        supports.push(Support {
            name: ss.name.clone(),
            end,
            kind: joint_kind(&ctx, s, &field, true)?,
        });
    }
    // Structure-level errors: attribute to the joint/support/beam they name.
    let structure = Structure::new(
        beams,
        joints,
        supports,
        StructureSettings { allow_disconnected: spec.allow_disconnected, ..Default::default() },
    )
    .or_else(|e| {
        let (span, field) = entry_of(spec, &e);
        ctx.err(span, field, e.to_string())
    })?;
    Ok((structure, beam_names))
}
