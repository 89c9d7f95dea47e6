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


def _buffers(fun: ca.Function, n: int):
    """A buffered call of ``fun`` (mapped over ``n`` argument sets, threads) kept for the next call."""
    entry = _BUFFERS.get((id(fun), n))
    if entry is None:
        mapped = fun if n == 1 else fun.map(n, "thread" if THREADS > 1 else "serial", min(THREADS, n))
        entry = _BUFFERS.keep((id(fun), n), (fun, BufferedCall(mapped), threading.Lock()))
    return entry[1], entry[2]


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
            try:
                outs = _evaluate(fun, [(jobs[i], states[i], cuts[i][c]) for i in idx], record)
            except PieceFailed as exc:
                exc.start, exc.stop = cuts[idx[0]][c][:2]
                raise
            for i, (args, out) in zip(idx, outs):
                j, (start, stop, size) = jobs[i], cuts[i][c]
                take = stop - start
                if record:
                    results[i]["pieces"].append((args, out, take))
                carry = j.carry or {k: f"{k}_next" for k in j.state}
                states[i] = {k: out[o][:, out[o].shape[1] - fun.size2_in(k):].copy() for k, o in carry.items()}
                for name in collect or ():
                    _gather(results[i], name, out[name], fun.size2_out(name) // size, j.n, start, take)
    for i in range(len(jobs)):
        results[i]["memory"] = states[i]
        for name in collect or ():
            a = results[i].get(name)
            if a is not None:
                a.flags.writeable = False
    return results


def _gather(result: dict, name: str, out: np.ndarray, cols: int, n: int, start: int, take: int) -> None:
    """Copy a piece's per-sample output (rows x size*cols) into the job's ``(n, rows, cols)`` array."""
    rows = out.shape[0]
    if name not in result:
        block = np.empty((n, cols, rows))          # each sample's matrix in column-major order, as CasADi has it
        result[name] = block.transpose(0, 2, 1)
    target = result[name].transpose(0, 2, 1)      # (n, cols, rows) view of the block
    target[start:start + take] = out[:, :take * cols].T.reshape(take, cols, rows)


def _evaluate(fun: ca.Function, batch: list, record: bool) -> list:
    """Evaluate ``fun`` for each ``(job, memory, (start, stop, size))`` of ``batch``: one call of its map."""
    n = len(batch)
    call, lock = _buffers(fun, n)
    with lock:                                    # one evaluation at a time on these buffers
        for name in fun.name_in():
            rows, cols = fun.size_in(name)
            view = call.arg(name)
            for b, (job, state, (start, stop, size)) in enumerate(batch):
                target = view[:, b * cols:(b + 1) * cols]
                if name in job.per:
                    _copy_piece(job.per[name], start, stop, size, job.pad.get(name), target, cols // size)
                else:
                    v = state.get(name, job.consts.get(name))
                    target[:] = 0.0 if v is None else np.reshape(v, (rows, cols), order="F")
        try:
            call()
        except RuntimeError as exc:
            raise PieceFailed(str(exc), call.fun, {k: call.arg(k).copy() for k in call.names_in}) from exc
        block = call.block.copy()
        args = [{name: call.arg(name)[:, b * fun.size2_in(name):(b + 1) * fun.size2_in(name)].copy()
                 for name in fun.name_in()} for b in range(n)] if record else [None] * n
    outs = {}
    for j, name in enumerate(fun.name_out()):
        rows, cols = fun.size_out(name)
        outs[name] = block[call.offsets[j]:call.offsets[j + 1]].reshape((rows, cols * n), order="F")
    return [(args[b], {k: v[:, b * fun.size2_out(k):(b + 1) * fun.size2_out(k)] for k, v in outs.items()})
            for b in range(n)]
