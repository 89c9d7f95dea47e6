"""Compiled code: the compiler flags that win, and what the on-disk compile cache saves a new process.

Flags: the Functions casship compiles most (the EKF step, lean and with every diagnostic; the EKF
and UKF folds over 512 samples that ``filter`` runs; the MHE real-time-iteration step, N = 20), on
the 6-state ship model of ``bench_ship_filters``, compiled with ``-O1``, ``-O2``, ``-O3``,
``-O3 -fno-math-errno`` (the default) and ``-O3 -fno-math-errno -march=native`` through :func:`casship.runtime.compile_function` (no cache). Each is timed on
the same inputs through bound buffers, all flag sets in turn, several rounds (median CPU time per
call); the ratio is the ``-O2`` time over this one (above 1: faster than ``-O2``). The compile time
is the wall-clock time of generating and compiling the C code.

Cache: a fresh Python process builds an estimator with ``jit`` and runs it once, first with an empty
compile cache (it compiles), then again in another fresh process with the cache the first one
filled (it loads the libraries). Times are wall clock inside the subprocess, from after the imports
and the data set-up to the end of the first call. Run ``python -m benchmarks.bench_compile [--quick]``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import casship as cs
from benchmarks import format_table, row
from casship.runtime import DEFAULT_FLAGS, BufferedCall, compile_function

FLAG_SETS = (("-O1",), ("-O2",), ("-O3",), ("-O3", "-fno-math-errno"), ("-O3", "-fno-math-errno", "-march=native"))


def functions() -> dict:
    """Name -> (Function, inputs) of the Functions measured."""
    from benchmarks.bench_ship_filters import case

    model, dm, data, prior, Q, R, Qx, U, Y = case(600)
    ekf, ukf = cs.EKF(dm, Q, R), cs.UKF(dm, Q, R)
    arrays = ekf.prepare(data)
    mem = ekf.memory_from(prior)

    def step_inputs(f, k=5):
        return {"x": mem["x"], "P": mem["P"], **{n: arrays[n][:, k] for n in ("u_prev", "u", "y", "mask", "dt", "gate")},
                "p": arrays["p"], "Q": Q, "R": R}

    def fold_inputs(f):
        return {"x": mem["x"], "P": mem["P"], **{n: arrays[n][:, :512] for n in ("u_prev", "u", "y", "mask", "dt", "gate")},
                "p": arrays["p"], "Q": Q, "R": R}

    from benchmarks.bench_mhe import problem
    _, mdm, mdata, mprior, mQ, mR = problem(10.0)
    mhe = cs.MHE(mdm, mQ, mR, options={"horizon": 20, "solver": "rti"})
    run = mhe.online(mprior)
    Ym, Um = mdata.matrix(mhe.measured), mdata.matrix(mhe.model.input_names)
    for k in range(30):
        run.update(Ym[k], 0.1 if k else 0.0, Um[max(k - 1, 0)], Um[k])
    eng = run._engine
    rti = eng.win.make_gn(False, "riccati").fun      # the symbolic step that option jit compiles
    return {"EKF step, lean (x, P)": (ekf.step_function(("x", "P")), step_inputs),
            "EKF step, every diagnostic": (ekf.step_function("all"), step_inputs),
            "EKF fold, 512 samples": (ekf.fold(512, "all"), fold_inputs),
            "UKF fold, 512 samples": (ukf.fold(512, "all"), fold_inputs),
            "MHE RTI step (Riccati), N = 20": (rti, lambda f: {"z": eng.z, "p": eng.par})}


def _timer(fun, inputs, budget: float = 0.05):
    call = BufferedCall(fun, cannot_fail=True)
    for k, v in inputs.items():
        call[k] = v
    call.trigger()
    t0, reps = time.process_time(), 0
    while time.process_time() - t0 < 0.01:
        call.trigger()
        reps += 1
    reps = max(1, int(reps * budget / 0.01))

    def timed():
        t0 = time.process_time()
        for _ in range(reps):
            call.trigger()
        return (time.process_time() - t0) / reps

    return timed, call


def flag_rows(quick: bool) -> list[dict]:
    rows = []
    rounds = 3 if quick else 7
    for name, (fun, make_inputs) in functions().items():
        inputs = make_inputs(fun)
        timers, compile_s, outs = {}, {}, {}
        for flags in FLAG_SETS:
            t0 = time.perf_counter()
            compiled = compile_function(fun, flags=flags, cache=False)
            compile_s[flags] = time.perf_counter() - t0
            timers[flags], call = _timer(compiled, inputs)
            outs[flags] = call.block
        times = {f: [] for f in FLAG_SETS}
        for _ in range(rounds):
            for f in FLAG_SETS:
                times[f].append(timers[f]())
        base = np.array(times[("-O2",)])
        for f in FLAG_SETS:
            t = np.array(times[f])
            ratios = np.sort(base / t)
            diff = float(np.max(np.abs(outs[f] - outs[("-O2",)])))
            r = row(f"{name}: {' '.join(f)}", float(np.median(t)), "the same Function compiled with -O2",
                    float(np.median(base)), f"compile {compile_s[f]:.2f} s; max |output - output(-O2)| = {diff:.1e}",
                    compile_s=compile_s[f], flags=" ".join(f), function=name,
                    default=tuple(f) == tuple(DEFAULT_FLAGS))
            r.update(ratio=float(np.median(ratios)), ratio_min=float(ratios[0]), ratio_max=float(ratios[-1]))
            rows.append(r)
    return rows


FIRST_CALL = """
import json, sys, time
sys.path.insert(0, {root!r})
import numpy as np, casship as cs
from benchmarks.bench_ship_filters import case
from benchmarks.bench_mhe import problem
model, dm, data, prior, Q, R, Qx, U, Y = case(600)
what = {what!r}
t0 = time.perf_counter()
if what == "EKF step":
    from casship.runtime import compile_function
    compile_function(cs.EKF(dm, Q, R).step_function())
