"""Course and heading autopilots: Nomoto models, pole placement and LQR designs, reference model,
rudder limits with anti-windup, python-control margins and closed-loop validation on the nonlinear
ship with sensors and an estimator in the loop.

Conventions: the steering input (rudder angle, or a yaw moment for a thruster-steered craft) turns
the craft with the sign of the Nomoto gain ``K`` (positive ``K``: positive steering increases the
heading). Designs work on the first-order Nomoto model written as ``m r' + d r = delta`` with
``m = T/K`` and ``d = 1/K`` (Fossen 2021, Sec. 15.3), which stays finite for course-unstable ships
(``T < 0``) and for ``T`` near infinity.

Control law (course ``chi`` or heading ``psi``, the same form)::

    delta = m a_d + d r_d - (Kp e + Kd (r - r_d) + Ki z),    e = wrap(chi - chi_d),    z' = e

with ``chi_d, r_d, a_d`` from a third-order reference model with rate saturation, the command
saturated and rate limited, and the integrator clamped while the command saturates (anti-windup).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import casadi as ca
import control
import numpy as np

from ._fast import BufferedCall
from .angles import wrap, wrap_sym
from .data import Dataset, Gaussian
from .discretize import discretize
from .linear import linearize, trim
from .model import Model, ModelBuilder

__all__ = ["Nomoto", "nomoto_from_model", "fit_nomoto", "PIDGains", "pid_pole_placement", "lqr_design",
           "ReferenceModel", "Autopilot", "loop_transfer", "closed_loop_tf", "margins", "SteeringPlant",
           "steering_model", "twin_propeller_allocation", "twin_propeller_yaw_limit", "ClosedLoopResult",
           "simulate_autopilot", "step_metrics", "course_scenario", "plot_design", "plot_closed_loop", "Design",
           "design_autopilot"]


# ---------------------------------------------------------------------------------------------------
# Nomoto models
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Nomoto:
    """Nomoto steering model ``r/delta = K (1 + T3 s) / ((1 + T1 s)(1 + T2 s))``.

    The first-order model has ``T = T1 + T2 - T3``. ``m = T/K`` and ``d = 1/K`` are the inertia-
    and damping-like coefficients of ``m r' + d r = delta`` used by the designs.

    Attributes
    ----------
    K : float
        Gain [1/s] (or [1/(N m s)] for a yaw-moment input).
    T : float
        First-order time constant [s] (negative for a course-unstable ship).
    T1, T2, T3 : float
        Second-order time constants (NaN when only a first-order model is known).
    source : str
        Where the numbers came from.
    """

    K: float
    T: float
    T1: float = float("nan")
    T2: float = float("nan")
    T3: float = float("nan")
    source: str = ""

    def __post_init__(self):
        for name in ("K", "T"):
            v = getattr(self, name)
            if not np.isfinite(v) or v == 0:
                raise ValueError(f"Nomoto {name} must be finite and non-zero, got {v}")

    @property
    def m(self) -> float:
        return self.T / self.K

    @property
    def d(self) -> float:
        return 1.0 / self.K

    @property
    def second_order(self) -> bool:
        return bool(np.isfinite(self.T1) and np.isfinite(self.T2) and np.isfinite(self.T3))

    def yaw_rate_tf(self, order: int = 1) -> control.TransferFunction:
        """Transfer function ``r/delta`` (order 1 or 2)."""
        if order == 2:
            if not self.second_order:
                raise ValueError("this Nomoto model has no second-order time constants")
            return control.tf([self.K * self.T3, self.K], np.polymul([self.T1, 1], [self.T2, 1]))
        return control.tf([self.K], [self.T, 1])

    def heading_tf(self, order: int = 1) -> control.TransferFunction:
        """Transfer function ``psi/delta`` (the yaw rate integrated)."""
        return self.yaw_rate_tf(order) * control.tf([1], [1, 0])

    def as_dict(self) -> dict:
        return {"K": self.K, "T": self.T, "T1": self.T1, "T2": self.T2, "T3": self.T3, "source": self.source}


def nomoto_from_model(model: Model, x=None, u=None, p=None, *, steer: str = "delta", yaw_rate: str = "r",
                      tol: float = 1e-6) -> Nomoto:
    """Nomoto model from the exact linearisation of ``model`` at the operating point ``(x, u, p)``.

    The transfer function from ``steer`` to ``yaw_rate`` is reduced to a minimal realisation
    (integrators of position and heading and a decoupled surge mode drop out); one remaining pole
    gives a first-order model, two poles and one zero the second-order one
    (``K, T1, T2, T3``, with ``T = T1 + T2 - T3``).

    Raises
    ------
    ValueError
        If the reduced transfer function has more than two poles (e.g. a rudder actuator state:
        linearise with the actual rudder angle as input instead), or a zero gain.
    """
    sys = linearize(model, x, u, p, outputs=[yaw_rate])
    siso = sys[0, model.index(steer, "input")]
    tf = control.minreal(control.ss2tf(siso), tol=tol, verbose=False)
    if not np.any(np.abs(np.ravel(tf.num[0][0])) > 0):
        raise ValueError(f"{steer!r} does not move {yaw_rate!r} at this operating point")
    poles = np.real_if_close(tf.poles())
    zeros = np.real_if_close(tf.zeros())
    num, den = np.ravel(tf.num[0][0]), np.ravel(tf.den[0][0])
    K = float(num[-1] / den[-1]) if den[-1] != 0 else float("nan")
    if poles.size == 1:
        return Nomoto(K=K, T=float(-1 / poles[0].real), source=f"linearisation of {model.name}")
    if poles.size == 2 and zeros.size <= 1 and np.all(np.isreal(poles)):
        T1, T2 = sorted((float(-1 / pp.real) for pp in poles), key=abs, reverse=True)
        T3 = float(-1 / zeros[0].real) if zeros.size else 0.0
        return Nomoto(K=K, T=T1 + T2 - T3, T1=T1, T2=T2, T3=T3, source=f"linearisation of {model.name}")
    if poles.size == 2 and zeros.size <= 1 and den[-1] != 0 and num[-1] != 0:
        # oscillatory sway-yaw mode: first-order equivalent from the coefficients
        a1, a0 = den[-2] / den[-3], den[-1] / den[-3]
        T3 = float(num[-2] / num[-1]) if num.size > 1 else 0.0
        return Nomoto(K=K, T=float(a1 / a0) - T3, T3=T3, source=f"linearisation of {model.name} (complex poles)")
    raise ValueError(f"the reduced {steer!r} -> {yaw_rate!r} transfer function of {model.name!r} has poles "
                     f"{np.round(poles, 6).tolist()} and zeros {np.round(zeros, 6).tolist()}; a Nomoto model "
                     "needs one pole, or two real poles and at most one zero")


def fit_nomoto(data: Dataset | Sequence[Dataset], *, steer: str = "delta", heading: str = "psi",
               guess: Nomoto | None = None, heading_var: float = 1e-6, bias: bool = True):
    """First-order Nomoto model (K, T and a rudder bias) fitted to heading records, e.g. zig-zags.

    Maximum likelihood through an EKF on the first-order Nomoto model
    (:class:`casship.identify.MLEProblem`), with a small process noise so that the fit is close to
    output error. The records need columns ``steer`` (rad) and ``heading`` (rad; NaN = not measured);
    the yaw rate starts at zero (records start on a straight course).

    Returns
    -------
    (Nomoto, FitResult)
    """
    from .identify import MLEProblem
    from .models import nomoto_first_order

    records = [data] if isinstance(data, Dataset) else list(data)
    if not records:
        raise ValueError("fit_nomoto needs at least one record")
    renamed = []
    for rec in records:
        for col in (steer, heading):
            if col not in rec:
                raise ValueError(f"record has no column {col!r}; columns: {list(rec.names)}")
        renamed.append(Dataset(rec.t, {"delta": rec[steer], "psi": rec[heading]}))
    g = guess or Nomoto(K=0.1, T=50.0)
    model = nomoto_first_order(K=g.K, T=g.T, rudder_bias=bias)
    dt = float(np.median(np.diff(renamed[0].t)))
    ekf_cls = __import__("casship.estimators", fromlist=["EKF"]).EKF
    ekf = ekf_cls(discretize(model, dt, "rk4"), Q=1e-12, R=heading_var)
    free = ["K", "T"] + (["delta_0"] if bias else [])
    x0 = [Gaussian(np.array([rec["psi"][np.isfinite(rec["psi"])][0], 0.0]), np.diag([heading_var, 1e-10]))
          for rec in renamed]
    fit = MLEProblem(ekf, renamed, free=free, x0=x0, scale={"K": abs(g.K), "T": abs(g.T)}).solve(
        guess={"K": g.K, "T": g.T})
    nom = Nomoto(K=fit.params["K"], T=fit.params["T"], source="fit to heading records (MLE through an EKF)")
    return nom, fit


# ---------------------------------------------------------------------------------------------------
# Designs
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PIDGains:
    """Gains of the control law in the module docstring plus the feed-forward model ``m, d``."""

    Kp: float
    Kd: float
    Ki: float
    m: float
    d: float
    method: str = ""
    poles: tuple = ()

    def as_dict(self) -> dict:
        return {"Kp": self.Kp, "Kd": self.Kd, "Ki": self.Ki, "m": self.m, "d": self.d, "method": self.method,
                "poles": [complex(p) if np.iscomplex(p) else float(np.real(p)) for p in self.poles]}


def pid_pole_placement(nomoto: Nomoto, wn: float, zeta: float = 1.0, *, integral: str | None = "fossen",
                       wi_ratio: float = 0.1) -> PIDGains:
    """PID by pole placement on the first-order Nomoto model (Fossen 2021, Sec. 15.3.4).

    ``integral="fossen"`` (MSS/PVS): ``Kp = m wn^2``, ``Kd = 2 zeta wn m - d``, ``Ki = wn/10 Kp``
    (the PD loop has its poles at ``s^2 + 2 zeta wn s + wn^2``; the slow integrator moves them
    slightly). ``integral="exact"``: the third-order loop ``m s^3 + (d + Kd) s^2 + Kp s + Ki``
    gets exactly the poles of ``(s^2 + 2 zeta wn s + wn^2)(s + wi)``, ``wi = wi_ratio wn``.
    ``integral=None``: PD only.
    """
    if not (np.isfinite(wn) and wn > 0):
        raise ValueError(f"wn must be positive, got {wn}")
    if not (np.isfinite(zeta) and zeta > 0):
        raise ValueError(f"zeta must be positive, got {zeta}")
    m, d = nomoto.m, nomoto.d
    pd_poles = np.roots([1, 2 * zeta * wn, wn**2])
    if integral is None:
        return PIDGains(m * wn**2, 2 * zeta * wn * m - d, 0.0, m, d, "pd-pole-placement", tuple(pd_poles))
    if integral == "fossen":
        Kp = m * wn**2
        return PIDGains(Kp, 2 * zeta * wn * m - d, wn / 10 * Kp, m, d, "pid-pole-placement-fossen",
                        tuple(pd_poles))
    if integral == "exact":
        wi = wi_ratio * wn
        return PIDGains(m * (wn**2 + 2 * zeta * wn * wi), m * (2 * zeta * wn + wi) - d, m * wn**2 * wi, m, d,
                        "pid-pole-placement-exact", tuple(np.append(pd_poles, -wi)))
    raise ValueError(f"integral must be 'fossen', 'exact' or None, got {integral!r}")


def lqr_design(nomoto: Nomoto, *, q_int: float, q_e: float, q_r: float = 0.0, r_delta: float = 1.0) -> PIDGains:
    """LQR with integral action on the first-order Nomoto model (``control.lqr``).

    State ``[z, e, r]`` with ``z' = e``, ``e' = r``, ``r' = -r/T + (K/T) delta``; cost
    ``int q_int z^2 + q_e e^2 + q_r r^2 + r_delta delta^2 dt``. The optimal feedback
    ``delta = -(k_z z + k_e e + k_r r)`` is returned as ``Ki = k_z, Kp = k_e, Kd = k_r``.
    """
    a, b = 1.0 / nomoto.T, nomoto.K / nomoto.T
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -a]])
    B = np.array([[0.0], [0.0], [b]])
    for name, v in (("q_int", q_int), ("q_e", q_e), ("q_r", q_r)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be >= 0, got {v}")
    if not (np.isfinite(r_delta) and r_delta > 0):
        raise ValueError(f"r_delta must be positive, got {r_delta}")
    Kx, _, E = control.lqr(A, B, np.diag([q_int, q_e, q_r]), np.array([[r_delta]]))
    k = np.ravel(Kx)
    return PIDGains(float(k[1]), float(k[2]), float(k[0]), nomoto.m, nomoto.d, "lqr-integral", tuple(E))


@dataclass(frozen=True)
class ReferenceModel:
    """Third-order reference model with rate saturation (MSS ``refModel.m``).

    ``a_d' = wn^3 (ref - chi_d) - (2 zeta + 1) wn^2 r_d - (2 zeta + 1) wn a_d``, ``r_d`` saturated
    at ``r_max`` (Euler steps, like MSS). ``r_max = inf`` gives the linear filter
    ``wn^3 / ((s + wn)(s^2 + 2 zeta wn s + wn^2))``.
    """

    wn: float
    zeta: float = 1.0
    r_max: float = float("inf")

    def __post_init__(self):
        if not (np.isfinite(self.wn) and self.wn > 0):
            raise ValueError(f"reference model wn must be positive, got {self.wn}")
        if not self.r_max > 0:
            raise ValueError(f"r_max must be positive, got {self.r_max}")

    def symbolic_step(self, xd, ref, dt):
        """One Euler step of ``[chi_d, r_d, a_d]`` (CasADi expressions)."""
        wn, z = self.wn, self.zeta
        e = wrap_sym(ref - xd[0])
        jerk = wn**3 * e - (2 * z + 1) * wn**2 * xd[1] - (2 * z + 1) * wn * xd[2]
        r_next = xd[1] + dt * xd[2]
        if np.isfinite(self.r_max):
            r_next = ca.fmin(ca.fmax(r_next, -self.r_max), self.r_max)
        return ca.vertcat(wrap_sym(xd[0] + dt * xd[1]), r_next, xd[2] + dt * jerk)

    def tf(self) -> control.TransferFunction:
        wn, z = self.wn, self.zeta
        return control.tf([wn**3], np.polymul([1, wn], [1, 2 * z * wn, wn**2]))

    def response(self, t, ref, x0=(0.0, 0.0, 0.0)) -> np.ndarray:
        """``(N, 3)`` array of ``chi_d, r_d, a_d`` for the command ``ref`` (array or constant) on the
        uniform grid ``t`` (one compiled fold)."""
        t = np.asarray(t, dtype=float)
        dt = float(t[1] - t[0])
        xd, r, h = ca.SX.sym("xd", 3), ca.SX.sym("ref"), ca.SX.sym("dt")
        F = ca.Function("ref_step", [xd, r, h], [self.symbolic_step(xd, r, h)])
        refs = np.broadcast_to(np.asarray(ref, dtype=float), t.shape)
        X = np.asarray(F.mapaccum(t.size - 1)(np.asarray(x0, float), refs[:-1][None, :], dt))
        return np.vstack([np.asarray(x0, float), X.T])


@dataclass(frozen=True)
class Autopilot:
    """PID/LQR course (or heading) autopilot with reference model, steering limits and anti-windup.

    Parameters
    ----------
    gains : PIDGains
    reference : ReferenceModel
    steer_max : float
        Saturation of the steering command (rudder angle [rad] or yaw moment).
    steer_rate_max : float
        Rate limit of the command [unit/s] (``inf`` for none).
    anti_windup : bool
        Stop integrating while the command saturates in the direction the integrator pushes.
    feedforward : bool
        Use ``m a_d + d r_d`` from the reference model.
    filter_T : float
        Time constant [s] of a first-order low-pass on the command before the limits (0 = none;
        MSS uses 1 s on the Mariner rudder command), against sensor noise on the rudder.
    """

    gains: PIDGains
    reference: ReferenceModel
    steer_max: float = float("inf")
    steer_rate_max: float = float("inf")
    anti_windup: bool = True
    feedforward: bool = True
    filter_T: float = 0.0

    def __post_init__(self):
        if not self.steer_max > 0 or not self.steer_rate_max > 0:
            raise ValueError("steer_max and steer_rate_max must be positive")
        if not (np.isfinite(self.filter_T) and self.filter_T >= 0):
            raise ValueError(f"filter_T must be >= 0, got {self.filter_T}")

    @property
    def function(self) -> ca.Function:
        """``autopilot(z, ref, chi, r, dt) -> (z_next, steer, chi_d, r_d, a_d, e)`` with the memory
        ``z = [chi_d, r_d, a_d, integral, steer_prev, filtered]``."""
        g = self.gains
        z, ref, chi, r, dt = ca.SX.sym("z", 6), ca.SX.sym("ref"), ca.SX.sym("chi"), ca.SX.sym("r"), ca.SX.sym("dt")
        chi_d, r_d, a_d, integ, prev, filt = z[0], z[1], z[2], z[3], z[4], z[5]
        e = wrap_sym(chi - chi_d)
        ff = (g.m * a_d + g.d * r_d) if self.feedforward else 0
        raw = ff - (g.Kp * e + g.Kd * (r - r_d) + g.Ki * integ)
        if self.filter_T > 0:
            alpha = dt / (self.filter_T + dt)         # backward-Euler first-order low-pass
            filt_next = filt + alpha * (raw - filt)
        else:
            filt_next = raw
        sat = ca.fmin(ca.fmax(filt_next, -self.steer_max), self.steer_max) if np.isfinite(self.steer_max) \
            else filt_next
        if np.isfinite(self.steer_rate_max):
            step = self.steer_rate_max * dt
            cmd = ca.fmin(ca.fmax(sat, prev - step), prev + step)
        else:
            cmd = sat
        grow = g.Ki * e      # d(raw)/dt from the integrator is -Ki e
        if self.anti_windup and np.isfinite(self.steer_max):
            hold = ca.logic_or(ca.logic_and(raw > self.steer_max, grow < 0),
                               ca.logic_and(raw < -self.steer_max, grow > 0))
            integ_next = ca.if_else(hold, integ, integ + dt * e)
        else:
            integ_next = integ + dt * e
        xd_next = self.reference.symbolic_step(z[:3], ref, dt)
        z_next = ca.vertcat(xd_next, integ_next, cmd, filt_next)
        return ca.Function("autopilot", [z, ref, chi, r, dt], [z_next, cmd, chi_d, r_d, a_d, e],
                           ["z", "ref", "chi", "r", "dt"], ["z_next", "steer", "chi_d", "r_d", "a_d", "e"])


# ---------------------------------------------------------------------------------------------------
# Linear analysis
# ---------------------------------------------------------------------------------------------------
def loop_transfer(nomoto: Nomoto, gains: PIDGains, *, order: int = 1, actuator_T: float = 0.0,
                  delay: float = 0.0, filter_T: float = 0.0) -> control.TransferFunction:
    """Open-loop transfer function ``L = C(s) G(s)`` of the course loop (cut at the steering input).

    ``C(s) = Kp + Kd s + Ki/s`` (``Kd`` acts on the measured rate), ``G(s) = psi/delta`` of the
    Nomoto model of ``order``, times ``1/(1 + actuator_T s)`` (steering servo), ``1/(1 + filter_T s)``
    (command filter of :class:`Autopilot`) and a first-order Pade delay.
    """
    s = control.tf("s")
    C = gains.Kp + gains.Kd * s + gains.Ki / s
    L = C * nomoto.heading_tf(order)
    for tau in (actuator_T, filter_T):
        if tau > 0:
            L = L / (1 + tau * s)
    if delay > 0:
        num, den = control.pade(delay, 1)
        L = L * control.tf(num, den)
    return control.minreal(L, verbose=False)


def closed_loop_tf(nomoto: Nomoto, gains: PIDGains, **kw) -> control.TransferFunction:
    """Closed loop from the set-point to the course (no feed-forward): ``L / (1 + L)``."""
    return control.feedback(loop_transfer(nomoto, gains, **kw), 1)


def margins(L: control.TransferFunction) -> dict:
    """Stability margins of the loop ``L`` and closed-loop stability.

    Returns the upper gain margin (how much the loop gain may grow) and, for a conditionally
    stable loop (course-unstable ship), the lower gain margin (how much it may shrink), both in
    dB (``inf``/``-inf`` when absent), the phase margin [deg] at the gain crossover, the
    frequencies [rad/s] and whether the closed loop ``L/(1+L)`` is stable.
    """
    gms, pms, sms, wgs, wps, wss = control.stability_margins(L, returnall=True)
    gms, wgs = np.asarray(gms, dtype=float), np.asarray(wgs, dtype=float)
    up, lo = gms > 1, (gms < 1) & (gms > 0)
    gm_up = float(20 * np.log10(gms[up].min())) if up.any() else float("inf")
    gm_lo = float(20 * np.log10(gms[lo].max())) if lo.any() else float("-inf")
    w_up = float(wgs[up][np.argmin(gms[up])]) if up.any() else float("nan")
    pms, wps = np.asarray(pms, dtype=float), np.asarray(wps, dtype=float)
    k = int(np.argmin(pms)) if pms.size else None
    cl = control.feedback(L, 1)
    stable = bool(np.all(np.real(cl.poles()) < 0))
    return {"gain_margin_db": gm_up, "lower_gain_margin_db": gm_lo,
            "phase_margin_deg": float(pms[k]) if k is not None else float("inf"),
            "stability_margin": float(np.min(sms)) if np.size(sms) else float("nan"),
            "phase_crossover_rad_s": w_up, "gain_crossover_rad_s": float(wps[k]) if k is not None else float("nan"),
            "closed_loop_stable": stable}


def plot_design(L: control.TransferFunction, path, title: str = "", reference: ReferenceModel | None = None):
    """Bode plot of the loop and step response of the closed loop (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7, 9))
    w = np.logspace(-4, 1, 600) * max(1e-3, control.stability_margins(L)[4] or 1.0)
    mag, phase, w = control.frequency_response(L, w)
    axes[0].semilogx(w, 20 * np.log10(np.abs(mag)))
    axes[0].axhline(0, color="k", lw=0.5)
    axes[0].set_ylabel("|L| [dB]")
    axes[1].semilogx(w, np.degrees(np.unwrap(phase)))
    axes[1].axhline(-180, color="k", lw=0.5)
    axes[1].set_ylabel("phase [deg]")
    axes[1].set_xlabel("frequency [rad/s]")
    cl = control.feedback(L, 1)
    if reference is not None:
        cl = cl * reference.tf()
    resp = control.step_response(cl)
    axes[2].plot(resp.time, np.ravel(resp.outputs))
    axes[2].set_xlabel("time [s]")
    axes[2].set_ylabel("course / command")
    axes[0].set_title(title)
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------------
# Plants
# ---------------------------------------------------------------------------------------------------
def steering_model(model: Model, new_inputs: Sequence[str], allocation: Callable, name: str | None = None) -> Model:
    """A copy of ``model`` whose inputs are replaced by ``new_inputs`` through an allocation.

    ``allocation(new, p)`` receives dicts of the new input symbols and the model's parameter
    symbols by name and returns a dict old input name -> expression. Use it to steer a
    thruster-driven craft by a yaw moment: ``{"n1": ..., "n2": ...}`` from ``tau_X, tau_N``.
    """
    b = ModelBuilder(name or f"{model.name}+allocation", model.doc)
    xs = [b.state(v.name, unit=v.unit, angle=v.angle, doc=v.doc) for v in model.state_vars]
    ps = [b.param(v.name, v.value, bounds=(v.lower, v.upper), unit=v.unit, doc=v.doc, source=v.source)
          for v in model.param_vars]
    ws = [b.noise(v.name, unit=v.unit, doc=v.doc) for v in model.noise_vars]
    us = {n: b.input(n) for n in new_inputs}
    pd = dict(zip(model.param_names, ps))
    mapping = allocation(us, pd)
    missing = [n for n in model.input_names if n not in mapping]
    if missing:
        raise ValueError(f"allocation gives no expression for input(s) {missing} of {model.name!r}")
    old = ca.vertcat(model.x, model.p, model.w, model.u)
    new = ca.vertcat(*xs, *ps, *ws, *[ca.SX(mapping[n]) for n in model.input_names])
    xdot, y = ca.substitute([model.xdot, model.y], [old], [new])
    b.ode(**{n: xdot[i] for i, n in enumerate(model.state_names)})
    for i, v in enumerate(model.output_vars):
        b.output(v.name, y[i], unit=v.unit, angle=v.angle, doc=v.doc)
    b.meta.update(dict(model.meta))
    if model.vessel is not None:      # the new inputs are generalised forces, not rudders or propellers
        b.vessel = model.vessel.replace(rudders=(), propellers=())
    return b.build()


