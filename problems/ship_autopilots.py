"""Ship course autopilots designed on Nomoto models identified from simulated zig-zags.

For the KVLCC2 tanker (full scale, 15.5 kn) and the Mariner-class cargo ship (15 kn):

1. simulate 10/10 and 20/20 (port first) zig-zags on the full nonlinear model, measure the heading
   with noise, and fit a first-order Nomoto model (K, T and a rudder bias) by maximum likelihood
   (:func:`casship.autopilot.fit_nomoto`); compare with the Nomoto model of the exact linearisation;
2. design a PID by Fossen's pole placement and an LQR with integral action on the identified model
   with casship's defaults (:func:`casship.autopilot.design_autopilot`: bandwidth, reference model,
   estimator tuning derived from the ship and the sensors); margins by python-control on the
   linearised ship with the steering gear, the sensor delay and the estimator in the loop;
3. validate on the full nonlinear model with wind (Fujiwara loads, 5 m/s) for 20 and 60 deg course
   changes, as heading control (compass + rate gyro into the heading observer) and as course control
   (GNSS into the SOG/COG EKF);
4. robustness: hull and rudder parameters of the truth model off by +-20 % and wind 10 m/s;
5. Monte Carlo over sensor-noise seeds and speeds (80 %, 100 %, 120 % of the design speed) of the
   design from the linearisation with the API defaults.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

import casship as cs
from casship import autopilot as ap
from casship.autopilot.montecarlo import monte_carlo
from casship.maneuvers import run_maneuver
from casship.models import get_model
from casship.models.wind import add_wind
from casship.parallel import run_cases
from casship.progress import progress

from . import Study
from .kit import Departure, Report, figure, write_json

# Parameters perturbed by +-20 % in the robustness cases (those that set the Nomoto K and T).
SHIPS = {
    "mariner": {"perturb": ["Yv", "Yr", "Nv", "Nr", "Yd", "Nd"],
                # Mariner-class wind geometry (not published; estimates for a 161 m general cargo ship)
                "wind": {"A_F": 450.0, "A_L": 2100.0, "L_OA": 171.8, "B": 23.2, "A_OD": 700.0, "H_BR": 28.0,
                         "H_C": 9.0, "C": 0.0}},
    "kvlcc2": {"perturb": ["Y_v_dash", "Y_r_dash", "N_v_dash", "N_r_dash", "f_alpha"], "wind": None},
}
WIND_NOMINAL = (5.0, np.radians(45.0))      # speed [m/s], direction it comes from
WIND_ROBUST = (10.0, np.radians(45.0))
HEADING_NOISE = np.radians(0.2)            # heading measurement noise of the zig-zag records
STABLE_ERROR_DEG = 5.0


def ship_model(name: str):
    """The registered ship with Fujiwara wind loads (inputs ``wind_speed``, ``wind_dir``), and the ship."""
    base = get_model(name)
    return add_wind(base, SHIPS[name]["wind"]), base


def identify(name: str, seed: int = 0):
    """Zig-zags on the nonlinear ship and the Nomoto fit; also the linearised Nomoto model."""
    _, base = ship_model(name)
    rng = np.random.default_rng(seed)
    records, overshoots = [], {}
    for rudder in (10.0, -20.0):
        res = run_maneuver(base, "zigzag", rudder_deg=rudder, heading_deg=abs(rudder))
        tr = res.trajectory
        t = np.arange(tr.t[0], tr.t[-1], 1.0)                     # heading sampled at 1 Hz
        psi = np.interp(t, tr.t, tr["psi"]) + HEADING_NOISE * rng.standard_normal(t.size)
        records.append(cs.Dataset(t, {"delta": np.interp(t, tr.t, tr["delta"]), "psi": psi}))
        overshoots[f"{abs(rudder):.0f}/{abs(rudder):.0f}"] = res.metrics.get("overshoot_1_deg")
    nom_fit, fit = ap.fit_nomoto(records, heading_var=HEADING_NOISE**2, guess=ap.Nomoto(0.1, 100.0))
    plant = ap.steering_plant(base)
    linear = ap.nomoto_from_linear(ap.course_linearization(plant))
    return {"fit": nom_fit, "fit_std": fit.std_errors, "linear": linear, "records": records,
            "zigzag_overshoot_1_deg": overshoots}


def design(name: str, nomoto: ap.Nomoto, method: str = "pid", mode: str = "heading") -> ap.Design:
    """Autopilot for the ship (wind model, calm water) on the given Nomoto model, casship's defaults."""
    model, _ = ship_model(name)
    return ap.design_autopilot(model, nomoto=nomoto, method=method, mode=mode)


