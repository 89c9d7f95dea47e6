"""What the ship workflow (:func:`casship.identify.identify_ship`) reads from its records: the records
resampled for fitting, the approach resistance, and the run-level evidence of a problem (each record's,
or each block's, information and score) for the selection of the free set.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from .identifiability import RunEvidence

__all__ = ["resample", "approach_resistance", "run_evidence", "MEASURED", "MIN_UNITS", "MIN_RECORD_UNITS"]

MEASURED = ("psi", "r", "u", "v", "x", "y")
MIN_UNITS = 6           # a jackknife over fewer records uses blocks of them, this many in all
MIN_RECORD_UNITS = 4    # from this many records on, the records themselves are the units


def resample(record, dt: float, outputs: Sequence[str] = MEASURED, states: Sequence[str] = ("u", "v", "r", "x", "y",
             "psi"), inputs: Sequence[str] | None = None):
    """The record every ``dt`` seconds for fitting: inputs averaged over each interval (the zero-order
    hold of the full-rate signals), outputs and states sampled.

             Parameters
             ----------
             record : Dataset
             dt : float
                 The fitting step [s].
             outputs, states : sequence of str
                 Columns sampled (those the record holds).
             inputs : sequence of str, optional
                 Columns averaged over each interval (default: the record's inputs).

             Returns
             -------
             Dataset
             """
    from ..data import Dataset

    d = record
    step = max(1, int(round(dt / float(np.median(np.diff(d.t))))))
    idx = np.arange(0, len(d), step)
    cols = {}
    for name in (inputs if inputs is not None else ()):
        v = np.asarray(d[name], dtype=float)
        cols[name] = np.array([v[i:i + step].mean() for i in idx])
    for name in dict.fromkeys((*outputs, *states)):
        if name in d and name not in cols:
            cols[name] = np.asarray(d[name], dtype=float)[idx]
    return Dataset(d.t[idx], cols, {k: d.units.get(k, "") for k in cols}, d.meta)


def _approach(model, record) -> dict:
    from ..maneuvers import execute_time

    k = max(int(np.searchsorted(record.t, execute_time(record))), 3)
    return {"u": float(np.mean(record["u"][:k])), "n": float(np.mean(record["n"][:k]))}


def approach_resistance(model, record, params) -> float:
    """``R_0'`` that makes ``du/dt = 0`` at the record's approach speed and propeller rate (the surge
    equation is linear in it: evaluated at 0 and 1).

    Parameters
    ----------
    model : Model
    record : Dataset
        A record that starts with a straight approach (its first samples give the speed and rate).
    params : array_like or mapping
        The other parameters.

    Returns
    -------
    float
    """
    a = _approach(model, record)
    i = model.index("R_0_dash", "param")
    x, u = model.states(u=a["u"]), model.inputs(n=a["n"])
    rates = []
    for value in (0.0, 1.0):
        p = np.array(params, dtype=float)
        p[i] = value
        rates.append(float(np.asarray(model.f(x, u, p, np.zeros(model.nw)))[0, 0]))
    return rates[0] / (rates[0] - rates[1])


def run_evidence(problem, at: Mapping[str, float] | None = None, *, min_units: int = MIN_UNITS,
                 min_record_units: int = MIN_RECORD_UNITS) -> RunEvidence:
    """Each record's (or block's) information and gradient at ``at``, for run-level selection.

    With at least ``min_record_units`` records the records are the units; with fewer, each record is
    cut into ``ceil(min_units / n_records)`` contiguous blocks of equal length (their gradients from
    the per-sample scores, their information the record's in proportion to the measured samples).

                 Parameters
                 ----------
                 problem : IdentificationProblem
                 at : mapping name -> value, optional
                     The point (default: the problem's start).
                 min_units : int
                     Units (blocks) in all when the records are too few to be the units.
                 min_record_units : int
                     From this many records on, the records are the units.
                 """
    theta = problem.space.theta(at)
    _, _, _, details = problem.engine.derivatives(theta)
    k = len(theta)
    prior_grad = problem.prior_cost(theta)[1]
    labels, F, G = [], [], []
    blocks = 1 if len(details) >= min_record_units else int(math.ceil(min_units / len(details)))
    for r, d in enumerate(details):
        cols = np.asarray(d["cols"], dtype=int)
        measured = np.isfinite(d["residuals"]).any(axis=1).astype(float)
        cuts = np.array_split(np.arange(len(d["scores"])), blocks)
        for b, rows in enumerate(cuts):
            Fu, gu = np.zeros((k, k)), np.zeros(k)
            share = measured[rows].sum() / max(measured.sum(), 1.0)
            Fu[np.ix_(cols, cols)] = d["H"] * (share if blocks > 1 else 1.0)
            gu[cols] = d["scores"][rows].sum(axis=0)
            labels.append(f"record {r}" + (f" block {b + 1}/{blocks}" if blocks > 1 else ""))
            F.append(Fu)
            G.append(gu)
    return RunEvidence(labels, np.array(F), np.array(G), prior_grad, "records" if blocks == 1 else "blocks")
