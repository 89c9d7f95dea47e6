"""How well any heading autopilot can hold a ship in a sea: the heading-error floor and the LQG loop.

First-order wave yaw (:class:`~casship.autopilot.estimation.WaveYaw`) reaches the autopilot only
through its compass and rate gyro; the ship itself is not moved by it. The autopilot can then
steer only on what the sensors tell it about the low-frequency heading ``psi``. For a linear ship
with Gaussian waves and sensor noise, the conditional mean of ``psi`` given the readings (the
Kalman-Bucy filter on the ship's exact linearisation with the wave model in it) has an error
variance ``P_psi`` that no controller changes (the separation principle), and

    E[psi^2] = E[psi_hat^2] + P_psi >= P_psi

for every causal controller, linear or not: :func:`heading_error_floor` is ``sqrt(P_psi)``, the
heading error no autopilot on these sensors gets below in this sea. A course-stable ship needs no
information at the wave's frequency to hold its heading and its floor is small; a course-unstable
ship must be held at the rate of its unstable yaw pole, and when the encounter frequency is near it,
the wave yaw there is indistinguishable from the ship's own motion.

:func:`wave_lqg` is the H2-optimal (LQG) loop for the same problem: LQR on the linearisation with
the heading error weighted against the steering, and the Kalman-Bucy filter with the wave model and
a steering bias; its heading error and steering in the sea are predicted exactly (the stationary
covariance of the linear closed loop, ``scipy.linalg.solve_continuous_lyapunov``) and approach the
floor as the steering gets cheaper. :func:`rice_exceedance` turns an error RMS into the expected
number of times a line (10 % of a course change) is crossed in a stretch of course keeping.
"""
from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from ..errors import InputError
from .estimation import WaveYaw, settings_wave

__all__ = ["heading_error_floor", "wave_lqg", "WaveLQG", "rice_exceedance", "sea_model"]


def _sea(design, wave: WaveYaw | None) -> WaveYaw:
    w = wave if wave is not None else settings_wave(design.settings)
    if w is None:
        raise InputError("no sea state: give wave, or design with wave_w0 and wave_std")
    if not isinstance(w, WaveYaw):
        raise InputError(f"wave must be a WaveYaw, got {type(w).__name__}")
    return w


def sea_model(design, wave: WaveYaw | None = None, *, bias: bool = False) -> dict:
    """The ship's exact linearisation with the wave yaw on its compass and gyro, as matrices.

    States: the linearisation's (``design.linearization``), then with ``bias`` a steering bias
    ``b`` (a random walk added to the steering), then the wave's ``psi_w, r_w``. Measurements:
    ``psi + psi_w`` (compass) and ``r + r_w`` (gyro) with the noise densities of the settings
    (``compass_std^2 / compass_rate``, ``gyro_std^2 dt``: the gyro read every loop period).
    Noises: the wave's white noise (unit intensity) and with ``bias`` the bias drift.

    Parameters
    ----------
    design : Design
        From :func:`~casship.autopilot.design_autopilot`.
    wave : WaveYaw, optional
        The sea (default: the design's ``wave_w0``, ``wave_std``).
    bias : bool
        Add the steering-bias state.

    Returns
    -------
    dict
        ``A, B, G, C, R`` (continuous), ``states`` (labels), ``ipsi, ir`` (indices of the ship's
        heading and yaw rate), ``n_ship`` and ``wave``.
    """
    w = _sea(design, wave)
    lin, s, pl = design.linearization, design.settings, design.plant
    labels = list(lin.state_labels)
    for name in (pl.heading, pl.yaw_rate):
        if name not in labels:
            raise InputError(f"the linearisation has no state {name!r} (states {labels})")
    A0, B0 = np.asarray(lin.A, float), np.asarray(lin.B, float)[:, :1]
    n0, nb = A0.shape[0], int(bias)
    n = n0 + nb + 2
    A, B = np.zeros((n, n)), np.zeros((n, 1))
    A[:n0, :n0], B[:n0] = A0, B0
    wave_ss = w.system()
    Aw, Gw = np.asarray(wave_ss.A, float), np.asarray(wave_ss.B, float)
    A[n - 2:, n - 2:] = Aw
    G = np.zeros((n, 1 + nb))
    G[n - 2:, 0] = Gw[:, 0]
    if bias:
        A[:n0, n0] = B0[:, 0]
        G[n0, 1] = 1.0
    ipsi, ir = labels.index(pl.heading), labels.index(pl.yaw_rate)
    C = np.zeros((2, n))
    C[0, ipsi] = C[0, n - 2] = 1.0
    C[1, ir] = C[1, n - 1] = 1.0
    R = np.diag([s.compass_std**2 / s.compass_rate, s.gyro_std**2 * s.dt])
    if not np.all(np.diag(R) > 0):
        raise InputError("the heading-error floor needs compass and gyro noise (compass_std, gyro_std > 0)")
    states = labels + (["b"] if bias else []) + ["psi_w", "r_w"]
    return {"A": A, "B": B, "G": G, "C": C, "R": R, "states": states, "ipsi": ipsi, "ir": ir, "n_ship": n0,
            "wave": w}


