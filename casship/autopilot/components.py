"""The parts of a closed loop that are values: the sensor suite, the estimator in the loop, the
named blocks of the loop state, and the record of a run (used by
:mod:`casship.autopilot.closed_loop`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..data import Dataset

from ..gaussian import Gaussian
from ..errors import InputError, InputTypeError
from .loop_variants import READINGS, LoopFeedback

__all__ = ["Sensors", "LoopEstimator", "ClosedLoopResult", "DRAWS", "MASKS", "Layout"]

#: Names of the per-sample standard-normal draws (one row each in :meth:`ClosedLoop.draws`).
DRAWS = ("gnss_north", "gnss_east", "compass", "gyro", "wave")
#: Names of the per-sample availability masks.
MASKS = ("gnss", "compass")


@dataclass(frozen=True)
class Sensors:
    """Sensor suite of the loop: GNSS positions, compass and rate gyro (white noise, SI units).

    Parameters
    ----------
    gnss_rate, gnss_std : float
        GNSS fix rate [Hz] and North/East position noise [m].
    compass_rate, compass_std : float
        Compass rate [Hz] and heading noise [rad].
    gyro_std : float
        Rate-gyro noise [rad/s] (one reading per loop sample).
    """

    gnss_rate: float = 5.0
    gnss_std: float = 0.5
    compass_rate: float = 10.0
    compass_std: float = float(np.radians(0.5))
    gyro_std: float = float(np.radians(0.01))

    def __post_init__(self):
        for name in ("gnss_rate", "compass_rate"):
            if not getattr(self, name) > 0:
                raise InputError(f"sensor {name} must be positive, got {getattr(self, name)}")
        for name in ("gnss_std", "compass_std", "gyro_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"sensor {name} must be >= 0, got {v}")


@dataclass(frozen=True)
class LoopEstimator(LoopFeedback):
    """An estimator in the loop and how the loop reads it: a feedback source
    (:class:`~casship.autopilot.loop_variants.LoopFeedback`).

    It feeds its estimate of the controlled angle and (with ``rate="estimator"``) its rate; its
    memory (mean, covariance, ...) is a block of the loop state. It feeds an autopilot of its
    ``kind``, or one of the other kind when guidance gives the command.

    Parameters
    ----------
    est : Estimator
        A casship estimator whose measured outputs are GNSS ``x_n, y_n`` (``kind="course"``) or
        compass and gyro ``psi_m, r_m`` (``kind="heading"``).
    prior : Gaussian
        Its belief at the start of the run (before the first measurement).
    kind : {"course", "heading"}
    """

    est: object
    prior: object
    kind: str = "course"

    def __post_init__(self):
        from ..estimators.base import StepEstimator

        if not isinstance(self.est, StepEstimator):   # the loop folds the estimator's step Function
            raise InputTypeError(f"the loop runs an estimator's step Function: give a KF, EKF, UKF, EnKF or KalmanBucy, "
                                 f"got {type(self.est).__name__}")
        if self.kind not in READINGS:
            raise InputError(f"estimator kind must be 'course' or 'heading', got {self.kind!r}")
        want = self.reading.measured
        if tuple(self.est.measured) != want:
            raise InputError(f"a {self.kind} estimator must measure {list(want)}, this one measures "
                             f"{list(self.est.measured)}")

    @property
    def reading(self):
        """How the loop reads this estimator (:mod:`casship.autopilot.loop_variants`)."""
        return READINGS[self.kind]

    @property
    def step(self) -> ca.Function:
        """The estimator's step Function (named slots; memory and ``x, P``)."""
        return self.est.step

    @property
    def memory(self) -> tuple[str, ...]:
        """Names of the step's memory slots (the estimator's memory)."""
        return tuple(self.est.memory)

    def prior_at(self, north: float, east: float, psi: float, r: float, chi: float):
        """The prior moved to a start state: position and course (course estimator) or heading and
        yaw rate (heading estimator) from the ship, the rest and the covariance from :attr:`prior`.

        Parameters
        ----------
        north, east : float
            Position [m].
        psi, r : float
            Heading [rad] and yaw rate [rad/s].
        chi : float
            Course over ground [rad].

        Returns
        -------
        Gaussian
        """
        mean = np.array(self.prior.mean, dtype=float)
        self.reading.place(mean, self.state_index, north, east, psi, r, chi)
        return Gaussian(mean, self.prior.cov)

    def state_index(self, name: str) -> int:
        """Index of the estimator's state ``name``.

        Parameters
        ----------
        name : str
        """
        return self.est.model.index(name)

    # -- as the loop's feedback source (see LoopFeedback) -----------------------------------------
    @property
    def modes(self) -> tuple:
        """The mode it feeds without guidance: its :attr:`kind`."""
        return (self.kind,)

    def check_mode(self, mode: str, *, guided: bool = False):
        if self.kind != mode and not guided:
            raise InputError(f"a {self.kind} estimator cannot feed a {mode} autopilot")

    def blocks(self) -> list:
        return [(f"est_{n}", self.step.nnz_in(n)) for n in self.memory]

    def memory0(self, prior) -> dict:
        return {f"est_{n}": v for n, v in self.est.memory_from(prior()).items()}

    def meta(self, prior) -> dict:
        return {"estimator_prior": prior(), "estimator": self.est}

    def symbolic(self, loop, parts, meas, mask, dt_est, motion, steer_prev) -> dict:
        fix = ca.if_else(mask[0] > 0, meas["gnss"], parts["gnss_hold"])      # last GNSS fix (heading kind)
        fun = self.step
        call = {n: ca.reshape(parts[f"est_{n}"], fun.size_in(n)) for n in self.memory}
        model = self.est.model
        rd = self.reading
        y, msk, u = rd.symbolic_input(meas, mask, steer_prev)
        call.update(u_prev=u, u=u, y=y * msk, mask=msk, dt=dt_est, p=ca.DM(model.params()),
                    Q=ca.DM(self.est.Q), R=ca.DM(self.est.R), gate=ca.inf)
        out = fun.call(call)
        xh = out["x"]
        P = ca.reshape(out["P"], model.nx, model.nx)
        ix = self.state_index
        angle, rate_est, north, east, U = rd.read(xh, ix, fix, motion[1])
        std = ca.sqrt(P[ix(rd.angle_state), ix(rd.angle_state)])
        bias = rd.bias(xh, ix, model.state_names, ca.SX(0))
        rate = rate_est if loop.rate == "estimator" else meas["gyro"]
        return {"angle": angle, "rate": rate, "north": north, "east": east, "U": U, "angle_std": std, "bias": bias,
                "memory": {n: out[n] for n in self.memory}, "compass_hold": parts["compass_hold"], "gnss_hold": fix}

    def stepwise(self, loop, prior):
        online = self.est.online(prior())
        rd, ix, names, gyro_rate = self.reading, self.state_index, self.est.model.state_names, loop.rate == "gyro"

        def feed(s):
            y, extra = rd.online_input(s["gnss"], s["compass"], s["gyro"], s["mask"], s["steer_prev"])
            xh = online.update(y, s["dt_est"], **extra)
            angle, rate, north, east, U = rd.read(xh, ix, s["fix"], s["U"])
            std = np.sqrt(online.P[ix(rd.angle_state), ix(rd.angle_state)])
            return {"angle": angle, "rate": s["gyro"] if gyro_rate else rate, "north": north, "east": east, "U": U,
                    "angle_std": std, "bias": rd.bias(xh, ix, names, 0.0), "compass_hold": s["compass_hold"]}
        return feed


