"""Replay validation: simulate a model with the measured inputs of a record and compare.

:func:`replay` starts the model from the measured initial state, drives it with the measured
inputs (zero-order hold on the record's time stamps) and reports the root-mean-square errors of
heading (wrapped differences), position and surge speed, plus the manoeuvre metrics of the
replayed run and of the measurement, computed by the same functions of :mod:`casship.maneuvers.metrics`.
Given the parameters' uncertainty, it also carries prediction bands on heading and track (exact
sensitivities, :mod:`casship.simulation.bands`) and intervals on the indices (parameter draws).

:func:`casship.identify.replay_file` is *the* replay of a fit file (through :func:`replay`): what ``casship
simulate --params FILE --inputs RUN`` prints, what the studies' cross-validation scores and what the tests check.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..angles import wrap
from ..data import Dataset
from ..trajectory import Trajectory
from .metrics import execute_time, turning_metrics, zigzag_metrics
from ..model import Model
from ..simulation import prediction_bands, sampled_metrics, simulate, simulate_many, trajectory_sensitivities
from ..errors import InputError

__all__ = ["replay", "ReplayResult", "classify_maneuver", "maneuver_metrics", "why_absent", "COVERAGE_SLACK",
           "UNINFORMATIVE_DEG"]

#: A heading band whose coverage of the measured heading falls more than this below its level is flagged.
COVERAGE_SLACK = 0.15
#: A heading band half-width [deg] beyond which a linearised band says nothing: past a quarter turn
#: either side the first-order propagation of the parameters' uncertainty no longer describes the
#: spread of replays, and covering the measured heading is no evidence of calibration.
UNINFORMATIVE_DEG = 90.0


@dataclass
class ReplayResult:
    """Result of :func:`replay`.

    Parameters
    ----------
    trajectory : Trajectory
        The replayed simulation on the record's time stamps.
    errors : dict
        ``psi_rmse_deg``, ``position_rmse_m``, ``u_rmse_mps`` (keys present when the record
        holds the columns).
    metrics, measured_metrics : dict
        Manoeuvre metrics of the replayed run and of the record (same functions, same execute).
    kind : str
        ``"turning"``, ``"zigzag"`` or ``"other"`` (from :func:`classify_maneuver`).
    measured : Dataset, optional
        The record replayed (for :meth:`plot`).
    bands : dict
        With a parameter uncertainty: per sample ``psi_std`` [rad], ``x_std``, ``y_std``,
        ``cross_track_std`` [m] (linearised, exact sensitivities), ``level`` and ``z``; and
        ``coverage``: the fraction of the measured heading inside the band. With a model-discrepancy
        term (:attr:`~casship.identify.ParameterBelief.psi_variance_rate` ``q``; 0 when the file carries none)
        also the predictive heading band ``psi_std_predictive = sqrt(psi_std^2 + q t)`` (the same
        covariance, so never narrower than the parameter band), ``psi_variance_rate`` and its
        ``coverage_predictive``.
    metric_intervals : dict
        With a parameter uncertainty: index -> ``[lo, hi]`` at ``bands["level"]`` from parameter
        draws.
    sampling : dict
        The number of draws, failures and the sampled/linearised ratio of the heading spread (a
        check of the linearisation).
    start : dict
        Where each state's initial value came from: ``"record"`` (its column's first row),
        ``"zero"`` (no such column) or ``"x0"`` (given).
    not_compared : list of str
        Columns of the record that the replay cannot be compared with, the model having no such
        state or output (``x, y, u`` of a Nomoto model).
    metric_notes : dict
        Metric -> why it is missing on one side (``"measured: ..."`` or ``"replayed: ..."``): the
        manoeuvre did not reach it in that record (:func:`why_absent`), or its metrics could not be
        taken at all (the reason the metric function gave).
    """

    trajectory: Trajectory
    errors: dict
    metrics: dict = field(default_factory=dict)
    measured_metrics: dict = field(default_factory=dict)
    kind: str = "other"
    measured: Dataset | None = field(default=None, repr=False)
    bands: dict = field(default_factory=dict, repr=False)
    metric_intervals: dict = field(default_factory=dict)
    sampling: dict = field(default_factory=dict)
    start: dict = field(default_factory=dict)
    not_compared: list = field(default_factory=list)
    metric_notes: dict = field(default_factory=dict)

    def band_summary(self) -> dict:
        """Scalar summary of the bands (JSON-friendly): level, largest and final half-widths of the
        heading [deg] and cross-track [m] bands, and the measured heading's coverage."""
        if not self.bands:
            return {}
        z = self.bands["z"]
        out = {"level": self.bands["level"], "source": self.bands.get("source", "")}
        if "psi_std" in self.bands:
            w = np.degrees(z * self.bands["psi_std"])
            out.update(psi_halfwidth_max_deg=float(w.max()), psi_halfwidth_end_deg=float(w[-1]))
        if "cross_track_std" in self.bands:
            w = z * self.bands["cross_track_std"]
            out.update(cross_track_halfwidth_max_m=float(w.max()), cross_track_halfwidth_end_m=float(w[-1]))
        if "coverage" in self.bands:
            out["psi_coverage"] = self.bands["coverage"]
        if "psi_std_predictive" in self.bands:
            w = np.degrees(z * self.bands["psi_std_predictive"])
            out.update(psi_predictive_halfwidth_max_deg=float(w.max()), psi_predictive_halfwidth_end_deg=float(w[-1]),
                       psi_discrepancy_deg2_per_s=float(np.degrees(np.degrees(self.bands.get("psi_variance_rate", 0.0)))))
            if "coverage_predictive" in self.bands:
                out["psi_predictive_coverage"] = self.bands["coverage_predictive"]
        return out

    def coverage_notes(self) -> list[str]:
        """Warnings, as text, for a heading band whose coverage of the measured heading falls more than
        :data:`COVERAGE_SLACK` below its nominal level, or that is wider than :data:`UNINFORMATIVE_DEG`
        (a band that does not mean what it says)."""
        if not self.bands:
            return []
        level, notes = self.bands["level"], []
        q = self.bands.get("psi_variance_rate", 0.0)
        for key, what, why in (("coverage", "parameter band", "it carries the parameters' uncertainty only, see "
                                                               "the predictive band"),
                               ("coverage_predictive", "predictive band",
                                "the file carries no model discrepancy (q = 0)" if q == 0 else
                                f"its model discrepancy q = {np.degrees(np.degrees(q)):.3g} deg^2/s is too small for "
                                "this record")):
            c = self.bands.get(key)
            if c is not None and np.isfinite(c) and c < level - COVERAGE_SLACK:
                notes.append(f"the {100 * level:.0f} % {what} covers {100 * c:.0f} % of the measured heading: far "
                             f"below its nominal {100 * level:.0f} %; {why}")
        halfwidth = self._heading_halfwidth()
        if halfwidth is not None:
            wide = halfwidth > UNINFORMATIVE_DEG
            if wide.any():
                t = np.asarray(self.trajectory.t)
                t0 = float(t[int(np.argmax(wide))] - t[0])
                notes.append(f"the {100 * level:.0f} % heading band is wider than +-{UNINFORMATIVE_DEG:.0f} deg from "
                             f"{t0:.0f} s of {float(t[-1] - t[0]):.0f} s ({100 * float(np.mean(wide)):.0f} % of the "
                             "record): there the linearised band says nothing, and its coverage is no evidence; "
                             "the parameters' uncertainty does not bound this replay")
        return notes

    def __repr__(self) -> str:
        errors = ", ".join(f"{k}={v:.3g}" for k, v in self.errors.items())
        return (f"ReplayResult({self.trajectory.model_name!r}, {self.kind}, N={len(self.trajectory)}, "
                f"{errors})")

    def start_notes(self) -> list[str]:
        """Where the replay started from, and the record's columns it is not compared with, as text."""
        notes = []
        for source, words in (("record", "from the record's first row"), ("zero", "at zero (no column)"),
                              ("x0", "given")):
            names = [n for n, s in self.start.items() if s == source]
            if names:
                notes.append(f"initial {', '.join(names)} {words}")
        if self.not_compared:
            notes.append(f"not compared (the model has no such state or output): {', '.join(self.not_compared)}")
        return notes

    def summary(self) -> str:
        """The replay errors and the metrics of replay and record side by side, as text.

        Returns
        -------
        str
        """
        tr = self.trajectory
        lines = [f"replay of {self.measured.meta.get('source', 'a record') if self.measured is not None else 'a record'}"
                 f" with {tr.model_name!r}: {self.kind}, {len(tr)} samples over {tr.t[-1] - tr.t[0]:.4g} s"]
        lines += [f"  {k:28s} {v:12.4f}" for k, v in self.errors.items()]
        lines += [f"  {line}" for line in self.start_notes()]
        keys = [k for k in self.metrics if k in self.measured_metrics and isinstance(self.metrics[k], float)]
        if keys:
            iv = self.metric_intervals
            lines.append(f"  {'metric':28s} {'replayed':>12s} {'measured':>12s}"
                         + (f"  {100 * self.bands['level']:.0f} % interval" if iv else ""))
            lines += [f"  {k:28s} {self.metrics[k]:12.2f} {self.measured_metrics[k]:12.2f}"
                      + (f"  [{iv[k][0]:.2f}, {iv[k][1]:.2f}]" if k in iv else "") for k in keys]
        lines += [f"  {k:28s} not compared: {why}" for k, why in self.metric_notes.items()]
        for k, v in self.band_summary().items():
            lines.append(f"  band {k:23s} {v}" if isinstance(v, str) else f"  band {k:23s} {v:12.4g}")
        lines += [f"  warning: {note}" for note in self.coverage_notes()]
        return "\n".join(lines)

    def plot(self, ax=None, path=None):
        """Track, heading, surge speed and rudder of the replay against the record.

        Parameters
        ----------
        ax : four matplotlib Axes, optional
            Draw into these axes (track, heading, speed, rudder) instead of a new figure.
        path : str or Path, optional
            Also write the figure there (PNG unless the suffix says otherwise).

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting`.
        """
        from ..plotting import finish, panels, split_args, view_lines

        ax, path = split_args(ax, path)
        given = ax
        tr, data = self.trajectory, self.measured
        fig, axes = panels(ax, 2, 2, figsize=(11, 7), what="the replay plot")
        track, heading, speed, rudder = axes.ravel()
        if "x" in tr and "y" in tr:
            track.plot(tr["y"], tr["x"], label="replayed")
        heading.plot(tr.t, np.degrees(np.unwrap(tr["psi"])), label="replayed")
        if self.bands:
            self._draw_bands(track, heading)
        if "u" in tr:
            speed.plot(tr.t, tr["u"], label="replayed")
        if data is not None:
            if "x" in data and "y" in data:
                track.plot(data["y"], data["x"], "--", label="measured")
            if "psi" in data:
                heading.plot(data.t, np.degrees(np.unwrap(data["psi"])), "--", label="measured")
            if "u" in data:
                speed.plot(data.t, data["u"], "--", label="measured")
        for name in tr.input_names:
            if name.startswith("delta"):
                rudder.plot(tr.t, np.degrees(tr[name]), label=f"{name}")
        lines = [ln for ln in (tr, data) if ln is not None]
        headings = [ln for ln in lines if "psi" in ln]
        tracks = [ln for ln in lines if "x" in ln and "y" in ln]
        ht = [ln.t for ln in headings]
        hy = [np.degrees(np.unwrap(ln["psi"])) for ln in headings]
        ty, tx = [ln["y"] for ln in tracks], [ln["x"] for ln in tracks]
        for t, edges, east, north in self._informative_band_edges():     # in view where the band says something
            ht += [t, t]
            hy += edges
            ty += east
            tx += north
        view_lines(heading, ht, hy, min_span=(0.0, 10.0))
        view_lines(track, ty, tx, min_span=(100.0, 100.0))
        track.set(xlabel="East y [m]", ylabel="North x [m]", title="track")
        track.set_aspect("equal", adjustable="datalim")
        heading.set(xlabel="time [s]", ylabel="heading psi [deg]")
        speed.set(xlabel="time [s]", ylabel="surge speed u [m/s]")
        rudder.set(xlabel="time [s]", ylabel="rudder angle [deg]")
        for ax in axes.ravel():
            ax.grid(alpha=0.3)
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=8)
        if given is None:
            fig.suptitle(f"replay of the measured inputs with {tr.model_name!r} ({self.kind})")
        return finish(fig, given, path)


    def _heading_halfwidth(self):
        """The widest heading band's half-width [deg] per sample (the predictive band where there is one), or None."""
        b = self.bands
        std = b.get("psi_std_predictive", b.get("psi_std")) if b else None
        return None if std is None else np.degrees(b["z"] * np.asarray(std))

    def _informative_band_edges(self) -> list:
        """The band edges where the heading band is at most :data:`UNINFORMATIVE_DEG` wide: ``[(t, [lower,
        upper heading], [two East], [two North])]`` (empty without bands)."""
        b, tr = self.bands, self.trajectory
        w = self._heading_halfwidth()
        if w is None:
            return []
        keep = w <= UNINFORMATIVE_DEG
        psi = np.degrees(np.unwrap(tr["psi"]))[keep]
        east, north = [], []
        if "cross_track_std" in b and "x" in tr and "y" in tr:
            off = b["z"] * b["cross_track_std"][:, None] * b["normal"]
            east = [np.asarray(tr["y"])[keep] + s * off[keep, 1] for s in (-1, 1)]
            north = [np.asarray(tr["x"])[keep] + s * off[keep, 0] for s in (-1, 1)]
        return [(np.asarray(tr.t)[keep], [psi - w[keep], psi + w[keep]], east, north)]

    def _draw_bands(self, track, heading) -> None:
        from ..plotting import mark_uninformative

        tr, b, z = self.trajectory, self.bands, self.bands["z"]
        label = f"{100 * b['level']:.0f} % band"
        if "psi_std" in b:
            psi = np.degrees(np.unwrap(tr["psi"]))
            w = np.degrees(z * b["psi_std"])
            heading.fill_between(tr.t, psi - w, psi + w, color="C0", alpha=0.25, lw=0,
                                 label=label + (" (parameters)" if b.get("psi_variance_rate", 0.0) > 0 else ""))
            if "psi_std_predictive" in b and b.get("psi_variance_rate", 0.0) > 0:     # dashed edges
                w = np.degrees(z * b["psi_std_predictive"])
                for sign in (-1, 1):
                    heading.plot(tr.t, psi + sign * w, color="C0", lw=0.8, ls="--",
                                 label=f"{100 * b['level']:.0f} % predictive band (with model discrepancy)"
                                 if sign > 0 else None)
            mark_uninformative(heading, tr.t, w, UNINFORMATIVE_DEG)
        if "cross_track_std" in b:
            w = z * b["cross_track_std"][:, None] * b["normal"]
            for sign in (-1, 1):
                track.plot(tr["y"] + sign * w[:, 1], tr["x"] + sign * w[:, 0], color="C0", lw=0.6, alpha=0.6,
                           label=label if sign > 0 else None)


