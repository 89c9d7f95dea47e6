"""Where identification compiles its Functions: :func:`casship.runtime.compile_function` (shared
libraries, kept in memory and in the on-disk cache), with the flags that suit identification.

The compiled Functions (sensitivity folds, lean cost folds, reverse sweeps) depend only on the model,
the estimator and the number of free values, so every problem of the same structure reuses them:
other records, other free sets of the same size, cross-validation folds, later processes.
"""
from __future__ import annotations

import os
import warnings

import casadi as ca

from ..runtime import compile_function

__all__ = ["compiled", "FLAGS"]

# -O1: as fast at run time as -O2/-O3 on the sensitivity folds and 2-5 times faster to compile
# (a 7-parameter EKF likelihood fold: 3 s at -O1, 15 s at -O2, 17 s at -O3; 0.04 s per evaluation of
# 3000 samples at each; -O0 compiles in 1.5 s but runs 2.5 times slower). $CASSHIP_CFLAGS overrides.
FLAGS = ("-O1",)
_BROKEN: list[str] = []   # why compiling failed (then identification runs interpreted)


def compiled(fun: ca.Function, *, jit=None) -> ca.Function:
    """``fun`` compiled to C and loaded (through the on-disk cache), or ``fun`` itself.

    Parameters
    ----------
    fun : casadi.Function
    jit : bool or None
        ``True``: compile, raise ``RuntimeError`` if that fails; ``False``: return ``fun``
        (interpreted); ``None``: compile when a compiler works, else warn once and interpret.
    """
    if jit is False or (_BROKEN and jit is None):
        return fun
    try:
        return compile_function(fun, flags=None if os.environ.get("CASSHIP_CFLAGS") else FLAGS)
    except RuntimeError as exc:
        if jit:
            raise
        _BROKEN.append(str(exc))
        warnings.warn(f"identification runs interpreted (slower): {exc}", RuntimeWarning, stacklevel=3)
        return fun
