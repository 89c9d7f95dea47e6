"""Monte Carlo runs of an autopilot over sensor-noise seeds and ship speeds, through the study runner
(:func:`casship.parallel.run_cases`: local processes, or a Dask cluster).

Each case designs the autopilot at the design speed (once per worker process, cached), sets the
ship to the case's speed (trim of the propeller or surge force) and runs the compiled closed loop
with the case's noise seed; it returns the per-change metrics and the performance report.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Mapping, Sequence

import numpy as np

from ..parallel import run_cases
from .plants import steering_plant

__all__ = ["monte_carlo", "run_case"]


@lru_cache(maxsize=8)
def _design(model_name: str, design_speed: float | None, settings: tuple):
    from ..models import get_model
    from .ship_design import design_autopilot

    return design_autopilot(get_model(model_name), design_speed, **dict(settings))


def run_case(case: Mapping) -> dict:
    """One closed-loop run (module level, so that it runs in worker processes).

    Parameters
    ----------
    case : mapping
        ``model`` (registered name), ``design_speed`` (None: the vessel's), ``speed`` (of the run),
        ``seed``, ``scenario``, ``t_end`` (None: the design's), ``settings`` (tuple of pairs).
    """
    from ..models import get_model

    design = _design(case["model"], case.get("design_speed"), tuple(case.get("settings", ())))
    truth = design.plant
    if case.get("speed") is not None:
        pl = steering_plant(get_model(case["model"]), case["speed"])
        truth = truth.replace(inputs=pl.inputs, x0=pl.x0)
    res = design.simulate(case.get("scenario", "course-20"), case.get("t_end"), seed=case["seed"], plant=truth,
                          warn=False)
    return {"model": case["model"], "speed": case.get("speed"), "seed": case["seed"],
            "metrics": res.metrics, "performance": res.performance}


def monte_carlo(model_name: str, seeds: Sequence[int], speeds: Sequence[float] | None = None, *,
                design_speed: float | None = None, scenario: str = "course-20", t_end: float | None = None,
                workers: int | None = 1, scheduler: str | None = None, **settings) -> dict:
    """Run the closed loop over every (speed, seed) pair and summarise.

    Parameters
    ----------
    model_name : str
        Registered model (the cases rebuild it in the workers).
    seeds : sequence of int
        Sensor-noise seeds.
    speeds : sequence of float, optional
        Ship speeds of the runs [m/s] (default: the design speed only).
    design_speed : float, optional
        Speed the autopilot is designed for (default ``vessel.U0``).
    scenario : str
        Course-change scenario (:func:`~casship.autopilot.performance.course_scenario`).
    t_end : float, optional
        Run length (default: the design's two segments).
    workers, scheduler
        As :func:`casship.parallel.run_cases` (``workers=1`` serial; a Dask scheduler address).
    **settings
        Autopilot settings (:data:`~casship.autopilot.defaults.RULES`).

    Returns
    -------
    dict
        ``runs`` (one row per case) and ``summary`` per speed: worst and mean overshoot [%],
        largest |steady error| [deg] and largest rate-limited fraction over the seeds.
    """
    speeds = [None] if speeds is None else [float(v) for v in speeds]
    frozen = tuple(sorted(settings.items()))
    cases = [{"model": model_name, "design_speed": design_speed, "speed": v, "seed": int(s), "scenario": scenario,
              "t_end": t_end, "settings": frozen} for v in speeds for s in seeds]
    runs = run_cases(run_case, cases, workers=workers, scheduler=scheduler)
    summary = {}
    for v in speeds:
        rows = [r for r in runs if r["speed"] == v]
        over = [m.get("overshoot_pct", np.nan) for r in rows for m in r["metrics"]]
        err = [abs(m["steady_state_error_deg"]) for r in rows for m in r["metrics"]]
        summary["design" if v is None else f"{v:g}"] = {
            "runs": len(rows), "overshoot_pct_max": float(np.nanmax(over)), "overshoot_pct_mean": float(np.nanmean(over)),
            "steady_error_deg_max": float(np.max(err)),
            "rate_limited_fraction_max": float(max(r["performance"]["rate_limited_fraction"] for r in rows))}
    return {"runs": runs, "summary": summary}
