"""Estimators of the autopilot loop and the first-order wave model.

* Course mode (Fossen & Fossen 2021): GNSS positions into the five-state SOG/COG EKF
  (:func:`casship.models.sog_cog`); :func:`course_ekf` tunes it from the sensor noise and the ship.
* Heading mode: compass and rate gyro into a Kalman filter on the Nomoto model with a rudder-bias
  state (:func:`heading_observer`), optionally with a wave filter (Fossen 2021, Sec. 10.2 and 13.4):
  the first-order (wave-frequency) yaw as a second-order resonant process in the estimator
  (:class:`WaveYaw`), so that the estimate the autopilot steers on is the low-frequency heading and
  the rudder does not chase the wave yaw.
* :class:`WaveYaw` is that resonant process as a python-control system and as a discrete step that
  the closed loop adds to the measured heading and yaw rate.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import control
import numpy as np

from ..gaussian import Gaussian
from ..discretize import discretize
from ..builder import ModelBuilder
from ..model import Model
from ..errors import InputError

__all__ = ["WaveYaw", "course_ekf", "course_prior", "heading_observer", "heading_kf", "heading_prior"]


@dataclass(frozen=True)
class WaveYaw:
    """First-order (wave-frequency) yaw as a narrow resonant process driven by white noise.

    ``psi_w'' + 2 lambda w0 psi_w' + w0^2 psi_w = K w`` with ``K = 2 lambda w0^2 sigma``, so that
    ``sigma`` [rad] is the peak amplitude of ``psi_w / w`` (Fossen 2021, Sec. 10.2.4 uses the same
    resonance); the states are the wave yaw ``psi_w`` and its rate ``r_w``, which the compass and
    the rate gyro both see. For unit-intensity white noise the standard deviation of ``psi_w`` is
    ``sigma sqrt(lambda w0)``. Fossen's wave filter writes the response with an extra zero at the
    origin (``K_w s / (s^2 + 2 lambda w0 s + w0^2)``); its rate then holds the white noise itself,
    which a gyro reading cannot be consistent with, so casship uses the position-and-rate form.

    Parameters
    ----------
    w0 : float
        Peak (encounter) frequency [rad/s].
    sigma : float
        Intensity [rad].
    lam : float
        Relative damping of the resonance (0.1 for a narrow sea spectrum).
    """

    w0: float
    sigma: float
    lam: float = 0.1

    def __post_init__(self):
        for name in ("w0", "lam"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise InputError(f"wave {name} must be positive, got {v}")
        if not (np.isfinite(self.sigma) and self.sigma >= 0):
            raise InputError(f"wave sigma must be >= 0, got {self.sigma}")

    @property
    def K(self) -> float:
        """Gain of the white noise on the wave yaw acceleration."""
        return 2 * self.lam * self.w0**2 * self.sigma

    @property
    def std(self) -> float:
        """Standard deviation of ``psi_w`` [rad] for unit-intensity white noise."""
        return float(self.sigma * np.sqrt(self.lam * self.w0))

    def _matrices(self):
        A = np.array([[0.0, 1.0], [-self.w0**2, -2 * self.lam * self.w0]])
        return A, np.array([[0.0], [self.K]])

    def system(self) -> control.StateSpace:
        """Labelled state space: input ``w``, states and outputs ``psi_w, r_w``."""
        A, B = self._matrices()
        return control.ss(A, B, np.eye(2), np.zeros((2, 1)), states=["psi_w", "r_w"], inputs=["w"],
                          outputs=["psi_w", "r_w"], name="wave_yaw")

    def discrete(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact zero-order-hold discretisation ``(Ad, Bd)`` of ``psi_w, r_w`` for a standard-normal
        draw per step scaled to the continuous intensity (``w = v / sqrt(dt)``).

        Parameters
        ----------
        dt : float
            Step [s].
        """
        from scipy.linalg import expm

        A, G = self._matrices()
        M = expm(np.block([[A, G], [np.zeros((1, 3))]]) * dt)
        return M[:2, :2], M[:2, 2:] / np.sqrt(dt)

    def symbolic_step(self, xw, draw, dt: float):
        """Next ``[psi_w, r_w]`` and the present ``(psi_w, r_w)`` (CasADi expressions).

        Parameters
        ----------
        xw : casadi.SX
            State ``[psi_w, r_w]``.
        draw : casadi.SX
            Standard-normal draw of the step.
        dt : float
            Step [s].
        """
        Ad, Bd = self.discrete(dt)
        return ca.mtimes(ca.DM(Ad), xw) + ca.DM(Bd) * draw, xw[0], xw[1]