def _kalman(m: dict, q_bias: float = 0.0):
    """Steady-state Kalman-Bucy gain and error covariance of :func:`sea_model` (``control.lqe``).
    The ship's states get a process noise 1e-12 of the wave's (through the steering) only to keep
    the Riccati equation regular: the truth has none."""
    G = np.hstack([m["G"], 1e-6 * m["B"] / max(np.abs(m["B"]).max(), 1e-300)])
    Q = np.diag([1.0] + ([max(q_bias, 1e-12)] if m["G"].shape[1] > 1 else []) + [1.0])
    L, P, _ = control.lqe(m["A"], G, m["C"], Q, m["R"])
    return np.asarray(L, float), np.asarray(P, float)


def heading_error_floor(design, wave: WaveYaw | None = None) -> float:
    """The heading error [rad RMS] no autopilot on compass and gyro gets below in the sea ``wave``.

    ``sqrt(P_psi)`` of the steady-state Kalman-Bucy filter of :func:`sea_model` (no bias state, no
    process noise on the ship): the error of the best estimate of the low-frequency heading, which
    every causal controller leaves in the true heading (module docstring).

    Parameters
    ----------
    design : Design
    wave : WaveYaw, optional
        The sea (default: the design's).

    Returns
    -------
    float
    """
    m = sea_model(design, wave)
    _, P = _kalman(m)
    return float(np.sqrt(P[m["ipsi"], m["ipsi"]]))


@dataclass(frozen=True)
class WaveLQG:
    """The LQG heading autopilot of a ship in a sea (see :func:`wave_lqg`).

    Parameters
    ----------
    K : ndarray
        LQR gain on the linearisation's states (``u = -K (x - x_d) - b_hat + u_ff``).
    L : ndarray
        Kalman-Bucy gain (states of :func:`sea_model` with ``bias``).
    controller : control.StateSpace
        Filter and feedback in one: inputs ``chi_d, r_d, a_d, psi_m, r_m``, output ``<steer>_c``
        (for :meth:`Design.simulate <casship.autopilot.ship_design.Design.simulate>` with
        ``controller=`` and ``estimator="raw"``).
    heading_rms : float
        Predicted heading error in the sea [rad RMS] (linear closed loop, stationary).
    rate_rms : float
        Predicted yaw rate [rad/s RMS] (for :func:`rice_exceedance`).
    steer_rms : float
        Predicted steering [rad or N m RMS].
    floor : float
        :func:`heading_error_floor` of the sea [rad].
    rho : float
        The steering weight used.
    closed_loop : control.StateSpace
        The linear loop in the sea: inputs ``w`` (the wave's white noise, unit intensity),
        ``v_psi``, ``v_r`` (compass and gyro noise, densities ``noise``); outputs ``psi, r`` (the
        ship's) and the steering ``u``.
    noise : ndarray
        Spectral densities of ``w, v_psi, v_r``.
    """

    K: np.ndarray
    L: np.ndarray
    controller: control.StateSpace
    heading_rms: float
    rate_rms: float
    steer_rms: float
    floor: float
    rho: float
    closed_loop: control.StateSpace
    noise: np.ndarray


