"""Fossen & Fossen (2021): five-state SOG/COG/course-rate EKF and an Otter USV course autopilot.

Parts
-----
(a) The five-state EKF (Euler, Joseph form, course innovation on the circle) in North-East and in
    latitude/longitude form, run at 50 Hz with GNSS positions at 5 Hz, on a simulated Otter course
    change; SOG, COG and course-rate errors against the truth. The EKF that ran online inside
    the autopilot loop (``EKF.step``) is compared with the batch filter (``EKF.filter``) on the
    same measurements.
(b) The lat/lon EKF on the real USV GNSS logs in ``shared/data/usv_fuzhou_gnss`` (2 Hz), compared
    with the log's own speed and course columns (skipped with a note when the folder is absent).
(c) Otter course autopilot (PID pole placement on the Nomoto model, third-order reference model)
    fed by the EKF's course and course-rate estimates: 20 deg course command, back to 0 deg at
    t = 20 s; figures like the paper's Figs. 4-6.

Constants: REFERENCE.md section 2 (MSS ``EKF_5states.m``, ``exOtter.m``; PVS ``otter.py``).
"""
from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np

import casship as cs
from casship import autopilot as ap
from casship.identify import MLEProblem
from casship.models import sog_cog, sog_cog_latlon
from casship.models import otter as casship_otter
from casship.progress import progress

from . import Study
from .kit import Departure, Report, data_folder, effect, figure, md_table, write_json

# Surge force [N]: 120 N gives about 1.5 m/s on this model, above the 1 m/s that the paper names as
# the speed from which GNSS SOG/COG are good (MSS exOtter uses 40 N, about 0.5 m/s here).
TAU_X, TAU_X_MSS = 120.0, 40.0
COURSE_DEG, SWITCH_BACK_S = 20.0, 20.0   # the paper's Figs. 4 and 6: 20 deg, back to 0 deg at t = 20 s
WN, ZETA = 1.5, 1.0              # autopilot (MSS exOtter)
WN_D, R_MAX = 1.0, np.radians(10.0)   # reference model (MSS exOtter)
# EKF at 50 Hz, GNSS at 5 Hz (the paper's Fig. 6). Position noise 2 cm (RTK class, an assumption: the
# paper does not state it); the sensitivity table shows what coarser GNSS does to the loop.
DT, GNSS_RATE, GNSS_STD = 0.02, 5.0, 0.02
EKF_Q, EKF_ALPHA = (0.1, 1.0), (0.01, 0.1)     # Q = diag(var w_U, var w_chi); MSS Singer constants
SENSITIVITY = {"gnss_std_m": (0.02, 0.1, 0.5), "wn": (1.5, 0.8, 0.5)}
ORIGIN = (np.radians(63.4389), np.radians(10.3994))   # Trondheim fjord (lat, lon)
KNOT = 1852.0 / 3600.0


def _latlon_dataset(t, north, east, std, seed, every):
    """GNSS lat/lon (rad) with ``std`` m noise every ``every`` rows (NaN elsewhere)."""
    rng = np.random.default_rng(seed)
    n_meas = north + std * rng.standard_normal(north.size)
    e_meas = east + std * rng.standard_normal(east.size)
    lat, lon = cs.frames.ne_to_latlon(n_meas, e_meas, *ORIGIN)
    keep = (np.arange(t.size) % every) == 0
    return cs.Dataset(t, {"lat": np.where(keep, lat, np.nan), "lon": np.where(keep, lon, np.nan)})


def _rad_per_m(lat):
    """Radians of latitude and of longitude per metre North and East at latitude ``lat``."""
    r_n, r_m = cs.frames.wgs84_radii(lat)
    return 1.0 / r_m, 1.0 / (r_n * np.cos(lat))