def twin_propeller_allocation(model: Model, names: tuple[str, str] = ("n1", "n2")):
    """Allocation ``tau_X, tau_N -> n1, n2`` for a craft steered by two propellers (e.g. the Otter).

    Thrust ``T = k n |n|`` (``k_pos`` ahead, ``k_neg`` astern) on lever arms ``-+ y_pont`` (port
    propeller ``n1``): ``tau_X = T1 + T2``, ``tau_N = y_pont (T1 - T2)``, inverted exactly. Reads
    ``k_pos``, ``k_neg`` and ``y_pont`` from the model's parameters. Use with :func:`steering_model`.
    """
    missing = [n for n in names if n not in model.input_names]
    missing += [k for k in ("k_pos", "k_neg", "y_pont") if k not in model.param_names]
    if missing:
        raise ValueError(f"twin-propeller allocation needs inputs {list(names)} and parameters k_pos, k_neg, "
                         f"y_pont; model {model.name!r} lacks {missing}")

    def alloc(new, p):
        out = {}
        for name, sign in zip(names, (1, -1)):
            T = new["tau_X"] / 2 + sign * new["tau_N"] / (2 * p["y_pont"])
            k = ca.if_else(T >= 0, p["k_pos"], p["k_neg"])
            out[name] = ca.sign(T) * ca.sqrt(ca.fabs(T) / k)
        return out
    return alloc