elif what in ("EKF filter", "UKF filter"):
    cls = cs.EKF if what == "EKF filter" else cs.UKF
    cls(dm, Q, R, options={{"jit": True}}).filter(data, prior)
elif what == "EKF online":
    run = cs.EKF(dm, Q, R, options={{"jit": True}}).online(prior, u=U[0])
    run.update(Y[0], 0.0)
elif what == "MHE RTI":
    _, mdm, mdata, mprior, mQ, mR = problem(2.0)
    mhe = cs.MHE(mdm, mQ, mR, options={{"horizon": 20, "solver": "rti", "jit": True}})
    run = mhe.online(mprior)
    run.update(mdata.matrix(mhe.measured)[0], 0.0)
print(json.dumps({{"seconds": time.perf_counter() - t0}}))
"""

CACHE_CASES = ("EKF step", "EKF online", "EKF filter", "UKF filter", "MHE RTI")


def _first_call(what: str, cache: str) -> float:
    root = str(Path(__file__).resolve().parents[1])
    out = subprocess.run([sys.executable, "-c", FIRST_CALL.format(root=root, what=what)], capture_output=True,
                         text=True, env={**os.environ, "CASSHIP_CACHE_DIR": cache}, cwd=root)
    if out.returncode != 0:
        raise RuntimeError(f"{what}: subprocess failed: {out.stderr.strip().splitlines()[-1:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])["seconds"]


def cache_rows(quick: bool) -> list[dict]:
    rows = []
    cases = CACHE_CASES[:2] if quick else CACHE_CASES
    for what in cases:
        with tempfile.TemporaryDirectory(prefix="casship-bench-cache-") as cache:
            cold = _first_call(what, cache)
            warm = _first_call(what, cache)
        rows.append(row(f"{what}, first call in a new process (6-state ship model, jit)", warm,
                        "the same with an empty compile cache", cold,
                        f"empty cache {cold:.2f} s (compiles), cache filled {warm:.3f} s (loads)",
                        cold_s=cold, warm_s=warm, series="cache"))
    return rows


def main(quick: bool = False) -> list[dict]:
    return flag_rows(quick) + cache_rows(quick)


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
