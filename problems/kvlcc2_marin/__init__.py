"""KVLCC2 MMG identification on all shared free-running runs, cross-validated on runs it has not seen.

Data: the three MARIN runs (full scale: 35 deg turning circle, 10/10 and 20/20 zig-zags) and the
thirteen HSVA zig-zags (model scale, Froude-scaled with ``lambda = 45.7``, with measured thrust and
torque), see :mod:`.data`.

Method (:mod:`.workflow`): propulsion from the measured thrust (:mod:`.propulsion`), then the
library's ship workflow (:func:`casship.identify.identify_ship`, what ``casship identify`` does
without ``--free``): EKF + RTS smoothing, a free set chosen from run-level evidence by a stated
rule (port/starboard and direction-switched terms only from mirrored evidence, the rudder neutral
angle per facility and pooled), and a MAP output-error refinement of the full-scale
:func:`casship.models.kvlcc2` with asymmetry terms and smooth sign switches
(``kvlcc2(asymmetry=True, smooth=True)``): one set of hull coefficients for the ship.

Validation (:mod:`.validate`): every fold writes its fit file and every held-out run is scored by
replaying that file through :func:`casship.identify.replay_file` (what ``casship simulate
--params`` does). Folds: leave-one-run-out (every run held out once; the whole workflow, propulsion
and free-set choice included, runs on the other fifteen), leave-one-regime-out (small-angle
zig-zags, large-rudder zig-zags, turning circles), leave-one-facility-out and
leave-one-direction-out (train on the runs that turn first to one side, predict the others).

Uncertainty (:mod:`.calibration`): run-level jackknife over the leave-one-run-out folds (the
covariance of ``fit.json``), the coverage of every left-out run of every fold family by its fold's
predictive band (the fold file's parameter band plus a discrepancy term from the held-out errors
of runs that fold did not hold out), and the port/starboard check against the HSVA mirror pairs.

Outputs (:mod:`.report`): ``report.md``, ``fit.json`` (the fit on all runs, with the jackknife
covariance; replays with ``casship simulate --model kvlcc2 --params fit.json``),
``fit_without_<run>.json`` and ``fit_<kind>_<label>.json`` (the fold files, robust covariance),
``cross_validation.csv``, figures, ``summary.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from casship.errors import InputError
from casship.parallel import call, run_cases
from casship.studies import Study

from ..kit import data_folder
from .choice import captive_only, choose
from .calibration import (asymmetry_check, band_check, calibration_table, heading_growth, jackknife, mirror_check,
                          predictive_coverage)
from .data import first_rudder_side, load_runs, regime
from .diagnose import steady_turn_balance, through_the_turn
from .propulsion import open_water
from .report import fold_figure, slug, write_outputs
from .validate import evaluate, published_model, write_fold_file
from .workflow import (VARIANTS, VARIANTS_EARLIER, captive_fit, fit_fold, smooth_runs, study_model,
                       with_smoothed_speed)

JOIN_CAPTIVE = True          # join the captive tests when present (declared before the run: workflow.VARIANTS)

QUICK = {"runs": ("MARIN tc_-35", "MARIN zz_-20", "MARIN zz_10", "HSVA Z_10_10_P", "HSVA Z_10_10_S",
                  "HSVA Z_20_10_S", "HSVA Z_35_05"),
         "held_out": ("MARIN zz_-20",), "dt": 4.0, "max_free": 6}
GROUPINGS = (("regime", regime), ("facility", lambda r: r.facility), ("direction", first_rudder_side))
#: Every fold family: leave one run out, then one regime, facility, direction out.
FOLD_FAMILIES = ("run",) + tuple(kind for kind, _ in GROUPINGS)
#: The families ``fit.json`` depends on (its jackknife covariance and its discrepancy term come from the
#: leave-one-run-out folds; the others only score the procedure): what a study that designs on the fit runs.
FIT_FILE_FAMILIES = ("run",)


def fold_specs(runs, quick: bool = False, families=FOLD_FAMILIES) -> list[tuple[str, str, tuple]]:
    """``(kind, label, held-out run names)`` of every fold of the fold ``families`` (see :data:`FOLD_FAMILIES`)."""
    unknown = sorted(set(families) - set(FOLD_FAMILIES))
    if unknown:
        raise InputError(f"unknown fold families {unknown}; known: {list(FOLD_FAMILIES)}")
    folds = []
    if "run" in families:
        folds += [("run", name, (name,)) for name in (QUICK["held_out"] if quick else [r.name for r in runs])]
    if not quick:
        for kind, label_of in GROUPINGS:
            if kind not in families:
                continue
            labels = {r.name: label_of(r) for r in runs}
            if len(set(labels.values())) > 1:
                folds += [(kind, label, tuple(n for n, v in labels.items() if v == label))
                          for label in sorted(set(labels.values()))]
    return folds


def fold_file_name(kind: str, label: str) -> str:
    """The fit file of a fold: ``fit_without_<run>.json`` or ``fit_without_<kind>_<label>.json``."""
    label = {"+": "positive", "-": "negative"}.get(label, label) if kind == "direction" else label
    return f"fit_without_{slug(label)}.json" if kind == "run" else f"fit_without_{kind}_{slug(label)}.json"


def run_fold(spec, runs, smoothed, curve, out: Path, *, dt: float, max_free: int, captive=None) -> dict:
    """One fold: fit on the runs not held out, write the fit file, replay it on the held-out runs and
    draw their figure. Independent of every other fold (folds may run in any order or in parallel)."""
    kind, label, held = spec
    train = [r for r in runs if r.name not in held]
    fold = fit_fold(train, smoothed, curve, dt=dt, max_free=max_free, captive=captive)
    chosen = choose(train, smoothed, curve, dt=dt, max_free=max_free, captive=captive) if captive else None
    facilities = sorted({r.facility for r in runs if r.name in held})
    base = out / fold_file_name(kind, label)
    captive_chosen = chosen is not None and chosen["choice"] == "captive-only"
    # the joint fit's files (the chosen ones, or kept beside as "joint_..." for inspection): one per
    # facility of the held-out runs, a facility quantity (the neutral angle) that facility's where the
    # training had it, else the population value with the spread in the band
    joint_base = base.with_name("joint_" + base.name[len("fit_"):]) if captive_chosen else base
    extra = {"nested_choice": chosen} if chosen else None
    joint = {f: write_fold_file(fold, joint_base if len(facilities) == 1
                                else joint_base.with_name(f"{joint_base.stem}_{f}.json"), extra=extra, facility=f)
             for f in facilities}
    if captive_chosen:                    # one file: the captive-only model has no facility quantity of its own
        path = captive_only(captive).write(base, fold.fit.noise, {"nested_choice": chosen})
        paths = {f: path for f in facilities}
    else:
        paths = joint
    rows = [evaluate(r, paths[r.facility]) for r in runs if r.name in held]
    res = {"kind": kind, "label": label, "held": held, "fold": fold, "choice": chosen,
           "file": ", ".join(sorted({p.name for p in paths.values()})),
           "joint_file": ", ".join(sorted({p.name for p in joint.values()})), "evaluations": rows}
    res["figure"] = fold_figure(out, runs, res)
    return res


def in_sample(run, fit_path: Path) -> tuple[dict, dict]:
    """A run replayed with the fit on all runs (with whether its predictive heading band is at least as
    wide as its parameter band on every sample), and its mirror-image check (a case of the loop)."""
    ev = evaluate(run, fit_path)
    b = ev["bands"] or {}
    row = dict(ev["row"], predictive_never_narrower=(bool(np.all(b["psi_std_predictive"] >= b["psi_std"]))
                                                     if "psi_std_predictive" in b else None))
    return row, mirror_check([run], fit_path, published_model())[run.name]


def run(out: Path, quick: bool = False, workers=None, scheduler=None, data_dir: Path | None = None,
        families=FOLD_FAMILIES) -> dict:
    """Fit, cross-validate and report (see the module text); ``quick``: seven runs, one fold.

    ``families``: the fold families to run (default all, :data:`FOLD_FAMILIES`); with
    :data:`FIT_FILE_FAMILIES` the study writes the same ``fit.json`` and reports only the
    leave-one-run-out folds (what ``casship study trial-design`` runs before it designs on the fit).

    The fit on all runs and the folds are independent cases, run by :func:`casship.parallel.run_cases`
    (``workers`` local processes, or the Dask cluster at ``scheduler``) with one BLAS thread each
    (the inverse dynamics at the process's count); every case is deterministic, so the numbers do
    not depend on how they are spread.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    marin = data_folder(data_dir, "kvlcc2_marin_free", study="kvlcc2-marin", part="the whole study")
    if marin is None:
        raise FileNotFoundError("kvlcc2-marin needs the measured runs (give --data DIR or set CASSHIP_DATA)")
    runs = load_runs(marin.parent)
    if quick:
        runs = [r for r in runs if r.name in QUICK["runs"]]
    curve = open_water(marin.parent / "kvlcc2_hsva_free")
    smoothed = smooth_runs(runs)
    runs = with_smoothed_speed(runs, smoothed)
    dt = QUICK["dt"] if quick else 2.0
    max_free = QUICK["max_free"] if quick else 15
    opts = {"dt": dt, "max_free": max_free}
    folder = marin.parent / "kvlcc2_hmri_captive"
    if JOIN_CAPTIVE and folder.is_dir():             # the captive tests in one objective with the runs
        opts["captive"] = (str(folder), captive_fit(folder))
    # the fit on all runs first: the longest case starts at once
    cases = [(fit_fold, (runs, smoothed, curve), opts)]
    if "captive" in opts:                            # the nested choice on all runs (module choice)
        cases.append((choose, (runs, smoothed, curve), opts))
    cases += [(run_fold, (spec, runs, smoothed, curve, out), opts) for spec in fold_specs(runs, quick, families)]
    everything, *results = run_cases(call, cases, workers=workers, scheduler=scheduler,
                                     label="kvlcc2-marin fits", unit="fit", blas_threads=1)
    chosen = results.pop(0) if "captive" in opts else None
    loro = [res["fold"] for res in results if res["kind"] == "run"]
    jack = jackknife(everything, loro) if len(loro) > 2 else None
    calibration = calibration_table(everything, loro, jack) if jack is not None else {}
    loro_results = [res for res in results if res["kind"] == "run"]
    bands = band_check(runs, loro_results) if len(loro) > 2 else {}
    q_by_run = heading_growth(runs, loro_results)
    coverage = predictive_coverage(runs, results, q_by_run) if len(q_by_run) > 1 else {}
    discrepancy = {"model_discrepancy": {
        "psi_variance_growth_deg2_per_s": bands["q_all_folds_deg2_per_s"],
        "meaning": "heading variance the parameter band misses, growing linearly with time (q t), least squares "
                   "over the leave-one-run-out held-out errors; replays of this file give the parameter band "
                   "(param_covariance) and the predictive band sqrt(s^2 + q t) on the same covariance, so the "
                   "predictive band is never the narrower"}} if bands else {}
    captive_chosen = chosen is not None and chosen["choice"] == "captive-only"
    joint_path = write_fold_file(everything, out / ("fit_joint.json" if captive_chosen else "fit.json"), jack,
                                 {**discrepancy, **({"nested_choice": chosen} if chosen else {})})
    if captive_chosen:
        shipped = captive_only(opts["captive"])
        fit_path = shipped.write(out / "fit.json", everything.fit.noise, {**discrepancy, "nested_choice": chosen})
        shipped_params = shipped.params()
    else:
        fit_path, shipped_params = joint_path, everything.params("HSVA")
    replays = run_cases(call, [(in_sample, (r, fit_path)) for r in runs], workers=workers, scheduler=scheduler,
                        blas_threads=1)
    model = study_model()
    asym = asymmetry_check(runs, shipped_params, model, published_model())
    asym["mirror"] = {r.name: mirror for r, (_, mirror) in zip(runs, replays)}
    turns = {}
    for circle in (r for r in runs if r.kind == "turning"):
        files = {"fit.json (in training)": fit_path}
        if (out / fold_file_name("run", circle.name)).exists():
            files[fold_file_name("run", circle.name)] = out / fold_file_name("run", circle.name)
        turns[circle.name] = {"turn": through_the_turn(circle, files, published_model()),
                              "balance": steady_turn_balance(circle, files, published_model())}
    return write_outputs(out, runs, everything, results, [row for row, _ in replays], calibration=calibration,
                         jack=jack, asymmetry=asym, bands=bands, turns=turns, quick=quick, coverage=coverage,
                         chosen=chosen, families=families,
                         variants={"this_round": len(VARIANTS), "declared": list(VARIANTS),
                                   "earlier_rounds": VARIANTS_EARLIER})


STUDY = Study("kvlcc2-marin", "KVLCC2 MMG identified on the MARIN and HSVA free-running runs, "
              "cross-validated on runs left out", run, needs_data=True)
