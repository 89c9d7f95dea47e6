"""Deprecated path of :mod:`casship.maneuvers.replay`: importing it warns and gives the same objects.

Import from :mod:`casship.maneuvers` (or :mod:`casship.maneuvers.replay`) instead.
"""
import importlib
import warnings

from .maneuvers.replay import *  # noqa: F401,F403  (the same objects, not copies)
from .maneuvers.replay import __all__  # noqa: F401

_NEW = importlib.import_module("casship.maneuvers.replay")

warnings.warn("casship.validation is deprecated: import from casship.maneuvers (module casship.maneuvers.replay)",
              DeprecationWarning, stacklevel=2)


def __getattr__(name):
    """Any other name of :mod:`casship.maneuvers.replay` (its private helpers included), the same object."""
    if name.startswith("__"):
        raise AttributeError(f"module 'casship.validation' has no attribute {name!r}")
    return getattr(_NEW, name)
