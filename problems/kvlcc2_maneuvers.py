"""KVLCC2 (full scale) manoeuvres with the MMG standard method against the MARIN free-running runs.

Manoeuvres (15.5 kn approach, full scale, L_pp = 320 m): 35 deg turning circle, 10/10 and 20/20
zig-zags. For each, three records are compared with the same metric functions
(:mod:`casship.maneuvers`):

* **measured**: the MARIN free-running run (``shared/data/kvlcc2_marin_free``, read by
  :func:`casship.io.read_marin`; rudder sign flipped to the MMG convention);
* **simulated**: :func:`casship.maneuvers.run_maneuver` on :func:`casship.models.kvlcc2` at the
  measured approach speed, the propeller rate solved for equilibrium at that speed, the rudder
  moved at 2.32 deg/s, the first side taken from the measured run;
* **replayed**: :func:`casship.maneuvers.replay` with the measured rudder and propeller rate from
  the measured initial state.

Outputs: ``metrics.md`` (table + IMO MSC.137(76) checks), ``report.md``, ``fig_<run>.png``
(trajectories and headings), ``summary.json``. Without the data folder the study simulates only
and says so. The report's departures table measures what the model's choices (propeller rate,
rudder rate, wake fraction) do to the turning circle.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

import casship as cs
from casship.io import marin_runs, read_marin
from casship.maneuvers import imo_check, imo_table, run_maneuver, turning_metrics, zigzag_metrics
from casship.models import kvlcc2
from casship.progress import progress
from casship.maneuvers import replay

from . import Study
from .kit import Departure, Report, data_folder, effect, write_json

L = 320.0
RUNS = {  # short name -> (kind, rudder deg, switch heading deg, MARIN file key)
    "turning_35": ("turning", 35.0, None, "tc_-35"),
    "zigzag_10": ("zigzag", 10.0, 10.0, "zz_10"),
    "zigzag_20": ("zigzag", 20.0, 20.0, "zz_-20"),
}
METRICS = {
    "turning": ["advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m", "steady_speed_mps",
                "time_to_90_s", "time_to_180_s"],
    "zigzag": ["initial_turning_time_s", "initial_turning_distance_m", "overshoot_1_deg", "overshoot_1_time_s",
               "overshoot_2_deg", "overshoot_2_time_s", "period_s"],
}


def _metrics(data, kind, heading, t_exec):
    if kind == "turning":
        return turning_metrics(data, t_exec=t_exec, L=L)
    return zigzag_metrics(data, heading, t_exec=t_exec, L=L)


def _plot(path, name, records):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(12, 4.8))
    ax1, ax2 = fig.subplots(1, 2)
    styles = {"measured": "k-", "simulated": "C0--", "replayed": "C1-."}
    for label, rec in records.items():
        ax1.plot(rec["y"] - rec["y"][0], rec["x"] - rec["x"][0], styles[label], label=label)
        ax2.plot(rec.t, np.degrees(np.unwrap(rec["psi"]) - np.unwrap(rec["psi"])[0]), styles[label], label=f"heading {label}")
    ref = records.get("measured", records.get("simulated"))
    ax2.plot(ref.t, np.degrees(ref["delta"]), "k:", lw=0.8, label="rudder (measured)" if "measured" in records
             else "rudder")
    ax1.set_xlabel("East y [m]")
    ax1.set_ylabel("North x [m]")
    ax1.set_aspect("equal", adjustable="datalim")
    ax1.legend(fontsize=8)
    ax2.set_xlabel("time [s]")
    ax2.set_ylabel("heading change, rudder [deg]")
    ax2.legend(fontsize=8)
    fig.suptitle(f"KVLCC2 {name.replace('_', ' ')}: MMG standard method vs MARIN free-running")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _fmt(v):
    return "-" if v is None or not np.isfinite(v) else f"{v:.1f}" if abs(v) >= 10 else f"{v:.2f}"


def _differences(name, kind, table):
    """Plain sentences on the largest relative differences simulated vs measured."""
    meas, sim = table.get("measured"), table["simulated"]
    if not meas:
        return []
    lines = []
    for key in METRICS[kind]:
        if key in meas and key in sim and abs(meas[key]) > 1e-9:
            rel = (sim[key] - meas[key]) / abs(meas[key])
            if abs(rel) >= 0.10:
                lines.append(f"- {name}: simulated `{key}` is {abs(rel) * 100:.0f}% "
                             f"{'larger' if rel > 0 else 'smaller'} than measured ({_fmt(sim[key])} vs {_fmt(meas[key])}).")
    return lines


def _turning_headline(ship, speed: float, t_exec: float, dt: float, duration: float, **kwargs) -> dict:
    """Advance and tactical diameter (in ship lengths) of a 35 deg starboard turning circle."""
    res = run_maneuver(ship, "turning", rudder_deg=35.0, speed=speed, duration=duration, dt=dt,
                       t_exec=round(t_exec / dt) * dt, **kwargs)
    m = turning_metrics(res.trajectory, t_exec=res.settings["t_exec_s"], L=L)
    return {"advance/L": m["advance_m"] / L, "tactical diameter/L": m["tactical_diameter_m"] / L}


def departures(speed: float, t_exec: float, dt: float, n_eq: float, n_meas: float | None) -> list[Departure]:
    """What the model's open choices do to the simulated turning circle (35 deg, starboard)."""
    ship = kvlcc2()
    duration = 900.0
    main = _turning_headline(ship, speed, t_exec, dt, duration)
    rows = [
        Departure("propeller rate", "the MARIN runs hold the approach speed at 1.53 rps (measured)",
                  f"solved for equilibrium at the measured approach speed ({n_eq:.3f} rps)",
                  effect(main, _turning_headline(ship, speed, t_exec, dt, duration, n=n_meas),
                         alt_name=f"the measured {n_meas:.3f} rps (the ship slows down)") if n_meas else
                  "not measured (no MARIN data)"),
        Departure("rudder rate", "2.32 deg/s full scale (SIMMAN 2020 conditions); 1.76 deg/s is also quoted",
                  "2.32 deg/s", effect(main, _turning_headline(ship, speed, t_exec, dt, duration,
                                                               rate=np.radians(1.76)), alt_name="a rudder rate of 1.76 deg/s")),
        Departure("wake fraction w_P0", "0.40 at model scale, 0.35 at full scale in the sources", "0.35 (full scale)",
                  effect(main, _turning_headline(kvlcc2({"w_P0": 0.40}), speed, t_exec, dt, duration),
                         alt_name="the model-scale w_P0 = 0.40")),
        Departure("scale of the hull coefficients", "Yasukawa & Yoshimura (2015) give model-scale coefficients",
                  "applied at full scale, as every implementation does (no scale-effect correction)", "not measured"),
    ]
    return rows


