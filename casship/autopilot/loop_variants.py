"""How the closed loop reads a loop estimator: one small class per estimator kind.

A course estimator (SOG/COG EKF) measures GNSS positions and gives course, course rate, position
and speed; a heading estimator (heading observer) measures compass and gyro, is driven by the
steering angle and gives heading, yaw rate and (optionally) a rudder bias. The loop picks the
reading once, from :attr:`LoopEstimator.kind`, and calls it on CasADi expressions (the compiled
loop) and on numbers (the step-by-step reference run) alike.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["CourseReading", "HeadingReading", "READINGS"]

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


#: The reading of each estimator kind.
READINGS = {"course": CourseReading(), "heading": HeadingReading()}
