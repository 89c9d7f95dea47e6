"""What a user knows about a ship's parameters before the next trial: :class:`ParameterBelief`.

The belief a trial design starts from is the one Gaussian over named parameters of casship
(:class:`casship.identify.ParameterBelief`, the same class): from a fit or its file
(:meth:`ParameterBelief.from_fit`: the covariance the file carries -- calibrated by a run-level
jackknife when the fit was -- or the fit's robust or model-based one, optionally widened by prior
standard deviations for parameters the fit held fixed), a file's uncertainty as read
(``read_fit_file(path).uncertainty``), an identification prior (:meth:`ParameterBelief.from_prior`)
or standard deviations around chosen values (:meth:`ParameterBelief.from_std`); its :attr:`kind`
names which covariance it is, for reports. Adding a trial's information gives the belief after it
(:meth:`ParameterBelief.after`).
"""
from ..identify.belief import COVARIANCES, ParameterBelief, covariance_kind

__all__ = ["ParameterBelief", "COVARIANCES", "covariance_kind"]
