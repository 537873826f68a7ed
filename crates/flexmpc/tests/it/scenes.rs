//! Scene files end to end: the scene reference of `docs/guide.md` against the parser's fields
//! and against the scenes that exercise them, every shipped scene loads and runs briefly,
//! malformed scenes give `file:line: field` errors that say what is allowed, and golden CSV
//! outputs of two small fixtures.
//!
//! `UPDATE_GOLDEN=1 cargo test --release -p flexmpc --test it scenes` rewrites the goldens.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

use flexmpc::scene;

fn manifest_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn workspace_root() -> PathBuf {
    manifest_dir().join("../..")
}

/// The `.toml` files of a folder, sorted.
fn toml_files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().and_then(|e| e.to_str()) == Some("toml"))
        .collect();
    v.sort();
    v
}

fn shipped_scenes() -> Vec<PathBuf> {
    toml_files(&workspace_root().join("scenes"))
}

fn fixture_scenes() -> Vec<PathBuf> {
    toml_files(&manifest_dir().join("tests/fixtures"))
}

/// A fresh, empty scratch folder under the target directory's temp space.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("flexmpc-scenes-test-{}", std::process::id()));
    let dir = dir.join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

// ---------------------------------------------------------------------------------------------
// Field coverage: guide ↔ parser ↔ scenes
// ---------------------------------------------------------------------------------------------

/// The TOML path of a scene-reference heading: its first backquoted token, `[[beams]]` →
/// `beams[]`, `[sections.<name>]` → `sections.*`, `[run]` → `run`; no token → top level.
fn heading_path(heading: &str) -> String {
    let Some(tok) = heading.split('`').nth(1) else {
        return String::new();
    };
    let (inner, array) = if let Some(t) = tok.strip_prefix("[[").and_then(|t| t.strip_suffix("]]"))
    {
        (t, true)
    } else if let Some(t) = tok.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        (t, false)
    } else {
        (tok, false)
    };
    let inner: Vec<String> = inner
        .split('.')
        .map(|s| if s.starts_with('<') && s.ends_with('>') { "*".to_string() } else { s.into() })
        .collect();
    let mut p = inner.join(".");
    if array {
        p.push_str("[]");
    }
    p
}

fn join(prefix: &str, key: &str) -> String {
    if prefix.is_empty() {
        key.to_string()
    } else {
        format!("{prefix}.{key}")
    }
}

/// The documented scene fields: every row of every `| field | type | units | default |
/// meaning |` table of docs/guide.md, as a TOML path (e.g. `beams[].attach.joint`), with the
/// guide's line number.
fn documented_fields() -> BTreeMap<String, usize> {
    let guide = workspace_root().join("docs/guide.md");
    let text = std::fs::read_to_string(&guide).expect("docs/guide.md exists");
    let mut out = BTreeMap::new();
    let mut heading = String::new();
    let mut in_table = false;
    let mut tables = 0;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim();
        if t.starts_with('#') {
            heading = heading_path(t);
            in_table = false;
            continue;
        }
        if !t.starts_with('|') {
            in_table = false;
            continue;
        }
        let cells: Vec<&str> = t.trim_matches('|').split('|').map(str::trim).collect();
        if cells == ["field", "type", "units", "default", "meaning"] {
            in_table = true;
            tables += 1;
            continue;
        }
        if !in_table || cells.iter().all(|c| c.chars().all(|ch| ch == '-' || ch == ':')) {
            continue;
        }
        assert_eq!(
            cells.len(),
            5,
            "docs/guide.md:{}: a scene-reference row has 5 cells (field | type | units | \
             default | meaning), got {}: {t}",
            i + 1,
            cells.len()
        );
        assert!(cells.iter().all(|c| !c.is_empty()), "docs/guide.md:{}: empty cell: {t}", i + 1);
        let field = cells[0].trim_matches('`');
        let path = join(&heading, field);
        if let Some(prev) = out.insert(path.clone(), i + 1) {
            panic!("docs/guide.md:{}: `{path}` already documented at line {prev}", i + 1);
        }
    }
    assert!(tables >= 10, "docs/guide.md has only {tables} scene-reference tables");
    out
}

/// A `pub struct …Spec` of scene/spec.rs: its serde field names and their Rust types.
struct SpecStruct {
    fields: Vec<(String, String)>,
}

/// Library settings types that the scene deserialises directly (the type's last path segment,
/// as spec.rs writes it, and its source file relative to this crate).
const LIBRARY_TYPES: [(&str, &str); 3] = [
    ("KindCounts", "../modal-rom/src/basis.rs"),
    ("CostWeights", "../mpc/src/weights.rs"),
    ("Timing", "../mpc/src/weights.rs"),
];