def _errors(x_est, truth, names=("U", "chi", "omega_chi"), skip=0):
    out = {}
    for k, name in enumerate(names):
        e = x_est[skip:, k] - truth[name][skip:]
        if name == "chi":
            e = cs.wrap(e)
        scale = np.degrees(1.0) if name != "U" else 1.0
        unit = "deg" if name == "chi" else ("deg_s" if name == "omega_chi" else "mps")
        out[f"{name}_rmse_{unit}"] = float(scale * np.sqrt(np.mean(e**2)))
    return out


def course_command(quick: bool):
    """The paper's scenario in both modes: 20 deg at t = 0, back to 0 deg at t = 20 s.

    Returns ``(command(t) -> rad, t_end, step_times)``; the full run lasts 50 s, the quick one 40 s.
    """
    a = np.radians(COURSE_DEG)
    t_end = 40.0 if quick else 50.0
    return (lambda t: a if t < SWITCH_BACK_S else 0.0), t_end, [0.0, SWITCH_BACK_S]


def part_c(otter, quick, *, wn=WN, gnss_std=GNSS_STD, seed=3, tau_x=TAU_X, gnss_rate=GNSS_RATE):
    """Otter course autopilot on the EKF estimates (the closed loop of parts a and c)."""
    steer_model = ap.steering_model(otter, ["tau_X", "tau_N"], ap.twin_propeller_allocation(otter), name="otter_tau")
    tr = cs.trim(steer_model, x={"u": 1.0}, u={"tau_X": tau_x}, free=["u"], zero=["u"])
    speed = tr.values["u"]
    tau_n_max = ap.twin_propeller_yaw_limit(otter, tau_x)       # keeps both propellers in range
    design = ap.design_autopilot(steer_model, speed, steer="tau_N", inputs={"tau_X": tau_x}, wn=wn, zeta=ZETA,
                                 wn_ref=min(WN_D, wn), r_max=R_MAX, steer_max=tau_n_max, steer_rate_max=np.inf,
                                 actuator_T=0.1, delay=1.0 / gnss_rate, mode="course", rate="estimator", dt=DT,
                                 gnss_rate=gnss_rate, gnss_std=gnss_std, ekf_q=EKF_Q, ekf_alpha=EKF_ALPHA)
    command, t_end, steps = course_command(quick)
    res = ap.simulate_autopilot(design, command, t_end, step_times=steps, seed=seed)
    # propeller rates from the allocation
    tx, tn = ca.SX.sym("tx"), ca.SX.sym("tn")
    p_sym = {n: ca.SX(v) for n, v in otter.param_dict().items()}
    n_expr = ap.twin_propeller_allocation(otter)({"tau_X": tx, "tau_N": tn}, p_sym)
    nfun = ca.Function("alloc", [tx, tn], [n_expr["n1"], n_expr["n2"]]).map(len(res.data))
    n1, n2 = (np.ravel(np.array(v)) for v in nfun(tau_x, res.data["steer"]))
    return design, res, (n1, n2), speed


