//! The staggered, energy-preserving discretisation of one beam (theory.md §2) and its
//! implicit-midpoint step rows, Jacobian, energy, powers and linearised operators.
//!
//! # Layout (theory.md §2)
//! With `N` elements and `k` components per field ([`Components`]), the beam's vector is
//!
//! ```text
//! [ x1_0, …, x1_N,  x2_0, …, x2_{N−1},  x2_L, x2_R ]      length k(2N+3)
//! ```
//!
//! and the beam writes `k(N+1)` node rows followed by `kN` element rows (`k(2N+1)` rows): row
//! `i < k(2N+1)` is the equation "belonging" to unknown `i`. The `2k` end unknowns are closed
//! by rows the caller supplies (single-beam end conditions in `problem`, joints in
//! `multibody-constraints`).
//!
//! # Step residual
//! For a step `t → t + dt` from `old` to `new`, every term is evaluated at the midpoint vector
//! `mid` ([`Beam::midpoint`]): `mid_i = (old_i + new_i)/2` for differential unknowns and
//! `mid_i = new_i` for *algebraic* ones (massless velocity components, rigid force components
//! and the end values `x2_L`, `x2_R`): these hold the step's midpoint value (a Lagrange
//! multiplier) and never need consistent initial values. The residual is
//!
//! ```text
//! node n:     w_n M (x1_n⁺ − x1_n)/dt − [ x2_n − x2_{n−1} + Σ_{e∋n} (h_e/2)(E x2_e − L2(x2_e) C x2_e)
//!                                         − w_n L1(x1_n) M x1_n + w_n D0 x1_n + damping fluxes
//!                                         + w_n f1_n + F_n ]                         (eq. 1)
//! element e:  h_e C (x2_e⁺ − x2_e)/dt − [ x1_{e+1} − x1_e + h_e (−Eᵀ x̄1_e + L1ᵀ(x̄1_e) C x2_e) ]   (eq. 2)
//! ```
//!
//! with `x2_{−1} := x2_L`, `x2_N := x2_R`, `x̄1_e = (x1_e + x1_{e+1})/2`, all at `mid`. Damping
//! fluxes per element: `g_e = D2 (x1_{e+1} − x1_e)/h_e` added to node `e` and subtracted from
//! node `e+1`; `D1`: `½ D1 (x1_{e+1} − x1_e)` added to both nodes of the element.
//! Summing `mid·(rows)` telescopes: `ε(new) − ε(old) = dt · (boundary + load + damping power)`
//! exactly ([`Beam::step_power`]).

use nalgebra::{Matrix3, Matrix6, SMatrix, SVector, Vector4, Vector6};

use crate::components::Components;
use crate::error::{check_len, BeamError, Result};
use crate::kernels::{Kernels, PlanarKernels, SpatialKernels};
use crate::loads::{LoadFrame, Loads};
use crate::mesh::Mesh;
use crate::operators::{
    e_matrix, e_times, et_times, halves, join, l1, l1_times, l1t_jacobian, l1t_times, l2, l2_times,
    planar_ops, tilde,
};
use crate::rotation::{quaternion_step, rotation};
use crate::section::Section;

/// Everything a step needs besides the two state vectors.
#[derive(Clone, Copy, Debug)]
pub struct StepInput<'a> {
    /// Time at the start of the step, `t_n`.
    pub time: f64,
    /// Step size `dt > 0`.
    pub dt: f64,
    /// Loads on this beam (amplitudes evaluated at `t_n + dt/2`).
    pub loads: &'a Loads,
    /// Node quaternions `ξ_n` at `t_n` (they rotate dead loads), one per node, as held by
    /// [`crate::Kinematics::xi`].
    pub node_quaternions: &'a [Vector4<f64>],
}

/// Powers at a step's midpoint; `ε(new) − ε(old) = dt (boundary + loads + damping)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepPower {
    /// Boundary power `x1_Nᵀ x2_R − x1_0ᵀ x2_L`.
    pub boundary: f64,
    /// Power of external loads `Σ x1_nᵀ (w_n f1_n + F_n)`.
    pub loads: f64,
    /// Power of damping forces (≤ 0 for dissipative damping); dissipated power is `−damping`.
    pub damping: f64,
}

impl StepPower {
    /// Dissipated power `−damping` (≥ 0 for dissipative damping).
    pub fn dissipated(&self) -> f64 {
        -self.damping
    }

    /// Total power `boundary + loads + damping`: `ε(new) − ε(old) = dt · total()`.
    pub fn total(&self) -> f64 {
        self.boundary + self.loads + self.damping
    }
}

