"""Prediction-error maximum likelihood through a recursive filter, over one or many records.

The negative log-likelihood of a record is the sum over its samples of
``0.5 (e_k' S_k^-1 e_k + log det S_k + m_k log 2 pi)``, with ``e_k`` and ``S_k`` the innovations
and their covariances from the filter's step Function folded over the record. Records are
independent: their likelihoods add. Derivatives are exact: forward sensitivities through the fold
give the gradient and the Fisher information (Fisher scoring), a backward sweep gives the gradient
alone (:meth:`MLEProblem.gradient`), and CasADi's second derivatives give the exact Hessian on
request.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..data import Dataset
from .spec import LikelihoodOptions
from ..gaussian import Gaussian
from ..discretize import DiscreteModel
from ..estimators.base import StepEstimator
from ..estimators.gaps import bridge_gaps
from ..runtime import piece, pieces
from ._likelihood import LikelihoodEngine, StepSlots
from ._solver import SolverReport
from .problem import IdentificationProblem
from .records import as_records, initial_states
from .result import FitResult
from ..errors import InputError, InputTypeError

__all__ = ["MLEProblem"]


def _record_prior(model, data: Dataset, R: np.ndarray, measured: Sequence[str], prior_var: float = 1.0,
                  estimated: Sequence[str] = ()) -> Gaussian:
    """The default initial-state prior of one record of an :class:`MLEProblem`.

    Its mean is the identification's one rule for a record's start (:func:`initial_states`, as in
    output-error fitting: a NaN first value is an error, not read forward), its variance the
    measurement variance of a state measured directly, ``prior_var`` for the others. A filter run
    outside identification starts from :func:`casship.prior_from_data`, the one public
    first-sample prior (it reads forward over a window and from the track).

    Parameters
    ----------
    model : Model
    data : Dataset
    R : (ny, ny) array
        Measurement covariance (the variance of a directly measured state's prior).
    measured : sequence of str
        Measured outputs.
    prior_var : float
        Variance of the states that are not measured directly.
    estimated : sequence of str
        States whose initial values are estimated (a NaN first value is then allowed).

    Returns
    -------
    Gaussian

    Raises
    ------
    ValueError
        Naming the column when a state's first value is NaN (and the state is not estimated).
    """
    mean = initial_states(model, [data], None, estimated)[0]
    var = np.full(model.nx, float(prior_var))
    for i, s in enumerate(model.state_names):
        if s in measured:
            j = list(measured).index(s)
            var[i] = R[j, j]
    return Gaussian(mean, var)


class MLEProblem(IdentificationProblem):
    """Maximum-likelihood (or MAP) identification through a filter (prediction error).

    Parameters
    ----------
    estimator : StepEstimator or DiscreteModel
        A recursive estimator (``EKF``, ``UKF``, ...) whose model carries the parameters. A
        :class:`~casship.DiscreteModel` is wrapped in an :class:`~casship.EKF` with ``Q``, ``R`` and
        ``measured``.
    datasets : Dataset or sequence of Dataset
        Records with the model's inputs and measured outputs (NaN = missing).
    free : sequence of str
        Free model parameters and biases (``"bias[n]"`` on an input, ``"bias[psi]"`` on a measured
        output).
    params : array or mapping, optional
        Values of the other parameters (nominal by default).
    noise : mapping, optional
        Diagonal noise variances to estimate: ``{"Q": ["w_r"], "R": True}`` (``True`` = all channels),
        named ``Q[w_r]``, ``R[psi]`` among the free quantities.
    x0 : Gaussian, sequence of Gaussian or mapping state -> value, optional
        Prior of the initial state of each record (one for all, or one per record). By default
        states named like a data column start at its first value (measured ones with their
        measurement variance, the others ``prior_var``; a NaN there is an error naming the record).
    estimate_x0 : sequence of str
        States whose initial means are estimated per record (``<state>@<record>``).
    prior_var : float
        Variance of unmeasured states in the default initial-state prior.
    share : mapping name -> "record" | "all" | grouping | labels, optional
        Which free quantities are per record or per group (see :func:`~casship.identify.share_labels`).
    groups : mapping grouping -> labels, optional
        Group labels per record (else from each record's ``meta``).
    prior : Prior or mapping name -> std, optional
        Gaussian prior on the free quantities (MAP), centred on the published values by default.
    bounds, scale : mapping name -> (lower, upper) / typical magnitude, optional
        For any free quantity (the model's parameter bounds apply too).
    Q, R, measured
        Only with a DiscreteModel: the filter's noise covariances and measured outputs.
    seed : int
        For stochastic estimators (EnKF): fixes the draws (common random numbers across evaluations).
    jit : bool or None
        Compile the likelihood and its derivatives to C (``None``: when a compiler works; code not in
        the cache yet is compiled in the background while the fit runs interpreted, with the same
        numbers). The compiled code does not depend on the data or on which quantities are free, and
        is kept in memory and on disk.

    Examples
    --------
    >>> import numpy as np, casship as cs
    >>> m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    >>> t = np.arange(0, 200, 1.0)
    >>> tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 30))})
    >>> data = cs.measure(tr, m, {"psi": 0.01}, seed=1)
    >>> ekf = cs.EKF(cs.discretize(m, 1.0), Q=1e-10, R=1e-4)
    >>> fit = cs.MLEProblem(ekf, data, free=["K", "T"]).solve(guess={"K": 0.05, "T": 10.0}, show=False)
    >>> abs(fit.params["K"] - 0.1) < 3 * fit.std_errors["K"]
    True
    """

    method = "mle"

    _SUBJECT = "estimator"
    OPTIONS = LikelihoodOptions

    def __init__(self, estimator, datasets, free: Sequence[str] = (), *, params=None, noise: Mapping | None = None,
                 x0=None, estimate_x0: Sequence[str] = (), prior_var: float = 1.0, share: Mapping | None = None,
                 groups: Mapping | None = None, prior=None, bounds: Mapping | None = None,
                 scale: Mapping | None = None, Q=None, R=None, measured=None, seed=0, jit: bool | None = None):
        kwargs = dict(estimator=estimator, datasets=datasets, free=free, params=params, noise=noise, x0=x0,
                      estimate_x0=estimate_x0, prior_var=prior_var, share=share, groups=groups, prior=prior,
                      bounds=bounds, scale=scale, Q=Q, R=R, measured=measured, seed=seed, jit=jit)
        if isinstance(estimator, DiscreteModel):
            from ..estimators import EKF

            if Q is None or R is None:
                raise InputError("with a DiscreteModel give the noise covariances Q and R (or pass an estimator)")
            estimator = EKF(estimator, Q, R, measured=measured)
            kwargs.update(estimator=estimator, Q=None, R=None, measured=None)
        elif not isinstance(estimator, StepEstimator):
            raise InputTypeError(f"MLEProblem folds a recursive estimator's step into the likelihood (KF, EKF, UKF, EnKF, "
                                 f"KalmanBucy) or takes a DiscreteModel, got {type(estimator).__name__}")
        elif Q is not None or R is not None or measured is not None:
            raise InputError("Q, R and measured are given to the estimator, not to MLEProblem")
        self.estimator = est = estimator
        m = est.model
        records = as_records(datasets)
        self.method = f"mle-{est.name.lower()}"
        slots = StepSlots(est)
        if list(estimate_x0) and slots.mean is None:
            raise InputError(f"estimate_x0 needs a mean/covariance filter; {est.name} carries an ensemble")
        self._priors = self._make_priors(m, records, x0, prior_var, estimate_x0)
        self._setup(m, records, free, kwargs=kwargs, share=share, groups=groups, prior=prior, params=params,
                    x0=[g.mean for g in self._priors], estimate_x0=estimate_x0, bounds=bounds, scale=scale,
                    measured=est.measured, noise=self._noise_entries(noise), Q=est.Q, R=est.R)
        rng = np.random.default_rng(seed)
        arrays = []
        for r, d in enumerate(self.records):
            # a gap beyond the one-step prediction limit raises, or is bridged (option on_gap)
            self.records[r] = d = bridge_gaps(est, d, self._priors[r], self.space.base)
            a = est.prepare(d)
            per = {n: np.asarray(a[n], dtype=float) for n in StepSlots.SAMPLE}
            per.update(slots.draws(len(d), rng))
            arrays.append({**per, "prior": self._priors[r], "seed": int(rng.integers(2**31))})
        self.engine = LikelihoodEngine(slots, self.space, arrays, est.Q, est.R, jit)
        self._check_data_amount()

    def _make_priors(self, m, records, x0, prior_var, estimated) -> list[Gaussian]:
        est, n = self.estimator, len(records)
        if x0 is None or isinstance(x0, Mapping):
            priors = [_record_prior(m, d, est.R, est.measured, prior_var, estimated) for d in records]
            if isinstance(x0, Mapping):
                idx = m.indices(x0, "state")
                vals = m.states(**x0)
                priors = [Gaussian(np.where(np.isin(np.arange(m.nx), idx), vals, g.mean), g.cov) for g in priors]
            return priors
        priors = [x0] * n if isinstance(x0, Gaussian) else list(x0)
        if len(priors) != n:
            raise InputError(f"x0: {len(priors)} priors for {n} records")
        for g in priors:
            est.check_prior(g)
        return priors

    def _noise_entries(self, noise):
        est, m = self.estimator, self.estimator.model
        noise = dict(noise or {})
        unknown = set(noise) - {"Q", "R"}
        if unknown:
            raise InputError(f"noise: unknown key(s) {sorted(unknown)}; use 'Q' and/or 'R'")
        out = []
        for kind, channels, mat in (("Q", m.noise_names, est.Q), ("R", est.measured, est.R)):
            sel = noise.get(kind, ())
            sel = list(channels) if sel is True else list(sel)
            bad = [c for c in sel if c not in channels]
            if bad:
                raise InputError(f"noise {kind}: unknown channel(s) {bad}; channels: {list(channels)}")
            for c in sel:
                i = list(channels).index(c)
                out.append((kind, i, f"{kind}[{c}]", mat[i, i] if mat[i, i] > 0 else 1e-6))
        return out

    # -- problem hooks -----------------------------------------------------------------------------
    def _n_obs(self) -> int:
        return int(sum(a["mask"].sum() for a in self.engine.arrays))

    def _noise_report(self, theta) -> dict:
        est, m = self.estimator, self.model
        Qd, Rd = np.diag(est.Q).copy(), np.diag(est.R).copy()
        for e, v in zip(self.space.entries, theta):
            if e.kind == "Q":
                Qd[e.index] = v
            elif e.kind == "R":
                Rd[e.index] = v
        return {"Q": dict(zip(m.noise_names, Qd.tolist())), "R": dict(zip(est.measured, Rd.tolist()))}

    def _first_nonfinite(self, r, theta) -> str:
        e, _ = self.engine.innovations(r, theta)
        mask = self.engine.arrays[r]["mask"].T > 0
        rows = np.flatnonzero(np.any(mask & ~np.isfinite(e), axis=1))
        return f" (innovations not finite from t = {self.records[r].t[rows[0]]:g} s)" if rows.size else ""

    def negloglik(self, values=None) -> float:
        """Negative log-likelihood of all records at the free values (without the prior).

        Parameters
        ----------
        values : mapping name -> value or array, optional
            Free values (missing names keep their start).

        Returns
        -------
        float
        """
        return self.engine.cost(self.space.theta(values))[0]

    # -- exact second derivatives ------------------------------------------------------------------
    def _graph(self, theta):
        """Symbolic negative log-likelihood (MX) of the free values ``theta`` (data as constants)."""
        eng, sp = self.engine, self.space
        fold = eng._value_raw()
        total = 0
        for r in range(len(self.records)):
            rm = sp.record_map(r)
            loc = theta[[int(c) for c in rm.cols]] if rm.k else ca.MX(0, 1)
            blk = {k: ca.DM(rm.fixed[k]) + (ca.mtimes(ca.DM(rm.E[k]), loc) if rm.k else 0) for k in rm.fixed}
            Q = ca.DM(eng.Q - np.diag(np.diag(eng.Q))) + ca.diag(blk["Q"])
            R = ca.DM(eng.R - np.diag(np.diag(eng.R))) + ca.diag(blk["R"])
            a = eng.arrays[r]
            mem = {f"m_{n}": ca.DM(v) for n, v in eng.slots.initial(Gaussian(a["prior"].mean, a["prior"].cov),
                                                                       np.random.default_rng(a["seed"])).items()}
            if eng.slots.mean is not None:
                slot, row = eng.slots.mean
                v = mem[f"m_{slot}"]
                mem[f"m_{slot}"] = ca.vertcat(v[:row], blk["x0"], v[row + self.model.nx:])
            per = {n: a[n] for n in (*StepSlots.SAMPLE, *eng.slots.draw_names)}
            for start, stop, size in pieces(per["dt"].shape[1]):
                ch = {n: ca.DM(piece(v, start, stop, size, 0.0 if n in ("mask", "dt") else None)) for n, v in per.items()}
                ones = ca.DM.ones(1, size)
                ch["u_prev"] = ch["u_prev"] + blk["u"] @ ones
                ch["u"] = ch["u"] + blk["u"] @ ones
                ch["y"] = (ch["y"] - blk["y"] @ ones) * ch["mask"]
                out = fold(**mem, **ch, p=blk["p"], Q=ca.vec(Q), R=ca.vec(R))
                mem = {n: out[f"{n}_next"] for n in mem}
                total = total - ca.sum2(out["ll"])
        return total

    def _exact_cost(self):
        """The cost (prior included) as a symbolic function of the solver's variables ``z``."""
        sp = self.space
        zs = ca.MX.sym("z", len(sp))
        theta = ca.vertcat(*[ca.exp(zs[i]) if e.log else zs[i] * e.scale for i, e in enumerate(sp.entries)])
        d = theta - self._mu
        f = self._graph(theta) + 0.5 * ca.sum1(ca.DM(self._prec) * d * d)
        return zs, f

    def solve(self, guess: Mapping[str, float] | None = None, *, hessian: str = "fisher",
              information: str = "fisher", max_iter: int = 100, tol: float = 1e-8, show: bool | None = None,
              options: Mapping | None = None, verdict: str | None = "replay") -> FitResult:
        """Maximise the likelihood (or the posterior, with a prior) from ``guess``.

        Parameters
        ----------
        guess : mapping, optional
            Starting values (default: the fixed parameter values, the estimator's noise, the priors).
        hessian : {"fisher", "exact", "limited-memory"}
            ``"fisher"``: bounded Fisher-scoring trust-region steps (exact gradient and the Fisher
            information of the innovations from forward sensitivities, compiled). ``"exact"`` /
            ``"limited-memory"``: IPOPT with the exact Hessian of the likelihood (second derivatives
            through the filter) or L-BFGS.
        information : {"fisher", "hessian"}
            Matrix inverted for the standard errors: expected (Fisher) or observed (exact Hessian)
            information at the optimum.
        max_iter : int
            Iteration limit.
        tol : float
            Convergence threshold (Fisher scoring; see :meth:`IdentificationProblem.solve`).
        show : bool, optional
            ``False`` hides the progress bar.
        options : mapping, optional
            IPOPT options (``hessian="exact"`` or ``"limited-memory"``).
        verdict : {"replay", "loo", None}
            Replay the fit on its records against the starting model (``"replay"``), also left-one-out
            (``"loo"``: one refit per record), or not (None); see :meth:`judge`.

        Returns
        -------
        FitResult
            A fit that stops early returns its iterate with the status and a warning.
        """
        if hessian not in ("fisher", "exact", "limited-memory"):
            raise InputError(f"unknown hessian {hessian!r}; use 'fisher', 'exact' or 'limited-memory'")
        if information not in ("fisher", "hessian"):
            raise InputError(f"information must be 'fisher' or 'hessian', got {information!r}")
        if hessian == "fisher":
            fit = super().solve(guess, max_iter=max_iter, tol=tol, show=show)
        else:
            fit = self._solve_ipopt(guess, hessian, max_iter, options)
        if information == "hessian":
            fit = self._observed(fit)
        return self._verdict(fit, verdict, guess)

    def _solve_ipopt(self, guess, hessian, max_iter, options) -> FitResult:
        from ._ipopt import IPOPT_OK, ipopt_solve

        sp = self.space
        theta0 = sp.theta(guess)
        sp.check_bounds(theta0)
        self._check_finite(theta0)
        zs, f = self._exact_cost()
        lbz, ubz = sp.z_bounds()
        opts = {"max_iter": max_iter, "hessian_approximation": hessian, **dict(options or {})}
        z_opt, st, seconds = ipopt_solve(f, zs, sp.to_z(theta0), lbz, ubz, options=opts, name=self.method)
        th = sp.natural(z_opt)
        fd, g, H, det = self.engine.derivatives(th)
        status = st.get("return_status", "unknown")
        rep = SolverReport(z_opt, fd + self._prior_terms(th)[0], g, H, "converged" if status in IPOPT_OK else status,
                           f"IPOPT: {status}", int(st.get("iter_count", 0)), seconds, float("nan"))
        fit = self._result(rep, {"f": fd, "H": H, "det": det}, self._shares(self.engine.derivatives(theta0)[3]))
        fit.status = status
        return fit

    def _observed(self, fit: FitResult) -> FitResult:
        """``fit`` with standard errors from the exact Hessian (observed information) at its optimum."""
        from .uncertainty import covariance_from_information

        sp = self.space
        theta = np.array([fit.estimates[n] for n in sp.names])
        ts = ca.MX.sym("theta", len(sp))
        d = ts - self._mu
        f = self._graph(ts) + 0.5 * ca.sum1(ca.DM(self._prec) * d * d)
        H = ca.jtimes(ca.gradient(f, ts), ts, ca.MX.eye(len(sp)))
        info = np.asarray(ca.Function("observed", [ts], [0.5 * (H + H.T)])(theta))
        cov, warn = covariance_from_information(info, sp.names)
        with np.errstate(invalid="ignore"):
            std = np.sqrt(np.diag(cov))
            fit.correlation = cov / np.outer(std, std)
        fit.covariance = cov
        fit.std_errors = {n: float(s) for n, s in zip(sp.names, std)}
        fit.warnings = list(fit.warnings) + [w for w in warn if w not in fit.warnings]
        return fit

    def __repr__(self) -> str:
        return (f"MLEProblem({self.model.name!r}, {len(self.records)} record(s), free={self.free}, "
                f"estimator={self.estimator.name})")
