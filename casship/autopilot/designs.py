"""Course-autopilot designs on the Nomoto model: PID pole placement, LQR with integral action, LQG.

Every design works on ``m r' + d r = delta`` (``m = T/K``, ``d = 1/K``; Fossen 2021, Sec. 15.3),
finite for course-unstable ships, and takes either a :class:`~casship.autopilot.nomoto.Nomoto`
model or the labelled :class:`control.StateSpace` of :func:`casship.linearize` (reduced to Nomoto
by :func:`~casship.autopilot.nomoto.nomoto_from_linear`). The gains come back as
:class:`~casship.autopilot.law.PIDGains`, whose :meth:`~casship.autopilot.law.PIDGains.controller`
is the labelled python-control system; the LQR and LQG use ``control.lqr`` and ``control.lqe``.
"""
from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from .law import PIDGains
from .nomoto import Nomoto, nomoto_from_linear
from ..errors import InputError, InputTypeError

__all__ = ["as_nomoto", "pid_pole_placement", "lqr_design", "LQG", "lqg_design"]


def as_nomoto(target, *, steer: str = "delta") -> Nomoto:
    """A :class:`Nomoto` model from a Nomoto model or a labelled linearisation.

    Parameters
    ----------
    target : Nomoto or control.StateSpace
    steer : str
        Steering input of the linearisation.
    """
    if isinstance(target, Nomoto):
        return target
    if isinstance(target, control.StateSpace):
        return nomoto_from_linear(target, steer=steer)
    raise InputTypeError(f"expected a Nomoto model or a labelled control.StateSpace, got {type(target).__name__}")


def _positive(name, value):
    if not (np.isfinite(value) and value > 0):
        raise InputError(f"{name} must be positive, got {value}")


def pid_pole_placement(target, wn: float, zeta: float = 1.0, *, integral: str | None = "fossen",
                       wi_ratio: float = 0.1, steer: str = "delta") -> PIDGains:
    """PID by pole placement on the first-order Nomoto model (Fossen 2021, Sec. 15.3.4).

    ``integral="fossen"`` (MSS/PVS): ``Kp = m wn^2``, ``Kd = 2 zeta wn m - d``, ``Ki = wn/10 Kp``
    (the PD loop has its poles at ``s^2 + 2 zeta wn s + wn^2``; the slow integrator moves them
    slightly). ``integral="exact"``: the third-order loop ``m s^3 + (d + Kd) s^2 + Kp s + Ki``
    gets exactly the poles of ``(s^2 + 2 zeta wn s + wn^2)(s + wi)``, ``wi = wi_ratio wn``.
    ``integral=None``: PD only. The gains are positive by construction for the sign convention of
    casship (steering turns the craft with the sign of ``K``, so ``m = T/K > 0``): where the ship's
    own damping ``d`` exceeds ``2 zeta wn m`` the derivative gain is 0 (not negative) and the poles
    returned are those of the resulting, better damped loop.

    Parameters
    ----------
    target : Nomoto or control.StateSpace
        The design model, or the labelled linearisation it is reduced from.
    wn, zeta : float
        Natural frequency [rad/s] and relative damping of the closed loop.
    integral : {"fossen", "exact", None}
        Integral action (see above).
    wi_ratio : float
        Integrator pole over ``wn`` for ``"exact"``.
    steer : str
        Steering input of a linearisation.

    Returns
    -------
    PIDGains

    Examples
    --------
    >>> g = pid_pole_placement(Nomoto(K=0.185, T=107.3), 0.05)
    >>> round(g.Kp, 3), round(g.Kd, 2), round(g.Ki, 5)
    (1.45, 52.59, 0.00725)
    """
    _positive("wn", wn)
    _positive("zeta", zeta)
    nom = as_nomoto(target, steer=steer)
    m, d = nom.m, nom.d
    if not m > 0:
        raise InputError(f"the Nomoto model has m = T/K = {m:.4g} <= 0 (K and T of opposite signs): no pole "
                         "placement on it makes the gains positive; check the steering sign")
    pd_poles = tuple(np.roots([1, 2 * zeta * wn, wn**2]))
    if integral is None:
        Kp, Kd, Ki, method, poles = m * wn**2, 2 * zeta * wn * m - d, 0.0, "pd-pole-placement", pd_poles
    elif integral == "fossen":
        Kp, Kd, method, poles = m * wn**2, 2 * zeta * wn * m - d, "pid-pole-placement-fossen", pd_poles
        Ki = wn / 10 * Kp
    elif integral == "exact":
        _positive("wi_ratio", wi_ratio)
        wi = wi_ratio * wn
        Kp, Kd, Ki = m * (wn**2 + 2 * zeta * wn * wi), m * (2 * zeta * wn + wi) - d, m * wn**2 * wi
        method, poles = "pid-pole-placement-exact", pd_poles + (-wi,)
    else:
        raise InputError(f"integral must be 'fossen', 'exact' or None, got {integral!r}")
    if Kd < 0:
        # the ship damps itself more than the placed poles ask: a negative derivative gain would take
        # damping away (and feed the rate noise back); keep Kd = 0, the loop then better damped
        Kd, method = 0.0, method + "-Kd0"
        poles = tuple(np.roots([m, d, Kp, Ki]) if Ki else np.roots([m, d, Kp]))
    return PIDGains(Kp, Kd, Ki, m, d, method, poles)


