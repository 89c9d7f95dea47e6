"""Where casship compiles its own numeric Functions: :func:`casship.runtime.compile_function` (shared
libraries, kept in memory and in the on-disk cache), with the flags that keep the numbers.

The identification's folds (sensitivity folds, lean cost folds, reverse sweeps) and the simulation
folds of replays (:mod:`casship.folds`) depend only on the model's structure and a few sizes, never on
the data, so every problem or replay of the same structure reuses them: other records, other free sets
of the same size, cross-validation folds, later processes.

By default (``jit=None``) a Function whose library is not in the cache yet is compiled in the
background (:func:`casship.runtime.compile_in_background`) while the caller evaluates it interpreted,
and switches to the compiled code as soon as it is loaded. With these flags (no ``-march=native``,
no fused multiply-adds) the interpreted and the compiled evaluations give the same numbers to the
last bit (tested), so where the switch happens does not change a fit or a replay. A progress bar on
a terminal says what is being compiled.
"""
from __future__ import annotations

import os
import threading
import warnings

import casadi as ca

from .progress import bar
from .runtime import Compiling, cached_function, compile_function, compile_in_background

__all__ = ["compiled", "resolve", "FLAGS"]

# -O1: as fast at run time as -O2/-O3 on the sensitivity folds and 2-5 times faster to compile
# (a 7-parameter EKF likelihood fold: 3 s at -O1, 15 s at -O2, 17 s at -O3; 0.04 s per evaluation of
# 3000 samples at each; -O0 compiles in 1.5 s but runs 2.5 times slower). $CASSHIP_CFLAGS overrides.
FLAGS = ("-O1",)
_BROKEN: list[str] = []   # why compiling failed (then these Functions run interpreted)
_PENDING: dict = {"bar": None, "n": 0, "done": 0}
_PENDING_LOCK = threading.Lock()


def _flags():
    return None if os.environ.get("CASSHIP_CFLAGS") else FLAGS


def compiled(fun: ca.Function, *, jit=None):
    """``fun`` compiled to C and loaded (through the on-disk cache), or ``fun`` itself, or a
    :class:`~casship.runtime.Compiling` handle (read it through :func:`resolve`).

    Parameters
    ----------
    fun : casadi.Function
    jit : bool or None
        ``True``: compile now, raise ``RuntimeError`` if that fails; ``False``: return ``fun``
        (interpreted); ``None``: the compiled library if the cache holds it, else compile it in the
        background and evaluate ``fun`` until then (a failed compile warns once and stays
        interpreted, and so do later ones with ``jit=None`` in this process).
    """
    if jit is False or (_BROKEN and jit is None):
        return fun
    if jit:
        return compile_function(fun, flags=_flags())
    hit = cached_function(fun, flags=_flags())
    if hit is not None:
        return hit
    with _PENDING_LOCK:
        if _PENDING["bar"] is None:
            _PENDING["bar"] = bar(None, "compiling numeric code (running interpreted meanwhile)",
                                  unit="Function")
        _PENDING["n"] += 1
        _PENDING["bar"].total = _PENDING["n"]
        _PENDING["bar"].refresh()
    return compile_in_background(fun, flags=_flags(), on_done=_finished)


def _finished(job: Compiling) -> None:
    """A background compile ended: advance the bar; a failure warns once and the caller stays interpreted."""
    if job.error is not None and not _BROKEN:
        _BROKEN.append(str(job.error))
        warnings.warn(f"casship runs its folds interpreted (slower): {job.error}", RuntimeWarning, stacklevel=2)
    with _PENDING_LOCK:
        _PENDING["done"] += 1
        b = _PENDING["bar"]
        if b is not None:
            b.update()
            if _PENDING["done"] >= _PENDING["n"]:
                b.close()
                _PENDING.update(bar=None, n=0, done=0)


def resolve(fun) -> ca.Function:
    """The Function to evaluate now: a :class:`~casship.runtime.Compiling` handle's current one, else ``fun``.

    Parameters
    ----------
    fun : casadi.Function or Compiling
    """
    return fun.function if isinstance(fun, Compiling) else fun
