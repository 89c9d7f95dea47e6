"""What one compiled ``EKF.filter`` costs, counted in machine instructions (not timed), part by part.

Instruction counts do not depend on the load of the machine, so they show where a call's time goes
when timings cannot (a shared machine). Each part runs under ``valgrind --tool=callgrind`` with
collection switched on only inside ``bisect.insort_right`` (a C function nothing else here calls),
which calls the part through its ``key``; each call is dumped as its own profile, and the count of
one call is the difference of a run of three calls and a run of one (so what happens once, like an
import, drops out). The code is compiled with portable flags (valgrind does not run every
``-march=native`` instruction) into a private cache folder.

Parts: the whole ``filter``, the C loop over the record (``NativeFold.run``), the record's
preparation (``prepare``), the result (``result``), the time-gap check (``bridge_gaps``), on the
6-state ship of ``bench_ship_filters`` (3000 samples). A division or a call into the maths library
counts as one or a hundred instructions whatever its cycles, so the step's arithmetic is better
compared by timing it against itself (``docs/benchmarks.md``).

Run ``python -m benchmarks.count_filter`` (needs valgrind).
"""
from __future__ import annotations

import bisect
import glob
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

PARTS = ("filter", "fold", "prepare", "result", "bridge")


def _count(fn, reps: int) -> None:
    bisect.insort_right([], 0, key=lambda _: [fn() for _ in range(reps)] and 0)


def _targets() -> dict:
    """The parts as callables on the benchmark's problem (run inside valgrind)."""
    import casship as cs
    from benchmarks.bench_ship_filters import case
    from casship.estimators.base import CONSTANT_INPUTS, DIAGNOSTICS, SAMPLE_INPUTS
    from casship.estimators.gaps import bridge_gaps

    _, dm, data, prior, Q, R, _, _, _ = case(3000)
    ekf = cs.EKF(dm, Q, R, options={"jit": True})
    ekf.filter(data, prior)
    arrays = ekf.prepare(data)
    fold = ekf._native_fold(ekf._output_names("all"))
    memory = ekf.memory_from(prior)
    per = {k: arrays[k].T for k in SAMPLE_INPUTS}
    constants = {k: arrays[k] for k in CONSTANT_INPUTS}
    run = lambda: fold.run(len(data), memory=memory, per_sample=per, constants=constants, keep=DIAGNOSTICS)  # noqa: E731
    outs = run()[1]
    return {"filter": lambda: ekf.filter(data, prior), "fold": run, "prepare": lambda: ekf.prepare(data),
            "result": lambda: ekf.result(data, arrays, outs), "bridge": lambda: bridge_gaps(ekf, data, prior.mean)}


def _inside(names: list[str]) -> None:
    targets = _targets()
    for name in names:
        targets[name]()
        _count(targets[name], 1)
        _count(targets[name], 3)


def count(parts=PARTS) -> dict:
    """Instructions per call of each part (name -> count).

    Parameters
    ----------
    parts : sequence of str
        Among :data:`PARTS`.
    """
    if shutil.which("valgrind") is None:
        raise RuntimeError("valgrind is not installed")
    root = str(Path(__file__).resolve().parents[1])
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp) / "cache"
        cache.mkdir(mode=0o700)
        env = {**os.environ, "CASSHIP_CACHE_DIR": str(cache), "CASSHIP_CFLAGS": "-O3 -fno-math-errno",
               "OPENBLAS_NUM_THREADS": "1", "PYTHONPATH": root}
        out = Path(tmp) / "cg"
        subprocess.run(["valgrind", "--tool=callgrind", "--toggle-collect=*insort_right*",
                        "--dump-after=_bisect_insort_right", f"--callgrind-out-file={out}",
                        f"--log-file={tmp}/log", sys.executable, "-W", "ignore", "-c",
                        f"from benchmarks.count_filter import _inside; _inside({list(parts)!r})"],
                       check=True, env=env, cwd=root)
        files = sorted(glob.glob(f"{out}.*"), key=lambda p: int(p.rsplit(".", 1)[1]))
        totals = [int(re.search(r"^totals:\s+(\d+)", Path(f).read_text(), re.M).group(1)) for f in files]
    totals = totals[-2 * len(parts):]
    return {name: (totals[2 * i + 1] - totals[2 * i]) / 2 for i, name in enumerate(parts)}


def main() -> None:
    for name, n in count().items():
        print(f"{name:10s} {n:14,.0f} instructions per call")


if __name__ == "__main__":
    main()
