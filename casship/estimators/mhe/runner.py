"""The per-sample recursion of the MHE, shared by ``MHE.filter`` and the online runner.

Each sample: the arrival-cost EKF step from the previous MHE estimate (its named step Function),
the window data shifted by one sample, a warm start shifted by one stage, one window solve.
"""
from __future__ import annotations

import time

import numpy as np

from ...runtime import BufferedCall
from ...gaussian import Gaussian
from .arrival import arrival_prior
from .solvers import gauss_newton_start, solve_window

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
        nu, ny, nx = m.nu, mhe.ny, m.nx
        xs = np.tile(prior.mean, (N + 1, 1))
        self.z = np.zeros(win.nz)
        self.z[win.ix] = xs
        self.P0 = prior.cov.copy()
        self._x, self._P = prior.mean.copy(), prior.cov.copy()
        self.hist_x, self.hist_P = xs.copy(), np.tile(prior.cov, (N + 1, 1, 1))
        # the window's parameter vector (params_vector layout) with views for its pieces: shifting a
        # view shifts the data in place, no vector is assembled per sample
        sizes = {"xbar": nx, "W": nx * nx, "Uh": nu * (N + 1), "Up": nu * N, "Y": ny * (N + 1), "M": ny * (N + 1),
                 "dt": N, "p": p_aug.size}
        self.par = np.zeros(sum(sizes.values()))
        ends = np.cumsum(list(sizes.values()))
        view = dict(zip(sizes, (self.par[e - n:e] for n, e in zip(sizes.values(), ends))))
        self.xbar, self.W = view["xbar"], view["W"].reshape(nx, nx, order="F")
        self.Uh, self.Up = view["Uh"].reshape(N + 1, nu), view["Up"].reshape(N, nu)
        self.Y, self.M, self.dt = view["Y"].reshape(N + 1, ny), view["M"].reshape(N + 1, ny), view["dt"]
        view["p"][:] = p_aug
        self.p = view["p"]
        self._started = False
        self.ekf = ekf = BufferedCall(mhe._compiled_function(("step", "all"), lambda: mhe.step_function("all")),
                                      cannot_fail=mhe.options.jit)
        ekf["p"], ekf["Q"], ekf["R"], ekf["gate"] = p_aug, mhe.Q, mhe.R, np.inf
        self._ekf_in = {k: ekf.flat_in(k) for k in ("x", "P", "u_prev", "u", "y", "mask", "dt")}
        self._ekf_out = {k: (ekf.offsets[i], ekf.offsets[i + 1], ekf.out(k).shape)
                         for i, k in enumerate(ekf.names_out)}
        self._stage = nx + mhe.nv
        u0 = np.zeros(nu) if u is None else np.asarray(u, dtype=float).reshape(-1)
        if u0.size != nu or not np.all(np.isfinite(u0)):
            raise ValueError(f"u must be {nu} finite values for the inputs {list(m.input_names)}, got {u0}")
        self._u_prev, self._u = u0.copy(), u0.copy()
        self._info: dict = {}

    def advance(self, u_prev, u, y, mask, dt, where: str):
        """One sample: EKF step from the previous MHE estimate, shift the window, solve it."""
        mhe, win, N = self.mhe, self.win, self.mhe.horizon
        nx = mhe.model.nx
        ekf, e_in = self.ekf, self._ekf_in
        e_in["x"][:], e_in["P"][:] = self._x, self._P.reshape(-1, order="F")
        e_in["u_prev"][:], e_in["u"][:], e_in["y"][:], e_in["mask"][:], e_in["dt"][:] = u_prev, u, y, mask, dt
        ekf()
        snap = ekf.block.copy()                          # every output of the step in one copy
        out = {k: snap[a:b].reshape(shape, order="F") for k, (a, b, shape) in self._ekf_out.items()}
        info = {k: out[k] for k in ("P_pred", "C", "S", "K")}
        info.update(x_pred=out["x_pred"].ravel(), e=out["e"].ravel(), nis=float(out["nis"][0, 0]),
                    ll=float(out["ll"][0, 0]))
        first = self.samples == 0
        # window data: slots 0..N hold rows k-N..k (rows before the record: dt = 0, nothing measured)
        if not self._started:
            self.Uh[:] = u
            self.Up[:] = u_prev
            self._started = True
        for buf, val in ((self.Uh, u), (self.Y, y), (self.M, mask), (self.Up, u_prev), (self.dt, dt)):
            _push(buf, val)
        _push(self.hist_x, info["x_pred"])
        _push(self.hist_P, info["P_pred"])
        self.xbar[:], self.W[:] = arrival_prior(mhe.options.arrival, self.samples, N, self.hist_x, self.hist_P,
                                                self.z[win.ix[1]], self.P0)
        # warm start: shift by one stage (z = [x_0 v_0 x_1 v_1 ... x_N]), new last state = prediction
        z0 = self.z.copy()
        if not first:
            stage = self._stage
            z0[: win.nz - stage] = self.z[stage:]
            z0[win.nz - stage: win.nz - nx] = 0.0
            z0[win.nz - nx:] = info["x_pred"]
        np.clip(z0, win.lbx, win.ubx, out=z0)
        lam = None
        if win.solver is not None:                      # NLP solvers: warm start (primal and dual)
            z0, lam = gauss_newton_start(win, z0, self.par)
        self.z, _ = solve_window(win, z0, self.par, where, lam)
        self._x, self._P = self.z[win.ix[-1]], out["P"]
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
        if not np.isfinite(self._u_prev.sum() + self._u.sum()):
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
