"""The per-sample recursion of the MHE, shared by ``MHE.filter`` and the online runner.

Each sample: the arrival-cost EKF step from the previous MHE estimate (its named step Function),
the window data shifted by one sample, a warm start shifted by one stage, one window solve. Online,
an interval longer than the one-step prediction limit raises or is bridged by prediction-only
samples, as ``filter`` bridges it by prediction-only rows (:mod:`casship.estimators.gaps`).
"""
from __future__ import annotations

import time
import warnings

import numpy as np

from ...runtime import BufferedCall, is_compiled
from ...gaussian import Gaussian
from ..gaps import gap_pieces, gap_threshold
from ..online import check_sample, first_input
from ..options import DIAGNOSTICS
from .arrival import arrival_prior
from .solvers import gauss_newton_start, solve_window

__all__: list[str] = []          # the package's own building blocks

ARRIVAL_OUTPUTS = ("x", "P", "x_pred", "P_pred")      # what the recursion itself needs of the EKF step


def _push(buffer: np.ndarray, value) -> None:
    """Shift a window buffer by one row (oldest out) and put ``value`` last, in place."""
    buffer[:-1] = buffer[1:]
    buffer[-1] = value


class WindowEngine:
    """The moving window of an :class:`~casship.MHE` run (also its online engine).

    ``advance`` takes one sample (masked measurement) and returns the new estimate, the EKF
    covariance run alongside and that step's diagnostics (``outputs``, at least those the recursion
    needs); ``update`` is the online protocol (an :class:`~casship.estimators.online.OnlineEngine`,
    its sample checked by :func:`~casship.estimators.online.check_sample`: masked = NaN = not measured).
    """

    def __init__(self, mhe, prior: Gaussian, p_aug: np.ndarray, u=None, outputs=DIAGNOSTICS):
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
        self.outputs = tuple(o for o in DIAGNOSTICS if o in outputs)
        needed = tuple(o for o in DIAGNOSTICS if o in (*ARRIVAL_OUTPUTS, *self.outputs))
        step = mhe.arrival_step(needed)
        self.ekf = ekf = BufferedCall(step, cannot_fail=is_compiled(step))
        ekf["p"], ekf["Q"], ekf["R"], ekf["gate"] = p_aug, mhe.Q, mhe.R, np.inf
        self._ekf_in = {k: ekf.flat_in(k) for k in ("x", "P", "u_prev", "u", "y", "mask", "dt")}
        self._ekf_out = {k: (ekf.offsets[i], ekf.offsets[i + 1], ekf.out(k).shape)
                         for i, k in enumerate(ekf.names_out)}
        self._stage = nx + mhe.nv
        u0 = first_input(u, m.input_names)
        self._u_prev, self._u = u0.copy(), u0.copy()
        self._info: dict = {}
        self._gap_limit = gap_threshold(mhe)      # longer intervals are checked at the estimate there

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
        info = {}
        for k, v in out.items():
            if k in ("x", "P"):
                continue
            info[k] = float(v[0, 0]) if k in ("nis", "ll", "accepted") else (v.ravel() if v.shape[1] == 1 else v)
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
        if not win.unbounded:
            np.clip(z0, win.lbx, win.ubx, out=z0)
        lam = None
        if win.solver is not None:                      # NLP solvers: warm start (primal and dual)
            z0, lam = gauss_newton_start(win, z0, self.par)
        self.z, _ = solve_window(win, z0, self.par, where, lam)
        self._x, self._P = self.z[win.ix[-1]], out["P"]
        self.samples += 1
        return self._x, self._P, info

    # -- the online protocol (casship.estimators.online.OnlineEngine) --------------------------------------
    def update(self, y, dt, u_prev, u):
        # everything is checked before anything changes: a refused update leaves the run as it was
        mhe, m = self.mhe, self.mhe.model
        y, dt, u_prev, u = check_sample(y, dt, u_prev, u, mhe.measured, m.input_names)
        u_prev = self._u if u_prev is None else u_prev
        u = u_prev if u is None else u
        where = f"before update {self.samples + 1}"
        pieces = 1
        if dt > self._gap_limit:
            pieces = gap_pieces(mhe, self._x, u_prev, self.p, float(dt), where)
            if pieces > 1:
                warnings.warn(f"{mhe.name}: time gap of {dt:.4g} s {where} bridged by {pieces - 1} prediction-only "
                              f"step(s) of {dt / pieces:.4g} s", UserWarning, stacklevel=4)
        t0 = time.perf_counter()
        nothing = np.zeros(mhe.ny)
        for _ in range(pieces - 1):                 # prediction-only samples across a bridged gap
            self.advance(u_prev, u_prev, nothing, nothing, dt / pieces, f"online sample {self.samples}")
        ok = np.isfinite(y)
        _, _, info = self.advance(u_prev, u, np.where(ok, y, 0.0), ok.astype(float), dt / pieces,
                                  f"online sample {self.samples}")
        self._u_prev, self._u = u_prev, u
        self._info = self._public(info, ok)
        self._info["solve_time"] = time.perf_counter() - t0
        return self._x.copy()

    def _public(self, info: dict, measured: np.ndarray) -> dict:
        """The diagnostics of option ``outputs`` (besides ``x`` and ``P``), ``e`` NaN where not measured."""
        out = {}
        for k in self.outputs:
            if k in ("x", "P"):
                continue
            if k == "e":
                out[k] = np.where(measured, info["e"], np.nan)
            elif k == "accepted":
                out["rejected"] = False             # the MHE has no gate: every sample is used
            else:
                out[k] = info[k]
        return out

    @property
    def x(self) -> np.ndarray:
        return self._x.copy()

    @property
    def P(self) -> np.ndarray:
        return self._P.copy()

    @property
    def info(self) -> dict:
        return dict(self._info)