def run_case(case: dict) -> dict:
    """One closed-loop run (module level, so that cases run in worker processes)."""
    d = design(case["ship"], ap.Nomoto(**case["nomoto"]), case["method"], case["mode"])
    truth_p = d.plant.model.params(d.plant.pvec)
    for pname in case.get("perturb", []):
        truth_p[d.plant.model.index(pname, "param")] *= 1.0 + case["scale"]
    env = {"wind_speed": case["wind"][0], "wind_dir": case["wind"][1]}
    truth = d.plant.replace(inputs=env, p=truth_p)
    command, t_end, steps = ap.course_scenario(f"course-{case['angle']:g}", segment=d.settings.segment)
    row = {k: v for k, v in case.items() if k != "nomoto"}
    try:
        res = ap.simulate_autopilot(d, command, t_end, step_times=steps, plant=truth, seed=case["seed"], warn=False)
    except FloatingPointError as exc:
        return {**row, "stable": False, "error": str(exc), "metrics": [], "rate_limited_fraction": float("nan")}
    # stable: bounded, settled near the command over the last 10 % of every segment, and the
    # steering off its limit there (a loop that holds the course only at full rudder has lost authority)
    t, steer = res.data.t, np.abs(res.data["steer"])
    bounds = list(steps) + [t[-1] + 1.0]
    end_free = []
    for t0, t1 in zip(bounds[:-1], bounds[1:]):
        tail = (t >= t0 + 0.9 * (min(t1, t[-1]) - t0)) & (t < t1)
        end_free.append(bool(steer[tail].max() < d.actuator.steer_max - 1e-9))
    stable = all(abs(m["steady_state_error_deg"]) < STABLE_ERROR_DEG for m in res.metrics) and all(end_free)
    out = {**row, "stable": stable, "metrics": res.metrics,
           "rate_limited_fraction": res.performance["rate_limited_fraction"]}
    if case.get("keep"):
        out["data"] = {k: res.data[k] for k in ("chi", "psi", "chi_hat", "chi_d", "ref", "steer", "north", "east")}
        out["t"] = res.data.t
    return out


def _cases(ship: str, nomoto: ap.Nomoto, quick: bool, linear: ap.Nomoto | None = None) -> list:
    base = dict(ship=ship, nomoto={"K": nomoto.K, "T": nomoto.T, "source": nomoto.source}, perturb=[], scale=0.0,
                wind=WIND_NOMINAL, mode="heading", method="pid", seed=7)
    cases = [dict(base, case="nominal", angle=20.0, keep=True), dict(base, case="nominal", angle=20.0, mode="course")]
    if not quick:
        cases += [dict(base, case="nominal", angle=60.0, keep=True),
                  dict(base, case="nominal", angle=60.0, mode="course"),
                  dict(base, case="nominal", angle=20.0, method="lqr"),
                  dict(base, case="nominal", angle=60.0, method="lqr")]
        if linear is not None:
            lin = {"K": linear.K, "T": linear.T, "source": linear.source}
            cases += [dict(base, case="nominal, designed on the linearisation", nomoto=lin, angle=a)
                      for a in (20.0, 60.0)]
    for scale in ((0.2, -0.2) if not quick else (-0.2,)):
        for angle in ((20.0, 60.0) if not quick else (60.0,)):
            cases.append(dict(base, case=f"params {scale:+.0%}, wind 10 m/s", perturb=SHIPS[ship]["perturb"],
                              scale=scale, wind=WIND_ROBUST, angle=angle, keep=angle == 60.0))
    return cases


