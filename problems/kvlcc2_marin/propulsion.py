"""Propulsion consistency: the measured propeller rate must hold the measured approach speed.

The published KVLCC2 constants need about 1.79 rps to hold 15.5 kn where the free-running tests ran
at 1.51-1.53 rps. The HSVA runs measured the thrust: about 4.1 MN (full scale), within 3 % of the
published propeller model's 4.0 MN at the approach, so the propeller (``w_P0``, ``K_T``) is kept and
the straight-run resistance ``R_0'`` is the term trimmed: in a straight run ``X(u0, n0) = 0`` is
linear in ``R_0'``, so each run's approach (mean ``u`` and ``n`` before the execute) gives the
``R_0'`` that holds it, and the training runs' mean is used (one value for both facilities: the
per-run values agree within 4 %). The residual mismatch of each run is reported as the propeller
rate the model needs to hold that run's approach speed against the measured rate, and the surge
acceleration the model has at the measured speed and rate.
"""
from __future__ import annotations

import numpy as np

import casship as cs
from casship.maneuvers import propeller_rate_for_speed

from .data import Run, approach

__all__ = ["resistance_for_run", "trim_resistance", "mismatch"]


def _surge_rate(model: cs.Model, p, u: float, n: float) -> float:
    x = model.states(u=u)
    return float(np.asarray(model.f(x, model.inputs(n=n), p, np.zeros(model.nw)))[0, 0])


def resistance_for_run(model: cs.Model, run: Run, p=None) -> float:
    """``R_0'`` that makes ``du/dt = 0`` at the run's approach speed and propeller rate."""
    base = model.params() if p is None else model.params(p)
    a = approach(run)
    i = model.index("R_0_dash", "param")
    lo, hi = base.copy(), base.copy()
    lo[i], hi[i] = 0.0, 1.0
    f0, f1 = _surge_rate(model, lo, a["u"], a["n"]), _surge_rate(model, hi, a["u"], a["n"])
    return f0 / (f0 - f1)


def trim_resistance(model: cs.Model, runs, p=None) -> tuple[float, dict]:
    """The mean ``R_0'`` over ``runs`` and each run's own value."""
    per = {r.name: resistance_for_run(model, r, p) for r in runs}
    return float(np.mean(list(per.values()))), per


def mismatch(model: cs.Model, run: Run, p=None) -> dict:
    """Propeller rate the model needs for the run's approach speed vs the measured one, and the
    model's surge acceleration at the measured speed and rate (measured: ``u_dot_measured``)."""
    a = approach(run)
    base = model.params() if p is None else model.params(p)
    need = propeller_rate_for_speed(model, a["u"], base, guess=a["n"])
    return {"u0_mps": a["u"], "n_measured": a["n"], "n_needed": need, "n_error_pct": 100.0 * (need / a["n"] - 1),
            "u_dot_model": _surge_rate(model, base, a["u"], a["n"]), "u_dot_measured": a["u_dot"]}
