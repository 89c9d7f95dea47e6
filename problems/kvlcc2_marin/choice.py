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

from casship.identify import ParameterBelief
from casship.identify.captive_choice import INNER_FOLDS, RULE, inner_groups
from casship.identify.rig import carried, write_carried
from casship.maneuvers import replay

from .data import Run, per_run
from .workflow import fit_fold, study_model

__all__ = ["INNER_FOLDS", "RULE", "CaptiveOnly", "captive_only", "inner_groups", "choose"]


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
        return write_carried(path, study_model(), self.values, self.belief, noise=noise,
                             method="captive-only (HMRI PMM tests), Gaussian ML", extra=extra)


_CAPTIVE_ONLY: dict[str, CaptiveOnly] = {}


def captive_only(captive) -> CaptiveOnly:
    """The captive-only candidate of ``captive = (folder, captive-only fit)``: the fit's hull and
    interaction estimates and their robust covariance (made once per process and folder)."""
    folder, fit = str(captive[0]), captive[1]
    if folder not in _CAPTIVE_ONLY:
        _CAPTIVE_ONLY[folder] = CaptiveOnly(*carried(fit, study_model()))
    return _CAPTIVE_ONLY[folder]


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
