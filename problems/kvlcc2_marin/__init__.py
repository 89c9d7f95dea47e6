"""KVLCC2 MMG identification on all shared free-running runs, cross-validated on runs it has not seen.

Data: the three MARIN runs (full scale: 35 deg turning circle, 10/10 and 20/20 zig-zags) and the
thirteen HSVA zig-zags (model scale, Froude-scaled with ``lambda = 45.7``), see :mod:`.data`.

Method (:mod:`.workflow`): propulsion trim (:mod:`.propulsion`), EKF + RTS smoothing, inverse
dynamics, a free set chosen from the Fisher information by a stated rule, and a MAP output-error
refinement of the full-scale :func:`casship.models.kvlcc2` with asymmetry terms and smooth sign
switches (``kvlcc2(asymmetry=True, smooth=True)``), asymmetry per facility.

Validation (:mod:`.validate`): leave-one-run-out (every run held out once; the whole workflow,
propulsion trim and free-set choice included, runs on the other fifteen), leave-one-facility-out
(train on one facility, predict the other's runs) and leave-one-direction-out (train on the runs
whose first rudder goes to one side, predict the runs that turn the other way first: the situation
of a user who has trials in one direction only); each held-out run replayed with the published
constants and with the fit that did not see it.

Outputs (:mod:`.report`): ``report.md``, ``fit.json`` (the fit on all runs for the full-scale model,
with the MARIN facility's asymmetry terms; replays with ``casship simulate --model kvlcc2 --params
fit.json``), ``fit_all_runs.json`` (with all per-facility copies), ``fit_without_<run>.json``,
``cross_validation.csv``, ``fig_heldout_<run>.png``, ``fig_facility_<name>.png``,
``fig_direction_<positive|negative>.png``, ``summary.json``.
"""
from __future__ import annotations

from pathlib import Path

from casship.progress import track
from casship.studies import Study

from ..kit import data_folder
from .data import first_rudder_side, load_runs
from .report import write_outputs
from .validate import evaluate
from .workflow import fit_fold, smooth_runs, with_smoothed_speed

QUICK = {"runs": ("MARIN tc_-35", "MARIN zz_-20", "MARIN zz_10", "HSVA Z_10_10_P", "HSVA Z_20_10_S",
                  "HSVA Z_35_05"),
         "held_out": ("MARIN zz_-20",), "dt": 4.0, "max_free": 6}


def run(out: Path, quick: bool = False, workers=None, scheduler=None, data_dir: Path | None = None) -> dict:
    """Fit, cross-validate and report (see the module text); ``quick``: six runs, one fold."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    marin = data_folder(data_dir, "kvlcc2_marin_free", study="kvlcc2-marin", part="the whole study")
    if marin is None:
        raise FileNotFoundError("kvlcc2-marin needs the measured runs (give --data DIR or set CASSHIP_DATA)")
    runs = load_runs(marin.parent)
    if quick:
        runs = [r for r in runs if r.name in QUICK["runs"]]
    smoothed = smooth_runs(runs)
    runs = with_smoothed_speed(runs, smoothed)
    dt = QUICK["dt"] if quick else 2.0
    max_free = QUICK["max_free"] if quick else 15
    folds = [("run", name, (name,)) for name in (QUICK["held_out"] if quick else [r.name for r in runs])]
    if not quick:
        for kind, label_of in (("facility", lambda r: r.facility), ("direction", first_rudder_side)):
            labels = {r.name: label_of(r) for r in runs}
            if len(set(labels.values())) > 1:
                folds += [(kind, label, tuple(n for n, v in labels.items() if v == label))
                          for label in sorted(set(labels.values()))]
    everything = fit_fold(runs, smoothed, dt=dt, max_free=max_free)
    in_sample = [evaluate(r, everything)["row"] for r in runs]
    results = []
    for kind, label, held in track(folds, "kvlcc2-marin folds", unit="fold"):
        fold = fit_fold([r for r in runs if r.name not in held], smoothed, dt=dt, max_free=max_free)
        rows = [evaluate(r, fold) for r in runs if r.name in held]
        results.append({"kind": kind, "label": label, "held": held, "fold": fold, "evaluations": rows})
    return write_outputs(out, runs, everything, results, in_sample, quick=quick)


STUDY = Study("kvlcc2-marin", "KVLCC2 MMG identified on the MARIN and HSVA free-running runs, "
              "cross-validated on runs left out", run, needs_data=True)
