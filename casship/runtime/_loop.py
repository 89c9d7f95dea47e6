"""A compiled step run over a whole record by one C loop: no pieces, no padding, no copies.

``mapaccum`` folds have a length fixed when they are built, so a record of any length runs in
pieces (see :func:`~casship.runtime.run_fold`), each piece a Python round trip that rebinds buffers
and copies the memory. :class:`NativeFold` compiles the step Function together with a small C
driver that calls it once per sample, with each input pointing straight into the caller's arrays
(any sample stride, also negative, so a reversed view needs no copy) and each output into the
result arrays. The memory of sample ``k`` is read where sample ``k - 1`` wrote it. One call from
Python runs the whole record, at the cost of the step's arithmetic alone. The driver is plain C
against the calling convention of CasADi's generated code, called through ``ctypes``.

The result arrays of a run are views of one block of fresh memory, read-only once written: a
result is never written again, by this run or a later one.
"""
from __future__ import annotations

import ctypes
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ._cache import compile_function

__all__ = ["NativeFold", "driver_source"]

_DOUBLE = 8


def driver_source(name: str, n_in: int, n_out: int) -> str:
    """C source of ``casship_fold_<name>``: calls ``name`` (a generated step) for ``n`` samples.

    Per input ``i``: ``in0[i] + k * in_step[i]`` at sample ``k``, unless ``feed[i] >= 0`` and
    ``k > 0``, when it reads what output ``feed[i]`` wrote at sample ``k - 1`` (the memory). Per
    output ``j``: ``out0[j] + slot * out_step[j]`` with ``slot = k``, or ``k % out_period[j]`` when
    the period is not 0 (a memory nobody keeps: two slots in turn); a NULL ``out0[j]`` is not
    written. Returns 0, or ``k + 1`` if the step failed at sample ``k``.

    Parameters
    ----------
    name : str
        The C name of the generated step.
    n_in, n_out : int
        Its numbers of inputs and outputs.
    """
    if not name.isidentifier():
        raise ValueError(f"a step compiled with a driver needs a C identifier as its name, got {name!r}")
    return f"""

/* casship: the step above, called once per sample of a record */
CASADI_SYMBOL_EXPORT int casship_fold_{name}(casadi_int n, const casadi_real* const* in0,
    const casadi_int* in_step, const casadi_int* feed, casadi_real* const* out0, const casadi_int* out_step,
    const casadi_int* out_period, const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w) {{
  /* per sample only the pointers that move are updated (the memory, the inputs with a stride, the outputs
     kept per sample), in copies of their own: the step may use arg and res as workspace */
  casadi_int k, i, t, n_fed = 0, n_moving = 0, n_written = 0;
  casadi_int fed[{max(n_in, 1)}], moving[{max(n_in, 1)}], written[{max(n_out, 1)}];
  const casadi_real* a[{max(n_in, 1)}];
  casadi_real* r[{max(n_out, 1)}];
  for (i = 0; i < {n_in}; ++i) {{
    a[i] = in0[i];
    if (feed[i] >= 0) fed[n_fed++] = i;
    else if (in_step[i]) moving[n_moving++] = i;
  }}
  for (i = 0; i < {n_out}; ++i) {{
    r[i] = out0[i];
    if (out0[i] && (out_step[i] || out_period[i])) written[n_written++] = i;
  }}
  for (k = 0; k < n; ++k) {{
    if (k > 0) {{
      for (t = 0; t < n_fed; ++t) a[fed[t]] = r[feed[fed[t]]];    /* where sample k - 1 wrote it */
      for (t = 0; t < n_moving; ++t) a[moving[t]] += in_step[moving[t]];
      for (t = 0; t < n_written; ++t) {{
        i = written[t];
        r[i] = out_period[i] ? out0[i] + (k % out_period[i]) * out_step[i] : r[i] + out_step[i];
      }}
    }}
    for (i = 0; i < {n_in}; ++i) arg[i] = a[i];
    for (i = 0; i < {n_out}; ++i) res[i] = r[i];
    if ({name}(arg, res, iw, w, 0)) return (int)(k + 1);
  }}
  return 0;
}}
"""


