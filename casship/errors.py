"""casship's own error types: what casship raises on purpose, as opposed to a bug.

Every error casship raises on purpose names the offending item (an option, a column, a state, a
file) and says what would be accepted. They share the base :class:`CasshipError`; each also derives
from the built-in exception a caller would expect (``ValueError`` for bad input, also ``TypeError``
for input of the wrong kind, ``RuntimeError`` for a solver that failed), so ``except ValueError``
keeps working. A check of an internal invariant (a casship bug if it fails) raises a plain built-in
exception instead.

The command line (:func:`casship.cli.main`) classifies by type alone: these, and ``OSError`` (a
missing or unwritable file), become one line ``casship CMD: error: ...`` with exit code 2; anything
else, a plain ``ValueError`` included, is a bug in casship and is reported as one (exit code 1),
with ``--debug`` for the traceback.

Examples
--------
>>> from casship.errors import CasshipError, InputError
>>> try:
...     raise InputError("--dt: must be positive, got -1")
... except ValueError as exc:                    # an InputError is a ValueError
...     isinstance(exc, CasshipError)
True
"""
from __future__ import annotations

__all__ = ["CasshipError", "InputError", "InputTypeError", "SolverError", "DivergenceError", "SetupError"]


class CasshipError(Exception):
    """Base of every error casship raises on purpose (bad input, a failed solve): never a bug."""


class InputError(CasshipError, ValueError):
    """Bad input (a value, a name, a record, a setting), named in the message with what is accepted."""


class InputTypeError(InputError, TypeError):
    """Input of the wrong kind (a list where a :class:`~casship.Dataset` is needed, a model where a
    discretised one is): an :class:`InputError`, and also a ``TypeError`` so that ``except TypeError``
    keeps working."""


class SolverError(CasshipError, RuntimeError):
    """A numerical method that failed (an integrator, an optimiser, a filter that diverged), with its status."""


class DivergenceError(SolverError, FloatingPointError):
    """A simulation or closed loop whose state left the finite numbers (a step too long for the
    dynamics, a load far beyond the model's range), naming the time; also a ``FloatingPointError``."""


class SetupError(CasshipError, RuntimeError):
    """Something casship needs is missing from the environment (a C compiler, an optional package, a
    folder of the source checkout), named with how to provide it."""
