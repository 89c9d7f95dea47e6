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

from .records import facility_of, record_label
from .shipfit import TRAINING

__all__ = ["INNER_FOLDS", "RULE", "CaptiveChoice", "CaptiveShip", "choose_with_captive", "identify_with_captive",
           "inner_groups"]

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
    labels = [record_label(d, i) for i, d in enumerate(records)]
    if len(set(labels)) < len(labels):          # the rule deals names: make repeated names distinct
        labels = [f"{i}:{lab}" for i, lab in enumerate(labels)]
    return labels


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
    from .verdict import heading_rmse
    from .workflow import identify_ship

    records = list(records)
    if not records:
        raise InputError("choose_with_captive: no records")
    missing = [record_label(d, i) for i, d in enumerate(records) if "psi" not in d]
    if missing:
        raise InputError(f"choose_with_captive: records {missing} hold no heading psi (the choice replays the heading)")
    labels = _unique_labels(records)
    values, _ = carried(captive_fit, model)
    captive_params = {**model.param_dict(), **values}
    per = {lab: {"captive-only": heading_rmse(model, d, captive_params)} for lab, d in zip(labels, records)}
    groups = inner_groups(labels) if len(records) >= 2 else []
    for g, group in enumerate(groups):
        if progress is not None:
            progress(f"inner fold {g + 1} of {len(groups)}: the joint fit without {', '.join(group)}")
        train = [d for lab, d in zip(labels, records) if lab not in group]
        ship = identify_ship(train, model, terms=[problem.cost_term(captive_fit)], verdict=None, **dict(workflow or {}))
        for lab, d in zip(labels, records):
            if lab in group:
                per[lab]["joint"] = heading_rmse(model, d, ship.params(facility_of(d)))
    scores = {"captive-only": float(np.mean([v["captive-only"] for v in per.values()])),
              "joint": float(np.mean([v["joint"] for v in per.values()])) if groups else float("nan")}
    choice = "joint" if groups and scores["joint"] < scores["captive-only"] else "captive-only"
    return CaptiveChoice(choice, scores, per, groups)


