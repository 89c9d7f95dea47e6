"""Extended Kalman filter, discrete and continuous-discrete, from the exact model Jacobians."""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..builder import ModelBuilder
from ..discretize import rk4
from .base import StepEstimator
from .options import EstimatorOptions, check_int, check_number
from .update import joseph_update, sandwich, symmetric
from ..errors import InputError

__all__ = ["EKF", "KF", "EKFOptions", "persistence_model"]


@dataclass(frozen=True)
class EKFOptions(EstimatorOptions):
    """Options of :class:`EKF` and :class:`KF` (and those of every estimator, see :class:`EstimatorOptions`).

    Parameters
    ----------
    gate, jit, outputs, max_gap, on_gap
        The options of every estimator (see :class:`~casship.estimators.EstimatorOptions`).
    covariance : {"discrete", "continuous"}
        ``"discrete"`` propagates ``P`` with the Jacobians of the discretised step
        (``A P A' + G Q G'``). ``"continuous"`` (continuous-discrete EKF) integrates
        ``P' = A P + P A' + G Qc G'`` between samples with the spectral density ``Qc = Q dt``
        (``dt`` = ``dmodel.dt``, the one meaning of ``Q``), by RK4 with ``substeps`` sub-steps.
    substeps : int
        Sub-steps of the continuous-discrete prediction.
    reacquire : int or None
        With a gate: after this many consecutive rejected samples the next measurement is used
        regardless of the gate, with the predicted covariance inflated by ``max(1, NIS / m)`` (``m``
        scalar measurements) so that the innovation becomes consistent. Rows that measure nothing
        neither count nor reset the count. A gated filter that
        trusted a faulty sensor (a frozen fix) then finds the ship again instead of rejecting every
        correct fix that follows. Adds the memory slot ``rejections``.
    """

    covariance: str = "discrete"
    substeps: int = 1
    reacquire: int | None = None

    def __post_init__(self):
        super().__post_init__()
        if self.covariance not in ("discrete", "continuous"):
            raise InputError(f"option 'covariance' must be 'discrete' or 'continuous', got {self.covariance!r}")
        object.__setattr__(self, "substeps", check_int(self.substeps, "substeps", 1))
        if self.reacquire is not None:
            if isinstance(self.reacquire, bool) or not check_number(self.reacquire, "reacquire").is_integer() \
                    or self.reacquire < 1:
                raise InputError(f"option 'reacquire' is a positive number of samples, got {self.reacquire!r}")
            if self.gate is None:
                raise InputError("option 'reacquire' needs a 'gate'")
            object.__setattr__(self, "reacquire", int(self.reacquire))


