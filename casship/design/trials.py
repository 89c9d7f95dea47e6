"""Candidate trials: the IMO/ITTC standard manoeuvres in both directions, as rudder records.

A :class:`Trial` is what a tank or a ship would run: a rudder record on the design's grid at a set
propeller rate from the straight approach. The standard manoeuvres (turning circles, zig-zags of
any angle, pull-outs, the spiral) are simulated with :func:`casship.maneuvers.run_maneuver` on the
current estimate; a closed-loop zig-zag's rudder is recorded as it would be measured. For the
information of a trial the recorded rudder is an input (the fit uses the measured rudder), so its
switching times are those of the current estimate.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from ..data import Dataset
from .sensitivity import Approach
from ..errors import InputError

__all__ = ["Trial", "standard_trials"]


@dataclass(frozen=True)
class Trial:
    """A trial: the rudder held over each step of the design's grid from the straight approach.

    Parameters
    ----------
    name : str
        E.g. ``"turning 35 starboard"``, ``"zig-zag 20/20 port"``, ``"free"``.
    kind : str
        ``turning``, ``zigzag``, ``pullout``, ``spiral`` or ``free``.
    dt : float
        Step of the grid [s].
    rudder : (n,) array
        Rudder angle over each step [rad] (held from ``k dt`` to ``(k + 1) dt``).
    settings : dict
        What defines the manoeuvre (angles in degrees, hold times...).
    """

    name: str
    kind: str
    dt: float
    rudder: np.ndarray = field(repr=False)
    settings: dict = field(default_factory=dict)

    def __post_init__(self):
        r = np.asarray(self.rudder, dtype=float).reshape(-1)
        if r.size < 2 or not np.all(np.isfinite(r)):
            raise InputError(f"trial {self.name!r}: the rudder record must have at least two finite values")
        r.setflags(write=False)
        object.__setattr__(self, "rudder", r)

    @property
    def duration(self) -> float:
        """Length of the trial [s]."""
        return self.rudder.size * self.dt

    @property
    def t(self) -> np.ndarray:
        """Sample times ``0, dt, ..., n dt`` (``n + 1`` samples)."""
        return np.arange(self.rudder.size + 1) * self.dt

    def sides(self) -> set:
        """The sides the rudder goes to by more than 1 deg (+1 starboard, -1 port)."""
        big = self.rudder[np.abs(self.rudder) > np.radians(1.0)]
        return set(np.sign(big).astype(int).tolist())

    def record(self, approach: Approach) -> Dataset:
        """The noise-free record of this trial on the model at ``approach.p`` (all outputs, inputs).

        Parameters
        ----------
        approach : Approach

        Returns
        -------
        Dataset
        """
        from ..simulation import simulate

        m = approach.model
        U = approach.inputs(np.append(self.rudder, self.rudder[-1]))
        traj = simulate(m, approach.x0, self.t, U.T, approach.p, method="rk4")
        cols = {n: np.asarray(traj[n]) for n in m.output_names}
        cols.update({n: U[i] for i, n in enumerate(m.input_names)})
        return Dataset(self.t, cols, meta={"trial": self.name})

    def to_csv(self, path, approach: Approach) -> Path:
        """Write the trial as a CSV a tank can run: ``t_s``, ``rudder_deg`` (held from this time to the
        next row; positive turns to starboard) and the propeller rate (column named like the model's
        propeller input), one row per step, from the straight approach at ``approach.speed``.

        Parameters
        ----------
        path : str or Path
        approach : Approach
            The approach (its propeller rate and speed are written too).

        Returns
        -------
        Path
        """
        path = Path(path)
        prop = approach.propellers[0] if approach.propellers else None
        with path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_s", "rudder_deg"] + ([f"{prop}"] if prop else []))
            for k, t in enumerate(self.t[:-1]):
                w.writerow([f"{t:.6g}", f"{np.degrees(self.rudder[k]):.4f}"] + ([f"{approach.n:.6g}"] if prop else []))
        return path


def _side_name(side: int) -> str:
    return "starboard" if side > 0 else "port"


def standard_trials(approach: Approach, *, turning: Sequence[float] = (35.0,), zigzag: Sequence[float] = (10.0, 20.0),
                    pullout: Sequence[float] = (35.0,), spiral: bool = True, sides: Sequence[int] = (1, -1),
                    durations: dict | None = None) -> list[Trial]:
    """The IMO/ITTC standard manoeuvres on the current estimate, in both directions.

    Parameters
    ----------
    approach : Approach
        Model, current parameters, approach speed and propeller rate, the design's step.
    turning : sequence of float
        Turning-circle rudder angles [deg].
    zigzag : sequence of float
        Zig-zag angles [deg] (rudder = switch heading: 10/10, 20/20...).
    pullout : sequence of float
        Pull-out rudder angles [deg].
    spiral : bool
        Include the direct spiral (25 deg to -25 deg; it turns both ways).
    sides : sequence of {+1, -1}
        First rudder to starboard (+1) and/or port (-1).
    durations : mapping kind -> float, optional
        Durations in units of ``L/U`` (defaults: turning 25, zigzag 16, pullout 30; the spiral holds
        each of its 15 rudder angles 8 L/U).

    Returns
    -------
    list of Trial

    Raises
    ------
    ValueError
        A side other than +1/-1, or an unknown kind in ``durations``.
    """
    from ..maneuvers import run_maneuver

    spans = {"turning": 25.0, "zigzag": 16.0, "pullout": 30.0, "spiral": 8.0}
    unknown = set(durations or {}) - set(spans)
    if unknown:
        raise InputError(f"durations given for unknown kind(s) {sorted(unknown)}; known: {list(spans)}")
    spans.update(durations or {})
    bad = [s for s in sides if s not in (1, -1)]
    if bad:
        raise InputError(f"sides must be +1 (starboard) or -1 (port), got {bad}")
    T, dt = approach.time_scale, approach.dt
    common = dict(speed=approach.speed, n=approach.n, p=approach.p, dt=dt / 10)
    jobs = []
    for side in sides:
        jobs += [(f"turning {a:g} {_side_name(side)}", "turning", dict(rudder_deg=side * a, duration=spans["turning"] * T))
                 for a in turning]
        jobs += [(f"zig-zag {a:g}/{a:g} {_side_name(side)}", "zigzag", dict(rudder_deg=side * a, duration=spans["zigzag"] * T))
                 for a in zigzag]
        jobs += [(f"pull-out {a:g} {_side_name(side)}", "pullout",
                  dict(rudder_deg=side * a, duration=spans["pullout"] * T, hold=spans["pullout"] * T / 2)) for a in pullout]
    if spiral:
        jobs.append(("spiral 25..-25", "spiral", dict(rudder_deg=25.0, hold=spans["spiral"] * T)))
    out = []
    for name, kind, kw in jobs:
        res = run_maneuver(approach.model, kind, **common, **kw)
        t_fine = res.trajectory.t
        rudder_name = approach.rudders[0]
        n = int(np.floor(t_fine[-1] / dt + 1e-9))
        rudder = np.interp(approach.midpoints(n), t_fine, np.asarray(res.trajectory[rudder_name]))
        out.append(Trial(name, kind, dt, rudder, {k: v for k, v in res.settings.items() if k != "n"}))
    return out