/// Linearised operators at rest (theory.md §4), local indices of the beam vector.
///
/// `B = blkdiag(w_n M, h_e C, 0)` (square, `k(2N+3)`); `A` has the `k(2N+1)` node and element
/// rows and all `k(2N+3)` columns: restricted to the first `k(2N+1)` columns it is skew; the end
/// columns carry `−I` (node 0, `x2_L`) and `+I` (node N, `x2_R`). `damping` is the linear
/// damping operator on the node velocities (node rows × node columns; symmetric negative
/// semidefinite for dissipative `D0`, `D2` with `D1 = 0`). Entries are `(row, col, value)`,
/// duplicates summed.
#[derive(Clone, Debug, Default)]
pub struct LinearOperators {
    /// Size of the beam vector `k(2N+3)`.
    pub dim: usize,
    /// Number of beam rows `k(2N+1)`.
    pub n_rows: usize,
    /// Mass/compliance weights.
    pub b: Vec<(usize, usize, f64)>,
    /// Skew operator of the staggered scheme.
    pub a: Vec<(usize, usize, f64)>,
    /// Damping operator (node rows and columns).
    pub damping: Vec<(usize, usize, f64)>,
}

/// One beam: section, mesh and component set, with the staggered FE operators.
#[derive(Clone, Debug)]
pub struct Beam {
    section: Section,
    mesh: Mesh,
    components: Components,
    k: usize,
    e_mat: Matrix6<f64>,
    /// `½` (differential) or `1` (algebraic) per local unknown: `∂mid/∂new`.
    mid_weight: Vec<f64>,
    has_flux_damping: bool,
}

thread_local! {
    /// Per-thread midpoint buffer of [`Beam::step_residual`] (no allocation per call).
    static MID_SCRATCH: std::cell::RefCell<Vec<f64>> = const { std::cell::RefCell::new(Vec::new()) };
}

impl Beam {
    /// Builds a beam; validates the section (and its planarity for [`Components::Planar`]).
    ///
    /// ```
    /// use intrinsic_beam::{Beam, Components, Mesh, Section};
    ///
    /// let beam = Beam::new(Section::paper_2d(), Mesh::uniform(1.0, 4)?, Components::Planar)?;
    /// // k = 3 planar components, k(2N + 3) unknowns, k(2N + 1) rows
    /// assert_eq!(beam.dim(), 3 * (2 * 4 + 3));
    /// assert_eq!(beam.n_rows(), 3 * (2 * 4 + 1));
    /// # Ok::<(), intrinsic_beam::BeamError>(())
    /// ```
    pub fn new(section: Section, mesh: Mesh, components: Components) -> Result<Self> {
        section.validate()?;
        components.check_section(&section)?;
        let k = components.k();
        let n = mesh.n_elements();
        let idx = components.indices();
        let mut mid_weight = vec![0.5; k * (2 * n + 3)];
        for node in 0..=n {
            for a in 0..k {
                if section.massless[idx[a]] {
                    mid_weight[node * k + a] = 1.0;
                }
            }
        }
        for e in 0..n {
            for a in 0..k {
                if section.rigid[idx[a]] {
                    mid_weight[k * (n + 1) + e * k + a] = 1.0;
                }
            }
        }
        for w in mid_weight.iter_mut().skip(k * (2 * n + 1)) {
            *w = 1.0;
        }
        let has_flux_damping = section.d1.iter().chain(section.d2.iter()).any(|&x| x != 0.0);
        Ok(Self {
            e_mat: e_matrix(&section.kappa0),
            section,
            mesh,
            components,
            k,
            mid_weight,
            has_flux_damping,
        })
    }

    /// The section.
    pub fn section(&self) -> &Section {
        &self.section
    }

    /// The mesh.
    pub fn mesh(&self) -> &Mesh {
        &self.mesh
    }

    /// The component set.
    pub fn components(&self) -> Components {
        self.components
    }

    /// Components per field, `k`.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Number of elements `N`.
    pub fn n_elements(&self) -> usize {
        self.mesh.n_elements()
    }

    /// Number of nodes `N + 1`.
    pub fn n_nodes(&self) -> usize {
        self.mesh.n_nodes()
    }

    /// Length of the beam vector, `k(2N+3)`.
    pub fn dim(&self) -> usize {
        self.k * (2 * self.n_elements() + 3)
    }

    /// Number of rows the beam writes, `k(2N+1)` (node rows, then element rows).
    pub fn n_rows(&self) -> usize {
        self.k * (2 * self.n_elements() + 1)
    }

    /// Local index of component `a < k` of `x1` at node `n`.
    #[inline]
    pub fn x1_index(&self, node: usize, a: usize) -> usize {
        node * self.k + a
    }

    /// Local index of component `a` of `x2` at element `e`.
    #[inline]
    pub fn x2_index(&self, element: usize, a: usize) -> usize {
        self.k * (self.n_nodes() + element) + a
    }

    /// Local index of component `a` of the end value `x2_L` (s = 0).
    #[inline]
    pub fn left_index(&self, a: usize) -> usize {
        self.k * (2 * self.n_elements() + 1) + a
    }

    /// Local index of component `a` of the end value `x2_R` (s = L).
    #[inline]
    pub fn right_index(&self, a: usize) -> usize {
        self.k * (2 * self.n_elements() + 2) + a
    }

    /// Whether local unknown `i` is algebraic (massless velocity, rigid force, end value).
    pub fn is_algebraic(&self, i: usize) -> bool {
        self.mid_weight[i] == 1.0
    }

