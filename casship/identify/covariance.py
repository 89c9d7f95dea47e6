"""Which covariance a Gaussian over parameters carries, and whether a matrix is one.

The kinds (:data:`COVARIANCE_KINDS`), the one rule that reads the kind of a covariance from a file older
than the ``kind`` field (:func:`kind_from_source`), the fit file's model-discrepancy reader
(:func:`discrepancy_of`) and the checks of a covariance matrix (symmetric within round-off,
positive semi-definite, naming the entry) used by :class:`~casship.identify.ParameterBelief`.
"""
from __future__ import annotations

from collections.abc import Mapping
from typing import Literal, get_args

import numpy as np

from ..errors import InputError
from ..gaussian import as_cov
from .fit_json import square_matrix

__all__ = ["CovarianceKind", "COVARIANCE_KINDS", "COVARIANCES", "kind_from_source", "checked_kind", "covariance_kind",
           "discrepancy_of", "Q_MAX_DEG2_PER_S", "SYMMETRY_TOL", "check_numbers", "checked_covariance", "free_block"]

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


def checked_kind(kind, what: str) -> str:
    """``kind`` when it is one of :data:`COVARIANCE_KINDS`, else an error naming ``what``.

    Parameters
    ----------
    kind : str
        The kind to check.
    what : str
        What carries it (for the message).
    """
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


def discrepancy_of(discrepancy, where: str, names, *, read) -> tuple[float, np.ndarray | None]:
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
    read : callable
        ``read(d, where, key=...)``: the reader of a covariance object
        (:meth:`~casship.identify.ParameterBelief.from_dict`).

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
        base = read(beside, where, key="model_discrepancy.estimated_with")
        if list(base.names) != list(names):
            raise InputError(f"{where}: model_discrepancy.estimated_with has parameters {list(base.names)}, "
                             f"param_covariance {list(names)}; they must be the same, in the same order")
    return float(np.radians(np.radians(q))), (None if base is None else base.covariance)


def check_numbers(value, shape: tuple, what: str) -> None:
    """Refuse a JSON value that is not a (nested) list of numbers of ``shape``, naming ``what``.

    Parameters
    ----------
    value : object
        The JSON value.
    shape : tuple of int
        The shape wanted.
    what : str
        The field (for the message).
    """
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


def checked_covariance(matrix, names, what: str) -> np.ndarray:
    """``matrix`` as a symmetric positive semi-definite covariance of ``names``, or ``ValueError``.

    An asymmetry within round-off (:data:`SYMMETRY_TOL`) is averaged away; beyond it the entry is named.

    Parameters
    ----------
    matrix : array_like
        The covariance.
    names : sequence of str
        The parameters, in its order.
    what : str
        The field (for the messages).
    """
    k = len(names)
    if matrix is None:
        raise InputError(f"ParameterBelief: {what} is null ({k} x {k} wanted for {list(names)})")
    a = square_matrix(matrix, names, f"ParameterBelief: {what}")
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
    # definiteness on the correlation matrix, naming the parameter (a test relative to the largest entry
    # passed an indefinite block of coefficients of size 1e-6 beside a time constant's variance of 100)
    return as_cov(0.5 * (a + a.T), k, f"ParameterBelief: {what}", list(names), allow_zero=True)


def free_block(fit, values: dict, *, robust: bool | None):
    """``(names, means, covariance, source, kind)``: the robust (``robust=None``: when the fit has a finite
    one) or model-based covariance of the fit's free model parameters (see
    :meth:`~casship.identify.ParameterBelief.from_fit`); None when no free quantity is a model parameter.

    Parameters
    ----------
    fit : FitResult or its file's fields
    values : dict
        The parameter values the fit applies (``fit.params``).
    robust : bool or None
        The robust covariance, the model-based one, or the robust one where finite.

    Returns
    -------
    tuple or None
    """
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
    return (tuple(names), [values[n] for n in names], 0.5 * (block + block.T), f"{how} of {len(names)} free parameter(s)",
            kind)
