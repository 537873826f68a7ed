"""CasADi peers of `cargo xtask bench peers`: solves one exported first-sample problem with
`sqpmethod` (Gauss-Newton, compiled) and IPOPT (exact Hessian).

Usage: python casadi_peers.py DIR [--only sqpmethod,ipopt] [--qpsol hpipm|qpoases|...]
                               [--max-iter-ls N] [--check-only] [--jit]
                               [--ipopt-hessian exact|limited-memory] [--max-iter N]

Two controller models, by problem.json's `model`:

* `paper` (default): the modal model (29) with Lawson RK4, described below.
* `exact-joints`: the exact-joints model (docs/theory.md §10) from its export
  (exact_joints.py: the right-hand side on CasADi SX scalars) with the implicit midpoint rule
  flexmpc uses (`substeps` steps per interval, each midpoint solved by CasADi's `newton`
  rootfinder to abstol = newton_tolerance, sensitivities through (I - h/2 f_x) as flexmpc's).
  First the right-hand side is compared with flexmpc's at problem.json's `rhs_check` samples
  (flexmpc's optimal nodes and synthetic states with joints turned up to 3 rad): `rhs_check`
  in the output holds the worst normwise relative difference max|df| / max|f| per sample kind
  (--check-only stops there). sqpmethod runs on the CasADi virtual machine (--jit compiles
  the NLP functions), IPOPT with the limited-memory Hessian unless --ipopt-hessian exact.
  --max-iter N caps the iterations of both peers (defaults 200 and 1000).

Inputs in DIR (written by xtask/src/peers.rs):
  * model.json + *.npy: the modal model (modal-rom's export), used here:
    sigma (m x m), omega (m), q2_modes, gamma1[l, i, j] (m x m x m),
    gamma2[l, i, j] (l, j over q2 coordinates, i over m), b_u (m x nu),
    a_xi (nxi x nxi), gamma_xi[l, i, j] (l, i over quaternion modes, j over m).
  * problem.json: the OCP (33)-(35): q, r, terminal, x_ref, u_ref, u_min, u_max, x0,
    intervals Nc, interval dt, substeps n; linear_part L and lawson_e = exp(L h/2),
    h = dt/n, exactly as flexmpc computes them; the start (start_states, start_controls:
    the linear MPC plan) and flexmpc's solution (flexmpc_states, flexmpc_controls,
    flexmpc_cost).

The NLP is flexmpc's multiple-shooting transcription (docs/theory.md §8): variables
s_0 .. s_Nc, u_0 .. u_{Nc-1}; constraints s_0 = x0 and s_{k+1} = Phi(s_k, u_k), with Phi
n Lawson RK4 substeps of q' = f(q, u) (eq. 29, the conventions of model.json):
g = f - L q, E = exp(L h/2),
  k1 = g(x), k2 = g(E x + h/2 E k1), k3 = g(E x + h/2 k2), k4 = g(E(E x + h k3)),
  x+ = E(E x + h/6 E k1 + h/3 (k2 + k3)) + h/6 k4;
bounds u_min <= u_k <= u_max; cost
  J = sum_k c_k dt 1/2 |s_k - x_ref|_Q^2 + 1/2 |s_Nc - x_ref|_P^2
      + sum_k dt 1/2 |u_k - u_ref|_R^2,  c_0 = c_Nc = 1/2, else 1.

The solutions are written to DIR/sqpmethod_solution.json and DIR/ipopt_solution.json
(states: Nc + 1 node vectors, controls: Nc vectors, cost, status), the format
`cargo xtask bench peers --start-from` reads (it reads ipopt_solution.json).

sqpmethod: CasADi's SQP with the Gauss-Newton Hessian sigma H (H the constant Hessian of the
quadratic cost; the constraint curvature is dropped), supplied as `hess_lag`; the objective
gradient and constraint Jacobian as `jac_fg`, with [A_k B_k] = dPhi/d(s_k, u_k) from forward
sensitivities through the substeps (`sensitivities`). jac_fg and the NLP's own functions are
generated as C and compiled by gcc -O2 (CasADi's `shell` JIT) before the solve; the build time
(Python process CPU plus the compiler's, and wall) is reported apart from the solve. QP solver
HPIPM (default settings, the OCP stages given by N, nx, nu; s_0 fixed by its bounds) or any
CasADi conic plugin (--qpsol). Merit line search with --max-iter-ls backtracking trials
(default 3, CasADi's; when they fail the last trial is taken); stops at tol_pr = tol_du = 1e-8
or after 200 iterations.

Output: one JSON line on stdout with
  check_cost_rel: |J(flexmpc optimum) - flexmpc_cost| / |flexmpc_cost| (this NLP's objective
                  at flexmpc's solution against flexmpc's own cost),
  check_defect:   max |constraint residual| of this NLP at flexmpc's solution,
  sqpmethod: {qpsol, status, success, cost, iterations, inf_pr, inf_du (max constraint
          violation and max |Lagrangian gradient| at the solution), cpu_s (process CPU time of
          the solve), wall_s, build_cpu_s, build_wall_s, max_defect (in the NLP with s_0 = x0)},
  ipopt: {status, cost, iterations, inf_pr, inf_du, cpu_s (process CPU time of the solve),
          wall_s}.
IPOPT runs with the exact Hessian of the Lagrangian (CasADi's AD of the expression graph),
tol 1e-10, MUMPS.
"""

