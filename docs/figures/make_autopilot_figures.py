"""Regenerate the figures of docs/autopilots.md and print the numbers quoted there.

Run from the repository root::

    python docs/figures/make_autopilot_figures.py

Writes ``docs/figures/autopilot_*.png`` (small, 80 dpi) and prints the headline numbers of the
API defaults (KVLCC2 and Otter) as JSON.
"""
from __future__ import annotations

import json
import warnings
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import casship as cs  # noqa: E402
from casship import autopilot as ap  # noqa: E402
from casship.models.wind import add_current  # noqa: E402

HERE = Path(__file__).resolve().parent
DPI = 64


def defaults_runs() -> dict:
    """The API defaults on KVLCC2 and the Otter: design, standard course changes, headline numbers."""
    out = {}
    for name in ("kvlcc2", "otter"):
        d = ap.design_autopilot(cs.models.get_model(name))
        res = d.simulate()
        out[name] = (d, res)
    return out


def figure_loop(design):
    w = np.logspace(-4, 1, 500)
    fig, axes = plt.subplots(2, 1, figsize=(6, 4.5), sharex=True)
    import control

    control.bode_plot(design.loop, w, ax=axes.reshape(2, 1), display_margins=True,
                      title="KVLCC2: loop on the linearised ship (control.bode_plot)")
    fig.tight_layout()
    fig.savefig(HERE / "autopilot_kvlcc2_loop.png", dpi=DPI)
    plt.close(fig)


def figure_course_changes(runs):
    fig, axes = plt.subplots(2, 2, figsize=(9, 5))
    for col, (name, (d, res)) in enumerate(runs.items()):
        D = res.data
        axes[0, col].plot(D.t, np.degrees(D["psi"]), label="heading")
        axes[0, col].plot(D.t, np.degrees(D["chi_d"]), "--", label="reference model")
        axes[0, col].plot(D.t, np.degrees(D["ref"]), ":", label="command")
        axes[0, col].set_ylabel("heading [deg]")
        axes[0, col].set_title(f"{name} (API defaults)")
        scale, unit = (1.0, "yaw moment [N m]") if d.plant.steer == "tau_N" else (np.degrees(1.0), "rudder [deg]")
        axes[1, col].plot(D.t, scale * D["steer"])
        axes[1, col].set_ylabel(unit)
        axes[1, col].set_xlabel("time [s]")
        axes[0, col].legend(fontsize=7)
    for a in axes.ravel():
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "autopilot_course_changes.png", dpi=DPI)
    plt.close(fig)


def figure_los():
    ship = add_current(cs.models.get_model("otter"))
    d = ap.design_autopilot(ship)
    wp = ap.Waypoints([0.0, 150.0, 150.0], [0.0, 0.0, 150.0])
    env = {"current_speed": 0.2, "current_dir": np.radians(90.0)}
    fig, ax = plt.subplots(figsize=(5.5, 5))
    ax.plot(wp.east, wp.north, "k:", lw=0.8, label="waypoints")
    track = wp.track(ap.LOSGuidance.for_design(wp, d).turn_radius)
    ax.plot(track[:, 1], track[:, 0], "k--", lw=1, label="track (turn at the wheel-over point)")
    for integral in (False, True):
        guidance = ap.LOSGuidance.for_design(wp, d, integral=integral)
        loop = d.closed_loop_system(environment=env, guidance=guidance)
        x0 = loop.plant.x0.copy()
        x0[loop.plant.model.index("y")] = -guidance.lookahead
        D = loop.run(0.0, 170.0, x0=x0, seed=1)
        ax.plot(D["east"], D["north"], lw=1, label="ILOS" if integral else "LOS")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_title("Otter, heading autopilot, 0.2 m/s current to the East")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "autopilot_los.png", dpi=DPI)
    plt.close(fig)


def figure_waves(design):
    w0 = 0.6
    wave = ap.WaveYaw(w0, np.radians(1.0) / np.sqrt(0.1 * w0), 0.1)
    fig, ax = plt.subplots(figsize=(8, 3.2))
    for filt in (False, True):
        res = design.simulate(wave=wave, wave_filter=filt, warn=False)
        D = res.data
        sel = D.t >= 0.75 * D.t[-1]
        ax.plot(D.t[sel], np.degrees(D["steer"][sel]), lw=0.8, label="wave filter" if filt else "no wave filter")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("rudder [deg]")
    ax.set_title("KVLCC2 heading keeping in waves (wave yaw 1 deg at 0.6 rad/s)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(HERE / "autopilot_waves.png", dpi=DPI)
    plt.close(fig)


def main():
    warnings.simplefilter("ignore")
    runs = defaults_runs()
    figure_loop(runs["kvlcc2"][0])
    figure_course_changes(runs)
    figure_los()
    figure_waves(runs["kvlcc2"][0])
    numbers = {name: {"wn_rad_s": d.settings.wn, "margins": {k: d.margins[k] for k in (
        "gain_margin_db", "gain_margin_side", "upper_gain_margin_db", "lower_gain_margin_db", "phase_margin_deg")},
        "overshoot_pct": [m["overshoot_pct"] for m in res.metrics],
        "steady_error_deg": [m["steady_state_error_deg"] for m in res.metrics],
        "rate_limited_fraction": res.performance["rate_limited_fraction"]}
        for name, (d, res) in runs.items()}
    print(json.dumps(numbers, indent=1, default=float))


if __name__ == "__main__":
    main()