def _integral_augmented(nom: Nomoto, steer: str) -> control.StateSpace:
    """The first-order Nomoto model with the course-error integral, built with ``control.interconnect``:
    states ``z, psi, r`` (``z' = psi``; in deviation from the desired course ``psi`` is the error)."""
    plant = nom.system(1, steer=steer, name="nomoto")
    integ = control.ss(0.0, 1.0, 1.0, 0.0, states=["z"], inputs=["psi"], outputs=["z"], name="integral")
    aug = control.interconnect([plant, integ], inplist=[steer], outlist=["z", "psi", "r"], name="nomoto_integral")
    return aug


def lqr_design(target, *, q_int: float, q_e: float, q_r: float = 0.0, r_delta: float = 1.0,
               steer: str = "delta") -> PIDGains:
    """LQR with integral action on the first-order Nomoto model (``control.lqr``).

    The plant is the labelled Nomoto system augmented with the error integral
    (``control.interconnect``): states ``z, e, r`` with ``z' = e``, ``e' = r``,
    ``r' = -r/T + (K/T) delta``; cost ``int q_int z^2 + q_e e^2 + q_r r^2 + r_delta delta^2 dt``.
    The optimal feedback ``delta = -(k_z z + k_e e + k_r r)`` is returned as ``Ki = k_z``,
    ``Kp = k_e``, ``Kd = k_r`` (with the closed-loop poles of ``control.lqr``).

    Parameters
    ----------
    target : Nomoto or control.StateSpace
    q_int, q_e, q_r : float
        State weights (integral, course error, yaw rate).
    r_delta : float
        Steering weight.
    steer : str
        Steering input of a linearisation.

    Returns
    -------
    PIDGains
    """
    for name, v in (("q_int", q_int), ("q_e", q_e), ("q_r", q_r)):
        if not (np.isfinite(v) and v >= 0):
            raise InputError(f"{name} must be >= 0, got {v}")
    _positive("r_delta", r_delta)
    nom = as_nomoto(target, steer=steer)
    aug = _integral_augmented(nom, steer)
    weights = {"integral_z": q_int, "nomoto_psi": q_e, "nomoto_r": q_r}     # interconnect's state labels
    Q = np.diag([weights[s] for s in aug.state_labels])
    Kx, _, E = control.lqr(aug, Q, np.array([[r_delta]]))
    k = {s.split("_", 1)[1]: v for s, v in zip(aug.state_labels, np.ravel(Kx))}
    return PIDGains(float(k["psi"]), float(k["r"]), float(k["z"]), nom.m, nom.d, "lqr-integral", tuple(E))


