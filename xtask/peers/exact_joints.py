"""The exact-joints reduced model (docs/theory.md §10) from its export, in CasADi.

Reads DIR/model.json (format `flexmpc-exact-joints-rom`, written by modal-rom's
`ExactJointsRom::export`) and its .npy arrays, and builds the right-hand side
x' = f(x, u) of §10.4 on CasADi SX scalars, in the order of the Rust evaluation:

    R(xi) = (xi0^2 - |xiv|^2) I + 2 xiv xiv^T + 2 xi0 skew(xiv)     (homogeneous eq. 9)
    C_j = C_c + sum_pq R_pq C_pq,  A = [S; C_j E_j ...]
    AA^T = L_g L_g^T,  H = (AA^T)^-1 C0,  C0 = A Z0,  S = I - C0^T H = L L^T
    y = L^-T p,  q1 = Z p = Z0 y - A^T (H y),  q2 = Z2 p2
    f1 = Sigma q1 + W q2 - q1_l Gamma1^l q1 - q2_l Gamma2^l q2 + B_u u,  f2 = -W^T q1 + q2_l Gamma2^l^T q1
    Z^T f1 = L^-1 (Z0^T f1 - H^T (A f1))
    rates from E_j q1 (joint ends a, b) and the root rows q1; xi_j' = U(w_b) xi_j - Ubar(w_a) xi_j,
    xi_root' = U(w_root) xi_root
    V_j = C_j' (E_j Z) with E_j Z = (E_j Z0 - (E_j A^T) H) L^-T, W_r = H L^-T (joint rows)
    P = V^T W_r,  K p = triu(P^T, 1) p - tril(P, -1) p   (K = -V^T W_r - Phi(X)^T of §10.4)
    p' = Z^T f1 - K p,  p2' = Z2^T f2.

`rhs_function(model)` returns the SX Function f(x, u); numeric evaluation through it is the
check against the Rust right-hand side (`check`).
"""

import json
import os

import casadi as ca
import numpy as np


def load_model(d):
    """Metadata and arrays of the exact-joints export in directory `d`."""
    with open(os.path.join(d, "model.json")) as f:
        meta = json.load(f)
    if meta.get("format") != "flexmpc-exact-joints-rom":
        raise ValueError(f"{d}/model.json: format {meta.get('format')!r} is not flexmpc-exact-joints-rom")
    arr = {k: np.load(os.path.join(d, v["file"])) for k, v in meta["arrays"].items()}
    return meta, arr


def sparse(a):
    """A constant with the exact zeros of `a` dropped from the sparsity."""
    return ca.sparsify(ca.DM(np.asarray(a, dtype=float)))


def skew(v):
    return ca.vertcat(ca.horzcat(0, -v[2], v[1]), ca.horzcat(v[2], 0, -v[0]),
                      ca.horzcat(-v[1], v[0], 0))


def rotation(xi):
    """R(xi), eq. (9) written homogeneous of degree 2."""
    w, v = xi[0], xi[1:4]
    return (w * w - ca.dot(v, v)) * ca.DM.eye(3) + 2 * ca.mtimes(v, v.T) + 2 * w * skew(v)


def rotation_rate(xi, xd):
    """dR/dt = sum_c dR/dxi_c xi'_c."""
    w, v = xi[0], xi[1:4]
    wd, vd = xd[0], xd[1:4]
    return ((2 * w * wd - 2 * ca.dot(v, vd)) * ca.DM.eye(3)
            + 2 * (ca.mtimes(vd, v.T) + ca.mtimes(v, vd.T)) + 2 * wd * skew(v) + 2 * w * skew(vd))


def u_right(w):
    """U(w) of eq. (8): U(w) xi = 1/2 xi (x) (0, w)."""
    return 0.5 * ca.vertcat(
        ca.horzcat(0, -w[0], -w[1], -w[2]),
        ca.horzcat(w[0], 0, w[2], -w[1]),
        ca.horzcat(w[1], -w[2], 0, w[0]),
        ca.horzcat(w[2], w[1], -w[0], 0))


