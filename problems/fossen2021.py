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

import json
from pathlib import Path

import casadi as ca
import numpy as np

import casship as cs
from casship import autopilot as ap
from casship.identify import MLEProblem
from casship.models import get_model, sog_cog, sog_cog_latlon
from casship.progress import progress

from . import DATA_DIR, Study

# Surge force [N]: 120 N gives about 1.5 m/s on this model, above the 1 m/s that the paper names as
# the speed from which GNSS SOG/COG are good (MSS exOtter uses 40 N, about 0.5 m/s here).
TAU_X = 120.0
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


def part_c(otter, quick, *, wn=WN, gnss_std=GNSS_STD, seed=3):
    """Otter course autopilot on the EKF estimates (the closed loop of parts a and c)."""
    steer_model = ap.steering_model(otter, ["tau_X", "tau_N"], ap.twin_propeller_allocation(otter), name="otter_tau")
    tr = cs.trim(steer_model, x={"u": 1.0}, u={"tau_X": TAU_X}, free=["u"], zero=["u"])
    speed = tr.values["u"]
    tau_n_max = ap.twin_propeller_yaw_limit(otter, TAU_X)       # keeps both propellers in range
    design = ap.design_autopilot(steer_model, speed, steer="tau_N", inputs={"tau_X": TAU_X}, wn=wn, zeta=ZETA,
                                 wn_ref=min(WN_D, wn), r_max=R_MAX, steer_max=tau_n_max, steer_rate_max=np.inf,
                                 actuator_T=0.1, delay=1.0 / GNSS_RATE, mode="course", rate="estimator", dt=DT,
                                 gnss_rate=GNSS_RATE, gnss_std=gnss_std, ekf_q=EKF_Q, ekf_alpha=EKF_ALPHA)
    command, t_end, steps = ap.course_scenario("course-20", 50.0 if not quick else 40.0)
    res = ap.simulate_autopilot(design, command, t_end, step_times=steps, seed=seed)
    # propeller rates from the allocation
    tx, tn = ca.SX.sym("tx"), ca.SX.sym("tn")
    p_sym = {n: ca.SX(v) for n, v in otter.param_dict().items()}
    n_expr = ap.twin_propeller_allocation(otter)({"tau_X": tx, "tau_N": tn}, p_sym)
    nfun = ca.Function("alloc", [tx, tn], [n_expr["n1"], n_expr["n2"]]).map(len(res.data))
    n1, n2 = (np.ravel(np.array(v)) for v in nfun(TAU_X, res.data["steer"]))
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
        # SOG and COG start from the displacement over the first 5 s (like MSS's x_prd_init): a prior
        # of U = 0, chi = 0 can converge to the mirror solution U < 0, chi + 180 deg.
        north, east = cs.frames.latlon_to_ne(lat, lon, lat[0], lon[0])
        k5 = int(np.searchsorted(t, t[0] + 5.0))
        U0 = float(np.hypot(north[k5], east[k5]) / (t[k5] - t[0]))
        chi0 = float(np.arctan2(east[k5], north[k5]))
        prior = cs.Gaussian(np.array([lat[0], lon[0], U0, chi0, 0.0]),
                            np.diag([(std * r_lat) ** 2, (std * r_lon) ** 2, 0.25, np.radians(30) ** 2, 0.01]))
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
            "Q_w_U_mle": float(Qf[0, 0]), "Q_w_chi_mle": float(Qf[1, 1]),
            "position_speed_over_log_speed": ratio,
            "sog_rmse_vs_log_mps": rms(U_err), "sog_bias_vs_log_mps": float(np.mean(U_err)),
            "sog_rmse_vs_differenced_mps": rms(res["U"][skip] - sog_diff[skip]),
            "cog_rmse_vs_log_deg": rms(chi_err), "cog_median_abs_vs_log_deg": float(np.median(np.abs(chi_err))),
            "cog_bias_vs_log_deg": float(np.mean(chi_err)),
            "cog_rmse_vs_differenced_deg": rms(np.degrees(cs.wrap(res["chi"][moving] - cog_diff[moving]))),
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


