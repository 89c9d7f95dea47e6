"""casship: ship manoeuvring models, state estimation and system identification on CasADi.

One symbolic model, written once, gives simulators, exact Jacobians, Kalman filters, smoothers,
moving-horizon estimation, maximum-likelihood identification and the linearisations that
python-control turns into autopilots.

The names below are imported when first used (``import casship`` itself loads nothing heavy), so
that the command line answers ``--help`` and argument errors without loading CasADi.
"""
from __future__ import annotations

import importlib
import importlib.util
import sys
import types

# public name -> the module that defines it
_EXPORTS = {
    "wrap": "angles", "unwrap": "angles", "Dataset": "data", "Gaussian": "gaussian", "Trajectory": "trajectory",
    "DiscreteModel": "discretize", "discretize": "discretize", "van_loan": "discretize",
    "Model": "model", "ModelBuilder": "builder", "Vessel": "vessel", "Limit": "vessel",
    "measure": "simulation", "simulate": "simulation", "simulate_many": "simulation",
    "EKF": "estimators", "KF": "estimators", "FilterResult": "estimators", "persistence_model": "estimators",
    "UKF": "estimators", "EnKF": "estimators", "KalmanBucy": "estimators", "augment": "estimators",
    "MHE": "estimators", "prior_from_data": "estimators", "noise_from_data": "estimators",
    "linearize": "linear", "to_iosys": "linear", "trim": "linear",
    "FitResult": "identify", "MLEProblem": "identify", "OutputErrorProblem": "identify",
    "identify_ship": "identify",
    "CasshipError": "errors", "InputError": "errors", "SolverError": "errors", "SetupError": "errors",
}
_SUBMODULES = ("frames", "identify", "models", "io")

__all__ = ["ModelBuilder", "Model", "Vessel", "Limit", "DiscreteModel", "discretize", "van_loan", "Dataset", "Gaussian",
           "Trajectory", "EKF", "KF", "FilterResult", "persistence_model", "UKF", "EnKF", "KalmanBucy", "augment",
           "simulate", "simulate_many", "measure", "linearize", "to_iosys", "trim", "wrap", "unwrap", "frames", "models", "__version__",
           "MLEProblem", "OutputErrorProblem", "FitResult", "identify", "MHE", "prior_from_data", "noise_from_data",
           "CasshipError", "identify_ship",
           "InputError", "SolverError", "SetupError", "io"]


class _Package(types.ModuleType):
    """The package, keeping the functions ``casship.discretize`` and ``casship.simulate`` when their
    modules of the same name are imported (the import system binds a submodule on its package; the
    module ``casship.simulate`` is the deprecated path of :mod:`casship.simulation`, and holds the
    same function)."""

    def __setattr__(self, name, value):
        if isinstance(value, types.ModuleType) and name in _EXPORTS and hasattr(value, name):
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


def _version() -> str:
    """The installed distribution's version; in a source checkout that is not installed, the version
    in its ``pyproject.toml`` (the one place where the version is written)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(__name__)
    except PackageNotFoundError:
        import re
        from pathlib import Path

        try:
            lines = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text().splitlines()
        except OSError:
            return "0+unknown"
        section = None
        for line in lines:                      # the 'version = "..."' line of the [project] table
            header = re.match(r"\s*\[([^\]]+)\]\s*$", line)
            if header:
                section = header.group(1).strip()
            found = re.match(r'\s*version\s*=\s*"([^"]+)"', line)
            if found and section == "project":
                return found.group(1)
        return "0+unknown"


def __getattr__(name: str):
    if name == "__version__":           # read once, when asked (importlib.metadata is not free at start-up)
        value = _version()
    elif name in _EXPORTS:
        value = getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    elif name in _SUBMODULES or (not name.startswith("__") and importlib.util.find_spec(f"{__name__}.{name}")):
        value = importlib.import_module(f".{name}", __name__)        # any submodule, as after an import
    else:
        raise AttributeError(f"module 'casship' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
