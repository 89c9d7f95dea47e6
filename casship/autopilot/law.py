"""The digital course autopilot and the steering actuator as CasADi steps with named slots.

Control law (course ``chi`` or heading ``psi``, the same form; Fossen 2021, Sec. 15.3)::

    delta_c = sat( m a_d + d r_d - (Kp e + Kd (r - r_d) + Ki z) ),    e = wrap(chi - chi_d),    z' = e

with ``chi_d, r_d, a_d`` from the third-order :class:`~casship.autopilot.reference.ReferenceModel`,
the command saturated at the steering limit and the integrator held while the command saturates
(anti-windup). The steering gear (:class:`Actuator`) is a first-order servo with the rate limit of
the ship's steering gear; the closed loop reports how often that rate limit is active.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..angles import wrap_sym
from .reference import ReferenceModel
from ..errors import InputError

__all__ = ["PIDGains", "Autopilot", "Actuator"]


@dataclass(frozen=True)
class PIDGains:
    """Gains of the control law plus the feed-forward model ``m, d`` and the placed poles.

    The linear controller they define is :meth:`controller` (a labelled python-control system).

    Parameters
    ----------
    Kp, Kd, Ki : float
        Proportional [steer/rad], derivative [steer s/rad] and integral [steer/(rad s)] gains.
    m, d : float
        Feed-forward model ``m a_d + d r_d`` (``T/K`` and ``1/K``).
    method : str
        How the gains were found.
    poles : tuple
        The closed-loop poles the design placed.
    m_hf, T3 : float
        With a second-order Nomoto model: ``T1 T2 / (K T3)`` (the inertia the ship shows to a quick
        change of the steering) and ``T3``; the nonlinear law's feed-forward then inverts the
        second-order model (see :func:`law_step`). NaN: the first-order ``m a_d``.
    """

    Kp: float
    Kd: float
    Ki: float
    m: float
    d: float
    method: str = ""
    poles: tuple = ()
    m_hf: float = float("nan")
    T3: float = float("nan")

    def __post_init__(self):
        for name in ("Kp", "Kd", "Ki", "m", "d"):
            v = getattr(self, name)
            if not np.isfinite(v):
                raise InputError(f"gain {name} must be finite, got {v}")
        if np.isfinite(self.T3) and not self.T3 > 0:
            raise InputError(f"T3 must be positive, got {self.T3}")

    def controller(self, *, steer: str = "delta", feedforward: bool = True, name: str = "autopilot"):
        """The linear control law as a labelled :class:`control.StateSpace`.

        Inputs ``chi_d, r_d, a_d`` (reference model) and ``chi, r`` (measured course and rate),
        output ``<steer>_c`` (the steering command), state ``z`` (integral of the course error).
        The angle wrap and the limits are the nonlinear parts left to :class:`Autopilot`.

        Parameters
        ----------
        steer : str
            Name of the steering input.
        feedforward : bool
            Include ``m a_d + d r_d``.
        name : str
            System name.
        """
        import control

        ff = 1.0 if feedforward else 0.0
        # z' = chi - chi_d;  delta_c = ff (m a_d + d r_d) - Kp (chi - chi_d) - Kd (r - r_d) - Ki z
        B = np.array([[-1.0, 0.0, 0.0, 1.0, 0.0]])
        C = np.array([[-self.Ki]])
        D = np.array([[self.Kp, ff * self.d + self.Kd, ff * self.m, -self.Kp, -self.Kd]])
        return control.ss(np.zeros((1, 1)), B, C, D, states=["z"], inputs=["chi_d", "r_d", "a_d", "chi", "r"],
                          outputs=[f"{steer}_c"], name=name)

    def as_dict(self) -> dict:
        """The gains as a plain dict (poles as ``[re, im]`` when complex)."""
        return {"Kp": self.Kp, "Kd": self.Kd, "Ki": self.Ki, "m": self.m, "d": self.d, "method": self.method,
                "poles": [[float(np.real(p)), float(np.imag(p))] if np.iscomplex(p) else float(np.real(p))
                          for p in self.poles]}


@dataclass(frozen=True)
class Autopilot:
    """PID/LQR course (or heading) autopilot with reference model, command limit and anti-windup.

    Parameters
    ----------
    gains : PIDGains
    reference : ReferenceModel
    steer_max : float
        Saturation of the steering command (rudder angle [rad] or yaw moment [N m]).
    anti_windup : bool
        Stop integrating while the command saturates in the direction the integrator pushes.
    feedforward : bool
        Use the feed-forward ``m a_d + d r_d`` from the reference model (with ``steering``:
        ``m a_d + s(r_d)``).
    filter_T : float
        Time constant [s] of a first-order low-pass on the command (0 = none).
    steering : SteeringFeedforward, optional
        The steady steering ``s(r)`` of the nonlinear ship (:func:`~casship.autopilot.plants.steering_feedforward`);
        replaces the linear ``d r_d`` of the feed-forward, so that a large turn is asked of the ship
        with the steering it needs (the yaw damping of most ships grows faster than linearly).
    """

    gains: PIDGains
    reference: ReferenceModel
    steer_max: float = float("inf")
    anti_windup: bool = True
    feedforward: bool = True
    filter_T: float = 0.0
    steering: object = None

    #: Names of the memory entries of :attr:`function` (``w``: ``a_d`` low-passed by ``T3``).
    MEMORY = ("chi_d", "r_d", "a_d", "z", "filtered", "w")

    def __post_init__(self):
        if not self.steer_max > 0:
            raise InputError(f"steer_max must be positive, got {self.steer_max}")
        if not (np.isfinite(self.filter_T) and self.filter_T >= 0):
            raise InputError(f"filter_T must be >= 0, got {self.filter_T}")

    def memory0(self, chi0: float = 0.0) -> np.ndarray:
        """Initial memory: reference model at rest at ``chi0``, no integral, no command.

        Parameters
        ----------
        chi0 : float
            Initial course (or heading) [rad].
        """
        return np.array([chi0, 0.0, 0.0, 0.0, 0.0, 0.0])

    def parameters(self, speed=None) -> dict:
        """The numbers of the law by name: gains, feed-forward model, reference model and the
        steady-steering table (what a gain schedule interpolates over the speed).

        Parameters
        ----------
        speed : float or casadi.SX, optional
            Ignored by a point design (used by :class:`~casship.autopilot.schedule.ScheduledAutopilot`).
        """
        g, ref = self.gains, self.reference
        second = np.isfinite(g.m_hf) and np.isfinite(g.T3)
        out = {"Kp": g.Kp, "Kd": g.Kd, "Ki": g.Ki, "m": g.m, "d": g.d, "m_hf": g.m_hf if second else g.m,
               "T3": g.T3 if second else 1.0, "wn_ref": ref.wn, "zeta_ref": ref.zeta, "r_max": ref.r_max,
               "steer_max": self.steer_max}
        if self.steering is not None:
            out["r_top"] = self.steering.r_top
            out.update({f"ff_{i}": v for i, v in enumerate(self.steering.steer)})
        return out

    def symbolic_step(self, mem, ref, chi, r, dt, speed=None, steer=None, bias=None) -> dict:
        """One sample of the law on CasADi expressions; returns a dict of named expressions
        (``memory, steer, chi_d, r_d, a_d, e``).

        Parameters
        ----------
        mem : casadi.SX
            Memory (:attr:`MEMORY`).
        ref : casadi.SX
            Course command [rad].
        chi, r : casadi.SX
            Measured course [rad] and rate [rad/s].
        dt : casadi.SX or float
            Sample period [s].
        speed : casadi.SX, optional
            Speed [m/s] (for a scheduled law; a point design ignores it).
        steer : casadi.SX, optional
            Present steering (unused by this law; the loop passes it to every law).
        bias : casadi.SX, optional
            The heading observer's steering-bias estimate (unused by this law).
        """
        return law_step(self, self.parameters(speed), mem, ref, chi, r, dt)

    @property
    def function(self) -> ca.Function:
        """``autopilot(memory, ref, chi, r, dt, speed, steering, bias) -> (memory_next, steer, chi_d, r_d, a_d, e)``
        with ``memory`` as in :attr:`MEMORY` (``speed`` used by a schedule, ``steering`` and ``bias`` by none)."""
        return law_function(self, "autopilot")


def law_function(law, name: str) -> ca.Function:
    """A law's ``symbolic_step`` as the Function ``name(memory, ref, chi, r, dt, speed, steering, bias)
    -> (memory_next, steer, chi_d, r_d, a_d, e)``: the one signature every law in the loop has.

    Parameters
    ----------
    law : Autopilot, LinearController or another law with ``MEMORY`` and ``symbolic_step``
    name : str
        The Function's name.

    Returns
    -------
    casadi.Function
    """
    mem, ref, chi, r, dt, U, st, bias = (ca.SX.sym(k, s) for k, s in (
        ("memory", len(law.MEMORY)), ("ref", 1), ("chi", 1), ("r", 1), ("dt", 1), ("speed", 1), ("steering", 1),
        ("bias", 1)))
    out = law.symbolic_step(mem, ref, chi, r, dt, U, st, bias)
    names = ["memory", "steer", "chi_d", "r_d", "a_d", "e"]
    return ca.Function(name, [mem, ref, chi, r, dt, U, st, bias], [out[k] for k in names],
                       ["memory", "ref", "chi", "r", "dt", "speed", "steering", "bias"], ["memory_next"] + names[1:])


def law_step(law, P: dict, mem, ref, chi, r, dt) -> dict:
    """The control law with its numbers ``P`` (:meth:`Autopilot.parameters`, numbers or CasADi
    expressions) and its structure (feed-forward, filter, anti-windup, steering table) from ``law``.

    One function for the point design and the gain schedule, so that both are the same law.

    The feed-forward inverts the Nomoto model along the reference: ``delta = (1/K) (1 + T1 s)
    (1 + T2 s) / (1 + T3 s) r_d``, written as ``s(r_d) + m w + m_hf (a_d - w)`` with ``w = a_d / (1 + T3
    s)`` (a memory state), ``m = T/K``, ``m_hf = T1 T2 / (K T3)``, and the static part ``s(r_d)``
    the nonlinear ship's steady steering (or the linear ``d r_d``). At low frequency it is the
    first-order ``m a_d + d r_d``; a quick change of the reference sees the smaller inertia
    ``m_hf`` the ship shows at once (the first-order ``m`` would overdrive the start of a large
    turn and carry the ship past the preset rate).
    """
    from .plants import SteeringFeedforward, piecewise_linear
    from .reference import reference_step

    chi_d, r_d, a_d, integ, filt, w = (mem[i] for i in range(6))
    e = wrap_sym(chi - chi_d)
    ff = 0
    if law.feedforward:
        accel = P["m"] * w + P["m_hf"] * (a_d - w)
        if law.steering is not None:
            table = [P[f"ff_{i}"] for i in range(len(SteeringFeedforward.FRACTIONS))]
            ff = accel + piecewise_linear(r_d / P["r_top"], SteeringFeedforward.FRACTIONS, table)
        else:
            ff = accel + P["d"] * r_d
    w_next = w + (1 - ca.exp(-dt / P["T3"])) * (a_d - w)
    raw = ff - (P["Kp"] * e + P["Kd"] * (r - r_d) + P["Ki"] * integ)
    if law.filter_T > 0:
        filt_next = filt + dt / (law.filter_T + dt) * (raw - filt)      # backward-Euler low-pass
    else:
        filt_next = raw
    limit = P["steer_max"]
    finite = not (isinstance(limit, float) and not np.isfinite(limit))
    sat = ca.fmin(ca.fmax(filt_next, -limit), limit) if finite else filt_next
    if law.anti_windup and finite:
        grow = P["Ki"] * e          # d(raw)/dt from the integrator is -Ki e
        hold = ca.logic_or(ca.logic_and(filt_next > limit, grow < 0), ca.logic_and(filt_next < -limit, grow > 0))
        integ_next = ca.if_else(hold, integ, integ + dt * e)
    else:
        integ_next = integ + dt * e
    xd_next = reference_step(mem[:3], ref, dt, P["wn_ref"], P["zeta_ref"], P["r_max"])
    return {"memory": ca.vertcat(xd_next, integ_next, filt_next, w_next), "steer": sat, "chi_d": chi_d,
            "r_d": r_d, "a_d": a_d, "e": e}


@dataclass(frozen=True)
class Actuator:
    """Steering gear: first-order servo with angle and rate limits.

    Over a sample ``dt`` the steering follows the command with time constant ``T``
    (``delta + (delta_c - delta)(1 - exp(-dt/T))``; ``T = 0``: at once), its change limited to
    ``rate_max dt`` and its value to ``+-steer_max``. The rate limit is *active* in a sample when
    the servo asks for a faster change than ``rate_max``.

    Parameters
    ----------
    steer_max : float
        Angle (or moment) limit.
    rate_max : float
        Rate limit [unit/s] (``inf`` for none).
    T : float
        Servo time constant [s].
    """

    steer_max: float = float("inf")
    rate_max: float = float("inf")
    T: float = 0.0

    def __post_init__(self):
        if not self.steer_max > 0 or not self.rate_max > 0:
            raise InputError(f"steer_max and rate_max must be positive, got {self.steer_max}, {self.rate_max}")
        if not (np.isfinite(self.T) and self.T >= 0):
            raise InputError(f"actuator time constant T must be >= 0, got {self.T}")

    def symbolic_step(self, steer, command, dt) -> dict:
        """``{"steer": next steering, "rate_limited": 1 where the rate limit is active}``.

        Parameters
        ----------
        steer : casadi.SX
            Present steering.
        command : casadi.SX
            Steering command.
        dt : casadi.SX or float
            Sample period [s].
        """
        cmd = command
        if np.isfinite(self.steer_max):
            cmd = ca.fmin(ca.fmax(cmd, -self.steer_max), self.steer_max)
        change = (cmd - steer) * (1 - ca.exp(-dt / self.T)) if self.T > 0 else cmd - steer
        if np.isfinite(self.rate_max):
            step = self.rate_max * dt
            limited = ca.fabs(change) > step
            change = ca.fmin(ca.fmax(change, -step), step)
        else:
            limited = ca.SX(0)
        return {"steer": steer + change, "rate_limited": limited}

    def tf(self):
        """Linear servo ``1/(1 + T s)`` (no limits) as a python-control transfer function."""
        import control

        return control.tf([1.0], [self.T, 1.0]) if self.T > 0 else control.tf([1.0], [1.0])
