"""Propulsion from the measured thrust, before the manoeuvring fit.

The published KVLCC2 constants need about 1.79 rps to hold 15.5 kn where the free-running tests ran
at 1.51-1.53 rps. Rather than trimming the resistance to hide that, the propeller model is fitted to
what HSVA measured: thrust (file column 10) and torque (column 11), with the shared open-water curve
of the propeller (``J, K_T, 10 K_Q``):

1. **Thrust coefficients** ``k_0, k_1, k_2``: the open-water ``K_T(J)`` of the model propeller
   (diameter ``D_OW``: 0.204 m at model scale, 9.32 m full scale) rewritten for the model's
   diameter ``D_p`` (the same thrust ``rho n^2 D^4 K_T(u_P / (n D))`` for any ``D``:
   ``K_T'(J) = (D_OW / D_p)^4 K_T(J D_p / D_OW)``), a quadratic by least squares over the curve.
2. **Wake** ``w_P0, C_1, C_2_plus, C_2_minus``: MAP fit of the model's thrust (exact Jacobians of
   :func:`casship.models.mmg.mmg_propeller` at the smoothed ``u, v, r`` and the measured rate) to the
   measured thrust of the training HSVA runs, weighted by the same rule as the manoeuvring fit
   (RMS error at the start times the square root of its autocorrelation time), the free set chosen
   by the prior-ratio rule of :meth:`casship.identify.Identifiability.propose` from the candidates' prior
   (the direction-switched ``C_2_plus``/``C_2_minus`` only when the thrust runs hold a mirror pair).
3. **Check with the torque**: ``Q = rho n^2 D_OW^5 K_Q(J_OW)`` at the fitted inflow, against the
   measured torque (the rudder inflow follows the fitted ``u_P`` and ``K_T``).

The thrust deduction ``t_P`` stays at the published value; the straight-run resistance ``R_0'`` is
a candidate of the manoeuvring fit like every other parameter (its start is the value that balances
the fitted thrust on the training runs' approaches, :func:`resistance_for_run`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import casadi as ca
import numpy as np

import casship as cs
from casship.identify.asymmetry import mirror_pairs
from casship.identify.identifiability import MAX_RATIO, Identifiability
from casship.identify.uncertainty import effective_samples
from casship.maneuvers import propeller_rate_for_speed
from casship.models.mmg import SMOOTH_WIDTH, mmg_propeller

from .data import Run, approach

__all__ = ["D_OW", "KT_NAMES", "WAKE_NAMES", "PropulsionFit", "open_water", "kt_for_diameter", "fit_propulsion",
           "resistance_for_run", "mismatch"]

D_OW = 0.204 * 45.7                      # m: the open-water propeller's diameter at full scale
KT_NAMES = ("k_0", "k_1", "k_2")
WAKE_NAMES = ("w_P0", "C_1", "C_2_plus", "C_2_minus")
WAKE_PRIOR_REL = {"w_P0": 0.2, "C_1": 0.3, "C_2_plus": 0.2, "C_2_minus": 0.2}


def open_water(folder: Path) -> np.ndarray:
    """The open-water curve ``(J, K_T, K_Q)`` rows (the file gives ``10 K_Q``)."""
    path = Path(folder) / "open_water_characteristics.csv"
    curve = np.loadtxt(path, delimiter=",", skiprows=1)
    return np.column_stack([curve[:, 0], curve[:, 1], curve[:, 2] / 10.0])


def kt_for_diameter(curve: np.ndarray, D_p: float, D_ow: float = D_OW) -> tuple[dict, float]:
    """``k_0, k_1, k_2`` of the curve rewritten for diameter ``D_p`` and the largest fit error in ``K_T``."""
    J = np.linspace(0.0, curve[-1, 0] * D_ow / D_p, 60)
    kt = (D_ow / D_p) ** 4 * np.interp(J * D_p / D_ow, curve[:, 0], curve[:, 1])
    coef = np.polyfit(J, kt, 2)
    return dict(zip(KT_NAMES, (float(coef[2]), float(coef[1]), float(coef[0])))), float(np.abs(np.polyval(coef, J) - kt).max())


def _thrust_function(model: cs.Model) -> ca.Function:
    P = {n: ca.SX.sym(n) for n in model.param_names}
    u, v, r, n = (ca.SX.sym(s) for s in ("u", "v", "r", "n"))
    smooth = SMOOTH_WIDTH if model.meta.get("options", {}).get("smooth") else None
    T, u_P, _ = mmg_propeller(P, u, v, r, n, smooth)
    p = ca.vertcat(*(P[k] for k in model.param_names))
    theta = ca.vertcat(*(P[k] for k in WAKE_NAMES))
    return ca.Function("thrust", [u, v, r, n, p], [T, ca.jacobian(T, theta), u_P], ["u", "v", "r", "n", "p"],
                       ["T", "dT", "u_P"])


@dataclass
class PropulsionFit:
    """The propeller model fitted to the measured thrust."""

    values: dict                     # k_0..k_2 and the chosen wake parameters
    std_errors: dict                 # of the chosen wake parameters (posterior) and of k (curve residual)
    free: list
    selection: list
    kt_fit_error: float
    thrust_error: dict               # run -> {"published_pct", "fit_pct"}: RMS thrust error relative to the mean
    torque_error: dict               # run -> RMS torque error [%] of the fitted inflow with the open-water K_Q
    sigma: float
    runs: list = field(default_factory=list)


def _call(fun, a, p):
    """Thrust, its Jacobian (N, 4) and the inflow at every row of ``a`` (one vectorised call)."""
    T, dT, u_P = fun(*(a[:, i][None, :] for i in range(4)), p)
    n = a.shape[0]
    return np.asarray(T).ravel(), np.asarray(dT).reshape(n, len(WAKE_NAMES)), np.asarray(u_P).ravel()


def _samples(runs, smoothed):
    rows = []
    for run in runs:
        s = smoothed[run.name]
        d = run.data
        rows.append(np.column_stack([s["u"], s["v"], s["r"], np.interp(s.t, d.t, d["n"]),
                                     np.interp(s.t, d.t, d["thrust"]), np.interp(s.t, d.t, d["torque"])]))
    return rows


def fit_propulsion(model: cs.Model, runs, smoothed: dict, curve: np.ndarray, *, max_iter: int = 30) -> PropulsionFit:
    """Fit ``k`` (open water) and the wake (measured thrust of ``runs``) as in the module text; without a
    run that measured the thrust, the published propeller is kept (an empty fit)."""
    runs = [r for r in runs if "thrust" in r.data]
    if not runs:                 # nothing measured the thrust: the published propeller stays
        return PropulsionFit({}, {}, [], [], math.nan, {}, {}, math.nan, [])
    k, kt_err = kt_for_diameter(curve, model.param_dict()["D_p"])
    fun = _thrust_function(model)
    data = _samples(runs, smoothed)
    nominal = model.param_dict()
    prior_std = np.array([WAKE_PRIOR_REL[n] * abs(nominal[n]) for n in WAKE_NAMES])
    mean = np.array([nominal[n] for n in WAKE_NAMES])

    def evaluate(theta):
        p = model.params({**k, **dict(zip(WAKE_NAMES, theta))})
        out = []
        for a in data:
            T, dT, _ = _call(fun, a, p)
            out.append((a[:, 4] - T, dT))
        return out

    at_start = evaluate(mean)
    neff = effective_samples([e[:, None] for e, _ in at_start], ["T"])["T"]["n_eff"]
    sigma = float(np.sqrt(sum(np.sum(e**2) for e, _ in at_start) / neff))
    info = sum(J.T @ J for _, J in at_start) / sigma**2
    idf = Identifiability(list(WAKE_NAMES), dict(zip(WAKE_NAMES, mean)), np.abs(mean), info, 1.0 / prior_std**2)
    pairs = mirror_pairs([r.data for r in runs], within=[r.facility for r in runs])
    cands = [n for n in WAKE_NAMES if pairs or n not in ("C_2_plus", "C_2_minus")]   # mirrored evidence only
    chosen, rows = idf.propose(max_ratio=MAX_RATIO, candidates=cands, keep=[], explain=True)
    idx = [WAKE_NAMES.index(n) for n in chosen]
    theta = mean.copy()
    for _ in range(max_iter):                          # Gauss-Newton on the MAP cost of the chosen ones
        res = evaluate(theta)
        g = sum(J[:, idx].T @ e for e, J in res) / sigma**2 - (theta[idx] - mean[idx]) / prior_std[idx] ** 2
        H = sum(J[:, idx].T @ J[:, idx] for _, J in res) / sigma**2 + np.diag(1.0 / prior_std[idx] ** 2)
        step = np.linalg.solve(H, g) if idx else np.zeros(0)
        theta[idx] += step
        if not idx or np.all(np.abs(step) < 1e-10 * np.maximum(np.abs(theta[idx]), 1e-6)):
            break
    res = evaluate(theta)
    H = sum(J[:, idx].T @ J[:, idx] for _, J in res) / sigma**2 + np.diag(1.0 / prior_std[idx] ** 2)
    se = np.sqrt(np.diag(np.linalg.inv(H))) if idx else np.zeros(0)
    values = {**k, **{n: float(theta[WAKE_NAMES.index(n)]) for n in chosen}}
    published = evaluate_published(model, fun, data)
    thrust_err, torque_err = {}, {}
    p_fit = model.params(values)
    for run, a, (e, _), e_pub in zip(runs, data, res, published):
        scale = float(np.mean(a[:, 4]))
        thrust_err[run.name] = {"published_pct": 100 * float(np.sqrt(np.mean(e_pub**2))) / scale,
                                "fit_pct": 100 * float(np.sqrt(np.mean(e**2))) / scale,
                                "mean_measured_N": scale}
        torque_err[run.name] = _torque_error(fun, a, p_fit, curve, model.param_dict()["rho"])
    return PropulsionFit(values, {n: float(s) for n, s in zip(chosen, se)}, chosen, rows, kt_err, thrust_err,
                         torque_err, sigma, [r.name for r in runs])


def evaluate_published(model, fun, data):
    """Thrust residuals of the published propeller model per run."""
    p = model.params()
    return [a[:, 4] - _call(fun, a, p)[0] for a in data]


def _torque_error(fun, a, p, curve, rho) -> float:
    u_P = _call(fun, a, p)[2]
    n = a[:, 3]
    J = u_P / (n * D_OW)
    Q = rho * n**2 * D_OW**5 * np.interp(J, curve[:, 0], curve[:, 2])
    return 100.0 * float(np.sqrt(np.mean((a[:, 5] - Q) ** 2)) / np.mean(a[:, 5]))


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


def mismatch(model: cs.Model, run: Run, p=None) -> dict:
    """Propeller rate the model needs for the run's approach speed vs the measured one, and the
    model's surge acceleration at the measured speed and rate (measured: ``u_dot_measured``)."""
    a = approach(run)
    base = model.params() if p is None else model.params(p)
    need = propeller_rate_for_speed(model, a["u"], base, guess=a["n"])
    return {"u0_mps": a["u"], "n_measured": a["n"], "n_needed": need, "n_error_pct": 100.0 * (need / a["n"] - 1),
            "u_dot_model": _surge_rate(model, base, a["u"], a["n"]), "u_dot_measured": a["u_dot"]}
