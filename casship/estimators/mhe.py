"""Moving-horizon estimation (MHE) and full-information (batch MAP) estimation on a DiscreteModel.

The window over the samples ``s .. k`` (``N + 1`` samples, ``N`` = horizon) is a multiple-shooting
least-squares problem in the states ``x_s .. x_k`` and the whitened process noise ``v_s .. v_{k-1}``
(``w = L_Q v``, ``Q = L_Q L_Q'``, so a singular ``Q`` simply has fewer noise variables)::

    min  |L_P (x_s - xbar_s)|^2 + sum_j |v_j|^2 + sum_j rho(|R^-1/2 mask_j * wrap(y_j - h(x_j))|^2)
    s.t. x_{j+1} = F(x_j, u_j, p, L_Q v_j, dt_{j+1}),  bounds on x and w

with ``rho`` quadratic or Huber. The problem is built once per horizon length (stage Functions
mapped over the window, data passed as NLP parameters) and re-solved at every sample with a shifted
warm start.

Arrival cost
    The prior ``N(xbar_s, P_s)`` on the first state of the window is the EKF prediction, with exact
    Jacobians, of the MHE's own filtered estimate ``x_{s-1|s-1}`` and its covariance (the
    "filtering update" of Rao, Rawlings & Lee 2001). It carries the information of the samples
    that have left the window exactly once. The option ``arrival="fixed"`` instead centres the
    prior on the previous window's estimate of ``x_s`` with the fixed initial covariance: that
    estimate already used ``y_s .. y_{k-1}``, which the window then counts a second time. It is
    kept for comparison only.

Covariances in the :class:`FilterResult`
    ``filter``: the covariance of the EKF recursion that runs alongside the MHE, linearised at and
    centred on the MHE estimates (the same recursion that supplies the arrival cost). For a linear
    model it equals the Kalman filter covariance. ``smooth``: the inverse Gauss-Newton Hessian's
    diagonal blocks (a forward Kalman pass and an RTS pass linearised at the MAP trajectory).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from .._fast import BufferedCall
from ..angles import wrap_sym
from ..data import Dataset, Gaussian, as_cov
from ..discretize import DiscreteModel, discretize
from ..model import Model
from .augmented import augment
from .base import Estimator, FilterResult
from .ekf import EKF

__all__ = ["MHE", "MHEOnline", "MHEFailed", "augment_model"]

_SOLVERS = ("ipopt", "sqp", "rti")
_ARRIVALS = ("ekf", "fixed")


class MHEFailed(RuntimeError):
    """The NLP solver of a moving-horizon window did not succeed (``status`` holds its return status)."""

    def __init__(self, message: str, status: str):
        super().__init__(message)
        self.status = status


# -- model augmentation ------------------------------------------------------------------------------
def augment_model(model: Model, estimate: Sequence[str] = (), disturbances: Sequence[str] = ()) -> Model:
    """A model with chosen parameters as random-walk states and additive random-walk disturbances.

    Parameters
    ----------
    model : Model
    estimate : sequence of str
        Parameters to estimate, made states by :func:`casship.augment` (``K' = w_K``; with zero
        variance of ``w_K`` they are constant).
    disturbances : sequence of str
        States ``s`` whose derivative gets an unknown additive term ``d_s``; ``d_s`` is a new state
        with ``d_s' = w_d_s`` (a random walk driven by the new noise channel ``w_d_s``).

    Returns
    -------
    Model
        States ``(*model.states, *estimate, *("d_" + s for s in disturbances))``, noise channels
        ``(*model.noises, *("w_" + p for p in estimate), *("w_d_" + s for s in disturbances))``.
    """
    estimate, disturbances = tuple(estimate), tuple(disturbances)
    for name in disturbances:
        if name not in model.state_names:
            raise ValueError(f"cannot add a disturbance to {name!r}: not a state of {model.name!r}; "
                             f"states: {list(model.state_names)}")
    if len(set(disturbances)) != len(disturbances):
        raise ValueError(f"disturbances repeat a state: {list(disturbances)}")
    aug = augment(model, estimate, name=f"{model.name}+mhe") if estimate else model
    if not disturbances:
        return aug
    b = aug.builder(f"{model.name}+mhe")
    for name in disturbances:
        state = model.state_vars[model.index(name)]
        unit = f"{state.unit}/s" if state.unit else ""
        d = b.state(f"d_{name}", unit=unit, doc=f"additive disturbance on d{name}/dt")
        b.add_to_ode(**{name: d})
        b.ode(**{f"d_{name}": b.noise(f"w_d_{name}")})
    return b.build()


def _sqrt_factor(Q: np.ndarray, tol: float = 1e-12):
    """``L`` with ``L L' = Q`` and full column rank (columns for the nonzero variance directions)."""
    n = Q.shape[0]
    if n == 0:
        return np.zeros((0, 0)), True
    if np.count_nonzero(Q - np.diag(np.diag(Q))) == 0:
        d = np.diag(Q)
        keep = d > tol * max(1.0, d.max())
        return np.diag(np.sqrt(d))[:, keep], True
    lam, V = np.linalg.eigh(Q)
    keep = lam > tol * max(1.0, lam.max())
    return V[:, keep] * np.sqrt(lam[keep]), False


def _push(buffer: np.ndarray, value) -> None:
    """Shift a window buffer by one row (oldest out) and put ``value`` last, in place."""
    buffer[:-1] = buffer[1:]
    buffer[-1] = value