def classify_maneuver(data: Dataset, rudder: str = "delta") -> tuple[str, dict]:
    """Guess the manoeuvre of a record from its rudder and heading.

    A rudder that reverses sign at least twice (beyond half its largest deflection) is a
    zig-zag, whose switch heading is the heading change when the rudder leaves its first side,
    snapped to a multiple of 5 deg if within 1.5 deg (else rounded to a whole degree); a record
    turning through more than 180 deg otherwise is a turning circle.

    Parameters
    ----------
    data : Dataset
        Record with the rudder column and ``psi``.
    rudder : str
        Name of the rudder column.

    Returns
    -------
    (kind, options)
        ``("zigzag", {"heading_deg": h})``, ``("turning", {})`` or ``("other", {})``.
    """
    if rudder not in data or "psi" not in data:
        return "other", {}
    d = np.asarray(data[rudder]) - data[rudder][0]
    big = np.abs(d) > 0.5 * np.abs(d).max()
    if not big.any():
        return "other", {}
    signs = np.sign(d[big])
    reversals = np.flatnonzero(np.diff(signs) != 0)
    psi = np.unwrap(np.asarray(data["psi"], dtype=float))
    t_exec = execute_time(data, rudder)
    psi0 = float(np.interp(t_exec, data.t, psi))
    if reversals.size >= 2:
        # the rudder leaves its first side when the heading change reaches the switch angle
        first = np.flatnonzero(big)[0]
        cross = np.flatnonzero(big)[reversals[0] + 1]
        side = np.sign(d[first])
        peak = int(first + np.argmax(side * d[first:cross]))
        leave = peak + int(np.flatnonzero(side * d[peak:cross + 1] < side * d[peak] - np.radians(0.5))[0])
        heading = float(np.degrees(abs(psi[leave] - psi0)))
        snapped = 5.0 * np.round(heading / 5.0)
        heading = float(snapped if abs(snapped - heading) <= 1.5 else np.round(heading))
        return "zigzag", {"heading_deg": max(heading, 1.0)}
    if np.abs(psi - psi0).max() > np.pi:
        return "turning", {}
    return "other", {}


