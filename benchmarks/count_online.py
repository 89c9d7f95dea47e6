"""What one online ``run.update`` costs, counted (not timed): Python bytecodes, Python frames, calls
of builtin functions and evaluations of CasADi Functions per update.

Counts do not depend on the load of the machine, so they show the per-call overhead where a timing
could not. The problem is the 6-state ship of ``bench_ship_filters`` (the EKF online row): ``jit``
and interpreted EKF, lean outputs, ``update(y, dt, u_prev, u)`` with float64 vectors as the
benchmark calls it. Bytecodes and frames are counted with ``sys.settrace`` (opcode events), builtin
calls with ``sys.setprofile``; CasADi evaluations by counting the calls of CasADi's buffer
evaluation (``casadi._casadi._function_buffer_eval``, the callable behind ``Function.buffer``)
during the updates. Run ``python -m benchmarks.count_online``.
"""
from __future__ import annotations

import collections
import sys

import casadi as ca

import casship as cs
from benchmarks.bench_ship_filters import DT, case

__all__ = ["count_updates", "main"]


def count_updates(update, Y, U, start: int = 1, n: int = 50) -> dict:
    """Per-update counts of ``update(Y[k], DT, U[k-1], U[k])`` over ``n`` samples from ``start``.

    Returns
    -------
    dict
        ``bytecodes``, ``frames`` (Python functions entered), ``builtin_calls`` (calls of builtin
        functions seen by the profiler) and ``frames_by_name`` (qualified name -> count per update).
    """
    opcodes, frames, builtins = 0, collections.Counter(), collections.Counter()

    def trace(frame, event, arg):
        nonlocal opcodes
        if event == "call":
            frame.f_trace_opcodes = True
            frames[frame.f_code.co_qualname if hasattr(frame.f_code, "co_qualname") else frame.f_code.co_name] += 1
        elif event == "opcode":
            opcodes += 1
        return trace

    def profile(frame, event, arg):
        if event == "c_call":
            builtins[getattr(arg, "__qualname__", repr(arg))] += 1

    def loop_under(install, hook):
        install(hook)
        try:
            for k in range(start, start + n):
                update(Y[k], DT, U[k - 1], U[k])
        finally:
            install(None)

    loop_under(sys.settrace, trace)
    loop_under(sys.setprofile, profile)
    builtins.pop("setprofile", None)
    return {"bytecodes": opcodes / n, "frames": sum(frames.values()) / n,
            "builtin_calls": sum(builtins.values()) / n,
            "frames_by_name": {k: v / n for k, v in frames.items()},
            "builtins_by_name": {k: v / n for k, v in builtins.items()}}


def _casadi_evaluations(make_run, Y, U, n: int = 50) -> float:
    """CasADi buffer evaluations per update (the run is made while the evaluation is counted)."""
    raw = ca._casadi._function_buffer_eval
    calls = [0]

    def counted(handle):
        calls[0] += 1
        return raw(handle)

    ca._casadi._function_buffer_eval = counted
    try:
        update = make_run().update
        update(Y[0], 0.0, U[0], U[0])
        calls[0] = 0
        for k in range(1, n + 1):
            update(Y[k], DT, U[k - 1], U[k])
    finally:
        ca._casadi._function_buffer_eval = raw
    return calls[0] / n


def main() -> list[dict]:
    model, dm, data, prior, Q, R, Qx, U, Y = case(200)
    rows = []
    for jit in (True, False):
        ekf = cs.EKF(dm, Q, R, options={"jit": jit})
        make = lambda: ekf.online(prior, u=U[0])  # noqa: E731
        run = make()
        run.update(Y[0], 0.0, U[0], U[0])
        counts = count_updates(run.update, Y, U)
        counts["casadi_evaluations"] = _casadi_evaluations(make, Y, U)
        counts["jit"] = jit
        rows.append(counts)
    return rows


if __name__ == "__main__":
    for r in main():
        print(f"EKF online update, jit={r['jit']}: {r['bytecodes']:.0f} bytecodes, {r['frames']:.0f} Python frames, "
              f"{r['builtin_calls']:.0f} builtin calls, {r['casadi_evaluations']:.0f} CasADi evaluation(s) per update")
        print("  frames:", ", ".join(f"{k} {v:g}" for k, v in sorted(r["frames_by_name"].items())))
        print("  builtins:", ", ".join(f"{k} {v:g}" for k, v in sorted(r["builtins_by_name"].items())))
