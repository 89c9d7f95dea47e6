"""The KVLCC2 free-running runs of the study: three MARIN runs and thirteen HSVA zig-zags at full scale.

* MARIN (``kvlcc2_marin_free``): full scale as published, read by :func:`casship.io.read_marin`.
* HSVA (``kvlcc2_hsva_free``): model scale 1:45.7, Froude-scaled to full scale with the same
  ``lambda = 45.7`` by :func:`casship.io.read_hsva` (``full_scale=True``), rudder sign flipped to
  the MMG convention, the two unestablished channels left out.

Each record carries ``meta["name"]`` (``MARIN tc_-35``, ``HSVA Z_10_10_P`` ...) and
``meta["facility"]``. For the fits a record is decimated to about 2 s; its inputs are averaged over
each new sample interval (the best zero-order hold of the full-rate rudder and propeller signals),
its measured outputs are sampled. Validation replays use the full-rate records.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

import casship as cs
from casship.identify.asymmetry import turn_side
from casship.io import hsva_runs, marin_runs, read_hsva, read_marin
from casship.maneuvers import execute_time

__all__ = ["Run", "load_runs", "fit_record", "per_run", "approach", "first_rudder_side", "regime", "FIT_DT",
           "INPUTS"]

FIT_DT = 2.0                       # s, sampling period of the fit records (full scale)
REGIME_DEG = 17.5                  # deg: zig-zags with a larger rudder angle are "large-rudder" runs
INPUTS = ("delta", "n")


@dataclass(frozen=True)
class Run:
    """A measured run: its name, facility, full-rate record and manoeuvre kind."""

    name: str
    facility: str
    data: cs.Dataset
    kind: str                       # "turning" or "zigzag"

    @property
    def label(self) -> str:
        return self.name.split(" ", 1)[1]


def load_runs(data_dir: Path) -> list[Run]:
    """All MARIN and HSVA runs in ``data_dir`` (full scale), MARIN first."""
    marin = Path(data_dir) / "kvlcc2_marin_free"
    hsva = Path(data_dir) / "kvlcc2_hsva_free"
    runs = []
    for key, path in (marin_runs(marin).items() if marin.is_dir() else ()):
        d = read_marin(path)
        runs.append(_run(f"MARIN {key}", "MARIN", d, "turning" if key.startswith("tc") else "zigzag"))
    for key, path in (hsva_runs(hsva).items() if hsva.is_dir() else ()):
        runs.append(_run(f"HSVA {key}", "HSVA", read_hsva(path, full_scale=True), "zigzag"))
    if not runs:
        raise FileNotFoundError(f"no MARIN or HSVA KVLCC2 runs in {data_dir}")
    return runs


def _run(name: str, facility: str, d: cs.Dataset, kind: str) -> Run:
    meta = dict(d.meta)
    meta.update(name=name, facility=facility)
    return Run(name, facility, cs.Dataset(d.t, {c: d[c] for c in d.names}, d.units, meta), kind)


_PER_RUN: dict = {}


def per_run(what: tuple, run: Run, make: Callable[[], object]):
    """``make()``, kept per process under ``what`` and the run's content (name and every column, to
    the bit): work that depends on one run alone (its fit record, its published replay) is done once
    however many folds hold the run. Results are shared: read them, do not change them."""
    h = hashlib.sha1(repr((run.name, run.facility, run.kind, run.data.names)).encode())
    h.update(np.ascontiguousarray(run.data.t, dtype=float).tobytes())
    for c in run.data.names:
        h.update(np.ascontiguousarray(run.data[c], dtype=float).tobytes())
    key = (what, h.hexdigest())
    if key not in _PER_RUN:
        _PER_RUN[key] = make()
    return _PER_RUN[key]


def fit_record(run: Run, dt: float = FIT_DT, outputs=("psi", "r", "u"), states=("u", "v", "r", "x", "y", "psi"),
               extra=()) -> cs.Dataset:
    """The run sampled every ``dt`` seconds for fitting: inputs averaged over each interval.

    ``psi`` is kept continuous; state columns that the run holds give the initial state; columns in
    ``extra`` (e.g. smoothed accelerations) are sampled like the outputs.
    """
    d = run.data
    step = max(1, int(round(dt / float(np.median(np.diff(d.t))))))
    idx = np.arange(0, len(d), step)
    cols = {}
    for name in INPUTS:
        v = np.asarray(d[name], dtype=float)
        cols[name] = np.array([v[i:i + step].mean() for i in idx])
    for name in dict.fromkeys((*outputs, *states, *extra)):
        if name in d:
            cols[name] = np.asarray(d[name], dtype=float)[idx]
    return cs.Dataset(d.t[idx], cols, {k: d.units.get(k, "") for k in cols}, d.meta)


def approach(run: Run) -> dict:
    """The straight run before the execute: mean surge speed, propeller rate, rudder angle, yaw rate
    and the measured surge acceleration (slope of ``u``) over it."""
    d = run.data
    t_exec = execute_time(d)
    k = max(int(np.searchsorted(d.t, t_exec)), 3)
    u = np.asarray(d["u"][:k])
    slope = float(np.polyfit(d.t[:k] - d.t[0], u, 1)[0])
    return {"t_exec_s": t_exec, "u": float(u.mean()), "n": float(np.mean(d["n"][:k])),
            "delta": float(np.mean(d["delta"][:k])), "r": float(np.mean(d["r"][:k])), "u_dot": slope}


def first_rudder_side(run: Run) -> str:
    """``"+"`` or ``"-"``: the side the manoeuvre turns to first (:func:`casship.identify.asymmetry.turn_side`:
    the first deflection beyond half the largest one, so that a 5/1 zig-zag is classified right)."""
    return turn_side(run.data)


def regime(run: Run) -> str:
    """The manoeuvre regime of a run: ``"turning circles"``, ``"large-rudder zig-zags"`` (rudder 20 deg
    and more) or ``"small-angle zig-zags"``."""
    if run.kind == "turning":
        return "turning circles"
    d = np.asarray(run.data["delta"], dtype=float)
    return "large-rudder zig-zags" if np.degrees(np.abs(d - d[0]).max()) >= REGIME_DEG else "small-angle zig-zags"
