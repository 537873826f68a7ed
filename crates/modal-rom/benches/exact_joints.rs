//! Criterion benches: right-hand side plus exact Jacobian of the exact-joints model
//! (theory.md §10) against the paper's modal model, 2D and 3D, in two pairings:
//!
//! * `*_rigid+N`: the controller's default exact-joints basis (per-link rigid motions + the
//!   lowest `N` constrained modes split per link, 4 in 2D, 16 in 3D) against the paper's model
//!   on the lowest constrained modes whose state count is closest;
//! * `*_paper_basis`: both models on the paper's own mode set (the exact-joints model by
//!   [`paper_reduction`]: same velocity and force coordinates, plus 4 quaternion entries for the
//!   root and each joint, against the paper model's quaternion states).

#![allow(missing_docs)] // a bench binary

use criterion::Criterion;
use modal_rom::exact_joints::{from_fields, paper_reduction, ExactJointsRom};
use modal_rom::samples;
use modal_rom::{
    BasisSettings, Input, LinkBasisSettings, ModalRom, ModeSelection, RomOptions, StructureModel,
};
use std::hint::black_box;

/// Prints the thread CPU time per call of `f` over `calls` calls (criterion's figures are
/// wall times, inflated when other jobs share the cores; thread CPU time is not).
fn cpu_report(label: &str, calls: usize, mut f: impl FnMut()) {
    let Some(c0) = ocp_transcription::thread_cpu_time() else { return };
    for _ in 0..calls {
        f();
    }
    let Some(c1) = ocp_transcription::thread_cpu_time() else { return };
    eprintln!("{label}: thread CPU {:.3e} s/call over {calls} calls", (c1 - c0) / calls as f64);
}

/// `calls` calls of `f` and nothing else: no clock is read, so that the loop also runs under
/// `valgrind --tool=callgrind` (whose instruction counts do not depend on the machine's load;
/// the vDSO clock of the thread-CPU lines does not start under valgrind).
fn profile_loop(calls: usize, mut f: impl FnMut()) {
    for _ in 0..calls {
        f();
    }
}

/// Thread CPU per call of each evaluation of `calls` in short blocks taken in turn: `ROUNDS`
/// rounds, each running one block of every evaluation (a twentieth of its line's calls). A burst
/// of load on a shared machine then lands in a few blocks of every evaluation rather than in
/// the whole figure of one; prints the lower quartile and the median over the blocks and the
/// exact-to-paper ratios at both.
fn interleaved_report(name: &str, calls: &mut [Call<'_>]) {
    const ROUNDS: usize = 200;
    let mut t = vec![Vec::with_capacity(ROUNDS); calls.len()];
    for _ in 0..ROUNDS {
        for (k, (_, n, f)) in calls.iter_mut().enumerate() {
            let block = (*n / 20).max(1);
            let Some(c0) = ocp_transcription::thread_cpu_time() else { return };
            for _ in 0..block {
                f();
            }
            let Some(c1) = ocp_transcription::thread_cpu_time() else { return };
            t[k].push((c1 - c0) / block as f64);
        }
    }
    let at = |v: &mut Vec<f64>, q: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q).round() as usize]
    };
    let stats: Vec<[f64; 2]> = t.iter_mut().map(|v| [at(v, 0.25), at(v, 0.5)]).collect();
    for ((what, _, _), [q1, med]) in calls.iter().zip(&stats) {
        eprintln!(
            "{name}/{what}: interleaved, {ROUNDS} blocks: lower quartile {:.3} µs, median {:.3} µs",
            q1 * 1e6,
            med * 1e6
        );
    }
    for (exact, paper) in [(0, 1), (2, 3)] {
        let (e, p) = (stats[exact], stats[paper]);
        eprintln!(
            "{name}: {} / {}: {:.3} (lower quartiles), {:.3} (medians)",
            calls[exact].0,
            calls[paper].0,
            e[0] / p[0],
            e[1] / p[1]
        );
    }
}

