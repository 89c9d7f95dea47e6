"""Froude similarity: a ship's dimensional particulars and operating point at another scale.

Two geometrically similar ships at the same Froude number ``Fn = U / sqrt(g L)`` have the same
non-dimensional manoeuvring coefficients (scale effects on friction and wake aside). With the scale
ratio ``lambda = L_from / L_to``: lengths divide by ``lambda``, areas by ``lambda^2``, volumes (and
masses, same density) by ``lambda^3``, speeds by ``sqrt(lambda)``, times by ``sqrt(lambda)``, and
rates (propeller revolutions, rudder rate, yaw rate) multiply by ``sqrt(lambda)``.

:func:`froude_scale` applies this to a parameter mapping of casship's ship models (MMG particulars
and wind geometry); non-dimensional coefficients and densities pass unchanged.
"""
from __future__ import annotations

import math
from typing import Mapping

from ..errors import InputError

__all__ = ["froude_scale", "froude_speed", "froude_rate", "LENGTHS", "AREAS", "VOLUMES"]

#: Names scaled as lengths (MMG particulars and wind geometry).
LENGTHS = frozenset({"L_pp", "B", "d", "x_G", "D_p", "H_R", "L_OA", "H_BR", "H_C", "C", "C_BR"})
#: Names scaled as areas.
AREAS = frozenset({"A_R", "A_F", "A_L", "A_OD"})
#: Names scaled as volumes.
VOLUMES = frozenset({"nabla"})


def _check_scale(scale: float) -> float:
    scale = float(scale)
    if not math.isfinite(scale) or scale <= 0:
        raise InputError(f"scale ratio must be a positive finite number, got {scale}")
    return scale


def froude_scale(values: Mapping[str, float], scale: float) -> dict:
    """The parameter values of a ship ``scale`` times smaller (``scale < 1``: larger), by Froude similarity.

    Parameters
    ----------
    values : mapping
        Parameter name -> value, e.g. a preset's particulars and coefficients (names in
        :data:`LENGTHS`, :data:`AREAS`, :data:`VOLUMES` are scaled; all others, such as the
        non-dimensional hull coefficients, ``rho`` and ``k_zz``, are copied). A ``"source"`` entry
        (a string) is copied as well.
    scale : float
        ``lambda = L_from / L_to``.

    Returns
    -------
    dict
        The scaled values.

    Examples
    --------
    >>> from casship.models.kvlcc2 import KVLCC2_FULL
    >>> small = froude_scale(KVLCC2_FULL, 320.0 / 7.0)
    >>> round(small["L_pp"], 6), round(small["nabla"], 3)
    (7.0, 3.272)
    """
    scale = _check_scale(scale)
    out = {}
    for name, value in values.items():
        if isinstance(value, str):
            out[name] = value
        elif name in LENGTHS:
            out[name] = float(value) / scale
        elif name in AREAS:
            out[name] = float(value) / scale**2
        elif name in VOLUMES:
            out[name] = float(value) / scale**3
        else:
            out[name] = float(value)
    return out


def froude_speed(speed: float, scale: float) -> float:
    """A speed [m/s] at the other scale (``U / sqrt(lambda)``, same Froude number).

    Parameters
    ----------
    speed : float
        Speed at the original scale [m/s].
    scale : float
        ``lambda = L_from / L_to``.

    Returns
    -------
    float
    """
    return float(speed) / math.sqrt(_check_scale(scale))


def froude_rate(rate: float, scale: float) -> float:
    """A rate (propeller revolutions [1/s], rudder rate or yaw rate [rad/s]) at the other scale
    (``n sqrt(lambda)``).

    Parameters
    ----------
    rate : float
        Rate at the original scale.
    scale : float
        ``lambda = L_from / L_to``.

    Returns
    -------
    float
    """
    return float(rate) * math.sqrt(_check_scale(scale))
