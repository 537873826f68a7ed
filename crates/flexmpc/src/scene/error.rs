//! Scene errors: the file, the line and the field of each error, and the mapping of a byte
//! offset in the scene text to its line and `table.key` path.

use std::fmt;
use std::path::{Path, PathBuf};

use multibody_constraints::{MultibodyError, Owner as StructureOwner};

use super::spec::SceneSpec;

/// A scene error: file, line (1-based, when known), field path and message.
#[derive(Debug)]
pub struct SceneError {
    /// The scene file.
    pub file: PathBuf,
    /// Line of the offending entry (1-based), if known.
    pub line: Option<usize>,
    /// Field path, e.g. `joints[1].ends`.
    pub field: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

impl fmt::Display for SceneError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => {
                write!(f, "{}:{}: field `{}`: {}", self.file.display(), l, self.field, self.message)
            }
            None => write!(f, "{}: field `{}`: {}", self.file.display(), self.field, self.message),
        }
    }
}

impl std::error::Error for SceneError {}

#[derive(Clone, Copy)]
pub(super) struct Ctx<'a> {
    pub(super) file: &'a Path,
    pub(super) text: &'a str,
}

impl Ctx<'_> {
    pub(super) fn line(&self, offset: usize) -> usize {
        self.text[..offset.min(self.text.len())].matches('\n').count() + 1
    }

    /// An error at the entry `span`; the line is that of the field's own `key = …` line
    /// inside the entry when there is one, else the entry's first line.
    pub(super) fn err<T>(
        &self,
        span: Option<std::ops::Range<usize>>,
        field: impl Into<String>,
        message: impl Into<String>,
    ) -> Result<T, SceneError> {
        let field = field.into();
        let key = field
            .rsplit('.')
            .next()
            .unwrap_or("")
            .split('[')
            .next()
            .unwrap_or("")
            .trim()
            .to_string();
        let line = span.map(|s| {
            // The entry runs from its span to the next table header (spans of array-of-table
            // entries may cover the header only).
            let start = s.start.min(self.text.len());
            let first_nl =
                self.text[start..].find('\n').map(|i| start + i + 1).unwrap_or(self.text.len());
            let end = self.text[first_nl..]
                .match_indices('\n')
                .map(|(i, _)| first_nl + i + 1)
                .find(|&i| self.text[i..].trim_start_matches([' ', '\t']).starts_with('['))
                .unwrap_or(self.text.len())
                .max(s.end.min(self.text.len()));
            let body = &self.text[start..end];
            let mut off = s.start;
            for l in body.split_inclusive('\n') {
                let t = l.trim_start();
                if !key.is_empty()
                    && field.contains('.')
                    && t.starts_with(&key)
                    && t[key.len()..].trim_start().starts_with('=')
                {
                    return self.line(off);
                }
                off += l.len();
            }
            self.line(s.start)
        });
        // Top-level keys without a span: their own line.
        let line = line.or_else(|| {
            self.text
                .lines()
                .position(|l| {
                    let t = l.trim_start();
                    !field.contains('.')
                        && t.starts_with(field.as_str())
                        && t[field.len()..].trim_start().starts_with('=')
                })
                .map(|i| i + 1)
        });
        Err(SceneError { file: self.file.to_path_buf(), line, field, message: message.into() })
    }
}

/// Which library settings an error comes from: the table that maps its fields to scene keys.
#[derive(Clone, Copy, Debug)]
pub(super) enum Owner {
    /// [`mpc::ControllerSettings::validate`] (fields as named there).
    Controller,
    /// [`mpc::Scenario::validate`] (its own fields, `mpc.<field>`, `plant.<field>`).
    Scenario,
}

