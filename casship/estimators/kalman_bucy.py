"""Continuous-time Kalman-Bucy filter (Kalman & Bucy 1961; Tomera 2011).

Between two samples the estimate and the covariance follow

    dx/dt = f(x, u, p, 0) + L (y - h(x, u, p)),      L = P H' Rc^-1
    dP/dt = A P + P A' - P H' Rc^-1 H P + G Qc G'

with the latest sample ``y`` held over the interval that it ends, ``A, G, H`` the exact Jacobians
(for a linear model the classical Kalman-Bucy filter ``A x + B u + L (y - C x)``) and the spectral
densities ``Qc = Q dt``, ``Rc = R dt`` of the one meaning of ``Q`` and ``R``
(``docs/architecture.md``; ``dt`` = ``dmodel.dt``, Tomera 2011, Eq. 31-35). The steady-state
filter takes ``L`` and ``P`` from ``control.lqe``.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..discretize import rk4
from .base import StepEstimator
from .options import EstimatorOptions, check_int
from .update import gaussian_terms, joseph_update, masked_innovation_cov, symmetric
from ..errors import InputError

__all__ = ["KalmanBucy", "KalmanBucyOptions"]

_INTEGRATORS = ("auto", "rk4", "split")
_RK4_SAFE = 0.5     # RK4 where h * tr(P H' Rc^-1 H) stays below this (its stability limit is ~1.39)


@dataclass(frozen=True)
class KalmanBucyOptions(EstimatorOptions):
    """Options of :class:`KalmanBucy` (and those of every estimator; ``gate`` is not available).

    Parameters
    ----------
    gate, jit, outputs, max_gap, on_gap
        The options of every estimator (see :class:`~casship.estimators.EstimatorOptions`).
    substeps : int
        Sub-steps of the coupled estimate/Riccati equations between two samples.
    integrator : {"auto", "rk4", "split"}
        ``"rk4"``: classical RK4 on the whole equation (fourth order; like every Runge-Kutta
        method its fixed point is exactly the algebraic Riccati solution, but it is unstable when
        ``P H' Rc^-1 H`` times the sub-step exceeds about 1.4, e.g. right after a vague prior).
        ``"split"``: Strang splitting into half a step of the exact measurement flow (a Kalman
        update with covariance ``2 Rc / h``), an RK4 step of the dynamics and another half
        measurement step: second order and stable for any prior, but its fixed point is off the
        Riccati solution by ``O(h^2)``. ``"auto"`` (default): per sub-step, RK4 where it is stable
        (``h tr(P H' Rc^-1 H) < 0.5``) and the splitting elsewhere: stable for any prior and exact
        in the steady state (equal to ``control.lqe``).
    steady_state : bool
        Use the constant gain and covariance of :meth:`KalmanBucy.steady_state` (linear model).
    """

    substeps: int = 10
    integrator: str = "auto"
    steady_state: bool = False

    def __post_init__(self):
        super().__post_init__()
        if self.gate is not None:
            raise InputError("KalmanBucy: option 'gate' is not available for a continuous filter")
        object.__setattr__(self, "substeps", check_int(self.substeps, "substeps", 1))
        if self.integrator not in _INTEGRATORS:
            raise InputError(f"option 'integrator' must be one of {_INTEGRATORS}, got {self.integrator!r}")
        if not isinstance(self.steady_state, bool):
            raise InputError(f"option 'steady_state' is True or False, got {self.steady_state!r}")


class KalmanBucy(StepEstimator):
    """Kalman-Bucy filter integrated between the samples of a record.

    Parameters
    ----------
    dmodel : DiscreteModel
        A discretised continuous model (its ``f`` is integrated; ``dmodel.dt`` converts ``Q, R``).
    Q, R : process and measurement noise covariances, the one meaning of ``docs/architecture.md``
        (the filter uses the spectral densities ``Qc = Q dt`` and ``Rc = R dt``).
    measured : sequence of str, optional
    options : KalmanBucyOptions or mapping
        ``jit``, ``outputs``, ``substeps``, ``integrator``, ``steady_state``.

    Notes
    -----
    The innovation reported per sample is ``y_k - h(x_{k-1})`` with ``S = H P_{k-1} H' + R``, as a
    diagnostic (NIS, log-likelihood); ``x_pred, P_pred`` hold the estimate at the start of the
    interval and ``K`` is the Kalman-Bucy gain ``P H' Rc^-1`` at its end. A continuous filter has
    no one-step prediction to smooth, so :meth:`smooth` refuses, and it has no innovation gate.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.double_integrator()
    >>> kb = cs.KalmanBucy(cs.discretize(m, 0.1), Q=[1.0, 2.0], R=0.1)
    >>> L, P = kb.steady_state()
    """

    name = "KalmanBucy"
    Options = KalmanBucyOptions
    continuous = True

    def _check_options(self) -> None:
        self.dmodel.require_continuous("KalmanBucy")

    def _build(self, s: dict) -> dict:
        m, S = self.model, self.sym
        n = m.nx
        x0, P0, mask = s["x"], s["P"], s["mask"]
        Dm = ca.diag(mask)
        dtn = self.dmodel.dt
        Rc, Qc = s["R"] * dtn, s["Q"] * dtn
        Rinv = Dm @ ca.inv(Dm @ Rc @ Dm + ca.diag(1 - mask)) @ Dm
        w0 = S.zeros(m.nw)
        u, p = s["u_prev"], s["p"]
        opt = self.options
        steady = opt.steady_state
        if steady:
            Lss, Pss = (ca.DM(a) for a in self.steady_state())

        def H_at(x):
            return m.h_jac(x, u, p)[0][self.meas_index, :]

        def e_at(x):
            return self.residual(s["y"], self.h_meas(x, u, p), mask)

        def full(x, P):
            A, _, _, G = m.f_jac(x, u, p, w0)
            if steady:
                return m.f(x, u, p, w0) + Lss @ e_at(x), S.zeros(n, n)
            PHt = P @ H_at(x).T
            return m.f(x, u, p, w0) + PHt @ Rinv @ e_at(x), A @ P + P @ A.T - PHt @ Rinv @ PHt.T + G @ Qc @ G.T

        def dynamics(x, P):
            A, _, _, G = m.f_jac(x, u, p, w0)
            return m.f(x, u, p, w0), A @ P + P @ A.T + G @ Qc @ G.T

        def measurement_flow(x, P, tau):
            # exact flow of dP/dt = -P H' Rc^-1 H P, dx/dt = P H' Rc^-1 (y - h(x)) over tau (linear h):
            # a Kalman update with covariance Rc / tau (none when tau = 0)
            active = mask * (tau > 0)
            Rd = Rc * ca.if_else(tau > 0, 1 / ca.if_else(tau > 0, tau, 1), 1)
            up = joseph_update(x, P, H_at(x), e_at(x), Rd, active, ca.inf)
            return up["x"], up["P"]

        def split(x, P, h):
            x, P = measurement_flow(x, P, h / 2)
            x, P = rk4(dynamics, (x, P), h)
            return measurement_flow(x, P, h / 2)

        h = s["dt"] / opt.substeps
        x, P = x0, P0
        for _ in range(opt.substeps):
            if steady or opt.integrator == "rk4":
                x, P = rk4(full, (x, P), h)
            elif opt.integrator == "split":
                x, P = split(x, P, h)
            else:
                Hx = H_at(x)
                stiff = h * ca.trace(Hx @ P @ Hx.T @ Rinv) >= _RK4_SAFE
                xr, Pr = rk4(full, (x, P), h)
                xs, Ps = split(x, P, h)
                x, P = ca.if_else(stiff, xs, xr), ca.if_else(stiff, Ps, Pr)
        P = Pss if steady else symmetric(P)
        # diagnostics: innovation of the sample against the estimate at the start of the interval
        H0 = Dm @ m.h_jac(x0, s["u"], p)[0][self.meas_index, :]
        e = self.residual(s["y"], self.h_meas(x0, s["u"], p), mask)
        Sm = masked_innovation_cov(H0 @ P0 @ H0.T, s["R"], mask)
        nis, ll = gaussian_terms(e, Sm, mask)
        K = Lss if steady else P @ H_at(x).T @ Rinv
        return {"x": x, "P": P, "x_pred": x0, "P_pred": P0, "C": S.zeros(n, n), "e": e, "S": Sm, "K": K,
                "nis": nis, "ll": ll, "accepted": S(1)}

    def smooth(self, data, prior, p=None, *, seed=None):
        """Not available: a continuous filter has no one-step predictions to smooth (raises ``ValueError``).

        Parameters
        ----------
        data, prior, p, seed
            As for :meth:`filter`.
        """
        raise InputError("KalmanBucy has no smoother: a continuous filter has no one-step predictions to "
                         "smooth; use KF, EKF, UKF, EnKF or MHE")

    def steady_state(self, x=None, u=None, p=None):
        """Steady-state gain ``L`` and covariance ``P`` from ``control.lqe`` at an operating point.

        Linearises the model at ``(x, u, p)`` (zeros and nominal parameters by default) and hands
        ``A, G, H, Qc = Q dt, Rc = R dt`` to python-control, which solves
        ``A P + P A' - P H' Rc^-1 H P + G Qc G' = 0``.

        Parameters
        ----------
        x, u : array, optional
            Operating point (zeros by default).
        p : array or mapping, optional
            Parameters (nominal by default).

        Returns
        -------
        L : (nx, ny) array
        P : (nx, nx) array
        """
        import control

        m = self.model
        x, u, p = self._operating_point(x, u, p)
        A, _, _, G = (np.array(M) for M in m.f_jac(x, u, p, np.zeros(m.nw)))
        H = np.array(m.h_jac(x, u, p)[0])[self.meas_index, :]
        dt = self.dmodel.dt
        L, P, _ = control.lqe(A, G, H, self.Q * dt, self.R * dt)
        return np.asarray(L), np.asarray(P)
