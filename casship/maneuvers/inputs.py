"""Manoeuvre inputs: which inputs steer and propel a ship, open-loop generators and closed-loop rudder laws.

Open-loop generators (:func:`turning_inputs`, :func:`pullout_inputs`, :func:`spiral_inputs`,
:func:`random_rudder_inputs`) return a mapping input name -> array on the time grid for
:func:`casship.simulate`; :class:`ZigZag` and :class:`ReverseSpiral` are closed-loop ``inputs(t, x)``
callables (the rudder switches on the heading / follows a yaw-rate target).

Sign convention: positive rudder turns the ship to starboard (heading increases), as in the MMG
standard; a zig-zag with a negative angle goes to port first.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..model import Model
from ..errors import InputError

__all__ = ["vessel_of", "rudder_inputs", "propeller_inputs", "straight_run_state", "turning_inputs", "pullout_inputs",
           "spiral_inputs", "random_rudder_inputs", "ZigZag", "ReverseSpiral"]


# -- model introspection ---------------------------------------------------------------------------------
def vessel_of(model: Model):
    """The model's :class:`~casship.vessel.Vessel`.

    Parameters
    ----------
    model : Model
        A ship model.

    Returns
    -------
    Vessel

    Raises
    ------
    ValueError
        Naming the model, if it has no vessel.
    """
    if model.vessel is None:
        raise InputError(f"model {model.name!r} has no vessel (particulars, rudder and propeller inputs); "
                         "build it with ModelBuilder.vessel = casship.Vessel(...)")
    return model.vessel


def rudder_inputs(model: Model) -> tuple[str, ...]:
    """Names of the model's rudder inputs (``model.vessel.rudders``).

    Parameters
    ----------
    model : Model
        A ship model with a vessel.

    Returns
    -------
    tuple of str

    Raises
    ------
    ValueError
        If the vessel names no rudder.
    """
    names = vessel_of(model).rudders
    if not names:
        raise InputError(f"model {model.name!r} has no rudder input (vessel {model.vessel.name!r} names none)")
    return names


def propeller_inputs(model: Model) -> tuple[str, ...]:
    """Names of the model's propeller inputs (``model.vessel.propellers``; may be empty).

    Parameters
    ----------
    model : Model
        A ship model with a vessel.

    Returns
    -------
    tuple of str
    """
    return vessel_of(model).propellers


def straight_run_state(model: Model, speed: float, psi: float = 0.0) -> np.ndarray:
    """State vector of a straight run: ``u = speed``, heading ``psi``, everything else zero.

    Parameters
    ----------
    model : Model
        A ship model with a state ``u`` (and optionally ``psi``).
    speed : float
        Surge speed [m/s].
    psi : float
        Heading [rad].

    Returns
    -------
    numpy.ndarray
        The state vector (nx,).
    """
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


# -- open-loop input generators --------------------------------------------------------------------------
def _ramp(t: np.ndarray, t0: float, start: float, target: float, rate: float | None) -> np.ndarray:
    if rate is None or not np.isfinite(rate):
        return np.where(t >= t0, target, start)
    if rate <= 0:
        raise InputError(f"rudder rate must be positive, got {rate}")
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
    state, which limits the rate itself); ``None`` steps at once.

    Parameters
    ----------
    model : Model
        Ship model with a vessel naming its rudder and propeller inputs.
    t : array_like (N,)
        Time grid [s].
    rudder : float
        Rudder angle [rad]; positive turns to starboard.
    n : float, optional
        Propeller rate given to every propeller input (zero if None).
    t_exec : float
        Execute time [s].
    rate : float, None or "model"
        Rudder rate [rad/s].
    **extra
        Other inputs by name (constants or arrays on ``t``).

    Returns
    -------
    dict
        Input name -> array (N,) for every input of the model.
    """
    t = np.asarray(t, dtype=float)
    delta = _ramp(t, t_exec, 0.0, rudder, _rate(model, rate))
    return _open_loop(model, t, delta, n, extra)


