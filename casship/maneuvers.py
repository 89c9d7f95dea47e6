"""Standard manoeuvres (input generators and runners) and their IMO/ITTC metrics.

Input generators
    :func:`turning_inputs`, :func:`pullout_inputs`, :func:`spiral_inputs`, :func:`random_rudder_inputs`
    return open-loop inputs (mapping name -> array on the time grid) for :func:`casship.simulate`;
    :class:`ZigZag` and :class:`ReverseSpiral` are closed-loop ``inputs(t, x)`` callables (the rudder
    switches on the heading / follows a yaw-rate target).
Runners
    :func:`run_maneuver` simulates a named manoeuvre from a straight run at a given speed (the
    propeller rate solved for equilibrium by :func:`propeller_rate_for_speed`) and returns the
    trajectory with its metrics.
Metrics (from any record, simulated or measured, with columns ``x, y, psi`` and optionally ``delta``)
    :func:`turning_metrics` (advance, transfer, tactical diameter, steady diameter and speed, times
    to 90/180 deg), :func:`zigzag_metrics` (overshoot angles, their times, period, initial turning
    time and distance) and :func:`imo_check` (IMO MSC.137(76) criteria, pass/fail rows) with
    :func:`imo_table` (Markdown).

Sign convention: positive rudder turns the ship to starboard (heading increases), as in the MMG
standard; a zig-zag with a negative angle goes to port first.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from .angles import unwrap
from .data import Dataset, Trajectory
from .model import Model
from .simulate import simulate

__all__ = ["rudder_inputs", "propeller_inputs", "propeller_rate_for_speed", "straight_run_state",
           "turning_inputs", "pullout_inputs", "spiral_inputs", "random_rudder_inputs", "ZigZag",
           "ReverseSpiral", "run_maneuver", "turning_metrics", "zigzag_metrics", "execute_time",
           "imo_check", "imo_table", "MANEUVERS"]

MANEUVERS = ("turning", "zigzag", "pullout", "spiral", "random")


# -- model introspection ---------------------------------------------------------------------------------
def vessel_of(model: Model):
    """The model's :class:`~casship.vessel.Vessel`; ``ValueError`` naming the model if it has none."""
    if model.vessel is None:
        raise ValueError(f"model {model.name!r} has no vessel (particulars, rudder and propeller inputs); "
                         "build it with ModelBuilder.vessel = casship.Vessel(...)")
    return model.vessel


def rudder_inputs(model: Model) -> tuple[str, ...]:
    """Names of the model's rudder inputs (``model.vessel.rudders``)."""
    names = vessel_of(model).rudders
    if not names:
        raise ValueError(f"model {model.name!r} has no rudder input (vessel {model.vessel.name!r} names none)")
    return names


def propeller_inputs(model: Model) -> tuple[str, ...]:
    """Names of the model's propeller inputs (``model.vessel.propellers``)."""
    return vessel_of(model).propellers


def straight_run_state(model: Model, speed: float, psi: float = 0.0) -> np.ndarray:
    """State vector of a straight run: ``u = speed``, heading ``psi``, everything else zero."""
    values = {"u": speed}
    if "psi" in model.state_names:
        values["psi"] = psi
    return model.states(**values)


def _input_vector(model: Model, rudder: float = 0.0, n: float | None = None, **extra) -> np.ndarray:
    names = vessel_of(model).rudders
    values = {name: rudder for name in names} if rudder is not None else {}
    if n is not None:
        values.update({name: n for name in propeller_inputs(model)})
    values.update(extra)
    return model.inputs(**values)


