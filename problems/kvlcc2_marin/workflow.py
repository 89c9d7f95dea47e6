"""The identification workflow of the study, applied to a set of training runs.

Every choice below (candidates, prior, weights, selection rule) is fixed before any
cross-validation; the report lists the ones that changed after a cross-validation run.

1. **Propulsion** (:mod:`.propulsion`): the propeller's thrust coefficients from the open-water
   curve and its wake from the measured HSVA thrust of the training runs, before the manoeuvring
   fit (each with a standard error, the wake's free set by the rule of step 5).
2. **Smooth** every run (EKF + RTS, :func:`casship.identify.smooth_trial`) into ``u, v, r`` and their
   rates. HSVA: positions, heading and yaw rate (the files' surge column disagrees with the positions
   by up to 4 % in the larger zig-zags, so the surge and sway speeds of the smoothed positions are
   used); MARIN: positions, heading, surge speed and yaw rate (its sway column is measured).
3. **Inverse dynamics** (:func:`casship.identify.inverse_dynamics`): the coefficients the model is
   linear in, by regularised least squares on the smoothed accelerations: *only a starting guess*
   for the quantities step 5 sets free (used when it lowers the cost); nothing else moves.
4. **Cost**: output error of heading, yaw rate, surge and sway speed and the track (``psi, r, u, v,
   x, y``). Channel weights: each channel's sigma is its RMS error at the preset times the square
   root of its integrated autocorrelation time (``N`` correlated samples weigh as their ``N / tau``
   effective ones). Record weights: every run counts the same however long it is (each record's
   squared residuals are multiplied by ``N_mean / N_r``), so that a long circle or small-angle
   zig-zag cannot swamp the large-rudder runs.
5. **Choose the free set** from the Fisher information at the preset (published constants with the
   fitted propeller), by a rule stated before any fit: greedy D-optimal forward selection among the
   candidates, adding a quantity only while every chosen one is determined by the data to at most
   half its prior standard deviation (``posterior std / prior std <= 0.5``) and no two chosen ones
   are correlated beyond 0.95; at most 15.
6. **Asymmetry from the mirror pairs only**: the asymmetry terms (rudder neutral angle,
   propeller-induced side force and yaw moment) are one value for the ship, estimated (free set by
   the rule of step 5, MAP) on the training runs that form mirror pairs within one facility
   (:mod:`casship.identify.asymmetry`: the same manoeuvre turning first to both sides; a
   difference between facilities is no port/starboard evidence) and nothing else; without a pair
   they are confounded with the turning dynamics and stay at zero. That is the ``"neutral angle"``
   form of :data:`ASYMMETRY_FORMS`; the ``"thrust"`` form applies only the propeller-induced terms
   and takes a neutral angle as one facility's (estimated after them, never applied). Chosen by
   cross-validation (the report's choices); the fit file records the form and its evidence.
7. **MAP refinement** of the chosen symmetric set on all training runs, the asymmetry terms held at
   step 6's values; every other parameter stays at the preset. Then the free set is **chosen again**
   by the rule of step 5 from the Fisher information at that estimate, and the set chosen there is
   refined (started from the estimate): at the preset many runs drift far from the measurement
   (heading errors of 20-60 deg), and sensitivities along trajectories that far off rank the
   candidates poorly; at the estimate the trajectories follow the runs. (Chosen by cross-validation:
   the report's choices.)

Prior (standard deviations, relative to the published value unless stated): linear hull
derivatives 20 %; cubic hull and surge derivatives 50 % (``X'_vr`` at least 0.01); straight-run
resistance 30 %; rudder and interaction factors 20 % (``gamma_R`` 25 %, ``a_H``, ``t_R`` 30 %); added
masses 20 %; rudder neutral angle 1 deg; propeller-induced side force and yaw moment 0.05 and 0.025
(what a 1 deg rudder gives at the approach); with the rudder-lift variant
(``kvlcc2(rudder_lift="cubic")``), its loss of lift slope ``c_alpha3`` 0.5 about 0: one standard
deviation weakens the rudder by 16 % at 35 deg effective angle and 6 % at 20 deg; the cubic rudder
terms of the Mariner (Chislett & Strøm-Tejsen 1965) amount to 0.19, a stall at 35 deg (the bound 1)
is two standard deviations away.

A run of any facility, direction or regime is replayed with the one parameter set of the fit (there
are no per-facility copies): the fit file's ``params``, exactly what ``casship simulate --params``
uses.
"""
from __future__ import annotations