/// The paper's 2D or 3D two-link sample (`elements` per link, modes `selection`) and its inputs.
fn sample(
    spatial: bool,
    elements: usize,
    selection: &ModeSelection,
) -> (samples::Sample, Vec<Input>) {
    let opts = RomOptions::default();
    let s = if spatial {
        samples::paper_3d(elements, 0.0, true, selection, &opts)
    } else {
        samples::paper_2d(elements, 0.0, true, selection, &opts)
    }
    .expect("paper sample");
    let inputs = if spatial {
        samples::inputs_3d(&s.structure, &s.model)
    } else {
        samples::inputs_2d(&s.structure, &s.model)
    }
    .expect("inputs");
    (s, inputs)
}

/// The exact-joints model on the per-link basis (rigid link motions + the lowest `elastic`
/// constrained modes at 0° split per link), and the paper's model (with quaternion states)
/// on the lowest constrained modes whose state count is closest to the exact-joints one.
fn models(spatial: bool, elements: usize, elastic: usize) -> (ExactJointsRom, ModalRom) {
    let (s, inputs) = sample(spatial, elements, &ModeSelection::Lowest(1));
    let model: &StructureModel = &s.model;
    let modes = model.modes(&BasisSettings::default()).expect("modes");
    let sel = modes.select(&ModeSelection::Lowest(modes.n_rigid() + elastic)).expect("select");
    let exact = from_fields(
        &s.structure,
        model,
        &[sel.phi1()],
        &LinkBasisSettings::default(),
        Some(&model.damping),
        &inputs,
    )
    .expect("exact-joints model");
    let target = exact.n_state();
    let mut best: Option<ModalRom> = None;
    for k in modes.n_rigid() + 1..modes.n_modes() {
        let picked = modes.select(&ModeSelection::Lowest(k)).expect("select");
        let rom = ModalRom::new(&picked, Some(&model.damping), &inputs, &RomOptions::default())
            .expect("paper model");
        let better = best
            .as_ref()
            .is_none_or(|b| rom.n_state().abs_diff(target) < b.n_state().abs_diff(target));
        let over = rom.n_state() > target + 8;
        if better {
            best = Some(rom);
        }
        if over {
            break;
        }
    }
    (exact, best.expect("a paper model"))
}

/// A state away from the reference: velocities and forces from a fixed pattern, every joint
/// turned by 0.7 rad about a skew axis (3D) or about the plane's normal `y` (2D: the planar
/// model's joint rotations stay in the plane).
fn exact_state(rom: &ExactJointsRom, spatial: bool) -> Vec<f64> {
    let mut x = rom.reference_state();
    let k = rom.n_p() + rom.n_p2();
    for (i, v) in x[..k].iter_mut().enumerate() {
        *v = 0.2 * (0.37 * i as f64 + 0.1).sin();
    }
    for j in 0..rom.n_joints() {
        let o = rom.joint_offset(j);
        let r = rom.joint_quaternion(&x, j);
        let (c, s) = ((0.35f64).cos(), (0.35f64).sin());
        let axis =
            if spatial { nalgebra::Vector3::new(0.2, 1.0, 0.1) } else { nalgebra::Vector3::y() };
        let a = axis.normalize() * s;
        // r ⊗ (c, a)
        let (r0, rv) = (r[0], nalgebra::Vector3::new(r[1], r[2], r[3]));
        let v = a * r0 + rv * c + rv.cross(&a);
        x[o..o + 4].copy_from_slice(&[r0 * c - rv.dot(&a), v.x, v.y, v.z]);
    }
    x
}

/// Both models on the paper's mode set of the 2D / 3D scene.
fn paper_basis_models(spatial: bool, elements: usize) -> (ExactJointsRom, ModalRom) {
    let opts = RomOptions::default();
    let selection =
        if spatial { samples::paper_3d_selection() } else { samples::paper_2d_selection() };
    let (s, inputs) = sample(spatial, elements, &selection);
    let modes = s.basis.select(&selection).expect("select");
    let exact = paper_reduction(&s.structure, &s.model, &modes, Some(&s.model.damping), &inputs)
        .expect("exact-joints model on the paper basis");
    let paper = ModalRom::new(&modes, Some(&s.model.damping), &inputs, &opts).expect("paper");
    (exact, paper)
}

/// One timed evaluation: its name, the calls of its thread-CPU line, the call.
type Call<'a> = (&'static str, usize, Box<dyn FnMut() + 'a>);

/// One pairing: its models, state and buffers.
struct Pair {
    exact: ExactJointsRom,
    paper: ModalRom,
    x: Vec<f64>,
    q: Vec<f64>,
    u: Vec<f64>,
}