/// The spec structs of crates/flexmpc/src/scene/spec.rs and the [`LIBRARY_TYPES`] (by a simple
/// parse of `pub name: Type,` lines between `pub struct XxxSpec {` (or `pub struct KindCounts {`)
/// and the closing `}`; `#[serde(rename = "…")]`, `#[serde(flatten)]` (the field's name is then
/// empty: its type's fields sit in the same table) and `rename_all = "kebab-case"` are
/// honoured).
fn spec_structs() -> BTreeMap<String, SpecStruct> {
    let mut out = BTreeMap::new();
    let src = std::fs::read_to_string(manifest_dir().join("src/scene/spec.rs")).unwrap();
    parse_structs(&src, |name| name.ends_with("Spec"), &mut out);
    for (name, file) in LIBRARY_TYPES {
        let src = std::fs::read_to_string(manifest_dir().join(file)).unwrap();
        parse_structs(&src, |n| n == name, &mut out);
        assert!(out.contains_key(name), "{file} has no `pub struct {name} {{`");
    }
    assert!(out.contains_key("SceneSpec"), "scene/spec.rs has no `pub struct SceneSpec {{`");
    out
}

/// The `pub struct`s of `src` whose names pass `wanted`, into `out`.
fn parse_structs(src: &str, wanted: impl Fn(&str) -> bool, out: &mut BTreeMap<String, SpecStruct>) {
    let mut current: Option<(String, SpecStruct, bool)> = None;
    let mut kebab_next = false;
    let mut rename: Option<String> = None;
    let mut flatten = false;
    for line in src.lines() {
        let t = line.trim();
        if current.is_none() {
            if t.starts_with("#[serde(") && t.contains("rename_all = \"kebab-case\"") {
                kebab_next = true;
            }
            if let Some(rest) = t.strip_prefix("pub struct ") {
                let name: String =
                    rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                if wanted(&name) && t.ends_with('{') {
                    current = Some((name, SpecStruct { fields: Vec::new() }, kebab_next));
                }
                kebab_next = false;
            } else if t.starts_with("pub enum ") || t.starts_with("pub fn ") {
                kebab_next = false;
            }
            continue;
        }
        if t == "}" {
            let (name, s, _) = current.take().unwrap();
            out.insert(name, s);
            continue;
        }
        if let Some(r) = t.strip_prefix("#[serde(rename = \"") {
            rename = r.split('"').next().map(str::to_string);
            continue;
        }
        if t == "#[serde(flatten)]" {
            flatten = true;
            continue;
        }
        if let Some(rest) = t.strip_prefix("pub ") {
            if let Some((name, ty)) = rest.split_once(':') {
                let (_, s, kebab) = current.as_mut().unwrap();
                let mut name = rename.take().unwrap_or_else(|| name.trim().to_string());
                if *kebab {
                    name = name.replace('_', "-");
                }
                if std::mem::take(&mut flatten) {
                    name.clear();
                }
                s.fields.push((name, ty.trim().trim_end_matches(',').to_string()));
            }
        }
    }
}

/// Every field path the parser accepts (leaves and nested tables), walking the spec structs
/// from `SceneSpec`: `Vec<…Spec>` → `name[]`, maps → `name.*`.
fn parser_fields() -> (BTreeSet<String>, BTreeSet<String>) {
    fn walk(
        prefix: &str,
        name: &str,
        structs: &BTreeMap<String, SpecStruct>,
        leaves: &mut BTreeSet<String>,
        tables: &mut BTreeSet<String>,
    ) {
        for (field, ty) in &structs[name].fields {
            let path = join(prefix, field);
            let child = ty
                .split(|c: char| !c.is_alphanumeric() && c != '_')
                .find(|tok| structs.contains_key(*tok));
            match child {
                Some(c) if field.is_empty() => walk(prefix, c, structs, leaves, tables),
                Some(c) => {
                    let p = if ty.contains("Vec<") {
                        format!("{path}[]")
                    } else if ty.contains("Map<") {
                        format!("{path}.*")
                    } else {
                        path
                    };
                    tables.insert(p.clone());
                    walk(&p, c, structs, leaves, tables);
                }
                None => {
                    leaves.insert(path);
                }
            }
        }
    }
    let structs = spec_structs();
    let (mut leaves, mut tables) = (BTreeSet::new(), BTreeSet::new());
    walk("", "SceneSpec", &structs, &mut leaves, &mut tables);
    (leaves, tables)
}

/// Every field path used by a scene file (`sections.*` for map entries, `[]` for arrays of
/// tables).
fn used_fields(text: &str, maps: &BTreeSet<String>, out: &mut BTreeSet<String>) {
    fn walk(v: &toml::Value, prefix: &str, maps: &BTreeSet<String>, out: &mut BTreeSet<String>) {
        match v {
            toml::Value::Table(t) => {
                for (k, x) in t {
                    let key = if maps.contains(&format!("{prefix}.*")) { "*" } else { k };
                    let p = join(prefix, key);
                    out.insert(p.clone());
                    walk(x, &p, maps, out);
                }
            }
            toml::Value::Array(a) if !a.is_empty() && a.iter().all(|x| x.is_table()) => {
                let p = format!("{prefix}[]");
                out.insert(p.clone());
                for x in a {
                    walk(x, &p, maps, out);
                }
            }
            _ => {}
        }
    }
    let v: toml::Value = toml::from_str(text).expect("valid TOML");
    walk(&v, "", maps, out);
}

