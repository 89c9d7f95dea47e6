"""Ships as an autopilot sees them: which input steers, the straight-run operating point, and the
steering of a craft without a rudder (two propellers, e.g. the Otter) by a yaw moment.

:func:`steering_plant` reads ``model.vessel`` (rudders, propellers, ``U0``) and returns a
:class:`SteeringPlant` at the trim point that holds the speed: the propeller rate of a rudder ship,
or the surge force of a twin-propeller craft, whose propellers are then driven through
:func:`twin_propeller_allocation` from a surge force ``tau_X`` and a yaw moment ``tau_N`` (the
steering input).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from ..discretize import discretize
from ..linear import trim
from ..builder import ModelBuilder
from ..model import Model
from ..errors import InputError
from ..simulation import ValidityError

__all__ = ["SteeringPlant", "steering_plant", "steering_model", "twin_propeller_allocation", "SteeringFeedforward",
           "steering_feedforward", "piecewise_linear", "speed_profile",
           "twin_propeller_yaw_limit"]


@dataclass(frozen=True)
class SteeringPlant:
    """A ship model seen by an autopilot: which input steers, which states are position and heading.

    Parameters
    ----------
    model : Model
        States must include the North/East position and the heading (names below).
    steer : str
        Input name of the steering command (rudder angle [rad] or yaw moment [N m]).
    inputs : mapping
        Values of the other inputs (e.g. the propeller rate from :func:`casship.trim`, wind and current).
    p : array or mapping, optional
        Parameters of the ship (the truth in a simulation; nominal by default).
    north, east, heading, yaw_rate : str
        State names.
    x0 : array, optional
        The straight-run operating point (set by :func:`steering_plant`).
    """

    model: Model
    steer: str = "delta"
    inputs: Mapping[str, float] = field(default_factory=dict)
    p: object = None
    north: str = "x"
    east: str = "y"
    heading: str = "psi"
    yaw_rate: str = "r"
    x0: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        m = self.model
        m.index(self.steer, "input")
        for n in (self.north, self.east, self.heading, self.yaw_rate):
            m.index(n)
        unknown = set(self.inputs) - set(m.input_names)
        if unknown:
            raise InputError(f"unknown input(s) {sorted(unknown)} of {m.name!r}; inputs: {list(m.input_names)}")
        missing = [n for n in m.input_names if n != self.steer and n not in self.inputs]
        if missing:
            raise InputError(f"give values for the input(s) {missing} of {m.name!r}")
        object.__setattr__(self, "inputs", {k: float(v) for k, v in self.inputs.items()})
        object.__setattr__(self, "pvec", m.params(self.p) if self.p is not None else m.params())
        if self.x0 is not None:
            object.__setattr__(self, "x0", np.asarray(self.x0, dtype=float).reshape(m.nx))

    def replace(self, **changes) -> "SteeringPlant":
        """A copy with fields changed (``inputs`` are merged into the present ones).

        Parameters
        ----------
        **changes
            Fields of :class:`SteeringPlant`.
        """
        if "inputs" in changes:
            changes["inputs"] = {**self.inputs, **changes["inputs"]}
        return replace(self, **changes)

    def input_vector(self, steer: float = 0.0) -> np.ndarray:
        """All inputs of the model with the steering input set to ``steer``.

        Parameters
        ----------
        steer : float
        """
        return self.model.inputs(**{**self.inputs, self.steer: steer})

    def symbolic_step(self, x, steer, p, dt):
        """One RK4 step of the ship with the other inputs bound (CasADi expressions).

        Parameters
        ----------
        x : casadi.SX
            State.
        steer : casadi.SX
            Steering held over the step.
        p : casadi.SX or array
            Parameters.
        dt : casadi.SX or float
            Step [s].
        """
        m = self.model
        dm = discretize(m, 1.0, "rk4")
        u = ca.SX(ca.DM(self.input_vector(0.0)))
        u[m.index(self.steer, "input")] = steer
        return dm.F(x, u, p, ca.SX.zeros(m.nw), dt)

    def symbolic_motion(self, x, steer, p):
        """Course over ground, speed over ground and yaw rate at ``x`` (CasADi expressions).

        Parameters
        ----------
        x : casadi.SX
            State.
        steer : casadi.SX or float
            Steering.
        p : casadi.SX or array
            Parameters.
        """
        m = self.model
        u = ca.SX(ca.DM(self.input_vector(0.0)))
        u[m.index(self.steer, "input")] = steer
        xdot = m.f(x, u, p, ca.SX.zeros(m.nw))
        vn, ve = xdot[m.index(self.north)], xdot[m.index(self.east)]
        return ca.atan2(ve, vn), ca.sqrt(vn**2 + ve**2), x[m.index(self.yaw_rate)]

    def step_function(self) -> ca.Function:
        """``plant(x, steer, p, dt) -> (x_next, chi, U)``: one RK4 step with the other inputs bound,
        and the course and speed over ground at ``x`` (the position rates)."""
        m = self.model
        x, s, p, h = ca.SX.sym("x", m.nx), ca.SX.sym("steer"), ca.SX.sym("p", m.np), ca.SX.sym("dt")
        chi, U, _ = self.symbolic_motion(x, s, p)
        return ca.Function("plant", [x, s, p, h], [self.symbolic_step(x, s, p, h), chi, U],
                           ["x", "steer", "p", "dt"], ["x_next", "chi", "U"])


def steering_model(model: Model, new_inputs: Sequence[str], allocation: Callable, name: str | None = None, *,
                   clock: str | None = None) -> Model:
    """A copy of ``model`` whose inputs are driven by ``new_inputs`` through an allocation.

    ``allocation(new, p)`` receives dicts of the new input symbols and the model's parameter
    symbols by name and returns a dict old input name -> expression. Use it to steer a
    thruster-driven craft by a yaw moment: ``{"n1": ..., "n2": ...}`` from ``tau_X, tau_N``. Inputs
    the allocation does not give (e.g. a current or wind) stay inputs of the new model.

    Parameters
    ----------
    model : Model
    new_inputs : sequence of str
        Names of the new inputs.
    allocation : callable
        ``allocation(new, p) -> {old input: expression}``.
    name : str, optional
        Name of the new model.
    clock : str, optional
        Add a state of this name counting time (``clock' = 1``), given to the allocation among
        the new inputs (an input that follows a schedule in time).
    """
    b = ModelBuilder(name or f"{model.name}+allocation", model.doc)
    xs = [b.state(v.name, unit=v.unit, angle=v.angle, doc=v.doc) for v in model.state_vars]
    tick = b.state(clock, unit="s", doc="time") if clock else None
    ps = [b.param(v.name, v.value, bounds=(v.lower, v.upper), unit=v.unit, doc=v.doc, source=v.source)
          for v in model.param_vars]
    ws = [b.noise(v.name, unit=v.unit, doc=v.doc) for v in model.noise_vars]
    us = {n: b.input(n) for n in new_inputs}
    if clock:
        us[clock] = tick
    pd = dict(zip(model.param_names, ps))
    mapping = dict(allocation(us, pd))
    replaced = set(mapping)
    unknown = [n for n in mapping if n not in model.input_names]
    if unknown:
        raise InputError(f"allocation gives input(s) {unknown} that {model.name!r} does not have")
    for v in model.input_vars:
        if v.name not in mapping:
            mapping[v.name] = b.input(v.name, unit=v.unit, angle=v.angle, doc=v.doc)
    old = ca.vertcat(model.x, model.p, model.w, model.u)
    new = ca.vertcat(*xs, *ps, *ws, *[ca.SX(mapping[n]) for n in model.input_names])
    xdot, y = ca.substitute([model.xdot, model.y], [old], [new])
    b.ode(**{n: xdot[i] for i, n in enumerate(model.state_names)}, **({clock: ca.SX(1.0)} if clock else {}))
    for i, v in enumerate(model.output_vars):
        b.output(v.name, y[i], unit=v.unit, angle=v.angle, doc=v.doc)
    b.meta.update(dict(model.meta))
    if model.vessel is not None:      # the new inputs are generalised forces, not rudders or propellers
        kept = [n for n in model.input_names if n not in replaced]
        b.vessel = model.vessel.replace(rudders=tuple(r for r in model.vessel.rudders if r in kept),
                                        propellers=tuple(q for q in model.vessel.propellers if q in kept))
    return b.build()


def speed_profile(plant: SteeringPlant, times: Sequence[float], speeds: Sequence[float], *,
                  propulsion: str | None = None) -> SteeringPlant:
    """The plant with its propulsion following a speed profile in time: a speed change in the
    closed loop.

    At each of ``times`` the propulsion input (a propeller rate, or the surge force of a craft
    steered by a yaw moment) takes the value that holds ``speeds`` on a straight run (solved by
    :func:`casship.trim`), linearly in between and held beyond; the ship's speed follows through
    its own surge dynamics. The model gains a state ``t_clock`` (time, from 0).

    Parameters
    ----------
    plant : SteeringPlant
        The ship at its first operating point.
    times : sequence of float
        Increasing times [s].
    speeds : sequence of float
        Straight-run speeds [m/s] at those times.
    propulsion : str, optional
        The input that sets the speed (default: ``tau_X`` of a twin-propeller craft, else the
        vessel's first propeller).
    """
    from ..linear import trim

    m = plant.model
    times, speeds = [float(t) for t in times], [float(v) for v in speeds]
    if len(times) != len(speeds) or len(times) < 2 or np.any(np.diff(times) <= 0):
        raise InputError("speed_profile needs at least two increasing times and one speed for each")
    if propulsion is None:
        props = [n for n in ("tau_X",) + tuple(m.vessel.propellers if m.vessel else ()) if n in plant.inputs]
        if not props:
            raise InputError(f"no propulsion input among {sorted(plant.inputs)} of {m.name!r}; give propulsion")
        propulsion = props[0]
    if propulsion not in plant.inputs:
        raise InputError(f"{propulsion!r} is not a bound input of the plant; inputs: {sorted(plant.inputs)}")
    values = []
    for v in speeds:
        tr = trim(m, m.states(u=v), plant.input_vector(0.0), plant.pvec, free=[propulsion], zero=["u"])
        values.append(float(tr.values[propulsion]))

    def schedule(new, p):
        return {propulsion: piecewise_linear(new["t_clock"], times, values)}

    model = steering_model(m, [], schedule, name=f"{m.name}_profile", clock="t_clock")
    x0 = np.concatenate([plant.x0, [0.0]])
    others = {k: v for k, v in plant.inputs.items() if k != propulsion}
    return SteeringPlant(model, plant.steer, others, plant.p, plant.north, plant.east, plant.heading, plant.yaw_rate,
                         x0=x0)


def twin_propeller_allocation(model: Model, names: tuple[str, str] = ("n1", "n2")):
    """Allocation ``tau_X, tau_N -> n1, n2`` for a craft steered by two propellers (e.g. the Otter).

    Thrust ``T = k n |n|`` (``k_pos`` ahead, ``k_neg`` astern) on lever arms ``-+ y_pont`` (port
    propeller ``n1``): ``tau_X = T1 + T2``, ``tau_N = y_pont (T1 - T2)``, inverted exactly. Reads
    ``k_pos``, ``k_neg`` and ``y_pont`` from the model's parameters. Use with :func:`steering_model`.

    Parameters
    ----------
    model : Model
    names : (str, str)
        Port and starboard propeller inputs.
    """
    missing = [n for n in names if n not in model.input_names]
    missing += [k for k in ("k_pos", "k_neg", "y_pont") if k not in model.param_names]
    if missing:
        raise InputError(f"twin-propeller allocation needs inputs {list(names)} and parameters k_pos, k_neg, "
                         f"y_pont; model {model.name!r} lacks {missing}")

    def alloc(new, p):
        out = {}
        for name, sign in zip(names, (1, -1)):
            T = new["tau_X"] / 2 + sign * new["tau_N"] / (2 * p["y_pont"])
            k = ca.if_else(T >= 0, p["k_pos"], p["k_neg"])
            out[name] = ca.sign(T) * ca.sqrt(ca.fabs(T) / k)
        return out
    return alloc


def twin_propeller_yaw_limit(model: Model, tau_X: float, p=None) -> float:
    """Largest yaw moment [N m] that keeps both propellers inside ``model.vessel.propeller_range``
    at surge force ``tau_X``.

    Parameters
    ----------
    model : Model
        With ``k_pos, k_neg, y_pont`` parameters and a vessel propeller range.
    tau_X : float
        Surge force [N].
    p : array or mapping, optional
        Parameters.
    """
    pd = model.param_dict(model.params(p) if p is not None else None)
    if model.vessel is None or model.vessel.propeller_range is None:
        raise InputError(f"model {model.name!r} has no vessel propeller_range")
    n_min, n_max = model.vessel.propeller_range
    lever = pd["y_pont"]
    ahead = pd["k_pos"] * n_max**2
    astern = pd["k_neg"] * n_min**2
    limit = 2 * lever * min(ahead - tau_X / 2, tau_X / 2 + astern)
    if limit <= 0:
        raise InputError(f"surge force {tau_X} N leaves no yaw moment within the propeller limits")
    return float(limit)


def _is_twin_propeller(model: Model) -> bool:
    v = model.vessel
    return v is not None and not v.rudders and len(v.propellers) == 2


def steering_plant(model: Model, speed: float | None = None, *, p=None, steer: str | None = None,
                   inputs: Mapping[str, float] | None = None, surge: str = "u") -> SteeringPlant:
    """The ship at its straight-run operating point, as a :class:`SteeringPlant`.

    * A ship with a rudder (``model.vessel.rudders``) steers by its first rudder; with one propeller
      the propeller rate that holds ``speed`` is solved by :func:`casship.trim`.
    * A craft with two propellers and no rudder (the Otter) is steered by a yaw moment: the model's
      propeller inputs are replaced by ``tau_X, tau_N`` (:func:`steering_model`,
      :func:`twin_propeller_allocation`), ``tau_X`` trimmed for ``speed``, ``tau_N`` steers.
    * Any other model needs ``steer`` and values of its other ``inputs``.

    Parameters
    ----------
    model : Model
    speed : float, optional
        Straight-run speed [m/s] (default ``model.vessel.U0``).
    p : array or mapping, optional
        Parameters (nominal by default).
    steer : str, optional
        Steering input (default from the vessel).
    inputs : mapping, optional
        Fixed values of other inputs (a given propeller rate is not trimmed).
    surge : str
        Name of the surge-speed state.

    Returns
    -------
    SteeringPlant
        With ``x0`` the trimmed state.

    Examples
    --------
    >>> from casship.models import get_model
    >>> plant = steering_plant(get_model("otter"))
    >>> plant.steer, sorted(plant.inputs)
    ('tau_N', ['tau_X'])
    """
    vessel = model.vessel
    inputs = dict(inputs or {})
    if speed is None:
        if vessel is None or vessel.U0 is None:
            raise InputError(f"model {model.name!r} has no vessel speed U0; give speed")
        speed = vessel.U0
    speed = float(speed)
    if not (np.isfinite(speed) and speed > 0):
        raise InputError(f"speed must be positive, got {speed}")
    free = None
    if steer is None and _is_twin_propeller(model):
        model = steering_model(model, ["tau_X", "tau_N"], twin_propeller_allocation(model, vessel.propellers),
                               name=f"{model.name}_tau")
        steer = "tau_N"
        if "tau_X" not in inputs:
            free, inputs["tau_X"] = "tau_X", 10.0
    elif steer is None:
        if vessel is None or not vessel.rudders:
            raise InputError(f"model {model.name!r} names no rudder (vessel.rudders); give steer")
        steer = vessel.rudders[0]
        props = vessel.propellers
        if len(props) == 1 and props[0] not in inputs:
            free, inputs[props[0]] = props[0], float(vessel.n0 or 1.0)
    if surge not in model.state_names:
        raise InputError(f"model {model.name!r} has no surge state {surge!r}; states: {list(model.state_names)}")
    pv = model.params(p) if p is not None else model.params()
    x = model.states(**{surge: speed})
    u = model.inputs(**{k: v for k, v in inputs.items() if k != steer})
    if free is not None:
        try:
            tr = trim(model, x, u, pv, free=[free], zero=[surge])
        except ValidityError:
            if free == "tau_X" or vessel.n0:
                raise
            # no stated rate to start from (a model-scale ship): the start at 1 rps ended on the propeller's
            # reversed root; propeller_rate_for_speed scans the declared range for the sign change of du/dt
            from ..maneuvers import propeller_rate_for_speed

            inputs[free] = propeller_rate_for_speed(model, speed, pv, inputs={k: v for k, v in inputs.items()
                                                                            if k not in (steer, free)})
            u = model.inputs(**{k: v for k, v in inputs.items() if k != steer})
            tr = trim(model, x, u, pv, free=[free], zero=[surge])
        x, u = tr.x, tr.u
        inputs[free] = tr.values[free]
    others = {n: float(u[model.index(n, "input")]) for n in model.input_names if n != steer}
    return SteeringPlant(model, steer, others, p, x0=x)


@dataclass(frozen=True)
class SteeringFeedforward:
    """The steady steering that holds a rate of turn, from the nonlinear ship (a reverse spiral at
    the design speed).

    For each rate of turn ``r`` on the grid the steering and the sway velocity are solved
    (:func:`casship.trim`) so that sway and yaw accelerate no more, the surge speed held at the
    design speed: the quasi-steady turn of a course change, which is over before the speed has
    dropped (a ship that keeps turning slows down and needs more steering than this). On a
    course-unstable ship the curve is not monotonic near ``r = 0`` (the spiral loop): the steady
    steering there has the opposite sign and the feedback keeps the turn stable.

    Parameters
    ----------
    rates : tuple of float
        Rates of turn [rad/s], increasing, symmetric about 0 (fractions :attr:`FRACTIONS` of
        ``r_top``).
    steer : tuple of float
        Steady steering at each rate.
    r_top : float
        The rate of turn the ship reaches in this way with the full steering (the smaller of the
        two sides) [rad/s].
    steer_max : float
        The steering limit the table was made for.
    """

    rates: tuple
    steer: tuple
    r_top: float
    steer_max: float

    #: Grid of the table as fractions of ``r_top``.
    FRACTIONS = tuple(np.linspace(-1.0, 1.0, 17))

    def __call__(self, r):
        """Steady steering at rate ``r`` (numbers or CasADi expressions; clamped at the table's ends).

        Parameters
        ----------
        r : float or casadi.SX
        """
        return piecewise_linear(r, self.rates, self.steer)

    def rate_for(self, fraction: float) -> float:
        """The smallest rate of turn [rad/s] (both sides) at which the steady steering reaches
        ``fraction`` of the steering limit.

        Parameters
        ----------
        fraction : float
            Of the steering limit, in (0, 1].
        """
        r, s = np.asarray(self.rates), np.asarray(self.steer) / self.steer_max
        out = []
        for side in (1, -1):
            sel = side * r >= 0
            rr, ss = side * r[sel], side * s[sel]
            order = np.argsort(rr)
            rr, ss = rr[order], ss[order]
            above = np.flatnonzero(ss >= fraction)
            if above.size == 0:
                out.append(rr[-1])
                continue
            k = int(above[-1])
            while k > 0 and ss[k - 1] >= fraction:      # the last crossing from below (past the spiral loop)
                k -= 1
            if k == 0:
                out.append(rr[0])
                continue
            out.append(rr[k - 1] + (fraction - ss[k - 1]) * (rr[k] - rr[k - 1]) / (ss[k] - ss[k - 1]))
        return float(min(out))


def piecewise_linear(x, xs, ys):
    """Linear interpolation through ``(xs, ys)`` clamped at the ends, as a sum of clipped ramps
    (works on numbers and CasADi expressions; ``ys`` may be expressions).

    Parameters
    ----------
    x : float or casadi.SX
    xs : sequence of float
        Increasing breakpoints.
    ys : sequence
        Values at the breakpoints.
    """
    xs = [float(v) for v in xs]
    if len(xs) != len(ys) or len(xs) < 2 or np.any(np.diff(xs) <= 0):
        raise InputError("piecewise_linear needs at least two increasing breakpoints and one value for each")
    out = ys[0]
    for i in range(len(xs) - 1):
        w = (x - xs[i]) / (xs[i + 1] - xs[i])
        w = ca.fmin(ca.fmax(w, 0), 1) if isinstance(w, (ca.SX, ca.MX, ca.DM)) else min(max(w, 0.0), 1.0)
        out = out + (ys[i + 1] - ys[i]) * w
    return out


def steering_feedforward(plant: SteeringPlant, steer_max: float, *, x0=None) -> SteeringFeedforward:
    """The :class:`SteeringFeedforward` of a ship at its operating point.

    The rate of turn is raised from 0 in steps (each trim starting from the last) until the steady
    steering passes ``steer_max`` on each side; ``r_top`` is where it reaches the limit, and the
    table is then solved on :attr:`SteeringFeedforward.FRACTIONS` of ``r_top``.

    Parameters
    ----------
    plant : SteeringPlant
    steer_max : float
        Steering limit.
    x0 : array, optional
        Straight-run state (default ``plant.x0``).

    Raises
    ------
    ValueError
        When no steady turn is found below 20 times ``0.3 U/L`` (or 2 rad/s).
    """
    from ..linear import trim

    m = plant.model
    x0 = np.asarray(x0 if x0 is not None else plant.x0, float)
    js, ir = m.index(plant.steer, "input"), m.index(plant.yaw_rate)
    sway = "v" if "v" in m.state_names else None
    free = ([sway] if sway else []) + [plant.steer]
    zero = ([sway] if sway else []) + [plant.yaw_rate]

    def solve(r, x, u):
        x = np.array(x, float)
        x[ir] = r
        tr = trim(m, x, u, plant.pvec, free=free, zero=zero, check_limits=False)
        return tr.x, tr.u, float(tr.u[js])

    vessel = m.vessel
    U = float(np.hypot(x0[m.index("u")], x0[sway and m.index(sway)] if sway else 0.0)) if "u" in m.state_names else 1.0
    step = (0.3 * U / vessel.L_pp if vessel is not None and vessel.L_pp else 0.1) / 8
    tops = []
    for side in (1.0, -1.0):
        x, u, prev = x0.copy(), plant.input_vector(0.0), (0.0, 0.0)
        for k in range(1, 161):
            r = side * k * step
            x, u, s = solve(r, x, u)
            if side * s >= steer_max:
                r0, s0 = prev
                tops.append(abs(r0 + (side * steer_max - s0) * (r - r0) / (s - s0)))
                break
            prev = (r, s)
        else:
            raise InputError(f"{m.name!r}: no steady turn reaches the steering limit {steer_max:.4g} below "
                             f"{160 * step:.3g} rad/s")
    r_top = float(min(tops))
    rates = [f * r_top for f in SteeringFeedforward.FRACTIONS]
    steer = [0.0] * len(rates)
    mid = len(rates) // 2
    for idx in (range(mid, len(rates)), range(mid, -1, -1)):     # from straight ahead outwards
        x, u = x0.copy(), plant.input_vector(0.0)
        for i in idx:
            x, u, steer[i] = solve(rates[i], x, u)
    return SteeringFeedforward(tuple(rates), tuple(steer), r_top, float(steer_max))