    /// `∂mid_i/∂new_i`: `½` for differential unknowns, `1` for algebraic ones.
    pub fn midpoint_weight(&self, i: usize) -> f64 {
        self.mid_weight[i]
    }

    /// The step's midpoint vector (see the module doc).
    pub fn midpoint(&self, old: &[f64], new: &[f64], mid: &mut [f64]) -> Result<()> {
        check_len("old state", self.dim(), old.len())?;
        check_len("new state", self.dim(), new.len())?;
        check_len("midpoint", self.dim(), mid.len())?;
        // μ new + (1 − μ) old with μ ∈ {½, 1}: bitwise equal to ½(old + new) resp. new (the
        // products by ½ are exact), and branch-free
        for (((m, &w), &o), &x) in mid.iter_mut().zip(&self.mid_weight).zip(old).zip(new) {
            *m = w * x + (1.0 - w) * o;
        }
        Ok(())
    }

    /// `x1` at node `n` of a beam vector, as a 6-vector.
    ///
    /// Accessors like this one index the slice directly: they panic (like a shape assertion)
    /// if `x` is shorter than [`Beam::dim`] or the node/element does not exist.
    #[inline]
    pub fn x1(&self, x: &[f64], node: usize) -> Vector6<f64> {
        let s = node * self.k;
        self.components.embed(&x[s..s + self.k])
    }

    /// `x2` at element `e`, as a 6-vector.
    #[inline]
    pub fn x2(&self, x: &[f64], element: usize) -> Vector6<f64> {
        let s = self.x2_index(element, 0);
        self.components.embed(&x[s..s + self.k])
    }

    /// The end value `x2_L`.
    pub fn x2_left(&self, x: &[f64]) -> Vector6<f64> {
        let s = self.left_index(0);
        self.components.embed(&x[s..s + self.k])
    }

    /// The end value `x2_R`.
    pub fn x2_right(&self, x: &[f64]) -> Vector6<f64> {
        let s = self.right_index(0);
        self.components.embed(&x[s..s + self.k])
    }

    /// Writes a 6-vector's active components into `x1` at node `n`.
    pub fn set_x1(&self, x: &mut [f64], node: usize, value: &Vector6<f64>) {
        let s = node * self.k;
        self.components.extract(value, &mut x[s..s + self.k]);
    }

    /// Writes a 6-vector's active components into `x2` at element `e`.
    pub fn set_x2(&self, x: &mut [f64], element: usize, value: &Vector6<f64>) {
        let s = self.x2_index(element, 0);
        self.components.extract(value, &mut x[s..s + self.k]);
    }

    /// Discrete energy (eq. 6): `ε_h = ½ Σ w_n x1_nᵀ M x1_n + ½ Σ h_e x2_eᵀ C x2_e`.
    pub fn energy(&self, x: &[f64]) -> Result<f64> {
        check_len("state", self.dim(), x.len())?;
        let (m, c) = (&self.section.mass, &self.section.compliance);
        let mut e = 0.0;
        for (n, w) in self.mesh.weights().iter().enumerate() {
            let x1 = self.x1(x, n);
            e += 0.5 * w * x1.dot(&(m * x1));
        }
        for (el, h) in self.mesh.lengths().iter().enumerate() {
            let x2 = self.x2(x, el);
            e += 0.5 * h * x2.dot(&(c * x2));
        }
        Ok(e)
    }

    /// Checks the step inputs (time step, loads, number of node quaternions).
    pub fn check_input(&self, input: &StepInput<'_>) -> Result<()> {
        if !crate::error::positive_finite(input.dt) {
            return Err(BeamError::NonPositiveTime { field: "dt".into(), value: input.dt });
        }
        if !input.time.is_finite() {
            return Err(BeamError::NonFinite {
                field: "time".into(),
                index: "t".into(),
                value: input.time,
            });
        }
        input.loads.validate(self.components, self.n_nodes())?;
        check_len("node quaternions", self.n_nodes(), input.node_quaternions.len())?;
        Ok(())
    }

    /// Midpoint rotation of every node: `T(exp(dt/2 U(ω_mid)) ξ_n)`.
    pub(crate) fn midpoint_rotations(
        &self,
        input: &StepInput<'_>,
        mid: &[f64],
    ) -> Vec<Matrix3<f64>> {
        if !input.loads.has_dead() {
            return Vec::new();
        }
        (0..self.n_nodes())
            .map(|n| {
                let (_, w) = halves(&self.x1(mid, n));
                rotation(&quaternion_step(&input.node_quaternions[n], &w, 0.5 * input.dt))
            })
            .collect()
    }