class Layout:
    """Named blocks of a flat vector (the loop state).

    Parameters
    ----------
    blocks : sequence of (str, int)
        Block names and sizes, in order.
    """

    def __init__(self, blocks: Sequence[tuple[str, int]]):
        self.names = [n for n, _ in blocks]
        self.sizes = dict(blocks)
        offsets = np.concatenate([[0], np.cumsum([k for _, k in blocks])]).astype(int)
        self.slices = {n: slice(int(a), int(b)) for n, a, b in zip(self.names, offsets[:-1], offsets[1:])}
        self.size = int(offsets[-1])

    def split(self, v) -> dict:
        """The blocks of ``v`` by name.

        Parameters
        ----------
        v : casadi.SX or array
        """
        return {n: v[s] for n, s in self.slices.items()}

    def join(self, parts: Mapping) -> ca.SX:
        """One column of the named parts (CasADi), in block order.

        Parameters
        ----------
        parts : mapping
        """
        return ca.vertcat(*[ca.reshape(parts[n], -1, 1) for n in self.names])

    def pack(self, parts: Mapping) -> np.ndarray:
        """One flat array of the named parts (numbers, matrices column-major), in block order.

        Parameters
        ----------
        parts : mapping
        """
        out = np.zeros(self.size)
        for n, s in self.slices.items():
            out[s] = np.asarray(parts[n], float).reshape(-1, order="F")
        return out


@dataclass(frozen=True)
class ClosedLoopResult:
    """Record of a closed-loop run.

    Parameters
    ----------
    data : Dataset
        Logged signals (SI units, angles in rad).
    metrics : list of dict
        Per command step (:func:`casship.autopilot.performance.course_change_metrics`).
    mode : str
        ``"course"`` or ``"heading"``.
    performance : dict
        :func:`casship.autopilot.performance.performance_report` of the run.
    controller : str
        The control law that ran (``"pid"``, ``"lqr"``, ``"mpc"``, ``"pid gain schedule (5
        speeds)"``...; :func:`casship.autopilot.plots.controller_name`).
    steer : str
        The steering input (``"delta"`` a rudder, ``"tau_N"`` a yaw moment).
    guidance : LOSGuidance, optional
        The path guidance of a track-control run.
    """

    data: Dataset
    metrics: list
    mode: str
    performance: dict = field(default_factory=dict)
    controller: str = ""
    steer: str = "delta"
    guidance: object = None

    def summary(self) -> dict:
        """Mode, per-step metrics and the performance report."""
        return {"mode": self.mode, "steps": self.metrics, "performance": self.performance}

    def plot(self, ax=None, path=None, *, title: str = ""):
        """Course, rate, steering and track of the run (waypoints and intended track with guidance).

        Parameters
        ----------
        ax : four matplotlib Axes, optional
            Draw into these axes instead of a new figure.
        path : str or Path, optional
            Also write the figure there (PNG unless the suffix says otherwise).
        title : str
            Figure title (default: mode and controller).

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting` and :func:`casship.autopilot.plots.plot_closed_loop`.
        """
        from ..plotting import split_args
        from .plots import plot_closed_loop

        ax, path = split_args(ax, path)
        return plot_closed_loop(self, path, title, ax=ax)

    def __repr__(self) -> str:
        return (f"ClosedLoopResult(mode={self.mode!r}"
                + (f", controller={self.controller!r}" if self.controller else "")
                + f", samples={len(self.data)}, steps={len(self.metrics)}, "
                f"rate_limited={self.performance.get('rate_limited_fraction', float('nan')):.3f})")