def part_a(res, seed=5):
    """Batch EKFs (NE and lat/lon) on the closed-loop record; online vs batch check."""
    d = res.data
    t = d.t
    every = int(round(1 / (GNSS_RATE * DT)))
    truth = {"U": d["U"], "chi": d["chi"], "omega_chi": d["omega_chi"]}
    ne = cs.Dataset(t, {"x_n": d["gnss_north"], "y_n": d["gnss_east"]})
    ekf_ne = cs.EKF(cs.discretize(sog_cog(*EKF_ALPHA), DT, "euler"), Q=np.diag(EKF_Q), R=np.eye(2) * GNSS_STD**2)
    prior = d.meta["estimator_prior"]
    # the loop's EKF started from this prior (first step: update only): the batch filter must agree
    res_ne = ekf_ne.filter(ne, prior)
    online_vs_batch = float(np.max(np.abs(res_ne.x[:, 3] - d["chi_hat"])))
    ll = _latlon_dataset(t, d["north"], d["east"], GNSS_STD, seed, every)
    r_lat, r_lon = _rad_per_m(ORIGIN[0])
    ekf_ll = cs.EKF(cs.discretize(sog_cog_latlon(*EKF_ALPHA), DT, "euler"), Q=np.diag(EKF_Q),
                    R=np.diag([(GNSS_STD * r_lat) ** 2, (GNSS_STD * r_lon) ** 2]))
    lat0, lon0 = ll["lat"][0], ll["lon"][0]
    prior_ll = cs.Gaussian(np.array([lat0, lon0, prior.mean[2], prior.mean[3], prior.mean[4]]),
                           np.diag([(GNSS_STD * r_lat) ** 2, (GNSS_STD * r_lon) ** 2, *np.diag(prior.cov)[2:]]))
    res_ll = ekf_ll.filter(ll, prior_ll)
    skip = int(5.0 / DT)       # leave out the first 5 s (filter start-up)
    table = {"EKF north-east (online, in the loop)": _errors(np.column_stack([d["U_hat"], d["chi_hat"],
                                                                               d["omega_hat"]]), truth, skip=skip),
             "EKF north-east (batch)": _errors(res_ne.x[:, 2:], truth, skip=skip),
             "EKF lat/lon (batch, independent noise)": _errors(res_ll.x[:, 2:], truth, skip=skip)}
    return table, res_ne, res_ll, online_vs_batch