def _in_place(a: np.ndarray, n: int, rows: int, cols: int, what: str) -> bool:
    """Whether ``a`` (``(n, rows*cols)`` or ``(n, rows, cols)``, else ``ValueError`` naming ``what``) holds
    each sample's entries contiguously in column-major order, at a whole number of doubles apart."""
    if a.ndim == 2 and a.shape == (n, rows * cols):
        ok = a.strides[1] == _DOUBLE or a.shape[1] == 1
    elif a.ndim == 3 and a.shape == (n, rows, cols):
        ok = (a.strides[1] == _DOUBLE or rows == 1) and (a.strides[2] == _DOUBLE * rows or cols == 1)
    else:
        raise ValueError(f"{what} needs shape ({n}, {rows * cols}) or ({n}, {rows}, {cols}), got {a.shape}")
    return ok and a.strides[0] % _DOUBLE == 0


def _address(a: np.ndarray) -> int:
    return a.ctypes.data


class NativeFold:
    """A step Function compiled with its C driver: runs a record in one call.

    Parameters
    ----------
    step : casadi.Function
        The step, with dense inputs and outputs named by slot; the memory slots are inputs and
        outputs of the same name.
    memory : sequence of str
        The memory slots.
    compiled : (casadi.Function, ctypes.CDLL), optional
        The step and its driver compiled already (a background compile); else compiled here now.

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> x, u = ca.SX.sym("x"), ca.SX.sym("u")
    >>> step = ca.Function("acc_step", [x, u], [x + u], ["x", "u"], ["x"], {"allow_duplicate_io_names": True})
    >>> fold = NativeFold(step, ["x"])                                  # doctest: +SKIP
    >>> _, out = fold.run(3, memory={"x": [0.0]}, per_sample={"u": np.ones((3, 1))})  # doctest: +SKIP
    >>> out["x"].ravel().tolist()                                       # doctest: +SKIP
    [1.0, 2.0, 3.0]
    """

    def __init__(self, step: ca.Function, memory: Sequence[str], *, compiled: tuple | None = None):
        for i in range(step.n_in()):
            if not step.sparsity_in(i).is_dense():
                raise ValueError(f"{step.name()}: input {step.name_in(i)!r} is not dense")
        for i in range(step.n_out()):
            if not step.sparsity_out(i).is_dense():
                raise ValueError(f"{step.name()}: output {step.name_out(i)!r} is not dense")
        self.names_in, self.names_out = tuple(step.name_in()), tuple(step.name_out())
        missing = [m for m in memory if m not in self.names_in or m not in self.names_out]
        if missing:
            raise ValueError(f"{step.name()}: memory slot(s) {missing} are not both an input and an output")
        self.memory = tuple(memory)
        self.fun, lib = compiled or compile_function(
            step, extra_source=driver_source(step.name(), step.n_in(), step.n_out()), library=True)
        self._driver = getattr(lib, f"casship_fold_{step.name()}")
        self._driver.restype = ctypes.c_int
        self._driver.argtypes = [ctypes.c_longlong] + [ctypes.c_void_p] * 10
        self._size_in = {n: self.fun.size_in(i) for i, n in enumerate(self.names_in)}
        self._size_out = {n: self.fun.size_out(i) for i, n in enumerate(self.names_out)}
        self._work = (self.fun.sz_arg(), self.fun.sz_res(), self.fun.sz_iw(), self.fun.sz_w())
        self._feed = np.array([self.names_out.index(n) if n in self.memory else -1 for n in self.names_in],
                              dtype=np.int64)

    def _per_sample(self, name: str, a, n: int):
        """``(array kept alive, address of sample 0, sample stride in doubles)`` of a per-sample input."""
        rows, cols = self._size_in[name]
        a = np.asarray(a, dtype=float)
        if not _in_place(a, n, rows, cols, f"per-sample input {name!r}"):   # copied into the layout
            if a.ndim == 2:                                 # rows: the samples' flat entries
                a = np.ascontiguousarray(a)
            else:
                block = np.empty((n, cols, rows))
                block[:] = a.transpose(0, 2, 1)
                a = block
        return a, _address(a), a.strides[0] // _DOUBLE

    def _constant(self, name: str, v):
        rows, cols = self._size_in[name]
        a = np.asarray(v, dtype=float)
        if a.size == 1:
            a = np.full(rows * cols, float(a.reshape(())))
        elif a.size != rows * cols:
            raise ValueError(f"input {name!r} has shape ({rows}, {cols}), got {a.size} values (shape {a.shape})")
        a = np.ascontiguousarray(a.reshape(-1, order="F"))      # a matrix in column-major order
        return a, _address(a), 0

    def _target(self, name: str, a, n: int):
        """``(address of sample 0, sample stride in doubles)`` of a caller's output array, checked."""
        rows, cols = self._size_out[name]
        if not isinstance(a, np.ndarray) or a.dtype != np.float64 or not a.flags.writeable:
            raise ValueError(f"output {name!r} needs a writable float64 array")
        if not _in_place(a, n, rows, cols, f"output {name!r}"):
            raise ValueError(f"output {name!r}: each sample's entries must be contiguous in column-major order")
        return _address(a), a.strides[0] // _DOUBLE

    def run(self, n: int, *, memory: Mapping, per_sample: Mapping, constants: Mapping | None = None,
            keep: Sequence[str] | None = None, out: Mapping | None = None) -> tuple[dict, dict]:
        """Run the step over ``n`` samples.

        Parameters
        ----------
        n : int
            Samples (at least 1).
        memory : mapping name -> array
            The memory before the first sample.
        per_sample : mapping name -> array
            ``(n, size)`` (each row a sample's entries in column-major order) or ``(n, rows, cols)``;
            any sample stride, negative too (a reversed view is read in place).
        constants : mapping name -> array
            Inputs that are the same for every sample.
        keep : sequence of str, optional
            Outputs to return per sample (default: all); memory slots not kept still run.
        out : mapping name -> array, optional
            Arrays to write kept outputs into, shaped like ``per_sample`` entries (any sample
            stride; each sample's entries contiguous in column-major order). The others are
            allocated as one block, read-only once written.

        Returns
        -------
        memory : dict
            The memory after the last sample.
        outputs : dict name -> array
            Each kept output per sample, shape ``(n, rows, cols)`` (the caller's array for those in ``out``).
        """
        n = int(n)
        if n < 1:
            raise ValueError(f"a fold needs at least one sample, got {n}")
        constants, targets = dict(constants or {}), dict(out or {})
        keep = tuple(self.names_out if keep is None else keep)
        unknown = [k for k in (*memory, *per_sample, *constants) if k not in self.names_in]
        unknown += [k for k in (*keep, *targets) if k not in self.names_out]
        unknown += [k for k in targets if k not in keep]
        if unknown:
            raise ValueError(f"{self.fun.name()} has no slot(s) {unknown} here; inputs {list(self.names_in)}, "
                             f"outputs {list(self.names_out)}, kept {list(keep)}")
        alive, in0, in_step = [], np.zeros(len(self.names_in), np.uint64), np.zeros(len(self.names_in), np.int64)
        for i, name in enumerate(self.names_in):
            if name in per_sample:
                a, addr, step = self._per_sample(name, per_sample[name], n)
            elif name in memory or name in constants:
                a, addr, step = self._constant(name, memory[name] if name in memory else constants[name])
            else:
                raise ValueError(f"{self.fun.name()}: input {name!r} is not given")
            alive.append(a)
            in0[i], in_step[i] = addr, step
        # one block for the outputs written here
        slots = {k: (n if k in keep else 2) for k in self.names_out
                 if k not in targets and (k in keep or k in self.memory)}
        sizes = {k: self._size_out[k][0] * self._size_out[k][1] for k in self.names_out}
        block = np.empty(sum(slots[k] * sizes[k] for k in slots))
        views, offset = {}, 0
        for k, count in slots.items():
            rows, cols = self._size_out[k]
            views[k] = block[offset:offset + count * sizes[k]].reshape(count, cols, rows).transpose(0, 2, 1)
            offset += count * sizes[k]
        out0, out_step = np.zeros(len(self.names_out), np.uint64), np.zeros(len(self.names_out), np.int64)
        period = np.zeros(len(self.names_out), np.int64)
        for j, name in enumerate(self.names_out):
            if name in targets:
                out0[j], out_step[j] = self._target(name, targets[name], n)
            elif name in views:
                out0[j], out_step[j] = _address(views[name]), sizes[name]
                period[j] = 0 if name in keep else 2
        sz_arg, sz_res, sz_iw, sz_w = self._work
        arg, res = np.zeros(sz_arg, np.uint64), np.zeros(sz_res, np.uint64)
        iw, w = np.zeros(max(sz_iw, 1), np.int64), np.zeros(max(sz_w, 1))
        status = self._driver(n, *(_address(a) for a in (in0, in_step, self._feed, out0, out_step, period,
                                                          arg, res, iw, w)))
        if status:
            raise RuntimeError(f"evaluation of {self.fun.name()} failed at sample {status - 1}")
        block.setflags(write=False)
        for v in views.values():
            v.setflags(write=False)
        outs = {k: (targets[k] if k in targets else views[k]) for k in keep}
        final = {}
        for k in self.memory:
            last = outs[k][n - 1] if k in outs else views[k][(n - 1) % 2]
            final[k] = (last.reshape(self._size_out[k], order="F") if last.ndim == 1 else last).copy()
        return final, outs
