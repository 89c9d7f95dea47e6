"""The window problem of the MHE: a multiple-shooting least-squares NLP built once per horizon length.

Over the samples ``s .. k`` (``N + 1`` samples) the unknowns are the states ``x_s .. x_k`` and the
whitened process noise ``v_s .. v_{k-1}`` (``w = L_Q v``, ``Q = L_Q L_Q'``, so a singular ``Q``
simply has fewer noise variables)::

    min  |W (x_s - xbar_s)|^2 + sum_j |v_j|^2 + sum_j rho(|R^-1/2 mask_j * wrap(y_j - h(x_j))|^2)
    s.t. x_{j+1} = F(x_j, u_j, p, L_Q v_j, dt_{j+1}),  bounds on x and w

with ``rho`` quadratic or Huber. The stage Functions are mapped over the window and the data
enter as NLP parameters, so the problem is built once per horizon and re-solved per sample.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...angles import wrap_sym
from ...runtime import BufferedCall, current_function, is_compiled, jit_function
from .riccati import riccati_step

__all__: list[str] = []          # the package's own building blocks

# Expand the window NLP (and the Gauss-Newton step) to scalar expressions when it has at most this
# many scalar operations (horizon x operations of one stage, SX nodes). Expanded, a window solves
# 1.2 - 2.8 times faster, but the build costs about 20 us per operation (1 s at 52 000 - 67 000,
# 5 - 7 s at 210 000 - 270 000 on the ship models at N = 200) against 0.03 - 0.21 s unexpanded:
# below the threshold the expanded build stays near half a second.
# Measured in benchmarks/bench_mhe_build.py.
EXPAND_NODES = 40_000


def sqrt_factor(Q: np.ndarray, tol: float = 1e-12):
    """``L`` with ``L L' = Q`` and full column rank (columns for the nonzero variance directions),
    and whether ``Q`` is diagonal.

    Unit-free: a diagonal ``Q`` keeps every positive variance however small (a yaw acceleration's
    1e-14 rad^2/s^4 beside a surge's 1e-2 m^2/s^4 is noise, not round-off); a full ``Q`` is factored
    through its correlation matrix, whose eigenvalues below ``tol`` of the largest are the singular
    directions."""
    n = Q.shape[0]
    if n == 0:
        return np.zeros((0, 0)), True
    d = np.diag(Q).copy()
    if np.count_nonzero(Q - np.diag(d)) == 0:
        keep = d > 0
        return np.diag(np.sqrt(np.where(keep, d, 0.0)))[:, keep], True
    sd = np.sqrt(np.where(d > 0, d, 0.0))
    live = sd > 0                      # a zero variance has no correlations: its direction is dropped
    C = Q[np.ix_(live, live)] / np.outer(sd[live], sd[live])
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    keep = lam > tol * max(lam.max(), 1e-300)
    L = np.zeros((n, int(keep.sum())))
    L[live] = sd[live, None] * V[:, keep] * np.sqrt(lam[keep])
    return L, False


@dataclass
class Window:
    """The NLP of one horizon length and the index maps into its decision vector ``z``.

    ``z = [x_0 v_0 x_1 v_1 ... x_N]``; the parameter vector is :func:`params_vector`.
    """

    N: int
    solver: ca.Function
    ix: np.ndarray       # (N+1, nx) positions of the states in z
    iv: np.ndarray       # (N, nv) positions of the noise variables in z
    nz: int
    lbx: np.ndarray
    ubx: np.ndarray
    ok_status: tuple
    unbounded: bool                       # no finite bound on any variable
    ng: int                               # dynamics constraints (nx per stage)
    make_gn: object                       # (multipliers, method) -> BufferedCall of the Gauss-Newton step
    make_qp: object                       # () -> (QP data Function, QP solver): the step with bounds
    gn_step: BufferedCall | None = None
    gn_warm: BufferedCall | None = None
    _qp: tuple | None = None
    _nlp_call: BufferedCall | None = None
    lam_sign: float = 1.0                 # -1: the solver's constraints are the negated gaps (fatrop)
    expanded: bool = False                # the NLP and the Gauss-Newton step in scalar expressions
    tol: float = 1e-8                     # the NLP solver's convergence tolerance
    make_kkt: object = None               # () -> Function (z, p, lam_g) -> (Lagrangian gradient, gaps)
    _kkt: BufferedCall | None = None
    scale: ca.Function | None = None      # (z, p) -> (D, D_g): the solvers' scales (Window.scaling)
    _scale_call: BufferedCall | None = None

    def nlp_call(self) -> BufferedCall:
        """The NLP solver through buffers, for solvers that raise on failure."""
        if self._nlp_call is None:
            call = BufferedCall(self.solver)
            call["lbg"], call["ubg"] = 0.0, 0.0
            self._nlp_call = call
        return self._nlp_call

    def scaling(self, z: np.ndarray, par: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The NLP solvers' variable scale ``D`` (``z = D zeta``) and constraint scale ``D_g`` at the
        start point ``z``: each state by ``min(1, 1 / sqrt(c))``, ``c`` its Gauss-Newton curvature in
        the window's first stage (arrival and measurement), the noise variables (already whitened) by
        1, each dynamics gap by its state's scale. Latitude and longitude in radians, whose curvature
        is ``1 / R`` of a few-centimetre fix (about 1e16), then sit beside speeds at unit size. A state
        is only scaled down: one the first stage hardly sees may be determined through the dynamics
        by later stages, and scaled up its gaps would be held only to the tolerance times the scale."""
        if self._scale_call is None:
            self._scale_call = BufferedCall(self.scale, cannot_fail=True)
        call = self._scale_call
        call["z"], call["p"] = z, par
        call.trigger()
        return call.out("D").ravel().copy(), call.out("D_g").ravel().copy()

    def gn(self, multipliers: bool = False) -> BufferedCall:
        """The Gauss-Newton step of the window, built on first use.

        Parameters
        ----------
        multipliers : bool
            ``False``: ``(z, p) -> z_next`` (solver ``"rti"``); ``True``: ``(z, p) -> (z_next, lam_g)``
            with the multipliers of the dynamics (the warm start of the NLP solvers).

        Returns
        -------
        BufferedCall
        """
        if multipliers:
            if self.gn_warm is None:
                self.gn_warm = self.make_gn(True)
            return self.gn_warm
        if self.gn_step is None:
            self.gn_step = self.make_gn(False)
        return self.gn_step

    def kkt(self) -> BufferedCall:
        """The first-order optimality errors of a point and multipliers (built on first use):
        ``dual = max |grad f + G' lam_g|``, ``primal = max |g|``."""
        if self._kkt is None:
            self._kkt = BufferedCall(self.make_kkt())
        return self._kkt

    def qp(self) -> tuple:
        """The Gauss-Newton QP data Function and the bounded QP solver (built on first use)."""
        if self._qp is None:
            self._qp = self.make_qp()
        return self._qp


def params_vector(xbar, W, Uh, Up, Y, M, dt, p) -> np.ndarray:
    """The window's NLP parameters: arrival mean and whitening, inputs, measurements, mask, steps, parameters."""
    f = lambda a: np.asarray(a, dtype=float).reshape(-1, order="F")  # noqa: E731
    return np.concatenate([f(xbar), f(W), f(Uh), f(Up), f(Y), f(M), f(dt), f(p)])


def _meas_residual(mhe, x, u, p, y, mask):
    """Whitened (and Huber-transformed) measurement residual of one sample."""
    e = mhe.residual(y, mhe.h_meas(x, u, p), mask)
    if mhe.R_diagonal:
        r = e / np.sqrt(np.diag(mhe.R))
    else:
        Dm = ca.diag(mask)
        L = ca.chol(Dm @ ca.DM(mhe.R) @ Dm + ca.diag(1 - mask))
        r = ca.solve(L.T, e)
    delta = mhe.options.huber
    if delta is not None:
        a = ca.fabs(r)
        r = ca.if_else(a <= delta, r, ca.sign(r) * ca.sqrt(ca.fmax(2 * delta * a - delta**2, 0)))
    return r


def _stage_functions(mhe):
    m, S, nv = mhe.model, ca.SX, mhe.nv
    x, xn, v = S.sym("x", m.nx), S.sym("x_next", m.nx), S.sym("v", nv)
    u, up, dt, p = S.sym("u", m.nu), S.sym("u_next_prev", m.nu), S.sym("dt"), S.sym("p", m.np)
    y, mask = S.sym("y", mhe.ny), S.sym("mask", mhe.ny)
    w = ca.DM(mhe.LQ) @ v if nv else S.zeros(m.nw)
    gap = mhe.dmodel.F(x, up, p, w, dt) - xn
    r = ca.vertcat(_meas_residual(mhe, x, u, p, y, mask), v)
    stage = ca.Function("mhe_stage", [x, v, xn, u, y, mask, up, dt, p], [gap, r],
                        ["x", "v", "x_next", "u", "y", "mask", "u_prev_next", "dt_next", "p"], ["gap", "r"])
    term = ca.Function("mhe_terminal", [x, u, y, mask, p], [_meas_residual(mhe, x, u, p, y, mask)],
                       ["x", "u", "y", "mask", "p"], ["r"])
    xbar, W = S.sym("xbar", m.nx), S.sym("W", m.nx, m.nx)
    d = x - xbar
    if m.angle_states.any():
        d = ca.vertcat(*[wrap_sym(d[i]) if a else d[i] for i, a in enumerate(m.angle_states)])
    arrival = ca.Function("mhe_arrival", [x, xbar, W], [W @ d], ["x", "xbar", "W"], ["r"])
    return stage, term, arrival


def stage_nodes(mhe) -> int:
    """Scalar operations of one stage of the window (dynamics gap and residuals, SX nodes)."""
    stage, _, _ = _stage_functions(mhe)
    return int(stage.n_nodes())


def _qp_options(qp: str) -> dict:
    qopts = {"error_on_fail": False}
    if qp == "qrqp":
        qopts.update(print_iter=False, print_header=False, print_info=False)
    elif qp == "osqp":
        qopts["osqp"] = {"verbose": False, "eps_abs": 1e-9, "eps_rel": 1e-9, "polish": True}
    return qopts


def build_window(mhe, N: int, solver: str) -> Window:
    """The window NLP of horizon ``N`` for ``solver`` (``"ipopt"``, ``"sqp"`` or ``"rti"``)."""
    m, o = mhe.model, mhe.options
    nx, nv, ny, nu = m.nx, mhe.nv, mhe.ny, m.nu
    stage, term, arrival = _stage_functions(mhe)
    nz = (N + 1) * nx + N * nv
    z = ca.MX.sym("z", nz)
    blk = ca.reshape(z[: N * (nx + nv)], nx + nv, N)
    X, V, xN = blk[:nx, :], blk[nx:, :], z[N * (nx + nv):]
    Xn = ca.horzcat(X[:, 1:], xN) if N > 1 else xN
    xbar, W = ca.MX.sym("xbar", nx), ca.MX.sym("W", nx, nx)
    Uh, Up = ca.MX.sym("U", nu, N + 1), ca.MX.sym("U_prev", nu, N)
    Y, M = ca.MX.sym("Y", ny, N + 1), ca.MX.sym("M", ny, N + 1)
    dt, p = ca.MX.sym("dt", 1, N), ca.MX.sym("p", m.np)
    G, Rs = stage.map(N)(X, V, Xn, Uh[:, :N], Y[:, :N], M[:, :N], Up, dt, p)
    res = ca.vertcat(arrival(X[:, 0], xbar, W), ca.vec(Rs), term(xN, Uh[:, N], Y[:, N], M[:, N], p))
    par = ca.vertcat(xbar, ca.vec(W), ca.vec(Uh), ca.vec(Up), ca.vec(Y), ca.vec(M), ca.vec(dt), p)
    nlp = {"x": z, "p": par, "f": 0.5 * ca.sumsqr(res), "g": ca.vec(G)}
    # the NLP solvers see z = D zeta and the gaps divided by D_g (Window.scaling, given with the parameters)
    zs, Ds, Dg = ca.MX.sym("z_scaled", nz), ca.MX.sym("D", nz), ca.MX.sym("D_g", nlp["g"].numel())
    f_s, g_s, res_s = ca.substitute([nlp["f"], nlp["g"] / Dg, res], [z], [Ds * zs])
    nlp_s = {"x": zs, "p": ca.vertcat(par, Ds, Dg), "f": f_s, "g": g_s}
    expand = o.expand if o.expand is not None else N * int(stage.n_nodes()) <= EXPAND_NODES
    common = {"expand": bool(expand), "print_time": False, "error_on_fail": False}
    if solver == "ipopt":
        # warm start (the moving window passes the previous multipliers, shifted): primal and dual
        # start values are used as given, not pushed away from the bounds
        iopts = {"print_level": 0, "sb": "yes", "tol": o.tol, "max_iter": 100 if o.max_iter is None else o.max_iter,
                 "mu_strategy": "adaptive", "warm_start_init_point": "yes", "warm_start_bound_push": 1e-9,
                 "warm_start_mult_bound_push": 1e-9, "bound_relax_factor": 0.0}
        # error_on_fail: a failed solve raises from the buffered call (the status is then read by a plain call)
        S = ca.nlpsol(f"mhe_ipopt_{N}", "ipopt", nlp_s, {**common, "error_on_fail": True, "ipopt": iopts})
        ok = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    elif solver == "fatrop":
        # fatrop's stage structure: z = [x_0 v_0 ... x_N] and the dynamics as x_{j+1} - F(...) = 0 (the
        # negated gaps, so its multipliers are those of the other solvers negated); no other constraints
        fopts = {"structure_detection": "manual", "N": N, "nx": [nx] * (N + 1), "nu": [nv] * N + [0],
                 "ng": [0] * (N + 1),
                 "fatrop": {"print_level": 0, "tol": o.tol, "max_iter": 100 if o.max_iter is None else o.max_iter}}
        S = ca.nlpsol(f"mhe_fatrop_{N}", "fatrop", {**nlp_s, "g": -nlp_s["g"]}, {**common, **fopts})
        ok = ("SOLVER_RET_SUCCESS",)
    elif solver == "sqp":
        J = ca.jacobian(res_s, zs)
        lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", nlp["g"].numel())
        H = ca.Function("mhe_gn_hessian", [zs, nlp_s["p"], lam_f, lam_g], [lam_f * (J.T @ J)],
                        ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
        qp = o.qpsol or "qrqp"
        sopts = {**common, "hess_lag": H, "qpsol": qp, "qpsol_options": _qp_options(qp),
                 "print_iteration": False, "print_header": False, "print_status": False,
                 "max_iter": 50 if o.max_iter is None else o.max_iter, "tol_pr": o.tol, "tol_du": max(o.tol, 1e-8)}
        S = ca.nlpsol(f"mhe_sqp_{N}", "sqpmethod", nlp_s, sopts)
        # a vanishing search direction means the start point is already optimal
        ok = ("Solve_Succeeded", "Search_Direction_Becomes_Too_Small")
    else:
        S, ok = None, ()
    pieces = {"X": X, "V": V, "xN": xN, "Xn": Xn, "xbar": xbar, "W": W, "Uh": Uh, "Up": Up, "Y": Y, "M": M,
              "dt": dt, "p": p}

    scale = _scale_function(stage, arrival, mhe, z, par, pieces, N)

    def gauss_newton(multipliers: bool, method: str | None = None):
        # chosen by measurement (docs/benchmarks.md): compiled, the Riccati recursion is the fastest
        # (about 0.6 us per stage); under the virtual machine the sparse QR of the expanded KKT system
        # is, where expansion pays (its build grows with the expanded size like the NLP's)
        method = method or ("riccati" if o.jit or not expand else "kkt")
        fun = (riccati_step(stage, term, arrival, nx, nv, N, z, par, pieces, multipliers) if method == "riccati"
               else _kkt_step(z, par, res, nlp["g"], N, multipliers, scale))
        fun = current_function(jit_function(fun, o.jit))       # the runtime's policy (option jit)
        return BufferedCall(fun, cannot_fail=is_compiled(fun))

    idx = np.arange(nz)
    blk_idx = idx[: N * (nx + nv)].reshape(N, nx + nv)
    ix = np.vstack([blk_idx[:, :nx], idx[N * (nx + nv):][None, :]])
    iv = blk_idx[:, nx:]
    lbx, ubx = np.empty(nz), np.empty(nz)
    lbx[ix], ubx[ix] = mhe.x_bounds
    lbx[iv], ubx[iv] = mhe.v_bounds
    win = Window(N, S, ix, iv, nz, lbx, ubx, ok, not (np.isfinite(lbx).any() or np.isfinite(ubx).any()),
                 nlp["g"].numel(), gauss_newton,
                 lambda: _bounded_qp(z, par, res, nlp["g"], N, o.qpsol or "qrqp"))
    win.expanded, win.tol = bool(expand), o.tol

    def kkt_error():
        lam = ca.MX.sym("lam_g", nlp["g"].numel())
        dual = ca.gradient(nlp["f"] + ca.dot(lam, nlp["g"]), z)
        fun = ca.Function(f"mhe_kkt_error_{N}", [z, par, lam], [dual, nlp["g"]], ["z", "p", "lam_g"],
                          ["dual", "primal"])
        return fun.expand() if expand else fun

    win.make_kkt = kkt_error
    win.scale = scale
    if solver == "fatrop":
        win.lam_sign = -1.0
    if solver == "rti":
        win.gn()
    return win


def _scale_function(stage, arrival, mhe, z, par, pieces, N) -> ca.Function:
    """``(z, p) -> (D, D_g)``, :meth:`Window.scaling`: each state by ``min(1, 1 / sqrt(c))`` (clipped at
    1e-12), ``c`` its Gauss-Newton curvature ``diag(J'J)`` in the window's first stage (arrival and
    measurement residuals), the noise variables by 1, each dynamics gap by its state's scale."""
    m, S = mhe.model, ca.SX
    sym = {n: S.sym(n, stage.size_in(n)) for n in stage.name_in()}
    xbar, W = S.sym("xbar", m.nx), S.sym("W", m.nx, m.nx)
    r = ca.vertcat(arrival(x=sym["x"], xbar=xbar, W=W)["r"], stage.call(sym)["r"])
    J = ca.jacobian(r, sym["x"])
    c = ca.sum1(J * J).T
    dx = ca.if_else(c > 0, ca.fmax(ca.fmin(1.0 / ca.sqrt(ca.fmax(c, 1e-300)), 1.0), 1e-12), 1.0)
    names = list(stage.name_in()) + ["xbar", "W"]
    first = ca.Function("mhe_first_stage_scale", [sym[n] for n in stage.name_in()] + [xbar, W], [dx], names, ["d"])
    P = pieces
    d = first(x=P["X"][:, 0], v=P["V"][:, 0] if mhe.nv else ca.MX(0, 1), x_next=P["Xn"][:, 0], u=P["Uh"][:, 0],
              y=P["Y"][:, 0], mask=P["M"][:, 0], u_prev_next=P["Up"][:, 0], dt_next=P["dt"][0, 0], p=P["p"],
              xbar=P["xbar"], W=P["W"])["d"]
    D = ca.vertcat(*([ca.vertcat(d, ca.MX.ones(mhe.nv))] * N), d)
    return ca.Function(f"mhe_scale_{N}", [z, par], [D, ca.repmat(d, N, 1)], ["z", "p"], ["D", "D_g"]).expand()


def _kkt_step(z, par, res, g, N, multipliers: bool = False, scale: ca.Function | None = None) -> ca.Function:
    """The Gauss-Newton step solving the KKT system ``[J'J  G'; G  0] [dz; lam] = -[J'r; g]`` with
    CasADi's sparse QR (block-banded: the stages are interleaved in ``z``), in one Function. With
    ``scale`` (:meth:`Window.scaling`) the system is first equilibrated, ``S K S y = S b`` with
    ``S = diag(D, 1 / D_g)``, so that the step holds in each state's deviations (the unscaled solve
    left yaw-rate gaps of 8e-5 deviations where positions in metres sat beside a rate known to 1e-6)."""
    Jr, Jg = ca.jacobian(res, z), ca.jacobian(g, z)
    parts = ca.Function(f"mhe_gn_kkt_{N}", [z, par], [Jr.T @ Jr, Jr.T @ res, Jg, g]).expand()
    zs, ps = ca.MX.sym("z", z.sparsity()), ca.MX.sym("p", par.sparsity())
    H, grad, G, gv = parts(zs, ps)
    ng = g.numel()
    K = ca.blockcat([[H, G.T], [G, ca.MX(ng, ng)]])
    rhs = -ca.vertcat(grad, gv)
    if scale is None:
        sol = ca.solve(K, rhs, "qr")
    else:
        scales = scale(z=zs, p=ps)
        Dz, Dg = scales["D"], scales["D_g"]
        s_ = ca.vertcat(Dz, 1.0 / Dg)
        Sd = ca.diag(s_)
        sol = s_ * ca.solve(ca.mtimes(Sd, ca.mtimes(K, Sd)), s_ * rhs, "qr")
    dz = sol[: z.numel()]
    if not multipliers:
        return ca.Function(f"mhe_gn_step_{N}", [zs, ps], [zs + dz], ["z", "p"], ["z_next"])
    return ca.Function(f"mhe_gn_step_{N}", [zs, ps], [zs + dz, sol[z.numel():]], ["z", "p"], ["z_next", "lam_g"])


def _bounded_qp(z, par, res, g, N, qpsol: str):
    """The Gauss-Newton QP data ``(J'J, J'r, G, g)`` of the window and a QP solver for it with bounds
    (built when a real-time iteration first leaves the bounds)."""
    Jr, Jg = ca.jacobian(res, z), ca.jacobian(g, z)
    parts = ca.Function(f"mhe_gn_parts_{N}", [z, par], [Jr.T @ Jr, Jr.T @ res, Jg, g],
                        ["z", "p"], ["H", "grad", "G", "g"]).expand()
    sp = parts.sparsity_out
    solver = ca.conic(f"mhe_rti_qp_{N}", qpsol, {"h": sp(0), "a": sp(2)}, _qp_options(qpsol))
    return parts, solver
