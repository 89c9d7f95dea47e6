"""KVLCC2 MMG coefficients from the HMRI captive (PMM) tests alone, beside Yasukawa & Yoshimura (2015),
and that model replaying the shared free-running runs.

Data: ``kvlcc2_hmri_captive`` (static rudder, static drift, drift with counter-rudder, pure sway,
pure yaw, yaw with drift; read by :func:`casship.io.read_captive`) and, for the replays, the three
MARIN and thirteen HSVA free-running runs (loaded and replayed as :mod:`.kvlcc2_marin` does).

Method, fixed before any replay was looked at:

* **Model**: :func:`casship.models.kvlcc2_l7` with HMRI's particulars (:data:`HMRI`) and the
  extended variant (neutral angle) with smooth sign switches. What the captive rig measures is the
  force of the model on the rig, rigid-body inertia included (:mod:`casship.identify.captive_forces`).
* **Evidence**: every measured force channel the MMG models: hull ``X, Y, N``, rudder normal force
  on the stock ``RY`` and thrust ``T``; every static point and every harmonic component of the
  dynamic tests except their means (referenced to the running condition in the tables).
* **Free set** (:data:`FREE`): every hull coefficient the tests are designed to measure (the
  polynomial derivatives, ``m'_x, m'_y, J'_z``), the hull-rudder and hull-propeller interaction
  (``t_R, a_H, x'_H, gamma_R+-, l'_R, C_2+-``) and HMRI's own ``t_P, w_P0, f_alpha, delta_0``.
  Fixed: ``R'_0`` at HMRI's resistance test, ``K_T`` from HMRI's open-water curve, ``epsilon`` and
  ``kappa`` published (``epsilon`` cannot be separated from ``f_alpha`` by these tests), ``C_1``
  and ``x'_P`` published.
* **Weights**: Gaussian noise, one standard deviation per group (static / dynamic, per channel),
  estimated with the coefficients (concentrated likelihood); no prior.
* **Replays**: the full-scale :func:`casship.models.kvlcc2` with the captive estimates of the hull
  and interaction quantities; the facility quantities of the free-running models (propeller,
  rudder, neutral angle) stay published. Nothing is tuned on the replays.
* **A structure the tests were read for** (:func:`lever_structure`): the yaw moment per rudder
  force of the static rudder tests falls with the propeller loading (``docs/identification.md``,
  "What the captive tests say about hard-over"); the same fit with ``rudder_lever="loading"``
  (one more coefficient, ``x'_HJ``) is reported beside: its likelihood-ratio statistic, the
  coefficient and its errors, the residuals and its replays. Reported, not adopted: the study's
  model and the captive-only candidate of ``kvlcc2-marin`` keep the published constant lever this
  round (decided before it was fitted).

Outputs: ``report.md``, ``coefficients.csv``, ``fig_forces.png`` (measured vs model per test kind),
``fig_replays.png``, ``captive_fit.json``, ``summary.json``.
"""
from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np

from casship.identify.rig import classical_derivatives
from casship.io import read_captive
from casship.models import kvlcc2
from casship.models.kvlcc2 import KVLCC2_COMMON, KVLCC2_L7
from casship.maneuvers import replay

from . import Study
from .kit import Departure, Report, data_folder, figure, fmt, md_table, write_json

from .hmri import (CHANNELS, FACILITY, FREE, HMRI, HULL, INTERACTION, IZ_MIDSHIP, KINDS, L_HMRI, MASS,  # noqa: F401
                   OWN, RHO, WATCH, X_G, captive_problem, hmri_model, shared_estimates)


# -- figures -------------------------------------------------------------------------------------
def _replay_figure(path: Path, rows) -> None:
    with figure(path, 1, 1, figsize=(10, 4)) as (fig, ax):
        x = np.arange(len(rows))
        ax.bar(x - 0.2, [r["published_deg"] for r in rows], 0.4, label="published (Yasukawa & Yoshimura 2015)",
               color="tab:gray")
        ax.bar(x + 0.2, [r["captive_deg"] for r in rows], 0.4, label="captive-only (HMRI)", color="tab:blue")
        ax.set_xticks(x)
        ax.set_xticklabels([r["run"] for r in rows], rotation=60, ha="right", fontsize=7)
        ax.set_ylabel("heading RMSE [deg]")
        ax.legend(fontsize=8)


