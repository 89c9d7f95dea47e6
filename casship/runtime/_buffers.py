"""Low-overhead numeric calls of CasADi Functions: named buffers and folds in pieces.

Calling a Function with numpy arrays converts every argument to ``DM`` and every result back,
which costs tens of microseconds per call. :class:`BufferedCall` instead binds preallocated numpy
arrays once through CasADi's own buffer API (``Function.buffer``), addressed by the Function's
input and output *names*; a call only triggers the evaluation (the fold driver,
:func:`~casship.runtime.run_pieces`, runs its pieces through such buffers). :class:`BoundedTable`
keeps such Functions and buffers for reuse within a process, up to a limit.
"""
from __future__ import annotations

import threading
from typing import Mapping

import casadi as ca
import numpy as np

__all__ = ["BufferedCall", "DUPLICATE_NAMES", "BoundedTable"]

# Step Functions name their memory slots alike on both sides (input ``x``, output ``x``).
DUPLICATE_NAMES = {"allow_duplicate_io_names": True}


class BoundedTable(dict):
    """A dict of things built once per process and found again (Functions, buffer sets), holding at
    most ``limit`` entries: :meth:`keep` adds one and drops the oldest beyond the limit, under a lock
    (threads may build at the same time).

    Parameters
    ----------
    limit : int
        Entries kept.

    Examples
    --------
    >>> t = BoundedTable(2)
    >>> for k in "abc":
    ...     _ = t.keep(k, k.upper())
    >>> sorted(t)
    ['b', 'c']
    """

    def __init__(self, limit: int):
        super().__init__()
        self.limit = int(limit)
        self._lock = threading.Lock()

    def keep(self, key, value):
        """``self[key] = value``, the oldest entries beyond the limit dropped; returns ``value``."""
        with self._lock:
            self[key] = value
            while len(self) > self.limit:
                del self[next(iter(self))]
        return value


