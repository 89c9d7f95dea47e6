"""casship: ship manoeuvring models, state estimation and system identification on CasADi.

One symbolic model, written once, gives simulators, exact Jacobians, Kalman filters, smoothers,
moving-horizon estimation, maximum-likelihood identification and the linearisations that
python-control turns into autopilots.
"""
from .angles import wrap, unwrap
from .data import Dataset
from .gaussian import Gaussian
from .trajectory import Trajectory
from .discretize import DiscreteModel, discretize, van_loan
from .builder import ModelBuilder
from .model import Model
from .vessel import Limit, Vessel
from .simulate import measure, simulate
from .estimators import EKF, KF, FilterResult, persistence_model
from .estimators import UKF, EnKF, KalmanBucy, augment
from .estimators import MHE
from .linear import linearize, to_iosys, trim
from .identify import FitResult, MLEProblem, OutputErrorProblem
from . import frames, identify, models
from . import io  # data import: read_csv (units), read_nmea (NMEA 0183), read_marin

__version__ = "0.1.0"

__all__ = ["ModelBuilder", "Model", "Vessel", "Limit", "DiscreteModel", "discretize", "van_loan", "Dataset", "Gaussian",
           "Trajectory", "EKF", "KF", "FilterResult", "persistence_model", "UKF", "EnKF", "KalmanBucy", "augment", "simulate", "measure", "linearize", "to_iosys", "trim", "wrap", "unwrap", "frames", "models", "__version__",
           "MLEProblem", "OutputErrorProblem", "FitResult", "identify", "MHE"]