/// Every documented field is one the parser accepts, and every field the parser accepts is
/// documented.
#[test]
fn guide_documents_exactly_the_parser_fields() {
    let documented = documented_fields();
    let (leaves, tables) = parser_fields();
    let undocumented: Vec<&String> =
        leaves.iter().filter(|f| !documented.contains_key(*f)).collect();
    assert!(
        undocumented.is_empty(),
        "fields accepted by the scene parser but missing from docs/guide.md: {undocumented:?}"
    );
    let unknown: Vec<String> = documented
        .iter()
        .filter(|(f, _)| !leaves.contains(*f) && !tables.contains(*f))
        .map(|(f, l)| format!("{f} (docs/guide.md:{l})"))
        .collect();
    assert!(
        unknown.is_empty(),
        "documented fields that the scene parser does not accept: {unknown:?}"
    );
}

/// Fields the parser reads only to reject them with a pointed message (a joint's `end`, a
/// support's `ends`): exercised by a malformed case (by name) instead of a scene that loads.
const ERROR_ONLY: [(&str, &str); 2] =
    [("joints[].end", "a joint given `end`"), ("supports[].ends", "a support given `ends`")];

/// Every documented field appears in a shipped scene or in a fixture scene, and each of those
/// scenes loads.
#[test]
fn every_documented_field_is_exercised_by_a_scene_that_loads() {
    let documented = documented_fields();
    let (_, tables) = parser_fields();
    let maps: BTreeSet<String> =
        tables.iter().filter_map(|t| t.strip_suffix(".*").map(str::to_string)).collect();
    let maps: BTreeSet<String> = maps.iter().map(|m| format!("{m}.*")).collect();
    let mut used = BTreeSet::new();
    for path in shipped_scenes().into_iter().chain(fixture_scenes()) {
        let text = std::fs::read_to_string(&path).unwrap();
        used_fields(&text, &maps, &mut used);
        if let Err(e) = scene::load(&path) {
            panic!("{e}");
        }
    }
    let names: Vec<&str> = cases().iter().map(|c| c.name).collect();
    for (field, case) in ERROR_ONLY {
        assert!(names.contains(&case), "no malformed case `{case}` for {field}");
        used.insert(field.to_string());
    }
    let unexercised: Vec<String> = documented
        .iter()
        .filter(|(f, _)| !used.contains(*f))
        .map(|(f, l)| format!("{f} (docs/guide.md:{l})"))
        .collect();
    assert!(
        unexercised.is_empty(),
        "documented fields used by no scene in scenes/ or crates/flexmpc/tests/fixtures/: \
         {unexercised:?}"
    );
}

// ---------------------------------------------------------------------------------------------
// Shipped scenes and fixtures run
// ---------------------------------------------------------------------------------------------

/// Whether a scene is a closed-loop (MPC) scene rather than a plain simulation.
fn is_mpc_scene(text: &str) -> bool {
    text.lines().any(|l| {
        let t = l.trim();
        t == "[controller]" || t == "[scenario]" || t == "[sweep]"
    })
}

/// Reads a CSV written by `simulate`: header and rows of numbers.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(str::to_string).collect();
    let rows = lines
        .map(|l| {
            l.split(',')
                .map(|x| x.parse::<f64>().unwrap_or_else(|_| panic!("{}: `{x}`", path.display())))
                .collect::<Vec<f64>>()
        })
        .collect();
    (header, rows)
}

/// Every shipped scene (and fixture) passes `scene::load`; the non-MPC ones run their first 20
/// steps through `run::simulate` (the full runs take minutes: CI runs them from the CLI), and
/// the CSV has the expected rows, all finite.
#[test]
fn shipped_scenes_and_fixtures_load_and_run_briefly() {
    let scenes = shipped_scenes();
    assert!(scenes.len() >= 5, "only {} shipped scenes", scenes.len());
    for path in scenes.iter().chain(fixture_scenes().iter()) {
        let text = std::fs::read_to_string(path).unwrap();
        let mut s = scene::load(path).unwrap_or_else(|e| panic!("{e}"));
        if is_mpc_scene(&text) {
            continue;
        }
        let steps = s.steps.min(20);
        s.steps = steps;
        s.output_every = 5;
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let out = scratch(&format!("brief-{stem}"));
        let summary = flexmpc::run::simulate(s, &out, true)
            .unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
        assert_eq!(summary.steps, steps);
        let (header, rows) = read_csv(&summary.csv);
        assert_eq!(rows.len(), 1 + steps.div_ceil(5), "{}", path.display());
        for r in &rows {
            assert_eq!(r.len(), header.len(), "{}", path.display());
            assert!(r.iter().all(|x| x.is_finite()), "{}: {r:?}", path.display());
        }
        // The step count moves time by dt per step.
        let t_end = rows.last().unwrap()[0];
        assert!(t_end > 0.0 || steps == 0, "{}: t_end = {t_end}", path.display());
    }
}