def part_b(folder: Path, quick: bool = False):
    """Lat/lon EKF on the real USV logs, against the logs' speed and course columns."""
    rows, fits = {}, {}
    for fname in ("zigzag_30_inter_xy.csv", "turnningdata_xy.csv")[: 1 if quick else None]:
        path = folder / fname
        if not path.exists():
            continue
        raw = cs.Dataset.from_csv(path)
        lat, lon = np.radians(raw["lat"]), np.radians(raw["lon"])
        t = raw.t
        data = cs.Dataset(t, {"lat": lat, "lon": lon})
        dt = float(np.median(np.diff(t)))
        std = 0.5                                     # assumed GNSS noise [m]
        r_lat, r_lon = _rad_per_m(lat[0])
        ekf = cs.EKF(cs.discretize(sog_cog_latlon(), dt, "euler"), Q=np.diag([0.01, 0.001]),
                     R=np.diag([(std * r_lat) ** 2, (std * r_lon) ** 2]))
        # SOG and COG start from the track of the first 5 s (like MSS's x_prd_init; cs.prior_from_data):
        # a prior of U = 0, chi = 0 can converge to the mirror solution U < 0, chi + 180 deg.
        north, east = cs.frames.latlon_to_ne(lat, lon, lat[0], lon[0])
        start = cs.prior_from_data(ekf.model, data, measured=ekf.measured, R=ekf.R, window=5.0)
        prior = cs.Gaussian(start.mean, np.diag([(std * r_lat) ** 2, (std * r_lon) ** 2, 0.25, np.radians(30) ** 2,
                                                 0.01]))
        # process noise by maximum likelihood through the EKF (R fixed at the assumed 0.5 m)
        fit = MLEProblem(ekf, data, noise={"Q": True}, x0=prior).solve()
        Qf = np.diag([fit.estimates["Q[w_U]"], fit.estimates["Q[w_chi]"]])
        ekf = cs.EKF(ekf.dmodel, Q=Qf, R=ekf.R)
        res = ekf.filter(data, prior)
        # speed and course from differenced positions (what the log's columns should approximate)
        vn, ve = np.gradient(north, t), np.gradient(east, t)
        sog_diff, cog_diff = np.hypot(vn, ve), np.arctan2(ve, vn)
        # The log's speed column is about twice the speed of its own positions: it is in knots
        # (ratio printed below), so it is converted here.
        ratio = float(np.mean(sog_diff) / np.mean(raw["speed"]))
        sog_log = raw["speed"] * KNOT
        cog_log = np.radians(raw["zcourse"])
        head_log = np.radians(raw["heading"])
        skip = t >= t[0] + 10.0                       # after start-up
        moving = skip & (sog_log > 0.3)
        U_err = res["U"][skip] - sog_log[skip]
        chi_err = np.degrees(cs.wrap(res["chi"][moving] - cog_log[moving]))
        rms = lambda a: float(np.sqrt(np.mean(np.square(a))))  # noqa: E731
        rows[fname] = {
            "samples": int(t.size), "rate_hz": float(1 / dt),
            "log_sog_p5_mps": float(np.percentile(sog_log, 5)), "log_sog_p95_mps": float(np.percentile(sog_log, 95)),
            "Q_w_U_mle": float(Qf[0, 0]), "Q_w_chi_mle": float(Qf[1, 1]),
            "position_speed_over_log_speed": ratio,
            "sog_rmse_vs_log_mps": rms(U_err), "sog_bias_vs_log_mps": float(np.mean(U_err)),
            "sog_rmse_vs_differenced_mps": rms(res["U"][skip] - sog_diff[skip]),
            "cog_rmse_vs_log_deg": rms(chi_err), "cog_median_abs_vs_log_deg": float(np.median(np.abs(chi_err))),
            "cog_bias_vs_log_deg": float(np.mean(chi_err)),
            "cog_rmse_vs_differenced_deg": rms(np.degrees(cs.wrap(res["chi"][moving] - cog_diff[moving]))),
            "cog_median_abs_vs_differenced_deg": float(np.median(np.abs(np.degrees(
                cs.wrap(res["chi"][moving] - cog_diff[moving]))))),
            "log_course_vs_log_heading_rms_deg": rms(np.degrees(cs.wrap(cog_log[moving] - head_log[moving]))),
        }
        # time shift of the EKF course (from positions) against the log course that aligns them best
        lags = np.arange(0, int(round(10.0 / dt)) + 1)
        cost = [np.median(np.abs(cs.wrap(res["chi"][lag:][moving[:t.size - lag]]
                                         - cog_log[:t.size - lag][moving[:t.size - lag]]))) for lag in lags]
        best = int(lags[int(np.argmin(cost))])
        sel = moving[:t.size - best]
        shifted = np.degrees(cs.wrap(res["chi"][best:][sel] - cog_log[:t.size - best][sel]))
        rows[fname].update({"best_lag_of_positions_s": best * dt,
                            "cog_median_abs_vs_log_after_lag_deg": float(np.median(np.abs(shifted))),
                            "cog_bias_vs_log_after_lag_deg": float(np.median(shifted))})
        raw = raw.with_columns(sog_log=sog_log)
        fits[fname] = (t, res, raw, cog_log, head_log)
    return rows, fits