def propeller_rate_for_speed(model: Model, speed: float, p=None, *, guess: float | None = None,
                             inputs: Mapping[str, float] | None = None) -> float:
    """Propeller rate that holds ``speed`` in a straight run (``du/dt = 0`` with zero rudder).

    Solved with a CasADi Newton root finder (``casadi.rootfinder``) started from a bracketing
    scan; all propeller inputs of the model get the same rate.

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

    Returns
    -------
    float
        The propeller rate in the unit of the model's propeller input.

    Raises
    ------
    ValueError
        If the model has no propeller input or no rate in the scanned range gives the speed.
    RuntimeError
        If the Newton iteration fails (the status is reported).
    """
    props = propeller_inputs(model)
    if not props:
        raise ValueError(f"model {model.name!r} has no propeller input; its speed is not set by a propeller rate")
    speed = float(speed)
    if not np.isfinite(speed) or speed <= 0:
        raise ValueError(f"speed must be a positive finite number, got {speed}")
    p = model.params(p) if p is not None else model.params()
    x = straight_run_state(model, speed)
    iu = model.index("u")
    n = ca.SX.sym("n")
    base = _input_vector(model, 0.0, 0.0, **dict(inputs or {}))
    u_sym = ca.SX(base)
    for name in props:
        u_sym[model.index(name, "input")] = n
    g = model.f(x, u_sym, p, np.zeros(model.nw))[iu]
    G = ca.Function("du", [n], [g])
    start = guess if guess is not None else vessel_of(model).n0
    if start is None:
        grid = np.concatenate([np.linspace(0.0, 10.0, 201)[1:], np.geomspace(10.0, 1e4, 121)[1:]])
        vals = np.asarray(G.map(grid.size)(grid[None, :])).ravel()
        change = np.flatnonzero(np.sign(vals[:-1]) != np.sign(vals[1:]))
        if change.size == 0:
            raise ValueError(f"no propeller rate in [0, 1e4] holds {speed} m/s for model {model.name!r}")
        start = 0.5 * (grid[change[0]] + grid[change[0] + 1])
    rf = ca.rootfinder("propeller_rate", "newton", G, {"abstol": 1e-12, "max_iter": 100, "error_on_fail": False})
    root = float(rf(float(start)))
    stats = rf.stats()
    if not stats.get("success", False) or not np.isfinite(root) or abs(float(G(root))) > 1e-8:
        raise RuntimeError(f"propeller rate for {speed} m/s: Newton iteration failed "
                           f"(status {stats.get('return_status')!r})")
    return root


# -- open-loop input generators --------------------------------------------------------------------------
def _ramp(t: np.ndarray, t0: float, start: float, target: float, rate: float | None) -> np.ndarray:
    if rate is None or not np.isfinite(rate):
        return np.where(t >= t0, target, start)
    if rate <= 0:
        raise ValueError(f"rudder rate must be positive, got {rate}")
    step = np.clip(rate * (t - t0), 0.0, abs(target - start))
    return start + np.sign(target - start) * step


def _rate(model: Model, rate) -> float | None:
    if rate == "model":
        if any(n.endswith("_cmd") for n in rudder_inputs(model)):
            return None                    # the actuator states limit the rate
        return vessel_of(model).rudder_rate
    return rate


def turning_inputs(model: Model, t, rudder: float, n: float | None = None, *, t_exec: float = 0.0,
                   rate: float | None | str = "model", **extra) -> dict[str, np.ndarray]:
    """Turning circle: rudder from 0 to ``rudder`` [rad] at ``t_exec``, moved at ``rate`` [rad/s].

    ``rate="model"`` uses ``model.vessel.rudder_rate`` (no ramp for models with a rudder actuator
    state, which limits the rate itself); ``None`` steps at once. Propeller inputs get ``n``;
    ``extra`` sets other inputs (constants or arrays).
    """
    t = np.asarray(t, dtype=float)
    delta = _ramp(t, t_exec, 0.0, rudder, _rate(model, rate))
    return _open_loop(model, t, delta, n, extra)


def pullout_inputs(model: Model, t, rudder: float, n: float | None = None, *, t_exec: float = 0.0,
                   hold: float = 300.0, rate: float | None | str = "model", **extra) -> dict[str, np.ndarray]:
    """Pull-out: rudder to ``rudder`` at ``t_exec``, held for ``hold`` [s], then back to zero."""
    t = np.asarray(t, dtype=float)
    r = _rate(model, rate)
    delta = _ramp(t, t_exec, 0.0, rudder, r)
    back = _ramp(t, t_exec + hold, rudder, 0.0, r)
    delta = np.where(t >= t_exec + hold, back, delta)
    return _open_loop(model, t, delta, n, extra)


