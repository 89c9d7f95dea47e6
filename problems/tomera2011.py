"""Tomera (2011), "Kalman-Bucy filter design for multivariable ship motion control".

Reproduction and extension:

1. Truth: a stand-in for the paper's training ship Blue Lady (a 1:24 tanker model, L = 13.75 m,
   B = 2.38 m, m = 22 934 kg; its own simulation model, Gierusz 2001, is not available): the KVLCC2
   MMG model L7 scaled by Froude similarity to L = 13.75 m (:func:`casship.models.scaling.froude_scale`),
   its breadth set to 2.38 m and its draught to give 22 934 kg at the same block coefficient. Fujiwara
   wind loads of a 2 m/s wind from North (the paper's simulation: 2 m/s, 0 deg) act on it while it
   sails a rudder sequence; DGPS positions (R_x = R_y = 0.01 m^2) and a gyro-compass (R_psi = 0.1,
   read as deg^2) at 10 Hz.
2. Kinematic filters of the paper: per axis a double integrator (Eq. 56-59) with G, Q, R of
   Eq. 61-62, as the discrete Kalman filter and as the continuous Kalman-Bucy filter (Riccati
   differential equation between samples); body velocities by Eq. 60
   (``casship.frames.ned_to_body``). The printed G and Q are garbled in the source text, so both
   readings are run: **reading A** x, y: ``G = diag(1, 0.01)``, ``Q = diag(0.1, 0.2)``; psi:
   ``G = diag(0.2, 0.01)``, ``Q = I`` (the matrices as extracted); **reading B** the same with
   the G diagonal swapped (``diag(0.01, 1)`` and ``diag(0.01, 0.2)``), which gives the noisy
   velocities that the paper's figures show. The paper's R (0.01, 0.1) is read as the variance of
   one sampled measurement, so the Kalman-Bucy filter uses the spectral density ``Rc = R dt``
   (Eq. 35); the other reading (R as the spectral density itself) runs as well.
3. Both filters get the same ``Q`` in casship's one meaning (the covariance held over a step,
   ``Q = Qc / dt`` for the paper's spectral densities ``Qc``); the Kalman-Bucy steady-state gain
   (``control.lqe``) is compared with the discrete steady gain over ``dt``.
4. What the paper names as the weakness (noisy velocities because the filter ignores the ship's
   dynamics) is then addressed with a model-based continuous-discrete EKF on the MMG model of the
   same ship, without the wind in its model (the wind is an unmodelled disturbance), measuring
   the same x, y, psi.

The lake trials on Lake Silm (Figs. 7-9) cannot be reproduced: their records are not available.

Run ``casship study tomera2011 [--quick]``.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import casship as cs
from casship.frames import ned_to_body
from casship.maneuvers import propeller_rate_for_speed, straight_run_state
from casship.models import get_model, tomera_kinematic
from casship.models.kvlcc2 import KVLCC2_COMMON, KVLCC2_L7, KVLCC2_SOURCES, RUDDER_RATE_FULL
from casship.models.mmg import mmg_standard
from casship.models.scaling import froude_rate, froude_scale
from casship.models.wind import add_wind
from casship.progress import progress

from . import Study
from .kit import Departure, Report, effect, figure, md_table, write_json
from casship.errors import InputError

DT = 0.1
R_XY = 0.01                          # m^2 (Eq. 61)
R_PSI = np.deg2rad(np.sqrt(0.1)) ** 2  # Eq. 62: 0.1, read as deg^2
READINGS = {
    "A": {"g_xy": (1.0, 0.01), "g_psi": (0.2, 0.01), "q_xy": (0.1, 0.2), "q_psi": (1.0, 1.0)},
    "B": {"g_xy": (0.01, 1.0), "g_psi": (0.01, 0.2), "q_xy": (0.1, 0.2), "q_psi": (1.0, 1.0)},
}
R_READINGS = ("sampled", "continuous")   # the paper's R: variance of a sample (Rc = R dt) or Rc itself
#: Blue Lady (Tomera 2011, Sect. 5): length overall, breadth, mass.
BLUE_LADY = {"L": 13.75, "B": 2.38, "mass": 22934.0}
FROUDE_NUMBER = 0.142                # KVLCC2 free-running tests (SIMMAN 2020), kept at the new scale
FULL_SCALE_WIND = {"A_F": 1624.0, "A_L": 4910.0, "L_OA": 325.0, "B": 58.0, "A_OD": 750.0, "H_BR": 45.0,
                   "H_C": 20.0, "C": 5.0}


def blue_lady_standin() -> cs.Model:
    """KVLCC2 model L7 (MMG) scaled by Froude similarity to Blue Lady's length, breadth and mass.

    A stand-in, not Blue Lady: the hull coefficients are KVLCC2's (a tanker like Blue Lady's
    prototype); the draught is chosen so that the displacement is Blue Lady's 22 934 kg at KVLCC2's
    block coefficient 0.81.
    """
    scale = KVLCC2_L7["L_pp"] / BLUE_LADY["L"]
    values = froude_scale({**KVLCC2_COMMON, **KVLCC2_L7}, scale)
    rho = values["rho"]
    c_b = KVLCC2_L7["nabla"] / (KVLCC2_L7["L_pp"] * KVLCC2_L7["B"] * KVLCC2_L7["d"])
    values["L_pp"], values["B"] = BLUE_LADY["L"], BLUE_LADY["B"]      # exact (the scaling rounds)
    values["nabla"] = BLUE_LADY["mass"] / rho
    values["d"] = values["nabla"] / (c_b * values["L_pp"] * values["B"])
    full = 320.0 / BLUE_LADY["L"]
    rudder_rate = froude_rate(RUDDER_RATE_FULL, full)
    vessel = cs.Vessel("Blue Lady stand-in (KVLCC2 L7 MMG, Froude-scaled)", L_pp=BLUE_LADY["L"], B=BLUE_LADY["B"],
                       draught=values["d"], mass=BLUE_LADY["mass"], scale=24.0,
                       U0=FROUDE_NUMBER * math.sqrt(9.81 * BLUE_LADY["L"]), rudder_max=math.radians(35.0),
                       rudder_rate=rudder_rate, param_set="kvlcc2/YY2015-L7-froude-scaled-to-blue-lady",
                       source="KVLCC2 L7 (Yasukawa & Yoshimura 2015) scaled to Blue Lady's L, B, m (Tomera 2011)",
                       wind=froude_scale(FULL_SCALE_WIND, full))
    return mmg_standard(values, name="blue-lady-standin", doc="Blue Lady stand-in: KVLCC2 L7 MMG Froude-scaled "
                        "to L = 13.75 m, B = 2.38 m, m = 22 934 kg", sources=KVLCC2_SOURCES, vessel=vessel,
                        rudder_rate_max=rudder_rate)


def simulate_truth(ship: cs.Model, duration: float, seed: int = 1, wind_speed: float = 2.0):
    """``ship`` with a ``wind_speed`` wind from North, rudder +-20 deg, measured x, y, psi at 10 Hz."""
    geometry = ship.vessel.wind or froude_scale(FULL_SCALE_WIND, 320.0 / ship.vessel.L_pp)
    windy = add_wind(ship, {k: v for k, v in geometry.items() if k != "source"})
    U0 = ship.vessel.U0
    n0 = propeller_rate_for_speed(ship, U0)
    t = np.arange(0.0, duration + 1e-9, DT)
    delta = np.deg2rad(20.0) * np.tanh(3.0 * np.sin(2 * np.pi * t / 90.0))
    inputs = {"delta": delta, "n": n0, "wind_speed": wind_speed, "wind_dir": 0.0}
    traj = cs.simulate(windy, straight_run_state(windy, U0, psi=np.deg2rad(30.0)), t, inputs)
    rng = np.random.default_rng(seed)
    cols = {"delta": delta, "n": np.full(t.size, n0),
            "x": traj["x"] + np.sqrt(R_XY) * rng.standard_normal(t.size),
            "y": traj["y"] + np.sqrt(R_XY) * rng.standard_normal(t.size),
            "psi": cs.wrap(traj["psi"] + np.sqrt(R_PSI) * rng.standard_normal(t.size))}
    return traj, cs.Dataset(t, cols, meta={"wind": f"{wind_speed:g} m/s from North"})


def kinematic_filters(data, reading: dict, r_reading: str = "sampled", substeps: int = 5):
    """Discrete KF and Kalman-Bucy filter of Tomera on the double integrators.

    ``r_reading`` says what the paper's R is: the variance of one sample (``"sampled"``; the
    Kalman-Bucy filter uses ``Rc = R dt``) or the spectral density itself (``"continuous"``; the
    variance of a sample is then ``R / dt``). Returns both results, the relative gap between the
    discrete steady gain over ``dt`` and the Kalman-Bucy gain, and the Kalman-Bucy gain ``L``.
    """
    if r_reading not in R_READINGS:
        raise InputError(f"unknown R reading {r_reading!r}; use one of {R_READINGS}")
    m = tomera_kinematic(reading["g_xy"], reading["g_psi"])
    Qc = np.diag([*reading["q_xy"], *reading["q_xy"], *reading["q_psi"]])
    R = np.diag([R_XY, R_XY, R_PSI]) / (DT if r_reading == "continuous" else 1.0)
    dm = cs.discretize(m, DT, method="euler")
    prior = cs.Gaussian(m.states(x=data["x"][0], y=data["y"][0], psi=data["psi"][0]),
                        [R_XY, 1.0, R_XY, 1.0, R_PSI, 0.01])
    kf = cs.KF(dm, Qc / DT, R).filter(data, prior)
    kb_est = cs.KalmanBucy(dm, Qc / DT, R, options={"substeps": substeps})   # Q: covariance over DT, PSD Qc
    kb = kb_est.filter(data, prior)
    L, _ = kb_est.steady_state()
    H = np.array(m.h_jac(m.states(), m.inputs(), m.params())[0])
    K = kf.P_pred[-1] @ H.T @ np.linalg.inv(kf.S[-1])
    gain_gap = float(np.abs(K / DT - L).max() / np.abs(L).max())
    return kf, kb, gain_gap, np.asarray(L)


def body_velocities(res) -> np.ndarray:
    """(N, 3) body velocities u, v, r from the earth-fixed estimates (Eq. 60)."""
    u, v, r = ned_to_body(res["vx"], res["vy"], res["r"], res["psi"])
    return np.column_stack([u, v, r])


def model_based_ekf(ship, data):
    """Continuous-discrete EKF on the MMG model (no wind in the model), measuring x, y, psi."""
    m = ship.with_outputs(["x", "y", "psi"])
    dm = cs.discretize(m, DT, method="rk4")
    Qc = np.diag([1e-5, 1e-5, 1e-7])        # PSD of the unmodelled accelerations (wind ~ 1e-3 m/s^2)
    R = np.diag([R_XY, R_XY, R_PSI])
    prior = cs.Gaussian(m.states(u=ship.vessel.U0, x=data["x"][0], y=data["y"][0], psi=data["psi"][0]),
                        [0.01, 0.01, 1e-4, R_XY, R_XY, R_PSI])
    ekf = cs.EKF(dm, Qc / DT, R, options={"covariance": "continuous"})      # Q: covariance over DT, PSD Qc
    return ekf.filter(data, prior)


def metrics(est: np.ndarray, truth: np.ndarray, skip: int) -> dict:
    """RMSE of u, v, r and their noise (RMS of the sample-to-sample change of the error)."""
    err = est[skip:] - truth[skip:]
    rmse = np.sqrt(np.mean(err**2, axis=0))
    rough = np.sqrt(np.mean(np.diff(err, axis=0) ** 2, axis=0))
    return {"rmse_u": rmse[0], "rmse_v": rmse[1], "rmse_r": rmse[2],
            "noise_u": rough[0], "noise_v": rough[1], "noise_r": rough[2]}


def run_all(ship, duration: float, *, r_reading: str = "sampled", wind_speed: float = 2.0,
            readings=("A", "B")) -> dict:
    """Every filter on one simulated record: metrics per filter, gains, the velocity series."""
    traj, data = simulate_truth(ship, duration, wind_speed=wind_speed)
    truth = np.column_stack([traj["u"], traj["v"], traj["r"]])
    skip = int(20.0 / DT)
    rows, gaps, gains, series = {}, {}, {}, {}
    for name in readings:
        kf, kb, gaps[name], gains[name] = kinematic_filters(data, READINGS[name], r_reading)
        series[f"discrete KF, reading {name}"], series[f"Kalman-Bucy, reading {name}"] = body_velocities(kf), \
            body_velocities(kb)
        rows[f"discrete KF, reading {name}"] = metrics(series[f"discrete KF, reading {name}"], truth, skip)
        rows[f"Kalman-Bucy, reading {name}"] = metrics(series[f"Kalman-Bucy, reading {name}"], truth, skip)
    ekf = model_based_ekf(ship, data)
    series["MMG EKF"] = np.column_stack([ekf["u"], ekf["v"], ekf["r"]])
    rows["model-based EKF (MMG, no wind in model)"] = metrics(series["MMG EKF"], truth, skip)
    return {"t": data.t, "truth": truth, "rows": rows, "gaps": gaps, "gains": gains, "series": series}


def headline(res: dict) -> dict:
    """The headline numbers: Kalman-Bucy (reading B) sway-velocity error and noise, its steady-state
    velocity gain on x, and the model-based EKF's noise against it."""
    kb, ekf = res["rows"]["Kalman-Bucy, reading B"], res["rows"]["model-based EKF (MMG, no wind in model)"]
    return {"KB v RMSE [m/s]": kb["rmse_v"], "KB v noise [m/s]": kb["noise_v"],
            "KB velocity gain on x [1/s^2]": float(res["gains"]["B"][1, 0]),
            "KB / EKF v noise": kb["noise_v"] / ekf["noise_v"]}