def _plots(out: Path, design, res, n12, res_ll, fits):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = res.data
    t = d.t
    # Fig. 4: North-East positions
    fig, ax = plt.subplots(figsize=(6, 5))
    ax.plot(d["east"], d["north"], label="true")
    ok = np.isfinite(d["gnss_north"])
    ax.plot(d["gnss_east"][ok], d["gnss_north"][ok], ".", ms=2, alpha=0.6, label="GNSS (5 Hz)")
    ax.set_xlabel("East [m]")
    ax.set_ylabel("North [m]")
    ax.set_title("Otter: 20 deg course command, back to 0 deg at t = 20 s")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "fig4_north_east.png", dpi=110)
    plt.close(fig)
    # Fig. 5: propeller revolutions
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ax.plot(t, n12[0] * 60 / (2 * np.pi), label="n1 (port)")
    ax.plot(t, n12[1] * 60 / (2 * np.pi), label="n2 (starboard)")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("propeller [rpm]")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "fig5_propellers.png", dpi=110)
    plt.close(fig)
    # Fig. 6: SOG, COG, course rate estimates vs truth, with a zoom
    fig, axes = plt.subplots(3, 2, figsize=(11, 8), gridspec_kw={"width_ratios": [3, 1]})
    zoom = (t >= 20.0) & (t <= 21.0)
    series = [("U", "U_hat", 1.0, "SOG [m/s]"), ("chi", "chi_hat", np.degrees(1.0), "COG [deg]"),
              ("omega_chi", "omega_hat", np.degrees(1.0), "course rate [deg/s]")]
    for row, (true, est, sc, label) in enumerate(series):
        for col, sel in enumerate((slice(None), zoom)):
            ax = axes[row, col]
            ax.plot(t[sel], d[true][sel] * sc, label="true")
            ax.plot(t[sel], d[est][sel] * sc, lw=0.8, label="EKF (50 Hz)")
            if row == 1:
                ax.plot(t[sel], d["chi_d"][sel] * sc, "--", lw=0.8, label="desired")
            if col == 1:
                gn = np.isfinite(d["gnss_north"][sel])
                for tt in t[sel][gn]:
                    ax.axvline(tt, color="k", lw=0.4, alpha=0.4)
            ax.grid(alpha=0.3)
        axes[row, 0].set_ylabel(label)
    axes[0, 0].legend(fontsize=8)
    axes[0, 1].set_title("zoom: GNSS fixes (5 Hz) as lines")
    axes[2, 0].set_xlabel("time [s]")
    axes[2, 1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(out / "fig6_sog_cog_rate.png", dpi=110)
    plt.close(fig)
    ap.plot_design(design.loop, out / "otter_loop_bode_step.png", "Otter course loop (linearised Otter)",
                   design.closed_loop)
    # real data
    for fname, (tt, r, raw, cog_log, head_log) in fits.items():
        fig, axes = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
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
        fig.suptitle(f"USV GNSS log {fname}: lat/lon EKF")
        fig.tight_layout()
        fig.savefig(out / f"real_{Path(fname).stem}.png", dpi=110)
        plt.close(fig)


def _md_table(rows: dict, title: str) -> str:
    keys = list(next(iter(rows.values())).keys())
    lines = [f"### {title}", "", "| case | " + " | ".join(keys) + " |", "|---" * (len(keys) + 1) + "|"]
    for name, row in rows.items():
        lines.append(f"| {name} | " + " | ".join(f"{row[k]:.4g}" if isinstance(row[k], float) else str(row[k])
                                                 for k in keys) + " |")
    return "\n".join(lines) + "\n"


def run(out: Path, quick: bool = False, workers=None, scheduler=None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stages = progress(["Otter course autopilot with the EKF in the loop (c)", "EKFs NE and lat/lon (a)",
                       "sensitivity to GNSS noise and bandwidth",
                       "real USV GNSS logs (b)", "figures and tables"], "fossen2021")
    next(stages)
    otter, otter_source = get_model("otter"), "casship.models 'otter' (MSS otter.m, horizontal plane)"
    design, res, n12, speed = part_c(otter, quick)
    next(stages)
    table_a, res_ne, res_ll, online_vs_batch = part_a(res)
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
    next(stages)
    folder = DATA_DIR / "usv_fuzhou_gnss"
    if folder.is_dir():
        table_b, fits = part_b(folder, quick)
        note_b = ""
    else:
        table_b, fits = {}, {}
        note_b = f"skipped: {folder} is absent"
    next(stages)
    _plots(out, design, res, n12, res_ll, fits)
    metrics = res.metrics
    md = ["# Fossen & Fossen (2021): SOG/COG/course-rate EKF and Otter course autopilot", "",
          f"Vessel: {otter_source}; surge force {TAU_X} N gives {speed:.2f} m/s. EKF at {1 / DT:.0f} Hz, "
          f"GNSS at {GNSS_RATE:.0f} Hz with {GNSS_STD} m noise; Q = diag{EKF_Q}, alpha = {EKF_ALPHA}.", "",
          f"Nomoto (from the exact linearisation, yaw moment -> yaw rate): K = {design.nomoto.K:.4g}, "
          f"T = {design.nomoto.T:.4g} s. PID (Fossen's pole placement, wn = {WN}, zeta = {ZETA}): "
          f"Kp = {design.gains.Kp:.4g}, Kd = {design.gains.Kd:.4g}, Ki = {design.gains.Ki:.4g}. Reference model "
          f"wn_d = {WN_D}, r_max = 10 deg/s.", "",
          f"Margins on the design model (with 0.1 s thrust lag and a 0.2 s delay): gain "
          f"{design.margins['gain_margin_db']:.1f} dB, phase {design.margins['phase_margin_deg']:.1f} deg.", "",
          _md_table({f"segment {k} (to {m['target_deg']:.0f} deg)": {kk: m[kk] for kk in
                     ("rise_time_s", "overshoot_deg", "settling_time_s", "steady_state_error_deg", "iae_deg_s")}
                     for k, m in enumerate(metrics)}, "(c) closed-loop course metrics (true course)"),
          _md_table(sens, "(c) sensitivity: GNSS noise and autopilot bandwidth (one seed)"),
          "With the MSS bandwidth (wn = 1.5 rad/s) the loop needs near-RTK positions; with metre-class "
          "GNSS noise the course and course-rate estimates are too noisy for it and the bandwidth must come "
          "down.", "",
          _md_table(table_a, "(a) estimation errors against the truth (after 5 s)"),
          f"Online EKF step in the loop vs batch filter on the same GNSS record: max |chi difference| = "
          f"{online_vs_batch:.2e} rad.", ""]
    if table_b:
        md.append(_md_table(table_b, "(b) real USV logs: lat/lon EKF vs the log's columns"))
        md.append("The log's `zcourse` column is taken as its course over ground and `speed` as its SOG. The "
                  "speed of the logged positions is about 0.51-0.55 times the `speed` column "
                  "(`position_speed_over_log_speed`), i.e. the column is in knots; it is converted to m/s. The log "
                  "course follows the log heading closely (last column) while the course of the positions "
                  "differs from both: the log course is probably heading-aided, so the EKF course (from positions "
                  "only) is compared with the differenced positions as well. The EKF's process noise is "
                  "estimated by maximum likelihood on each record (`MLEProblem`, R fixed at 0.5 m). The EKF "
                  "course lags the log course by a few seconds (`best_lag_of_positions_s`, found by aligning "
                  "them): the logged positions trail the logged heading/course; after that shift the median "
                  "difference is the crab angle plus noise.\n")
    else:
        md.append(f"(b) real USV logs: {note_b}\n")
    (out / "report.md").write_text("\n".join(md))
    summary = {"vessel": otter_source, "speed_mps": speed, "nomoto": design.nomoto.as_dict(),
               "gains": design.gains.as_dict(), "margins": design.margins, "closed_loop": metrics,
               "estimation": table_a, "online_vs_batch_max_chi_diff_rad": online_vs_batch, "sensitivity": sens,
               "real_data": table_b or note_b,
               "figures": sorted(p.name for p in out.glob("*.png"))}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float))
    for _ in stages:
        pass
    return summary


STUDY = Study("fossen2021", "Fossen & Fossen 2021: SOG/COG EKF (NE, lat/lon, real USV logs), Otter course autopilot",
              run)
