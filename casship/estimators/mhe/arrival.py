"""Arrival cost of the MHE window: the prior on the first state of the window.

``arrival="ekf"`` (default): the EKF prediction, with exact Jacobians, of the MHE's own filtered
estimate ``x_{s-1|s-1}`` and its covariance (the "filtering update" of Rao, Rawlings & Lee 2001).
It carries the information of the samples that have left the window exactly once.
``arrival="fixed"``: the previous window's estimate of ``x_s`` with the fixed initial covariance;
that estimate already used ``y_s .. y_{k-1}``, which the window then counts a second time. It is
kept for comparison only.
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dpotrf as _potrf, dtrtri as _trtri

__all__: list[str] = []          # the package's own building blocks


def inv_sqrt(P: np.ndarray) -> np.ndarray:
    """``W`` with ``W' W = P^-1``, through the correlation matrix ``C = S^-1 P S^-1`` (``S`` the standard
    deviations): ``W = W_C S^-1`` with ``W_C`` from the Cholesky factor of ``C``, or for a near-singular
    ``C`` from its eigenvalues floored at 1e-14 of the largest. On ``C`` the test and the floor do not
    depend on the states' units (a latitude's variance of 1e-16 rad^2 beside a speed's of 1 (m/s)^2
    is no sign of singularity); a state with zero variance is scaled by the largest deviation."""
    P = 0.5 * (P + P.T)
    d = P.diagonal().copy()
    top = float(np.sqrt(max(d.max(), 1e-300)))
    sd = np.where(np.isfinite(d) & (d > 0), np.sqrt(np.abs(d)), top)
    C = P / np.outer(sd, sd)
    L, info = _potrf(C, lower=1, clean=1)
    # a positive definite C has a positive diagonal (potrf fails otherwise)
    if info == 0 and L.diagonal().min() > 1e-7 * float(C.diagonal().max()) ** 0.5:
        Linv, info = _trtri(L, lower=1)
        if info == 0:
            return Linv / sd
    lam, V = np.linalg.eigh(C)
    lam = np.maximum(lam, 1e-14 * max(lam.max(), 1e-300))
    return (V / np.sqrt(lam)).T / sd


def arrival_prior(kind: str, k: int, N: int, hist_x: np.ndarray, hist_P: np.ndarray, previous_x1: np.ndarray,
                  P0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and whitening ``W`` of the arrival cost of the window ending at sample ``k``.

    ``hist_x, hist_P`` hold the EKF predictions of the window's samples from the MHE estimate
    before each (oldest first); ``previous_x1`` is the previous window's estimate of this window's
    first state, ``P0`` the prior covariance.
    """
    if kind == "fixed" and k > N:
        return previous_x1, inv_sqrt(P0)
    return hist_x[0], inv_sqrt(hist_P[0])
