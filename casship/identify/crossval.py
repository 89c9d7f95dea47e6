"""Cross-validation as an output: leave one run (or one group of runs) out, fit, replay what was left out.

:func:`cross_validate` refits a problem on every fold and replays each held-out record with the
fitted and with the reference (published) parameters (:func:`casship.maneuvers.replay`: the
measured inputs from the measured initial state), comparing heading, speed and track RMSE and the
manoeuvre indices (advance, transfer, tactical diameter, overshoots) with the measured ones. The
result is a value (:class:`CrossValidation`) with a table (:meth:`~CrossValidation.summary`) and
overlay figures (:meth:`~CrossValidation.plot`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .records import share_labels
from ..errors import InputError

__all__ = ["cross_validate", "CrossValidation", "METRICS", "ERRORS"]

ERRORS = ("psi_rmse_deg", "u_rmse_mps", "position_rmse_m")
METRICS = ("advance_m", "transfer_m", "tactical_diameter_m", "overshoot_1_deg", "overshoot_2_deg")


def _labels(problem, by) -> list:
    n = len(problem.records)
    if by == "record":
        return [str(i) for i in range(n)]
    if isinstance(by, str):
        groups = dict(problem.spec.groups or {})
        if by in groups:
            return [str(v) for v in groups[by]]
        missing = [problem.labels[i] for i, d in enumerate(problem.records) if by not in d.meta]
        if missing:
            raise InputError(f"cross-validation by {by!r}: not a grouping of the problem and records {missing} "
                             f"have no meta[{by!r}]")
        return [str(d.meta[by]) for d in problem.records]
    labels = [str(v) for v in by]
    if len(labels) != n:
        raise InputError(f"cross-validation: {len(labels)} labels for {n} records")
    return labels


def _held_out_values(fit, problem, r: int) -> tuple[dict, dict]:
    """Parameters and biases to replay held-out record ``r`` with: the fit's values for a new run,
    with the copies of the record's groups where the fold estimated them."""
    model = problem.model
    params = dict(fit.params)
    biases = {}
    share = dict(problem.spec.share or {})
    labels = share_labels(problem.records, share, problem.spec.groups)
    declared = dict.fromkeys(e.declared for e in problem.space.entries if e.kind in ("param", "bias_in", "bias_out"))
    for name in declared:
        value = fit.estimates.get(name)
        if name in labels:      # per group: the copy of the record's group, if the fold estimated it
            label = labels[name][r]
            value = None if share[name] == "record" or label is None else fit.estimates.get(f"{name}@{label}")
        if value is None:
            continue
        if name.startswith("bias["):
            biases[name[5:-1]] = value
        elif name in model.param_names:
            params[name] = value
    return params, biases


def debiased(model, data, biases: dict):
    """``data`` with a fit's per-record biases taken out, as a replay of the fit needs it.

    Parameters
    ----------
    model : Model
    data : Dataset
    biases : dict
        Channel -> bias the fit estimated for this record (inputs and outputs).

    Returns
    -------
    Dataset
    """
    cols = {}
    for ch, b in biases.items():
        if ch in model.input_names:
            cols[ch] = data[ch] + b            # the model is driven by the measured input plus its bias
        elif ch in data:
            cols[ch] = data[ch] - b            # the sensor reads the model output plus its bias
    return data.with_columns(**cols) if cols else data


def _replay(model, data, params, biases, method):
    from ..maneuvers import replay

    return replay(model, debiased(model, data, biases), model.params(params), method=method)


def _fold_rows(fold, problem, reference, method):
    """Replay of each held-out record of a fold with the fitted and the reference parameters."""
    rows, replays = [], {}
    model = problem.model
    for r in fold["held_out"]:
        data = problem.records[r]
        params, biases = _held_out_values(fold["fit"], problem, r)
        fitted = _replay(model, data, params, biases, method)
        ref = _replay(model, data, reference, {}, method)
        rows.append({"record": problem.labels[r], "fold": fold["label"], "kind": fitted.kind,
                     "fit": dict(fitted.errors), "reference": dict(ref.errors),
                     "metrics_fit": dict(fitted.metrics), "metrics_reference": dict(ref.metrics),
                     "metrics_measured": dict(fitted.measured_metrics)})
        replays[problem.labels[r]] = {"data": data, "fit": fitted, "reference": ref}
    return rows, replays


