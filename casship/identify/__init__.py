"""System identification: maximum likelihood through a filter, output error, and the fit result.

* :class:`MLEProblem` -- prediction-error maximum likelihood through an EKF/UKF, exact derivatives.
* :class:`OutputErrorProblem` -- weighted least squares of simulated outputs (single or multiple shooting).
* :class:`FitResult` -- estimates, standard errors, correlation, identifiability warnings, AIC/BIC,
  residual whiteness, JSON and a plot.
"""
from .mle import MLEProblem, default_prior
from .output_error import OutputErrorProblem
from .inverse_dynamics import inverse_dynamics, linear_in, rates_model, smooth_trial
from .result import FitResult, IdentificationError

__all__ = ["MLEProblem", "OutputErrorProblem", "FitResult", "IdentificationError", "default_prior"]
__all__ += ["smooth_trial", "inverse_dynamics", "linear_in", "rates_model"]