def pullout_inputs(model: Model, t, rudder: float, n: float | None = None, *, t_exec: float = 0.0,
                   hold: float = 300.0, rate: float | None | str = "model", **extra) -> dict[str, np.ndarray]:
    """Pull-out: rudder to ``rudder`` at ``t_exec``, held for ``hold`` [s], then back to zero.

    Parameters
    ----------
    model : Model
        Ship model with a vessel naming its rudder and propeller inputs.
    t : array_like (N,)
        Time grid [s].
    rudder : float
        Rudder angle [rad].
    n : float, optional
        Propeller rate given to every propeller input.
    t_exec : float
        Execute time [s].
    hold : float
        Time the rudder is held before it returns to zero [s].
    rate : float, None or "model"
        Rudder rate [rad/s] (see :func:`turning_inputs`).
    **extra
        Other inputs by name.

    Returns
    -------
    dict
        Input name -> array (N,) for every input of the model.
    """
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

    Parameters
    ----------
    model : Model
        Ship model with a vessel naming its rudder and propeller inputs.
    t : array_like (N,)
        Time grid [s].
    rudders : sequence of float
        Rudder angles [rad], in order.
    n : float, optional
        Propeller rate given to every propeller input.
    hold : float
        Hold time of each rudder angle [s].
    rate : float, None or "model"
        Rudder rate [rad/s] (see :func:`turning_inputs`).
    **extra
        Other inputs by name.

    Returns
    -------
    dict
        Input name -> array (N,) for every input of the model.
    """
    t = np.asarray(t, dtype=float)
    if t[-1] - t[0] <= (len(rudders) - 1) * hold:
        raise InputError(f"time grid covers {t[-1] - t[0]:g} s, the spiral needs more than "
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
                         rate: float | None | str = None, **extra) -> dict[str, np.ndarray]:
    """Random rudder sequence: each rudder uniform in its range, held ``hold`` [s] (Koike et al. 2023, Fig. 8).

    Default ranges: ``delta_s`` in [-35, 105] deg and ``delta_p`` in [-105, 35] deg for twin rudders
    (Koike et al. 2023), [-35, 35] deg for a single rudder. Koike et al. (2023) do not state the hold time; 10 s is
    an assumption. Deterministic for a given ``seed``.

    Parameters
    ----------
    model : Model
        Ship model with a vessel naming its rudder and propeller inputs.
    t : array_like (N,)
        Time grid [s].
    n : float, optional
        Propeller rate given to every propeller input.
    hold : float
        Hold time of each random value [s].
    seed : int or numpy.random.Generator, optional
        Random source.
    ranges_deg : mapping rudder name -> (low, high), optional
        Ranges [deg] replacing the defaults.
    rate : float, None or "model"
        Rudder rate [rad/s] at which each rudder moves to its next value (see
        :func:`turning_inputs`); ``None`` (default) steps at once.
    **extra
        Other inputs by name.

    Returns
    -------
    dict
        Input name -> array (N,) for every input of the model.
    """
    t = np.asarray(t, dtype=float)
    rng = np.random.default_rng(seed)
    names = rudder_inputs(model)
    defaults = {"delta_s": (-35.0, 105.0), "delta_p": (-105.0, 35.0), "delta_s_cmd": (-35.0, 105.0),
                "delta_p_cmd": (-105.0, 35.0)}
    ranges = {name: defaults.get(name, (-35.0, 35.0)) for name in names}
    for key, val in (ranges_deg or {}).items():
        if key not in names:
            raise InputError(f"range given for unknown rudder {key!r}; rudders: {list(names)}")
        ranges[key] = tuple(val)
    if hold <= 0:
        raise InputError(f"hold must be positive, got {hold}")
    if hold >= t[-1] - t[0]:
        raise InputError(f"hold {hold:g} s is not shorter than the record ({t[-1] - t[0]:g} s): the random sequence "
                         "would be one rudder angle held throughout")
    segment = np.floor((t - t[0]) / hold).astype(int)
    count = segment[-1] + 1
    values = {}
    for name in names:
        lo, hi = np.radians(ranges[name][0]), np.radians(ranges[name][1])
        if not lo < hi:
            raise InputError(f"range of {name!r} must have low < high, got {ranges[name]}")
        values[name] = _rate_limited(t, rng.uniform(lo, hi, count)[segment], _rate(model, rate))
    out = _open_loop(model, t, None, n, extra)
    out.update(values)
    return out


def _rate_limited(t: np.ndarray, target: np.ndarray, rate: float | None) -> np.ndarray:
    """``target`` followed at most at ``rate`` per second (``None``: exactly)."""
    if rate is None or not np.isfinite(rate):
        return target
    if rate <= 0:
        raise InputError(f"rudder rate must be positive, got {rate}")
    followed = np.empty_like(target)
    followed[0] = target[0]
    steps = rate * np.diff(t)
    for k in range(1, t.size):
        followed[k] = followed[k - 1] + np.clip(target[k] - followed[k - 1], -steps[k - 1], steps[k - 1])
    return followed


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
            raise InputError(f"unknown input name {key!r}; model inputs: {list(model.input_names)}")
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
            raise InputError(f"zig-zag needs a non-zero rudder and a positive switch heading, got {rudder}, {heading}")
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
            raise InputError(f"ZigZag instances are single-use: time went backwards from {self.t_prev:g} s to "
                             f"{t:g} s (create a new instance per run)")
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

    Parameters
    ----------
    model : Model
        Ship model with a vessel naming its rudder inputs and a state ``r``.
    yaw_rates : sequence of float
        Yaw-rate targets [rad/s], in order.
    hold : float
        Hold time of each target [s].
    n : float, optional
        Propeller rate held constant.
    gain : float
        Feedback gain [s] from yaw-rate error to rudder angle.
    rudder_max : float, optional
        Rudder limit [rad] (default ``model.vessel.rudder_max``, else 35 deg).
    rate : float, None or "model"
        Rudder rate [rad/s].
    t0 : float
        Start of the first hold [s].
    **extra
        Other inputs held constant.
    """

    def __init__(self, model: Model, yaw_rates: Sequence[float], hold: float, n: float | None = None, *,
                 gain: float = 20.0, rudder_max: float | None = None, rate: float | None | str = "model",
                 t0: float = 0.0, **extra):
        if hold <= 0:
            raise InputError(f"hold must be positive, got {hold}")
        self.model, self.yaw_rates, self.hold, self.gain, self.t0 = model, list(yaw_rates), hold, gain, t0
        vessel_max = vessel_of(model).rudder_max
        self.rudder_max = rudder_max if rudder_max is not None else vessel_max if vessel_max else np.radians(35)
        self.rate = _rate(model, rate)
        self.base = _input_vector(model, 0.0, n, **extra)
        self.rudder_index = model.indices(rudder_inputs(model), "input")
        self.i_r = model.index("r")
        self.delta, self.t_prev = 0.0, None

    def target(self, t: float) -> float:
        """The yaw-rate target [rad/s] at time ``t`` [s].

        Parameters
        ----------
        t : float
            Time [s].

        Returns
        -------
        float
        """
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
