"""Figures of a design and of a closed-loop run (PNG, units on the axes)."""
from __future__ import annotations

import control
import numpy as np

from .analysis import margins

__all__ = ["plot_design", "plot_closed_loop", "bode_phase_deg"]


def _plt():
    import matplotlib.pyplot as plt

    return plt


def _omega(L) -> np.ndarray:
    mg = margins(L)
    w_c = mg["gain_crossover_rad_s"] if np.isfinite(mg["gain_crossover_rad_s"]) else 1.0
    return np.logspace(np.log10(w_c) - 3, np.log10(w_c) + 2.5, 800)


def bode_phase_deg(L, omega) -> np.ndarray:
    """The loop phase [deg] on ``omega`` as ``control.bode_plot`` draws it (continuous, starting
    within -360..0 deg at the lowest frequency).

    Parameters
    ----------
    L : control.StateSpace or control.TransferFunction
    omega : array
        Frequencies [rad/s].
    """
    plt = _plt()
    fig, axes = plt.subplots(2, 1)
    cplt = control.bode_plot(L, omega, ax=axes.reshape(2, 1))
    phase = np.asarray(cplt.lines[1, 0][0].get_ydata(), dtype=float)
    plt.close(fig)
    return phase


def plot_design(L, path, title: str = "", closed=None):
    """Bode plot of the loop ``L`` (``control.bode_plot`` with the margins marked) and the response
    of the closed loop to a unit course command (``closed``: a design's ``closed_loop``; default
    ``L / (1 + L)``), as a PNG. Returns ``path``.

    Parameters
    ----------
    L : control.StateSpace or control.TransferFunction
        The open loop.
    path : path
        PNG file.
    title : str
    closed : control.StateSpace, optional
        The closed loop.
    """
    plt = _plt()
    fig = plt.figure(figsize=(7, 9))
    gs = fig.add_gridspec(3, 1)
    bode_axes = np.array([[fig.add_subplot(gs[0])], [fig.add_subplot(gs[1])]])
    control.bode_plot(L, _omega(L), ax=bode_axes, display_margins=True, dB=True)
    # python-control writes the margins into the axes title: the figure keeps the caller's title
    fig.suptitle(title or "loop")
    ax = fig.add_subplot(gs[2])
    cl = control.ss(closed if closed is not None else control.feedback(L, 1))
    resp = control.step_response(cl[0, 0])          # first output (the course) from the first input
    ax.plot(resp.time, np.ravel(resp.outputs))
    ax.set_xlabel("time [s]")
    ax.set_ylabel("course / command [-]")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_closed_loop(result, path, title: str = "", steer_label: str = "rudder [deg]",
                     steer_scale: float = float(np.degrees(1.0))):
    """Course (true, fed to the autopilot, desired, command), steering and track of a closed-loop
    run (PNG). Returns ``path``.

    Parameters
    ----------
    result : ClosedLoopResult
    path : path
        PNG file.
    title : str
    steer_label : str
        Axis label of the steering.
    steer_scale : float
        Factor on the steering (degrees per radian by default).
    """
    plt = _plt()
    d = result.data
    t = d.t
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    ax = axes[0, 0]
    key = "chi" if result.mode == "course" else "psi"
    ax.plot(t, np.degrees(np.unwrap(d[key])), label=f"true {key}")
    ax.plot(t, np.degrees(np.unwrap(d["chi_hat"])), lw=0.7, label="fed to autopilot")
    ax.plot(t, np.degrees(np.unwrap(d["chi_d"])), "--", label="reference model")
    ax.plot(t, np.degrees(np.unwrap(d["ref"])), ":", label="command")
    ax.set_ylabel(f"{key} [deg]")
    ax.legend(fontsize=8)
    ax = axes[1, 0]
    ax.plot(t, d["steer_cmd"] * steer_scale, lw=0.6, label="command")
    ax.plot(t, d["steer"] * steer_scale, label="steering gear")
    ax.set_ylabel(steer_label)
    ax.set_xlabel("time [s]")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    ax.plot(t, np.degrees(d["r"]), label="yaw rate")
    ax.plot(t, np.degrees(d["omega_hat"]), lw=0.7, label="fed to autopilot")
    ax.plot(t, np.degrees(d["r_d"]), "--", label="desired rate")
    ax.set_ylabel("rate [deg/s]")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    ax.plot(d["east"], d["north"])
    ok = np.isfinite(d["gnss_north"])
    if ok.any() and result.mode == "course":
        ax.plot(d["gnss_east"][ok], d["gnss_north"][ok], ".", ms=1.5, alpha=0.5, label="GNSS")
        ax.legend(fontsize=8)
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal", adjustable="datalim")
    fig.suptitle(title)
    for a in axes.ravel():
        a.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
