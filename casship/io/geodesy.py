"""Latitude/longitude to a local North-East frame on the WGS-84 ellipsoid (via :mod:`pymap3d`)."""
from __future__ import annotations

import numpy as np

__all__ = ["geodetic_to_ne", "ne_to_geodetic"]


def _check(lat, lon, what: str):
    lat = np.asarray(lat, dtype=float)
    lon = np.asarray(lon, dtype=float)
    if lat.shape != lon.shape:
        raise ValueError(f"{what}: latitude has shape {lat.shape}, longitude {lon.shape}")
    ok = np.isfinite(lat)
    if np.any(np.abs(lat[ok]) > np.pi / 2 + 1e-12):
        raise ValueError(f"{what}: latitude outside [-pi/2, pi/2] rad (degrees given?)")
    return lat, lon


def geodetic_to_ne(lat, lon, lat0: float, lon0: float):
    """North and East [m] of ``lat, lon`` [rad] in the tangent plane at ``lat0, lon0`` [rad].

    The points and the origin are taken on the WGS-84 ellipsoid surface (height 0), so heights
    do not leak into the horizontal position. NaN positions stay NaN ("not measured").

    Parameters
    ----------
    lat, lon : array_like
        Geodetic latitude and longitude [rad].
    lat0, lon0 : float
        Origin of the local frame [rad].

    Returns
    -------
    north, east : ndarray
        Local North-East coordinates [m].

    Examples
    --------
    >>> import numpy as np
    >>> n, e = geodetic_to_ne(np.radians(60.001), np.radians(10.0), np.radians(60.0), np.radians(10.0))
    >>> round(float(n), 2)
    111.41
    """
    import pymap3d

    lat, lon = _check(lat, lon, "geodetic_to_ne")
    if not (np.isfinite(lat0) and np.isfinite(lon0)):
        raise ValueError(f"geodetic_to_ne: origin ({lat0}, {lon0}) is not finite")
    north, east, _ = pymap3d.geodetic2ned(lat, lon, np.zeros_like(lat), lat0, lon0, 0.0, deg=False)
    return np.asarray(north, dtype=float), np.asarray(east, dtype=float)


def ne_to_geodetic(north, east, lat0: float, lon0: float):
    """Inverse of :func:`geodetic_to_ne`: latitude and longitude [rad] of local North/East [m]."""
    import pymap3d

    north = np.asarray(north, dtype=float)
    east = np.asarray(east, dtype=float)
    lat, lon, _ = pymap3d.ned2geodetic(north, east, np.zeros_like(north), lat0, lon0, 0.0, deg=False)
    return np.asarray(lat, dtype=float), np.asarray(lon, dtype=float)