def _plots(out: Path, design, res, n12, fits):
    d = res.data
    t = d.t
    with figure(out / "fig4_north_east.png", figsize=(6, 5)) as (fig, ax):
        ax.plot(d["east"], d["north"], label="true")
        ok = np.isfinite(d["gnss_north"])
        ax.plot(d["gnss_east"][ok], d["gnss_north"][ok], ".", ms=2, alpha=0.6, label=f"GNSS ({GNSS_RATE:g} Hz)")
        ax.set_xlabel("East [m]")
        ax.set_ylabel("North [m]")
        ax.set_title(f"Otter: {COURSE_DEG:g} deg course command, back to 0 deg at t = {SWITCH_BACK_S:g} s")
        ax.set_aspect("equal", adjustable="datalim")
        ax.legend()
        ax.grid(alpha=0.3)
    with figure(out / "fig5_propellers.png", figsize=(7, 3.5)) as (fig, ax):
        ax.plot(t, n12[0] * 60 / (2 * np.pi), label="n1 (port)")
        ax.plot(t, n12[1] * 60 / (2 * np.pi), label="n2 (starboard)")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("propeller [rpm]")
        ax.legend()
        ax.grid(alpha=0.3)
    with figure(out / "fig6_sog_cog_rate.png", 3, 2, figsize=(11, 8), gridspec_kw={"width_ratios": [3, 1]}) as (
            fig, axes):
        zoom = (t >= SWITCH_BACK_S) & (t <= SWITCH_BACK_S + 1.0)
        series = [("U", "U_hat", 1.0, "SOG [m/s]"), ("chi", "chi_hat", np.degrees(1.0), "COG [deg]"),
                  ("omega_chi", "omega_hat", np.degrees(1.0), "course rate [deg/s]")]
        for row, (true, est, sc, label) in enumerate(series):
            for col, sel in enumerate((slice(None), zoom)):
                ax = axes[row, col]
                ax.plot(t[sel], d[true][sel] * sc, label="true")
                ax.plot(t[sel], d[est][sel] * sc, lw=0.8, label=f"EKF ({1 / DT:.0f} Hz)")
                if row == 1:
                    ax.plot(t[sel], d["chi_d"][sel] * sc, "--", lw=0.8, label="desired")
                if col == 1:
                    for tt in t[sel][np.isfinite(d["gnss_north"][sel])]:
                        ax.axvline(tt, color="k", lw=0.4, alpha=0.4)
                ax.grid(alpha=0.3)
            axes[row, 0].set_ylabel(label)
        axes[0, 0].legend(fontsize=8)
        axes[0, 1].set_title(f"zoom: GNSS fixes ({GNSS_RATE:g} Hz) as lines")
        axes[2, 0].set_xlabel("time [s]")
        axes[2, 1].set_xlabel("time [s]")
    ap.plot_design(design.loop, out / "otter_loop_bode_step.png", "Otter course loop (linearised Otter)",
                   design.closed_loop)
    for fname, (tt, r, raw, cog_log, head_log) in fits.items():
        with figure(out / f"real_{Path(fname).stem}.png", 2, 1, figsize=(9, 6), sharex=True) as (fig, axes):
            axes[0].plot(tt, raw["sog_log"], label="log speed (knots -> m/s)")
            axes[0].plot(tt, r["U"], label="EKF SOG")
            axes[0].set_ylabel("SOG [m/s]")
            axes[0].legend()
            axes[1].plot(tt, np.degrees(cs.wrap(cog_log)), ".", ms=3, label="log course")
            axes[1].plot(tt, np.degrees(cs.wrap(head_log)), lw=0.8, label="log heading")
            axes[1].plot(tt, np.degrees(cs.wrap(r["chi"])), ".", ms=3, label="EKF COG")
            axes[1].set_ylabel("angle [deg]")
            axes[1].set_xlabel("time [s]")
            axes[1].legend()
            for a in axes:
                a.grid(alpha=0.3)
            fig.suptitle(f"Substitute vessel (Fuzhou USV, slow-speed regime), log {fname}: lat/lon EKF")


def _headline(res) -> dict:
    """The study's headline numbers for one closed-loop run: online EKF errors after 5 s, overshoot."""
    d = res.data
    est = np.column_stack([d["U_hat"], d["chi_hat"], d["omega_hat"]])
    e = _errors(est, {"U": d["U"], "chi": d["chi"], "omega_chi": d["omega_chi"]}, skip=int(5.0 / DT))
    return {"SOG RMSE [m/s]": e["U_rmse_mps"], "COG RMSE [deg]": e["chi_rmse_deg"],
            "course-rate RMSE [deg/s]": e["omega_chi_rmse_deg_s"],
            "max overshoot [deg]": max(m["overshoot_deg"] for m in res.metrics)}


