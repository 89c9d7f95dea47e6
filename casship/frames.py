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
    """Earth-fixed rates ``(x_dot, y_dot, psi_dot)`` from body velocities (Fossen; Tomera 2011, Eq. 60).

    ``x_dot = u cos psi - v sin psi``, ``y_dot = u sin psi + v cos psi``, ``psi_dot = r``.

    Parameters
    ----------
    u, v : float, array_like or casadi.SX/MX
        Surge (forward) and sway (starboard) velocity in body axes [m/s].
    r : float, array_like or casadi.SX/MX
        Yaw rate [rad/s] (passed through unchanged).
    psi : float, array_like or casadi.SX/MX
        Heading from North, clockwise positive [rad].

    Returns
    -------
    x_dot, y_dot : same type as the inputs
        North and East velocity [m/s].
    psi_dot : same type as ``r``
        Heading rate [rad/s] (``r`` itself).

    Examples
    --------
    >>> x_dot, y_dot, psi_dot = body_to_ned(2.0, 0.5, 0.01, np.pi / 2)   # heading East
    >>> round(float(x_dot), 9), round(float(y_dot), 9), psi_dot
    (-0.5, 2.0, 0.01)
    """
    lib = _lib(u, v, r, psi)
    c, s = lib.cos(psi), lib.sin(psi)
    return u * c - v * s, u * s + v * c, r


def ned_to_body(x_dot, y_dot, psi_dot, psi):
    """Body velocities ``(u, v, r)`` from earth-fixed rates (inverse rotation, Tomera 2011, Eq. 60).

    ``u = x_dot cos psi + y_dot sin psi``, ``v = -x_dot sin psi + y_dot cos psi``, ``r = psi_dot``.

    Parameters
    ----------
    x_dot, y_dot : float, array_like or casadi.SX/MX
        North and East velocity [m/s].
    psi_dot : float, array_like or casadi.SX/MX
        Heading rate [rad/s] (passed through unchanged).
    psi : float, array_like or casadi.SX/MX
        Heading from North, clockwise positive [rad].

    Returns
    -------
    u, v : same type as the inputs
        Surge (forward) and sway (starboard) velocity [m/s].
    r : same type as ``psi_dot``
        Yaw rate [rad/s] (``psi_dot`` itself).

    Examples
    --------
    >>> u, v, r = ned_to_body(-0.5, 2.0, 0.01, np.pi / 2)   # inverse of the body_to_ned example
    >>> round(float(u), 9), round(float(v), 9), r
    (2.0, 0.5, 0.01)
    """
    lib = _lib(x_dot, y_dot, psi_dot, psi)
    c, s = lib.cos(psi), lib.sin(psi)
    return x_dot * c + y_dot * s, -x_dot * s + y_dot * c, psi_dot


def course_speed(x_dot, y_dot):
    """Speed over ground ``U`` and course over ground ``chi`` (rad) from North/East rates.

    Numbers only (numpy); for CasADi symbols write ``sqrt``/``atan2`` directly.

    Parameters
    ----------
    x_dot, y_dot : float or array_like
        North and East velocity over ground [m/s].

    Returns
    -------
    U : float or ndarray
        Speed over ground [m/s].
    chi : float or ndarray
        Course over ground, from North clockwise, in [-pi, pi] (``arctan2``) [rad]; 0 for a
        ship at rest.

    Examples
    --------
    >>> U, chi = course_speed(0.0, -3.0)   # due West
    >>> float(U), float(chi)
    (3.0, -1.5707963267948966)
    """
    return np.hypot(x_dot, y_dot), np.arctan2(y_dot, x_dot)


def wgs84_radii(lat):
    """Prime-vertical ``R_N`` and meridian ``R_M`` radii of curvature [m] at latitude ``lat`` (rad).

    ``R_N = a / sqrt(1 - e^2 sin^2 lat)``, ``R_M = R_N (1 - e^2) / (1 - e^2 sin^2 lat)`` on the WGS-84
    ellipsoid (``a = WGS84_A``, flattening ``WGS84_F``). A North step ``dN`` [m] is ``dN / R_M``
    [rad] of latitude, an East step ``dE`` is ``dE / (R_N cos lat)`` [rad] of longitude.

    Parameters
    ----------
    lat : float, array_like or casadi.SX/MX
        Geodetic latitude [rad].

    Returns
    -------
    R_N, R_M : same type as ``lat``
        Prime-vertical (East-West) and meridian (North-South) radius of curvature [m].

    Examples
    --------
    >>> r_n, r_m = wgs84_radii(0.0)   # on the equator
    >>> float(r_n), round(float(r_m), 3)
    (6378137.0, 6335439.327)
    """
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

    ``north = (lat - lat0) R_M(lat0)``, ``east = (lon - lon0) R_N(lat0) cos(lat0)`` with the radii of
    :func:`wgs84_radii`. For numbers, :func:`casship.io.geodesy.geodetic_to_ne` gives the exact
    local North-East projection on the ellipsoid (without the second-order error).

    Parameters
    ----------
    lat, lon : float, array_like or casadi.SX/MX
        Geodetic latitude and longitude of the point(s) [rad].
    lat0, lon0 : float
        Origin of the local frame [rad] (numbers).

    Returns
    -------
    north, east : ndarray or casadi.SX/MX
        Local North and East coordinates [m].

    Examples
    --------
    >>> n, e = latlon_to_ne(np.radians(60.001), np.radians(10.001), np.radians(60.0), np.radians(10.0))
    >>> round(float(n), 2), round(float(e), 2)
    (111.41, 55.8)
    """
    lib = _lib(lat, lon)
    r_n, r_m = wgs84_radii(lat0)
    if lib is ca:
        dlon = ca.atan2(ca.sin(lon - lon0), ca.cos(lon - lon0))
        return (lat - lat0) * r_m, dlon * r_n * np.cos(lat0)
    dlon = np.angle(np.exp(1j * (np.asarray(lon) - lon0)))
    return (np.asarray(lat) - lat0) * r_m, dlon * r_n * np.cos(lat0)


def ne_to_latlon(north, east, lat0, lon0):
    """Inverse of :func:`latlon_to_ne` (numbers or CasADi symbols).

    ``lat = lat0 + north / R_M(lat0)``, ``lon = lon0 + east / (R_N(lat0) cos lat0)``: the exact
    inverse of :func:`latlon_to_ne` (same approximation, same validity range). The longitude is not
    wrapped to (-pi, pi].

    Parameters
    ----------
    north, east : float, array_like or casadi.SX/MX
        Local North and East coordinates [m].
    lat0, lon0 : float
        Origin of the local frame [rad] (numbers).

    Returns
    -------
    lat, lon : ndarray or casadi.SX/MX
        Geodetic latitude and longitude [rad].

    Examples
    --------
    >>> lat0, lon0 = np.radians(60.0), np.radians(10.0)
    >>> lat, lon = ne_to_latlon(*latlon_to_ne(np.radians(60.001), np.radians(10.001), lat0, lon0), lat0, lon0)
    >>> round(float(np.degrees(lat)), 9), round(float(np.degrees(lon)), 9)
    (60.001, 10.001)
    """
    r_n, r_m = wgs84_radii(lat0)
    if _lib(north, east) is ca:
        return lat0 + north / r_m, lon0 + east / (r_n * np.cos(lat0))
    return lat0 + np.asarray(north) / r_m, lon0 + np.asarray(east) / (r_n * np.cos(lat0))
