"""Figures of the Shi et al. (2009) study, numbered like the paper's (Figs. 2-9)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..kit import figure
from .pipeline import T

SHOWN = ("a1", "b2", "c1")              # the paper's Figs. 4-6
CLAIM_STEP = 200                        # "converged quite well after 200 recursive steps"


def rate_of_turn(path: Path, raw, smoothed) -> None:
    """Figs. 2-3: rate of turn from the raw heading, and smoothed."""
    with figure(path, 1, 2, figsize=(11, 3.8), sharey=True) as (fig, ax):
        ax[0].plot(raw.t[1:], np.degrees(np.diff(np.unwrap(raw["psi"])) / T), lw=0.7)
        ax[0].set_title("rate of turn from raw heading (Fig. 2)")
        ax[1].plot(smoothed.t, np.degrees(smoothed["r"]), lw=1, label="smoothed")
        ax[1].plot(smoothed.t, np.degrees(smoothed["true_r"]), "k--", lw=0.8, label="truth")
        ax[1].set_title("smoothed rate of turn (Fig. 3)")
        ax[1].legend(fontsize=8)
        for a in ax:
            a.set_xlabel("t [s]")
        ax[0].set_ylabel("r [deg/s]")


def panel_limits(traj, reference: float) -> tuple[float, float]:
    """y-limits holding the second half of ``traj``, its end value and ``reference`` (with margins)."""
    traj = np.asarray(traj, dtype=float)
    keep = np.concatenate([traj[traj.size // 2:], [reference, traj[-1]]])
    lo, hi = float(np.min(keep)), float(np.max(keep))
    pad = 0.5 * (hi - lo) or 0.5 * abs(hi) or 1.0
    return lo - pad, hi + pad


def convergence(path: Path, runs, reference: dict, reference_label: str, title: str) -> None:
    """Figs. 4-6: parameter estimates of the augmented EKF against the recursive step.

    The y-limits always contain the second half of the trajectory, its end value (marked and
    written) and the reference, so that an estimate that has not converged is seen as such.
    """
    with figure(path, 1, 3, figsize=(13, 3.8)) as (fig, axes):
        for ax, name in zip(axes, SHOWN):
            traj = np.concatenate([run.trajectory(name) for run in runs])
            steps = np.arange(1, traj.size + 1)
            ax.plot(steps, traj, "C0", lw=1, label="augmented EKF")
            ax.axhline(reference[name], color="k", ls="--", lw=0.8, label=reference_label)
            ax.plot(steps[-1], traj[-1], "C3o", ms=5)
            ax.annotate(f"end {traj[-1]:.3g}", (steps[-1], traj[-1]), textcoords="offset points", xytext=(-60, 8),
                        fontsize=8, color="C3")
            ax.axvline(CLAIM_STEP, color="0.5", ls=":", lw=0.8, label=f"step {CLAIM_STEP} (paper's claim)")
            edge = len(runs[0].trajectory(name))
            ax.axvline(edge + 0.5, color="0.7", lw=0.6)
            ax.set_ylim(*panel_limits(traj, reference[name]))
            ax.set_title(f"{name} (Fig. {4 + SHOWN.index(name)})")
            ax.set_xlabel("recursive step (zig-zag | turning circle)")
            ax.set_ylabel(f"{name} [-]")
            ax.grid(alpha=0.3)
        axes[0].legend(fontsize=7)
        fig.suptitle(title)


def validation(out: Path, checks: dict, target_label: str, suffix: str = "") -> None:
    """Figs. 7-9: 20/20 zig-zag heading and speed, 35 deg turning circle, target vs identified."""
    styles = {"truth": ("k-", target_label), "aekf": ("C1--", "augmented EKF"), "mle": ("C0-", "ML (EKF)")}
    with figure(out / f"fig_zigzag{suffix}.png", 1, 2, figsize=(11, 3.8)) as (fig, ax):
        for key, (st, label) in styles.items():
            tr = checks[key]["traj"].get("zigzag")
            if tr is not None:
                ax[0].plot(tr.t, np.degrees(tr["psi"]), st, lw=1, label=label)
                ax[1].plot(tr.t, np.hypot(tr["u"], tr["v"]), st, lw=1, label=label)
        ax[0].set_ylabel("heading [deg] (Fig. 7)")
        ax[1].set_ylabel("speed [m/s] (Fig. 8)")
        for a in ax:
            a.set_xlabel("t [s]")
            a.legend(fontsize=8)
    with figure(out / f"fig_turning{suffix}.png", figsize=(5.5, 5.5)) as (fig, ax):
        for key, (st, label) in styles.items():
            tr = checks[key]["traj"].get("turning")
            if tr is not None:
                ax.plot(tr["y"], tr["x"], st, lw=1, label=label)
        ax.set_xlabel("East y [m]")
        ax.set_ylabel("North x [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title("35 deg turning circle (Fig. 9)")
        ax.legend(fontsize=8)