/// `flexmpc check` accepts every shipped scene and fixture (exit code 0, summary on stdout).
#[test]
fn cli_check_accepts_every_shipped_scene() {
    for path in shipped_scenes().iter().chain(fixture_scenes().iter()) {
        let out = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
            .arg("check")
            .arg(path)
            .output()
            .expect("the binary runs");
        assert!(
            out.status.success(),
            "{}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains("ok"), "{}", path.display());
    }
}

// ---------------------------------------------------------------------------------------------
// Malformed scenes
// ---------------------------------------------------------------------------------------------

/// A valid spatial scene touching most sections; each malformed case edits one spot of it.
const BASE: &str = r#"description = "malformed-scene base"
components = "spatial"
gravity = [0.0, 0.0, -9.81]

[sections.link]
preset = "paper-3d"

[sections.rod]
mass = [1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4]
stiffness = [1000.0, 1e5, 1e5, 0.05, 1.0, 2.0]

[[beams]]
name = "a"
section = "link"
length = 1.0
elements = 4

[[beams]]
name = "b"
section = "rod"
length = 1.0
elements = 4
attach = { joint = "elbow", axis = [0.0, 0.0, 1.0], angle_deg = 30.0 }

[[joints]]
name = "elbow"
kind = "hinge"
ends = ["a:end", "b:start"]
axis = [0.0, 0.0, 1.0]

[[supports]]
name = "root"
end = "a:start"
kind = "weld"

[[loads]]
name = "tip"
beam = "b"
node = "end"
frame = "follower"
force = [0.0, 0.0, 0.1]
amplitude = { ramp = 0.5 }

[[torques]]
joint = "elbow"
value = 0.1

[[initial.rigid]]
beams = ["b"]
omega = [0.0, 0.0, 0.0]

[run]
dt = 1e-3
duration = 0.01
output_every = 2

[output]
plot = ["b.end.z"]
"#;

/// One malformed scene: replace `from` by `to` (first occurrence) in [`BASE`]; the error must
/// be on the line containing `at` (first such line of the edited text), name `field` and
/// contain `allowed` (what is allowed / expected).
struct Case {
    name: &'static str,
    from: &'static str,
    to: &'static str,
    at: &'static str,
    field: &'static str,
    allowed: &'static str,
}

const fn case(
    name: &'static str,
    from: &'static str,
    to: &'static str,
    at: &'static str,
    field: &'static str,
    allowed: &'static str,
) -> Case {
    Case { name, from, to, at, field, allowed }
}

const BEAM_B: &str = "name = \"b\"\nsection = \"rod\"\nlength = 1.0\nelements = 4\n";
const ROD_STIFFNESS: &str = "stiffness = [1000.0, 1e5, 1e5, 0.05, 1.0, 2.0]";
const ROD_MASS: &str = "mass = [1.0, 1.0, 1.0, 2e-4, 1e-4, 1e-4]";
const BEAMS: &str = "[[beams]]\nname = \"a\"\nsection = \"link\"\nlength = 1.0\nelements = 4\n\n\
                     [[beams]]\nname = \"b\"\nsection = \"rod\"\nlength = 1.0\nelements = 4\n\
                     attach = { joint = \"elbow\", axis = [0.0, 0.0, 1.0], angle_deg = 30.0 }\n";

fn cases() -> Vec<Case> {
    vec![
        case(
            "wrong type (string for a number)",
            "length = 1.0\nelements = 4\n\n",
            "length = \"one\"\nelements = 4\n\n",
            "length = \"one\"",
            "beams[0].length",
            "expected",
        ),
        case(
            "wrong array length",
            "force = [0.0, 0.0, 0.1]",
            "force = [0.0, 0.1]",
            "force = [0.0, 0.1]",
            "loads[0].force",
            "3",
        ),
        case(
            "unknown field (typo)",
            "length = 1.0\nelements = 4\nattach",
            "lenght = 1.0\nelements = 4\nattach",
            "lenght",
            "beams[1].lenght",
            "expected one of",
        ),
        case(
            "unknown top-level key",
            "gravity = [",
            "gravty = [",
            "gravty",
            "gravty",
            "expected one of",
        ),
        case("missing beams", BEAMS, "", "description", "beams", "missing field"),
        case("missing dt", "dt = 1e-3\n", "", "[run]", "run.dt", "missing field"),
        case(
            "negative length",
            BEAM_B,
            "name = \"b\"\nsection = \"rod\"\nlength = -1.0\nelements = 4\n",
            "length = -1.0",
            "beams[1].length",
            "positive",
        ),
        case(
            "zero elements",
            BEAM_B,
            "name = \"b\"\nsection = \"rod\"\nlength = 1.0\nelements = 0\n",
            "elements = 0",
            "beams[1].elements",
            "at least 1",
        ),
        case(
            "bad joint kind",
            "kind = \"hinge\"",
            "kind = \"slider\"",
            "slider",
            "joints[0].kind",
            "`weld`, `ball`, `hinge`, `universal`, `wheel`, `custom`",
        ),
        case(
            "joint end used twice",
            "end = \"a:start\"",
            "end = \"a:end\"",
            "[[supports]]",
            "supports[0]",
            "used twice",
        ),
        case(
            "unknown section preset",
            "preset = \"paper-3d\"",
            "preset = \"paper-4d\"",
            "paper-4d",
            "sections.link.preset",
            "expected `paper-2d` or `paper-3d`",
        ),
        case(
            "NaN in a section",
            ROD_STIFFNESS,
            "stiffness = [1000.0, nan, 1e5, 0.05, 1.0, 2.0]",
            "[sections.rod]",
            "sections.rod",
            "positive",
        ),
        case(
            "indefinite section (negative mass)",
            ROD_MASS,
            "mass = [1.0, -1.0, 1.0, 2e-4, 1e-4, 1e-4]",
            "[sections.rod]",
            "sections.rod",
            "positive",
        ),
        case(
            "preset and explicit diagonals together",
            "preset = \"paper-3d\"",
            "preset = \"paper-3d\"\nmass = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]",
            "preset = \"paper-3d\"",
            "sections.link.preset",
            "not both",
        ),
        case(
            "section without preset or stiffness",
            "stiffness = [1000.0, 1e5, 1e5, 0.05, 1.0, 2.0]\n",
            "",
            ROD_MASS,
            "sections.rod.mass",
            "give `preset`",
        ),
        case(
            "negative stiffness factor",
            "preset = \"paper-3d\"",
            "preset = \"paper-3d\"\nstiffness_factor = -2.0",
            "stiffness_factor",
            "sections.link.stiffness_factor",
            "positive",
        ),
        case(
            "unknown section name",
            "section = \"rod\"",
            "section = \"bar\"",
            "section = \"bar\"",
            "beams[1].section",
            "sections: link, rod",
        ),
        case("dt = 0", "dt = 1e-3", "dt = 0.0", "dt = 0.0", "run.dt", "positive"),
        case("dt < 0", "dt = 1e-3", "dt = -1e-3", "dt = -1e-3", "run.dt", "positive"),
        case(
            "negative duration",
            "duration = 0.01",
            "duration = -1.0",
            "duration = -1.0",
            "run.duration",
            "non-negative",
        ),
        case(
            "output_every = 0",
            "output_every = 2",
            "output_every = 0",
            "output_every = 0",
            "run.output_every",
            "at least 1",
        ),
        case(
            "unknown end name",
            "ends = [\"a:end\", \"b:start\"]",
            "ends = [\"a:end\", \"b:middle\"]",
            "b:middle",
            "joints[0].ends",
            "allowed: start, end",
        ),
        case(
            "unknown beam in joint ends",
            "ends = [\"a:end\", \"b:start\"]",
            "ends = [\"a:end\", \"z:start\"]",
            "z:start",
            "joints[0].ends",
            "beams: a, b",
        ),
        case(
            "end without beam:end form",
            "end = \"a:start\"",
            "end = \"a\"",
            "end = \"a\"",
            "supports[0].end",
            "beam:start",
        ),
        case(
            "axis of zero length",
            "axis = [0.0, 0.0, 1.0]\n\n[[supports]]",
            "axis = [0.0, 0.0, 0.0]\n\n[[supports]]",
            "[[joints]]",
            "joints[0]",
            "axis",
        ),
        case(
            "hinge without axis",
            "ends = [\"a:end\", \"b:start\"]\naxis = [0.0, 0.0, 1.0]",
            "ends = [\"a:end\", \"b:start\"]",
            "[[joints]]",
            "joints[0].axis",
            "axis = [x, y, z]",
        ),
        case(
            "bad joint frame",
            "kind = \"hinge\"",
            "kind = \"hinge\"\nframe = \"local\"",
            "frame = \"local\"",
            "joints[0].frame",
            "allowed: global, each-end, end-N",
        ),
        case(
            "custom joint with a bad freedom",
            "kind = \"hinge\"",
            "kind = \"custom\"\ntranslation = [\"rigid\", \"loose\", \"rigid\"]\n\
             rotation = [\"rigid\", \"rigid\", \"free\"]",
            "translation = [",
            "joints[0].translation",
            "`loose`, expected `rigid` or `free`",
        ),
        case(
            "custom joint without rotation freedoms",
            "kind = \"hinge\"",
            "kind = \"custom\"\ntranslation = [\"rigid\", \"rigid\", \"rigid\"]",
            "[[joints]]",
            "joints[0].rotation",
            "`rigid` or `free`",
        ),
        case(
            "a support given `ends`",
            "end = \"a:start\"",
            "ends = [\"a:start\"]",
            "[[supports]]",
            "supports[0].end",
            "end = \"beam:start\"",
        ),
        case(
            "a joint given `end`",
            "ends = [\"a:end\", \"b:start\"]",
            "end = \"a:end\"",
            "[[joints]]",
            "joints[0].ends",
            "ends = [",
        ),
        case(
            "attach and origin together",
            "attach = { joint",
            "origin = [0.0, 0.0, 0.0]\nattach = { joint",
            "attach = { joint",
            "beams[1].attach",
            "not both",
        ),
        case(
            "attach to an unknown joint",
            "attach = { joint = \"elbow\"",
            "attach = { joint = \"knee\"",
            "attach = { joint",
            "beams[1].attach",
            "knee",
        ),
        case(
            "load on a node that does not exist",
            "node = \"end\"",
            "node = 9",
            "node = 9",
            "loads[0].node",
            "0..=4",
        ),
        case(
            "load on a bad node name",
            "node = \"end\"",
            "node = \"middle\"",
            "node = \"middle\"",
            "loads[0].node",
            "start, end",
        ),
        case(
            "load on an unknown beam",
            "beam = \"b\"\nnode",
            "beam = \"c\"\nnode",
            "beam = \"c\"",
            "loads[0].beam",
            "beams: a, b",
        ),
        case(
            "bad load frame",
            "frame = \"follower\"",
            "frame = \"body\"",
            "frame = \"body\"",
            "loads[0].frame",
            "expected `follower` or `dead`",
        ),
        case(
            "non-finite load",
            "force = [0.0, 0.0, 0.1]",
            "force = [0.0, 0.0, inf]",
            "force = [0.0, 0.0, inf]",
            "loads[0].force",
            "finite",
        ),
        case(
            "amplitude with ramp and table",
            "amplitude = { ramp = 0.5 }",
            "amplitude = { ramp = 0.5, table = [[0.0, 1.0]] }",
            "amplitude = {",
            "loads[0].amplitude",
            "exactly one",
        ),
        case(
            "torque on an unknown joint",
            "joint = \"elbow\"\nvalue",
            "joint = \"wrist\"\nvalue",
            "joint = \"wrist\"",
            "torques[0].joint",
            "wrist",
        ),
        case(
            "initial rotation of an unknown beam",
            "beams = [\"b\"]",
            "beams = [\"q\"]",
            "beams = [\"q\"]",
            "initial.rigid[0].beams",
            "unknown beam `q`",
        ),
        case(
            "bad components",
            "components = \"spatial\"",
            "components = \"3d\"",
            "components",
            "components",
            "expected `planar` or `spatial`",
        ),
        case(
            "more steps than a run can take",
            "duration = 0.01",
            "duration = 1e15",
            "duration = 1e15",
            "run.duration",
            "at most",
        ),
        case(
            "duration not a multiple of dt (the run would end at t = 10)",
            "dt = 1e-3\nduration = 0.01",
            "dt = 10.0\nduration = 6.0",
            "duration = 6.0",
            "run.duration",
            "whole multiple",
        ),
        case(
            "TOML syntax error",
            "length = 1.0\nelements = 4\n\n",
            "length = 1.0.0\nelements = 4\n\n",
            "length = 1.0.0",
            "beams[0]",
            "",
        ),
    ]
}

/// Malformed closed-loop sections, as edits of the fixture `mpc-lowest.toml`.
fn mpc_cases() -> Vec<Case> {
    vec![
        case(
            "load that is not a control input in a closed-loop scene",
            "force = [0.0, 0.0, 1.0]\ncontrol = true",
            "force = [0.0, 0.0, 1.0]",
            "[[loads]]",
            "loads[0].control",
            "control = true",
        ),
        case(
            "control load in the dead frame",
            "frame = \"follower\"",
            "frame = \"dead\"",
            "frame = \"dead\"",
            "loads[0].frame",
            "follower",
        ),
        case(
            "control torque with a value other than 1",
            "value = 1.0",
            "value = 0.5",
            "value = 0.5",
            "torques[0].value",
            "must be 1",
        ),
        case(
            "two mode selections",
            "lowest = 5",
            "lowest = 5\nindices = [0, 1]",
            "[modes]",
            "modes",
            "only one of",
        ),
        case(
            "zero lowest modes",
            "lowest = 5",
            "lowest = 0",
            "lowest = 0",
            "modes.lowest",
            "at least 1",
        ),
        case(
            "unknown controller kind",
            "[scenario]",
            "[controller]\nkind = \"pid\"\n\n[scenario]",
            "kind = \"pid\"",
            "controller.kind",
            "nmpc",
        ),
        case(
            "unknown plant",
            "plant = \"rom\"",
            "plant = \"exact\"",
            "plant = \"exact\"",
            "scenario.plant",
            "fe",
        ),
        case(
            "scenario without axis",
            "axis = [0.0, 1.0, 0.0]\nduration",
            "duration",
            "[scenario]",
            "scenario.axis",
            "missing field",
        ),
        case(
            "empty sweep",
            "omega0 = [0.5, 1.0]",
            "omega0 = []",
            "omega0 = []",
            "sweep.omega0",
            "at least one",
        ),
        case(
            "more modes than the structure has",
            "lowest = 5",
            "lowest = 10000",
            "lowest = 10000",
            "modes.lowest",
            "10000",
        ),
        case(
            "closed loop with more plant steps than a run can take",
            "duration = 0.4",
            "duration = 1e15",
            "duration = 1e15",
            "scenario.duration",
            "at most",
        ),
        case(
            "unknown weight",
            "[scenario]",
            "[controller.weights]\nkx3 = 1.0\n\n[scenario]",
            "kx3",
            "controller.weights.kx3",
            "expected one of",
        ),
    ]
}

/// Runs one malformed case through `scene::check` (what `flexmpc check` runs) on a real file and returns the error.
fn malformed_error(c: &Case, dir: &Path) -> (PathBuf, usize, scene::SceneError) {
    malformed_error_in(BASE, c, dir)
}

/// As [`malformed_error`], editing `base` instead of [`BASE`].
fn malformed_error_in(base: &str, c: &Case, dir: &Path) -> (PathBuf, usize, scene::SceneError) {
    assert!(base.contains(c.from), "{}: the base scene lacks {:?}", c.name, c.from);
    let text = base.replacen(c.from, c.to, 1);
    let file: String =
        c.name.chars().map(|ch| if ch.is_ascii_alphanumeric() { ch } else { '-' }).collect();
    let path = dir.join(format!("{file}.toml"));
    std::fs::write(&path, &text).unwrap();
    let line = text
        .find(c.at)
        .map(|off| text[..off].matches('\n').count() + 1)
        .unwrap_or_else(|| panic!("{}: {:?} not in the edited text", c.name, c.at));
    match scene::check(&path) {
        Ok(_) => panic!("{}: the malformed scene was accepted:\n{text}", c.name),
        Err(e) => (path, line, e),
    }
}

/// At least 25 malformed scenes: each error names the file, the line of the offending entry
/// and the field, and says what is allowed.
#[test]
fn malformed_scenes_name_file_line_field_and_what_is_allowed() {
    let dir = scratch("malformed");
    let cases = cases();
    let mpc_base = std::fs::read_to_string(manifest_dir().join("tests/fixtures/mpc-lowest.toml"))
        .expect("the closed-loop fixture");
    let mpc_cases = mpc_cases();
    assert!(cases.len() + mpc_cases.len() >= 25, "only {} cases", cases.len());
    assert!(scene::load_str(Path::new("base.toml"), BASE).is_ok(), "the base scene loads");
    let mut failures = Vec::new();
    let all = cases.iter().map(|c| (BASE, c)).chain(mpc_cases.iter().map(|c| (&*mpc_base, c)));
    for (base, c) in all {
        let (path, line, e) = malformed_error_in(base, c, &dir);
        let msg = e.to_string();
        let mut problems = Vec::new();
        if e.file != path || !msg.starts_with(&format!("{}:", path.display())) {
            problems.push("file".to_string());
        }
        if e.line != Some(line) {
            problems.push(format!("line {:?} (expected {line})", e.line));
        }
        if !e.field.contains(c.field) {
            problems.push(format!("field `{}` (expected `{}`)", e.field, c.field));
        }
        if !e.message.contains(c.allowed) {
            problems.push(format!("message lacks {:?}", c.allowed));
        }
        if !problems.is_empty() {
            failures.push(format!("{}: {}\n    error: {msg}", c.name, problems.join("; ")));
        }
    }
    assert!(failures.is_empty(), "{} case(s) failed:\n{}", failures.len(), failures.join("\n"));
}

/// A value of the right TOML type but out of the Rust type's range (a negative count) names
/// its field. scene.rs used to take the field from the first backquoted word of toml's
/// message, which here is the value ("field `beams[1].-4`"); it now takes the key at the
/// span for "invalid …" messages. Regression test.
#[test]
fn negative_count_names_its_field() {
    let dir = scratch("negative-count");
    let c = case(
        "wrong type (negative element count)",
        "elements = 4\nattach",
        "elements = -4\nattach",
        "elements = -4",
        "beams[1].elements",
        "expected usize",
    );
    let (path, line, e) = malformed_error(&c, &dir);
    assert_eq!(e.file, path);
    assert_eq!(e.line, Some(line));
    assert!(e.message.contains(c.allowed), "{e}");
    assert_eq!(e.field, c.field, "{e}");
}

/// `flexmpc check` on a malformed scene fails with `file:line: field` on stderr.
#[test]
fn cli_check_reports_file_line_and_field() {
    let dir = scratch("cli-malformed");
    let c = &cases()[7]; // negative length
    let (path, line, _) = malformed_error(c, &dir);
    let out = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
        .arg("check")
        .arg(&path)
        .output()
        .expect("the binary runs");
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("{}:{line}: field `{}`", path.display(), c.field)),
        "stderr: {err}"
    );
}