import json
import os
import sys
import time

import casadi as ca
import numpy as np


def sparse(a):
    """A constant with the exact zeros of `a` dropped from the sparsity."""
    return ca.sparsify(ca.DM(np.asarray(a, dtype=float)))


def load(d):
    with open(os.path.join(d, "model.json")) as f:
        meta = json.load(f)
    with open(os.path.join(d, "problem.json")) as f:
        prob = json.load(f)
    arr = {k: np.load(os.path.join(d, v["file"])) for k, v in meta["arrays"].items()}
    return meta, prob, arr


def remainder(meta, prob, arr):
    """g(q, u) = f(q, u) - L q: the quadratic terms and the input (eq. 29)."""
    m, nq2, nxi, nu = meta["n_modes"], meta["n_q2"], meta["n_xi"], meta["n_inputs"]
    nx = prob["nx"]
    assert nx == m + nq2 + nxi, "state size of model.json and problem.json differ"
    q = ca.SX.sym("q", nx)
    u = ca.SX.sym("u", nu)
    q1, q2, qx = q[:m], q[m:m + nq2], q[m + nq2:]
    g1 = ca.mtimes(sparse(arr["b_u"]), u)
    g2 = ca.SX.zeros(nq2)
    g1x = ca.SX.zeros(nxi)
    gam1 = arr["gamma1"]
    for l in range(m):
        if np.any(gam1[l]):
            g1 -= q1[l] * ca.mtimes(sparse(gam1[l]), q1)
    if nq2:
        gam2 = arr["gamma2"]
        for l in range(nq2):
            if np.any(gam2[l]):
                # out[i] -= G[l, i, j] q2_j q2_l; out[q2_j] += G[l, i, j] q1_i q2_l
                g1 -= q2[l] * ca.mtimes(sparse(gam2[l]), q2)
                g2 += q2[l] * ca.mtimes(sparse(gam2[l].T), q1)
    if nxi:
        ainv = np.linalg.inv(arr["a_xi"])
        gx = arr["gamma_xi"]
        for l in range(nxi):
            s = ainv @ gx[l]
            if np.any(s):
                g1x += qx[l] * ca.mtimes(sparse(s), q1)
    g = ca.vertcat(g1, g2, g1x)
    return ca.Function("g", [q, u], [g]), q, u


def interval_map(meta, prob, arr):
    gfun, _, _ = remainder(meta, prob, arr)
    nx, nu = prob["nx"], prob["nu"]
    e = sparse(prob["lawson_e"])
    n = prob["substeps"]
    h = prob["interval"] / n
    x0 = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", nu)
    x = x0
    for _ in range(n):
        k1 = gfun(x, u)
        ex = ca.mtimes(e, x)
        ek1 = ca.mtimes(e, k1)
        k2 = gfun(ex + 0.5 * h * ek1, u)
        k3 = gfun(ex + 0.5 * h * k2, u)
        k4 = gfun(ca.mtimes(e, ex + h * k3), u)
        x = ca.mtimes(e, ex + h / 6.0 * ek1 + h / 3.0 * (k2 + k3)) + h / 6.0 * k4
    return ca.Function("Phi", [x0, u], [x])