# -- replays -------------------------------------------------------------------------------------
def _group_mean(rows, key) -> dict:
    groups = {}
    for r in rows:
        groups.setdefault(r[key], []).append(r)
    per = {g: (float(np.mean([r["published_deg"] for r in rs])), float(np.mean([r["captive_deg"] for r in rs])))
           for g, rs in groups.items()}
    return {"published_mean_deg": float(np.mean([p for p, _ in per.values()])),
            "fit_mean_deg": float(np.mean([f for _, f in per.values()])),
            "better": int(sum(f < p for p, f in per.values())), "of": len(per),
            "groups": {g: {"published_mean_deg": p, "fit_mean_deg": f} for g, (p, f) in per.items()}}


def replays(runs, captive_model) -> tuple[list, dict]:
    """Heading RMSE of every run replayed with the published constants and the captive-only model."""
    from .kvlcc2_marin.data import first_rudder_side, regime
    from .kvlcc2_marin.validate import published_replay

    rows, circle = [], {}
    for run in runs:
        pub = published_replay(run)
        cap = replay(captive_model, run.data)
        row = {"run": run.name, "facility": run.facility, "kind": run.kind, "regime": regime(run),
               "direction": first_rudder_side(run), "published_deg": float(pub.errors["psi_rmse_deg"]),
               "captive_deg": float(cap.errors["psi_rmse_deg"])}
        rows.append(row)
        if run.kind == "turning":
            c = {}
            for key in ("advance_m", "tactical_diameter_m"):
                meas = pub.measured_metrics.get(key, np.nan)
                c[key] = {"measured": meas, "published": pub.metrics.get(key, np.nan),
                          "captive": cap.metrics.get(key, np.nan)}
            circle[run.name] = c
    return rows, circle


def _circle_summary(circle) -> dict:
    if not circle:
        return {"advance_pct": None, "tactical_diameter_pct": None}
    out = {}
    for key, name in (("advance_m", "advance_pct"), ("tactical_diameter_m", "tactical_diameter_pct")):
        errs = [100.0 * (c[key]["captive"] / c[key]["measured"] - 1) for c in circle.values()]
        out[name] = float(np.mean(errs))
        out[name.replace("_pct", "_published_pct")] = float(
            np.mean([100.0 * (c[key]["published"] / c[key]["measured"] - 1) for c in circle.values()]))
    out["runs"] = list(circle)
    return out


def lever_structure(tests, fit, runs) -> dict:
    """The captive fit with the loading-dependent rudder lever beside ``fit`` (the constant lever).

    Returns the log-likelihoods and their likelihood-ratio statistic (chi-square with one degree of
    freedom under the constant lever), ``x_HJ_dash`` with its standard and robust errors, the RMS
    residual per group, and with ``runs`` the full-scale captive-only replays of both structures.
    """
    pb = captive_problem(tests, hmri_model(tests, rudder_lever="loading"))
    alt = pb.solve(show=False)
    name = pb.joint_name("x_HJ_dash")
    out = {"status": alt.status, "loglik_constant": fit.loglik, "loglik_loading": alt.loglik,
           "lr_statistic": 2.0 * (alt.loglik - fit.loglik), "lr_critical_1pct": 6.635,
           "x_HJ_dash": alt.estimates[name], "std_error": alt.std_errors[name],
           "std_error_robust": alt.std_errors_robust[name],
           "x_H_dash": {"constant": fit.estimates["x_H_dash"], "loading": alt.estimates["x_H_dash"]},
           "rms_by_group": {g: {"constant": fit.noise["rms"][g], "loading": alt.noise["rms"][g]}
                            for g in fit.noise["rms"]}}
    if runs:
        rows, circle = replays(runs, kvlcc2(shared_estimates(alt), rudder_lever="loading"))
        out["replays_mean_deg"] = float(np.mean([r["captive_deg"] for r in rows]))
        out["circle"] = _circle_summary(circle)
    return out


