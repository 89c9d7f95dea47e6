"""Time gaps in a record: longer than the prediction can bridge in one step, they raise or are bridged.

A fixed-step discretisation (``euler``, ``rk4``) predicts over a sample interval in
``dmodel.substeps`` steps; over a gap longer than its stability limit the prediction explodes
(states of 1e29 from a 1e4 s gap). The limit is the option ``max_gap`` [s] when given, else the
stability limit of the discretisation at the start (:func:`casship.validity.stable_step` times the
sub-steps; no limit for adaptive or exact discretisations). A longer gap raises ``ValueError``
naming it (``on_gap="raise"``, the default) or, with ``on_gap="bridge"``, is bridged by
prediction-only steps no longer than half the limit (at the limit itself a fixed-step prediction
no longer damps the mode; at half of it rk4 damps it by 0.29 per step), the covariance propagated over
the gap with the process noise, with a warning; in a batch run the bridging rows appear in the result.
"""
from __future__ import annotations

import warnings

import numpy as np

from ..data import Dataset
from ..validity import is_stable_step, stable_step

__all__ = ["gap_limit", "bridge_gaps", "bridge_pieces", "online_pieces"]


def bridge_pieces(gap: float, limit: float) -> int:
    """Number of equal prediction steps that bridge ``gap`` [s], each at most half of ``limit``.

    Parameters
    ----------
    gap, limit : float
        The interval and the one-step limit [s].

    Returns
    -------
    int
    """
    return int(np.ceil(gap / (0.5 * limit)))


def gap_limit(est, x, u, p=None) -> float:
    """Longest sample interval [s] the estimator predicts over in one step.

    Parameters
    ----------
    est : Estimator
        The estimator (its options ``max_gap`` and its discretisation).
    x, u : array_like
        State and input of the linearisation (e.g. the prior mean and the first input).
    p : array_like, optional
        Parameters (nominal by default).

    Returns
    -------
    float
        ``options.max_gap`` if given, else the stability limit of a fixed-step discretisation
        (``inf`` for others).
    """
    if est.options.max_gap is not None:
        return float(est.options.max_gap)
    dm, m = est.dmodel, est.model
    pv = m.params() if p is None else m.params(p)
    return stable_step(m, np.asarray(x, dtype=float), np.asarray(u, dtype=float), pv, dm.method) \
        * getattr(dm, "substeps", 1)


def _within_limit(est, x, u, p, dt: float) -> bool:
    """Whether one prediction over ``dt`` [s] stays within :func:`gap_limit` (one stability test)."""
    if est.options.max_gap is not None:
        return dt <= est.options.max_gap
    m, dm = est.model, est.dmodel
    pv = m.params() if p is None else m.params(p)
    return is_stable_step(m, np.asarray(x, dtype=float), np.asarray(u, dtype=float), pv, dm.method,
                          dt / getattr(dm, "substeps", 1))


def _message(est, where: str, gap: float, limit: float) -> str:
    return (f"{est.name}: time gap of {gap:.4g} s {where} is longer than {limit:.4g} s, the longest interval the "
            f"{est.dmodel.method} prediction bridges in one step (option max_gap; the stability limit by default); "
            "pass options={'on_gap': 'bridge'} to bridge it with prediction-only steps, or split the record")


def bridge_gaps(est, data: Dataset, x, p=None) -> Dataset:
    """``data`` unchanged, or with prediction-only rows inside gaps longer than :func:`gap_limit`.

    Parameters
    ----------
    est : Estimator
        The estimator (options ``max_gap``, ``on_gap``).
    data : Dataset
        The record.
    x : array_like
        State of the linearisation (the prior mean).
    p : array_like or mapping, optional
        Parameters (nominal by default).

    Returns
    -------
    Dataset

    Raises
    ------
    ValueError
        A gap longer than the limit with ``on_gap="raise"``.

    Warns
    -----
    UserWarning
        When gaps are bridged (how many rows were inserted, and where).
    """
    m = est.model
    if len(data) < 2:
        return data
    missing = [n for n in m.input_names if n not in data]
    if missing:
        return data                                # prepare() names the missing columns
    U = data.matrix(m.input_names)
    u0 = U[0] if m.nu else np.zeros(0)
    if _within_limit(est, x, u0, p, float(data.dt.max())):
        return data                                # the usual case, without searching for the limit
    limit = gap_limit(est, x, u0, p)
    long = np.flatnonzero(data.dt > limit)
    if long.size == 0:
        return data
    k = int(long[0])
    where = f"between t = {data.t[k]:g} and {data.t[k + 1]:g} s (rows {k} and {k + 1})"
    if est.options.on_gap == "raise":
        raise ValueError(_message(est, where, float(data.dt[k]), limit))
    inserted = []
    for k in long:
        pieces = bridge_pieces(float(data.dt[k]), limit)
        inserted.append(data.t[k] + np.arange(1, pieces) * (data.dt[k] / pieces))
    t_new = np.concatenate(inserted)
    warnings.warn(f"{est.name}: {long.size} time gap(s) longer than {limit:.4g} s (the first {where}) bridged "
                  f"by {t_new.size} prediction-only row(s); the result has {len(data) + t_new.size} rows",
                  UserWarning, stacklevel=3)
    bridged = data.with_rows(t_new, hold=m.input_names)
    bridged.meta["bridged_rows"] = int(t_new.size)
    return bridged


def online_pieces(est, dt: float, x, u, p, where: str) -> int:
    """Number of equal steps an online update over ``dt`` [s] takes: 1 within :func:`gap_limit`, else
    raise (``on_gap="raise"``) or bridge (``"bridge"``: more steps, with a warning).

    Online runners call this only for an interval longer than the limit they found at the start,
    so the stability limit is searched for only then.

    Parameters
    ----------
    est : Estimator
        The estimator (options ``max_gap``, ``on_gap``).
    dt : float
        The interval before the update [s].
    x, u : array_like
        Current state and the input held over the interval.
    p : array_like or mapping, optional
        Parameters (nominal by default).
    where : str
        Where the gap is (for the messages).

    Returns
    -------
    int
    """
    limit = gap_limit(est, x, u, p)
    if dt <= limit:
        return 1
    if est.options.on_gap == "raise":
        raise ValueError(_message(est, where, float(dt), limit))
    pieces = bridge_pieces(float(dt), limit)
    warnings.warn(f"{est.name}: time gap of {dt:.4g} s {where} bridged by {pieces - 1} prediction-only "
                  f"step(s) of {dt / pieces:.4g} s", UserWarning, stacklevel=4)
    return pieces