@dataclass
class CaptiveShip:
    """The result of :func:`identify_with_captive`: the chosen model of the ship and why.

    Parameters
    ----------
    model : Model
        The ship.
    captive_fit : FitResult
        The captive tests' own fit (on their rig's model).
    choice : CaptiveChoice
        The nested choice (``"captive-only"`` without records).
    ship : ShipFit or None
        The joint fit, when chosen.
    values : dict
        The captive-only model's carried values (hull and interaction), when chosen.
    belief : ParameterBelief or None
        Their robust covariance.
    verdict, discrepancy : dict or None
        The captive-only model judged on the records it has not seen
        (:func:`~.verdict.judge_unseen`); None without records.
    classical : dict
        The classical linear derivatives of the tests (:func:`~.rig.classical_derivatives`), beside the
        captive-only model's.
    """

    model: object = field(repr=False)
    captive_fit: object = field(repr=False)
    choice: CaptiveChoice
    ship: object = None
    values: dict = field(default_factory=dict)
    belief: object = field(default=None, repr=False)
    verdict: dict | None = None
    discrepancy: dict | None = None
    classical: dict = field(default_factory=dict)

    @property
    def worse(self) -> bool:
        """True when the chosen model is worse than its start, or its fit stalled."""
        if self.ship is not None:
            return bool(self.ship.fit.worse)
        return self.verdict is not None and self.verdict["verdict"] in ("worse", "stalled")

    @property
    def verdict_block(self) -> dict | None:
        """The chosen model's verdict (the joint fit's own, or the captive-only model's out of sample)."""
        return self.ship.fit.verdict if self.ship is not None else self.verdict

    def to_json(self, path, facility: str | None = TRAINING):
        """Write the chosen model as a fit file (``casship simulate --params`` replays it), with the choice
        (``captive_choice``) and the captive fit (``captive_fit``).

        Parameters
        ----------
        path : str or Path
        facility : str or None
            The facility of the records the file will replay (the joint fit's facility quantities;
            :meth:`~.shipfit.ShipFit.to_json`: by default the records' facility when they share one).

        Returns
        -------
        Path
        """
        from .rig import write_carried

        extra = {"captive_choice": self.choice.to_dict(), "captive_fit": self.captive_fit.to_dict()}
        if self.ship is not None:
            return self.ship.to_json(path, facility, extra=extra)
        if self.verdict is not None:
            extra.update(verdict=self.verdict, model_discrepancy=self.discrepancy)
        return write_carried(path, self.model, self.values, self.belief, extra=extra)

    def summary(self) -> str:
        """The choice, then the joint fit, or the carried coefficients beside the model's and their verdict."""
        s = self.choice.scores
        if not self.choice.per_record:
            lines = ["[captive] captive-only: no free-running record, the captive tests alone (the classical route)"]
        else:
            how = (f"captive-only {s['captive-only']:.3g} deg, joint {s['joint']:.3g} deg (inner cross-validation)"
                   if self.choice.groups else "no inner split: a single record")
            lines = [f"[captive] {self.choice.choice}: mean heading RMSE of the records, {how}",
                     f"      because {self.choice.rule}"]
        if self.ship is not None:
            lines.append(self.ship.fit.summary())
            return "\n".join(lines)
        lines.append(self.captive_fit.summary())
        start = self.model.param_dict()
        if self.classical:
            lines.append("\nclassical linear derivatives from the first harmonics and the static drift slope (cross-check):")
            lines.append(f"{'name':>16} {'classical':>11} {'fit':>11} {'published':>11}")
            for n in ("Y_v_dash", "N_v_dash", "N_r_dash", "m_y_dash", "J_z_dash"):
                if n in self.classical and n in self.captive_fit.estimates:
                    lines.append(f"{n:>16} {self.classical[n]:>11.5g} {self.captive_fit.estimates[n]:>11.5g} "
                                 f"{start.get(n, float('nan')):>11.5g}")
        sd = dict(zip(self.belief.names, np.sqrt(np.diag(self.belief.cov))))
        own = [n for n in self.captive_fit.free if "@" in n]
        lines.append(f"\ncarried to {self.model.name!r} ({len(self.values)} hull and interaction coefficients, robust "
                     f"standard errors; {', '.join(own)} stay with the rig):")
        lines.append(f"{'name':>16} {'published':>11} {'captive':>11} {'SE':>9} {'z':>7}")
        for n, v in self.values.items():
            lines.append(f"{n:>16} {start[n]:>11.5g} {v:>11.5g} {sd[n]:>9.3g} {(v - start[n]) / sd[n]:>7.1f}")
        held = [n for n in self.belief.names if n not in self.values]
        if held:
            lines.append("at the preset, with the facility rule's spread in the bands (no captive test pins them on "
                         "the ship): " + ", ".join(f"{n} {start[n]:.4g} +- {sd[n]:.3g}" for n in held))
        if self.verdict is None:
            lines.append("no free-running record: no model-discrepancy term, so replays' predictive band is the "
                         "parameter band alone; give records beside the captive tests to estimate one")
        else:
            for row in self.verdict["records"]:
                lines.append(f"  {row['record']}: heading RMSE {row['psi_rmse_deg_start']:.3g} deg published, "
                             f"{row['psi_rmse_deg_fit']:.3g} deg captive-only")
            lines.append(f"model discrepancy q = {self.discrepancy['psi_variance_growth_deg2_per_s']:.3g} deg^2/s "
                         f"({self.discrepancy['method']})")
            lines.append(f"VERDICT: {self.verdict['verdict']}: {self.verdict['reason']}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready: the choice, the chosen model's verdict, and the joint fit or the carried values."""
        out = {"model": self.model.name, "captive_choice": self.choice.to_dict(),
               "captive_fit": self.captive_fit.to_dict(), "verdict": self.verdict_block}
        if self.ship is not None:
            return {**out, "joint": self.ship.to_dict()}
        return {**out, "carried": dict(self.values), "model_discrepancy": self.discrepancy,
                "classical_derivatives": dict(self.classical)}


def identify_with_captive(records, model, problem, captive_fit=None, *, workflow: Mapping | None = None,
                          verbose: bool = False, progress=None) -> CaptiveShip:
    """Captive tests, alone or beside free-running records, in one call: the model :data:`RULE` chooses.

    Without records the captive-only model is the result (the classical route, carried to
    ``model``). With records the nested choice (:func:`choose_with_captive`) picks the captive-only
    model or the joint fit: the joint fit is then the ship workflow on all records with the captive
    term (:func:`~.workflow.identify_ship`, judged as it judges itself); the captive-only model is
    judged on the records, all out of sample (:func:`~.verdict.judge_unseen`).

    Parameters
    ----------
    records : sequence of Dataset
        Free-running records (may be empty).
    model : str or Model
        The ship (a registered name or a model).
    problem : CaptiveProblem
        The captive tests on their rig's model (:meth:`~.rig.Rig.problem`).
    captive_fit : FitResult, optional
        Its fit (default: solved here).
    workflow : mapping, optional
        Keyword arguments of :func:`~.workflow.identify_ship` (``weights``, ``prior``, ``measured``...).
    verbose : bool
        Print the joint workflow's choices as they are made.
    progress : callable, optional
        ``progress(text)`` before each long step.

    Returns
    -------
    CaptiveShip
    """
    from ..models import get_model
    from .rig import carried, classical_derivatives
    from .verdict import judge_unseen
    from .workflow import identify_ship

    model = get_model(model) if isinstance(model, str) else model
    records = list(records)
    if captive_fit is None:
        captive_fit = problem.solve()
    if not records:
        values, belief = carried(captive_fit, model)
        return CaptiveShip(model, captive_fit, CaptiveChoice("captive-only", {"captive-only": float("nan"),
                                                                              "joint": float("nan")}, {}),
                           values=values, belief=belief, classical=classical_derivatives(problem))
    choice = choose_with_captive(records, model, problem, captive_fit, workflow=workflow, progress=progress)
    if choice.choice == "joint":
        if progress is not None:
            progress("the joint fit on every record")
        ship = identify_ship(records, model, terms=[problem.cost_term(captive_fit)], verbose=verbose,
                             **dict(workflow or {}))
        return CaptiveShip(model, captive_fit, choice, ship=ship)
    if progress is not None:
        progress("judging the captive-only model on the records (out of sample)")
    values, belief = carried(captive_fit, model)
    verdict, discrepancy = judge_unseen(model, records, values, uncertainty=belief)
    return CaptiveShip(model, captive_fit, choice, values=values, belief=belief, verdict=verdict,
                       discrepancy=discrepancy, classical=classical_derivatives(problem))
