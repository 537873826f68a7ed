"""CasADi/IPOPT peer of `cargo xtask bench peers`: solves one exported first-sample problem.

Usage: python casadi_peers.py DIR

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

IPOPT's primal solution is written to DIR/ipopt_solution.json (states: Nc + 1 node vectors,
controls: Nc vectors, cost), the format `cargo xtask bench peers --start-from` reads.

Output: one JSON line on stdout with
  check_cost_rel: |J(flexmpc optimum) - flexmpc_cost| / |flexmpc_cost| (this NLP's objective
                  at flexmpc's solution against flexmpc's own cost),
  check_defect:   max |constraint residual| of this NLP at flexmpc's solution,
  ipopt: {status, cost, iterations, inf_pr, inf_du, cpu_s (process CPU time of the solve),
          wall_s)}.
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


def nlp(meta, prob, arr):
    nx, nu, nc = prob["nx"], prob["nu"], prob["intervals"]
    dt = prob["interval"]
    phi = interval_map(meta, prob, arr)
    qw, rw, pw = (np.array(prob[k]) for k in ("q", "r", "terminal"))
    xr, ur = np.array(prob["x_ref"]), np.array(prob["u_ref"])
    s = [ca.MX.sym(f"s{k}", nx) for k in range(nc + 1)]
    uu = [ca.MX.sym(f"u{k}", nu) for k in range(nc)]
    w, lbw, ubw = [], [], []
    j = 0
    g = [s[0] - np.array(prob["x0"])]
    for k in range(nc + 1):
        e = s[k] - xr
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


def stack(prob, states, controls):
    nc = prob["intervals"]
    v = []
    for k in range(nc + 1):
        v += prob[states][k]
        if k < nc:
            v += prob[controls][k]
    return np.array(v)


def main():
    d = sys.argv[1]
    meta, prob, arr = load(d)
    problem, lbw, ubw = nlp(meta, prob, arr)
    ng = problem["g"].shape[0]
    fg = ca.Function("fg", [problem["x"]], [problem["f"], problem["g"]])
    jf, gf = fg(stack(prob, "flexmpc_states", "flexmpc_controls"))
    jf = float(jf)
    check_cost = abs(jf - prob["flexmpc_cost"]) / abs(prob["flexmpc_cost"])
    check_def = float(np.max(np.abs(np.array(gf))))
    opts = {
        "ipopt.tol": 1e-10,
        "ipopt.print_level": 0,
        "print_time": False,
        "ipopt.max_iter": 1000,
        "ipopt.hessian_approximation": "exact",
    }
    solver = ca.nlpsol("ipopt", "ipopt", problem, opts)
    w0 = stack(prob, "start_states", "start_controls")
    c0, t0 = time.process_time(), time.perf_counter()
    sol = solver(x0=w0, lbx=lbw, ubx=ubw, lbg=np.zeros(ng), ubg=np.zeros(ng))
    cpu, wall = time.process_time() - c0, time.perf_counter() - t0
    st = solver.stats()
    its = st.get("iterations", {})
    wopt = np.array(sol["x"]).ravel()
    nx, nu, nc = prob["nx"], prob["nu"], prob["intervals"]
    states, controls, i = [], [], 0
    for k in range(nc + 1):
        states.append(wopt[i:i + nx].tolist())
        i += nx
        if k < nc:
            controls.append(wopt[i:i + nu].tolist())
            i += nu
    with open(os.path.join(d, "ipopt_solution.json"), "w") as f:
        json.dump({"states": states, "controls": controls, "cost": float(sol["f"]),
                   "status": st["return_status"]}, f)
    out = {
        "check_cost": jf,
        "check_cost_rel": check_cost,
        "check_defect": check_def,
        "ipopt": {
            "status": st["return_status"],
            "cost": float(sol["f"]),
            "iterations": int(st["iter_count"]),
            "inf_pr": float(its["inf_pr"][-1]) if its else float("nan"),
            "inf_du": float(its["inf_du"][-1]) if its else float("nan"),
            "cpu_s": cpu,
            "wall_s": wall,
        },
    }
    print(json.dumps(out).replace("NaN", "null"))


if __name__ == "__main__":
    main()
