"""Compiling in the background: a Function is evaluated interpreted until its library is ready.

A first fit on a machine used to wait, silent, while the C compiler built its sensitivity Functions
(tens of seconds for a large model). :func:`compile_in_background` starts the compile in a thread
(the compiler is a separate process, so it runs on another core) and returns a
:class:`Compiling` handle whose :attr:`~Compiling.function` is the interpreted Function until the
compiled one is loaded, and the compiled one from then on. A one-off fit that ends before the
compiler does never waits for it; a longer one switches to compiled code as soon as it exists.

The compiles run one at a time in a daemon worker thread: a process whose work is done exits at
once, without waiting for them. At a normal exit the compiles not finished yet are handed to one
detached process (its own session, no output) that compiles them into the cache for the next run
(:func:`hand_off`; ``CASSHIP_COMPILE_AFTER_EXIT=0`` drops them instead); the compiler this process was
running is stopped with everything it started and its build folder removed
(:func:`~._compiler.stop_compilers`). A Ctrl-C drops them: nothing compiles on after an interrupt.
"""
from __future__ import annotations

import atexit
import json
import os
import queue
import subprocess
import sys
import tempfile
import threading
from typing import Callable, Sequence

import casadi as ca

from ._cache import compile_function
from ._compiler import stopping
from ._settings import ENV_AFTER_EXIT
from ..errors import InputTypeError

__all__ = ["Compiling", "compile_in_background", "hand_off"]

_JOBS: "queue.Queue[Compiling]" = queue.Queue()
_OPEN: list = []                    # compiles queued or running (handed off at exit)
_WORKER: list[threading.Thread] = []
_WORKER_LOCK = threading.Lock()


def _fresh_after_fork() -> None:
    """A forked child starts with no worker and no queue: the parent's worker thread does not exist
    there (a pending handle of the parent compiles again in the child when the child first reads it,
    and finds the parent's library in the cache once the parent has written it)."""
    global _JOBS, _WORKER_LOCK
    _JOBS, _WORKER_LOCK = queue.Queue(), threading.Lock()
    _WORKER.clear()
    _OPEN.clear()


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

    def __init__(self, fun: ca.Function, flags: Sequence[str] | None = None, on_done: Callable | None = None,
                 extra_source: str = ""):
        if not isinstance(fun, ca.Function):
            raise InputTypeError(f"compile_in_background needs a casadi.Function, got {type(fun).__name__}")
        self.interpreted = fun
        self.flags = None if flags is None else tuple(flags)
        self.extra_source = extra_source
        self.error: Exception | None = None
        self.library = None             # the ctypes handle of the library (with extra_source)
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

    @property
    def cancelled(self) -> bool:
        """Whether the compile was stopped because the process is ending."""
        return stopping()

    def _run(self) -> None:
        try:
            if self.extra_source:
                self._compiled, self.library = compile_function(self.interpreted, flags=self.flags,
                                                                extra_source=self.extra_source, library=True)
            else:
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
        try:
            job._run()
        finally:
            with _WORKER_LOCK:
                if job in _OPEN:
                    _OPEN.remove(job)


def hand_off() -> int:
    """Hand the compiles not finished yet to one detached process that compiles them into the cache
    (run at exit, before the compilers are stopped); returns how many. Nothing after a Ctrl-C
    (:func:`~._compiler.stopping`), with ``CASSHIP_COMPILE_AFTER_EXIT=0`` or without a cache."""
    from ._cache import cache_dir

    with _WORKER_LOCK:
        jobs = [j for j in _OPEN if not j.done]
    if (not jobs or stopping() or os.environ.get(ENV_AFTER_EXIT, "1").strip().lower() in ("0", "no", "off", "false")
            or cache_dir() is None):
        return 0
    work = [{"fun": j.interpreted.serialize(), "flags": None if j.flags is None else list(j.flags),
             "extra_source": j.extra_source} for j in jobs]
    fd, path = tempfile.mkstemp(prefix="casship-handoff-", suffix=".json")
    with os.fdopen(fd, "w") as f:
        json.dump(work, f)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), ENV_AFTER_EXIT: "0",
           "CASSHIP_PROGRESS": "0"}
    try:
        subprocess.Popen([sys.executable, "-c", "import sys; from casship.runtime import finish_handed_off; "
                          "finish_handed_off(sys.argv[1])", path], env=env, start_new_session=True,
                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         close_fds=True)
    except OSError:
        os.unlink(path)
        return 0
    return len(jobs)


def finish_handed_off(path: str) -> None:
    """Compile the Functions a process handed off at its exit (:func:`hand_off`) into the cache.

    Parameters
    ----------
    path : str
        The hand-off file (removed here).
    """
    try:
        with open(path) as f:
            work = json.load(f)
    finally:
        os.unlink(path)
    for item in work:
        fun = ca.Function.deserialize(item["fun"])
        try:
            compile_function(fun, flags=item["flags"], extra_source=item["extra_source"])
        except Exception:           # noqa: BLE001 - nobody to tell: the next run compiles it itself
            pass


atexit.register(hand_off)           # registered after the compiler's stop_compilers: runs before it


def compile_in_background(fun: ca.Function, *, flags: Sequence[str] | None = None,
                          on_done: Callable | None = None, extra_source: str = "") -> Compiling:
    """Compile ``fun`` in a background thread (through the on-disk cache); interpreted until then.

    Parameters
    ----------
    fun : casadi.Function
    flags : sequence of str, optional
        Compiler flags (default as for :func:`~casship.runtime.compile_function`).
    on_done : callable, optional
        ``on_done(handle)``, called from the worker thread when the compile ended.
    extra_source : str
        C source compiled into the same library (then ``handle.library`` is its ctypes handle).

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
    return _submit(Compiling(fun, flags, on_done, extra_source))


def _submit(job: Compiling) -> Compiling:
    """Queue ``job`` and make sure a worker thread runs."""
    with _WORKER_LOCK:
        _OPEN.append(job)
    _JOBS.put(job)
    with _WORKER_LOCK:
        if not _WORKER:
            worker = threading.Thread(target=_work, name="casship-compile", daemon=True)
            _WORKER.append(worker)
            worker.start()
    return job
