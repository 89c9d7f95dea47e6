"""What a user knows about a ship's parameters before the next trial: a Gaussian over named parameters.

:class:`ParameterBelief` is the prior (or posterior) a trial design starts from: the mean and the
covariance of named model parameters. It comes from a fit or its file
(:meth:`ParameterBelief.from_fit`: the covariance the file carries -- calibrated by a run-level
jackknife when the fit was -- or the fit's robust or model-based one, optionally widened by prior
standard deviations for parameters the fit held fixed), from a file's
:class:`~casship.identify.ParameterUncertainty` (:meth:`ParameterBelief.from_uncertainty`) or from
standard deviations around chosen values (:meth:`ParameterBelief.from_std`); its :attr:`kind`
names which covariance it is, for reports. Adding a trial's information gives the belief after it
(:meth:`ParameterBelief.after`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..gaussian import Gaussian
from ..errors import InputError
from ..identify.params_file import COVARIANCE_KINDS, CovarianceKind, kind_from_source

__all__ = ["ParameterBelief", "COVARIANCES", "covariance_kind"]

#: The covariances of a fit file a belief can be built from (:meth:`ParameterBelief.from_fit`).
COVARIANCES = ("jackknife", "robust", "model")


def covariance_kind(covariance) -> str:
    """The kind of a parameter covariance, for reports.

    Parameters
    ----------
    covariance : ParameterUncertainty, ParameterBelief or str
        An uncertainty or a belief (its ``kind``, set where the covariance was made), or the prose
        ``source`` of a covariance from a file older than the ``kind`` field (read by
        :func:`casship.identify.params_file.kind_from_source`, the one rule for those).

    Returns
    -------
    str
        One of :data:`casship.identify.COVARIANCE_KINDS` (``"calibrated"``, ``"robust"``,
        ``"model-based"``, ``"standard errors"``, ``"prior"``, ``"stated"``).

    Examples
    --------
    >>> from casship.identify import ParameterUncertainty
    >>> covariance_kind(ParameterUncertainty(["K"], [0.1], [[1e-4]], "by hand", kind="prior"))
    'prior'
    >>> covariance_kind("run-level jackknife over 16 leave-one-run-out folds")
    'calibrated'
    """
    if isinstance(covariance, str):
        return kind_from_source(covariance)
    return covariance.kind


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
    kind : CovarianceKind
        Which covariance it is: ``"prior"``, ``"calibrated"``, ``"robust"``, ``"model-based"``,
        ``"standard errors"`` or ``"stated"`` (:data:`casship.identify.COVARIANCE_KINDS`; see
        :meth:`from_fit`).

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
    kind: CovarianceKind = "stated"

    def __post_init__(self):
        if self.kind not in COVARIANCE_KINDS:
            raise InputError(f"parameter belief: unknown covariance kind {self.kind!r}; use one of {COVARIANCE_KINDS}")
        names = tuple(str(n) for n in self.names)
        if len(set(names)) != len(names):
            dup = sorted({n for n in names if names.count(n) > 1})
            raise InputError(f"parameter belief: duplicate name(s) {dup}")
        if len(names) != self.gaussian.mean.size:
            raise InputError(f"parameter belief: {len(names)} names for a Gaussian of size {self.gaussian.mean.size}")
        if not names:
            raise InputError("parameter belief: no parameters (nothing to learn from a trial)")
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
            raise InputError(f"standard deviations must be positive and finite: {bad}")
        missing = [n for n in names if n not in mean]
        if missing:
            known = list(mean)
            raise InputError(f"unknown parameter(s) {missing}: no mean value for them among the {len(known)} "
                             f"parameters given ({', '.join(map(str, known[:12]))}"
                             f"{', ...' if len(known) > 12 else ''})")
        s = np.array([float(std[n]) for n in names])
        return cls(tuple(names), Gaussian([float(mean[n]) for n in names], np.diag(s**2)), source, "prior")

    @classmethod
    def from_prior(cls, prior, params: Mapping[str, float] | None = None, *,
                   source: str = "prior") -> "ParameterBelief":
        """The belief an identification :class:`~casship.identify.Prior` states (independent parameters).

        Parameters
        ----------
        prior : casship.identify.Prior
            Its ``std`` names the parameters; its ``mean`` gives their means.
        params : mapping, optional
            Means of the parameters the prior gives none for (a Prior defaults to the model's
            nominal values: give ``model.param_dict(p)``).
        source : str
            Description for reports.

        Returns
        -------
        ParameterBelief
            With :attr:`kind` ``"prior"``.

        Examples
        --------
        >>> from casship.identify import Prior
        >>> ParameterBelief.from_prior(Prior({"K": 0.02}, {"K": 0.1})).std
        {'K': 0.02}
        """
        mean = {**dict(params or {}), **dict(prior.mean)}
        return cls.from_std(prior.std, mean, source=source)

    def to_prior(self, *, weight: float = 1.0, marginal: bool = False):
        """This belief as an identification :class:`~casship.identify.Prior` (see ``Prior.from_belief``).

        Parameters
        ----------
        weight : float
            Multiplies the prior's cost.
        marginal : bool
            Accept correlated parameters, keeping their marginal standard deviations only.

        Returns
        -------
        casship.identify.Prior
        """
        from ..identify import Prior

        return Prior.from_belief(self, weight=weight, marginal=marginal)

    def to_uncertainty(self):
        """This belief as a :class:`~casship.identify.ParameterUncertainty` (same names, means,
        covariance, source and kind), e.g. to draw replays' bands from it.

        Returns
        -------
        casship.identify.ParameterUncertainty
        """
        from ..identify import ParameterUncertainty

        return ParameterUncertainty(list(self.names), self.gaussian.mean, self.cov, self.source, kind=self.kind)

    @classmethod
    def from_uncertainty(cls, uncertainty, *, extra_std: Mapping[str, float] | None = None,
                         params: Mapping[str, float] | None = None, source: str | None = None) -> "ParameterBelief":
        """The belief a parameter file's uncertainty states: its parameters, values and covariance.

        Parameters
        ----------
        uncertainty : casship.identify.ParameterUncertainty
            E.g. ``read_fit_file(path, model).uncertainty``.
        extra_std : mapping name -> float, optional
            Prior standard deviations of further parameters (independent of the rest, centred on
            ``params``); a name the uncertainty covers is an error.
        params : mapping, optional
            Values of the model's parameters (needed with ``extra_std``: the means of those).
        source : str, optional
            Description for reports (default: the kind of covariance and its source).

        Returns
        -------
        ParameterBelief
            With the uncertainty's :attr:`kind`.

        Examples
        --------
        >>> from casship.identify import ParameterUncertainty
        >>> u = ParameterUncertainty(["K", "T"], [0.1, 20.0], [[1e-4, 0.0], [0.0, 4.0]], "run-level jackknife",
        ...                          kind="calibrated")
        >>> ParameterBelief.from_uncertainty(u).kind
        'calibrated'
        """
        kind = uncertainty.kind
        text = source or (f"{kind} covariance ({uncertainty.source or 'source not stated'}) of "
                          f"{len(uncertainty.names)} parameter(s)")
        belief = cls(tuple(uncertainty.names), Gaussian(uncertainty.values, uncertainty.covariance), text, kind)
        return belief._with_extra(extra_std, params, source)

    @classmethod
    def from_fit(cls, fit, *, covariance: str | None = None, extra_std: Mapping[str, float] | None = None,
                 params: Mapping[str, float] | None = None, source: str | None = None) -> "ParameterBelief":
        """The belief a fit leaves: the covariance its file carries, or its robust or model-based one.

        A fit file carries the uncertainty a new run is replayed with (``param_covariance``): a
        calibrated one when the fit was calibrated (the kvlcc2-marin study's run-level jackknife),
        else the robust (sandwich) covariance of its shared free model parameters. By default that
        one is taken; ``covariance`` asks for a kind and refuses a file that lacks it.

        For the robust and model-based covariances of the fit itself, free quantities that are not
        model parameters (initial states, biases, noise variances) and per-record or per-group copies
        other than the one the fit's ``params`` apply (the copy whose estimate equals
        ``fit.params[name]``) are marginalised out: the belief keeps the block of the copies that
        describe the ship of ``fit.params``. A model-based covariance that is not finite falls back
        to the standard errors (independent).

        Parameters
        ----------
        fit : FitResult, str or Path
            The fit, or its file (``FitResult.to_json``).
        covariance : {None, "jackknife", "robust", "model"}
            None: the file's own (calibrated when present); ``"jackknife"``: the calibrated one
            (an error when the file has none); ``"robust"``: the robust one the file carries, else
            the fit's sandwich covariance; ``"model"``: the fit's model-based covariance.
        extra_std : mapping name -> float, optional
            Prior standard deviations of parameters the fit held fixed (independent of the rest,
            centred on ``fit.params``); a name the covariance covers is an error.
        params : mapping, optional
            Parameter values (default ``fit.params``).
        source : str, optional
            Description for reports (default: where the covariance comes from and what it covers).

        Returns
        -------
        ParameterBelief
            Its :attr:`kind` says which covariance was used (``"calibrated"``, ``"robust"``,
            ``"model-based"``, ``"standard errors"``).

        Raises
        ------
        ValueError
            An unknown ``covariance``, a kind the fit lacks (naming what it has), a free parameter
            with an infinite or undefined standard error, no model parameter among the free
            quantities and no ``extra_std``, or an ``extra_std`` name the covariance covers.

        Examples
        --------
        >>> belief = ParameterBelief.from_fit("fit.json")                         # doctest: +SKIP
        >>> belief.kind, belief.source                                            # doctest: +SKIP
        ('calibrated', 'fit.json: calibrated covariance (run-level jackknife over 16 ...) of 10 parameter(s)')
        """
        from ..identify import FitResult, ParameterUncertainty

        where = "the fit"
        if isinstance(fit, (str, os.PathLike)):
            where = Path(fit).name
            fit = FitResult.from_json(fit)
        if covariance not in (None, *COVARIANCES):
            raise InputError(f"unknown covariance {covariance!r}; use one of {COVARIANCES} (or None: the file's own)")
        values = dict(params or fit.params)
        carried = ParameterUncertainty.from_dict(fit.param_covariance, where) if fit.param_covariance else None
        kind = carried.kind if carried is not None else None
        wanted = {None: kind, "jackknife": "calibrated", "robust": "robust", "model": "model-based"}[covariance]
        if carried is not None and kind == wanted:
            bad = [n for n, v in zip(carried.names, carried.values)
                   if not np.isclose(v, values.get(n, np.nan), rtol=1e-12, atol=0.0)]
            if bad:
                raise InputError(f"{where}: the values of {bad} in its covariance differ from its parameters")
            belief = cls.from_uncertainty(carried)
        elif covariance == "jackknife":
            has = f"it carries a {kind} one ({carried.source})" if carried is not None else "it carries none"
            raise InputError(f"{where} has no calibrated (jackknife) covariance: {has}; ask for the robust or the "
                             "model-based one")
        else:
            belief = cls._free_block(fit, values, robust={None: None, "robust": True, "model": False}[covariance])
            if belief is None:
                if not extra_std:
                    raise InputError(f"{where} has no free model parameter among {list(fit.free)}; give prior "
                                     "standard deviations (extra_std)")
                return cls.from_std(extra_std, values, source=source or f"prior around the values of {where}")
        belief = ParameterBelief(belief.names, belief.gaussian, f"{where}: {belief.source}", belief.kind)
        return belief._with_extra(extra_std, values, source, clash="the fit estimated")

    @classmethod
    def _free_block(cls, fit, values: dict, *, robust: bool | None) -> "ParameterBelief | None":
        """The robust (``robust=None``: when the fit has a finite one) or model-based covariance of the
        fit's free model parameters (see from_fit); None when no free quantity is a model parameter."""
        pick, names = [], []
        for i, q in enumerate(fit.free):
            base = q.split("@", 1)[0]
            if base not in values or base in names:
                continue
            if "@" in q and not np.isclose(fit.estimates[q], values[base], rtol=1e-12, atol=0.0):
                continue                                   # another record's / group's copy
            pick.append(i)
            names.append(base)
        if not names:
            return None
        if robust is None:
            robust = (fit.covariance_robust is not None
                      and bool(np.all(np.isfinite(np.asarray(fit.covariance_robust)[np.ix_(pick, pick)]))))
        if robust and fit.covariance_robust is None:
            raise InputError("the fit has no robust covariance; use covariance='model'")
        full = np.asarray(fit.covariance_robust if robust else fit.covariance, dtype=float)
        block = full[np.ix_(pick, pick)]
        kind = "robust" if robust else "model-based"
        if not np.all(np.isfinite(block)):
            if robust:
                raise InputError(f"the fit's robust covariance is not finite for {names}; use covariance='model'")
            se = np.array([fit.std_errors[fit.free[i]] for i in pick])
            bad = [n for n, s in zip(names, se) if not (np.isfinite(s) and s > 0)]
            if bad:
                raise InputError(f"the fit does not determine {bad} (standard error not finite); give them a "
                                 "prior standard deviation instead")
            block, kind = np.diag(se**2), "standard errors"
        how = {"robust": "robust (sandwich) covariance", "model-based": "model-based covariance",
               "standard errors": "standard errors (no covariance in the fit)"}[kind]
        return cls(tuple(names), Gaussian([values[n] for n in names], 0.5 * (block + block.T)),
                   f"{how} of {len(names)} free parameter(s)", kind)

    def extended(self, std: Mapping[str, float], mean: Mapping[str, float], *,
                 source: str | None = None) -> "ParameterBelief":
        """This belief with more parameters, independent of the others, with standard deviations ``std``.

        Parameters
        ----------
        std : mapping name -> float
            Standard deviation of each added parameter (positive, finite; not already in the belief).
        mean : mapping name -> float
            Their values (a model's ``param_dict()`` may be given whole).
        source : str, optional
            Description for reports (default: this one's and the added prior's).

        Returns
        -------
        ParameterBelief
            Same :attr:`kind` as this one.
        """
        return self._with_extra(std, mean, source)

    def _with_extra(self, extra_std, values, source, clash: str = "the belief covers") -> "ParameterBelief":
        extra = dict(extra_std or {})
        if not extra:
            return self if source is None else ParameterBelief(self.names, self.gaussian, source, self.kind)
        both = sorted(set(extra) & set(self.names))
        if both:
            raise InputError(f"extra_std given for {both}, which {clash} (their covariance comes from it)")
        if values is None:
            raise InputError("extra_std needs the parameters' values (params)")
        e = ParameterBelief.from_std(extra, values)
        k, n = len(self.names), len(self.names) + len(e.names)
        big = np.zeros((n, n))
        big[:k, :k], big[k:, k:] = self.cov, e.cov
        text = source or f"{self.source}, and the prior std of {len(e.names)} more"
        return ParameterBelief(self.names + e.names, Gaussian(np.r_[self.gaussian.mean, e.gaussian.mean], big), text,
                               self.kind)

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
            raise InputError(f"gradient has {g.size} entries for {len(self.names)} parameters")
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
            raise InputError(f"information has shape {info.shape}, expected ({k}, {k})")
        if not np.all(np.isfinite(info)):
            raise InputError("information contains non-finite entries (did the trial's simulation diverge?)")
        w, v = np.linalg.eigh(self.cov)
        S = v * np.sqrt(np.clip(w, 0.0, None))
        inner = np.eye(k) + S.T @ (0.5 * (info + info.T)) @ S
        cov = S @ np.linalg.solve(inner, S.T)
        return ParameterBelief(self.names, Gaussian(self.gaussian.mean, 0.5 * (cov + cov.T)), self.source, self.kind)

    def __repr__(self) -> str:
        return f"ParameterBelief({len(self.names)} parameters: {', '.join(self.names)}; {self.source})"
