"""A free rudder sequence optimised for what it teaches, under the ship's and the site's limits.

The rudder is piecewise linear between knots ``knot`` seconds apart (zero at the execute), sampled
at mid-step and held over each step of the design's grid. Limits (:class:`TrialLimits`): the
rudder angle (bounds on the knots), the rudder rate (``|d_(i+1) - d_i| <= rate * knot``, linear),
the duration (the grid's length), a track corridor (``|y| <= half width`` from the approach line
at every sample) and a speed floor (``u^2 + v^2 >= speed_min^2`` at every sample). The objective is
the target's variance after the trial (its logarithm), or the D- or A-criterion, with the trial's
information ``J' J`` built from the exact sensitivities of the symbolic simulation (the same
weighted residuals as :func:`~.information.trial_information`); IPOPT solves it with exact
gradients (reverse mode over the forward sensitivities) and a limited-memory Hessian.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..errors import SolverError
from .belief import ParameterBelief
from .information import CRITERIA, check_noise
from .sensitivity import Approach
from .trials import Trial

__all__ = ["TrialLimits", "optimise_free_trial", "FreeTrialError"]


class FreeTrialError(SolverError):
    """The optimiser found no rudder sequence within the limits (its status is given)."""


@dataclass(frozen=True)
class TrialLimits:
    """Limits of a free trial.

    Parameters
    ----------
    duration : float
        Length of the trial [s] (a free trial has the whole steps that fit in it).
    rudder_max : float, optional
        Largest rudder angle [rad] (default: the vessel's rudder stop).
    rudder_rate : float, optional
        Largest rudder rate [rad/s] (default: the vessel's).
    corridor : float, optional
        Half width of the track corridor around the approach line [m] (None: no corridor).
    speed_min : float, optional
        Speed floor ``hypot(u, v)`` [m/s] (None: none).
    knot : float, optional
        Time between rudder knots [s] (default ``L/U / 4``, rounded to whole steps).
    """

    duration: float
    rudder_max: float | None = None
    rudder_rate: float | None = None
    corridor: float | None = None
    speed_min: float | None = None
    knot: float | None = None

    def resolved(self, approach: Approach) -> "TrialLimits":
        """These limits with the vessel's defaults filled in, checked for a possible trial.

        Parameters
        ----------
        approach : Approach
            The ship, its approach and the design's step.

        Returns
        -------
        TrialLimits

        Raises
        ------
        ValueError
            Naming the limit: a non-positive or non-finite value, a rudder angle beyond the rudder
            stop, a speed floor not below the approach speed, a duration shorter than two knots.
        """
        dt = approach.dt
        rmax = approach.rudder_max if self.rudder_max is None else float(self.rudder_max)
        rate = approach.rudder_rate if self.rudder_rate is None else float(self.rudder_rate)
        if rate is None:
            raise ValueError("rudder_rate: the vessel states no rudder rate; give one [rad/s]")
        knot = self.knot if self.knot is not None else max(dt, round(approach.time_scale / 4 / dt) * dt)
        for what, v in (("duration", self.duration), ("rudder_max", rmax), ("rudder_rate", rate), ("knot", knot),
                        ("corridor", self.corridor), ("speed_min", self.speed_min)):
            if v is not None and not (np.isfinite(float(v)) and float(v) > 0):
                raise ValueError(f"{what} must be positive and finite, got {v}")
        if approach.rudder_max is not None and rmax > approach.rudder_max * (1 + 1e-12):
            raise ValueError(f"rudder_max = {np.degrees(rmax):.4g} deg is beyond the rudder stop "
                             f"({np.degrees(approach.rudder_max):.4g} deg)")
        if abs(knot / dt - round(knot / dt)) > 1e-9:
            raise ValueError(f"knot = {knot:g} s must be a whole number of design steps ({dt:g} s)")
        if self.duration < 2 * knot:
            raise ValueError(f"duration = {self.duration:g} s is shorter than two rudder knots ({knot:g} s apart)")
        if self.speed_min is not None and self.speed_min >= approach.speed:
            raise ValueError(f"speed_min = {self.speed_min:g} m/s is not below the approach speed "
                             f"{approach.speed:.4g} m/s: no trial can keep it")
        return replace(self, rudder_max=rmax, rudder_rate=rate, knot=float(knot))

    def violations(self, trial: Trial, approach: Approach, tol: float = 1e-6) -> list[str]:
        """Every limit a trial breaks (on its noise-free record at ``approach.p``), one line each.

        Parameters
        ----------
        trial : Trial
        approach : Approach
        tol : float
            Relative tolerance of the checks.

        Returns
        -------
        list of str
            Empty when the trial is within every limit.
        """
        lim = self.resolved(approach)
        out = []
        if trial.duration > lim.duration * (1 + tol):
            out.append(f"duration {trial.duration:g} s > {lim.duration:g} s")
        peak = np.max(np.abs(trial.rudder))
        if peak > lim.rudder_max * (1 + tol):
            out.append(f"rudder {np.degrees(peak):.4g} deg > {np.degrees(lim.rudder_max):.4g} deg")
        steps = np.abs(np.diff(np.concatenate([[0.0], trial.rudder]))) / trial.dt
        if steps.max() > lim.rudder_rate * (1 + tol):
            out.append(f"rudder rate {np.degrees(steps.max()):.4g} deg/s > {np.degrees(lim.rudder_rate):.4g} deg/s")
        if lim.corridor is not None or lim.speed_min is not None:
            rec = trial.record(approach)
            if lim.corridor is not None and np.max(np.abs(rec["y"])) > lim.corridor * (1 + tol):
                out.append(f"track {np.max(np.abs(rec['y'])):.4g} m off the approach line > {lim.corridor:g} m")
            speed = np.hypot(rec["u"], rec["v"])
            if lim.speed_min is not None and speed.min() < lim.speed_min * (1 - tol):
                out.append(f"speed {speed.min():.4g} m/s < {lim.speed_min:g} m/s")
        return out


def _interpolation(n: int, dt: float, knot: float, m: int) -> np.ndarray:
    """Matrix (n, m) from knot values at ``knot, 2 knot, ...`` (0 at t = 0) to mid-step samples."""
    tm = (np.arange(n) + 0.5) * dt
    grid = np.arange(m + 1) * knot
    B = np.zeros((n, m + 1))
    for j in range(m + 1):
        e = np.zeros(m + 1)
        e[j] = 1.0
        B[:, j] = np.interp(tm, grid, e)
    return B[:, 1:]


def optimise_free_trial(approach: Approach, belief: ParameterBelief, noise: Mapping[str, float], limits: TrialLimits, *,
                        gradient: Sequence[float] | None = None, criterion: str | None = None,
                        start: Trial | None = None, max_iter: int = 150) -> tuple[Trial, dict]:
    """Optimise a rudder sequence for the target's variance after it (or a D-/A-criterion).

    Parameters
    ----------
    approach : Approach
        Model, current estimate (``approach.p``, which should hold ``belief.mean``), approach, step.
    belief : ParameterBelief
        What is known before the trial.
    noise : mapping output -> standard deviation
        Measured channels.
    limits : TrialLimits
    gradient : array_like (k,), optional
        The target's gradient (the objective is then ``log(g' cov_after g)``).
    criterion : {"D", "A"}, optional
        Instead of a target.
    start : Trial, optional
        Starting rudder record (sampled at the knots, its last value held beyond its end, limited to
        the rudder angle); default a 10 deg sine of period 8 knots.
    max_iter : int
        IPOPT iteration limit.

    Returns
    -------
    (Trial, dict)
        The trial ``"free"`` and a report: ``status``, ``iterations``, ``objective`` at the start and
        the end, ``violations`` (re-checked on a plain simulation).

    Raises
    ------
    ValueError
        Impossible limits, or neither/both of ``gradient`` and ``criterion``.
    FreeTrialError
        IPOPT ends without a sequence within the limits.
    """
    if (gradient is None) == (criterion is None):
        raise ValueError("give either the target's gradient or a criterion ('D' or 'A'), not both or neither")
    if criterion is not None and criterion not in CRITERIA:
        raise ValueError(f"unknown criterion {criterion!r}; use one of {CRITERIA}")
    noise = check_noise(approach.model, noise)
    lim = limits.resolved(approach)
    dt, names, k = approach.dt, belief.names, len(belief.names)
    n = int(np.floor(lim.duration / dt + 1e-9))
    m = int(np.floor(n * dt / lim.knot + 1e-9))
    B = _interpolation(n, dt, lim.knot, m)
    fold = approach.fold(names, n)
    d = ca.MX.sym("d", m)
    th = ca.MX.sym("theta", k)
    U = approach.inputs(ca.mtimes(ca.DM(B), d).T)
    X = fold.states(th, U)
    sig = np.array([noise[c] for c in noise])
    Y = fold.outputs(th, U, X, list(noise)) / ca.DM(sig)
    J = ca.jacobian(ca.vec(Y), th)
    w, v = np.linalg.eigh(belief.cov)
    S = v * np.sqrt(np.clip(w, 0.0, None))
    JS = ca.mtimes(J, ca.DM(S))
    A = ca.DM.eye(k) + ca.mtimes(JS.T, JS)
    if gradient is not None:
        h = ca.DM(S.T @ np.asarray(gradient, dtype=float))
        obj = ca.log(ca.dot(h, ca.solve(A, h)))
    elif criterion == "D":
        obj = -ca.log(ca.det(A))
    else:
        obj = ca.trace(ca.solve(A, ca.DM(S.T @ np.diag(1.0 / np.diag(belief.cov)) @ S))) / k
    f = ca.substitute(obj, th, ca.DM(fold.theta0))
    Xn = ca.substitute(X, th, ca.DM(fold.theta0))
    g, lbg, ubg = [ca.diff(ca.vertcat(0, d))], [-lim.rudder_rate * lim.knot * np.ones(m)], \
        [lim.rudder_rate * lim.knot * np.ones(m)]
    mm = approach.model
    if lim.corridor is not None:
        g.append(Xn[mm.index("y"), 1:].T)
        lbg.append(-lim.corridor * np.ones(n))
        ubg.append(lim.corridor * np.ones(n))
    if lim.speed_min is not None:
        g.append((Xn[mm.index("u"), 1:] ** 2 + Xn[mm.index("v"), 1:] ** 2).T)
        lbg.append(lim.speed_min ** 2 * np.ones(n))
        ubg.append(np.inf * np.ones(n))
    nlp = {"x": d, "f": f, "g": ca.vertcat(*g)}
    opts = {"ipopt.hessian_approximation": "limited-memory", "ipopt.max_iter": int(max_iter), "ipopt.tol": 1e-6,
            "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"}
    solver = ca.nlpsol("free_trial", "ipopt", nlp, opts)
    knots = np.arange(1, m + 1) * lim.knot
    if start is None:
        d0 = np.radians(10.0) * np.sin(2 * np.pi * knots / (8 * lim.knot))
    else:
        d0 = np.interp(knots, (np.arange(start.rudder.size) + 0.5) * start.dt, start.rudder)
    d0 = np.clip(d0, -lim.rudder_max, lim.rudder_max)          # a starting guess only
    f_start = float(ca.Function("f", [d], [f])(d0))
    sol = solver(x0=d0, lbx=-lim.rudder_max * np.ones(m), ubx=lim.rudder_max * np.ones(m),
                 lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    st = solver.stats()
    dopt = np.asarray(sol["x"]).reshape(-1)
    trial = Trial("free", "free", dt, B @ dopt, {"knot_s": lim.knot, "knots_deg": np.degrees(dopt).tolist()})
    bad = limits.violations(trial, approach, tol=1e-4)
    report = {"status": st.get("return_status", "unknown"), "iterations": int(st.get("iter_count", 0)),
              "objective_start": f_start, "objective": float(sol["f"]), "violations": bad,
              "objective_kind": "log variance" if gradient is not None else f"criterion {criterion}",
              "start": start.name if start is not None else "sine"}
    if bad or not st.get("success", False) and report["status"] not in ("Maximum_Iterations_Exceeded",):
        raise FreeTrialError(f"free trial: IPOPT ended with {report['status']!r}" +
                             (f"; limits broken: {'; '.join(bad)}" if bad else ""))
    return trial, report
