"""The built-in end-to-end demonstration behind ``casship demo``.

KVLCC2 (full scale, MMG standard method) sea trials are simulated and measured with noisy sensors
(GNSS position, gyro-compass heading, rate-of-turn gyro); EKF, UKF and an RTS smoother estimate
the unmeasured surge and sway speeds; a maximum-likelihood fit through the EKF re-identifies hull
derivatives with standard errors from a deliberately wrong start; the fitted model is validated on
manoeuvres it was not fitted to; finally a course autopilot is designed on the fitted model and
run in closed loop on the true ship. Everything is written into one folder: ``report.md``, PNG
figures and ``summary.json``.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import models
from .gaussian import Gaussian
from .discretize import discretize
from .estimators import EKF, UKF, prior_from_data
from .io.jsonfile import write_json
from .progress import progress
from .simulation import measure, simulate

__all__ = ["run_demo", "DemoConfig"]

# Sensor noise (standard deviations): GNSS position, gyro-compass, rate-of-turn gyro.
SENSORS = {"x": 2.0, "y": 2.0, "psi": np.radians(0.2), "r": np.radians(0.02)}


@dataclass(frozen=True)
class DemoConfig:
    """Sizes of the demonstration (``quick`` shrinks records and the fit).

    Parameters
    ----------
    dt : float
        Sample time of the records and the filters [s].
    trial_s : float
        Length of each identification record [s].
    free : tuple of str
        Hull and resistance derivatives the fit estimates.
    random_record : bool
        Add a random-rudder record (+-20 deg, moved at the ship's rudder rate) to the zig-zag.
    guess_factor : float
        The fit starts at ``guess_factor`` times the true values.
    validation_s : float
        Length of the validation manoeuvres [s].
    seed : int
        Seed of the random rudder and the sensor noise.
    compile_fit : bool
        Compile the likelihood and its sensitivities to C (kept in the on-disk cache). The quick
        two-parameter fit runs faster interpreted (measured: about 4 s for the whole quick demo
        against 5 s with the compiled code cached and 18 s when it is compiled first); the full
        six-parameter fit runs faster compiled once the code is cached (6 s against 13 s).
    """

    dt: float = 1.0
    trial_s: float = 1200.0
    free: tuple = ("Y_v_dash", "Y_r_dash", "N_v_dash", "N_r_dash", "R_0_dash", "X_vv_dash")
    random_record: bool = True         # a second identification record: random rudder (+-20 deg)
    guess_factor: float = 1.25
    validation_s: float = 900.0
    seed: int = 1
    compile_fit: bool = True

    @classmethod
    def make(cls, quick: bool) -> "DemoConfig":
        """The full or the quick configuration.

        Parameters
        ----------
        quick : bool
            Shorter records and a two-parameter fit.

        Returns
        -------
        DemoConfig
        """
        if quick:
            return cls(trial_s=700.0, free=("N_r_dash", "N_v_dash"), random_record=False, validation_s=500.0,
                       compile_fit=False)
        return cls()


def _rmse(a, b) -> float:
    return float(np.sqrt(np.nanmean((np.asarray(a) - np.asarray(b)) ** 2)))


# -- stages ------------------------------------------------------------------------------------------------
def _trials(ship, cfg: DemoConfig) -> list:
    """Identification records ``[(name, truth, data), ...]``: a 20/20 zig-zag (and a random rudder run)."""
    from .maneuvers import ZigZag, propeller_rate_for_speed, random_rudder_inputs, straight_run_state

    U0 = ship.vessel.U0
    n = propeller_rate_for_speed(ship, U0)
    t = np.arange(0.0, cfg.trial_s, cfg.dt)
    x0 = straight_run_state(ship, U0)
    runs = [("20/20 zig-zag", simulate(ship, x0, t, ZigZag(ship, np.radians(20.0), np.radians(20.0), n,
                                                               t_exec=10.0)))]
    if cfg.random_record:
        inputs = random_rudder_inputs(ship, t, n, hold=100.0, seed=cfg.seed, ranges_deg={"delta": (-20.0, 20.0)},
                                      rate="model")
        runs.append(("random rudder", simulate(ship, x0, t, inputs)))
    return [(name, truth, measure(truth, ship, SENSORS, seed=cfg.seed + i)) for i, (name, truth) in enumerate(runs)]


def _rudder_motion(truth) -> dict:
    """Largest rudder angle [deg] and rudder rate [deg/s] (largest and RMS) of a record."""
    delta = np.degrees(np.asarray(truth["delta"], dtype=float))
    rate = np.diff(delta) / np.diff(truth.t)
    return {"max_rudder_deg": float(np.max(np.abs(delta))), "max_rudder_rate_deg_s": float(np.max(np.abs(rate))),
            "rms_rudder_rate_deg_s": float(np.sqrt(np.mean(rate**2)))}


def _prior(ship, data) -> Gaussian:
    """The filter starts 5 % off in speed and knows little about it; the rest from the first samples
    (:func:`casship.prior_from_data`).

    v = 1 mm/s keeps the start off v = r = 0, where the MMG wake and flow-straightening terms switch
    with the sign of the drift (not twice differentiable there, which the fit's exact Hessian would see).
    """
    return prior_from_data(ship, data, measured=list(SENSORS), R={k: s**2 for k, s in SENSORS.items()},
                           x0={"u": 0.95 * ship.vessel.U0, "v": 1e-3})


def _filters(ship, data, truth, cfg: DemoConfig):
    dm = discretize(ship, cfg.dt, "rk4")
    Q = np.diag([1e-8, 1e-8, 1e-12])          # small process noise on the accelerations
    R = {k: s**2 for k, s in SENSORS.items()}
    measured = list(SENSORS)
    prior = _prior(ship, data)
    ekf = EKF(dm, Q, R, measured=measured)
    out = {}
    for name, est in (("EKF", ekf), ("UKF", UKF(dm, Q, R, measured=measured))):
        t0 = time.perf_counter()
        out[name] = est.filter(data, prior)
        out[name + "_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    out["EKF+RTS"] = ekf.smooth(data, prior)          # filter and backward pass
    out["EKF+RTS_s"] = time.perf_counter() - t0
    rmse = {name: {s: _rmse(out[name][s], truth[s]) for s in ("u", "v", "r")} for name in ("EKF", "UKF", "EKF+RTS")}
    health = {name: bool(out[name].health().ok) for name in ("EKF", "UKF")}
    return ekf, prior, out, rmse, health


def _fit(ship, ekf, records, cfg: DemoConfig):
    from .identify import MLEProblem

    truth = ship.param_dict()
    guess = {k: truth[k] * cfg.guess_factor for k in cfg.free}
    data = [d for _, _, d in records]
    t0 = time.perf_counter()
    fit = MLEProblem(ekf, data, free=list(cfg.free), x0=[_prior(ship, d) for d in data],
                     jit=None if cfg.compile_fit else False).solve(guess=guess)
    seconds = time.perf_counter() - t0
    rows = {k: {"true": truth[k], "guess": guess[k], "estimate": fit.estimates[k], "std_error": fit.std_errors[k],
                "z": (fit.estimates[k] - truth[k]) / fit.std_errors[k]} for k in cfg.free}
    return fit, guess, rows, seconds


METRICS = {"zigzag 10/10": ("overshoot_1_deg", "overshoot_2_deg", "period_s"),
           "turning 35 deg": ("advance_m", "transfer_m", "tactical_diameter_m", "time_to_90_s")}


def _validate(ship, fit, guess, cfg: DemoConfig):
    """Manoeuvres the fit never saw (10/10 zig-zag, 35 deg turning circle): true vs fitted vs guess."""
    from .maneuvers import run_maneuver

    variants = {"true": ship.params(), "fitted": ship.params(fit.params), "initial guess": ship.params(guess)}
    runs, table = {}, {}
    for man, (kind, rudder) in (("zigzag 10/10", ("zigzag", 10.0)), ("turning 35 deg", ("turning", 35.0))):
        res = {name: run_maneuver(ship, kind, rudder_deg=rudder, p=p, dt=cfg.dt, duration=cfg.validation_s)
               for name, p in variants.items()}
        runs[man] = {name: r.trajectory for name, r in res.items()}
        ref = res["true"].trajectory
        table[man] = {}
        for name, r in res.items():
            tr = r.trajectory
            row = {k: float(r.metrics[k]) for k in METRICS[man] if k in r.metrics}
            row["position_rms_m"] = float(np.sqrt(np.mean((tr["x"] - ref["x"]) ** 2 + (tr["y"] - ref["y"]) ** 2)))
            row["heading_rms_deg"] = float(np.degrees(_rmse(tr["psi"], ref["psi"])))
            table[man][name] = row
    return runs, table


def _autopilot(ship, fit, cfg: DemoConfig, out: Path):
    """Course-keeping autopilot designed on the *fitted* model, run in closed loop on the *true* ship."""
    from . import autopilot as ap

    design = ap.design_autopilot(ship, p=fit.params, mode="heading", compass_rate=1.0, compass_std=SENSORS["psi"],
                                 gyro_std=SENSORS["r"])
    truth = design.plant.replace(p=None)                                  # truth: nominal parameters
    run = design.simulate("course-20", plant=truth, seed=cfg.seed)        # two segments of the design's length
    ap.plot_design(design.loop, out / "autopilot_design.png", "Heading autopilot on the fitted KVLCC2 model",
                   design.closed_loop)
    ap.plot_closed_loop(run, out / "autopilot_closed_loop.png", "Closed loop on the true ship (compass + rate gyro)")
    return design, run


# -- figures ---------------------------------------------------------------------------------------------
def _subplots(nrows: int, ncols: int, figsize, **kwargs):
    """A figure and its axes, made without pyplot (no backend chosen, nothing kept open)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **kwargs)


def _plot_filters(path: Path, truth, data, est) -> None:
    fig, axes = _subplots(5, 1, (8, 10.5), sharex=True)
    t = truth.t
    axes[0].plot(t, np.degrees(truth["delta"]), "k", lw=1)
    axes[0].set_ylabel("rudder angle [deg]")
    axes[1].plot(0.5 * (t[1:] + t[:-1]), np.diff(np.degrees(truth["delta"])) / np.diff(t), "k", lw=1)
    axes[1].set_ylabel("rudder rate [deg/s]")
    for ax, name, scale, unit in ((axes[2], "u", 1.0, "m/s"), (axes[3], "v", 1.0, "m/s"),
                                  (axes[4], "r", np.degrees(1.0), "deg/s")):
        if name in data:
            ax.plot(t, data[name] * scale, ".", ms=2, color="0.75", label="measured")
        ax.plot(t, truth[name] * scale, "k", lw=1.2, label="true")
        for key, style in (("EKF", "C0-"), ("UKF", "C1--"), ("EKF+RTS", "C2-")):
            ax.plot(t, est[key][name] * scale, style, lw=0.9, label=key)
        ax.set_ylabel(f"{name} [{unit}]")
    axes[2].legend(loc="upper right", ncol=5, fontsize=8)
    axes[-1].set_xlabel("t [s]")
    fig.suptitle("20/20 zig-zag: u and v are not measured")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _plot_validation(path: Path, runs, L: float) -> None:
    fig, axes = _subplots(1, len(runs), (11, 5))
    for ax, (man, variants) in zip(np.atleast_1d(axes), runs.items()):
        for (name, tr), style in zip(variants.items(), ("k-", "C0--", "C3:")):
            ax.plot(tr["y"] / L, tr["x"] / L, style, label=name)
        ax.set_title(man)
        ax.set_xlabel("East y / L [-]")
        ax.set_ylabel("North x / L [-]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


# -- the run -----------------------------------------------------------------------------------------------
def run_demo(out: Path, quick: bool = False, *, overwrite: bool = False) -> dict:
    """Run the demonstration and write ``report.md``, ``summary.json`` and PNG figures into ``out``.

    Parameters
    ----------
    out : Path
        Report folder. It is written only when the run succeeds (see :func:`casship.outdir.output_folder`).
    quick : bool
        Shorter records and a two-parameter fit.
    overwrite : bool
        Replace an existing non-empty report folder (its old files are removed).

    Returns
    -------
    dict
        The summary also written to ``summary.json``; ``summary["headline"]`` holds the key numbers.

    Raises
    ------
    FileExistsError
        ``out`` is a file, or a non-empty folder and ``overwrite`` is false.
    """
    from .outdir import output_folder

    with output_folder(out, overwrite=overwrite) as folder:
        summary = _run(folder, quick)
    return summary


def _run(out: Path, quick: bool) -> dict:
    cfg = DemoConfig.make(quick)
    stages = ["simulate and measure sea trials", "EKF, UKF and RTS smoother", "maximum-likelihood fit",
              "validation manoeuvres", "autopilot design and closed loop", "report"]
    steps = progress(stages, "demo")
    t_start = time.perf_counter()
    ship = models.kvlcc2()
    L = ship.vessel.L_pp

    next(steps)
    records = _trials(ship, cfg)
    _, truth, data = records[0]

    next(steps)
    ekf, prior, est, rmse, health = _filters(ship, data, truth, cfg)
    _plot_filters(out / "filters.png", truth, data, est)

    next(steps)
    fit, guess, fit_rows, fit_s = _fit(ship, ekf, records, cfg)

    next(steps)
    runs, validation = _validate(ship, fit, guess, cfg)
    _plot_validation(out / "validation.png", runs, L)

    next(steps)
    design, loop = _autopilot(ship, fit, cfg, out)

    next(steps)
    total = time.perf_counter() - t_start
    summary = {
        "ship": ship.vessel.name, "quick": quick, "dt_s": cfg.dt, "trial_s": cfg.trial_s,
        "identification_records": [name for name, _, _ in records],
        "rudder": {name: _rudder_motion(truth) for name, truth, _ in records},
        "rudder_rate_limit_deg_s": float(np.degrees(ship.vessel.rudder_rate)),
        "sensors_std": {k: float(v) for k, v in SENSORS.items()},
        "rmse": rmse, "filter_health_ok": health,
        "filter_seconds": {k: est[k + "_s"] for k in ("EKF", "UKF", "EKF+RTS")},
        "fit": {"status": fit.status, "iterations": fit.iterations, "seconds": fit_s, "params": fit_rows,
                "warnings": list(fit.warnings)},
        "validation": validation,
        "autopilot": {"design": design.summary(), "closed_loop": loop.metrics, "performance": loop.performance},
        "figures": ["filters.png", "validation.png", "autopilot_design.png", "autopilot_closed_loop.png"],
        "seconds": total,
    }
    worst_z = max(abs(r["z"]) for r in fit_rows.values())
    summary["headline"] = {
        "EKF RMSE v [m/s] (unmeasured)": round(rmse["EKF"]["v"], 4),
        "EKF+RTS RMSE v [m/s]": round(rmse["EKF+RTS"]["v"], 4),
        "fit: largest |estimate - true| / std error": round(worst_z, 2),
        "10/10 zig-zag position RMS, fitted vs true [m]": round(validation["zigzag 10/10"]["fitted"]["position_rms_m"], 2),
        "autopilot 20 deg change: overshoot [%] ([deg])": f"{loop.metrics[0]['overshoot_pct']:.2f} % "
                                                          f"({loop.metrics[0]['overshoot_deg']:.2f} deg)",
        "run time [s]": round(total, 1),
    }
    write_json(out / "summary.json", summary)
    (out / "report.md").write_text(_report(summary, ship))
    next(steps, None)
    return summary


def _report(s: dict, ship) -> str:
    lines = [
        f"# casship demo ({'quick' if s['quick'] else 'full'} run): KVLCC2 from noisy trials to an identified model",
        "",
        f"Ship: {s['ship']} (MMG standard method, L_pp = {ship.vessel.L_pp:g} m), approach speed "
        f"{ship.vessel.U0:.2f} m/s. Identification records: {' and '.join(s['identification_records'])}, "
        f"{s['trial_s']:g} s each at dt = {s['dt_s']:g} s" + (" (quick mode)." if s["quick"] else "."), "",
        "**The trials are simulated, not measured:** the MMG model with its published parameters plays the ship, "
        "and simulated sensors with seeded noise measure it, so every estimate can be compared with the truth. "
        "For measured trials see the ship workflow in docs/getting-started.md and `casship study kvlcc2-marin`.", "",
        "| record | max rudder angle [deg] | max rudder rate [deg/s] | RMS rudder rate [deg/s] |",
        "|---|---|---|---|",
        *(f"| {name} | {r['max_rudder_deg']:.1f} | {r['max_rudder_rate_deg_s']:.2f} | {r['rms_rudder_rate_deg_s']:.2f} |"
          for name, r in s["rudder"].items()),
        "", f"The rudder moves at most at the ship's rudder rate ({s['rudder_rate_limit_deg_s']:.2f} deg/s).", "",
        "## 1. Sensors and state estimation", "",
        "Measured: GNSS position (std 2 m), heading (0.2 deg), rate of turn (0.02 deg/s). Surge u and sway v "
        "are not measured; the filters reconstruct them from the model.", "",
        "| estimator | RMSE u [m/s] | RMSE v [m/s] | RMSE r [deg/s] | time [s] | NIS health |",
        "|---|---|---|---|---|---|",
    ]
    for name in ("EKF", "UKF", "EKF+RTS"):
        r = s["rmse"][name]
        health = s["filter_health_ok"].get(name, None)
        lines.append(f"| {name} | {r['u']:.4f} | {r['v']:.4f} | {np.degrees(r['r']):.5f} | "
                     f"{s['filter_seconds'][name]:.3f} | {'ok' if health else ('-' if health is None else 'flagged')} |")
    lines += ["", "![filters](filters.png)", "",
              "## 2. Maximum-likelihood fit through the EKF", "",
              f"Free hull derivatives start {100 * (DemoConfig().guess_factor - 1):.0f} % off their true values; "
              "one likelihood over all identification records (the estimation part above shows the first). "
              f"solver status: {s['fit']['status']} after {s['fit']['iterations']} iterations ({s['fit']['seconds']:.1f} s).", "",
              "| parameter | true | initial guess | estimate | std error | (estimate - true) / std error |",
              "|---|---|---|---|---|---|"]
    for k, r in s["fit"]["params"].items():
        lines.append(f"| {k} | {r['true']:.5g} | {r['guess']:.5g} | {r['estimate']:.5g} | {r['std_error']:.2g} | "
                     f"{r['z']:+.2f} |")
    if s["fit"]["warnings"]:
        lines += ["", "Fit diagnostics: " + "; ".join(s["fit"]["warnings"])]
    lines += ["", "## 3. Validation on manoeuvres not used in the fit", "",
              "Metrics by `casship.maneuvers` on each simulation; RMS differences against the true ship's run.", ""]
    for man, rows in s["validation"].items():
        keys = [k for k in METRICS[man] if k in rows["true"]]
        lines += [f"**{man}**", "", "| model | " + " | ".join(keys) + " | position RMS vs true [m] | heading RMS [deg] |",
                  "|---" * (len(keys) + 3) + "|"]
        for name, r in rows.items():
            lines.append(f"| {name} | " + " | ".join(f"{r[k]:.4g}" if k in r else "-" for k in keys)
                         + f" | {r['position_rms_m']:.2f} | {r['heading_rms_deg']:.3f} |")
        lines.append("")
    lines += ["![validation](validation.png)", "",
              "## 4. Autopilot designed on the fitted model, run on the true ship", ""]
    d = s["autopilot"]["design"]
    lines += [f"Nomoto model from the exact linearisation of the fitted model: K = {d['nomoto']['K']:.4g} 1/s, "
              f"T = {d['nomoto']['T']:.4g} s. PID pole placement (wn = {d['settings']['wn']:.4g} rad/s, "
              f"zeta = {d['settings']['zeta']:g}): Kp = {d['gains']['Kp']:.4g}, Kd = {d['gains']['Kd']:.4g} s, "
              f"Ki = {d['gains']['Ki']:.4g} 1/s; gain margin {d['margins']['gain_margin_db']:.1f} dB, phase margin "
              f"{d['margins']['phase_margin_deg']:.1f} deg (python-control). Closed loop at "
              f"{1 / d['settings']['dt']:g} Hz on the true (nominal) ship with a 1 Hz compass and a rate gyro into "
              "the heading observer, rudder limited to 35 deg and 2.32 deg/s (rate limit active "
              f"{100 * s['autopilot']['performance']['rate_limited_fraction']:.1f} % of the time):", "",
              "| step | change [deg] | rise time [s] | overshoot [%] ([deg]) | settling time [s] | steady error [deg] | "
              "max rudder angle [deg] | max rudder rate [deg/s] | RMS rudder rate [deg/s] |",
              "|---|---|---|---|---|---|---|---|---|"]
    for i, m in enumerate(s["autopilot"]["closed_loop"]):
        lines.append(f"| {i + 1} | {m['change_deg']:.1f} | {m['rise_time_s']:.0f} | {m['overshoot_pct']:.2f} "
                     f"({m['overshoot_deg']:.2f}) | "
                     f"{m['settling_time_s']:.0f} | {m['steady_state_error_deg']:.2f} | "
                     f"{np.degrees(m['steer_max_abs']):.1f} | {np.degrees(m['steer_rate_max']):.2f} | "
                     f"{np.degrees(m['steer_rate_rms']):.2f} |")
    lines += ["", "![design](autopilot_design.png)", "", "![closed loop](autopilot_closed_loop.png)", "",
              f"Total run time: {s['seconds']:.1f} s.", ""]
    return "\n".join(lines)
