//! `--vtk`: the deformed structure over time as VTK XML files that ParaView opens.
//!
//! One unstructured grid (`.vtu`, ASCII) per output step and a collection (`.pvd`) that lists
//! them with their times, so that ParaView plays the motion with the right time axis.
//!
//! Geometry. When the node orientations are known (`simulate`), every beam is a *ribbon*: node
//! `n` at `r_n` gives the two points `r_n ∓ ½ w e2,n`, with `e2,n = T(ξ_n) e2` the section's
//! second axis in global components (`docs/theory.md §1`), and element `e` is the quad between
//! nodes `e` and `e + 1`; a twist of the section turns the ribbon, so torsion shows. The
//! centreline is the midpoint of each pair. `simulate` writes the FE plant at every output
//! step; `mpc` writes the closed loop's snapshots, which carry the plant's node positions,
//! orientations and state (the FE plant's own; for the ROM plant, the fields rebuilt from
//! its modal state). Without orientations a beam is a polyline of its nodes.
//!
//! Data. Point data: the node's global translational and angular velocity; the element
//! values averaged onto the nodes — sectional force `F` and moment `M` (section frame, eq. 2)
//! and the strains `γ`, curvatures `κ` (`[γ; κ] = C [F; M]`). Cell data: the element values
//! themselves, and the beam index.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// One beam at one time.
#[derive(Clone, Debug, Default)]
pub struct BeamFrame {
    /// Global node positions.
    pub positions: Vec<[f64; 3]>,
    /// Global section axis `e2` at each node (`None`: polyline geometry).
    pub e2: Option<Vec<[f64; 3]>>,
    /// Global translational velocity of each node.
    pub velocity: Option<Vec<[f64; 3]>>,
    /// Global angular velocity of each node.
    pub angular_velocity: Option<Vec<[f64; 3]>>,
    /// Per element: sectional force and moment `[F; M]` (section frame).
    pub force: Option<Vec<[f64; 6]>>,
    /// Per element: strain and curvature `[γ; κ] = C [F; M]` (section frame).
    pub strain: Option<Vec<[f64; 6]>>,
}

/// The structure at one time.
#[derive(Clone, Debug, Default)]
pub struct Frame {
    /// Time (s).
    pub t: f64,
    /// Beams, structure order.
    pub beams: Vec<BeamFrame>,
}

/// VTK cell types used here.
const VTK_LINE: u8 = 3;
const VTK_QUAD: u8 = 9;

fn array(x: &mut String, name: &str, comps: usize, values: impl Iterator<Item = f64>) {
    let _ = write!(
        x,
        r#"<DataArray type="Float64" Name="{name}" NumberOfComponents="{comps}" format="ascii">"#
    );
    for (i, v) in values.enumerate() {
        if i % (3 * comps.max(1)) == 0 {
            x.push('\n');
        } else {
            x.push(' ');
        }
        // full precision (round trip), finite by construction; NaN would not parse in VTK
        let v = if v.is_finite() { v } else { 0.0 };
        let _ = write!(x, "{v:e}");
    }
    x.push_str("\n</DataArray>\n");
}

/// The element values of `beam` averaged onto its nodes (end nodes: their one element).
fn nodal(values: &[[f64; 6]], n_nodes: usize) -> Vec<[f64; 6]> {
    (0..n_nodes)
        .map(|n| {
            let adj: Vec<&[f64; 6]> = [n.checked_sub(1), (n < values.len()).then_some(n)]
                .into_iter()
                .flatten()
                .filter_map(|e| values.get(e))
                .collect();
            let mut out = [0.0; 6];
            for a in &adj {
                for k in 0..6 {
                    out[k] += a[k] / adj.len() as f64;
                }
            }
            out
        })
        .collect()
}

