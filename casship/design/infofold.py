"""A trial's information as one compiled fold: states, their exact sensitivities and ``J' W J`` step by step.

The information a trial carries about the uncertain parameters ``theta`` is the Gauss-Newton matrix
of the output-error likelihood at the current estimate. Rather than building the whole residual
Jacobian ``J`` (samples x channels x parameters) and multiplying it out afterwards, one symbolic step
carries

- the state ``x`` and its sensitivity ``S = dx/dtheta`` (exact: ``S+ = F_x S + F_theta``),
- the information accumulated so far (upper triangle of ``sum_t r_t' r_t``, ``r_t`` the weighted
  output sensitivities of sample ``t``),
- the sensitivity of the heading's model-discrepancy estimate (below),

so that a record of any length is a fold of one small SX Function, compiled once per model and set
of uncertain parameters (never per fit, per trial or per noise level: those are inputs).

Model discrepancy. A fit that carries a model-discrepancy term says that its heading prediction
error grows as a random walk, variance ``q t`` (``model_discrepancy`` of a fit file). The heading
residuals of a new trial are then white noise (``sigma_psi``) plus that random walk, and the
likelihood of the trial weighs its innovations: a scalar Kalman filter on the random walk (gain
``K_t``, innovation variance ``s_t``, both known before any data) whitens them. The information is
the exact Fisher information of the trial under that error model; with ``q = 0`` it is ``J' J`` of
the weighted residuals. Long trials then stop adding information in proportion to their length: the
random walk absorbs what a parameter would explain only slowly.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..runtime import current_function, fold_chunk, jit_function
from .sensitivity import Approach

__all__ = ["InformationFold", "discrepancy_gains"]



def discrepancy_gains(n: int, dt: float, sigma: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Gains of the scalar Kalman filter that whitens heading residuals made of white noise plus a random walk.

    The random walk starts at zero at the first sample (t = 0) and its variance grows by ``q dt``
    per step; the white noise has standard deviation ``sigma``.

    Parameters
    ----------
    n : int
        Steps (samples ``1..n`` are weighed; the first sample carries no information).
    dt : float
        Step [s].
    sigma : float
        Standard deviation of the white part [rad].
    q : float
        Variance growth of the random walk [rad^2/s] (0: white residuals).

    Returns
    -------
    gain : (n,) array
        ``K_t`` of samples ``1..n``.
    inv_sd : (n,) array
        ``1 / sqrt(s_t)``, the innovations' inverse standard deviations.
    """
    gain, inv_sd = np.zeros(n), np.full(n, 1.0 / sigma)
    if q <= 0:
        return gain, inv_sd
    P = 0.0
    r = sigma ** 2
    for t in range(n):
        P += q * dt
        s = P + r
        gain[t], inv_sd[t] = P / s, 1.0 / np.sqrt(s)
        P *= r / s
    return gain, inv_sd


@lru_cache(maxsize=16)
def _step(F: ca.Function, h: ca.Function, nx: int, nu: int, npar: int, idx: tuple, rows: tuple,
          heading: int, dt: float) -> ca.Function:
    """The symbolic step (cached per model structure and uncertain set; see :class:`InformationFold`)."""
    k = len(idx)
    ntri = k * (k + 1) // 2
    z = ca.SX.sym("z", nx + nx * k + ntri + k)
    c = ca.SX.sym("c", nu + 3)                  # u, heading gain K_t, 1/sqrt(s_t), on (0 for padding)
    P = ca.SX.sym("p", npar)
    isig = ca.SX.sym("isig", len(rows))
    x, S = z[:nx], ca.reshape(z[nx:nx + nx * k], nx, k)
    M, a = z[nx + nx * k:nx + nx * k + ntri], z[nx + nx * k + ntri:]
    u, K, isd, on = c[:nu], c[nu], c[nu + 1], c[nu + 2]
    xn = F(x, u, P, ca.SX.zeros(F.size1_in(3), 1), dt)
    Pth = ca.jacobian(xn, P)[:, list(idx)]
    Sn = ca.mtimes(ca.jacobian(xn, x), S) + Pth
    xs = ca.SX.sym("xs", nx)
    ys = h(xs, u, P)
    Hx, Hp = ca.Function("h_jac", [xs, u, P], [ca.jacobian(ys, xs), ca.jacobian(ys, P)[:, list(idx)]])(xn, u, P)
    G = ca.mtimes(Hx, Sn) + Hp
    R, an = [], a
    for j, row in enumerate(rows):
        g = G[row, :].T
        if j == heading:
            nu_s = -g - a                           # innovation sensitivity: residual minus the walk's estimate
            R.append(nu_s * isd)
            an = a + K * nu_s
        else:
            R.append(g * isig[j])
    Rm = ca.horzcat(*R)                         # k x channels
    inc = ca.mtimes(Rm, Rm.T)
    tri = ca.vertcat(*[inc[i, j] for j in range(k) for i in range(j + 1)])
    zn = ca.vertcat(on * xn + (1 - on) * x, ca.vec(on * Sn + (1 - on) * S), M + on * tri, on * an + (1 - on) * a)
    return ca.Function("information_step", [z, c, P, isig], [zn], ["z", "c", "p", "isig"], ["z_next"])


