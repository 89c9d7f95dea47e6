"""Koike et al.'s (2023) figures (the paper's Figs. 2-10, regenerated as PNG with units on every axis)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..kit import figure
from .experiments import truth
from .scenario import DT, STATES, UNITS, WIND_MEANS, gust_record


def bars(path: Path, exp: dict, filters, conditions, labels, title: str) -> None:
    """RMSE per state (mean and spread over the seeds), one panel per filter, one bar per condition."""
    with figure(path, len(filters), 1, figsize=(9, 2.6 * len(filters)), sharex=True, squeeze=False) as (fig, axes):
        width = 0.8 / len(conditions)
        for ax, name in zip(axes[:, 0], filters):
            for i, (cond, label) in enumerate(zip(conditions, labels)):
                cell = exp[str(cond)][name]
                ax.bar(np.arange(6) + (i - (len(conditions) - 1) / 2) * width, [cell[s]["mean"] for s in STATES],
                       width, yerr=[cell[s]["std"] for s in STATES], capsize=2, label=label)
            ax.set_yscale("log")
            ax.set_ylabel(f"RMSE\n{name}")
            ax.grid(axis="y", alpha=0.3)
        axes[0, 0].legend(fontsize=8, ncol=len(conditions))
        axes[-1, 0].set_xticks(np.arange(6), [f"{s} [{UNITS[s]}]" for s in STATES])
        fig.suptitle(title)


def tuned_q(path: Path, cell: dict) -> None:
    """Fig. 5: RMSE at the strongest wind, Q = 0 against the paper's tuned Q."""
    bars(path, {"Q=0": {n: cell[f"{n} Q=0"] for n in ("UKF", "EnKF")},
                "tuned": {n: cell[f"{n} tuned"] for n in ("UKF", "EnKF")}},
         ("UKF", "EnKF"), ("Q=0", "tuned"), ["Q = 0", "tuned Q"],
         f"RMSE at mean wind {WIND_MEANS[-1]} m/s: Q = 0 vs tuned Q")


def wind_records(path: Path, duration: float) -> None:
    """Fig. 2: the gust records (one record scaled to the paper's mean speeds)."""
    with figure(path, 2, 1, figsize=(8, 5), sharex=True) as (fig, axes):
        for w in WIND_MEANS[1:]:
            t, speed, direction = gust_record(duration, w)
            axes[0].plot(t, speed, lw=0.8, label=f"mean {w:g} m/s")
            axes[1].plot(t, np.degrees(direction), lw=0.8)
        axes[0].set_ylabel("U_T [m/s]")
        axes[1].set_ylabel("gamma_T [deg]")
        axes[1].set_xlabel("t [s]")
        axes[0].legend(fontsize=8)
        fig.suptitle("Gusty wind records (one record scaled by 0, 0.5, 1)")


def wind_effect(path: Path, duration: float) -> None:
    """Fig. 3: the zig-zag with and without wind, both wind forms."""
    with figure(path, figsize=(6, 6)) as (fig, ax):
        for w, style in zip(WIND_MEANS[::-1], ("C3-", "C1-", "k--")):
            tr = truth("zigzag", w, duration)
            ax.plot(tr["y"], tr["x"], style, lw=1, label=f"wind {w:g} m/s (Eq. 34)" if w else "without wind")
        tr = truth("zigzag", WIND_MEANS[-1], duration, "fujiwara2005")
        ax.plot(tr["y"], tr["x"], "C0:", lw=1, label=f"wind {WIND_MEANS[-1]:g} m/s (Fujiwara 2005)")
        ax.set_xlabel("y (East) [m]")
        ax.set_ylabel("x (North) [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8)
        ax.set_title("Zig-zag with and without wind (the filters' model has none)")


def maneuvers(path: Path, duration: float) -> None:
    """Figs. 7-8: rudder angles and trajectories of the zig-zag and the random manoeuvre."""
    with figure(path, 2, 2, figsize=(10, 7)) as (fig, axes):
        for col, kind in enumerate(("zigzag", "random")):
            tr = truth(kind, 0.0, duration)
            for name in ("delta_s", "delta_p"):
                axes[0, col].plot(tr.t, np.degrees(tr[name]), lw=0.8, label=name)
            axes[0, col].set_xlabel("t [s]")
            axes[0, col].set_ylabel("rudder [deg]")
            axes[0, col].set_title(kind)
            axes[0, col].legend(fontsize=8)
            axes[1, col].plot(tr["y"], tr["x"], "k", lw=1)
            axes[1, col].set_xlabel("y (East) [m]")
            axes[1, col].set_ylabel("x (North) [m]")
            axes[1, col].set_aspect("equal", adjustable="datalim")


def timing(path: Path, times: dict) -> None:
    """Fig. 10: computation time per 0.1 s step, batch and online."""
    names = list(times)
    with figure(path, figsize=(7, 4)) as (fig, ax):
        x = np.arange(len(names))
        ax.bar(x - 0.2, [times[n]["batch_s_per_step"] for n in names], 0.4, label="batch (compiled fold)")
        ax.bar(x + 0.2, [times[n]["online_s_per_step"] for n in names], 0.4, label="online (update calls)")
        ax.axhline(DT, color="k", ls="--", lw=0.8, label="real time (0.1 s)")
        ax.set_yscale("log")
        ax.set_xticks(x, names)
        ax.set_ylabel("seconds per 0.1 s step")
        ax.legend(fontsize=8)
