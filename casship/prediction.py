"""Deprecated path of :mod:`casship.simulation.bands`: importing it warns and gives the same objects.

Import from :mod:`casship.simulation` (or :mod:`casship.simulation.bands`) instead.
"""
import importlib
import warnings

from .simulation.bands import *  # noqa: F401,F403  (the same objects, not copies)
from .simulation.bands import __all__  # noqa: F401

_NEW = importlib.import_module("casship.simulation.bands")

warnings.warn("casship.prediction is deprecated: import from casship.simulation (module casship.simulation.bands)",
              DeprecationWarning, stacklevel=2)


def __getattr__(name):
    """Any other name of :mod:`casship.simulation.bands` (its private helpers included), the same object."""
    if name.startswith("__"):
        raise AttributeError(f"module 'casship.prediction' has no attribute {name!r}")
    return getattr(_NEW, name)
