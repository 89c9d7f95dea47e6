"""What the identification problems share: records and their free quantities, the prior, the solve
loop, the result, the identifiability analysis and subsets for cross-validation.

:class:`~casship.identify.OutputErrorProblem` and :class:`~casship.identify.MLEProblem` differ in
their cost (simulated output error, or the innovations' likelihood through a filter) and build an
engine for it (:mod:`casship.identify._engine`); everything else lives here.
"""
from __future__ import annotations

import warnings
from typing import Mapping, Sequence

import numpy as np

from ._solver import trust_region
from ._space import ParamSpace
from .identifiability import Identifiability
from .prior import Prior
from .spec import ProblemSpec
from .records import as_records, initial_states, record_label, share_labels
from .result import FitResult, IdentificationError, IdentificationWarning
from .uncertainty import covariance_from_information, effective_samples, sandwich_covariance, whiteness
from ..errors import InputError, InputTypeError

__all__ = ["IdentificationProblem"]

UNSEEN_FACTOR = 1e3    # std error beyond this many times the magnitude: the data cannot see it
RHO_WARN = 0.95


def _as_prior(prior) -> Prior:
    if prior is None:
        return Prior()
    if isinstance(prior, Prior):
        return prior
    if isinstance(prior, Mapping):
        return Prior(std=prior)
    raise InputTypeError(f"prior must be a casship.identify.Prior or a mapping name -> std, got {type(prior).__name__}")


def whiteness_warning(coloured, ratio) -> str:
    """The warning for residuals that are not white, reading the robust / model-based standard errors.

    Parameters
    ----------
    coloured : list of str
        The outputs whose residuals failed the Ljung-Box test.
    ratio : array_like
        Robust (HAC sandwich) over model-based standard error, per free quantity (non-finite: left out).

    Returns
    -------
    str
        Which way the model-based standard errors err, and the range of the ratio as printed (one
        number when both ends print alike, so never "1-1 times").
    """
    ratio = np.asarray(ratio, dtype=float)
    ratio = ratio[np.isfinite(ratio)]
    if not ratio.size:
        reading, span = "the model-based standard errors do not hold as they are", "unlike"
    else:
        lo, hi = f"{ratio.min():.2g}", f"{ratio.max():.2g}"
        span = f"{lo} times" if lo == hi else f"{lo}-{hi} times"
        # read on the printed numbers, so that the words never contradict them ("optimistic ... 1 times")
        reading = ("the model-based standard errors hold nonetheless" if lo == hi == "1" else
                   "the model-based standard errors are optimistic" if float(lo) >= 1 else
                   "the model-based standard errors are conservative" if float(hi) <= 1 else
                   "the model-based standard errors do not hold as they are")
    return (f"residuals of {coloured} are not white (Ljung-Box): {reading}; the robust ones "
            f"(std_errors_robust, HAC sandwich) are {span} the model-based ones")