# -- the study -----------------------------------------------------------------------------------
def run(out: Path, quick: bool = False, workers=None, scheduler=None, data_dir=None) -> dict:
    """Fit the captive tests, compare with the published coefficients, replay the free-running runs."""
    t_start = time.perf_counter()
    out = Path(out)
    folder = data_folder(data_dir, "kvlcc2_hmri_captive", study="kvlcc2-captive", part="the captive fit")
    rep = Report("KVLCC2 MMG coefficients from HMRI captive tests alone", quick=quick)
    if folder is None:
        rep.add("The captive-test folder `kvlcc2_hmri_captive` is absent: nothing was fitted.")
        rep.departures([Departure("data", "HMRI PMM tests", "absent", "no result")])
        rep.write(out)
        return write_json(out / "summary.json", {"skipped": "no captive data"})
    tests = read_captive(folder)
    model = hmri_model(tests)
    pb = captive_problem(tests, model)
    fit = pb.solve(show=False)
    fit.to_json(out / "captive_fit.json")
    published_pred = pb.predictor.predict(model.params())     # the published hull on HMRI's model
    lin = classical_derivatives(pb)

    # coefficients beside the published ones
    rows = {}
    for name in FREE:
        jn = pb.joint_name(name)
        pub = {**KVLCC2_COMMON, **KVLCC2_L7, "delta_0": 0.0}.get(name, np.nan)
        est, se = fit.estimates[jn], fit.std_errors[jn]
        rows[jn] = {"published": pub, "captive": est, "std_error": se, "std_error_robust": fit.std_errors_robust[jn],
                    "z": (est - pub) / se if np.isfinite(pub) and se > 0 else np.nan}
    with open(out / "coefficients.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", "published", "captive", "std_error", "std_error_robust", "z"])
        for n, r in rows.items():
            w.writerow([n, r["published"], r["captive"], r["std_error"], r["std_error_robust"], r["z"]])
    pb.plot(fit, path=out / "fig_forces.png")
    meas = pb.predictor.measured
    gidx = np.array(pb.groups)
    pred = pb.prediction(np.array([fit.estimates[n] for n in pb.free]))
    rms = {g: {"published": float(np.sqrt(np.mean((published_pred - meas)[gidx == g] ** 2))),
               "captive": float(np.sqrt(np.mean((pred - meas)[gidx == g] ** 2)))} for g in pb.group_names}

    # replays of the free-running runs
    runs_folder = data_folder(data_dir, "kvlcc2_marin_free", study="kvlcc2-captive", part="the replays")
    replay_rows, circle, runs = [], {}, []
    if runs_folder is not None:
        from .kvlcc2_marin.data import load_runs

        runs = load_runs(runs_folder.parent)
        if quick:
            runs = [r for r in runs if r.facility == "MARIN"]
        full = kvlcc2(shared_estimates(fit))
        replay_rows, circle = replays(runs, full)
        _replay_figure(out / "fig_replays.png", replay_rows)
    for r in replay_rows:
        r["better"] = r["captive_deg"] < r["published_deg"]
    loro = ({"published_mean_deg": float(np.mean([r["published_deg"] for r in replay_rows])),
             "fit_mean_deg": float(np.mean([r["captive_deg"] for r in replay_rows])),
             "better": int(sum(r["better"] for r in replay_rows)), "of": len(replay_rows)} if replay_rows else None)
    summary = {
        "note": ("captive-only model: no free-running run is used in the fit, so every replay is out of sample; "
                 "loro is the replay of every run, loro_regime / lodo / lofo the same replays averaged per "
                 "regime / first-turn direction / facility (means of the group means)"),
        "loro": loro,
        "loro_regime": _group_mean(replay_rows, "regime") if replay_rows else None,
        "lodo": _group_mean(replay_rows, "direction") if replay_rows else None,
        "lofo": _group_mean(replay_rows, "facility") if replay_rows else None,
        "circle_left_out": _circle_summary(circle),
        "predictive_coverage": None,
        "variants_tried": 2,
        "variants_note": ("1: epsilon free with f_alpha (not separable: near-singular information, so fixed); "
                          "2: the study's set. Decided on the captive fit's information alone, before any replay."),
        "captive": {"n_obs": fit.n_obs, "status": fit.status, "noise_sigma": fit.noise["sigma"],
                    "coefficients": {n: {k: (None if not np.isfinite(v) else v) for k, v in r.items()}
                                     for n, r in rows.items()},
                    "rms_by_group": rms, "linear_derivatives": lin},
        "replays": replay_rows, "circle": circle,
        "rudder_lever": lever_structure(tests, fit, runs),
        "wall_time_s": None,
    }
    _report(rep, out, tests, fit, rows, rms, lin, replay_rows, summary, quick)
    summary["wall_time_s"] = time.perf_counter() - t_start
    return write_json(out / "summary.json", summary)


