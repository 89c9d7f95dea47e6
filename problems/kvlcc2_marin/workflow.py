"""The identification workflow of the study, applied to a set of training runs.

1. **Propulsion** (:mod:`.propulsion`): ``R_0'`` from the training runs' straight approaches.
2. **Smooth** every run (EKF + RTS, :func:`casship.identify.smooth_trial`) into ``u, v, r`` and their
   rates. HSVA: positions, heading and yaw rate (the files' surge column disagrees with the positions
   by up to 4 % in the larger zig-zags, so the surge speed of the smoothed positions replaces it);
   MARIN: positions, heading, surge speed and yaw rate.
3. **Inverse dynamics** (:func:`casship.identify.inverse_dynamics`): the hull derivatives, the rudder
   lift gradient and the propeller-induced side force and yaw moment (the coefficients the model is
   linear in) by least squares with the prior below, equation weights corrected for the
   autocorrelation of the residuals.
4. **Output weights**: the output errors at that start are coloured (model-structure error), so each
   channel's sigma is its RMS error times the square root of its integrated autocorrelation time:
   ``N`` correlated samples weigh as their ``N / tau`` effective ones, which gives the prior its
   proper weight and each channel the share of its effective samples.
5. **Choose the free set** from the Fisher information at the start (:meth:`identifiability`), by a
   rule stated before any fit: greedy D-optimal forward selection among the candidates, adding a
   quantity only while every chosen one is determined by the data to at most half its prior
   standard deviation (``posterior std / prior std <= 0.5``) and no two chosen ones are correlated
   beyond 0.95; at most 15.
6. **MAP refinement**: output error (``psi, r, u``) with the Gaussian prior centred on the published
   values, the asymmetry terms per facility (the two facilities' models have different propellers).

Prior (standard deviations, relative to the published value unless stated): linear hull
derivatives 20 %; cubic hull and surge derivatives 50 % (``X'_vr`` at least 0.01); rudder and
interaction factors 20 % (``gamma_R`` 25 %, ``a_H``, ``t_R``, ``C_1`` 30 %); added masses 20 %;
rudder neutral angle 1 deg; propeller-induced side force and yaw moment 0.05 and 0.025 (what a
1 deg rudder gives at the approach). ``t_P``, ``w_P0`` and ``R_0'`` are not candidates: the measured
thrust confirms the propeller and the straight-run balance fixes the resistance.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

import casship as cs
from casship.identify import IdentificationWarning, Prior, inverse_dynamics, smooth_trial
from casship.identify.uncertainty import effective_samples
from casship.models import kvlcc2

from .data import Run, fit_record
from .propulsion import trim_resistance

__all__ = ["MODEL_OPTIONS", "study_model", "MEASURED", "CANDIDATES", "REGRESSED", "BY_FACILITY", "prior_std",
           "smooth_runs", "with_smoothed_speed", "FoldFit", "fit_fold", "select_free", "params_for"]

MODEL_OPTIONS = {"asymmetry": True, "smooth": True}
MEASURED = ("psi", "r", "u")
SMOOTHER = {  # facility -> (channels, measurement standard deviations)
    "MARIN": (("x", "y", "psi", "u", "r"), {"x": 3.0, "y": 3.0, "psi": np.radians(0.3), "u": 0.01,
                                            "r": np.radians(0.002)}),   # 3-digit print: +-5 m, 1 deg late
    "HSVA": (("x", "y", "psi", "r"), {"x": 0.05, "y": 0.05, "psi": np.radians(0.02), "r": np.radians(0.002)}),
}
JERK = {"u": 1e-3, "v": 1e-3, "r": 1e-5}
HULL_LINEAR = ("Y_v_dash", "Y_r_dash", "N_v_dash", "N_r_dash")
HULL_CUBIC = ("Y_vvv_dash", "Y_vvr_dash", "Y_vrr_dash", "Y_rrr_dash", "N_vvv_dash", "N_vvr_dash", "N_vrr_dash",
              "N_rrr_dash", "X_vv_dash", "X_vr_dash", "X_rr_dash", "X_vvvv_dash")
REGRESSED = (*HULL_LINEAR, *HULL_CUBIC, "f_alpha", "Y_0_dash", "N_0_dash")
CANDIDATES = (*HULL_LINEAR, *HULL_CUBIC, "gamma_R_minus", "gamma_R_plus", "l_R_dash", "epsilon", "kappa", "f_alpha",
              "a_H", "x_H_dash", "t_R", "C_1", "C_2_plus", "C_2_minus", "m_x_dash", "m_y_dash", "J_z_dash",
              "delta_0", "Y_0_dash", "N_0_dash")
BY_FACILITY = ("delta_0", "Y_0_dash", "N_0_dash")
PRIOR_REL = {**{k: 0.2 for k in HULL_LINEAR}, **{k: 0.5 for k in HULL_CUBIC}, "gamma_R_minus": 0.25,
             "gamma_R_plus": 0.25, "l_R_dash": 0.2, "epsilon": 0.2, "kappa": 0.2, "f_alpha": 0.2, "a_H": 0.3,
             "x_H_dash": 0.2, "t_R": 0.3, "C_1": 0.3, "C_2_plus": 0.2, "C_2_minus": 0.2, "m_x_dash": 0.2,
             "m_y_dash": 0.2, "J_z_dash": 0.2}
PRIOR_ABS = {"delta_0": np.radians(1.0), "Y_0_dash": 0.05, "N_0_dash": 0.025}
PRIOR_FLOOR = {"X_vr_dash": 0.01}
MAX_RATIO, MAX_CORR, MAX_FREE = 0.5, 0.95, 15


def study_model() -> cs.Model:
    """The full-scale KVLCC2 with the asymmetry terms and smooth sign switches (published values)."""
    return kvlcc2(**MODEL_OPTIONS)


def prior_std(model: cs.Model, names) -> dict[str, float]:
    """Prior standard deviation of each named parameter (see the module text)."""
    nominal = model.param_dict()
    return {n: PRIOR_ABS[n] if n in PRIOR_ABS else max(PRIOR_REL[n] * abs(nominal[n]), PRIOR_FLOOR.get(n, 0.0))
            for n in names}


def smooth_runs(runs, dt: float = 1.0) -> dict[str, cs.Dataset]:
    """Every run smoothed (EKF + RTS) at about ``dt`` seconds, by name."""
    out = {}
    for run in runs:
        measured, sigma = SMOOTHER[run.facility]
        out[run.name] = smooth_trial(fit_record(run, dt), sigma, JERK, measured=measured)
    return out


def with_smoothed_speed(runs, smoothed) -> list[Run]:
    """HSVA runs with ``u`` from the smoothed positions (the files' ``u`` kept as ``u_file``)."""
    out = []
    for run in runs:
        if run.facility == "HSVA":
            d, s = run.data, smoothed[run.name]
            data = d.with_columns(u=np.interp(d.t, s.t, s["u"]), u_file=d["u"])
            run = Run(run.name, run.facility, data, run.kind)
        out.append(run)
    return out


@dataclass
class FoldFit:
    """The identification on one set of training runs."""

    train: list
    R_0: float
    R_0_per_run: dict
    start: dict
    sigma: dict
    candidates: list
    selection: list                 # rows: quantity, posterior/prior std ratio when added
    free: list
    fit: object                     # FitResult of the MAP refinement
    seconds: float
    inverse_dynamics: object = field(repr=False, default=None)
    identifiability: object = field(repr=False, default=None)


def _share(names):
    return {k: "facility" for k in BY_FACILITY if k in names}


def _scale(names):
    return {k: PRIOR_ABS[k] for k in BY_FACILITY if k in names}


def fit_fold(train: list[Run], smoothed: dict, *, dt: float = 2.0, max_free: int = MAX_FREE,
             show: bool = False) -> FoldFit:
    """Propulsion trim, inverse dynamics, free-set choice and MAP refinement on ``train``."""
    t0 = time.perf_counter()
    model = study_model()
    R_0, per_run = trim_resistance(model, train)
    base = {"R_0_dash": R_0}
    idfit = inverse_dynamics(model, [smoothed[r.name] for r in train], list(REGRESSED), params=model.params(base),
                             prior=prior_std(model, REGRESSED), autocorrelation=True)
    start = {**base, **idfit.estimates}
    fixed = model.params(start)
    recs = [fit_record(r, dt) for r in train]
    facilities = sorted({r.facility for r in train})
    at = {k: v for k, v in start.items() if k in CANDIDATES and k not in BY_FACILITY}
    for k in BY_FACILITY:
        for fac in facilities:
            at[f"{k}@{fac}"] = float(start.get(k, 0.0))
    unit = cs.OutputErrorProblem(model, recs, list(CANDIDATES), measured=list(MEASURED),
                                 sigma={c: 1.0 for c in MEASURED}, params=fixed, share=_share(CANDIDATES),
                                 scale=_scale(CANDIDATES))
    res = unit.residuals(at)
    neff = effective_samples(res, list(MEASURED))
    sigma = {c: float(np.sqrt(sum(np.nansum(r[:, j] ** 2) for r in res) / neff[c]["n_eff"]))
             for j, c in enumerate(MEASURED)}
    prior = Prior(prior_std(model, CANDIDATES))
    prob = cs.OutputErrorProblem(model, recs, list(CANDIDATES), measured=list(MEASURED), sigma=sigma, params=fixed,
                                 share=_share(CANDIDATES), scale=_scale(CANDIDATES), prior=prior)
    idf = prob.identifiability(at=at)
    chosen, rows = select_free(idf, max_count=max_free)
    declared = list(dict.fromkeys(q.split("@")[0] for q in chosen))
    # a per-facility quantity is free only for the facilities whose copy was chosen
    share = {k: [r.facility if f"{k}@{r.facility}" in chosen else None for r in train]
             for k in BY_FACILITY if k in declared}
    refine = cs.OutputErrorProblem(model, recs, declared, measured=list(MEASURED), sigma=sigma, params=fixed,
                                   share=share, scale=_scale(declared),
                                   prior=Prior(prior_std(model, declared)))
    guess = {q: v for q, v in at.items() if q in chosen}
    with warnings.catch_warnings():        # coloured residuals are expected here; fit.warnings keeps them
        warnings.simplefilter("ignore", IdentificationWarning)
        fit = refine.solve(guess=guess, show=show)
    return FoldFit([r.name for r in train], R_0, per_run, start, sigma, list(CANDIDATES), rows, chosen, fit,
                   time.perf_counter() - t0, idfit, idf)


def select_free(idf, *, max_ratio: float = MAX_RATIO, max_corr: float = MAX_CORR,
                max_count: int = MAX_FREE) -> tuple[list[str], list[dict]]:
    """Greedy D-optimal forward selection in prior-normalised units (the rule in the module text).

    With ``F`` the data's Fisher information and ``P`` the prior covariance, a set ``S`` has the
    posterior-to-prior covariance ``C = (I + P^1/2 F P^1/2)^-1`` restricted to ``S``; candidates are
    added one at a time, each time the one that maximises ``log det (I + P^1/2 F P^1/2)_S`` among
    those that keep every ``sqrt(C_ii) <= max_ratio`` and every ``|corr| <= max_corr``.
    """
    F = np.asarray(idf.information, dtype=float)
    prec = np.asarray(idf.prior_precision, dtype=float)
    if np.any(prec <= 0):
        raise ValueError("select_free needs a prior on every candidate")
    s = 1.0 / np.sqrt(prec)
    Fs = F * np.outer(s, s)
    names = list(idf.names)
    chosen, pool, rows = [], list(range(len(names))), []
    while pool and len(chosen) < max_count:
        best = None
        for c in pool:
            S = chosen + [c]
            M = np.eye(len(S)) + Fs[np.ix_(S, S)]
            C = np.linalg.inv(M)
            d = np.sqrt(np.diag(C))
            corr = C / np.outer(d, d) - np.eye(len(S))
            if d.max() > max_ratio or (len(S) > 1 and np.abs(corr).max() > max_corr):
                continue
            logdet = np.linalg.slogdet(M)[1]
            if best is None or logdet > best[0]:
                best = (logdet, c, float(d[-1]), float(np.abs(corr).max()) if len(S) > 1 else 0.0)
        if best is None:
            break
        chosen.append(best[1])
        pool.remove(best[1])
        rows.append({"quantity": names[best[1]], "ratio_when_added": best[2], "max_corr": best[3]})
    alone = 1.0 / np.sqrt(1.0 + np.diag(Fs))
    for i in pool:
        rows.append({"quantity": names[i], "ratio_when_added": float("nan"), "ratio_alone": float(alone[i])})
    return [names[i] for i in chosen], rows


def params_for(fold: FoldFit, facility: str) -> dict[str, float]:
    """All model parameters of the fold's fit for a run of ``facility``: per-facility copies of that
    facility, or for a facility without its own copy the mean of the fitted copies."""
    fit = fold.fit
    p = dict(fit.params)
    for name in {q.split("@")[0] for q in fit.estimates if "@" in q}:
        copies = {q.split("@")[1]: v for q, v in fit.estimates.items() if q.startswith(name + "@")}
        p[name] = float(copies.get(facility, np.mean(list(copies.values()))))
    return p
