"""Deprecated path of :mod:`casship.simulation.simulate`: importing it warns and gives the same objects.

Import from :mod:`casship.simulation` (or :mod:`casship.simulation.simulate`) instead.
The function ``casship.simulate`` is not this module: the package keeps the function on its
attribute (``cs.simulate(...)``); import the module with :func:`importlib.import_module`.
"""
import importlib
import warnings

from .simulation.simulate import *  # noqa: F401,F403  (the same objects, not copies)
from .simulation.simulate import __all__  # noqa: F401

_NEW = importlib.import_module("casship.simulation.simulate")

warnings.warn("casship.simulate is deprecated: import from casship.simulation (module casship.simulation.simulate)",
              DeprecationWarning, stacklevel=2)


def __getattr__(name):
    """Any other name of :mod:`casship.simulation.simulate` (its private helpers included), the same object."""
    if name.startswith("__"):
        raise AttributeError(f"module 'casship.simulate' has no attribute {name!r}")
    return getattr(_NEW, name)
