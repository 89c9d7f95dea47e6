"""Low-overhead numeric calls of CasADi Functions through ``Function.buffer``.

Calling a Function with numpy arrays converts every argument to ``DM`` and every result back,
which costs tens of microseconds per call. Online estimator steps instead bind preallocated
numpy arrays once and only trigger the evaluation.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["BufferedCall"]


class BufferedCall:
    """Evaluate ``fun`` repeatedly on preallocated arrays.

    ``args[i]`` and ``res[i]`` are flat numpy arrays holding the entries of dense inputs and
    outputs in CasADi's column-major order; ``arg_views``/``res_views`` show them with their
    matrix shapes. Write inputs in place, call, read the results (no copies, no ``DM``).
    """

    def __init__(self, fun: ca.Function):
        for i in range(fun.n_in()):
            if not fun.sparsity_in(i).is_dense():
                raise ValueError(f"{fun.name()}: input {fun.name_in(i)!r} is not dense")
        self.fun = fun
        self.args = [np.zeros(fun.nnz_in(i)) for i in range(fun.n_in())]
        sizes = [fun.nnz_out(i) for i in range(fun.n_out())]
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.block = np.zeros(int(offsets[-1]))   # all results, contiguous (one copy snapshots them)
        self.offsets = offsets
        self.res = [self.block[offsets[i]:offsets[i + 1]] for i in range(fun.n_out())]
        self.arg_views = [a.reshape(fun.size_in(i), order="F") for i, a in enumerate(self.args)]
        self.res_views = [r.reshape(fun.size_out(i), order="F") for i, r in enumerate(self.res)]
        self._buf, self._trigger = fun.buffer()
        for i, a in enumerate(self.args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self.res):
            self._buf.set_res(i, memoryview(r))

    def trigger(self) -> None:
        """Evaluate without fetching the return status (for Functions that cannot fail: SX, compiled)."""
        self._trigger()

    def __call__(self) -> list[np.ndarray]:
        self._trigger()
        status = self._buf.ret()
        if status != 0:
            raise RuntimeError(f"evaluation of {self.fun.name()} failed (status {status})")
        return self.res
