"""Moving-horizon estimation (MHE) and full-information (batch MAP) estimation on a DiscreteModel.

The package along its jobs: ``options`` (typed options and the priors of estimated parameters and
disturbances), ``problem`` (the window NLP), ``arrival`` (the arrival cost), ``solvers`` (solving a
window), ``runner`` (the per-sample recursion, also the online engine) and ``estimator`` (the
:class:`MHE` with the contract of every estimator).
"""
from .estimator import MHE
from .options import MHEOptions
from .solvers import MHEFailed

__all__ = ["MHE", "MHEOptions", "MHEFailed"]
