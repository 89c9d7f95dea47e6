"""Ensemble Kalman filter with perturbed observations (Evensen 1994; Burgers et al. 1998; seed 002).

The random draws are generated in numpy before the run (from the ``seed``) and enter the
compiled step as per-step inputs, so a seeded run is reproducible and the batch fold and the
online stepper give identical numbers for the same draws.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .._fast import BufferedCall
from ..data import Gaussian
from .base import STEP_INPUTS, STEP_OUTPUTS, Estimator
from .ukf import circular_mean, deviations, psd_sqrt, weighted_outer

__all__ = ["EnKF"]


class EnKF(Estimator):
    """Ensemble Kalman filter with ``N`` members and perturbed observations.

    Each member is propagated through the discretised model with its own process-noise draw
    ``w ~ N(0, Q)`` held over the step; the update uses the ensemble cross-covariances and the
    observation perturbed by ``v ~ N(0, R)``. Means of angle states and outputs are taken on the
    circle, residuals wrapped. The reported ``x, P`` are the ensemble mean and sample covariance;
    ``C`` is the sample cross-covariance of consecutive ensembles (so :func:`rts_smooth` applies).

    Options
    -------
    members : int
        Ensemble size ``N`` (seed 002: 100).
    gate : float or None
        Chi-square innovation gate on the ensemble-mean innovation.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.sog_cog()
    >>> enkf = cs.EnKF(cs.discretize(m, 0.1), Q=[1e-3, 1e-4], R=1.0, options={"members": 50})
    """

    name = "EnKF"
    _options = {"members": 100}

    @property
    def members(self) -> int:
        return int(self.options["members"])

    def _build_step(self) -> ca.Function:
        N = int(self.options["members"])
        if N < 2 or N != self.options["members"]:
            raise ValueError(f"option 'members' must be an integer >= 2, got {self.options['members']!r}")
        m, S, dm = self.model, self.sym, self.dmodel
        n, ny = m.nx, self.ny
        s = self._symbols()
        carry = S.sym("carry", n * N)
        zw, zv = S.sym("z_w", m.nw * N), S.sym("z_v", ny * N)
        X = ca.reshape(carry, n, N)
        W = psd_sqrt(s["Q"]) @ ca.reshape(zw, m.nw, N)
        V = psd_sqrt(s["R"]) @ ca.reshape(zv, ny, N)
        wts = np.full(N, 1.0 / N)
        scale = 1.0 / np.sqrt(N - 1)
        ang = m.angle_states
        # forecast
        Xf = ca.horzcat(*[dm.F(X[:, j], s["u_prev"], s["p"], W[:, j], s["dt"]) for j in range(N)])
        x0 = circular_mean(X, wts, ang)
        xp = circular_mean(Xf, wts, ang)
        dX0 = scale * deviations(X, x0, ang)
        dXf = scale * deviations(Xf, xp, ang)
        Pp = weighted_outer(dXf)
        C = dX0 @ dXf.T
        # analysis with perturbed observations
        mask = s["mask"]
        Yf = ca.horzcat(*[self.h_meas(Xf[:, j], s["u"], s["p"]) for j in range(N)])
        yhat = circular_mean(Yf, wts, self.angle_meas)
        dY = ca.diag(mask) @ (scale * deviations(Yf, yhat, self.angle_meas))
        Sm = self.masked_innovation_cov(weighted_outer(dY), s["R"], mask)
        Sm = 0.5 * (Sm + Sm.T)
        K = ca.solve(Sm, (dXf @ dY.T).T).T
        e = self.residual(s["y"], yhat, mask)
        nis, ll = self.gaussian_terms(e, Sm, mask)
        acc = nis <= s["gate"]
        Xa = ca.horzcat(*[Xf[:, j] + acc * K @ self.residual(s["y"] + V[:, j], Yf[:, j], mask) for j in range(N)])
        xa = circular_mean(Xa, wts, ang)
        dXa = scale * deviations(Xa, xa, ang)
        Pa = weighted_outer(dXa)
        vec = lambda a: ca.reshape(a, -1, 1)  # noqa: E731
        outs = [vec(Xa), xa, vec(Pa), xp, vec(Pp), vec(C), e, vec(Sm), nis, ll, acc]
        ins = [carry] + [s[k] for k in STEP_INPUTS[1:]] + [zw, zv]
        return ca.Function("enkf_step", ins, outs, STEP_INPUTS + ["z_w", "z_v"], STEP_OUTPUTS)

    # -- ensemble memory and random draws ----------------------------------------------------------
    def ensemble(self, prior: Gaussian, seed=None) -> np.ndarray:
        """Initial ensemble (nx, N) drawn from ``prior``."""
        self._check_prior(prior)
        return prior.sample(self.members, np.random.default_rng(seed)).T.copy()

    def carry_from(self, prior: Gaussian, seed=None) -> np.ndarray:
        return self.ensemble(prior, seed).reshape(-1, order="F")

    def _draw_size(self) -> tuple[int, int]:
        return self.model.nw * self.members, self.ny * self.members

    def extra_inputs(self, n: int, seed) -> list[np.ndarray]:
        """Standard-normal process and observation draws for ``n`` steps (one row per step, in the
        order the online :meth:`step` draws them)."""
        nw, nv = self._draw_size()
        z = np.random.default_rng(seed).standard_normal((n, nw + nv))
        return [z[:, :nw].T.copy(), z[:, nw:].T.copy()]

    def filter(self, data, prior: Gaussian, p=None, *, seed=None):
        """Run the EnKF over a record (see :meth:`Estimator.filter`); ``seed`` fixes every draw."""
        return super().filter(data, prior, p, seed=seed)

    # -- online -----------------------------------------------------------------------------------
    def step(self, ensemble, u_prev, y, dt, *, u=None, p=None, rng=None):
        """One online step on an ensemble (nx, N).

        ``rng`` (a ``numpy.random.Generator``, required) supplies the draws in the same order as
        :meth:`filter`, so stepping with ``rng = default_rng(seed)`` after
        ``ensemble(prior, rng)`` reproduces ``filter(..., seed=seed)``. Returns
        ``(ensemble_next, info)`` with ``info = {"x", "P", "e", "nis", "ll", "rejected", "x_pred", "P_pred"}``.
        """
        if not isinstance(rng, np.random.Generator):
            raise TypeError("EnKF.step needs rng=numpy.random.Generator for its random draws")
        m = self.model
        if self._online is None:
            self._online = BufferedCall(self._eval_step)
            a = self._online.args
            a[6][:] = m.params()
            a[7][:] = self.Q.reshape(-1, order="F")
            a[8][:] = self.R.reshape(-1, order="F")
        call = self._online
        a = call.args
        ens = np.asarray(ensemble, dtype=float)
        if ens.shape != (m.nx, self.members):
            raise ValueError(f"ensemble must have shape ({m.nx}, {self.members}), got {ens.shape}")
        a[0][:] = ens.reshape(-1, order="F")
        a[1][:] = u_prev
        a[2][:] = u_prev if u is None else u
        y = np.asarray(y, dtype=float)
        ok = np.isfinite(y)
        a[3][:] = np.where(ok, y, 0.0)
        a[4][:] = ok
        a[5][0] = dt
        if p is not None:
            a[6][:] = m.params(p)
        a[9][0] = self._gate_threshold(int(ok.sum()))
        nw, nv = self._draw_size()
        z = rng.standard_normal(nw + nv)
        a[10][:], a[11][:] = z[:nw], z[nw:]
        r = call()
        nx = m.nx
        info = {"x": r[1].copy(), "P": r[2].reshape(nx, nx, order="F").copy(),
                "e": np.where(ok, r[6], np.nan), "nis": float(r[8][0]), "ll": float(r[9][0]),
                "rejected": bool(r[10][0] < 0.5), "x_pred": r[3].copy(),
                "P_pred": r[4].reshape(nx, nx, order="F").copy()}
        return r[0].reshape(nx, self.members, order="F").copy(), info
