"""Standard manoeuvres: input generators and closed-loop rudder laws, runners, IMO/ITTC metrics.

:mod:`casship.maneuvers.inputs`
    :func:`turning_inputs`, :func:`pullout_inputs`, :func:`spiral_inputs`, :func:`random_rudder_inputs`
    (open-loop inputs for :func:`casship.simulate`), :class:`ZigZag` and :class:`ReverseSpiral`
    (closed-loop ``inputs(t, x)``), and which inputs of a model are rudders and propellers.
:mod:`casship.maneuvers.runners`
    :func:`run_maneuver` simulates a named manoeuvre from a straight run at a given speed (the
    propeller rate from :func:`propeller_rate_for_speed`, a :func:`casship.trim`) and returns the
    trajectory with its metrics.
:mod:`casship.maneuvers.metrics`
    :func:`turning_metrics`, :func:`zigzag_metrics`, :func:`execute_time`, :func:`imo_check` (IMO
    MSC.137(76) criteria) and :func:`imo_table` (Markdown), from any record with ``x, y, psi``.
:mod:`casship.maneuvers.replay`
    :func:`replay` drives a model with the measured inputs of a record from its measured initial
    state and scores the run with the metrics above (errors, indices, prediction bands):
    :class:`ReplayResult`, :func:`classify_maneuver`, :func:`maneuver_metrics`.

Sign convention: positive rudder turns the ship to starboard (heading increases), as in the MMG
standard; a zig-zag with a negative angle goes to port first.
"""
from .inputs import (ReverseSpiral, ZigZag, propeller_inputs, pullout_inputs, random_rudder_inputs, rudder_inputs,
                     spiral_inputs, straight_run_state, turning_inputs, vessel_of)
from .metrics import execute_time, imo_check, imo_table, turning_metrics, zigzag_metrics
from .runners import MANEUVERS, ManeuverResult, propeller_rate_for_speed, run_maneuver
from .replay import COVERAGE_SLACK, UNINFORMATIVE_DEG, ReplayResult, classify_maneuver, maneuver_metrics, replay, why_absent

__all__ = ["rudder_inputs", "propeller_inputs", "propeller_rate_for_speed", "straight_run_state",
           "turning_inputs", "pullout_inputs", "spiral_inputs", "random_rudder_inputs", "ZigZag",
           "ReverseSpiral", "run_maneuver", "ManeuverResult", "turning_metrics", "zigzag_metrics", "execute_time",
           "imo_check", "imo_table", "MANEUVERS", "vessel_of",
           "replay", "ReplayResult", "classify_maneuver", "maneuver_metrics", "why_absent", "COVERAGE_SLACK",
           "UNINFORMATIVE_DEG"]