def x_ref(prob, k):
    """The state reference at node k (the nodes' own when the reference varies)."""
    nodes = prob.get("x_ref_nodes") or []
    return np.array(nodes[k] if nodes else prob["x_ref"])


def nlp(prob, phi):
    nx, nu, nc = prob["nx"], prob["nu"], prob["intervals"]
    dt = prob["interval"]
    qw, rw, pw = (np.array(prob[k]) for k in ("q", "r", "terminal"))
    ur = np.array(prob["u_ref"])
    s = [ca.MX.sym(f"s{k}", nx) for k in range(nc + 1)]
    uu = [ca.MX.sym(f"u{k}", nu) for k in range(nc)]
    w, lbw, ubw = [], [], []
    j = 0
    g = [s[0] - np.array(prob["x0"])]
    for k in range(nc + 1):
        e = s[k] - x_ref(prob, k)
        c = 0.5 * dt if k in (0, nc) else dt
        j += 0.5 * c * ca.bilin(qw, e, e)
        if k == nc:
            j += 0.5 * ca.bilin(pw, e, e)
    for k in range(nc):
        e = uu[k] - ur
        j += 0.5 * dt * ca.bilin(rw, e, e)
        g.append(phi(s[k], uu[k]) - s[k + 1])
    inf = [np.inf] * nx
    for k in range(nc + 1):
        w.append(s[k])
        lbw += [-np.inf] * nx
        ubw += inf
        if k < nc:
            w.append(uu[k])
            lbw += prob["u_min"]
            ubw += prob["u_max"]
    return {"x": ca.vertcat(*w), "f": j, "g": ca.vertcat(*g)}, lbw, ubw


def sensitivities(meta, prob, arr):
    """Phi and its Jacobian [A B] = dPhi/d(x, u) as MX functions of dense matrix products.

    The forward sensitivities are propagated through the Lawson RK4 substeps with the
    recursion of the integrator itself (X = dx/d(x0, u), K_i = dg/dq(y_i) Y_i + [0 dg/du]),
    the scheme flexmpc integrates; the remainder g and its Jacobian dg/dq are scalar (SX)
    functions called inside. Differentiating the expanded scalar graph instead would give
    (nx + nu) times the graph of Phi as straight-line code (tens of millions of operations at
    the 3D sizes), too large to compile.
    """
    gfun, qs, us = remainder(meta, prob, arr)
    nx, nu = prob["nx"], prob["nu"]
    gq = ca.Function("gq", [qs, us], [ca.jacobian(gfun(qs, us), qs)])
    gu = ca.Function("gu", [qs, us], [ca.jacobian(gfun(qs, us), us)])
    bu = ca.sparsify(ca.horzcat(ca.DM(nx, nx), gu(np.zeros(nx), np.zeros(nu))))
    e = sparse(prob["lawson_e"])
    n = prob["substeps"]
    h = prob["interval"] / n
    x0 = ca.MX.sym("x", nx)
    u = ca.MX.sym("u", nu)
    x = x0
    xs = ca.MX(ca.horzcat(ca.DM.eye(nx), ca.DM(nx, nu)))

    def stage(y, ys):
        return gfun(y, u), ca.mtimes(gq(y, u), ys) + bu

    for _ in range(n):
        k1, k1s = stage(x, xs)
        ex, exs = ca.mtimes(e, x), ca.mtimes(e, xs)
        ek1, ek1s = ca.mtimes(e, k1), ca.mtimes(e, k1s)
        k2, k2s = stage(ex + 0.5 * h * ek1, exs + 0.5 * h * ek1s)
        k3, k3s = stage(ex + 0.5 * h * k2, exs + 0.5 * h * k2s)
        k4, k4s = stage(ca.mtimes(e, ex + h * k3), ca.mtimes(e, exs + h * k3s))
        x = ca.mtimes(e, ex + h / 6.0 * ek1 + h / 3.0 * (k2 + k3)) + h / 6.0 * k4
        xs = ca.mtimes(e, exs + h / 6.0 * ek1s + h / 3.0 * (k2s + k3s)) + h / 6.0 * k4s
    return ca.Function("Phi", [x0, u], [x]), ca.Function("PhiS", [x0, u], [x, xs])


