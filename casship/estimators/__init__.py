"""Recursive and optimisation-based state estimators sharing one interface."""
from .base import Estimator, FilterResult, Health
from .ekf import EKF, KF, persistence_model
from .ukf import UKF
from .rts import rts_smooth
from .enkf import EnKF
from .kalman_bucy import KalmanBucy
from .augmented import AugmentedResult, augment, augmented_ekf
from .mhe import MHE, MHEFailed

# Estimators by command-line name (``casship filter --estimator NAME``); other modules may add theirs.
ESTIMATORS = {"kf": KF, "ekf": EKF, "ukf": UKF, "enkf": EnKF, "kalman-bucy": KalmanBucy, "mhe": MHE}

__all__ = ["Estimator", "FilterResult", "Health", "EKF", "KF", "persistence_model",
           "UKF", "rts_smooth",
           "EnKF", "KalmanBucy", "augment", "augmented_ekf", "AugmentedResult", "ESTIMATORS", "MHE", "MHEFailed"]
