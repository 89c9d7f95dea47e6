"""Extended Kalman filter, discrete and continuous-discrete, from the exact model Jacobians."""
from __future__ import annotations

import casadi as ca
import numpy as np

from .base import STEP_INPUTS, STEP_OUTPUTS, Estimator

__all__ = ["EKF", "KF"]


class EKF(Estimator):
    """Extended Kalman filter with exact Jacobians, Joseph-form update and angle-aware residuals.

    Options
    -------
    gate : float or None
        Chi-square innovation gate probability (e.g. 0.999); rejected updates are reported.
    covariance : {"discrete", "continuous"}
        ``"discrete"`` propagates ``P`` with the Jacobians of the discretised step and treats
        ``Q`` as the covariance of ``w`` held over a step. ``"continuous"`` (continuous-discrete
        EKF) integrates ``P' = A P + P A' + G Q G'`` with ``Q`` the power spectral density of
        continuous white noise, by RK4 with ``substeps`` sub-steps between samples.
    substeps : int
        Sub-steps of the continuous-discrete prediction.
    reacquire : int or None
        With a gate: after this many consecutive rejected samples the next measurement is used
        regardless of the gate, with the predicted covariance inflated by ``max(1, NIS / m)`` (``m``
        scalar measurements) so that the innovation becomes consistent. This lets a gated filter
        that trusted a faulty sensor (e.g. a frozen fix) find the ship again instead of rejecting
        every correct fix that follows. Reported as accepted samples; off by default.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order()
    >>> ekf = cs.EKF(cs.discretize(m, 0.1), Q=1e-8, R=1e-4)
    """

    name = "EKF"
    _options = {"covariance": "discrete", "substeps": 1, "reacquire": None}

    def _build_step(self) -> ca.Function:
        if self.options["covariance"] not in ("discrete", "continuous"):
            raise ValueError(f"option 'covariance' must be 'discrete' or 'continuous', "
                             f"got {self.options['covariance']!r}")
        reacquire = self.options["reacquire"]
        if reacquire is not None and (int(reacquire) != reacquire or reacquire < 1):
            raise ValueError(f"option 'reacquire' is a positive number of samples, got {reacquire!r}")
        if reacquire is not None and self.options["gate"] is None:
            raise ValueError("option 'reacquire' needs a 'gate'")
        m, S = self.model, self.sym
        s = self._symbols()
        n_carry = m.nx + m.nx * m.nx + (reacquire is not None)
        carry = S.sym("carry", n_carry)
        x, P = carry[: m.nx], ca.reshape(carry[m.nx:m.nx + m.nx * m.nx], m.nx, m.nx)
        if self.options["covariance"] == "discrete":
            xp, Pp, C = self._predict_discrete(x, P, s)
        else:
            xp, Pp, C = self._predict_continuous(x, P, s)
        xu, Pu, e, Sm, nis, ll, acc = self._update(xp, Pp, s)
        vec = lambda a: ca.reshape(a, -1, 1)  # noqa: E731
        carry_next = ca.vertcat(xu, vec(Pu))
        if reacquire is not None:
            # Count consecutive rejected samples (rows without measurements leave the count alone);
            # once the count reaches `reacquire`, redo the update ungated on an inflated covariance.
            count = carry[-1]
            force = (count >= reacquire) * (1 - acc) * (ca.sum1(s["mask"]) > 0)
            inflation = ca.fmax(1, nis / ca.fmax(1, ca.sum1(s["mask"])))
            xf, Pf, _, _, _, _, _ = self._update(xp, inflation * Pp, {**s, "gate": ca.inf})
            xu = ca.if_else(force, xf, xu)
            Pu = ca.if_else(force, Pf, Pu)
            acc = ca.fmax(acc, force)
            new_count = ca.if_else(acc, 0, ca.if_else(ca.sum1(s["mask"]) > 0, count + 1, count))
            carry_next = ca.vertcat(xu, vec(Pu), new_count)
        outs = [carry_next, xu, vec(Pu), xp, vec(Pp), vec(C), e, vec(Sm), nis, ll, acc]
        ins = [carry] + [s[k] for k in STEP_INPUTS[1:]]
        return ca.Function(f"{self.name.lower()}_step", ins, outs, STEP_INPUTS, STEP_OUTPUTS)

    def carry_from(self, prior, seed=None):
        carry = super().carry_from(prior, seed)
        return carry if self.options["reacquire"] is None else np.concatenate([carry, [0.0]])

    def _predict_discrete(self, x, P, s):
        dm, m = self.dmodel, self.model
        w0 = self.sym.zeros(m.nw)
        xp = dm.F(x, s["u_prev"], s["p"], w0, s["dt"])
        A, _, _, G = dm.F_jac(x, s["u_prev"], s["p"], w0, s["dt"])
        Pp = A @ P @ A.T + G @ s["Q"] @ G.T
        return xp, 0.5 * (Pp + Pp.T), P @ A.T

    def _predict_continuous(self, x, P, s):
        m = self.model
        n_sub = int(self.options["substeps"])
        if n_sub < 1:
            raise ValueError(f"option 'substeps' must be >= 1, got {n_sub}")
        w0 = self.sym.zeros(m.nw)
        u, p, Qc = s["u_prev"], s["p"], s["Q"]

        def rhs(xi, Pi):
            A, _, _, G = m.f_jac(xi, u, p, w0)
            return m.f(xi, u, p, w0), A @ Pi + Pi @ A.T + G @ Qc @ G.T

        h = s["dt"] / n_sub
        xi, Pi = x, P
        for _ in range(n_sub):
            k1x, k1P = rhs(xi, Pi)
            k2x, k2P = rhs(xi + h / 2 * k1x, Pi + h / 2 * k1P)
            k3x, k3P = rhs(xi + h / 2 * k2x, Pi + h / 2 * k2P)
            k4x, k4P = rhs(xi + h * k3x, Pi + h * k3P)
            xi = xi + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
            Pi = Pi + h / 6 * (k1P + 2 * k2P + 2 * k3P + k4P)
        Phi = ca.jacobian(xi, x)
        return xi, 0.5 * (Pi + Pi.T), P @ Phi.T

    def _update(self, xp, Pp, s):
        m = self.model
        mask = s["mask"]
        yhat = self.h_meas(xp, s["u"], s["p"])
        H = ca.diag(mask) @ self.model.h_jac(xp, s["u"], s["p"])[0][self.meas_index, :]
        e = self.residual(s["y"], yhat, mask)
        Sm = self.masked_innovation_cov(H @ Pp @ H.T, s["R"], mask)
        Sm = 0.5 * (Sm + Sm.T)
        K = ca.solve(Sm, H @ Pp).T
        nis, ll = self.gaussian_terms(e, Sm, mask)
        acc = nis <= s["gate"]
        Rm = ca.diag(mask) @ s["R"] @ ca.diag(mask)
        IKH = ca.DM.eye(m.nx) - acc * K @ H
        Pu = IKH @ Pp @ IKH.T + acc * K @ Rm @ K.T
        xu = xp + acc * K @ e
        return xu, 0.5 * (Pu + Pu.T), e, Sm, nis, ll, acc


