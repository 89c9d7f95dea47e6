"""Ensemble Kalman filter with perturbed observations (Evensen 1994; Burgers et al. 1998; seed 002).

The random draws are generated in numpy (from the ``seed``) and enter the compiled step as the
per-step inputs ``z_w`` (nw x N) and ``z_v`` (ny x N), so a seeded run is reproducible and the
batch fold and the online runner give identical numbers for the same draws.

The members go through one member step ``map``-ped over the ensemble (model step, outputs and
analysis), and the ensemble statistics are matrix products, so the size of the step Function and
its compile time do not grow with the number of members.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..gaussian import Gaussian
from .base import Estimator
from .options import EstimatorOptions, check_int
from .ukf import psd_sqrt, wrap_fast
from .update import gain_and_terms, masked_innovation_cov, residual, symmetric

__all__ = ["EnKF", "EnKFOptions"]


@dataclass(frozen=True)
class EnKFOptions(EstimatorOptions):
    """Options of :class:`EnKF` (and those of every estimator, see :class:`EstimatorOptions`).

    Parameters
    ----------
    gate, jit, outputs, max_gap, on_gap
        The options of every estimator (see :class:`~casship.estimators.EstimatorOptions`).
    members : int
        Ensemble size ``N`` (seed 002: 100).
    """

    members: int = 100

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "members", check_int(self.members, "members", 2))


def _wrap_rows(D, angles):
    """``D`` with its angle rows wrapped to [-pi, pi).

    Only the angle rows are computed on (a few of the rows: the wrap is the costliest elementwise
    chain of the step), and the correction is scattered back by a constant 0/1 matrix.
    """
    rows = np.flatnonzero(np.asarray(angles, dtype=bool))
    if not rows.size:
        return D
    A = D[rows.tolist(), :]
    scatter = ca.DM.zeros(D.shape[0], rows.size)           # sparse: one entry per angle row
    for j, i in enumerate(rows):
        scatter[int(i), j] = 1.0
    scatter = ca.sparsify(scatter)
    return D - scatter @ (2 * np.pi * ca.floor((A + np.pi) / (2 * np.pi)))


def _mean(X, angles):
    """Ensemble mean of the columns of ``X``; angle rows averaged on the circle around the first member."""
    N = X.shape[1]
    if not np.any(angles):
        return ca.sum2(X) / N
    ref = X[:, 0]
    return ref + ca.sum2(_wrap_rows(X - ca.repmat(ref, 1, N), angles)) / N


def _deviations(X, mean, angles):
    """Columns of ``X`` minus ``mean``, angle rows wrapped to [-pi, pi)."""
    return _wrap_rows(X - ca.repmat(mean, 1, X.shape[1]), angles)


def _member(name, inputs: dict, outputs: dict) -> tuple[ca.Function, list]:
    """A member Function of the non-empty ``inputs`` (name -> SX) and the names it takes (empty
    inputs, e.g. a model without inputs, are left out: a mapped empty input makes CasADi's C invalid)."""
    used = [k for k, v in inputs.items() if v.numel()]
    return ca.Function(name, [inputs[k] for k in used], list(outputs.values()), used, list(outputs)), used


class EnKF(Estimator):
    """Ensemble Kalman filter with ``N`` members and perturbed observations.

    Each member is propagated through the discretised model with its own process-noise draw
    ``w ~ N(0, Q)`` held over the step; the update uses the ensemble cross-covariances and the
    observation perturbed by ``v ~ N(0, R)``. Means of angle states and outputs are taken on the
    circle, residuals wrapped. The memory is the ensemble ``X`` (nx x N); the reported ``x, P`` are
    the ensemble mean and sample covariance, ``C`` the sample cross-covariance of consecutive
    ensembles (so smoothing applies).

    Parameters
    ----------
    dmodel : DiscreteModel
    Q, R : process and measurement noise covariances (the one meaning, ``docs/architecture.md``)
    measured : sequence of str, optional
    options : EnKFOptions or mapping
        ``gate`` (on the ensemble-mean innovation), ``jit``, ``outputs``, ``members``.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.sog_cog()
    >>> enkf = cs.EnKF(cs.discretize(m, 0.1), Q=[1e-3, 1e-4], R=1.0, options={"members": 50})
    >>> enkf.memory
    ('X',)
    """

    name = "EnKF"
    Options = EnKFOptions
    stochastic = True

    @property
    def members(self) -> int:
        """Ensemble size."""
        return self.options.members

    def _symbolic(self):
        return ca.MX

    def _memory_shapes(self) -> dict:
        return {"X": (self.model.nx, self.members)}

    def _draw_shapes(self) -> dict:
        return {"z_w": (self.model.nw, self.members), "z_v": (self.ny, self.members)}

    def memory_from(self, prior: Gaussian, rng=None) -> dict:
        return {"X": self.ensemble(prior, rng)}

    def ensemble(self, prior: Gaussian, seed=None) -> np.ndarray:
        """Initial ensemble (nx, N) drawn from ``prior``.

        Parameters
        ----------
        prior : Gaussian
        seed : int or numpy.random.Generator, optional
        """
        self._check_prior(prior)
        return prior.sample(self.members, np.random.default_rng(seed)).T.copy()

    def _member_functions(self):
        """The per-member Functions (SX) with the names of their inputs, to be mapped over the ensemble."""
        m, dm = self.model, self.dmodel
        S = dm.symbolic
        x, u, p, w, dt = S.sym("x", m.nx), S.sym("u", m.nu), S.sym("p", m.np), S.sym("w", m.nw), S.sym("dt")
        forecast = _member("enkf_member_forecast", {"x": x, "u": u, "p": p, "w": w, "dt": dt},
                           {"xf": dm.F(x, u, p, w, dt)})
        output = _member("enkf_member_output", {"x": x, "u": u, "p": p}, {"y": self.h_meas(x, u, p)})
        yf, v, y, mask = S.sym("yf", self.ny), S.sym("v", self.ny), S.sym("y", self.ny), S.sym("mask", self.ny)
        K = S.sym("K", m.nx, self.ny)
        analysis = _member("enkf_member_analysis", {"xf": x, "yf": yf, "v": v, "y": y, "mask": mask, "K": K},
                           {"xa": x + K @ residual(y + v, yf, mask, self.angle_meas, wrap_fast)})
        return forecast, output, analysis

    def _build(self, s: dict) -> dict:
        m, N = self.model, self.members
        (forecast, f_in), (output, o_in), (analysis, a_in) = self._member_functions()
        ang, angy = m.angle_states, self.angle_meas
        scale = 1.0 / np.sqrt(N - 1)
        X, mask = s["X"], s["mask"]
        # one factor per step for all members (an SX Function of the small Q and R)
        Qs, Rs = ca.SX.sym("Q", m.nw, m.nw), ca.SX.sym("R", self.ny, self.ny)
        LQ, LR = ca.Function("enkf_noise_roots", [Qs, Rs], [psd_sqrt(Qs), psd_sqrt(Rs)])(s["Q"], s["R"])

        def mapped(fun, names, args):
            return fun.map(N)(*[args[k] for k in names])

        # forecast: every member through the model with its own held noise
        Xf = mapped(forecast, f_in, {"x": X, "u": s["u_prev"], "p": s["p"], "w": LQ @ s["z_w"], "dt": s["dt"]})
        x0, xp = _mean(X, ang), _mean(Xf, ang)
        dX0, dXf = scale * _deviations(X, x0, ang), scale * _deviations(Xf, xp, ang)
        # analysis with perturbed observations
        Yf = mapped(output, o_in, {"x": Xf, "u": s["u"], "p": s["p"]})
        yhat = _mean(Yf, angy)
        dY = ca.diag(mask) @ (scale * _deviations(Yf, yhat, angy))
        Sm = masked_innovation_cov(dY @ dY.T, s["R"], mask)
        e = residual(s["y"], yhat, mask, angy)
        K, nis, ll, acc = self._gain_function()(Sm, dXf @ dY.T, e, mask, s["gate"])
        Xa = mapped(analysis, a_in, {"xf": Xf, "yf": Yf, "v": LR @ s["z_v"], "y": s["y"], "mask": mask, "K": K})
        xa = _mean(Xa, ang)
        dXa = scale * _deviations(Xa, xa, ang)
        return {"X": Xa, "x": xa, "P": symmetric(dXa @ dXa.T), "x_pred": xp, "P_pred": symmetric(dXf @ dXf.T),
                "C": dX0 @ dXf.T, "e": e, "S": Sm, "K": K, "nis": nis, "ll": ll, "accepted": acc}

    def _gain_function(self) -> ca.Function:
        """Gain (zero when gated out), NIS, log-likelihood and acceptance from ``S`` and ``Pxy`` (SX)."""
        nx, ny = self.model.nx, self.ny
        S, Pxy, e = ca.SX.sym("S", ny, ny), ca.SX.sym("Pxy", nx, ny), ca.SX.sym("e", ny)
        mask, gate = ca.SX.sym("mask", ny), ca.SX.sym("gate")
        K, nis, ll = gain_and_terms(S, Pxy.T, e, mask)
        acc = nis <= gate
        return ca.Function("enkf_gain", [S, Pxy, e, mask, gate], [acc * K, nis, ll, acc],
                           ["S", "Pxy", "e", "mask", "gate"], ["K", "nis", "ll", "accepted"])
