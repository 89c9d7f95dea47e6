"""Rauch-Tung-Striebel fixed-interval smoother over a :class:`FilterResult` (used by ``Estimator.smooth``).

The backward pass uses what every recursive filter stores per sample: the filtered belief
``(x_k, P_k)``, the next prediction ``(x-_{k+1}, P-_{k+1})`` and the cross-covariance
``C_{k+1} = cov(x_k, x-_{k+1})`` (``P_k A'`` for the KF/EKF, the sigma-point or ensemble
estimate for the UKF/EnKF). With the smoother gain ``J_k = C_{k+1} (P-_{k+1})^-1``::

    xs_k = x_k + J_k (xs_{k+1} - x-_{k+1})
    Ps_k = P_k + J_k (Ps_{k+1} - P-_{k+1}) J_k'

``J_k`` comes from a Cholesky solve, which stays accurate for badly scaled covariances (latitude
in rad next to speed in m/s) where a plain symbolic solve loses every digit and the smoothed
covariances stop being positive definite. Differences of angle states are wrapped. The pass is one
fold (``mapaccum``) over the reversed record, in pieces of 512 samples through buffers; compiled
(``jit``), one C loop reads the filter's arrays backwards in place (:class:`~casship.runtime.NativeFold`).
"""
from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from ..runtime import DUPLICATE_NAMES, Job, record_loop, run_pieces
from .result import FilterResult
from .update import from_lower, sandwich, spd_solve, wrap_residual
from ..errors import InputError, InputTypeError

__all__ = ["rts_smooth", "backward_step"]

@lru_cache(maxsize=32)
def backward_step(nx: int, angles: tuple) -> ca.Function:
    """One backward step with named slots: memory ``x, P`` (smoothed at ``k+1`` in, at ``k`` out);
    inputs ``x_filt, P_filt`` (filtered at ``k``), ``x_pred, P_pred, C`` (at ``k+1``); output ``J``."""
    xs1, Ps1 = ca.SX.sym("x", nx), ca.SX.sym("P", nx, nx)
    x, P = ca.SX.sym("x_filt", nx), ca.SX.sym("P_filt", nx, nx)
    xp1, Pp1, C = ca.SX.sym("x_pred", nx), ca.SX.sym("P_pred", nx, nx), ca.SX.sym("C", nx, nx)
    d = xs1 - xp1
    if any(angles):
        d = ca.vertcat(*[wrap_residual(d[i]) if angles[i] else d[i] for i in range(nx)])
    J = spd_solve(Pp1, C.T, exact=True).T        # the filters' covariances are exactly symmetric
    JDJ = sandwich(J, from_lower(lambda i, j: Ps1[i, j] - Pp1[i, j], nx))
    Ps = from_lower(lambda i, j: P[i, j] + JDJ[i, j], nx)
    return ca.Function("rts_step", [xs1, Ps1, x, P, xp1, Pp1, C], [x + J @ d, Ps, J],
                       ["x", "P", "x_filt", "P_filt", "x_pred", "P_pred", "C"], ["x", "P", "J"], DUPLICATE_NAMES)


@lru_cache(maxsize=256)
def _backward_fold(nx: int, angles: tuple, n: int) -> ca.Function:
    return backward_step(nx, angles).mapaccum(f"rts_fold{n}", n, ["x", "P"], ["x", "P"], DUPLICATE_NAMES)


def rts_smooth(result: FilterResult, *, jit=False) -> FilterResult:
    """Fixed-interval (RTS) smoothing of a filter run (``Estimator.smooth`` runs the filter and this).

    Parameters
    ----------
    result : FilterResult
        Output of ``KF``, ``EKF`` (discrete or continuous-discrete), ``UKF`` or ``EnKF``
        ``.filter``; its predictions and cross-covariances ``C`` drive the backward pass.
    jit : bool, None, str or casship.runtime.JitPolicy
        Run the backward pass as a compiled C loop (``True``: compiled now; ``None``: once the
        cache or a background compile has it), see :class:`casship.runtime.JitPolicy`.

    Returns
    -------
    FilterResult
        The same record with ``x`` and ``P`` replaced by the smoothed means and covariances and
        ``estimator`` marked ``"<filter>+RTS"``; predictions, innovations and likelihood terms are
        those of the forward filter.
    """
    if not isinstance(result, FilterResult):
        raise InputTypeError(f"rts_smooth needs a FilterResult, got {type(result).__name__}")
    if result.estimator.split("+")[0].split(" ")[0] == "KalmanBucy":
        raise InputError(f"rts_smooth: a {result.estimator} result has no one-step predictions to smooth; "
                         "use KF, EKF, UKF or EnKF")
    if result.estimator.endswith("+RTS"):
        raise InputError("rts_smooth: the result is already smoothed")
    n, nx = result.x.shape
    if n == 1:
        return result.replace(estimator=f"{result.estimator}+RTS")
    angles = tuple(bool(a) for a in result.angle_states)
    # backwards in time, as (sample, rows, cols) views (the C loop reads them in place)
    per = {"x_filt": result.x[-2::-1, :, None], "P_filt": result.P[-2::-1], "x_pred": result.x_pred[:0:-1, :, None],
           "P_pred": result.P_pred[:0:-1], "C": result.C[:0:-1]}
    memory = {"x": result.x[-1], "P": result.P[-1]}
    fold = record_loop(backward_step(nx, angles), ["x", "P"], jit) if jit else None
    if fold is not None:
        # one block for the smoothed x and P (P per sample in column-major order), written backwards in place
        flat = np.empty(n * (nx + nx * nx))
        block = flat.reshape(n, nx + nx * nx)
        xs, Ps = block[:, :nx], block[:, nx:].reshape(n, nx, nx).transpose(0, 2, 1)
        xs[-1], Ps[-1] = result.x[-1], result.P[-1]
        fold.run(n - 1, memory=memory, per_sample=per, keep=("x", "P"), out={"x": xs[-2::-1], "P": Ps[-2::-1]})
        flat.setflags(write=False)
    else:
        flat = {k: np.ascontiguousarray(v.transpose(1, 0, 2).reshape(v.shape[1], (n - 1) * v.shape[2]))
                for k, v in per.items()}
        job = Job(lambda size: _backward_fold(nx, angles, size), memory, {}, flat, n - 1, carry={"x": "x", "P": "P"},
                  pad={})
        outs = run_pieces([job], shrink=True, collect=("x", "P"), record=False)[0]
        xs = np.vstack([outs["x"].reshape(n - 1, nx)[::-1], result.x[-1:]])
        Ps = np.concatenate([outs["P"][::-1], result.P[-1:]], axis=0)
        for a in (xs, Ps):                        # own arrays: the result keeps them without a copy
            a.setflags(write=False)
    return result.replace(x=xs, P=Ps, estimator=f"{result.estimator}+RTS")
