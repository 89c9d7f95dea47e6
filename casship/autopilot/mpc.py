"""Model-predictive course (or heading) control with rudder angle, rudder rate and turn-rate limits.

The prediction model is the first-order Nomoto model of the design with the steering as a state
driven by its rate and a constant steering bias ``b`` (from the heading observer, which gives
offset-free control in wind and current)::

    e' = r,   r' = (K (delta + b) - r) / T,   delta' = u          (e = wrap(psi - command))

(the second-order model ``r/delta = K (1 + T3 s)/((1 + T1 s)(1 + T2 s))`` when it is known),
discretised exactly (zero-order hold on ``u``) at the MPC period ``T_s``. Each solve minimises
``sum q_e e_k^2 + q_r r_k^2 + r_u u_k^2`` over ``N`` steps subject to ``|delta| <= delta_max``,
``|u| <= rate_max`` and ``|r| <= r_max`` (the preset rate of turn), as one quadratic program
built with ``casadi.Opti`` (solver qpOASES; each plan is checked against the constraints and
the model, and a failed solve raises), warm-started with the previous solution shifted by a
step. Between solves the steering command ramps at the planned rate, so the steering gear is never
asked for more than its rate limit.

The MPC runs in the step-by-step closed loop (:meth:`ClosedLoop.run_stepwise
<casship.autopilot.closed_loop.ClosedLoop.run_stepwise>`), the QP solved from Python at every
MPC period.
"""
from __future__ import annotations

import io
import os
import sys
from contextlib import contextmanager, redirect_stdout
from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.linalg import expm

from ..angles import wrap
from .nomoto import Nomoto
from .reference import ReferenceModel

__all__ = ["MPCAutopilot", "mpc_for_design"]