def _inv_sqrt(P: np.ndarray) -> np.ndarray:
    """``W`` with ``W' W = P^-1`` (Cholesky; for a near-singular ``P`` eigenvalues floored at 1e-14
    of the largest)."""
    P = 0.5 * (P + P.T)
    try:
        L = np.linalg.cholesky(P)
        if np.all(np.diag(L) > 1e-7 * np.sqrt(np.abs(np.diag(P)).max())):
            return np.linalg.inv(L)
    except np.linalg.LinAlgError:
        pass
    lam, V = np.linalg.eigh(P)
    lam = np.maximum(lam, 1e-14 * max(lam.max(), 1e-300))
    return (V / np.sqrt(lam)).T


@dataclass
class _Window:
    """The NLP of one horizon length and the index maps into its decision vector."""

    N: int
    solver: ca.Function
    ix: np.ndarray       # (N+1, nx) positions of the states in z
    iv: np.ndarray       # (N, nv) positions of the noise variables in z
    nz: int
    lbx: np.ndarray
    ubx: np.ndarray
    ok_status: tuple
    gn_step: object = None   # BufferedCall of the Gauss-Newton step (solver "rti")
    gn_parts: object = None  # its QP data, for the bounded QP step


class MHE(Estimator):
    """Moving-horizon estimator with the interface of the Kalman filters.

    Parameters
    ----------
    dmodel : DiscreteModel
    Q : covariance of the process noise ``w`` (held over a step, as for :class:`EKF`)
    R : covariance of the measured outputs
    measured : sequence of str, optional
    options : mapping, optional
        horizon : int (20)
            Number of steps ``N`` in the window (``N + 1`` samples). ``N >= len(data) - 1`` turns
            :meth:`filter` into full-information estimation; :meth:`smooth` solves one window over
            the whole record (batch MAP smoother).
        solver : {"ipopt", "sqp", "rti"}
            IPOPT with the exact Hessian (default); ``"sqp"``: CasADi ``sqpmethod`` with the
            Gauss-Newton Hessian and a sparse QP solver, iterated to convergence; ``"rti"``:
            real-time iteration, one Gauss-Newton SQP step per sample from the shifted solution.
        qpsol : str ("qrqp")
            QP solver of ``"sqp"``/``"rti"`` (``"qrqp"`` or ``"osqp"``).
        arrival : {"ekf", "fixed"}
            Arrival cost (see the module notes); ``"fixed"`` double counts and is for comparison.
        huber : float or None
            Huber threshold on the whitened measurement residuals (in standard deviations).
        bounds : mapping state name -> (lower, upper)
            Bounds on states (estimated parameters default to their model bounds).
        noise_bounds : mapping noise name -> (lower, upper)
            Bounds on process-noise channels (needs a diagonal ``Q``).
        estimate : mapping parameter name -> prior std or (prior std, random-walk variance)
            Parameters estimated as extra states (prior mean: the value in ``p``; constant unless
            a random-walk variance is given).
        disturbances : mapping state name -> variance or (variance, prior std)
            Additive random-walk disturbances ``d_<state>`` on the state's derivative; the variance
            is that of the noise ``w_d_<state>`` driving ``d_<state>' = w_d_<state>`` (default
            prior std 1).
        max_iter : int or None
            Iteration limit of the NLP solver (IPOPT 100, SQP 50).
        tol : float (1e-8)
            Convergence tolerance of IPOPT / SQP.
        expand : bool or None
            Expand the NLP to scalar expressions (default: when ``N <= 200``).

    Notes
    -----
    The states of the result are those of the augmented model (:func:`augment_model`): the
    original states, then the estimated parameters, then the disturbances ``d_<state>``. The
    ``p`` given to :meth:`filter` is a parameter vector (or mapping) of the original model.
    Solver failures raise :class:`MHEFailed` (a ``RuntimeError``) naming the row and the solver's
    return status.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order()
    >>> mhe = cs.MHE(cs.discretize(m, 0.1), Q=1e-8, R=1e-4, options={"horizon": 10})
    """

    name = "MHE"
    _options = {"horizon": 20, "solver": "ipopt", "qpsol": "qrqp", "arrival": "ekf", "huber": None,
                "bounds": None, "noise_bounds": None, "estimate": None, "disturbances": None,
                "max_iter": None, "tol": 1e-8, "expand": None}

    def __init__(self, dmodel: DiscreteModel, Q, R, *, measured: Sequence[str] | None = None,
                 options: Mapping | None = None):
        if not isinstance(dmodel, DiscreteModel):
            raise TypeError(f"MHE needs a DiscreteModel (use casship.discretize), got {type(dmodel).__name__}")
        opts = dict(options or {})
        base = dmodel.model
        self.base_model = base
        estimate = opts.get("estimate") or {}
        disturbances = opts.get("disturbances") or {}
        if not isinstance(estimate, Mapping):
            raise TypeError("option 'estimate' maps parameter names to prior standard deviations")
        if not isinstance(disturbances, Mapping):
            raise TypeError("option 'disturbances' maps state names to random-walk variances")
        aug = augment_model(base, list(estimate), list(disturbances))
        self._est_names = tuple(estimate)
        self._dist_names = tuple(disturbances)
        q_est, s_est = [], []
        for n, spec in estimate.items():
            s0, q = (spec, 0.0) if np.ndim(spec) == 0 else tuple(spec)
            s_est.append(_positive(s0, f"estimate[{n!r}] prior std"))
            q_est.append(_nonneg(q, f"estimate[{n!r}] random-walk variance"))
        self._est_std = np.array(s_est)
        q_dist, s_dist = [], []
        for n, spec in disturbances.items():
            q, s0 = (spec, 1.0) if np.ndim(spec) == 0 else tuple(spec)
            q_dist.append(_nonneg(q, f"disturbances[{n!r}] variance"))
            s_dist.append(_positive(s0, f"disturbances[{n!r}] prior std"))
        self._dist_q, self._dist_std = np.array(q_dist), np.array(s_dist)
        self._kept_params = [base.index(n, "param") for n in base.param_names if n not in estimate]
        Q0 = as_cov(Q, base.nw, "Q", base.noise_names)
        Qa = np.zeros((aug.nw, aug.nw))
        Qa[: base.nw, : base.nw] = Q0
        Qa[base.nw:, base.nw:] = np.diag(np.concatenate([q_est, self._dist_q]))
        adm = dmodel if aug is base else discretize(aug, dmodel.dt, dmodel.method, dmodel.substeps)
        super().__init__(adm, Qa, R, measured=measured, options=opts)
        self._check_options()
        self._windows: dict[int, _Window] = {}
        self._run = None
        self._fwd = None

    # -- configuration -----------------------------------------------------------------------------
    def _check_options(self) -> None:
        o, m = self.options, self.model
        N = o["horizon"]
        if not isinstance(N, (int, np.integer)) or N < 1:
            raise ValueError(f"option 'horizon' must be an integer >= 1, got {N!r}")
        if o["solver"] not in _SOLVERS:
            raise ValueError(f"option 'solver' must be one of {_SOLVERS}, got {o['solver']!r}")
        if o["arrival"] not in _ARRIVALS:
            raise ValueError(f"option 'arrival' must be one of {_ARRIVALS}, got {o['arrival']!r}")
        if o["gate"] is not None:
            raise ValueError("MHE has no innovation gate; use option 'huber' against outliers")
        if o["huber"] is not None and not (np.isfinite(o["huber"]) and o["huber"] > 0):
            raise ValueError(f"option 'huber' must be a positive threshold, got {o['huber']!r}")
        self._LQ, q_diag = _sqrt_factor(self.Q)
        self.nv = self._LQ.shape[1]
        # bounds on states (estimated parameters default to their model bounds)
        lo, hi = np.full(m.nx, -np.inf), np.full(m.nx, np.inf)
        for n in self._est_names:
            i, j = m.index(n), self.base_model.index(n, "param")
            lo[i], hi[i] = self.base_model.param_lower[j], self.base_model.param_upper[j]
        for n, (a, b) in dict(o["bounds"] or {}).items():
            i = m.index(n)
            lo[i], hi[i] = _bound_pair(n, a, b)
        self._xlo, self._xhi = lo, hi
        vlo, vhi = np.full(self.nv, -np.inf), np.full(self.nv, np.inf)
        nb = dict(o["noise_bounds"] or {})
        if nb and not q_diag:
            raise ValueError("option 'noise_bounds' needs a diagonal Q")
        cols = np.flatnonzero(np.diag(self.Q) > 0) if q_diag else np.arange(self.nv)
        for n, (a, b) in nb.items():
            i = m.index(n, "noise")
            a, b = _bound_pair(n, a, b)
            if i not in cols:
                if a > 0 or b < 0:
                    raise ValueError(f"noise bound on {n!r} excludes 0, but Q gives it zero variance")
                continue
            j = int(np.flatnonzero(cols == i)[0])
            s = np.sqrt(self.Q[i, i])
            vlo[j], vhi[j] = a / s, b / s
        self._vlo, self._vhi = vlo, vhi
        self._Rdiag = np.count_nonzero(self.R - np.diag(np.diag(self.R))) == 0

    def _build_step(self) -> ca.Function:
        # The EKF that runs alongside the MHE (arrival cost, innovations, covariances).
        self._ekf = EKF(self.dmodel, self.Q, self.R, measured=self.measured)
        return self._ekf.step_function

    @property
    def step_function(self) -> ca.Function:
        """The step Function of the EKF that runs alongside the MHE (arrival cost, innovations, ``P``).

        The window problem itself is a CasADi NLP solver per horizon length, not one step Function.
        """
        return self._step

    @property
    def horizon(self) -> int:
        return int(self.options["horizon"])

    # -- symbolic window ------------------------------------------------------------------------------
    def _meas_residual(self, x, u, p, y, mask):
        """Whitened (and Huber-transformed) measurement residual of one sample."""
        e = self.residual(y, self.h_meas(x, u, p), mask)
        if self._Rdiag:
            r = e / np.sqrt(np.diag(self.R))
        else:
            L = ca.chol(self.masked_innovation_cov(ca.DM.zeros(self.ny, self.ny), self.R, mask))
            r = ca.solve(L.T, e)
        delta = self.options["huber"]
        if delta is not None:
            a = ca.fabs(r)
            r = ca.if_else(a <= delta, r, ca.sign(r) * ca.sqrt(ca.fmax(2 * delta * a - delta**2, 0)))
        return r

    def _stage_functions(self):
        m, S = self.model, ca.SX
        x, xn, v = S.sym("x", m.nx), S.sym("x_next", m.nx), S.sym("v", self.nv)
        u, up, dt, p = S.sym("u", m.nu), S.sym("u_next_prev", m.nu), S.sym("dt"), S.sym("p", m.np)
        y, mask = S.sym("y", self.ny), S.sym("mask", self.ny)
        if self.dmodel.symbolic is ca.MX:
            raise ValueError("MHE needs an explicit discretisation ('euler' or 'rk4')")
        w = ca.DM(self._LQ) @ v if self.nv else S.zeros(m.nw)
        gap = self.dmodel.F(x, up, p, w, dt) - xn
        r = ca.vertcat(self._meas_residual(x, u, p, y, mask), v)
        stage = ca.Function("mhe_stage", [x, v, xn, u, y, mask, up, dt, p], [gap, r])
        term = ca.Function("mhe_terminal", [x, u, y, mask, p], [self._meas_residual(x, u, p, y, mask)])
        xbar, W = S.sym("xbar", m.nx), S.sym("W", m.nx, m.nx)
        d = x - xbar
        if m.angle_states.any():
            d = ca.vertcat(*[wrap_sym(d[i]) if a else d[i] for i, a in enumerate(m.angle_states)])
        arrival = ca.Function("mhe_arrival", [x, xbar, W], [W @ d])
        return stage, term, arrival

    def _window(self, N: int, solver: str | None = None) -> _Window:
        solver = solver or self.options["solver"]
        if (N, solver) in self._windows:
            return self._windows[N, solver]
        m, o = self.model, self.options
        nx, nv, ny, nu = m.nx, self.nv, self.ny, m.nu
        stage, term, arrival = self._stage_functions()
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
        expand = o["expand"] if o["expand"] is not None else N <= 200
        common = {"expand": bool(expand), "print_time": False, "error_on_fail": False}
        if solver == "ipopt":
            iopts = {"print_level": 0, "sb": "yes", "tol": float(o["tol"]),
                     "max_iter": 100 if o["max_iter"] is None else int(o["max_iter"]), "mu_strategy": "adaptive",
                     "warm_start_init_point": "no", "bound_relax_factor": 0.0}
            S = ca.nlpsol(f"mhe_ipopt_{N}", "ipopt", nlp, {**common, "ipopt": iopts})
            ok = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
        else:
            qp = o["qpsol"]
            qopts = {"error_on_fail": False}
            if qp == "qrqp":
                qopts.update(print_iter=False, print_header=False, print_info=False)
            elif qp == "osqp":
                qopts["osqp"] = {"verbose": False, "eps_abs": 1e-9, "eps_rel": 1e-9, "polish": True}
            if solver == "sqp":
                J = ca.jacobian(res, z)
                lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", nlp["g"].numel())
                H = ca.Function("mhe_gn_hessian", [z, par, lam_f, lam_g], [lam_f * (J.T @ J)],
                                ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])
                sopts = {**common, "hess_lag": H, "qpsol": qp, "qpsol_options": qopts,
                         "print_iteration": False, "print_header": False, "print_status": False,
                         "max_iter": 50 if o["max_iter"] is None else int(o["max_iter"]),
                         "tol_pr": float(o["tol"]), "tol_du": max(float(o["tol"]), 1e-8)}
                S = ca.nlpsol(f"mhe_sqp_{N}", "sqpmethod", nlp, sopts)
                # a vanishing search direction means the start point is already optimal
                ok = ("Solve_Succeeded", "Search_Direction_Becomes_Too_Small")
            else:
                parts, step = self._gn_functions(z, par, res, nlp["g"], N)
                sp = parts.sparsity_out
                S = ca.conic(f"mhe_rti_qp_{N}", qp, {"h": sp(0), "a": sp(2)}, qopts)
                ok = ()
        idx = np.arange(nz)
        blk_idx = idx[: N * (nx + nv)].reshape(N, nx + nv)
        ix = np.vstack([blk_idx[:, :nx], idx[N * (nx + nv):][None, :]])
        iv = blk_idx[:, nx:]
        lbx, ubx = np.empty(nz), np.empty(nz)
        lbx[ix], ubx[ix] = self._xlo, self._xhi
        lbx[iv], ubx[iv] = self._vlo, self._vhi
        win = _Window(N, S, ix, iv, nz, lbx, ubx, ok)
        if solver == "rti":
            win.gn_step, win.gn_parts = BufferedCall(step), parts
        self._windows[N, solver] = win
        return win

    @staticmethod
    def _gn_functions(z, par, res, g, N):
        """The Gauss-Newton QP data ``(J'J, J'r, G, g)`` of the window and its equality-constrained step.

        The step solves the KKT system ``[J'J  G'; G  0] [dz; lam] = -[J'r; g]``, which is
        block-banded (stages are interleaved in ``z``), with CasADi's sparse QR, in one Function.
        """
        Jr, Jg = ca.jacobian(res, z), ca.jacobian(g, z)
        parts = ca.Function(f"mhe_gn_parts_{N}", [z, par], [Jr.T @ Jr, Jr.T @ res, Jg, g],
                            ["z", "p"], ["H", "grad", "G", "g"]).expand()
        zs, ps = ca.MX.sym("z", z.sparsity()), ca.MX.sym("p", par.sparsity())
        H, grad, G, gv = parts(zs, ps)
        ng = g.numel()
        K = ca.blockcat([[H, G.T], [G, ca.MX(ng, ng)]])
        dz = ca.solve(K, -ca.vertcat(grad, gv), "qr")[: z.numel()]
        step = ca.Function(f"mhe_gn_step_{N}", [zs, ps], [zs + dz], ["z", "p"], ["z_next"])
        return parts, step

    @staticmethod
    def _params_vector(xbar, W, Uh, Up, Y, M, dt, p) -> np.ndarray:
        f = lambda a: np.asarray(a, dtype=float).reshape(-1, order="F")  # noqa: E731
        return np.concatenate([f(xbar), f(W), f(Uh), f(Up), f(Y), f(M), f(dt), f(p)])

    def _solve(self, win: _Window, z0, par, where: str):
        if win.gn_step is not None:
            # real-time iteration: one Gauss-Newton step; the QP solver only when a bound is hit
            win.gn_step.args[0][:] = z0
            win.gn_step.args[1][:] = par
            z = win.gn_step()[0]
            if np.all(np.isfinite(z)) and np.all(z >= win.lbx) and np.all(z <= win.ubx):
                return z.copy()
            H, grad, G, g = win.gn_parts(z0, par)
            sol = win.solver(h=H, g=grad, a=G, lba=-g, uba=-g, lbx=win.lbx - z0, ubx=win.ubx - z0)
            stats = win.solver.stats()
            z = z0 + np.asarray(sol["x"]).reshape(-1)
            if not stats["success"] or not np.all(np.isfinite(z)):
                status = stats["return_status"]
                raise MHEFailed(f"MHE (real-time iteration, N = {win.N}) failed at {where}: QP solver "
                                f"{win.solver.name()} status {status!r}", status)
            return z
        sol = win.solver(x0=z0, p=par, lbx=win.lbx, ubx=win.ubx, lbg=0.0, ubg=0.0)
        status = win.solver.stats()["return_status"]
        z = np.asarray(sol["x"]).reshape(-1)
        gap = float(np.max(np.abs(np.asarray(sol["g"])), initial=0.0))
        if status not in win.ok_status or not np.all(np.isfinite(z)):
            raise MHEFailed(f"MHE ({win.solver.name()}) failed at {where}: "
                            f"solver status {status!r}", status)
        if not gap <= 1e-6 * max(1.0, float(np.max(np.abs(z)))):
            raise MHEFailed(f"MHE ({win.solver.name()}) failed at {where}: solver status {status!r} "
                            f"but the dynamics are violated by {gap:.3g} (infeasible window)", status)
        return z

    # -- priors and parameters ------------------------------------------------------------------------
    def _full_params(self, p) -> np.ndarray:
        return self.base_model.params() if p is None else self.base_model.params(p)

    def augmented_prior(self, prior: Gaussian, p=None) -> Gaussian:
        """The prior over the augmented states.

        A prior over the original states is extended with the estimated parameters (mean: their
        value in ``p``, std: option ``estimate``) and the disturbances (mean 0, std from option
        ``disturbances``), independent of the rest. A prior over the augmented states is returned as is.
        """
        if not isinstance(prior, Gaussian):
            raise TypeError(f"prior must be a casship.Gaussian, got {type(prior).__name__}")
        m, b = self.model, self.base_model
        if prior.mean.size == m.nx:
            return prior
        if prior.mean.size != b.nx:
            raise ValueError(f"prior has {prior.mean.size} entries; expected {b.nx} (states of {b.name!r}) "
                             f"or {m.nx} (augmented states {list(m.state_names)})")
        pf = self._full_params(p)
        mean = np.concatenate([prior.mean, pf[[b.index(n, 'param') for n in self._est_names]],
                               np.zeros(len(self._dist_names))])
        cov = np.zeros((m.nx, m.nx))
        cov[: b.nx, : b.nx] = prior.cov
        extra = np.concatenate([self._est_std, self._dist_std]) ** 2
        cov[b.nx:, b.nx:] = np.diag(extra)
        return Gaussian(mean, cov)

    def _check_prior(self, prior: Gaussian) -> None:
        self.augmented_prior(prior)

    def _arrays(self, data: Dataset, p):
        pf = self._full_params(p)
        return self.prepare(data, pf[self._kept_params]), pf

    # -- the per-sample recursion (shared by filter and step) -------------------------------------------
    def _new_run(self, prior: Gaussian, p_aug: np.ndarray) -> dict:
        m, N = self.model, self.horizon
        win = self._window(N)
        nu, ny = m.nu, self.ny
        xs = np.tile(prior.mean, (N + 1, 1))
        z = np.zeros(win.nz)
        z[win.ix] = xs
        ekf = self._ekf_call()
        return {"k": 0, "win": win, "z": z, "p": p_aug.copy(), "P0": prior.cov.copy(),
                "x": prior.mean.copy(), "P": prior.cov.copy(),
                "hist_x": xs.copy(), "hist_P": np.tile(prior.cov, (N + 1, 1, 1)),
                "Uh": None, "Up": np.zeros((N, nu)), "Y": np.zeros((N + 1, ny)), "M": np.zeros((N + 1, ny)),
                "dt": np.zeros(N), "ekf": ekf}

    def _ekf_call(self):
        call = BufferedCall(self._step)
        call.args[7][:] = self.Q.reshape(-1, order="F")
        call.args[8][:] = self.R.reshape(-1, order="F")
        call.args[9][0] = np.inf
        return call

    def _advance(self, run: dict, u_prev, u, y, mask, dt, where: str):
        """One sample: EKF step from the previous MHE estimate, shift the window, solve it."""
        m, N, win = self.model, self.horizon, run["win"]
        nx = m.nx
        call = run["ekf"]
        a = call.args
        a[0][:nx] = run["x"]
        a[0][nx:] = run["P"].reshape(-1, order="F")
        a[1][:], a[2][:], a[3][:], a[4][:], a[5][0] = u_prev, u, y, mask, dt
        a[6][:] = run["p"]
        r = call()
        x_pred, P_pred = r[3].copy(), r[4].reshape(nx, nx, order="F").copy()
        info = {"P_ekf": r[2].reshape(nx, nx, order="F").copy(), "x_pred": x_pred, "P_pred": P_pred,
                "C": r[5].reshape(nx, nx, order="F").copy(), "e": r[6].copy(),
                "S": r[7].reshape(self.ny, self.ny, order="F").copy(), "nis": float(r[8][0]), "ll": float(r[9][0])}
        first = run["k"] == 0
        # window data: slots 0..N hold rows k-N..k (rows before the record: dt = 0, nothing measured)
        if run["Uh"] is None:
            run["Uh"] = np.tile(u, (N + 1, 1))
            run["Up"][:] = u_prev
        for key, val in (("Uh", u), ("Y", y), ("M", mask), ("Up", u_prev), ("dt", dt)):
            _push(run[key], val)
        # arrival-cost history: the EKF prediction of each row from the MHE estimate before it
        prev_z = run["z"]
        _push(run["hist_x"], x_pred)
        _push(run["hist_P"], P_pred)
        if self.options["arrival"] == "fixed" and run["k"] > N:
            xbar, Pbar = prev_z[win.ix[1]], run["P0"]
        else:
            xbar, Pbar = run["hist_x"][0], run["hist_P"][0]
        # warm start: shift by one stage (z = [x_0 v_0 x_1 v_1 ... x_N]), new last state = prediction
        if first:
            z0 = prev_z.copy()
        else:
            stage = nx + self.nv
            z0 = np.empty_like(prev_z)
            z0[: win.nz - stage] = prev_z[stage:]
            z0[win.nz - stage: win.nz - nx] = 0.0
            z0[win.nz - nx:] = x_pred
        z0 = np.clip(z0, win.lbx, win.ubx)
        par = self._params_vector(xbar, _inv_sqrt(Pbar), run["Uh"].T, run["Up"].T, run["Y"].T, run["M"].T,
                                  run["dt"], run["p"])
        z = self._solve(win, z0, par, where)
        run["z"] = z
        run["x"] = z[win.ix[-1]]
        run["P"] = info["P_ekf"]
        run["k"] += 1
        return run["x"], run["P"], info

    # -- public API -----------------------------------------------------------------------------------
    def filter(self, data: Dataset, prior: Gaussian, p=None, *, seed=None, progress=None) -> FilterResult:
        """Moving-horizon estimates over a record (one window solve per sample).

        Parameters
        ----------
        data : Dataset
            Inputs (finite) and measured outputs (NaN = not measured).
        prior : Gaussian
            Belief about the (original or augmented) state at the first time stamp.
        p : array or mapping, optional
            Parameters of the original model (estimated ones: prior means).
        seed : ignored
            For interface compatibility with the stochastic filters.
        progress : callable, optional
            ``progress(k, n)`` called after each sample.

        Returns
        -------
        FilterResult
            ``x``: the last state of each window; ``P``: the EKF covariance run alongside (see the
            module notes); predictions, innovations and likelihood terms from that EKF step.
        """
        prior = self.augmented_prior(prior, p)
        arrays, _ = self._arrays(data, p)
        n = len(data)
        run = self._new_run(prior, arrays["p"])
        nx, ny = self.model.nx, self.ny
        out = {k: np.empty((n, nx)) for k in ("x", "x_pred")}
        out.update({k: np.empty((n, nx, nx)) for k in ("P", "P_pred", "C")})
        out["e"], out["S"] = np.empty((n, ny)), np.empty((n, ny, ny))
        out["nis"], out["ll"] = np.empty(n), np.empty(n)
        U, Up, Y, M, dt = arrays["u"].T, arrays["u_prev"].T, arrays["y"].T, arrays["mask"].T, arrays["dt"][0]
        for k in range(n):
            x, P, info = self._advance(run, Up[k], U[k], Y[k], M[k], dt[k], f"row {k} (t = {data.t[k]:g} s)")
            out["x"][k], out["P"][k] = x, P
            out["x_pred"][k], out["P_pred"][k], out["C"][k] = info["x_pred"], info["P_pred"], info["C"]
            out["e"][k], out["S"][k], out["nis"][k], out["ll"][k] = info["e"], info["S"], info["nis"], info["ll"]
            if progress is not None:
                progress(k + 1, n)
        return self._make_result(data.t, M, out, self.name)

    def _make_result(self, t, M, out, name) -> FilterResult:
        e = out["e"].copy()
        e[M == 0] = np.nan
        return FilterResult(
            t=np.asarray(t), x=out["x"], P=out["P"], x_pred=out["x_pred"], P_pred=out["P_pred"], C=out["C"],
            innovations=e, S=out["S"], nis=out["nis"], n_measured=M.sum(axis=1).astype(int),
            loglik_terms=out["ll"], rejected=np.zeros(t.size, dtype=bool), state_names=self.model.state_names,
            output_names=self.measured, estimator=name, angle_states=self.model.angle_states)

    def reset(self) -> None:
        """Forget the online window (the next :meth:`step` starts from its ``x, P`` as the prior)."""
        self._run = None

    def step(self, x, P, u_prev, y, dt, *, u=None, p=None):
        """One online step: add the sample ``y`` (NaN = not measured) and solve the shifted window.

        The first call after construction or :meth:`reset` takes ``(x, P)`` as the prior at this
        sample (its ``dt`` is ignored); later calls take them as the previous filtered belief,
        i.e. pass back what the previous call returned (as for the Kalman filters). ``p`` is only
        read on that first call. Returns ``(x, P, info)`` like :meth:`EKF.step` (``info`` also
        holds ``"solve_time"``).
        """
        m = self.model
        x = np.asarray(x, dtype=float).reshape(-1)
        P = np.asarray(P, dtype=float)
        u_prev = np.asarray(u_prev, dtype=float).reshape(-1)
        u = u_prev if u is None else np.asarray(u, dtype=float).reshape(-1)
        y = np.asarray(y, dtype=float).reshape(-1)
        if y.size != self.ny:
            raise ValueError(f"y has {y.size} entries; measured outputs are {list(self.measured)}")
        if not (np.all(np.isfinite(u_prev)) and np.all(np.isfinite(u))):
            raise ValueError("inputs must be finite")
        if self._run is None:
            prior = self.augmented_prior(Gaussian(x, P), p)
            pf = self._full_params(p)
            self._run = self._new_run(prior, pf[self._kept_params])
            dt = 0.0
        elif x.size != m.nx:
            raise ValueError(f"x has {x.size} entries; the MHE states are {list(m.state_names)}")
        else:
            self._run["x"], self._run["P"] = x, P
        ok = np.isfinite(y)
        t0 = time.perf_counter()
        xk, Pk, info = self._advance(self._run, u_prev, u, np.where(ok, y, 0.0), ok.astype(float), float(dt),
                                     f"online sample {self._run['k']}")
        info["solve_time"] = time.perf_counter() - t0
        info["e"] = np.where(ok, info["e"], np.nan)
        info["rejected"] = False
        return xk.copy(), Pk.copy(), info

    def online(self, prior: Gaussian, p=None, *, u=None, seed=None) -> "MHEOnline":
        """A stateful online runner started from ``prior`` (``update(y, dt, u_prev=None, u=None) -> x``).

        Same use as :meth:`Estimator.online`; numbers equal :meth:`filter` on the same record.
        """
        return MHEOnline(self, prior, p, u)

    def smooth(self, data: Dataset, prior: Gaussian, p=None, *, guess: FilterResult | None = None) -> FilterResult:
        """Full-information estimation: one window over the whole record (batch MAP smoother).

        The same NLP as the moving window with ``N = len(data) - 1`` and the prior as arrival cost.
        The initial guess is the EKF run (or ``guess``). Covariances are the diagonal blocks of the
        inverse Gauss-Newton Hessian at the solution. The RTI solver is iterated to convergence here
        (``"sqp"``).

        Returns
        -------
        FilterResult
            ``x``: MAP states; ``P``: their covariances; predictions and innovations of the forward
            pass linearised at the MAP trajectory; ``estimator = "MHE-full"``.
        """
        prior = self.augmented_prior(prior, p)
        arrays, _ = self._arrays(data, p)
        n = len(data)
        N = n - 1
        if N < 1:
            raise ValueError("smooth needs at least two samples")
        win = self._window(N, "sqp" if self.options["solver"] == "rti" else None)
        if guess is None:
            guess = self._ekf.filter(data, prior, arrays["p"])
        z0 = np.zeros(win.nz)
        z0[win.ix] = guess.x
        z0 = np.clip(z0, win.lbx, win.ubx)
        par = self._params_vector(prior.mean, _inv_sqrt(prior.cov), arrays["u"], arrays["u_prev"][:, 1:],
                                  arrays["y"], arrays["mask"], arrays["dt"][:, 1:], arrays["p"])
        z = self._solve(win, z0, par, f"the full record ({n} samples)")
        X, Vv = z[win.ix], z[win.iv]
        return self._covariances(data.t, X, Vv, arrays, prior)

    def _covariances(self, t, X, Vv, arrays, prior) -> FilterResult:
        """Forward Kalman pass and RTS pass linearised at the MAP trajectory (inverse GN Hessian blocks)."""
        from .rts import rts_smooth

        m, n = self.model, t.size
        nx, ny = m.nx, self.ny
        fold = self._forward_step().mapaccum(n)
        Xprev = np.vstack([X[:1], X[:-1]]).T
        W = np.zeros((n, m.nw))
        if self.nv:
            W[1:] = Vv @ self._LQ.T
        carry0 = prior.cov.reshape(-1, order="F")
        outs = fold(carry0, Xprev, W.T, X.T, arrays["u_prev"], arrays["u"], arrays["y"], arrays["mask"], arrays["dt"],
                    arrays["p"], self.R)
        _, Pf, xp, Pp, C, e, Sm, nis, ll = (np.asarray(o) for o in outs)
        cube = lambda a, k: a.T.reshape(n, k, k).transpose(0, 2, 1)  # noqa: E731
        out = {"x": X, "P": cube(Pf, nx), "x_pred": xp.T, "P_pred": cube(Pp, nx), "C": cube(C, nx),
               "e": e.T, "S": cube(Sm, ny), "nis": nis.ravel(), "ll": ll.ravel()}
        forward = self._make_result(t, arrays["mask"].T, out, "MHE-full")
        smoothed = rts_smooth(forward)
        return replace(forward, P=smoothed.P)

    def _forward_step(self) -> ca.Function:
        """Covariance step linearised at given states and noise: ``(P; x_prev, w_prev, x, ...) -> ...``."""
        if self._fwd is not None:
            return self._fwd
        m, dm, S = self.model, self.dmodel, ca.SX
        nx = m.nx
        Pv = S.sym("P", nx * nx)
        P = ca.reshape(Pv, nx, nx)
        xprev, wprev, x = S.sym("x_prev", nx), S.sym("w_prev", m.nw), S.sym("x", nx)
        up, u, mask, dt, p = S.sym("u_prev", m.nu), S.sym("u", m.nu), S.sym("mask", self.ny), S.sym("dt"), S.sym("p", m.np)
        R = S.sym("R", self.ny, self.ny)
        A, _, _, G = dm.F_jac(xprev, up, p, wprev, dt)
        xp = dm.F(xprev, up, p, S.zeros(m.nw), dt)
        Pp = A @ P @ A.T + G @ ca.DM(self.Q) @ G.T
        Pp = 0.5 * (Pp + Pp.T)
        H = ca.diag(mask) @ m.h_jac(x, u, p)[0][self.meas_index, :]
        y = S.sym("y", self.ny)
        e = self.residual(y, self.h_meas(xp, u, p), mask)
        Sm = self.masked_innovation_cov(H @ Pp @ H.T, R, mask)
        Sm = 0.5 * (Sm + Sm.T)
        K = ca.solve(Sm, H @ Pp).T
        IKH = ca.DM.eye(nx) - K @ H
        Rm = ca.diag(mask) @ R @ ca.diag(mask)
        Pu = IKH @ Pp @ IKH.T + K @ Rm @ K.T
        Pu = 0.5 * (Pu + Pu.T)
        nis, ll = self.gaussian_terms(e, Sm, mask)
        vec = lambda a: ca.reshape(a, -1, 1)  # noqa: E731
        self._fwd = ca.Function("mhe_gn_forward", [Pv, xprev, wprev, x, up, u, y, mask, dt, p, R],
                                [vec(Pu), vec(Pu), xp, vec(Pp), vec(P @ A.T), e, vec(Sm), nis, ll])
        return self._fwd


