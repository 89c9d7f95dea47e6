"""The one fold driver: a folded step (``mapaccum``) run over records of any length in pieces.

A fold has a length fixed when it is built, so a record runs in pieces of :func:`fold_chunk` samples
(the last one padded), the memory carried from piece to piece. Every fold over a record in casship
runs through :func:`run_pieces`: the filters and smoothers, the simulation and sensitivity folds of
replays, the identification's cost and sensitivity folds.

* **Pieces** (:func:`pieces`): ``chunk`` samples each; with ``shrink`` the last one takes the next
  power of two at or above its length (interpreted folds of short records: less padding, and a fold
  of another length costs nothing to build), else ``chunk`` too (one compiled library per structure).
* **Padding**: a per-sample input repeats its last sample in the padded part, unless ``pad`` gives it
  a value; a caller pads so that the padded steps leave the memory alone (``dt = 0``, ``mask = 0``)
  or does not use what follows them.
* **Memory**: input ``k`` of the next piece is the last columns of output ``carry[k]`` (the whole
  output when it is the final value only, as a fold that returns its memory once).
* **Records in step**: jobs whose pieces at the same position use the same Function are evaluated
  in one call of its ``map`` over the jobs (threads), so a many-record problem uses the cores.

Calls go through :class:`~casship.runtime.BufferedCall` buffers kept per Function and number of jobs
(no conversion of CasADi matrices), the inputs copied straight from the records into them.
"""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from typing import Sequence

import casadi as ca
import numpy as np

from ._buffers import BoundedTable, BufferedCall
from ._settings import fold_chunk

__all__ = ["Job", "PieceFailed", "pieces", "piece", "run_pieces", "THREADS"]


class PieceFailed(RuntimeError):
    """The evaluation of a piece failed: ``fun`` (the Function called, mapped over the jobs of the
    piece), ``inputs`` (name -> the array it was called with), ``start`` and ``stop`` (the piece's
    samples in the record of the first job of the call)."""

    def __init__(self, message: str, fun: ca.Function, inputs: dict, start: int = 0, stop: int = 0):
        super().__init__(message)
        self.fun, self.inputs, self.start, self.stop = fun, inputs, start, stop

THREADS = max(1, min(os.cpu_count() or 1, 8))
_BUFFERS = BoundedTable(256)         # (id(Function), jobs) -> (Function, BufferedCall, lock)


def pieces(n: int, chunk: int | None = None, *, shrink: bool = False) -> list[tuple[int, int, int]]:
    """``(start, stop, size)`` of the pieces of a record of ``n`` samples.

    Parameters
    ----------
    n : int
    chunk : int, optional
        Samples per piece (default :func:`fold_chunk`).
    shrink : bool
        The last piece the next power of two at or above its length (at most ``chunk``).

    Examples
    --------
    >>> pieces(600, 256), pieces(600, 256, shrink=True)[-1]
    ([(0, 256, 256), (256, 512, 256), (512, 600, 256)], (512, 600, 128))
    """
    chunk = fold_chunk() if chunk is None else int(chunk)
    out, start = [], 0
    while start < n:
        size = min(chunk, 1 << (n - start - 1).bit_length()) if shrink else chunk
        stop = min(start + size, n)
        out.append((start, stop, size))
        start = stop
    return out


def piece(a: np.ndarray, start: int, stop: int, size: int, fill: float | None = None, cols: int = 1) -> np.ndarray:
    """Samples ``start:stop`` of ``a`` (rows x samples*cols, each sample's columns side by side) padded
    to ``size`` samples: the last sample repeated, or ``fill``.

    Parameters
    ----------
    a : (rows, n*cols) array
    start, stop, size : int
    fill : float, optional
    cols : int
        Columns per sample.
    """
    return _copy_piece(a, start, stop, size, fill, None, cols)


def _copy_piece(src: np.ndarray, start: int, stop: int, size: int, fill, out: np.ndarray | None,
                cols: int = 1) -> np.ndarray:
    """Samples ``start:stop`` of ``src`` (``cols`` columns each) into ``out`` (rows, size*cols), padded."""
    take = stop - start
    if out is None:
        out = np.empty((src.shape[0], size * cols))
    out[:, :take * cols] = src[:, start * cols:stop * cols]
    if take < size:
        if fill is not None:
            out[:, take * cols:] = fill
        elif src.shape[0]:
            out[:, take * cols:] = np.tile(src[:, (stop - 1) * cols:stop * cols], (1, size - take))
        else:
            out[:, take * cols:] = 0.0
    return out


