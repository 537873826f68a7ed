//! `--vtk`: the VTK files parse as XML (quick-xml), the `.pvd` lists one `.vtu` per output
//! step with its time, and the geometry is the one of the CSV time series: the ribbon's
//! centreline (the midpoint of each pair of points) at the beam ends equals the positions of
//! `simulate`'s `timeseries.csv`; the closed loop's centreline equals its snapshots and its last
//! node its `tip` columns.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use quick_xml::events::Event;
use quick_xml::Reader;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scratch(tag: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("vtk-{tag}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn run(args: &[&str], out: &Path) {
    let o = Command::new(env!("CARGO_BIN_EXE_flexmpc"))
        .current_dir(root())
        .args(["--quiet", "--vtk"])
        .args(args)
        .arg("--out")
        .arg(out)
        .output()
        .expect("the binary runs");
    assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
}

/// A parsed `.vtu`: piece sizes, the attributes of the root, and every `DataArray` as numbers
/// under `<section>/<Name>` (`Points/Points`, `PointData/velocity`, `Cells/types`, …).
struct Vtu {
    n_points: usize,
    n_cells: usize,
    arrays: HashMap<String, Vec<f64>>,
}

fn parse_vtu(path: &Path) -> Vtu {
    let text = std::fs::read_to_string(path).unwrap();
    let mut r = Reader::from_str(&text);
    let (mut section, mut name, mut buf) = (String::new(), None::<String>, String::new());
    let mut v = Vtu { n_points: 0, n_cells: 0, arrays: HashMap::new() };
    let mut root_type = String::new();
    loop {
        match r.read_event().unwrap_or_else(|e| panic!("{}: not XML: {e}", path.display())) {
            Event::Start(e) => {
                let tag = String::from_utf8(e.name().as_ref().to_vec()).unwrap();
                let attr = |k: &str| {
                    e.attributes()
                        .map(|a| a.unwrap())
                        .find(|a| a.key.as_ref() == k.as_bytes())
                        .map(|a| String::from_utf8(a.value.to_vec()).unwrap())
                };
                match tag.as_str() {
                    "VTKFile" => root_type = attr("type").unwrap(),
                    "Piece" => {
                        v.n_points = attr("NumberOfPoints").unwrap().parse().unwrap();
                        v.n_cells = attr("NumberOfCells").unwrap().parse().unwrap();
                    }
                    "PointData" | "CellData" | "Points" | "Cells" | "FieldData" => section = tag,
                    "DataArray" => {
                        name = Some(attr("Name").unwrap_or_else(|| "Points".into()));
                        buf.clear();
                    }
                    _ => {}
                }
            }
            Event::Text(t) if name.is_some() => buf.push_str(&t.decode().unwrap()),
            Event::End(e) if e.name().as_ref() == b"DataArray" => {
                let n = name.take().unwrap();
                let values: Vec<f64> = buf
                    .split_whitespace()
                    .map(|x| x.parse().unwrap_or_else(|_| panic!("`{x}` in {n}")))
                    .collect();
                v.arrays.insert(format!("{section}/{n}"), values);
            }
            Event::Eof => break,
            _ => {}
        }
    }
    assert_eq!(root_type, "UnstructuredGrid");
    v
}

/// `(time, file)` of every data set of a `.pvd`.
fn parse_pvd(path: &Path) -> Vec<(f64, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut r = Reader::from_str(&text);
    let mut out = Vec::new();
    loop {
        match r.read_event().unwrap() {
            Event::Empty(e) if e.name().as_ref() == b"DataSet" => {
                let get = |k: &str| {
                    e.attributes()
                        .map(|a| a.unwrap())
                        .find(|a| a.key.as_ref() == k.as_bytes())
                        .map(|a| String::from_utf8(a.value.to_vec()).unwrap())
                        .unwrap()
                };
                out.push((get("timestep").parse().unwrap(), get("file")));
            }
            Event::Eof => break,
            _ => {}
        }
    }
    out
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let mut r = csv::Reader::from_path(path).unwrap();
    let h: Vec<String> = r.headers().unwrap().iter().map(String::from).collect();
    let rows =
        r.records().map(|x| x.unwrap().iter().map(|v| v.parse().unwrap()).collect()).collect();
    (h, rows)
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * (1.0 + a.abs().max(b.abs()))
}

/// The 3D two-link (`paper-3d.toml`, spatial, 2 × 50 elements) under `simulate --vtk`: one
/// `.vtu` per CSV row with its time; ribbons of 2 points per node and one quad per element;
/// the centreline at each beam's ends equals the CSV positions; velocity, strain and force
/// on every point; the ribbon has one width and turns with the sections.
#[test]
fn simulate_3d_ribbons_match_the_csv() {
    let out = scratch("simulate-3d");
    run(&["simulate", "scenes/paper-3d.toml", "--duration", "0.1"], &out);
    let (h, rows) = read_csv(&out.join("timeseries.csv"));
    let col = |n: &str| h.iter().position(|c| c == n).unwrap_or_else(|| panic!("no {n}"));
    let sets = parse_pvd(&out.join("vtk/simulate.pvd"));
    assert_eq!(sets.len(), rows.len(), "one .vtu per CSV row");
    let elements = [50usize, 50];
    let mut turned = 0.0f64;
    for ((t, file), row) in sets.iter().zip(&rows) {
        assert!(close(*t, row[0]), "time {t} vs CSV {}", row[0]);
        let v = parse_vtu(&out.join("vtk").join(file));
        let nodes: usize = elements.iter().map(|e| e + 1).sum();
        assert_eq!(v.n_points, 2 * nodes, "two ribbon points per node");
        assert_eq!(v.n_cells, elements.iter().sum::<usize>());
        assert!(v.arrays["Cells/types"].iter().all(|&c| c == 9.0), "VTK_QUAD");
        let pts = &v.arrays["Points/Points"];
        assert_eq!(pts.len(), 3 * v.n_points);
        for key in ["PointData/velocity", "PointData/strain", "PointData/force"] {
            assert_eq!(v.arrays[key].len(), 3 * v.n_points, "{key}");
        }
        assert_eq!(v.arrays["CellData/force"].len(), 3 * v.n_cells);
        let mid = |node: usize| -> [f64; 3] {
            std::array::from_fn(|k| 0.5 * (pts[6 * node + k] + pts[6 * node + 3 + k]))
        };
        let half = |node: usize| -> [f64; 3] {
            std::array::from_fn(|k| 0.5 * (pts[6 * node + 3 + k] - pts[6 * node + k]))
        };
        let mut first = 0;
        for (b, name) in ["link1", "link2"].iter().enumerate() {
            for (node, end) in [(first, "start"), (first + elements[b], "end")] {
                let p = mid(node);
                for (k, x) in ["x", "y", "z"].iter().enumerate() {
                    let c = row[col(&format!("{name}.{end}.{x}"))];
                    assert!(close(p[k], c), "{file}: {name}.{end}.{x} = {} vs CSV {c}", p[k]);
                }
            }
            first += elements[b] + 1;
        }
        // one ribbon width everywhere, and the section axis turns as the structure moves
        let w0 = half(0).iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(w0 > 0.0);
        for n in 0..nodes {
            let w = half(n).iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!(close(w, w0), "width {w} vs {w0} at node {n}");
        }
        let tip = half(nodes - 1);
        turned = turned.max(((tip[0] / w0).powi(2) + (tip[2] / w0).powi(2)).sqrt());
    }
    assert!(turned > 1e-3, "the tip section's e2 axis leaves the y direction: {turned}");
}

/// The 3D closed loop (`paper-3d-mpc-paper-model.toml` on 8 elements per link, ω0 = 1, 0.6 s) under `mpc --vtk`,
/// on the FE plant and on the ROM plant: one `.vtu` per snapshot with its time; ribbons of
/// two points per node and one quad per element whose centreline is the snapshot's node
/// positions (`snapshots.json`) and whose last node is the CSV's `tip` at that time; the
/// ribbon's direction `e2` is the second axis of the snapshot's node quaternions, stays across
/// each element's chord (from the positions) and turns as the structure spins; at t = 0 the point
/// velocity is the initial rigid rotation `ω × r`, `ω = ω0 (0, 1, 1)`; sectional force and
/// strain on every point.
#[test]
fn mpc_3d_ribbons_match_the_csv() {
    for plant in ["fe", "rom"] {
        mpc_3d_ribbons(plant);
    }
}

fn mpc_3d_ribbons(plant: &str) {
    let dir = scratch(&format!("mpc-3d-{plant}"));
    let text =
        std::fs::read_to_string(root().join("scenes/paper-3d-mpc-paper-model.toml")).unwrap();
    assert_eq!(text.matches("elements = 50").count(), 2);
    let scene = dir.join("small-3d.toml");
    std::fs::write(&scene, text.replace("elements = 50", "elements = 8")).unwrap();
    let out = dir.join("out");
    run(
        &["mpc", scene.to_str().unwrap(), "--duration", "0.6", "--plant", plant, "--omega0", "1"],
        &out,
    );
    let snaps: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("snapshots.json")).unwrap())
            .unwrap();
    let snaps = snaps.as_array().unwrap();
    let sets = parse_pvd(&out.join("vtk/mpc.pvd"));
    assert_eq!(sets.len(), snaps.len());
    assert!(sets.len() >= 2);
    let (h, rows) = read_csv(&out.join("timeseries.csv"));
    let col = |n: &str| h.iter().position(|c| c == n).unwrap();
    let (nodes, elements) = (18, 16);
    let mut turned = 0.0f64;
    let mut largest_force = 0.0f64;
    let mut worst = 0.0f64;
    for ((t, file), s) in sets.iter().zip(snaps) {
        assert!(close(*t, s["t"].as_f64().unwrap()));
        let v = parse_vtu(&out.join("vtk").join(file));
        assert_eq!(v.n_points, 2 * nodes, "{plant}: two ribbon points per node, 9 nodes per link");
        assert_eq!(v.n_cells, elements);
        assert!(v.arrays["Cells/types"].iter().all(|&c| c == 9.0), "VTK_QUAD");
        for key in ["PointData/velocity", "PointData/strain", "PointData/force"] {
            assert_eq!(v.arrays[key].len(), 3 * v.n_points, "{plant}: {key}");
            assert!(v.arrays[key].iter().all(|x| x.is_finite()), "{plant}: {key}");
        }
        let pts = &v.arrays["Points/Points"];
        let mid = |node: usize| -> [f64; 3] {
            std::array::from_fn(|k| 0.5 * (pts[6 * node + k] + pts[6 * node + 3 + k]))
        };
        let half = |node: usize| -> [f64; 3] {
            std::array::from_fn(|k| 0.5 * (pts[6 * node + 3 + k] - pts[6 * node + k]))
        };
        let json: Vec<[f64; 3]> = s["positions"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|b| b.as_array().unwrap().iter())
            .map(|p| std::array::from_fn(|k| p[k].as_f64().unwrap()))
            .collect();
        assert_eq!(json.len(), nodes);
        for (n, p) in json.iter().enumerate() {
            let m = mid(n);
            assert!((0..3).all(|k| close(m[k], p[k])), "{plant} {file}: node {n} {m:?} vs {p:?}");
        }
        let row = rows.iter().find(|r| close(r[0], *t)).expect("a CSV row at the snapshot time");
        for (k, x) in ["tip.x", "tip.y", "tip.z"].iter().enumerate() {
            let c = row[col(x)];
            let p = mid(nodes - 1)[k];
            assert!((p - c).abs() <= 1e-9 * (1.0 + c.abs()), "{file}: {x} = {p} vs CSV {c}");
        }
        // one width
        let norm = |a: [f64; 3]| a.iter().map(|x| x * x).sum::<f64>().sqrt();
        let w0 = norm(half(0));
        assert!(w0 > 0.0);
        for n in 0..nodes {
            assert!(close(norm(half(n)), w0), "{plant}: width at node {n}");
        }
        // e2 is the second column of T(ξ) of the snapshot's node quaternions
        let xi: Vec<[f64; 4]> = s["orientations"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|b| b.as_array().unwrap().iter())
            .map(|q| std::array::from_fn(|k| q[k].as_f64().unwrap()))
            .collect();
        assert_eq!(xi.len(), nodes);
        for (n, &[w, x, y, z]) in xi.iter().enumerate() {
            let e2 = [2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)];
            let h = half(n);
            assert!((0..3).all(|k| (h[k] - w0 * e2[k]).abs() < 1e-9), "{plant}: e2 at node {n}");
        }
        // e2 of each element's midpoint frame (the normalised sum of its nodes' quaternions)
        // stays across the element's chord: the chord is T(ξ_mid)(e1 + γ) up to the plant's
        // kinematic mismatch (theory.md §2, "Kinematics")
        for link in 0..2 {
            for e in 0..8 {
                let n = 9 * link + e;
                let (a, b) = (json[n], json[n + 1]);
                let tan: [f64; 3] = std::array::from_fn(|k| b[k] - a[k]);
                let sign = if (0..4).map(|k| xi[n][k] * xi[n + 1][k]).sum::<f64>() < 0.0 {
                    -1.0
                } else {
                    1.0
                };
                let q: [f64; 4] = std::array::from_fn(|k| xi[n][k] + sign * xi[n + 1][k]);
                let [w, x, y, z] = q.map(|c| c / q.iter().map(|c| c * c).sum::<f64>().sqrt());
                let e2 =
                    [2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)];
                let c = (0..3).map(|k| tan[k] * e2[k]).sum::<f64>() / norm(tan);
                worst = worst.max(c.abs());
            }
        }
        let tip = half(nodes - 1);
        turned = turned.max(((tip[0] / w0).powi(2) + (tip[2] / w0).powi(2)).sqrt());
        largest_force =
            v.arrays["PointData/force"].iter().fold(largest_force, |m, x| m.max(x.abs()));
        if *t == 0.0 {
            // the initial rigid rotation about the root: ω × r with ω = (0, 1, 1)
            let vel = &v.arrays["PointData/velocity"];
            for (n, r) in json.iter().enumerate() {
                let want = [r[2] - r[1], r[0], -r[0]];
                for k in 0..3 {
                    let got = vel[6 * n + k];
                    assert_eq!(got, vel[6 * n + 3 + k], "both ribbon points carry the node's");
                    assert!(
                        (got - want[k]).abs() < 1e-6,
                        "{plant}: velocity at node {n}: {got} vs ω × r = {}",
                        want[k]
                    );
                }
            }
        }
    }
    // The ROM plant rebuilds its configuration from the strains: e2 · chord is a shear strain
    // (measured 7.1e-5). The FE plant integrates node positions and orientations side by side;
    // they agree with the strains to the spatial scheme's second-order mismatch (measured
    // 1.8e-2 on this 8-element mesh, 4.9e-3 on 16, 1.3e-3 on 32; the verification case
    // `intrinsic-beam/kinematic-compatibility`). A wrong axis, node or beam would be O(1).
    let bound = if plant == "rom" { 1e-3 } else { 0.03 };
    assert!(worst < bound, "{plant}: e2 · chord = {worst}");
    assert!(turned > 1e-3, "{plant}: the tip section's e2 leaves the y direction: {turned}");
    assert!(largest_force > 0.0, "{plant}: the sectional loads are recorded");
}