def _positive(value, what: str) -> float:
    v = float(value)
    if not np.isfinite(v) or v <= 0:
        raise ValueError(f"{what} must be positive and finite, got {value!r}")
    return v


def _nonneg(value, what: str) -> float:
    v = float(value)
    if not np.isfinite(v) or v < 0:
        raise ValueError(f"{what} must be >= 0 and finite, got {value!r}")
    return v


def _bound_pair(name: str, lo, hi):
    lo = -np.inf if lo is None else float(lo)
    hi = np.inf if hi is None else float(hi)
    if np.isnan(lo) or np.isnan(hi) or lo > hi:
        raise ValueError(f"bounds of {name!r} must satisfy lower <= upper, got ({lo}, {hi})")
    return lo, hi


class MHEOnline:
    """Run an :class:`MHE` on a stream, one sample per :meth:`update`, keeping the window inside.

    Examples
    --------
    >>> run = mhe.online(prior)                      # doctest: +SKIP
    >>> for y, dt in stream:                          # doctest: +SKIP
    ...     x = run.update(y, dt)
    """

    def __init__(self, est: MHE, prior: Gaussian, p=None, u=None):
        self.est = est
        prior = est.augmented_prior(prior, p)
        self._run = est._new_run(prior, est._full_params(p)[est._kept_params])
        nu = est.model.nu
        self._u_prev = np.zeros(nu) if u is None else np.asarray(u, dtype=float).reshape(nu)
        self._u = self._u_prev
        self._info: dict = {}

    def update(self, y, dt: float, u_prev=None, u=None) -> np.ndarray:
        """Predict over ``dt`` with ``u_prev`` held (the previous input by default), add the sample
        ``y`` (NaN = not measured) and solve the shifted window; returns a copy of the new estimate."""
        if u_prev is not None:
            self._u_prev = np.asarray(u_prev, dtype=float).reshape(-1)
            self._u = self._u_prev if u is None else np.asarray(u, dtype=float).reshape(-1)
        elif u is not None:
            self._u = np.asarray(u, dtype=float).reshape(-1)
        y = np.asarray(y, dtype=float).reshape(-1)
        if y.size != self.est.ny:
            raise ValueError(f"y has {y.size} entries; measured outputs are {list(self.est.measured)}")
        ok = np.isfinite(y)
        k = self._run["k"]
        _, _, info = self.est._advance(self._run, self._u_prev, self._u, np.where(ok, y, 0.0), ok.astype(float),
                                       float(dt), f"online sample {k}")
        info["e"] = np.where(ok, info["e"], np.nan)
        self._info = info
        return self._run["x"].copy()

    @property
    def x(self) -> np.ndarray:
        """Current estimate (copy)."""
        return self._run["x"].copy()

    @property
    def P(self) -> np.ndarray:
        """Current covariance (copy; see :class:`MHE` for what it is)."""
        return self._run["P"].copy()

    @property
    def info(self) -> dict:
        """Diagnostics of the last update (innovation ``e``, ``nis``, ``ll``, ``x_pred``, ``P_pred``, ...)."""
        return dict(self._info)