def _report(rep, out, tests, fit, rows, rms, lin, replay_rows, summary, quick) -> None:
    rep.section("Rule (fixed before any replay)")
    rep.add("Evidence: every static point and every dynamic harmonic component (means left out) of the channels "
            f"{', '.join(CHANNELS)}. Free: the hull polynomial coefficients and added masses ({len(HULL)}), the "
            f"interaction quantities ({', '.join(INTERACTION)}) and HMRI's own {', '.join(OWN)} (as @HMRI). Fixed: "
            "R'_0 at HMRI's resistance test, K_T from its open-water curve, epsilon, kappa, C_1, x'_P published. "
            "Weights: one noise level per group (static/dynamic x channel), estimated with the coefficients; no "
            "prior. Replay model: full-scale KVLCC2 with the captive hull and interaction estimates, the "
            "free-running facilities' propeller, rudder and neutral angle published. Variants tried: "
            f"{summary['variants_tried']} ({summary['variants_note']})")
    rep.section("What was fitted")
    rep.add(f"{fit.n_obs} measured values ({', '.join(CHANNELS)}) of {len(tests.static)} static points and "
            f"{len(tests.dynamic)} PMM tests (dynamic means left out); {len(fit.free)} free quantities; "
            f"status {fit.status} after {fit.iterations} iterations. Notes of the reader: "
            + "; ".join(tests.notes) + ".")
    rep.add("Non-dimensionalisation (established from the data, see docs/data.md): X', Y' = F / (0.5 rho U^2 L^2), "
            "N' = N / (0.5 rho U^2 L^3); the dynamic components include the rigid-body inertia. From the first "
            "harmonics: m'_y = {:.3f} (published 0.223; {:.3f} if the inertia were subtracted), J'_z = {:.4f} "
            "(published 0.011), Y'_v = {:.3f} (PMM) / {:.3f} (static), N'_v = {:.3f} / {:.3f}, N'_r = {:.4f} "
            "(published -0.315, -0.137, -0.049).".format(
                lin["m_y_dash"], lin["m_y_dash_if_inertia_subtracted"], lin["J_z_dash"], lin["Y_v_dash"],
                lin["Y_v_static_dash"], lin["N_v_dash"], lin["N_v_static_dash"], lin["N_r_dash"]))
    rep.section("Coefficients: captive tests alone vs Yasukawa & Yoshimura (2015)")
    rep.add(md_table({n: {"published": fmt(r["published"]), "captive": fmt(r["captive"]),
                          "std error": fmt(r["std_error"], ".2g"), "robust": fmt(r["std_error_robust"], ".2g"),
                          "z": fmt(r["z"], ".2g")} for n, r in rows.items()},
                     first="coefficient"))
    rep.add("`@HMRI`: HMRI's own model quantities (propeller, rudder, neutral angle); not carried to the "
            "free-running models; their published column is the L7 model's (HMRI's workbook gives w = 0.428 and "
            "t = 0.233 at its design point). Standard errors from the information at the estimated noise levels; "
            "robust: sandwich, each value's squared residual in place of its group's level; z = (captive - "
            "published) / std error.")
    rep.section("Residuals per group (RMS, table units)")
    rep.add(md_table({g: {"published": fmt(v["published"], ".3g"), "captive fit": fmt(v["captive"], ".3g")}
                      for g, v in rms.items()}, first="group"))
    rep.image("fig_forces.png", "measured vs model force components per test kind")
    if replay_rows:
        rep.section("Replays of the free-running runs (heading RMSE, deg)")
        rep.add(md_table({r["run"]: {"published": fmt(r["published_deg"], ".3g"),
                                     "captive-only": fmt(r["captive_deg"], ".3g"),
                                     "better": "yes" if r["better"] else "no"} for r in replay_rows}, first="run"))
        lo = summary["loro"]
        rep.add(f"Mean over {lo['of']} runs: published {lo['published_mean_deg']:.2f} deg, captive-only "
                f"{lo['fit_mean_deg']:.2f} deg; better on {lo['better']} of {lo['of']}. Circle: "
                + ", ".join(f"{k} {fmt(v, '.3g')} %" for k, v in summary["circle_left_out"].items() if k != "runs")
                + ".")
        rep.image("fig_replays.png", "heading RMSE per run")
    _lever_report(rep, summary)
    rep.departures([
        Departure("facility", "Yasukawa & Yoshimura's model (NMRI L7)", "HMRI model T530 (L 6.83 m), its own "
                  "propeller, rudder, resistance and open-water curve", "hull coefficients shared; facility "
                  "quantities @HMRI not carried over"),
        Departure("rudder inflow", "epsilon, kappa from the paper", "kept published (epsilon not separable from "
                  "f_alpha in these tests)", "f_alpha@HMRI absorbs it"),
        Departure("dynamic means", "used in a PMM analysis", "left out: the tables' means are referenced to the "
                  "running condition", "Y_vrr, N_vrr from the 2nd harmonics only"),
    ])
    rep.write(out)


