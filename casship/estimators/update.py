"""The measurement update shared by the estimators, as symbolic building blocks.

One home for the pieces every Gaussian estimator uses: the masked, angle-wrapped residual, the
innovation covariance with unmeasured channels neutralised, the NIS and log-likelihood of an
innovation, the Joseph-form Kalman update (EKF, Kalman-Bucy measurement flow, the MHE's
arrival-cost EKF and its covariance pass), and the symmetric products they are built from.

For ``SX`` the symmetric results (``A P A'``, the Joseph form, weighted outer products) are
computed on one triangle and mirrored: exactly symmetric, with about half the arithmetic of the full
product and no ``(X + X') / 2`` pass. Cholesky solves use explicit substitution with the reciprocal
diagonal (one division per row, multiplications elsewhere), which costs a fraction of a general
symbolic solve.
"""
from __future__ import annotations

import casadi as ca
import numpy as np


__all__ = ["residual", "masked_innovation_cov", "gaussian_terms", "gain_and_terms", "joseph_update", "symmetric",
           "spd_solve", "sandwich", "outer_sum", "from_lower", "wrap_residual"]

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


def from_lower(entry, n: int):
    """The symmetric ``n x n`` SX matrix with ``(i, j)`` and ``(j, i)`` both ``entry(i, j)``, ``i >= j``.

    Parameters
    ----------
    entry : callable
        ``entry(i, j)`` gives the SX scalar at row ``i >= j``, column ``j``.
    n : int
    """
    rows = [[None] * n for _ in range(n)]
    for i in range(n):
        for j in range(i + 1):
            rows[i][j] = rows[j][i] = entry(i, j)
    return ca.vertcat(*[ca.horzcat(*r) for r in rows]) if n else ca.SX(0, 0)


def sandwich(A, P, AP=None):
    """``A P A'`` for a symmetric ``P``, exactly symmetric.

    For SX only one triangle is computed (``A P`` once, then the row products of the lower
    triangle); for MX it is ``(A P A' + (A P A')') / 2``.

    Parameters
    ----------
    A : symbolic (m, n)
    P : symbolic (n, n)
        Symmetric.
    AP : symbolic (m, n), optional
        The product ``A P`` if it is at hand already (e.g. the transposed cross-covariance
        ``(P A')'``), so it is not formed again.
    """
    AP = A @ P if AP is None else AP
    if not isinstance(AP, ca.SX):
        return symmetric(AP @ A.T)
    At = A.T
    return from_lower(lambda i, j: ca.mtimes(AP[i, :], At[:, j]), A.shape[0])


def outer_sum(D, w=None):
    """``sum_i w_i d_i d_i'`` over the columns ``d_i`` of ``D`` (``D D'`` without weights), exactly symmetric.

    Parameters
    ----------
    D : symbolic (n, k)
    w : sequence of k floats, optional
        Weights (numbers).
    """
    DW = D if w is None else D @ ca.diag(ca.DM(w))
    if not isinstance(D, ca.SX):
        return symmetric(DW @ D.T)
    Dt = D.T
    return from_lower(lambda i, j: ca.mtimes(DW[i, :], Dt[:, j]), D.shape[0])


def _reciprocals(L) -> list:
    """``1 / L[i, i]`` for the positive diagonal of a Cholesky factor, kept as reciprocals.

    CasADi simplifies ``a * (1 / d)`` to ``a / d`` as the expression is built, which would turn the
    substitutions' multiplications back into divisions (a division costs several multiplications).
    The absolute value (a no-op on a positive diagonal, one cheap instruction) keeps the
    reciprocal a value of its own.
    """
    return [ca.fabs(1 / L[i, i]) for i in range(L.shape[0])]


def _forward(L, B, inv=None):
    """``(L')^-1 B`` for the upper Cholesky factor ``L``: forward substitution for SX (``inv``: the
    :func:`_reciprocals` of ``L`` when at hand)."""
    if not isinstance(L, ca.SX):
        return ca.solve(L.T, B)
    n = L.shape[0]
    inv = _reciprocals(L) if inv is None else inv
    rows = []
    for i in range(n):
        acc = B[i, :]
        for k in range(i):
            acc = acc - L[k, i] * rows[k]
        rows.append(acc * inv[i])
    return ca.vertcat(*rows) if n else B


