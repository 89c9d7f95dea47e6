"""Captive tests beside free-running records: the captive-only model or the joint fit, chosen without
grading itself.

Captive tests and free-running records can make two models of a ship: the **captive-only** model
(the hull and interaction coefficients of the captive fit carried to the ship, :func:`~.rig.carried`;
it has seen no free-running record, so every record is out of sample for it) and the **joint** fit
(the captive tests and the records in one objective, :func:`~.workflow.identify_ship` with the
captive term). Which predicts a new run better is decided on the records by nested cross-validation
(:data:`RULE`): the records are dealt to :data:`INNER_FOLDS` groups, each group replayed by the joint
fit of the other groups; the captive-only model replays every record. The joint fit is chosen only
when its mean heading RMSE is lower; a tie, or a single record (no split), keeps the captive-only
model, the one that spends no free-running evidence. The rule is the ``kvlcc2-marin`` study's
(``casship study kvlcc2-marin``), declared there before it was first run.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

__all__ = ["INNER_FOLDS", "RULE", "CaptiveChoice", "choose_with_captive", "inner_groups"]

#: Groups of the inner cross-validation.
INNER_FOLDS = 3
#: The rule, as the fit files record it.
RULE = ("nested choice on the training runs only: captive-only model (scored on every training run, all out of "
        "sample) against the joint fit (scored by an inner 3-fold cross-validation of the training runs, dealt in "
        "name order); lower mean heading RMSE wins, a tie or fewer than 2 training runs keeps the captive-only model")


def inner_groups(names: Sequence[str], k: int = INNER_FOLDS) -> list[list[str]]:
    """The inner folds: ``names`` in sorted order dealt round-robin to ``min(k, len(names))`` groups.

    Parameters
    ----------
    names : sequence of str
        Record names.
    k : int
        Number of groups at most.

    Returns
    -------
    list of list of str
    """
    names = sorted(names)
    k = min(k, len(names))
    return [names[i::k] for i in range(k)]


@dataclass
class CaptiveChoice:
    """The outcome of :func:`choose_with_captive`.

    Parameters
    ----------
    choice : {"captive-only", "joint"}
    scores : dict
        Mean heading RMSE [deg] per candidate (``nan`` for the joint fit without an inner split).
    per_record : dict
        Record -> candidate -> heading RMSE [deg] (captive-only: a replay; joint: its inner fold's).
    groups : list of list of str
        The inner folds (records held out together).
    rule : str
    """

    choice: str
    scores: dict
    per_record: dict
    groups: list = field(default_factory=list)
    rule: str = RULE

    def to_dict(self) -> dict:
        """JSON-ready."""
        return {"choice": self.choice, "scores": self.scores, "per_run": self.per_record, "groups": self.groups,
                "rule": self.rule}


def _unique_labels(records) -> list[str]:
    labels = [str(d.meta.get("name", i)) for i, d in enumerate(records)]
    if len(set(labels)) < len(labels):          # the rule deals names: make repeated names distinct
        labels = [f"{i}:{lab}" for i, lab in enumerate(labels)]
    return labels


def _heading_rmse(model, data, params) -> float:
    from ..maneuvers import replay
    from ..simulation import IntegrationError

    try:
        e = replay(model, data, model.params(params), check_limits=False, samples=0).errors.get("psi_rmse_deg")
    except (IntegrationError, ValueError, FloatingPointError, RuntimeError):
        return float("inf")
    return float(e) if e is not None and np.isfinite(e) else float("inf")


def choose_with_captive(records, model, problem, captive_fit, *, workflow: Mapping | None = None,
                        progress=None) -> CaptiveChoice:
    """The nested choice of :data:`RULE` between the captive-only model and the joint fit on ``records``.

    Parameters
    ----------
    records : sequence of Dataset
        Free-running records with a heading ``psi``.
    model : Model
        The ship.
    problem : CaptiveProblem
        The captive tests on their rig's model (:meth:`~.rig.Rig.problem`).
    captive_fit : FitResult
        Its fit (:meth:`~.captive.CaptiveProblem.solve`): the captive-only estimates and the noise
        levels that weigh the tests in the joint objective.
    workflow : mapping, optional
        Further keyword arguments of :func:`~.workflow.identify_ship` for the inner fits.
    progress : callable, optional
        ``progress(text)`` before each inner fit.

    Returns
    -------
    CaptiveChoice
    """
    from ..errors import InputError
    from .rig import carried
    from .workflow import identify_ship

    records = list(records)
    if not records:
        raise InputError("choose_with_captive: no records")
    missing = [str(d.meta.get("name", i)) for i, d in enumerate(records) if "psi" not in d]
    if missing:
        raise InputError(f"choose_with_captive: records {missing} hold no heading psi (the choice replays the heading)")
    labels = _unique_labels(records)
    values, _ = carried(captive_fit, model)
    captive_params = {**model.param_dict(), **values}
    per = {lab: {"captive-only": _heading_rmse(model, d, captive_params)} for lab, d in zip(labels, records)}
    groups = inner_groups(labels) if len(records) >= 2 else []
    for g, group in enumerate(groups):
        if progress is not None:
            progress(f"inner fold {g + 1} of {len(groups)}: the joint fit without {', '.join(group)}")
        train = [d for lab, d in zip(labels, records) if lab not in group]
        ship = identify_ship(train, model, terms=[problem.cost_term(captive_fit)], verdict=None, **dict(workflow or {}))
        for lab, d in zip(labels, records):
            if lab in group:
                per[lab]["joint"] = _heading_rmse(model, d, ship.params(d.meta.get("facility")))
    scores = {"captive-only": float(np.mean([v["captive-only"] for v in per.values()])),
              "joint": float(np.mean([v["joint"] for v in per.values()])) if groups else float("nan")}
    choice = "joint" if groups and scores["joint"] < scores["captive-only"] else "captive-only"
    return CaptiveChoice(choice, scores, per, groups)
