"""Continuous-time Kalman-Bucy filter (Kalman & Bucy 1961; Tomera 2011, seed 001).

Between two samples the estimate and the covariance follow

    dx/dt = f(x, u, p, 0) + L (y - h(x, u, p)),      L = P H' Rc^-1
    dP/dt = A P + P A' - P H' Rc^-1 H P + G Qc G'

with the latest sample ``y`` held over the interval that it ends (integrated in sub-steps, by
default with a splitting that is stable for any prior, see :class:`KalmanBucy`), ``A, G, H`` the exact
Jacobians (for a linear model the classical Kalman-Bucy filter ``A x + B u + L (y - C x)``),
``Qc`` the power spectral density of ``w`` and ``Rc = R * dt`` the spectral density that
corresponds to the sampled measurement covariance ``R`` averaged over the nominal step ``dt``
(Tomera 2011, Eq. 31-35). The steady-state filter takes ``L`` and ``P`` from ``control.lqe``.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .base import STEP_INPUTS, STEP_OUTPUTS, Estimator

__all__ = ["KalmanBucy"]


class KalmanBucy(Estimator):
    """Kalman-Bucy filter integrated between the samples of a record.

    Parameters are those of every estimator, with ``Q`` the power spectral density of ``w``
    and ``R`` the covariance of a *sampled* measurement (converted to ``Rc = R * dmodel.dt``).

    Options
    -------
    substeps : int
        Sub-steps of the coupled estimate/Riccati equations between two samples.
    integrator : {"split", "rk4"}
        ``"split"`` (default): Strang splitting of each sub-step into half a step of the exact
        measurement flow (``-P H' Rc^-1 H P``, a Kalman update with covariance ``2 Rc / h``), an
        RK4 step of the dynamics ``A P + P A' + G Qc G'`` and another half measurement step:
        second order, stable for any prior however stiff the Riccati equation. ``"rk4"``: classical
        RK4 on the whole equation (fourth order, but unstable when ``P H' Rc^-1 H`` times the
        sub-step exceeds about 2.8, e.g. right after a vague prior).
    steady_state : bool
        Use the constant gain and covariance of :meth:`steady_state` (model must be linear).

    Notes
    -----
    The innovation reported per sample is ``y_k - h(x_{k-1})`` with ``S = H P_{k-1} H' + R``,
    as a diagnostic (NIS, log-likelihood); ``x_pred, P_pred`` hold the estimate at the start of
    the interval. A continuous filter has no one-step prediction to smooth, so
    :func:`rts_smooth` refuses its results, and it has no innovation gate.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.double_integrator()
    >>> kb = cs.KalmanBucy(cs.discretize(m, 0.1), Q=[0.1, 0.2], R=0.01)
    >>> L, P = kb.steady_state()
    """

    name = "KalmanBucy"
    _options = {"substeps": 10, "steady_state": False, "integrator": "split"}

    def _build_step(self) -> ca.Function:
        if self.options["gate"] is not None:
            raise ValueError("KalmanBucy: option 'gate' is not available for a continuous filter")
        n_sub = int(self.options["substeps"])
        if n_sub < 1 or n_sub != self.options["substeps"]:
            raise ValueError(f"option 'substeps' must be an integer >= 1, got {self.options['substeps']!r}")
        if self.options["integrator"] not in ("split", "rk4"):
            raise ValueError(f"option 'integrator' must be 'split' or 'rk4', got {self.options['integrator']!r}")
        m, S = self.model, self.sym
        n = m.nx
        s = self._symbols()
        carry = S.sym("carry", n + n * n)
        x0, P0 = carry[:n], ca.reshape(carry[n:], n, n)
        mask = s["mask"]
        Dm = ca.diag(mask)
        Rc = s["R"] * self.dmodel.dt
        Rinv = Dm @ ca.inv(Dm @ Rc @ Dm + ca.diag(1 - mask)) @ Dm
        w0 = S.zeros(m.nw)
        u, p = s["u_prev"], s["p"]
        steady = bool(self.options["steady_state"])
        if steady:
            Lss, Pss = self.steady_state()
            Lss = ca.DM(Lss)

        def hm(x):
            return self.h_meas(x, u, p)

        def rhs(x, P):
            A, _, _, G = m.f_jac(x, u, p, w0)
            H = m.h_jac(x, u, p)[0][self.meas_index, :]
            e = self.residual(s["y"], hm(x), mask)
            if steady:
                return m.f(x, u, p, w0) + Lss @ e, S.zeros(n, n)
            PHt = P @ H.T
            dP = A @ P + P @ A.T - PHt @ Rinv @ PHt.T + G @ s["Q"] @ G.T
            return m.f(x, u, p, w0) + PHt @ Rinv @ e, dP

        h = s["dt"] / n_sub
        x, P = x0, P0
        split = self.options["integrator"] == "split" and not steady

        def rk4(x, P, rhs):
            k1x, k1P = rhs(x, P)
            k2x, k2P = rhs(x + h / 2 * k1x, P + h / 2 * k1P)
            k3x, k3P = rhs(x + h / 2 * k2x, P + h / 2 * k2P)
            k4x, k4P = rhs(x + h * k3x, P + h * k3P)
            return x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x), P + h / 6 * (k1P + 2 * k2P + 2 * k3P + k4P)

        def dynamics(x, P):
            A, _, _, G = m.f_jac(x, u, p, w0)
            return m.f(x, u, p, w0), A @ P + P @ A.T + G @ s["Q"] @ G.T

        def measurement_flow(x, P, tau):
            # exact flow of dP/dt = -P H' Rc^-1 H P, dx/dt = P H' Rc^-1 (y - H x) over tau (linear h):
            # a Kalman update with covariance Rc / tau, in Joseph form
            H = Dm @ m.h_jac(x, u, p)[0][self.meas_index, :]
            Rd = Rc * ca.if_else(tau > 0, 1 / ca.if_else(tau > 0, tau, 1), 0)
            Sd = self.masked_innovation_cov(H @ P @ H.T, Rd, mask)
            K = ca.if_else(tau > 0, ca.solve(0.5 * (Sd + Sd.T), H @ P).T, S.zeros(n, self.ny))
            IKH = ca.DM.eye(n) - K @ H
            Pn = IKH @ P @ IKH.T + K @ (Dm @ Rd @ Dm) @ K.T
            return x + K @ self.residual(s["y"], hm(x), mask), 0.5 * (Pn + Pn.T)

        for _ in range(n_sub):
            if split:     # Strang splitting: half measurement flow, dynamics by RK4, half measurement flow
                x, P = measurement_flow(x, P, h / 2)
                x, P = rk4(x, P, dynamics)
                x, P = measurement_flow(x, P, h / 2)
            else:
                x, P = rk4(x, P, rhs)
        P = ca.DM(Pss) if steady else 0.5 * (P + P.T)
        # diagnostics: innovation of the sample against the estimate at the start of the interval
        H0 = ca.diag(mask) @ m.h_jac(x0, s["u"], p)[0][self.meas_index, :]
        e = self.residual(s["y"], self.h_meas(x0, s["u"], p), mask)
        Sm = self.masked_innovation_cov(H0 @ P0 @ H0.T, s["R"], mask)
        Sm = 0.5 * (Sm + Sm.T)
        nis, ll = self.gaussian_terms(e, Sm, mask)
        vec = lambda a: ca.reshape(a, -1, 1)  # noqa: E731
        outs = [ca.vertcat(x, vec(P)), x, vec(P), x0, vec(P0), S.zeros(n * n), e, vec(Sm), nis, ll, S(1)]
        ins = [carry] + [s[k] for k in STEP_INPUTS[1:]]
        return ca.Function("kalman_bucy_step", ins, outs, STEP_INPUTS, STEP_OUTPUTS)

    def steady_state(self, x=None, u=None, p=None):
        """Steady-state gain ``L`` and covariance ``P`` from ``control.lqe`` at an operating point.

        Linearises the model at ``(x, u, p)`` (zeros and nominal parameters by default) and solves
        the filter Riccati equation ``A P + P A' - P H' Rc^-1 H P + G Qc G' = 0``.

        Returns
        -------
        L : (nx, ny) array
        P : (nx, nx) array
        """
        import control

        m = self.model
        x = m.states() if x is None else np.asarray(x, dtype=float)
        u = m.inputs() if u is None else np.asarray(u, dtype=float)
        p = m.params() if p is None else m.params(p)
        A, _, _, G = (np.array(M) for M in m.f_jac(x, u, p, np.zeros(m.nw)))
        H = np.array(m.h_jac(x, u, p)[0])[self.meas_index, :]
        L, P, _ = control.lqe(A, G, H, self.Q, self.R * self.dmodel.dt)
        return np.asarray(L), np.asarray(P)