@dataclass
class MPCAutopilot:
    """Receding-horizon course autopilot (see the module docstring).

    Parameters
    ----------
    nomoto : Nomoto
        Prediction model.
    period : float
        MPC period ``T_s`` [s] (a multiple of the loop period).
    horizon : int
        Prediction steps ``N``.
    steer_max, rate_max, r_max : float
        Steering limit, steering rate limit [unit/s] and turn-rate limit [rad/s].
    q_e, q_r, r_u : float
        Weights of the course error [1/rad^2], yaw rate [1/(rad/s)^2] and steering rate.
    reference : ReferenceModel, optional
        Reference model whose preview the plan tracks (None: the command itself).
    """

    nomoto: Nomoto
    period: float
    horizon: int
    steer_max: float
    rate_max: float
    r_max: float
    q_e: float = 1.0
    q_r: float = 0.0
    r_u: float = 1.0
    reference: ReferenceModel | None = None
    _solver: object = field(default=None, init=False, repr=False)

    MEMORY_LOG = ("chi_d", "r_d", "e")

    def __post_init__(self):
        for name in ("period", "steer_max", "rate_max", "r_max", "q_e", "r_u"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"MPC {name} must be positive and finite, got {v}")
        if int(self.horizon) != self.horizon or self.horizon < 2:
            raise ValueError(f"MPC horizon must be an integer >= 2, got {self.horizon}")
        with _quiet_stdout():           # qpOASES prints its licence banner when its first solver is made
            self._solver = self._build()

    @property
    def order(self) -> int:
        """Order of the Nomoto prediction model (2 when ``T1, T2, T3`` are known)."""
        return 2 if self.nomoto.second_order else 1

    def model(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact discretisation ``x+ = A x + B u + E b`` at ``period`` of ``[e, r, delta]`` (first
        order) or ``[e, r, xi, delta]`` (second order, the observer form of
        :meth:`Nomoto.system <casship.autopilot.nomoto.Nomoto.system>`)."""
        sys = self.nomoto.system(self.order)
        n = sys.nstates
        Ac = np.zeros((n + 1, n + 1))
        Ac[:n, :n], Ac[:n, n] = sys.A, np.ravel(sys.B)                 # steering is the last state
        Bc = np.zeros((n + 1, 2))
        Bc[n, 0], Bc[:n, 1] = 1.0, np.ravel(sys.B)                     # columns: u (rate), b (bias)
        M = expm(np.block([[Ac, Bc], [np.zeros((2, n + 3))]]) * self.period)
        return M[:n + 1, :n + 1], M[:n + 1, n + 1:n + 2], M[:n + 1, n + 2:n + 3]

    def _build(self) -> ca.Function:
        """The QP in condensed form: the steering rates are the variables, the states linear
        expressions of them (``casadi.Opti`` with qpOASES)."""
        A, B, E = (ca.DM(M) for M in self.model())
        N, nx = int(self.horizon), A.shape[0]
        opti = ca.Opti("conic")
        U = opti.variable(1, N)
        x0, b, target = opti.parameter(nx), opti.parameter(), opti.parameter(2, N)
        cols, x, cost = [x0], x0, 0
        for k in range(N):
            x = A @ x + B * U[0, k] + E * b
            cols.append(x)
            cost += (self.q_e * (x[0] - target[0, k]) ** 2 + self.q_r * (x[1] - target[1, k]) ** 2
                     + self.r_u * U[0, k] ** 2)
        X = ca.horzcat(*cols)
        opti.subject_to(opti.bounded(-self.rate_max, U, self.rate_max))
        opti.subject_to(opti.bounded(-self.steer_max, X[nx - 1, 1:], self.steer_max))
        opti.subject_to(opti.bounded(-self.r_max, X[1, 1:], self.r_max))
        opti.minimize(cost)
        opti.solver("qpoases", {"printLevel": "none", "error_on_fail": False})
        return opti.to_function("mpc", [x0, b, target, U], [U[0, 0], X, U], ["x0", "b", "target", "U_guess"],
                                ["u0", "X", "U"])

    def _preview(self, xr: np.ndarray, ref: float) -> np.ndarray:
        """Course error and rate of the reference model over the horizon (``2 x N``), relative to the
        command: the linear reference model (no rate saturation) stepped exactly at ``period``."""
        N = int(self.horizon)
        if self.reference is None:
            return np.zeros((2, N))
        sysr = self.reference.system()
        Ad = expm(np.asarray(sysr.A) * self.period)
        z = np.array([float(wrap(xr[0] - ref)), xr[1], xr[2]])     # deviation from the command (a fixed point)
        out = np.empty((2, N))
        for k in range(N):
            z = Ad @ z
            out[:, k] = z[:2]
        return out

    def memory0(self, chi0: float = 0.0) -> dict:
        """Initial controller memory: the command at rest, no plan.

        Parameters
        ----------
        chi0 : float
            Initial course (or heading) of the reference model [rad].
        """
        N, nx = int(self.horizon), 3 + (self.order == 2)
        return {"steer_cmd": 0.0, "rate": 0.0, "X": np.zeros((nx, N + 1)), "U": np.zeros((1, N)), "count": 0,
                "xr": np.array([chi0, 0.0, 0.0])}

    def update(self, memory: dict, ref: float, chi: float, r: float, dt: float, bias: float = 0.0):
        """One loop sample: solve the QP when a new MPC period starts (warm-started with the previous
        plan shifted by one step), then ramp the command at the planned rate.

        Parameters
        ----------
        memory : dict
            From :meth:`memory0` or the previous update.
        ref : float
            Course command [rad].
        chi, r : float
            Estimated course [rad] and rate [rad/s].
        dt : float
            Loop period [s].
        bias : float
            Steering bias estimate (the heading observer's ``b``).

        Returns
        -------
        (dict, float, dict)
            Memory, steering command, and ``chi_d`` (reference), ``r_d`` (planned rate of turn),
            ``e`` (course error).
        """
        every = max(1, int(round(self.period / dt)))
        e = float(wrap(chi - ref))
        mem = dict(memory)
        if self.reference is not None:      # the reference model runs at the loop rate, as in the PID law
            mem["xr"] = np.asarray(self._ref_step()(mem["xr"], ref, dt)).ravel()
        if mem["count"] % every == 0:
            U_guess = np.hstack([mem["U"][:, 1:], mem["U"][:, -1:]])          # the last plan, shifted
            delta = mem["steer_cmd"]
            if self.order == 1:
                x0 = [e, r, delta]
            else:        # internal state of the observer form with r' = 0 (the rate is estimated, not its change)
                sys = self.nomoto.system(2)
                x0 = [e, r, -sys.A[1, 1] * r - sys.B[1, 0] * (delta + bias), delta]
            out = self._solve({"x0": np.array(x0), "b": bias, "target": self._preview(mem["xr"], ref),
                               "U_guess": U_guess})
            mem["X"], mem["U"] = np.asarray(out["X"]), np.asarray(out["U"])
            self._check(mem["X"], mem["U"], np.array(x0), bias)
            mem["rate"] = float(out["u0"])
        mem["count"] += 1
        cmd = float(np.clip(mem["steer_cmd"] + mem["rate"] * dt, -self.steer_max, self.steer_max))
        mem["steer_cmd"] = cmd
        chi_d = float(mem["xr"][0]) if self.reference is not None else ref
        return mem, cmd, {"chi_d": chi_d, "r_d": float(mem["X"][1, 1]), "e": float(wrap(chi - chi_d))}

    def _solve(self, args: dict) -> dict:
        """One QP solve with the C-level standard output closed (qpOASES prints its licence notice
        whenever it builds a problem)."""
        import os
        import sys

        sys.stdout.flush()
        saved = os.dup(1)
        try:
            with open(os.devnull, "w") as null:
                os.dup2(null.fileno(), 1)
                out = self._solver.call(args)
        finally:
            os.dup2(saved, 1)
            os.close(saved)
        return out

    def _check(self, X, U, x0, bias, tol: float = 1e-6) -> None:
        """Raise ``RuntimeError`` when the plan breaks a limit or the model (a failed QP solve)."""
        A, B, E = self.model()
        n = X.shape[0]
        bad = []
        if np.max(np.abs(U)) > self.rate_max * (1 + tol) + 1e-12:
            bad.append("steering rate")
        if np.max(np.abs(X[n - 1, 1:])) > self.steer_max * (1 + tol) + 1e-12:
            bad.append("steering angle")
        if np.max(np.abs(X[1, 1:])) > self.r_max * (1 + tol) + 1e-12:
            bad.append("rate of turn")
        resid = X[:, 1:] - (A @ X[:, :-1] + B @ U + E * bias)
        scale = 1 + np.max(np.abs(X))
        if np.max(np.abs(resid)) > 1e-6 * scale or np.max(np.abs(X[:, 0] - x0)) > 1e-6 * scale:
            bad.append("the model")
        if bad:
            from ..errors import SolverError

            raise SolverError(f"the MPC's QP solve failed (qpOASES): the plan breaks {', '.join(bad)}")

    def _ref_step(self) -> ca.Function:
        if getattr(self, "_ref_fun", None) is None:
            xr, r, h = ca.SX.sym("xr", 3), ca.SX.sym("ref"), ca.SX.sym("dt")
            self._ref_fun = ca.Function("ref_step", [xr, r, h], [self.reference.symbolic_step(xr, r, h)])
        return self._ref_fun


def mpc_for_design(design, *, horizon_time: float | None = None, steps: int = 60, q_r: float | None = None,
                   r_u: float | None = None) -> MPCAutopilot:
    """An MPC with the design's model, limits and reference model: horizon ``6 pi / wn_ref`` (three
    periods of the reference model's natural frequency) in ``steps`` steps (the period rounded to a
    multiple of the loop period); weights: course error 1/(1 deg)^2, yaw rate ``1/r_max^2`` (both
    against the reference model's preview), steering rate ``(100 / rate_max)^2`` (a steering rate
    of 1 % of the limit costs as much as 1 deg of course error).

    Parameters
    ----------
    design : Design
    horizon_time : float, optional
        Prediction horizon [s].
    steps : int
        Steps over the horizon.
    q_r, r_u : float, optional
        Replace the yaw-rate and steering-rate weights.
    """
    s = design.settings
    horizon_time = horizon_time or 6 * np.pi / s.wn_ref
    period = max(s.dt, round(horizon_time / steps / s.dt) * s.dt)
    return MPCAutopilot(design.nomoto, period, steps, s.steer_max, s.steer_rate_max, s.r_max,
                        q_e=1.0 / np.radians(1.0) ** 2, q_r=(1.0 / s.r_max**2) if q_r is None else q_r,
                        r_u=(100.0 / s.steer_rate_max) ** 2 if r_u is None else r_u,
                        reference=design.autopilot.reference)


@contextmanager
def _quiet_stdout():
    """Standard output discarded while the block runs (Python's and file descriptor 1 of compiled code)."""
    try:
        sys.stdout.flush()
        saved = os.dup(1)
    except (OSError, ValueError, AttributeError):         # no real descriptor (an embedded interpreter)
        yield
        return
    try:
        with open(os.devnull, "w") as null, redirect_stdout(io.StringIO()):     # CasADi may print through Python
            os.dup2(null.fileno(), 1)
            yield
    finally:
        _flush_c_stdout()           # what compiled code buffered goes to the null device, not later to the user
        os.dup2(saved, 1)
        os.close(saved)


def _flush_c_stdout() -> None:
    import ctypes

    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass
