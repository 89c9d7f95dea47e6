"""Koike et al. (2023): guidelines for UKF and EnKF in ship state estimation (automatic berthing), reproduced.

Koike, Dostal, Sawada, Miyauchi & Maki (2023), "A study on the implementation of nonlinear Kalman filter
applying MMG model", Journal of Marine Science and Technology 28, 733-745.

The system: a single-propeller, twin-rudder ship with Yoshimura's low-speed hull model (MMG form,
Koike et al. 2023, Eq. 20-22), Euler-discretised at dt = 0.1 s (Eq. 25), every state measured (H = I6).
The filters: UKF (2n+1 sigma points, kappa = 3), EnKF (N = 100, perturbed observations) and the
linear KF on the persistence model (A = I) as baseline, each with Q = 0 and with tuned Q
(UKF diag(1e-4), EnKF diag(1e-2) as in the paper; the KF's Q tuned per state on a separate
record), R = diag(5e-2), P(0) = I, x(0) = y(0). casship's EKF and MHE are extra columns.

Experiments (RMSE of the filtered states against the noise-free truth, Monte Carlo over noise seeds):

1. modelling error: a gusty wind (the paper's Eq. 34) acts on the ship in the data but is absent
   from the filter model; mean wind speed 0, 0.82 and 1.64 m/s (one gust record scaled by 0, 0.5, 1);
2. observation noise in the data: R = 0.05^2, 0.10^2, 0.20^2 (the filters keep their R);
3. zig-zag versus random rudder (delta_s uniform in [-35, 105] deg, delta_p in [-105, 35] deg);
4. computation time per 0.1 s step, batch (compiled fold) and online (one call per sample).

The other readings of what the paper leaves open (wind by Fujiwara's 2005 regression instead of
Eq. 34; data noise std 0.05 instead of the paper's N(0, R)) run on experiment 1 as well; their
effects fill the report's "Departures from the paper" table.

Modules: :mod:`.scenario` (ship, wind, records), :mod:`.experiments` (cases, timing, MHE),
:mod:`.figures`, :mod:`.findings` (claims, verdicts, departures).

Run: ``casship study filter-guidelines [--quick] [--workers N] [--scheduler tcp://...]``.
"""
from __future__ import annotations

import time
from pathlib import Path

from casship.progress import progress

from .. import Study
from ..kit import Report, md_table, run_cases, write_json
from . import figures
from .experiments import aggregate, cases, mhe_column, run_case, timing, tune_kf
from .findings import ALT_FORM, ALT_NOISE, W2, comparison, departures, findings, gap_table, headline, rmse_table, verdicts
from .scenario import (DATA_STD, DATA_STD_ALT, DT, FILTERS, NOISE_STDS, R_FILTER, STATES, WIND_MEANS, Config,
                       gust_record, rudder_inputs, ship_models)

__all__ = ["run", "STUDY", "run_case", "STATES", "FILTERS", "WIND_MEANS", "NOISE_STDS", "DATA_STD", "DATA_STD_ALT",
           "gust_record", "rudder_inputs", "ship_models"]

_SCOPE = __doc__.split("\n\n", 1)[1].split("The other readings")[0].strip()