import functools
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

import casship as cs
from casship.identify import IdentificationWarning, Prior, inverse_dynamics, smooth_trial
from casship.identify.asymmetry import confounded_asymmetry, mirror_pairs
from casship.identify.uncertainty import effective_samples
from casship.models import kvlcc2
from casship.parallel import blas_threads

from .data import Run, fit_record, per_run
from .propulsion import PropulsionFit, fit_propulsion, resistance_for_run
from casship.errors import InputError

__all__ = ["MODEL_OPTIONS", "study_model", "MEASURED", "CANDIDATES", "OPTION_CANDIDATES", "candidates", "REGRESSED",
           "ASYMMETRY", "prior_std",
           "smooth_runs", "with_smoothed_speed", "FoldFit", "fit_fold", "select_free", "record_weights"]

MODEL_OPTIONS = {"asymmetry": True, "smooth": True}
MEASURED = ("psi", "r", "u", "v", "x", "y")
SMOOTHER = {  # facility -> (channels, measurement standard deviations)
    "MARIN": (("x", "y", "psi", "u", "r"), {"x": 3.0, "y": 3.0, "psi": np.radians(0.3), "u": 0.01,
                                            "r": np.radians(0.002)}),   # 3-digit print: +-5 m, 1 deg late
    "HSVA": (("x", "y", "psi", "r"), {"x": 0.05, "y": 0.05, "psi": np.radians(0.02), "r": np.radians(0.002)}),
}
JERK = {"u": 1e-3, "v": 1e-3, "r": 1e-5}
HULL_LINEAR = ("Y_v_dash", "Y_r_dash", "N_v_dash", "N_r_dash")
HULL_CUBIC = ("Y_vvv_dash", "Y_vvr_dash", "Y_vrr_dash", "Y_rrr_dash", "N_vvv_dash", "N_vvr_dash", "N_vrr_dash",
              "N_rrr_dash", "X_vv_dash", "X_vr_dash", "X_rr_dash", "X_vvvv_dash")
ASYMMETRY = ("delta_0", "Y_0_dash", "N_0_dash")
#: How the asymmetry terms are treated: ``"ship"``, one value for the ship applied to every run (the
#: file's ``params``), ``"rig"``, one copy per facility from that facility's mirror pairs, considered only
#: when no ship term can be added and never applied to a run (held at 0 in the fit file).
ASYMMETRY_FORMS = {
    "neutral angle": {"ship": ("delta_0", "Y_0_dash", "N_0_dash"), "rig": ()},
    "thrust": {"ship": ("Y_0_dash", "N_0_dash"), "rig": ("delta_0",)},
}
ASYMMETRY_FORM = "neutral angle"          # chosen by cross-validation (the report's choices)
ASYMMETRY_RULES = {
    "neutral angle": "one value for the ship, estimated on the mirror-pair runs (MAP, free set by the selection "
                     "rule among delta_0, Y_0_dash, N_0_dash) and applied to every run of any facility or direction",
    "thrust": "the ship's propeller-induced terms (Y_0_dash, N_0_dash, scaling with the thrust) apply to every run; "
              "a rudder neutral angle is taken as one rig's: estimated per facility from that facility's mirror "
              "pairs after the ship's terms, never applied to a run (held at 0 in the file)",
}
REGRESSED = (*HULL_LINEAR, *HULL_CUBIC, "f_alpha", "Y_0_dash", "N_0_dash")
CANDIDATES = (*HULL_LINEAR, *HULL_CUBIC, "R_0_dash", "gamma_R_minus", "gamma_R_plus", "l_R_dash", "epsilon", "kappa",
              "f_alpha", "a_H", "x_H_dash", "t_R", "m_x_dash", "m_y_dash", "J_z_dash", *ASYMMETRY)
