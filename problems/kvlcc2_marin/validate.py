"""Validation of a fold: the fold's fit file replayed on each held-out run, as a user replays it.

Every fold writes the fit file a user gets (:func:`write_fold_file`) and every held-out run is
scored by replaying *that file* with :func:`casship.identify.replay_file`, the function behind
``casship simulate --model kvlcc2 --params FILE --inputs RUN``: the same parameters for every run,
whatever its facility, direction or regime, with the file's covariance giving the prediction bands
and the index intervals. The published constants (:func:`casship.models.kvlcc2`) are replayed
alongside, and both are compared with the measurement: RMS errors of heading, surge speed and
track, and the manoeuvre indices (advance, transfer, tactical diameter; first and second
overshoot) computed by the same functions.
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from casship.io.jsonfile import write_json
from casship.models import kvlcc2
from casship.identify import replay_file
from casship.maneuvers import UNINFORMATIVE_DEG, replay
from casship.plotting import mark_uninformative, view_lines

from .data import Run, per_run
from .workflow import study_model

__all__ = ["ERRORS", "INDICES", "evaluate", "closer", "plot_overlay", "write_fold_file", "SAMPLES", "published_model",
           "published_replay"]

ERRORS = ("psi_rmse_deg", "u_rmse_mps", "position_rmse_m")
INDICES = {"turning": ("advance_m", "transfer_m", "tactical_diameter_m"),
           "zigzag": ("overshoot_1_deg", "overshoot_2_deg")}
SAMPLES = 40                       # parameter draws per replay for the index intervals


def write_fold_file(fold, path: Path, uncertainty=None, extra=None, facility: str | None = None) -> Path:
    """Write the fold's fit as the fit file a user gets, for replaying runs of ``facility``.

    The file's parameters are the fit's with the facility quantities (the neutral angle) of
    ``facility`` when the training had a value for it, else their population values; its covariance
    is ``uncertainty`` when given, else the robust (sandwich) covariance of the refinement and the
    mirror-pair stage with each facility quantity's standard error (or the population value's with
    the between-facility spread) beside it (:meth:`casship.identify.ShipFit.uncertainty`). It also
    says which asymmetry it carries and from which evidence (key ``"asymmetry"``), and the entries
    of ``extra``.
    """
    return fold.ship.to_json(path, facility, uncertainty, {"asymmetry": fold.asymmetry_record(), **(extra or {})})


@functools.cache
def published_model():
    """The published KVLCC2 (:func:`casship.models.kvlcc2`), built once per process."""
    return kvlcc2()


def published_replay(run: Run):
    """``run`` replayed with the published constants, once per process and run (see :func:`.data.per_run`)."""
    return per_run(("published replay",), run, lambda: replay(published_model(), run.data))


def evaluate(run: Run, fit_file: Path, *, published=None, seed: int = 0) -> dict:
    """Replay ``run`` with the published constants (``published``: another model) and with the fit
    file (on the study's model variant, which the file names); errors, indices, bands."""
    pub = published_replay(run) if published is None else replay(published, run.data)
    fit = replay_file(fit_file, run.data, study_model(), samples=SAMPLES, seed=seed)
    row = {"run": run.name, "facility": run.facility, "kind": run.kind, "fit_file": Path(fit_file).name}
    for key in ERRORS:
        row[f"{key}_published"] = pub.errors.get(key, np.nan)
        row[f"{key}_fit"] = fit.errors.get(key, np.nan)
    for key in INDICES[run.kind]:
        row[f"{key}_published"] = pub.metrics.get(key, np.nan)
        row[f"{key}_fit"] = fit.metrics.get(key, np.nan)
        row[f"{key}_measured"] = pub.measured_metrics.get(key, np.nan)
        lo, hi = fit.metric_intervals.get(key, (np.nan, np.nan))
        row[f"{key}_fit_lo"], row[f"{key}_fit_hi"] = lo, hi
    band = fit.band_summary()
    row["psi_band_coverage"] = band.get("psi_coverage", np.nan)
    row["psi_band_halfwidth_max_deg"] = band.get("psi_halfwidth_max_deg", np.nan)
    row["psi_better"] = bool(row["psi_rmse_deg_fit"] < row["psi_rmse_deg_published"])
    row["indices_closer"] = closer(row, run.kind)
    return {"row": row, "published": pub.trajectory, "fit": fit.trajectory, "bands": fit.bands}


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


def plot_overlay(axes, run: Run, published, fit, title: str, bands=None) -> None:
    """Track and heading of the measured run, the published replay and the fit's replay (with its
    prediction band when given)."""
    ax1, ax2 = axes
    d = run.data
    ax1.plot(d["y"], d["x"], "k-", lw=1.2, label=f"measured ({run.facility})")
    ax1.plot(published["y"], published["x"], "C1--", lw=1, label="published constants")
    ax1.plot(fit["y"], fit["x"], "C0-", lw=1, label="fit (run not in training)")
    ax1.set_xlabel("East y [m]")
    ax1.set_ylabel("North x [m]")
    ax1.set_aspect("equal", adjustable="datalim")
    ax2.plot(d.t, np.degrees(np.unwrap(d["psi"])), "k-", lw=1.2, label="measured")
    ax2.plot(published.t, np.degrees(published["psi"]), "C1--", lw=1, label="published")
    ax2.plot(fit.t, np.degrees(fit["psi"]), "C0-", lw=1, label="fit")
    east = [d["y"], published["y"], fit["y"]]
    north = [d["x"], published["x"], fit["x"]]
    times = [d.t, published.t, fit.t, d.t]
    headings = [np.degrees(np.unwrap(d["psi"])), np.degrees(published["psi"]), np.degrees(fit["psi"]),
                np.degrees(d["delta"])]
    if bands:
        z, psi = bands["z"], np.degrees(np.unwrap(fit["psi"]))
        w = np.degrees(z * bands["psi_std"])
        ax2.fill_between(fit.t, psi - w, psi + w, color="C0", alpha=0.25, lw=0,
                         label=f"{100 * bands['level']:.0f} % band")
        mark_uninformative(ax2, fit.t, w, UNINFORMATIVE_DEG)
        off = z * bands["cross_track_std"][:, None] * bands["normal"]
        keep = w <= UNINFORMATIVE_DEG            # the view holds the band where it says something
        for sign in (-1, 1):
            ax1.plot(fit["y"] + sign * off[:, 1], fit["x"] + sign * off[:, 0], "C0-", lw=0.5, alpha=0.6)
            east.append(np.asarray(fit["y"])[keep] + sign * off[keep, 1])
            north.append(np.asarray(fit["x"])[keep] + sign * off[keep, 0])
            times.append(np.asarray(fit.t)[keep])
            headings.append(psi[keep] + sign * w[keep])
    view_lines(ax1, east, north, min_span=(100.0, 100.0))
    view_lines(ax2, times, headings, min_span=(0.0, 10.0))
    ax1.legend(fontsize=7)
    ax2.plot(d.t, np.degrees(d["delta"]), "k:", lw=0.8, label="rudder [deg]")
    ax2.set_xlabel("t [s]")
    ax2.set_ylabel("heading [deg]")
    ax2.set_title(title, fontsize=9, y=1.0)               # placed, not searched for (no ticks on top)
    ax2.legend(fontsize=7)