// ---------------------------------------------------------------------------------------------
// Golden outputs
// ---------------------------------------------------------------------------------------------

/// Runs a fixture with `run::simulate` and compares its CSV with `tests/golden/<name>.csv`.
///
/// The run is deterministic (no randomness, fixed orderings, sequential sparse LU): on one
/// machine the CSV is identical byte for byte. Across machines, libm and FMA contraction may
/// move values by a few ulps, which Newton (tolerance 1e-12) carries through as relative
/// differences of order 1e-12; the CSV prints 11 significant digits (`{:.10e}`), so such a
/// difference can still flip the last printed digit. Tolerance per value: `1e-12 |golden| +
/// 1e-12 max|column|` plus one unit in the 11th significant digit (`1e-10 |golden|`) for that
/// printing effect; the column term and an absolute floor of 1e-15 cover values that are
/// roundoff noise around an exact zero (e.g. the clamped end's position, ~1e-35: the noise
/// there depends on the linear solver's operation order, not on the physics; the smallest
/// physical values, e.g. a 4e-11 axial reaction in the first rows, are thereby still checked
/// to 1e-15 absolute). `UPDATE_GOLDEN=1` rewrites the golden file.
fn golden(name: &str) {
    const ABS_FLOOR: f64 = 1e-15;
    let scene_path = manifest_dir().join(format!("tests/fixtures/{name}.toml"));
    let golden_path = manifest_dir().join(format!("tests/golden/{name}.csv"));
    let s = scene::load(&scene_path).unwrap_or_else(|e| panic!("{e}"));
    let out = scratch(&format!("golden-{name}"));
    let summary = flexmpc::run::simulate(s, &out, true).unwrap();
    let produced = std::fs::read_to_string(&summary.csv).unwrap();
    if std::env::var("UPDATE_GOLDEN").is_ok_and(|v| v == "1") {
        std::fs::write(&golden_path, &produced).unwrap();
        return;
    }
    let expected = std::fs::read_to_string(&golden_path).unwrap_or_else(|e| {
        panic!("{}: {e} (run with UPDATE_GOLDEN=1 to create it)", golden_path.display())
    });
    if produced == expected {
        return;
    }
    let (h1, a) = read_csv(&summary.csv);
    let (h0, b) = read_csv(&golden_path);
    assert_eq!(h1, h0, "{name}: columns differ from the golden file");
    assert_eq!(a.len(), b.len(), "{name}: row count differs from the golden file");
    let colmax: Vec<f64> =
        (0..h0.len()).map(|j| b.iter().map(|r| r[j].abs()).fold(0.0, f64::max)).collect();
    for (i, (ra, rb)) in a.iter().zip(&b).enumerate() {
        for j in 0..h0.len() {
            // Newton iteration counts may differ by one where a cross-machine difference
            // moves a residual across the tolerance; everything else as above.
            let tol = if h0[j] == "newton_iterations" {
                1.0
            } else {
                (1e-12 + 1e-10) * rb[j].abs() + 1e-12 * colmax[j] + ABS_FLOOR
            };
            assert!(
                (ra[j] - rb[j]).abs() <= tol,
                "{name}: row {i}, column `{}`: {} vs golden {} (tolerance {tol:.1e})",
                h0[j],
                ra[j],
                rb[j]
            );
        }
    }
}