#: Candidates that exist only in a model variant (``MODEL_OPTIONS``): the rudder's loss of lift slope.
OPTION_CANDIDATES = ("c_alpha3",)
PRIOR_REL = {**{k: 0.2 for k in HULL_LINEAR}, **{k: 0.5 for k in HULL_CUBIC}, "R_0_dash": 0.3, "gamma_R_minus": 0.25,
             "gamma_R_plus": 0.25, "l_R_dash": 0.2, "epsilon": 0.2, "kappa": 0.2, "f_alpha": 0.2, "a_H": 0.3,
             "x_H_dash": 0.2, "t_R": 0.3, "m_x_dash": 0.2, "m_y_dash": 0.2, "J_z_dash": 0.2}
PRIOR_ABS = {"delta_0": np.radians(1.0), "Y_0_dash": 0.05, "N_0_dash": 0.025, "c_alpha3": 0.5}
PRIOR_FLOOR = {"X_vr_dash": 0.01}
MAX_RATIO, MAX_CORR, MAX_FREE = 0.5, 0.95, 15


def study_model() -> cs.Model:
    """The full-scale KVLCC2 with the asymmetry terms and smooth sign switches (published values),
    built once per process and :data:`MODEL_OPTIONS` (a model is immutable: every fold and replay
    shares it and what it derives)."""
    return _model_with(tuple(sorted(MODEL_OPTIONS.items())))


@functools.cache
def _model_with(options: tuple) -> cs.Model:
    return kvlcc2(**dict(options))


def candidates(model: cs.Model) -> list[str]:
    """The candidates of the free set: :data:`CANDIDATES` and those of :data:`OPTION_CANDIDATES` the model has."""
    return [*CANDIDATES, *(c for c in OPTION_CANDIDATES if c in model.param_names)]


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
    """HSVA runs with ``u`` and ``v`` from the smoothed positions (the files' ``u`` kept as ``u_file``)."""
    out = []
    for run in runs:
        if run.facility == "HSVA":
            d, s = run.data, smoothed[run.name]
            data = d.with_columns(u=np.interp(d.t, s.t, s["u"]), v=np.interp(d.t, s.t, s["v"]), u_file=d["u"])
            run = Run(run.name, run.facility, data, run.kind)
        out.append(run)
    return out


def record_weights(records) -> np.ndarray:
    """Every record counts the same: its squared residuals weighted by ``N_mean / N_r``."""
    n = np.array([len(r) for r in records], dtype=float)
    return n.mean() / n


