"""Where identification compiles its Functions: :func:`casship.runtime.compile_function` (shared
libraries, kept in memory and in the on-disk cache), with the flags that suit identification.

The compiled Functions (sensitivity folds, lean cost folds, reverse sweeps) depend only on the model,
the estimator and the number of free values, so every problem of the same structure reuses them:
other records, other free sets of the same size, cross-validation folds, later processes.

A Function the cache does not hold yet is compiled in the background (the C compiler runs in its
own process, beside this one) while the problem evaluates it interpreted; the compiled code takes
over at the next evaluation after it is ready. A one-off fit therefore never waits for the compiler
(a 29-parameter sensitivity fold of the KVLCC2 model takes about 9 s to compile and 1.4 s to
evaluate interpreted), and the next run finds the code in the cache. With the default flags the
compiled code gives the interpreted numbers bit for bit (no ``-ffast-math``, no fused multiply-add
without ``-march``), so when the switch happens does not change a result.
"""
from __future__ import annotations

import os
import threading
import warnings

import casadi as ca

from ..runtime import cached_function, compile_function

__all__ = ["compiled", "current", "Background", "FLAGS"]

# -O1: as fast at run time as -O2/-O3 on the sensitivity folds and 2-5 times faster to compile
# (a 7-parameter EKF likelihood fold: 3 s at -O1, 15 s at -O2, 17 s at -O3; 0.04 s per evaluation of
# 3000 samples at each; -O0 compiles in 1.5 s but runs 2.5 times slower). $CASSHIP_CFLAGS overrides.
FLAGS = ("-O1",)
_BROKEN: list[str] = []   # why compiling failed (then identification runs interpreted)


def _flags():
    return None if os.environ.get("CASSHIP_CFLAGS") else FLAGS


def _failed(exc: Exception) -> None:
    if not _BROKEN:
        warnings.warn(f"identification runs interpreted (slower): {exc}", RuntimeWarning, stacklevel=4)
    _BROKEN.append(str(exc))


class Background:
    """A Function evaluated interpreted until its compiled twin, built in a background thread, is ready.

    :meth:`get` returns the Function to use now. The thread waits for the C compiler (a separate
    process), so it leaves this process's cores to the interpreted evaluations. A process forked
    while the compile ran (a worker of a process pool) starts its own compile, which finds the
    library in the cache when the parent's has finished (the cache's lock file orders the two).
    """

    def __init__(self, fun: ca.Function):
        self.interpreted = fun
        self._result: ca.Function | None = None
        self._start()

    def _start(self) -> None:
        self._pid = os.getpid()
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._work, name=f"casship-compile-{self.interpreted.name()}")
        self._thread.start()

    def _work(self) -> None:
        try:
            self._result = compile_function(self.interpreted, flags=_flags())
        except RuntimeError as exc:                 # CompileError included: stay interpreted
            _failed(exc)
        finally:
            self._done.set()

    @property
    def ready(self) -> bool:
        """Whether the compile has ended (compiled, or failed and interpreted for good)."""
        return self._pid == os.getpid() and self._done.is_set()

    def get(self) -> ca.Function:
        """The compiled Function when it is ready, else the interpreted one."""
        if self._pid != os.getpid() and self._result is None:
            self._start()
        return self._result if self.ready and self._result is not None else self.interpreted

    def wait(self, timeout: float | None = None) -> ca.Function:
        """Wait for the compile (at most ``timeout`` seconds) and return :meth:`get`."""
        if self._pid == os.getpid():
            self._thread.join(timeout)
        return self.get()


def compiled(fun: ca.Function, *, jit=None):
    """``fun`` compiled to C and loaded (through the on-disk cache), or ``fun`` itself, or a
    :class:`Background` compile of it.

    Parameters
    ----------
    fun : casadi.Function
    jit : bool or None
        ``True``: compile now, raise ``RuntimeError`` if that fails; ``False``: return ``fun``
        (interpreted); ``None``: the cached compiled code when there is some, else a
        :class:`Background` compile (``fun`` interpreted meanwhile; interpreted for good, with one
        warning, when no compiler works).

    Returns
    -------
    casadi.Function or Background
        Resolve with :func:`current` at each evaluation.
    """
    if jit is False or (_BROKEN and jit is None):
        return fun
    if jit:
        return compile_function(fun, flags=_flags())
    hit = cached_function(fun, flags=_flags())
    return hit if hit is not None else Background(fun)


def current(fun) -> ca.Function:
    """The Function to evaluate now: ``fun`` itself, or what a :class:`Background` compile offers."""
    return fun.get() if isinstance(fun, Background) else fun
