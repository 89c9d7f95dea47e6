"""The one place where identification compiles CasADi Functions to C, and keeps them.

Compiled Functions are kept in memory per key (the serialised symbolic Function and the compile
flags), so every problem of the same structure in a process reuses them: cross-validation folds,
Monte Carlo repetitions, other records and other free sets of the same size. They are compiled
through :func:`casship.compile.compile_function`, whose on-disk cache keeps them for the next
process too.
"""
from __future__ import annotations

import hashlib
import warnings

import casadi as ca

from ..compile import compile_function

__all__ = ["compiled", "FLAGS", "clear"]

# -O0 compiles the generated straight-line code in about a tenth of the time of -O2 and runs within
# a factor of about two of it (measured on the likelihood sensitivities of a 6-state EKF): for a fit
# that is compiled once per process the lower level wins.
FLAGS = ("-O0",)
_MEMORY: dict[str, ca.Function] = {}
_BROKEN: list[str] = []   # reason the compiler is unusable (then Functions run interpreted)


def _key(fun: ca.Function, flags) -> str:
    h = hashlib.sha256(fun.serialize().encode())
    h.update(repr(tuple(flags)).encode())
    return h.hexdigest()


def compiled(fun: ca.Function, *, jit=None, flags=FLAGS) -> ca.Function:
    """``fun`` compiled to C (system compiler) and loaded, cached in memory by its serialised form.

    Parameters
    ----------
    fun : casadi.Function
    jit : bool or None
        ``True``: compile, raise ``RuntimeError`` if no working C compiler; ``False``: return ``fun``
        (interpreted); ``None``: compile when a compiler works, else warn once and interpret.
    flags : sequence of str
        Compiler flags.
    """
    if jit is False:
        return fun
    if _BROKEN and jit is None:
        return fun
    key = _key(fun, flags)
    if key not in _MEMORY:
        try:
            _MEMORY[key] = compile_function(fun, flags=flags)
        except RuntimeError as exc:
            reason = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
            if jit:
                raise RuntimeError(f"compiling {fun.name()!r} to C failed (is a C compiler installed?): "
                                   f"{reason}") from None
            _BROKEN.append(reason)
            warnings.warn(f"identification runs interpreted (slower): compiling to C failed ({reason})",
                          RuntimeWarning, stacklevel=3)
            return fun
    return _MEMORY[key]


def clear() -> None:
    """Forget the compiled Functions kept in memory."""
    _MEMORY.clear()
    _BROKEN.clear()
