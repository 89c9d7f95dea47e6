"""Port/starboard asymmetry from mirrored evidence only.

A term that makes a ship turn differently to port and to starboard (a rudder neutral angle, a
propeller-induced side force and yaw moment, a rudder offset ``bias[delta]``) can only be told apart
from the turning dynamics by records that turn both ways under the same conditions. Fitted on
records that turn one way, it absorbs whatever the model gets wrong in that turn and then predicts
the mirror image of the runs wrongly: it is *confounded with the turning dynamics*.

The rule, used by :meth:`~casship.identify.IdentificationProblem.identifiability` (which flags such
quantities in :attr:`~casship.identify.Identifiability.confounded`, and leaves them out of
:meth:`~casship.identify.Identifiability.propose`):

* a record's **turning side** is the sign of its first rudder deflection from the approach angle
  beyond half its largest deflection (:func:`turn_side`);
* two records are a **mirror pair** when they are the same manoeuvre (turning circle, or zig-zag
  with the same switch heading within 2 deg) with the same rudder angle within 2 deg, turning
  first to opposite sides (:func:`mirror_pairs`);
* an asymmetry quantity is estimable only from records that contain a mirror pair: a copy per
  group (e.g. per facility) needs a pair within its group, a shared copy a pair among all records
  (:func:`confounded_asymmetry`; ``within=`` a grouping such as the facility: only records of the
  same group pair). Otherwise it stays at its prior (or the shared value).
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..errors import InputError

__all__ = ["turn_side", "maneuver_signature", "mirror_pairs", "confounded_asymmetry", "asymmetric_quantities",
           "ANGLE_TOL_DEG"]

ANGLE_TOL_DEG = 2.0     # rudder and switch-heading angles within this are the same manoeuvre


def turn_side(data, rudder: str = "delta") -> str:
    """``"+"`` or ``"-"``: the side of the first rudder deflection of a record.

    The first sample whose rudder differs from the approach value (the first sample) by more than
    half the record's largest deflection decides; ``"+"`` is a positive rudder (to starboard in the
    MMG convention). A half-amplitude threshold classifies small manoeuvres (a 5/1 zig-zag) as
    surely as large ones.

    Parameters
    ----------
    data : Dataset
        Record with the rudder column.
    rudder : str
        Name of the rudder column.

    Returns
    -------
    str

    Raises
    ------
    ValueError
        For a record without the column or whose rudder does not move.
    """
    if rudder not in data:
        raise InputError(f"record has no rudder column {rudder!r}")
    d = np.asarray(data[rudder], dtype=float)
    d = d - d[0]
    big = np.abs(d) > 0.5 * np.abs(d).max() if np.abs(d).max() > 0 else np.zeros(d.size, bool)
    if not big.any():
        raise InputError(f"the rudder {rudder!r} of the record does not move")
    return "+" if d[np.flatnonzero(big)[0]] > 0 else "-"


def maneuver_signature(data, rudder: str = "delta") -> dict:
    """Kind, rudder angle [deg], zig-zag switch heading [deg] and first side of a record.

    Parameters
    ----------
    data : Dataset
    rudder : str

    Returns
    -------
    dict
        ``kind`` (``turning``, ``zigzag``, ``other``), ``rudder_deg`` (largest deflection from the
        approach angle), ``heading_deg`` (zig-zags) and ``side``.
    """
    from ..maneuvers import classify_maneuver

    kind, options = classify_maneuver(data, rudder)
    d = np.asarray(data[rudder], dtype=float)
    return {"kind": kind, "rudder_deg": float(np.degrees(np.abs(d - d[0]).max())),
            "heading_deg": options.get("heading_deg"), "side": turn_side(data, rudder)}


def _same(a: dict, b: dict) -> bool:
    if a["kind"] != b["kind"] or a["kind"] == "other" or abs(a["rudder_deg"] - b["rudder_deg"]) > ANGLE_TOL_DEG:
        return False
    return a["kind"] != "zigzag" or abs(a["heading_deg"] - b["heading_deg"]) <= ANGLE_TOL_DEG


def mirror_pairs(records: Sequence, rudder: str = "delta", within: Sequence | None = None) -> list[tuple[int, int]]:
    """Index pairs of records that are the same manoeuvre turning first to opposite sides.

    Parameters
    ----------
    records : sequence of Dataset
    rudder : str
    within : sequence, optional
        One label per record: only records with the same label pair.

    Returns
    -------
    list of (int, int)
    """
    sig = [maneuver_signature(d, rudder) for d in records]
    return [(i, j) for i in range(len(sig)) for j in range(i + 1, len(sig))
            if sig[i]["side"] != sig[j]["side"] and _same(sig[i], sig[j])
            and (within is None or within[i] == within[j])]


def asymmetric_quantities(model) -> list[str]:
    """The model's port/starboard asymmetry parameters (``model.meta["asymmetric"]``) and the
    offsets of its rudder inputs (``bias[<rudder>]``).

    Parameters
    ----------
    model : Model

    Returns
    -------
    list of str
    """
    rudders = list(model.vessel.rudders) if getattr(model, "vessel", None) is not None else []
    return [*model.meta.get("asymmetric", ()), *(f"bias[{r}]" for r in rudders)]


def confounded_asymmetry(records: Sequence, quantities: Sequence[str], copies: Mapping[str, Sequence] | None = None,
                         rudder: str = "delta", within: Sequence | None = None) -> dict[str, str]:
    """Free asymmetry quantities the records cannot tell from the turning dynamics, with the reason.

    Parameters
    ----------
    records : sequence of Dataset
    quantities : sequence of str
        Free quantities (``name`` or per-group copies ``name@label``); those whose declared name is
        not asymmetric are ignored by the caller's choice of ``quantities``.
    copies : mapping name -> labels, optional
        For a quantity estimated per group, the group label of each record (``None``: the record
        does not use a copy), as from :func:`casship.identify.share_labels`.
    rudder : str
    within : sequence, optional
        One label per record (e.g. its facility): only records with the same label form a mirror
        pair (a difference between facilities is not a port/starboard asymmetry).

    Returns
    -------
    dict
        Quantity -> why it is confounded (empty when every quantity has mirrored evidence).
    """
    copies = dict(copies or {})
    sig = [maneuver_signature(d, rudder) for d in records]
    same = (lambda i, j: True) if within is None else (lambda i, j: within[i] == within[j])  # noqa: E731
    pairs = {(i, j) for i in range(len(sig)) for j in range(i + 1, len(sig))
             if sig[i]["side"] != sig[j]["side"] and _same(sig[i], sig[j]) and same(i, j)}
    out = {}
    for q in quantities:
        name, _, label = q.partition("@")
        if label and name in copies:
            members = [i for i, lab in enumerate(copies[name]) if lab is not None and str(lab) == label]
            where = f"the records of group {label!r}"
        else:
            members = list(range(len(records)))
            where = "the records"
        if not any(i in members and j in members for i, j in pairs):
            sides = sorted({sig[i]["side"] for i in members})
            out[q] = (f"{where} hold no mirror pair (same manoeuvre turning first to both sides; first sides "
                      f"{'/'.join(sides) or 'none'}): confounded with the turning dynamics")
    return out
