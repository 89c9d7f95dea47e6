"""Angle helpers: wrapping to (-pi, pi] on the circle, numerically and symbolically."""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["wrap", "wrap_sym", "unwrap", "deg", "rad"]


def wrap(angle):
    """Wrap angles (rad) to the interval (-pi, pi].

    Examples
    --------
    >>> float(wrap(3 * np.pi / 2))
    -1.5707963267948966
    """
    a = np.asarray(angle, dtype=float)
    out = np.pi - np.mod(np.pi - a, 2.0 * np.pi)
    # np.mod may round up to exactly 2 pi for arguments just above pi; keep the interval half-open.
    out = np.where(out <= -np.pi, out + 2.0 * np.pi, out)
    return out if out.ndim else float(out)


def wrap_sym(angle):
    """Symbolic wrap to [-pi, pi] via ``atan2(sin, cos)``: smooth away from +-pi, exact derivative 1."""
    return ca.atan2(ca.sin(angle), ca.cos(angle))


def unwrap(angle):
    """Remove 2*pi jumps from a sampled angle sequence (NaN entries are kept and skipped)."""
    a = np.asarray(angle, dtype=float).copy()
    ok = np.isfinite(a)
    a[ok] = np.unwrap(a[ok])
    return a


def deg(rad_value):
    """Radians to degrees (only at the edges of the library)."""
    return np.degrees(rad_value)


def rad(deg_value):
    """Degrees to radians."""
    return np.radians(deg_value)