def cross_validate(problem, *, by="record", guess: Mapping[str, float] | None = None, reference=None,
                   method: str = "rk4", solve: Mapping | None = None) -> "CrossValidation":
    """Leave-one-run-out (or leave-one-group-out) cross-validation of an identification problem.

    Parameters
    ----------
    problem : OutputErrorProblem or MLEProblem
        The problem on all records; each fold is ``problem.subset(training records)``.
    by : "record", str or sequence of labels
        ``"record"``: leave one record out at a time; a grouping name (from the problem's ``groups``
        or the records' ``meta``, e.g. ``"facility"``) or one label per record: leave one group out.
    guess : mapping, optional
        Starting values of every fold's fit.
    reference : array or mapping, optional
        Parameters the fit is compared with (default: the model's published values).
    method : str
        Integration method of the replays.
    solve : mapping, optional
        Further arguments of ``problem.solve`` (e.g. ``{"max_iter": 50}``).

    Returns
    -------
    CrossValidation

    Examples
    --------
    >>> cv = cross_validate(problem, by="record")      # doctest: +SKIP
    >>> print(cv.summary())                             # doctest: +SKIP
    >>> cv.plot("cv")                                   # doctest: +SKIP
    """
    from ..progress import track

    labels = _labels(problem, by)
    model = problem.model
    ref = model.param_dict(model.params() if reference is None else model.params(reference))
    folds, rows, replays = [], [], {}
    for label in track(list(dict.fromkeys(labels)), "cross-validation", unit="fold"):
        held = [i for i, v in enumerate(labels) if v == label]
        train = [i for i, v in enumerate(labels) if v != label]
        if not train:
            raise InputError(f"cross-validation by {by!r}: fold {label!r} leaves no record to train on")
        fit = problem.subset(train).solve(guess=guess, **{"show": False, **dict(solve or {})})
        fold = {"label": label, "held_out": held, "train": train, "fit": fit}
        folds.append(fold)
        r_rows, r_replays = _fold_rows(fold, problem, ref, method)
        rows += r_rows
        replays.update(r_replays)
    return CrossValidation(by=by if isinstance(by, str) else "labels", folds=folds, rows=rows, replays=replays,
                           model=model.name, free=list(problem.free))


def _mean(values) -> float:
    v = np.array([x for x in values if x is not None and np.isfinite(x)], dtype=float)
    return float(v.mean()) if v.size else float("nan")