def u_left(w):
    """Ubar(w): Ubar(w) xi = 1/2 (0, w) (x) xi."""
    return 0.5 * ca.vertcat(
        ca.horzcat(0, -w[0], -w[1], -w[2]),
        ca.horzcat(w[0], 0, -w[2], w[1]),
        ca.horzcat(w[1], w[2], 0, -w[0]),
        ca.horzcat(w[2], -w[1], w[0], 0))


def cholesky(a):
    """Lower Cholesky factor of the symmetric SX matrix `a` (column by column)."""
    n = a.shape[0]
    lo = ca.SX(n, n)
    for j in range(n):
        d = a[j, j]
        if j:
            d = d - ca.sumsqr(lo[j, :j])
        ljj = ca.sqrt(d)
        lo[j, j] = ljj
        if j + 1 < n:
            c = a[j + 1:, j]
            if j:
                c = c - ca.mtimes(lo[j + 1:, :j], lo[j, :j].T)
            lo[j + 1:, j] = c / ljj
    return lo


def forward_solve(lo, b):
    """X with lo X = b (lo lower triangular)."""
    n = lo.shape[0]
    rows = []
    for i in range(n):
        r = b[i, :]
        if i:
            r = r - ca.mtimes(lo[i, :i], ca.vertcat(*rows))
        rows.append(r / lo[i, i])
    return ca.vertcat(*rows)


def back_solve_t(lo, b):
    """y with lo^T y = b (b a column)."""
    n = lo.shape[0]
    y = [None] * n
    for i in reversed(range(n)):
        r = b[i]
        if i + 1 < n:
            r = r - ca.dot(lo[i + 1:, i], ca.vertcat(*y[i + 1:]))
        y[i] = r / lo[i, i]
    return ca.vertcat(*y)


def ambient(meta, arr):
    """(f1, f2) of the link Galerkin operators as an SX Function of (q1, q2, u)."""
    na, nb, nu = meta["n_fields"], meta["n_force_fields"], meta["n_inputs"]
    q1, q2, u = ca.SX.sym("q1", na), ca.SX.sym("q2", nb), ca.SX.sym("u", nu)
    g1, g2 = arr["gamma1"], arr["gamma2"]
    m1 = sparse(g1.reshape(na * na, na))              # row l na + i: Gamma1[l, i, :]
    m2 = sparse(g2.reshape(nb * na, nb))              # row l na + i: Gamma2[l, i, :]
    m3 = sparse(g2.transpose(2, 1, 0).reshape(nb * na, nb))  # row j na + i: Gamma2[:, i, j]
    u1 = ca.reshape(ca.mtimes(m1, q1), na, na)        # U1[i, l] = sum_j Gamma1[l, i, j] q1_j
    s2 = ca.reshape(ca.mtimes(m2, q2), na, nb)        # S2[i, l] = sum_j Gamma2[l, i, j] q2_j
    t2 = ca.reshape(ca.mtimes(m3, q2), na, nb)        # T2[i, j] = sum_l Gamma2[l, i, j] q2_l
    w = sparse(arr["w"])
    f1 = (ca.mtimes(sparse(arr["sigma"]), q1) + ca.mtimes(w, q2) + ca.mtimes(sparse(arr["b_u"]), u)
          - ca.mtimes(u1, q1) - ca.mtimes(s2, q2))
    f2 = -ca.mtimes(w.T, q1) + ca.mtimes(t2.T, q1)
    return ca.Function("ambient", [q1, q2, u], [f1, f2])