def course_ekf(dt: float, *, gnss_std: float, alpha=(0.01, 0.1), q=(0.1, 0.01), options=None):
    """The SOG/COG EKF (Euler, as MSS ``EKF_5states.m``) on GNSS North/East positions.

    Parameters
    ----------
    dt : float
        Filter period [s].
    gnss_std : float
        Position noise [m] (``R = gnss_std^2 I``).
    alpha : (float, float)
        Singer constants of speed and course rate [1/s].
    q : (float, float)
        Variances of ``w_U`` and ``w_chi`` held over a sample (the estimator's ``Q``).
    options : mapping, optional
        EKF options.
    """
    from ..estimators import EKF
    from ..models import sog_cog

    return EKF(discretize(sog_cog(*alpha), dt, "euler"), Q=np.diag(np.asarray(q, float)), R=np.eye(2) * gnss_std**2,
               options=options)


def course_prior(north: float, east: float, speed: float, chi: float, gnss_std: float) -> Gaussian:
    """Prior of the SOG/COG EKF at the start of a run (course known to about 5 deg).

    Parameters
    ----------
    north, east : float
        Position [m].
    speed : float
        Speed over ground [m/s].
    chi : float
        Course [rad].
    gnss_std : float
        Position noise [m].
    """
    return Gaussian(np.array([north, east, speed, chi, 0.0]),
                    np.diag([gnss_std**2, gnss_std**2, 1.0, np.radians(5.0) ** 2, 0.01]))


def heading_observer(K: float, T: float, wave: WaveYaw | None = None, *, steer: str = "delta",
                     steering=None, second: tuple | None = None) -> Model:
    """Nomoto heading model with a rudder bias and optionally Fossen's wave filter (a casship Model).

    States ``psi, r, b`` (``T r' + r = K (delta + b)``, ``b`` a slowly varying rudder bias that a
    steady wind or current moment looks like), and with ``wave`` the wave states ``psi_w, r_w``
    (:class:`WaveYaw`). Outputs ``psi_m = psi + psi_w`` (compass) and ``r_m = r + r_w`` (rate gyro).
    Noises ``w_r`` (yaw acceleration), ``w_b`` (bias drift), ``w_w`` (wave intensity).

    With ``steering`` (the ship's steady steering ``s(r)``) the damping is the nonlinear ship's:
    ``T r' + K s(r) = K (delta + b)`` (the nonlinear Nomoto model, ``K s`` the steady-turn curve), so
    that the bias does not take up the extra steering of a large turn (the model of the MPC, whose
    disturbance this bias is). With ``second = (T1, T2, T3)`` the yaw dynamics are the second-order
    Nomoto model in the observer form of :meth:`Nomoto.system <casship.autopilot.nomoto.Nomoto.system>`
    (the extra state ``xi``): ``T1 T2 r'' + (T1 + T2) r' + K s(r) = K (delta + b + T3 delta')``.

    Parameters
    ----------
    K, T : float
        Nomoto gain and time constant.
    wave : WaveYaw, optional
        The wave model of the filter.
    steer : str
        Name of the steering input.
    steering : SteeringFeedforward, optional
        Steady steering of the nonlinear ship (:func:`~casship.autopilot.plants.steering_feedforward`).
    second : tuple of float, optional
        ``T1, T2, T3`` of the second-order Nomoto model.
    """
    name = "heading-observer" + ("+wave" if wave is not None else "")
    b = ModelBuilder(name, "Nomoto heading model with rudder bias" + (" and wave filter" if wave else ""))
    psi = b.state("psi", unit="rad", angle=True)
    r = b.state("r", unit="rad/s")
    bias = b.state("b", unit="rad", doc="rudder bias")
    delta = b.input(steer)
    Kp, Tp = b.param("K", K, unit="1/s"), b.param("T", T, unit="s")
    damping = r if steering is None else Kp * steering(r)
    if second is None:
        b.ode(psi=r, r=(Kp * (delta + bias) - damping) / Tp + b.noise("w_r"), b=b.noise("w_b"))
    else:
        T1, T2, T3 = (float(v) for v in second)
        xi = b.state("xi", unit="rad/s^2", doc="internal state of the second-order Nomoto model")
        b.ode(psi=r, r=-(T1 + T2) / (T1 * T2) * r + xi + Kp * T3 / (T1 * T2) * (delta + bias) + b.noise("w_r"),
              xi=(Kp * (delta + bias) - damping) / (T1 * T2), b=b.noise("w_b"))
    psi_w = r_w = 0
    if wave is not None:
        psi_w = b.state("psi_w", unit="rad", doc="first-order wave yaw")
        r_w = b.state("r_w", unit="rad/s", doc="its rate")
        w0, lam = b.param("w0", wave.w0, unit="rad/s"), b.param("lam", wave.lam)
        b.ode(psi_w=r_w, r_w=-w0**2 * psi_w - 2 * lam * w0 * r_w + wave.K * b.noise("w_w"))
    b.output("psi_m", psi + psi_w, angle=True)
    b.output("r_m", r + r_w)
    return b.build()