class IdentificationProblem:
    """Base class of the identification problems (not used directly)."""

    method = "identification"
    #: the constructor's name of its first argument (the model or the estimator)
    _SUBJECT = "model"
    #: the type of the method's own options in :attr:`spec` (set by each method)
    OPTIONS: type

    # -- set-up (called by the subclasses) ---------------------------------------------------------
    def _setup(self, model, records, free, *, kwargs: dict, share, groups, prior, params, x0, estimate_x0,
               bounds, scale, measured, noise=(), Q=None, R=None, record_params=None) -> None:
        self.spec = ProblemSpec.from_arguments(type(self), kwargs, self._SUBJECT)
        self.records = as_records(records)
        self.model = model
        self.measured = tuple(measured)
        self.labels = [record_label(d, i) for i, d in enumerate(self.records)]
        base = model.params(params) if params is not None else model.params()
        estimate_x0 = list(estimate_x0)
        model.indices(estimate_x0, "state")
        self.x0 = initial_states(model, self.records, x0, estimate_x0)
        x0_entries = [(r, model.index(s), self.x0[r][model.index(s)]) for r in range(len(self.records))
                      for s in estimate_x0]
        if record_params is not None and len(record_params) != len(self.records):
            raise InputError(f"record_params: {len(record_params)} entries for {len(self.records)} records")
        # a record's own fixed values (e.g. its facility's measured wake) over the shared ones
        record_base = None if record_params is None else [
            None if not own else model.params({**model.param_dict(base), **dict(own)}) for own in record_params]
        self.space = ParamSpace(model, len(self.records), free, copies=share_labels(self.records, share, groups),
                                base=base, measured=self.measured, noise=noise, x0=x0_entries, x0_fixed=self.x0,
                                Q=Q, R=R, bounds=bounds, scale=scale, record_base=record_base)
        if not len(self.space):
            raise InputError("nothing to estimate: give free parameters, biases, noise or estimate_x0")
        self.prior = _as_prior(prior)
        self._mu, self._prec = self.prior.vectors(self.space, model)
        left_out = [n for n, a in zip(model.output_names, model.angle_outputs)
                    if a and n not in self.measured and all(n in d for d in self.records)]
        if left_out:
            warnings.warn(f"{self.method}: heading {left_out} is measured in every record but not in the cost "
                          f"(measured = {list(self.measured)})", IdentificationWarning, stacklevel=3)

    def _check_data_amount(self) -> None:
        """Refuse a problem with no more measured values than free quantities the prior leaves open."""
        n_obs, open_ = self._n_obs(), int(np.sum(self._prec == 0))
        if n_obs <= open_:
            raise InputError(f"{self.method}: {n_obs} measured value(s) in {len(self.records)} record(s) for "
                             f"{open_} free quantities without a prior ({', '.join(self.free)}): the data cannot "
                             "determine them; give longer records, fewer free quantities or a prior")

    # -- what the subclasses provide ---------------------------------------------------------------
    def _residual_scale(self, f_data: float, n_obs: int) -> float:
        """Variance factor of the residuals (1 for a likelihood)."""
        return 1.0

    def _noise_report(self, theta) -> dict:
        return {}

    def _loglik(self, f_data: float, s2: float, n_obs: int) -> float:
        return -f_data

    def _n_obs(self) -> int:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- evaluation ------------------------------------------------------------------------------
    @property
    def free(self) -> list[str]:
        """Names of the free quantities, in the order of vectors and matrices."""
        return list(self.space.names)

    def _prior_terms(self, theta):
        d = theta - self._mu
        return 0.5 * float(np.sum(self._prec * d * d)), self._prec * d

    def cost(self, values=None) -> float:
        """The cost minimised by :meth:`solve`: the data cost plus the prior's.

        Parameters
        ----------
        values : mapping name -> value or array, optional
            Free values (missing names keep their starting value).

        Returns
        -------
        float
        """
        theta = self.space.theta(values)
        return self.engine.cost(theta)[0] + self._prior_terms(theta)[0]

    def gradient(self, values=None) -> np.ndarray:
        """Exact gradient of :meth:`cost` with respect to the free values (ordered like :attr:`free`).

        Parameters
        ----------
        values : mapping name -> value or array, optional
            Free values.

        Returns
        -------
        (k,) array
        """
        theta = self.space.theta(values)
        return self.engine.gradient(theta) + self._prior_terms(theta)[1]

    def information(self, values=None) -> np.ndarray:
        """Gauss-Newton / Fisher information of the data cost at the free values (natural units).

        Parameters
        ----------
        values : mapping name -> value or array, optional
            Free values.

        Returns
        -------
        (k, k) array
        """
        return self.engine.derivatives(self.space.theta(values))[2]

    def channel_shares(self, values=None) -> dict[str, float]:
        """Share of each measured channel in the weighted squared residuals at the free values.

        A channel whose share dwarfs the others decides the fit: check the weights (``sigma``, ``R``).

        Parameters
        ----------
        values : mapping name -> value or array, optional
            Free values.

        Returns
        -------
        dict
            Channel -> fraction (summing to 1).
        """
        return self._shares(self.engine.derivatives(self.space.theta(values))[3])

    def _shares(self, details) -> dict[str, float]:
        sq = np.zeros(len(self.measured))
        for d in details:
            sq += np.nansum(d["residuals"] ** 2, axis=0)
        total = sq.sum()
        return {n: float(v / total) if total > 0 else float("nan") for n, v in zip(self.measured, sq)}

    def _check_finite(self, theta) -> None:
        total, per = self.engine.cost(theta)
        if np.all(np.isfinite(per)):
            return
        bad = [self.labels[r] for r in np.flatnonzero(~np.isfinite(per))]
        where = self._first_nonfinite(int(np.flatnonzero(~np.isfinite(per))[0]), theta)
        values = ", ".join(f"{n}={v:.4g}" for n, v in zip(self.space.names, theta))
        raise IdentificationError(f"{self.method}: the cost is not finite at the start ({values}) in record(s) "
                                  f"{bad}{where}; change the guess, bound the free quantities or free fewer of them",
                                  "nan")

    def _first_nonfinite(self, r, theta) -> str:
        return ""

    # -- what a joint objective adds to (casship.identify.cost_term.JointProblem) ---------------------
    def prior_cost(self, theta) -> tuple[float, np.ndarray]:
        """The prior's cost and gradient.

        Parameters
        ----------
        theta : array_like
            Free values (natural units, ordered like :attr:`free`).

        Returns
        -------
        (float, array)
        """
        return self._prior_terms(np.asarray(theta, dtype=float))

    def noise_report(self, theta) -> dict:
        """The output noise of the fit at ``theta`` as a fit file records it (``sigma`` and its fitted
        scale for output error, ``R`` for a likelihood).

        Parameters
        ----------
        theta : array_like
            Free values (natural units, ordered like :attr:`free`).

        Returns
        -------
        dict
        """
        return self._noise_report(np.asarray(theta, dtype=float))

    @property
    def prior_precision(self) -> np.ndarray:
        """The prior's precision of each free quantity (0: no prior), ordered like :attr:`free`."""
        return self._prec.copy()

    @property
    def n_measured(self) -> int:
        """Number of scalar measurements in the cost."""
        return self._n_obs()

    def data_loglik(self, f_data: float) -> float:
        """Log-likelihood of the data for a data cost taken as a negative log-likelihood.

        Parameters
        ----------
        f_data : float
            The data cost (without the prior).

        Returns
        -------
        float
        """
        return self._loglik(f_data, 1.0, self._n_obs())

    # -- solve -----------------------------------------------------------------------------------
    def solve(self, guess: Mapping[str, float] | None = None, *, max_iter: int = 100, tol: float = 1e-8,
              show: bool | None = None) -> FitResult:
        """Minimise the cost from ``guess`` with bounded Gauss-Newton / Fisher-scoring trust-region steps.

        Parameters
        ----------
        guess : mapping name -> value, optional
            Starting values (default: the fixed values, 0 for biases, the noise and initial states
            the problem starts from).
        max_iter : int
            Iteration limit.
        tol : float
            Convergence threshold on the predicted remaining decrease of the cost, in the cost's
            statistical unit (1 for a likelihood, the residual variance for output error): the
            estimate is then within ``sqrt(2 tol)`` standard errors of the optimum.
        show : bool, optional
            ``False`` hides the progress bar (shown on a terminal).

        Returns
        -------
        FitResult
            Always: a fit that stops early (iteration limit, no descent, non-finite cost) returns its
            best iterate with the status and a warning (also issued as an ``IdentificationWarning``).

        Raises
        ------
        IdentificationError
            If the cost is not finite at the start (naming the records).
        """
        sp = self.space
        theta0 = sp.theta(guess)
        sp.check_bounds(theta0)
        self._check_finite(theta0)
        lb, ub = sp.z_bounds()
        n_obs, k = self._n_obs(), len(sp)
        cache = {}

        def derivs(z):
            theta = sp.natural(z)
            f, g, H, det = self.engine.derivatives(theta)
            cache.update(z=z.copy(), f=f, g=g, H=H, det=det)
            if not np.isfinite(f):
                return np.inf, g, H
            fp, gp = self._prior_terms(theta)
            D = sp.jac_natural(z)
            Hp = H + np.diag(self._prec)
            with np.errstate(over="ignore", invalid="ignore"):  # beyond float range: the solver rejects the step
                return f + fp, D * (g + gp), D[:, None] * Hp * D[None, :]

        def cost(z):
            theta = sp.natural(z)
            if not np.all(np.isfinite(theta)):       # a trial step beyond float range (exp of a log-variance)
                return np.inf
            return self.engine.cost(theta)[0] + self._prior_terms(theta)[0]

        def unit(f):
            return 1.0 if self._residual_scale(1.0, n_obs) == 1.0 else max(2 * f / max(n_obs - k, 1), 1e-300)

        start = self.engine.derivatives(theta0)
        rep = trust_region(derivs, cost, sp.to_z(theta0), lb, ub, unit=unit, tol=tol, max_iter=max_iter,
                           label=f"{self.method} fit", show=show)
        if not np.array_equal(cache.get("z"), rep.z):
            derivs(rep.z)
        return self._result(rep, cache, self._shares(start[3]))

    def judge(self, fit: FitResult, *, loo: bool | None = None, refit=None, guess=None,
              solve: Mapping | None = None) -> FitResult:
        """Replay ``fit`` on the records against the starting model (and left-one-out): its verdict and
        model discrepancy (see :func:`casship.identify.verdict.judge`), set on ``fit`` and returned.

        Parameters
        ----------
        fit : FitResult
            A fit of this problem.
        loo : bool, optional
            Refit without each record and replay it (default: when there are several records).
        refit, guess, solve
            See :func:`casship.identify.verdict.judge`.

        Returns
        -------
        FitResult
            ``fit``, with :attr:`~FitResult.verdict` and :attr:`~FitResult.model_discrepancy` set.
        """
        return self._judge(fit, loo=loo, refit=refit, guess=guess, solve=solve, stacklevel=3)

    def _judge(self, fit, *, loo, refit, guess, solve, stacklevel) -> FitResult:
        from .verdict import judge

        fit.verdict, fit.model_discrepancy = judge(self, fit, loo=loo, refit=refit, guess=guess,
                                                   solve=dict(solve or {}))
        if fit.worse:       # at the caller's line (of judge, or of solve through _verdict)
            warnings.warn(f"{self.method}: verdict {fit.verdict['verdict']}: {fit.verdict['reason']}",
                          IdentificationWarning, stacklevel=stacklevel)
        return fit

    def _verdict(self, fit: FitResult, verdict, guess) -> FitResult:
        """``fit`` judged as ``solve(verdict=...)`` asks: None (not), "replay" or "loo"."""
        if verdict is None:
            return fit
        if verdict not in ("replay", "loo"):
            raise InputError(f"verdict must be 'replay', 'loo' or None, got {verdict!r}")
        return self._judge(fit, loo=verdict == "loo", refit=None, guess=guess, solve=None, stacklevel=4)

    def _result(self, rep, at: dict, start_shares: dict) -> FitResult:
        sp, m = self.space, self.model
        theta = sp.natural(rep.z)
        names, k, n_obs = sp.names, len(sp), self._n_obs()
        f_data, H, det = at["f"], at["H"], at["det"]
        s2 = self._residual_scale(f_data, n_obs)
        info = H / s2 + np.diag(self._prec)
        cov, warn = covariance_from_information(info, names)
        robust, _ = sandwich_covariance(H / s2, self._prec, [(d["scores"] / s2, d["cols"]) for d in det], k, names)
        with np.errstate(invalid="ignore"):
            std = np.sqrt(np.diag(cov))
            corr = cov / np.outer(std, std)
            std_r = np.sqrt(np.diag(robust))
        std_r = np.where(np.isfinite(std), std_r, std)
        estimates = {n: float(v) for n, v in zip(names, theta)}
        residuals = [d["residuals"] / np.sqrt(s2) for d in det]
        white = whiteness(residuals, self.measured)
        neff = effective_samples(residuals, self.measured)
        out = []
        if rep.status != "converged":
            out.append(f"solver stopped early ({rep.status}: {rep.message}); the estimates are its best iterate")
        out += [f"{e.name} ended at a bound ({v:g})" for e, v in zip(sp.entries, theta)
                if np.isclose(v, e.lower, rtol=1e-6, atol=1e-12) or np.isclose(v, e.upper, rtol=1e-6, atol=1e-12)]
        out += warn
        for i in range(k):
            for j in range(i + 1, k):
                if np.isfinite(corr[i, j]) and abs(corr[i, j]) > RHO_WARN:
                    out.append(f"{names[i]} and {names[j]} are highly correlated (rho = {corr[i, j]:+.3f})")
        scales = sp.scales()
        for i, n in enumerate(names):
            mag = max(abs(theta[i]), abs(scales.get(n, 0.0)), 1e-12)
            if not np.isfinite(std[i]) or std[i] > UNSEEN_FACTOR * mag:
                out.append(f"the data do not determine {n}: standard error {std[i]:.3g} vs magnitude {mag:.3g}")
        coloured = [n for n, w in white.items() if not w["white"]]
        if coloured:
            with np.errstate(invalid="ignore", divide="ignore"):
                out.append(whiteness_warning(coloured, std_r / std))
        # issued once per fit, at the caller's line: _result <- the solver <- MLEProblem/OutputErrorProblem.solve
        # <- the caller (FitResult.summary lists them again, as the report of the fit)
        for w in out:
            if w.startswith(("solver stopped", "residuals of")):
                warnings.warn(f"{self.method}: {w}", IdentificationWarning, stacklevel=4)
        record_params = []
        for r in range(len(self.records)):
            p_r = sp.params(theta, r)
            vals = sp.record_map(r).values(theta)
            own = {n: float(v) for n, v, b in zip(m.param_names, p_r, sp.params(theta)) if v != b}
            own.update({f"bias[{c}]": float(vals["u"][i]) for i, c in enumerate(m.input_names) if vals["u"][i] != 0})
            own.update({f"bias[{c}]": float(vals["y"][i]) for i, c in enumerate(self.measured) if vals["y"][i] != 0})
            record_params.append(own)
        vessel = getattr(m, "vessel", None)
        loglik = self._loglik(f_data, s2, n_obs)
        return FitResult(
            model=m.name, params=m.param_dict(sp.params(theta)), free=list(names), estimates=estimates,
            std_errors={n: float(s) for n, s in zip(names, std)}, correlation=corr, covariance=cov,
            cost=float(rep.f), loglik=float(loglik), n_obs=int(n_obs), aic=float(2 * k - 2 * loglik),
            bic=float(k * np.log(max(n_obs, 1)) - 2 * loglik), whiteness=white, warnings=out, method=self.method,
            status=rep.status, iterations=rep.iterations, solve_time_s=rep.seconds,
            noise=self._noise_report(theta),
            x0=[dict(zip(m.state_names, sp.record_map(r).values(theta)["x0"].tolist())) for r in range(len(self.records))],
            predictions=[self._free_run(r, theta) for r in range(len(self.records))],
            message=rep.message, std_errors_robust={n: float(s) for n, s in zip(names, std_r)},
            covariance_robust=np.where(np.isfinite(robust), robust, np.nan),
            effective_samples=neff, channel_share={"start": start_shares, "optimum": self._shares(det)},
            prior=self.prior.describe(sp, m) if np.any(self._prec > 0) else {},
            records=list(self.labels), record_params=record_params,
            model_options=dict(m.meta.get("options", {})), param_set=vessel.param_set if vessel else "",
            param_names=list(m.param_names))

    def _free_run(self, r: int, theta) -> dict:
        """Free-run simulation of record ``r`` at ``theta`` against its measured outputs (for plots)."""
        from ..simulation import IntegrationError, simulate

        m, d = self.model, self.records[r]
        vals = self.space.record_map(r).values(theta)
        inputs = {n: d[n] + vals["u"][i] for i, n in enumerate(m.input_names)}
        try:
            tr = simulate(m, vals["x0"], d.t, inputs, vals["p"], method="rk4")
            sim = {n: tr[n] + vals["y"][j] for j, n in enumerate(self.measured)}
        except (IntegrationError, ValueError, FloatingPointError):    # a diverging replay is shown as missing
            sim = {n: np.full(len(d), np.nan) for n in self.measured}
        units = {v.name: v.unit for v in m.output_vars}
        return {"t": d.t, "label": self.labels[r], "kind": "free-run simulation",
                "measured": {n: d[n] for n in self.measured}, "predicted": sim,
                "units": {n: units.get(n, "") for n in self.measured},
                "angle": {n: bool(m.angle_outputs[m.index(n, "output")]) for n in self.measured}}

    # -- analysis --------------------------------------------------------------------------------
    def identifiability(self, at: Mapping[str, float] | None = None, *, max_rel_std: float | None = None,
                        max_corr: float | None = None, asymmetric: Sequence[str] | None = None,
                        pairs_within=None) -> Identifiability:
        """Fisher-information analysis of the free quantities at ``at`` (default: the starting values).

        Free port/starboard asymmetry quantities whose records hold no mirror pair (the same
        manoeuvre turning first to both sides, see :mod:`casship.identify.asymmetry`) are flagged in
        ``confounded`` and left out of ``propose()``.

        Parameters
        ----------
        at : mapping name -> value, optional
            The point (e.g. the published values, or a previous fit's estimates).
        max_rel_std, max_corr : float, optional
            Report thresholds (relative standard error, correlation).
        asymmetric : sequence of str, optional
            Declared names of the asymmetry quantities (default: the model's
            ``meta["asymmetric"]`` parameters and the offsets of its rudder inputs).
        pairs_within : str or sequence, optional
            A grouping (name from ``groups``/``meta``, or one label per record) within which mirror
            pairs must lie, e.g. ``"facility"``.

        Returns
        -------
        Identifiability
            With ``summary()``, ``plot(path)`` and ``propose()`` (a free set by a stated criterion).

        Examples
        --------
        >>> idf = problem.identifiability()       # doctest: +SKIP
        >>> print(idf.summary())                   # doctest: +SKIP
        """
        from .asymmetry import asymmetric_quantities, confounded_asymmetry
        from .identifiability import MAX_CORR, MAX_REL_STD

        theta = self.space.theta(at)
        H = self.engine.derivatives(theta)[2]
        mags = np.array([(abs(v) or e.scale) if e.kind == "param" else 1.0 for e, v in zip(self.space.entries, theta)])
        names = set(asymmetric_quantities(self.model) if asymmetric is None else asymmetric)
        rudders = [n[5:-1] for n in names if n.startswith("bias[")] or ["delta"]
        flagged = [q for q in self.free if q.split("@")[0] in names]
        confounded = {}
        if flagged and rudders[0] in self.records[0]:
            copies = share_labels(self.records, self.spec.share, self.spec.groups)
            within = None
            if pairs_within is not None:
                within = share_labels(self.records, {"_": pairs_within}, self.spec.groups).get("_")
            confounded = confounded_asymmetry(self.records, flagged, copies, rudder=rudders[0], within=within)
        return Identifiability(self.free, dict(zip(self.free, theta.tolist())), mags, H, self._prec.copy(),
                               kinds=[e.kind for e in self.space.entries],
                               max_rel_std=MAX_REL_STD if max_rel_std is None else float(max_rel_std),
                               max_corr=MAX_CORR if max_corr is None else float(max_corr), confounded=confounded)

    # -- variants --------------------------------------------------------------------------------
    def replace(self, **changes) -> "IdentificationProblem":
        """The same problem with constructor arguments changed (e.g. ``free=[...]``, ``prior=...``).

        Parameters
        ----------
        **changes
            Constructor arguments to change.

        Returns
        -------
        IdentificationProblem
            A new problem of the same class.
        """
        return self.spec.replace(**changes).build()

    def subset(self, indices: Sequence[int]) -> "IdentificationProblem":
        """The same problem on some of its records (per-record arguments are subset alike).

        Parameters
        ----------
        indices : sequence of int
            Records to keep, in order.

        Returns
        -------
        IdentificationProblem
        """
        idx = [int(i) for i in indices]
        if not idx or any(not 0 <= i < len(self.records) for i in idx):
            raise InputError(f"record indices must be in 0..{len(self.records) - 1}, got {list(indices)}")
        return self.spec.with_records([self.records[i] for i in idx], idx).build()