def spiral_inputs(model: Model, t, rudders: Sequence[float], n: float | None = None, *, hold: float,
                  rate: float | None | str = "model", **extra) -> dict[str, np.ndarray]:
    """Dieudonné spiral: rudder stepped through ``rudders`` [rad], each held ``hold`` [s].

    Use the steady yaw rate at the end of each hold (e.g. the mean over its last quarter) against
    the rudder angle for the spiral curve. ``t`` must reach into the last hold; the last rudder is
    held to the end of ``t``.
    """
    t = np.asarray(t, dtype=float)
    if t[-1] - t[0] <= (len(rudders) - 1) * hold:
        raise ValueError(f"time grid covers {t[-1] - t[0]:g} s, the spiral needs more than "
                         f"{(len(rudders) - 1) * hold:g} s")
    r = _rate(model, rate)
    delta = np.zeros_like(t)
    prev = 0.0
    for i, target in enumerate(rudders):
        t0 = t[0] + i * hold
        seg = (t >= t0) & (t < t0 + hold) if i < len(rudders) - 1 else t >= t0
        delta[seg] = _ramp(t[seg], t0, prev, float(target), r)
        prev = float(target)
    return _open_loop(model, t, delta, n, extra)


def random_rudder_inputs(model: Model, t, n: float | None = None, *, hold: float = 10.0, seed=None,
                         ranges_deg: Mapping[str, tuple[float, float]] | None = None,
                         **extra) -> dict[str, np.ndarray]:
    """Random rudder sequence: each rudder uniform in its range, held ``hold`` [s] (seed 002 Fig. 8).

    Default ranges: ``delta_s`` in [-35, 105] deg and ``delta_p`` in [-105, 35] deg for twin rudders
    (seed 002), [-35, 35] deg for a single rudder. Seed 002 does not state the hold time; 10 s is
    an assumption. Deterministic for a given ``seed``.
    """
    t = np.asarray(t, dtype=float)
    rng = np.random.default_rng(seed)
    names = rudder_inputs(model)
    defaults = {"delta_s": (-35.0, 105.0), "delta_p": (-105.0, 35.0), "delta_s_cmd": (-35.0, 105.0),
                "delta_p_cmd": (-105.0, 35.0)}
    ranges = {name: defaults.get(name, (-35.0, 35.0)) for name in names}
    for key, val in (ranges_deg or {}).items():
        if key not in names:
            raise ValueError(f"range given for unknown rudder {key!r}; rudders: {list(names)}")
        ranges[key] = tuple(val)
    if hold <= 0:
        raise ValueError(f"hold must be positive, got {hold}")
    segment = np.floor((t - t[0]) / hold).astype(int)
    count = segment[-1] + 1
    values = {}
    for name in names:
        lo, hi = np.radians(ranges[name][0]), np.radians(ranges[name][1])
        if not lo < hi:
            raise ValueError(f"range of {name!r} must have low < high, got {ranges[name]}")
        values[name] = rng.uniform(lo, hi, count)[segment]
    out = _open_loop(model, t, None, n, extra)
    out.update(values)
    return out


def _open_loop(model: Model, t, delta, n, extra) -> dict[str, np.ndarray]:
    out = {}
    for name in model.input_names:
        out[name] = np.zeros_like(t)
    if delta is not None:
        for name in rudder_inputs(model):
            out[name] = np.asarray(delta, dtype=float)
    if n is not None:
        for name in propeller_inputs(model):
            out[name] = np.full_like(t, float(n))
    for key, val in extra.items():
        if key not in out:
            raise ValueError(f"unknown input name {key!r}; model inputs: {list(model.input_names)}")
        out[key] = np.broadcast_to(np.asarray(val, dtype=float), t.shape).copy()
    return out