def heading_kf(observer: Model, dt: float, *, compass_std: float, gyro_std: float, q_r: float, q_b: float,
               q_w: float = 1.0, options=None):
    """Kalman filter (casship's EKF, linear model) of :func:`heading_observer` at period ``dt``.

    ``q_r``, ``q_b``, ``q_w`` are spectral densities of ``w_r, w_b, w_w``; the filter's ``Q`` is
    ``q / dt`` (the variance of the noise held over a sample, RK4 step).

    Parameters
    ----------
    observer : Model
        From :func:`heading_observer`.
    dt : float
        Filter period [s].
    compass_std, gyro_std : float
        Measurement noise [rad], [rad/s].
    q_r, q_b, q_w : float
        Process noise densities.
    options : mapping, optional
        EKF options.
    """
    from ..estimators import EKF

    q = {"w_r": q_r / dt, "w_b": q_b / dt, "w_w": q_w / dt}
    Q = np.diag([q[n] for n in observer.noise_names])
    return EKF(discretize(observer, dt, "rk4"), Q=Q, R=np.diag([compass_std**2, gyro_std**2]), options=options)


def heading_prior(observer: Model, psi: float, r: float, compass_std: float) -> Gaussian:
    """Prior of the heading observer at the start of a run.

    Parameters
    ----------
    observer : Model
    psi, r : float
        Heading [rad] and yaw rate [rad/s].
    compass_std : float
        Heading noise [rad].
    """
    mean = observer.states(psi=psi, r=r)
    var = {"psi": compass_std**2, "r": 1e-6, "xi": 1e-10, "b": np.radians(2.0) ** 2, "psi_w": np.radians(2.0) ** 2,
           "r_w": np.radians(2.0) ** 2}
    return Gaussian(mean, np.diag([var[n] for n in observer.state_names]))


def command_noise(Ad, G, C, Q, R, angle: int, rate: int, Kp: float, Kd: float) -> float:
    """Standard deviation of the steering command that estimation errors cause: ``Kp`` times the
    angle error plus ``Kd`` times the rate error, from the steady-state (predicted) covariance of the
    Kalman filter ``x+ = Ad x + G w``, ``y = C x + v`` (``control.dlqe``)."""
    _, P, _ = control.dlqe(Ad, G, C, Q, R)
    k = np.zeros(np.shape(Ad)[0])
    k[angle], k[rate] = Kp, Kd
    return float(np.sqrt(max(k @ np.asarray(P) @ k, 0.0)))


