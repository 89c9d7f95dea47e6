"""Compiling in the background: a Function is evaluated interpreted until its library is ready.

A first fit on a machine used to wait, silent, while the C compiler built its sensitivity Functions
(tens of seconds for a large model). :func:`compile_in_background` starts the compile in a thread
(the compiler is a separate process, so it runs on another core) and returns a
:class:`Compiling` handle whose :attr:`~Compiling.function` is the interpreted Function until the
compiled one is loaded, and the compiled one from then on. A one-off fit that ends before the
compiler does never waits for it; a longer one switches to compiled code as soon as it exists.

The compiles run one at a time in a worker thread that is not a daemon: a process that ends
while a compile runs finishes it first, so the library is in the cache for the next run.
"""
from __future__ import annotations

import os
import queue
import threading
from typing import Callable, Sequence

import casadi as ca

from ._cache import compile_function
from ..errors import InputTypeError

__all__ = ["Compiling", "compile_in_background"]

_JOBS: "queue.Queue[Compiling]" = queue.Queue()
_WORKER: list[threading.Thread] = []
_WORKER_LOCK = threading.Lock()


def _fresh_after_fork() -> None:
    """A forked child starts with no worker and no queue: the parent's worker thread does not exist
    there (a pending handle of the parent compiles again in the child when the child first reads it,
    and finds the parent's library in the cache once the parent has written it)."""
    global _JOBS, _WORKER_LOCK
    _JOBS, _WORKER_LOCK = queue.Queue(), threading.Lock()
    _WORKER.clear()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_fresh_after_fork)


class Compiling:
    """A Function being compiled in the background (made by :func:`compile_in_background`).

    Parameters
    ----------
    fun : casadi.Function
        The interpreted Function.
    flags : sequence of str or None
        Compiler flags (see :func:`~casship.runtime.compile_function`).
    on_done : callable, optional
        Called from the worker thread with the handle once the compile ended (done or failed).

    Attributes
    ----------
    interpreted : casadi.Function
    error : Exception or None
        Why compiling failed (the handle then stays interpreted).
    """

    def __init__(self, fun: ca.Function, flags: Sequence[str] | None = None, on_done: Callable | None = None):
        if not isinstance(fun, ca.Function):
            raise InputTypeError(f"compile_in_background needs a casadi.Function, got {type(fun).__name__}")
        self.interpreted = fun
        self.flags = None if flags is None else tuple(flags)
        self.error: Exception | None = None
        self._compiled: ca.Function | None = None
        self._done = threading.Event()
        self._on_done = on_done
        self._pid = os.getpid()

    @property
    def function(self) -> ca.Function:
        """The compiled Function once it is loaded, the interpreted one until then."""
        if self._compiled is None and self._pid != os.getpid():
            self._adopt()
        return self._compiled if self._compiled is not None else self.interpreted

    def _adopt(self) -> None:
        """In a process forked while this compile was pending: start it again here."""
        self._pid, self._done, self.error = os.getpid(), threading.Event(), None
        _submit(self)

    @property
    def ready(self) -> bool:
        """Whether the compiled Function is loaded."""
        return self._compiled is not None

    @property
    def done(self) -> bool:
        """Whether the compile ended (loaded or failed)."""
        return self._done.is_set()

    def wait(self, timeout: float | None = None) -> ca.Function:
        """Wait for the compile (at most ``timeout`` seconds) and return :attr:`function`.

        Parameters
        ----------
        timeout : float, optional
        """
        self._done.wait(timeout)
        return self.function

    def _run(self) -> None:
        try:
            self._compiled = compile_function(self.interpreted, flags=self.flags)
        except Exception as exc:       # noqa: BLE001 - reported through .error; the handle stays interpreted
            self.error = exc
        finally:
            self._done.set()
            if self._on_done is not None:
                self._on_done(self)

    def __repr__(self) -> str:
        state = "compiled" if self.ready else ("failed" if self.done else "compiling")
        return f"Compiling({self.interpreted.name()!r}, {state})"


def _work() -> None:
    while True:
        try:
            job = _JOBS.get(timeout=0.2)
        except queue.Empty:
            with _WORKER_LOCK:              # nothing left: let the thread end (a new job starts another)
                if _JOBS.empty():
                    _WORKER.clear()
                    return
            continue
        job._run()


def compile_in_background(fun: ca.Function, *, flags: Sequence[str] | None = None,
                          on_done: Callable | None = None) -> Compiling:
    """Compile ``fun`` in a background thread (through the on-disk cache); interpreted until then.

    Parameters
    ----------
    fun : casadi.Function
    flags : sequence of str, optional
        Compiler flags (default as for :func:`~casship.runtime.compile_function`).
    on_done : callable, optional
        ``on_done(handle)``, called from the worker thread when the compile ended.

    Returns
    -------
    Compiling
        ``handle.function`` is the Function to evaluate now.

    Examples
    --------
    >>> import casadi as ca
    >>> x = ca.SX.sym("x")
    >>> h = compile_in_background(ca.Function("twice", [x], [2 * x]))   # doctest: +SKIP
    >>> float(h.function(3.0))                                          # doctest: +SKIP
    6.0
    """
    return _submit(Compiling(fun, flags, on_done))


def _submit(job: Compiling) -> Compiling:
    """Queue ``job`` and make sure a worker thread runs."""
    _JOBS.put(job)
    with _WORKER_LOCK:
        if not _WORKER:
            worker = threading.Thread(target=_work, name="casship-compile", daemon=False)
            _WORKER.append(worker)
            worker.start()
    return job
