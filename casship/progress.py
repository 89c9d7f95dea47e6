"""Progress of long work (identification, studies, batches, compile steps), in any output mode.

On a terminal, bars are drawn on standard error (tqdm). When standard error is not a terminal (a
pipe, a log file, CI), long work writes one plain line at most every 10 s instead: the stage, the
fraction done, the elapsed time and an estimate of the time left, e.g. ::

    casship: design-trial [3/4] information: 2/4 stages (50 %), 1:20 elapsed, ETA ~1:20

Work that ends before the first interval writes nothing; work that wrote lines ends with one
``... done in 1:52`` line. ``CASSHIP_PROGRESS=0`` (or ``--quiet`` on the command line) silences
both, ``CASSHIP_PROGRESS=1`` draws bars even when not on a terminal; ``CASSHIP_PROGRESS_INTERVAL``
sets the seconds between lines (default 10).

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
import time
from contextlib import contextmanager
from typing import Iterable, Iterator, TypeVar

from tqdm.auto import tqdm

__all__ = ["progress", "track", "bar", "enabled", "activity", "command", "stage", "mode", "interval", "set_quiet"]

T = TypeVar("T")

#: Seconds between progress lines when standard error is not a terminal.
DEFAULT_INTERVAL = 10.0


def set_quiet(quiet: bool = True) -> None:
    """Silence progress (bars and lines) in this process and the processes it starts.

    Parameters
    ----------
    quiet : bool
        True: as ``CASSHIP_PROGRESS=0``; False: back to the default (bars on a terminal, lines
        otherwise).
    """
    if quiet:
        os.environ["CASSHIP_PROGRESS"] = "0"
    else:
        os.environ.pop("CASSHIP_PROGRESS", None)


def interval() -> float:
    """Seconds between progress lines (``CASSHIP_PROGRESS_INTERVAL``, default 10).

    Returns
    -------
    float
    """
    text = os.environ.get("CASSHIP_PROGRESS_INTERVAL", "").strip()
    if not text:
        return DEFAULT_INTERVAL
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value > 0 and value < float("inf")):
        from .errors import InputError

        raise InputError(f"CASSHIP_PROGRESS_INTERVAL={text!r}: give a positive number of seconds")
    return value


def mode(stream=None) -> str:
    """How progress shows on ``stream`` (standard error by default).

    Parameters
    ----------
    stream : file-like, optional

    Returns
    -------
    str
        ``"bar"`` (a terminal, or ``CASSHIP_PROGRESS=1``), ``"lines"`` (not a terminal) or
        ``"off"`` (``CASSHIP_PROGRESS=0``).
    """
    flag = os.environ.get("CASSHIP_PROGRESS", "").strip()
    if flag == "0":
        return "off"
    if flag == "1":
        return "bar"
    stream = stream or sys.stderr
    try:
        return "bar" if stream.isatty() else "lines"
    except (AttributeError, ValueError):
        return "lines"


def enabled(stream=None) -> bool:
    """Whether progress bars are drawn on ``stream`` (standard error by default).

    Parameters
    ----------
    stream : file-like, optional
        The stream the bars would be written to.

    Returns
    -------
    bool
        ``CASSHIP_PROGRESS`` if set (``0``/``1``), else whether ``stream`` is a terminal (see
        :func:`mode` for the lines written otherwise).
    """
    return mode(stream) == "bar"


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class _Lines:
    """The part of tqdm's interface casship uses, reported as plain lines by :data:`_REPORTER`."""

    def __init__(self, total, label: str, unit: str, stream):
        self.total, self.desc, self.label, self.unit, self.stream = total, label, label, unit, stream
        self.n, self.postfix, self.eta = 0, "", True
        self.start = time.monotonic()
        self.disable = False
        _REPORTER.add(self)

    def update(self, k: int = 1) -> None:
        self.n += k

    def set_description_str(self, desc: str, refresh: bool = True) -> None:
        self.desc = desc

    def set_postfix_str(self, text: str, refresh: bool = True) -> None:
        self.postfix = text

    def refresh(self) -> None:
        pass

    def close(self, ok: bool = True) -> None:
        _REPORTER.remove(self, ok)

    def __enter__(self):
        return self

    def __exit__(self, exc_type, *exc) -> None:
        # a stage generator or a tracked iterable left unfinished by its caller ends with GeneratorExit:
        # the caller moved on, nothing failed
        self.close(exc_type is None or issubclass(exc_type, GeneratorExit))

    def line(self, now: float) -> str:
        elapsed = now - self.start
        text = self.desc
        total = self.total
        if total:
            frac = min(max(self.n / total, 0.0), 1.0)
            text += f": {self.n}/{total} {self.unit}{'s' if total != 1 and self.unit != 'it' else ''} ({100 * frac:.0f} %)"
            text += f", {_clock(elapsed)} elapsed"
            if 0 < frac < 1 and self.eta:
                text += f", ETA ~{_clock(elapsed * (1 - frac) / frac)}"
        else:
            text += (f": {self.n} {self.unit}" if self.n else "") + f"{',' if self.n else ':'} {_clock(elapsed)} elapsed"
        if self.postfix:
            text += f" ({self.postfix})"
        return text