@dataclass
class Job:
    """One record through one fold.

    Parameters
    ----------
    fold : casadi.Function or callable
        The fold over a piece; a callable ``fold(size)`` gives the fold over ``size`` samples
        (needed with ``shrink``).
    state : dict
        The memory before the first sample (input name -> array).
    consts : dict
        Inputs the same for every sample.
    per : dict
        Per-sample inputs, ``rows x n*cols`` (sample ``k``'s columns at ``[:, k*cols:(k+1)*cols]``).
    n : int
        Samples in the record.
    carry : dict, optional
        Memory input -> the output whose last columns continue it (default ``<name>_next``).
    pad : dict, optional
        Per-sample input -> its value in the padded samples (others repeat their last sample).
    """

    fold: object
    state: dict
    consts: dict
    per: dict
    n: int
    carry: dict | None = None
    pad: dict = field(default_factory=lambda: {"mask": 0.0, "dt": 0.0})

    def function(self, size: int) -> ca.Function:
        return self.fold if isinstance(self.fold, ca.Function) else self.fold(size)


class _Calls:
    """A Function's buffered call (mapped over ``n`` argument sets, threads), its slot sizes, a lock."""

    def __init__(self, fun: ca.Function, n: int):
        mapped = fun if n == 1 else fun.map(n, "thread" if THREADS > 1 else "serial", min(THREADS, n))
        self.fun, self.call, self.lock = fun, BufferedCall(mapped), threading.Lock()
        self.size_in = {k: tuple(fun.size_in(k)) for k in fun.name_in()}
        self.size_out = {k: tuple(fun.size_out(k)) for k in fun.name_out()}


def _buffers(fun: ca.Function, n: int) -> _Calls:
    """The kept :class:`_Calls` of ``fun`` over ``n`` argument sets."""
    entry = _BUFFERS.get((id(fun), n))
    if entry is None:
        entry = _BUFFERS.keep((id(fun), n), _Calls(fun, n))
    return entry


