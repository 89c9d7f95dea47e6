"""Validation of a fold: replay a held-out run with the published constants and with the fit.

Each held-out run is replayed at its full rate (:func:`casship.validation.replay`: measured rudder
and propeller rate, measured initial state) with

* the **published** constants: :func:`casship.models.kvlcc2` as published (no propulsion trim), and
* the **fit** of the fold that did not see the run (its facility's asymmetry copies, or their mean
  for a facility left out of training),

and compared with the measurement: RMS errors of heading, surge speed and track, and the manoeuvre
indices of the replayed and measured runs computed by the same functions (advance, transfer and
tactical diameter of a turning circle; first and second overshoot of a zig-zag).
"""
from __future__ import annotations

import numpy as np

from casship.models import kvlcc2
from casship.validation import replay

from .data import Run
from .workflow import params_for, study_model

__all__ = ["ERRORS", "INDICES", "evaluate", "closer", "plot_overlay"]

ERRORS = ("psi_rmse_deg", "u_rmse_mps", "position_rmse_m")
INDICES = {"turning": ("advance_m", "transfer_m", "tactical_diameter_m"),
           "zigzag": ("overshoot_1_deg", "overshoot_2_deg")}


def evaluate(run: Run, fold, *, published=None) -> dict:
    """Replay ``run`` with the published constants and with ``fold``'s fit; errors and indices."""
    pub = replay(published or kvlcc2(), run.data)
    model = study_model()
    fit = replay(model, run.data, model.params(params_for(fold, run.facility)))
    row = {"run": run.name, "facility": run.facility, "kind": run.kind}
    for key in ERRORS:
        row[f"{key}_published"] = pub.errors.get(key, np.nan)
        row[f"{key}_fit"] = fit.errors.get(key, np.nan)
    for key in INDICES[run.kind]:
        row[f"{key}_published"] = pub.metrics.get(key, np.nan)
        row[f"{key}_fit"] = fit.metrics.get(key, np.nan)
        row[f"{key}_measured"] = pub.measured_metrics.get(key, np.nan)
    row["psi_better"] = bool(row["psi_rmse_deg_fit"] < row["psi_rmse_deg_published"])
    row["indices_closer"] = closer(row, run.kind)
    return {"row": row, "published": pub.trajectory, "fit": fit.trajectory}


def closer(row: dict, kind: str) -> bool:
    """Every index of the fit at least as close to the measured one as the published index (an
    index the replay does not reach counts as not closer)."""
    for key in INDICES[kind]:
        meas, pub, fit = row[f"{key}_measured"], row[f"{key}_published"], row[f"{key}_fit"]
        if not np.isfinite(meas):
            continue
        if not np.isfinite(fit):
            return False
        if np.isfinite(pub) and abs(fit - meas) > abs(pub - meas):
            return False
    return True


def plot_overlay(axes, run: Run, published, fit, title: str) -> None:
    """Track and heading of the measured run, the published replay and the fit's replay."""
    ax1, ax2 = axes
    d = run.data
    ax1.plot(d["y"], d["x"], "k-", lw=1.2, label=f"measured ({run.facility})")
    ax1.plot(published["y"], published["x"], "C1--", lw=1, label="published constants")
    ax1.plot(fit["y"], fit["x"], "C0-", lw=1, label="fit (run not in training)")
    ax1.set_xlabel("East y [m]")
    ax1.set_ylabel("North x [m]")
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.legend(fontsize=7)
    ax2.plot(d.t, np.degrees(np.unwrap(d["psi"])), "k-", lw=1.2, label="measured")
    ax2.plot(published.t, np.degrees(published["psi"]), "C1--", lw=1, label="published")
    ax2.plot(fit.t, np.degrees(fit["psi"]), "C0-", lw=1, label="fit")
    ax2.plot(d.t, np.degrees(d["delta"]), "k:", lw=0.8, label="rudder [deg]")
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("heading [deg]")
    ax2.set_title(title, fontsize=9)
    ax2.legend(fontsize=7)