def twin_propeller_yaw_limit(model: Model, tau_X: float, p=None) -> float:
    """Largest yaw moment [N m] that keeps both propellers inside ``model.vessel.propeller_range``
    at surge force ``tau_X``."""
    pd = model.param_dict(model.params(p) if p is not None else None)
    if model.vessel is None or model.vessel.propeller_range is None:
        raise ValueError(f"model {model.name!r} has no vessel propeller_range")
    n_min, n_max = model.vessel.propeller_range
    l = pd["y_pont"]
    ahead = pd["k_pos"] * n_max**2
    astern = pd["k_neg"] * n_min**2
    limit = 2 * l * min(ahead - tau_X / 2, tau_X / 2 + astern)
    if limit <= 0:
        raise ValueError(f"surge force {tau_X} N leaves no yaw moment within the propeller limits")
    return float(limit)


@dataclass
class SteeringPlant:
    """A ship model seen by an autopilot: which input steers, which states are position and heading.

    Parameters
    ----------
    model : Model
        States must include the North/East position and the heading (names below).
    steer : str
        Input name of the steering command.
    inputs : mapping
        Values of the other inputs (e.g. the propeller rate from :func:`casship.trim`).
    p : array or mapping, optional
        Parameters of the ship (the truth in a simulation).
    north, east, heading, yaw_rate : str
        State names.
    """

    model: Model
    steer: str = "delta"
    inputs: Mapping[str, float] = field(default_factory=dict)
    p: object = None
    north: str = "x"
    east: str = "y"
    heading: str = "psi"
    yaw_rate: str = "r"

    def __post_init__(self):
        m = self.model
        m.index(self.steer, "input")
        for n in (self.north, self.east, self.heading, self.yaw_rate):
            m.index(n)
        unknown = set(self.inputs) - set(m.input_names)
        if unknown:
            raise ValueError(f"unknown input(s) {sorted(unknown)} of {m.name!r}")
        missing = [n for n in m.input_names if n != self.steer and n not in self.inputs]
        if missing:
            raise ValueError(f"give values for the input(s) {missing} of {m.name!r}")
        self.pvec = m.params(self.p) if self.p is not None else m.params()

    def input_vector(self, steer: float = 0.0) -> np.ndarray:
        return self.model.inputs(**{**self.inputs, self.steer: steer})

    def step_function(self) -> ca.Function:
        """``plant(x, steer, p, dt) -> (xf, xdot_f)``: one RK4 step with the other inputs bound, and the
        state derivative at the new state ``xf`` (same inputs; its position rates give the true
        course and speed over ground)."""
        m = self.model
        dm = discretize(m, 1.0, "rk4")
        x, s, p, h = ca.SX.sym("x", m.nx), ca.SX.sym("steer"), ca.SX.sym("p", m.np), ca.SX.sym("dt")
        u = ca.SX(ca.DM(self.input_vector(0.0)))
        u[m.index(self.steer, "input")] = s
        w0 = ca.SX.zeros(m.nw)
        xf = dm.F(x, u, p, w0, h)
        return ca.Function("plant", [x, s, p, h], [xf, m.f(xf, u, p, w0)], ["x", "steer", "p", "dt"],
                           ["xf", "xdot_f"])