#: why a manoeuvre metric is absent from a record: what the manoeuvre did not reach (see
#: :func:`casship.maneuvers.zigzag_metrics`, :func:`casship.maneuvers.turning_metrics`)
_ABSENT = {
    "initial_turning": "the heading never reaches the switch heading",
    "period_s": "the heading crosses the switch heading fewer than three times (three rudder reversals)",
    "advance": "the heading never changes by 90 deg",
    "transfer": "the heading never changes by 90 deg",
    "tactical_diameter": "the heading never changes by 180 deg",
}


def why_absent(key: str) -> str:
    """Why a manoeuvre metric is absent from a record, in words.

    Parameters
    ----------
    key : str
        The metric (``overshoot_2_deg``, ``period_s``, ``tactical_diameter_m``...).

    Returns
    -------
    str

    Examples
    --------
    >>> why_absent("overshoot_2_deg")
    'the record ends before the heading turns back after the 2nd overshoot'
    """
    import re

    m = re.match(r"overshoot_(\d)_", key)
    if m:
        k = int(m.group(1))
        return f"the record ends before the heading turns back after the {k}{ {1: 'st', 2: 'nd', 3: 'rd'}.get(k, 'th')} overshoot"
    for prefix, why in _ABSENT.items():
        if key.startswith(prefix):
            return why
    return "not reached in this record"


