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
* :func:`band_check` -- a check that is not automatic: does each leave-one-run-out fold's
  prediction band (parameter covariance of its fit file) cover the held-out run's measured heading
  and indices at the nominal rate? And with a model-discrepancy term estimated from the *other*
  folds' held-out errors only (heading: a variance growing linearly with time, ``q t``; overshoots:
  the RMS error of the other held-out runs)?
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

from casship.identify import ParameterBelief
from casship.identify.asymmetry import mirror_pairs, turn_side
from casship.maneuvers import run_maneuver
from casship.identify import replay_file
from casship.maneuvers import replay
from casship.maneuvers import UNINFORMATIVE_DEG

from .validate import INDICES
from .workflow import study_model

__all__ = ["jackknife", "calibration_table", "band_check", "heading_growth", "predictive_coverage", "asymmetry_check", "mirror_check", "mirrored", "Z95"]

Z95 = 1.959963984540054


def jackknife(everything, folds) -> ParameterBelief:
    """Run-level jackknife covariance of the moved parameters of ``everything`` over ``folds``
    (the leave-one-run-out :class:`.workflow.FoldFit` values)."""
    names = [n for n in everything.moved() if not n.startswith("k_")]
    theta = np.array([[fold.params()[n] for n in names] for fold in folds])
    n = len(folds)
    d = theta - theta.mean(axis=0)
    C = (n - 1) / n * d.T @ d
    for q, pool in everything.ship.facility.items():       # a run of an unknown facility: the spread too
        if q in names:
            C[names.index(q), names.index(q)] += pool["spread"] ** 2
    values = [everything.params()[k] for k in names]
    return ParameterBelief.from_values(names, values, C, f"run-level jackknife over {n} leave-one-run-out folds "
                                       "(facility quantities: population value, with the between-facility spread added)",
                                       {"folds": n}, kind="calibrated")


def calibration_table(everything, folds, jack: ParameterBelief) -> dict:
    """Per quantity: estimate, standard errors and the share of fold estimates in each 95 % interval."""
    moved = everything.moved()
    rows = {}
    for i, name in enumerate(jack.names):
        est = jack.values[i]
        fold_values = np.array([f.params()[name] for f in folds])
        ses = {"model-based": moved[name]["std_error"], "robust": moved[name].get("std_error_robust", np.nan),
               "jackknife": jack.std[name]}
        row = {"estimate": est, "published": moved[name]["published"], "stage": moved[name]["stage"],
               "fold spread (std)": float(np.std(fold_values, ddof=1))}
        for kind, se in ses.items():
            row[f"SE {kind}"] = se
            row[f"in 95 % ({kind})"] = (float(np.mean(np.abs(fold_values - est) <= Z95 * se))
                                        if np.isfinite(se) else np.nan)
        rows[name] = row
    return rows


def _heading_errors(run, ev):
    """Time since the start [s], heading error [rad] and parameter-band std [rad] of one replay."""
    fit, data = ev["fit"], run.data
    e = np.angle(np.exp(1j * (np.asarray(fit["psi"]) - np.asarray(data["psi"]))))
    return fit.t - fit.t[0], e, np.asarray(ev["bands"]["psi_std"])


def _growth(t, e, s) -> float:
    """Least-squares ``q`` of ``e^2 - s^2 = q t``: the heading variance the parameter band misses [rad^2/s]."""
    return float(np.sum((e**2 - s**2) * t) / np.sum(t**2))


