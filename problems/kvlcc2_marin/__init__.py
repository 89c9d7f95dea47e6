"""KVLCC2 MMG hull/rudder parameters identified from the MARIN free-running runs, cross-validated.

Data: the three MARIN free-running runs of the KVLCC2 (SIMMAN 2008, full scale, read by
:func:`casship.io.read_marin`, rudder sign flipped to the MMG convention): 35 deg turning circle,
10/10 and 20/20 zig-zags.

Method: output-error identification (:class:`casship.OutputErrorProblem`, exact derivatives, IPOPT)
of a subset of the parameters of :func:`casship.models.kvlcc2`, starting from the published values
(Yasukawa & Yoshimura 2015): the rudder flow-straightening coefficients ``gamma_R_minus``,
``gamma_R_plus`` (they set how much rudder force the ship gets at a given drift and yaw rate), the
straight-run resistance ``R_0_dash`` and the surge coupling ``X_vr_dash`` (speed loss in turns).
The outputs compared are the surge speed ``u`` and the yaw rate ``r``; the recorded sway speed is
left out because the files do not state its reference point (see the data README), and the heading
is left to the validation because its simulated error accumulates over the run.

A second fit on the headline fold maximises the likelihood through an EKF (:class:`casship.MLEProblem`,
u, r and heading measured, noise variances estimated; full study only).

Cross-validation: fit on two runs (decimated), predict the third by replaying its measured rudder and
propeller rate at full rate from its measured initial state (:func:`casship.validation.replay`);
RMS errors of heading, position and speed before (published values) and after the fit. The fold
that holds out the 20/20 zig-zag is the headline; its fit is written to ``fit.json``, readable by
``casship simulate --model kvlcc2 --params fit.json``. All folds are reported, including any where the fit
does not generalise.

Outputs: ``cross_validation.md``, ``fit.json`` (and ``fit_without_<run>.json`` per fold, ``fit_ml_ekf.json``),
``fig_heldout_<run>.png``, ``fig_fit_residuals.png``, ``summary.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

import casship as cs
from casship.io import marin_runs, read_marin
from casship.progress import progress
from casship.validation import replay

from .. import DATA_DIR, Study

FREE = ["gamma_R_minus", "gamma_R_plus", "R_0_dash", "X_vr_dash"]
FREE_QUICK = FREE  # quick mode: same parameters, coarser data, one fold
MEASURED = ["u", "r"]
SIGMA = {"u": 0.05, "r": float(np.radians(0.05))}
HEADLINE = "zz_-20"
ML_MEASURED = ["u", "r", "psi"]
ML_Q = [1e-5, 1e-5, 1e-9]                                            # starting values (estimated)
ML_R = [0.01**2, float(np.radians(0.02)) ** 2, float(np.radians(0.1)) ** 2]
ERRORS = ("psi_rmse_deg", "position_rmse_m", "u_rmse_mps")


def _decimate(data, step: int):
    idx = np.arange(0, len(data), step)
    return cs.Dataset(data.t[idx], {n: data[n][idx] for n in data.names}, data.units, data.meta)


def _plot_heldout(path, name, data, before, after):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(14, 4.2))
    ax1.plot(data["y"], data["x"], "k-", lw=1.2, label="measured (MARIN)")
    ax1.plot(before["y"], before["x"], "C1--", lw=1, label="published parameters")
    ax1.plot(after["y"], after["x"], "C0-", lw=1, label="identified")
    ax1.set_xlabel("East y [m]")
    ax1.set_ylabel("North x [m]")
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.legend(fontsize=8)
    for ax, key, scale, label in ((ax2, "psi", np.degrees, "heading [deg]"), (ax3, "u", lambda v: v, "u [m/s]")):
        meas = np.unwrap(data[key]) if key == "psi" else data[key]
        ax.plot(data.t, scale(meas), "k-", lw=1.2, label="measured")
        ax.plot(before.t, scale(before[key]), "C1--", lw=1, label="published")
        ax.plot(after.t, scale(after[key]), "C0-", lw=1, label="identified")
        ax.set_xlabel("t [s]")
        ax.set_ylabel(label)
    fig.suptitle(f"KVLCC2 run {name} replayed (not used in the fit)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def cross_validate(runs: dict, held: str, free, decimate: int, model=None) -> dict:
    """Fit on every run but ``held`` and replay ``held`` before and after."""
    model = model or cs.models.get_model("kvlcc2")
    train = {k: _decimate(d, decimate) for k, d in runs.items() if k != held}
    prob = cs.OutputErrorProblem(model, list(train.values()), free, measured=MEASURED, sigma=SIGMA)
    fit = prob.solve()
    before = replay(model, runs[held])
    after = replay(model, runs[held], fit.params)
    train_err = {k: {"before": replay(model, runs[k]).errors, "after": replay(model, runs[k], fit.params).errors}
                 for k in train}
    return {"held": held, "train": list(train), "fit": fit, "before": before, "after": after,
            "train_errors": train_err}


def ml_fit(runs: dict, held: str, free, decimate: int, model=None) -> dict:
    """Maximum likelihood through an EKF (u, r, heading measured; noise variances estimated) on every
    run but ``held``, and the replay of ``held`` with the result."""
    model = model or cs.models.get_model("kvlcc2")
    train = [_decimate(d, decimate) for k, d in runs.items() if k != held]
    train = [d.with_columns(psi=cs.wrap(d["psi"])) for d in train]   # the files hold a continuous heading
    dt = float(np.median(np.diff(train[0].t)))
    ekf = cs.EKF(cs.discretize(model, dt), Q=ML_Q, R=ML_R, measured=ML_MEASURED)
    fit = cs.MLEProblem(ekf, train, free, noise={"Q": True, "R": True}).solve()
    return {"fit": fit, "after": replay(model, runs[held], fit.params)}


def run(out: Path, quick: bool = False, workers=None, scheduler=None, data_dir: Path | None = None) -> dict:
    out = Path(out)
    folder = Path(data_dir or DATA_DIR) / "kvlcc2_marin_free"
    files = marin_runs(folder)
    if not files:
        raise FileNotFoundError(f"no MARIN runs in {folder}")
    runs = {k: read_marin(p) for k, p in files.items()}
    if HEADLINE not in runs:
        raise FileNotFoundError(f"the 20/20 zig-zag run ({HEADLINE}) is missing in {folder}")
    free = FREE_QUICK if quick else FREE
    decimate = 40 if quick else 20
    folds = [HEADLINE] if quick else [HEADLINE] + [k for k in runs if k != HEADLINE]
    model = cs.models.get_model("kvlcc2")
    results = []
    for held, _ in zip(folds, progress(folds, "kvlcc2-marin folds")):
        res = cross_validate(runs, held, free, decimate, model)
        results.append(res)
        res["fit"].to_json(out / f"fit_without_{held}.json")
        _plot_heldout(out / f"fig_heldout_{held}.png", held, runs[held], res["before"].trajectory,
                      res["after"].trajectory)
    head = results[0]
    ml = None
    if not quick:
        ml = ml_fit(runs, HEADLINE, free, decimate, model)
        ml["fit"].to_json(out / "fit_ml_ekf.json")
    head["fit"].to_json(out / "fit.json")
    head["fit"].plot(out / "fig_fit_residuals.png")

    lines = ["# KVLCC2 MMG parameters from the MARIN free-running runs", "",
             f"Output-error fit of {', '.join(free)} to {', '.join(MEASURED)} (every {decimate}th sample, "
             f"{'quick mode' if quick else 'full study'}); held-out run replayed at full rate.", "",
             "## Cross-validation (held-out run, RMS errors)", "",
             "| held out | trained on | heading [deg] before -> after | position [m] before -> after | "
             "u [m/s] before -> after |", "|---|---|---|---|---|"]
    summary_folds = {}
    for res in results:
        b, a = res["before"].errors, res["after"].errors
        lines.append(f"| {res['held']} | {', '.join(res['train'])} | " + " | ".join(
            f"{b[k]:.3g} -> {a[k]:.3g}" for k in ERRORS) + " |")
        if ml is not None and res is head:
            a = ml["after"].errors
            lines.append(f"| {res['held']} (ML through EKF) | {', '.join(res['train'])} | " + " | ".join(
                f"{b[k]:.3g} -> {a[k]:.3g}" for k in ERRORS) + " |")
        summary_folds[res["held"]] = {"trained_on": res["train"], "before": b, "after": a,
                                      "train_errors": res["train_errors"],
                                      "estimates": res["fit"].estimates, "std_errors": res["fit"].std_errors,
                                      "whiteness": res["fit"].whiteness, "warnings": res["fit"].warnings}
    lines += ["", "## Estimates (headline fold, held out: " + HEADLINE + ")", "",
              "| parameter | published | estimate | std error |", "|---|---:|---:|---:|"]
    nominal = model.param_dict()
    for k in free:
        lines.append(f"| {k} | {nominal[k]:.4g} | {head['fit'].estimates[k]:.4g} | {head['fit'].std_errors[k]:.2g} |")
    lines += ["", "Estimates across folds:", "", "| parameter | " + " | ".join(f"without {r['held']}" for r in results)
              + " |", "|---|" + "---:|" * len(results)]
    for k in free:
        lines.append(f"| {k} | " + " | ".join(f"{r['fit'].estimates[k]:.4g} ± {r['fit'].std_errors[k]:.2g}"
                                              for r in results) + " |")
    white = {n: w["p_value"] for n, w in head["fit"].whiteness.items()}
    lines += ["", "The standard errors assume white output errors; the Ljung-Box p-values of the headline fit's "
              f"residuals ({', '.join(f'{n}: {p:.2g}' for n, p in white.items())}) show they are not "
              "(model-structure error), so the spread of the estimates across folds is the more honest "
              "uncertainty.", ""]
    if head["fit"].warnings:
        lines += ["Warnings of the headline fit:", ""] + [f"- {w}" for w in head["fit"].warnings] + [""]
    (out / "cross_validation.md").write_text("\n".join(lines))
    if ml is not None:
        lines += ["## Maximum likelihood through an EKF (headline fold)", "",
                  f"Measured {', '.join(ML_MEASURED)}; process and measurement noise variances estimated too. "
                  "It fits one-step predictions rather than the simulated run, yet improves the replay of the "
                  "held-out run as well (table above).", "", "```", ml["fit"].summary(), "```", ""]
        (out / "cross_validation.md").write_text("\n".join(lines))
    hb, ha = head["before"].errors, head["after"].errors
    return {"study": "kvlcc2-marin", "quick": quick, "free": free, "measured": MEASURED, "decimate": decimate,
            "headline_held_out": HEADLINE, "headline_before": hb, "headline_after": ha,
            "headline_improved": bool(all(ha[k] < hb[k] for k in ERRORS)), "folds": summary_folds,
            "fit_json": str(out / "fit.json"),
            "ml_ekf": None if ml is None else {"after": ml["after"].errors, "estimates": ml["fit"].estimates,
                                               "std_errors": ml["fit"].std_errors,
                                               "iterations": ml["fit"].iterations}}


STUDY = Study("kvlcc2-marin", "KVLCC2 MMG parameters fitted to MARIN free-running runs, cross-validated", run,
              needs_data=True)