def _largest_within(q_max: float, noise, budget: float, steps: int = 40) -> tuple[float, float]:
    """The largest ``q = q_max 10^(-k/4)``, ``k = 0 .. steps``, with ``noise(q) <= budget`` (the noise
    grows with ``q``: bisection over ``k``); ``k = steps`` if none meets it. Returns ``(q, noise(q))``."""
    sigma = noise(q_max)
    if sigma <= budget:
        return q_max, sigma
    lo, hi = 0, steps            # noise(lo) > budget; find the smallest k in (lo, hi] that meets it
    found = None
    while hi - lo > 1:
        mid = (lo + hi) // 2
        s_mid = noise(q_max / 10 ** (mid / 4))
        if s_mid <= budget:
            hi, found = mid, s_mid
        else:
            lo = mid
    q = q_max / 10 ** (hi / 4)
    return q, found if found is not None else noise(q)


def _multirate(Ad, G, Q, every: int):
    """Transition and noise covariance over ``every`` steps (measurements once per ``every`` steps)."""
    A_k, N = np.eye(Ad.shape[0]), np.zeros_like(Ad)
    for _ in range(every):
        N = Ad @ N @ Ad.T + G @ Q @ G.T
        A_k = Ad @ A_k
    return A_k, N


def tune_course_q(*, speed: float, alpha, q_U: float, q_chi_max: float, dt: float, gnss_every: int,
                  gnss_std: float, Kp: float, Kd: float, budget: float) -> tuple[float, float]:
    """Largest course-rate process noise (from ``q_chi_max`` down in steps of 10^(1/4)) for which
    the SOG/COG filter, linearised on a straight course, makes a steering-command noise of at most
    ``budget``. Returns ``(q_chi, command noise std)``."""
    a1, a2 = alpha
    A = np.zeros((5, 5))
    A[0, 2], A[1, 3], A[2, 2], A[3, 4], A[4, 4] = 1.0, speed, -a1, 1.0, -a2
    Ad = np.eye(5) + dt * A
    G = np.zeros((5, 2))
    G[2, 0] = G[4, 1] = dt
    C = np.zeros((2, 5))
    C[0, 0] = C[1, 1] = 1.0
    R = np.eye(2) * gnss_std**2

    def noise(q):
        A_k, N = _multirate(Ad, G, np.diag([q_U, q]), gnss_every)
        return command_noise(A_k, np.eye(5), C, N + 1e-30 * np.eye(5), R, 3, 4, Kp, Kd)

    return _largest_within(q_chi_max, noise, budget)


def _heading_matrices(K: float, T: float, wave: WaveYaw | None):
    """Continuous ``A, B, G, C`` of the heading observer (:func:`heading_observer`): states ``psi, r, b``
    and with ``wave`` the wave states ``psi_w, r_w``; noises ``w_r, w_b`` (and ``w_w``); outputs
    compass and gyro."""
    n = 5 if wave is not None else 3
    A = np.zeros((n, n))
    A[0, 1], A[1, 1], A[1, 2] = 1.0, -1.0 / T, K / T
    B = np.zeros((n, 1))
    B[1, 0] = K / T
    G = np.zeros((n, 3 if wave is not None else 2))
    G[1, 0] = G[2, 1] = 1.0
    C = np.zeros((2, n))
    C[0, 0] = C[1, 1] = 1.0
    if wave is not None:
        Aw, Gw = wave._matrices()
        A[3:, 3:], G[3:, 2:] = Aw, Gw
        C[0, 3] = C[1, 4] = 1.0
    return A, B, G, C


