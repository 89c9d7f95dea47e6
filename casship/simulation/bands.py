"""Prediction bands: the parameter uncertainty of a fit carried through a simulation.

A fit's parameters are uncertain (:class:`~casship.identify.ParameterBelief`: values and
covariance). Two routes carry that uncertainty into a replayed or simulated manoeuvre:

* **Exact sensitivities** (:func:`trajectory_sensitivities`): the forward sensitivities
  ``S_k = dx_k / dtheta`` of the discrete simulation, propagated step by step with CasADi's exact
  Jacobian-times-seed products (``S_{k+1} = F_x S_k + F_theta``). The linearised covariance of the
  states is ``S_k C S_k'``; :func:`prediction_bands` turns it into standard deviations of heading,
  position and the cross-track distance (the position spread normal to the simulated path).
* **Sampling** (:func:`sampled_metrics`): parameter vectors drawn from the Gaussian, each simulated
  and its manoeuvre indices computed (advance, transfer, tactical diameter, overshoots: functions
  of crossing times, not smooth in the parameters); their percentiles give the intervals of the
  indices, and the sampled heading spread checks the linearised band.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from scipy import stats

from .folds import sensitivity_fold
from ..runtime import Job, run_pieces
from ..model import Model
from ..errors import InputError

__all__ = ["trajectory_sensitivities", "prediction_bands", "sampled_metrics", "band_z"]

def band_z(level: float) -> float:
    """Half-width of a two-sided normal interval of probability ``level`` in standard deviations.

    Parameters
    ----------
    level : float
        Coverage probability in (0, 1).

    Returns
    -------
    float
    """
    if not 0.0 < float(level) < 1.0:
        raise InputError(f"level must be in (0, 1), got {level}")
    return float(stats.norm.ppf(0.5 + 0.5 * float(level)))


def trajectory_sensitivities(model: Model, x0, t, U, p, names, *, method: str = "rk4", max_step: float | None = None,
                             jit: bool | None = False):
    """States of a simulation and their exact sensitivities to some parameters.

    Parameters
    ----------
    model : Model
        A continuous-time model.
    x0 : array_like (nx,)
        Initial state (not a function of the parameters).
    t : array_like (N,)
        Time grid [s].
    U : array (N, nu)
        Inputs held over each interval.
    p : array_like (np,)
        Parameter vector.
    names : sequence of str
        The parameters ``theta`` to differentiate with respect to.
    method, max_step
        Discretisation as in :func:`casship.simulate` (the same sub-steps).
    jit : bool or None
        The sensitivity fold interpreted (``False``), compiled (``True``), or compiled from the cache,
        else in the background while it runs interpreted (``None``); shared per process by the
        model's structure (:func:`casship.simulation.folds.sensitivity_fold`). The same numbers either way.

    Returns
    -------
    X : (N, nx) array
        The states.
    S : (N, nx, k) array
        ``dX / dtheta`` (zero at the first sample).
    """
    from ..discretize import discretize

    t = np.asarray(t, dtype=float)
    dt = np.diff(t)
    substeps = 1 if max_step is None else max(1, int(np.ceil(dt.max(initial=0.0) / max_step)))
    key = ("discretize", method, substeps, ())
    dmodel = model.derived(key, lambda: discretize(model, float(dt[0]) if dt.size else 1.0, method=method,
                                                   substeps=substeps))
    idx = model.indices(list(names), "param")
    k = len(idx)
    E = np.zeros((model.np, k))
    E[idx, np.arange(k)] = 1.0
    p = np.asarray(p, dtype=float)
    steps = dt.size
    X, S = np.empty((steps + 1, model.nx)), np.zeros((steps + 1, model.nx, k))
    X[0] = np.asarray(x0, dtype=float).reshape(-1)
    if steps:
        # padded steps (dt = 0, no input) leave the state alone; the runtime's driver runs the pieces
        job = Job(sensitivity_fold(dmodel, k, jit=jit), {"x": X[0], "S": S[0]}, {"p": p, "E": E},
                  {"u": np.asarray(U, dtype=float)[:steps].T.reshape(model.nu, steps), "dt": dt[None, :]}, steps,
                  carry={"x": "xn", "S": "Sn"}, pad={"u": 0.0, "dt": 0.0})
        out = run_pieces([job], collect=("xn", "Sn"), record=False)[0]
        X[1:] = out["xn"][:, :, 0]
        S[1:] = out["Sn"]
    return X, S


def prediction_bands(model: Model, X: np.ndarray, S: np.ndarray, covariance: np.ndarray, level: float = 0.95) -> dict:
    """Linearised standard deviations of heading, position and cross-track distance.

    Parameters
    ----------
    model : Model
        A ship model with states ``x, y, psi`` (and ``u, v`` for the path direction).
    X, S : arrays
        From :func:`trajectory_sensitivities`.
    covariance : (k, k) array
        Covariance of the parameters ``S`` is taken with respect to.
    level : float
        Coverage of the bands (``z`` is stored with them).

    Returns
    -------
    dict
        ``psi_std`` [rad], ``x_std``, ``y_std``, ``cross_track_std`` [m] per sample, ``level``, ``z``.
    """
    C = np.asarray(covariance, dtype=float)
    out = {"level": float(level), "z": band_z(level)}
    cov = {}
    for name in ("psi", "x", "y"):
        if name in model.state_names:
            cov[name] = model.index(name)
    for name, i in cov.items():
        out[f"{name}_std"] = np.sqrt(np.clip(np.einsum("nk,kl,nl->n", S[:, i], C, S[:, i]), 0.0, None))
    if {"x", "y", "psi", "u", "v"} <= set(model.state_names):
        ix, iy = model.index("x"), model.index("y")
        course = X[:, model.index("psi")] + np.arctan2(X[:, model.index("v")], X[:, model.index("u")])
        normal = np.stack([-np.sin(course), np.cos(course)], axis=1)            # (N, 2): x North, y East
        Sn = normal[:, 0, None] * S[:, ix] + normal[:, 1, None] * S[:, iy]       # (N, k)
        out["cross_track_std"] = np.sqrt(np.clip(np.einsum("nk,kl,nl->n", Sn, C, Sn), 0.0, None))
        out["normal"] = normal
    return out


def sampled_metrics(run: Callable, draws: np.ndarray, level: float = 0.95, *, batch: bool = False) -> dict:
    """Intervals of manoeuvre indices (and the heading spread) from parameter draws.

    Parameters
    ----------
    run : callable
        ``run(p) -> (metrics, psi)``: the indices of one simulation with parameter vector ``p`` and
        its heading (or None); a draw whose simulation fails raises and is counted as failed. With
        ``batch=True``, ``run(draws)`` simulates all draws at once (e.g. through
        :func:`casship.simulate_many`) and returns one entry per draw: ``(metrics, psi)``, or the
        exception its simulation failed with (counted as failed).
    draws : (n, np) array
        Parameter vectors (e.g. :meth:`~casship.identify.ParameterBelief.sample`).
    level : float
        Coverage of the intervals (equal-tailed percentiles).
    batch : bool
        Whether ``run`` takes all draws at once.

    Returns
    -------
    dict
        ``intervals`` (index -> ``[lo, hi]``), ``psi_std`` (the sampled heading standard deviation per
        sample, or None), ``samples``, ``failed`` (draws whose simulation failed) and ``failures``
        (each distinct reason a draw failed, its first line, -> how many draws it stopped).
    """
    from ..angles import wrap

    failures = (ValueError, RuntimeError, FloatingPointError)
    if batch:
        outcomes = list(run(draws))
        if len(outcomes) != len(draws):
            raise InputError(f"sampled_metrics: run gave {len(outcomes)} outcome(s) for {len(draws)} draws")
    else:
        outcomes = []
        for p in draws:
            try:
                outcomes.append(run(p))
            except failures as exc:
                outcomes.append(exc)
    values, psis, failed, reasons = {}, [], 0, {}
    for outcome in outcomes:
        if isinstance(outcome, failures):
            failed += 1
            why = (str(outcome).strip().splitlines() or [type(outcome).__name__])[0]
            reasons[why] = reasons.get(why, 0) + 1
            continue
        metrics, psi = outcome
        for key, v in metrics.items():
            if isinstance(v, (int, float)) and np.isfinite(v):
                values.setdefault(key, []).append(float(v))
        if psi is not None:
            psis.append(np.asarray(psi, dtype=float))
    tail = 50.0 * (1.0 - float(level))
    intervals = {k: [float(np.percentile(v, tail)), float(np.percentile(v, 100.0 - tail))]
                 for k, v in values.items() if len(v) >= max(2, 0.5 * len(draws))}
    psi_std = None
    if len(psis) >= 2:
        P = np.array(psis)
        ref = P.mean(axis=0)
        psi_std = np.sqrt(np.mean(wrap(P - ref) ** 2, axis=0) * len(psis) / (len(psis) - 1))
    return {"intervals": intervals, "psi_std": psi_std, "samples": int(len(draws)), "failed": failed,
            "failures": reasons}