def rhs_expr(meta, arr, x, u):
    """f(x, u) of §10.4 for SX `x`, `u`."""
    k = meta["k"]
    m, m2 = meta["n_p"], meta["n_p2"]
    z0, z2 = ca.DM(arr["z0"]), ca.DM(arr["z2"])
    sup = ca.DM(arr["support"])
    p, p2 = x[:m], x[m:m + m2]
    joints = meta["joints"]
    # rows A(xi): support rows, then C_j(xi_j) E_j
    es, cs, xis, blocks = [], [], [], [sup]
    for j in joints:
        e = ca.DM(arr[j["arrays"][0]])
        c = arr[j["arrays"][1]]
        xi = x[j["offset"]:j["offset"] + 4]
        rot = rotation(xi)
        cj = ca.DM(c[0])
        for pq in range(9):
            cj = cj + rot[pq // 3, pq % 3] * ca.DM(c[1 + pq])
        es.append(e)
        cs.append(c)
        xis.append(xi)
        blocks.append(ca.mtimes(cj, e))
    a = ca.vertcat(*blocks)
    gram = ca.mtimes(a, a.T)
    lg = cholesky(0.5 * (gram + gram.T))
    c0 = ca.mtimes(a, z0)
    h = back_solve_mat(lg, forward_solve(lg, c0))
    s = ca.DM.eye(m) - ca.mtimes(c0.T, h)
    lo = cholesky(0.5 * (s + s.T))
    y = back_solve_t(lo, p)
    hy = ca.mtimes(h, y)
    q1 = ca.mtimes(z0, y) - ca.mtimes(a.T, hy)
    q2 = ca.mtimes(z2, p2)
    f1, f2 = ambient(meta, arr)(q1, q2, u)
    ztf = forward_solve(lo, ca.mtimes(z0.T, f1) - ca.mtimes(h.T, ca.mtimes(a, f1)))
    out = ca.SX.zeros(meta["n_state"])
    rates = {c: ax for c, ax in meta["rate_components"]}

    def omega(vals, end):
        w = [0, 0, 0]
        for c, ax in rates.items():
            w[ax] = vals[end * k + c]
        return ca.vertcat(*w)

    # K p on the joint rows
    pmat = ca.SX.zeros(m, m)
    for j, e, c, xi in zip(joints, es, cs, xis):
        ro, r = j["row_offset"], j["rows"]
        t = ca.mtimes(e, z0) - ca.mtimes(ca.mtimes(e, a.T), h)            # E_j Z L^T
        hj = h[ro:ro + r, :]
        sol = forward_solve(lo, ca.horzcat(t.T, hj.T)).T                  # [E_j Z; W_r,j]
        ez, wr = sol[:2 * k, :], sol[2 * k:, :]
        vals = ca.mtimes(ez, p)
        xd = ca.mtimes(u_right(omega(vals, 1)) - u_left(omega(vals, 0)), xi)
        out[j["offset"]:j["offset"] + 4] = xd
        rdot = rotation_rate(xi, xd)
        cd = ca.SX.zeros(r, 2 * k)
        for pq in range(9):
            cd = cd + rdot[pq // 3, pq % 3] * ca.DM(c[1 + pq])
        v = ca.mtimes(cd, ez)
        pmat = pmat + ca.mtimes(v.T, wr)
    kp = ca.mtimes(ca.triu(pmat.T, False), p) - ca.mtimes(ca.tril(pmat, False), p)
    out[:m] = ztf - kp
    out[m:m + m2] = ca.mtimes(z2.T, f2)
    if meta["root_offset"] is not None:
        o = meta["root_offset"]
        vals = ca.mtimes(ca.DM(arr["root_rows"]), q1)
        out[o:o + 4] = ca.mtimes(u_right(omega(vals, 0)), x[o:o + 4])
    return out


def back_solve_mat(lo, b):
    """X with lo^T X = b (lo lower triangular, b a matrix)."""
    n = lo.shape[0]
    rows = [None] * n
    for i in reversed(range(n)):
        r = b[i, :]
        if i + 1 < n:
            r = r - ca.mtimes(lo[i + 1:, i].T, ca.vertcat(*rows[i + 1:]))
        rows[i] = r / lo[i, i]
    return ca.vertcat(*rows)


def rhs_function(meta, arr):
    """The SX Function f(x, u)."""
    x = ca.SX.sym("x", meta["n_state"])
    u = ca.SX.sym("u", meta["n_inputs"])
    return ca.Function("f", [x, u], [rhs_expr(meta, arr, x, u)], ["x", "u"], ["xdot"])


def check(f, samples):
    """Compares f with flexmpc's values at `samples` (problem.json's rhs_check): per sample the
    normwise max |df| / max |f| (theory.md §10.6's measure); returns the worst per kind and the
    worst componentwise relative difference over entries above 1e-3 max |f|."""
    worst = {}
    comp = 0.0
    for s in samples:
        ref = np.array(s["f"])
        val = np.array(f(s["x"], s["u"])).ravel()
        d = np.abs(val - ref)
        scale = np.max(np.abs(ref))
        rel = float(np.max(d) / scale)
        worst[s["kind"]] = max(worst.get(s["kind"], 0.0), rel)
        big = np.abs(ref) > 1e-3 * scale
        comp = max(comp, float(np.max(d[big] / np.abs(ref[big]))))
    return {"normwise": worst, "componentwise_above_1e-3": comp, "samples": len(samples)}


def midpoint_maps(meta, arr, prob):
    """(Phi, PhiS): the shooting interval map of `substeps` implicit midpoint steps and the
    same with its Jacobian [A B] = dPhi/d(x, u), as flexmpc integrates (ocp-transcription's
    midpoint substep): per step the midpoint z solves z - x - h/2 f(z, u) = 0 by CasADi's
    `newton` rootfinder (from z = x + h/2 f(x, u), flexmpc's guess; abstol = flexmpc's
    newton_tolerance on max |residual|, flexmpc scales it by 1 + max |z|), x+ = 2 z - x;
    sensitivities (I - h/2 f_x(z)) dz = S + h/2 [0 f_u(z)], S+ = 2 dz - S."""
    nx, nu = prob["nx"], prob["nu"]
    n = prob["substeps"]
    h = prob["interval"] / n
    f = rhs_function(meta, arr)
    xs, us = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    fxs = f(xs, us)
    jac = ca.Function("fxu", [xs, us], [ca.jacobian(fxs, xs), ca.jacobian(fxs, us)])
    zs, ps = ca.SX.sym("z", nx), ca.SX.sym("p", nx + nu)
    g = ca.Function("g", [zs, ps], [zs - ps[:nx] - 0.5 * h * f(zs, ps[nx:])])
    tol = prob.get("newton_tolerance", 1e-13)
    rf = ca.rootfinder("midpoint", "newton", g, {
        "abstol": tol, "abstolStep": 0.0, "max_iter": prob.get("newton_max_iterations", 30),
        "error_on_fail": False})
    x0, u = ca.MX.sym("x", nx), ca.MX.sym("u", nu)
    x = x0
    sens = ca.MX(ca.horzcat(ca.DM.eye(nx), ca.DM(nx, nu)))
    xo = x0
    for _ in range(n):
        z = rf(xo + 0.5 * h * f(xo, u), ca.vertcat(xo, u))
        a, b = jac(z, u)
        mat = ca.MX(ca.DM.eye(nx)) - 0.5 * h * a
        rhs = sens + 0.5 * h * ca.horzcat(ca.MX(nx, nx), b)
        dz = ca.solve(mat, rhs, "lapacklu")
        sens = 2 * dz - sens
        xo = 2 * z - xo
    for _ in range(n):
        z = rf(x + 0.5 * h * f(x, u), ca.vertcat(x, u))
        x = 2 * z - x
    return (ca.Function("Phi", [x0, u], [x]), ca.Function("PhiS", [x0, u], [xo, sens]),
            f, jac)