def wave_command_noise(Ad, C, L, k, wave: WaveYaw, dt: float) -> float:
    """Standard deviation of the steering command ``k x_hat`` that first-order wave yaw on the compass
    and the gyro makes through the steady-state filter ``x_hat+ = (Ad - L C) x_hat + L y`` (the ship
    itself held still: the noise budget's open-loop reading). The wave process (:meth:`WaveYaw.discrete`)
    and the filter are one linear system; its stationary covariance by ``scipy.linalg.solve_discrete_lyapunov``.

    Parameters
    ----------
    Ad, C, L : ndarray
        The filter's transition, output matrix and (predictor-form) gain.
    k : ndarray
        Command weights on the filter's states.
    wave : WaveYaw
    dt : float
        Filter period [s].
    """
    from scipy.linalg import solve_discrete_lyapunov

    Aw, Bw = wave.discrete(dt)
    n = Ad.shape[0]
    Az = np.block([[Aw, np.zeros((2, n))], [L @ np.eye(2), Ad - L @ C]])
    Bz = np.vstack([Bw, np.zeros((n, 1))])
    Pz = solve_discrete_lyapunov(Az, Bz @ Bz.T)
    kz = np.concatenate([np.zeros(2), k])
    return float(np.sqrt(max(kz @ Pz @ kz, 0.0)))


def tune_heading_q(*, K: float, T: float, q_r_max: float, q_b: float, dt: float, compass_every: int,
                   compass_std: float, gyro_std: float, Kp: float, Kd: float, budget: float,
                   wave: WaveYaw | None = None, wave_filter: bool = False) -> tuple[float, float]:
    """Like :func:`tune_course_q` for the heading observer (compass readings once per
    ``compass_every`` samples taken as one reading per sample with ``compass_every`` times the
    variance). With ``wave`` the first-order wave yaw on compass and gyro counts too: through the
    observer without the wave model (:func:`wave_command_noise`), or, with ``wave_filter``, through
    the observer with it (its error covariance holds the wave's share). Returns ``(q_r, command noise std)``."""
    model_wave = wave if (wave is not None and wave_filter) else None
    A, _, G, C = _heading_matrices(K, T, model_wave)
    Ad = np.eye(A.shape[0]) + dt * A
    Gd = dt * G
    R = np.diag([compass_std**2 * compass_every, gyro_std**2])
    k = np.zeros(A.shape[0])
    k[0], k[1] = Kp, Kd

    def noise(q):
        Q = np.diag([q / dt, max(q_b, 1e-30) / dt] + ([1.0 / dt] if model_wave is not None else []))
        L, P, _ = control.dlqe(Ad, Gd, C, Q, R)
        sensor = float(np.sqrt(max(k @ np.asarray(P) @ k, 0.0)))
        if wave is None or wave_filter:
            return sensor
        L = Ad @ np.asarray(P) @ C.T @ np.linalg.inv(C @ np.asarray(P) @ C.T + R)     # predictor-form gain
        return float(np.hypot(sensor, wave_command_noise(Ad, C, L, k, wave, dt)))

    return _largest_within(q_r_max, noise, budget)


def course_filter_system(speed: float, alpha2: float, q_chi: float, r_pos: float) -> control.StateSpace:
    """The SOG/COG filter's cross-track part on a straight course as a steady-state Kalman-Bucy
    filter (``control.lqe``), a labelled system for the linear loop.

    States ``y_n, chi, omega_chi`` (``y_n' = U chi``, ``chi' = omega_chi``,
    ``omega_chi' = -alpha2 omega_chi + w_chi``); input the measured cross position ``y_n``;
    outputs ``chi_hat, rate_hat``. ``q_chi`` and ``r_pos`` are the spectral densities of the course
    acceleration noise and of the position noise (variance times sampling period).
    """
    A = np.array([[0.0, speed, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -alpha2]])
    G = np.array([[0.0], [0.0], [1.0]])
    C = np.array([[1.0, 0.0, 0.0]])
    L, _, _ = control.lqe(A, G, C, np.array([[q_chi]]), np.array([[r_pos]]))
    L = np.asarray(L)
    Co = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    return control.ss(A - L @ C, L, Co, np.zeros((2, 1)), states=["y_h", "chi_h", "omega_h"], inputs=["y_n"],
                      outputs=["chi_hat", "rate_hat"], name="estimator")


