"""Recursive and optimisation-based state estimators sharing one interface."""
from .base import Estimator, FilterResult, Health
from .ekf import EKF, KF, persistence_model

__all__ = ["Estimator", "FilterResult", "Health", "EKF", "KF", "persistence_model"]