def gauss_newton_nlp(prob, phi, phis, jit):
    """The same NLP for `sqpmethod`: s_0 fixed by its bounds (lbx = ubx = x0) instead of the
    constraint s_0 = x0, constraints the gaps Phi(s_k, u_k) - s_{k+1} in stage order (the
    [gap_0 gap_1 ...] layout HPIPM reads), the cost 1/2 (w - w_ref)' H (w - w_ref) with the
    constant block-diagonal H of the trapezoidal weights, and the Gauss-Newton Hessian of the
    Lagrangian sigma H (constraint curvature dropped; the cost is quadratic in w, so this is
    the Gauss-Newton Hessian of its residual sum of squares). Returns the NLP, the explicit
    derivative functions and the bounds."""
    nx, nu, nc = prob["nx"], prob["nu"], prob["intervals"]
    dt = prob["interval"]
    qw, rw, pw = (np.array(prob[k]) for k in ("q", "r", "terminal"))
    blocks, wref, lbw, ubw = [], [], [], []
    for k in range(nc + 1):
        c = 0.5 * dt if k in (0, nc) else dt
        blocks.append(c * qw + (pw if k == nc else 0.0))
        wref += list(x_ref(prob, k))
        lbw += prob["x0"] if k == 0 else [-np.inf] * nx
        ubw += prob["x0"] if k == 0 else [np.inf] * nx
        if k < nc:
            blocks.append(dt * rw)
            wref += prob["u_ref"]
            lbw += prob["u_min"]
            ubw += prob["u_max"]
    hess = ca.sparsify(ca.diagcat(*[ca.DM(b) for b in blocks]))
    nw = hess.shape[0]
    w = ca.MX.sym("w", nw)
    p = ca.MX.sym("p", 0)
    m = ca.reshape(w[: nc * (nx + nu)], nx + nu, nc)
    s, uu = m[:nx, :], m[nx:, :]
    snext = ca.horzcat(m[:nx, 1:], w[nc * (nx + nu):])
    dw = w - np.array(wref)
    hdw = ca.mtimes(hess, dw)
    f = 0.5 * ca.dot(dw, hdw)
    g = ca.vec(phi.map(nc)(s, uu) - snext)
    xn, sens = phis.map(nc)(s, uu)
    gaps = ca.vec(xn - snext)
    minus_i = ca.MX(-ca.DM.eye(nx))
    rows = []
    for k in range(nc):
        ab = sens[:, k * (nx + nu):(k + 1) * (nx + nu)]
        left = k * (nx + nu)
        right = nw - left - (nx + nu) - nx
        rows.append(ca.horzcat(ca.MX(nx, left), ab, minus_i, ca.MX(nx, right)))
    jac = ca.vertcat(*rows)
    jopts = dict(jit)
    jac_fg = ca.Function("nlp_jac_fg", [w, p], [f, hdw, gaps, jac], ["x", "p"],
                         ["f", "grad_f_x", "g", "jac_g_x"], jopts)
    lam_f = ca.MX.sym("lam_f")
    lam_g = ca.MX.sym("lam_g", nc * nx)
    hess_lag = ca.Function("nlp_hess_l", [w, p, lam_f, lam_g], [lam_f * ca.MX(hess)],
                           ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
    return {"x": w, "p": p, "f": f, "g": g}, jac_fg, hess_lag, lbw, ubw


def sqpmethod(prob, maps, w0, qpsol, max_iter_ls, compiled=True, max_iter=200):
    """Solves the NLP with CasADi's `sqpmethod`, Gauss-Newton Hessian, `qpsol`; with
    `compiled` every NLP function generated as C and compiled by gcc -O2 before the solve.
    `maps()` builds (Phi, PhiS): the interval map and its map with sensitivities."""
    nx, nu, nc = prob["nx"], prob["nu"], prob["intervals"]
    jit = {"jit": True, "compiler": "shell", "jit_cleanup": True,
           "jit_options": {"flags": ["-O2"], "verbose": False}} if compiled else {}
    c0, t0, ch0 = time.process_time(), time.perf_counter(), children_cpu()
    phi, phis = maps()
    problem, jac_fg, hess_lag, lbw, ubw = gauss_newton_nlp(prob, phi, phis, jit)
    qopts = {"printLevel": "none", "error_on_fail": False} if qpsol == "qpoases" else {}
    # HPIPM with its default settings reads the OCP stages from the variable layout
    if qpsol == "hpipm":
        qopts = {"N": nc, "nx": [nx] * (nc + 1), "nu": [nu] * nc + [0],
                 "ng": [0] * (nc + 1), "error_on_fail": False,
                 "hpipm": {}}
    opts = dict(jit)
    opts.update({
        "hess_lag": hess_lag,
        "jac_fg": jac_fg,
        "qpsol": qpsol,
        "qpsol_options": qopts,
        "max_iter": max_iter,
        "max_iter_ls": max_iter_ls,
        "tol_pr": 1e-8,
        "tol_du": 1e-8,
        "print_header": False,
        "print_iteration": os.environ.get("PEERS_LOG") is not None,
        "print_status": False,
        "print_time": False,
        "error_on_fail": False,
    })
    solver = ca.nlpsol("sqpmethod", "sqpmethod", problem, opts)
    build_cpu = time.process_time() - c0 + children_cpu() - ch0
    build_wall = time.perf_counter() - t0
    ng = nc * nx
    c0, t0 = time.process_time(), time.perf_counter()
    sol = solver(x0=w0, lbx=lbw, ubx=ubw, lbg=np.zeros(ng), ubg=np.zeros(ng))
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    st = solver.stats()
    if os.environ.get("PEERS_LOG") is not None:
        print({k: v for k, v in st.items() if k.startswith("t_") or k.startswith("n_")},
              file=sys.stderr)
    # residuals at the solution (the stats hold no iteration history): constraint violation
    # and the infinity norm of the Lagrangian's gradient
    _, grad, gaps, jac = jac_fg(sol["x"], [])
    xs = np.array(sol["x"]).ravel()
    viol = max(float(np.max(np.abs(np.array(gaps)))),
               float(np.max(np.maximum(np.array(lbw) - xs, 0.0))),
               float(np.max(np.maximum(xs - np.array(ubw), 0.0))))
    lag = grad + ca.mtimes(jac.T, sol["lam_g"]) + sol["lam_x"]
    return sol, {
        "qpsol": qpsol,
        "status": st.get("return_status", "?"),
        "success": bool(st.get("success", False)),
        "cost": float(sol["f"]),
        "iterations": int(st.get("iter_count", 0)),
        "inf_pr": viol,
        "inf_du": float(np.max(np.abs(np.array(lag)))),
        "cpu_s": cpu,
        "wall_s": wall,
        "build_cpu_s": build_cpu,
        "build_wall_s": build_wall,
    }


def children_cpu():
    t = os.times()
    return t.children_user + t.children_system


def unstack(prob, w):
    nx, nu, nc = prob["nx"], prob["nu"], prob["intervals"]
    states, controls, i = [], [], 0
    for k in range(nc + 1):
        states.append(w[i:i + nx].tolist())
        i += nx
        if k < nc:
            controls.append(w[i:i + nu].tolist())
            i += nu
    return states, controls


def stack(prob, states, controls):
    nc = prob["intervals"]
    v = []
    for k in range(nc + 1):
        v += prob[states][k]
        if k < nc:
            v += prob[controls][k]
    return np.array(v)


def ipopt(problem, lbw, ubw, w0, hessian="exact", max_iter=1000):
    """IPOPT with the exact Hessian of the Lagrangian (AD of the MX graph), or `hessian` =
    limited-memory (L-BFGS), tol 1e-10."""
    ng = problem["g"].shape[0]
    opts = {
        "ipopt.tol": 1e-10,
        "ipopt.print_level": 5 if os.environ.get("PEERS_LOG") is not None else 0,
        "print_time": False,
        "ipopt.max_iter": max_iter,
        "ipopt.hessian_approximation": hessian,
    }
    solver = ca.nlpsol("ipopt", "ipopt", problem, opts)
    c0, t0 = time.process_time(), time.perf_counter()
    sol = solver(x0=w0, lbx=lbw, ubx=ubw, lbg=np.zeros(ng), ubg=np.zeros(ng))
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    st = solver.stats()
    its = st.get("iterations", {})
    return sol, {
        "status": st["return_status"],
        "hessian": hessian,
        "cost": float(sol["f"]),
        "iterations": int(st["iter_count"]),
        "inf_pr": float(its["inf_pr"][-1]) if its else float("nan"),
        "inf_du": float(its["inf_du"][-1]) if its else float("nan"),
        "cpu_s": cpu,
        "wall_s": wall,
    }


def write_solution(d, name, prob, sol, status):
    states, controls = unstack(prob, np.array(sol["x"]).ravel())
    with open(os.path.join(d, name), "w") as f:
        json.dump({"states": states, "controls": controls, "cost": float(sol["f"]),
                   "status": status}, f)


def main():
    args = sys.argv[1:]
    d = args[0]
    peers = ["sqpmethod", "ipopt"]
    qpsol = "hpipm"
    max_iter_ls = 3
    check_only, jit_exact, ipopt_hessian, max_iter = False, False, None, None
    rest = args[1:]
    while rest:
        a = rest.pop(0)
        if a == "--only":
            peers = rest.pop(0).split(",")
        elif a == "--qpsol":
            qpsol = rest.pop(0)
        elif a == "--max-iter-ls":
            max_iter_ls = int(rest.pop(0))
        elif a == "--max-iter":
            max_iter = int(rest.pop(0))
        elif a == "--check-only":
            check_only = True
        elif a == "--jit":
            jit_exact = True
        elif a == "--ipopt-hessian":
            ipopt_hessian = rest.pop(0)
        else:
            sys.exit(f"unknown argument {a}")
    out = {}
    with open(os.path.join(d, "problem.json")) as f:
        prob = json.load(f)
    if prob.get("model") == "exact-joints":
        sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
        import exact_joints
        meta, arr = exact_joints.load_model(d)
        c0 = time.process_time()
        phi, phis, f, jac = exact_joints.midpoint_maps(meta, arr, prob)
        out["rhs_check"] = exact_joints.check(f, prob["rhs_check"])
        out["model_build_cpu_s"] = time.process_time() - c0
        out["rhs_instructions"] = f.n_instructions()
        out["jacobian_instructions"] = jac.n_instructions()
        if check_only:
            print(json.dumps(out).replace("NaN", "null"))
            return

        def maps():
            return phi, phis
        compiled = jit_exact
        hessian = ipopt_hessian or "limited-memory"
    else:
        meta, prob, arr = load(d)
        phi = interval_map(meta, prob, arr)

        def maps():
            return sensitivities(meta, prob, arr)
        compiled = True
        hessian = ipopt_hessian or "exact"
    problem, lbw, ubw = nlp(prob, phi)
    fg = ca.Function("fg", [problem["x"]], [problem["f"], problem["g"]])
    jf, gf = fg(stack(prob, "flexmpc_states", "flexmpc_controls"))
    jf = float(jf)
    out.update({
        "check_cost": jf,
        "check_cost_rel": abs(jf - prob["flexmpc_cost"]) / abs(prob["flexmpc_cost"]),
        "check_defect": float(np.max(np.abs(np.array(gf)))),
    })
    # the checks first (stderr), a solve that is stopped still leaves them
    print(json.dumps(out).replace("NaN", "null"), file=sys.stderr, flush=True)
    w0 = stack(prob, "start_states", "start_controls")
    if "sqpmethod" in peers:
        sol, out["sqpmethod"] = sqpmethod(prob, maps, w0, qpsol, max_iter_ls, compiled,
                                          max_iter or 200)
        # the optimum in IPOPT's NLP (constraint s_0 = x0 included)
        _, gs = fg(sol["x"])
        out["sqpmethod"]["max_defect"] = float(np.max(np.abs(np.array(gs))))
        write_solution(d, "sqpmethod_solution.json", prob, sol, out["sqpmethod"]["status"])
    if "ipopt" in peers:
        sol, out["ipopt"] = ipopt(problem, lbw, ubw, w0, hessian, max_iter or 1000)
        write_solution(d, "ipopt_solution.json", prob, sol, out["ipopt"]["status"])
    print(json.dumps(out).replace("NaN", "null"))


if __name__ == "__main__":
    main()
