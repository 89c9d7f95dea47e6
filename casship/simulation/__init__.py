"""Simulation: running a model over a record, the folds that do it, prediction bands, validity ranges.

:mod:`casship.simulation.simulate`
    :func:`simulate` (one run from an initial state, inputs as arrays, mappings, a record or a
    closed-loop ``inputs(t, x)``), :func:`simulate_many` (one run per parameter vector) and
    :func:`measure` (noisy measurements of a trajectory). The functions a user calls.
:mod:`casship.simulation.folds`
    The compiled or interpreted folds (``mapaccum``) of the discretised step over a record, built once
    per process and shared by every model of the same equations: :func:`simulation_fold`,
    :func:`fold_steps`, :func:`sensitivity_fold`; an integrator that fails raises
    :class:`IntegrationError`.
:mod:`casship.simulation.bands`
    A fit's parameter uncertainty carried through a simulation: exact
    :func:`trajectory_sensitivities`, :func:`prediction_bands` on heading and track,
    :func:`sampled_metrics` (intervals of manoeuvre indices from parameter draws), :func:`band_z`.
:mod:`casship.simulation.validity`
    A model's declared validity ranges: :func:`check_inputs`, :func:`check_states`,
    :func:`check_step` and :func:`stable_step` (the longest stable fixed step), raising
    :class:`ValidityError` for out-of-range use.

The replay of a measured record, scored with the manoeuvre metrics, is
:func:`casship.maneuvers.replay`.
"""
from .bands import band_z, prediction_bands, sampled_metrics, trajectory_sensitivities
from .folds import (COUNTS, IntegrationError, fold_steps, padded, sensitivity_fold, signature, simulation_fold,
                    solver_status)
from .simulate import input_matrix, measure, simulate, simulate_many
from .validity import (MARGIN, OPT_IN, ValidityError, ValidityWarning, check_inputs, check_start, check_states,
                       check_step, decaying_modes, describe_limit, is_stable_step, stable_step, warn_states)

__all__ = ["simulate", "simulate_many", "measure", "input_matrix",
           "simulation_fold", "sensitivity_fold", "fold_steps", "padded", "signature", "IntegrationError",
           "solver_status", "COUNTS",
           "trajectory_sensitivities", "prediction_bands", "sampled_metrics", "band_z",
           "ValidityError", "ValidityWarning", "OPT_IN", "MARGIN", "check_inputs", "is_stable_step",
           "decaying_modes", "check_states", "warn_states", "stable_step", "check_step", "describe_limit",
           "check_start"]