class _Reporter:
    """Writes one line for the active line-mode bars every :func:`interval` seconds (a daemon
    thread, so that it never holds up the end of a process)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._bars: list[_Lines] = []
        self._wake = threading.Event()
        self._thread = None
        self._wrote = False

    def add(self, b: _Lines) -> None:
        with self._lock:
            if not self._bars:
                self._wrote = False
                self._every = interval()
            self._bars.append(b)
            if self._thread is None or not self._thread.is_alive():
                self._wake.clear()
                self._thread = threading.Thread(target=self._run, name="casship-progress", daemon=True)
                self._thread.start()

    def remove(self, b: _Lines, ok: bool = True) -> None:
        with self._lock:
            if b not in self._bars:
                return
            outermost = self._bars[0] is b
            self._bars.remove(b)
            if outermost and self._wrote:
                self._write(b.stream, f"casship: {b.label}: {'done in' if ok else 'stopped after'} "
                                      f"{_clock(time.monotonic() - b.start)}")
            if not self._bars:
                self._wake.set()

    def _write(self, stream, text: str) -> None:
        try:
            print(text, file=stream, flush=True)
        except (OSError, ValueError):       # a closed pipe or stream: progress is not worth an error
            pass

    def _run(self) -> None:
        while True:
            with self._lock:
                every = self._every
            if self._wake.wait(every):
                with self._lock:
                    if not self._bars:
                        self._thread = None
                        return
                    self._wake.clear()
                continue
            with self._lock:
                if not self._bars:
                    self._thread = None
                    return
                now = time.monotonic()
                # a command's own line without a stage adds nothing beside the bars of its work
                shown = [b for b in self._bars if not (b is _COMMAND and b.total is None and len(self._bars) > 1)]
                self._write(self._bars[0].stream, "casship: " + " | ".join(b.line(now) for b in shown))
                self._wrote = True


_REPORTER = _Reporter()


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
    tqdm.tqdm or a line reporter with the same ``update``/``n``/``set_description_str``/``close``
        A bar on a terminal; plain lines every :func:`interval` seconds otherwise; nothing when
        progress is silenced.
    """
    stream = stream or sys.stderr
    how = mode(stream)
    if how == "lines":
        return _Lines(total, label, unit, stream)
    return tqdm(total=total, desc=label, unit=unit, file=stream, leave=leave, disable=how != "bar",
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
        for i, name in enumerate(stages):
            if _COMMAND is not None and _COMMAND.label == label:     # the command's own stages: name them on its line
                stage(name, i + 1, total)
            b.set_description_str(f"{label} [{i + 1}/{total}] {name}", refresh=False)
            b.n = i                       # stages completed
            b.refresh()
            yield
        b.set_description_str(f"{label} [{total}/{total}] done", refresh=False)
        b.n = total
        b.refresh()


@contextmanager
def command(label: str, *, stream=None) -> Iterator[None]:
    """The whole of a command-line run, reported only as lines (when standard error is not a
    terminal): a long command says it is still at work even in phases without a bar of their own,
    and its inner bars are appended to the same line.

    Parameters
    ----------
    label : str
        The command (e.g. ``"identify"``).
    stream : file-like, optional
        Where to write (standard error by default).

    Yields
    ------
    None
    """
    global _COMMAND
    stream = stream or sys.stderr
    if mode(stream) != "lines":
        yield
        return
    with _Lines(None, label, "stage", stream) as line:
        line.eta = False            # stages of a command are not of equal length: no time left from them
        _COMMAND = line
        try:
            yield
        finally:
            _COMMAND = None


def stage(name: str, index: int, total: int) -> None:
    """Name the stage a command-line run is in (shown by the lines of :func:`command`).

    Parameters
    ----------
    name : str
        The stage (e.g. ``"fitting"``).
    index : int
        Its number, from 1.
    total : int
        The number of stages.
    """
    line = _COMMAND
    if line is not None:
        line.desc, line.n, line.total = f"{line.label} [{index}/{total}] {name}", index - 1, total


_COMMAND = None


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
    how = mode(stream)
    if how != "bar":
        if how == "off":
            yield
            return
        with _Lines(None, label.removeprefix("casship: "), "it", stream):
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
