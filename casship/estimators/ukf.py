"""Unscented Kalman filter with angle-aware sigma-point statistics.

The sigma points follow the scaled unscented transform (Julier 2002; Wan & van der Merwe 2000):
``lambda = alpha^2 (n + kappa) - n``, points ``x`` and ``x +- sqrt(n + lambda) * S[:, i]`` with
``S S' = P``, mean weights ``W0 = lambda / (n + lambda)``, ``Wi = 1 / (2 (n + lambda))`` and the
covariance weight ``W0c = W0 + 1 - alpha^2 + beta``. With ``alpha = 1, beta = 0`` this is the
original form of Julier & Uhlmann that Koike et al. (2023) use (``W0 = kappa / (n + kappa)``, ``kappa = 3``),
the default here.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from dataclasses import dataclass

from .base import StepEstimator
from .options import EstimatorOptions, check_number
from .update import gain_and_terms, masked_innovation_cov, outer_sum, sandwich
from ..errors import InputError

__all__ = ["UKF", "UKFOptions", "psd_sqrt", "sigma_weights", "circular_mean", "deviations", "wrap_fast"]


def psd_sqrt(P, tol: float = 0.0):
    """Symbolic lower Cholesky factor ``L`` (``L L' = P``) that tolerates positive *semi*-definite ``P``.

    A pivot that is not larger than ``tol`` gives a zero column instead of a division by zero, so
    states with zero variance (fixed parameters, noise-free channels) yield no NaN.

    Parameters
    ----------
    P : symbolic or numeric (n, n)
    tol : float
        Largest pivot treated as zero.
    """
    n = P.shape[0]
    sym = type(P) if isinstance(P, (ca.SX, ca.MX)) else ca.SX
    L = [[sym(0) for _ in range(n)] for _ in range(n)]
    for j in range(n):
        d = P[j, j] - sum((L[j][k] * L[j][k] for k in range(j)), sym(0))
        ok = d > tol
        ljj = ca.if_else(ok, ca.sqrt(ca.if_else(ok, d, 1)), 0)
        L[j][j] = ljj
        inv = ca.if_else(ok, 1 / ca.if_else(ok, ljj, 1), 0)
        for i in range(j + 1, n):
            L[i][j] = (P[i, j] - sum((L[i][k] * L[j][k] for k in range(j)), sym(0))) * inv
    return ca.vertcat(*[ca.horzcat(*row) for row in L])


def sigma_weights(n: int, alpha: float, beta: float, kappa: float):
    """Scale ``c = n + lambda`` and the mean and covariance weights of the ``2n+1`` sigma points.

    Parameters
    ----------
    n : int
        State dimension.
    alpha, beta, kappa : float
        Scaled unscented transform parameters.
    """
    lam = alpha**2 * (n + kappa) - n
    c = n + lam
    if c <= 0:
        raise InputError(f"UKF: n + lambda = {c:g} must be positive (n = {n}, alpha = {alpha}, kappa = {kappa})")
    wm = np.full(2 * n + 1, 1.0 / (2 * c))
    wm[0] = lam / c
    wc = wm.copy()
    wc[0] += 1 - alpha**2 + beta
    return c, wm, wc


def wrap_fast(angle):
    """Symbolic wrap to [-pi, pi) by ``floor`` (four cheap operations instead of ``atan2(sin, cos)``;
    derivative 1 almost everywhere), for the many sigma-point and ensemble deviations.

    Parameters
    ----------
    angle : symbolic
    """
    return angle - 2 * np.pi * ca.floor((angle + np.pi) / (2 * np.pi))


def circular_mean(points, wm, angles):
    """Weighted mean of sigma points (columns); angle rows averaged on the circle.

    For an angle row the mean is the central point plus the weighted mean of the wrapped deviations
    from it, which equals the arithmetic mean when no point crosses +-pi and never jumps by 2 pi.

    Parameters
    ----------
    points : symbolic (n, k)
    wm : array (k,)
        Mean weights.
    angles : array (n,) of bool
        Which rows are angles.
    """
    ref = points[:, 0]
    rows = []
    for i in range(points.shape[0]):
        if angles[i]:
            dev = ca.horzcat(*[wrap_fast(points[i, j] - ref[i]) for j in range(points.shape[1])])
            rows.append(ref[i] + ca.mtimes(dev, ca.DM(wm)))
        else:
            rows.append(ca.mtimes(points[i, :], ca.DM(wm)))
    return ca.vertcat(*rows)


def deviations(points, mean, angles):
    """Columns ``points[:, j] - mean`` with angle rows wrapped to (-pi, pi].

    Parameters
    ----------
    points : symbolic (n, k)
    mean : symbolic (n,)
    angles : array (n,) of bool
    """
    d = points - ca.repmat(mean, 1, points.shape[1])
    if not np.any(angles):
        return d
    return ca.vertcat(*[ca.horzcat(*[wrap_fast(d[i, j]) for j in range(d.shape[1])]) if angles[i] else d[i, :]
                        for i in range(d.shape[0])])


@dataclass(frozen=True)
class UKFOptions(EstimatorOptions):
    """Options of :class:`UKF` (and those of every estimator, see :class:`EstimatorOptions`).

    Parameters
    ----------
    gate, jit, outputs, max_gap, on_gap
        The options of every estimator (see :class:`~casship.estimators.EstimatorOptions`).
    alpha, beta, kappa : float
        Scaled unscented transform parameters. The default ``alpha = 1, beta = 0, kappa = 3`` is
        the unscaled form of Koike et al. (2023); ``alpha = 1e-3, beta = 2, kappa = 0`` is the common scaled form.
    """

    alpha: float = 1.0
    beta: float = 0.0
    kappa: float = 3.0

    def __post_init__(self):
        super().__post_init__()
        for name in ("alpha", "beta", "kappa"):
            v = getattr(self, name)
            if isinstance(v, bool) or not np.isfinite(check_number(v, name)):
                raise InputError(f"option {name!r} must be a finite number, got {v!r}")
            object.__setattr__(self, name, float(v))
        if self.alpha <= 0:
            raise InputError(f"option 'alpha' must be positive, got {self.alpha}")


class UKF(StepEstimator):
    """Unscented Kalman filter with ``2n+1`` sigma points, angle-aware means and residuals.

    The process noise enters additively through the exact noise Jacobian of the discretised step at
    the mean, ``P- = sum Wc (X_i - x-)(X_i - x-)' + G Q G'`` (exact for models linear in ``w``).
    Sigma points are redrawn from the predicted belief before the update (as in Koike et al. 2023).

    Parameters
    ----------
    dmodel : DiscreteModel
    Q, R : process and measurement noise covariances (the one meaning, ``docs/architecture.md``)
    measured : sequence of str, optional
    options : UKFOptions or mapping
        ``gate``, ``jit``, ``outputs``, ``alpha``, ``beta``, ``kappa``.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order()
    >>> ukf = cs.UKF(cs.discretize(m, 0.1), Q=1e-8, R=1e-4, options={"kappa": 3})
    """

    name = "UKF"
    Options = UKFOptions

    def _check_options(self) -> None:
        o = self.options
        self.sigma_scale, self.wm, self.wc = sigma_weights(self.model.nx, o.alpha, o.beta, o.kappa)

    def _build(self, s: dict) -> dict:
        m, S, dm = self.model, self.sym, self.dmodel
        n = m.nx
        c, wm, wc = self.sigma_scale, self.wm, self.wc
        ang_x = m.angle_states
        x, P = s["x"], s["P"]
        Wc = ca.DM(np.diag(wc))

        def points(mean, cov):                  # cov is exactly symmetric: its lower triangle is read
            L = np.sqrt(c) * psd_sqrt(cov)
            return ca.horzcat(mean, ca.repmat(mean, 1, n) + L, ca.repmat(mean, 1, n) - L)

        # predict
        w0 = S.zeros(m.nw)
        X = points(x, P)
        Xf = ca.horzcat(*[dm.F(X[:, j], s["u_prev"], s["p"], w0, s["dt"]) for j in range(2 * n + 1)])
        xp = circular_mean(Xf, wm, ang_x)
        dX0 = deviations(X, x, ang_x)
        dXf = deviations(Xf, xp, ang_x)
        G = dm.F_jac(x, s["u_prev"], s["p"], w0, s["dt"])[3]
        Pp = outer_sum(dXf, wc) + sandwich(G, s["Q"])
        C = dX0 @ Wc @ dXf.T
        # update with redrawn points
        mask = s["mask"]
        Xp = points(xp, Pp)
        Y = ca.horzcat(*[self.h_meas(Xp[:, j], s["u"], s["p"]) for j in range(2 * n + 1)])
        yhat = circular_mean(Y, wm, self.angle_meas)
        dY = ca.diag(mask) @ deviations(Y, yhat, self.angle_meas)
        dXp = deviations(Xp, xp, ang_x)
        Pyy = outer_sum(dY, wc)
        Pxy = dXp @ Wc @ dY.T
        e = self.residual(s["y"], yhat, mask)
        Sm = masked_innovation_cov(Pyy, s["R"], mask)
        K, nis, ll = gain_and_terms(Sm, Pxy.T, e, mask)
        acc = nis <= s["gate"]
        Ka = acc * K
        if np.all(wc >= 0):
            # Joseph form in sigma points: sum_i Wc_i (dX_i - K dY_i)(dX_i - K dY_i)' + K R K' equals
            # Pp - K S K' but is a sum of positive semi-definite terms (no loss of definiteness)
            D = dXp - Ka @ dY
            P_upd = outer_sum(D, wc) + sandwich(Ka, ca.diag(mask) @ s["R"] @ ca.diag(mask))
        else:            # a negative central weight (scaled form): the plain update
            P_upd = Pp - sandwich(Ka, Sm)
        return {"x": xp + Ka @ e, "P": P_upd, "x_pred": xp, "P_pred": Pp, "C": C,
                "e": e, "S": Sm, "K": Ka, "nis": nis, "ll": ll, "accepted": acc}
