"""Figures of a design and of a closed-loop run (units on the axes).

Both follow :mod:`casship.plotting`: a new figure is returned when no path is given (nothing is
closed, no backend chosen), the caller's axes when ``ax`` is given, and the path when the figure
is also written there.
"""
from __future__ import annotations

import control
import numpy as np

from .analysis import margins

__all__ = ["plot_design", "plot_closed_loop", "bode_phase_deg", "controller_name"]


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
    from matplotlib.figure import Figure

    axes = Figure().subplots(2, 1)
    cplt = control.bode_plot(L, omega, ax=axes.reshape(2, 1))
    return np.asarray(cplt.lines[1, 0][0].get_ydata(), dtype=float)


def controller_name(law) -> str:
    """What a person calls the control law that ran in a loop.

    Parameters
    ----------
    law : Autopilot, ScheduledAutopilot, MPCLaw, LinearController or MPCAutopilot

    Returns
    -------
    str
        the design method of a point design (``"pid-pole-placement-fossen"``, ``"lqr..."``), ``"...
        gain schedule (3 speeds)"``, ``"mpc"``,
        ``"python-control controller"``.
    """
    kind = type(law).__name__
    if kind in ("MPCLaw", "MPCAutopilot"):
        return "mpc"
    if kind == "LinearController":
        return "python-control controller"
    if kind == "ScheduledAutopilot":
        return f"{controller_name(law.laws[0])} gain schedule ({len(law.speeds)} speeds)"
    gains = getattr(law, "gains", None)
    return getattr(gains, "method", "") or kind


def plot_design(L, path=None, title: str = "", closed=None, *, ax=None, schedule=()):
    """Bode plot of the loop ``L`` (``control.bode_plot`` with the margins marked) and the response
    of the closed loop to a unit course command (``closed``: a design's ``closed_loop``; default
    ``L / (1 + L)``).

    Parameters
    ----------
    L : control.StateSpace or control.TransferFunction
        The open loop.
    path : path, optional
        Also write the figure there (PNG unless the suffix says otherwise).
    title : str
    closed : control.StateSpace, optional
        The closed loop.
    ax : three matplotlib Axes, optional
        Magnitude, phase and step response axes to draw into instead of a new figure.
    schedule : sequence of Design, optional
        A gain schedule's point designs: their loops and steps are drawn too, labelled with speed
        and gains.

    Returns
    -------
    matplotlib.figure.Figure, the axes given, or Path
        See :mod:`casship.plotting`.
    """
    from ..plotting import finish, panels

    given = ax
    fig, axes = panels(ax, 3, 1, figsize=(7, 9), what="the design plot (magnitude, phase, step)")
    axes = axes.ravel()
    bode_axes = np.array([[axes[0]], [axes[1]]])
    w = _omega(L)
    control.bode_plot(L, w, ax=bode_axes, display_margins=True, dB=True,
                      **({"label": "design (scheduled at its speed)"} if schedule else {}))
    for d in schedule:
        g = d.gains
        control.bode_plot(d.loop, w, ax=bode_axes, dB=True,
                          label=f"{d.settings.speed:.3g} m/s: Kp {g.Kp:.3g}, Kd {g.Kd:.3g} s, Ki {g.Ki:.3g} 1/s")
    if schedule:
        axes[0].legend(fontsize=7)
    # python-control writes the margins into the axes title: the figure keeps the caller's title
    if given is None:
        fig.suptitle(title or "loop")
    ax = axes[2]
    cl = control.ss(closed if closed is not None else control.feedback(L, 1))
    resp = control.step_response(cl[0, 0])          # first output (the course) from the first input
    ax.plot(resp.time, np.ravel(resp.outputs), label="design" if schedule else None)
    for d in schedule:
        r = control.step_response(control.ss(d.closed_loop)[0, 0])
        ax.plot(r.time, np.ravel(r.outputs), lw=0.8, label=f"{d.settings.speed:.3g} m/s")
    if schedule:
        ax.legend(fontsize=7)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("course / command [-]")
    ax.grid(True, alpha=0.3)
    return finish(fig, given, path, dpi=100)


def plot_closed_loop(result, path=None, title: str = "", steer_label: str | None = None,
                     steer_scale: float | None = None, *, ax=None, guidance=None):
    """Course (true, fed to the autopilot, desired, command), steering, rate and track of a
    closed-loop run; with guidance, the waypoints and the intended track on the track panel.

    Parameters
    ----------
    result : ClosedLoopResult
    path : path, optional
        Also write the figure there (PNG unless the suffix says otherwise).
    title : str
        Figure title (default: mode and controller of the run).
    steer_label : str, optional
        Axis label of the steering (default: rudder in degrees, or yaw moment in N m for a craft
        steered by one).
    steer_scale : float, optional
        Factor on the steering (default: degrees per radian for a rudder, 1 for a yaw moment).
    ax : four matplotlib Axes, optional
        Course, rate, steering and track axes to draw into instead of a new figure.
    guidance : LOSGuidance, optional
        The path guidance of the run (default: the result's).

    Returns
    -------
    matplotlib.figure.Figure, the axes given, or Path
        See :mod:`casship.plotting`.
    """
    from ..plotting import finish, panels

    moment = getattr(result, "steer", "delta") == "tau_N"
    if steer_label is None:
        steer_label = "yaw moment [N m]" if moment else "rudder [deg]"
    if steer_scale is None:
        steer_scale = 1.0 if moment else float(np.degrees(1.0))
    guidance = guidance if guidance is not None else getattr(result, "guidance", None)
    given = ax
    d = result.data
    t = d.t
    fig, axes = panels(ax, 2, 2, figsize=(11, 7), what="the closed-loop plot")
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
    ax.plot(d["east"], d["north"], label="ship")
    if guidance is not None:
        wp = guidance.waypoints
        track = wp.track(getattr(guidance, "turn_radius", None))
        ax.plot(track[:, 1], track[:, 0], "--", color="0.4", lw=1.0, label="intended track")
        ax.plot(wp.east, wp.north, "s", color="C3", ms=5, label="waypoints")
        for k, (n, e) in enumerate(zip(wp.north, wp.east)):
            ax.annotate(f"WP{k}", (e, n), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ok = np.isfinite(d["gnss_north"])
    if ok.any() and result.mode == "course":
        ax.plot(d["gnss_east"][ok], d["gnss_north"][ok], ".", ms=1.5, alpha=0.5, label="GNSS")
    if ax.get_legend_handles_labels()[0] and (guidance is not None or result.mode == "course"):
        ax.legend(fontsize=8)
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_aspect("equal", adjustable="datalim")
    if given is None:
        name = getattr(result, "controller", "")
        fig.suptitle(title or f"{result.mode} control" + (f", {name}" if name else ""))
    for a in axes.ravel():
        a.grid(True, alpha=0.3)
    return finish(fig, given, path, dpi=100)