@dataclass
class FoldFit:
    """The identification on one set of training runs."""

    train: list
    propulsion: PropulsionFit
    preset: dict                    # the parameters that differ from the published ones before the fit
    start: dict                     # inverse-dynamics estimates (starting guesses only)
    guess_from: str                 # "first estimate" or "preset": the start of the second refinement
    sigma: dict
    candidates: list
    selection: list                 # rows: quantity, posterior/prior std ratio when added
    confounded: dict                # asymmetry quantity -> why it is not estimated
    free: list
    fit: object                     # FitResult of the MAP refinement
    seconds: float
    inverse_dynamics: object = field(repr=False, default=None)
    identifiability: object = field(repr=False, default=None)
    asymmetry_fit: object = field(repr=False, default=None)   # FitResult of the mirror-pair stage
    asymmetry: list = field(default_factory=list)              # the ship's asymmetry terms taken from it
    rig: dict = field(default_factory=dict)                    # estimated asymmetry terms not applied
    first_free: list = field(default_factory=list)             # the free set chosen at the preset (first pass)

    def asymmetry_record(self) -> dict:
        """Which port/starboard terms the fit file applies, from which evidence, and which it does not."""
        a = self.asymmetry_fit
        pairs = next((r["stage"].split("runs ", 1)[1] for r in self.selection
                      if r.get("stage", "").startswith("asymmetry: mirror-pair")), "")
        return {"applied": {n: float(self.fit.params[n]) for n in ASYMMETRY},
                "estimated": {n: {"value": float(a.estimates[n]), "std_error": float(a.std_errors[n])}
                              for n in self.asymmetry},
                "evidence": (f"MAP on the mirror-pair runs {pairs}" if pairs else
                             "no mirror pair in the training runs: every asymmetry term at zero"),
                "estimated_not_applied": {n: {"value": float(v), "std_error": float(a.std_errors[n])}
                                                  for n, v in self.rig.items()},
                "confounded": dict(self.confounded),
                "form": ASYMMETRY_FORM,
                "rule": ASYMMETRY_RULES[ASYMMETRY_FORM]}

    def moved(self) -> dict:
        """Every parameter that differs from the published value, with its standard error and stage."""
        nominal = study_model().param_dict()
        out = {}
        for n, v in self.propulsion.values.items():
            out[n] = {"value": v, "published": nominal[n], "std_error": self.propulsion.std_errors.get(n, np.nan),
                      "stage": "propulsion (open-water curve)" if n.startswith("k_") else "propulsion (measured thrust)"}
        for n in self.asymmetry:
            a = self.asymmetry_fit
            out[n] = {"value": a.estimates[n], "published": nominal[n], "std_error": a.std_errors[n],
                      "std_error_robust": a.std_errors_robust.get(n, np.nan),
                      "stage": "asymmetry (MAP on the mirror-pair runs)"}
        for n in self.fit.free:
            out[n] = {"value": self.fit.estimates[n], "published": nominal[n], "std_error": self.fit.std_errors[n],
                      "std_error_robust": self.fit.std_errors_robust.get(n, np.nan), "stage": "MAP refinement"}
        return out