def _fmt(v, nd=3):
    if isinstance(v, bool):
        return "yes" if v else "NO"
    if isinstance(v, (float, np.floating)):
        return "nan" if not np.isfinite(v) else f"{v:.{nd}g}"
    return str(v)


def _plots(out: Path, ship: str, designs: dict, results: list):
    d = designs["pid"]
    ap.plot_design(d.loop, out / f"{ship}_loop_bode_step.png", f"{ship}: PID loop (identified Nomoto gains, "
                   "linearised ship)", d.closed_loop)
    kept = [r for r in results if "data" in r and r["ship"] == ship]
    with figure(out / f"{ship}_course_changes.png", 2, 1, figsize=(9, 7), sharex=True) as (fig, axes):
        _draw_course_changes(fig, axes, ship, kept)


def _draw_course_changes(fig, axes, ship: str, kept: list) -> None:
    for r in kept:
        label = f"{r['case']}, {r['angle']:.0f} deg ({r['method']})"
        axes[0].plot(r["t"], np.degrees(np.unwrap(r["data"]["psi"])), label=label)
        axes[1].plot(r["t"], np.degrees(r["data"]["steer"]), lw=0.8, label=label)
    for r in kept[:1]:
        axes[0].plot(r["t"], np.degrees(r["data"]["ref"]), "k:", lw=0.8, label="command (20 deg)")
    axes[0].set_ylabel("heading [deg]")
    axes[1].set_ylabel("rudder [deg]")
    axes[1].set_xlabel("time [s]")
    axes[0].legend(fontsize=7)
    for a in axes:
        a.grid(alpha=0.3)
    fig.suptitle(f"{ship}: heading changes on the nonlinear model with wind (compass, gyro, observer in the loop)")


def _design_rows(s: str, ident: dict, designs: dict) -> dict:
    rows = {}
    for method, d in designs.items():
        mg = d.margins
        on_model = ap.margins(ap.loop_transfer(d.nomoto, d.gains, actuator_T=d.settings.actuator_T,
                                               delay=d.settings.delay, order=1))
        rows[f"{s} {method}"] = {
            "wn_rad_s": d.settings.wn, "Kp": d.gains.Kp, "Kd_s": d.gains.Kd, "Ki_1_s": d.gains.Ki,
            "PM_deg": mg["phase_margin_deg"], "GM_upper_dB": mg["upper_gain_margin_db"],
            "GM_lower_dB": mg["lower_gain_margin_db"], "GM_control_dB": mg["gain_margin_db"],
            "meets_GM6_PM45": bool(mg["upper_gain_margin_db"] > 6 and mg["phase_margin_deg"] > 45
                                   and mg["closed_loop_stable"]),
            "PM_deg_on_design_model": on_model["phase_margin_deg"]}
    return rows