@dataclass(frozen=True)
class LQG:
    """LQR state feedback on the Nomoto model with a steady-state Kalman filter (``control.lqe``).

    Parameters
    ----------
    gains : PIDGains
        The LQR part (``lqr_design``).
    L : ndarray
        Kalman gain of the estimator (states ``psi, r, b``; measurements ``psi, r``).
    estimator : control.StateSpace
        The Kalman filter as a labelled system: inputs ``<steer>, psi_m, r_m``, outputs ``psi_hat,
        r_hat, b_hat``.
    controller : control.StateSpace
        Estimator and feedback in one labelled system: inputs ``chi_d, r_d, a_d, psi_m, r_m``,
        output ``<steer>_c`` (the regulator a python-control user closes the loop with).
    """

    gains: PIDGains
    L: np.ndarray
    estimator: control.StateSpace
    controller: control.StateSpace


def lqg_design(target, *, q_int: float, q_e: float, q_r: float = 0.0, r_delta: float = 1.0,
               heading_var: float, rate_var: float, yaw_accel_var: float, bias_var: float = 0.0,
               steer: str = "delta") -> LQG:
    """LQG course autopilot: :func:`lqr_design` plus a Kalman filter from ``control.lqe``.

    The estimator model is the first-order Nomoto model with a rudder-bias (steady yaw moment)
    state ``b``: ``psi' = r``, ``r' = (K (delta + b) - r)/T + w_r``, ``b' = w_b``; compass and rate
    gyro measure ``psi`` and ``r`` with variances ``heading_var`` and ``rate_var``; ``w_r`` and
    ``w_b`` are white with spectral densities ``yaw_accel_var`` and ``bias_var``. In the nonlinear
    closed loop the same model runs in casship's EKF (:func:`casship.autopilot.estimation.heading_observer`).

    Parameters
    ----------
    target : Nomoto or control.StateSpace
    q_int, q_e, q_r, r_delta : float
        LQR weights (:func:`lqr_design`).
    heading_var, rate_var : float
        Measurement noise densities of compass and gyro.
    yaw_accel_var, bias_var : float
        Process noise densities.
    steer : str
        Steering input of a linearisation.

    Returns
    -------
    LQG
    """
    gains = lqr_design(target, q_int=q_int, q_e=q_e, q_r=q_r, r_delta=r_delta, steer=steer)
    nom = as_nomoto(target, steer=steer)
    K, T = nom.K, nom.T
    A = np.array([[0.0, 1.0, 0.0], [0.0, -1.0 / T, K / T], [0.0, 0.0, 0.0]])
    B = np.array([[0.0], [K / T], [0.0]])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    G = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    QN = np.diag([yaw_accel_var, bias_var])
    RN = np.diag([heading_var, rate_var])
    if bias_var == 0.0:        # b is then a constant: keep the filter detectable by a tiny drift
        QN[1, 1] = 1e-12 * yaw_accel_var
    L, _, _ = control.lqe(A, G, C, QN, RN)
    L = np.asarray(L)
    # estimator: xh' = A xh + B delta + L (y - C xh); outputs the estimates
    est = control.ss(A - L @ C, np.hstack([B, L]), np.eye(3), np.zeros((3, 3)), states=["psi_h", "r_h", "b_h"],
                     inputs=[steer, "psi_m", "r_m"], outputs=["psi_hat", "r_hat", "b_hat"], name="kalman")
    law = gains.controller(steer=steer)
    fb_in = control.ss([], [], [], np.eye(2), inputs=["psi_hat", "r_hat"], outputs=["chi", "r"], name="estimates")
    # the controller's own command drives the estimator (the commanded steering is the estimator input)
    ctrl = control.interconnect([est, fb_in, law], connections=[[f"kalman.{steer}", f"autopilot.{steer}_c"],
                                                                ["estimates.psi_hat", "kalman.psi_hat"],
                                                                ["estimates.r_hat", "kalman.r_hat"],
                                                                ["autopilot.chi", "estimates.chi"],
                                                                ["autopilot.r", "estimates.r"]],
                                inplist=["autopilot.chi_d", "autopilot.r_d", "autopilot.a_d", "kalman.psi_m",
                                         "kalman.r_m"],
                                inputs=["chi_d", "r_d", "a_d", "psi_m", "r_m"],
                                outlist=[f"autopilot.{steer}_c"], outputs=[f"{steer}_c"],
                                ignore_outputs=["kalman.b_hat"], name="lqg")
    return LQG(gains, L, est, ctrl)