# -- closed-loop manoeuvres -------------------------------------------------------------------------------
class ZigZag:
    """Zig-zag test as a closed-loop input function ``inputs(t, x)`` for :func:`casship.simulate`.

    The rudder goes to ``rudder`` [rad] (its sign is the first side: positive = starboard first)
    at ``t_exec``; whenever the heading change from the heading at execute reaches the switch
    angle on the side the ship is turning to, the rudder is reversed. The rudder moves at
    ``rate`` [rad/s] (``"model"``: ``model.vessel.rudder_rate``; models with a rudder actuator
    get the command directly). Create a new instance for every run (it keeps the rudder state).

    Parameters
    ----------
    model : Model
    rudder : float
        Rudder angle [rad]; sign = first side.
    heading : float
        Heading-change switch angle [rad] (> 0).
    n : float, optional
        Propeller rate held constant.
    t_exec : float
    rate : float, None or "model"
    extra : float
        Other inputs held constant.
    """

    def __init__(self, model: Model, rudder: float, heading: float, n: float | None = None, *,
                 t_exec: float = 0.0, rate: float | None | str = "model", **extra):
        if rudder == 0 or heading <= 0:
            raise ValueError(f"zig-zag needs a non-zero rudder and a positive switch heading, got {rudder}, {heading}")
        self.model, self.rudder, self.heading, self.t_exec = model, float(rudder), float(heading), float(t_exec)
        self.rate = _rate(model, rate)
        self.base = _input_vector(model, 0.0, n, **extra)
        self.rudder_index = model.indices(rudder_inputs(model), "input")
        self.i_psi = model.index("psi")
        self.side = np.sign(rudder)
        self.target = 0.0
        self.delta = 0.0
        self.t_prev = None
        self.psi0 = None
        self.switch_times: list[float] = []

    def __call__(self, t: float, x: np.ndarray) -> np.ndarray:
        if self.t_prev is not None and t < self.t_prev:
            raise ValueError("ZigZag instances are single-use: time went backwards (create a new instance)")
        if t >= self.t_exec:
            if self.psi0 is None:
                self.psi0 = float(x[self.i_psi])
                self.target = self.rudder
            change = float(x[self.i_psi]) - self.psi0
            # target > 0 turns to starboard: switch when the change reaches +heading, and vice versa
            if np.sign(self.target) * change >= self.heading:
                self.target = -self.target
                self.switch_times.append(float(t))
        if self.rate is None or self.t_prev is None:
            self.delta = self.target if self.rate is None else self.delta
        else:
            step = self.rate * (t - self.t_prev)
            self.delta += float(np.clip(self.target - self.delta, -step, step))
        self.t_prev = t
        u = self.base.copy()
        u[self.rudder_index] = self.delta
        return u