# ---------------------------------------------------------------------------------------------------
# Closed-loop simulation
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ClosedLoopResult:
    """Record of a closed-loop run: ``data`` columns (SI units) and ``metrics`` per command step."""

    data: Dataset
    metrics: list
    mode: str

    def summary(self) -> dict:
        return {"mode": self.mode, "steps": self.metrics}


def course_scenario(name: str, t_end: float | None = None) -> tuple[Callable[[float], float], float, list]:
    """A named course-change scenario: ``course-20`` (20 deg at t = 0 s, back to 0 at t = 20 s as in
    Fossen & Fossen 2021), ``course-A`` for any angle A in degrees (A at t = 0, back at t_end/2),
    ``step-A`` (A at t = 0, held).

    Returns ``(command(t) -> rad, t_end, step_times)``.
    """
    try:
        kind, angle = name.rsplit("-", 1)
        a = np.radians(float(angle))
    except ValueError:
        raise ValueError(f"unknown scenario {name!r}; use course-A or step-A (A in degrees)") from None
    if kind == "course":
        t_end = float(t_end or 40.0)
        back = 20.0 if t_end <= 40.0 else t_end / 2
        return (lambda t: a if t < back else 0.0), t_end, [0.0, back]
    if kind == "step":
        t_end = float(t_end or 40.0)
        return (lambda t: a), t_end, [0.0]
    raise ValueError(f"unknown scenario {name!r}; use course-A or step-A (A in degrees)")


