"""Extra evidence in one objective: a :class:`CostTerm` and a :class:`JointProblem` that adds terms to a
free-running identification problem.

A cost term is a whitened residual vector ``r(theta)`` with its exact Jacobian, over *named*
quantities: it adds ``0.5 |r|^2`` (a negative log-likelihood up to a constant) to the cost,
``J' r`` to the gradient and ``J' J`` to the Gauss-Newton curvature. Its names are matched with the
free quantities of the problem it joins (``N_vvr_dash``, or a per-group copy ``w_P0@HSVA``); the
names the problem lacks (a facility's own quantities, e.g. ``w_P0@HMRI``) become extra free
quantities of the joint problem. The covariance of the joint estimate is the inverse of the joint
curvature (problem + prior + terms).

:class:`~casship.identify.captive.CaptiveProblem` gives the term of a captive-test record
(:meth:`~casship.identify.captive.CaptiveProblem.cost_term`).
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np

from ..errors import InputError
from ._solver import trust_region
from .result import FitResult, IdentificationWarning
from .uncertainty import covariance_from_information

__all__ = ["CostTerm", "JointProblem", "fit_result"]


@dataclass(frozen=True)
class CostTerm:
    """A whitened residual vector over named quantities, to add to an identification cost.

    Parameters
    ----------
    label : str
        What the evidence is (shown in results).
    names : tuple of str
        The quantities ``r`` depends on, in the order of the Jacobian's columns.
    start, lower, upper : arrays
        Starting values and bounds of those quantities (used for names the joined problem lacks).
    residual : callable
        ``values (ordered like names) -> (r, J)``: residuals divided by their noise standard
        deviations, and their exact Jacobian ``(n_obs, len(names))``.
    n_obs : int
        Number of residuals.
    prior_std : mapping name -> float, optional
        Gaussian prior (mean ``start``) on names the joined problem lacks; ignored for shared names
        (their prior is the problem's).
    value : callable, optional
        ``values -> r`` alone (cheaper than ``residual`` where the Jacobian is not needed, e.g. the
        trial points of a solver); default: ``residual(values)[0]``.
    """

    label: str
    names: tuple
    start: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    residual: Callable
    n_obs: int
    prior_std: Mapping = None
    value: Callable = None

    def cost(self, values) -> float:
        """``0.5 |r|^2``.

        Parameters
        ----------
        values : array_like
            Values ordered like :attr:`names`.

        Returns
        -------
        float
        """
        values = np.asarray(values, dtype=float)
        r = self.value(values) if self.value is not None else self.residual(values)[0]
        return 0.5 * float(r @ r)


def fit_result(*, model_name: str, params: dict, names: Sequence[str], theta, info, cost: float, n_obs: int,
               loglik: float, method: str, status: str, message: str, iterations: int, seconds: float,
               lower=None, upper=None, noise=None, records=(), prior=None, model=None,
               extra_warnings=(), robust=None) -> FitResult:
    """A :class:`FitResult` from an estimate and its information matrix (covariance = its inverse).

    Parameters
    ----------
    model_name : str
        Name of the model.
    params : dict
        All model parameters at the estimate.
    names : sequence of str
        Free quantities.
    theta : array_like
        Their estimates.
    info : 2-d array
        Information matrix (natural units, prior included).
    cost, loglik : float
        Optimal cost and log-likelihood.
    n_obs : int
        Number of scalar measurements.
    method, status, message : str
        Method name, solver status and message.
    iterations : int
        Solver iterations.
    seconds : float
        Solve time.
    lower, upper : array_like, optional
        Bounds (for the "ended at a bound" warnings).
    noise : dict, optional
        Noise levels used.
    records : sequence of str
        Record labels.
    prior : dict, optional
        The prior as stated.
    model : Model, optional
        The model (its options, parameter set and parameter names).
    extra_warnings : sequence of str
        Warnings to list first.
    robust : 2-d array, optional
        A robust (sandwich) covariance; default: the model-based one.

    Returns
    -------
    FitResult
    """
    names = list(names)
    cov, warn = covariance_from_information(info, names)
    with np.errstate(invalid="ignore", divide="ignore"):
        std = np.sqrt(np.diag(cov))
        corr = cov / np.outer(std, std)
    out = list(extra_warnings)
    if status != "converged":
        out.append(f"solver stopped early ({status}: {message}); the estimates are its best iterate")
    if lower is not None:
        out += [f"{n} ended at a bound ({v:g})" for n, v, lo, hi in zip(names, theta, lower, upper)
                if np.isclose(v, lo, rtol=1e-6, atol=1e-12) or np.isclose(v, hi, rtol=1e-6, atol=1e-12)]
    out += warn
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if np.isfinite(corr[i, j]) and abs(corr[i, j]) > 0.95:
                out.append(f"{names[i]} and {names[j]} are highly correlated (rho = {corr[i, j]:+.3f})")
    for w in out:
        if w.startswith("solver stopped"):
            warnings.warn(f"{method}: {w}", IdentificationWarning, stacklevel=3)
    k = len(names)
    robust = cov.copy() if robust is None else np.asarray(robust, dtype=float)
    with np.errstate(invalid="ignore"):
        std_r = np.sqrt(np.diag(robust))
    vessel = getattr(model, "vessel", None) if model is not None else None
    return FitResult(model=model_name, params=dict(params), free=names,
                     estimates={n: float(v) for n, v in zip(names, theta)},
                     std_errors={n: float(s) for n, s in zip(names, std)}, correlation=corr, covariance=cov,
                     cost=float(cost), loglik=float(loglik), n_obs=int(n_obs), aic=float(2 * k - 2 * loglik),
                     bic=float(k * np.log(max(n_obs, 1)) - 2 * loglik), warnings=out, method=method, status=status,
                     iterations=int(iterations), solve_time_s=float(seconds), noise=dict(noise or {}),
                     message=message, std_errors_robust={n: float(s) for n, s in zip(names, std_r)},
                     covariance_robust=robust, records=list(records), prior=dict(prior or {}),
                     model_options=dict(model.meta.get("options", {})) if model is not None else {},
                     param_set=vessel.param_set if vessel else "",
                     param_names=list(model.param_names) if model is not None else [])


class JointProblem:
    """An identification problem and extra cost terms, solved as one objective.

    Parameters
    ----------
    problem : IdentificationProblem
        A free-running problem (:class:`~casship.identify.MLEProblem`, or an
        :class:`~casship.identify.OutputErrorProblem` whose ``sigma`` are the noise standard
        deviations): its cost is taken as a negative log-likelihood.
    terms : sequence of CostTerm
        Extra evidence (e.g. :meth:`CaptiveProblem.cost_term`).
    hold_fixed : bool
        A term quantity that is a parameter the problem holds fixed: ``False`` (default) refuses it;
        ``True`` holds it in the term too, at the problem's value (one value for both).

    Raises
    ------
    InputError
        A term quantity that is a parameter of the problem's model but not free in it (free it in
        both, give the term its own name or ``hold_fixed=True``), or a name given two different
        starting values.

    Examples
    --------
    >>> joint = JointProblem(mle, [captive.cost_term()])        # doctest: +SKIP
    >>> fit = joint.solve()                                       # doctest: +SKIP
    """

    method = "joint"

    def __init__(self, problem, terms: Sequence[CostTerm], *, hold_fixed: bool = False):
        self.problem = problem
        self.terms = list(terms)
        self.hold_fixed = bool(hold_fixed)
        if not self.terms:
            raise InputError("JointProblem: give at least one cost term")
        sp = problem.space
        main = list(sp.names)
        declared = set(problem.model.param_names)
        fixed_values = problem.model.param_dict(sp.params(sp.theta()))
        extras, start, lower, upper, pstd = [], {}, {}, {}, {}
        for t in self.terms:
            for j, n in enumerate(t.names):
                if n in main:
                    continue
                if n in declared and self.hold_fixed:
                    continue
                if n in declared:
                    raise InputError(f"JointProblem: term {t.label!r} estimates {n!r}, a parameter of "
                                     f"{problem.model.name!r} that the problem holds fixed; free it in the problem "
                                     "too (one value for both) or give the term its own name (e.g. name@facility)")
                if n in start:
                    if not np.isclose(start[n], t.start[j]):
                        raise InputError(f"JointProblem: {n!r} starts at {start[n]} in one term, {t.start[j]} in another")
                    continue
                extras.append(n)
                start[n], lower[n], upper[n] = float(t.start[j]), float(t.lower[j]), float(t.upper[j])
                if t.prior_std and n in t.prior_std:
                    pstd[n] = float(t.prior_std[n])
        self._main, self._extras = main, extras
        self._k0 = len(main)
        self._extra_start = np.array([start[n] for n in extras])
        self._extra_lb = np.array([lower[n] for n in extras])
        self._extra_ub = np.array([upper[n] for n in extras])
        self._extra_prec = np.array([1.0 / pstd[n] ** 2 if n in pstd else 0.0 for n in extras])
        index = {n: i for i, n in enumerate(main + extras)}
        # per term: its columns in the joint vector (-1: held at the problem's fixed value)
        self._cols = [np.array([index.get(n, -1) for n in t.names], dtype=int) for t in self.terms]
        self._held = [np.array([fixed_values.get(n, np.nan) for n in t.names]) for t in self.terms]

    @property
    def free(self) -> list[str]:
        """The joint free quantities: the problem's, then the terms' own."""
        return self._main + self._extras

    def _theta(self, values=None) -> np.ndarray:
        values = dict(values or {})
        unknown = set(values) - set(self.free)
        if unknown:
            raise InputError(f"JointProblem: {sorted(unknown)} are not free; free: {self.free}")
        main = self.problem.space.theta({k: v for k, v in values.items() if k in self._main})
        extra = np.array([values.get(n, s) for n, s in zip(self._extras, self._extra_start)], dtype=float)
        return np.concatenate([main, extra])

    def _terms(self, theta):
        """Sum of the terms' cost, gradient and curvature (natural units), the extras' prior included."""
        k = len(theta)
        f, g, H = 0.0, np.zeros(k), np.zeros((k, k))
        for t, cols, held in zip(self.terms, self._cols, self._held):
            on = cols >= 0
            r, J = t.residual(np.where(on, theta[np.where(on, cols, 0)], held))
            J, c = J[:, on], cols[on]
            f += 0.5 * float(r @ r)
            g[c] += J.T @ r
            H[np.ix_(c, c)] += J.T @ J
        d = theta[self._k0:] - self._extra_start
        f += 0.5 * float(np.sum(self._extra_prec * d * d))
        g[self._k0:] += self._extra_prec * d
        H[self._k0:, self._k0:] += np.diag(self._extra_prec)
        return f, g, H

    def _terms_cost(self, theta) -> float:
        """The terms' cost alone (no Jacobians), the extras' prior included."""
        f = sum(t.cost(np.where(c >= 0, theta[np.where(c >= 0, c, 0)], h))
                for t, c, h in zip(self.terms, self._cols, self._held))
        d = theta[self._k0:] - self._extra_start
        return f + 0.5 * float(np.sum(self._extra_prec * d * d))

    def cost(self, values=None) -> float:
        """The joint cost: the problem's (data and prior) plus the terms'.

        Parameters
        ----------
        values : mapping name -> value, optional
            Joint free values (missing ones: the starting values).

        Returns
        -------
        float
        """
        theta = self._theta(values)
        return self.problem.cost(dict(zip(self._main, theta[:self._k0]))) + self._terms_cost(theta)

    def gradient(self, values=None) -> np.ndarray:
        """Exact gradient of :meth:`cost` (ordered like :attr:`free`).

        Parameters
        ----------
        values : mapping name -> value, optional
            Joint free values (missing ones: the starting values).

        Returns
        -------
        array
        """
        theta = self._theta(values)
        g = self._terms(theta)[1]
        g[:self._k0] += self.problem.gradient(dict(zip(self._main, theta[:self._k0])))
        return g

    def information(self, values=None) -> np.ndarray:
        """Joint Gauss-Newton information: the problem's data, its prior and the terms.

        Parameters
        ----------
        values : mapping name -> value, optional
            Joint free values (missing ones: the starting values).

        Returns
        -------
        2-d array
        """
        theta = self._theta(values)
        H = self._terms(theta)[2]
        H[:self._k0, :self._k0] += self.problem.information(dict(zip(self._main, theta[:self._k0])))
        H[:self._k0, :self._k0] += np.diag(self.problem.prior_precision)
        return H

    def solve(self, guess: Mapping[str, float] | None = None, *, max_iter: int = 100, tol: float = 1e-8,
              show: bool | None = None) -> FitResult:
        """Minimise the joint cost (bounded Gauss-Newton trust-region steps, as the problems do).

        Parameters
        ----------
        guess : mapping name -> value, optional
            Starting values (default: the problem's start and the terms' ``start``).
        max_iter : int
            Iteration limit.
        tol : float
            Convergence threshold on the predicted remaining decrease of the cost.
        show : bool, optional
            ``False`` hides the progress bar.

        Returns
        -------
        FitResult
            Estimates of :attr:`free`; covariance the inverse of the joint information.
        """
        pb, sp, k0 = self.problem, self.problem.space, self._k0
        theta0 = self._theta(guess)
        sp.check_bounds(theta0[:k0])
        lb0, ub0 = sp.z_bounds()
        lb, ub = np.concatenate([lb0, self._extra_lb]), np.concatenate([ub0, self._extra_ub])

        def split(z):
            return np.concatenate([sp.natural(z[:k0]), z[k0:]])

        def derivs(z):
            theta = split(z)
            f, g, H, _ = pb.engine.derivatives(theta[:k0])
            if not np.isfinite(f):
                return np.inf, np.zeros(len(z)), np.eye(len(z))
            fp, gp = pb.prior_cost(theta[:k0])
            ft, gt, Ht = self._terms(theta)
            D = np.concatenate([sp.jac_natural(z[:k0]), np.ones(len(z) - k0)])
            G = gt.copy()
            G[:k0] += g + gp
            HH = Ht.copy()
            HH[:k0, :k0] += H + np.diag(pb.prior_precision)
            return f + fp + ft, D * G, D[:, None] * HH * D[None, :]

        def cost(z):
            theta = split(z)
            return pb.engine.cost(theta[:k0])[0] + pb.prior_cost(theta[:k0])[0] + self._terms_cost(theta)

        z0 = np.concatenate([sp.to_z(theta0[:k0]), theta0[k0:]])
        t0 = time.perf_counter()
        rep = trust_region(derivs, cost, z0, lb, ub, tol=tol, max_iter=max_iter, label="joint fit", show=show)
        theta = split(rep.z)
        info = self.information(dict(zip(self.free, theta)))
        n_obs = pb.n_measured + sum(t.n_obs for t in self.terms)
        m = pb.model
        f_data = pb.engine.cost(theta[:k0])[0]
        loglik = pb.data_loglik(f_data) - sum(t.cost(np.where(c >= 0, theta[np.where(c >= 0, c, 0)], h))
                                              for t, c, h in zip(self.terms, self._cols, self._held))
        lower = np.concatenate([[e.lower for e in sp.entries], self._extra_lb])
        upper = np.concatenate([[e.upper for e in sp.entries], self._extra_ub])
        return fit_result(model_name=m.name, params=m.param_dict(sp.params(theta[:k0])), names=self.free, theta=theta,
                          info=info, cost=rep.f, n_obs=n_obs, loglik=loglik, method=f"joint ({pb.method} + "
                          + " + ".join(t.label for t in self.terms) + ")", status=rep.status, message=rep.message,
                          iterations=rep.iterations, seconds=time.perf_counter() - t0, lower=lower, upper=upper,
                          records=list(pb.labels) + [t.label for t in self.terms], model=m,
                          noise=pb.noise_report(theta[:k0]) if pb.method == "output-error" else None)

    def subset(self, indices: Sequence[int]) -> "JointProblem":
        """The same joint problem with the free-running problem on some of its records (terms kept).

        Parameters
        ----------
        indices : sequence of int
            Records to keep.

        Returns
        -------
        JointProblem
        """
        return JointProblem(self.problem.subset(indices), self.terms, hold_fixed=self.hold_fixed)

    def __repr__(self) -> str:
        return (f"JointProblem({self.problem.method}, {len(self.problem.records)} record(s), terms="
                f"{[t.label for t in self.terms]}, free={len(self.free)})")