@dataclass
class CrossValidation:
    """Result of :func:`cross_validate`.

    Parameters
    ----------
    by : str
        How the folds were formed (``"record"``, a grouping name or ``"labels"``).
    folds : list of dict
        Per fold its ``label``, ``held_out`` and ``train`` record indices and its ``fit`` (FitResult).
    rows : list of dict
        Per held-out record: ``record``, ``fold``, manoeuvre ``kind``, replay errors with the ``fit``
        and the ``reference`` parameters (``psi_rmse_deg``, ``u_rmse_mps``, ``position_rmse_m``) and
        the manoeuvre indices ``metrics_fit``, ``metrics_reference``, ``metrics_measured``.
    replays : dict
        Record label -> ``{"data", "fit", "reference"}`` (the replays, for plots; not in JSON).
    model : str
        Model name.
    free : list of str
        The problem's free quantities.
    """

    by: str
    folds: list
    rows: list
    replays: dict = field(default_factory=dict, repr=False)
    model: str = ""
    free: list = field(default_factory=list)

    @property
    def improved(self) -> list[str]:
        """Held-out records whose heading RMSE is lower with the fit than with the reference."""
        return [r["record"] for r in self.rows
                if r["fit"].get("psi_rmse_deg", np.inf) < r["reference"].get("psi_rmse_deg", -np.inf)]

    def table(self) -> list[dict]:
        """One flat row per held-out record (errors and indices: reference, fit, measured)."""
        out = []
        for r in self.rows:
            flat = {"record": r["record"], "fold": r["fold"], "kind": r["kind"]}
            for key in ERRORS:
                flat[f"{key} reference"] = r["reference"].get(key)
                flat[f"{key} fit"] = r["fit"].get(key)
            for key in METRICS:
                if key in r["metrics_measured"] or key in r["metrics_fit"]:
                    for who in ("reference", "fit", "measured"):
                        flat[f"{key} {who}"] = r[f"metrics_{who}"].get(key)
            out.append(flat)
        return out

    def summary(self) -> str:
        """A plain-text table: per held-out record the errors and indices, reference -> fit (measured)."""
        lines = [f"cross-validation of {self.model!r} ({len(self.folds)} folds by {self.by}; free: {', '.join(self.free)})",
                 f"{'held-out record':>24s} {'psi RMSE deg':>16s} {'u RMSE m/s':>15s} {'track RMSE m':>17s}  indices "
                 "reference -> fit (measured)"]
        arrow = lambda a, b, f: f"{a:{f}} -> {b:{f}}" if a is not None and b is not None else "-"  # noqa: E731
        for r in self.rows:
            e, q = r["fit"], r["reference"]
            idx = []
            for key in METRICS:
                if key in r["metrics_measured"]:
                    idx.append(f"{key} {r['metrics_reference'].get(key, np.nan):.4g} -> "
                               f"{r['metrics_fit'].get(key, np.nan):.4g} ({r['metrics_measured'][key]:.4g})")
            lines.append(f"{r['record']:>24s} {arrow(q.get('psi_rmse_deg'), e.get('psi_rmse_deg'), '6.2f'):>16s} "
                         f"{arrow(q.get('u_rmse_mps'), e.get('u_rmse_mps'), '5.3f'):>15s} "
                         f"{arrow(q.get('position_rmse_m'), e.get('position_rmse_m'), '6.1f'):>17s}  {'; '.join(idx)}")
        ref = _mean(r["reference"].get("psi_rmse_deg") for r in self.rows)
        fit = _mean(r["fit"].get("psi_rmse_deg") for r in self.rows)
        lines.append(f"mean psi RMSE {ref:.2f} -> {fit:.2f} deg; the fit predicts the heading better on "
                     f"{len(self.improved)} of {len(self.rows)} held-out records")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"CrossValidation({self.model!r}, {len(self.folds)} folds by {self.by}, {len(self.rows)} held-out records)"

    def to_json(self, path) -> Path:
        """Write the table and each fold's estimates as JSON.

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        from ..io.jsonfile import write_json

        doc = {"model": self.model, "by": self.by, "free": self.free, "rows": self.rows,
               "folds": [{"label": f["label"], "held_out": f["held_out"], "train": f["train"],
                          "estimates": f["fit"].estimates, "std_errors": f["fit"].std_errors,
                          "status": f["fit"].status} for f in self.folds]}
        path = Path(path)
        write_json(path, doc, what="cross-validation file")
        return path

    def plot(self, directory=None, records: Sequence[str] | None = None, *, ax=None) -> list:
        """Overlay figures, one per held-out record: track, heading and speed, measured against the
        replays with the reference and the fitted parameters.

        Parameters
        ----------
        directory : str or Path, optional
            Write the figures there as PNG (the folder is created if needed) and return their paths;
            without it the figures are returned.
        records : sequence of str, optional
            Records to plot (default: all held out).
        ax : three matplotlib Axes, optional
            Draw the one record named in ``records`` into these axes (returned in a list).

        Returns
        -------
        list of matplotlib.figure.Figure, of Path, or of the axes given
            See :mod:`casship.plotting`.
        """
        from ..plotting import finish, panels

        names = list(records or list(self.replays))
        if ax is not None and len(names) != 1:
            raise InputError(f"ax: draws one record's figure; name one in records (got {len(names)})")
        if directory is not None:
            directory = Path(directory)
            directory.mkdir(parents=True, exist_ok=True)
        out = []
        for i, name in enumerate(names):
            if name not in self.replays:
                raise InputError(f"records: {name!r} was not held out; held out: {list(self.replays)}")
            fig, axes = panels(ax, 1, 3, figsize=(14, 4.2), what="the cross-validation plot of one record")
            self._draw(name, axes.ravel(), fig if ax is None else None)
            path = None
            if directory is not None:
                safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in name)
                path = directory / f"cv_{i:02d}_{safe}.png"
            out.append(finish(fig, ax, path, dpi=100))
        return out

    def _draw(self, name: str, axes, fig) -> None:
        from ..angles import unwrap

        rep = self.replays[name]
        data = rep["data"]
        styles = (("measured", data, dict(color="0.3", lw=1.6)),
                  ("reference", rep["reference"].trajectory, dict(color="C1", lw=1.0, ls="--")),
                  ("fit", rep["fit"].trajectory, dict(color="C0", lw=1.0)))
        for label, d, st in styles:
            if "x" in d and "y" in d:
                axes[0].plot(d["y"], d["x"], label=label, **st)
            if "psi" in d:
                axes[1].plot(d.t, np.degrees(unwrap(np.nan_to_num(d["psi"]))), label=label, **st)
            if "u" in d:
                axes[2].plot(d.t, d["u"], label=label, **st)
        axes[0].set(xlabel="y (East) [m]", ylabel="x (North) [m]", title="track")
        axes[0].set_aspect("equal", adjustable="datalim")
        axes[1].set(xlabel="t [s]", ylabel="psi [deg]", title="heading")
        axes[2].set(xlabel="t [s]", ylabel="u [m/s]", title="surge speed")
        axes[1].legend(fontsize=8)
        if fig is not None:
            row = next(r for r in self.rows if r["record"] == name)
            fig.suptitle(f"{name} (held out, fold {row['fold']}): psi RMSE "
                         f"{row['reference'].get('psi_rmse_deg', np.nan):.2f} deg reference, "
                         f"{row['fit'].get('psi_rmse_deg', np.nan):.2f} deg fit", fontsize=10)