def simulate_autopilot(plant: SteeringPlant, autopilot: Autopilot, command: Callable[[float], float], t_end: float,
                       *, dt: float = 0.02, mode: str = "course", estimator: str = "ekf",
                       gnss_rate: float = 5.0, gnss_std: float = 0.5, compass_rate: float = 10.0,
                       compass_std: float = np.radians(0.5), gyro_std: float = np.radians(0.01),
                       ekf_q=(0.1, 0.01), ekf_alpha=(0.01, 0.1), rate: str = "estimator", x0=None,
                       step_times: Sequence[float] = (0.0,), settle_band: float = np.radians(1.0),
                       seed=0) -> ClosedLoopResult:
    """Run ship + sensors + estimator + autopilot at ``1/dt`` Hz.

    Parameters
    ----------
    plant : SteeringPlant
        The nonlinear ship (truth), with its parameters (model error) and other inputs bound:
        for wind and current use a model from :func:`casship.models.wind.add_current` /
        :func:`~casship.models.wind.add_wind` and give ``wind_speed``, ``current_speed``, ... in
        ``plant.inputs``.
    autopilot : Autopilot
    command : callable t -> course or heading command [rad]
    t_end : float
    dt : float
        Loop period (0.02 s = 50 Hz).
    mode : {"course", "heading"}
        ``"course"``: GNSS positions at ``gnss_rate`` into the five-state SOG/COG EKF
        (:func:`casship.models.sog_cog`), the autopilot acting on its ``chi`` and ``omega_chi``
        (Fossen & Fossen 2021). ``"heading"``: compass heading at ``compass_rate`` and a rate gyro
        every step.
    estimator : {"ekf", "truth"}
        ``"truth"`` feeds the true course and course rate (no sensors).
    ekf_q : (float, float)
        Process-noise variances of ``w_U`` and ``w_chi`` in the SOG/COG EKF.
    ekf_alpha : (float, float)
        Singer constants ``alpha1, alpha2`` [1/s] of the SOG/COG EKF (0.01, 0.1 in MSS for a USV;
        use small values, e.g. 1e-5, for ships whose speed and turn rate change slowly).
    rate : {"estimator", "gyro"}
        Rate fed to the autopilot in course mode: the EKF's course rate ``omega_chi`` (Fossen &
        Fossen 2021) or a rate gyro's yaw rate (noise ``gyro_std``; equal to the course rate in a
        steady turn).
    step_times : sequence of float
        Times of command changes; metrics are computed for each segment.
    settle_band : float
        Absolute settling band [rad] (the band is the larger of this and 2 % of the change).
    seed : int or Generator
    """
    from .estimators import EKF
    from .models import sog_cog

    if mode not in ("course", "heading"):
        raise ValueError(f"mode must be 'course' or 'heading', got {mode!r}")
    if rate not in ("estimator", "gyro"):
        raise ValueError(f"rate must be 'estimator' or 'gyro', got {rate!r}")
    if estimator not in ("ekf", "truth"):
        raise ValueError(f"estimator must be 'ekf' or 'truth', got {estimator!r}")
    m = plant.model
    rng = np.random.default_rng(seed)
    n = int(round(t_end / dt)) + 1
    t = np.arange(n) * dt
    ix, iy, ipsi, ir = (m.index(k) for k in (plant.north, plant.east, plant.heading, plant.yaw_rate))
    x = np.asarray(x0 if x0 is not None else plant.model.states(), dtype=float).copy()
    ship = BufferedCall(plant.step_function())
    ship.args[2][:] = plant.pvec
    ap = BufferedCall(autopilot.function)
    ap.args[4][0] = dt
    # initial course and speed from the model derivative (a zero-length step)
    ship.args[0][:] = x
    ship.args[1][0] = 0.0
    ship.args[3][0] = 0.0
    xdot = ship()[1].copy()
    ship.args[3][0] = dt
    vg0 = xdot[[ix, iy]]
    chi0 = float(np.arctan2(vg0[1], vg0[0])) if mode == "course" else float(x[ipsi])
    ap.args[0][:] = [chi0, 0.0, 0.0, 0.0, 0.0, 0.0]
    gnss_every = int(round(1.0 / (gnss_rate * dt)))
    compass_every = int(round(1.0 / (compass_rate * dt)))
    if mode == "course" and estimator == "ekf":
        ekf = EKF(discretize(sog_cog(*ekf_alpha), dt, "euler"), Q=np.diag(ekf_q), R=np.eye(2) * gnss_std**2)
        xh = np.array([x[ix], x[iy], float(np.hypot(*vg0)), chi0, 0.0])
        Ph = np.diag([gnss_std**2, gnss_std**2, 1.0, np.radians(5) ** 2, 0.01])
        prior_mean, prior_cov = xh.copy(), Ph.copy()
        ekf_run = ekf.online(Gaussian(prior_mean, prior_cov))
    nan2 = np.full(2, np.nan)
    cols = {k: np.empty(n) for k in ("north", "east", "psi", "r", "U", "chi", "chi_hat", "omega_hat", "U_hat",
                                     "chi_std", "steer", "chi_d", "r_d", "ref", "e", "gnss_north", "gnss_east")}
    psi_meas = float(x[ipsi])
    for k in range(n):
        vg = xdot[[ix, iy]]
        chi_true = float(np.arctan2(vg[1], vg[0]))
        gn = ge = np.nan
        if mode == "course":
            if estimator == "ekf":
                y = nan2
                if k % gnss_every == 0:
                    gn, ge = x[ix] + gnss_std * rng.standard_normal(), x[iy] + gnss_std * rng.standard_normal()
                    y = np.array([gn, ge])
                xh = ekf_run.update(y, dt if k else 0.0)
                Ph = ekf_run.P
                chi_f, om_f, U_f, chi_s = xh[3], xh[4], xh[2], np.sqrt(Ph[3, 3])
                if rate == "gyro":
                    om_f = x[ir] + gyro_std * rng.standard_normal()
            else:     # true course; its rate by a backward difference (the yaw rate on the first tick)
                om_f = x[ir] if k == 0 else wrap(chi_true - cols["chi"][k - 1]) / dt
                chi_f, U_f, chi_s = chi_true, float(np.hypot(*vg)), 0.0
        else:
            if estimator == "ekf":
                if k % compass_every == 0:
                    psi_meas = float(wrap(x[ipsi] + compass_std * rng.standard_normal()))
                chi_f, om_f = psi_meas, x[ir] + gyro_std * rng.standard_normal()
            else:
                chi_f, om_f = float(wrap(x[ipsi])), x[ir]
            U_f, chi_s = float(np.hypot(*vg)), 0.0
        ref = float(command(t[k]))
        a = ap.args
        a[1][0], a[2][0], a[3][0] = ref, chi_f, om_f
        z_next, steer, chi_d, r_d, _, e = ap()
        steer_v = float(steer[0])
        cols["north"][k], cols["east"][k], cols["psi"][k], cols["r"][k] = x[ix], x[iy], x[ipsi], x[ir]
        cols["U"][k], cols["chi"][k] = np.hypot(*vg), chi_true
        cols["chi_hat"][k], cols["omega_hat"][k], cols["U_hat"][k], cols["chi_std"][k] = chi_f, om_f, U_f, chi_s
        cols["steer"][k], cols["chi_d"][k], cols["r_d"][k], cols["ref"][k] = steer_v, chi_d[0], r_d[0], ref
        cols["e"][k], cols["gnss_north"][k], cols["gnss_east"][k] = e[0], gn, ge
        a[0][:] = z_next
        if k + 1 < n:
            ship.args[0][:] = x
            ship.args[1][0] = steer_v
            xf, xdot_f = ship()
            x, xdot = xf.copy(), xdot_f.copy()
            if not np.all(np.isfinite(x)):
                raise FloatingPointError(f"closed-loop simulation of {m.name!r} diverged at t = {t[k]:g} s")
    cols["omega_chi"] = np.gradient(np.unwrap(cols["chi"]), t)
    meta = {"mode": mode, "estimator": estimator, "model": m.name, "dt": dt}
    if mode == "course" and estimator == "ekf":
        meta["ekf_prior"] = Gaussian(prior_mean, prior_cov)
        meta["ekf"] = ekf
    data = Dataset(t, cols, meta=meta)
    controlled = cols["chi"] if mode == "course" else cols["psi"]
    metrics = []
    bounds = list(step_times) + [t[-1] + dt]
    for t0, t1 in zip(bounds[:-1], bounds[1:]):
        sel = (t >= t0) & (t < t1)
        metrics.append(step_metrics(t[sel], controlled[sel], float(command(t0)), cols["steer"][sel],
                                    abs_band=settle_band))
    return ClosedLoopResult(data=data, metrics=metrics, mode=mode)