def heading_filter_system(K: float, T: float, q_r: float, q_b: float, r_psi: float, r_r: float, *,
                          steer: str = "delta", wave: WaveYaw | None = None) -> control.StateSpace:
    """The heading observer as a steady-state Kalman-Bucy filter (``control.lqe``), a labelled
    system for the linear loop: inputs ``<steer>, psi, r`` (measured), outputs ``chi_hat, rate_hat``
    (heading and yaw-rate estimates). Densities as in :func:`course_filter_system`; with ``wave`` the
    filter holds the wave model (Fossen's wave filter, unit wave intensity), so that the loop's
    margins are those of the loop with the wave filter in it."""
    A, B, G, C = _heading_matrices(K, T, wave)
    Q = np.diag([q_r, max(q_b, 1e-30)] + ([1.0] if wave is not None else []))
    L, _, _ = control.lqe(A, G, C, Q, np.diag([r_psi, r_r]))
    L = np.asarray(L)
    n = A.shape[0]
    states = ["psi_h", "r_h", "b_h"] + (["psi_w_h", "r_w_h"] if wave is not None else [])
    return control.ss(A - L @ C, np.hstack([B, L]), np.eye(n)[:2], np.zeros((2, 3)), states=states,
                      inputs=[steer, "psi", "r"], outputs=["chi_hat", "rate_hat"], name="estimator")


def linear_estimator(settings, nomoto, steer: str = "delta") -> control.StateSpace:
    """The loop's estimator as a steady-state Kalman-Bucy filter for the linear analysis, from
    autopilot settings (:class:`~casship.autopilot.defaults.AutopilotSettings` or any object with
    the same fields): :func:`course_filter_system` in course mode, :func:`heading_filter_system` in
    heading mode. The discrete filter's ``Q`` (held over ``dt``) and ``R`` (one reading per sensor
    period) become spectral densities ``Q dt`` and ``R / rate``."""
    s = settings
    if s.mode == "course":
        return course_filter_system(s.speed, s.ekf_alpha[1], s.ekf_q[1] * s.dt, s.gnss_std**2 / s.gnss_rate)
    q_r, q_b = s.observer_q
    wave = settings_wave(s) if getattr(s, "wave_filter", False) else None
    kappa = observer_damping(s, nomoto) if wave is not None else 1.0
    return heading_filter_system(nomoto.K / kappa, nomoto.T / kappa, q_r, q_b, s.compass_std**2 / s.compass_rate,
                                 s.gyro_std**2 * s.dt, steer=steer, wave=wave)


def observer_damping(settings, nomoto) -> float:
    """The yaw damping of the loop's heading observer on a straight course, relative to the Nomoto model's.

    With the wave filter and the nonlinear feed-forward the observer damps on the ship's steady
    steering (``T r' + K s(r) = K (delta + b)``, :func:`heading_observer`): linearised on a straight
    course its damping is ``kappa r`` with ``kappa = K s'(0)``, the slope of the steering table at
    ``r = 0`` taken as the mean of its two sides (the secant between the table's points either side of
    0). The linear observer is then the Nomoto model ``(K / kappa, T / kappa)``, and the loop's margins
    are those of the observer that runs. 1 when the observer damps linearly.

    Parameters
    ----------
    settings : AutopilotSettings
    nomoto : Nomoto

    Returns
    -------
    float
    """
    table = getattr(settings, "steering", None)
    if table is None or getattr(settings, "feedforward", "linear") != "nonlinear":
        return 1.0
    r, s = np.asarray(table.rates, float), np.asarray(table.steer, float)
    i = int(np.argmin(np.abs(r)))
    kappa = float(nomoto.K * (s[i + 1] - s[i - 1]) / (r[i + 1] - r[i - 1]))
    if not np.isfinite(kappa) or kappa == 0.0:
        raise InputError(f"the observer's steady steering has no slope at r = 0 (K s'(0) = {kappa}); the table's "
                         "rates about 0 cannot give a linear observer")
    return kappa


def settings_wave(settings) -> WaveYaw | None:
    """The sea state the settings design for (``wave_w0``, ``wave_std``; relative damping 0.1), or
    None in calm water."""
    w0, std = float(getattr(settings, "wave_w0", 0.0) or 0.0), float(getattr(settings, "wave_std", 0.0) or 0.0)
    if w0 <= 0 or std <= 0:
        return None
    lam = 0.1
    return WaveYaw(w0, std / np.sqrt(lam * w0), lam)
