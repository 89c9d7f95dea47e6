"""The measurement update shared by the estimators, as symbolic building blocks.

One home for the pieces every Gaussian estimator uses: the masked, angle-wrapped residual, the
innovation covariance with unmeasured channels neutralised, the NIS and log-likelihood of an
innovation, and the Joseph-form Kalman update (EKF, Kalman-Bucy measurement flow, the MHE's
arrival-cost EKF and its covariance pass).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..angles import wrap_sym

__all__ = ["residual", "masked_innovation_cov", "gaussian_terms", "joseph_update", "symmetric", "spd_solve"]

_CHOL: dict[int, ca.Function] = {}


def _chol(S):
    """Upper Cholesky factor ``L`` (``S = L' L``); an SX Function for MX (``ca.chol`` has no MX overload)."""
    if isinstance(S, ca.SX):
        return ca.chol(S)
    n = S.shape[0]
    if n not in _CHOL:
        Ssym = ca.SX.sym("S", n, n)
        _CHOL[n] = ca.Function(f"chol{n}", [Ssym], [ca.chol(Ssym)], ["S"], ["L"])
    return _CHOL[n](S)


def symmetric(A):
    """``(A + A') / 2``.

    Parameters
    ----------
    A : symbolic or numeric square matrix
    """
    return 0.5 * (A + A.T)


def spd_solve(A, B):
    """``A^-1 B`` for a symmetric positive definite ``A``, by Cholesky factor and two triangular solves.

    Unlike a general symbolic solve this keeps its accuracy when ``A`` is badly scaled (variances
    of latitude in rad^2 next to speeds in (m/s)^2): Cholesky's error is governed by the condition
    of the correlation matrix, not of ``A`` itself.

    Parameters
    ----------
    A : symbolic (n, n)
    B : symbolic (n, k)
    """
    L = _chol(symmetric(A))          # A = L' L, L upper triangular
    return ca.solve(L, ca.solve(L.T, B))


def residual(y, yhat, mask, angles):
    """Masked residual ``y - yhat``, angle channels wrapped to (-pi, pi].

    Unmeasured channels (``mask = 0``) give exactly 0 even when ``y`` holds NaN there.

    Parameters
    ----------
    y, yhat, mask : symbolic (ny,)
        Measurement, prediction and mask (1 = measured).
    angles : sequence of bool
        Which channels are angles.
    """
    e = y - yhat
    return ca.vertcat(*[ca.if_else(mask[i] > 0, wrap_sym(e[i]) if a else e[i], 0) for i, a in enumerate(angles)])


def masked_innovation_cov(HPH, R, mask):
    """``S`` with unmeasured channels replaced by unit diagonal entries (they then carry no gain).

    Parameters
    ----------
    HPH : symbolic (ny, ny)
        Predicted output covariance.
    R : symbolic (ny, ny)
    mask : symbolic (ny,)
    """
    Dm = ca.diag(mask)
    return symmetric(Dm @ (HPH + R) @ Dm + ca.diag(1 - mask))


def gaussian_terms(e, S, mask):
    """NIS ``e' S^-1 e`` and log-likelihood ``log N(e; 0, S)`` of a masked innovation.

    Parameters
    ----------
    e : symbolic (ny,)
    S : symbolic (ny, ny)
    mask : symbolic (ny,)
        Counts the measured channels in the normalising constant.
    """
    L = _chol(S)
    z = ca.solve(L.T, e)
    nis = ca.dot(z, z)
    logdet = 2 * ca.sum1(ca.log(ca.diag(L)))
    return nis, -0.5 * (nis + logdet + ca.sum1(mask) * np.log(2 * np.pi))


def joseph_update(xp, Pp, H, e, R, mask, gate):
    """Kalman update of the prediction ``(xp, Pp)`` with the residual ``e`` of the outputs ``H``.

    ``H`` rows of unmeasured channels (``mask = 0``) are ignored. The covariance update is the
    Joseph form ``(I - K H) Pp (I - K H)' + K R K'``, symmetric and positive semi-definite for any
    gain. An update whose NIS exceeds ``gate`` is not applied (``accepted = 0``).

    Parameters
    ----------
    xp, Pp : symbolic
        Predicted mean and covariance.
    H : symbolic (ny, nx)
        Output Jacobian.
    e : symbolic (ny,)
        Masked residual.
    R, mask, gate : symbolic
        Measurement covariance, mask and chi-square threshold.

    Returns
    -------
    dict
        ``x, P`` (updated), ``S, K`` (the gain applied: zero when rejected), ``nis, ll, accepted``.
    """
    Dm = ca.diag(mask)
    Hm = Dm @ H
    S = masked_innovation_cov(Hm @ Pp @ Hm.T, R, mask)
    K = spd_solve(S, Hm @ Pp).T
    nis, ll = gaussian_terms(e, S, mask)
    acc = nis <= gate
    Ka = acc * K
    IKH = ca.DM.eye(Pp.shape[0]) - Ka @ Hm
    P = IKH @ Pp @ IKH.T + Ka @ (Dm @ R @ Dm) @ Ka.T
    return {"x": xp + Ka @ e, "P": symmetric(P), "S": S, "K": Ka, "nis": nis, "ll": ll, "accepted": acc}