/// The scene key of each settings field that the `mpc` crate's `validate()`s name: `(owner,
/// library field, scene key)`. A field not listed is reported against its owner's table.
const KEYS: &[(&str, &str, &str)] = &[
    ("controller", "max_iterations", "controller.max_iterations"),
    ("controller", "first_sample_iterations", "controller.first_sample_iterations"),
    ("controller", "first_sample_continuation", "controller.first_sample_continuation"),
    ("controller", "rollout_intervals", "controller.rollout_intervals"),
    (
        "controller",
        "first_sample_levenberg_marquardt",
        "controller.first_sample_levenberg_marquardt",
    ),
    ("controller", "kkt_tolerance", "controller.kkt_tolerance"),
    ("controller", "accept_violation", "controller.accept_violation"),
    ("controller", "levenberg_marquardt", "controller.levenberg_marquardt"),
    ("controller", "retry_levenberg_marquardt", "controller.retry_levenberg_marquardt"),
    ("controller", "retry_relaxation", "controller.retry_relaxation"),
    ("controller", "plan_joint_limit_deg", "controller.plan_joint_limit_deg"),
    ("controller", "integrator.substeps", "controller.substeps"),
    ("controller", "integrator.tail.substeps", "controller.tail_substeps"),
    ("controller", "integrator.tail.from_interval", "controller.tail_from_interval"),
    ("controller", "integrator.tail", "controller.tail_substeps"),
    ("controller", "integrator.newton_tolerance", "controller.newton_tolerance"),
    ("controller", "kind", "controller.kind"),
    ("controller", "link_elastic_modes", "controller.link_elastic_modes"),
    ("scenario", "mpc.kx1", "controller.weights.kx1"),
    ("scenario", "mpc.kx2", "controller.weights.kx2"),
    ("scenario", "mpc.k_dxi", "controller.weights.k_dxi"),
    ("scenario", "mpc.ku", "controller.weights.ku"),
    ("scenario", "mpc.k_xi_rigid", "controller.weights.k_xi_rigid"),
    ("scenario", "mpc.k_xi_elastic", "controller.weights.k_xi_elastic"),
    ("scenario", "mpc.u_max", "controller.weights.u_max"),
    ("scenario", "mpc.horizon", "scenario.horizon"),
    ("scenario", "mpc.sampling", "scenario.sampling"),
    ("scenario", "mpc.intervals", "scenario.intervals"),
    ("scenario", "duration", "scenario.duration"),
    ("scenario", "output_interval", "scenario.output_interval"),
    ("scenario", "snapshot_interval", "scenario.snapshot_interval"),
    ("scenario", "rom_plant_substeps", "scenario.rom_plant_substeps"),
    ("scenario", "omega_direction", "scenario.axis"),
    ("scenario", "center", "scenario.center"),
    ("scenario", "root", "scenario.root"),
    ("scenario", "inputs", "scenario"),
    ("scenario", "plant.dt", "run.dt"),
    ("scenario", "plant.newton_tolerance", "run.newton_tolerance"),
];

/// Scene-file advice appended to a library message, by scene key.
const HINTS: &[(&str, &str)] = &[(
    "scenario",
    "mark [[loads]] or [[torques]] with `control = true` (the closed loop's inputs)",
)];

impl Ctx<'_> {
    /// A settings error of the `mpc` crate at the scene key of the field it names ([`KEYS`]),
    /// on that key's line.
    pub(super) fn library<T>(
        &self,
        spec: &SceneSpec,
        owner: Owner,
        e: mpc::MpcError,
    ) -> Result<T, SceneError> {
        let table = match owner {
            Owner::Controller => "controller",
            Owner::Scenario => "scenario",
        };
        let (key, message) = match &e {
            mpc::MpcError::Invalid { field, value, reason } => (
                KEYS.iter()
                    .find(|(o, f, _)| *o == table && f == field)
                    .map_or(table, |(_, _, k)| *k),
                format!("{reason}, got {value}"),
            ),
            _ => (table, e.to_string()),
        };
        let message = match HINTS.iter().find(|(k, _)| *k == key) {
            Some((_, hint)) => format!("{message}: {hint}"),
            None => message,
        };
        let span = if key.starts_with("controller.weights.") {
            spec.controller.as_ref().and_then(|c| c.get_ref().weights.as_ref()).map(|w| w.span())
        } else if key.starts_with("controller") {
            spec.controller.as_ref().map(|c| c.span())
        } else if key.starts_with("run") {
            Some(spec.run.span())
        } else {
            spec.scenario.as_ref().map(|s| s.span())
        };
        self.err(span, key, message)
    }
}