    /// Local load 6-vectors per node (`w_n f1_n + F_n`) and the dead part (for Jacobians).
    pub(crate) fn node_loads(
        &self,
        time: f64,
        loads: &Loads,
        rotations: &[Matrix3<f64>],
    ) -> (Vec<Vector6<f64>>, Vec<Vector6<f64>>) {
        let n_nodes = self.n_nodes();
        if loads.point.is_empty() && loads.distributed.is_empty() {
            return (Vec::new(), Vec::new());
        }
        let mut total = vec![Vector6::zeros(); n_nodes];
        let mut dead = vec![Vector6::zeros(); n_nodes];
        let to_local = |t: &Matrix3<f64>, v: &Vector6<f64>| {
            let (f, m) = halves(v);
            join(&(t.transpose() * f), &(t.transpose() * m))
        };
        for d in &loads.distributed {
            let a = d.amplitude.at(time);
            for n in 0..n_nodes {
                let w = self.mesh.weights()[n];
                match d.frame {
                    LoadFrame::Follower => total[n] += d.value * (a * w),
                    LoadFrame::Dead => {
                        let l = to_local(&rotations[n], &d.value) * (a * w);
                        total[n] += l;
                        dead[n] += l;
                    }
                }
            }
        }
        for p in &loads.point {
            let a = p.amplitude.at(time);
            match p.frame {
                LoadFrame::Follower => total[p.node] += p.value * a,
                LoadFrame::Dead => {
                    let l = to_local(&rotations[p.node], &p.value) * a;
                    total[p.node] += l;
                    dead[p.node] += l;
                }
            }
        }
        (total, dead)
    }

    /// The right-hand side `f(mid)` of the semi-discrete system `B ẋ = f(x)` in row layout
    /// (node rows then element rows), given per-node local loads. Also returns the damping
    /// forces per node.
    pub(crate) fn rhs(
        &self,
        x: &[f64],
        node_loads: &[Vector6<f64>],
        out: &mut [f64],
    ) -> Vec<Vector6<f64>> {
        let mut damp = vec![Vector6::zeros(); self.n_nodes()];
        self.rhs_into(x, node_loads, out, Some(&mut damp));
        damp
    }

    /// Streaming evaluation of `f(x)` (see [`Beam::rhs`]); `node_loads` may be empty (no
    /// loads); damping forces per node are written to `damp` if given.
    pub(crate) fn rhs_into(
        &self,
        x: &[f64],
        node_loads: &[Vector6<f64>],
        out: &mut [f64],
        mut damp: Option<&mut [Vector6<f64>]>,
    ) {
        if self.components == Components::Planar {
            self.rhs_planar(x, node_loads, out, damp);
            return;
        }
        let n = self.n_elements();
        let k = self.k;
        let (m, c) = (&self.section.mass, &self.section.compliance);
        let d0 = &self.section.d0;
        let has_d0 = d0.iter().any(|&v| v != 0.0);
        let kappa0 = self.section.kappa0;
        let hs = self.mesh.lengths();
        let ws = self.mesh.weights();
        let node_term = |i: usize, x1: &Vector6<f64>| {
            let mut f = -l1_times(x1, &(m * x1)) * ws[i];
            if has_d0 {
                f += d0 * x1 * ws[i];
            }
            if !node_loads.is_empty() {
                f += node_loads[i];
            }
            f
        };
        let mut x1_prev = self.x1(x, 0);
        let mut f_prev = node_term(0, &x1_prev) - self.x2_left(x);
        if let Some(d) = damp.as_deref_mut() {
            if has_d0 {
                d[0] = d0 * x1_prev * ws[0];
            }
        }
        for e in 0..n {
            let x1_next = self.x1(x, e + 1);
            let mut f_next = node_term(e + 1, &x1_next);
            if let Some(d) = damp.as_deref_mut() {
                if has_d0 {
                    d[e + 1] = d0 * x1_next * ws[e + 1];
                }
            }
            let x2 = self.x2(x, e);
            let cx2 = c * x2;
            // E always couples (its ẽ1 block), also without initial curvature
            let q = (e_times(&kappa0, &x2) - l2_times(&x2, &cx2)) * (0.5 * hs[e]);
            f_prev += x2 + q;
            f_next += q - x2;
            let dx = x1_next - x1_prev;
            if self.has_flux_damping {
                let g = self.section.d2 * dx / hs[e] + self.section.d1 * dx * 0.5;
                let g2 = -self.section.d2 * dx / hs[e] + self.section.d1 * dx * 0.5;
                f_prev += g;
                f_next += g2;
                if let Some(d) = damp.as_deref_mut() {
                    d[e] += g;
                    d[e + 1] += g2;
                }
            }
            let xb = (x1_prev + x1_next) * 0.5;
            let f2 = dx + (l1t_times(&xb, &cx2) - et_times(&kappa0, &xb)) * hs[e];
            let s = k * (n + 1 + e);
            self.components.extract(&f2, &mut out[s..s + k]);
            self.components.extract(&f_prev, &mut out[e * k..(e + 1) * k]);
            x1_prev = x1_next;
            f_prev = f_next;
        }
        f_prev += self.x2_right(x);
        self.components.extract(&f_prev, &mut out[n * k..(n + 1) * k]);
    }

