"""The MPC of a design: its horizon, period and weights from the design's settings and model
(:func:`mpc_for_design`), and the weights from the PID design's bandwidth (:func:`mpc_weights`)."""
from __future__ import annotations

import numpy as np

from ..errors import InputError
from .mpc import MPCAutopilot

__all__ = ["mpc_for_design", "mpc_weights"]


def mpc_for_design(design, *, horizon_time: float | None = None, steps: int = 60, q_r: float | None = None,
                   r_u: float | None = None, q_d: float | None = None, tuning: str = "limits",
                   offset: str = "bias") -> MPCAutopilot:
    """An MPC (heading control; a course-mode design is refused) with the design's model, limits and
    reference model (the PID law's, ``design.autopilot.reference``: the default design runs its PID
    with it, so the two are compared like with like).

    Horizon ``6 pi / wn_ref`` (three periods of the reference model's natural frequency) in
    ``steps`` steps (the period rounded to a multiple of the loop period; on a course-unstable ship
    (``T < 0``) at most ``|T| / 10``, the horizon then shorter), re-planned ten times per period.
    Weights (``tuning``):

    - ``"limits"`` (default): course error 1/(1 deg)^2, yaw rate ``1/r_max^2``, steering rate
      ``(100 / rate_max)^2`` (a steering rate of 1 % of the limit costs as much as 1 deg of course
      error), no steering weight;
    - ``"bandwidth"``: from the PID design's ``wn`` and ``zeta`` (:func:`mpc_weights`), stated
      before it was measured: on the inertia part of the model (``e'' = delta / m``, ``delta' =
      u``, ``m = T / K``) the unconstrained infinite-horizon law of the cost ``q_e e^2 + q_r r^2 +
      q_d delta^2 + r_u u^2`` has its poles at the roots of ``(s + w)(s^2 + 2 zeta w s + w^2)``, the
      PID's closed-loop pair plus the steering, at ``w = max(wn, 1 / |T|)`` (below ``1 / |T|`` the
      ship is not an inertia: its rate follows the steering); the steering and its rate measured
      from the reference steering along the preview. It is not the default: on the docs' table it
      is at or below the PID in more rows and where the limits bind, but above the ``"limits"``
      tuning in some (docs/autopilots.md section 9).

    Offset-free control (``offset``): ``"bias"`` (default) plans with the heading observer's steering
    bias; ``"integral"`` with the integral of the tracking error, as the PID law (the bias unused),
    weighted ``q_z = q_e (wn / 10)^2`` (the integral weight of casship's LQR rule,
    ``settings.lqr_weights``, relative to the course error's: the PID's integral pole at ``wn / 10``).

    ``q_r``, ``r_u``, ``q_d`` given replace the tuning's. The steady steering of the design's PID
    law (``design.autopilot.steering``) along the preview. In the design's loop
    (``design.simulate(controller=mpc)``) the heading observer runs on the MPC's model
    (:func:`~casship.autopilot.estimation.heading_observer` with ``steering`` and ``second``).

    Parameters
    ----------
    design : Design
    horizon_time : float, optional
        Prediction horizon [s].
    steps : int
        Steps over the horizon.
    q_r, r_u, q_d : float, optional
        Replace the yaw-rate, steering-rate and steering weights.
    tuning : {"limits", "bandwidth"}
        The rule of the weights.
    offset : {"bias", "integral"}
        Offset-free control from the observer's bias or from the integral of the tracking error.
    """
    s = design.settings
    if s.mode == "course":
        raise InputError("the MPC is for heading control (mode 'heading'): its prediction model is the Nomoto "
                         "heading model, and the course over ground adds the drift angle of a turn, which it does "
                         "not predict (in course mode the KVLCC2's 60 deg change overshot 22-27 % and did not "
                         "settle); use the PID/LQR law for course control")
    horizon_time = horizon_time or 6 * np.pi / s.wn_ref
    period = horizon_time / steps
    nom = design.nomoto
    if nom.T < 0:        # a course-unstable ship drifts off between solves: re-plan within a tenth of |T|
        period = min(period, abs(nom.T) / 10)
    period = max(s.dt, round(period / s.dt) * s.dt)
    if tuning == "bandwidth":
        weights = mpc_weights(s.wn, s.zeta, nom.K, nom.T)
    elif tuning == "limits":
        weights = {"q_e": 1.0 / np.radians(1.0) ** 2, "q_r": 1.0 / s.r_max**2, "q_d": 0.0,
                   "r_u": (100.0 / s.steer_rate_max) ** 2}
    else:
        raise InputError(f"MPC tuning must be 'limits' or 'bandwidth', got {tuning!r}")
    if offset == "integral":
        weights["q_z"] = weights["q_e"] * (s.wn / 10) ** 2
    elif offset != "bias":
        raise InputError(f"MPC offset must be 'bias' or 'integral', got {offset!r}")
    for name, given in (("q_r", q_r), ("r_u", r_u), ("q_d", q_d)):
        if given is not None:
            weights[name] = given
    return MPCAutopilot(design.nomoto, period, steps, s.steer_max, s.steer_rate_max, s.r_max,
                        replan=max(s.dt, round(period / 10 / s.dt) * s.dt), **weights, offset=offset,
                        reference=design.autopilot.reference, steering=design.autopilot.steering)


def mpc_weights(wn: float, zeta: float, K: float, T: float) -> dict:
    """The MPC's weights from the PID design's bandwidth (``tuning="bandwidth"`` of
    :func:`mpc_for_design`): with ``w = max(wn, 1 / |T|)``, ``m = T / K`` and ``c = 4 zeta^2 - 1``::

        q_e = 1 / (1 deg)^2,  q_r = c q_e / w^2,  q_d = c q_e / (m^2 w^4),  r_u = q_e / (m^2 w^6)

    the weights whose unconstrained infinite-horizon law on ``e'' = delta / m``, ``delta' = u`` has
    its poles at the roots of ``(s + w)(s^2 + 2 zeta w s + w^2)`` (the optimal poles are the stable
    roots of ``r_u m^2 (-s^2)^3 + q_d m^2 s^4 - q_r s^2 + q_e = 0``).

    Parameters
    ----------
    wn, zeta : float
        Closed-loop natural frequency [rad/s] and damping (at least 1/2) of the PID design.
    K, T : float
        Nomoto gain and time constant.
    """
    if not (np.isfinite(wn) and wn > 0):
        raise InputError(f"MPC weights: wn must be positive and finite, got {wn}")
    if not (np.isfinite(zeta) and zeta >= 0.5):
        raise InputError(f"MPC weights: zeta = {zeta} < 1/2 has no such weights (give q_r, q_d and r_u)")
    if not (np.isfinite(K) and K != 0 and np.isfinite(T) and T != 0):
        raise InputError(f"MPC weights: the Nomoto K and T must be finite and nonzero, got K = {K}, T = {T}")
    q_e, c, w, m = 1.0 / np.radians(1.0) ** 2, 4 * zeta**2 - 1, max(wn, 1.0 / abs(T)), T / K
    return {"q_e": q_e, "q_r": c * q_e / w**2, "q_d": c * q_e / (m**2 * w**4), "r_u": q_e / (m**2 * w**6)}
