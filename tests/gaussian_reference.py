"""Independent answers for the statistics tests: a linear Gaussian state-space model in plain NumPy.

The outputs of ``x[k+1] = A x[k] + B u[k] + w[k]``, ``y[k] = H x[k] + v[k]`` with ``x[0] ~ N(m0, P0)``,
``w ~ N(0, Q)``, ``v ~ N(0, R)`` are jointly Gaussian: their stacked mean and covariance are written
here directly from the model, with no Kalman filter, so the log-likelihood of a record is the log
density of its measured values (the prediction-error decomposition says a correct filter gives the
same number), and the Fisher information is that of a Gaussian vector.
"""
from __future__ import annotations

import numpy as np
from scipy import stats

import casship as cs

DT = 0.5
H_CV = np.array([[1.0, 0.0], [1.0, 2.0]])


def cv_model(gain: float = 1.0, name: str = "cv-gain"):
    """Discrete-time constant-velocity model driven by ``g * a``, two outputs (``y1 = x``, ``y2 = x + 2 v``)."""
    b = cs.ModelBuilder(name, "constant velocity with an input gain", dt=DT)
    x, v = b.state("x", unit="m"), b.state("v", unit="m/s")
    a = b.input("a", unit="m/s^2")
    g = b.param("g", gain)
    b.next(x=x + DT * v + 0.5 * DT**2 * g * a + b.noise("w_x"), v=v + DT * g * a + b.noise("w_v"))
    b.output("y1", x)
    b.output("y2", x + 2.0 * v)
    return b.build()


def cv_matrices(gain: float = 1.0):
    """``A, B, H`` of :func:`cv_model` written out by hand."""
    return np.array([[1.0, DT], [0.0, 1.0]]), gain * np.array([0.5 * DT**2, DT]), H_CV


def state_moments(A, B, Q, m0, P0, u):
    """Means ``(N, n)`` and the joint covariance ``(N n, N n)`` of the states ``x[0..N-1]``."""
    N, n = len(u), A.shape[0]
    powers = [np.linalg.matrix_power(A, k) for k in range(N)]
    mean = np.zeros((N, n))
    mean[0] = m0
    for k in range(1, N):
        mean[k] = A @ mean[k - 1] + B * u[k - 1]
    cov = np.zeros((N * n, N * n))
    for j in range(N):
        for k in range(j + 1):
            c = powers[j] @ P0 @ powers[k].T
            for i in range(k):                      # the noise of steps before both j and k
                c = c + powers[j - 1 - i] @ Q @ powers[k - 1 - i].T
            cov[j * n:(j + 1) * n, k * n:(k + 1) * n] = c
            cov[k * n:(k + 1) * n, j * n:(j + 1) * n] = c.T
    return mean, cov


def output_moments(A, B, H, Q, R, m0, P0, u, bias=None):
    """Stacked mean ``(N ny,)`` and covariance of the outputs (plus a constant output ``bias``)."""
    N = len(u)
    mean, cov = state_moments(A, B, Q, m0, P0, u)
    Hb = np.kron(np.eye(N), H)
    my = Hb @ mean.reshape(-1)
    if bias is not None:
        my = my + np.tile(bias, N)
    return my, Hb @ cov @ Hb.T + np.kron(np.eye(N), R)


def loglik(Y, mean, cov):
    """Log density of the measured (finite) entries of ``Y`` (N, ny) under the stacked Gaussian."""
    y = np.asarray(Y, dtype=float).reshape(-1)
    ok = np.isfinite(y)
    if not ok.any():
        return 0.0
    return float(stats.multivariate_normal(mean[ok], cov[np.ix_(ok, ok)]).logpdf(y[ok]))


def loglik_terms(Y, mean, cov):
    """Per-sample terms ``log p(y_k | y_0..k-1)`` by the chain rule of the joint density."""
    Y = np.asarray(Y, dtype=float)
    ny = Y.shape[1]
    total = [loglik(Y[:k], mean[:k * ny], cov[:k * ny, :k * ny]) for k in range(len(Y) + 1)]
    return np.diff(total)


def gaussian_fisher(dmean, dcov, cov):
    """Fisher information of ``N(mean(theta), cov(theta))``: ``dm' C^-1 dm + 0.5 tr(C^-1 dC_i C^-1 dC_j)``.

    ``dmean`` is a list of mean derivatives, ``dcov`` of covariance derivatives, one per parameter.
    """
    Ci = np.linalg.inv(cov)
    k = len(dmean)
    M = [Ci @ dc for dc in dcov]
    return np.array([[dmean[i] @ Ci @ dmean[j] + 0.5 * np.trace(M[i] @ M[j]) for j in range(k)] for i in range(k)])