def run(out: Path, quick: bool = False, workers=None, scheduler=None, data_dir=None) -> dict:
    """Run the study; ``quick`` uses a 0.5 s step, shorter runs and every 4th measured sample."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    folder = data_folder(data_dir, "kvlcc2_marin_free", study="kvlcc2-maneuvers",
                         part="the comparison with the MARIN free-running runs")
    files = marin_runs(folder) if folder is not None else {}
    have_data = bool(files)
    ship = kvlcc2()
    dt = 0.5 if quick else 0.1
    summary = {"quick": quick, "data": have_data, "L_pp_m": L, "runs": {}}
    rep = Report("KVLCC2 manoeuvres: MMG standard method vs MARIN free-running tests", quick=quick)
    if not have_data:
        rep.add("**The MARIN data folder is absent (give `--data DIR` or set `CASSHIP_DATA`): simulated "
                "manoeuvres only, no comparison.**")
    tables = {}
    imo_rows = {}
    stages = progress(list(RUNS) + ["departures"], "kvlcc2-maneuvers")
    for name, (kind, rudder, heading, key) in RUNS.items():
        next(stages)
        measured = read_marin(files[key]) if have_data and key in files else None
        speed, first_side, t_exec = 15.5 * 1852 / 3600, 1.0, 10.0
        if measured is not None:
            if quick:
                measured = measured.between(0.0, 700.0 if kind == "zigzag" else 900.0).decimate(4)
            speed = float(measured["u"][0])
            t_exec = cs.maneuvers.execute_time(measured)
            first_side = float(np.sign(measured["delta"][np.searchsorted(measured.t, t_exec) + 20]
                                       - measured["delta"][0]))
        duration = (measured.t[-1] if measured is not None else (2000.0 if kind == "turning" else 700.0))
        if quick:
            duration = min(duration, 900.0 if kind == "turning" else 700.0)
        sim = run_maneuver(ship, kind, rudder_deg=first_side * rudder, heading_deg=heading, speed=speed,
                           duration=duration, dt=dt, t_exec=round(t_exec / dt) * dt)
        records = {"simulated": sim.trajectory}
        table = {"simulated": _metrics(sim.trajectory, kind, heading, sim.settings["t_exec_s"])}
        entry = {"speed_mps": speed, "rps_equilibrium": sim.settings["n"], "first_side": int(first_side),
                 "t_exec_s": t_exec}
        if measured is not None:
            rp = replay(ship, measured)
            records["measured"], records["replayed"] = measured, rp.trajectory
            table["measured"] = _metrics(measured, kind, heading, t_exec)
            table["replayed"] = _metrics(rp.trajectory, kind, heading, t_exec)
            entry.update({"rps_measured": float(np.mean(measured["n"])), "replay_errors": rp.errors})
        entry["metrics"] = table
        tables[name] = table
        summary["runs"][name] = entry
        _plot(out / f"fig_{name}.png", name, records)
        imo_rows.setdefault("turning" if kind == "turning" else f"zz{int(rudder)}", {}).update(table)
    next(stages)
    lines = ["| run | metric | measured | simulated | replayed |", "|---|---|---:|---:|---:|"]
    for name, (kind, *_rest) in RUNS.items():
        t = tables[name]
        for key in METRICS[kind]:
            vals = [t.get(src, {}).get(key) for src in ("measured", "simulated", "replayed")]
            if all(v is None for v in vals):
                continue
            lines.append(f"| {name} | {key} | " + " | ".join(_fmt(v) for v in vals) + " |")
    metric_table = "\n".join(lines)
    imo_md = []
    summary["imo"] = {}
    for src in ("measured", "simulated"):
        if src == "measured" and not have_data:
            continue
        speed = summary["runs"]["turning_35"]["speed_mps"]
        rows = imo_check(L, speed, turning=imo_rows.get("turning", {}).get(src), zz10=imo_rows.get("zz10", {}).get(src),
                         zz20=imo_rows.get("zz20", {}).get(src))
        summary["imo"][src] = rows
        imo_md += [f"### IMO MSC.137(76) criteria, {src}", "", imo_table(rows), ""]
    (out / "metrics.md").write_text(metric_table + "\n\n" + "\n".join(imo_md))
    diffs = []
    for name, (kind, *_rest) in RUNS.items():
        diffs += _differences(name, kind, tables[name])
    turn = summary["runs"]["turning_35"]
    n_eq, n_meas = turn["rps_equilibrium"], turn.get("rps_measured")
    deps = departures(turn["speed_mps"], turn["t_exec_s"], dt, n_eq, n_meas)
    rep.add("Model: `casship.models.kvlcc2()` (MMG standard method, Yasukawa & Yoshimura 2015, model-scale "
            "coefficients applied at full scale). Simulated runs start from a straight run at the measured approach "
            f"speed with the propeller rate solved for equilibrium ({n_eq:.3f} rps); replayed runs use the measured "
            "rudder angle and propeller rate from the measured initial state.")
    rep.section("Metrics")
    rep.add(metric_table, *imo_md)
    if have_data:
        rep.section("Differences (|relative difference| >= 10 %, simulated vs measured)")
        rep.add("\n".join(diffs or ["- none above 10 %."]))
        notes = [
            f"- The model needs {n_eq:.2f} rps to hold the approach speed while the ship ran at {n_meas:.2f} rps: "
            "the straight-run resistance R'_0 = 0.022 is a model-scale value (friction is relatively larger at "
            "model scale), so replays with the measured rate lose speed (see `replay_errors.u_rmse_mps`).",
            "- Free-running data: positions are printed with three significant digits (about +-5 m late in the "
            "turn); the reference point of positions and velocities is not stated in the files.",
            "- The model is 3-DOF: the roll recorded in the files (phi, p) is not modelled.",
            "- Metric definitions (casship.maneuvers): execute = first rudder change > 1 deg; advance/transfer at "
            "90 deg and tactical diameter at 180 deg heading change from the execute; steady diameter = least-"
            "squares circle from 360 deg heading change until the rudder is returned (pull-out at the end of the "
            "MARIN turning run); zig-zag overshoots from the heading change at the execute.",
            "- The measured 10/10 record ends before its third rudder reversal, so it has no period."]
        for name in RUNS:
            e = summary["runs"][name].get("replay_errors", {})
            if e:
                notes.append(f"- replay {name}: psi RMSE {e['psi_rmse_deg']:.1f} deg, position RMSE "
                             f"{e['position_rmse_m']:.0f} m, u RMSE {e['u_rmse_mps']:.2f} m/s.")
        rep.section("Notes")
        rep.add("\n".join(notes))
    rep.add(*[f"![{name}](fig_{name}.png)" for name in RUNS])
    rep.departures(deps, "Headline numbers: the simulated 35 deg turning circle's advance and tactical diameter "
                         "(in ship lengths). Reference: Yasukawa & Yoshimura (2015) and the SIMMAN 2020 test "
                         "conditions.")
    rep.write(out)
    summary["differences"] = diffs
    summary["departures"] = [d.__dict__ for d in deps]
    next(stages, None)
    return write_json(out / "summary.json", summary)


STUDY = Study("kvlcc2-maneuvers", "KVLCC2 turning circle and zig-zags: MMG standard method vs MARIN free-running",
              run)