class KF(EKF):
    """Linear Kalman filter: the EKF on a model whose dynamics and outputs are linear.

    Raises ``ValueError`` if the discretised model is not linear in its states, inputs and noise
    (its Jacobians would depend on them), so a nonlinear model is never filtered as if linear.
    For a linear model the KF and the EKF give identical numbers.
    """

    name = "KF"

    def _build_step(self) -> ca.Function:
        m, dm = self.model, self.dmodel
        Ssym = dm.symbolic
        x, u, p, w, dt = (Ssym.sym("x", m.nx), Ssym.sym("u", m.nu), Ssym.sym("p", m.np),
                          Ssym.sym("w", m.nw), Ssym.sym("dt"))
        xf = dm.F(x, u, p, w, dt)
        y = m.h(x, u, p)
        z = ca.vertcat(x, u, w)
        for what, expr in (("dynamics", xf), ("outputs", y)):
            if ca.depends_on(ca.jacobian(expr, z), z):
                raise ValueError(f"KF: the {what} of model {m.name!r} are not linear in states, inputs and "
                                 "noise; use EKF, UKF or EnKF")
        return super()._build_step()


def persistence_model(names, name: str = "persistence"):
    """A random-walk (persistence, ``A = I``) model measuring each named state directly.

    The baseline of seed 002: ``x[k+1] = x[k] + w``; use it with :class:`KF`.
    """
    from ..model import ModelBuilder

    b = ModelBuilder(name, "persistence (random-walk) model, A = I")
    for n in names:
        angle = n in ("psi", "chi", "heading")
        b.state(n, angle=angle)
    for n in names:
        b.ode(**{n: b.noise(f"w_{n}")})
        b.output(n, b.sym(n))
    return b.build()