def run(out: Path, quick: bool = False, workers=None, scheduler=None) -> dict:
    """Run every experiment, write figures (PNG), tables and ``report.md`` into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    cfg = Config.make(quick)
    steps = progress(["tune the persistence KF", "Monte Carlo (wind, noise, manoeuvre, other readings)",
                      "computation time", "MHE column", "figures and report"], "filter-guidelines")
    t_start = time.perf_counter()
    next(steps)
    q_kf = tune_kf(cfg.duration)
    next(steps)
    table = aggregate(run_cases(run_case, cases(cfg, q_kf), workers=workers, scheduler=scheduler))
    next(steps)
    times = timing(cfg, q_kf)
    next(steps)
    mhe = mhe_column(cfg, q_kf)
    next(steps)
    figures.wind_records(out / "fig02_wind.png", cfg.duration)
    figures.wind_effect(out / "fig03_wind_effect.png", cfg.duration)
    figures.bars(out / "fig04_rmse_wind.png", table["wind"], ("UKF Q=0", "EnKF Q=0", "KF"), WIND_MEANS,
                 [f"{w:g} m/s" for w in WIND_MEANS], "RMSE vs mean wind speed (modelling error), Q = 0")
    figures.tuned_q(out / "fig05_rmse_tuned_q.png", table["wind"][W2])
    figures.bars(out / "fig06_rmse_noise.png", table["noise"], ("UKF Q=0", "EnKF Q=0", "KF"), NOISE_STDS,
                 [f"std {s:g}" for s in NOISE_STDS], "RMSE vs observation noise of the data")
    figures.maneuvers(out / "fig07_08_maneuvers.png", cfg.duration)
    figures.bars(out / "fig09_rmse_maneuver.png", table["maneuver"], ("UKF Q=0", "EnKF Q=0", "KF"),
                 ("zigzag", "random"), ["zig-zag", "random"], "RMSE for periodic (zig-zag) and aperiodic (random) rudder")
    figures.bars(out / "fig_extra_ekf.png", table["wind"], ("EKF Q=0", "EKF tuned"), WIND_MEANS,
                 [f"{w:g} m/s" for w in WIND_MEANS], "casship EKF (extra column): RMSE vs mean wind speed")
    figures.timing(out / "fig10_time.png", times)
    found = findings(table, times)
    tables = {"wind": rmse_table(table["wind"], FILTERS, WIND_MEANS, "mean wind [m/s]"),
              "noise": rmse_table(table["noise"], FILTERS, NOISE_STDS, "noise std"),
              "maneuver": rmse_table(table["maneuver"], FILTERS, ("zigzag", "random"), "rudder")}
    for name, text in tables.items():
        (out / f"table_{name}.md").write_text(text + "\n")
    deps = departures(table)
    seconds = time.perf_counter() - t_start
    report(cfg, q_kf, table, tables, times, mhe, found, deps, seconds, quick).write(out)
    summary = {"config": cfg.__dict__, "q_kf_tuned": q_kf, "rmse": table, "time_per_step": times, "mhe": mhe,
               "findings": found, "headline": headline(table["wind"][str(WIND_MEANS[0])], table["wind"][W2]),
               "seconds": seconds, "departures": [d.__dict__ for d in deps],
               "verdicts": [{"claim": c, "ours": o, "agrees": bool(ok)} for c, o, ok, _ in verdicts(found)],
               "figures": sorted(p.name for p in out.glob("*.png"))}
    next(steps, None)
    return write_json(out / "summary.json", summary)


def report(cfg, q_kf, table, tables, times, mhe, found, deps, seconds, quick) -> Report:
    """The report: scope, the four experiments with the paper's figure numbers, MHE, comparison, departures."""
    rep = Report("Koike et al. (2023) reproduced: guidelines for UKF and EnKF in ship state estimation", quick=quick)
    rep.add(_SCOPE)
    rep.add(f"Records of {cfg.duration:g} s at dt = {DT} s; {cfg.seeds} noise seeds per condition. Data noise in "
            f"experiments 1 and 3: std {DATA_STD:.3f} on every state (w ~ N(0, R), R = diag({R_FILTER})); the "
            f"filters use R = diag({R_FILTER}). Persistence KF, Q per state tuned on a separate record: "
            + ", ".join(f"{s}: {q:.1e}" for s, q in q_kf.items()) + ".")
    rep.section("1. Modelling error: wind in the data, not in the filter model (paper Figs. 2-5)")
    rep.image("fig02_wind.png", "Fig. 2: wind records").image("fig03_wind_effect.png", "Fig. 3: effect of the wind")
    rep.add(tables["wind"], "![rmse wind](fig04_rmse_wind.png)", "![tuned Q](fig05_rmse_tuned_q.png)",
            "![EKF](fig_extra_ekf.png)")
    rep.add("Absolute RMSE of the Q = 0 filters, the EnKF - UKF gap and the growth ratios (the growth ratios alone "
            "hide how far apart the two filters are):", gap_table(table["wind"]))
    rep.section("2. Observation noise (paper Fig. 6)")
    rep.add(tables["noise"], "![rmse noise](fig06_rmse_noise.png)")
    rep.section("3. Zig-zag vs random rudder (paper Figs. 7-9)")
    rep.add("![manoeuvres](fig07_08_maneuvers.png)", tables["maneuver"], "![rmse manoeuvre](fig09_rmse_maneuver.png)")
    rep.section("4. Computation time per 0.1 s step (paper Fig. 10)")
    rep.add(md_table({n: {"batch [ms/step]": 1e3 * v["batch_s_per_step"], "online [ms/step]": 1e3 * v["online_s_per_step"]}
                      for n, v in times.items()}, first="filter", spec=".3f"), "![time](fig10_time.png)")
    rep.section("Extra column: moving-horizon estimation (MHE, real-time iteration)")
    rep.add(f"One seed, first {cfg.mhe_duration:g} s of the wind records, horizon {cfg.mhe_horizon} steps, tuned Q; "
            "the UKF (tuned) on the same shortened record for reference.")
    fmt3 = lambda d: ", ".join(f"{d[s]:.3g}" for s in STATES)  # noqa: E731
    rows = ["| mean wind [m/s] | MHE RMSE x, u, y, v, psi, r | UKF tuned, same record | MHE ms/step |", "|---|---|---|---|"]
    for w, r in mhe.items():
        rows.append(f"| {w} | failed: {r['error']} | {fmt3(r['ukf_same_record'])} | - |" if "error" in r else
                    f"| {w} | {fmt3(r['rmse'])} | {fmt3(r['ukf_same_record'])} | {1e3 * r['s_per_step']:.1f} |")
    rep.add("\n".join(rows))
    rep.section("Comparison with the paper's conclusions")
    rep.add(comparison(found))
    rep.add("The other readings on experiment 1 (RMSE tables, same seeds):", "Wind by Fujiwara's 2005 regression:",
            rmse_table(table[ALT_FORM], ("UKF Q=0", "EnKF Q=0", "KF"), (WIND_MEANS[-1],), "mean wind [m/s]"),
            f"Data noise std {DATA_STD_ALT}:",
            rmse_table(table[ALT_NOISE], ("UKF Q=0", "EnKF Q=0", "KF"), (WIND_MEANS[0], WIND_MEANS[-1]),
                       "mean wind [m/s]"))
    rep.departures(deps, "Each choice the paper leaves open or that this study makes differently, the reading "
                         "taken, and its effect on the headline numbers of experiment 1 (Q = 0: growth of the RMSE "
                         "from no wind to 1.64 m/s, and the EnKF - UKF gap at 1.64 m/s).")
    rep.add(f"Run time: {seconds:.0f} s.")
    return rep


STUDY = Study("filter-guidelines", "Koike et al. 2023: UKF/EnKF/KF guidelines (modelling error, noise, manoeuvre, time)",
              run)
