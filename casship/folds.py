"""Deprecated path of :mod:`casship.simulation.folds`: importing it warns and gives the same objects.

Import from :mod:`casship.simulation` (or :mod:`casship.simulation.folds`) instead.
"""
import importlib
import warnings

from .simulation.folds import *  # noqa: F401,F403  (the same objects, not copies)
from .simulation.folds import __all__  # noqa: F401

_NEW = importlib.import_module("casship.simulation.folds")

warnings.warn("casship.folds is deprecated: import from casship.simulation (module casship.simulation.folds)",
              DeprecationWarning, stacklevel=2)


def __getattr__(name):
    """Any other name of :mod:`casship.simulation.folds` (its private helpers included), the same object."""
    if name.startswith("__"):
        raise AttributeError(f"module 'casship.folds' has no attribute {name!r}")
    return getattr(_NEW, name)