impl Pair {
    fn new(name: &str, spatial: bool, elastic: Option<usize>) -> Self {
        let (exact, paper) = match elastic {
            Some(e) => models(spatial, 20, e),
            None => paper_basis_models(spatial, 20),
        };
        let x = exact_state(&exact, spatial);
        let nu = exact.n_inputs();
        let u: Vec<f64> = (0..nu).map(|i| 0.3 * (i as f64 + 1.0)).collect();
        let np = paper.n_state();
        let q: Vec<f64> = (0..np).map(|i| 0.1 * (i as f64 * 0.37).sin()).collect();
        eprintln!(
            "{name}: exact-joints state {} (p {}, p2 {}), paper state {np} ({} modes)",
            exact.n_state(),
            exact.n_p(),
            exact.n_p2(),
            paper.n_modes()
        );
        Pair { exact, paper, x, q, u }
    }

    /// The four evaluations, each as a closure over its own output buffers.
    fn calls(&self) -> [Call<'_>; 4] {
        let (n, nu, np) = (self.exact.n_state(), self.u.len(), self.paper.n_state());
        let (mut f, mut jx, mut ju) = (vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
        let mut f2 = vec![0.0; n];
        let (mut fp, mut jp, mut jup) = (vec![0.0; np], vec![0.0; np * np], vec![0.0; np * nu]);
        let mut fp2 = vec![0.0; np];
        let (exact, paper, x, q, u) = (&self.exact, &self.paper, &self.x, &self.q, &self.u);
        [
            (
                "exact_rhs_and_jacobian",
                2_000,
                Box::new(move || {
                    exact
                        .rhs_and_jacobian(black_box(x), black_box(u), &mut f, &mut jx, &mut ju)
                        .expect("exact")
                }),
            ),
            (
                "paper_rhs_and_jacobian",
                20_000,
                Box::new(move || {
                    paper
                        .rhs_and_jacobian(black_box(q), black_box(u), &mut fp, &mut jp, &mut jup)
                        .expect("paper")
                }),
            ),
            (
                "exact_rhs",
                2_000,
                Box::new(move || exact.rhs(black_box(x), black_box(u), &mut f2).expect("exact")),
            ),
            (
                "paper_rhs",
                20_000,
                Box::new(move || paper.rhs(black_box(q), black_box(u), &mut fp2).expect("paper")),
            ),
        ]
    }
}

/// The pairings: name, spatial, elastic modes per link (`None`: the paper's basis).
const PAIRS: [(&str, bool, Option<usize>); 4] = [
    ("2d_rigid+4", false, Some(4)),
    ("3d_rigid+16", true, Some(16)),
    ("2d_paper_basis", false, None),
    ("3d_paper_basis", true, None),
];

/// The bench's own arguments (without them: criterion, with criterion's arguments).
const USAGE: &str = "\
usage: cargo bench -p modal-rom --bench exact_joints -- [CRITERION ARGS]
       cargo bench -p modal-rom --bench exact_joints -- --cpu [--pair NAME] [--profile CALLS [--paper]]

