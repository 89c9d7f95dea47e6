"""What the closed loop feeds back, and how it reads it: one small class per variant.

Readings, one per controlled angle: a course estimator (SOG/COG EKF) measures GNSS positions and
gives course, course rate, position and speed; a heading estimator (heading observer) measures
compass and gyro, is driven by the steering angle and gives heading, yaw rate and (optionally) a
rudder bias. The loop picks the reading of its mode from :data:`READINGS`, an estimator's from
:attr:`LoopEstimator.kind`, and calls it on CasADi expressions (the compiled loop) and on numbers
(the step-by-step reference run) alike.

Feedback sources, one per kind of feedback (:class:`LoopFeedback`): :class:`TrueState` (the true
angle and rate, no sensors), :class:`RawMeasurement` (compass and gyro as read) and
:class:`~casship.autopilot.components.LoopEstimator` (a casship estimator in the loop). The loop
resolves its ``estimator`` argument once (:func:`feedback_source`) and calls the source's methods.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..angles import wrap
from ..errors import InputError, InputTypeError

__all__ = ["CourseReading", "HeadingReading", "READINGS", "LoopFeedback", "TrueState", "RawMeasurement",
           "FEEDBACK_SHORTHAND", "feedback_source"]

_PLACE = """Move the prior mean to a start state ({what}), in place.

    Parameters
    ----------
    mean : ndarray
        The estimator's prior mean (changed).
    ix : callable
        Index of an estimator state by name.
    north, east, psi, r, chi : float
        The start state: position [m], heading [rad], yaw rate [rad/s], course [rad].
    """
_SYMBOLIC = """Measurement, its mask and the input of one compiled estimator step ({what}).

    Parameters
    ----------
    meas : dict
        The loop's sensor readings (``gnss``, ``compass``, ``gyro``) as CasADi expressions.
    mask : casadi.SX
        Sensor availability (GNSS, compass).
    steer_prev : casadi.SX
        The steering angle of the previous sample.
    """
_ONLINE = """Measurement and keyword inputs of one online update ({what}; NaN = not measured).

    Parameters
    ----------
    gnss : pair of float
        The GNSS fix (north, east) [m].
    compass, gyro : float
        Compass heading [rad] and gyro yaw rate [rad/s].
    mask : array_like
        Sensor availability (GNSS, compass).
    steer_prev : float
        The steering angle of the previous sample [rad].
    """
_READ = """Angle, rate, north, east and speed from the estimate ({what}).

    Parameters
    ----------
    xh : vector
        The estimated state.
    ix : callable
        Index of an estimator state by name.
    fix : pair
        The last GNSS fix (north, east).
    U : scalar
        The loop's own speed.
    """
_BIAS = """Rudder bias estimate ({what}).

    Parameters
    ----------
    xh : vector
        The estimated state.
    ix : callable
        Index of an estimator state by name.
    names : sequence of str
        The estimator's state names.
    zero : scalar
        The zero to give when there is no bias.
    """
_TRUE = """The true controlled angle and its rate ({what}).

    Parameters
    ----------
    meas : dict
        The loop's true ``psi`` and ``r`` (and sensor readings).
    chi, chi_prev : scalar
        Course over ground now and at the previous sample [rad].
    dt_est : scalar
        Time since the previous sample (0 on the first) [s].
    dt : float
        Loop period [s].

    Returns
    -------
    angle, rate
    """
_START = """The controlled angle at the start ({what}).

    Parameters
    ----------
    psi : float
        Heading [rad].
    course : callable
        Gives the course over ground [rad] (evaluated only when it is the controlled angle).
    """


def _doc(template: str, what: str):
    def put(func):
        func.__doc__ = template.format(what=what)
        return func
    return put


class CourseReading:
    """Reading of a course estimator (states ``x_n, y_n, chi, omega_chi, U``; measures GNSS)."""

    kind = "course"
    measured = ("x_n", "y_n")
    angle_state = "chi"

    @_doc(_PLACE, "position and course")
    def place(self, mean, ix, north, east, psi, r, chi):
        mean[ix("x_n")], mean[ix("y_n")], mean[ix("chi")] = north, east, chi

    @_doc(_SYMBOLIC, "GNSS, no input")
    def symbolic_input(self, meas, mask, steer_prev):
        return meas["gnss"], ca.vertcat(mask[0], mask[0]), ca.SX(0, 1)

    @_doc(_ONLINE, "GNSS")
    def online_input(self, gnss, compass, gyro, mask, steer_prev):
        return (np.asarray(gnss, float) if mask[0] else np.full(2, np.nan)), {}

    @_doc(_READ, "position and speed the estimator's")
    def read(self, xh, ix, fix, U):
        return xh[ix("chi")], xh[ix("omega_chi")], xh[ix("x_n")], xh[ix("y_n")], xh[ix("U")]

    @_doc(_BIAS, "none for a course estimator")
    def bias(self, xh, ix, names, zero):
        return zero

    @_doc(_TRUE, "course; its rate a backward difference, the yaw rate on the first sample; CasADi")
    def true_symbolic(self, meas, chi, chi_prev, dt_est, dt):
        return chi, ca.if_else(dt_est > 0, ca.atan2(ca.sin(chi - chi_prev), ca.cos(chi - chi_prev)) / dt, meas["r"])

    @_doc(_TRUE, "course; its rate a backward difference, the yaw rate on the first sample; numbers")
    def true_numeric(self, meas, chi, chi_prev, dt_est, dt):
        return chi, (float(wrap(chi - chi_prev)) / dt if dt_est > 0 else meas["r"])

    @_doc(_START, "course over ground")
    def start_angle(self, psi, course):
        return course()


class HeadingReading:
    """Reading of a heading estimator (states ``psi, r`` and optionally ``b``; measures compass and gyro)."""

    kind = "heading"
    measured = ("psi_m", "r_m")
    angle_state = "psi"

    @_doc(_PLACE, "heading and yaw rate")
    def place(self, mean, ix, north, east, psi, r, chi):
        mean[ix("psi")], mean[ix("r")] = psi, r

    @_doc(_SYMBOLIC, "compass and gyro, driven by the steering angle")
    def symbolic_input(self, meas, mask, steer_prev):
        return ca.vertcat(meas["compass"], meas["gyro"]), ca.vertcat(mask[1], 1), steer_prev

    @_doc(_ONLINE, "compass and gyro")
    def online_input(self, gnss, compass, gyro, mask, steer_prev):
        return np.array([compass if mask[1] else np.nan, gyro]), {"u_prev": np.array([steer_prev])}

    @_doc(_READ, "position from the last GNSS fix, speed the loop's")
    def read(self, xh, ix, fix, U):
        return xh[ix("psi")], xh[ix("r")], fix[0], fix[1], U

    @_doc(_BIAS, "``b`` when the estimator has one")
    def bias(self, xh, ix, names, zero):
        return xh[ix("b")] if "b" in names else zero

    @_doc(_TRUE, "heading and yaw rate; CasADi")
    def true_symbolic(self, meas, chi, chi_prev, dt_est, dt):
        return meas["psi"], meas["r"]

    @_doc(_TRUE, "heading and yaw rate; numbers")
    def true_numeric(self, meas, chi, chi_prev, dt_est, dt):
        return meas["psi"], meas["r"]

    @_doc(_START, "heading, wrapped")
    def start_angle(self, psi, course):
        return float(wrap(psi))


#: The reading of each estimator kind.
READINGS = {"course": CourseReading(), "heading": HeadingReading()}


class LoopFeedback:
    """What a closed loop feeds its law: the base of the feedback sources.

    A source says which modes it serves (:meth:`check_mode`), which blocks it adds to the loop
    state (:meth:`blocks`, :meth:`memory0`), what it feeds on CasADi expressions (:meth:`symbolic`,
    the compiled loop) and on numbers (:meth:`stepwise`, the reference run), and what it adds to the
    record's ``meta`` (:meth:`meta`). Both runs return, per sample, a dict with the fed ``angle`` and
    ``rate``, the position ``north, east`` and speed ``U`` guidance uses, the angle's standard
    deviation ``angle_std``, the rudder ``bias`` and the held compass reading ``compass_hold``; the
    symbolic one also the held GNSS fix ``gnss_hold`` and the estimator ``memory`` next.
    """

    #: Modes ("course", "heading") the source can feed.
    modes: tuple = ("course", "heading")

    def check_mode(self, mode: str, *, guided: bool = False):
        """Raise :class:`~casship.errors.InputError` naming ``mode`` when this source cannot feed it.

        Parameters
        ----------
        mode : str
            The loop's controlled angle.
        guided : bool
            Whether path guidance gives the command (it may use an estimator of the other kind).
        """
        if mode not in self.modes:
            raise InputError(f"{type(self).__name__} feeds a {' or '.join(self.modes)} autopilot, not mode {mode!r}")

    def blocks(self) -> list:
        """``(name, size)`` blocks the source adds to the loop state (none by default)."""
        return []

    def memory0(self, prior) -> dict:
        """Values of :meth:`blocks` at the start.

        Parameters
        ----------
        prior : callable
            Gives the estimator prior at the run's start (called only by a source with an estimator).
        """
        return {}

    def meta(self, prior) -> dict:
        """Entries of the record's ``meta`` (none by default).

        Parameters
        ----------
        prior : callable
            As :meth:`memory0`.
        """
        return {}

    def symbolic(self, loop, parts, meas, mask, dt_est, motion, steer_prev) -> dict:
        """What the source feeds in one compiled sample (CasADi expressions).

        Parameters
        ----------
        loop : ClosedLoop
            The loop (its ``reading``, ``dt`` and ``rate``).
        parts : dict
            Blocks of the loop state (``chi_prev``, ``compass_hold``, ``gnss_hold``, the source's own).
        meas : dict
            True ``north, east, psi, r`` and readings ``gnss, compass, gyro``.
        mask : casadi.SX
            Sensor availability (GNSS, compass).
        dt_est : casadi.SX
            Time since the previous sample (0 on the first) [s].
        motion : tuple
            Course over ground, speed and the rest of the ship's motion.
        steer_prev : casadi.SX
            The steering angle of the previous sample.
        """
        raise NotImplementedError

    def stepwise(self, loop, prior):
        """A function of one sample's numbers giving what the source feeds (the reference run).

        Parameters
        ----------
        loop : ClosedLoop
        prior : callable
            As :meth:`memory0`.

        Returns
        -------
        callable
            ``feed(sample) -> dict``; ``sample`` holds ``meas``' keys as numbers and ``mask``,
            ``dt_est``, ``fix`` (last GNSS fix), ``chi``, ``chi_prev``, ``U``, ``steer_prev`` and
            ``compass_hold``.
        """
        raise NotImplementedError


@dataclass(frozen=True)
class TrueState(LoopFeedback):
    """Feed the true controlled angle and its rate (no sensors, no estimator): the ideal loop.

    Course mode feeds the course over ground and its backward difference (the yaw rate on the
    first sample), heading mode the heading and the yaw rate; guidance gets the true position.
    ``estimator="truth"`` is the shorthand.

    Examples
    --------
    >>> loop = d.closed_loop_system(estimator=TrueState())     # doctest: +SKIP
    """

    def symbolic(self, loop, parts, meas, mask, dt_est, motion, steer_prev):
        chi_true, U_true, _ = motion
        angle, rate = loop.reading.true_symbolic(meas, chi_true, parts["chi_prev"], dt_est, loop.dt)
        return {"angle": angle, "rate": rate, "north": meas["north"], "east": meas["east"], "U": U_true,
                "angle_std": ca.SX(0), "bias": ca.SX(0), "memory": {}, "compass_hold": parts["compass_hold"],
                "gnss_hold": parts["gnss_hold"]}

    def stepwise(self, loop, prior):
        reading, dt = loop.reading, loop.dt

        def feed(s):
            angle, rate = reading.true_numeric(s, s["chi"], s["chi_prev"], s["dt_est"], dt)
            return {"angle": angle, "rate": rate, "north": s["north"], "east": s["east"], "U": s["U"],
                    "angle_std": 0.0, "bias": 0.0, "compass_hold": s["compass_hold"]}
        return feed


@dataclass(frozen=True)
class RawMeasurement(LoopFeedback):
    """Feed the last compass reading and the gyro rate as read (heading mode only; no estimator).

    Guidance gets the last GNSS fix. ``estimator="raw"`` is the shorthand: the loop of a
    python-control controller with its own filter (an LQG's Kalman filter) on compass and gyro.
    """

    modes = ("heading",)

    def check_mode(self, mode: str, *, guided: bool = False):
        if mode not in self.modes:
            raise InputError(f"RawMeasurement (estimator 'raw': compass and gyro as read) is for heading mode, "
                             f"not mode {mode!r}")

    def symbolic(self, loop, parts, meas, mask, dt_est, motion, steer_prev):
        fix = ca.if_else(mask[0] > 0, meas["gnss"], parts["gnss_hold"])
        hold = ca.if_else(mask[1] > 0, meas["compass"], parts["compass_hold"])
        return {"angle": hold, "rate": meas["gyro"], "north": fix[0], "east": fix[1], "U": motion[1],
                "angle_std": ca.SX(0), "bias": ca.SX(0), "memory": {}, "compass_hold": hold, "gnss_hold": fix}

    def stepwise(self, loop, prior):
        def feed(s):
            hold = s["compass"] if s["mask"][1] else s["compass_hold"]
            return {"angle": hold, "rate": s["gyro"], "north": s["fix"][0], "east": s["fix"][1], "U": s["U"],
                    "angle_std": 0.0, "bias": 0.0, "compass_hold": hold}
        return feed


#: The documented string shorthands of the loop's ``estimator`` argument.
FEEDBACK_SHORTHAND = {"truth": TrueState, "raw": RawMeasurement}


def feedback_source(value) -> LoopFeedback:
    """The feedback source a loop's ``estimator`` argument names (the one place strings are read).

    Parameters
    ----------
    value : LoopFeedback or str
        A :class:`TrueState`, :class:`RawMeasurement` or
        :class:`~casship.autopilot.components.LoopEstimator`, or the shorthand ``"truth"``
        (:class:`TrueState`) or ``"raw"`` (:class:`RawMeasurement`).

    Returns
    -------
    LoopFeedback

    Raises
    ------
    InputError
        An unknown string (named, with the allowed ones); :class:`~casship.errors.InputTypeError`
        for another type.
    """
    if isinstance(value, str):
        if value not in FEEDBACK_SHORTHAND:
            raise InputError(f"estimator must be a LoopEstimator, TrueState, RawMeasurement or one of "
                             f"{sorted(FEEDBACK_SHORTHAND)}, got {value!r}")
        return FEEDBACK_SHORTHAND[value]()
    if not isinstance(value, LoopFeedback):
        raise InputTypeError(f"estimator must be a LoopEstimator, TrueState, RawMeasurement, 'truth' or 'raw', "
                             f"got {type(value).__name__}")
    return value
