"""A free rudder sequence optimised for what it teaches, under the ship's and the site's limits.

The rudder is piecewise linear between knots ``knot`` seconds apart (zero at the execute), sampled
at mid-step and held over each step of the design's grid. Limits (:class:`TrialLimits`): the
rudder angle (bounds on the knots), the rudder rate (``|d_(i+1) - d_i| <= rate * knot``, linear),
the duration (the grid's length), a track corridor (``|y| <= half width`` from the approach line
at every sample) and a speed floor (``u^2 + v^2 >= speed_min^2`` at every sample). The objective is
the target's variance after the trial (its logarithm, with the model-error floor added), or the D-
or A-criterion, with the trial's information from the same compiled fold as
:func:`~.information.trial_information` (:mod:`~.infofold`: exact sensitivities, the heading's
model discrepancy whitened). Its exact gradient in the knots is the fold's reverse sweep, compiled
with it; SLSQP handles the bounds, the linear rate limit and the path constraints.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..runtime import current_function, jit_function
from ..errors import InputError, SolverError
from .belief import ParameterBelief
from .infofold import InformationFold, free_trial_objective
from .information import CRITERIA, check_noise
from .sensitivity import Approach
from .trials import Trial

__all__ = ["TrialLimits", "optimise_free_trial", "FreeTrialError", "OUTCOMES"]


#: The largest free trial designed: steps of the design's grid, and rudder knots (memory of the reverse
#: sweep grows with the steps, the optimiser's dense algebra with the knots).
MAX_STEPS, MAX_KNOTS = 20_000, 1_000


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
            raise InputError("rudder_rate: the vessel states no rudder rate; give one [rad/s]")
        knot = self.knot if self.knot is not None else max(dt, round(approach.time_scale / 4 / dt) * dt)
        for what, v in (("duration", self.duration), ("rudder_max", rmax), ("rudder_rate", rate), ("knot", knot),
                        ("corridor", self.corridor), ("speed_min", self.speed_min)):
            if v is not None and not (np.isfinite(float(v)) and float(v) > 0):
                raise InputError(f"{what} must be positive and finite, got {v}")
        if approach.rudder_max is not None and rmax > approach.rudder_max * (1 + 1e-12):
            raise InputError(f"rudder_max = {np.degrees(rmax):.4g} deg is beyond the rudder stop "
                             f"({np.degrees(approach.rudder_max):.4g} deg)")
        if abs(knot / dt - round(knot / dt)) > 1e-9:
            raise InputError(f"knot = {knot:g} s must be a whole number of design steps ({dt:g} s)")
        if self.duration < 2 * knot:
            raise InputError(f"duration = {self.duration:g} s is shorter than two rudder knots ({knot:g} s apart)")
        steps, knots = self.duration / dt, self.duration / knot
        if steps > MAX_STEPS or knots > MAX_KNOTS:
            raise InputError(f"duration = {self.duration:g} s is {steps:.4g} design steps of {dt:g} s and {knots:.4g} "
                             f"rudder knots; a free trial is designed over at most {MAX_STEPS} steps and {MAX_KNOTS} "
                             "knots (a shorter duration, a longer step or a longer knot interval)")
        if self.speed_min is not None and self.speed_min >= approach.speed:
            raise InputError(f"speed_min = {self.speed_min:g} m/s is not below the approach speed "
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


#: What the optimiser's outcomes mean, in words.
OUTCOMES = {
    "converged": "converged: no sequence within the limits nearby teaches more",
    "iteration limit": "stopped at the iteration limit (--max-iter) with the best sequence found so far; more "
                       "iterations may improve it a little",
    "line search failed": "stopped where no step improved the objective further (the best sequence found so far)",
}


def _outcome(res) -> str:
    """The optimiser's result as one of :data:`OUTCOMES` (or its own message)."""
    if res.status == 0:
        return "converged"
    if res.status == 9:
        return "iteration limit"
    if res.status in (4, 8):
        return "line search failed"
    return str(res.message)