class ReverseSpiral:
    """Bech reverse spiral as ``inputs(t, x)``: the rudder holds a yaw-rate target by feedback.

    ``delta = -gain * (r - r_target)`` (rate limited by ``rate``), with the target stepped through
    ``yaw_rates`` [rad/s], each held ``hold`` [s]; the mean rudder against the yaw rate over the end
    of each hold gives the (possibly unstable) spiral curve.
    """

    def __init__(self, model: Model, yaw_rates: Sequence[float], hold: float, n: float | None = None, *,
                 gain: float = 20.0, rudder_max: float | None = None, rate: float | None | str = "model",
                 t0: float = 0.0, **extra):
        if hold <= 0:
            raise ValueError(f"hold must be positive, got {hold}")
        self.model, self.yaw_rates, self.hold, self.gain, self.t0 = model, list(yaw_rates), hold, gain, t0
        vessel_max = vessel_of(model).rudder_max
        self.rudder_max = rudder_max if rudder_max is not None else vessel_max if vessel_max else np.radians(35)
        self.rate = _rate(model, rate)
        self.base = _input_vector(model, 0.0, n, **extra)
        self.rudder_index = model.indices(rudder_inputs(model), "input")
        self.i_r = model.index("r")
        self.delta, self.t_prev = 0.0, None

    def target(self, t: float) -> float:
        k = min(int(max(t - self.t0, 0.0) // self.hold), len(self.yaw_rates) - 1)
        return float(self.yaw_rates[k])

    def __call__(self, t: float, x: np.ndarray) -> np.ndarray:
        want = float(np.clip(-self.gain * (x[self.i_r] - self.target(t)) + self.delta, -self.rudder_max,
                             self.rudder_max)) if self.t_prev is not None else 0.0
        dt = 0.0 if self.t_prev is None else t - self.t_prev
        if self.rate is None:
            self.delta = want
        else:
            step = self.rate * dt
            self.delta += float(np.clip(want - self.delta, -step, step))
        self.t_prev = t
        u = self.base.copy()
        u[self.rudder_index] = self.delta
        return u


# -- runner ---------------------------------------------------------------------------------------------
@dataclass
class ManeuverResult:
    """A simulated manoeuvre: the trajectory, its metrics and the settings used."""

    trajectory: Trajectory
    metrics: dict
    settings: dict = field(default_factory=dict)


def run_maneuver(model: Model, kind: str = "turning", *, rudder_deg: float = 35.0, heading_deg: float | None = None,
                 speed: float | None = None, n: float | None = None, duration: float | None = None,
                 dt: float | None = None, t_exec: float | None = None, p=None, hold: float | None = None,
                 seed=None, method: str = "rk4", rate: float | None | str = "model") -> ManeuverResult:
    """Simulate a named manoeuvre from a straight run and compute its metrics.

    Parameters
    ----------
    model : Model
        A 3-DOF ship model with states ``u, v, r, x, y, psi``.
    kind : {"turning", "zigzag", "pullout", "spiral", "random"}
    rudder_deg : float
        Rudder angle [deg]; negative = to port (for a zig-zag: port first).
    heading_deg : float, optional
        Zig-zag switch heading [deg] (default ``|rudder_deg|``); its sign, if negative, also
        selects port first.
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

    Returns
    -------
    ManeuverResult
    """
    if kind not in MANEUVERS:
        raise ValueError(f"unknown manoeuvre {kind!r}; use one of {MANEUVERS}")
    vessel = vessel_of(model)
    L = vessel.L_pp
    speed = float(speed if speed is not None else vessel.U0 or 0.0)
    if not speed > 0:
        raise ValueError(f"model {model.name!r}: the approach speed must be positive, got {speed} m/s "
                         f"(vessel {vessel.name!r} U0 = {vessel.U0})")
    pv = model.params(p) if p is not None else model.params()
    props = propeller_inputs(model)
    if props and n is None:
        n = propeller_rate_for_speed(model, speed, pv)
    T = L / speed
    dt = float(dt if dt is not None else _nice_step(T / 400))
    t_exec = float(t_exec if t_exec is not None else round(T / 4 / dt) * dt)
    rudder = np.radians(rudder_deg)
    defaults = {"turning": 50 * T, "zigzag": 16 * T, "pullout": 40 * T, "spiral": None, "random": 20 * T}
    x0 = straight_run_state(model, speed)
    settings = {"kind": kind, "rudder_deg": rudder_deg, "speed_mps": speed, "n": n, "dt_s": dt, "t_exec_s": t_exec}
    if kind == "zigzag":
        heading = np.radians(abs(heading_deg) if heading_deg is not None else abs(rudder_deg))
        sign = np.sign(rudder_deg) * (np.sign(heading_deg) if heading_deg else 1.0)
        t = np.arange(0.0, (duration or defaults["zigzag"]) + dt / 2, dt)
        ctrl = ZigZag(model, sign * abs(rudder), heading, n, t_exec=t_exec, rate=rate)
        traj = simulate(model, x0, t, ctrl, pv, method=method)
        metrics = zigzag_metrics(traj, np.degrees(heading), t_exec=t_exec, L=L)
        settings["heading_deg"] = float(np.degrees(heading) * sign)
    elif kind == "spiral":
        hold = float(hold or 12 * T)
        steps = np.radians([25, 20, 15, 10, 5, 3, 1, 0, -1, -3, -5, -10, -15, -20, -25]) * abs(rudder_deg) / 25
        t = np.arange(0.0, len(steps) * hold + dt / 2, dt)
        traj = simulate(model, x0, t, spiral_inputs(model, t, steps, n, hold=hold, rate=rate), pv, method=method)
        metrics = _spiral_points(traj, steps, hold)
    else:
        t = np.arange(0.0, (duration or defaults[kind]) + dt / 2, dt)
        if kind == "turning":
            inputs = turning_inputs(model, t, rudder, n, t_exec=t_exec, rate=rate)
        elif kind == "pullout":
            inputs = pullout_inputs(model, t, rudder, n, t_exec=t_exec, hold=float(hold or 20 * T), rate=rate)
        else:
            inputs = random_rudder_inputs(model, t, n, hold=float(hold or 1.25 * T), seed=seed)
        traj = simulate(model, x0, t, inputs, pv, method=method)
        metrics = turning_metrics(traj, t_exec=t_exec, L=L) if kind == "turning" else {}
        if kind == "pullout":
            metrics = _pullout_metrics(traj, t_exec + float(hold or 20 * T))
    return ManeuverResult(traj, metrics, settings)


def _nice_step(value: float) -> float:
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


# -- metrics --------------------------------------------------------------------------------------------
def execute_time(data: Dataset, rudder: str = "delta", threshold_deg: float = 1.0) -> float:
    """Time of the execute: first sample where ``|delta - delta(0)| > threshold_deg``."""
    if rudder not in data:
        raise ValueError(f"no rudder column {rudder!r} to find the execute time; give t_exec")
    d = np.asarray(data[rudder])
    moved = np.flatnonzero(np.abs(d - d[0]) > np.radians(threshold_deg))
    if moved.size == 0:
        raise ValueError(f"rudder column {rudder!r} never moves by more than {threshold_deg} deg")
    return float(data.t[moved[0]])


def _crossing(t, s, level, start=0):
    """First fractional time (linear interpolation) at or after index ``start`` where s >= level."""
    idx = np.flatnonzero(s[start:] >= level)
    if idx.size == 0:
        return None, None
    k = start + idx[0]
    if k == 0 or s[k - 1] >= level:
        return float(t[k]), k
    frac = (level - s[k - 1]) / (s[k] - s[k - 1])
    return float(t[k - 1] + frac * (t[k] - t[k - 1])), k


def _interp_at(t, values, t_star, k):
    if k == 0:
        return values[0]
    return float(np.interp(t_star, t[k - 1:k + 1], values[k - 1:k + 1]))


def _fit_circle(x, y):
    A = np.column_stack([2 * x, 2 * y, np.ones_like(x)])
    sol, *_ = np.linalg.lstsq(A, x**2 + y**2, rcond=None)
    a, b, c = sol
    return float(np.sqrt(c + a * a + b * b)), (float(a), float(b))


def turning_metrics(data: Dataset, *, t_exec: float | None = None, L: float | None = None,
                    rudder: str = "delta", steady_from_deg: float = 360.0) -> dict:
    """Turning-circle metrics from a record with columns ``x, y, psi`` (and ``delta`` or ``t_exec``).

    Distances are measured from the position at the execute, in the frame of the heading at the
    execute: *advance* is the distance along the original heading when the heading has changed
    by 90 deg, *transfer* the lateral distance then, *tactical diameter* the lateral distance at a
    180 deg change. The *steady diameter* is a least-squares circle through the positions from
    ``steady_from_deg`` heading change (180 deg if the record turns less) to the end of the record
    or, with a rudder column, until the rudder leaves its turning angle (pull-out). The steady speed
    is the mean of ``hypot(u, v)`` (or of the position rates) over the same part.

    Returns
    -------
    dict
        ``advance_m, transfer_m, tactical_diameter_m, steady_diameter_m, steady_speed_mps,
        time_to_90_s, time_to_180_s, turn_direction`` (+1 starboard, -1 port) and, with ``L``,
        the ``*_L`` ratios. Keys of quantities the record does not reach are absent.
    """
    t = data.t
    if t_exec is None:
        t_exec = execute_time(data, rudder)
    k0 = int(np.searchsorted(t, t_exec))
    if k0 >= t.size - 2:
        raise ValueError(f"execute time {t_exec} s is at the end of the record")
    x, y = np.asarray(data["x"], dtype=float), np.asarray(data["y"], dtype=float)
    psi = unwrap(np.asarray(data["psi"], dtype=float))
    psi0 = float(np.interp(t_exec, t, psi))
    x0, y0 = float(np.interp(t_exec, t, x)), float(np.interp(t_exec, t, y))
    along = (x - x0) * np.cos(psi0) + (y - y0) * np.sin(psi0)
    lateral = -(x - x0) * np.sin(psi0) + (y - y0) * np.cos(psi0)
    change = psi - psi0
    sub = change[k0:]
    direction = 1.0 if sub[np.argmax(np.abs(sub))] >= 0 else -1.0
    s = direction * change
    out = {"turn_direction": int(direction), "t_exec_s": float(t_exec)}
    for angle, key in ((90.0, "90"), (180.0, "180")):
        tc, k = _crossing(t, s, np.radians(angle), k0)
        if tc is None:
            continue
        out[f"time_to_{key}_s"] = tc - t_exec
        if angle == 90.0:
            out["advance_m"] = _interp_at(t, along, tc, k)
            out["transfer_m"] = direction * _interp_at(t, lateral, tc, k)
        else:
            out["tactical_diameter_m"] = direction * _interp_at(t, lateral, tc, k)
    # steady part
    end = t.size
    if rudder in data:
        d = np.asarray(data[rudder])
        k_hold = int(np.searchsorted(t, t_exec + out.get("time_to_90_s", 0.0)))
        if k_hold < t.size:
            left = np.flatnonzero(np.abs(d[k_hold:] - d[k_hold]) > np.radians(1.0))
            if left.size:
                end = k_hold + left[0]
    s_end = s[:end]
    start_deg = steady_from_deg if s_end.max(initial=-np.inf) >= np.radians(steady_from_deg + 90) else 180.0
    steady = np.flatnonzero(s_end >= np.radians(start_deg))
    if steady.size >= 10 and s_end[steady[-1]] - s_end[steady[0]] >= np.radians(60):
        seg = slice(steady[0], steady[-1] + 1)
        out["steady_diameter_m"] = 2 * _fit_circle(x[seg], y[seg])[0]
        if "u" in data and "v" in data:
            speed = np.hypot(data["u"][seg], data["v"][seg])
        else:
            speed = np.hypot(np.gradient(x[seg], t[seg]), np.gradient(y[seg], t[seg]))
        out["steady_speed_mps"] = float(np.mean(speed))
        out["steady_from_deg"] = float(start_deg)
    if L:
        for key in ("advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m"):
            if key in out:
                out[key[:-2] + "_L"] = out[key] / L
    return out


def zigzag_metrics(data: Dataset, heading_deg: float, *, t_exec: float | None = None, rudder: str = "delta",
                   L: float | None = None) -> dict:
    """Zig-zag metrics from a record with ``psi`` (and ``delta`` or ``t_exec``; ``x, y`` optional).

    With ``dpsi`` the heading change from the execute and ``s`` the first side (+1 starboard; from
    the first crossing of ``+-heading_deg``), the reversals happen where ``s dpsi`` reaches
    ``+heading``, ``-heading``, ``+heading`` ...; the *k-th overshoot* is the largest excess of
    ``|dpsi|`` over the switch angle between reversal k and k+1.

    Returns
    -------
    dict
        ``overshoot_1_deg, overshoot_2_deg`` (and ``_3``), ``overshoot_k_time_s`` (time of the
        peak after the execute), ``initial_turning_time_s`` (execute -> first reversal),
        ``period_s`` (first -> third reversal), ``first_side`` (+1/-1), with ``x, y``
        ``initial_turning_distance_m`` (track length to the first reversal) and, with ``L``,
        ``initial_turning_distance_L``. Quantities not reached are absent.
    """
    heading = np.radians(float(heading_deg))
    if not heading > 0:
        raise ValueError(f"heading_deg must be positive, got {heading_deg}")
    t = data.t
    if t_exec is None:
        t_exec = execute_time(data, rudder)
    k0 = int(np.searchsorted(t, t_exec))
    psi = unwrap(np.asarray(data["psi"], dtype=float))
    change = psi - float(np.interp(t_exec, t, psi))
    up, ku = _crossing(t, change, heading, k0)
    down, kd = _crossing(t, -change, heading, k0)
    if up is None and down is None:
        raise ValueError(f"the heading never changes by {heading_deg} deg after the execute")
    side = 1.0 if down is None or (up is not None and up <= down) else -1.0
    out = {"first_side": int(side), "t_exec_s": float(t_exec)}
    reversals, k = [], k0
    sign = side
    while True:
        tc, k_new = _crossing(t, sign * change, heading, k)
        if tc is None:
            break
        reversals.append((tc, k_new))
        k, sign = k_new, -sign
    if not reversals:
        return out
    out["initial_turning_time_s"] = reversals[0][0] - t_exec
    sign = side
    for i in range(min(3, len(reversals))):
        k_a = reversals[i][1]
        k_b = reversals[i + 1][1] if i + 1 < len(reversals) else None
        if k_b is None:
            # the peak counts only if the heading has turned back after it
            seg = sign * change[k_a:]
            j = int(np.argmax(seg))
            if j >= seg.size - 1 or seg[-1] > seg[j] - np.radians(0.5):
                break
        else:
            seg = sign * change[k_a:k_b]
            j = int(np.argmax(seg))
        out[f"overshoot_{i + 1}_deg"] = float(np.degrees(seg[j] - heading))
        out[f"overshoot_{i + 1}_time_s"] = float(t[k_a + j] - t_exec)
        sign = -sign
    if len(reversals) >= 3:
        out["period_s"] = reversals[2][0] - reversals[0][0]
    if "x" in data and "y" in data:
        k1 = reversals[0][1]
        track = np.hypot(np.diff(data["x"][k0:k1 + 1]), np.diff(data["y"][k0:k1 + 1])).sum()
        out["initial_turning_distance_m"] = float(track)
        if L:
            out["initial_turning_distance_L"] = float(track / L)
    return out


# -- IMO MSC.137(76) ----------------------------------------------------------------------------------------
def _zz10_limits(L_over_V: float) -> tuple[float, float]:
    if L_over_V < 10:
        first = 10.0
    elif L_over_V < 30:
        first = 5.0 + 0.5 * L_over_V
    else:
        first = 20.0
    return first, first + 15.0          # second overshoot: 15 deg above the first-overshoot limit


def imo_check(L: float, V: float, *, turning: Mapping | None = None, zz10: Mapping | None = None,
              zz20: Mapping | None = None) -> list[dict]:
    """Check metrics against the IMO Standards for Ship Manoeuvrability (MSC.137(76), 2002).

    Criteria: advance <= 4.5 L and tactical diameter <= 5 L (35 deg turning circle); distance
    travelled before a 10 deg heading change with 10 deg rudder <= 2.5 L (from the 10/10
    zig-zag); 10/10 first overshoot <= 10 deg if L/V < 10 s, <= 20 deg if L/V >= 30 s, else
    5 + 0.5 L/V deg; 10/10 second overshoot <= those limits + 15 deg; 20/20 first overshoot <= 25 deg.
    (Stopping ability is not checked.)

    Parameters
    ----------
    L : float
        Length between perpendiculars [m].
    V : float
        Approach speed [m/s].
    turning, zz10, zz20 : mapping, optional
        Outputs of :func:`turning_metrics` / :func:`zigzag_metrics`; missing ones are skipped.

    Returns
    -------
    list of dict
        Rows ``{"criterion", "value", "limit", "unit", "pass"}``.
    """
    if not (L > 0 and V > 0):
        raise ValueError(f"L and V must be positive, got {L}, {V}")
    L_over_V = L / V
    first, second = _zz10_limits(L_over_V)
    rows = []

    def add(name, source, key, limit, unit, scale=1.0):
        if source is not None and key in source:
            value = float(source[key]) * scale
            rows.append({"criterion": name, "value": value, "limit": limit, "unit": unit, "pass": value <= limit})

    add("advance / L (35 deg turning)", turning, "advance_m", 4.5, "-", 1 / L)
    add("tactical diameter / L (35 deg turning)", turning, "tactical_diameter_m", 5.0, "-", 1 / L)
    add("initial turning distance / L (10/10)", zz10, "initial_turning_distance_m", 2.5, "-", 1 / L)
    add(f"10/10 first overshoot (L/V = {L_over_V:.1f} s)", zz10, "overshoot_1_deg", first, "deg")
    add(f"10/10 second overshoot (L/V = {L_over_V:.1f} s)", zz10, "overshoot_2_deg", second, "deg")
    add("20/20 first overshoot", zz20, "overshoot_1_deg", 25.0, "deg")
    return rows


def imo_table(rows: Sequence[Mapping]) -> str:
    """Markdown table of :func:`imo_check` rows."""
    lines = ["| criterion | value | limit | result |", "|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row['criterion']} | {row['value']:.2f} | {row['limit']:.2f} | "
                     f"{'pass' if row['pass'] else 'FAIL'} |")
    return "\n".join(lines)
