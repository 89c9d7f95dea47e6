"""Trial design: which manoeuvre to run next, to learn most about a prediction a user cares about.

A trial's expected information comes from the exact sensitivities of its simulated outputs through
the fit's output-error likelihood; added to what is known now (a fit's covariance or a prior), it
gives the parameters' covariance after the trial, and the delta method with the exact gradient of
the target (tactical diameter, advance, first overshoot, the port/starboard difference...) gives
the target's standard deviation after it.

* :class:`ParameterBelief` -- what is known now: a Gaussian over named parameters (from a fit file's
  calibrated, robust or model-based covariance, or a prior); :func:`fit_noise` -- the noise a fit weighs.
* :func:`design_trials` -> :class:`DesignResult` -- the candidates ranked (and a free trial optimised).
* :func:`standard_trials`, :class:`Trial` -- the IMO/ITTC manoeuvres in both directions as rudder records.
* :func:`optimise_free_trial`, :class:`TrialLimits` -- a free rudder sequence under the ship's limits.
* :data:`TARGETS`, :class:`Turning`, :class:`FirstOvershoot`, :class:`Difference` -- targets with exact gradients.
* :func:`trial_information`, :func:`criterion_value` -- a trial's Fisher information, D- and A-criteria.
* :class:`Approach` -- the straight approach, propeller rate and step every manoeuvre starts from.
"""
from .belief import COVARIANCES, ParameterBelief, covariance_kind
from .free import FreeTrialError, TrialLimits, optimise_free_trial
from .information import CRITERIA, criterion_value, fit_noise, trial_information
from .ranking import DesignResult, design_trials
from .sensitivity import Approach, ManoeuvreFold
from .targets import TARGETS, Difference, FirstOvershoot, Target, TargetValue, Turning, get_target
from .trials import Trial, standard_trials

__all__ = ["ParameterBelief", "COVARIANCES", "covariance_kind", "fit_noise", "design_trials", "DesignResult",
           "standard_trials", "Trial", "optimise_free_trial", "TrialLimits", "FreeTrialError", "TARGETS", "Target",
           "TargetValue", "Turning", "FirstOvershoot", "Difference", "get_target", "trial_information",
           "criterion_value", "CRITERIA", "Approach", "ManoeuvreFold"]