    /// The planar (`k = 3`) specialisation of [`Beam::rhs_into`] on 3-vectors
    /// `(v1, v3, ω2)`, `(f1, f3, m2)`; same arithmetic as the 6-component kernel restricted to
    /// the in-plane components (see [`planar_ops`]).
    fn rhs_planar(
        &self,
        x: &[f64],
        node_loads: &[Vector6<f64>],
        out: &mut [f64],
        mut damp: Option<&mut [Vector6<f64>]>,
    ) {
        use nalgebra::Vector3 as V3;
        let r = |m: &Matrix6<f64>| Matrix3::from_fn(|a, b| self.components.entry(m, a, b));
        let (m, c, d0, d1, d2) = (
            r(&self.section.mass),
            r(&self.section.compliance),
            r(&self.section.d0),
            r(&self.section.d1),
            r(&self.section.d2),
        );
        let has_d0 = d0.iter().any(|&v| v != 0.0);
        let kappa = self.section.kappa0.y;
        let n = self.n_elements();
        let hs = self.mesh.lengths();
        let ws = self.mesh.weights();
        let get = |i: usize| V3::new(x[i], x[i + 1], x[i + 2]);
        let load = |i: usize| {
            if node_loads.is_empty() {
                V3::zeros()
            } else {
                let l = &node_loads[i];
                V3::new(l[0], l[2], l[4])
            }
        };
        let to6 = |v: &V3<f64>| Vector6::new(v[0], 0.0, v[1], 0.0, v[2], 0.0);
        let node_term = |i: usize, x1: &V3<f64>| {
            let mut f = -planar_ops::l1_times(x1, &(m * x1)) * ws[i] + load(i);
            if has_d0 {
                f += d0 * x1 * ws[i];
            }
            f
        };
        let mut x1_prev = get(0);
        let mut f_prev = node_term(0, &x1_prev) - get(self.left_index(0));
        if let Some(d) = damp.as_deref_mut() {
            if has_d0 {
                d[0] = to6(&(d0 * x1_prev * ws[0]));
            }
        }
        for e in 0..n {
            let x1_next = get(3 * (e + 1));
            let mut f_next = node_term(e + 1, &x1_next);
            if let Some(d) = damp.as_deref_mut() {
                if has_d0 {
                    d[e + 1] = to6(&(d0 * x1_next * ws[e + 1]));
                }
            }
            let x2 = get(self.x2_index(e, 0));
            let cx2 = c * x2;
            let q =
                (planar_ops::e_times(kappa, &x2) - planar_ops::l2_times(&x2, &cx2)) * (0.5 * hs[e]);
            f_prev += x2 + q;
            f_next += q - x2;
            let dx = x1_next - x1_prev;
            if self.has_flux_damping {
                let g = d2 * dx / hs[e] + d1 * dx * 0.5;
                let g2 = -d2 * dx / hs[e] + d1 * dx * 0.5;
                f_prev += g;
                f_next += g2;
                if let Some(d) = damp.as_deref_mut() {
                    d[e] += to6(&g);
                    d[e + 1] += to6(&g2);
                }
            }
            let xb = (x1_prev + x1_next) * 0.5;
            let f2 =
                dx + (planar_ops::l1t_times(&xb, &cx2) - planar_ops::et_times(kappa, &xb)) * hs[e];
            let s = 3 * (n + 1 + e);
            out[s..s + 3].copy_from_slice(f2.as_slice());
            out[3 * e..3 * e + 3].copy_from_slice(f_prev.as_slice());
            x1_prev = x1_next;
            f_prev = f_next;
        }
        f_prev += get(self.right_index(0));
        out[3 * n..3 * n + 3].copy_from_slice(f_prev.as_slice());
    }

    /// Writes the `k(2N+1)` step residual rows `B (new − old)/dt − f(mid)` into `out`.
    pub fn step_residual(
        &self,
        input: &StepInput<'_>,
        old: &[f64],
        new: &[f64],
        out: &mut [f64],
    ) -> Result<()> {
        self.check_input(input)?;
        check_len("residual", self.n_rows(), out.len())?;
        let dead = input.loads.has_dead();
        let (loads, _) = if dead {
            MID_SCRATCH.with(|cell| -> Result<_> {
                let mut mid = cell.borrow_mut();
                mid.resize(self.dim(), 0.0);
                self.midpoint(old, new, &mut mid)?;
                let rot = self.midpoint_rotations(input, &mid);
                Ok(self.node_loads(input.time + 0.5 * input.dt, input.loads, &rot))
            })?
        } else {
            check_len("old state", self.dim(), old.len())?;
            check_len("new state", self.dim(), new.len())?;
            self.node_loads(input.time + 0.5 * input.dt, input.loads, &[])
        };
        match self.components {
            Components::Planar => self.residual_k(
                &PlanarKernels { kappa: self.section.kappa0.y },
                old,
                new,
                input.dt,
                &loads,
                out,
            ),
            Components::Spatial => self.residual_k(
                &SpatialKernels { kappa0: self.section.kappa0 },
                old,
                new,
                input.dt,
                &loads,
                out,
            ),
        }
        if out.iter().any(|v| !v.is_finite()) {
            return Err(BeamError::NonFiniteState { what: "step residual".into() });
        }
        Ok(())
    }