def _plot(out: Path, t, truth, series: dict, name: str, title: str) -> str:
    labels = ("u [m/s]", "v [m/s]", "r [deg/s]")
    with figure(out / name, 3, 1, figsize=(9, 7.5), sharex=True) as (fig, axes):
        for i, ax in enumerate(axes):
            scale = np.rad2deg(1.0) if i == 2 else 1.0
            for k, (label, vel) in enumerate(series.items()):
                ax.plot(t, scale * vel[:, i], lw=0.8, color=f"C{k}", label=label, alpha=0.85)
            ax.plot(t, scale * truth[:, i], "k--", lw=1.0, label="truth")
            ax.set_ylabel(labels[i])
            ax.grid(alpha=0.3)
        axes[0].set_title(title)
        axes[0].legend(fontsize=8, ncol=len(series) + 1)
        axes[-1].set_xlabel("t [s]")
    return name


def departures(main: dict, alt: dict, ship: cs.Model) -> list[Departure]:
    """The choices the paper leaves open or that this study makes differently, with their effects."""
    h = headline(main)
    c_b = KVLCC2_L7["nabla"] / (KVLCC2_L7["L_pp"] * KVLCC2_L7["B"] * KVLCC2_L7["d"])
    return [
        Departure("ship", "Blue Lady, a 1:24 tanker model (L 13.75 m, B 2.38 m, m 22 934 kg), simulated with "
                  "Gierusz's model (2001), which is not available", "a stand-in: KVLCC2 L7 MMG scaled by Froude "
                  f"similarity to L 13.75 m, B 2.38 m and 22 934 kg (draught {ship.vessel.draught:.3f} m at KVLCC2 "
                  f"L7's block coefficient {c_b:.3f})",
                  effect(h, headline(alt["KVLCC2 L7 (7 m)"]), alt_name="the study's earlier ship, KVLCC2 model L7")),
        Departure("lake trials (Figs. 7-9)", "Blue Lady on Lake Silm near Ilawa, DGPS and gyro-compass records",
                  "not reproduced: the records are not available", "none (no data)"),
        Departure("G and Q (Eq. 61-62)", "garbled in the source text",
                  "both readings run: A (G as extracted) and B (G diagonal swapped, the noisy velocities of the "
                  "paper's Figs. 4-6); headline numbers are reading B's",
                  "reading A: KB v RMSE {:.3g} m/s, v noise {:.3g} m/s (reading B: {:.3g}, {:.3g}); velocity gain on x "
                  "{:.3g} (B: {:.3g})".format(main["rows"]["Kalman-Bucy, reading A"]["rmse_v"],
                                              main["rows"]["Kalman-Bucy, reading A"]["noise_v"], h["KB v RMSE [m/s]"],
                                              h["KB v noise [m/s]"], float(main["gains"]["A"][1, 0]),
                                              h["KB velocity gain on x [1/s^2]"])),
        Departure("R (Eq. 61-62, 35)", "R_x = R_y = 0.01, R_psi = 0.1 'covariances of the measurements'; "
                  "Eq. 35 relates the sampled R_k to the continuous R by R_k = R / dt",
                  "R is the variance of one sample; the Kalman-Bucy filter uses Rc = R dt",
                  effect(h, headline(alt["R as spectral density"]), alt_name="R read as the spectral density Rc "
                         "(sampled variance R / dt)")),
        Departure("unit of R_psi = 0.1", "not stated", "deg^2 (a gyro-compass of 0.32 deg)",
                  "not run: 0.1 rad^2 (18 deg) is not a gyro-compass"),
        Departure("wind", "2 m/s from 0 deg in Gierusz's model", "2 m/s from North, Fujiwara's 2005 regression "
                  "on KVLCC2's above-water geometry scaled to 13.75 m",
                  effect(h, headline(alt["no wind"]), alt_name="no wind at all (bounds the effect of the wind model)")),
        Departure("manoeuvre and sampling", "not stated", "rudder +-20 deg (smoothed square wave, 90 s period), "
                  "x, y, psi at 10 Hz for 400 s (quick run: 120 s)", "not measured"),
    ]