class InformationFold:
    """The information of trials about ``names``, one compiled fold per model and uncertain set.

    Parameters
    ----------
    approach : Approach
        Model, current estimate, approach (the fold's step ``approach.dt``).
    names : sequence of str
        The uncertain parameters.
    channels : sequence of str
        Measured outputs (their order is the order of ``sigma`` in :meth:`information`).
    jit : bool or None
        Compile policy of the chunk (the runtime's :class:`~casship.runtime.JitPolicy`).
    """

    def __init__(self, approach: Approach, names: Sequence[str], channels: Sequence[str], *, jit=None):
        m = approach.model
        self.approach, self.names, self.channels = approach, tuple(names), tuple(channels)
        self.k, self.nx, self.nu = len(self.names), m.nx, m.nu
        rows = tuple(m.indices(self.channels, "output"))
        heading = self.channels.index("psi") if "psi" in self.channels else -1
        self.heading = heading
        self.step = _step(approach.dmodel.F, m.h, m.nx, m.nu, m.np, tuple(m.indices(self.names, "param")), rows,
                          heading, float(approach.dt))
        self.nz = self.step.size1_in(0)
        self.size = fold_chunk()          # steps per chunk: the runtime's one setting (padding changes nothing)
        self._chunk = jit_function(self.step.mapaccum("information_chunk", self.size), jit)

    # -- inputs ------------------------------------------------------------------------------------
    def z0(self) -> np.ndarray:
        """The accumulator at the execute: the approach state, zero sensitivities and information."""
        z = np.zeros(self.nz)
        z[:self.nx] = self.approach.x0
        return z

    def weights(self, n: int, sigma: Mapping[str, float], q: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """Per-channel inverse standard deviations and the heading's per-sample gains.

        Parameters
        ----------
        n : int
            Steps of the record.
        sigma : mapping channel -> standard deviation of one sample (SI, rad)
        q : float
            Heading model discrepancy [rad^2/s].

        Returns
        -------
        isig : (channels,) array
        kc : (2, n) array
            Gain ``K_t`` and ``1/sqrt(s_t)`` of the heading innovations (zeros without a heading channel).
        """
        isig = np.array([1.0 / float(sigma[c]) for c in self.channels])
        if self.heading < 0:
            return isig, np.zeros((2, n))
        return isig, np.vstack(discrepancy_gains(n, self.approach.dt, float(sigma["psi"]), q))

    def unpack(self, z):
        """The symmetric information matrix ``(k, k)`` from an accumulator (numbers or symbols).

        Parameters
        ----------
        z : array_like or casadi.MX
            The fold's accumulator (state, sensitivities, information, walk sensitivity).

        Returns
        -------
        ndarray or casadi.MX
        """
        k, off = self.k, self.nx + self.nx * self.k
        pos = np.zeros((k, k), dtype=int)
        t = 0
        for j in range(k):
            for i in range(j + 1):
                pos[i, j] = pos[j, i] = t
                t += 1
        if isinstance(z, (ca.MX, ca.SX)):
            tri = z[off:off + k * (k + 1) // 2]
            return ca.reshape(tri[pos.reshape(-1, order="F").tolist()], k, k)
        tri = np.asarray(z, dtype=float).reshape(-1)[off:off + k * (k + 1) // 2]
        return tri[pos]

    # -- evaluation -----------------------------------------------------------------------------------
    def columns(self, U: np.ndarray, kc: np.ndarray) -> np.ndarray:
        """The per-step input columns ``(nu + 3, n)`` of a record.

        Parameters
        ----------
        U : (nu, n) array
            Inputs held over each step.
        kc : (2, n) array
            The heading's gains (:meth:`weights`).

        Returns
        -------
        (nu + 3, n) array
        """
        n = U.shape[1]
        return np.vstack([U, kc, np.ones((1, n))])

    def information(self, U: np.ndarray, sigma: Mapping[str, float], q: float = 0.0) -> np.ndarray:
        """The information ``(k, k)`` of a record with inputs ``U`` ``(nu, n)`` held over each step.

        Parameters
        ----------
        U : (nu, n) array
        sigma : mapping channel -> standard deviation of one sample (SI, rad)
        q : float
            Heading model discrepancy [rad^2/s].
        """
        n = U.shape[1]
        isig, kc = self.weights(n, sigma, q)
        C = self.columns(np.asarray(U, dtype=float), kc)
        size = self.size
        pad = (-n) % size
        if pad:
            C = np.hstack([C, np.zeros((C.shape[0], pad))])      # on = 0: the padded steps change nothing
        z, p = self.z0(), self.approach.p
        for i in range(0, C.shape[1], size):
            z = np.asarray(current_function(self._chunk)(z, C[:, i:i + size], p, isig))[:, -1]
        return self.unpack(z)

    def symbolic(self, z0: ca.MX, C: ca.MX, p: ca.MX, isig: ca.MX) -> ca.MX:
        """The information (symbolic) of a record: chunk calls of the interpreted step fold, so that the
        caller can differentiate and compile the whole.

        Parameters
        ----------
        z0 : casadi.MX
            The accumulator at the execute (:meth:`z0`).
        C : casadi.MX (nu + 3, n)
            The step columns (:meth:`columns`).
        p : casadi.MX
            The model's parameter vector.
        isig : casadi.MX
            The channels' inverse standard deviations.

        Returns
        -------
        casadi.MX (k, k)
        """
        n = C.shape[1]
        size = self.size
        chunk = self.step.mapaccum("information_chunk_sym", size)
        pad = (-n) % size
        if pad:
            C = ca.horzcat(C, ca.MX.zeros(C.shape[0], pad))
        z = z0
        for i in range(0, n + pad, size):
            z = chunk(z, C[:, i:i + size], p, isig)[:, -1]
        return self.unpack(z)


def free_trial_objective(fold: InformationFold, B: np.ndarray, rudder_rows: Sequence[int], *,
                         criterion: str | None = None) -> ca.Function:
    """The free trial's objective and its exact gradient in the rudder knots, as one Function.

    ``(d, z0, p, isig, u0, kc, h, L, floor2) -> (f, df/dd)``: ``d`` the knot values, ``u0`` the
    inputs held through the trial (the propeller rate; the rudder rows are ``B d``), ``kc`` the
    heading's gains (:meth:`InformationFold.weights`), ``L`` a square root of the prior covariance
    (``cov = L L'``). With a target, ``h = L' g`` (``g`` its gradient) and ``f = log(h' (I + L' M L)^-1 h
    + floor2)``, the log of the target's variance after the trial with the model-error floor
    ``floor2`` added; with a criterion, ``D``: ``-log det(I + L' M L)``, ``A``: the mean relative
    variance ``trace((I + L' M L)^-1 L' diag(1/diag(cov)) L) / k`` (``h`` then holds ``1/diag(cov)``).
    Every number is an input, so one compiled Function serves every fit of the same model, uncertain
    set and trial grid.
    """
    n, m = B.shape
    k, nu = fold.k, fold.nu
    d = ca.MX.sym("d", m)
    z0 = ca.MX.sym("z0", fold.nz)
    p = ca.MX.sym("p", fold.approach.model.np)
    isig = ca.MX.sym("isig", len(fold.channels))
    u0 = ca.MX.sym("u0", nu)
    kc = ca.MX.sym("kc", 2, n)
    h = ca.MX.sym("h", k)
    L = ca.MX.sym("L", k, k)
    floor2 = ca.MX.sym("floor2")
    rud = ca.mtimes(ca.DM(B), d).T
    rows = [rud if i in rudder_rows else ca.repmat(u0[i], 1, n) for i in range(nu)]
    C = ca.vertcat(*rows, kc, ca.DM.ones(1, n))
    M = fold.symbolic(z0, C, p, isig)
    A = ca.DM.eye(k) + ca.mtimes([L.T, M, L])
    if criterion is None:
        f = ca.log(ca.dot(h, ca.solve(A, h)) + floor2)
    elif criterion == "D":
        f = -ca.log(ca.det(A))
    else:
        f = ca.trace(ca.solve(A, ca.mtimes([L.T, ca.diag(h), L]))) / k
    return ca.Function("free_trial_objective", [d, z0, p, isig, u0, kc, h, L, floor2], [f, ca.gradient(f, d)],
                       ["d", "z0", "p", "isig", "u0", "kc", "h", "L", "floor2"], ["f", "grad"])