def optimise_free_trial(approach: Approach, belief: ParameterBelief, noise: Mapping[str, float], limits: TrialLimits, *,
                        gradient: Sequence[float] | None = None, criterion: str | None = None,
                        start: Trial | None = None, max_iter: int = 60, discrepancy: float = 0.0,
                        floor: float = 0.0, fold: InformationFold | None = None, jit=None) -> tuple[Trial, dict]:
    """Optimise a rudder sequence for the target's variance after it (or a D-/A-criterion).

    The objective and its exact gradient come from one compiled Function
    (:func:`~.infofold.free_trial_objective`: the information fold of the whole trial and its
    reverse sweep), so an iteration costs a few hundredths of a second; SLSQP takes the rudder
    angle (bounds), the rudder rate (linear) and the corridor and speed floor (nonlinear, exact
    Jacobians) as constraints.

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
        The target's gradient (the objective is then ``log(g' cov_after g + floor^2)``).
    criterion : {"D", "A"}, optional
        Instead of a target.
    start : Trial, optional
        Starting rudder record (sampled at the knots, its last value held beyond its end, limited to
        the rudder angle); default a 10 deg sine of period 8 knots.
    max_iter : int
        Iteration limit of the optimiser.
    discrepancy : float
        The heading's model discrepancy ``q`` [rad^2/s] (see :mod:`~.infofold`).
    floor : float
        The target's model-error floor (standard deviation) added to its variance after the trial.
    fold : InformationFold, optional
        The information fold (built when not given).
    jit : bool or None
        Compile policy (the runtime's :class:`~casship.runtime.JitPolicy`).

    Returns
    -------
    (Trial, dict)
        The trial ``"free"`` and a report: ``status`` (``converged``, ``iteration limit``...),
        ``outcome`` (the status in words), ``iterations``, ``objective`` at the start and the end,
        ``violations`` (re-checked on a plain simulation).

    Raises
    ------
    ValueError
        Impossible limits, or neither/both of ``gradient`` and ``criterion``.
    FreeTrialError
        No sequence within the limits.
    """
    from scipy.optimize import minimize

    if (gradient is None) == (criterion is None):
        raise InputError("give either the target's gradient or a criterion ('D' or 'A'), not both or neither")
    if criterion is not None and criterion not in CRITERIA:
        raise InputError(f"unknown criterion {criterion!r}; use one of {CRITERIA}")
    noise = check_noise(approach.model, noise)
    lim = limits.resolved(approach)
    dt, names, k = approach.dt, belief.names, len(belief.names)
    n = int(np.floor(lim.duration / dt + 1e-9))
    m = int(np.floor(n * dt / lim.knot + 1e-9))
    B = _interpolation(n, dt, lim.knot, m)
    mm = approach.model
    fold = fold if fold is not None else InformationFold(approach, names, list(noise), jit=jit)
    rudder_rows = [mm.input_names.index(r) for r in approach.rudders]
    fg = jit_function(free_trial_objective(fold, B, rudder_rows, criterion=criterion), jit)
    isig, kc = fold.weights(n, noise, discrepancy)
    u0 = approach.inputs(np.zeros(1))[:, 0]
    w, v = np.linalg.eigh(belief.cov)
    L = v * np.sqrt(np.clip(w, 0.0, None))
    if gradient is not None:
        h = L.T @ np.asarray(gradient, dtype=float)
    elif criterion == "A":
        h = 1.0 / np.diag(belief.cov)
    else:
        h = np.zeros(k)
    fixed = (fold.z0(), approach.p, isig, u0, kc, h, L, float(floor) ** 2)
    last = {}

    def evaluate(dv):
        key = dv.tobytes()
        if last.get("key") != key:
            f, g = current_function(fg)(dv, *fixed)
            last.update(key=key, f=float(f), g=np.asarray(g, dtype=float).reshape(-1))
        return last["f"], last["g"]

    # rudder rate: |d_1| <= rate knot and |d_(i+1) - d_i| <= rate knot (the rudder is 0 at the execute)
    D = np.eye(m) - np.eye(m, k=-1)
    step = lim.rudder_rate * lim.knot
    cons = [{"type": "ineq", "fun": lambda dv: step - D @ dv, "jac": lambda dv: -D},
            {"type": "ineq", "fun": lambda dv: step + D @ dv, "jac": lambda dv: D}]
    if lim.corridor is not None or lim.speed_min is not None:
        path = jit_function(_path_constraints(approach, B, rudder_rows, lim), jit)
        path_args = (approach.x0, approach.p, u0)

        def path_eval(dv):
            g, J = current_function(path)(dv, *path_args)
            return np.asarray(g, dtype=float).reshape(-1), np.asarray(J, dtype=float)
        cons.append({"type": "ineq", "fun": lambda dv: path_eval(dv)[0], "jac": lambda dv: path_eval(dv)[1]})
    knots = np.arange(1, m + 1) * lim.knot
    if start is None:
        d0 = np.radians(10.0) * np.sin(2 * np.pi * knots / (8 * lim.knot))
    else:
        d0 = np.interp(knots, (np.arange(start.rudder.size) + 0.5) * start.dt, start.rudder)
    d0 = _within_rate(np.clip(d0, -lim.rudder_max, lim.rudder_max), step)   # a starting guess only
    f_start = evaluate(d0)[0]
    res = minimize(lambda dv: evaluate(dv)[0], d0, jac=lambda dv: evaluate(dv)[1], method="SLSQP",
                   bounds=[(-lim.rudder_max, lim.rudder_max)] * m, constraints=cons,
                   options={"maxiter": int(max_iter), "ftol": 1e-6})
    dopt = np.clip(np.asarray(res.x, dtype=float), -lim.rudder_max, lim.rudder_max)
    trial = Trial("free", "free", dt, B @ dopt, {"knot_s": lim.knot, "knots_deg": np.degrees(dopt).tolist()})
    bad = limits.violations(trial, approach, tol=1e-4)
    status = _outcome(res)
    report = {"status": status, "outcome": OUTCOMES.get(status, status), "iterations": int(res.nit),
              "objective_start": f_start, "objective": float(evaluate(dopt)[0]), "violations": bad,
              "objective_kind": "log variance" if gradient is not None else f"criterion {criterion}",
              "start": start.name if start is not None else "sine"}
    if bad:
        raise FreeTrialError(f"free trial: the optimiser ended ({status}) with a sequence that breaks the limits: "
                             + "; ".join(bad))
    return trial, report


