"""Calibrated uncertainty and the port/starboard check of the study.

* :func:`jackknife` -- the run-level jackknife over the leave-one-run-out folds: with ``theta_i``
  the parameters of the fit without run ``i`` (a quantity not free in a fold counts at the value
  that fold used), ``C = (n - 1) / n sum (theta_i - mean)(theta_i - mean)'``. It measures how much
  the estimates move when the runs change, which the model-based and robust standard errors of
  one fit (residuals treated as a stationary process of one long record) do not see. The study's
  ``fit.json`` carries this covariance.
* :func:`calibration_table` -- for every quantity, the fraction of the fold estimates inside the
  reported 95 % interval (estimate +- 1.96 standard errors) for the model-based, robust and
  jackknife standard errors.
* :func:`asymmetry_check` -- the sign of the port/starboard asymmetry: the HSVA mirror pairs'
  measured overshoot differences (starboard-first minus port-first) against the fit's and the
  published constants' replays, and the fit's port/starboard ratio of the steady yaw rate in
  +-35 deg turning circles.
* :func:`mirror_check` -- every run and its mirror image (rudder, heading, sway, yaw rate and
  East position negated) replayed with the fit file and the published constants: a symmetric
  ship would run the mirror image exactly so; a fit whose prediction of the mirror image is much
  worse than of the run itself carries an asymmetry the data may not support. (The mirror image
  of a measured run is not a measured run of the other direction: a diagnostic, not a validation.)
"""
from __future__ import annotations

import numpy as np

from casship.identify import ParameterUncertainty
from casship.identify.asymmetry import mirror_pairs, turn_side
from casship.maneuvers import run_maneuver
from casship.identify import replay_file
from casship.validation import replay

__all__ = ["jackknife", "calibration_table", "asymmetry_check", "mirror_check", "mirrored", "Z95"]

Z95 = 1.959963984540054


def jackknife(everything, folds) -> ParameterUncertainty:
    """Run-level jackknife covariance of the moved parameters of ``everything`` over ``folds``
    (the leave-one-run-out :class:`.workflow.FoldFit` values)."""
    names = [n for n in everything.moved() if not n.startswith("k_")]
    theta = np.array([[fold.fit.params[n] for n in names] for fold in folds])
    n = len(folds)
    d = theta - theta.mean(axis=0)
    C = (n - 1) / n * d.T @ d
    values = [everything.fit.params[k] for k in names]
    return ParameterUncertainty(names, values, C, f"run-level jackknife over {n} leave-one-run-out folds",
                                {"folds": n})


def calibration_table(everything, folds, jack: ParameterUncertainty) -> dict:
    """Per quantity: estimate, standard errors and the share of fold estimates in each 95 % interval."""
    moved = everything.moved()
    rows = {}
    for i, name in enumerate(jack.names):
        est = jack.values[i]
        fold_values = np.array([f.fit.params[name] for f in folds])
        ses = {"model-based": moved[name]["std_error"], "robust": moved[name].get("std_error_robust", np.nan),
               "jackknife": float(jack.std[i])}
        row = {"estimate": est, "published": moved[name]["published"], "stage": moved[name]["stage"],
               "fold spread (std)": float(np.std(fold_values, ddof=1))}
        for kind, se in ses.items():
            row[f"SE {kind}"] = se
            row[f"in 95 % ({kind})"] = (float(np.mean(np.abs(fold_values - est) <= Z95 * se))
                                        if np.isfinite(se) else np.nan)
        rows[name] = row
    return rows


def asymmetry_check(runs, fit_file_params, model, published) -> dict:
    """Measured vs replayed overshoot differences of the mirror pairs; steady-turn yaw-rate ratio."""
    pairs = mirror_pairs([r.data for r in runs], within=[r.facility for r in runs])
    out = {"pairs": []}
    for i, j in pairs:
        star, port = (runs[i], runs[j]) if turn_side(runs[i].data) == "+" else (runs[j], runs[i])
        row = {"starboard first": star.name, "port first": port.name}
        for who, m, p in (("measured", None, None), ("fit", model, fit_file_params), ("published", published, None)):
            diffs = []
            for r in (star, port):
                res = replay(published if m is None else m, r.data, p)
                src = res.measured_metrics if m is None else res.metrics
                diffs.append([src.get(k, np.nan) for k in ("overshoot_1_deg", "overshoot_2_deg")])
            for k, label in enumerate(("1st", "2nd")):
                row[f"{who}: {label} overshoot S - P [deg]"] = diffs[0][k] - diffs[1][k]
        for label in ("1st", "2nd"):
            meas, fit = row[f"measured: {label} overshoot S - P [deg]"], row[f"fit: {label} overshoot S - P [deg]"]
            row[f"sign agrees ({label})"] = bool(np.sign(meas) == np.sign(fit)) if np.isfinite(meas + fit) else None
        out["pairs"].append(row)
    rates = {}
    for label, m, p in (("fit", model, fit_file_params), ("published", published, None)):
        r = {}
        for sign in (1, -1):
            res = run_maneuver(m, "turning", rudder_deg=35.0 * sign, p=p)
            r[sign] = res.metrics.get("steady_speed_mps", np.nan) / (0.5 * res.metrics.get("steady_diameter_m", np.nan))
        rates[label] = {"steady yaw rate starboard [deg/s]": float(np.degrees(r[1])),
                        "steady yaw rate port [deg/s]": float(np.degrees(r[-1])),
                        "port / starboard": float(r[-1] / r[1])}
    out["steady_turn"] = rates
    return out



def mirrored(data):
    """The mirror image of a record: rudder, heading, sway speed, yaw rate and East position negated."""
    return data.with_columns(**{c: -data[c] for c in ("delta", "psi", "v", "r", "y") if c in data})


def mirror_check(runs, fit_file, published) -> dict:
    """Heading RMSE and indices of each run and of its mirror image, published and fit."""
    out = {}
    for run in runs:
        row = {}
        for label, data in (("run", run.data), ("mirror image", mirrored(run.data))):
            pub, fit = replay(published, data), replay_file(fit_file, data, "kvlcc2", samples=0)
            row[f"{label}: psi RMSE published [deg]"] = pub.errors["psi_rmse_deg"]
            row[f"{label}: psi RMSE fit [deg]"] = fit.errors["psi_rmse_deg"]
        out[run.name] = row
    return out