def wave_lqg(design, wave: WaveYaw | None = None, *, rho: float, q_bias: float | None = None) -> WaveLQG:
    """The H2-optimal (LQG) heading autopilot of ``design``'s ship in the sea ``wave``.

    LQR (``control.lqr``) on the exact linearisation with cost ``psi^2 + rho u^2`` (``u`` the
    steering, in its unit), and the Kalman-Bucy filter (``control.lqe``) of :func:`sea_model` with
    the steering bias; the law cancels the estimated bias and follows the reference model with the
    linearisation's steady turn (``x_d`` and ``u_ff`` for ``r_d``) and ``a_d / B_r``. Among all
    linear loops on compass and gyro it minimises ``E[psi^2] + rho E[u^2]`` in this sea.

    Parameters
    ----------
    design : Design
    wave : WaveYaw, optional
        The sea (default: the design's).
    rho : float
        Steering weight [rad^2 per (steering unit)^2], positive.
    q_bias : float, optional
        Spectral density of the bias drift [(steering unit)^2 / s] (default: the heading observer's,
        ``settings.observer_q[1]``).

    Returns
    -------
    WaveLQG
    """
    from scipy.linalg import solve_continuous_lyapunov

    if not (np.isfinite(rho) and rho > 0):
        raise InputError(f"rho must be positive and finite, got {rho}")
    s = design.settings
    qb = float(s.observer_q[1]) if q_bias is None else float(q_bias)
    if not (np.isfinite(qb) and qb >= 0):
        raise InputError(f"q_bias must be >= 0, got {q_bias}")
    m = sea_model(design, wave, bias=True)
    floor = heading_error_floor(design, m["wave"])
    A, B, C, R, n0 = m["A"], m["B"], m["C"], m["R"], m["n_ship"]
    ipsi, ir = m["ipsi"], m["ir"]
    A0, B0 = A[:n0, :n0], B[:n0]
    Qx = np.zeros((n0, n0))
    Qx[ipsi, ipsi] = 1.0
    K, _, _ = control.lqr(A0, B0, Qx, np.array([[rho]]))
    K = np.asarray(K, float)
    L, _ = _kalman(m, qb)
    n = A.shape[0]
    Kh = np.zeros((1, n))
    Kh[0, :n0], Kh[0, n0] = K[0], 1.0                        # u = -K x_hat - b_hat (+ reference terms)
    # stationary closed loop in the sea: true ship x, filter x_hat, wave; inputs wave noise, compass, gyro
    Ct = C[:, :n0]
    Aw, Gw = A[n - 2:, n - 2:], m["G"][n - 2:, :1]
    N = n0 + n + 2
    Acl = np.zeros((N, N))
    Acl[:n0, :n0], Acl[:n0, n0:n0 + n] = A0, -B0 @ Kh
    Acl[n0:n0 + n, :n0], Acl[n0:n0 + n, n0:n0 + n] = L @ Ct, A - B @ Kh - L @ C
    Acl[n0:n0 + n, n0 + n:] = L @ np.eye(2)
    Acl[n0 + n:, n0 + n:] = Aw
    Bcl = np.zeros((N, 3))
    Bcl[n0 + n:, :1], Bcl[n0:n0 + n, 1:] = Gw, L
    if np.any(np.linalg.eigvals(Acl).real >= 0):
        raise InputError(f"the LQG loop with rho = {rho:g} is not stable")
    W = np.array([1.0, R[0, 0], R[1, 1]])
    X = solve_continuous_lyapunov(Acl, -Bcl @ np.diag(W) @ Bcl.T)
    ku = np.concatenate([np.zeros(n0), -Kh[0], np.zeros(2)])
    Cy = np.zeros((3, N))
    Cy[0, ipsi], Cy[1, ir], Cy[2] = 1.0, 1.0, ku
    loop = control.ss(Acl, Bcl, Cy, np.zeros((3, 3)), inputs=["w", "v_psi", "v_r"], outputs=["psi", "r", "u"],
                      name="wave-lqg-loop")
    # reference: steady turn of the linearisation at r_d (x_d, u_ff), and a_d through the yaw-rate input gain
    free = [i for i in range(n0) if i not in (ipsi, ir)]
    M = np.hstack([A0[np.ix_(free + [ir], free)], B0[free + [ir]]])
    sol = np.linalg.solve(M, -A0[free + [ir], ir]) if M.shape[0] == M.shape[1] else np.zeros(len(free) + 1)
    Dref = np.zeros((n0, 3))                                  # x_d from (chi_d, r_d, a_d)
    Dref[ipsi, 0], Dref[ir, 1] = 1.0, 1.0
    for j, i in enumerate(free):
        Dref[i, 1] = sol[j]
    kref = (K @ Dref)[0] + np.array([0.0, sol[-1], 1.0 / B0[ir, 0]])
    ctrl = control.ss(A - B @ Kh - L @ C, np.hstack([B @ kref[None, :], L]), -Kh,
                      np.hstack([kref[None, :], np.zeros((1, 2))]), inputs=["chi_d", "r_d", "a_d", "psi_m", "r_m"],
                      outputs=[f"{design.plant.steer}_c"], name="wave-lqg")
    return WaveLQG(K, L, ctrl, float(np.sqrt(X[ipsi, ipsi])), float(np.sqrt(X[ir, ir])),
                   float(np.sqrt(max(ku @ X @ ku, 0.0))), floor, float(rho), loop, W)


def rice_exceedance(sigma: float, sigma_rate: float, level: float, duration: float) -> float:
    """Expected number of up-crossings of ``level`` by a stationary zero-mean Gaussian error with RMS
    ``sigma`` and RMS rate ``sigma_rate`` within ``duration`` (Rice's formula,
    ``duration sigma_rate / (2 pi sigma) exp(-level^2 / (2 sigma^2))``).

    Parameters
    ----------
    sigma : float
        Error RMS [rad], positive.
    sigma_rate : float
        RMS of its rate [rad/s], positive.
    level : float
        The line [rad] (e.g. 10 % of a course change).
    duration : float
        Time [s], >= 0.
    """
    for name, v in (("sigma", sigma), ("sigma_rate", sigma_rate)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"{name} must be positive, got {v}")
    if not (np.isfinite(duration) and duration >= 0) or not np.isfinite(level):
        raise InputError(f"level and duration must be finite (duration >= 0), got {level}, {duration}")
    return float(duration * sigma_rate / (2 * np.pi * sigma) * np.exp(-level**2 / (2 * sigma**2)))
