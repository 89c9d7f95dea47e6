"""What a user knows about a ship's parameters before the next trial: a Gaussian over named parameters.

:class:`ParameterBelief` is the prior (or posterior) a trial design starts from: the mean and the
covariance of named model parameters. It comes from a fit (:meth:`ParameterBelief.from_fit`: the
fit's covariance over its free parameters, optionally widened by prior standard deviations for
parameters the fit held fixed) or from standard deviations around chosen values
(:meth:`ParameterBelief.from_std`). Adding a trial's information gives the belief after it
(:meth:`ParameterBelief.after`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..gaussian import Gaussian

__all__ = ["ParameterBelief"]


@dataclass(frozen=True)
class ParameterBelief:
    """A Gaussian belief ``N(mean, cov)`` over named model parameters.

    Parameters
    ----------
    names : sequence of str
        Model parameter names, in the order of ``mean`` and ``cov``.
    gaussian : Gaussian
        Mean and covariance (natural units of the parameters).
    source : str
        Where the belief comes from (for reports).

    Examples
    --------
    >>> from casship.design import ParameterBelief
    >>> b = ParameterBelief.from_std({"K": 0.02, "T": 5.0}, mean={"K": 0.1, "T": 20.0})
    >>> b.std
    {'K': 0.02, 'T': 5.0}
    """

    names: tuple
    gaussian: Gaussian
    source: str = ""

    def __post_init__(self):
        names = tuple(str(n) for n in self.names)
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise ValueError(f"parameter belief: duplicate name(s) {dup}")
        if len(names) != self.gaussian.mean.size:
            raise ValueError(f"parameter belief: {len(names)} names for a Gaussian of size {self.gaussian.mean.size}")
        if not names:
            raise ValueError("parameter belief: no parameters (nothing to learn from a trial)")
        object.__setattr__(self, "names", names)

    # -- construction ------------------------------------------------------------------------------
    @classmethod
    def from_std(cls, std: Mapping[str, float], mean: Mapping[str, float], *, source: str = "prior") -> "ParameterBelief":
        """Independent parameters with standard deviations ``std`` around ``mean``.

        Parameters
        ----------
        std : mapping name -> float
            Standard deviation of each uncertain parameter (positive, finite).
        mean : mapping name -> float
            Value of each (a model's ``param_dict()`` may be given whole: only the names in ``std``
            are taken).
        source : str
            Description for reports.

        Returns
        -------
        ParameterBelief

        Raises
        ------
        ValueError
            A standard deviation that is not positive and finite, or a name without a mean.
        """
        names = list(std)
        bad = [n for n in names if not (np.isfinite(float(std[n])) and float(std[n]) > 0)]
        if bad:
            raise ValueError(f"standard deviations must be positive and finite: {bad}")
        missing = [n for n in names if n not in mean]
        if missing:
            raise ValueError(f"no mean value for parameter(s) {missing}")
        s = np.array([float(std[n]) for n in names])
        return cls(tuple(names), Gaussian([float(mean[n]) for n in names], np.diag(s**2)), source)

    @classmethod
    def from_fit(cls, fit, *, extra_std: Mapping[str, float] | None = None, params: Mapping[str, float] | None = None,
                 source: str | None = None) -> "ParameterBelief":
        """The belief a fit leaves: its covariance over the free model parameters.

        Free quantities that are not model parameters (initial states, biases, noise variances) and
        per-record or per-group copies other than the one the fit's ``params`` apply (the copy whose
        estimate equals ``fit.params[name]``) are marginalised out: the belief keeps the block of
        the covariance of the copies that describe the ship of ``fit.params``. A fit file without a
        covariance falls back to its standard errors (independent).

        Parameters
        ----------
        fit : FitResult
            The fit (e.g. ``FitResult.from_json("fit.json")``).
        extra_std : mapping name -> float, optional
            Prior standard deviations of parameters the fit held fixed (independent of the rest,
            centred on ``fit.params``); a name that is free in the fit is an error.
        params : mapping, optional
            Parameter values (default ``fit.params``).
        source : str, optional
            Description for reports.

        Returns
        -------
        ParameterBelief

        Raises
        ------
        ValueError
            A free parameter with an infinite or undefined standard error, no model parameter among
            the free quantities and no ``extra_std``, or an ``extra_std`` name that is free.
        """
        values = dict(params or fit.params)
        pick, names = [], []
        for i, q in enumerate(fit.free):
            base = q.split("@", 1)[0]
            if base not in values or base in names:
                continue
            if "@" in q and not np.isclose(fit.estimates[q], values[base], rtol=1e-12, atol=0.0):
                continue                                   # another record's / group's copy
            pick.append(i)
            names.append(base)
        cov_full = np.asarray(fit.covariance, dtype=float)
        if pick and np.all(np.isfinite(cov_full[np.ix_(pick, pick)])):
            cov = cov_full[np.ix_(pick, pick)]
            how = "covariance"
        else:
            se = np.array([fit.std_errors[fit.free[i]] for i in pick])
            bad = [n for n, s in zip(names, se) if not (np.isfinite(s) and s > 0)]
            if bad:
                raise ValueError(f"the fit does not determine {bad} (standard error not finite); give them a "
                                 "prior standard deviation instead")
            cov = np.diag(se**2)
            how = "standard errors (no covariance in the fit)"
        extra = dict(extra_std or {})
        clash = sorted(set(extra) & set(names))
        if clash:
            raise ValueError(f"extra_std given for {clash}, which the fit estimated (their covariance comes from it)")
        missing = [n for n in extra if n not in values]
        if missing:
            raise ValueError(f"extra_std names parameter(s) {missing} that the fit's model lacks")
        e = cls.from_std(extra, values) if extra else None
        if not names and e is None:
            raise ValueError(f"the fit has no free model parameter among {list(fit.free)}; give extra_std")
        k = len(names)
        n = k + (len(e.names) if e else 0)
        big = np.zeros((n, n))
        big[:k, :k] = cov
        if e:
            big[k:, k:] = e.gaussian.cov
        mean = [values[q] for q in names] + ([values[q] for q in e.names] if e else [])
        text = source or (f"fit of {fit.model} ({how} of {k} free parameter(s)"
                          + (f", prior std of {len(extra)} more)" if extra else ")"))
        return cls(tuple(names) + (e.names if e else ()), Gaussian(mean, 0.5 * (big + big.T)), text)

    # -- queries -----------------------------------------------------------------------------------
    @property
    def mean(self) -> dict:
        """Mean value of each parameter."""
        return dict(zip(self.names, self.gaussian.mean.tolist()))

    @property
    def std(self) -> dict:
        """Standard deviation of each parameter."""
        return dict(zip(self.names, self.gaussian.std.tolist()))

    @property
    def cov(self) -> np.ndarray:
        """Covariance matrix (ordered like :attr:`names`)."""
        return self.gaussian.cov

    def variance_of(self, gradient: Sequence[float]) -> float:
        """Variance of a scalar function of the parameters by the delta method, ``g' cov g``.

        Parameters
        ----------
        gradient : array_like (k,)
            Gradient of the function with respect to the parameters (ordered like :attr:`names`).

        Returns
        -------
        float
        """
        g = np.asarray(gradient, dtype=float).reshape(-1)
        if g.size != len(self.names):
            raise ValueError(f"gradient has {g.size} entries for {len(self.names)} parameters")
        return float(g @ self.cov @ g)

    def after(self, information: np.ndarray) -> "ParameterBelief":
        """The belief after data with Fisher information ``information`` (linear-Gaussian update).

        ``cov_after = (cov^-1 + I)^-1``, computed as ``S (1 + S' I S)^-1 S'`` with a square root
        ``cov = S S'`` so that a singular prior direction (variance 0) stays known exactly.

        Parameters
        ----------
        information : (k, k) array
            Fisher information of the new data about the parameters (ordered like :attr:`names`).

        Returns
        -------
        ParameterBelief
            Same mean, the posterior covariance.
        """
        info = np.asarray(information, dtype=float)
        k = len(self.names)
        if info.shape != (k, k):
            raise ValueError(f"information has shape {info.shape}, expected ({k}, {k})")
        if not np.all(np.isfinite(info)):
            raise ValueError("information contains non-finite entries (did the trial's simulation diverge?)")
        w, v = np.linalg.eigh(self.cov)
        S = v * np.sqrt(np.clip(w, 0.0, None))
        inner = np.eye(k) + S.T @ (0.5 * (info + info.T)) @ S
        cov = S @ np.linalg.solve(inner, S.T)
        return ParameterBelief(self.names, Gaussian(self.gaussian.mean, 0.5 * (cov + cov.T)), self.source)

    def __repr__(self) -> str:
        return f"ParameterBelief({len(self.names)} parameters: {', '.join(self.names)}; {self.source})"
