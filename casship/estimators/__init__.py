"""Recursive and optimisation-based state estimators sharing one interface."""
from .base import Estimator, FilterResult, Health
from .ekf import EKF, KF, persistence_model
from .ukf import UKF
from .rts import rts_smooth

__all__ = ["Estimator", "FilterResult", "Health", "EKF", "KF", "persistence_model",
           "UKF", "rts_smooth"]