def _metrics_and_reason(data, kind, options, *, t_exec, L) -> tuple[dict, str | None]:
    """:func:`maneuver_metrics` with the reason when none could be taken."""
    try:
        if kind == "turning":
            return turning_metrics(data, t_exec=t_exec, L=L), None
        if kind == "zigzag":
            return zigzag_metrics(data, options["heading_deg"], t_exec=t_exec, L=L), None
    except ValueError as exc:
        return {}, str(exc)
    return {}, None


def _metric_notes(replayed: dict, measured: dict, reasons: dict) -> dict:
    """Metric -> why it is on one side only (numbers only: ``first_side`` and the like are labels)."""
    notes = {}
    for key in sorted(set(replayed) ^ set(measured), key=lambda k: list({**replayed, **measured}).index(k)):
        if not isinstance({**replayed, **measured}[key], float) or key.endswith("_time_s"):
            continue
        side = "measured" if key in replayed else "replayed"
        notes[key] = f"{side}: {reasons.get(side) or why_absent(key)}"
    return notes


def maneuver_metrics(data: Dataset, kind: str, options: dict, *, t_exec: float, L: float | None) -> dict:
    """Metrics of ``kind`` (see :func:`classify_maneuver`) for a record, or ``{}`` if not defined.

    Parameters
    ----------
    data : Dataset
        The record (``x, y, psi``).
    kind : str
        ``"turning"``, ``"zigzag"`` or ``"other"``.
    options : dict
        From :func:`classify_maneuver` (``heading_deg`` of a zig-zag).
    t_exec : float
        Execute time [s].
    L : float or None
        Ship length [m], for ratios.

    Returns
    -------
    dict
    """
    try:
        if kind == "turning":
            return turning_metrics(data, t_exec=t_exec, L=L)
        if kind == "zigzag":
            return zigzag_metrics(data, options["heading_deg"], t_exec=t_exec, L=L)
    except ValueError:
        return {}
    return {}


