"""What is known about a ship's parameters: a Gaussian over named parameters (:class:`ParameterBelief`).

One value serves as an identification prior (:meth:`ParameterBelief.to_prior`), as the uncertainty
a fit file carries (``read_fit_file(path).uncertainty``: replays and manoeuvre simulations draw
their prediction bands from it, with the file's model discrepancy beside it) and as the knowledge a
trial design starts from (:meth:`ParameterBelief.after` a trial). Its :attr:`~ParameterBelief.kind`
names which covariance it carries (:data:`COVARIANCE_KINDS`).

A leaf of :mod:`casship.identify`: it imports the fit file's JSON reader and the prior, never the fit
or the file reader that build beliefs.
"""
from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Literal, get_args

import numpy as np

from ..errors import InputError
from ..gaussian import Gaussian
from .fit_json import fit_fields, load_fit_json

__all__ = ["ParameterBelief", "ParameterUncertainty", "CovarianceKind", "COVARIANCE_KINDS", "COVARIANCES",
           "kind_from_source", "covariance_kind", "discrepancy_of", "SYMMETRY_TOL", "Q_MAX_DEG2_PER_S"]

#: The covariances of a fit file a belief can be built from (:meth:`ParameterBelief.from_fit`).
COVARIANCES = ("jackknife", "robust", "model")

#: Which covariance a Gaussian over parameters carries: a run-level calibration (``"calibrated"``,
#: e.g. a jackknife), the robust (sandwich) or the model-based covariance of a fit, a fit's standard
#: errors alone (independent), a prior stated by hand, or a covariance that says none of these.
CovarianceKind = Literal["calibrated", "robust", "model-based", "standard errors", "prior", "stated"]
COVARIANCE_KINDS: tuple = get_args(CovarianceKind)


def kind_from_source(source: str) -> CovarianceKind:
    """The kind of a covariance read from its prose ``source``: the rule for files older than the ``kind`` field.

    Files written since carry the kind itself (``ParameterBelief.kind``); only
    :meth:`ParameterBelief.from_dict` falls back to this rule, for a file without it.

    Parameters
    ----------
    source : str
        The covariance's stated source (e.g. ``"run-level jackknife over 16 folds"``).

    Returns
    -------
    str
        ``"calibrated"`` (a jackknife or another calibration over runs), ``"robust"`` (sandwich),
        ``"model-based"``, or ``"stated"`` (a source that says none of these).

    Examples
    --------
    >>> kind_from_source("run-level jackknife over 16 leave-one-run-out folds")
    'calibrated'
    >>> kind_from_source("robust (sandwich)")
    'robust'
    """
    text = str(source).lower()
    if "jackknife" in text or "calibrat" in text:
        return "calibrated"
    if "robust" in text or "sandwich" in text:
        return "robust"
    if "model-based" in text or "model based" in text:
        return "model-based"
    return "stated"


def _checked_kind(kind, what: str) -> str:
    """``kind`` when it is one of :data:`COVARIANCE_KINDS`, else an error naming ``what``."""
    if kind not in COVARIANCE_KINDS:
        raise InputError(f"{what}: unknown covariance kind {kind!r}; use one of {COVARIANCE_KINDS}")
    return str(kind)

#: Upper bound of a fit file's model discrepancy [deg^2/s]: beyond it the heading's 95 % band spans a
#: full turn (+-180 deg) within about 10 s, i.e. the file predicts nothing.
Q_MAX_DEG2_PER_S = 1e3




def covariance_kind(covariance) -> str:
    """The kind of a parameter covariance, for reports.

    Parameters
    ----------
    covariance : ParameterBelief or str
        A belief (its ``kind``, set where the covariance was made), or the prose ``source`` of a
        covariance from a file older than the ``kind`` field (read by :func:`kind_from_source`, the
        one rule for those).

    Returns
    -------
    str
        One of :data:`COVARIANCE_KINDS` (``"calibrated"``, ``"robust"``, ``"model-based"``,
        ``"standard errors"``, ``"prior"``, ``"stated"``).

    Examples
    --------
    >>> covariance_kind(ParameterBelief.from_values(["K"], [0.1], [[1e-4]], "by hand", kind="prior"))
    'prior'
    >>> covariance_kind("run-level jackknife over 16 leave-one-run-out folds")
    'calibrated'
    """
    if isinstance(covariance, str):
        return kind_from_source(covariance)
    return covariance.kind


