"""One call from a ship model to an autopilot and its closed loop: :func:`design_autopilot` and the
:class:`Design` value it returns (python-control systems, margins, the nonlinear law, the steering
gear, the settings and where each came from).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from typing import Mapping

import control
import numpy as np

from ..model import Model
from .analysis import course_linearization, loop_systems, margins
from .closed_loop import ClosedLoop
from .components import ClosedLoopResult, LoopEstimator, Sensors
from .defaults import AutopilotSettings, derive_settings
from .designs import lqr_design, pid_pole_placement
from .estimation import WaveYaw, linear_estimator, settings_wave, course_ekf, course_prior, heading_kf, heading_observer, heading_prior
from .law import Actuator, Autopilot, PIDGains
from .nomoto import Nomoto, nomoto_from_linear
from .performance import CRITERIA, course_change_metrics, course_scenario, performance_report
from .plants import SteeringPlant, steering_plant
from .reference import ReferenceModel
from .slot import LinearController
from .mpc import MPCAutopilot, MPCLaw
from ..errors import InputError, InputTypeError

__all__ = ["Design", "design_autopilot", "simulate_autopilot", "RateLimitWarning"]


class RateLimitWarning(UserWarning):
    """The steering gear ran at its rate limit for longer than the criterion allows."""


@dataclass(frozen=True)
class Design:
    """An autopilot designed for a ship at an operating point (see :func:`design_autopilot`).

    Parameters
    ----------
    plant : SteeringPlant
        The ship at its trim point (``plant.x0``) with the other inputs bound.
    linearization : control.StateSpace
        Exact linearisation from the steering to ``chi, psi, r`` (labelled).
    nomoto : Nomoto
        The design model.
    gains : PIDGains
    controller : control.StateSpace
        The linear law: inputs ``chi_d, r_d, a_d, chi, r``, output ``<steer>_c``.
    loop : control.StateSpace
        Open loop cut at the steering command (``control.margin`` convention).
    closed_loop : control.StateSpace
        Reference model, law, steering gear and ship (input ``chi_ref``; outputs ``chi, r,
        <steer>_c, <steer>``).
    margins : dict
        :func:`~casship.autopilot.analysis.margins` of ``loop``.
    autopilot : Autopilot
        The digital law with reference model, limit and anti-windup.
    actuator : Actuator
        The steering gear.
    settings : AutopilotSettings
    schedule : tuple of Design
        With a gain schedule: the point designs at the schedule's speeds (``autopilot`` is then a
        :class:`~casship.autopilot.schedule.ScheduledAutopilot`; ``gains``, ``loop``, ``margins`` are
        the schedule's at this design's speed).
    """

    plant: SteeringPlant
    linearization: control.StateSpace
    nomoto: Nomoto
    gains: PIDGains
    controller: control.StateSpace
    loop: control.StateSpace
    closed_loop: control.StateSpace
    margins: dict
    autopilot: Autopilot
    actuator: Actuator
    settings: AutopilotSettings
    schedule: tuple = ()

    @property
    def x0(self) -> np.ndarray:
        """The trim state."""
        return self.plant.x0

    def summary(self) -> dict:
        """Nomoto model, gains, margins, settings (with sources), operating point and inputs."""
        m = self.plant.model
        return {"nomoto": self.nomoto.as_dict(), "gains": self.gains.as_dict(), "margins": self.margins,
                "settings": self.settings.as_dict(), "sources": dict(self.settings.sources),
                "operating_point": dict(zip(m.state_names, map(float, self.x0))),
                "inputs": {k: float(v) for k, v in self.plant.inputs.items()}, "steer": self.plant.steer}

    def __repr__(self) -> str:
        mg = self.margins
        return (f"Design({self.plant.model.name!r}, {self.gains.method}, wn={self.settings.wn:.4g} rad/s, "
                f"PM={mg['phase_margin_deg']:.1f} deg, GM={mg['upper_gain_margin_db']:.1f}/"
                f"{mg['lower_gain_margin_db']:.1f} dB)")

    # -- the nonlinear closed loop ----------------------------------------------------------------
    def sensors(self) -> Sensors:
        """The sensor suite of the settings."""
        s = self.settings
        return Sensors(s.gnss_rate, s.gnss_std, s.compass_rate, s.compass_std, s.gyro_std)

    def estimator(self, kind: str | None = None, *, wave: WaveYaw | None = None, x0=None,
                  steering=None, second: bool = False) -> LoopEstimator:
        """The loop's estimator (tuned by the settings) started at ``x0`` (the trim point).

        Parameters
        ----------
        kind : {"course", "heading"}, optional
            ``"course"``: the SOG/COG EKF on GNSS; ``"heading"``: the heading observer on compass and
            gyro (default: the settings' mode).
        wave : WaveYaw, optional
            Put this wave model into the heading observer (wave filter).
        x0 : array, optional
            Start state (default: the trim point).
        steering : SteeringFeedforward, optional
            The heading observer's damping from the ship's steady steering (:func:`heading_observer`;
            the MPC's model).
        second : bool
            The heading observer on the second-order Nomoto model (when the design has it; the MPC's
            model).
        """
        s, pl = self.settings, self.plant
        kind = kind or s.mode
        m = pl.model
        x0 = np.asarray(x0 if x0 is not None else pl.x0, float)
        if kind == "course":
            est = course_ekf(s.dt, gnss_std=s.gnss_std, alpha=s.ekf_alpha, q=s.ekf_q)
            loop = ClosedLoop(pl, self.autopilot, self.actuator, dt=s.dt, mode="course")
            chi0 = loop.initial_angle(x0)
            speed = float(np.hypot(x0[m.index("u")], x0[m.index("v")])) if "u" in m.state_names else s.speed
            prior = course_prior(x0[m.index(pl.north)], x0[m.index(pl.east)], speed, chi0, s.gnss_std)
            return LoopEstimator(est, prior, "course")
        nom = self.nomoto
        obs = heading_observer(nom.K, nom.T, wave, steer=pl.steer, steering=steering,
                               second=(nom.T1, nom.T2, nom.T3) if second and nom.second_order else None)
        q_r, q_b = s.observer_q
        est = heading_kf(obs, s.dt, compass_std=s.compass_std, gyro_std=s.gyro_std, q_r=q_r, q_b=q_b)
        prior = heading_prior(obs, x0[m.index(pl.heading)], x0[m.index(pl.yaw_rate)], s.compass_std)
        return LoopEstimator(est, prior, "heading")

    def closed_loop_system(self, *, plant: SteeringPlant | None = None, environment: Mapping | None = None,
                           estimator="ekf", sensors: Sensors | None = None, wave: WaveYaw | None = None,
                           wave_filter: bool | None = None, guidance=None, mode: str | None = None,
                           rate: str | None = None, controller=None) -> ClosedLoop:
        """The :class:`ClosedLoop` of this design.

        Parameters
        ----------
        plant : SteeringPlant, optional
            The truth (default: the design's plant, calm water).
        environment : mapping, optional
            Values of environment inputs of the plant (``wind_speed``, ``current_dir``, ...).
        estimator : {"ekf", "truth", "raw"}, LoopEstimator, TrueState or RawMeasurement
            ``"ekf"``: the estimator of :meth:`estimator` for the mode; the rest as
            :class:`ClosedLoop` (``"truth"`` and ``"raw"`` stand for :class:`TrueState` and
            :class:`RawMeasurement`).
        sensors : Sensors, optional
            Default: from the settings.
        wave : WaveYaw, optional
            First-order wave yaw on the measured heading and rate.
        wave_filter : bool, optional
            Put the wave model into the heading observer (Fossen's wave filter): ``wave``, else the
            sea state of the settings (``wave_w0``, ``wave_std``). Default: the settings' ``wave_filter``.
            With the nonlinear feed-forward the filter's yaw damping is then the ship's steady steering
            (:func:`heading_observer` with ``steering``).
        guidance : LOSGuidance, optional
            Path following: the course command comes from the guidance.
        mode, rate : str, optional
            Replace the settings' mode and rate source.
        controller : control.StateSpace, control.TransferFunction, LinearController or MPCAutopilot, optional
            Replaces the PID/LQR law: a python-control controller runs in the compiled loop
            (:meth:`linear_controller`), and so does an :class:`~casship.autopilot.mpc.MPCAutopilot`
            (its QP solved by HPIPM as a call node of the loop's step).
        """
        s = self.settings
        mode, rate = mode or s.mode, rate or s.rate
        pl = plant or self.plant
        if environment:
            pl = pl.replace(inputs=dict(environment))
        if wave_filter is None:
            wave_filter = s.wave_filter
        if estimator == "ekf":
            model_wave = (wave if wave is not None else settings_wave(s)) if wave_filter else None
            if wave_filter and model_wave is None:
                raise InputError("wave_filter needs a wave model: give wave, or design with wave_w0 and wave_std")
            # the MPC's disturbance is the observer's bias: estimated on the model the MPC plans with
            mpc = isinstance(controller, MPCAutopilot)
            steering = controller.steering if mpc else None
            if model_wave is not None and not mpc and s.feedforward == "nonlinear":
                # with the wave filter the observer damps on the ship's steady steering: with the linear
                # damping the wave states take up the model's error in a large turn (docs, section 8)
                steering = s.steering
            estimator = self.estimator("course" if mode == "course" else "heading", wave=model_wave, x0=pl.x0,
                                       steering=steering, second=mpc and controller.order == 2)
        law = self.autopilot
        if isinstance(controller, (control.StateSpace, control.TransferFunction)):
            law = self.linear_controller(controller)
        elif isinstance(controller, MPCAutopilot):
            law = controller.law(s.dt)
        elif controller is not None:
            if not isinstance(controller, (LinearController, MPCLaw)):
                raise InputTypeError(f"controller must be a python-control system, a LinearController or an "
                                     f"MPCAutopilot, got {type(controller).__name__}")
            law = controller
        return ClosedLoop(pl, law, self.actuator, dt=s.dt, mode=mode, rate=rate, estimator=estimator,
                          sensors=sensors or self.sensors(), wave=wave, guidance=guidance)

    def linear_controller(self, sys, **options) -> LinearController:
        """A python-control controller in this design's loop: its reference model, loop period and
        steering gear (:class:`~casship.autopilot.slot.LinearController`).

        Parameters
        ----------
        sys : control.StateSpace or control.TransferFunction
            Inputs named among ``chi_d, r_d, a_d, chi, r, psi_m, r_m, e``; one output.
        **options
            ``method`` (sampling of a continuous controller), ``anti_windup``.

        Examples
        --------
        >>> lqg = lqg_design(d.nomoto, q_int=1e-6, q_e=1.0, heading_var=1e-5, rate_var=1e-9,
        ...                  yaw_accel_var=1e-10)                          # doctest: +SKIP
        >>> res = d.simulate(controller=lqg.controller, estimator="raw")   # doctest: +SKIP
        """
        return LinearController(sys, self.settings.dt, self.autopilot.reference, self.actuator, **options)

    def simulate(self, scenario: str = "course-20", t_end: float | None = None, *, seed=0, stepwise: bool = False,
                 warn: bool = True, **loop_options) -> ClosedLoopResult:
        """Run a course-change scenario on the nonlinear closed loop (one compiled fold).

        Parameters
        ----------
        scenario : str
            ``course-A``, ``step-A`` or ``rot-R`` (:func:`~casship.autopilot.performance.course_scenario`;
            a rate of turn R above the preset ``settings.r_max`` is refused); the segment length is
            ``settings.segment`` unless ``t_end`` is given.
        t_end : float, optional
            Duration [s].
        seed : int
            Sensor-noise seed.
        stepwise : bool
            Run the step-by-step reference instead of the compiled fold (same numbers, slower).
        warn : bool
            Warn (:class:`RateLimitWarning`) when the steering gear is at its rate limit for
            longer than the criterion (10 % of the time), with the fraction.
        **loop_options
            Passed to :meth:`closed_loop_system` (``plant``, ``environment``, ``estimator``, ``wave``,
            ``wave_filter``, ``mode``, ``rate``, ``sensors``).
        """
        command, t_end, steps = course_scenario(scenario, t_end, segment=self.settings.segment)
        if scenario.startswith("rot-"):
            rate = abs(np.radians(float(scenario.rsplit("-", 1)[1])) / 60.0)
            if rate > self.settings.r_max * (1 + 1e-9):
                raise InputError(f"scenario {scenario!r}: the rate of turn {np.degrees(rate) * 60:g} deg/min is above "
                                 f"the preset rate of turn r_max = {np.degrees(self.settings.r_max) * 60:.4g} deg/min "
                                 "the reference model holds the turn to (give a lower rate, or r_max within what "
                                 f"the ship turns: {np.degrees(self.settings.turn_rate_top) * 60:.4g} deg/min at its "
                                 "steering limit)")
        return simulate_autopilot(self, command, t_end, step_times=steps, seed=seed, stepwise=stepwise, warn=warn,
                                  **loop_options)

    def evaluate(self, loop: ClosedLoop, data, steps, *, warn: bool = True) -> ClosedLoopResult:
        """Metrics and the performance report of a closed-loop record.

        Parameters
        ----------
        loop : ClosedLoop
        data : Dataset
            Its record.
        steps : sequence of float
            Times of the command changes [s].
        warn : bool
            Warn when the rate limit is active too long.
        """
        controlled = "chi" if loop.mode == "course" else "psi"
        metrics = course_change_metrics(data, steps, controlled=controlled)
        report = performance_report(data, metrics, steer_max=self.actuator.steer_max, controlled=controlled,
                                    r_max=self.settings.r_max)
        limit = CRITERIA["rate_limited_fraction"][0]
        if warn and report["rate_limited_fraction"] >= limit:
            warnings.warn(f"{self.plant.model.name}: the steering gear ran at its rate limit "
                          f"({self.actuator.rate_max:.4g}/s) {100 * report['rate_limited_fraction']:.1f} % of the "
                          f"time (criterion < {100 * limit:.0f} %); lower wn_ref or wn, or filter the feedback",
                          RateLimitWarning, stacklevel=3)
        from .plots import controller_name

        return ClosedLoopResult(data=data, metrics=metrics, mode=loop.mode, performance=report,
                                controller=controller_name(loop.autopilot), steer=self.plant.steer,
                                guidance=loop.guidance)


def design_autopilot(model: Model, speed: float | None = None, *, p=None, steer: str | None = None,
                     inputs: Mapping[str, float] | None = None, nomoto: Nomoto | None = None,
                     schedule=None, **settings) -> Design:
    """Design a course autopilot for ``model`` at a straight-run ``speed``.

    Steps: the operating point (:func:`~casship.autopilot.plants.steering_plant`: trim of the
    propeller rate, or the surge force of a two-propeller craft steered by a yaw moment), the exact
    labelled linearisation (:func:`~casship.autopilot.analysis.course_linearization`), its Nomoto
    reduction (unless ``nomoto`` is given, e.g. one fitted to zig-zags), the settings from the
    ship (:func:`~casship.autopilot.defaults.derive_settings`; any of them may be given here),
    PID pole placement or LQR, the reference model, the steering gear, and the loop, closed loop
    and margins by python-control on the linearised ship.

    Parameters
    ----------
    model : Model
    speed : float, optional
        Straight-run speed [m/s] (default ``model.vessel.U0``).
    p : array or mapping, optional
        Parameters of the design model (e.g. a fit's); the plant's truth by default too.
    steer : str, optional
        Steering input (default from ``model.vessel``).
    inputs : mapping, optional
        Values of other inputs held fixed (a propeller rate given here is not trimmed).
    nomoto : Nomoto, optional
        Design on this model instead of the linearisation's.
    schedule : sequence of float or "default", optional
        Gain scheduling: design at each of these speeds [m/s] (``"default"``: 40 % to 100 % of the
        approach speed, :func:`~casship.autopilot.schedule.default_schedule`) and run one law
        interpolating them in the measured speed (:class:`~casship.autopilot.schedule.ScheduledAutopilot`);
        the returned design is at ``speed``, with the schedule's gains there.
    **settings
        Any name of :data:`~casship.autopilot.defaults.RULES` (``wn``, ``wn_ref``, ``method``,
        ``mode``, ``dt``, ``gnss_std``, ...); an unknown name raises ``ValueError``.

    Examples
    --------
    >>> from casship.models import get_model
    >>> d = design_autopilot(get_model("kvlcc2"))       # doctest: +SKIP
    >>> control.margin(d.loop)                          # doctest: +SKIP
    """
    if settings.get("speed") is not None:      # the speed setting is the operating point
        if speed is not None and float(settings["speed"]) != float(speed):
            raise InputError(f"speed {speed} and the speed setting {settings['speed']} disagree")
        speed = settings.pop("speed")
    if schedule is not None:
        return _scheduled_design(model, speed, schedule, p=p, steer=steer, inputs=inputs, nomoto=nomoto,
                                 settings=settings)
    plant = steering_plant(model, speed, p=p, steer=steer, inputs=inputs)
    lin = course_linearization(plant)
    nom = nomoto if nomoto is not None else nomoto_from_linear(lin, steer=plant.steer)
    s = derive_settings(plant, lin, nom, settings)
    if s.method == "pid":
        gains = pid_pole_placement(nom, s.wn, s.zeta, integral=s.integral)
    else:
        gains = lqr_design(nom, **s.lqr_weights)
    if nom.second_order and nom.T3 > 0:       # the inertia of a quick steering change, for the feed-forward
        gains = replace(gains, m_hf=nom.T1 * nom.T2 / (nom.K * nom.T3), T3=nom.T3)
    reference = ReferenceModel(s.wn_ref, s.zeta_ref, s.r_max)
    actuator = Actuator(s.steer_max, s.steer_rate_max, s.actuator_T)
    autopilot = Autopilot(gains, reference, s.steer_max, filter_T=s.filter_T,
                          steering=s.steering if s.feedforward == "nonlinear" else None)
    controlled = "chi" if s.mode == "course" else "psi"
    L, closed = loop_systems(lin, gains, actuator, delay=s.delay, reference=reference, controlled=controlled,
                             filter_T=s.filter_T, estimator=linear_estimator(s, nom, plant.steer), rate=s.rate)
    controller = gains.controller(steer=plant.steer)
    return Design(plant, lin, nom, gains, controller, L, closed, margins(L), autopilot, actuator, s)


def _scheduled_design(model, speed, schedule, *, p, steer, inputs, nomoto, settings) -> Design:
    """The design at ``speed`` whose law is the gain schedule over the ``schedule`` speeds."""
    from .schedule import ScheduledAutopilot, default_schedule

    if nomoto is not None:
        raise InputError("a gain schedule designs on each speed's own linearisation; do not give nomoto")
    vessel = model.vessel
    if speed is None:
        point = design_autopilot(model, speed, p=p, steer=steer, inputs=inputs, **settings)
    else:
        point = _schedule_point(model, float(speed), p=p, steer=steer, inputs=inputs, settings=settings)
    approach = vessel.U0 if vessel is not None and vessel.U0 else point.settings.speed
    speeds = default_schedule(approach, point.settings.speed) \
        if isinstance(schedule, str) and schedule == "default" else schedule
    try:
        speeds = sorted(float(v) for v in speeds)
    except (TypeError, ValueError):
        raise InputError(f"schedule must be a sequence of speeds [m/s] or 'default', got {schedule!r}") from None
    designs = tuple(_schedule_point(model, v, p=p, steer=steer, inputs=inputs, settings=settings) for v in speeds)
    law = ScheduledAutopilot(tuple(speeds), tuple(d.autopilot for d in designs))
    s0 = point.settings
    here = law.at(s0.speed)
    src = {**s0.sources, **{k: f"gain schedule over {['%.3g' % v for v in speeds]} m/s" for k in
                            ("wn_ref", "r_max", "steer_max")}}
    s = replace(s0, wn_ref=here.reference.wn, r_max=here.reference.r_max, steer_max=here.steer_max,
                segment=max(s0.segment, max(d.settings.segment for d in designs)), sources=src)
    L, closed = loop_systems(point.linearization, here.gains, point.actuator, delay=s.delay, reference=here.reference,
                             controlled="chi" if s.mode == "course" else "psi", filter_T=s.filter_T,
                             estimator=linear_estimator(s, point.nomoto, point.plant.steer), rate=s.rate)
    controller = here.gains.controller(steer=point.plant.steer)
    return Design(point.plant, point.linearization, point.nomoto, here.gains, controller,
                  L, closed, margins(L), law, point.actuator, s, designs)


def _schedule_point(model, speed, *, p, steer, inputs, settings) -> Design:
    """The point design of a schedule at ``speed``; a speed where the model is not valid, or where no
    design exists, is refused naming the speed and the model's range."""

    limit = model.limits.get("u")
    if not (np.isfinite(speed) and speed > 0):
        raise InputError(f"schedule speed {speed:g} m/s must be positive and finite")
    if limit is not None and not (limit.lower <= speed <= limit.upper):
        raise InputError(f"schedule speed {speed:.4g} m/s is outside the speed range of model {model.name!r}, "
                         f"u in [{limit.lower:.4g}, {limit.upper:.4g}] m/s ({limit.why})")
    try:
        return design_autopilot(model, speed, p=p, steer=steer, inputs=inputs, **settings)
    except (ValueError, ArithmeticError) as err:
        rng = (f"u in [{limit.lower:.4g}, {limit.upper:.4g}] m/s" if limit is not None else
               "its straight run trimmed with steering to spare")
        raise InputError(f"schedule speed {speed:.4g} m/s: {err}; no autopilot design for model {model.name!r} "
                         f"there (the model is valid for {rng})") from err


def simulate_autopilot(design: Design, command, t_end: float, *, step_times=(0.0,), seed=0, stepwise: bool = False,
                       warn: bool = True, **loop_options) -> ClosedLoopResult:
    """Run a design's nonlinear closed loop for ``t_end`` seconds on the course ``command``.

    Parameters
    ----------
    design : Design
    command : callable t -> rad, or array on the loop grid
    t_end : float
    step_times : sequence of float
        Times of command changes; metrics are computed per segment.
    seed : int
        Sensor-noise seed.
    stepwise : bool
        Run the step-by-step reference instead of the compiled fold.
    warn : bool
        Warn when the steering gear sits at its rate limit too long (:class:`RateLimitWarning`).
    **loop_options
        See :meth:`Design.closed_loop_system` (``plant``, ``environment``, ``estimator``, ``mode``,
        ``rate``, ``sensors``, ``wave``, ``wave_filter``, ``guidance``).
    """
    loop = design.closed_loop_system(**loop_options)
    data = (loop.run_stepwise if stepwise else loop.run)(command, t_end, seed=seed, x0=loop.plant.x0)
    return design.evaluate(loop, data, step_times, warn=warn)
