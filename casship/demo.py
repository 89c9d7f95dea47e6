"""The built-in demonstration behind ``casship demo``."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from . import models
from .data import Gaussian
from .discretize import discretize
from .estimators import EKF
from .simulate import measure, simulate
from .progress import progress


def run_demo(out: Path, quick: bool = False) -> dict:
    """Simulate a zig-zag of the Shi et al. Taylor model, measure it with noise, filter it with the EKF.

    Writes ``report.md``, ``summary.json`` and PNG figures into ``out``; returns the summary.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    steps = progress(["simulate", "measure", "filter", "report"], "demo")
    model = models.shi_taylor()
    dt = 0.5
    t = np.arange(0.0, 300.0 if quick else 1200.0, dt)
    delta = np.radians(20.0) * np.sign(np.sin(2 * np.pi * t / 120.0) + 1e-9)
    next(steps)
    truth = simulate(model, model.states(u=8.0), t, {"delta": delta, "n": 1.5})
    next(steps)
    std = {"u": 0.05, "v": 0.05, "r": np.radians(0.1)}
    data = measure(truth, model, std, seed=1)
    next(steps)
    ekf = EKF(discretize(model, dt, "rk4"), Q=np.diag([1e-6, 1e-6, 1e-9]), R={k: s**2 for k, s in std.items()})
    prior = Gaussian(model.states(u=7.0), np.diag([1.0, 0.1, 1e-4, 100.0, 100.0, 0.1]))
    t0 = time.perf_counter()
    res = ekf.filter(data, prior)
    elapsed = time.perf_counter() - t0
    next(steps)
    rmse = {n: float(np.sqrt(np.mean((res[n] - truth[n]) ** 2))) for n in ("u", "v", "r")}
    meas_rmse = {n: float(np.sqrt(np.mean((data[n] - truth[n]) ** 2))) for n in ("u", "v", "r")}
    _plot(out / "filter.png", t, truth, data, res)
    summary = {
        "model": model.name, "samples": int(t.size), "filter_seconds": elapsed,
        "rmse_ekf": rmse, "rmse_measurement": meas_rmse, "loglik": res.loglik,
        "health_ok": bool(res.health().ok),
        "headline": {"EKF RMSE r [deg/s]": round(np.degrees(rmse["r"]), 4),
                     "measurement RMSE r [deg/s]": round(np.degrees(meas_rmse["r"]), 4),
                     "filter time per sample [us]": round(1e6 * elapsed / t.size, 2)},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    (out / "report.md").write_text(
        "# casship demo\n\n"
        f"Shi et al. (2009) Taylor model, 20 deg zig-zag, {t.size} samples at {dt} s; noisy u, v, r; EKF.\n\n"
        "| state | EKF RMSE | measurement RMSE |\n|---|---|---|\n"
        + "".join(f"| {n} | {rmse[n]:.4g} | {meas_rmse[n]:.4g} |\n" for n in rmse)
        + "\n![filter](filter.png)\n")
    next(steps, None)
    return summary


def _plot(path: Path, t, truth, data, res) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for ax, name in zip(axes, ("u", "v", "r")):
        ax.plot(t, data[name], ".", ms=2, color="0.7", label="measured")
        ax.plot(t, truth[name], "k", lw=1, label="true")
        ax.plot(t, res[name], "C0", lw=1, label="EKF")
        ax.set_ylabel(name)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