/// The table path (e.g. `beams[1]`) in effect at byte `offset`.
pub(super) fn table_at(text: &str, offset: usize) -> Option<String> {
    let mut current: Option<String> = None;
    let mut counts: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    let mut pos = 0;
    for line in text.split_inclusive('\n') {
        if pos > offset {
            break;
        }
        let t = line.trim();
        if let Some(name) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
            let c = counts.entry(name.trim().to_string()).or_insert(0);
            current = Some(format!("{}[{}]", name.trim(), *c));
            *c += 1;
        } else if let Some(name) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
            current = Some(name.trim().to_string());
        }
        pos += line.len();
    }
    current
}

/// The dotted field path (`table.key`) of the `key = value` line containing byte `offset`.
pub(super) fn field_at(text: &str, offset: usize) -> String {
    let start = text[..offset.min(text.len())].rfind('\n').map(|i| i + 1).unwrap_or(0);
    let line = text[start..].lines().next().unwrap_or("");
    let key = line.split('=').next().unwrap_or("").trim().to_string();
    match (table_at(text, offset), key.is_empty() || !line.contains('=')) {
        (Some(t), false) => format!("{t}.{key}"),
        (None, false) => key,
        (Some(t), true) => t,
        (None, true) => "(syntax)".into(),
    }
}

pub(super) fn field_from_message(m: &str) -> Option<String> {
    let start = m.find('`')?;
    let rest = &m[start + 1..];
    let end = rest.find('`')?;
    Some(rest[..end].to_string())
}

/// The scene entry (span and field) a structure error is about, from the error's typed
/// fields: the joint or support that owns it (the owner labels of `multibody_constraints`,
/// "joint `name`" and "support `name`"; the last one listed when several are involved),
/// else the beam it names.
pub(super) fn entry_of(
    spec: &SceneSpec,
    e: &MultibodyError,
) -> (Option<std::ops::Range<usize>>, String) {
    let beam = |name: &str, placement: bool| {
        spec.beams.iter().enumerate().find(|(_, b)| b.get_ref().name == name).map(|(i, b)| {
            let field = if placement && b.get_ref().attach.is_some() {
                format!("beams[{i}].attach")
            } else {
                format!("beams[{i}] (`{name}`)")
            };
            (Some(b.span()), field)
        })
    };
    // (label, span, field) of every joint and support
    let owners = spec
        .joints
        .iter()
        .enumerate()
        .map(|(i, j)| ("joint", "joints", i, j))
        .chain(spec.supports.iter().enumerate().map(|(i, s)| ("support", "supports", i, s)))
        .map(|(what, table, i, j)| {
            let name = &j.get_ref().name;
            (format!("{what} `{name}`"), j.span(), format!("{table}[{i}] (`{name}`)"))
        })
        .collect::<Vec<_>>();
    let owner = |label: &str| {
        owners.iter().find(|(l, _, _)| l == label).map(|(_, s, f)| (Some(s.clone()), f.clone()))
    };
    let of_owner = |o: &StructureOwner| match o {
        StructureOwner::Joint(_) | StructureOwner::Support(_) => owner(&o.to_string()),
        StructureOwner::Beam(n) => beam(n, false),
        StructureOwner::Placement(n) => beam(n, true),
        _ => None,
    };
    let found = match e {
        MultibodyError::UnknownBeam { owner: o, .. }
        | MultibodyError::UnknownEnd { owner: o, .. }
        | MultibodyError::ZeroAxis { owner: o, .. }
        | MultibodyError::NotPlanar { owner: o, .. } => of_owner(o),
        MultibodyError::EndUsedTwice { second, .. } => of_owner(second),
        MultibodyError::TooFewEnds { joint, .. } => owner(&format!("joint `{joint}`")),
        MultibodyError::DuplicateName { name, .. } => owner(&format!("joint `{name}`"))
            .or_else(|| owner(&format!("support `{name}`")))
            .or_else(|| beam(name, false)),
        MultibodyError::BadPlacement { beam: b, .. } => beam(b, true),
        MultibodyError::RedundantConstraints { involved, .. } => owners
            .iter()
            .filter_map(|(l, s, f)| involved.rfind(l.as_str()).map(|at| (at, s, f)))
            .max_by_key(|(at, _, _)| *at)
            .map(|(_, s, f)| (Some(s.clone()), f.clone())),
        _ => None,
    };
    found.unwrap_or((None, "(structure)".into()))
}