def fit_fold(train: list[Run], smoothed: dict, curve: np.ndarray, *, dt: float = 2.0, max_free: int = MAX_FREE,
             show: bool = False) -> FoldFit:
    """Propulsion, asymmetry from the mirror pairs, free-set choice and MAP refinement on ``train``
    (see the module text)."""
    t0 = time.perf_counter()
    model = study_model()
    prop = fit_propulsion(model, train, smoothed, curve)
    preset = dict(prop.values)
    fixed = model.params(preset)
    r0 = float(np.mean([resistance_for_run(model, r, fixed) for r in train]))
    with blas_threads(None):     # its least squares at the process's BLAS threads: the numbers depend on them
        idfit = inverse_dynamics(model, [smoothed[r.name] for r in train], list(REGRESSED),
                                 params=model.params({**preset, "R_0_dash": r0}), prior=prior_std(model, REGRESSED),
                                 autocorrelation=True)
    start = {**idfit.estimates, "R_0_dash": r0}
    recs = [per_run(("fit record", dt, MEASURED), r, lambda r=r: fit_record(r, dt, outputs=MEASURED)) for r in train]
    cands = candidates(model)
    at = {k: float(fixed[model.index(k, "param")]) for k in cands}
    unit = cs.OutputErrorProblem(model, recs, cands, measured=list(MEASURED), sigma={c: 1.0 for c in MEASURED},
                                 params=fixed, scale={k: v for k, v in PRIOR_ABS.items() if k in cands})
    res = unit.residuals(at)
    neff = effective_samples(res, list(MEASURED))
    sigma = {c: float(np.sqrt(sum(np.nansum(r[:, j] ** 2) for r in res) / neff[c]["n_eff"]))
             for j, c in enumerate(MEASURED)}
    facilities = [r.facility for r in train]
    paired = sorted({i for pair in mirror_pairs(recs, within=facilities) for i in pair})
    ship, rig_terms = ASYMMETRY_FORMS[ASYMMETRY_FORM]["ship"], ASYMMETRY_FORMS[ASYMMETRY_FORM]["rig"]
    rig_names = [f"{q}@{f}" for q in rig_terms for f in sorted(set(facilities))]
    confounded = confounded_asymmetry(recs, [*ship, *rig_names], {q: facilities for q in rig_terms},
                                      within=facilities)
    asym, rig, asym_stage, rows_a = {}, {}, None, []
    if paired:           # stage A: the asymmetry terms from the mirror-pair runs only
        sub = [recs[i] for i in paired]
        share = {q: [facilities[i] for i in paired] for q in rig_terms}
        asym_stage, chosen_a, rows_a, _, _ = _select_and_refine(
            model, sub, [c for c in cands if c not in rig_terms] + list(rig_terms), sigma, fixed, at,
            start, max_free, show, share=share)
        asym = {n: asym_stage.estimates[n] for n in chosen_a if n in ship}
        rig = {n: asym_stage.estimates[n] for n in chosen_a if n not in asym and n.split("@")[0] in ASYMMETRY}
        rows_a = [dict(r, stage=f"asymmetry: mirror-pair runs {', '.join(train[i].name for i in paired)}")
                  for r in rows_a if r["quantity"].split("@")[0] in ASYMMETRY]
    fixed = model.params({**preset, **asym})
    symmetric = [c for c in cands if c not in ASYMMETRY]
    fit, first, _, _, _ = _select_and_refine(model, recs, symmetric, sigma, fixed, at, start, max_free, show)
    # the free set chosen again by the same rule, from the information at this estimate, and refined
    est = {k: float(v) for k, v in fit.estimates.items()}
    fit, chosen, rows, idf, use_id = _select_and_refine(model, recs, symmetric, sigma, fixed, {**at, **est},
                                                        {**start, **est}, max_free, show)
    rows = rows_a + [dict(r, stage="all runs") for r in rows]
    rows += [{"quantity": q, "ratio_when_added": float("nan"), "confounded": why, "stage": "asymmetry"}
             for q, why in confounded.items()]
    return FoldFit([r.name for r in train], prop, preset, start, "first estimate" if use_id else "preset", sigma,
                   cands, rows, confounded, chosen, fit, time.perf_counter() - t0, idfit, idf,
                   asym_stage, sorted(asym), rig, first)


def _select_and_refine(model, recs, candidates, sigma, fixed, at, start, max_free, show, share=None):
    """Free set by :func:`select_free` from the information at ``at`` and the MAP refinement of it
    (started from the inverse-dynamics values when they give a lower cost than the preset). The
    quantities of ``share`` (name -> one group label per record) have one copy per group; a rig's
    asymmetry terms are considered only when none of the ship's can be added (:data:`ASYMMETRY_FORMS`)."""
    share = dict(share or {})
    prob = cs.OutputErrorProblem(model, recs, candidates, measured=list(MEASURED), sigma=sigma, params=fixed,
                                 scale={k: v for k, v in PRIOR_ABS.items() if k in candidates},
                                 prior=Prior(prior_std(model, candidates)), record_weights=record_weights(recs),
                                 share=share or None)
    names = prob.free
    idf = prob.identifiability(at={k: at[k.split("@")[0]] for k in names}, pairs_within="facility")
    form = ASYMMETRY_FORMS[ASYMMETRY_FORM]
    ship = [k for k in names if k in form["ship"]]
    chosen, rows = select_free(idf, max_count=max_free,
                               after={k: ship for k in names if k.split("@")[0] in form["rig"]})
    declared = list(dict.fromkeys(k.split("@")[0] for k in chosen))
    refine = prob.replace(free=declared, prior=Prior(prior_std(model, declared)),
                          scale={k: v for k, v in PRIOR_ABS.items() if k in declared},
                          share={k: [lab if f"{k}@{lab}" in chosen else None for lab in v]
                                 for k, v in share.items() if k in declared} or None)
    guess_id = {q: start.get(q, at[q.split("@")[0]]) for q in chosen}
    use_id = bool(chosen) and refine.cost(guess_id) < refine.cost({q: at[q.split("@")[0]] for q in chosen})
    with warnings.catch_warnings():        # coloured residuals are expected here; fit.warnings keeps them
        warnings.simplefilter("ignore", IdentificationWarning)
        fit = refine.solve(guess=guess_id if use_id else None, show=show)
    return fit, chosen, rows, idf, use_id