/// The `.vtu` text of `frame`; `width` is the ribbon width.
pub fn vtu(frame: &Frame, width: f64) -> String {
    let ribbon = frame.beams.iter().all(|b| b.e2.is_some());
    let per_node = if ribbon { 2 } else { 1 };
    let n_points: usize = frame.beams.iter().map(|b| per_node * b.positions.len()).sum();
    let n_cells: usize = frame.beams.iter().map(|b| b.positions.len().saturating_sub(1)).sum();
    let mut x = String::new();
    x.push_str("<?xml version=\"1.0\"?>\n");
    x.push_str(
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
         header_type=\"UInt64\">\n<UnstructuredGrid>\n",
    );
    let _ = writeln!(
        x,
        "<FieldData>\n<DataArray type=\"Float64\" Name=\"TimeValue\" NumberOfTuples=\"1\" \
         format=\"ascii\">{:e}</DataArray>\n</FieldData>",
        frame.t
    );
    let _ = writeln!(x, r#"<Piece NumberOfPoints="{n_points}" NumberOfCells="{n_cells}">"#);

    // point data: every array on every point (zeros where a beam lacks it)
    let point_vec3 = |get: &dyn Fn(&BeamFrame) -> Option<&Vec<[f64; 3]>>| -> Vec<f64> {
        let mut v = Vec::new();
        for b in &frame.beams {
            for n in 0..b.positions.len() {
                let p = get(b).and_then(|a| a.get(n)).copied().unwrap_or([0.0; 3]);
                for _ in 0..per_node {
                    v.extend(p);
                }
            }
        }
        v
    };
    let point_el = |get: &dyn Fn(&BeamFrame) -> Option<&Vec<[f64; 6]>>, half: usize| -> Vec<f64> {
        let mut v = Vec::new();
        for b in &frame.beams {
            let nod = get(b).map(|e| nodal(e, b.positions.len()));
            for n in 0..b.positions.len() {
                let p = nod.as_ref().and_then(|a| a.get(n)).copied().unwrap_or([0.0; 6]);
                for _ in 0..per_node {
                    v.extend(&p[3 * half..3 * half + 3]);
                }
            }
        }
        v
    };
    let has = |f: &dyn Fn(&BeamFrame) -> bool| frame.beams.iter().any(f);
    x.push_str("<PointData Vectors=\"velocity\">\n");
    if has(&|b| b.velocity.is_some()) {
        array(&mut x, "velocity", 3, point_vec3(&|b| b.velocity.as_ref()).into_iter());
    }
    if has(&|b| b.angular_velocity.is_some()) {
        let w = point_vec3(&|b| b.angular_velocity.as_ref());
        array(&mut x, "angular_velocity", 3, w.into_iter());
    }
    if has(&|b| b.force.is_some()) {
        array(&mut x, "force", 3, point_el(&|b| b.force.as_ref(), 0).into_iter());
        array(&mut x, "moment", 3, point_el(&|b| b.force.as_ref(), 1).into_iter());
    }
    if has(&|b| b.strain.is_some()) {
        array(&mut x, "strain", 3, point_el(&|b| b.strain.as_ref(), 0).into_iter());
        array(&mut x, "curvature", 3, point_el(&|b| b.strain.as_ref(), 1).into_iter());
    }
    x.push_str("</PointData>\n<CellData Scalars=\"beam\">\n");
    let cell = |get: &dyn Fn(&BeamFrame) -> Option<&Vec<[f64; 6]>>, half: usize| -> Vec<f64> {
        let mut v = Vec::new();
        for b in &frame.beams {
            for e in 0..b.positions.len().saturating_sub(1) {
                let p = get(b).and_then(|a| a.get(e)).copied().unwrap_or([0.0; 6]);
                v.extend(&p[3 * half..3 * half + 3]);
            }
        }
        v
    };
    let beam_ids = frame
        .beams
        .iter()
        .enumerate()
        .flat_map(|(i, b)| std::iter::repeat_n(i as f64, b.positions.len().saturating_sub(1)));
    array(&mut x, "beam", 1, beam_ids);
    if has(&|b| b.force.is_some()) {
        array(&mut x, "force", 3, cell(&|b| b.force.as_ref(), 0).into_iter());
        array(&mut x, "moment", 3, cell(&|b| b.force.as_ref(), 1).into_iter());
    }
    if has(&|b| b.strain.is_some()) {
        array(&mut x, "strain", 3, cell(&|b| b.strain.as_ref(), 0).into_iter());
        array(&mut x, "curvature", 3, cell(&|b| b.strain.as_ref(), 1).into_iter());
    }
    x.push_str("</CellData>\n<Points>\n");
    let mut pts = Vec::with_capacity(3 * n_points);
    for b in &frame.beams {
        for (n, p) in b.positions.iter().enumerate() {
            match &b.e2 {
                Some(e2) if ribbon => {
                    let d = e2.get(n).copied().unwrap_or([0.0; 3]);
                    for s in [-0.5, 0.5] {
                        pts.extend((0..3).map(|k| p[k] + s * width * d[k]));
                    }
                }
                _ => pts.extend(p),
            }
        }
    }
    array(&mut x, "Points", 3, pts.into_iter());
    x.push_str("</Points>\n<Cells>\n");
    let (mut conn, mut offsets, mut types) = (Vec::new(), Vec::new(), Vec::new());
    let mut base = 0usize;
    for b in &frame.beams {
        let nn = b.positions.len();
        for e in 0..nn.saturating_sub(1) {
            if ribbon {
                let (a, c) = (base + 2 * e, base + 2 * (e + 1));
                conn.extend([a, c, c + 1, a + 1]);
                types.push(VTK_QUAD);
            } else {
                conn.extend([base + e, base + e + 1]);
                types.push(VTK_LINE);
            }
            offsets.push(conn.len());
        }
        base += per_node * nn;
    }
    let ints = |x: &mut String, name: &str, ty: &str, v: &[usize]| {
        let _ = write!(x, r#"<DataArray type="{ty}" Name="{name}" format="ascii">"#);
        for (i, c) in v.iter().enumerate() {
            x.push(if i % 16 == 0 { '\n' } else { ' ' });
            let _ = write!(x, "{c}");
        }
        x.push_str("\n</DataArray>\n");
    };
    ints(&mut x, "connectivity", "Int64", &conn);
    ints(&mut x, "offsets", "Int64", &offsets);
    let types: Vec<usize> = types.into_iter().map(usize::from).collect();
    ints(&mut x, "types", "UInt8", &types);
    x.push_str("</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    x
}

/// The ribbon width for `frames`: 4% of the largest extent of the first frame.
pub fn default_width(frames: &[Frame]) -> f64 {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in frames.iter().take(1).flat_map(|f| f.beams.iter().flat_map(|b| &b.positions)) {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let ext = (0..3).map(|k| hi[k] - lo[k]).filter(|d| d.is_finite()).fold(0.0, f64::max);
    if ext > 0.0 {
        0.04 * ext
    } else {
        0.04
    }
}

/// A `.pvd` collection being written: each frame goes to its `.vtu` file as it comes
/// ([`Collection::push`]), the `.pvd` at the end ([`Collection::finish`]).
pub struct Collection {
    dir: PathBuf,
    name: String,
    width: Option<f64>,
    entries: Vec<(f64, String)>,
}

impl Collection {
    /// A collection `dir/<name>.pvd` of files `dir/<name>-<k>.vtu`; creates `dir`.
    pub fn new(dir: &Path, name: &str) -> Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Self { dir: dir.to_path_buf(), name: name.to_string(), width: None, entries: vec![] })
    }

    /// Writes the next frame (the ribbon width is fixed by the first one).
    pub fn push(&mut self, frame: &Frame) -> Result<()> {
        let width = *self.width.get_or_insert_with(|| default_width(std::slice::from_ref(frame)));
        let file = format!("{}-{:06}.vtu", self.name, self.entries.len());
        let path = self.dir.join(&file);
        std::fs::write(&path, vtu(frame, width))
            .with_context(|| format!("writing {}", path.display()))?;
        self.entries.push((frame.t, file));
        Ok(())
    }

    /// Writes the `.pvd` listing every frame with its time; returns its path.
    pub fn finish(self) -> Result<PathBuf> {
        let mut pvd = String::from(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" \
             byte_order=\"LittleEndian\">\n<Collection>\n",
        );
        for (t, file) in &self.entries {
            let _ = writeln!(
                pvd,
                r#"<DataSet timestep="{t:e}" group="" part="0" file="{}"/>"#,
                file.replace('&', "&amp;").replace('"', "&quot;").replace('<', "&lt;")
            );
        }
        pvd.push_str("</Collection>\n</VTKFile>\n");
        let path = self.dir.join(format!("{}.pvd", self.name));
        std::fs::write(&path, pvd).with_context(|| format!("writing {}", path.display()))?;
        Ok(path)
    }
}

/// Writes `dir/<name>-<k>.vtu` for every frame and `dir/<name>.pvd` listing them with their
/// times; returns the path of the `.pvd`.
pub fn write(dir: &Path, name: &str, frames: &[Frame]) -> Result<PathBuf> {
    let mut c = Collection::new(dir, name)?;
    for f in frames {
        c.push(f)?;
    }
    c.finish()
}

/// The frames of a closed loop on `structure`: every snapshot as ribbons through its node
/// positions and section orientations, with the velocities, sectional loads and strains of
/// the plant's state (the FE plant's own; the ROM plant's rebuilt from its modal state).
/// Snapshots without orientations give polylines; without a state of the structure's size,
/// geometry only.
pub fn frames_of_snapshots(
    snapshots: &[mpc::Snapshot],
    structure: &multibody_constraints::Structure,
) -> Vec<Frame> {
    snapshots
        .iter()
        .map(|s| {
            let state = (s.state.len() == structure.dim()).then_some(s.state.as_slice());
            frame_of_state(structure, s.t, &s.positions, &s.orientations, state)
        })
        .collect()
}

/// The current state of a constrained FE plant as a frame: positions, section axes,
/// velocities, sectional loads and strains.
pub fn frame_of_plant(plant: &multibody_constraints::Plant) -> Frame {
    let kin = plant.kinematics();
    let positions: Vec<Vec<[f64; 3]>> =
        kin.iter().map(|k| k.r.iter().map(|r| [r.x, r.y, r.z]).collect()).collect();
    let xi: Vec<Vec<[f64; 4]>> =
        kin.iter().map(|k| k.xi.iter().map(|q| [q[0], q[1], q[2], q[3]]).collect()).collect();
    frame_of_state(plant.structure(), plant.time(), &positions, &xi, Some(plant.state()))
}

/// One frame from node positions, node quaternions `xi` (section frame → global; empty or
/// short: polyline geometry and no velocities) and the full FE state `x` of `structure`
/// (velocities `x1` rotated to global by `T(ξ)`, element loads `x2`, strains `C x2`).
fn frame_of_state(
    s: &multibody_constraints::Structure,
    t: f64,
    positions: &[Vec<[f64; 3]>],
    xi: &[Vec<[f64; 4]>],
    x: Option<&[f64]>,
) -> Frame {
    let beams = positions
        .iter()
        .enumerate()
        .map(|(b, pos)| {
            let rot: Option<Vec<nalgebra::Matrix3<f64>>> =
                xi.get(b).filter(|q| q.len() == pos.len()).map(|q| {
                    q.iter().map(|q| rotation(&nalgebra::Vector4::from_column_slice(q))).collect()
                });
            let mut frame = BeamFrame {
                positions: pos.clone(),
                e2: rot
                    .as_ref()
                    .map(|r| r.iter().map(|t| [t[(0, 1)], t[(1, 1)], t[(2, 1)]]).collect()),
                ..Default::default()
            };
            let Some(sb) = s.beams().get(b).filter(|sb| sb.beam.n_nodes() == pos.len()) else {
                return frame;
            };
            let Some(x) = x else { return frame };
            let beam = &sb.beam;
            let xb = s.beam_slice(b, x);
            if let Some(rot) = &rot {
                let v = |n: usize, a: usize| -> [f64; 3] {
                    let x1 = beam.x1(xb, n);
                    let g = rot[n] * nalgebra::Vector3::new(x1[a], x1[a + 1], x1[a + 2]);
                    [g.x, g.y, g.z]
                };
                frame.velocity = Some((0..pos.len()).map(|n| v(n, 0)).collect());
                frame.angular_velocity = Some((0..pos.len()).map(|n| v(n, 3)).collect());
            }
            let force: Vec<[f64; 6]> = (0..beam.n_elements())
                .map(|e| {
                    let f = beam.x2(xb, e);
                    std::array::from_fn(|k| f[k])
                })
                .collect();
            let c = beam.section().compliance;
            frame.strain = Some(
                force
                    .iter()
                    .map(|f| {
                        let g = c * nalgebra::Vector6::from_column_slice(f);
                        std::array::from_fn(|k| g[k])
                    })
                    .collect(),
            );
            frame.force = Some(force);
            frame
        })
        .collect();
    Frame { t, beams }
}

/// `T(ξ)`, local → global, of a unit quaternion `ξ` (scalar first).
fn rotation(q: &nalgebra::Vector4<f64>) -> nalgebra::Matrix3<f64> {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    nalgebra::Matrix3::new(
        1.0 - 2.0 * (y * y + z * z),
        2.0 * (x * y - w * z),
        2.0 * (x * z + w * y),
        2.0 * (x * y + w * z),
        1.0 - 2.0 * (x * x + z * z),
        2.0 * (y * z - w * x),
        2.0 * (x * z - w * y),
        2.0 * (y * z + w * x),
        1.0 - 2.0 * (x * x + y * y),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `T(ξ)` of a quarter turn about z maps e1 to e2.
    #[test]
    fn quaternion_rotation() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let t = rotation(&nalgebra::Vector4::new(h, 0.0, 0.0, h));
        let e = t * nalgebra::Vector3::x();
        assert!((e - nalgebra::Vector3::y()).norm() < 1e-15);
    }

    /// Ribbon points straddle the centreline along e2; quads join consecutive nodes.
    #[test]
    fn ribbon_geometry() {
        let f = Frame {
            t: 0.5,
            beams: vec![BeamFrame {
                positions: vec![[0.0; 3], [1.0, 0.0, 0.0]],
                e2: Some(vec![[0.0, 1.0, 0.0]; 2]),
                ..Default::default()
            }],
        };
        let x = vtu(&f, 0.2);
        assert!(x.contains(r#"NumberOfPoints="4" NumberOfCells="1""#), "{x}");
        assert!(x.contains("0e0 -1e-1 0e0 0e0 1e-1 0e0"), "{x}");
        assert!(x.contains("\n0 2 3 1\n"), "{x}");
    }
}