class EKF(StepEstimator):
    """Extended Kalman filter with exact Jacobians, Joseph-form update and angle-aware residuals.

    Parameters
    ----------
    dmodel : DiscreteModel
    Q, R : process and measurement noise covariances (the one meaning, ``docs/architecture.md``)
    measured : sequence of str, optional
    options : EKFOptions or mapping
        ``gate``, ``jit``, ``outputs``, ``covariance``, ``substeps``, ``reacquire``.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order()
    >>> ekf = cs.EKF(cs.discretize(m, 0.1), Q=1e-8, R=1e-4)
    >>> ekf.memory
    ('x', 'P')
    """

    name = "EKF"
    Options = EKFOptions

    def _check_options(self) -> None:
        if self.options.covariance == "continuous":
            self.dmodel.require_continuous(f"{self.name} option covariance='continuous'")

    def _memory_shapes(self) -> dict:
        shapes = super()._memory_shapes()
        if self.options.reacquire is not None:
            shapes["rejections"] = (1, 1)
        return shapes

    def memory_from(self, prior, rng=None) -> dict:
        mem = super().memory_from(prior, rng)
        if self.options.reacquire is not None:
            mem["rejections"] = np.zeros(1)
        return mem

    def _build(self, s: dict) -> dict:
        x, P = s["x"], s["P"]
        if self.options.covariance == "discrete":
            xp, Pp, C = self._predict_discrete(x, P, s)
        else:
            xp, Pp, C = self._predict_continuous(x, P, s)
        up = self._update(xp, Pp, s)
        out = {**up, "x_pred": xp, "P_pred": Pp, "C": C}
        reacquire = self.options.reacquire
        if reacquire is not None:
            # Count consecutive rejected samples (rows without measurements leave the count alone);
            # once the count reaches `reacquire`, redo the update ungated on an inflated covariance.
            count, measured = s["rejections"], ca.sum1(s["mask"])
            force = (count >= reacquire) * (1 - up["accepted"]) * (measured > 0)
            inflation = ca.fmax(1, up["nis"] / ca.fmax(1, measured))
            forced = self._update(xp, inflation * Pp, {**s, "gate": ca.inf})
            for k in ("x", "P", "K"):
                out[k] = ca.if_else(force, forced[k], up[k])
            out["accepted"] = ca.fmax(up["accepted"], force)
            # (a row measuring nothing passes the gate trivially: it must not reset the count)
            out["rejections"] = ca.if_else(measured > 0, ca.if_else(out["accepted"], 0, count + 1), count)
        return out

    def _predict_discrete(self, x, P, s):
        w0 = self.sym.zeros(self.model.nw)
        xp = self.dmodel.F(x, s["u_prev"], s["p"], w0, s["dt"])
        A, _, _, G = self.dmodel.F_jac(x, s["u_prev"], s["p"], w0, s["dt"])
        C = P @ A.T
        return xp, sandwich(A, P, C.T) + sandwich(G, s["Q"]), C

    def _predict_continuous(self, x, P, s):
        m = self.model
        w0 = self.sym.zeros(m.nw)
        u, p, Qc = s["u_prev"], s["p"], s["Q"] * self.dmodel.dt

        def rhs(xi, Pi):
            A, _, _, G = m.f_jac(xi, u, p, w0)
            return m.f(xi, u, p, w0), A @ Pi + Pi @ A.T + G @ Qc @ G.T

        h = s["dt"] / self.options.substeps
        xi, Pi = x, P
        for _ in range(self.options.substeps):
            xi, Pi = rk4(rhs, (xi, Pi), h)
        return xi, symmetric(Pi), P @ ca.jacobian(xi, x).T

    def steady_state(self, x=None, u=None, p=None):
        """Steady-state gain and covariance of the linearised filter, from ``control.dlqe``.

        The exact Jacobians of the discretised step at ``(x, u, p)`` (zeros and nominal parameters
        by default; for a linear model the operating point does not matter) are handed to
        python-control, which solves the discrete Riccati equation.

        Parameters
        ----------
        x, u : array, optional
            Operating point (zeros by default).
        p : array or mapping, optional
            Parameters (nominal by default).

        Returns
        -------
        L : (nx, ny) array
            Predictor gain (``x-_{k+1} = A x-_k + B u_k + L (y_k - H x-_k)``); the filter gain of the
            update is ``K = P H' (H P H' + R)^-1`` and ``L = A K``.
        P : (nx, nx) array
            Steady-state predicted covariance.
        """
        import control

        if self.options.covariance != "discrete":
            raise InputError("steady_state: a continuous-discrete EKF has no constant discrete gain; "
                             "use covariance='discrete' or KalmanBucy.steady_state")
        m = self.model
        x, u, p = self._operating_point(x, u, p)
        A, _, G = self.dmodel.linearize(x, u, p)
        H = np.array(m.h_jac(x, u, p)[0])[self.meas_index]
        L, P, _ = control.dlqe(A, G, H, self.Q, self.R)
        return np.asarray(L), np.asarray(P)

    def _update(self, xp, Pp, s):
        H = self.model.h_jac(xp, s["u"], s["p"])[0][self.meas_index, :]
        e = self.residual(s["y"], self.h_meas(xp, s["u"], s["p"]), s["mask"])
        return {**joseph_update(xp, Pp, H, e, s["R"], s["mask"], s["gate"]), "e": e}


class KF(EKF):
    """Linear Kalman filter: the EKF on a model whose dynamics and outputs are linear.

    Raises ``ValueError`` if the discretised model is not linear in its states, inputs and noise
    (its Jacobians would depend on them), so a nonlinear model is never filtered as if linear.
    For a linear model the KF and the EKF give identical numbers.

    Examples
    --------
    >>> import casship as cs
    >>> kf = cs.KF(cs.discretize(cs.models.double_integrator(), 0.1), Q=[0.1, 0.2], R=0.01)
    >>> L, P = kf.steady_state()
    """

    name = "KF"
    linear = True            # needs a model linear in states, inputs and noise

    def _check_options(self) -> None:
        super()._check_options()
        m, dm = self.model, self.dmodel
        S = dm.symbolic
        x, u, p, w, dt = (S.sym("x", m.nx), S.sym("u", m.nu), S.sym("p", m.np), S.sym("w", m.nw), S.sym("dt"))
        z = ca.vertcat(x, u, w)
        for what, expr in (("dynamics", dm.F(x, u, p, w, dt)), ("outputs", m.h(x, u, p))):
            if ca.depends_on(ca.jacobian(expr, z), z):
                raise InputError(f"KF: the {what} of model {m.name!r} are not linear in states, inputs and "
                                 "noise; use EKF, UKF or EnKF")

def persistence_model(names, name: str = "persistence"):
    """A random-walk (persistence, ``A = I``) model measuring each named state directly.

    The baseline of Koike et al. (2023): ``x[k+1] = x[k] + w``; use it with :class:`KF`.

    Parameters
    ----------
    names : sequence of str
        The states (``psi``, ``chi`` and ``heading`` are angles).
    name : str
        Model name.
    """
    b = ModelBuilder(name, "persistence (random-walk) model, A = I")
    for n in names:
        angle = n in ("psi", "chi", "heading")
        b.state(n, angle=angle)
    for n in names:
        b.ode(**{n: b.noise(f"w_{n}")})
        b.output(n, b.sym(n))
    return b.build()