def _q_effect(res) -> str:
    """Batch NE EKF on the loop's GNSS record with Q x 10 and Q / 10 (COG and SOG RMSE after 5 s)."""
    d = res.data
    data = cs.Dataset(d.t, {"x_n": d["gnss_north"], "y_n": d["gnss_east"]})
    truth = {"U": d["U"], "chi": d["chi"], "omega_chi": d["omega_chi"]}
    out = []
    for factor in (1.0, 10.0, 0.1):
        ekf = cs.EKF(cs.discretize(sog_cog(*EKF_ALPHA), DT, "euler"), Q=np.diag(EKF_Q) * factor,
                     R=np.eye(2) * GNSS_STD**2)
        e = _errors(ekf.filter(data, d.meta["estimator_prior"]).x[:, 2:], truth, skip=int(5.0 / DT))
        out.append(f"Q x {factor:g}: COG {e['chi_rmse_deg']:.3g} deg, SOG {e['U_rmse_mps']:.3g} m/s")
    return "batch EKF on the same record, " + "; ".join(out)


def departures(head, alt_speed, speed_mss, alt_rate, sens, q_text, table_b) -> list[Departure]:
    """The choices the paper leaves open or that this study makes differently, with their effects."""
    std_keys = [k for k in sens if k.endswith(f"wn {WN}")]
    lo, hi = sens[std_keys[0]], sens[std_keys[-1]]
    if table_b:
        logs = "; ".join(f"{name}: SOG {r['log_sog_p5_mps']:.2f}-{r['log_sog_p95_mps']:.2f} m/s, median "
                         f"|COG error| {r['cog_median_abs_vs_differenced_deg']:.1f} deg against the differenced "
                         "positions" for name, r in table_b.items())
    else:
        logs = "not run (no measured data)"
    return [
        Departure("vessel model", "the Otter USV of the MSS toolbox (6 DOF, otter.m)",
                  "casship's 'otter' preset: the same constants in the horizontal plane (3 DOF)",
                  "not measured (no 6-DOF model in casship)"),
        Departure("speed of the simulated course change", "not stated in the available text (MSS exOtter: "
                  "surge force 40 N)", f"surge force {TAU_X:g} N ({head['speed_mps']:.2f} m/s), above the 1 m/s "
                  "from which the paper finds GNSS SOG/COG good",
                  effect(head["numbers"], alt_speed, alt_name=f"MSS's surge force {TAU_X_MSS:g} N ({speed_mss:.2f} m/s)")),
        Departure("GNSS rate", "5 Hz in the paper's Figs. 5-6 (MSS exOtter: every 5th of 50 Hz steps)",
                  f"{GNSS_RATE:g} Hz with the EKF at {1 / DT:.0f} Hz",
                  effect(head["numbers"], alt_rate, alt_name="GNSS at 10 Hz")),
        Departure("GNSS position noise", "not stated", f"{GNSS_STD} m (RTK class)",
                  f"sensitivity table in (c): COG RMSE {lo['chi_rmse_deg']:.3g} deg at {std_keys[0].split(',')[0]} "
                  f"-> {hi['chi_rmse_deg']:.3g} deg at {std_keys[-1].split(',')[0]}; worst overshoot "
                  f"{lo['max_overshoot_deg']:.3g} -> {hi['max_overshoot_deg']:.3g} deg"),
        Departure("EKF process noise Q", "not stated for the Otter simulation (MSS exOtter: Qd = 1e6 I)",
                  f"Q = diag{EKF_Q} (variances of w_U, w_chi), alpha = {EKF_ALPHA} (MSS Singer constants)", q_text),
        Departure("experiments (Figs. 7-11)", "Mariner and Otter USVs in the Trondheim fjord, GNSS at 5 Hz, "
                  "mostly above 1 m/s; SOG/COG good above about 1 m/s, less accurate at low speed",
                  "substitute vessel: the Fuzhou USV logs (unknown small twin-propeller USV, 2 Hz), entirely "
                  "in the slow-speed regime below 1 m/s that the paper's caveat is about", logs),
    ]