def run(out: Path, quick: bool = False, workers=None, scheduler=None) -> dict:
    """Filters on the Blue Lady stand-in, the other readings, figures, ``report.md``, ``summary.json``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    duration = 120.0 if quick else 400.0
    stages = progress(["Blue Lady stand-in: truth and filters", "other readings (ship, R, wind)", "report"],
                      "tomera2011")
    next(stages)
    ship = blue_lady_standin()
    main = run_all(ship, duration)
    next(stages)
    alt = {"KVLCC2 L7 (7 m)": run_all(get_model("kvlcc2-l7"), duration, readings=("B",)),
           "R as spectral density": run_all(ship, duration, r_reading="continuous", readings=("B",)),
           "no wind": run_all(ship, duration, wind_speed=0.0, readings=("B",))}
    next(stages)
    rows, t, truth, s = main["rows"], main["t"], main["truth"], main["series"]
    figures = [_plot(out, t, truth, {"discrete KF": s[f"discrete KF, reading {r}"],
                                     "Kalman-Bucy": s[f"Kalman-Bucy, reading {r}"]}, f"velocities_reading_{r}.png",
                     f"Tomera (2011) kinematic filters, reading {r}: body velocities (Eq. 60; paper Figs. 4-6)")
               for r in ("A", "B")]
    figures.append(_plot(out, t, truth, {"Kalman-Bucy, reading B": s["Kalman-Bucy, reading B"], "MMG EKF": s["MMG EKF"]},
                         "kinematic_vs_model_based.png",
                         "Kinematic Kalman-Bucy filter vs model-based EKF (2 m/s wind unmodelled)"))
    table = {k: {"RMSE u [m/s]": v["rmse_u"], "RMSE v [m/s]": v["rmse_v"], "RMSE r [deg/s]": np.rad2deg(v["rmse_r"]),
                 "noise u [m/s]": v["noise_u"], "noise v [m/s]": v["noise_v"], "noise r [deg/s]": np.rad2deg(v["noise_r"])}
             for k, v in rows.items()}
    best_kin = min((k for k in rows if "EKF" not in k), key=lambda k: rows[k]["rmse_v"])
    ekf_row = rows["model-based EKF (MMG, no wind in model)"]
    gain = {c: rows[best_kin][f"noise_{c}"] / ekf_row[f"noise_{c}"] for c in "uvr"}
    deps = departures(main, alt, ship)
    rep = Report("Tomera (2011): discrete Kalman filter vs Kalman-Bucy filter, and a model-based EKF", quick=quick)
    rep.add(f"Ship: a stand-in for Blue Lady (KVLCC2 L7 MMG, Froude-scaled to L = {BLUE_LADY['L']} m, B = "
            f"{BLUE_LADY['B']} m, m = {BLUE_LADY['mass']:.0f} kg; approach speed {ship.vessel.U0:.2f} m/s at Fn "
            f"{FROUDE_NUMBER}), 2 m/s wind from North (Fujiwara loads), rudder +-20 deg, {duration:.0f} s at "
            f"{1 / DT:.0f} Hz; DGPS R = {R_XY} m^2, gyro R_psi = 0.1 deg^2. Errors after the first 20 s. Noise = RMS "
            "of the sample-to-sample change of the error. The lake trials (paper Figs. 7-9) cannot be reproduced "
            "without their records, which are not available.")
    rep.add("Readings of the garbled Eq. 61-62: A = G as extracted (x, y: diag(1, 0.01); psi: diag(0.2, 0.01)), "
            "B = G diagonal swapped; Q = diag(0.1, 0.2) (x, y), I (psi) in both.")
    rep.section("Simulation study (paper Figs. 4-6): body velocities")
    rep.add(md_table(table, first="filter"))
    rep.add(f"Steady-state gains: |K_discrete / dt - L_lqe| / |L_lqe| = {main['gaps']['A']:.2f} (reading A), "
            f"{main['gaps']['B']:.2f} (reading B) at dt = {DT} s. The Kalman-Bucy filter is the dt -> 0 limit of the "
            "discrete filter (Tomera's derivation, checked in casship's tests); at this sampling rate the position "
            "gains are not small against 1, so the two filters differ visibly although their velocity errors are "
            "close.")
    rep.add(f"Velocity noise of the best kinematic filter ({best_kin}) over the model-based EKF: u x{gain['u']:.1f}, "
            f"v x{gain['v']:.1f}, r x{gain['r']:.1f}.")
    rep.add(*[f"![{Path(p).stem}]({p})" for p in figures])
    rep.departures(deps, "Headline numbers: the Kalman-Bucy filter's (reading B) sway-velocity RMSE and noise, its "
                         "steady-state velocity gain on x, and its velocity noise over the model-based EKF's.")
    rep.write(out)
    (out / "velocities.md").write_text(md_table(table, first="filter") + "\n")
    next(stages, None)
    return write_json(out / "summary.json", {
        "duration_s": duration, "ship": ship.vessel.name, "ship_particulars": {
            "L_pp": ship.vessel.L_pp, "B": ship.vessel.B, "draught": ship.vessel.draught, "mass": ship.vessel.mass,
            "U0": ship.vessel.U0},
        "readings": {k: {kk: list(vv) for kk, vv in v.items()} for k, v in READINGS.items()},
        "R_psi_rad2": R_PSI, "metrics": rows, "gain_gap": main["gaps"],
        "kb_gain": {k: v.tolist() for k, v in main["gains"].items()}, "noise_ratio_kinematic_over_ekf": gain,
        "best_kinematic": best_kin, "headline": headline(main),
        "other_readings": {k: headline(v) for k, v in alt.items()}, "departures": [d.__dict__ for d in deps],
        "figures": figures})


STUDY = Study("tomera2011", "Tomera 2011: discrete KF vs Kalman-Bucy filter (two readings of G, Q; two of R), body "
                            "velocities, and a model-based MMG EKF, on a Froude-scaled Blue Lady stand-in", run)
