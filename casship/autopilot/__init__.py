"""Course and heading autopilots: from a ship model to python-control designs and a compiled closed loop.

The package, one job per module:

* :mod:`~casship.autopilot.nomoto` -- Nomoto models from the labelled linearisation or fitted to records;
* :mod:`~casship.autopilot.designs` -- PID pole placement, LQR with integral action, LQG (``control.lqr``,
  ``control.lqe``);
* :mod:`~casship.autopilot.reference` -- the third-order reference model;
* :mod:`~casship.autopilot.law` -- the digital law and the steering gear as CasADi steps;
* :mod:`~casship.autopilot.plants` -- the ship as a steering plant (trim, two-propeller craft);
* :mod:`~casship.autopilot.estimation` -- the loop's estimators and the first-order wave model;
* :mod:`~casship.autopilot.analysis` -- python-control loops (``interconnect``) and margins;
* :mod:`~casship.autopilot.defaults` -- the defaults, derived from the ship, shared with the CLI;
* :mod:`~casship.autopilot.ship_design` -- :func:`design_autopilot` and the :class:`Design` value;
* :mod:`~casship.autopilot.schedule` -- gain scheduling over the speed;
* :mod:`~casship.autopilot.slot` -- any python-control controller as the law of the compiled loop;
* :mod:`~casship.autopilot.closed_loop` -- the closed loop as one compiled CasADi step;
* :mod:`~casship.autopilot.components` -- sensors, the estimator in the loop, the record of a run;
* :mod:`~casship.autopilot.loop_variants` -- what the loop feeds back (true state, raw compass and gyro,
  an estimator) and how it reads the course or heading;
* :mod:`~casship.autopilot.performance` -- course-changing and course-keeping checks;
* :mod:`~casship.autopilot.guidance` -- waypoints, LOS and integral LOS;
* :mod:`~casship.autopilot.mpc` -- a CasADi model-predictive course controller (:mod:`~casship.autopilot.mpc_design`: one for a design);
* :mod:`~casship.autopilot.wave_limit` -- the heading-error floor in a sea and the LQG loop there;
* :mod:`~casship.autopilot.montecarlo` -- runs over sensor-noise seeds and speeds;
* :mod:`~casship.autopilot.plots` -- figures.

Conventions: the steering input (rudder angle, or a yaw moment for a craft steered by its
propellers) turns the craft with the sign of the Nomoto gain ``K``; angles in radians, course and
heading from North clockwise, errors wrapped to (-pi, pi].
"""
from .analysis import closed_loop_tf, course_linearization, loop_systems, loop_transfer, margins
from .closed_loop import ClosedLoop
from .components import ClosedLoopResult, LoopEstimator, Sensors
from .defaults import WaveBudgetWarning, RULES, AutopilotSettings, derive_settings
from .designs import LQG, lqg_design, lqr_design, pid_pole_placement
from .estimation import WaveYaw, course_ekf, heading_kf, heading_observer, linear_estimator
from .guidance import LOSGuidance, Waypoints, cross_track_metrics, track_deviation
from .law import Actuator, Autopilot, PIDGains
from .loop_variants import LoopFeedback, RawMeasurement, TrueState
from .mpc import MPCAutopilot, MPCLaw
from .mpc_design import mpc_for_design, mpc_weights
from .nomoto import Nomoto, fit_nomoto, nomoto_from_linear, nomoto_from_model
from .performance import (CRITERIA, course_change_metrics, course_keeping_metrics, course_scenario,
                          performance_report, step_metrics)
from .plants import (SteeringFeedforward, SteeringPlant, speed_profile, steering_feedforward, steering_model,
                     steering_plant, twin_propeller_allocation, twin_propeller_yaw_limit)
from .plots import bode_phase_deg, plot_closed_loop, plot_design
from .reference import ReferenceModel
from .schedule import ScheduledAutopilot, default_schedule
from .slot import LinearController
from .ship_design import Design, RateLimitWarning, design_autopilot, simulate_autopilot
from .wave_limit import WaveLQG, heading_error_floor, rice_exceedance, sea_model, wave_lqg

__all__ = ["Nomoto", "nomoto_from_linear", "nomoto_from_model", "fit_nomoto", "PIDGains", "pid_pole_placement",
           "lqr_design", "lqg_design", "LQG", "ReferenceModel", "Autopilot", "Actuator", "loop_systems",
           "loop_transfer", "closed_loop_tf", "margins", "course_linearization", "SteeringPlant", "steering_plant",
           "steering_model", "twin_propeller_allocation", "twin_propeller_yaw_limit", "ClosedLoop", "ClosedLoopResult",
           "LoopEstimator", "LoopFeedback", "TrueState",
           "RawMeasurement", "Sensors", "WaveYaw", "course_ekf", "heading_kf", "heading_observer", "linear_estimator",
           "step_metrics", "course_change_metrics", "course_keeping_metrics", "performance_report", "CRITERIA",
           "course_scenario", "plot_design", "plot_closed_loop", "bode_phase_deg", "Design", "design_autopilot",
           "simulate_autopilot", "RateLimitWarning", "RULES", "AutopilotSettings", "derive_settings", "Waypoints",
           "LOSGuidance", "cross_track_metrics", "MPCAutopilot", "mpc_for_design", "mpc_weights", "ScheduledAutopilot",
           "default_schedule", "SteeringFeedforward", "steering_feedforward", "LinearController", "speed_profile",
           "track_deviation", "MPCLaw", "heading_error_floor", "wave_lqg", "WaveLQG", "rice_exceedance",
           "sea_model"]
