"""Records of an identification: noise estimates, initial states and groups.

Functions here prepare what a multi-run fit needs from its records before any model is evaluated:
the measurement noise of each channel estimated from the record itself (:func:`noise_std`), each
record's initial state from its first row, refusing a missing value (:func:`initial_states`), and
the labels that say which records share a copy of a per-record or per-group quantity
(:func:`share_labels`); sample intervals a simulation cannot step over are refused (:func:`check_gaps`).
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from ..data import Dataset
from ..estimators.prior import second_difference_std
from ..errors import InputError, InputTypeError

__all__ = ["check_gaps", "noise_std", "initial_states", "share_labels", "record_label", "facility_of", "DEFAULT_FACILITY",
           "as_records"]


def as_records(datasets) -> list[Dataset]:
    """A list of :class:`~casship.Dataset` from one record or a sequence.

    Parameters
    ----------
    datasets : Dataset or sequence of Dataset

    Returns
    -------
    list of Dataset

    Raises
    ------
    TypeError
        Naming the first item that is not a Dataset.
    ValueError
        For no records, or a record of fewer than two rows (naming it).
    """
    records = [datasets] if isinstance(datasets, Dataset) else list(datasets)
    if not records:
        raise InputError("no data records given")
    for i, d in enumerate(records):
        if not isinstance(d, Dataset):
            raise InputTypeError(f"record {i} is a {type(d).__name__}, not a casship.Dataset")
        if len(d) < 2:
            raise InputError(f"record {record_label(d, i)!r} has {len(d)} row(s); an identification record "
                             "needs at least two samples")
    return records


#: The facility of a record whose ``meta`` names none (all such records are one facility).
DEFAULT_FACILITY = "records"


def facility_of(record: Dataset) -> str:
    """The facility label of a record: its ``meta["facility"]``, else :data:`DEFAULT_FACILITY`.

    Parameters
    ----------
    record : Dataset

    Returns
    -------
    str
    """
    return str(record.meta.get("facility", DEFAULT_FACILITY))


def record_label(data: Dataset, i: int) -> str:
    """A record's name for messages and plots.

    Parameters
    ----------
    data : Dataset
    i : int
        Its index among the records.

    Returns
    -------
    str
        ``meta["name"]``, else ``meta["source"]``, else ``"record i"``.
    """
    return str(data.meta.get("name", data.meta.get("source", f"record {i}")))


def noise_std(records, names: Sequence[str], angles: Sequence[str] = ()) -> dict[str, float]:
    """Measurement noise standard deviation of each named channel, estimated from the records.

    A high-pass of each record: the second difference of a smooth signal sampled fast is small,
    that of white noise has variance ``6 sigma^2``; the median absolute second difference
    (robust to manoeuvres and outliers) gives ``sigma = MAD / 0.6745 / sqrt(6)``, pooled over the
    records (median of the per-record values). Channels named in ``angles`` are unwrapped first.
    Assumes samples faster than the dynamics; coloured or quantised measurements bias it.

    Parameters
    ----------
    records : Dataset or sequence of Dataset
    names : sequence of str
        Channels (columns).
    angles : sequence of str
        Channels that are angles (unwrapped before differencing).

    Returns
    -------
    dict
        Channel -> standard deviation.

    Raises
    ------
    ValueError
        For a channel with fewer than 5 finite samples in every record, or whose estimate is zero
        (a constant or quantised channel: give its standard deviation instead).
    """
    out = {}
    for n in names:
        per = []
        for d in as_records(records):
            if n not in d:
                raise InputError(f"no column {n!r} in record {record_label(d, 0)!r}; columns: {list(d.names)}")
            std = second_difference_std(d[n], n in angles)
            if std is not None:
                per.append(std)
        if not per:
            raise InputError(f"channel {n!r}: fewer than 5 finite samples in every record; give its noise level")
        s = float(np.median(per))
        if not s > 0:
            raise InputError(f"channel {n!r}: noise estimate is zero (constant or quantised channel); "
                             "give its standard deviation")
        out[n] = s
    return out


def initial_states(model, records, x0=None, estimated: Sequence[str] = ()) -> list[np.ndarray]:
    """Initial state of each record.

    Parameters
    ----------
    model : Model
    records : Dataset or sequence of Dataset
    x0 : None, mapping or sequence, optional
        See below.
    estimated : sequence of str
        States whose initial values are free.

    Returns
    -------
    list of (nx,) arrays

    Notes
    -----
    ``x0`` is ``None`` (states named like a column start at its first value, the others at 0), a
    mapping state -> value for every record, or one vector/mapping per record. States in
    ``estimated`` are free (their start is still taken from the data when a column has them).

    Raises ``ValueError`` naming the record and column when a state's column is NaN in the first
    row (and neither ``x0`` nor ``estimated`` gives it): a missing start is never taken as 0.
    """
    records = as_records(records)
    if x0 is not None and not isinstance(x0, Mapping):
        x0 = list(x0)
        if len(x0) != len(records):
            raise InputError(f"x0: {len(x0)} initial states for {len(records)} records")
        out = []
        for i, v in enumerate(x0):
            v = model.states(**v) if isinstance(v, Mapping) else np.asarray(v, dtype=float).reshape(-1)
            if v.shape != (model.nx,):
                raise InputError(f"x0 of record {i} has {v.size} values, model {model.name!r} has {model.nx} states")
            if not np.all(np.isfinite(v)):
                raise InputError(f"x0 of record {i} is not finite: {v}")
            out.append(v)
        return out
    given = dict(x0 or {})
    model.indices(given, "state")
    out = []
    for i, d in enumerate(records):
        v = np.zeros(model.nx)
        for j, s in enumerate(model.state_names):
            if s in given:
                v[j] = float(given[s])
            elif s in d:
                first = float(d[s][0])
                if not np.isfinite(first):
                    if s in estimated:
                        ok = np.flatnonzero(np.isfinite(d[s]))
                        first = float(d[s][ok[0]]) if ok.size else 0.0
                    else:
                        raise InputError(f"record {record_label(d, i)!r}: state {s!r} is NaN in the first row "
                                         f"(t = {d.t[0]:g} s); give x0 for it, estimate it (estimate_x0) "
                                         "or start the record where it is measured")
                v[j] = first
        out.append(v)
    return out


def share_labels(records, share: Mapping | None, groups: Mapping | None = None) -> dict[str, list]:
    """Per-record labels of the quantities that are not shared by all records.

    ``share`` maps a free quantity to ``"record"`` (one copy per record, labelled by its index),
    ``"all"`` (the default), the name of a grouping or a list of labels (one per record; ``None``
    = the record keeps the fixed value). A grouping name is looked up in ``groups`` (name -> list of
    labels) and then in each record's ``meta``.

    Parameters
    ----------
    records : Dataset or sequence of Dataset
    share : mapping name -> str or sequence, optional
    groups : mapping grouping name -> sequence of labels, optional

    Returns
    -------
    dict
        Name -> one label (str, or None) per record, for the names not shared by all records.

    Examples
    --------
    >>> import numpy as np, casship as cs
    >>> recs = [cs.Dataset([0.0, 1.0], {"a": [0.0, 0.0]}, meta={"facility": f}) for f in ("A", "A", "B")]
    >>> share_labels(recs, {"X": "record", "Y": "facility"})
    {'X': ['0', '1', '2'], 'Y': ['A', 'A', 'B']}
    """
    records = as_records(records)
    groups = dict(groups or {})
    for key, labels in groups.items():
        if len(labels) != len(records):
            raise InputError(f"grouping {key!r}: {len(labels)} labels for {len(records)} records")
    out = {}
    for name, how in dict(share or {}).items():
        if isinstance(how, str):
            if how == "all":
                continue
            if how == "record":
                labels = [str(i) for i in range(len(records))]
            elif how in groups:
                labels = list(groups[how])
            else:
                missing = [record_label(d, i) for i, d in enumerate(records) if how not in d.meta]
                if missing:
                    raise InputError(f"share[{name!r}] = {how!r}: not a grouping given in groups "
                                     f"{sorted(groups)} and records {missing} have no meta[{how!r}]")
                labels = [d.meta[how] for d in records]
        else:
            labels = list(how)
            if len(labels) != len(records):
                raise InputError(f"share[{name!r}]: {len(labels)} labels for {len(records)} records")
        labels = [None if lab is None else str(lab) for lab in labels]
        bad = [lab for lab in labels if lab is not None and (not lab or any(c in lab for c in "@[], "))]
        if bad:
            raise InputError(f"share[{name!r}]: labels must be non-empty without '@[], ', got {bad}")
        if how != "record" and any(lab is not None and lab.isdigit() for lab in labels):
            raise InputError(f"share[{name!r}]: group labels must not be plain numbers (those name records)")
        out[name] = labels
    return out


def check_gaps(dmodel, records, x0, params, labels) -> None:
    """Refuse a sample interval longer than a fixed-step discretisation predicts over stably.

    A simulation (output error) steps from sample to sample; over a gap beyond the stability limit of
    ``euler``/``rk4`` at the start (:func:`casship.simulation.validity.stable_step` times the sub-steps) it
    explodes instead of predicting. Adaptive and exact discretisations have no limit.

    Parameters
    ----------
    dmodel : DiscreteModel
    records : list of Dataset
    x0 : list of array
        Each record's initial state (the linearisation point).
    params : array
        Parameter vector.
    labels : list of str
        Record names for the message.

    Raises
    ------
    ValueError
        Naming the record, the rows and the limit.
    """
    from ..simulation import is_stable_step, stable_step

    m = dmodel.model
    substeps = getattr(dmodel, "substeps", 1)
    for d, x, label in zip(records, x0, labels):
        u = d.matrix(m.input_names)[0] if m.nu else np.zeros(0)
        x = np.asarray(x, dtype=float)
        if is_stable_step(m, x, u, params, dmodel.method, float(d.dt.max()) / substeps):
            continue
        limit = stable_step(m, x, u, params, dmodel.method) * substeps
        long = np.flatnonzero(d.dt > limit)
        if long.size:
            k = int(long[0])
            raise InputError(f"record {label!r}: time gap of {d.dt[k]:.4g} s between t = {d.t[k]:g} and "
                             f"{d.t[k + 1]:g} s (rows {k} and {k + 1}) is longer than {limit:.4g} s, the longest "
                             f"step the {dmodel.method} simulation takes stably; split the record there")