def replay(model: Model, data: Dataset, p=None, *, method: str = "rk4", max_step: float | None = None,
           x0=None, check_limits: bool = True, uncertainty=None, level: float = 0.95, samples: int = 40,
           seed=0, jit: bool | None = None) -> ReplayResult:
    """Simulate ``model`` with the measured inputs of ``data`` from its measured initial state.

    Parameters
    ----------
    model : Model
        A model whose inputs are columns of ``data`` (e.g. ``delta, n`` for KVLCC2).
    data : Dataset
        The record (inputs must be finite; NaN in inputs is an error).
    p : array_like or mapping, optional
        Parameters (nominal by default), e.g. a fit's estimates.
    method, max_step
        Integration settings (see :func:`casship.simulate`).
    x0 : array_like or mapping, optional
        Initial state; by default the first row of the record's columns named like the states
        (states without a column start at zero).
    check_limits : bool
        Check the measured inputs, the initial state and the time steps against the model's
        validity ranges (see :func:`casship.simulate`).
    uncertainty : ParameterBelief, optional
        Uncertainty of some of the parameters (e.g. from a fit file): the result then carries
        prediction bands (exact sensitivities) and index intervals (``samples`` draws).
    level : float
        Coverage of the bands and intervals.
    samples : int
        Parameter draws for the index intervals and the check of the bands (0: none).
    seed : int or numpy.random.Generator
        Seed of the draws.
    jit : bool or None
        How the simulation folds run (see :mod:`casship.simulation.folds`): compiled from the cache, else
        compiled in the background while they run interpreted (``None``, the default), compiled
        now (``True``) or interpreted (``False``). The numbers are the same either way. The draws
        run as one mapped call per chunk of the record (:func:`casship.simulate_many`).

    Returns
    -------
    ReplayResult
    """
    if len(data) < 2:
        raise InputError(f"replay: the record has {len(data)} row(s); a replay compares at least two samples")
    if x0 is None:
        values = {}
        for name in model.state_names:
            if name in data:
                v = float(data[name][0])
                if not np.isfinite(v):
                    raise InputError(f"initial value of state {name!r} is missing (NaN) in the first row")
                values[name] = v
        x0 = model.states(**values)
        start = {n: "record" if n in values else "zero" for n in model.state_names}
    else:
        start = dict.fromkeys(model.state_names, "x0")
    traj = simulate(model, x0, data.t, data, p, method=method, max_step=max_step, check_limits=check_limits,
                    jit=jit)
    errors = {}
    # compared where both the record and the replayed model have the quantity
    not_compared = [n for n in ("psi", "x", "y", "u") if n in data and n not in traj]
    if "psi" in data and "psi" in traj:
        e = wrap(traj["psi"] - data["psi"])
        ok = np.isfinite(e)
        errors["psi_rmse_deg"] = float(np.degrees(np.sqrt(np.mean(e[ok] ** 2))))
    if all(n in data and n in traj for n in ("x", "y")):
        d2 = (traj["x"] - data["x"]) ** 2 + (traj["y"] - data["y"]) ** 2
        ok = np.isfinite(d2)
        errors["position_rmse_m"] = float(np.sqrt(np.mean(d2[ok])))
    if "u" in data and "u" in traj:
        e = traj["u"] - data["u"]
        ok = np.isfinite(e)
        errors["u_rmse_mps"] = float(np.sqrt(np.mean(e[ok] ** 2)))
    kind, options = classify_maneuver(data)
    metrics, measured = {}, {}
    L = model.vessel.L_pp if model.vessel is not None else None
    t_exec = execute_time(data) if kind != "other" else None
    notes = {}
    if kind != "other":
        metrics, why_replayed = _metrics_and_reason(traj, kind, options, t_exec=t_exec, L=L)
        measured, why_measured = _metrics_and_reason(data, kind, options, t_exec=t_exec, L=L)
        notes = _metric_notes(metrics, measured, {"replayed": why_replayed, "measured": why_measured})
    result = ReplayResult(traj, errors, metrics, measured, kind, data, start=start, not_compared=not_compared,
                          metric_notes=notes)
    if uncertainty is not None:
        _add_uncertainty(result, model, traj, data, uncertainty, level, samples, seed, method, max_step, jit,
                         lambda tr: maneuver_metrics(tr, kind, options, t_exec=t_exec, L=L) if kind != "other" else {})
    return result


