"""The nested choice between the captive-only model and the joint fit, made on training runs only.

The rule (:data:`RULE`), declared before it was first run and never changed on its numbers: every
fold (and the fit on all runs) chooses between two candidates using its *training* runs alone, so
the held-out runs a headline reports never take part in the choice (nested cross-validation):

* **captive-only**: the hull and interaction coefficients of the HMRI captive tests alone on the
  full-scale ship, every facility quantity published (the model of ``casship study
  kvlcc2-captive``); it has seen no free-running run, so every training run is out of sample;
* **joint**: the captive tests and the training runs in one objective (:func:`.workflow.fit_fold`),
  scored by an inner cross-validation: the training runs in name order dealt to
  :data:`INNER_FOLDS` groups, each group replayed by the joint fit on the other groups.

Score: the mean heading RMSE of the training runs so replayed. The joint fit is chosen only when
its score is lower; a tie, or too few training runs for an inner split, keeps the captive-only
model (the one that spends no free-running evidence).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from casship.identify import ParameterBelief, write_params_file
from casship.maneuvers import replay

from .data import Run, per_run
from .workflow import fit_fold, study_model

__all__ = ["INNER_FOLDS", "RULE", "CaptiveOnly", "captive_only", "inner_groups", "choose"]

INNER_FOLDS = 3
RULE = ("nested choice per fold on its training runs only: captive-only model (scored on every training run, "
        "all out of sample) against the joint fit (scored by an inner 3-fold cross-validation of the training "
        "runs, dealt in name order); lower mean heading RMSE wins, a tie or fewer than 2 training runs keeps "
        "the captive-only model")


@dataclass(frozen=True)
class CaptiveOnly:
    """The captive-only candidate: the captive estimates that carry to the full-scale ship.

    Parameters
    ----------
    values : dict
        Hull and interaction estimates of the captive-only fit (no ``name@facility`` quantity).
    belief : ParameterBelief
        Their robust covariance from the captive fit.
    """

    values: dict
    belief: ParameterBelief

    def params(self, facility: str | None = None) -> dict:
        """The parameters a run of any facility is replayed with (facility quantities published)."""
        return {**study_model().param_dict(), **self.values}

    def write(self, path: Path, noise: dict, extra=None) -> Path:
        """The candidate as a fit file (:func:`casship.identify.write_params_file`): its values, their
        robust covariance as the fit's, and ``noise`` (the free-running channels' noise, which the
        captive tests do not measure: the joint fit's on the same runs), so that trial design and
        replays read it as they read a fit."""
        names, cov = list(self.belief.names), self.belief.cov
        sd = np.sqrt(np.diag(cov))
        fit = {"free": names, "estimates": dict(self.values), "std_errors": dict(zip(names, sd.tolist())),
               "std_errors_robust": dict(zip(names, sd.tolist())), "covariance": cov.tolist(),
               "covariance_robust": cov.tolist(), "correlation": (cov / np.outer(sd, sd)).tolist(),
               "noise": noise, "method": "captive-only (HMRI PMM tests), Gaussian ML"}
        return write_params_file(path, study_model(), self.values, self.belief,
                                 {**fit, "candidate": "captive-only", **(extra or {})})


_CAPTIVE_ONLY: dict[str, CaptiveOnly] = {}


def captive_only(captive) -> CaptiveOnly:
    """The captive-only candidate of ``captive = (folder, captive-only fit)``: the fit's hull and
    interaction estimates and their robust covariance (made once per process and folder)."""
    folder, fit = str(captive[0]), captive[1]
    if folder not in _CAPTIVE_ONLY:
        belief = fit.uncertainty("robust")
        model = set(study_model().param_names)
        keep = [i for i, n in enumerate(belief.names) if "@" not in n and n in model]
        names = [belief.names[i] for i in keep]
        cov = belief.cov[np.ix_(keep, keep)]
        values = {n: float(fit.estimates[n]) for n in names}
        _CAPTIVE_ONLY[folder] = CaptiveOnly(values, ParameterBelief.from_values(
            names, [values[n] for n in names], cov, "captive-only fit of the HMRI tests (robust covariance)",
            kind="robust"))
    return _CAPTIVE_ONLY[folder]


def inner_groups(names, k: int = INNER_FOLDS) -> list[list[str]]:
    """The inner folds: ``names`` in sorted order dealt round-robin to ``min(k, len(names))`` groups."""
    names = sorted(names)
    k = min(k, len(names))
    return [names[i::k] for i in range(k)]


def heading_rmse(run: Run, params: dict) -> float:
    """Heading RMSE [deg] of ``run`` replayed with ``params`` on the study's model."""
    return float(replay(study_model(), run.data, params).errors["psi_rmse_deg"])


def choose(train: list[Run], smoothed: dict, curve, *, dt: float, max_free: int, captive) -> dict:
    """The nested choice of :data:`RULE` on the training runs ``train``.

    Returns
    -------
    dict
        ``choice`` (``"joint"`` or ``"captive-only"``), ``scores`` (mean heading RMSE per candidate
        [deg]), ``per_run`` (each training run's held-out RMSE per candidate), ``groups`` and ``rule``.
    """
    cap = captive_only(captive)
    per = {r.name: {"captive-only": per_run(("captive-only replay",), r, lambda r=r: heading_rmse(r, cap.params()))}
           for r in train}
    groups = inner_groups([r.name for r in train]) if len(train) >= 2 else []
    for group in groups:
        inner = fit_fold([r for r in train if r.name not in group], smoothed, curve, dt=dt, max_free=max_free,
                         captive=captive)
        for r in (r for r in train if r.name in group):
            per[r.name]["joint"] = heading_rmse(r, inner.params(r.facility))
    scores = {"captive-only": float(np.mean([v["captive-only"] for v in per.values()])),
              "joint": float(np.mean([v["joint"] for v in per.values()])) if groups else float("nan")}
    choice = "joint" if groups and scores["joint"] < scores["captive-only"] else "captive-only"
    return {"choice": choice, "scores": scores, "per_run": per, "groups": groups, "rule": RULE}