def discrepancy_of(discrepancy, where: str, names) -> tuple[float, np.ndarray | None]:
    """A fit file's ``model_discrepancy`` object read: its heading variance rate and the covariance beside it.

    Parameters
    ----------
    discrepancy : mapping or None
        ``{"psi_variance_growth_deg2_per_s": q, "estimated_with": {...}}`` (``estimated_with``
        optional: the covariance of the same parameters ``q`` was estimated beside).
    where : str
        What holds it (for the messages).
    names : sequence of str
        The parameters of the file's ``param_covariance`` (``estimated_with`` must have the same).

    Returns
    -------
    (float, ndarray or None)
        ``q`` [rad^2/s] (0 when none is given) and the ``estimated_with`` covariance (None when absent).

    Raises
    ------
    casship.errors.InputError
        A discrepancy that is not an object, a rate outside ``[0, Q_MAX_DEG2_PER_S]`` deg^2/s, or an
        ``estimated_with`` covariance that is not valid or not of the same parameters.
    """
    if not discrepancy:
        return 0.0, None
    if not isinstance(discrepancy, Mapping):
        raise InputError(f"{where}: model_discrepancy must be an object, got {discrepancy!r:.60}")
    q = discrepancy.get("psi_variance_growth_deg2_per_s")
    if not isinstance(q, (int, float)) or isinstance(q, bool) or not np.isfinite(q) or not 0 <= q <= Q_MAX_DEG2_PER_S:
        raise InputError(f"{where}: model_discrepancy.psi_variance_growth_deg2_per_s must be a number in "
                         f"[0, {Q_MAX_DEG2_PER_S:g}] deg^2/s (beyond, the 95 % heading band spans a full turn within "
                         f"about 10 s), got {q!r}")
    beside = discrepancy.get("estimated_with")
    base = None
    if beside is not None:      # the covariance whose band q completes (same parameters, same order)
        base = ParameterBelief.from_dict(beside, where, key="model_discrepancy.estimated_with")
        if list(base.names) != list(names):
            raise InputError(f"{where}: model_discrepancy.estimated_with has parameters {list(base.names)}, "
                             f"param_covariance {list(names)}; they must be the same, in the same order")
    return float(np.radians(np.radians(q))), (None if base is None else base.covariance)


