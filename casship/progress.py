"""Progress of long work (identification, studies, batches, compile steps) through tqdm.

Bars are drawn on standard error and only when it is a terminal: piped or captured output (CI,
log files, tests) stays quiet. ``CASSHIP_PROGRESS=0`` silences them, ``CASSHIP_PROGRESS=1`` forces
them.

* :func:`progress` walks through named stages (``next(steps)`` before each stage);
* :func:`track` wraps an iterable (Monte Carlo runs, cross-validation folds, records);
* :func:`bar` is a bar advanced by hand (``b.update()``), e.g. from an optimiser's callback;
* :func:`activity` shows that one long call is running (its name and the elapsed time), e.g. a C
  compiler.

Examples
--------
>>> from casship.progress import progress, track
>>> steps = progress(["simulate", "filter"], "demo")
>>> next(steps)          # stage 1 of 2
>>> next(steps)          # stage 2 of 2
>>> next(steps, None)    # done
>>> sum(track(range(3), "runs"))
3
"""
from __future__ import annotations

import os
import sys
import threading
from contextlib import contextmanager
from typing import Iterable, Iterator, TypeVar

from tqdm.auto import tqdm

__all__ = ["progress", "track", "bar", "enabled", "activity"]

T = TypeVar("T")


def enabled(stream=None) -> bool:
    """Whether progress bars are drawn on ``stream`` (standard error by default).

    Parameters
    ----------
    stream : file-like, optional
        The stream the bars would be written to.

    Returns
    -------
    bool
        ``CASSHIP_PROGRESS`` if set (``0``/``1``), else whether ``stream`` is a terminal.
    """
    flag = os.environ.get("CASSHIP_PROGRESS", "").strip()
    if flag in ("0", "1"):
        return flag == "1"
    stream = stream or sys.stderr
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def bar(total: int | None, label: str, *, unit: str = "it", stream=None, leave: bool = False,
        bar_format: str | None = None) -> tqdm:
    """A progress bar advanced by hand (``b.update(k)``; close it or use it as a context manager).

    Parameters
    ----------
    total : int or None
        Number of steps (None: unknown, a counter is shown).
    label : str
        Text before the bar.
    unit : str
        Name of one step (e.g. ``"iter"``, ``"run"``).
    stream : file-like, optional
        Where to draw (standard error by default).
    leave : bool
        Keep the finished bar on screen.
    bar_format : str, optional
        tqdm's ``bar_format`` (default: tqdm's own).

    Returns
    -------
    tqdm.tqdm
        A bar that draws nothing when progress is not :func:`enabled`.
    """
    stream = stream or sys.stderr
    return tqdm(total=total, desc=label, unit=unit, file=stream, leave=leave, disable=not enabled(stream),
                dynamic_ncols=True, bar_format=bar_format)


def track(items: Iterable[T], label: str, *, total: int | None = None, unit: str = "it", stream=None) -> Iterator[T]:
    """Iterate over ``items`` with a progress bar.

    Parameters
    ----------
    items : iterable
        The work items.
    label : str
        Text before the bar.
    total : int, optional
        Number of items when ``len(items)`` is not available.
    unit : str
        Name of one item.
    stream : file-like, optional
        Where to draw (standard error by default).

    Yields
    ------
    object
        The items, unchanged.
    """
    if total is None and hasattr(items, "__len__"):
        total = len(items)
    with bar(total, label, unit=unit, stream=stream) as b:
        for item in items:
            yield item
            b.update()


def progress(stages: Iterable[str], label: str, stream=None) -> Iterator[None]:
    """A generator that advances a stage bar each time it is advanced (``next(steps)``).

    The bar shows ``label``, the stage number, the current stage's name and the elapsed time;
    exhausting the generator (``next(steps, None)`` after the last stage) closes it.

    Parameters
    ----------
    stages : iterable of str
        Names of the stages, in order.
    label : str
        Name of the whole job (e.g. ``"demo"``).
    stream : file-like, optional
        Where to draw (standard error by default).

    Yields
    ------
    None
        Once per stage, before the stage runs.
    """
    stages = list(stages)
    total = len(stages)
    with bar(total, label, unit="stage", stream=stream, leave=True, bar_format="{desc} |{bar}| {elapsed}") as b:
        for i, stage in enumerate(stages):
            b.set_description_str(f"{label} [{i + 1}/{total}] {stage}", refresh=False)
            b.n = i                       # stages completed
            b.refresh()
            yield
        b.set_description_str(f"{label} [{total}/{total}] done", refresh=False)
        b.n = total
        b.refresh()


@contextmanager
def activity(label: str, *, stream=None, every: float = 0.5) -> Iterator[None]:
    """Show ``label`` and the elapsed time while the block runs (a call that reports no progress itself).

    Parameters
    ----------
    label : str
        What is running (e.g. ``"compiling ekf_step to C (once; then cached)"``).
    stream : file-like, optional
        Where to draw (standard error by default).
    every : float
        Seconds between redraws.

    Yields
    ------
    None
    """
    stream = stream or sys.stderr
    if not enabled(stream):
        yield
        return
    done = threading.Event()
    with tqdm(total=None, desc=label, file=stream, leave=False, bar_format="{desc} {elapsed}") as b:
        def tick():
            while not done.wait(every):
                b.refresh()

        thread = threading.Thread(target=tick, daemon=True)
        thread.start()
        try:
            yield
        finally:
            done.set()
            thread.join()
