"""Run independent study cases in parallel: a local process pool by default, or a Dask cluster.

Cases carry their own seeds, so a parallel run returns exactly what a serial run returns.
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor
from typing import Callable, Iterable, Sequence

__all__ = ["run_cases"]


def run_cases(func: Callable, cases: Iterable, *, workers: int | None = None, scheduler: str | None = None) -> list:
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
    """
    cases: Sequence = list(cases)
    if scheduler is not None:
        try:
            from dask.distributed import Client
        except ImportError as exc:  # pragma: no cover - optional extra
            from .errors import SetupError

            raise SetupError("a Dask scheduler was given but dask.distributed is not installed "
                               "(pip install 'casship[dask]')") from exc
        with Client(scheduler) as client:
            return client.gather(client.map(func, cases, pure=False))
    if workers == 1 or len(cases) <= 1:
        return [func(c) for c in cases]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(pool.map(func, cases))
