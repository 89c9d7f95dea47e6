"""Time gaps in a record: checked at the state where they happen, then refused or bridged.

A fixed-step discretisation (``euler``, ``rk4``) predicts over a sample interval in
``dmodel.substeps`` steps; over a gap longer than its stability limit the prediction explodes
(states of 1e29 from a 1e4 s gap). That limit depends on the state: a ship at rest has none, the
same ship at full speed a few seconds. So a gap is checked **at the state where it happens** (the
estimate at the sample before it, with the input held over it), online as in batch:

* an interval up to :func:`gap_threshold` is one of the record's own steps: ``max_gap`` [s] when
  given (then every longer interval is a gap, whatever the state), else 1.5 times the nominal step
  ``dmodel.dt``. Discretisations without a step limit (adaptive, exact, discrete-time) have no gaps;
* a longer interval is tested against the stability limit at the estimate before it
  (:func:`casship.simulation.validity.is_stable_step`); where the model's Jacobian is not finite there, the
  gap cannot be checked and is refused;
* a gap beyond the limit raises ``ValueError`` naming it (``on_gap="raise"``, the default) or, with
  ``on_gap="bridge"``, is bridged by prediction-only steps no longer than half the limit (at the limit
  itself a fixed-step prediction no longer damps the mode; at half of it rk4 damps it by 0.29 per
  step), the covariance propagated over the gap with the process noise, with a warning; in a batch
  run the bridging rows appear in the result.

In a batch run the estimates before a gap come from a run over the record; a bridged gap changes
what follows it, so the record is run again from there on until every gap has passed (one run more
per bridged gap, none for a record without gaps).
"""
from __future__ import annotations

import warnings

import numpy as np

from ..data import Dataset
from ..errors import InputError
from ..simulation import decaying_modes, is_stable_step, stable_step

__all__ = ["gap_threshold", "gap_limit", "gap_pieces", "checked_run", "bridge_gaps", "bridge_pieces", "GAP_FACTOR"]

#: Intervals up to this many nominal steps are the record's own steps (not checked per state).
GAP_FACTOR = 1.5


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


def gap_threshold(est) -> float:
    """Longest interval [s] taken as one of the record's own steps, without a check at the state.

    Parameters
    ----------
    est : Estimator

    Returns
    -------
    float
        ``options.max_gap`` if given; else ``GAP_FACTOR`` times the nominal step for a fixed-step
        discretisation; ``inf`` for discretisations without a step limit.
    """
    if est.options.max_gap is not None:
        return float(est.options.max_gap)
    dm = est.dmodel
    if dm.method not in ("euler", "rk4"):
        return np.inf
    return GAP_FACTOR * float(dm.dt)


def gap_limit(est, x, u, p=None) -> float:
    """Longest sample interval [s] the estimator predicts over in one step from the state ``x``.

    Parameters
    ----------
    est : Estimator
        The estimator (its option ``max_gap`` and its discretisation).
    x, u : array_like
        State and input of the linearisation (the estimate before the gap, the input held over it).
    p : array_like or mapping, optional
        Parameters (nominal by default).

    Returns
    -------
    float
        ``options.max_gap`` if given, else the stability limit of a fixed-step discretisation at
        ``x`` (``inf`` for others).

    Raises
    ------
    InputError
        When the model's Jacobian is not finite at ``x`` (no limit can be found there).
    """
    if est.options.max_gap is not None:
        return float(est.options.max_gap)
    dm, m = est.dmodel, est.model
    pv = m.params() if p is None else m.params(p)
    x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
    if dm.method in ("euler", "rk4") and decaying_modes(m, x, u, pv) is None:
        raise InputError(f"{est.name}: the model {m.name!r} is not finite at the estimate "
                         f"({', '.join(f'{n} = {v:.4g}' for n, v in zip(m.state_names, x))}), so no time gap can be "
                         "checked there")
    return stable_step(m, x, u, pv, dm.method) * getattr(dm, "substeps", 1)


def _message(est, where: str, gap: float, limit: float) -> str:
    return (f"{est.name}: time gap of {gap:.4g} s {where} is longer than {limit:.4g} s, the longest interval the "
            f"{est.dmodel.method} prediction bridges in one step from the estimate there (option max_gap; the "
            "stability limit at that state by default); pass options={'on_gap': 'bridge'} to bridge it with "
            "prediction-only steps, or split the record")


