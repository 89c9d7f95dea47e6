"""The identification study as a user meets it: ``casship study kvlcc2-marin`` cold and warm.

Wall-clock seconds of the whole command (the fit on the 16 runs, its 23 cross-validation folds,
the replays and the report) in fresh processes: *cold* with an empty compile cache, *warm* with
the cache it filled, each with the folds spread over the machine's cores (the default) and warm
once more serially (``--workers 1``, the peer of the ratio: what the parallel loop gains). The
targets are absolute: warm <= 15 s, cold <= 45 s on a 2-core machine. Wall-clock time of a
shared, loaded machine says little: run it on a quiet one.

Run ``python -m benchmarks.bench_study [--quick]`` (``--quick``: the seven-run study with one fold).
Needs the measured data (``CASSHIP_DATA`` or ``../shared/data``); without them the rows are skipped.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import format_table, row, skipped_row

TARGET_WARM_S, TARGET_COLD_S = 15.0, 45.0
_NOISY = ("seconds", "solve_time_s", "fit_seconds", "workflow_seconds", "created")


def _run(args: list[str], cache: Path) -> tuple[float, float]:
    """Wall-clock and CPU seconds (all processes) of ``casship study ...`` with the compile cache ``cache``."""
    env = {**os.environ, "CASSHIP_CACHE_DIR": str(cache), "CASSHIP_PROGRESS": "0"}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "casship", "study", *args], env=env, check=True, capture_output=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _numbers(path: Path):
    """A fit file without its timings (what must agree between the runs)."""
    def strip(v):
        if isinstance(v, dict):
            return {k: strip(x) for k, x in v.items() if k not in _NOISY}
        return [strip(x) for x in v] if isinstance(v, list) else v
    return strip(json.loads(path.read_text()))


def main(quick: bool = False) -> list[dict]:
    from casship.io import data_dir

    try:
        data = data_dir()
    except FileNotFoundError:
        data = None
    what = "kvlcc2-marin study" + (" --quick" if quick else "")
    if data is None or not (Path(data) / "kvlcc2_marin_free").is_dir():
        return [skipped_row(f"{what}, warm", "--workers 1", "the measured data are absent (CASSHIP_DATA)")]
    extra = ["--quick"] if quick else []
    with tempfile.TemporaryDirectory(prefix="casship-bench-study-") as tmp:
        tmp = Path(tmp)
        cache = tmp / "cache"
        cold, cold_cpu = _run(["kvlcc2-marin", "--out", str(tmp / "cold"), *extra], cache)
        warm, warm_cpu = _run(["kvlcc2-marin", "--out", str(tmp / "warm"), *extra], cache)
        serial, serial_cpu = _run(["kvlcc2-marin", "--out", str(tmp / "serial"), "--workers", "1", *extra], cache)
        same = all(_numbers(tmp / d / "fit.json") == _numbers(tmp / "serial" / "fit.json") for d in ("cold", "warm"))
    check = f"fit.json numbers {'identical' if same else 'DIFFER'} in the three runs"
    return [
        row(f"{what}, warm (cache filled), wall-clock; target <= {TARGET_WARM_S:g} s", warm, "--workers 1 (serial)",
            serial, check, cpu_s=warm_cpu, peer_cpu_s=serial_cpu, target_s=TARGET_WARM_S),
        row(f"{what}, cold (empty cache), wall-clock; target <= {TARGET_COLD_S:g} s", cold, "warm, parallel", warm,
            check, cpu_s=cold_cpu, target_s=TARGET_COLD_S),
    ]


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