@dataclass(frozen=True)
class ParameterBelief:
    """A Gaussian belief ``N(mean, cov)`` over named model parameters.

    Parameters
    ----------
    names : sequence of str
        Model parameter names, in the order of the Gaussian's mean and covariance.
    gaussian : Gaussian
        Mean and covariance (natural units of the parameters).
    source : str
        Where the belief comes from (for reports; e.g. ``"run-level jackknife over 16 folds"``).
    kind : CovarianceKind
        Which covariance it is: ``"prior"``, ``"calibrated"``, ``"robust"``, ``"model-based"``,
        ``"standard errors"`` or ``"stated"`` (:data:`COVARIANCE_KINDS`; see :meth:`from_fit`), set
        where the covariance is made and written to a fit file beside ``source``.
    info : dict
        Further facts about the covariance (e.g. the number of folds of a jackknife).
    psi_variance_rate : float
        Model discrepancy: a heading variance growing linearly with the time since the start of a
        replay [rad^2/s], added to the parameter band's variance in the predictive band (0: none).
    discrepancy_covariance : (k, k) array, optional
        The covariance of the same parameters that ``psi_variance_rate`` was estimated beside (the
        predictive band adds ``q t`` to the band of this covariance, as in its estimation); None:
        :attr:`covariance`.

    Notes
    -----
    :attr:`mean` and :attr:`std` are dictionaries by name; :attr:`values` and :attr:`covariance`
    (alias :attr:`cov`) the arrays in the order of :attr:`names`.

    Examples
    --------
    >>> b = ParameterBelief.from_std({"K": 0.02, "T": 5.0}, mean={"K": 0.1, "T": 20.0})
    >>> b.std
    {'K': 0.02, 'T': 5.0}
    >>> u = ParameterBelief.from_values(["K", "T"], [0.1, 20.0], [[1e-4, 0.0], [0.0, 4.0]])
    >>> u.values, u.std
    (array([ 0.1, 20. ]), {'K': 0.01, 'T': 2.0})
    """

    names: tuple
    gaussian: Gaussian
    source: str = ""
    kind: CovarianceKind = "stated"
    info: dict = field(default_factory=dict)
    psi_variance_rate: float = 0.0
    discrepancy_covariance: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "kind", _checked_kind(self.kind, "ParameterBelief"))
        names = tuple(str(n) for n in self.names)
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise InputError(f"ParameterBelief: parameter name(s) {twice} given more than once")
        if not isinstance(self.gaussian, Gaussian):
            raise InputError(f"ParameterBelief: gaussian must be a casship.Gaussian, got {type(self.gaussian).__name__}")
        if len(names) != self.gaussian.mean.size:
            raise InputError(f"ParameterBelief: {len(names)} names for a Gaussian of size {self.gaussian.mean.size}")
        if not names:
            raise InputError("ParameterBelief: no parameters (nothing to learn from a trial)")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "source", str(self.source))
        object.__setattr__(self, "info", dict(self.info or {}))
        q = float(self.psi_variance_rate)
        q_max = float(np.radians(np.radians(Q_MAX_DEG2_PER_S)))
        if not (np.isfinite(q) and 0.0 <= q <= q_max):
            raise InputError(f"ParameterBelief: psi_variance_rate must be finite, >= 0 and <= {q_max:.4g} rad^2/s "
                             f"({Q_MAX_DEG2_PER_S:g} deg^2/s), got {q}")
        object.__setattr__(self, "psi_variance_rate", q)
        if self.discrepancy_covariance is not None:
            object.__setattr__(self, "discrepancy_covariance",
                               _checked_covariance(self.discrepancy_covariance, names, "discrepancy_covariance"))

    # -- construction ------------------------------------------------------------------------------
    @classmethod
    def from_values(cls, names, values, covariance, source: str = "", info: Mapping | None = None,
                    psi_variance_rate: float = 0.0, discrepancy_covariance=None,
                    kind: CovarianceKind = "stated") -> "ParameterBelief":
        """The belief of parameter values and their covariance matrix (checked, entries named).

        Parameters
        ----------
        names : sequence of str
            Model parameter names, in the order of ``covariance``.
        values : (k,) array_like
            Their values (the estimates).
        covariance : (k, k) array_like
            Covariance [units of the parameters squared]: symmetric (an asymmetry within round-off,
            :data:`SYMMETRY_TOL`, is averaged away) and positive semi-definite.
        source, info, psi_variance_rate, discrepancy_covariance, kind
            As for the class.

        Returns
        -------
        ParameterBelief

        Raises
        ------
        casship.errors.InputError
            A name given twice, values of another size, a covariance not finite, not symmetric
            (naming the entry) or not positive semi-definite.
        """
        names = [str(n) for n in names]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise InputError(f"ParameterBelief: parameter name(s) {twice} given more than once")
        values = np.asarray(values, dtype=float).reshape(-1)
        if values.size != len(names):
            raise InputError(f"ParameterBelief: {values.size} values for {len(names)} names")
        cov = _checked_covariance(covariance, names, "covariance")
        return cls(tuple(names), Gaussian(values, cov), source, kind, dict(info or {}), psi_variance_rate,
                   discrepancy_covariance)

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
        from .prior import Prior

        return Prior.from_belief(self, weight=weight, marginal=marginal)

    def to_uncertainty(self) -> "ParameterBelief":
        """Deprecated: a belief is the uncertainty (returns this belief itself).

        Returns
        -------
        ParameterBelief
        """
        warnings.warn("ParameterBelief.to_uncertainty() is deprecated: the belief is the uncertainty (use it as is)",
                      DeprecationWarning, stacklevel=2)
        return self

    @classmethod
    def from_uncertainty(cls, uncertainty, *, extra_std: Mapping[str, float] | None = None,
                         params: Mapping[str, float] | None = None, source: str | None = None) -> "ParameterBelief":
        """Deprecated: :meth:`described` (and :meth:`extended`) of a fit file's uncertainty.

        Parameters
        ----------
        uncertainty : ParameterBelief
            E.g. ``read_fit_file(path, model).uncertainty``.
        extra_std, params, source
            As for :meth:`from_fit`.

        Returns
        -------
        ParameterBelief
        """
        warnings.warn("ParameterBelief.from_uncertainty(u) is deprecated: a file's uncertainty is a ParameterBelief; "
                      "use u.described() (and .extended(std, mean) for further parameters)", DeprecationWarning,
                      stacklevel=2)
        return uncertainty.described(source)._with_extra(extra_std, params, source)

    def described(self, source: str | None = None) -> "ParameterBelief":
        """This belief with a source for reports: by default its kind, its own source and its size.

        Parameters
        ----------
        source : str, optional
            The description (default ``"<kind> covariance (<source>) of <k> parameter(s)"``).

        Returns
        -------
        ParameterBelief
        """
        text = source or (f"{self.kind} covariance ({self.source or 'source not stated'}) of "
                          f"{len(self.names)} parameter(s)")
        return dataclasses.replace(self, source=text)

    @classmethod
    def from_fit(cls, fit, *, covariance: str | None = None, extra_std: Mapping[str, float] | None = None,
                 params: Mapping[str, float] | None = None, source: str | None = None) -> "ParameterBelief":
        """The belief a fit leaves: the covariance its file carries, or its robust or model-based one.

        A fit file carries the uncertainty a new run is replayed with (``param_covariance``): a
        calibrated one when the fit was calibrated (the kvlcc2-marin study's run-level jackknife),
        else the robust (sandwich) covariance of its shared free model parameters. By default that
        one is taken, with the file's model discrepancy (``psi_variance_rate``, and the covariance
        it was estimated beside); ``covariance`` asks for a kind and refuses a file that lacks it.

        For the robust and model-based covariances of the fit itself, free quantities that are not
        model parameters (initial states, biases, noise variances) and per-record or per-group copies
        other than the one the fit's ``params`` apply (the copy whose estimate equals
        ``fit.params[name]``) are marginalised out: the belief keeps the block of the copies that
        describe the ship of ``fit.params``. A model-based covariance that is not finite falls back
        to the standard errors (independent). These carry the file's discrepancy rate alone.

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
        where = "the fit"
        if isinstance(fit, (str, os.PathLike)):
            where = Path(fit).name
            fit = _fit_of_file(fit)
        if covariance not in (None, *COVARIANCES):
            raise InputError(f"unknown covariance {covariance!r}; use one of {COVARIANCES} (or None: the file's own)")
        values = dict(params or fit.params)
        carried = cls.from_dict(fit.param_covariance, where) if fit.param_covariance else None
        kind = carried.kind if carried is not None else None
        wanted = {None: kind, "jackknife": "calibrated", "robust": "robust", "model": "model-based"}[covariance]
        discrepancy = getattr(fit, "model_discrepancy", None) or {}
        if carried is not None and kind == wanted:
            bad = [n for n, v in zip(carried.names, carried.values)
                   if not np.isclose(v, values.get(n, np.nan), rtol=1e-12, atol=0.0)]
            if bad:
                raise InputError(f"{where}: the values of {bad} in its covariance differ from its parameters")
            q, beside = discrepancy_of(discrepancy, where, carried.names)
            belief = dataclasses.replace(carried.described(), psi_variance_rate=q, discrepancy_covariance=beside)
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
            q = float(np.radians(np.radians(discrepancy.get("psi_variance_growth_deg2_per_s", 0.0) or 0.0)))
            belief = dataclasses.replace(belief, psi_variance_rate=q)
        belief = dataclasses.replace(belief, source=f"{where}: {belief.source}")
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
            Same :attr:`kind` and model discrepancy as this one (a discrepancy covariance extended
            by the same independent block).
        """
        return self._with_extra(std, mean, source)

    def _with_extra(self, extra_std, values, source, clash: str = "the belief covers") -> "ParameterBelief":
        extra = dict(extra_std or {})
        if not extra:
            return self if source is None else dataclasses.replace(self, source=source)
        both = sorted(set(extra) & set(self.names))
        if both:
            raise InputError(f"extra_std given for {both}, which {clash} (their covariance comes from it)")
        if values is None:
            raise InputError("extra_std needs the parameters' values (params)")
        e = ParameterBelief.from_std(extra, values)

        def grown(cov):
            k, n = len(self.names), len(self.names) + len(e.names)
            big = np.zeros((n, n))
            big[:k, :k], big[k:, k:] = cov, e.cov
            return big
        text = source or f"{self.source}, and the prior std of {len(e.names)} more"
        beside = None if self.discrepancy_covariance is None else grown(self.discrepancy_covariance)
        return dataclasses.replace(self, names=self.names + e.names,
                                   gaussian=Gaussian(np.r_[self.gaussian.mean, e.gaussian.mean], grown(self.cov)),
                                   source=text, discrepancy_covariance=beside)

    # -- queries -----------------------------------------------------------------------------------
    @property
    def mean(self) -> dict:
        """Mean value of each parameter, by name."""
        return dict(zip(self.names, self.gaussian.mean.tolist()))

    @property
    def std(self) -> dict:
        """Standard deviation of each parameter, by name."""
        return dict(zip(self.names, self.gaussian.std.tolist()))

    @property
    def values(self) -> np.ndarray:
        """The means as an array (ordered like :attr:`names`)."""
        return self.gaussian.mean

    @property
    def cov(self) -> np.ndarray:
        """Covariance matrix (ordered like :attr:`names`)."""
        return self.gaussian.cov

    @property
    def covariance(self) -> np.ndarray:
        """Covariance matrix (ordered like :attr:`names`; the same array as :attr:`cov`)."""
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
        return dataclasses.replace(self, gaussian=Gaussian(self.gaussian.mean, 0.5 * (cov + cov.T)))

    def sample(self, model, p, n: int, seed=0) -> np.ndarray:
        """``n`` parameter vectors of ``model``: ``p`` with these parameters drawn from the Gaussian.

        Parameters
        ----------
        model : Model
        p : array_like
            The full parameter vector (the other parameters keep these values).
        n : int
            Number of draws.
        seed : int or numpy.random.Generator

        Returns
        -------
        (n, np) array
        """
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        idx = model.indices(list(self.names), "param")
        w, V = np.linalg.eigh(self.covariance)
        L = V * np.sqrt(np.clip(w, 0.0, None))
        draws = self.values + rng.standard_normal((int(n), len(self.names))) @ L.T
        out = np.tile(np.asarray(p, dtype=float), (int(n), 1))
        out[:, idx] = draws
        return out

    # -- file form ---------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """JSON-friendly form (``names``, ``values``, ``matrix``, ``source``, ``kind``, ``info``): a fit
        file's ``param_covariance`` (the model discrepancy is the file's own ``model_discrepancy``)."""
        return {"names": list(self.names), "values": self.values.tolist(), "matrix": self.covariance.tolist(),
                "source": self.source, "kind": self.kind, "info": dict(self.info)}

    @classmethod
    def from_dict(cls, d, where: str = "the file", *, key: str = "param_covariance") -> "ParameterBelief":
        """Read the form of :meth:`to_dict`.

        Parameters
        ----------
        d : mapping
            With ``names``, ``values``, ``matrix`` (and optionally ``source``, ``kind``, ``info``); a
            file without ``kind`` (older than the field) gets the kind its ``source`` states
            (:func:`kind_from_source`).
        where : str
            What holds it (for the messages).
        key : str
            The field of the file that holds it (for the messages).

        Returns
        -------
        ParameterBelief

        Raises
        ------
        ValueError
            Naming the field: missing or null names, values or matrix, a shape other than the names',
            a name given twice, a matrix not symmetric beyond round-off (naming the entry) or not
            positive semi-definite.
        """
        field_ = f"{where}: {key}"
        if not isinstance(d, Mapping):
            raise InputError(f"{field_}: expected an object with names, values and matrix, got {type(d).__name__}")
        missing = [k for k in ("names", "matrix") if k not in d]
        if missing:
            raise InputError(f"{field_} lacks {missing}")
        names = d["names"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise InputError(f"{field_}.names: expected a list of parameter names, got {names!r}")
        values = d.get("values")
        if values is None:
            raise InputError(f"{field_} lacks the values of {names}")
        _numbers(values, (len(names),), f"{field_}.values")
        _numbers(d["matrix"], (len(names), len(names)), f"{field_}.matrix")
        source = str(d.get("source", ""))
        kind = _checked_kind(d["kind"], f"{field_}.kind") if "kind" in d else kind_from_source(source)
        try:
            return ParameterBelief.from_values(names, values, d["matrix"], source, dict(d.get("info") or {}), kind=kind)
        except ValueError as exc:
            msg = str(exc).removeprefix("ParameterBelief: ")
            raise InputError(f"{field_}.matrix {msg.removeprefix('covariance ')}" if msg.startswith("covariance ")
                             else f"{field_}: {msg}") from None

    def __repr__(self) -> str:
        return f"ParameterBelief({len(self.names)} parameters: {', '.join(self.names)}; {self.source})"


class ParameterUncertainty(ParameterBelief):
    """Deprecated name (casship 0.3) of a :class:`ParameterBelief` made from values and a covariance.

    ``ParameterUncertainty(names, values, covariance, source, info, psi_variance_rate,
    discrepancy_covariance, kind)`` warns (:class:`DeprecationWarning`) and returns
    ``ParameterBelief.from_values(...)`` -- a :class:`ParameterBelief`, whose :attr:`~ParameterBelief.std`
    is a dictionary by name (0.3 gave an array: ``np.sqrt(np.diag(u.covariance))``).
    ``ParameterUncertainty.from_dict`` is :meth:`ParameterBelief.from_dict`.
    """

    def __new__(cls, names, values, covariance, source: str = "", info: Mapping | None = None,
                psi_variance_rate: float = 0.0, discrepancy_covariance=None, kind: CovarianceKind = "stated"):
        warnings.warn("ParameterUncertainty is deprecated: use ParameterBelief.from_values(names, values, covariance, "
                      "...) (note: its .std is a dict by name)", DeprecationWarning, stacklevel=2)
        return ParameterBelief.from_values(names, values, covariance, source, info, psi_variance_rate,
                                           discrepancy_covariance, kind)


def _fit_of_file(path) -> SimpleNamespace:
    """The fields of a fit file (those :meth:`ParameterBelief.from_fit` reads) as attributes.

    A view, not a :class:`~casship.identify.FitResult`: the fit builds its uncertainty as a belief, so
    the belief reads the file through the JSON reader both share.
    """
    path = Path(path)
    try:
        fields = fit_fields(load_fit_json(path))
    except ValueError as exc:
        text = str(exc)
        raise InputError(text if text.startswith(str(path)) else f"{path}: {text}") from None
    return SimpleNamespace(**{"covariance_robust": None, "param_covariance": {}, "model_discrepancy": {}, **fields})


def _numbers(value, shape: tuple, what: str) -> None:
    """Refuse a JSON value that is not a (nested) list of numbers of ``shape``, naming ``what``."""
    if value is None:
        raise InputError(f"{what} is null; a fit file carries a {' x '.join(map(str, shape))} list of numbers there")
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a {' x '.join(map(str, shape))} list of numbers, got {value!r:.80}") from None
    if a.shape != shape:
        raise InputError(f"{what}: shape {a.shape}, {' x '.join(map(str, shape))} wanted")


#: Relative asymmetry of a covariance entry tolerated as round-off (``|a_ij - a_ji| / sqrt(a_ii a_jj)``).
SYMMETRY_TOL = 1e-8


def _checked_covariance(matrix, names, what: str) -> np.ndarray:
    """``matrix`` as a symmetric positive semi-definite covariance of ``names``, or ``ValueError``.

    An asymmetry within round-off (:data:`SYMMETRY_TOL`) is averaged away; beyond it the entry is named.
    """
    k = len(names)
    if matrix is None:
        raise InputError(f"ParameterBelief: {what} is null ({k} x {k} wanted for {list(names)})")
    try:
        a = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"ParameterBelief: {what} is not a matrix of numbers") from None
    if a.size != k * k:
        raise InputError(f"ParameterBelief: {what} has {a.size} entries, {k} x {k} wanted for {list(names)}")
    a = a.reshape(k, k)
    if not np.all(np.isfinite(a)):
        bad = [n for n, d in zip(names, np.diag(a)) if not np.isfinite(d)]
        raise InputError(f"ParameterBelief: {what} not finite for {bad or list(names)}")
    scale = np.sqrt(np.abs(np.outer(np.diag(a), np.diag(a))))
    gap = np.abs(a - a.T)
    bad = gap > SYMMETRY_TOL * np.maximum(scale, np.abs(a).max(initial=0.0) * 1e-12) + 1e-300
    if bad.any():
        i, j = (int(x) for x in np.argwhere(np.triu(bad, 1))[0])
        raise InputError(f"ParameterBelief: {what} is not symmetric: entry ({names[i]}, {names[j]}) = {a[i, j]:.6g} "
                         f"but ({names[j]}, {names[i]}) = {a[j, i]:.6g} (beyond round-off)")
    a = 0.5 * (a + a.T)
    if np.linalg.eigvalsh(a).min(initial=0.0) < -1e-9 * max(1.0, np.abs(a).max()):
        raise InputError(f"ParameterBelief: {what} is not positive semi-definite")
    return a