def _backward(L, Z, inv=None):
    """``L^-1 Z`` for the upper triangular ``L``: back substitution for SX (``inv`` as for :func:`_forward`)."""
    if not isinstance(L, ca.SX):
        return ca.solve(L, Z)
    n = L.shape[0]
    inv = _reciprocals(L) if inv is None else inv
    rows = [None] * n
    for i in reversed(range(n)):
        acc = Z[i, :]
        for k in range(i + 1, n):
            acc = acc - L[i, k] * rows[k]
        rows[i] = acc * inv[i]
    return ca.vertcat(*rows) if n else Z


def symmetric(A):
    """``(A + A') / 2``.

    Parameters
    ----------
    A : symbolic or numeric square matrix
    """
    return 0.5 * (A + A.T)


def spd_solve(A, B, exact: bool = False):
    """``A^-1 B`` for a symmetric positive definite ``A``, by Cholesky factor and two triangular solves.

    Unlike a general symbolic solve this keeps its accuracy when ``A`` is badly scaled (variances
    of latitude in rad^2 next to speeds in (m/s)^2): Cholesky's error is governed by the condition
    of the correlation matrix, not of ``A`` itself.

    Parameters
    ----------
    A : symbolic (n, n)
    B : symbolic (n, k)
    exact : bool
        ``A`` is exactly symmetric (as every covariance an estimator computes): its triangle is
        factored as it is, without the ``(A + A') / 2`` pass.
    """
    L = _chol(A if exact else symmetric(A))          # A = L' L, L upper triangular
    inv = _reciprocals(L) if isinstance(L, ca.SX) else None
    return _backward(L, _forward(L, B, inv), inv)


def wrap_residual(angle):
    """Symbolic wrap to (-pi, pi] by ``ceil``: ``angle - 2 pi ceil((angle - pi) / (2 pi))``.

    The angle itself (exactly) inside the interval, and derivative 1 wherever the wrap is
    continuous, like ``atan2(sin, cos)`` (:func:`casship.angles.wrap_sym`) but with three cheap
    operations instead of three transcendental calls (a tenth of an EKF step on a 6-state ship).

    Parameters
    ----------
    angle : symbolic
    """
    return angle - 2 * np.pi * ca.ceil((angle - np.pi) * (0.5 / np.pi))


def residual(y, yhat, mask, angles, wrap=wrap_residual):
    """Masked residual ``y - yhat``, angle channels wrapped to (-pi, pi].

    Unmeasured channels (``mask = 0``) give exactly 0 even when ``y`` holds NaN there.

    Parameters
    ----------
    y, yhat, mask : symbolic (ny,)
        Measurement, prediction and mask (1 = measured).
    angles : sequence of bool
        Which channels are angles.
    wrap : callable
        The wrap of angle channels (default :func:`wrap_residual`).
    """
    e = y - yhat
    return ca.vertcat(*[ca.if_else(mask[i] > 0, wrap(e[i]) if a else e[i], 0) for i, a in enumerate(angles)])


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
    return _factor_terms(e, _chol(S), mask)


def gain_and_terms(S, cov_yx, e, mask):
    """Kalman gain ``K = cov_yx' S^-1``, NIS and log-likelihood of the innovation ``e``, from one
    Cholesky factor of ``S``.

    Parameters
    ----------
    S : symbolic (ny, ny)
        Innovation covariance (symmetric positive definite).
    cov_yx : symbolic (ny, nx)
        Covariance of the outputs with the state (``H P`` for a linearised model).
    e : symbolic (ny,)
    mask : symbolic (ny,)

    Returns
    -------
    K : symbolic (nx, ny)
    nis, ll : symbolic scalars
    """
    L = _chol(S)
    inv = _reciprocals(L) if isinstance(L, ca.SX) else None
    return (_backward(L, _forward(L, cov_yx, inv), inv).T, *_factor_terms(e, L, mask, inv))


def _factor_terms(e, L, mask, inv=None):
    """:func:`gaussian_terms` from the upper Cholesky factor ``L`` of ``S`` (``inv``: its reciprocals)."""
    z = _forward(L, e, inv)
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
    HP = Hm @ Pp
    S = masked_innovation_cov(sandwich(Hm, Pp, HP), R, mask)
    K, nis, ll = gain_and_terms(S, HP, e, mask)
    acc = nis <= gate
    Ka = acc * K
    IKH = ca.DM.eye(Pp.shape[0]) - Ka @ Hm
    P = sandwich(IKH, Pp) + sandwich(Ka, Dm @ R @ Dm)
    return {"x": xp + Ka @ e, "P": P, "S": S, "K": Ka, "nis": nis, "ll": ll, "accepted": acc}