class BufferedCall:
    """Evaluate ``fun`` repeatedly on preallocated arrays addressed by name.

    Write an input with ``call["dt"] = 0.1`` (any array with the input's number of entries, in
    column-major order, or a scalar broadcast to all of them), evaluate with ``call()`` and read an
    output with ``call.out("x")`` (a view with the output's matrix shape, overwritten by the next
    call). ``call.arg(name)`` is the writable view of an input for loops that write it in place.
    All outputs live in one contiguous block (``call.block``), so one copy snapshots them.
    ``call.trigger()`` evaluates without reading the status (CasADi's buffered evaluation itself,
    no Python in between), for Functions that cannot fail (``call.checked`` is then false); it
    works on the call's buffers, so whoever keeps ``call.trigger`` keeps ``call`` too.

    A call is not for two threads at once: its buffers are shared state (the online runner holds
    a lock around its calls).

    Parameters
    ----------
    fun : casadi.Function
        A Function with dense inputs.
    cannot_fail : bool
        The caller knows that the evaluation cannot fail (compiled code): no status is read. SX
        Functions never fail.
    bind_in, bind_out : mapping name -> array, optional
        Arrays to use as the buffers of those inputs and outputs (contiguous float vectors of
        their sizes), shared with the caller.

    Examples
    --------
    >>> import casadi as ca
    >>> x = ca.SX.sym("x", 2)
    >>> call = BufferedCall(ca.Function("f", [x], [2 * x], ["x"], ["y"]))
    >>> call["x"] = [1.0, 2.0]
    >>> _ = call()
    >>> call.out("y").ravel().tolist()
    [2.0, 4.0]
    """

    def __init__(self, fun: ca.Function, *, cannot_fail: bool = False, bind_in: Mapping | None = None,
                 bind_out: Mapping | None = None):
        for i in range(fun.n_in()):
            if not fun.sparsity_in(i).is_dense():
                raise ValueError(f"{fun.name()}: input {fun.name_in(i)!r} is not dense")
        self.fun = fun
        self.names_in = tuple(fun.name_in())
        self.names_out = tuple(fun.name_out())
        bind_in, bind_out = dict(bind_in or {}), dict(bind_out or {})
        self.args = [bind_in.get(n, np.zeros(fun.nnz_in(i))) for i, n in enumerate(self.names_in)]
        sizes = [fun.nnz_out(i) for i in range(fun.n_out())]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.block = np.zeros(int(offsets[-1]))
        self.offsets = offsets
        self.res = [bind_out.get(n, self.block[offsets[i]:offsets[i + 1]]) for i, n in enumerate(self.names_out)]
        for kind, arrays, sizes_ in (("input", self.args, [fun.nnz_in(i) for i in range(fun.n_in())]),
                                     ("output", self.res, sizes)):
            for a, s in zip(arrays, sizes_):
                if a.dtype != np.float64 or a.ndim != 1 or a.size != s or not a.flags.c_contiguous:
                    raise ValueError(f"{fun.name()}: a bound {kind} array must be a contiguous float vector of {s}")
        self._in = {n: a.reshape(fun.size_in(i), order="F") for i, (n, a) in enumerate(zip(self.names_in, self.args))}
        self._out = {n: r.reshape(fun.size_out(i), order="F") for i, (n, r) in enumerate(zip(self.names_out, self.res))}
        self._flat_in = dict(zip(self.names_in, self.args))
        self._flat_out = dict(zip(self.names_out, self.res))
        self._buf, self.trigger = fun.buffer()
        self._redirected = {}
        for i, a in enumerate(self.args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.res):
            self._buf.set_res(i, memoryview(r))
        # SX Functions (and compiled code, when the caller says so) cannot fail: no status round trip
        self.checked = not (cannot_fail or fun.is_a("SXFunction"))

    def _unknown(self, name, kind, names):
        return ValueError(f"{self.fun.name()} has no {kind} {name!r}; {kind}s: {list(names)}")

    def arg(self, name: str) -> np.ndarray:
        """Writable view of input ``name`` with its matrix shape."""
        try:
            return self._in[name]
        except KeyError:
            raise self._unknown(name, "input", self.names_in) from None

    def out(self, name: str) -> np.ndarray:
        """View of output ``name`` with its matrix shape (valid until the next call)."""
        try:
            return self._out[name]
        except KeyError:
            raise self._unknown(name, "output", self.names_out) from None

    def __setitem__(self, name: str, value) -> None:
        flat = self._flat_in.get(name)
        if flat is None:
            raise self._unknown(name, "input", self.names_in)
        v = np.asarray(value, dtype=float)
        if v.size == flat.size:
            flat[:] = v.reshape(-1, order="F")
        elif v.size == 1:
            flat[:] = v.reshape(())
        else:
            raise ValueError(f"{self.fun.name()}: input {name!r} has shape {self._in[name].shape}, "
                             f"got {v.size} values (shape {v.shape})")

    def redirect(self, name: str, target: np.ndarray | None) -> None:
        """Write output ``name`` straight into ``target`` (a contiguous float vector of its size) on
        the following calls, or back into its own array with ``None``. Lets a fold write its
        per-sample results into the final result block without a copy."""
        i = self.names_out.index(name)
        if target is None:
            self._redirected.pop(name, None)
            self._buf.set_res(i, memoryview(self.res[i]))
            return
        if target.dtype != np.float64 or target.size != self.res[i].size or not target.flags.c_contiguous:
            raise ValueError(f"{self.fun.name()}: output {name!r} needs a contiguous float vector of {self.res[i].size}")
        self._redirected[name] = target                 # keeps the target alive while CasADi holds its address
        self._buf.set_res(i, memoryview(target))

    def restore_outputs(self) -> None:
        """Write every redirected output into its own array again (and let go of the targets)."""
        for name in list(self._redirected):
            self.redirect(name, None)

    def flat_in(self, name: str) -> np.ndarray:
        """The flat (column-major) array bound to input ``name``."""
        self.arg(name)
        return self._flat_in[name]

    def flat_out(self, name: str) -> np.ndarray:
        """The flat (column-major) array bound to output ``name``."""
        self.out(name)
        return self._flat_out[name]

    def partner(self, memory) -> "BufferedCall":
        """A second buffered call of the same Function that reads the ``memory`` outputs of this one
        and writes its ``memory`` outputs into this one's ``memory`` inputs (the other inputs shared,
        the other outputs its own): alternating the two calls hands the memory over without a copy,
        and the outputs of the call before the last stay readable.

        Parameters
        ----------
        memory : sequence of str
            Names that are both an input and an output.
        """
        bind_in = {n: self.flat_in(n) for n in self.names_in}
        bind_out = {}
        for n in memory:
            bind_in[n], bind_out[n] = self.flat_out(n), self.flat_in(n)
        return BufferedCall(self.fun, cannot_fail=not self.checked, bind_in=bind_in, bind_out=bind_out)

    def __call__(self) -> list:
        """Evaluate; raises ``RuntimeError`` if the evaluation reports a failure. Read the results
        by name with :meth:`out` (the flat output arrays are also returned, in output order)."""
        self.trigger()
        if self.checked:
            status = self._buf.ret()
            if status != 0:
                raise RuntimeError(f"evaluation of {self.fun.name()} failed (status {status})")
        return self.res
