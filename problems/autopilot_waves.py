"""Course changes and rudder activity in waves with and without Fossen's wave filter (KVLCC2, Otter).

First-order wave-induced yaw (:class:`casship.autopilot.WaveYaw`: a narrow resonant process at the
encounter frequency, Fossen 2021, Sec. 10.2.4) is added to the measured heading and yaw rate of a
heading autopilot (compass + rate gyro, casship's defaults). Without the wave filter the heading
observer takes the wave yaw for ship motion and the rudder chases it; with the wave model in the
observer (:func:`casship.autopilot.heading_observer` with ``wave``) the autopilot steers on the
low-frequency heading. Both runs make the standard course changes (20 deg and back) in the same
waves (same seed); reported are the course-change checks and, over the last quarter (course
keeping), the heading error, rudder RMS, rudder rate RMS, rudder travel and the fraction of time
the steering gear is at its rate limit (IMO MSC.64(67) Annex 3, 3.4: no unnecessary rudder
activity due to normal yaw motion).

The full run makes the 20, 60 and 90 deg changes (and back) with two noise seeds per case; each
design is made for the sea it sails in (``wave_w0``, ``wave_std``, ``wave_filter``: the wave yaw's
spectrum enters the steering-noise budget, and the margins are those of the loop with the wave
filter when it is on). The Otter is casship's default (with the Munk moment: course-unstable). Each
sea's heading-error floor (:func:`casship.autopilot.heading_error_floor`: no autopilot on compass and
gyro holds the heading better) is reported next to the heading error of the runs.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from casship import autopilot as ap
from casship.models import get_model
from casship.progress import progress

from . import Study
from .kit import Departure, Report, figure, md_table, run_cases, write_json

#: Encounter frequency [rad/s] and standard deviation of the wave yaw [deg] (a moderate sea).
WAVES = {"kvlcc2": (0.6, 1.0), "otter": (2.5, 3.0)}
LAMBDA = 0.1


def wave_yaw(name: str) -> ap.WaveYaw:
    w0, std_deg = WAVES[name]
    return ap.WaveYaw(w0, np.radians(std_deg) / np.sqrt(LAMBDA * w0), LAMBDA)


def design_for(name: str, wave_filter: bool):
    """The default design of ``name`` for the study's sea, with or without the wave filter, and the
    warnings it gave (e.g. :class:`casship.autopilot.WaveBudgetWarning`)."""
    import warnings

    w0, std_deg = WAVES[name]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = ap.design_autopilot(get_model(name), wave_w0=w0, wave_std=float(np.radians(std_deg)),
                                wave_filter=wave_filter)
    return d, [str(w.message) for w in caught]


def run_case(case: dict) -> dict:
    """One design and its runs (module level, for worker processes)."""
    from scipy.signal import welch

    d, notes = design_for(case["ship"], case["filter"])
    runs = []
    for change in case["changes"]:
        for seed in case["seeds"]:
            res = d.simulate(f"course-{change}", wave=wave_yaw(case["ship"]), seed=seed, warn=False)
            keep = ap.course_keeping_metrics(res.data, controlled="psi", start=0.75 * res.data.t[-1])
            runs.append({"change": change, "seed": seed, "overshoot_pct": [m["overshoot_pct"] for m in res.metrics],
                         "steady_error_deg": [m["steady_state_error_deg"] for m in res.metrics], "keeping": keep,
                         "rate_limited_fraction": res.performance["rate_limited_fraction"], "res": res})
    res = runs[0]["res"]
    f, psd = welch(res.data["steer_cmd"], fs=1.0 / d.settings.dt, nperseg=min(4096, len(res.data) // 4))
    s, mg = d.settings, d.margins
    for r in runs:
        r.pop("res")
    floor = float(np.degrees(ap.heading_error_floor(d, wave_yaw(case["ship"]))))
    return {"ship": case["ship"], "filter": case["filter"], "runs": runs, "notes": notes, "floor_deg": floor,
            "design": {"wn": s.wn, "wn_ref": s.wn_ref, "Kp": d.gains.Kp, "Kd": d.gains.Kd, "Ki": d.gains.Ki,
                       "observer_q": list(s.observer_q), "phase_margin_deg": mg["phase_margin_deg"],
                       "upper_gain_margin_db": mg["upper_gain_margin_db"], "steer_max": s.steer_max},
            "t": res.data.t, "steer": res.data["steer"], "psi": res.data["psi"], "psi_wave": res.data["psi_wave"],
            "psd_f": f, "psd": psd, "steer_unit": "N m" if d.plant.steer == "tau_N" else "rad"}


def _plots(out: Path, name: str, rows: list):
    with figure(out / f"{name}_waves.png", 3, 1, figsize=(9, 9)) as (fig, axes):
        _draw(fig, axes, name, rows)


def _draw(fig, axes, name, rows):
    w0 = WAVES[name][0]
    for r in rows:
        label = "wave filter" if r["filter"] else "no wave filter"
        scale = 1.0 if r["steer_unit"] == "N m" else float(np.degrees(1.0))
        axes[0].plot(r["t"], np.degrees(r["psi"]), lw=0.8, label=label)
        axes[1].plot(r["t"], scale * r["steer"], lw=0.6, label=label)
        axes[2].semilogy(2 * np.pi * r["psd_f"], r["psd"], lw=0.8, label=label)
    axes[2].axvline(w0, color="k", ls=":", lw=0.8, label="wave peak")
    unit = "N m" if rows[0]["steer_unit"] == "N m" else "deg"
    axes[0].set_ylabel("heading [deg]")
    axes[1].set_ylabel(f"steering [{unit}]")
    axes[1].set_xlabel("time [s]")
    axes[2].set_xlabel("frequency [rad/s]")
    axes[2].set_ylabel(f"command PSD [{'(N m)^2' if unit == 'N m' else 'rad^2'} s]")
    for a in axes:
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"{name}: heading autopilot in waves (wave yaw std {WAVES[name][1]:g} deg at {w0:g} rad/s)")


def run(out: Path, quick: bool = False, workers=None, scheduler=None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ships = ["otter"] if quick else ["kvlcc2", "otter"]
    changes, seeds = ((20,), (1,)) if quick else ((20, 60, 90), (1, 2))
    stages = progress(["designs and runs with and without the wave filter", "tables and figures"], "autopilot-waves")
    next(stages)
    cases = [{"ship": s, "filter": f, "changes": changes, "seeds": seeds} for s in ships for f in (False, True)]
    results = run_cases(run_case, cases, workers=workers, scheduler=scheduler)
    next(stages)
    table, overshoots = [], []
    for r in results:
        first = r["runs"][0]
        k = first["keeping"]
        table.append({"ship": r["ship"], "wave_filter": r["filter"],
                      "overshoot_pct": first["overshoot_pct"], "steady_error_deg": first["steady_error_deg"],
                      "heading_error_rms_deg": k["error_rms_deg"], "heading_floor_deg": r["floor_deg"],
                      "steer_rms": k["steer_rms"],
                      "steer_rms_of_limit": k["steer_rms"] / r["design"]["steer_max"],
                      "steer_rate_rms": k["steer_rate_rms"], "steer_travel": k["steer_travel"],
                      "rate_limited_fraction": first["rate_limited_fraction"], "steer_unit": r["steer_unit"],
                      "phase_margin_deg": r["design"]["phase_margin_deg"],
                      "upper_gain_margin_db": r["design"]["upper_gain_margin_db"], "wn": r["design"]["wn"],
                      "notes": r["notes"]})
        for run_ in r["runs"]:
            worst = max(run_["overshoot_pct"])
            overshoots.append({"ship": r["ship"], "wave_filter": r["filter"], "change_deg": run_["change"],
                               "seed": run_["seed"], "overshoot_pct": run_["overshoot_pct"], "worst_pct": worst,
                               "met": bool(worst <= ap.CRITERIA["overshoot_pct"][0])})
    for s in ships:
        _plots(out, s, [r for r in results if r["ship"] == s])
    rows = [{k: (", ".join(f"{x:.2f}" for x in v) if isinstance(v, list) else v) for k, v in r.items() if k != "notes"}
            for r in table]
    rep = Report("Heading autopilot in waves: course changes with and without the wave filter", quick=quick)
    rep.add("Each design is made for the sea it sails in (the wave yaw's spectrum in the steering-noise budget; "
            "with the wave filter, the margins of the loop with the filter in it). Course keeping over the last "
            "quarter of the first run (seed 1, the first change); steering in rad (KVLCC2 rudder) or N m (Otter "
            "yaw moment), its RMS also as a fraction of the steering limit. heading_floor_deg is the heading error "
            "no autopilot on compass and gyro gets below in this sea (casship.autopilot.heading_error_floor: the "
            "Kalman-Bucy error of the low-frequency heading on the exact linearisation with the wave model).")
    rep.add(md_table(rows, ["ship", "wave_filter", "wn", "phase_margin_deg", "upper_gain_margin_db", "overshoot_pct",
                            "heading_error_rms_deg", "heading_floor_deg", "steer_rms", "steer_rms_of_limit",
                            "steer_rate_rms",
                            "rate_limited_fraction"], spec=".3g"))
    rep.add("Overshoot of every course change (both changes of each run; the line is 10 % of the change):")
    rep.add(md_table([{**o, "overshoot_pct": ", ".join(f"{x:.1f}" for x in o["overshoot_pct"])} for o in overshoots],
                     ["ship", "wave_filter", "change_deg", "seed", "overshoot_pct", "met"], spec=".3g"))
    for r in table:
        for note in r["notes"]:
            rep.add(f"Design note ({r['ship']}, wave filter {'on' if r['wave_filter'] else 'off'}): {note}")
    for s in ships:
        rep.image(f"{s}_waves.png", f"{s} in waves")
    rep.departures([
        Departure("wave spectrum", "Fossen (2021, Sec. 10.2.4): a linear second-order approximation of the wave "
                  "spectrum, damping lambda about 0.1, peak at the encounter frequency",
                  f"lambda = {LAMBDA}; KVLCC2 {WAVES['kvlcc2'][0]} rad/s, {WAVES['kvlcc2'][1]} deg; Otter "
                  f"{WAVES['otter'][0]} rad/s, {WAVES['otter'][1]} deg (moderate seas, chosen)",
                  "not measured: the comparison with and without the filter is made in the same waves"),
        Departure("wave parameters in the filter", "estimated on line (frequency tracking) or set by hand",
                  "the filter knows the simulated w0 and lambda exactly", "not measured: a best case for the filter")])
    rep.write(out)
    summary = write_json(out / "summary.json", {"table": table, "overshoots": overshoots,
                                                 "figures": sorted(p.name for p in out.glob("*.png"))})
    next(stages, None)
    return summary


STUDY = Study("autopilot-waves", "Course changes and rudder activity of a heading autopilot in first-order waves "
              "with and without Fossen's wave filter (KVLCC2, Otter)", run)
