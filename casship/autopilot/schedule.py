"""Gain scheduling over the speed: point designs at several speeds, one law interpolating them.

IMO Resolution A.342(IX), 3.1, asks a heading control system to adapt to the ship's speed (and
loading). A course autopilot designed at the approach speed is too fast and asks too much of the
ship at half speed: the ship turns more slowly, and its Nomoto time constants and gain change.
:func:`~casship.autopilot.ship_design.design_autopilot` with ``schedule=speeds`` designs at each
speed from that speed's exact linearisation (trim, Nomoto model, bandwidth, reference model, preset
turn rate and steady-steering table, all by the rules of :mod:`~casship.autopilot.defaults`), and
:class:`ScheduledAutopilot` interpolates every number of the law linearly in the measured speed
(clamped outside the designed range), inside the compiled closed loop. At a design speed the
scheduled law is that point design.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .law import Autopilot, PIDGains, law_step
from .plants import SteeringFeedforward, piecewise_linear
from .reference import ReferenceModel
from ..errors import InputError, InputTypeError

__all__ = ["ScheduledAutopilot", "default_schedule"]

#: Fractions of the approach speed of the default schedule.
SCHEDULE_FRACTIONS = (0.4, 0.55, 0.7, 0.85, 1.0)


def default_schedule(speed: float, operating: float | None = None) -> tuple:
    """The default design speeds: :data:`SCHEDULE_FRACTIONS` of the approach ``speed`` [m/s], extended
    to the ``operating`` speed where it lies outside them: above the approach speed in steps of 15 %
    of it up to the operating speed, below 40 % by the operating speed itself, so that the schedule
    covers every speed the ship sails at between its slowest and its fastest (beyond its designs the
    scheduled law only holds the nearest design).

    Parameters
    ----------
    speed : float
        Approach speed [m/s].
    operating : float, optional
        The speed the design is for [m/s].

    Examples
    --------
    >>> default_schedule(10.0, 12.5)
    (4.0, 5.5, 7.0, 8.5, 10.0, 11.5, 12.5)
    """
    speeds = [float(f * speed) for f in SCHEDULE_FRACTIONS]
    if operating is not None and operating > speeds[-1] * (1 + 1e-9):
        step = (SCHEDULE_FRACTIONS[-1] - SCHEDULE_FRACTIONS[-2]) * speed
        while speeds[-1] + step < operating * (1 - 1e-9) - 0.25 * step:
            speeds.append(round(speeds[-1] + step, 12))
        speeds.append(float(operating))
    elif operating is not None and operating < speeds[0] * (1 - 1e-9):
        speeds.insert(0, float(operating))
    return tuple(speeds)


@dataclass(frozen=True)
class ScheduledAutopilot:
    """One control law whose numbers are interpolated over the speed between point designs.

    Parameters
    ----------
    speeds : tuple of float
        Design speeds [m/s], increasing.
    laws : tuple of Autopilot
        The point designs' laws, one per speed, of the same structure (feed-forward, filter,
        anti-windup, steering table).
    """

    speeds: tuple
    laws: tuple

    MEMORY = Autopilot.MEMORY

    def __post_init__(self):
        speeds = np.asarray(self.speeds, float)
        if speeds.ndim != 1 or speeds.size < 2 or np.any(np.diff(speeds) <= 0) or not np.all(speeds > 0):
            raise InputError(f"schedule speeds must be at least two positive, increasing speeds, got {self.speeds}")
        if len(self.laws) != speeds.size:
            raise InputError(f"{len(self.laws)} laws for {speeds.size} schedule speeds")
        first = self.laws[0]
        for k, law in enumerate(self.laws):
            if not isinstance(law, Autopilot):
                raise InputTypeError(f"schedule law {k} is a {type(law).__name__}, not an Autopilot")
            same = (law.feedforward, law.anti_windup, law.filter_T, law.steering is None) == \
                (first.feedforward, first.anti_windup, first.filter_T, first.steering is None)
            if not same:
                raise InputError(f"schedule law {k} (at {speeds[k]:g} m/s) differs in structure from the first")
        object.__setattr__(self, "speeds", tuple(map(float, speeds)))

    # the structure of the law (law_step reads these)
    @property
    def feedforward(self) -> bool:
        """Whether the law has the feed-forward (the same in every design)."""
        return self.laws[0].feedforward

    @property
    def anti_windup(self) -> bool:
        """Whether the integrator is held at the limit (the same in every design)."""
        return self.laws[0].anti_windup

    @property
    def filter_T(self) -> float:
        """Command low-pass time constant [s] (the same in every design)."""
        return self.laws[0].filter_T

    @property
    def steering(self):
        """The first design's steering table (its values are scheduled by :meth:`parameters`)."""
        return self.laws[0].steering

    def memory0(self, chi0: float = 0.0) -> np.ndarray:
        """Initial memory (as :meth:`Autopilot.memory0`).

        Parameters
        ----------
        chi0 : float
            Initial course (or heading) [rad].
        """
        return self.laws[0].memory0(chi0)

    def parameters(self, speed) -> dict:
        """The law's numbers at ``speed`` (numbers or CasADi expressions), each interpolated linearly
        between the design speeds and held beyond them.

        Parameters
        ----------
        speed : float or casadi.SX
            Measured speed [m/s].
        """
        if speed is None:
            raise InputError("a scheduled autopilot needs the speed")
        tables = [law.parameters() for law in self.laws]
        return {k: piecewise_linear(speed, self.speeds, [t[k] for t in tables]) for k in tables[0]}

    def symbolic_step(self, mem, ref, chi, r, dt, speed=None, steer=None, bias=None) -> dict:
        """One sample of the law at the measured ``speed`` (see :meth:`Autopilot.symbolic_step`).

        Parameters
        ----------
        mem, ref, chi, r, dt
            As :meth:`Autopilot.symbolic_step`.
        speed : casadi.SX
            Speed [m/s] (the course estimator's in course mode, the speed log's in heading mode).
        steer, bias : casadi.SX, optional
            Unused.
        """
        return law_step(self, self.parameters(speed), mem, ref, chi, r, dt)

    function = Autopilot.function

    def at(self, speed: float) -> Autopilot:
        """The point law the schedule gives at ``speed`` (its gains, reference model and steering table).

        Parameters
        ----------
        speed : float
            Speed [m/s].
        """
        P = {k: float(v) for k, v in self.parameters(float(speed)).items()}
        g0 = self.laws[0].gains
        gains = PIDGains(P["Kp"], P["Kd"], P["Ki"], P["m"], P["d"], f"scheduled ({g0.method})", m_hf=P["m_hf"],
                         T3=P["T3"])
        ref = ReferenceModel(P["wn_ref"], P["zeta_ref"], P["r_max"])
        steering = None
        if self.steering is not None:
            n = len(SteeringFeedforward.FRACTIONS)
            steering = SteeringFeedforward(tuple(f * P["r_top"] for f in SteeringFeedforward.FRACTIONS),
                                           tuple(P[f"ff_{i}"] for i in range(n)), P["r_top"], P["steer_max"])
        return replace(self.laws[0], gains=gains, reference=ref, steer_max=P["steer_max"], steering=steering)

    @property
    def reference(self) -> ReferenceModel:
        """The reference model of the fastest design (for tools that need one model)."""
        return self.laws[-1].reference

    @property
    def gains(self) -> PIDGains:
        """The gains of the fastest design."""
        return self.laws[-1].gains