    /// The step residual on `K`-vectors, streaming along the beam: midpoint values formed on
    /// the fly (`μ new + (1 − μ) old`), `B (new − old)/dt − f(mid)` written per node and
    /// element (the arithmetic of [`Beam::rhs_into`] plus the inertia term, fused).
    fn residual_k<const K: usize, O: Kernels<K>>(
        &self,
        ops: &O,
        old: &[f64],
        new: &[f64],
        dt: f64,
        node_loads: &[Vector6<f64>],
        out: &mut [f64],
    ) {
        type V<const K: usize> = SVector<f64, K>;
        let restrict =
            |m: &Matrix6<f64>| SMatrix::<f64, K, K>::from_fn(|a, b| self.components.entry(m, a, b));
        let (m, c, d0) = (
            restrict(&self.section.mass),
            restrict(&self.section.compliance),
            restrict(&self.section.d0),
        );
        let (d1, d2) = (restrict(&self.section.d1), restrict(&self.section.d2));
        let has_d0 = d0.iter().any(|&v| v != 0.0);
        let idx = self.components.indices();
        let n = self.n_elements();
        let hs = self.mesh.lengths();
        let ws = self.mesh.weights();
        let mu = &self.mid_weight;
        let at = |i: usize| {
            let (o, x, w) = (
                V::<K>::from_column_slice(&old[i..i + K]),
                V::<K>::from_column_slice(&new[i..i + K]),
                V::<K>::from_column_slice(&mu[i..i + K]),
            );
            // mid = μ new + (1 − μ) old (bitwise as `midpoint`), and new − old
            (x.component_mul(&w) + o.component_mul(&V::<K>::from_fn(|a, _| 1.0 - w[a])), x - o)
        };
        let inv_dt = 1.0 / dt;
        // B (new − old)/dt − (node terms without x2) at node i
        let node_term = |i: usize, x1: &V<K>, dx1: &V<K>| {
            let w = ws[i];
            let mut f = ops.l1_times(x1, &(m * x1)) * w + m * dx1 * (w * inv_dt);
            if has_d0 {
                f -= d0 * x1 * w;
            }
            if !node_loads.is_empty() {
                f -= V::<K>::from_fn(|a, _| node_loads[i][idx[a]]);
            }
            f
        };
        let (x1_0, dx1_0) = at(0);
        let (x2_left, _) = at(self.left_index(0));
        let mut x1_prev = x1_0;
        let mut r_prev = node_term(0, &x1_0, &dx1_0) + x2_left;
        for e in 0..n {
            let (x1_next, dx1_next) = at((e + 1) * K);
            let mut r_next = node_term(e + 1, &x1_next, &dx1_next);
            let s = K * (n + 1 + e);
            let (x2, dx2) = at(s);
            let cx2 = c * x2;
            let h = hs[e];
            let q = (ops.e_times(&x2) - ops.l2_times(&x2, &cx2)) * (0.5 * h);
            r_prev -= x2 + q;
            r_next -= q - x2;
            let dx = x1_next - x1_prev;
            if self.has_flux_damping {
                let g = d2 * dx / h + d1 * dx * 0.5;
                let g2 = -d2 * dx / h + d1 * dx * 0.5;
                r_prev -= g;
                r_next -= g2;
            }
            let xb = (x1_prev + x1_next) * 0.5;
            let r2 =
                c * dx2 * (h * inv_dt) - (dx + (ops.l1t_times(&xb, &cx2) - ops.et_times(&xb)) * h);
            out[s..s + K].copy_from_slice(r2.as_slice());
            out[e * K..(e + 1) * K].copy_from_slice(r_prev.as_slice());
            x1_prev = x1_next;
            r_prev = r_next;
        }
        let (x2_right, _) = at(self.right_index(0));
        r_prev -= x2_right;
        out[n * K..(n + 1) * K].copy_from_slice(r_prev.as_slice());
    }

    /// Number of Jacobian entries the beam emits (fixed pattern, structural zeros included).
    pub fn jacobian_nnz(&self) -> usize {
        let kk = self.k * self.k;
        let n = self.n_elements();
        let node_blocks = if self.has_flux_damping { 3 * (n + 1) + 2 * n } else { 3 * (n + 1) };
        (node_blocks + 3 * n) * kk
    }

    /// The Jacobian's sparsity pattern `(row, col)` in emission order, shifted by the caller's
    /// row and column offsets (where the beam's rows and vector sit in a global system).
    pub fn jacobian_pattern(
        &self,
        row_offset: usize,
        col_offset: usize,
        out: &mut Vec<(usize, usize)>,
    ) {
        self.jacobian_blocks(None, |r, c, _| out.push((row_offset + r, col_offset + c)));
    }

