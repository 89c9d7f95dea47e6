"""System identification over one or many records: output error, maximum likelihood through a
filter, priors, identifiability and the fit result.

* :class:`OutputErrorProblem` -- weighted least squares of simulated outputs (single or multiple shooting).
* :class:`MLEProblem` -- prediction-error maximum likelihood through an EKF/UKF/EnKF.
* Both take a list of records, each with its own initial state (given or estimated) and, where
  declared, its own copies of parameters and biases (``share=``); a Gaussian prior (:class:`Prior`,
  MAP); bounds; exact derivatives compiled to C; bounded Gauss-Newton / Fisher-scoring steps.
* :class:`FitResult` -- estimates, model-based and robust (sandwich) standard errors, correlations,
  warnings, channel shares, residual whiteness, the model's identity, JSON and a plot.
* :class:`Identifiability` -- Fisher-information analysis before fitting, and a proposed free set.
* :func:`cross_validate` -- leave-one-run-out / leave-one-group-out replays against the published
  values, as a :class:`CrossValidation` value with a table and overlay figures.
* :func:`noise_std`, :func:`decimate`, :func:`share_labels`, :func:`initial_states` -- record helpers.
* :func:`read_fit_file` (and :func:`read_params`) and :class:`ParameterBelief` -- a fit file's parameters and
  their covariance, the same Gaussian over named parameters a prior and a trial design use;
  :func:`replay_file` -- a record replayed with a fit file (the path of ``casship simulate --params``).
  :func:`write_params_file` -- values from elsewhere (another facility's tests) written as a replayable file.
* :func:`identify_ship` -- the ship workflow in one call (propulsion, weights, prior, a free set from
  run-level evidence, the inverse-dynamics start), every choice with its reason (:class:`ShipFit`).
* :mod:`casship.identify.asymmetry` -- port/starboard terms only from mirrored evidence.
* :class:`CaptiveProblem` -- captive (PMM) model tests: forces of a model at a prescribed motion and their
  harmonics (:mod:`casship.identify.captive_forces`), fitted alone or as a :class:`CostTerm` of a
  :class:`JointProblem` with the free-running records; a facility's :class:`Rig` (its model of the ship,
  :func:`read_rig`) and :func:`identify_with_captive` (the captive tests alone, or beside records with the
  captive-only model or the joint fit chosen by nested cross-validation, :class:`CaptiveShip`).
"""
from .crossval import CrossValidation, cross_validate
from .identifiability import Identifiability
from .mle import MLEProblem
from .output_error import OutputErrorProblem
from .belief import COVARIANCE_KINDS, CovarianceKind, ParameterBelief, ParameterUncertainty
from .params_file import FitFile, read_fit_file, read_params, replay_file, write_params_file
from .prior import Prior
from .problem import IdentificationProblem
from .records import initial_states, noise_std, share_labels
from .inverse_dynamics import inverse_dynamics, linear_in, rates_model, smooth_trial
from .result import FitResult, IdentificationError, IdentificationWarning
from .cost_term import CostTerm, JointProblem
from .captive import CaptiveProblem, linear_derivatives
from .workflow import ShipFit, identify_ship
from .rig import Rig, read_rig
from .captive_choice import CaptiveShip, identify_with_captive
from .spec import LikelihoodOptions, OutputErrorOptions, ProblemSpec

__all__ = ["MLEProblem", "OutputErrorProblem", "IdentificationProblem", "FitResult", "IdentificationError",
           "IdentificationWarning", "Prior", "Identifiability", "noise_std",
           "share_labels", "initial_states", "read_params", "read_fit_file", "FitFile", "replay_file", "write_params_file", "ParameterBelief", "ParameterUncertainty", "CovarianceKind",
           "COVARIANCE_KINDS", "cross_validate", "CrossValidation"]
__all__ += ["identify_ship", "ShipFit"]
__all__ += ["smooth_trial", "inverse_dynamics", "linear_in", "rates_model"]
__all__ += ["CaptiveProblem", "CostTerm", "JointProblem", "linear_derivatives", "Rig", "read_rig", "CaptiveShip",
            "identify_with_captive"]
__all__ += ["ProblemSpec", "OutputErrorOptions", "LikelihoodOptions"]
