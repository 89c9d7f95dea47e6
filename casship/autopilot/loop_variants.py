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


class CourseReading:
    """Reading of a course estimator (states ``x_n, y_n, chi, omega_chi, U``; measures GNSS)."""

    kind = "course"
    measured = ("x_n", "y_n")
    angle_state = "chi"

    def place(self, mean, ix, north, east, psi, r, chi):
        """Move the prior mean to a start state (position and course)."""
        mean[ix("x_n")], mean[ix("y_n")], mean[ix("chi")] = north, east, chi

    def symbolic_input(self, meas, mask, steer_prev):
        """Measurement, its mask and the input of one compiled estimator step."""
        return meas["gnss"], ca.vertcat(mask[0], mask[0]), ca.SX(0, 1)

    def online_input(self, gnss, compass, gyro, mask, steer_prev):
        """Measurement and keyword inputs of one online update (NaN = not measured)."""
        return (np.asarray(gnss, float) if mask[0] else np.full(2, np.nan)), {}

    def read(self, xh, ix, fix, U):
        """Angle, rate, north, east and speed from the estimate (``fix``, ``U``: the loop's own)."""
        return xh[ix("chi")], xh[ix("omega_chi")], xh[ix("x_n")], xh[ix("y_n")], xh[ix("U")]

    def bias(self, xh, ix, names, zero):
        """Rudder bias estimate (none for a course estimator)."""
        return zero


class HeadingReading:
    """Reading of a heading estimator (states ``psi, r`` and optionally ``b``; measures compass and gyro)."""

    kind = "heading"
    measured = ("psi_m", "r_m")
    angle_state = "psi"

    def place(self, mean, ix, north, east, psi, r, chi):
        """Move the prior mean to a start state (heading and yaw rate)."""
        mean[ix("psi")], mean[ix("r")] = psi, r

    def symbolic_input(self, meas, mask, steer_prev):
        """Measurement, its mask and the input (the steering angle) of one compiled estimator step."""
        return ca.vertcat(meas["compass"], meas["gyro"]), ca.vertcat(mask[1], 1), steer_prev

    def online_input(self, gnss, compass, gyro, mask, steer_prev):
        """Measurement and keyword inputs of one online update (NaN = not measured)."""
        return np.array([compass if mask[1] else np.nan, gyro]), {"u_prev": np.array([steer_prev])}

    def read(self, xh, ix, fix, U):
        """Angle, rate, north, east and speed: position from the last GNSS fix, speed the loop's."""
        return xh[ix("psi")], xh[ix("r")], fix[0], fix[1], U

    def bias(self, xh, ix, names, zero):
        """Rudder bias estimate ``b`` when the estimator has one."""
        return xh[ix("b")] if "b" in names else zero


#: The reading of each estimator kind.
READINGS = {"course": CourseReading(), "heading": HeadingReading()}