def run(out: Path, quick: bool = False, workers=None, scheduler=None, data_dir=None) -> dict:
    """Run parts (a)-(c) and the departure checks; write figures, ``report.md`` and ``summary.json``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stages = progress(["Otter course autopilot with the EKF in the loop (c)", "EKFs NE and lat/lon (a)",
                       "sensitivity and departures", "real USV GNSS logs (b)", "figures and report"], "fossen2021")
    next(stages)
    # the paper's Otter: MSS otter.m of 2021, which neglected the Munk moment (revision 2021-06-21)
    otter = casship_otter(munk_moment=False)
    otter_source = "casship.models.otter(munk_moment=False) (MSS otter.m of 2021, horizontal plane)"
    design, res, n12, speed = part_c(otter, quick)
    d = res.data
    back = d.t[np.flatnonzero((d.t > 0) & np.isclose(d["ref"], 0.0))[0]]
    next(stages)
    table_a, res_ne, res_ll, online_vs_batch = part_a(res)
    next(stages)
    sens = {}
    for std in SENSITIVITY["gnss_std_m"][: 2 if quick else None]:
        for wn in SENSITIVITY["wn"][: 2 if quick else None]:
            _, r, _, _ = part_c(otter, quick, wn=wn, gnss_std=std, seed=11)
            dd = r.data
            sk = dd.t >= 5.0
            sens[f"GNSS {std} m, wn {wn}"] = {
                "max_overshoot_deg": max(m["overshoot_deg"] for m in r.metrics),
                "max_abs_ss_error_deg": max(abs(m["steady_state_error_deg"]) for m in r.metrics),
                "iae_deg_s": sum(m["iae_deg_s"] for m in r.metrics),
                "chi_rmse_deg": float(np.degrees(np.sqrt(np.mean(cs.wrap(dd["chi_hat"] - dd["chi"])[sk] ** 2)))),
                "omega_rmse_deg_s": float(np.degrees(np.sqrt(np.mean((dd["omega_hat"] - dd["omega_chi"])[sk] ** 2))))}
    head = {"speed_mps": speed, "numbers": _headline(res)}
    _, r_mss, _, speed_mss = part_c(otter, quick, tau_x=TAU_X_MSS)
    _, r_rate, _, _ = part_c(otter, quick, gnss_rate=10.0)
    q_text = _q_effect(res)
    next(stages)
    folder = data_folder(data_dir, "usv_fuzhou_gnss", study="fossen2021", part="part (b), the real USV logs")
    table_b, fits = part_b(folder, quick) if folder is not None else ({}, {})
    next(stages)
    _plots(out, design, res, n12, fits)
    deps = departures(head, _headline(r_mss), speed_mss, _headline(r_rate), sens, q_text, table_b)
    rep = Report("Fossen & Fossen (2021): SOG/COG/course-rate EKF and Otter course autopilot", quick=quick)
    rep.add(f"Vessel: {otter_source}; surge force {TAU_X:g} N gives {speed:.2f} m/s. EKF at {1 / DT:.0f} Hz, GNSS "
            f"at {GNSS_RATE:g} Hz with {GNSS_STD} m noise; Q = diag{EKF_Q}, alpha = {EKF_ALPHA}. Course command "
            f"{COURSE_DEG:g} deg at t = 0, back to 0 deg at t = {back:g} s (the paper's Figs. 4 and 6: 20 s).")
    rep.add(f"Nomoto (from the exact linearisation, yaw moment -> yaw rate): K = {design.nomoto.K:.4g}, "
            f"T = {design.nomoto.T:.4g} s. PID (Fossen's pole placement, wn = {WN}, zeta = {ZETA}): "
            f"Kp = {design.gains.Kp:.4g}, Kd = {design.gains.Kd:.4g}, Ki = {design.gains.Ki:.4g}. Reference model "
            f"wn_d = {WN_D}, r_max = 10 deg/s. Margins on the design model (0.1 s thrust lag, "
            f"{1 / GNSS_RATE:g} s delay): gain {design.margins['gain_margin_db']:.1f} dB, phase "
            f"{design.margins['phase_margin_deg']:.1f} deg.")
    rep.section("(c) Course autopilot on the EKF estimates (paper Figs. 4-6)")
    rep.image("fig4_north_east.png", "Fig. 4: North-East positions").image("fig5_propellers.png", "Fig. 5: propellers")
    rep.image("fig6_sog_cog_rate.png", "Fig. 6: SOG, COG and course rate")
    rep.add(md_table({f"segment {k} (to {m['target_deg']:.0f} deg)": m for k, m in enumerate(res.metrics)},
                     ("rise_time_s", "overshoot_deg", "settling_time_s", "steady_state_error_deg", "iae_deg_s")))
    rep.add("Sensitivity to GNSS noise and autopilot bandwidth (one seed):", md_table(sens))
    rep.add("With the MSS bandwidth (wn = 1.5 rad/s) the loop needs near-RTK positions; with metre-class GNSS noise "
            "the course and course-rate estimates are too noisy for it and the bandwidth must come down.")
    rep.section("(a) Estimation errors against the truth (after 5 s)")
    rep.add(md_table(table_a), f"Online EKF step in the loop vs batch filter on the same GNSS record: max |chi "
            f"difference| = {online_vs_batch:.2e} rad.")
    rep.section("(b) Real USV logs: substitute vessel in the slow-speed regime (paper Figs. 7-11)")
    if table_b:
        rep.add("The paper's experiments (Mariner and Otter USVs in the Trondheim fjord, Figs. 7-11) are not "
                "available; the Fuzhou USV logs stand in for them. They are another, unidentified small "
                "twin-propeller USV, logged at 2 Hz and sailing at "
                + ", ".join(f"{r['log_sog_p5_mps']:.2f}-{r['log_sog_p95_mps']:.2f} m/s ({n})" for n, r in table_b.items())
                + ": entirely below the ~1 m/s above which the paper finds GNSS SOG/COG good, i.e. in the "
                "low-speed regime of its caveat (Figs. 8 and 11: less accurate at very low speeds). The numbers "
                "below are therefore a low-speed check, not a reproduction of Figs. 7-11.")
        rep.add(md_table(table_b))
        rep.add("The log's `zcourse` column is taken as its course over ground and `speed` as its SOG; the speed "
                "of the logged positions is about 0.51-0.55 times the `speed` column, so the column is in knots "
                "and is converted. The log course follows the log heading closely while the course of the "
                "positions differs from both: the log course is probably heading-aided, so the EKF course (from "
                "positions only) is compared with the differenced positions as well. The EKF's process noise is "
                "estimated by maximum likelihood on each record (R fixed at 0.5 m). The EKF course lags the log "
                "course by a few seconds (`best_lag_of_positions_s`); after that shift the median difference is "
                "the crab angle plus noise.")
        rep.add(*[f"![{n}](real_{Path(n).stem}.png)" for n in fits])
    else:
        rep.add("Skipped: no measured-data folder (give `--data DIR` or set `CASSHIP_DATA`).")
    rep.departures(deps)
    rep.write(out)
    summary = {"vessel": otter_source, "speed_mps": speed, "command_back_s": float(back),
               "nomoto": design.nomoto.as_dict(), "gains": design.gains.as_dict(), "margins": design.margins,
               "closed_loop": res.metrics, "estimation": table_a, "online_vs_batch_max_chi_diff_rad": online_vs_batch,
               "sensitivity": sens, "headline": head["numbers"], "real_data": table_b or "skipped: no measured data",
               "departures": [d.__dict__ for d in deps], "figures": sorted(p.name for p in out.glob("*.png"))}
    for _ in stages:
        pass
    return write_json(out / "summary.json", summary)


STUDY = Study("fossen2021", "Fossen & Fossen 2021: SOG/COG EKF (NE, lat/lon, real USV logs), Otter course autopilot",
              run)
