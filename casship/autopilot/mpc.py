"""Model-predictive course (or heading) control with rudder angle, rudder rate and turn-rate limits.

The prediction model is the first-order Nomoto model of the design with the steering as a state
driven by its rate and a constant steering bias ``b`` (from the heading observer, which gives
offset-free control in wind and current)::

    e' = r,   r' = (K (delta + w) - r) / T,   delta' = u          (e = wrap(psi - command))

(the second-order model ``r/delta = K (1 + T3 s)/((1 + T1 s)(1 + T2 s))`` when it is known),
discretised exactly (zero-order hold on ``u``) at the MPC period ``T_s``. The disturbance of each
step, ``w_k = b - f(r_d)`` with ``f(r) = s(r) - r / K``, adds to the bias the steering the
nonlinear ship needs beyond the linear model's at the reference rate ``r_d`` of that step
(``s`` the ship's steady steering, :func:`~casship.autopilot.plants.steering_feedforward`, the
PID law's feed-forward): the linear model then plans only the deviation from the steady steering
along the reference preview, and the steering limits still bound the total steering. Without a
steering table ``f = 0``. Each solve minimises
``sum q_e (e_k - e_d,k)^2 + q_r (r_k - r_d,k)^2 + q_d (delta_k - delta_d,k)^2 + r_u (u_k - u_d,k)^2``
over ``N`` steps subject to ``|delta| <= delta_max``, ``|u| <= rate_max`` and ``|r| <= r_max``
(the preset rate of turn, a soft limit); ``e_d, r_d`` are the reference model's preview,
``delta_d`` the steering that holds the model on it, ``s(r_d) + (T / K) a_d - b`` (the PID law's
low-frequency feed-forward, less the bias), and ``u_d`` its rate, so that following the reference
costs nothing and the weights price only the departures from it. The quadratic program keeps
the optimal-control structure (variables ``x0, u0, x1, u1, ..., xN``, the model as equality
constraints stage by stage) and is solved by HPIPM (Frison & Diehl 2020), the structure-exploiting
interior-point QP solver shipped with CasADi (``casadi.conic(..., "hpipm")``), whose cost grows
linearly with the horizon. Between solves the steering command ramps at the planned rate, so the
steering gear is never asked for more than its rate limit.

The MPC runs inside the compiled closed loop (:meth:`MPCAutopilot.law`: the solve is a call node
of the loop's step, taken once per ``replan`` interval through ``casadi.Function.conditional``), and from
Python (:meth:`MPCAutopilot.update`, which checks each plan against the limits and the model and
raises on a failed solve).

Offset-free control comes from the observer's bias (``offset="bias"``, above) or, as in the PID
law, from the integral of the tracking error (``offset="integral"``): the prediction model then
carries ``z' = e`` (before the steering state), the cost adds ``q_z (z_k - z_d,k)^2`` with
``z_d,k`` the integral of the reference preview's course error (exact, from the reference model),
so that ``z_k - z_d,k`` is the integral of ``chi - chi_d`` the law keeps (from the start of the
run, held while the command is at its limit and the error would drive it further, the PID law's
anti-windup); the observer's bias is then not used (``w_k = -f(r_d)``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
from scipy.linalg import expm

from ..angles import wrap
from .nomoto import Nomoto
from .reference import ReferenceModel
from ..errors import InputError

__all__ = ["MPCAutopilot", "MPCLaw"]


def _casadi(x):
    """``x`` as a CasADi value (numbers as ``DM``): the plan's inputs are built one way for both."""
    return x if isinstance(x, (ca.MX, ca.SX, ca.DM)) else ca.DM(np.asarray(x, dtype=float))