def gap_pieces(est, x, u, p, dt: float, where: str) -> int:
    """How many prediction steps the interval ``dt`` needs from the state ``x``: 1 when one step is stable.

    Parameters
    ----------
    est : Estimator
    x, u : array_like
        The estimate before the interval and the input held over it.
    p : array_like or mapping, optional
        Parameters.
    dt : float
        The interval [s].
    where : str
        Where the interval is, for messages (e.g. ``"before update 12"``).

    Returns
    -------
    int
        1, or the number of steps that bridge it (``on_gap="bridge"``).

    Raises
    ------
    ValueError
        A gap beyond the limit with ``on_gap="raise"``, or a state where no limit can be found.
    """
    if dt <= gap_threshold(est):
        return 1
    m, dm = est.model, est.dmodel
    if est.options.max_gap is None:
        pv = m.params() if p is None else m.params(p)
        x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
        if is_stable_step(m, x, u, pv, dm.method, dt / getattr(dm, "substeps", 1)) \
                and decaying_modes(m, x, u, pv) is not None:
            return 1
    limit = gap_limit(est, x, u, p)
    if est.options.on_gap == "raise":
        raise InputError(_message(est, where, float(dt), limit))
    return bridge_pieces(float(dt), limit)


def _candidates(est, data: Dataset) -> np.ndarray:
    """Rows ``k`` whose interval to row ``k + 1`` is longer than :func:`gap_threshold`."""
    if len(data) < 2:
        return np.zeros(0, dtype=int)
    return np.flatnonzero(data.dt > gap_threshold(est))


def checked_run(est, data: Dataset, run, p=None):
    """``run(data)`` with every gap checked at the estimate before it (see the module notes).

    Parameters
    ----------
    est : Estimator
    data : Dataset
        The record.
    run : callable
        ``run(data) -> FilterResult``: the estimator's plain run over a record.
    p : array_like or mapping, optional
        Parameters.

    Returns
    -------
    (Dataset, FilterResult)
        The record (with bridging rows where gaps were bridged) and the run over it.

    Raises
    ------
    ValueError
        A gap beyond the limit with ``on_gap="raise"``.

    Warns
    -----
    UserWarning
        Once, when gaps were bridged (how many rows were inserted, and where the first gap is).
    """
    m = est.model
    inserted, first, gaps = 0, None, set()
    original = data.t
    while True:
        result = run(data)
        candidates = _candidates(est, data)
        U = data.matrix(m.input_names) if m.nu and candidates.size else np.zeros((len(data), 0))
        for k in candidates:
            where = f"between t = {data.t[k]:g} and {data.t[k + 1]:g} s (rows {k} and {k + 1})"
            pieces = gap_pieces(est, result.x[k], U[k], p, float(data.dt[k]), where)
            if pieces > 1:
                t_new = data.t[k] + np.arange(1, pieces) * (data.dt[k] / pieces)
                first = first or where
                inserted += t_new.size
                gaps.add(int(np.searchsorted(original, data.t[k], side="right")))
                data = data.with_rows(t_new, hold=m.input_names)
                break
        else:
            break
    if inserted:
        warnings.warn(f"{est.name}: {len(gaps)} time gap(s) longer than the prediction bridges in one step (the first "
                      f"{first}) bridged by {inserted} prediction-only row(s); the result has {len(data)} rows",
                      UserWarning, stacklevel=3)
        data.meta["bridged_rows"] = inserted
    return data, result


def bridge_gaps(est, data: Dataset, prior, p=None, *, through=None) -> Dataset:
    """``data`` unchanged, or with prediction-only rows inside the gaps that need them.

    Each gap is checked at the estimate before it, from a run of ``est`` (or ``through``) over the
    record started at ``prior`` (none when the record has no interval longer than
    :func:`gap_threshold`).

    Parameters
    ----------
    est : Estimator
        The estimator whose options (``max_gap``, ``on_gap``) and name apply.
    data : Dataset
        The record.
    prior : Gaussian
        The start of the run.
    p : array_like or mapping, optional
        Parameters (nominal by default).
    through : StepEstimator, optional
        The recursive filter whose estimates locate the state before each gap (default ``est``;
        the MHE checks its gaps through its arrival EKF, a full MHE pass per gap being the cost
        otherwise).

    Returns
    -------
    Dataset

    Raises
    ------
    ValueError
        A gap longer than the limit with ``on_gap="raise"``.
    """
    missing = [n for n in est.model.input_names if n not in data]
    if missing or not _candidates(est, data).size:
        return data                                 # prepare() names missing columns
    runner = est if through is None else through
    return checked_run(est, data, lambda d: runner._run(d, prior, p, None), p)[0]
