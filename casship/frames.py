"""Frames and geodesy: NED <-> body rotation (3-DOF) and WGS-84 radii of curvature.

Conventions: earth-fixed North-East-Down, x North, y East, heading psi from North, clockwise
positive; body x forward, y starboard. Works on numbers and on CasADi symbols alike.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["body_to_ned", "ned_to_body", "WGS84_A", "WGS84_F", "wgs84_radii", "course_speed",
           "latlon_to_ne", "ne_to_latlon"]

WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_E2 = 2 * WGS84_F - WGS84_F**2


def _lib(*values):
    return ca if any(isinstance(v, (ca.SX, ca.MX)) for v in values) else np


def body_to_ned(u, v, r, psi):
    """Earth-fixed rates ``(x_dot, y_dot, psi_dot)`` from body velocities (Fossen; seed 001 Eq. 60)."""
    lib = _lib(u, v, r, psi)
    c, s = lib.cos(psi), lib.sin(psi)
    return u * c - v * s, u * s + v * c, r


def ned_to_body(x_dot, y_dot, psi_dot, psi):
    """Body velocities ``(u, v, r)`` from earth-fixed rates (inverse rotation, seed 001 Eq. 60)."""
    lib = _lib(x_dot, y_dot, psi_dot, psi)
    c, s = lib.cos(psi), lib.sin(psi)
    return x_dot * c + y_dot * s, -x_dot * s + y_dot * c, psi_dot


def course_speed(x_dot, y_dot):
    """Speed over ground ``U`` and course over ground ``chi`` (rad) from North/East rates."""
    return np.hypot(x_dot, y_dot), np.arctan2(y_dot, x_dot)


def wgs84_radii(lat):
    """Prime-vertical ``R_N`` and meridian ``R_M`` radii of curvature [m] at latitude ``lat`` (rad)."""
    lib = _lib(lat)
    s2 = lib.sin(lat) ** 2
    r_n = WGS84_A / lib.sqrt(1 - WGS84_E2 * s2)
    r_m = r_n * (1 - WGS84_E2) / (1 - WGS84_E2 * s2)
    return r_n, r_m


def latlon_to_ne(lat, lon, lat0, lon0):
    """Local North/East [m] of ``lat, lon`` (rad) about the origin ``lat0, lon0`` (rad).

    Uses the WGS-84 ellipsoid tangent plane (second-order accurate: under a metre at 2 km from the
    origin); for long tracks use a proper geodesic library. The longitude difference is taken on
    the circle (across the date line). Works on CasADi symbols too (e.g. in a measurement model).
    """
    lib = _lib(lat, lon)
    r_n, r_m = wgs84_radii(lat0)
    if lib is ca:
        dlon = ca.atan2(ca.sin(lon - lon0), ca.cos(lon - lon0))
        return (lat - lat0) * r_m, dlon * r_n * np.cos(lat0)
    dlon = np.angle(np.exp(1j * (np.asarray(lon) - lon0)))
    return (np.asarray(lat) - lat0) * r_m, dlon * r_n * np.cos(lat0)


def ne_to_latlon(north, east, lat0, lon0):
    """Inverse of :func:`latlon_to_ne` (numbers or CasADi symbols)."""
    r_n, r_m = wgs84_radii(lat0)
    if _lib(north, east) is ca:
        return lat0 + north / r_m, lon0 + east / (r_n * np.cos(lat0))
    return lat0 + np.asarray(north) / r_m, lon0 + np.asarray(east) / (r_n * np.cos(lat0))
