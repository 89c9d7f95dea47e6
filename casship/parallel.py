"""Run independent study cases in parallel: a local process pool by default, or a Dask cluster.

Cases carry their own seeds, so a parallel run returns exactly what a serial run returns. Local
workers are forked from the calling process on POSIX, so they start with everything it has built
(models, compiled Functions in memory) and find the rest in the on-disk compile cache.

Cases may run with their BLAS (OpenBLAS, MKL) held to a number of threads (``blas_threads``): the
cases are the parallelism, and a BLAS thread woken by one large product spins on a core for a while
after it (15-20 % of the kvlcc2-marin study's CPU time with two BLAS threads). A threaded BLAS
may sum a product's terms in another order than a single thread does (results that differ in the
last bits): code whose numbers must not depend on the limit runs inside :func:`blas_threads` with
``None``, the count the BLAS had before any limit of this module.

CasADi is not safe to call from several threads at once (building or calling Functions from two
threads can crash the process). Cases handed to a Dask scheduler therefore run under a process-wide
lock: a worker process with several threads, or several workers in one process (``processes=False``),
runs its cases one at a time. Parallelism comes from worker processes (``--nthreads 1``, several
processes); in a worker process with one thread the lock is never contended and costs nothing.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from functools import partial
from threading import Lock
from typing import Callable, Iterable, Iterator, Sequence

from .errors import InputError

__all__ = ["run_cases", "call", "blas_threads"]


def run_cases(func: Callable, cases: Iterable, *, workers: int | None = None, scheduler: str | None = None,
              label: str | None = None, unit: str = "case", blas_threads: int | None = None) -> list:
    """``[func(case) for case in cases]``, in parallel, results in the order of ``cases``.

    Parameters
    ----------
    func : callable
        A module-level (picklable) function of one case.
    cases : iterable
        Picklable case descriptions (each with its own seed).
    workers : int, optional
        Local processes; ``1`` runs serially in this process, ``None`` uses the CPU count.
    scheduler : str, optional
        Address of a ``dask.distributed`` scheduler (``tcp://host:8786``); needs the ``dask`` extra.
    label : str, optional
        Show a progress bar with this text, advanced as cases finish (see :mod:`casship.progress`).
    unit : str
        Name of one case on the bar.
    blas_threads : int, optional
        Run each case with at most this many BLAS threads (see the module text; serial cases too);
        None leaves the BLAS as it is.

    Returns
    -------
    list
        ``func(case)`` for each case, in the order of ``cases``; the first case that raises stops
        the run with its exception.

    Examples
    --------
    >>> run_cases(abs, [-1, 2, -3], workers=1)
    [1, 2, 3]
    """
    cases: Sequence = list(cases)
    if blas_threads is not None:
        if isinstance(blas_threads, bool) or not isinstance(blas_threads, int) or blas_threads < 1:
            raise InputError(f"blas_threads must be a positive int or None, got {blas_threads!r}")
        func = partial(_limited, func, blas_threads)
    if scheduler is not None:
        try:
            from dask.distributed import Client
            from dask.distributed import as_completed as dask_completed
        except ImportError as exc:  # pragma: no cover - optional extra
            from .errors import SetupError

            raise SetupError("a Dask scheduler was given but dask.distributed is not installed "
                               "(pip install 'casship[dask]')") from exc
        with Client(scheduler) as client:
            futures = client.map(partial(_one_at_a_time, func), cases, pure=False)
            _wait(dask_completed(futures), len(cases), label, unit)
            return client.gather(futures)
    if workers == 1 or len(cases) <= 1:
        return [func(c) for c in _track(cases, label, unit)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = [pool.submit(func, c) for c in cases]
        try:
            _wait(as_completed(futures), len(cases), label, unit)
        except BaseException:
            for f in futures:
                f.cancel()
            raise
        return [f.result() for f in futures]


def call(case: tuple):
    """``func(*args, **kwargs)`` of a case ``(func, args, kwargs)``: any module-level function as a case.

    Parameters
    ----------
    case : tuple
        ``(func, args)`` or ``(func, args, kwargs)``, all picklable.

    Returns
    -------
    object
        What ``func`` returns.

    Examples
    --------
    >>> run_cases(call, [(divmod, (7, 2)), (max, (1, 5))], workers=1)
    [(3, 1), 5]
    """
    func, args, *rest = case
    return func(*args, **(rest[0] if rest else {}))


_STARTED: dict = {}      # BLAS library path -> its threads before any limit of this module


def _blas():
    """The BLAS libraries of this process (threadpoolctl), their thread counts first recorded."""
    from threadpoolctl import ThreadpoolController

    blas = ThreadpoolController().select(user_api="blas")
    for lib in blas.lib_controllers:
        _STARTED.setdefault(lib.filepath, lib.num_threads)
    return blas


@contextmanager
def blas_threads(n: int | None) -> Iterator[None]:
    """Hold the BLAS libraries to ``n`` threads within the block (``None``: the number each had when
    this module first met it, e.g. inside a case limited by :func:`run_cases`); restored after.

    Parameters
    ----------
    n : int or None

    Examples
    --------
    >>> import numpy as np
    >>> with blas_threads(1):
    ...     float(np.ones((200, 200)) @ np.ones(200) @ np.ones(200))
    40000.0
    """
    blas = _blas()
    before = {lib.filepath: lib.num_threads for lib in blas.lib_controllers}
    try:
        for lib in blas.lib_controllers:
            lib.set_num_threads(_STARTED[lib.filepath] if n is None else n)
        yield
    finally:
        for lib in blas.lib_controllers:
            lib.set_num_threads(before[lib.filepath])


def _limited(func: Callable, n: int, case):
    """``func(case)`` with the BLAS held to ``n`` threads."""
    with blas_threads(n):
        return func(case)


_CASADI_LOCK = Lock()     # one case at a time per process: CasADi is not thread-safe


def _one_at_a_time(func: Callable, case):
    """``func(case)`` holding this process's case lock (a Dask worker may run cases in threads)."""
    with _CASADI_LOCK:
        return func(case)


def _track(cases, label, unit):
    if label is None:
        return cases
    from .progress import track

    return track(cases, label, unit=unit)


def _wait(done, total: int, label, unit) -> None:
    """Go through the finished futures ``done`` (raising the first failure), advancing a bar."""
    if label is None:
        for f in done:
            f.result()
        return
    from .progress import bar

    with bar(total, label, unit=unit) as b:
        for f in done:
            f.result()
            b.update(1)
