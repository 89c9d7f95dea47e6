"""Path following through waypoints with LOS and integral LOS in current and wind (KVLCC2, Otter).

For each ship, with casship's autopilot defaults (:func:`casship.autopilot.design_autopilot`) and
LOS guidance from the design (:meth:`casship.autopilot.guidance.LOSGuidance.for_design`: lookahead
``Delta``, circle of acceptance ``Delta``), the ship starts ``Delta`` left of a path of two legs
(North, then East, each ``12 Delta`` long) in a current across the first leg (10 % of the ship's
speed; KVLCC2 also in a 10 m/s beam wind):

* heading autopilot (compass + gyro, heading observer) with plain LOS: the current sets the ship
  off; LOS leaves a steady cross-track offset (the heading does not see the crab angle);
* the same with integral LOS (crab-angle compensation): the offset goes;
* course autopilot (GNSS + SOG/COG EKF) with plain LOS: steering the course over ground, no offset.

Reported: cross-track error RMS, mean and maximum over the second half of each leg, in metres and
in lookahead distances; figures of the tracks and cross-track errors.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from casship import autopilot as ap
from casship.autopilot.guidance import LOSGuidance, Waypoints, cross_track_metrics
from casship.models import get_model
from casship.models import otter as casship_otter
from casship.models.wind import add_current, add_wind
from casship.progress import progress

from . import Study
from .kit import Departure, Report, effect, figure, md_table, run_cases, write_json

CURRENT = 0.10             # current speed as a fraction of the ship's speed, flowing East (across leg 1)
WIND = {"kvlcc2": (10.0, np.radians(270.0)), "otter": None}     # speed [m/s], from (West)
MSS_RULE = "MSS ILOS rule"
CONTROLLERS = {"heading, LOS": ("heading", False), "heading, ILOS": ("heading", True),
               "course, LOS": ("course", False)}



def _ship(name: str):
    """The study's ship; its Otter is MSS otter.m of 2021 without the Munk moment, the craft the
    study was tuned on (the course-unstable Otter of current MSS needs the defaults' own design)."""
    return casship_otter(munk_moment=False) if name == "otter" else get_model(name)

def ship_model(name: str):
    """The ship with a current (and Fujiwara wind loads when the ship has a wind geometry)."""
    model = add_current(_ship(name))
    return add_wind(model) if WIND[name] is not None else model


def lookahead(design) -> float:
    """The study's lookahead: the path loop five times slower than the course loop's reference
    model, ``max(5 U / wn_ref, 2 L)``, longer than casship's track-control default
    (:meth:`LOSGuidance.for_design`), so that the crab angle of plain LOS shows apart from the course
    loop's own dynamics."""
    s = design.settings
    return max(5.0 * s.speed / s.wn_ref, 2.0 * design.plant.model.vessel.L_pp)


def scenario(design) -> tuple[Waypoints, float]:
    """The two-leg path scaled by the study's lookahead, and that lookahead."""
    Delta = lookahead(design)
    return Waypoints([0.0, 12 * Delta, 12 * Delta], [0.0, 0.0, 12 * Delta]), Delta


def run_case(case: dict) -> dict:
    """One path-following run (module level, for worker processes). ``case["lookahead_L"]`` replaces
    the lookahead by that many ship lengths, ``case["kappa_U"]`` the ILOS gain by that fraction of
    the speed (the alternative readings of the departures table)."""
    name, label = case["ship"], case["controller"]
    mode, integral = CONTROLLERS[label]
    model = ship_model(name)
    # the study compares LOS and ILOS on the linear feed-forward it was tuned with
    design = ap.design_autopilot(model, mode=mode, feedforward="linear")
    wp, Delta = scenario(design)
    kappa = LOSGuidance.for_design(wp, design, integral=integral, wheel_over=False).kappa
    at_switch = case.get("at_switch", LOSGuidance.at_switch)
    within = case.get("integrate_within", LOSGuidance.integrate_within)
    guidance = LOSGuidance(wp, Delta, Delta, kappa, at_switch=at_switch, integrate_within=within)   # legs change at the circle of acceptance
    if case.get("lookahead_L") or case.get("kappa_U"):
        look = case["lookahead_L"] * model.vessel.L_pp if case.get("lookahead_L") else guidance.lookahead
        kappa = case["kappa_U"] * design.settings.speed if case.get("kappa_U") else guidance.kappa
        guidance = LOSGuidance(wp, look, look, kappa, at_switch=at_switch, integrate_within=within)
    U = design.settings.speed
    env = {"current_speed": CURRENT * U, "current_dir": np.radians(90.0)}
    if WIND[name] is not None:
        env.update(wind_speed=WIND[name][0], wind_dir=WIND[name][1])
    loop = design.closed_loop_system(environment=env, guidance=guidance)
    x0 = loop.plant.x0.copy()
    x0[loop.plant.model.index(loop.plant.east)] = -Delta
    t_end = 26.0 * Delta / U
    data = loop.run(0.0, t_end, x0=x0, seed=case["seed"])
    seg = data["segment"]
    if seg[-1] < 1:
        raise RuntimeError(f"{name} {label}: the ship never reached the first waypoint")
    t_switch = float(data.t[np.argmax(seg > 0)])
    legs = {"leg 1 (across the current)": cross_track_metrics(data, start=0.5 * t_switch, end=t_switch),
            "leg 2 (with the current)": cross_track_metrics(data, start=t_switch + 0.5 * (t_end - t_switch))}
    keep = {k: data[k] for k in ("north", "east", "cross_track", "psi", "chi", "steer")}
    return {"ship": name, "controller": label, "lookahead_m": guidance.lookahead, "legs": legs, "t": data.t,
            "data": keep, "reading": case.get("reading", "casship"),
            "waypoints": (wp.north, wp.east), "turn_radius": guidance.turn_radius,
            "rate_limited_fraction": float(np.mean(data["rate_limited"] > 0.5))}


def _plots(out: Path, name: str, rows: list):
    with figure(out / f"{name}_path_following.png", 1, 2, figsize=(12, 5)) as (fig, axes):
        _draw(fig, axes, name, rows)


def _draw(fig, axes, name, rows):
    # every track against its own path (the paths are scaled by each design's lookahead), the
    # intended track with the guidance's turns dashed in the track's colour
    for r in rows:
        wn, we = r["waypoints"]
        path = Waypoints(wn, we).track(r.get("turn_radius"))
        line, = axes[0].plot(r["data"]["east"], r["data"]["north"], lw=1, label=r["controller"])
        axes[0].plot(path[:, 1], path[:, 0], "--", lw=0.8, color=line.get_color())
        axes[1].plot(r["t"], r["data"]["cross_track"], lw=1, label=r["controller"])
    axes[0].plot([], [], "k--", lw=0.8, label="path (each track's own)")
    axes[0].set_xlabel("East [m]")
    axes[0].set_ylabel("North [m]")
    axes[0].set_aspect("equal", adjustable="datalim")
    axes[1].set_xlabel("time [s]")
    axes[1].set_ylabel("cross-track error [m]")
    for a in axes:
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    fig.suptitle(f"{name}: LOS path following, current {100 * CURRENT:.0f} % of the speed towards East"
                 + (f", wind {WIND[name][0]:.0f} m/s" if WIND[name] else ""))


def _leg1_mean(results, reading, controller="heading, LOS", ship="otter") -> float:
    r = [x for x in results if x["reading"] == reading and x["controller"] == controller and x["ship"] == ship][0]
    return r["legs"]["leg 1 (across the current)"]


def run(out: Path, quick: bool = False, workers=None, scheduler=None) -> dict:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    ships = ["otter"] if quick else ["kvlcc2", "otter"]
    stages = progress(["path-following runs", "tables and figures"], "path-following")
    next(stages)
    cases = [{"ship": s, "controller": c, "seed": 3} for s in ships for c in CONTROLLERS]
    cases += [{"ship": "otter", "controller": "heading, LOS", "seed": 3, "lookahead_L": 2.5, "reading": "Delta 2.5 L"},
              {"ship": "otter", "controller": "heading, ILOS", "seed": 3, "kappa_U": 0.5, "reading": "kappa U/2"}]
    # MSS's ILOS rule (ILOSpsi.m): the integral kept at a waypoint and integrated everywhere
    cases += [{"ship": s, "controller": "heading, ILOS", "seed": 3, "at_switch": "keep", "integrate_within": None,
               "reading": MSS_RULE} for s in ships]
    results = run_cases(run_case, cases, workers=workers, scheduler=scheduler)
    next(stages)
    main = [r for r in results if r["reading"] == "casship"]
    table = []
    for r in main:
        for leg, m in r["legs"].items():
            table.append({"ship": r["ship"], "controller": r["controller"], "leg": leg, "lookahead_m": r["lookahead_m"],
                          **m, "mean_over_lookahead": m["cross_track_mean_m"] / r["lookahead_m"],
                          "rate_limited_fraction": r["rate_limited_fraction"]})
    for s in ships:
        _plots(out, s, [r for r in main if r["ship"] == s])
    keys = ("cross_track_rms_m", "cross_track_mean_m")
    base_los, base_ilos = _leg1_mean(results, "casship"), _leg1_mean(results, "casship", "heading, ILOS")
    rep = Report("Path following with LOS and integral LOS in current and wind", quick=quick)
    rep.add(f"Current {100 * CURRENT:.0f} % of the ship's speed flowing East (across leg 1, along leg 2); KVLCC2 "
            "also in a 10 m/s wind from the West (Fujiwara loads). The ship starts one lookahead distance left of "
            "the path. Cross-track errors over the second half of each leg (positive: right of the path). A "
            "heading autopilot with plain LOS keeps a steady offset across the current (it does not see the crab "
            "angle); integral LOS removes it; a course autopilot (course over ground from GNSS) needs no integral.")
    rep.add(md_table(table, ["ship", "controller", "leg", "lookahead_m", "cross_track_rms_m", "cross_track_mean_m",
                             "cross_track_max_m", "mean_over_lookahead", "rate_limited_fraction"], spec=".3g"))
    ilos_rule = []
    for s in ships:
        ours = [r for r in main if r["ship"] == s and r["controller"] == "heading, ILOS"][0]
        mss = [r for r in results if r["ship"] == s and r["reading"] == MSS_RULE][0]
        ilos_rule.append({"ship": s, **{f"{who} {leg.split(' (')[0]} mean [m]": r_["legs"][leg]["cross_track_mean_m"]
                                        for who, r_ in (("casship", ours), ("MSS", mss)) for leg in r_["legs"]}})
    rep.add("Integral LOS: casship's rule against MSS's (`ILOSpsi.m`: the integral kept at a waypoint and "
            "integrated everywhere). casship projects the integral onto the new leg (the cosine of the course change: "
            "the drift of a current or a wind is fixed in the earth frame) and integrates only within half a "
            "lookahead of the path, where the LOS angle is in the linear region its gain kappa = U/4 is chosen for; "
            "a turn's transient does not wind it up. Mean cross-track error over the second half of each leg:")
    rep.add(md_table(ilos_rule, list(ilos_rule[0]), spec=".3g"))
    for s in ships:
        rep.image(f"{s}_path_following.png", f"{s} tracks")
    rep.departures([
        Departure("lookahead distance Delta", "Fossen (2021, Sec. 12.4): a design choice, typically a few ship lengths "
                  "(MSS Mariner: 500 m = 3.1 L)", "Delta = max(5 U / wn_ref, 2 L): the path loop five times slower "
                  "than the heading loop's reference model",
                  effect({k: base_los[k] for k in keys}, {k: _leg1_mean(results, "Delta 2.5 L")[k] for k in keys},
                         alt_name="Otter, heading LOS, Delta = 2.5 L", units={k: "m" for k in keys})),
        Departure("ILOS gain kappa", "Borhaug et al. (2008), Fossen (2021): any kappa > 0", "kappa = U / 4 (critically "
                  "damped linearised cross-track dynamics)",
                  effect({k: base_ilos[k] for k in keys},
                         {k: _leg1_mean(results, "kappa U/2", "heading, ILOS")[k] for k in keys},
                         alt_name="Otter, heading ILOS, kappa = U / 2", units={k: "m" for k in keys})),
        Departure("ILOS integral at a waypoint", "MSS ILOSpsi.m: kept; integrated everywhere",
                  "projected onto the new leg; integrated within half a lookahead of the path",
                  "; ".join(f"{r['ship']}: leg-2 mean {r['casship leg 2 mean [m]']:.3g} m against "
                            f"{r['MSS leg 2 mean [m]']:.3g} m with MSS's rule" for r in ilos_rule))])
    rep.write(out)
    summary = write_json(out / "summary.json", {"table": table, "ilos_rule": ilos_rule,
                                                 "figures": sorted(p.name for p in out.glob("*.png"))})
    next(stages, None)
    return summary


STUDY = Study("path-following", "LOS and integral-LOS path following through waypoints in current and wind "
              "(KVLCC2, Otter): the crab angle with heading and course autopilots", run)