  (no --cpu)        thread-CPU lines of every pairing, then the criterion benches
  --cpu             the thread-CPU lines only (no criterion)
  --pair NAME       with --cpu: this pairing only (2d_rigid+4, 3d_rigid+16, 2d_paper_basis,
                    3d_paper_basis)
  --profile CALLS   with --cpu: only a loop of CALLS exact-joints rhs + Jacobian calls (for
                    `perf record`, or `valgrind --tool=callgrind`: instruction counts, the
                    same whatever the machine's load)
  --paper           with --profile: the loop calls the paper model's rhs + Jacobian instead
  --dump PATH       with --cpu: also write the exact-joints rhs (alone and with the
                    Jacobians), ∂f/∂x and ∂f/∂u of each selected pairing to PATH.NAME, one
                    value per line (to compare two builds' results)";

/// `--cpu` options: the pairing filter and the profile loop length.
#[derive(Default)]
struct CpuOnly {
    pair: Option<String>,
    profile: Option<usize>,
    /// The profile loop calls the paper model.
    paper: bool,
    dump: Option<String>,
}

/// `Ok(None)`: no `--cpu`, run criterion; `Err`: a message naming the argument.
fn parse(args: &[String]) -> Result<Option<CpuOnly>, String> {
    let (mut cpu, mut opts) = (false, CpuOnly::default());
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value =
            |name: &str| it.next().cloned().ok_or_else(|| format!("`{name}` needs a value"));
        match a.as_str() {
            "--cpu" => cpu = true,
            "--pair" => {
                let v = value("--pair")?;
                if !PAIRS.iter().any(|p| p.0 == v) {
                    return Err(format!("`--pair {v}`: no such pairing"));
                }
                opts.pair = Some(v);
            }
            "--profile" => {
                let v = value("--profile")?;
                let n =
                    v.parse().ok().filter(|n: &usize| *n > 0).ok_or_else(|| {
                        format!("`--profile {v}`: not a positive number of calls")
                    })?;
                opts.profile = Some(n);
            }
            "--paper" => opts.paper = true,
            "--dump" => opts.dump = Some(value("--dump")?),
            _ => {}
        }
    }
    if opts.paper && opts.profile.is_none() {
        return Err("`--paper` goes with `--profile`".into());
    }
    match (cpu, opts.pair.is_some() || opts.profile.is_some() || opts.dump.is_some()) {
        (false, false) => Ok(None),
        (false, true) => Err("`--pair`, `--profile` and `--dump` go with `--cpu`".into()),
        (true, _) => Ok(Some(opts)),
    }
}

/// The exact-joints model's rhs (alone, then with the Jacobians), `∂f/∂x` and `∂f/∂u` at the
/// pairing's state, one value per line (`{:e}`, shortest round-trip form).
fn dump(pair: &Pair, path: &str) {
    let (n, nu) = (pair.exact.n_state(), pair.u.len());
    let (mut f0, mut f, mut jx, mut ju) =
        (vec![0.0; n], vec![0.0; n], vec![0.0; n * n], vec![0.0; n * nu]);
    pair.exact.rhs(&pair.x, &pair.u, &mut f0).expect("exact rhs");
    pair.exact.rhs_and_jacobian(&pair.x, &pair.u, &mut f, &mut jx, &mut ju).expect("exact");
    let text: String = [f0, f, jx, ju].iter().flatten().map(|v| format!("{v:e}\n")).collect();
    if let Err(e) = std::fs::write(path, text) {
        eprintln!("error: `--dump`: cannot write {path}: {e}");
        std::process::exit(2);
    }
}

/// Thread-CPU lines (or the profile loop) of the selected pairings.
fn cpu_lines(opts: &CpuOnly) {
    for (name, spatial, elastic) in PAIRS {
        if opts.pair.as_deref().is_some_and(|p| p != name) {
            continue;
        }
        let pair = Pair::new(name, spatial, elastic);
        if let Some(path) = &opts.dump {
            dump(&pair, &format!("{path}.{name}"));
        }
        let mut calls = pair.calls();
        let profiled = if opts.paper { "paper_rhs_and_jacobian" } else { "exact_rhs_and_jacobian" };
        for (what, n, f) in &mut calls {
            match opts.profile {
                Some(n) if *what == profiled => profile_loop(n, f),
                Some(_) => {}
                None => cpu_report(&format!("{name}/{what}"), *n, f),
            }
        }
        if opts.profile.is_none() {
            interleaved_report(name, &mut calls);
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.iter().any(|a| a == "--help" || a == "-h") && !args.iter().any(|a| a == "--cpu") {
        println!("{USAGE}\n\ncriterion's arguments:");
    }
    match parse(&args) {
        Ok(Some(opts)) => cpu_lines(&opts),
        Ok(None) => {
            cpu_lines(&CpuOnly::default());
            let mut c = Criterion::default().configure_from_args();
            let mut group = c.benchmark_group("exact_joints");
            for (name, spatial, elastic) in PAIRS {
                let pair = Pair::new(name, spatial, elastic);
                for (what, _, mut f) in pair.calls() {
                    group.bench_function(format!("{name}/{what}"), |b| b.iter(&mut f));
                }
            }
            group.finish();
            c.final_summary();
        }
        Err(e) => {
            eprintln!("error: {e}\n\n{USAGE}");
            std::process::exit(2);
        }
    }
}