def step_metrics(t, y, target: float, steer=None, *, band: float = 0.02, abs_band: float = 0.0,
                 ss_window: float = 0.1) -> dict:
    """Step-response metrics of ``y`` (angles, rad) moving from ``y[0]`` to ``target``.

    Returns rise time (10 % -> 90 % of the change) [s], overshoot [% of the change and deg],
    settling time (last entry into the band ``max(band * |change|, abs_band)``) [s], steady-state
    error (mean over the last ``ss_window`` fraction) [deg], IAE [deg s], and with ``steer`` the
    mean and maximum absolute steering and the RMS and maximum steering rate (per second). Times
    are measured from ``t[0]``; ``nan`` where not reached.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if t.size < 3:
        raise ValueError("step_metrics needs at least 3 samples")
    y = y[0] + np.unwrap(wrap(y - y[0]))          # continuous around the start value
    change = float(wrap(target - y[0]))
    goal = y[0] + change
    err = y - goal
    out = {"target_deg": float(np.degrees(target)), "change_deg": float(np.degrees(change))}
    if abs(change) > 0:
        frac = (y - y[0]) / change
        i10 = np.flatnonzero(frac >= 0.1)
        i90 = np.flatnonzero(frac >= 0.9)
        out["rise_time_s"] = float(t[i90[0]] - t[i10[0]]) if i10.size and i90.size else float("nan")
        over = max(0.0, float(np.max(frac) - 1.0))
        out["overshoot_pct"] = 100 * over
        out["overshoot_deg"] = float(np.degrees(over * abs(change)))
        tol = max(band * abs(change), abs_band)
        outside = np.flatnonzero(np.abs(err) > tol)
        if outside.size == 0:
            out["settling_time_s"] = 0.0
        elif outside[-1] == t.size - 1:
            out["settling_time_s"] = float("nan")
        else:
            out["settling_time_s"] = float(t[outside[-1] + 1] - t[0])
    tail = t >= t[0] + (1 - ss_window) * (t[-1] - t[0])
    out["steady_state_error_deg"] = float(np.degrees(np.mean(err[tail])))
    out["iae_deg_s"] = float(np.degrees(np.trapezoid(np.abs(err), t)))
    if steer is not None:
        s = np.asarray(steer, dtype=float)
        rate = np.diff(s) / np.diff(t)
        out.update({"steer_mean_abs": float(np.mean(np.abs(s))), "steer_max_abs": float(np.max(np.abs(s))),
                    "steer_rate_rms": float(np.sqrt(np.mean(rate**2))),
                    "steer_rate_max": float(np.max(np.abs(rate)))})
    return out


# ---------------------------------------------------------------------------------------------------
# One-call design for a ship model at a speed
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Design:
    """An autopilot designed for a ship at an operating point (see :func:`design_autopilot`)."""

    plant: SteeringPlant
    x0: np.ndarray
    nomoto: Nomoto
    gains: PIDGains
    autopilot: Autopilot
    loop: control.TransferFunction
    margins: dict
    settings: dict

    def summary(self) -> dict:
        return {"nomoto": self.nomoto.as_dict(), "gains": self.gains.as_dict(), "margins": self.margins,
                "settings": self.settings, "operating_point": dict(zip(self.plant.model.state_names,
                                                                       map(float, self.x0))),
                "inputs": {k: float(v) for k, v in self.plant.inputs.items()}}


def _vessel(model: Model, key: str, default=None):
    value = getattr(model.vessel, key, None) if model.vessel is not None else None
    return default if value is None else value


def design_autopilot(model: Model, speed: float | None = None, *, p=None, steer: str = "delta",
                     propeller: str | None = "auto", surge: str = "u", nomoto: Nomoto | None = None,
                     method: str = "pid", wn: float | None = None, zeta: float = 1.0,
                     integral: str | None = "fossen", lqr_weights: Mapping | None = None,
                     wn_ref: float | None = None, r_max: float | None = None, steer_max: float | None = None,
                     steer_rate_max: float | None = None, actuator_T: float = 1.0, delay: float = 0.2,
                     filter_T: float = 0.0,
                     inputs: Mapping[str, float] | None = None) -> Design:
    """Design a course autopilot for ``model`` at a straight-run ``speed``.

    Steps: trim (the propeller rate that holds ``speed``, :func:`casship.trim`), exact
    linearisation and reduction to a Nomoto model (unless ``nomoto`` is given, e.g. one fitted to
    zig-zags), PID pole placement or LQR, third-order reference model, limits, and the margins of
    the loop on the design model (second-order Nomoto when known) with a first-order steering
    servo ``actuator_T`` and a delay ``delay`` (e.g. the GNSS period).

    Defaults come from the model's ``vessel`` where present: ``wn = U/L`` (L = ``L_pp``),
    ``r_max = 0.5 U/L``, ``steer_max`` = ``rudder_max`` or 35 deg, ``steer_rate_max`` =
    ``rudder_rate`` or 2.32 deg/s.
    """
    if method not in ("pid", "lqr"):
        raise ValueError(f"method must be 'pid' or 'lqr', got {method!r}")
    inputs = dict(inputs or {})
    pv = model.params(p) if p is not None else model.params()
    if propeller == "auto":
        props = _vessel(model, "propellers", default=())
        propeller = props[0] if len(props) == 1 else None
    speed = float(speed if speed is not None else _vessel(model, "U0", default=0.0))
    x = model.states(**({surge: speed} if surge in model.state_names else {}))
    u = model.inputs(**{k: v for k, v in inputs.items()})
    if propeller is not None and propeller not in inputs:
        u[model.index(propeller, "input")] = float(_vessel(model, "n0", default=1.0))
        tr = trim(model, x, u, pv, free=[propeller], zero=[surge])
        x, u = tr.x, tr.u
        inputs[propeller] = tr.values[propeller]
    others = {n: float(u[model.index(n, "input")]) for n in model.input_names if n != steer}
    others.update(inputs)
    nom = nomoto or nomoto_from_model(model, x, u, pv, steer=steer)
    L = _vessel(model, "L_pp")
    if wn is None:
        if L is None or speed <= 0:
            raise ValueError("give wn (the model has no vessel length L_pp, or speed is zero)")
        wn = speed / float(L)
    if r_max is None:
        r_max = 0.5 * speed / float(L) if L is not None and speed > 0 else float("inf")
    steer_max = float(steer_max if steer_max is not None else _vessel(model, "rudder_max", default=np.radians(35)))
    steer_rate_max = float(steer_rate_max if steer_rate_max is not None
                           else _vessel(model, "rudder_rate", default=np.radians(2.32)))
    if method == "pid":
        gains = pid_pole_placement(nom, wn, zeta, integral=integral)
    else:
        w = {"q_int": (wn / 10) ** 2, "q_e": 1.0, "q_r": 1.0 / wn**2, "r_delta": (np.radians(10) / np.radians(5)) ** 2
             * (nom.m * wn**2) ** -2}
        w.update(lqr_weights or {})
        gains = lqr_design(nom, **w)
    ref = ReferenceModel(wn_ref or wn, 1.0, r_max)
    pilot = Autopilot(gains, ref, steer_max, steer_rate_max, filter_T=filter_T)
    order = 2 if nom.second_order else 1
    loop = loop_transfer(nom, gains, order=order, actuator_T=actuator_T, delay=delay, filter_T=filter_T)
    plant = SteeringPlant(model, steer, others, pv)
    settings = {"speed_mps": speed, "method": method, "wn": wn, "zeta": zeta, "wn_ref": ref.wn,
                "r_max_deg_s": float(np.degrees(r_max)), "steer_max": steer_max,
                "steer_rate_max": steer_rate_max, "actuator_T_s": actuator_T, "delay_s": delay, "filter_T_s": filter_T,
                "design_model_order": order}
    return Design(plant, x, nom, gains, pilot, loop, margins(loop), settings)


def plot_closed_loop(result: ClosedLoopResult, path, title: str = "", steer_label: str = "rudder [deg]",
                     steer_scale: float = float(np.degrees(1.0))):
    """Course (true, estimated, desired, command), steering and track of a closed-loop run (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = result.data
    t = d.t
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    ax = axes[0, 0]
    key = "chi" if result.mode == "course" else "psi"
    ax.plot(t, np.degrees(np.unwrap(d[key])), label=f"true {key}")
    ax.plot(t, np.degrees(np.unwrap(d["chi_hat"])), lw=0.7, label="fed to autopilot")
    ax.plot(t, np.degrees(np.unwrap(d["chi_d"])), "--", label="reference model")
    ax.plot(t, np.degrees(d["ref"]), ":", label="command")
    ax.set_ylabel(f"{key} [deg]")
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.plot(t, d["steer"] * steer_scale)
    ax.set_ylabel(steer_label)
    ax.set_xlabel("time [s]")
    ax = axes[0, 1]
    ax.plot(t, np.degrees(d["omega_chi"]), label="true course rate")
    ax.plot(t, np.degrees(d["omega_hat"]), lw=0.7, label="fed to autopilot")
    ax.plot(t, np.degrees(d["r_d"]), "--", label="desired rate")
    ax.set_ylabel("rate [deg/s]")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    ax.plot(d["east"], d["north"])
    ok = np.isfinite(d["gnss_north"])
    if ok.any():
        ax.plot(d["gnss_east"][ok], d["gnss_north"][ok], ".", ms=1.5, alpha=0.5, label="GNSS")
        ax.legend(fontsize=8)
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(title)
    for a in axes.ravel():
        a.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
