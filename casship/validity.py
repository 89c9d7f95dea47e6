"""Deprecated path of :mod:`casship.simulation.validity`: importing it warns and gives the same objects.

Import from :mod:`casship.simulation` (or :mod:`casship.simulation.validity`) instead.
"""
import importlib
import warnings

from .simulation.validity import *  # noqa: F401,F403  (the same objects, not copies)
from .simulation.validity import __all__  # noqa: F401

_NEW = importlib.import_module("casship.simulation.validity")

warnings.warn("casship.validity is deprecated: import from casship.simulation (module casship.simulation.validity)",
              DeprecationWarning, stacklevel=2)


def __getattr__(name):
    """Any other name of :mod:`casship.simulation.validity` (its private helpers included), the same object."""
    if name.startswith("__"):
        raise AttributeError(f"module 'casship.validity' has no attribute {name!r}")
    return getattr(_NEW, name)