def band_check(runs, loro_results, *, z: float = Z95) -> dict:
    """Coverage of the held-out runs by their folds' 95 % bands, parameter-only and with a
    discrepancy term from the other folds only (see the module text).

    Returns ``{"runs": {run: row}, "summary": {...}}``; a row holds the heading coverage (share of
    samples inside the band) without and with the discrepancy, the ``q`` used, and for each index
    whether the measured value lies in the interval without and with the discrepancy (``None``
    where no other held-out run has that index).
    """
    by_name = {r.name: r for r in runs}
    evs = [res["evaluations"][0] for res in loro_results]
    series = {ev["row"]["run"]: _heading_errors(by_name[ev["row"]["run"]], ev) for ev in evs if ev["bands"]}
    q = {name: max(_growth(*ser), 0.0) for name, ser in series.items()}
    rows = {}
    for ev in evs:
        row, name = ev["row"], ev["row"]["run"]
        if name not in series:
            continue
        t, e, s = series[name]
        q_other = float(np.mean([v for k, v in q.items() if k != name]))
        out = {"psi coverage, parameter band": float(np.mean(np.abs(e) <= z * s)),
               "psi coverage, with discrepancy": float(np.mean(np.abs(e) <= z * np.sqrt(s**2 + q_other * t))),
               "q from the other folds [deg^2/s]": float(np.degrees(np.degrees(q_other))),
               "psi half-width at the end, with discrepancy [deg]": float(np.degrees(z * np.sqrt(s[-1]**2 + q_other * t[-1])))}
        for key in INDICES[row["kind"]]:
            meas, fit, lo, hi = (row[f"{key}_{k}"] for k in ("measured", "fit", "fit_lo", "fit_hi"))
            if not np.isfinite(meas):
                continue
            out[f"{key} in interval, parameter"] = bool(lo <= meas <= hi)
            others = [o for o in (ev2["row"] for ev2 in evs if ev2["row"]["run"] != name)   # replays that reach it
                      if np.isfinite(o.get(f"{key}_measured", np.nan)) and np.isfinite(o.get(f"{key}_fit", np.nan))]
            if others:
                d = float(np.sqrt(np.mean([(o[f"{key}_fit"] - o[f"{key}_measured"]) ** 2 for o in others])))
                half = np.sqrt((0.5 * (hi - lo)) ** 2 + (z * d) ** 2)
                out[f"{key} in interval, with discrepancy"] = bool(abs(meas - fit) <= half)
            else:
                out[f"{key} in interval, with discrepancy"] = None
        rows[name] = out
    def share(col):
        v = [r[col] for r in rows.values() if r.get(col) is not None]
        return float(np.mean(v)) if v else np.nan
    summary = {"psi coverage, parameter band (mean)": share("psi coverage, parameter band"),
               "psi coverage, with discrepancy (mean)": share("psi coverage, with discrepancy")}
    idx_cols = sorted({c for r in rows.values() for c in r if " in interval, " in c})
    for how in ("parameter", "with discrepancy"):
        v = [r[c] for r in rows.values() for c in idx_cols if c.endswith(how) and r.get(c) is not None]
        summary[f"indices in interval, {how}"] = float(np.mean(v)) if v else np.nan
        summary[f"indices checked, {how}"] = len(v)
    return {"runs": rows, "summary": summary, "q_all_folds_deg2_per_s": float(np.degrees(np.degrees(np.mean(list(q.values())))))}


def heading_growth(runs, loro_results) -> dict:
    """``q`` [rad^2/s] of each leave-one-run-out held-out run: the heading variance its fold's parameter
    band misses, growing linearly with time (least squares, floored at 0)."""
    by_name = {r.name: r for r in runs}
    out = {}
    for res in loro_results:
        ev = res["evaluations"][0]
        if ev["bands"]:
            out[ev["row"]["run"]] = max(_growth(*_heading_errors(by_name[ev["row"]["run"]], ev)), 0.0)
    return out


def predictive_coverage(runs, results, q_by_run: dict, *, z: float = Z95) -> dict:
    """Coverage of every left-out run (every fold family) by its fold's 95 % predictive band.

    The predictive band is the fold file's parameter band (its covariance) plus the model discrepancy
    ``q t``, with ``q`` the mean over the leave-one-run-out held-out runs *not held out by that fold*
    (a fold never sees its own held-out errors): ``sqrt(s^2 + q t) >= s`` on every sample. Returns
    the share of heading samples inside the band per held-out run and fold, their mean over all folds
    (``mean``) and per family (``by_kind``), and the parameter band's share beside it; and how much of it
    is informative: the share of samples where the band is at most :data:`UNINFORMATIVE_DEG` wide
    (``informative_share``) and the share both inside and informative (``inside_and_informative``).
    """
    by_name = {r.name: r for r in runs}
    rows = []
    for res in results:
        held = set(res["held"])
        others = [q for name, q in q_by_run.items() if name not in held]
        if not others:
            continue
        q = float(np.mean(others))
        for ev in res["evaluations"]:
            if not ev["bands"]:
                continue
            t, e, s = _heading_errors(by_name[ev["row"]["run"]], ev)
            wide = np.sqrt(s**2 + q * t)
            informative = np.degrees(z * wide) <= UNINFORMATIVE_DEG
            rows.append({"kind": res["kind"], "label": res["label"], "run": ev["row"]["run"],
                         "predictive": float(np.mean(np.abs(e) <= z * wide)),
                         "parameter": float(np.mean(np.abs(e) <= z * s)),
                         "informative_share": float(np.mean(informative)),
                         "inside_and_informative": float(np.mean((np.abs(e) <= z * wide) & informative)),
                         "q_deg2_per_s": float(np.degrees(np.degrees(q))),
                         "never_narrower": bool(np.all(wide >= s))})
    kinds = sorted({r["kind"] for r in rows})

    def mean(key, kind=None):
        v = [r[key] for r in rows if kind is None or r["kind"] == kind]
        return float(np.mean(v)) if v else float("nan")
    return {"rows": rows, "mean": mean("predictive"), "parameter_mean": mean("parameter"),
            "informative_share": mean("informative_share"), "inside_and_informative": mean("inside_and_informative"),
            "by_kind": {k: mean("predictive", k) for k in kinds}}


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
            pub, fit = replay(published, data), replay_file(fit_file, data, study_model(), samples=0)
            row[f"{label}: psi RMSE published [deg]"] = pub.errors["psi_rmse_deg"]
            row[f"{label}: psi RMSE fit [deg]"] = fit.errors["psi_rmse_deg"]
        out[run.name] = row
    return out