def run_pieces(jobs: Sequence[Job], *, chunk: int | None = None, shrink: bool = False,
               collect: Sequence[str] | None = None, record: bool = True):
    """Run each job's record piece by piece through its fold; jobs at the same piece with the same
    Function run in one mapped call.

    Parameters
    ----------
    jobs : sequence of Job
    chunk : int, optional
        Samples per piece (default :func:`fold_chunk`).
    shrink : bool
        See :func:`pieces`.
    collect : sequence of str, optional
        Per-sample outputs to gather per job as ``(n, rows, cols)`` arrays.
    record : bool
        Keep every piece's inputs and outputs (for a backward sweep).

    Returns
    -------
    list
        Per job a dict: ``pieces`` (with ``record``: a list of ``(args, outputs, samples)`` per piece;
        the arrays are copies), ``memory`` (after the last sample), and the ``collect``-ed outputs.
    """
    cuts = [pieces(j.n, chunk, shrink=shrink) for j in jobs]
    states = [{k: np.asarray(v, dtype=float) for k, v in j.state.items()} for j in jobs]
    results: list[dict] = [{"pieces": []} for _ in jobs]
    for c in range(max((len(p) for p in cuts), default=0)):
        groups: dict = {}
        for i, j in enumerate(jobs):
            if c < len(cuts[i]):
                fun = j.function(cuts[i][c][2])
                groups.setdefault(id(fun), (fun, []))[1].append(i)
        for fun, idx in groups.values():
            direct = {}
            if collect and len(idx) == 1 and cuts[idx[0]][c][1] - cuts[idx[0]][c][0] == cuts[idx[0]][c][2]:
                # a whole piece of one record writes its outputs straight into the result arrays
                i, (start, stop, size) = idx[0], cuts[idx[0]][c]
                sizes = _buffers(fun, 1)
                for name in collect:
                    rows, cols = sizes.size_out[name]
                    flat = _result(results[i], name, rows, cols // size, jobs[i].n)
                    direct[name] = flat[start * rows * (cols // size):stop * rows * (cols // size)]

            def consume(b, args, out, sizes, idx=idx, direct=direct):
                i = idx[b]
                j, (start, stop, size) = jobs[i], cuts[i][c]
                take = stop - start
                if record:
                    results[i]["pieces"].append((args, out, take))
                carry = j.carry or {k: f"{k}_next" for k in j.state}
                states[i] = {k: out[o][:, out[o].shape[1] - sizes.size_in[k][1]:].copy() for k, o in carry.items()}
                for name in collect or ():
                    if name not in direct:
                        rows, cols = sizes.size_out[name]
                        flat = _result(results[i], name, rows, cols // size, j.n)
                        per = rows * (cols // size)
                        flat[start * per:stop * per] = out[name].reshape(-1, order="F")[:take * per]
            try:
                _evaluate(fun, [(jobs[i], states[i], cuts[i][c]) for i in idx], record, consume, direct)
            except PieceFailed as exc:
                exc.start, exc.stop = cuts[idx[0]][c][:2]
                raise
    for i in range(len(jobs)):
        results[i]["memory"] = states[i]
        flats = results[i].pop("_flat", {})
        for name in collect or ():
            if name in flats:               # read-only: results may share them without a copy
                for a in (flats[name].base, flats[name], results[i][name]):
                    a.flags.writeable = False
    return results


def _result(result: dict, name: str, rows: int, cols: int, n: int) -> np.ndarray:
    """The flat array behind the job's ``(n, rows, cols)`` output ``name`` (made on first use): sample
    ``k``'s matrix in column-major order at ``[k*rows*cols:(k+1)*rows*cols]``, as CasADi writes it."""
    flats = result.setdefault("_flat", {})
    if name not in flats:
        block = np.empty((n, cols, rows))
        result[name] = block.transpose(0, 2, 1)
        flats[name] = block.reshape(-1)
    return flats[name]


def _evaluate(fun: ca.Function, batch: list, record: bool, consume, direct: dict | None = None) -> None:
    """Evaluate ``fun`` for each ``(job, memory, (start, stop, size))`` of ``batch`` in one call of its
    map; ``consume(b, args, outputs, calls)`` reads the outputs of set ``b`` under the buffers' lock
    (views of the buffers, or copies with ``record``; ``args`` only with ``record``). ``direct``: outputs
    written straight into the given flat arrays (one set only)."""
    n = len(batch)
    calls = _buffers(fun, n)
    call = calls.call
    with calls.lock:                              # one evaluation at a time on these buffers
        for name, (rows, cols) in calls.size_in.items():
            view = call.arg(name)
            for b, (job, state, (start, stop, size)) in enumerate(batch):
                target = view[:, b * cols:(b + 1) * cols] if n > 1 else view
                if name in job.per:
                    _copy_piece(job.per[name], start, stop, size, job.pad.get(name), target, cols // size)
                else:
                    v = state.get(name, job.consts.get(name))
                    target[:] = 0.0 if v is None else np.reshape(v, (rows, cols), order="F")
        for name, target in (direct or {}).items():
            call.redirect(name, target)
        try:
            call()
        except RuntimeError as exc:
            raise PieceFailed(str(exc), call.fun, {k: call.arg(k).copy() for k in call.names_in}) from exc
        finally:
            if direct:
                call.restore_outputs()          # kept buffers must not write into (or keep) a result
        block = call.block.copy() if record else call.block
        for b in range(n):
            args = ({name: call.arg(name)[:, b * cols:(b + 1) * cols].copy()
                     for name, (_, cols) in calls.size_in.items()} if record else None)
            out = {}
            for j, (name, (rows, cols)) in enumerate(calls.size_out.items()):
                whole = block[call.offsets[j]:call.offsets[j + 1]].reshape((rows, cols * n), order="F")
                out[name] = whole[:, b * cols:(b + 1) * cols] if n > 1 else whole
            for name in direct or ():           # written into the result: read there
                rows, cols = calls.size_out[name]
                out[name] = direct[name].reshape((rows, cols), order="F")
            consume(b, args, out, calls)
