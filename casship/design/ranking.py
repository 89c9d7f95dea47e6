"""Rank candidate trials by what they would teach: :func:`design_trials` and :class:`DesignResult`.

For each candidate the trial's Fisher information (:func:`~.information.trial_information`) is
added to the current belief, and the target's standard deviation is propagated through the belief
after it by the delta method (the target's exact gradient, :mod:`.targets`). Candidates are ranked
by that standard deviation, or by a D-/A-criterion on the parameters (the target's figure is still
reported). With limits, a free rudder sequence is optimised (:func:`~.free.optimise_free_trial`)
and ranked with the others.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError
from .belief import ParameterBelief
from .free import FreeTrialError, TrialLimits, optimise_free_trial
from .infofold import InformationFold
from .information import CRITERIA, check_noise, criterion_value, trial_information
from .sensitivity import Approach
from .targets import TargetValue, get_target
from .trials import Trial, standard_trials

__all__ = ["design_trials", "DesignResult"]


@dataclass
class DesignResult:
    """Candidate trials ranked by what they would teach about a target.

    Parameters
    ----------
    target : TargetValue
        The target at the current estimate, with its gradient.
    belief : ParameterBelief
        The belief before any new trial.
    noise : dict
        Measured channels and their standard deviations.
    rows : list of dict
        One per candidate, best first: ``trial``, ``kind``, ``duration_s``, ``sides``,
        ``sd_before``, ``sd_after`` (the target's standard deviation before and after the trial),
        ``reduction`` (their ratio), ``criterion`` (D/A value, when ranked by one),
        ``violations`` (the limits the trial breaks; empty when within them or without limits).
    trials : dict
        Trial name -> :class:`Trial`.
    criterion : str or None
        ``"D"``, ``"A"`` or None (ranked by the target).
    free : dict
        The free trial's optimisation report (empty without limits).
    approach : dict
        Speed, propeller rate and step of the design.
    information : dict
        Trial name -> Fisher information (k x k) about ``belief.names``.
    discrepancy : float
        The heading's model discrepancy ``q`` [rad^2/s] the design assumed (0: none).
    model_floor : float
        The target's standard deviation that the model's own error sets (:meth:`TargetValue.floor`):
        included in ``sd_before`` and ``sd_after``, so no trial is predicted to know the target better.
    """

    target: TargetValue
    belief: ParameterBelief
    noise: dict
    rows: list
    trials: dict = field(repr=False)
    criterion: str | None = None
    free: dict = field(default_factory=dict)
    approach: dict = field(default_factory=dict)
    information: dict = field(default_factory=dict, repr=False)
    discrepancy: float = 0.0
    model_floor: float = 0.0

    @property
    def per_hour(self) -> list:
        """The trials within the limits ranked by the target's variance removed per hour of trial time
        (tank and sea time are what a trial costs): dicts ``trial``, ``hours``,
        ``variance_reduction_per_hour`` (target unit squared per hour), ``sd_after``."""
        out = [{"trial": r["trial"], "hours": r["duration_s"] / 3600.0,
                "variance_reduction_per_hour": (r["sd_before"] ** 2 - r["sd_after"] ** 2) / (r["duration_s"] / 3600.0),
                "sd_after": r["sd_after"]} for r in self.rows if not r["violations"]]
        return sorted(out, key=lambda r: -r["variance_reduction_per_hour"])

    @property
    def best(self) -> Trial:
        """The best-ranked trial within the limits (the best-ranked one when none is)."""
        ok = [r for r in self.rows if not r["violations"]]
        return self.trials[(ok or self.rows)[0]["trial"]]

    def row(self, name: str) -> dict:
        """The row of trial ``name``.

        Parameters
        ----------
        name : str

        Returns
        -------
        dict
        """
        for r in self.rows:
            if r["trial"] == name:
                return r
        raise InputError(f"no trial {name!r}; trials: {[r['trial'] for r in self.rows]}")

    def table(self) -> str:
        """The ranking as a Markdown table (lengths in the target's unit, angles in degrees)."""
        deg = self.target.unit == "rad"
        unit = "deg" if deg else self.target.unit
        scale = np.degrees(1.0) if deg else 1.0
        head = ["rank", "trial", "duration [s]", f"sd before [{unit}]", f"sd after [{unit}]", "reduction",
                "per hour"]
        if self.criterion:
            head.append(f"{self.criterion}-criterion")
        head.append("limits")
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        hourly = {r["trial"]: f"#{i}" for i, r in enumerate(self.per_hour, 1)}
        for i, r in enumerate(self.rows, 1):
            cells = [str(i), r["trial"], f"{r['duration_s']:.0f}", f"{r['sd_before'] * scale:.4g}",
                     f"{r['sd_after'] * scale:.4g}", f"x{r['reduction']:.3g}", hourly.get(r["trial"], "-")]
            if self.criterion:
                cells.append(f"{r['criterion']:.4g}")
            cells.append("; ".join(r["violations"]) or "within")
            lines.append("| " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def summary(self) -> str:
        """A few lines: the target, the belief, the best trial."""
        r = self.row(self.best.name)
        deg = self.target.unit == "rad"
        scale, unit = (np.degrees(1.0), "deg") if deg else (1.0, self.target.unit)
        by = f"{self.criterion}-criterion" if self.criterion else "the target's standard deviation after the trial"
        return (f"target {self.target.name} = {self.target.value * scale:.4g} {unit}, standard deviation "
                f"{r['sd_before'] * scale:.4g} {unit} now ({self.belief.source}; {len(self.belief.names)} uncertain "
                f"parameters)\nranked by {by}; best within the limits: {self.best.name} "
                f"({r['duration_s']:.0f} s): {r['sd_after'] * scale:.4g} {unit} after it (x{r['reduction']:.3g})"
                + (f"\nmodel-error floor: {self.model_floor * scale:.4g} {unit} (heading discrepancy "
                   f"{np.degrees(np.degrees(self.discrepancy)):.3g} deg^2/s; no trial removes it)" if self.discrepancy > 0
                   else "\nno model error assumed (no discrepancy term): the standard deviations after a trial are "
                        "those of a model that is right in its structure")
                + (f"\nbest per hour of trial time: {self.per_hour[0]['trial']}" if self.per_hour else ""))

    def __repr__(self) -> str:
        return f"DesignResult(target={self.target.name!r}, {len(self.rows)} trials, best={self.best.name!r})"

    def to_dict(self) -> dict:
        """JSON-ready dict (trials as rudder records in degrees)."""
        return {"target": {"name": self.target.name, "value": self.target.value, "unit": self.target.unit,
                           "gradient": dict(zip(self.belief.names, self.target.gradient.tolist()))},
                "belief": {"names": list(self.belief.names), "mean": self.belief.mean, "std": self.belief.std,
                           "source": self.belief.source, "covariance": self.belief.kind},
                "noise": dict(self.noise), "criterion": self.criterion, "approach": dict(self.approach),
                "ranking": [dict(r) for r in self.rows], "free": dict(self.free),
                "model_floor": self.model_floor, "discrepancy_deg2_per_s": float(np.degrees(np.degrees(self.discrepancy))),
                "per_hour": self.per_hour,
                "trials": {n: {"kind": t.kind, "dt_s": t.dt, "rudder_deg": np.degrees(t.rudder).tolist()}
                           for n, t in self.trials.items()}}

    def to_json(self, path) -> Path:
        """Write :meth:`to_dict` as JSON (:func:`casship.io.jsonfile.write_json`: atomic, non-finite
        numbers as text).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        from ..io.jsonfile import write_json

        write_json(path, self.to_dict(), what="design result")
        return Path(path)

    def plot(self, ax=None, path=None, approach: Approach | None = None):
        """Bar chart of the target's standard deviation after each trial; with ``approach``, also the
        best trial's rudder, track and speed.

        Parameters
        ----------
        ax : matplotlib Axes (four with ``approach``), optional
            Draw into these axes instead of a new figure.
        path : str or Path, optional
            Also write the figure there (PNG unless the suffix says otherwise).
        approach : Approach, optional

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting`.
        """
        from ..plotting import finish, panels, split_args

        if isinstance(path, Approach) and approach is None:      # the earlier plot(path, approach)
            path, approach = None, path
        ax, path = split_args(ax, path)
        given = ax
        deg = self.target.unit == "rad"
        scale, unit = (np.degrees(1.0), "deg") if deg else (1.0, self.target.unit)
        n = 1 if approach is None else 2
        fig, axes = panels(ax, n, n, figsize=(10, 4.5 if approach is None else 8), what="the design plot")
        axes = axes.ravel()
        names = [r["trial"] for r in self.rows]
        ax = axes[0]
        from matplotlib.ticker import NullFormatter

        ax.barh(names[::-1], [r["sd_after"] * scale for r in self.rows][::-1], color="tab:blue")
        ax.axvline(self.rows[0]["sd_before"] * scale, color="k", ls="--")
        if self.model_floor > 0:
            ax.axvline(self.model_floor * scale, color="tab:red", ls=":", label="model-error floor")
            ax.legend(loc="lower right")
        ax.set_xscale("log")
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xlabel(f"standard deviation of {self.target.name} [{unit}]")
        ax.set_title("after each trial (bars) and now (dashed)")
        if approach is not None:
            best = self.best
            rec = best.record(approach)
            axes[1].step(best.t[:-1], np.degrees(best.rudder), where="post")
            axes[1].set_xlabel("t [s]")
            axes[1].set_ylabel("rudder [deg]")
            axes[1].set_title(best.name)
            axes[2].plot(rec["y"], rec["x"])
            axes[2].set_xlabel("y (East) [m]")
            axes[2].set_ylabel("x (North) [m]")
            axes[2].set_aspect("equal", adjustable="datalim")
            axes[3].plot(rec.t, np.hypot(rec["u"], rec["v"]))
            axes[3].set_xlabel("t [s]")
            axes[3].set_ylabel("speed [m/s]")
        return finish(fig, given, path)


def design_trials(model, belief: ParameterBelief, noise: Mapping[str, float], target="tactical_diameter", *,
                  criterion: str | None = None, p=None, speed: float | None = None, dt: float | None = None,
                  candidates: Sequence[Trial] | None = None, limits: TrialLimits | None = None,
                  start: Trial | None = None, max_iter: int = 60, discrepancy: float = 0.0,
                  jit: bool | None = None) -> DesignResult:
    """Rank candidate trials (and optimise a free one) by what they would teach about ``target``.

    Parameters
    ----------
    model : Model
        A ship model (vessel with rudder and propeller inputs).
    belief : ParameterBelief
        What is known now: mean and covariance of the uncertain parameters (a fit's, or a prior).
    noise : mapping output -> standard deviation
        Measured channels of a new trial and the standard deviation of one sample (SI, radians), as
        the fit would weigh them.
    target : str or Target
        A name of :data:`~casship.design.TARGETS` (``tactical_diameter``, ``advance``,
        ``first_overshoot``, ``port_starboard_difference``...) or a :class:`~casship.design.Target`.
    criterion : {"D", "A"}, optional
        Rank by a classical criterion on the parameters instead of the target's variance.
    p : array_like or mapping, optional
        Parameters of the model (default: nominal with ``belief.mean``).
    speed : float, optional
        Approach speed [m/s] (default ``model.vessel.U0``).
    dt : float, optional
        Step of the design's simulations and sampling of a trial [s] (default ``L/U / 40``).
    candidates : sequence of Trial, optional
        Default :func:`~casship.design.standard_trials` (both directions).
    limits : TrialLimits, optional
        Optimise a free rudder sequence within these limits and rank it too; the standard trials
        are checked against them (the ``violations`` column).
    start : Trial, optional
        Starting sequence of the free optimisation (default a sine); the best-ranked candidate that
        keeps the limits other than the duration is a second start, and the better result is kept.
    max_iter : int
        Iteration limit of the free optimisation.
    discrepancy : float
        The heading's model discrepancy ``q`` [rad^2/s] (a fit file's ``model_discrepancy``): it sets
        the target's floor (:attr:`DesignResult.model_floor`, added to every standard deviation) and
        whitens the heading residuals in each trial's information (long trials no longer teach in
        proportion to their length). 0: a model right in its structure.
    jit : bool, optional
        Compile policy of the information fold (None: in the background when a compiler works).

    Returns
    -------
    DesignResult

    Raises
    ------
    ValueError
        Unknown target, criterion or channel; impossible limits (naming the limit).
    casship.design.FreeTrialError
        No free sequence within the limits.

    Examples
    --------
    >>> import numpy as np
    >>> from casship.models import kvlcc2
    >>> from casship.design import ParameterBelief, design_trials
    >>> ship = kvlcc2()
    >>> belief = ParameterBelief.from_std({"N_r_dash": 0.01}, ship.param_dict())
    >>> res = design_trials(ship, belief, {"psi": np.radians(0.2)}, "tactical_diameter")   # doctest: +SKIP
    >>> print(res.table())                                                              # doctest: +SKIP
    """
    from ..progress import progress

    if criterion is not None and criterion not in CRITERIA:
        raise InputError(f"unknown criterion {criterion!r}; use one of {CRITERIA}")
    tgt = get_target(target)
    noise = check_noise(model, noise)
    pv = model.params(p) if p is not None else model.params(belief.mean)
    approach = Approach(model, pv, speed=speed, dt=dt)
    if limits is not None:
        limits.resolved(approach)                      # impossible limits fail before any work
    stages = ["target", "candidates", "information"] + (["free trial"] if limits is not None else [])
    steps = progress(stages, "design-trial")
    next(steps)
    tv = tgt.evaluate(approach, belief.names)
    next(steps)
    trials = list(candidates) if candidates is not None else standard_trials(approach)
    if not trials and limits is None:
        raise InputError("no candidate trials and no free trial (limits): nothing to rank")
    names = [t.name for t in trials]
    if len(set(names)) != len(names):
        raise InputError(f"candidate trials need distinct names, got {names}")
    next(steps)
    floor = tv.floor(discrepancy)
    fold = InformationFold(approach, belief.names, list(noise), jit=jit)
    info = {t.name: trial_information(approach, t, belief.names, noise, discrepancy=discrepancy, fold=fold)
            for t in trials}
    sd0 = np.sqrt(belief.variance_of(tv.gradient) + floor ** 2)

    def row(t):
        after = belief.after(info[t.name])
        sd_par = np.sqrt(after.variance_of(tv.gradient))
        sd = np.hypot(sd_par, floor)
        return {"trial": t.name, "kind": t.kind, "duration_s": t.duration, "sides": sorted(t.sides()),
                "sd_before": float(sd0), "sd_after": float(sd), "sd_after_parameters": float(sd_par),
                "reduction": float(sd0 / sd) if sd > 0 else np.inf,
                "criterion": criterion_value(after, belief, criterion) if criterion else None,
                "violations": limits.violations(t, approach) if limits is not None else []}

    def key(r):
        return r["criterion"] if criterion else r["sd_after"]

    rows = sorted((row(t) for t in trials), key=key)
    free_report = {}
    if limits is not None:
        next(steps)
        # two starts: the given one (or a sine) and the best standard trial that keeps the other limits
        lim = limits.resolved(approach)
        starts = [start] + [trials[[t.name for t in trials].index(r["trial"])] for r in rows
                            if not [v for v in r["violations"] if not v.startswith("duration")]][:1]
        best, errors = None, []
        for s in starts:
            try:
                cand = optimise_free_trial(approach, belief, noise, lim, gradient=None if criterion else tv.gradient,
                                           criterion=criterion, start=s, max_iter=max_iter, discrepancy=discrepancy,
                                           floor=floor, fold=fold, jit=jit)
            except FreeTrialError as exc:
                errors.append(exc)
                continue
            if best is None or cand[1]["objective"] < best[1]["objective"]:
                best = cand
        if best is None:
            raise errors[-1]
        free, free_report = best
        trials.append(free)
        info[free.name] = trial_information(approach, free, belief.names, noise, discrepancy=discrepancy, fold=fold)
        rows = sorted(rows + [row(free)], key=key)
    next(steps, None)
    return DesignResult(tv, belief, noise, rows, {t.name: t for t in trials}, criterion, free_report,
                        {"speed_mps": approach.speed, "n": approach.n, "dt_s": approach.dt}, info,
                        float(discrepancy), floor)
