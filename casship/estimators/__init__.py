"""Estimators sharing one contract (``docs/architecture.md``): KF, EKF, UKF, EnKF, Kalman-Bucy, MHE.

Every estimator derives from the abstract :class:`Estimator`: it is built as ``Est(dmodel, Q, R, *,
measured=None, options=None)`` and offers ``filter``, ``online``, ``smooth``, ``predict`` and
``options`` (``docs/estimators.md``). The recursive filters share the step-based template
:class:`StepEstimator`, which adds ``step`` (the step Function with named slots); the MHE has none.
Records are checked and results assembled by the shared :class:`Records`; online samples by the one
:func:`check_sample` of every :class:`OnlineEngine`.
:data:`ESTIMATORS` maps names to classes; registering an estimator there also runs the
conformance suite ``tests/test_estimator_contract.py`` on it.
"""
from .options import EstimatorOptions
from .result import FilterResult, Health
from .records import Records
from .contract import Estimator
from .base import StepEstimator
from .online import OnlineEngine, OnlineRun, check_sample
from .ekf import EKF, KF, EKFOptions, persistence_model
from .ukf import UKF, UKFOptions
from .rts import rts_smooth
from .enkf import EnKF, EnKFOptions
from .kalman_bucy import KalmanBucy, KalmanBucyOptions
from .augmented import AugmentedResult, augment, augmented_ekf
from .mhe import MHE, MHEFailed, MHEOptions
from .prior import DataPrior, noise_from_data, prior_from_data
from .export import export_estimator, export_mhe_rti

# Estimators by command-line name (``casship filter --estimator NAME``); other modules may add theirs.
ESTIMATORS = {"kf": KF, "ekf": EKF, "ukf": UKF, "enkf": EnKF, "kalman-bucy": KalmanBucy, "mhe": MHE}

__all__ = ["Estimator", "StepEstimator", "Records", "EstimatorOptions", "FilterResult", "Health", "OnlineRun",
           "OnlineEngine", "check_sample",
           "EKF", "KF", "EKFOptions", "persistence_model", "UKF", "UKFOptions", "rts_smooth", "EnKF", "EnKFOptions", "KalmanBucy",
           "KalmanBucyOptions", "augment", "augmented_ekf", "AugmentedResult", "ESTIMATORS", "MHE", "MHEFailed",
           "MHEOptions", "prior_from_data", "noise_from_data", "DataPrior", "export_estimator", "export_mhe_rti"]