#[test]
fn golden_cantilever_10_elements() {
    golden("cantilever-10");
}

#[test]
fn golden_two_link_torque() {
    golden("two-link-torque");
}

/// `flexmpc check` refuses what the commands would refuse or run wrongly (the library's own
/// checks), and a `--duration` the closed loop's timing cannot take names the flag and the rule.
#[test]
fn cli_check_and_duration_override_use_the_library_rules() {
    let dir = scratch("cli-rules");
    let fixture = manifest_dir().join("tests/fixtures/mpc-lowest.toml");
    let text = std::fs::read_to_string(&fixture).unwrap();
    let bad = dir.join("lowest-10000.toml");
    std::fs::write(&bad, text.replacen("lowest = 5", "lowest = 10000", 1)).unwrap();
    let run = |args: &[&std::ffi::OsStr]| {
        let out = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
            .args(args)
            .env("RUST_BACKTRACE", "0")
            .output()
            .expect("the binary runs");
        (out.status.success(), String::from_utf8_lossy(&out.stderr).to_string())
    };
    let (ok, err) = run(&["check".as_ref(), bad.as_os_str()]);
    assert!(!ok, "check accepted `lowest = 10000`");
    assert!(err.contains("modes.lowest") && err.contains("10000"), "{err}");
    let (ok, err) = run(&[
        "mpc".as_ref(),
        fixture.as_os_str(),
        "--duration".as_ref(),
        "0.33".as_ref(),
        "--out".as_ref(),
        dir.join("out").as_os_str(),
    ]);
    assert!(!ok, "mpc ran with --duration 0.33 (output_interval 0.05)");
    assert!(err.contains("--duration 0.33 must be a whole multiple"), "{err}");
}
