"""The Gauss-Newton step of an MHE window by a Riccati recursion over its stages: cost linear in ``N``.

Linearised at the current iterate ``z = [x_0 v_0 ... x_N]``, the window problem
(:mod:`~casship.estimators.mhe.problem`) becomes the equality-constrained least-squares problem::

    min  |W dx_0 + r_a|^2 + sum_j (|C_j dx_j + r_j|^2 + |dv_j + v_j|^2) + |C_N dx_N + r_N|^2
    s.t. dx_{j+1} = A_j dx_j + B_j dv_j + c_j

(``A, B``: Jacobians of the step, ``c``: the gap ``F(x_j, v_j) - x_{j+1}``, ``C, r``: Jacobian and
value of the whitened measurement residual, ``W, r_a``: the arrival cost). Dynamic programming
from the last stage solves it exactly: the cost-to-go ``V_j(d) = d'P_j d / 2 + q_j'd`` is carried
backwards with

    M = I + B'P'B,   K = M^-1 B'P'A,   k = M^-1 (v + B'(P'c + q')),   A_K = A - B K,
    P = C'C + K'K + A_K'P'A_K,   q = C'r + K'(k - v) + A_K'(P'(c - B k) + q')

(a sum of positive semi-definite terms, so ``P`` stays symmetric and semi-definite), the first
state solves ``(W'W + P_0) dx_0 = -(W'r_a + q_0)`` and the rest follows forwards,
``dv_j = -K_j dx_j - k_j``. Only ``nv x nv`` and one ``nx x nx`` system are factorised, so the cost
grows linearly with the horizon (a sparse factorisation of the whole KKT system grows faster and
runs through CasADi's generic linear solver). The stages are mapped and folded
(``map``/``mapaccum``) over small SX Functions, so the Function stays small for any ``N`` and
compiles in about a second.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..update import spd_solve, symmetric

__all__ = ["riccati_step"]


def _linearised(stage: ca.Function, term: ca.Function, arrival: ca.Function, nx: int, nv: int):
    """SX Functions giving the stage, terminal and arrival Jacobians and values."""
    x, v, xn = ca.SX.sym("x", nx), ca.SX.sym("v", nv), ca.SX.sym("x_next", nx)
    rest = [ca.SX.sym(n, stage.size_in(n)) for n in ("u", "y", "mask", "u_prev_next", "dt_next", "p")]
    stage_out = stage.call(dict(zip(stage.name_in(), [x, v, xn, *rest])))
    gap, r = stage_out["gap"], stage_out["r"]
    ny = r.numel() - nv
    rm = r[:ny]
    lin = ca.Function("mhe_stage_lin", [x, v, xn, *rest],
                      [ca.jacobian(gap, x), ca.jacobian(gap, v), gap, ca.jacobian(rm, x), rm],
                      ["x", "v", "x_next", "u", "y", "mask", "u_prev_next", "dt_next", "p"],
                      ["A", "B", "c", "C", "r"])
    trest = [ca.SX.sym(n, term.size_in(n)) for n in ("u", "y", "mask", "p")]
    rN = term(x, *trest)
    tlin = ca.Function("mhe_terminal_lin", [x, *trest], [ca.jacobian(rN, x), rN], ["x", "u", "y", "mask", "p"],
                       ["C", "r"])
    xbar, W = ca.SX.sym("xbar", nx), ca.SX.sym("W", nx, nx)
    ra = arrival(x, xbar, W)
    alin = ca.Function("mhe_arrival_lin", [x, xbar, W], [ca.jacobian(ra, x), ra], ["x", "xbar", "W"], ["Wx", "r"])
    return lin, tlin, alin


def _backward(lin: ca.Function, nx: int, nv: int) -> ca.Function:
    """One backward step of the cost-to-go: ``(P', q', A, B, c, C, r, v) -> (P, q, K, k)``, with the
    sparsity of the Jacobians of ``lin`` (structural zeros cost nothing)."""
    S = ca.SX
    ny = lin.size_out("r")[0]
    P1, q1 = S.sym("P", nx, nx), S.sym("q", nx)
    A, B, c = S.sym("A", lin.sparsity_out("A")), S.sym("B", lin.sparsity_out("B")), S.sym("c", nx)
    C, r, v = S.sym("C", lin.sparsity_out("C")), S.sym("r", ny), S.sym("v", nv)
    PB = P1 @ B
    M = ca.DM.eye(nv) + symmetric(B.T @ PB)
    rhs = spd_solve(M, ca.horzcat(PB.T @ A, v + B.T @ (P1 @ c + q1))) if nv else S(0, nx + 1)
    K, k = rhs[:, :nx], rhs[:, nx]
    AK = A - B @ K
    P = symmetric(C.T @ C + K.T @ K + AK.T @ P1 @ AK)
    q = C.T @ r + K.T @ (k - v) + AK.T @ (P1 @ (c - B @ k) + q1)
    return ca.Function("mhe_riccati_back", [P1, q1, A, B, c, C, r, v], [P, q, K, k],
                       ["P", "q", "A", "B", "c", "C", "r", "v"], ["P", "q", "K", "k"],
                       {"allow_duplicate_io_names": True})


def _forward(lin: ca.Function, nx: int, nv: int) -> ca.Function:
    """One forward step: ``(d, A, B, c, K, k) -> (d_next, dv)``."""
    S = ca.SX
    d, A, B, c = S.sym("d", nx), S.sym("A", lin.sparsity_out("A")), S.sym("B", lin.sparsity_out("B")), S.sym("c", nx)
    K, k = S.sym("K", nv, nx), S.sym("k", nv)
    dv = -(K @ d + k)
    return ca.Function("mhe_riccati_fwd", [d, A, B, c, K, k], [A @ d + B @ dv + c, dv],
                       ["d", "A", "B", "c", "K", "k"], ["d", "dv"], {"allow_duplicate_io_names": True})


def _reverse_blocks(X, width: int, n: int):
    """The ``n`` column blocks of ``X`` (each ``width`` wide) in reverse order (one indexing node)."""
    cols = np.arange(n * width).reshape(n, width)[::-1].ravel()
    return X[:, list(map(int, cols))]


def riccati_step(stage: ca.Function, term: ca.Function, arrival: ca.Function, nx: int, nv: int, N: int,
                 z: ca.MX, par: ca.MX, pieces: dict, multipliers: bool = False) -> ca.Function:
    """The Gauss-Newton step ``(z, p) -> z_next`` of a window of horizon ``N`` by the Riccati recursion.

    Parameters
    ----------
    stage, term, arrival : casadi.Function
        The window's stage (``gap``, ``r`` = whitened measurement residual then ``v``), terminal and
        arrival-cost residual Functions (:mod:`~casship.estimators.mhe.problem`).
    nx, nv, N : int
        States, whitened noise variables per stage, horizon.
    z, par : casadi.MX
        The window's decision vector and parameter vector symbols.
    pieces : dict
        The views of ``z`` and ``par`` the window problem is written in: ``X`` (nx x N), ``V``
        (nv x N), ``xN``, ``Xn`` (next states), ``xbar``, ``W``, ``Uh``, ``Up``, ``Y``, ``M``, ``dt``, ``p``.
    multipliers : bool
        Also return the multipliers ``lam_g`` of the dynamics constraints (``g_j = F(x_j, v_j) -
        x_{j+1}``, Lagrangian ``f + lam_g'g``): ``lam_j = P_{j+1} dx_{j+1} + q_{j+1}``, the gradient of
        the cost-to-go.

    Returns
    -------
    casadi.Function
        ``mhe_gn_step_N(z, p) -> z_next`` (and ``lam_g``).
    """
    lin, tlin, alin = _linearised(stage, term, arrival, nx, nv)
    g = pieces
    L = lin.map(N)(x=g["X"], v=g["V"], x_next=g["Xn"], u=g["Uh"][:, :N], y=g["Y"][:, :N], mask=g["M"][:, :N],
                   u_prev_next=g["Up"], dt_next=g["dt"], p=g["p"])
    T = tlin(x=g["xN"], u=g["Uh"][:, N], y=g["Y"][:, N], mask=g["M"][:, N], p=g["p"])
    Ar = alin(x=g["X"][:, 0], xbar=g["xbar"], W=g["W"])
    back = _backward(lin, nx, nv).mapaccum("mhe_riccati_backward", N, ["P", "q"], ["P", "q"],
                                          {"allow_duplicate_io_names": True})
    rev = lambda key, w: _reverse_blocks(L[key], w, N)  # noqa: E731
    Bk = back(P=symmetric(T["C"].T @ T["C"]), q=T["C"].T @ T["r"], A=rev("A", nx), B=rev("B", nv), c=rev("c", 1),
              C=rev("C", nx), r=rev("r", 1), v=_reverse_blocks(g["V"], 1, N))
    # cost-to-go of stage 0 is the last column block of the backward fold
    P0, q0 = Bk["P"][:, (N - 1) * nx:], Bk["q"][:, N - 1]
    Wx = Ar["Wx"]
    d0 = -spd_solve(symmetric(Wx.T @ Wx) + P0, Wx.T @ Ar["r"] + q0)
    fwd = _forward(lin, nx, nv).mapaccum("mhe_riccati_forward", N, ["d"], ["d"], {"allow_duplicate_io_names": True})
    Fw = fwd(d=d0, A=L["A"], B=L["B"], c=L["c"], K=_reverse_blocks(Bk["K"], nx, N), k=_reverse_blocks(Bk["k"], 1, N))
    D = ca.horzcat(d0, Fw["d"])                    # dx_0 .. dx_N
    stages = ca.vertcat(D[:, :N], Fw["dv"]) if nv else D[:, :N]
    dz = ca.vertcat(ca.vec(stages), D[:, N])
    if not multipliers:
        return ca.Function(f"mhe_gn_step_{N}", [z, par], [z + dz], ["z", "p"], ["z_next"])
    # cost-to-go of stages 1 .. N: the backward fold's blocks N-2 .. 0, then the terminal one
    Ps = ca.horzcat(_reverse_blocks(Bk["P"][:, :(N - 1) * nx], nx, N - 1), symmetric(T["C"].T @ T["C"]))
    qs = ca.horzcat(_reverse_blocks(Bk["q"][:, :N - 1], 1, N - 1), T["C"].T @ T["r"])
    Pj, dj, qj = ca.MX.sym("P", nx, nx), ca.MX.sym("d", nx), ca.MX.sym("q", nx)
    costate = ca.Function("mhe_costate", [Pj, dj, qj], [Pj @ dj + qj]).map(N)
    lam = costate(Ps, Fw["d"], qs)
    return ca.Function(f"mhe_gn_step_{N}", [z, par], [z + dz, ca.vec(lam)], ["z", "p"], ["z_next", "lam_g"])