def _lever_report(rep, summary) -> None:
    lv = summary["rudder_lever"]
    rep.section("The rudder lever against propeller loading (reported, not adopted)")
    text = (f"With `rudder_lever=\"loading\"` (x'_H + x'_HJ J_P): x'_HJ = {lv['x_HJ_dash']:.3g} +- "
            f"{lv['std_error']:.2g} (robust {lv['std_error_robust']:.2g}), x'_H {lv['x_H_dash']['constant']:.3g} -> "
            f"{lv['x_H_dash']['loading']:.3g}; likelihood-ratio statistic {lv['lr_statistic']:.3g} (1 % point of "
            f"chi-square(1): {lv['lr_critical_1pct']}); static yaw-moment residual RMS "
            f"{fmt(lv['rms_by_group']['static:N']['constant'], '.3g')} -> "
            f"{fmt(lv['rms_by_group']['static:N']['loading'], '.3g')}.")
    if "circle" in lv:
        c = summary["circle_left_out"]
        text += (f" Replayed at full scale: mean heading RMSE {summary['loro']['fit_mean_deg']:.2f} -> "
                 f"{lv['replays_mean_deg']:.2f} deg; circle advance {fmt(c['advance_pct'], '+.1f')} -> "
                 f"{fmt(lv['circle']['advance_pct'], '+.1f')} %, tactical diameter "
                 f"{fmt(c['tactical_diameter_pct'], '+.1f')} -> {fmt(lv['circle']['tactical_diameter_pct'], '+.1f')} %.")
    supported = lv["lr_statistic"] > lv["lr_critical_1pct"]
    text += f" The captive tests {'support' if supported else 'do not support'} the structure at the 1 % level"
    if "circle" in lv:
        closer = abs(lv["circle"]["tactical_diameter_pct"]) < abs(summary["circle_left_out"]["tactical_diameter_pct"])
        text += f"; it brings the circle's tactical diameter {'closer to' if closer else 'further from'} the measured one"
    rep.add(text + " (see docs/identification.md). The study's model keeps the constant lever this round.")


STUDY = Study("kvlcc2-captive", "KVLCC2 MMG coefficients from HMRI captive (PMM) tests alone, beside Yasukawa & "
              "Yoshimura (2015), replaying the shared free-running runs", run, needs_data=True)
