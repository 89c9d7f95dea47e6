"""Angle helpers: wrapping to (-pi, pi] on the circle, numerically and symbolically."""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["wrap", "wrap_sym", "unwrap", "deg", "rad"]


def wrap(angle):
    """Wrap angles (rad) to the interval (-pi, pi].

    Parameters
    ----------
    angle : float or array_like
        Angle(s) [rad], any magnitude. NaN stays NaN and an infinite value stays infinite (it
        has no place on the circle: the checks downstream name it instead of taking it for a
        missing sample).

    Returns
    -------
    float or ndarray
        The angle(s) on (-pi, pi] [rad]: a float for a scalar input, else an array of the input's
        shape. ``-pi`` maps to ``+pi``.

    See Also
    --------
    wrap_sym : the same on CasADi symbols (smooth, for models and residuals).

    Examples
    --------
    >>> float(wrap(3 * np.pi / 2))
    -1.5707963267948966
    >>> wrap([-np.pi, 7.0])
    array([3.14159265, 0.71681469])
    """
    a = np.asarray(angle, dtype=float)
    with np.errstate(invalid="ignore"):           # np.mod(inf) is NaN: kept infinite below
        out = np.pi - np.mod(np.pi - a, 2.0 * np.pi)
    # np.mod may round up to exactly 2 pi for arguments just above pi; keep the interval half-open.
    out = np.where(out <= -np.pi, out + 2.0 * np.pi, out)
    out = np.where(np.isinf(a), a, out)
    return out if out.ndim else float(out)


def wrap_sym(angle):
    """Symbolic wrap to [-pi, pi] via ``atan2(sin, cos)``: smooth away from +-pi, exact derivative 1.

    Use it in CasADi expressions (angle residuals of an estimator, angle states of a model), where
    :func:`wrap` (numpy) cannot be applied.

    Parameters
    ----------
    angle : casadi.SX, casadi.MX, casadi.DM or float
        Angle(s) [rad], any magnitude.

    Returns
    -------
    casadi.SX, casadi.MX, casadi.DM or float
        ``atan2(sin(angle), cos(angle))`` [rad], of the input's type. Unlike :func:`wrap`, both
        ends can occur: ``-pi`` stays ``-pi`` (the sign of the sine decides).

    Examples
    --------
    >>> import casadi as ca
    >>> a = ca.SX.sym("a")
    >>> f = ca.Function("f", [a], [wrap_sym(a), ca.jacobian(wrap_sym(a), a)])
    >>> [round(float(v), 6) for v in f(3 * np.pi / 2)]
    [-1.570796, 1.0]
    """
    return ca.atan2(ca.sin(angle), ca.cos(angle))


def unwrap(angle):
    """Remove 2*pi jumps from a sampled angle sequence (NaN entries are kept and skipped).

    Parameters
    ----------
    angle : array_like
        One-dimensional sequence of angles [rad], in time order; NaN marks a sample that was not
        measured.

    Returns
    -------
    ndarray
        A new float array of the same shape: every jump larger than pi between consecutive finite
        samples is removed by adding a multiple of 2 pi [rad]; NaN entries stay NaN (the finite
        samples on both sides of a gap are unwrapped against each other).

    Examples
    --------
    >>> unwrap([3.0, -3.0, np.nan, -2.9])
    array([3.        , 3.28318531,        nan, 3.38318531])
    """
    a = np.asarray(angle, dtype=float).copy()
    ok = np.isfinite(a)
    a[ok] = np.unwrap(a[ok])
    return a


def deg(rad_value):
    """Radians to degrees (only at the edges of the library: printing, plots, ``*_deg`` options).

    Parameters
    ----------
    rad_value : float or array_like
        Angle(s) [rad].

    Returns
    -------
    float or ndarray
        The angle(s) [deg] (numpy scalar for a scalar input).

    Examples
    --------
    >>> float(deg(np.pi / 2))
    90.0
    """
    return np.degrees(rad_value)


def rad(deg_value):
    """Degrees to radians (for inputs given in degrees at the edges of the library).

    Parameters
    ----------
    deg_value : float or array_like
        Angle(s) [deg].

    Returns
    -------
    float or ndarray
        The angle(s) [rad] (numpy scalar for a scalar input).

    Examples
    --------
    >>> float(rad(180.0))
    3.141592653589793
    """
    return np.radians(deg_value)