def _add_uncertainty(result, model, traj, data, unc, level, samples, seed, method, max_step, jit, metrics_of) -> None:
    """Bands from exact sensitivities, index intervals from parameter draws (see :mod:`casship.simulation.bands`)."""
    p = model.params(traj.meta["params"])
    U = np.column_stack([traj[n] for n in model.input_names])
    x0 = np.array([traj[n][0] for n in model.state_names])
    X, S = trajectory_sensitivities(model, x0, traj.t, U, p, unc.names, method=method, max_step=max_step, jit=jit)
    bands = prediction_bands(model, X, S, unc.covariance, level)
    bands["source"] = unc.source
    if "psi_std" in bands:
        # the model discrepancy the file carries (0 when none): a heading variance growing with time, added to
        # the band of the same covariance (so the predictive band is never narrower than the parameter band)
        bands["psi_std_predictive"] = np.sqrt(bands["psi_std"] ** 2 + unc.psi_variance_rate * (traj.t - traj.t[0]))
        bands["psi_variance_rate"] = float(unc.psi_variance_rate)
    if "psi" in data and "psi_std" in bands:
        e = np.abs(wrap(traj["psi"] - data["psi"]))
        ok = np.isfinite(e)
        bands["coverage"] = float(np.mean(e[ok] <= bands["z"] * bands["psi_std"][ok] + 1e-12))
        if "psi_std_predictive" in bands:
            bands["coverage_predictive"] = float(np.mean(e[ok] <= bands["z"] * bands["psi_std_predictive"][ok] + 1e-12))
    result.bands = bands
    if samples:
        def run(draws):
            runs = simulate_many(model, x0, data.t, data, draws, method=method, max_step=max_step, check_limits=False,
                                 jit=jit)
            return [tr if isinstance(tr, Exception) else _outcome(metrics_of, tr) for tr in runs]
        s = sampled_metrics(run, unc.sample(model, p, samples, seed), level, batch=True)
        result.metric_intervals = s["intervals"]
        check = {"samples": s["samples"], "failed": s["failed"], "failures": s["failures"]}
        if s["psi_std"] is not None and "psi_std" in bands:
            lin = bands["psi_std"]
            check["psi_std_ratio_sampled_to_linear"] = float(np.sqrt(np.sum(s["psi_std"] ** 2) / max(np.sum(lin ** 2), 1e-300)))
        result.sampling = check


def _outcome(metrics_of, tr):
    """``(metrics, psi)`` of a drawn simulation, or the error its indices failed with (a failed draw)."""
    try:
        return metrics_of(tr), tr["psi"]
    except (ValueError, RuntimeError, FloatingPointError) as exc:
        return exc
