"""Manoeuvre runners: the propeller rate of a straight run and :func:`run_maneuver`.

:func:`run_maneuver` simulates a named manoeuvre from a straight run at a given speed (the
propeller rate solved for equilibrium by :func:`propeller_rate_for_speed`, a :func:`casship.trim`)
and returns the trajectory with its metrics, after checking the request against the model's
declared validity ranges.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..angles import unwrap
from ..data import Dataset, check_rows
from ..trajectory import Trajectory
from ..model import Model
from ..simulation import check_inputs, check_states, simulate
from .inputs import (ZigZag, _input_vector, propeller_inputs, pullout_inputs, random_rudder_inputs, rudder_inputs,
                     spiral_inputs, straight_run_state, turning_inputs, vessel_of)
from .metrics import turning_metrics, zigzag_metrics
from ..errors import InputError, InputTypeError

__all__ = ["MANEUVERS", "propeller_rate_for_speed", "ManeuverResult", "run_maneuver"]

MANEUVERS = ("turning", "zigzag", "pullout", "spiral", "random")


def propeller_rate_for_speed(model: Model, speed: float, p=None, *, guess: float | None = None,
                             inputs: Mapping[str, float] | None = None, check_limits: bool = True) -> float:
    """Propeller rate that holds ``speed`` in a straight run (``du/dt = 0`` with zero rudder).

    A :func:`casship.trim` with all propeller inputs tied to one rate, started from ``guess``,
    ``model.vessel.n0`` or the first sign change of ``du/dt`` on a scan of rates (within the
    declared propeller range when there is one).

    Parameters
    ----------
    model : Model
        A ship model with a state ``u`` and propeller input(s) (``n`` or ``n1, n2``).
    speed : float
        Surge speed [m/s].
    p : array_like or mapping, optional
        Parameters (nominal by default).
    guess : float, optional
        Starting rate; by default ``model.vessel.n0`` or a scan.
    inputs : mapping, optional
        Other inputs held fixed (e.g. a wind speed).
    check_limits : bool
        Check the speed and the solved rate against the model's declared ranges (``model.limits``).

    Returns
    -------
    float
        The propeller rate in the unit of the model's propeller input.

    Raises
    ------
    ValueError
        If the model has no propeller input, the speed is not positive, no scanned rate gives the
        speed, or the Newton iteration fails (its status is reported).
    casship.simulation.validity.ValidityError
        The speed or the solved rate lies outside the model's declared ranges.
    """
    from ..linear import trim
    from ..simulation import check_states

    props = propeller_inputs(model)
    if not props:
        raise InputError(f"model {model.name!r} has no propeller input; its speed is not set by a propeller rate")
    speed = float(speed)
    if not np.isfinite(speed) or speed <= 0:
        raise InputError(f"speed must be a positive finite number [m/s], got {speed}")
    if check_limits:
        check_states(model, {"u": speed}, "speed: state")
    pv = model.params(p) if p is not None else model.params()
    x = straight_run_state(model, speed)
    u = _input_vector(model, 0.0, None, **dict(inputs or {}))
    start = guess if guess is not None else vessel_of(model).n0
    if start is None:
        start = _scan_rate(model, x, u, pv, props, speed)
    u[model.indices(props, "input")] = float(start)
    group = tuple(props)
    result = trim(model, x, u, pv, free=[group], zero=["u"], tol=1e-12, check_limits=check_limits)
    return float(next(iter(result.values.values())))


def _scan_rate(model: Model, x, u, p, props, speed: float) -> float:
    """Midpoint of the first bracket of rates over which ``du/dt`` changes sign."""
    limit = model.limits.get(props[0])
    lo, hi = (0.0, 1e4) if limit is None else (max(limit.lower, 0.0), min(limit.upper, 1e4))
    grid = np.unique(np.concatenate([np.linspace(lo, min(hi, 10.0), 201),
                                     np.geomspace(10.0, hi, 121) if hi > 10.0 else []]))[1:]
    U = np.repeat(u[:, None], grid.size, axis=1)
    U[model.indices(props, "input"), :] = grid
    fmap = model.f.map(grid.size)
    xdot = np.asarray(fmap(np.repeat(x[:, None], grid.size, axis=1), U, p, np.zeros((model.nw, grid.size))))
    vals = xdot[model.index("u"), :]
    change = np.flatnonzero(np.sign(vals[:-1]) != np.sign(vals[1:]))
    if change.size == 0:
        raise InputError(f"no propeller rate in [{grid[0]:.4g}, {grid[-1]:.4g}] holds {speed} m/s for model "
                         f"{model.name!r}")
    return 0.5 * (grid[change[0]] + grid[change[0] + 1])


# -- runner ---------------------------------------------------------------------------------------------
@dataclass
class ManeuverResult:
    """A simulated manoeuvre: the trajectory, its metrics and the settings used.

    Parameters
    ----------
    trajectory : Trajectory
        The simulated record.
    metrics : dict
        Metrics of the manoeuvre (see :func:`~casship.maneuvers.turning_metrics`,
        :func:`~casship.maneuvers.zigzag_metrics`).
    settings : dict
        Manoeuvre, rudder angle, speed, propeller rate, step and execute time used.
    """

    trajectory: Trajectory
    metrics: dict
    settings: dict = field(default_factory=dict)

    def plot(self, ax=None, path=None):
        """Track and heading with the rudder in degrees (:meth:`Trajectory.plot`), titled with the
        manoeuvre.

        Parameters
        ----------
        ax : matplotlib Axes or sequence of Axes, optional
            Draw into these axes instead of a new figure.
        path : str or Path, optional
            Also write the figure there.

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting`.
        """
        s = self.settings
        title = f"{self.trajectory.model_name}: {s.get('kind', 'manoeuvre')}" + (
            f" {s['rudder_deg']:g} deg" if isinstance(s.get("rudder_deg"), (int, float)) else "")
        return self.trajectory.plot(ax, path, title=title)


def run_maneuver(model: Model, kind: str = "turning", *, rudder_deg: float = 35.0, heading_deg: float | None = None,
                 speed: float | None = None, n: float | None = None, duration: float | None = None,
                 dt: float | None = None, t_exec: float | None = None, p=None, hold: float | None = None,
                 seed=None, method: str = "rk4", rate: float | None | str = "model",
                 check_limits: bool = True, first: str | None = None) -> ManeuverResult:
    """Simulate a named manoeuvre from a straight run and compute its metrics.

    Parameters
    ----------
    model : Model
        A 3-DOF ship model with states ``u, v, r, x, y, psi``.
    kind : {"turning", "zigzag", "pullout", "spiral", "random"}
    rudder_deg : float
        Rudder angle [deg]; negative = to port (for a zig-zag: port first, unless ``first`` says it).
    heading_deg : float, optional
        Zig-zag switch heading [deg] (default ``|rudder_deg|``); negative also means port first.
    speed : float, optional
        Approach speed [m/s] (default ``model.vessel.U0``).
    n : float, optional
        Propeller rate; by default solved for equilibrium at ``speed``.
    duration, dt, t_exec : float, optional
        Defaults scale with ``L/U``: turning 50 L/U, zig-zag 16 L/U, ``dt`` = L/U/400 rounded down
        to 1, 2 or 5 x 10^k,
        ``t_exec = L/U / 4``.
    p : parameters, optional
    hold : float, optional
        Hold time for pull-out, spiral and random rudder [s] (defaults 20, 12, 1.25 L/U).
    seed : int, optional
        For ``random``.
    method : str
        Integration method (see :func:`casship.simulate`).
    rate : float, None or "model"
        Rudder rate [rad/s].
    check_limits : bool
        Check the rudder angle, propeller rate and speed against the model's declared ranges
        (``model.limits``) and the time step against the integrator's stability limit;
        ``False`` is the explicit opt-in for a deliberate out-of-range study.
    first : {"port", "starboard"}, optional
        Zig-zag: the side the rudder goes to first. Without it, port when ``rudder_deg`` or
        ``heading_deg`` is negative, else starboard; a negative angle with ``first="starboard"`` is
        an error. The side is in ``settings["first_side"]``.

    Returns
    -------
    ManeuverResult

    Raises
    ------
    ValueError
        Unknown manoeuvre, non-positive speed, step, duration or hold, a step not shorter than the
        duration.
    casship.simulation.validity.ValidityError
        Rudder, propeller rate or speed outside the model's ranges, or a step beyond the
        integrator's stability limit (unless ``check_limits=False``).

    Warns
    -----
    UserWarning
        A rudder angle below 1 deg (radians given where degrees are expected?) or a turning
        circle whose heading never changes by 90 deg.
    """
    if kind not in MANEUVERS:
        raise InputError(f"unknown manoeuvre {kind!r}; use one of {MANEUVERS}")
    vessel = vessel_of(model)
    L = vessel.L_pp
    if speed is None and vessel.U0 is None:
        raise InputError(f"model {model.name!r}: vessel {vessel.name!r} has no approach speed U0; give speed")
    speed = _positive(vessel.U0 if speed is None else speed, "speed", "m/s")
    rudder_deg = _finite(rudder_deg, "rudder_deg")
    _check_settings(kind, rudder_deg, heading_deg, duration, dt, t_exec, hold)
    pv = model.params(p) if p is not None else model.params()
    rudders = rudder_inputs(model)
    if check_limits:
        check_states(model, {"u": speed}, "speed: state")
        check_inputs(model, {name: np.radians(rudder_deg) for name in rudders})
    props = propeller_inputs(model)
    if n is not None:
        n = _finite(n, "n (propeller rate)")
        if check_limits:
            check_inputs(model, {name: n for name in props})
    if props and n is None:
        n = propeller_rate_for_speed(model, speed, pv, check_limits=check_limits)
    T = L / speed
    dt = float(dt if dt is not None else nice_step(T / 400))
    t_exec = float(t_exec if t_exec is not None else round(T / 4 / dt) * dt)
    if duration is not None and dt >= duration:
        raise InputError(f"dt = {dt:g} s must be shorter than the duration {duration:g} s")
    rudder = np.radians(rudder_deg)
    defaults = {"turning": 50 * T, "zigzag": 16 * T, "pullout": 40 * T, "spiral": None, "random": 20 * T}
    span = 15 * float(hold or 12 * T) if kind == "spiral" else (duration or defaults[kind])
    check_rows(span / dt + 1, f"{kind}: {span:g} s at steps of {dt:g} s")
    x0 = straight_run_state(model, speed)
    settings = {"kind": kind, "rudder_deg": rudder_deg, "speed_mps": speed, "n": n, "dt_s": dt, "t_exec_s": t_exec}
    if first is not None and kind != "zigzag":
        raise InputError(f"first (the side of a zig-zag's first rudder) means nothing for a {kind} manoeuvre")
    if kind == "zigzag":
        heading = np.radians(abs(heading_deg) if heading_deg is not None else abs(rudder_deg))
        sign = _first_side(rudder_deg, heading_deg, first)
        settings["first_side"] = "starboard" if sign > 0 else "port"
        t = np.arange(0.0, (duration or defaults["zigzag"]) + dt / 2, dt)
        ctrl = ZigZag(model, sign * abs(rudder), heading, n, t_exec=t_exec, rate=rate)
        traj = simulate(model, x0, t, ctrl, pv, method=method, check_limits=check_limits)
        metrics = zigzag_metrics(traj, np.degrees(heading), t_exec=t_exec, L=L)
        settings["heading_deg"] = float(np.degrees(heading) * sign)
    elif kind == "spiral":
        hold = float(hold or 12 * T)
        steps = np.radians([25, 20, 15, 10, 5, 3, 1, 0, -1, -3, -5, -10, -15, -20, -25]) * abs(rudder_deg) / 25
        t = np.arange(0.0, len(steps) * hold + dt / 2, dt)
        traj = simulate(model, x0, t, spiral_inputs(model, t, steps, n, hold=hold, rate=rate), pv, method=method,
                        check_limits=check_limits)
        metrics = _spiral_points(traj, steps, hold)
    else:
        t = np.arange(0.0, (duration or defaults[kind]) + dt / 2, dt)
        if kind == "turning":
            inputs = turning_inputs(model, t, rudder, n, t_exec=t_exec, rate=rate)
        elif kind == "pullout":
            if t_exec + float(hold or 20 * T) >= t[-1]:
                raise InputError(f"pull-out: the rudder would return at t = {t_exec + float(hold or 20 * T):g} s, not "
                                 f"before the end of the record ({t[-1]:g} s): a shorter hold or a longer duration")
            inputs = pullout_inputs(model, t, rudder, n, t_exec=t_exec, hold=float(hold or 20 * T), rate=rate)
        else:
            inputs = random_rudder_inputs(model, t, n, hold=float(hold or 1.25 * T), seed=seed)
        traj = simulate(model, x0, t, inputs, pv, method=method, check_limits=check_limits)
        metrics = turning_metrics(traj, t_exec=t_exec, L=L) if kind == "turning" else {}
        if kind == "turning" and "time_to_90_s" not in metrics:
            turned = np.degrees(np.ptp(unwrap(traj["psi"])))
            warnings.warn(f"turning circle with rudder_deg={rudder_deg:g}: the heading changed by only {turned:.3g} deg "
                          f"in {t[-1]:g} s, so advance, transfer and diameters are not reached (a longer duration, "
                          "or a larger rudder angle?)", UserWarning, stacklevel=2)
        if kind == "pullout":
            metrics = _pullout_metrics(traj, t_exec + float(hold or 20 * T))
    return ManeuverResult(traj, metrics, settings)


def _first_side(rudder_deg: float, heading_deg: float | None, first: str | None) -> float:
    """+1 (starboard first) or -1 (port first): ``first``, else port when either angle is negative."""
    negative = [k for k, v in (("rudder_deg", rudder_deg), ("heading_deg", heading_deg)) if v is not None and v < 0]
    if first is None:
        return -1.0 if negative else 1.0
    if first not in ("port", "starboard"):
        raise InputError(f"first must be 'port' or 'starboard', got {first!r}")
    if first == "starboard" and negative:
        raise InputError(f"first='starboard' but {negative[0]} is negative (port first): give magnitudes with first")
    return 1.0 if first == "starboard" else -1.0


def _finite(value, what: str) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise InputTypeError(f"{what} must be a number, got {value!r}") from None
    if not np.isfinite(value):
        raise InputError(f"{what} must be finite, got {value}")
    return value


def _positive(value, what: str, unit: str) -> float:
    value = _finite(value, what)
    if value <= 0:
        raise InputError(f"{what} must be positive, got {value:g} {unit}")
    return value


def _check_settings(kind, rudder_deg, heading_deg, duration, dt, t_exec, hold) -> None:
    """Plausibility of the manoeuvre settings (each named in its error)."""
    if kind != "random" and rudder_deg == 0:
        raise InputError(f"rudder_deg must be non-zero for a {kind} manoeuvre")
    if kind != "random" and abs(rudder_deg) < 1.0:
        warnings.warn(f"rudder_deg={rudder_deg:g} is below 1 deg: the angle is in degrees (np.radians(35) = "
                      f"{np.radians(35):.4f} would be a mistake); pass e.g. rudder_deg=35", UserWarning, stacklevel=3)
    if heading_deg is not None and (not np.isfinite(heading_deg) or heading_deg == 0):
        raise InputError(f"heading_deg must be finite and non-zero, got {heading_deg}")
    for what, value in (("duration", duration), ("dt", dt), ("hold", hold)):
        if value is not None:
            _positive(value, what, "s")
    if t_exec is not None and (_finite(t_exec, "t_exec") < 0 or (duration is not None and t_exec >= duration)):
        raise InputError(f"t_exec = {t_exec:g} s must lie in [0, duration)")


def nice_step(value: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above ``value``."""
    base = 10.0 ** np.floor(np.log10(value))
    return float(max(m * base for m in (1.0, 2.0, 5.0) if m * base <= value * (1 + 1e-12)))


def _spiral_points(traj: Dataset, steps, hold) -> dict:
    t = traj.t - traj.t[0]
    rows = []
    for i, d in enumerate(steps):
        seg = (t >= (i + 0.75) * hold) & (t < (i + 1) * hold)
        rows.append({"rudder_deg": float(np.degrees(d)), "yaw_rate_deg_s": float(np.degrees(traj["r"][seg].mean()))})
    return {"spiral": rows}


def _pullout_metrics(traj: Dataset, t_release: float) -> dict:
    k = np.searchsorted(traj.t, t_release)
    r = traj["r"]
    return {"yaw_rate_at_release_deg_s": float(np.degrees(r[min(k, r.size - 1)])),
            "residual_yaw_rate_deg_s": float(np.degrees(r[-1]))}