def _within_rate(d: np.ndarray, step: float) -> np.ndarray:
    """``d`` moved into the rate limit knot by knot (from 0 at the execute): a feasible start."""
    out, prev = np.empty_like(d), 0.0
    for i, v in enumerate(d):
        prev = out[i] = prev + np.clip(v - prev, -step, step)
    return out


def _path_constraints(approach: Approach, B: np.ndarray, rudder_rows: Sequence[int], lim: TrialLimits) -> ca.Function:
    """``(d, x0, p, u0) -> (g, dg/dd)``, ``g >= 0`` for the corridor and the speed floor at every sample."""
    n, m = B.shape
    mm = approach.model
    d, x0 = ca.MX.sym("d", m), ca.MX.sym("x0", mm.nx)
    p, u0 = ca.MX.sym("p", mm.np), ca.MX.sym("u0", mm.nu)
    rud = ca.mtimes(ca.DM(B), d).T
    U = ca.vertcat(*[rud if i in rudder_rows else ca.repmat(u0[i], 1, n) for i in range(mm.nu)])
    X = approach.dmodel.F.mapaccum(n)(x0, U, p, ca.DM.zeros(mm.nw, 1), approach.dt)
    g = []
    if lim.corridor is not None:
        y = X[mm.index("y"), :].T
        g += [lim.corridor - y, lim.corridor + y]
    if lim.speed_min is not None:
        g.append((X[mm.index("u"), :] ** 2 + X[mm.index("v"), :] ** 2).T - lim.speed_min ** 2)
    g = ca.vertcat(*g)
    return ca.Function("free_trial_path", [d, x0, p, u0], [g, ca.jacobian(g, d)], ["d", "x0", "p", "u0"], ["g", "jac"])
