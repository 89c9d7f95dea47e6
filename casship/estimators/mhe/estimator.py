"""The moving-horizon estimator: the estimator contract kept by solving a window problem per sample.

Covariances in the :class:`FilterResult`
    ``filter``: the covariance of the EKF recursion that runs alongside the MHE, linearised at and
    centred on the MHE estimates (the same recursion that supplies the arrival cost). For a linear
    model it equals the Kalman filter covariance. ``smooth``: the inverse Gauss-Newton Hessian's
    diagonal blocks (a forward Kalman pass and an RTS pass linearised at the MAP trajectory).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ...runtime import DUPLICATE_NAMES, current_function, jit_function
from ...data import Dataset
from ...gaussian import Gaussian, as_cov
from ...progress import track
from ...discretize import DiscreteModel, discretize
from ..augmented import augment, augmented_noise, augmented_prior
from ..base import per_sample
from ..contract import Estimator
from ..ekf import EKF
from ..gaps import bridge_gaps
from ..online import OnlineRun
from ..options import DIAGNOSTICS
from ..result import FilterResult
from ..rts import rts_smooth
from ..update import joseph_update
from .options import MHEOptions, bound_pair
from .problem import Window, build_window, params_vector, sqrt_factor
from .arrival import inv_sqrt
from .runner import WindowEngine
from .solvers import solve_window
from ...errors import InputError, InputTypeError

__all__ = ["MHE"]


class MHE(Estimator):
    """Moving-horizon estimator with the contract of every estimator.

    Parameters
    ----------
    dmodel : DiscreteModel
        An explicit discretisation (``"euler"`` or ``"rk4"``).
    Q, R : process and measurement noise covariances, the one meaning of ``docs/architecture.md``
        (``Q``: covariance of ``w`` held over a step, as for the :class:`~casship.EKF`)
    measured : sequence of str, optional
    options : MHEOptions or mapping
        ``horizon``, ``solver``, ``qpsol``, ``arrival``, ``huber``, ``bounds``, ``noise_bounds``,
        ``estimate``, ``disturbances``, ``max_iter``, ``tol``, ``expand``, and those of every
        estimator: ``jit``, ``outputs``, ``max_gap``, ``on_gap`` (``gate`` is refused: use ``huber``).

    Attributes
    ----------
    arrival_filter : EKF
        The EKF that runs alongside the MHE, linearised at the MHE's estimates: its prediction is the
        arrival cost of the next window, and it gives the covariances, innovations and likelihood
        terms of the result. Its step Function is what C export of the arrival cost takes.

    Notes
    -----
    The states of the result are those of the augmented model (:func:`~casship.augment`): the
    original states, then the estimated parameters, then the disturbances ``d_<state>``. The ``p``
    given to :meth:`filter` is a parameter vector (or mapping) of the original model. Solver
    failures raise :class:`MHEFailed` (a ``RuntimeError``) naming the row and the solver's return
    status. The MHE is not of the step family and has no ``step`` (each sample solves an
    optimisation problem): the window problem itself is :meth:`window`, the real-time-iteration step
    as C is ``casship.estimators.export_mhe_rti``, and the EKF step that supplies the arrival cost is
    ``mhe.arrival_filter.step``. Time gaps longer than the one-step prediction limit raise or
    are bridged by prediction-only rows (options ``max_gap``, ``on_gap``), in batch and online alike.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order()
    >>> mhe = cs.MHE(cs.discretize(m, 0.1), Q=1e-8, R=1e-4, options={"horizon": 10})
    """

    name = "MHE"
    Options = MHEOptions

    def __init__(self, dmodel: DiscreteModel, Q, R, *, measured=None, options=None):
        if not isinstance(dmodel, DiscreteModel):
            raise InputTypeError(f"MHE needs a DiscreteModel (use casship.discretize), got {type(dmodel).__name__}")
        opts = MHEOptions.from_value(options, "MHE")
        base = dmodel.model
        self.base_model = base
        est, dist = tuple(opts.estimate), tuple(opts.disturbances)
        aug = augment(base, est, disturbances=dist, name=f"{base.name}+mhe") if est or dist else base
        self._extra_names, self._extra_std, extra_var = opts.extra_priors()
        self._est_names = est
        self._kept_params = [base.index(n, "param") for n in base.param_names if n not in est]
        Qa = augmented_noise(as_cov(Q, base.nw, "Q", base.noise_names), extra_var)
        adm = dmodel if aug is base else discretize(aug, dmodel.dt, dmodel.method, dmodel.substeps)
        self._windows: dict[tuple, Window] = {}
        self._arrival_steps: dict[tuple, ca.Function] = {}
        self._covariance_step = None
        super().__init__(adm, Qa, R, measured=measured, options=opts)
        o = self.options
        self.arrival_filter = EKF(self.dmodel, self.Q, self.R, measured=self.measured,
                                  options={"jit": o.jit, "max_gap": o.max_gap, "on_gap": o.on_gap})

    # -- configuration -----------------------------------------------------------------------------
    def _check_options(self) -> None:
        o, m, b = self.options, self.model, self.base_model
        if self.dmodel.symbolic is ca.MX:
            raise InputError(f"MHE needs an explicit discretisation ('euler' or 'rk4'), got {self.dmodel.method!r}")
        self.LQ, q_diag = sqrt_factor(self.Q)
        self.nv = self.LQ.shape[1]
        lo, hi = np.full(m.nx, -np.inf), np.full(m.nx, np.inf)
        for n in self._est_names:                      # estimated parameters: their model bounds
            i, j = m.index(n), b.index(n, "param")
            lo[i], hi[i] = b.param_lower[j], b.param_upper[j]
        for n, (a, c) in o.bounds.items():
            i = m.index(n)
            lo[i], hi[i] = bound_pair(n, a, c)
        self.x_bounds = (lo, hi)
        vlo, vhi = np.full(self.nv, -np.inf), np.full(self.nv, np.inf)
        if o.noise_bounds and not q_diag:
            raise InputError("option 'noise_bounds' needs a diagonal Q")
        cols = np.flatnonzero(np.diag(self.Q) > 0) if q_diag else np.arange(self.nv)
        for n, (a, c) in o.noise_bounds.items():
            i = m.index(n, "noise")
            a, c = bound_pair(n, a, c)
            if i not in cols:
                if a > 0 or c < 0:
                    raise InputError(f"noise bound on {n!r} excludes 0, but Q gives it zero variance")
                continue
            j = int(np.flatnonzero(cols == i)[0])
            s = np.sqrt(self.Q[i, i])
            vlo[j], vhi[j] = a / s, c / s
        self.v_bounds = (vlo, vhi)
        self.R_diagonal = np.count_nonzero(self.R - np.diag(np.diag(self.R))) == 0

    def arrival_step(self, outputs) -> ca.Function:
        """The step of :attr:`arrival_filter` returning its memory and ``outputs`` (compiled with option
        ``jit``; cached).

        Parameters
        ----------
        outputs : tuple of str
            Diagnostics among ``x, P, x_pred, P_pred, C, e, S, K, nis, ll, accepted``.
        """
        key = tuple(outputs)
        if key not in self._arrival_steps:
            fun = self.arrival_filter.step_function(key)
            self._arrival_steps[key] = jit_function(fun, self.options.jit)    # the runtime's policy
        return current_function(self._arrival_steps[key])

    @property
    def horizon(self) -> int:
        """The number of steps ``N`` of the window."""
        return self.options.horizon

    def window(self, N: int, solver: str | None = None) -> Window:
        """The window problem of horizon ``N`` (built once per horizon and solver).

        Parameters
        ----------
        N : int
            Horizon (steps in the window).
        solver : {"ipopt", "fatrop", "sqp", "rti"}, optional
            Default: the ``solver`` option.
        """
        solver = solver or self.options.solver
        if (N, solver) not in self._windows:
            self._windows[N, solver] = build_window(self, N, solver)
        return self._windows[N, solver]

    # -- priors and parameters ------------------------------------------------------------------------
    def _full_params(self, p) -> np.ndarray:
        return self.base_model.params() if p is None else self.base_model.params(p)

    def _params(self, p) -> np.ndarray:
        """The parameter vector of the (augmented) model from one of the original model."""
        return self._full_params(p)[self._kept_params]

    def augmented_prior(self, prior: Gaussian, p=None) -> Gaussian:
        """The prior over the augmented states.

        A prior over the original states is extended with the estimated parameters (mean: their
        value in ``p``, std: option ``estimate``) and the disturbances (mean 0, std from option
        ``disturbances``), independent of the rest. A prior over the augmented states is returned as is.

        Parameters
        ----------
        prior : Gaussian
        p : array or mapping, optional
            Parameters of the original model (the prior means of the estimated ones).
        """
        if not isinstance(prior, Gaussian):
            raise InputTypeError(f"prior must be a casship.Gaussian, got {type(prior).__name__}")
        m, b = self.model, self.base_model
        if prior.mean.size == m.nx:
            return prior
        if prior.mean.size != b.nx:
            raise InputError(f"prior has {prior.mean.size} entries; expected {b.nx} (states of {b.name!r}) "
                             f"or {m.nx} (augmented states {list(m.state_names)})")
        pf = self._full_params(p)
        mean = np.concatenate([pf[[b.index(n, "param") for n in self._est_names]],
                               np.zeros(len(self._extra_names) - len(self._est_names))])
        return augmented_prior(prior, mean, self._extra_std ** 2)

    def check_prior(self, prior: Gaussian) -> None:
        """Check a prior of the model's states or of the augmented states (see :meth:`augmented_prior`).

        Parameters
        ----------
        prior : Gaussian
        """
        super().check_prior(self.augmented_prior(prior))

    def _prepare(self, data: Dataset, p=None) -> dict:
        """The per-sample arrays of a record (``p`` of the original model; estimated parameters dropped)."""
        return self.records.prepare(data, self._params(p))

    # -- the estimator contract ---------------------------------------------------------------------
    def filter(self, data: Dataset, prior: Gaussian, p=None, *, seed=None) -> FilterResult:
        """Moving-horizon estimates over a record (one window solve per sample).

        Parameters
        ----------
        data : Dataset
            Inputs (finite) and measured outputs (NaN = not measured).
        prior : Gaussian
            Belief about the (original or augmented) state at the first time stamp.
        p : array or mapping, optional
            Parameters of the original model (estimated ones: prior means).
        seed : ignored (the MHE draws nothing)

        Returns
        -------
        FilterResult
            ``x``: the last state of each window; ``P``: the EKF covariance run alongside;
            predictions, innovations and likelihood terms from that EKF step. A gap bridged by
            prediction-only rows (``on_gap="bridge"``) adds those rows.
        """
        self.check_prior(prior)
        prior = self.augmented_prior(prior, p)
        data = bridge_gaps(self, data, prior, self._params(p), through=self.arrival_filter)
        arrays = self._prepare(data, p)
        n = len(data)
        engine = WindowEngine(self, prior, arrays["p"], outputs=DIAGNOSTICS)
        nx = self.model.nx
        keys = ("x_pred", "P_pred", "C", "e", "S", "K", "nis", "ll")
        out = {k: [] for k in ("x", "P", *keys)}
        U, Up, Y, M, dt = arrays["u"].T, arrays["u_prev"].T, arrays["y"].T, arrays["mask"].T, arrays["dt"][0]
        for k in track(range(n), f"MHE (N = {self.horizon}, {self.options.solver})", unit="sample"):
            x, P, info = engine.advance(Up[k], U[k], Y[k], M[k], dt[k], f"row {k} (t = {data.t[k]:g} s)")
            out["x"].append(x.copy())
            out["P"].append(P.reshape(nx, nx))
            for key in keys:
                out[key].append(info[key])
        out = {k: np.array(v) for k, v in out.items()}
        out["accepted"] = np.ones(n)
        return self.records.result(data, arrays, out)

    def online(self, prior: Gaussian, p=None, *, u=None, seed=None) -> OnlineRun:
        """A stateful runner on a stream (``update(y, dt, u_prev=None, u=None) -> x``), started from
        ``prior``; numbers equal :meth:`filter` on the same record, gaps included.

        ``run.info`` holds the diagnostics of option ``outputs`` besides ``x`` and ``P`` (``rejected``
        for ``accepted``) and ``solve_time``, the time of the update [s].

        Parameters
        ----------
        prior : Gaussian
        p : array or mapping, optional
            Parameters of the original model.
        u : array, optional
            Inputs before the first update.
        seed : ignored (the MHE draws nothing)
        """
        self.check_prior(prior)
        return OnlineRun(WindowEngine(self, self.augmented_prior(prior, p), self._params(p), u,
                                      outputs=self.options.outputs))

    def predict(self, result: FilterResult, t, u=None, p=None, *, seed=None) -> FilterResult:
        """Predict past the last sample of ``result`` with the EKF that runs alongside the MHE
        (with nothing measured the window adds nothing to it).

        Parameters
        ----------
        result, t, u, seed
            As for :meth:`StepEstimator.predict <casship.estimators.base.StepEstimator.predict>`.
        p : array or mapping, optional
            Parameters of the original model.
        """
        pred = self.arrival_filter.predict(result, t, u, self._params(p))
        return pred.replace(estimator=f"{self.name} prediction")

    def smooth(self, data: Dataset, prior: Gaussian, p=None, *, seed=None, guess: FilterResult | None = None
               ) -> FilterResult:
        """Full-information estimation: one window over the whole record (batch MAP smoother).

        The same NLP as the moving window with ``N = len(data) - 1`` and the prior as arrival cost.
        The initial guess is the EKF run (or ``guess``). Covariances are the diagonal blocks of the
        inverse Gauss-Newton Hessian at the solution. The real-time-iteration solver is iterated to
        convergence here (``"sqp"``).

        Parameters
        ----------
        data, prior, p
            As for :meth:`filter`.
        seed : ignored
        guess : FilterResult, optional
            Initial guess of the trajectory (default: the EKF run).

        Returns
        -------
        FilterResult
            ``x``: MAP states; ``P``: their covariances; predictions and innovations of the forward
            pass linearised at the MAP trajectory; ``estimator = "MHE-full"``.
        """
        self.check_prior(prior)
        prior = self.augmented_prior(prior, p)
        data = bridge_gaps(self, data, prior, self._params(p), through=self.arrival_filter)
        arrays = self._prepare(data, p)
        n = len(data)
        if n < 2:
            raise InputError("smooth needs at least two samples")
        win = self.window(n - 1, "sqp" if self.options.solver == "rti" else None)
        if guess is None:
            guess = self.arrival_filter.filter(data, prior, arrays["p"])
        z0 = np.zeros(win.nz)
        z0[win.ix] = guess.x
        z0 = np.clip(z0, win.lbx, win.ubx)
        par = params_vector(prior.mean, inv_sqrt(prior.cov), arrays["u"], arrays["u_prev"][:, 1:], arrays["y"],
                            arrays["mask"], arrays["dt"][:, 1:], arrays["p"])
        z, _ = solve_window(win, z0, par, f"the full record ({n} samples)")
        return self._covariances(data, z[win.ix], z[win.iv], arrays, prior)

    # -- covariances of the MAP trajectory ------------------------------------------------------------
    def _covariances(self, data, X, Vv, arrays, prior) -> FilterResult:
        """Forward Kalman pass and RTS pass linearised at the MAP trajectory (inverse GN Hessian blocks)."""
        m, n = self.model, len(data)
        W = np.zeros((n, m.nw))
        if self.nv:
            W[1:] = Vv @ self.LQ.T
        fold = self._linearised_step().mapaccum("mhe_gn_fold", n, ["P"], ["P"], DUPLICATE_NAMES)
        res = fold(P=prior.cov, x_prev=np.vstack([X[:1], X[:-1]]).T, w_prev=W.T, x_map=X.T,
                   R=self.R, **{k: arrays[k] for k in ("u_prev", "u", "y", "mask", "dt", "p")})
        out = {k: per_sample(np.asarray(v), n) for k, v in res.items()}
        out["x"], out["accepted"] = X, np.ones(n)
        forward = self.records.result(data, arrays, out, estimator="MHE-full")
        return forward.replace(P=rts_smooth(forward).P)

    def _linearised_step(self) -> ca.Function:
        """The EKF covariance step linearised at given states and noise, with named slots."""
        if self._covariance_step is None:
            m, dm, S = self.model, self.dmodel, ca.SX
            P = S.sym("P", m.nx, m.nx)
            xprev, wprev, x = S.sym("x_prev", m.nx), S.sym("w_prev", m.nw), S.sym("x_map", m.nx)
            up, u, mask, dt, p = S.sym("u_prev", m.nu), S.sym("u", m.nu), S.sym("mask", self.ny), S.sym("dt"), S.sym("p", m.np)
            y, R = S.sym("y", self.ny), S.sym("R", self.ny, self.ny)
            A, _, _, G = dm.F_jac(xprev, up, p, wprev, dt)
            xp = dm.F(xprev, up, p, S.zeros(m.nw), dt)
            Pp = A @ P @ A.T + G @ ca.DM(self.Q) @ G.T
            Pp = 0.5 * (Pp + Pp.T)
            e = self.residual(y, self.h_meas(xp, u, p), mask)
            up_ = joseph_update(xp, Pp, m.h_jac(x, u, p)[0][self.meas_index, :], e, R, mask, ca.inf)
            names_in = ["P", "x_prev", "w_prev", "x_map", "u_prev", "u", "y", "mask", "dt", "p", "R"]
            names_out = ["P", "x_pred", "P_pred", "C", "e", "S", "K", "nis", "ll"]
            self._covariance_step = ca.Function(
                "mhe_gn_forward", [P, xprev, wprev, x, up, u, y, mask, dt, p, R],
                [up_["P"], xp, Pp, P @ A.T, e, up_["S"], up_["K"], up_["nis"], up_["ll"]], names_in, names_out,
                DUPLICATE_NAMES)
        return self._covariance_step
