"""The per-sample recursion of the MHE, shared by ``MHE.filter`` and the online runner.

Each sample: the arrival-cost EKF step from the previous MHE estimate (its named step Function),
the window data shifted by one sample, a warm start shifted by one stage, one window solve.
"""
from __future__ import annotations

import time

import numpy as np

from ..._fast import BufferedCall
from ...data import Gaussian
from .arrival import arrival_prior
from .problem import params_vector
from .solvers import solve_window

__all__: list[str] = []          # the package's own building blocks


def _push(buffer: np.ndarray, value) -> None:
    """Shift a window buffer by one row (oldest out) and put ``value`` last, in place."""
    buffer[:-1] = buffer[1:]
    buffer[-1] = value


class WindowEngine:
    """The moving window of an :class:`~casship.MHE` run (also its online engine).

    ``advance`` takes one sample (masked measurement) and returns the new estimate, the EKF
    covariance run alongside and that step's diagnostics; ``update`` is the online protocol.
    """

    def __init__(self, mhe, prior: Gaussian, p_aug: np.ndarray, u=None):
        m, N = mhe.model, mhe.horizon
        self.name, self.samples, self.mhe = mhe.name, 0, mhe
        self.win = win = mhe.window(N)
        nu, ny = m.nu, mhe.ny
        xs = np.tile(prior.mean, (N + 1, 1))
        self.z = np.zeros(win.nz)
        self.z[win.ix] = xs
        self.p, self.P0 = p_aug.copy(), prior.cov.copy()
        self._x, self._P = prior.mean.copy(), prior.cov.copy()
        self.hist_x, self.hist_P = xs.copy(), np.tile(prior.cov, (N + 1, 1, 1))
        self.Uh = None
        self.Up, self.Y, self.M, self.dt = np.zeros((N, nu)), np.zeros((N + 1, ny)), np.zeros((N + 1, ny)), np.zeros(N)
        self.ekf = ekf = BufferedCall(mhe.step_function("all"))
        ekf["p"], ekf["Q"], ekf["R"], ekf["gate"] = p_aug, mhe.Q, mhe.R, np.inf
        u0 = np.zeros(nu) if u is None else np.asarray(u, dtype=float).reshape(-1)
        if u0.size != nu or not np.all(np.isfinite(u0)):
            raise ValueError(f"u must be {nu} finite values for the inputs {list(m.input_names)}, got {u0}")
        self._u_prev, self._u = u0.copy(), u0.copy()
        self._info: dict = {}

    def advance(self, u_prev, u, y, mask, dt, where: str):
        """One sample: EKF step from the previous MHE estimate, shift the window, solve it."""
        mhe, win, N = self.mhe, self.win, self.mhe.horizon
        nx = mhe.model.nx
        ekf = self.ekf
        ekf["x"], ekf["P"] = self._x, self._P
        ekf["u_prev"], ekf["u"], ekf["y"], ekf["mask"], ekf["dt"] = u_prev, u, y, mask, dt
        ekf()
        info = {k: ekf.out(k).copy() for k in ("x_pred", "P_pred", "C", "S", "K")}
        info["x_pred"] = info["x_pred"].ravel()
        info["e"] = ekf.out("e").ravel().copy()
        info.update(nis=float(ekf.out("nis")[0, 0]), ll=float(ekf.out("ll")[0, 0]))
        P_ekf = ekf.out("P").copy()
        first = self.samples == 0
        # window data: slots 0..N hold rows k-N..k (rows before the record: dt = 0, nothing measured)
        if self.Uh is None:
            self.Uh = np.tile(u, (N + 1, 1))
            self.Up[:] = u_prev
        for buf, val in ((self.Uh, u), (self.Y, y), (self.M, mask), (self.Up, u_prev), (self.dt, dt)):
            _push(buf, val)
        _push(self.hist_x, info["x_pred"])
        _push(self.hist_P, info["P_pred"])
        xbar, W = arrival_prior(mhe.options.arrival, self.samples, N, self.hist_x, self.hist_P,
                                self.z[win.ix[1]], self.P0)
        # warm start: shift by one stage (z = [x_0 v_0 x_1 v_1 ... x_N]), new last state = prediction
        if first:
            z0 = self.z.copy()
        else:
            stage = nx + mhe.nv
            z0 = np.empty_like(self.z)
            z0[: win.nz - stage] = self.z[stage:]
            z0[win.nz - stage: win.nz - nx] = 0.0
            z0[win.nz - nx:] = info["x_pred"]
        z0 = np.clip(z0, win.lbx, win.ubx)
        par = params_vector(xbar, W, self.Uh.T, self.Up.T, self.Y.T, self.M.T, self.dt, self.p)
        self.z = solve_window(win, z0, par, where)
        self._x, self._P = self.z[win.ix[-1]], P_ekf
        self.samples += 1
        return self._x, self._P, info

    # -- the online protocol ------------------------------------------------------------------------
    def update(self, y, dt, u_prev, u):
        if not dt >= 0:
            raise ValueError(f"dt must be >= 0 and finite, got {dt}")
        mhe = self.mhe
        if u_prev is not None:
            self._u_prev = np.asarray(u_prev, dtype=float).reshape(-1)
        else:
            self._u_prev = self._u
        self._u = self._u_prev if u is None else np.asarray(u, dtype=float).reshape(-1)
        if not (np.all(np.isfinite(self._u_prev)) and np.all(np.isfinite(self._u))):
            raise ValueError(f"inputs must be finite, got u_prev = {self._u_prev}, u = {self._u}")
        y = np.asarray(y, dtype=float).reshape(-1)
        if y.size != mhe.ny:
            raise ValueError(f"y must hold {mhe.ny} values for {list(mhe.measured)}, got {y.size}")
        ok = np.isfinite(y)
        t0 = time.perf_counter()
        _, _, info = self.advance(self._u_prev, self._u, np.where(ok, y, 0.0), ok.astype(float),
                                  float(dt), f"online sample {self.samples}")
        info["solve_time"] = time.perf_counter() - t0
        info["e"] = np.where(ok, info["e"], np.nan)
        info["rejected"] = False
        self._info = info
        return self._x.copy()

    @property
    def x(self) -> np.ndarray:
        return self._x.copy()

    @property
    def P(self) -> np.ndarray:
        return self._P.copy()

    @property
    def info(self) -> dict:
        return dict(self._info)
