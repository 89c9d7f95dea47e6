"""Parameter files that replay: a fit (or any ``{"params": ...}`` JSON) on the model it belongs to.

A fit file written by :meth:`~casship.identify.FitResult.to_json` records the model's name, the
options it was built with (``model.meta["options"]``, e.g. a variant with extra asymmetry terms)
and the vessel's parameter-set identity. :func:`read_params` rebuilds that model and returns the
parameter vector, or refuses a model or parameter set other than the fitted one, naming both.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

__all__ = ["read_params", "check_model"]


def read_params(path, model=None):
    """The model a parameter file belongs to and its parameter vector.

    Parameters
    ----------
    path : str or Path
        JSON with key ``"params"`` (name -> value); a fit file also has ``"model"``,
        ``"model_options"`` and ``"param_set"``.
    model : Model, str or None
        The model to apply the parameters to: a built model (checked against the file), a registered
        name (built with the file's ``model_options`` when the file names the same model), or None
        (the file's own model).

    Returns
    -------
    (Model, ndarray)
        The model and its parameter vector with the file's values.

    Raises
    ------
    ValueError
        For a file that is not such JSON, a model or parameter set other than the file's (naming
        both), or parameter names the model lacks.

    Examples
    --------
    >>> model, p = read_params("fit.json", "kvlcc2")      # doctest: +SKIP
    """
    from ..model import Model
    from ..models import get_model

    path = Path(path)
    try:
        obj = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("params"), dict):
        raise ValueError(f'{path}: expected a JSON object with key "params": {{name: value}}')
    params = {str(k): float(v) for k, v in obj["params"].items()}
    name, options, pset = obj.get("model"), dict(obj.get("model_options") or {}), str(obj.get("param_set") or "")
    if model is None or isinstance(model, str):
        wanted = model or name
        if wanted is None:
            raise ValueError(f"{path} names no model; give the model to apply it to")
        if name is not None and wanted != name:
            raise ValueError(f"{path} holds parameters of model {name!r}, not {wanted!r}")
        model = get_model(wanted, **(options if wanted == name else {}))
    elif not isinstance(model, Model):
        raise TypeError(f"model must be a casship Model, a registered name or None, got {type(model).__name__}")
    return model, check_model(model, params, name=name, options=options, param_set=pset, source=str(path))


def check_model(model, params: dict, *, name=None, options=None, param_set: str = "", source: str = "the fit"):
    """``model``'s parameter vector with ``params``, after checking that they belong to it.

    Parameters
    ----------
    model : Model
        The model to apply the parameters to.
    params : dict
        Parameter name -> value.
    name : str, optional
        Name of the model the parameters were made for.
    options : dict, optional
        Options that model was built with (for the message).
    param_set : str
        Parameter-set identity the parameters were made for.
    source : str
        What holds the parameters (for the messages).

    Returns
    -------
    ndarray

    Raises
    ------
    ValueError
        Naming both models, both parameter sets, or the parameters the model lacks.
    """
    if name is not None and model.name != name:
        raise ValueError(f"{source} holds parameters of model {name!r}, not {model.name!r}")
    own = model.vessel.param_set if getattr(model, "vessel", None) is not None else ""
    if param_set and own and param_set != own:
        raise ValueError(f"{source} was fitted on parameter set {param_set!r}; model {model.name!r} has "
                         f"parameter set {own!r}")
    unknown = [n for n in params if n not in model.param_names]
    if unknown:
        built = f" built with options {options}" if options else ""
        raise ValueError(f"{source} has parameter(s) {unknown} that model {model.name!r} lacks"
                         + (f" (it was fitted on {name!r}{built})" if name else ""))
    return np.asarray(model.params(params))