    /// The Jacobian `∂(step residual)/∂new` values in the order of [`Beam::jacobian_pattern`].
    pub fn jacobian_values(
        &self,
        input: &StepInput<'_>,
        old: &[f64],
        new: &[f64],
        out: &mut [f64],
    ) -> Result<()> {
        self.check_input(input)?;
        check_len("jacobian values", self.jacobian_nnz(), out.len())?;
        let mut mid = vec![0.0; self.dim()];
        self.midpoint(old, new, &mut mid)?;
        let mut pos = 0;
        self.jacobian_blocks(Some((input, &mid)), |_, _, v| {
            out[pos] = v;
            pos += 1;
        });
        if out.iter().any(|v| !v.is_finite()) {
            return Err(BeamError::NonFiniteState { what: "step Jacobian".into() });
        }
        Ok(())
    }

    /// Emits `k×k` blocks `(row, col, value)`; values are zero when `data` is `None`.
    fn jacobian_blocks<F: FnMut(usize, usize, f64)>(
        &self,
        data: Option<(&StepInput<'_>, &[f64])>,
        mut emit: F,
    ) {
        let k = self.k;
        let n = self.n_elements();
        let idx = self.components.indices();
        let (m, c) = (&self.section.mass, &self.section.compliance);
        let e_mat = &self.e_mat;
        let hs = self.mesh.lengths();
        let ws = self.mesh.weights();
        let eye = Matrix6::<f64>::identity();
        // emits block `blk` (6×6, rows/cols restricted) at (row0, col0); column weights mid_weight
        let mut block =
            |row0: usize, col0: usize, blk: &Matrix6<f64>, diag_b: Option<&Matrix6<f64>>| {
                for a in 0..k {
                    for b in 0..k {
                        let mut v = blk[(idx[a], idx[b])] * self.mid_weight[col0 + b];
                        if let Some(bm) = diag_b {
                            v += bm[(idx[a], idx[b])];
                        }
                        emit(row0 + a, col0 + b, v);
                    }
                }
            };
        let zero = Matrix6::<f64>::zeros();
        // Precompute per-state quantities.
        let (dt, x1s, x2s, dead) = match data {
            Some((input, mid)) => {
                let rot = self.midpoint_rotations(input, mid);
                let (_, dead) = self.node_loads(input.time + 0.5 * input.dt, input.loads, &rot);
                let x1s: Vec<Vector6<f64>> = (0..=n).map(|i| self.x1(mid, i)).collect();
                let x2s: Vec<Vector6<f64>> = (0..n).map(|e| self.x2(mid, e)).collect();
                (input.dt, x1s, x2s, dead)
            }
            None => (
                1.0,
                vec![Vector6::zeros(); n + 1],
                vec![Vector6::zeros(); n],
                vec![Vector6::zeros(); n + 1],
            ),
        };
        let have = data.is_some();
        // Node rows.
        for node in 0..=n {
            let row0 = node * k;
            // x1_n block: −∂f/∂x1 · μ + w M/dt
            let (blk, bm) = if have {
                let x1 = &x1s[node];
                let mx1 = m * x1;
                let mut df = (self.section.d0 - (l1(x1) * m - l2(&mx1))) * ws[node];
                // dead loads: ∂(Tᵀ_mid G)/∂ω_mid ≈ (dt/2) tilde(local value)
                let (fd, md) = if dead.is_empty() {
                    (nalgebra::Vector3::zeros(), nalgebra::Vector3::zeros())
                } else {
                    halves(&dead[node])
                };
                let half = 0.5 * dt;
                let mut top = df.fixed_view_mut::<3, 3>(0, 3);
                top += tilde(&fd) * half;
                let mut bottom = df.fixed_view_mut::<3, 3>(3, 3);
                bottom += tilde(&md) * half;
                if self.has_flux_damping {
                    if node > 0 {
                        df -= self.section.d2 / hs[node - 1] - self.section.d1 * 0.5;
                    }
                    if node < n {
                        df -= self.section.d2 / hs[node] + self.section.d1 * 0.5;
                    }
                }
                (-df, m * (ws[node] / dt))
            } else {
                (zero, zero)
            };
            block(row0, self.x1_index(node, 0), &blk, Some(&bm));
            // left x2 (x2_{n−1} or x2_L)
            let (col, blk) = if node == 0 {
                (self.left_index(0), if have { eye } else { zero })
            } else {
                let e = node - 1;
                let blk = if have { eye - self.dq(&x2s[e], hs[e]) } else { zero };
                (self.x2_index(e, 0), blk)
            };
            block(row0, col, &blk, None);
            // right x2 (x2_n or x2_R)
            let (col, blk) = if node == n {
                (self.right_index(0), if have { -eye } else { zero })
            } else {
                let blk = if have { -eye - self.dq(&x2s[node], hs[node]) } else { zero };
                (self.x2_index(node, 0), blk)
            };
            block(row0, col, &blk, None);
            if self.has_flux_damping {
                if node > 0 {
                    let blk = if have {
                        -(self.section.d2 / hs[node - 1] - self.section.d1 * 0.5)
                    } else {
                        zero
                    };
                    block(row0, self.x1_index(node - 1, 0), &blk, None);
                }
                if node < n {
                    let blk = if have {
                        -(self.section.d2 / hs[node] + self.section.d1 * 0.5)
                    } else {
                        zero
                    };
                    block(row0, self.x1_index(node + 1, 0), &blk, None);
                }
            }
        }
        // Element rows.
        for e in 0..n {
            let row0 = self.x2_index(e, 0);
            let h = hs[e];
            let (b_x2, bm, b_left, b_right) = if have {
                let xb = (x1s[e] + x1s[e + 1]) * 0.5;
                let cx2 = c * x2s[e];
                let b_x2 = -(l1(&xb).transpose() * c) * h;
                let j = (l1t_jacobian(&cx2) - e_mat.transpose()) * (0.5 * h);
                (b_x2, c * (h / dt), eye - j, -eye - j)
            } else {
                (zero, zero, zero, zero)
            };
            block(row0, self.x1_index(e, 0), &b_left, None);
            block(row0, self.x1_index(e + 1, 0), &b_right, None);
            block(row0, row0, &b_x2, Some(&bm));
        }
    }

    /// `∂[(h/2)(E x2 − L2(x2) C x2)]/∂x2 = (h/2)(E − L2(x2) C + L1(C x2))`.
    fn dq(&self, x2: &Vector6<f64>, h: f64) -> Matrix6<f64> {
        let c = &self.section.compliance;
        (self.e_mat - l2(x2) * c + l1(&(c * x2))) * (0.5 * h)
    }

    /// Powers at the step midpoint (boundary, loads, damping); see [`StepPower`].
    pub fn step_power(&self, input: &StepInput<'_>, old: &[f64], new: &[f64]) -> Result<StepPower> {
        self.check_input(input)?;
        let mut mid = vec![0.0; self.dim()];
        self.midpoint(old, new, &mut mid)?;
        let rot = self.midpoint_rotations(input, &mid);
        let (loads, _) = self.node_loads(input.time + 0.5 * input.dt, input.loads, &rot);
        let mut scratch = vec![0.0; self.n_rows()];
        let damp = self.rhs(&mid, &loads, &mut scratch);
        let n = self.n_elements();
        let mut p = StepPower {
            boundary: self.x1(&mid, n).dot(&self.x2_right(&mid))
                - self.x1(&mid, 0).dot(&self.x2_left(&mid)),
            ..StepPower::default()
        };
        for node in 0..=n {
            let x1 = self.x1(&mid, node);
            if !loads.is_empty() {
                p.loads += x1.dot(&loads[node]);
            }
            p.damping += x1.dot(&damp[node]);
        }
        Ok(p)
    }

    /// Linearised operators at rest (no damping in `a`), see [`LinearOperators`].
    pub fn linear_operators(&self) -> LinearOperators {
        let k = self.k;
        let n = self.n_elements();
        let (m, c) = (&self.section.mass, &self.section.compliance);
        let hs = self.mesh.lengths();
        let ws = self.mesh.weights();
        let mut ops =
            LinearOperators { dim: self.dim(), n_rows: self.n_rows(), ..Default::default() };
        let push =
            |list: &mut Vec<(usize, usize, f64)>, r0: usize, c0: usize, blk: &Matrix6<f64>| {
                for a in 0..k {
                    for b in 0..k {
                        let v = self.components.entry(blk, a, b);
                        if v != 0.0 {
                            list.push((r0 + a, c0 + b, v));
                        }
                    }
                }
            };
        let eye = Matrix6::<f64>::identity();
        for node in 0..=n {
            push(&mut ops.b, node * k, node * k, &(m * ws[node]));
            push(&mut ops.damping, node * k, node * k, &(self.section.d0 * ws[node]));
        }
        for e in 0..n {
            let h = hs[e];
            let r = self.x2_index(e, 0);
            push(&mut ops.b, r, r, &(c * h));
            let half_e = self.e_mat * (0.5 * h);
            // node rows: +x2_e at node e, −x2_e at node e+1, plus (h/2) E x2_e at both
            push(&mut ops.a, e * k, r, &(eye + half_e));
            push(&mut ops.a, (e + 1) * k, r, &(half_e - eye));
            // element rows: x1_{e+1} − x1_e − (h/2) Eᵀ (x1_e + x1_{e+1})
            let half_et = self.e_mat.transpose() * (0.5 * h);
            push(&mut ops.a, r, e * k, &(-eye - half_et));
            push(&mut ops.a, r, (e + 1) * k, &(eye - half_et));
            // damping fluxes
            let g = self.section.d2 / h;
            let d1 = self.section.d1 * 0.5;
            push(&mut ops.damping, e * k, e * k, &(-g - d1));
            push(&mut ops.damping, e * k, (e + 1) * k, &(g + d1));
            push(&mut ops.damping, (e + 1) * k, e * k, &(g - d1));
            push(&mut ops.damping, (e + 1) * k, (e + 1) * k, &(-g + d1));
        }
        push(&mut ops.a, 0, self.left_index(0), &(-eye));
        push(&mut ops.a, n * k, self.right_index(0), &eye);
        ops
    }
}

mod balance;
pub use balance::EnergyBalance;

#[cfg(test)]
mod tests;