def run(out: Path, quick: bool = False, workers=None, scheduler=None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ships = ["mariner"] if quick else list(SHIPS)
    stages = progress(["zig-zags and Nomoto fits", "designs and margins", "closed-loop runs",
                       "Monte Carlo over noise seeds and speeds", "tables and figures"], "ship-autopilots")
    next(stages)
    ident = {s: identify(s) for s in ships}
    next(stages)
    designs, margin_rows, nomoto_rows = {}, {}, {}
    for s in ships:
        lin, fit = ident[s]["linear"], ident[s]["fit"]
        nomoto_rows[f"{s} (zig-zag fit)"] = {"K_1_s": fit.K, "T_s": fit.T, "K_std": ident[s]["fit_std"]["K"],
                                             "T_std": ident[s]["fit_std"]["T"], "T1_s": float("nan"),
                                             "T2_s": float("nan"), "T3_s": float("nan")}
        nomoto_rows[f"{s} (linearisation)"] = {"K_1_s": lin.K, "T_s": lin.T, "K_std": float("nan"),
                                               "T_std": float("nan"), "T1_s": lin.T1, "T2_s": lin.T2, "T3_s": lin.T3}
        designs[s] = {m: design(s, fit, m) for m in ("pid", "lqr")}
        margin_rows.update(_design_rows(s, ident[s], designs[s]))
    next(stages)
    cases = [c for s in ships for c in _cases(s, ident[s]["fit"], quick, ident[s]["linear"])]
    results = run_cases(run_case, cases, workers=workers, scheduler=scheduler)
    next(stages)
    mc = {}
    for s in ships:
        U = float(get_model(s).vessel.U0)
        seeds = range(2 if quick else 6)
        speeds = [U] if quick else [0.8 * U, U, 1.2 * U]
        mc[s] = monte_carlo(s, seeds, speeds, workers=workers, scheduler=scheduler)["summary"]
    next(stages)
    table = []
    for r in results:
        for k, m in enumerate(r["metrics"]):
            table.append({"ship": r["ship"], "case": r["case"], "method": r["method"], "mode": r["mode"],
                          "segment": f"{'to' if k == 0 else 'back'} {m['target_deg']:.0f} deg",
                          "rise_s": m.get("rise_time_s"), "overshoot_pct": m.get("overshoot_pct"),
                          "settling_s": m.get("settling_time_s"), "ss_error_deg": m["steady_state_error_deg"],
                          "max_rudder_deg": np.degrees(m["steer_max_abs"]),
                          "rate_limited": m.get("rate_limited_fraction"), "stable": r["stable"]})
        if not r["metrics"]:
            table.append({"ship": r["ship"], "case": r["case"], "method": r["method"], "mode": r["mode"],
                          "segment": r.get("error", ""), "stable": False})
    for s in ships:
        _plots(out, s, designs[s], results)
    _report(nomoto_rows, margin_rows, table, mc, quick).write(out)
    summary = {"nomoto": nomoto_rows, "designs": margin_rows, "closed_loop": table, "monte_carlo": mc,
               "all_stable": all(r["stable"] for r in results),
               "all_margins_met": all(v["meets_GM6_PM45"] for v in margin_rows.values()),
               "zigzag_overshoot_1_deg": {s: ident[s]["zigzag_overshoot_1_deg"] for s in ships},
               "figures": sorted(p.name for p in out.glob("*.png"))}
    summary = write_json(out / "summary.json", summary)
    for _ in stages:
        pass
    return summary


def _report(nomoto_rows, margin_rows, table, mc, quick) -> Report:
    md = ["Nomoto models: first order, fitted by maximum likelihood to simulated 10/10 and 20/20 zig-zags "
          f"(heading noise {np.degrees(HEADING_NOISE):.1f} deg at 1 Hz), and from the exact linearisation at "
          "the approach speed. The zig-zag fit has a much smaller K and T than the linearisation (nonlinear "
          "yaw damping at large rates) but nearly the same K/T, i.e. the same rudder effectiveness.", "",
          "| model | K [1/s] | T [s] | std K | std T | T1 [s] | T2 [s] | T3 [s] |", "|---|---|---|---|---|---|---|---|"]
    md += [f"| {k} | " + " | ".join(_fmt(v[c], 4) for c in ("K_1_s", "T_s", "K_std", "T_std", "T1_s", "T2_s", "T3_s"))
           + " |" for k, v in nomoto_rows.items()]
    md += ["", "Designs with casship's defaults on the fitted model (bandwidth, reference model and estimator tuning "
           "from the ship and the sensors; see docs/autopilots.md). Margins by python-control on the linearised "
           "ship with the steering servo, the sensor delay and the heading observer in the loop; 'GM control' is "
           "the one `control.margin` reports (the one nearest 0 dB), upper/lower are both crossings; the last "
           "column is the phase margin on the first-order design model:", "",
           "| design | wn [rad/s] | Kp | Kd [s] | Ki [1/s] | PM [deg] | GM upper [dB] | GM lower [dB] | GM control [dB] "
           "| GM > 6 dB, PM > 45 deg | PM on design model |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    md += [f"| {k} | " + " | ".join(_fmt(x) for x in v.values()) + " |" for k, v in margin_rows.items()]
    md += ["", f"Closed-loop runs on the full nonlinear model with Fujiwara wind ({WIND_NOMINAL[0]:.0f} m/s nominal, "
           f"{WIND_ROBUST[0]:.0f} m/s in the robustness cases, from 45 deg); heading mode: compass (10 Hz, 0.5 deg) "
           "and rate gyro into the heading observer; course mode: GNSS (5 Hz, 0.5 m) into the SOG/COG EKF. Rudder "
           "limit and rate limit of the ship's steering gear (first-order servo, 1 s). Stable = within "
           f"{STABLE_ERROR_DEG:g} deg of the command with the rudder off its limit over the last 10 % of every "
           "segment; 'rate limited' = fraction of the segment with the steering gear at its rate limit.", "",
           "| ship | case | method | mode | segment | rise [s] | overshoot [%] | settling [s] | ss error [deg] | "
           "max rudder [deg] | rate limited | stable |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    md += ["| " + " | ".join(_fmt(row.get(k, "")) for k in ("ship", "case", "method", "mode", "segment", "rise_s",
                                                            "overshoot_pct", "settling_s", "ss_error_deg",
                                                            "max_rudder_deg", "rate_limited", "stable")) + " |"
           for row in table]
    md += ["", "Monte Carlo (design from the linearisation, API defaults, calm water) over sensor-noise seeds and "
           "ship speeds (design at the approach speed):", "",
           "| ship | speed [m/s] | runs | overshoot max [%] | overshoot mean [%] | max steady error [deg] | "
           "max rate-limited fraction |", "|---|---|---|---|---|---|---|"]
    for s, rows in mc.items():
        for v, r in rows.items():
            md.append(f"| {s} | {v} | {r['runs']} | {_fmt(r['overshoot_pct_max'])} | {_fmt(r['overshoot_pct_mean'])} | "
                      f"{_fmt(r['steady_error_deg_max'])} | {_fmt(r['rate_limited_fraction_max'])} |")
    rep = Report("Ship course autopilots on Nomoto models identified from zig-zags", quick=quick)
    rep.add("\n".join(md))
    pid = [v for k, v in margin_rows.items() if k.endswith("pid")][0]
    rep.departures([
        Departure("design model of the PID", "Fossen (2021, Sec. 15.3.4): pole placement on the first-order Nomoto "
                  "model; MSS SIMmariner: wn = 0.05 rad/s, Ki = wn/10 Kp",
                  "gains on the zig-zag fit with casship's bandwidth rule; margins on the linearised ship with the "
                  "servo, the sensor delay and the heading observer",
                  f"phase margin {pid['PM_deg']:.1f} deg on the linearised ship against "
                  f"{pid['PM_deg_on_design_model']:.1f} deg on the first-order design model (first PID row)"),
        Departure("sensors and steering gear", "not part of the design rule", "compass 0.5 deg at 10 Hz, rate gyro "
                  "0.02 deg/s, GNSS 0.5 m at 5 Hz; 1 s servo with the ship's rudder rate limit",
                  "not measured here (the Monte Carlo table varies the noise seed and the speed)")])
    return rep


STUDY = Study("ship-autopilots", "KVLCC2 and Mariner course autopilots on Nomoto models identified from zig-zags, "
              "validated with wind and +-20 % model error, Monte Carlo over noise and speed", run)
