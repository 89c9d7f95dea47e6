"""Rauch-Tung-Striebel fixed-interval smoother over a :class:`FilterResult`.

The backward pass uses what every recursive filter stores per sample: the filtered belief
``(x_k, P_k)``, the next prediction ``(x-_{k+1}, P-_{k+1})`` and the cross-covariance
``C_{k+1} = cov(x_k, x-_{k+1})`` (``P_k A'`` for the KF/EKF, the sigma-point or ensemble
estimate for the UKF/EnKF). With the smoother gain ``J_k = C_{k+1} (P-_{k+1})^-1``::

    xs_k = x_k + J_k (xs_{k+1} - x-_{k+1})
    Ps_k = P_k + J_k (Ps_{k+1} - P-_{k+1}) J_k'

Differences of angle states are wrapped. The pass is one compiled fold (``mapaccum``) over the
reversed record
(in pieces of 512 samples through preallocated buffers).
"""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import casadi as ca
import numpy as np

from ..angles import wrap_sym
from .._fast import BufferedCall
from .base import FilterResult, compile_function, fold_in_pieces

__all__ = ["rts_smooth"]

_NOT_SMOOTHABLE = ("KalmanBucy",)


@lru_cache(maxsize=32)
def _backward_step(nx: int, angles: tuple) -> ca.Function:
    """``(carry=[xs_{k+1}, vec Ps_{k+1}], x_k, P_k, x-_{k+1}, P-_{k+1}, C_{k+1}) -> (carry, xs_k, Ps_k, J_k)``."""
    carry = ca.SX.sym("carry", nx + nx * nx)
    xs1, Ps1 = carry[:nx], ca.reshape(carry[nx:], nx, nx)
    x, Pv = ca.SX.sym("x", nx), ca.SX.sym("P", nx * nx)
    xp1, Ppv, Cv = ca.SX.sym("x_pred", nx), ca.SX.sym("P_pred", nx * nx), ca.SX.sym("C", nx * nx)
    P, Pp1, C = (ca.reshape(v, nx, nx) for v in (Pv, Ppv, Cv))
    d = xs1 - xp1
    if any(angles):
        d = ca.vertcat(*[wrap_sym(d[i]) if angles[i] else d[i] for i in range(nx)])
    J = ca.solve(0.5 * (Pp1 + Pp1.T), C.T).T
    xs = x + J @ d
    DJ = (0.5 * ((Ps1 - Pp1) + (Ps1 - Pp1).T)) @ J.T
    rows = [[None] * nx for _ in range(nx)]
    for i in range(nx):                      # J D J' is symmetric: upper triangle only
        for j in range(i, nx):
            rows[i][j] = rows[j][i] = P[i, j] + ca.dot(J[i, :].T, DJ[:, j])
    Ps = ca.vertcat(*[ca.horzcat(*r) for r in rows])
    vec = lambda a: ca.reshape(a, -1, 1)  # noqa: E731
    return ca.Function("rts_step", [carry, x, Pv, xp1, Ppv, Cv], [ca.vertcat(xs, vec(Ps)), xs, vec(Ps), vec(J)],
                       ["carry", "x", "P", "x_pred_next", "P_pred_next", "C_next"], ["carry_next", "xs", "Ps", "J"])


@lru_cache(maxsize=256)
def _backward_fold(nx: int, angles: tuple, n: int, jit: bool = False) -> BufferedCall:
    fold = _backward_step(nx, angles).mapaccum(n)
    return BufferedCall(compile_function(fold) if jit else fold)


FOLD_CHUNK = 512


def rts_smooth(result: FilterResult, *, jit: bool = False) -> FilterResult:
    """Fixed-interval (RTS) smoothing of a filter run.

    Parameters
    ----------
    result : FilterResult
        Output of ``KF``, ``EKF`` (discrete or continuous-discrete), ``UKF`` or ``EnKF``
        ``.filter``; its predictions and cross-covariances ``C`` drive the backward pass.
    jit : bool
        Compile the backward fold to C with the system compiler (one-off cost per fold length,
        cached for the session).

    Returns
    -------
    FilterResult
        The same record with ``x`` and ``P`` replaced by the smoothed means and covariances and
        ``estimator`` marked ``"<filter>+RTS"``; predictions, innovations and likelihood terms are
        those of the forward filter.

    Examples
    --------
    >>> smooth = rts_smooth(ekf.filter(data, prior))      # doctest: +SKIP
    >>> smooth["r"]                                        # doctest: +SKIP
    """
    if not isinstance(result, FilterResult):
        raise TypeError(f"rts_smooth needs a FilterResult, got {type(result).__name__}")
    if result.estimator.split("+")[0] in _NOT_SMOOTHABLE:
        raise ValueError(f"rts_smooth: a {result.estimator} result has no one-step predictions to smooth; "
                         "use KF, EKF, UKF or EnKF")
    if result.estimator.endswith("+RTS"):
        raise ValueError("rts_smooth: the result is already smoothed")
    n, nx = result.x.shape
    if n == 1:
        return replace(result, estimator=f"{result.estimator}+RTS")
    angles = tuple(bool(a) for a in (result.angle_states if result.angle_states is not None else np.zeros(nx)))
    flat = lambda a: a.transpose(0, 2, 1).reshape(a.shape[0], -1)  # noqa: E731 (column-major blocks)
    # rows k = N-2 .. 0, each with the next row's prediction and cross-covariance
    x = result.x[-2::-1].T
    P = flat(result.P[-2::-1]).T
    xp = result.x_pred[:0:-1].T
    Pp = flat(result.P_pred[:0:-1]).T
    C = flat(result.C[:0:-1]).T
    carry0 = np.concatenate([result.x[-1], result.P[-1].reshape(-1, order="F")])
    step = _backward_step(nx, angles)
    _, xs, Ps, _ = fold_in_pieces(lambda size: _backward_fold(nx, angles, size, bool(jit)), step,
                                  [carry0, x, P, xp, Pp, C], n - 1, range(1, 6), FOLD_CHUNK)
    xs = np.vstack([xs.T[::-1], result.x[-1:]])
    Ps = Ps.T.reshape(n - 1, nx, nx).transpose(0, 2, 1)[::-1]
    Ps = np.concatenate([Ps, result.P[-1:]], axis=0)
    return replace(result, x=xs, P=Ps, estimator=f"{result.estimator}+RTS")
