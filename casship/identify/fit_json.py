"""The JSON of a fit or parameter file: the one reader of such files and the fields of a fit.

A leaf module (numpy and casship's errors only), so that both the fit
(:class:`~casship.identify.FitResult`) and the parameter belief built from it
(:class:`~casship.identify.ParameterBelief`) read a file through it.
"""
from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..errors import InputError

__all__ = ["load_fit_json", "fit_fields", "fit_view", "square_matrix", "SCALARS", "DICTS", "LISTS"]

#: The fields of a fit file beside its parameters and covariances, by JSON type.
SCALARS = ("cost", "loglik", "n_obs", "aic", "bic", "method", "status", "iterations", "solve_time_s", "message",
           "param_set")
DICTS = ("whiteness", "noise", "std_errors_robust", "effective_samples", "channel_share", "prior", "model_options",
         "verdict", "model_discrepancy")
LISTS = ("warnings", "x0", "records", "record_params", "param_names")


def _refuse_duplicate_keys(pairs):
    """``object_pairs_hook`` of :func:`json.loads`: a key given twice in one object is refused, naming it."""
    seen = {}
    for key, value in pairs:
        if key in seen:
            raise InputError(f"the key {key!r} is given more than once in one object")
        seen[key] = value
    return seen


def load_fit_json(path) -> dict:
    """The JSON object of a parameter or fit file: the one reader of such files.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict

    Raises
    ------
    ValueError
        A file that is not JSON, not an object with ``"params"``, a key given twice in one object
        (JSON readers would silently keep the last), or ``params`` values that are not numbers.
    """
    path = Path(path)
    try:
        obj = json.loads(path.read_text(), object_pairs_hook=_refuse_duplicate_keys)
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("params"), dict):
        raise InputError(f'{path}: expected a JSON object with key "params": {{name: value}}')
    bad = [k for k, v in obj["params"].items() if isinstance(v, bool) or not isinstance(v, (int, float))]
    if bad:
        raise InputError(f"{path}: params {bad} are not numbers")
    return obj


def _unclean(value):
    if isinstance(value, dict):
        return {k: _unclean(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_unclean(v) for v in value]
    if isinstance(value, str) and value in ("nan", "inf", "-inf"):
        return float(value)
    return value


def fit_fields(d: Mapping) -> dict:
    """The fields of a fit (``FitResult`` keyword arguments) from its JSON object, checked.

    Parameters
    ----------
    d : mapping
        A fit's :meth:`~casship.identify.FitResult.to_dict` form.

    Returns
    -------
    dict

    Raises
    ------
    casship.errors.InputError
        Missing keys, free names given twice, or a covariance that is null or of the wrong size.
    """
    d = _unclean(dict(d))
    missing = [k for k in ("model", "params", "free", "estimates", "std_errors") if k not in d]
    if missing:
        raise InputError(f"fit JSON lacks key(s) {missing}")
    k = len(d["free"])
    twice = sorted({n for n in d["free"] if list(d["free"]).count(n) > 1})
    if twice:
        raise InputError(f"fit JSON: free names {twice} given more than once")

    def mat(key):
        value = d.get(key, np.full((k, k), np.nan))
        if value is None:
            raise InputError(f"fit JSON: {key} is null; a {k} x {k} matrix of the free quantities {d['free']} "
                             "is wanted (or leave the key out)")
        return square_matrix(value, d["free"], f"fit JSON: {key}")
    kw = {key: d[key] for key in (*SCALARS, *DICTS, *LISTS) if key in d}
    if "covariance_robust" in d:
        kw["covariance_robust"] = mat("covariance_robust")
    if d.get("param_covariance"):
        kw["param_covariance"] = dict(d["param_covariance"])
    return dict(model=d["model"], params={n: float(v) for n, v in d["params"].items()}, free=list(d["free"]),
                estimates={n: float(v) for n, v in d["estimates"].items()},
                std_errors={n: float(v) for n, v in d["std_errors"].items()},
                correlation=mat("correlation"), covariance=mat("covariance"),
                **{**dict(cost=np.nan, loglik=np.nan, n_obs=0, aic=np.nan, bic=np.nan), **kw})


def fit_view(path) -> SimpleNamespace:
    """The fields of a fit file (those :meth:`~casship.identify.ParameterBelief.from_fit` reads) as attributes.

    A view, not a :class:`~casship.identify.FitResult`: the fit builds its uncertainty as a belief, so
    the belief reads the file through the JSON reader both share.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    types.SimpleNamespace
    """
    path = Path(path)
    try:
        fields = fit_fields(load_fit_json(path))
    except ValueError as exc:
        text = str(exc)
        raise InputError(text if text.startswith(str(path)) else f"{path}: {text}") from None
    return SimpleNamespace(**{"covariance_robust": None, "param_covariance": {}, "model_discrepancy": {}, **fields})


def square_matrix(value, names, what: str) -> np.ndarray:
    """``value`` as a ``len(names)`` x ``len(names)`` float matrix, or an error naming ``what``.

    Parameters
    ----------
    value : array_like
        A (nested) list of numbers.
    names : sequence of str
        What its rows and columns are (for the size and the message).
    what : str
        The field, as the messages name it.

    Returns
    -------
    ndarray
    """
    k = len(names)
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what} is not a matrix of numbers") from None
    if a.size != k * k:
        raise InputError(f"{what} has {a.size} entries, {k} x {k} wanted for {list(names)}")
    return a.reshape(k, k)