def _like(result, *inputs):
    """``result`` as a numpy array when every input was numeric, else as built (symbolic)."""
    return result if any(isinstance(v, (ca.MX, ca.SX)) for v in inputs) else np.array(ca.DM(result))


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
    q_d : float
        Weight of the steering's departure from the reference steering (default 0: none).
    reference : ReferenceModel, optional
        Reference model whose preview the plan tracks (None: the command itself).
    replan : float, optional
        Time between solves [s] (default: the period). Solving more often than the model's step
        (the plan's first rate applied until the next solve) keeps the feedback of a long horizon
        with a coarse step.
    steering : SteeringFeedforward, optional
        The nonlinear ship's steady steering ``s(r)``; the plan then asks ``s(r_d) - r_d / K``
        more steering than the linear model along the reference preview (:meth:`feedforward`).
    offset : {"bias", "integral"}
        Offset-free control from the heading observer's steering bias, or from the integral of
        the tracking error (see the module docstring).
    q_z : float
        Weight of the integral of the tracking error [1/(rad s)^2] (``offset="integral"``).
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
    q_d: float = 0.0
    reference: ReferenceModel | None = None
    replan: float | None = None
    steering: object = None
    offset: str = "bias"
    q_z: float = 0.0
    _solver: object = field(default=None, init=False, repr=False)

    MEMORY_LOG = ("chi_d", "r_d", "e")

    def __post_init__(self):
        for name in ("period", "steer_max", "rate_max", "r_max", "q_e", "r_u"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"MPC {name} must be positive and finite, got {v}")
        if not (np.isfinite(self.q_d) and self.q_d >= 0):
            raise InputError(f"MPC q_d must be non-negative and finite, got {self.q_d}")
        if self.offset not in ("bias", "integral"):
            raise InputError(f"MPC offset must be 'bias' or 'integral', got {self.offset!r}")
        if not (np.isfinite(self.q_z) and (self.q_z > 0 if self.integral else self.q_z == 0)):
            raise InputError(f"MPC q_z = {self.q_z}: the integral's weight must be positive and finite with "
                             "offset='integral' and 0 without it")
        if self.replan is not None and not (np.isfinite(self.replan) and 0 < self.replan <= self.period):
            raise InputError(f"MPC replan must be in (0, period], got {self.replan}")
        if int(self.horizon) != self.horizon or self.horizon < 2:
            raise InputError(f"MPC horizon must be an integer >= 2, got {self.horizon}")
        self._solver = self._build()

    @property
    def integral(self) -> bool:
        """Whether the plan carries the integral of the tracking error (``offset="integral"``)."""
        return self.offset == "integral"

    @property
    def order(self) -> int:
        """Order of the Nomoto prediction model (2 when ``T1, T2, T3`` are known)."""
        return 2 if self.nomoto.second_order else 1

    def feedforward(self, r):
        """``f(r) = s(r) - r / K``: the steady steering the nonlinear ship needs at the rate of turn
        ``r`` beyond the linear model's (0 without a steering table).

        Parameters
        ----------
        r : float or casadi.MX
            Rate of turn [rad/s].
        """
        if self.steering is None:
            return 0.0 * r
        return self.steering(r) - r / self.nomoto.K

    def disturbance(self, bias, rate0, rates):
        """The disturbance ``w_k = b - (f(r_k) + f(r_{k+1})) / 2`` of each step (``1 x N``): the bias
        less the extra steady steering at the reference rate over the step (its ends averaged).

        Parameters
        ----------
        bias : float or casadi.MX
            Steering bias estimate.
        rate0 : float or casadi.MX
            Reference rate at the start of the horizon [rad/s].
        rates : array or casadi.MX
            Reference rate at the end of each step (``1 x N``, the preview's second row).
        """
        N = int(self.horizon)
        r = ca.horzcat(_casadi(rate0), ca.reshape(_casadi(rates), 1, N))
        f = ca.horzcat(*[self.feedforward(r[0, k]) for k in range(N + 1)])
        return _like(_casadi(bias) - 0.5 * (f[0, :N] + f[0, 1:]), bias, rate0, rates)

    def reference_steering(self, ref0, previews):
        """The reference steering ``s(r_d) + (T / K) a_d`` (``s(r) = r / K`` without a steering
        table) at the start and the end of each step (``1 x (N + 1)``).

        Parameters
        ----------
        ref0 : sequence
            Reference rate and acceleration at the start of the horizon.
        previews : array or casadi.MX
            Reference rate and acceleration at the end of each step (``2 x N``).
        """
        N, K, m = int(self.horizon), self.nomoto.K, self.nomoto.T / self.nomoto.K
        p = _casadi(previews)
        r = ca.horzcat(_casadi(ref0[0]), ca.reshape(p[0, :], 1, N))
        a = ca.horzcat(_casadi(ref0[1]), ca.reshape(p[1, :], 1, N))
        steady = ca.horzcat(*[self.feedforward(r[0, k]) + r[0, k] / K for k in range(N + 1)])
        return _like(steady + m * a, *ref0, previews)

    def steering_rates(self, ref0, previews):
        """Rate of the reference steering (:meth:`reference_steering`) over each step (``1 x N``):
        ``u_d,k`` of the cost.

        Parameters
        ----------
        ref0 : sequence
            Reference rate and acceleration at the start of the horizon.
        previews : array or casadi.MX
            Reference rate and acceleration at the end of each step (``2 x N``).
        """
        d = self.reference_steering(ref0, previews)
        return (d[:, 1:] - d[:, :-1]) / self.period

    def model(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact discretisation ``x+ = A x + B u + E b`` at ``period`` of ``[e, r, delta]`` (first
        order) or ``[e, r, xi, delta]`` (second order, the observer form of
        :meth:`Nomoto.system <casship.autopilot.nomoto.Nomoto.system>`), with the integral ``z``
        of ``e`` before the steering when the plan carries it (:attr:`integral`)."""
        sys = self.nomoto.system(self.order)
        m = sys.nstates
        n = m + self.integral
        Ac = np.zeros((n + 1, n + 1))
        Ac[:m, :m], Ac[:m, n] = sys.A, np.ravel(sys.B)                 # steering is the last state
        if self.integral:
            Ac[m, 0] = 1.0                                              # z' = e
        Bc = np.zeros((n + 1, 2))
        Bc[n, 0], Bc[:m, 1] = 1.0, np.ravel(sys.B)                     # columns: u (rate), b (bias)
        M = expm(np.block([[Ac, Bc], [np.zeros((2, n + 3))]]) * self.period)
        return M[:n + 1, :n + 1], M[:n + 1, n + 1:n + 2], M[:n + 1, n + 2:n + 3]

    def _build(self) -> ca.Function:
        """The QP in optimal-control form for HPIPM (``casadi.qpsol``, the stage structure detected
        from the variable and constraint order): variables ``[x0 u0 x1 u1 ... xN]`` with ``u_k`` the
        steering rate and a slack ``s_k >= 0`` of the turn-rate limit, constraints stage by stage:
        the model ``A x_k + B u_k + E w_k - x_{k+1} = 0``, then ``|r_k| <= r_max + s_k`` (soft: an
        estimated rate a little above the limit must not make the problem infeasible; an exact
        penalty on the slack makes the limit hard whenever it can be met), bounds on the steering
        and its rate, ``x0`` fixed by its bounds. Returns ``mpc(x0, b, target, U_guess) -> (u0, X,
        U)`` (an MX Function; ``b`` the disturbance ``w`` of each step, ``1 x N``, or one number for
        all; ``target`` the course error and rate of each step and, with :attr:`integral`, the
        integral's; the optional ``u_ref`` and ``steer_ref``, ``1 x N``, the steering rate and steering the
        cost measures from, default 0)."""
        A, B, E = (ca.DM(M) for M in self.model())
        N, nx = int(self.horizon), A.shape[0]
        X = [ca.SX.sym(f"x{k}", nx) for k in range(N + 1)]
        U = [ca.SX.sym(f"u{k}", 2) for k in range(N)]
        rows = 2 + self.integral
        b, target, uref = ca.SX.sym("b", 1, N), ca.SX.sym("target", rows, N), ca.SX.sym("u_ref", 1, N)
        sref = ca.SX.sym("steer_ref", 1, N)
        # exact (l1) penalty on the slack: the largest price the cost can put on the rate of turn of
        # one step (a course error of pi on every later step, moved by the period) bounds the
        # multiplier; a small quadratic term keeps the Hessian definite. (A larger weight only
        # slows the interior point down.)
        l_slack = 2 * (self.q_e * np.pi + 2 * self.q_r * self.r_max) * N * self.period
        q_slack = l_slack / self.r_max
        z, g, lbg, ubg, cost = [], [], [], [], 0
        for k in range(N):
            z += [X[k], U[k]]
            g.append(ca.mtimes(A, X[k]) + B * U[k][0] + E * b[0, k] - X[k + 1])
            lbg += [0.0] * nx
            ubg += [0.0] * nx
            if k > 0:
                g.append(ca.vertcat(X[k][1] - U[k][1], X[k][1] + U[k][1]))
                lbg += [-np.inf, -self.r_max]
                ubg += [self.r_max, np.inf]
            cost += (self.q_e * (X[k + 1][0] - target[0, k]) ** 2 + self.q_r * (X[k + 1][1] - target[1, k]) ** 2
                     + self.r_u * (U[k][0] - uref[0, k]) ** 2 + q_slack * U[k][1] ** 2 + l_slack * U[k][1])
            if self.q_d:
                cost += self.q_d * (X[k + 1][nx - 1] - sref[0, k]) ** 2
            if self.integral:
                cost += self.q_z * (X[k + 1][nx - 2] - target[2, k]) ** 2
        z.append(X[N])
        qp = ca.qpsol("mpc_qp", "hpipm", {"x": ca.vertcat(*z), "f": cost, "g": ca.vertcat(*g),
                                          "p": ca.vertcat(ca.vec(b), ca.vec(target), ca.vec(uref), ca.vec(sref))},
                      {"error_on_fail": False, "print_time": False})
        # bounds: x0 fixed; the steering limited from x1 on; course error, rate and the internal
        # state of the second-order model far outside any plan (HPIPM wants finite bounds)
        ix = [k * (nx + 2) for k in range(N + 1)]
        iu = [k * (nx + 2) + nx for k in range(N)]
        nv = N * (nx + 2) + nx
        lo, hi = np.full(nv, -1e4), np.full(nv, 1e4)
        for k in range(1, N + 1):
            lo[ix[k] + nx - 1], hi[ix[k] + nx - 1] = -self.steer_max, self.steer_max
        lo[iu], hi[iu] = -self.rate_max, self.rate_max
        lo[[i + 1 for i in iu]] = 0.0
        x0, bm = ca.MX.sym("x0", nx), ca.MX.sym("b", 1, N)
        tm, U_guess, um = ca.MX.sym("target", rows, N), ca.MX.sym("U_guess", 1, N), ca.MX.sym("u_ref", 1, N)
        sm = ca.MX.sym("steer_ref", 1, N)
        lbx = ca.vertcat(x0, ca.DM(lo[nx:]))
        ubx = ca.vertcat(x0, ca.DM(hi[nx:]))
        guess = ca.MX.zeros(nv)
        guess[iu] = U_guess.T
        sol = qp(x0=guess, p=ca.vertcat(ca.vec(bm), ca.vec(tm), ca.vec(um), ca.vec(sm)), lbx=lbx, ubx=ubx, lbg=ca.DM(lbg),
                 ubg=ca.DM(ubg))
        zs = sol["x"]
        Xs = ca.horzcat(*[zs[ix[k]:ix[k] + nx] for k in range(N + 1)])
        Us = ca.horzcat(*[zs[iu[k]] for k in range(N)])
        return ca.Function("mpc", [x0, bm, tm, U_guess, um, sm], [Us[0, 0], Xs, Us],
                           ["x0", "b", "target", "U_guess", "u_ref", "steer_ref"], ["u0", "X", "U"])

    def preview_matrix(self, rows: int = 2) -> np.ndarray:
        """``(rows N, 3)`` matrix taking the reference model's state relative to the command (a fixed
        point) to its course error and rate (``rows = 3``: and acceleration) over the horizon, step
        by step (the linear model, no rate saturation, stepped exactly at ``period``).

        Parameters
        ----------
        rows : {2, 3}
            Course error and rate, or also the acceleration.
        """
        N = int(self.horizon)
        if self.reference is None:
            return np.zeros((rows * N, 3))
        Ad = expm(np.asarray(self.reference.system().A) * self.period)
        out, M = [], np.eye(3)
        for _ in range(N):
            M = Ad @ M
            out.append(M[:rows])
        return np.vstack(out)

    def integral_preview(self) -> np.ndarray:
        """``(N, 3)`` matrix taking the reference model's state relative to the command to the
        integral of its course error from now to the end of each step (exact for the linear model:
        the last row of ``expm`` of the model with an integrator on its first state).
        """
        N = int(self.horizon)
        if self.reference is None:
            return np.zeros((N, 3))
        A = np.zeros((4, 4))
        A[:3, :3], A[3, 0] = np.asarray(self.reference.system().A), 1.0
        step = expm(A * self.period)
        Ad, Phi = step[:3, :3], step[3, :3]
        out, M, acc = [], np.eye(3), np.zeros(3)
        for _ in range(N):
            acc = acc + Phi @ M
            M = Ad @ M
            out.append(acc)
        return np.vstack(out)

    def plan_inputs(self) -> ca.Function:
        """``plan_inputs(bias, z) -> (target, w, u_ref)``: from the reference model's state relative to
        the command ``z`` (course error, rate, acceleration) the preview of the course error and rate
        (``2 x N``; with :attr:`integral` a third row, the integral of the course error,
        :meth:`integral_preview`), the disturbance of each step (:meth:`disturbance`), the reference
        steering's rate and the steering that holds the model on the preview, the reference steering
        less the bias (:meth:`steering_rates`); one SX Function, called once per solve. With
        :attr:`integral` the bias is not used."""
        if getattr(self, "_inputs_fun", None) is None:
            N = int(self.horizon)
            bias, z = ca.SX.sym("bias"), ca.SX.sym("z", 3)
            b = 0 * bias if self.integral else bias
            full = ca.reshape(ca.mtimes(ca.DM(self.preview_matrix(3)), z), 3, N)
            z0 = z if self.reference is not None else ca.SX.zeros(3)
            target = full[:2, :]
            w = self.disturbance(b, z0[1], target[1, :])
            if self.integral:
                target = ca.vertcat(target, ca.mtimes(ca.DM(self.integral_preview()), z).T)
            u_ref = self.steering_rates([z0[1], z0[2]], full[1:, :])
            # the steering that holds the model on the preview cancels the bias too
            s_ref = self.reference_steering([z0[1], z0[2]], full[1:, :])[:, 1:] - b
            self._inputs_fun = ca.Function("mpc_plan_inputs", [bias, z], [target, w, u_ref, s_ref], ["bias", "z"],
                                           ["target", "w", "u_ref", "steer_ref"])
        return self._inputs_fun

    def _preview(self, xr: np.ndarray, ref: float, rows: int = 2) -> np.ndarray:
        """Course error and rate (and acceleration) of the reference model over the horizon
        (``rows x N``)."""
        z = np.array([float(wrap(xr[0] - ref)), xr[1], xr[2]])
        return (self.preview_matrix(rows) @ z).reshape(int(self.horizon), rows).T

    def law(self, dt: float) -> "MPCLaw":
        """This MPC as the law of the compiled closed loop at loop period ``dt`` (:class:`MPCLaw`).

        Parameters
        ----------
        dt : float
            Loop period [s].
        """
        return MPCLaw(self, dt)

    def memory0(self, chi0: float = 0.0) -> dict:
        """Initial controller memory: the command at rest, no plan.

        Parameters
        ----------
        chi0 : float
            Initial course (or heading) of the reference model [rad].
        """
        N, nx = int(self.horizon), 3 + (self.order == 2) + self.integral
        return {"steer_cmd": 0.0, "rate": 0.0, "X": np.zeros((nx, N + 1)), "U": np.zeros((1, N)), "count": 0,
                "xr": np.array([chi0, 0.0, 0.0]), "integral": 0.0}

    def plan_start(self, e, r, delta, w0, integral):
        """The plan's start state from the course error ``e``, the rate ``r``, the steering command
        ``delta``, the first step's disturbance ``w0`` and the integral of the tracking error (used
        with :attr:`integral`); numbers or CasADi expressions. The second-order model's internal
        state is the one with ``r' = 0`` (the rate is estimated, not its change).

        Parameters
        ----------
        e, r : float or casadi.MX
            Course error to the command [rad] and rate [rad/s].
        delta : float or casadi.MX
            Steering command.
        w0 : float or casadi.MX
            Disturbance of the first step.
        integral : float or casadi.MX
            Integral of the tracking error [rad s].
        """
        x = [e, r]
        if self.order == 2:
            sys = self.nomoto.system(2)
            x.append(-float(sys.A[1, 1]) * r - float(sys.B[1, 0]) * (delta + w0))
        x += [integral] * self.integral + [delta]
        return _like(ca.vertcat(*[_casadi(v) for v in x]), e, r, delta, w0, integral)

    def integral_step(self, integral, e, cmd, dt):
        """The integral of the tracking error ``e = wrap(chi - chi_d)`` one sample on, held while the
        command ``cmd`` is at its limit and ``e`` would drive it further (the PID law's anti-windup);
        numbers or CasADi expressions.

        Parameters
        ----------
        integral : float or casadi.MX
            Integral so far [rad s].
        e : float or casadi.MX
            Tracking error of this sample [rad].
        cmd : float or casadi.MX
            Steering command of the previous sample.
        dt : float
            Loop period [s].
        """
        hold = ca.logic_or(ca.logic_and(cmd >= self.steer_max, e < 0), ca.logic_and(cmd <= -self.steer_max, e > 0))
        out = ca.if_else(hold, integral, integral + dt * e)
        return out if isinstance(out, (ca.MX, ca.SX)) else float(out)

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
            Steering bias estimate (the heading observer's ``b``); the plan's disturbance adds the
            extra steady steering along the preview (:meth:`disturbance`).

        Returns
        -------
        (dict, float, dict)
            Memory, steering command, and ``chi_d`` (reference), ``r_d`` (planned rate of turn),
            ``e`` (course error).
        """
        every = max(1, int(round((self.replan or self.period) / dt)))
        e = float(wrap(chi - ref))
        mem = dict(memory)
        if self.reference is not None:      # the reference model runs at the loop rate, as in the PID law
            mem["xr"] = np.asarray(self._ref_step()(mem["xr"], ref, dt)).ravel()
        if mem["count"] % every == 0:
            U_guess = np.hstack([mem["U"][:, 1:], mem["U"][:, -1:]])          # the last plan, shifted
            delta = mem["steer_cmd"]
            z = np.array([float(wrap(mem["xr"][0] - ref)), mem["xr"][1], mem["xr"][2]])
            target, w, u_ref, s_ref = (np.asarray(v) for v in self.plan_inputs()(bias, z))   # as the compiled law
            x0 = self.plan_start(e, r, delta, w[0, 0], mem["integral"]).ravel()
            out = self._solve({"x0": x0, "b": w, "target": target, "U_guess": U_guess, "u_ref": u_ref,
                               "steer_ref": s_ref})
            mem["X"], mem["U"] = np.asarray(out["X"]), np.asarray(out["U"])
            self._check(mem["X"], mem["U"], x0, w)
            mem["rate"] = float(out["u0"])
        mem["count"] += 1
        chi_d = float(mem["xr"][0]) if self.reference is not None else ref
        mem["integral"] = self.integral_step(mem["integral"], float(wrap(chi - chi_d)), mem["steer_cmd"], dt)
        cmd = float(np.clip(mem["steer_cmd"] + mem["rate"] * dt, -self.steer_max, self.steer_max))
        mem["steer_cmd"] = cmd
        return mem, cmd, {"chi_d": chi_d, "r_d": float(mem["X"][1, 1]), "e": float(wrap(chi - chi_d))}

    def _solve(self, args: dict) -> dict:
        """One QP solve (HPIPM)."""
        return self._solver.call(args)

    def _check(self, X, U, x0, bias, tol: float = 1e-6) -> None:
        """Raise ``RuntimeError`` when the plan breaks a limit or the model (a failed QP solve)."""
        A, B, E = self.model()
        n = X.shape[0]
        bad = []
        if np.max(np.abs(U)) > self.rate_max * (1 + tol) + 1e-12:
            bad.append("steering rate")
        if np.max(np.abs(X[n - 1, 1:])) > self.steer_max * (1 + tol) + 1e-12:
            bad.append("steering angle")
        resid = X[:, 1:] - (A @ X[:, :-1] + B @ U + E @ np.broadcast_to(np.reshape(bias, (1, -1)), U.shape))
        scale = 1 + np.max(np.abs(X))
        if np.max(np.abs(resid)) > 1e-6 * scale or np.max(np.abs(X[:, 0] - x0)) > 1e-6 * scale:
            bad.append("the model")
        if bad:
            from ..errors import SolverError

            raise SolverError(f"the MPC's QP solve failed (HPIPM): the plan breaks {', '.join(bad)}")

    def _ref_step(self) -> ca.Function:
        if getattr(self, "_ref_fun", None) is None:
            xr, r, h = ca.SX.sym("xr", 3), ca.SX.sym("ref"), ca.SX.sym("dt")
            self._ref_fun = ca.Function("ref_step", [xr, r, h], [self.reference.symbolic_step(xr, r, h)])
        return self._ref_fun


class MPCLaw:
    """The MPC as the law of the compiled closed loop (:meth:`MPCAutopilot.law`).

    Memory: the reference model ``chi_d, r_d, a_d``, the steering command and the planned rate, a
    sample counter, the integral of the tracking error (:meth:`MPCAutopilot.integral_step`; 0
    unless the plan carries it), and the last plan of steering rates (the warm start). Once per MPC period
    (``casadi.Function.conditional`` on the counter) the QP is solved from the present course
    error, rate, steering command and the heading observer's bias, against the preview of the
    reference model; in between the command ramps at the planned rate. The log's ``a_d`` is the
    planned rate of change of the steering.

    Parameters
    ----------
    mpc : MPCAutopilot
    dt : float
        Loop period [s].
    """

    mx_law = True

    def __init__(self, mpc: "MPCAutopilot", dt: float):
        if not (np.isfinite(dt) and dt > 0):
            raise InputError(f"dt must be positive, got {dt}")
        self.mpc, self.dt = mpc, float(dt)
        self.every = max(1, int(round((mpc.replan or mpc.period) / dt)))
        N = int(mpc.horizon)
        self.MEMORY = ("chi_d", "r_d", "a_d", "steer_cmd", "rate", "count", "integral") + tuple(
            f"plan{k}" for k in range(N))
        self.reference = mpc.reference
        self._function = None

    def memory0(self, chi0: float = 0.0) -> np.ndarray:
        """Reference model at rest at ``chi0``, no command, no plan.

        Parameters
        ----------
        chi0 : float
            Initial course (or heading) [rad].
        """
        return np.concatenate([[chi0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], np.zeros(int(self.mpc.horizon))])

    @property
    def function(self) -> ca.Function:
        """``mpc_law(memory, ref, chi, r, dt, speed, steering, bias) -> (memory_next, steer, chi_d,
        r_d, a_d, e)`` (an MX Function: the QP solve is a call node)."""
        if self._function is None:
            self._function = self._build()
        return self._function

    def _build(self) -> ca.Function:
        mpc, N = self.mpc, int(self.mpc.horizon)
        n = len(self.MEMORY)
        mem, ref, chi, r = ca.MX.sym("memory", n), ca.MX.sym("ref"), ca.MX.sym("chi"), ca.MX.sym("r")
        dt, U, st, bias = ca.MX.sym("dt"), ca.MX.sym("speed"), ca.MX.sym("steering"), ca.MX.sym("bias")
        xr, cmd, rate, count, integral, plan = mem[0:3], mem[3], mem[4], mem[5], mem[6], mem[7:].T
        xr_next = mpc._ref_step()(xr, ref, self.dt) if mpc.reference is not None else ca.vertcat(ref, 0, 0)
        e = ca.atan2(ca.sin(chi - ref), ca.cos(chi - ref))
        z = ca.vertcat(ca.atan2(ca.sin(xr_next[0] - ref), ca.cos(xr_next[0] - ref)), xr_next[1], xr_next[2])
        # the solve branch: preview, disturbance and reference steering are made only when a solve is due
        a = [ca.MX.sym(k, *sh) for k, sh in (("e", (1, 1)), ("r", (1, 1)), ("cmd", (1, 1)), ("bias", (1, 1)),
                                               ("z", (3, 1)), ("plan", (1, N)), ("rate", (1, 1)), ("integral", (1, 1)))]
        target, w, u_ref, s_ref = mpc.plan_inputs()(a[3], a[4])
        x0 = mpc.plan_start(a[0], a[1], a[2], w[0, 0], a[7])
        shifted = ca.horzcat(a[5][:, 1:], a[5][:, -1:])
        out = mpc._solver.call({"x0": x0, "b": w, "target": target, "U_guess": shifted, "u_ref": u_ref,
                                "steer_ref": s_ref})
        solve = ca.Function("mpc_solve", a, [out["u0"], out["U"]])
        hold = ca.Function("mpc_hold", a, [a[6], a[5]])
        branch = ca.Function.conditional("mpc_period", [hold], solve)
        due = ca.if_else(ca.fmod(count, self.every) == 0, 1, 0)
        rate_next, plan_next = branch(due, e, r, cmd, bias, z, plan, rate, integral)
        cmd_next = ca.fmin(ca.fmax(cmd + rate_next * self.dt, -mpc.steer_max), mpc.steer_max)
        chi_d = xr_next[0]
        integral_next = mpc.integral_step(integral, ca.atan2(ca.sin(chi - chi_d), ca.cos(chi - chi_d)), cmd, self.dt)
        return ca.Function("mpc_law", [mem, ref, chi, r, dt, U, st, bias],
                           [ca.vertcat(xr_next, cmd_next, rate_next, count + 1, integral_next, plan_next.T), cmd_next,
                            chi_d,
                            xr_next[1], rate_next, ca.atan2(ca.sin(chi - chi_d), ca.cos(chi - chi_d))],
                           ["memory", "ref", "chi", "r", "dt", "speed", "steering", "bias"],
                           ["memory_next", "steer", "chi_d", "r_d", "a_d", "e"])