def select_free(idf, *, max_ratio: float = MAX_RATIO, max_corr: float = MAX_CORR,
                max_count: int = MAX_FREE, after=None) -> tuple[list[str], list[dict]]:
    """Greedy D-optimal forward selection in prior-normalised units (the rule in the module text).

    With ``F`` the data's Fisher information and ``P`` the prior covariance, a set ``S`` has the
    posterior-to-prior covariance ``C = (I + P^1/2 F P^1/2)^-1`` restricted to ``S``; candidates are
    added one at a time, each time the one that maximises ``log det (I + P^1/2 F P^1/2)_S`` among
    those that keep every ``sqrt(C_ii) <= max_ratio`` and every ``|corr| <= max_corr``. Quantities
    flagged confounded (``idf.confounded``) are never chosen. ``after`` maps a candidate to the
    candidates it waits for: it is considered only when none of those can be added (a rig's
    asymmetry term after the ship's: where both explain the same port/starboard difference, the one
    that transfers to another rig is chosen).
    """
    F = np.asarray(idf.information, dtype=float)
    prec = np.asarray(idf.prior_precision, dtype=float)
    if np.any(prec <= 0):
        raise InputError("select_free needs a prior on every candidate")
    s = 1.0 / np.sqrt(prec)
    Fs = F * np.outer(s, s)
    names = list(idf.names)
    confounded = dict(getattr(idf, "confounded", {}) or {})
    chosen, rows = [], []
    pool = [i for i in range(len(names)) if names[i] not in confounded]
    after = dict(after or {})
    unknown = sorted({n for k, v in after.items() for n in (k, *v)} - set(names))
    if unknown:
        raise InputError(f"select_free: {unknown} in 'after' are not candidates")
    waits = {names.index(k): [names.index(n) for n in v] for k, v in after.items()}
    while pool and len(chosen) < max_count:
        best = None
        for c in pool:
            logdet, ratio, corr = _trial(Fs, chosen, c, max_ratio, max_corr)
            if logdet is None or any(f in pool and _trial(Fs, chosen, f, max_ratio, max_corr)[0] is not None
                                     for f in waits.get(c, ())):
                continue
            if best is None or logdet > best[0]:
                best = (logdet, c, ratio, corr)
        if best is None:
            break
        chosen.append(best[1])
        pool.remove(best[1])
        rows.append({"quantity": names[best[1]], "ratio_when_added": best[2], "max_corr": best[3]})
    alone = 1.0 / np.sqrt(1.0 + np.diag(Fs))
    for i in pool:
        rows.append({"quantity": names[i], "ratio_when_added": float("nan"), "ratio_alone": float(alone[i])})
    for q, why in confounded.items():
        rows.append({"quantity": q, "ratio_when_added": float("nan"), "confounded": why})
    return [names[i] for i in chosen], rows


def _trial(Fs, chosen, c, max_ratio, max_corr):
    """``(log det, posterior/prior std of c, largest |corr|)`` of ``chosen + [c]`` in prior-normalised
    units, or ``(None, ...)`` when the set breaks the rule of :func:`select_free`."""
    S = chosen + [c]
    M = np.eye(len(S)) + Fs[np.ix_(S, S)]
    C = np.linalg.inv(M)
    d = np.sqrt(np.diag(C))
    corr = float(np.abs(C / np.outer(d, d) - np.eye(len(S))).max()) if len(S) > 1 else 0.0
    if d.max() > max_ratio or corr > max_corr:
        return None, float(d[-1]), corr
    return float(np.linalg.slogdet(M)[1]), float(d[-1]), corr
