"""Where the kvlcc2-marin study spends its CPU time, stage by stage, with counts.

One serial run (``--workers 1``: every case in this process) with the functions that do each
stage wrapped by a timer of the process's CPU clock (no profiler: its overhead would swamp the
call-heavy stages such as the figures), and with calls counted. CPU seconds inflate less than a
wall clock on a loaded machine; the counts (fits, engine evaluations, simulations, models built,
figures) do not depend on the load at all. Stages overlap where one calls another (a fold's fit
includes its inverse dynamics); a function called inside itself is timed once. BLAS threads that
spin after a call charge their CPU to whatever runs next (the study's cases hold their BLAS to one
thread; compare runs made with the same BLAS settings).

Run ``python -m benchmarks.count_study [--quick] [--out DIR]`` with a filled compile cache (run the
study once before). Needs the measured data (``CASSHIP_DATA`` or ``../shared/data``).
"""
from __future__ import annotations

import functools
import importlib
import io
import sys
import tempfile
import time
from pathlib import Path

__all__ = ["STAGES", "COUNTS", "profile_study", "main"]

_S = "casship_studies.kvlcc2_marin"
#: stage -> the function (``module:qualified name``) whose CPU time it is
STAGES = {
    "loading the runs": f"{_S}.data:load_runs",
    "smoothing (EKF + RTS)": f"{_S}.workflow:smooth_runs",
    "fits, all (24 folds incl. the fit on all runs)": f"{_S}.workflow:fit_fold",
    "  propulsion": f"{_S}.propulsion:fit_propulsion",
    "  inverse dynamics": "casship.identify.inverse_dynamics:inverse_dynamics",
    "  Fisher information for the selection": "casship.identify.problem:IdentificationProblem.identifiability",
    "  refinements (solve)": "casship.identify.problem:IdentificationProblem.solve",
    "held-out and in-sample replays with bands": f"{_S}.validate:evaluate",
    "fold figures": f"{_S}.report:fold_figure",
    "fit.json replays with the mirror check": f"{_S}:in_sample",
    "port/starboard check": f"{_S}.calibration:asymmetry_check",
    "turning-circle diagnosis": f"{_S}.diagnose:through_the_turn",
    "report, tables, summary": f"{_S}.report:write_outputs",
}
#: count -> the function whose calls it counts
COUNTS = {
    "refinements": "casship.identify.problem:IdentificationProblem.solve",
    "engine requests with sensitivities": "casship.identify._engine:Engine.derivatives",
    "  of them evaluated (not answered from the last evaluation)": "casship.identify._engine:Engine._derivatives",
    "engine requests of the cost alone": "casship.identify._engine:Engine.cost",
    "  of them evaluated": "casship.identify._engine:Engine._cost",
    "simulations": "casship.simulation.simulate:simulate",
    "simulations of parameter draws (mapped)": "casship.simulation.simulate:simulate_many",
    "replays": "casship.maneuvers.replay:replay",
    "KVLCC2 models built": "casship.models.kvlcc2:kvlcc2",
    "discretisations": "casship.discretize:discretize",
    "figures drawn": f"{_S}.report:fold_figure",
}


def _patch(target: str, seconds: dict, calls: dict) -> None:
    """Wrap the function ``target`` where it is defined and wherever a loaded casship module holds it."""
    mod_name, qual = target.split(":")
    owner = importlib.import_module(mod_name)
    *path, name = qual.split(".")
    for part in path:
        owner = getattr(owner, part)
    func = getattr(owner, name)
    if getattr(func, "_counted", None) == target:
        return
    depth = [0]

    @functools.wraps(func)
    def timed(*args, **kwargs):
        calls[target] = calls.get(target, 0) + 1
        depth[0] += 1
        t0 = time.process_time()
        try:
            return func(*args, **kwargs)
        finally:
            depth[0] -= 1
            if not depth[0]:
                seconds[target] = seconds.get(target, 0.0) + time.process_time() - t0

    timed._counted = target
    setattr(owner, name, timed)
    if not path:                                  # a module-level function: also where it was imported
        for m in list(sys.modules.values()):
            if getattr(m, "__name__", "").startswith(("casship", _S)) and getattr(m, name, None) is func:
                setattr(m, name, timed)


def profile_study(out: Path, quick: bool = False) -> dict:
    """Run the study serially into ``out`` with its stages timed; CPU seconds per stage and counts."""
    from casship.studies import get_study, run_study

    get_study("kvlcc2-marin")                     # imports the study's modules
    seconds, calls, absent = {}, {}, set()
    for target in {*STAGES.values(), *COUNTS.values()}:
        try:
            _patch(target, seconds, calls)
        except AttributeError:                    # an older casship without it: shown as n/a
            absent.add(target)
    t0 = time.process_time()
    run_study("kvlcc2-marin", out, quick=quick, workers=1, overwrite=True, stream=io.StringIO())
    total = time.process_time() - t0
    return {"total_cpu_s": total,
            "stages": {k: None if v in absent else seconds.get(v, 0.0) for k, v in STAGES.items()},
            "counts": {k: None if v in absent else calls.get(v, 0) for k, v in COUNTS.items()}}


def main(argv=None) -> dict:
    argv = list(sys.argv[1:] if argv is None else argv)
    quick = "--quick" in argv
    out = Path(argv[argv.index("--out") + 1]) if "--out" in argv else None
    with tempfile.TemporaryDirectory(prefix="casship-count-study-") as tmp:
        res = profile_study(out or Path(tmp) / "study", quick=quick)
    print(f"kvlcc2-marin study{' --quick' if quick else ''}, --workers 1: {res['total_cpu_s']:.1f} CPU s in all "
          "(this process)")
    print("| stage | CPU [s] |\n|---|---:|")
    for k, v in res["stages"].items():
        print(f"| {k} | {'n/a' if v is None else f'{v:.1f}'} |")
    print("\n| count | calls |\n|---|---:|")
    for k, v in res["counts"].items():
        print(f"| {k} | {'n/a' if v is None else v} |")
    return res


if __name__ == "__main__":
    main()
