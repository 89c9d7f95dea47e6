"""The result of the ship workflow (:func:`casship.identify.identify_ship`) and the pooling of a
facility's own quantities over facilities.

:class:`ShipFit` holds the last refinement's fit, the choices that made it with their reasons, the
values set before the fit, and the facility quantities pooled over facilities
(:func:`pool_facilities`); it writes the fit file a replay reads (the parameters and the covariance
for a record of a given facility, the population value and the between-facility spread for a
facility the training lacks).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..errors import InputError
from .records import record_label

__all__ = ["ShipFit", "TRAINING", "pool_facilities"]

#: ``facility`` of :meth:`ShipFit.to_json`: the training records' facility when they share one.
TRAINING = "the training records' facility"


def pool_facilities(estimates: Mapping[str, tuple[float, float]], *, spread: float, prior_std: float,
                    prior_mean: float = 0.0) -> dict:
    """Normal-normal pooling of a facility quantity: ``value_f ~ N(mu, spread^2)``, ``mu ~ N(prior_mean,
    prior_std^2)``; ``estimates`` facility -> (estimate, standard error).

    Returns ``population`` (posterior mean of ``mu``), ``population_std`` and ``new_facility_std``
    (``sqrt(var(mu) + spread^2)``: what a record of a facility not in ``estimates`` is replayed with).

    Parameters
    ----------
    estimates : mapping facility -> (estimate, standard error)
    spread : float
        Between-facility standard deviation.
    prior_std, prior_mean : float
        Prior of the population value.

    Returns
    -------
    dict
        ``population``, ``population_std``, ``new_facility_std``, ``spread`` and ``facilities``.
    """
    prec = 1.0 / prior_std**2
    num = prior_mean * prec
    for est, se in estimates.values():
        w = 1.0 / (spread**2 + se**2)
        prec += w
        num += w * est
    var = 1.0 / prec
    return {"population": num * var, "population_std": math.sqrt(var),
            "new_facility_std": math.sqrt(var + spread**2), "spread": spread,
            "facilities": {f: {"value": float(e), "std_error": float(s)} for f, (e, s) in estimates.items()}}


@dataclass
class ShipFit:
    """The result of :func:`identify_ship`: the fit, the choices that made it and their reasons.

    Parameters
    ----------
    fit : FitResult
        The last refinement (with the workflow's verdict and model discrepancy when judged).
    model : Model
    free : list of str
        The free set of the last refinement.
    choices : list of dict
        Each choice: ``step``, ``choice``, ``reason``.
    sigma : dict
        Channel standard deviations of the cost.
    record_weights : list of float
    selection : list
        Rows of the last run-level selection.
    first_free : list of str
        The free set chosen at the preset.
    preset : dict
        Values set before the fit (propulsion, asymmetry).
    start : dict
        Inverse-dynamics estimates (guesses only).
    asymmetry_fit : FitResult or None
        The mirror-pair stage.
    asymmetry : dict
        Ship asymmetry terms applied.
    facility : dict
        Facility quantity -> :func:`pool_facilities` output.
    facilities : list of str
        One facility label per record.
    seconds : float
        Wall time of the workflow.
    unpinned : dict
        Mirror-only terms without mirrored evidence: their prior standard deviations.
    """

    fit: object                            # FitResult of the last refinement
    model: object = field(repr=False)
    free: list
    choices: list                          # dicts: step, choice, reason
    sigma: dict
    record_weights: list
    selection: list = field(default_factory=list)   # rows of the last run-level selection
    first_free: list = field(default_factory=list)
    preset: dict = field(default_factory=dict)      # values set before the fit (propulsion, asymmetry)
    start: dict = field(default_factory=dict)       # inverse-dynamics estimates (guesses only)
    asymmetry_fit: object = None                    # FitResult of the mirror-pair stage
    asymmetry: dict = field(default_factory=dict)   # ship asymmetry terms applied: name -> value
    facility: dict = field(default_factory=dict)    # facility quantity -> pool_facilities() output
    facilities: list = field(default_factory=list)  # one label per record
    seconds: float = 0.0
    unpinned: dict = field(default_factory=dict)    # mirror-only terms without mirrored evidence: prior std

    def params(self, facility: str | None = None) -> dict:
        """The parameter values to replay a record of ``facility`` with (its own neutral angle when the
        training had one, else the population value).

        Parameters
        ----------
        facility : str, optional
            The record's facility (None: the population values).

        Returns
        -------
        dict
        """
        p = dict(self.fit.params)
        for q, pool in self.facility.items():
            own = pool["facilities"].get(facility)
            p[q] = own["value"] if own else pool["population"]
        return p

    def uncertainty(self, facility: str | None = None):
        """The covariance a replay of a record of ``facility`` uses: the refinement's robust one, the
        mirror-pair stage's beside it (independent stages), each facility quantity's standard error
        (own facility) or the population value's with the between-facility spread, and the prior
        variance of the port/starboard terms held at the preset for want of mirrored evidence.

        Parameters
        ----------
        facility : str, optional
            The record's facility (None: the population values with the spread).

        Returns
        -------
        ParameterBelief or None
        """
        from scipy.linalg import block_diag

        from .belief import ParameterBelief

        parts, names, values = [], [], []
        b = self.fit.uncertainty("robust")
        if b is not None:
            parts.append(b.covariance)
            names += b.names
            values += list(b.values)
        if self.asymmetry:
            a = self.asymmetry_fit.uncertainty("robust")
            ia = [a.names.index(n) for n in self.asymmetry if n in a.names]
            parts.append(a.covariance[np.ix_(ia, ia)])
            names += [a.names[i] for i in ia]
            values += [float(a.values[i]) for i in ia]
        for q, std in self.unpinned.items():           # at the preset, known as well as the prior knows them
            if q not in names:
                parts.append(np.array([[std**2]]))
                names.append(q)
                values.append(float(self.fit.params[q]))
        for q, pool in self.facility.items():
            own = pool["facilities"].get(facility)
            parts.append(np.array([[(own["std_error"] if own else pool["new_facility_std"]) ** 2]]))
            names.append(q)
            values.append(own["value"] if own else pool["population"])
        if not names:
            return None
        return ParameterBelief.from_values(names, values, block_diag(*parts), "robust (sandwich) of the refinement and "
                                           "the mirror-pair stage; facility quantities pooled over facilities",
                                           kind="robust")

    def file_facility(self, facility: str | None = TRAINING) -> str | None:
        """The facility a fit file is written for: ``facility``, or with :data:`TRAINING` (the
        default of :meth:`to_json`) the training records' facility when they share one, else None
        (the population values: a file for records of any facility).

        Parameters
        ----------
        facility : str or None
            A facility, None (the population values) or :data:`TRAINING`.

        Returns
        -------
        str or None
        """
        if facility != TRAINING:
            return facility
        own = sorted(set(self.facilities))
        return own[0] if len(own) == 1 else None

    def to_dict(self, facility: str | None = TRAINING, uncertainty=None) -> dict:
        """The fit file's content for replaying records of ``facility`` (see :meth:`params`).

        Parameters
        ----------
        facility : str or None
            The facility of the records the file will replay; None: the population values;
            default :data:`TRAINING` (:meth:`file_facility`).
        uncertainty : ParameterBelief, optional
            The covariance to write (default :meth:`uncertainty`).

        Returns
        -------
        dict
        """
        import dataclasses

        facility = self.file_facility(facility)
        unc = self.uncertainty(facility) if uncertainty is None else uncertainty
        fit = self.fit
        if unc is not None:
            fit = dataclasses.replace(fit, param_covariance=unc.to_dict())
        d = fit.to_dict()
        d["params"] = {k: float(v) for k, v in self.params(facility).items()}
        d["workflow"] = {"choices": self.choices, "free": self.free, "first_free": self.first_free,
                         "sigma": self.sigma, "record_weights": self.record_weights,
                         "facility_quantities": self.facility, "replayed_as_facility": facility,
                         "asymmetry": self.asymmetry}
        return d

    def to_json(self, path, facility: str | None = TRAINING, uncertainty=None, extra: Mapping | None = None):
        """Write the fit file (``casship simulate --params`` replays it) for records of ``facility``.

        Parameters
        ----------
        path : str or Path
        facility : str or None
            The facility of the records the file will replay; None: the population values; default
            :data:`TRAINING`: the training records' facility when they share one (as ``casship
            identify`` writes it), else the population values.
        uncertainty : ParameterBelief, optional
            The covariance to write (default :meth:`uncertainty`).
        extra : mapping, optional
            More top-level entries of the file.

        Returns
        -------
        Path
        """
        from pathlib import Path

        from ..io.jsonfile import write_json

        content = self.to_dict(facility, uncertainty)
        content.update(dict(extra or {}))
        path = Path(path)
        write_json(path, content, what="fit file")
        return path

    def moved(self) -> dict:
        """Every parameter that differs from the preset, with its standard error and stage."""
        nominal = self.model.param_dict()
        out = {n: {"value": float(v), "published": nominal[n], "std_error": math.nan, "stage": "preset (given)"}
               for n, v in self.preset.items() if n not in self.asymmetry}
        for n, v in self.asymmetry.items():
            out[n] = {"value": v, "published": nominal[n], "std_error": self.asymmetry_fit.std_errors[n],
                      "std_error_robust": self.asymmetry_fit.std_errors_robust.get(n, math.nan),
                      "stage": "asymmetry (MAP on the mirror-pair records)"}
        for q, pool in self.facility.items():
            out[q] = {"value": pool["population"], "published": nominal[q], "std_error": pool["new_facility_std"],
                      "stage": "facility quantity, population value (pooled)"}
        for n in self.fit.free:
            if n not in nominal:          # a joined facility's own quantity (name@facility): not the ship's
                continue
            out[n] = {"value": self.fit.estimates[n], "published": nominal[n], "std_error": self.fit.std_errors[n],
                      "std_error_robust": self.fit.std_errors_robust.get(n, math.nan), "stage": "MAP refinement"}
        return out

    def judge(self, records, verdict: str, refit) -> None:
        """Set the verdict and the model discrepancy of ``self.fit``: its records replayed with the ship's full
        parameters (the workflow's presets, facility values and refinement) against the preset, and with
        ``verdict="loo"`` each record replayed by the workflow run without it (``refit(train)``).

        Parameters
        ----------
        records : list of Dataset
            The records the workflow was run on (in its order).
        verdict : {"replay", "loo"}
            Replays of the records only, or also left-one-out.
        refit : callable
            ``refit(train)``: the workflow run on the records whose indices are ``train`` (a ShipFit).
        """
        import dataclasses

        from .verdict import judge_records

        if verdict not in ("replay", "loo"):
            raise InputError(f"verdict must be 'replay', 'loo' or None, got {verdict!r}")
        labels = [record_label(d, i) for i, d in enumerate(records)]

        def as_replayed(s: ShipFit, facility=None):
            return dataclasses.replace(s.fit, params=s.params(facility))

        def refit_full(train):
            return as_replayed(refit(train), self.facilities[[i for i in range(len(records)) if i not in train][0]])

        one = self.facilities[0] if len(set(self.facilities)) == 1 else None
        self.fit.verdict, self.fit.model_discrepancy = judge_records(
            self.model, records, as_replayed(self, one), start=self.model.params(), labels=labels,
            loo=verdict == "loo" and len(records) > 1, refit=refit_full if len(records) > 1 else None)

    def summary(self) -> str:
        """The choices with their reasons, then the fit."""
        lines = ["ship identification workflow: every choice and why"]
        for c in self.choices:
            lines.append(f"  [{c['step']}] {c['choice']}\n      because {c['reason']}")
        lines.append(self.fit.summary())
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"ShipFit(free={self.free}, status={self.fit.status!r}, {len(self.choices)} choices)"
