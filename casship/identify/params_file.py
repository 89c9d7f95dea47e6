"""Parameter files that replay: a fit (or any ``{"params": ...}`` JSON) on the model it belongs to.

A fit file written by :meth:`~casship.identify.FitResult.to_json` records the model's name, the
options it was built with (``model.meta["options"]``, e.g. a variant with extra asymmetry terms)
and the vessel's parameter-set identity. :func:`read_params` rebuilds that model and returns the
parameter vector, or refuses a model or parameter set other than the fitted one, naming both.

A fit file also carries the uncertainty of the parameters a new run is replayed with
(``"param_covariance"``: names, covariance matrix and where it comes from);
:func:`read_fit_file` returns it as a :class:`~casship.identify.ParameterBelief` (``FitFile.uncertainty``), from which
replays and manoeuvre simulations draw their prediction bands. A file may also carry a
model-discrepancy estimate (``"model_discrepancy"``: ``psi_variance_growth_deg2_per_s``, a heading
variance ``q t`` that the parameter band misses, growing with the time since the start, estimated
from held-out runs); the replays then give a second, predictive heading band ``sqrt(s^2 + q t)``
beside the parameter-only one.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, InputTypeError
from .belief import COVARIANCE_KINDS, Q_MAX_DEG2_PER_S, SYMMETRY_TOL, CovarianceKind, ParameterBelief, discrepancy_of, \
    kind_from_source
from .fit_json import load_fit_json

__all__ = ["read_params", "read_fit_file", "FitFile", "replay_file", "write_params_file", "check_model", "load_fit_json", "SYMMETRY_TOL",
           "Q_MAX_DEG2_PER_S", "CovarianceKind", "COVARIANCE_KINDS", "kind_from_source"]

@dataclass(frozen=True)
class FitFile:
    """A parameter file read once: the model it belongs to, its parameter vector and their uncertainty.

    Parameters
    ----------
    model : Model
        The model the parameters belong to (rebuilt with the file's options when named).
    params : ndarray
        The model's parameter vector with the file's values.
    uncertainty : ParameterBelief or None
        The file's parameter covariance and model discrepancy (None when it carries none).
    """

    model: object
    params: np.ndarray
    uncertainty: "ParameterBelief | None"


def read_params(path, model=None, *, uncertainty: bool = False):
    """The model a parameter file belongs to and its parameter vector.

    Parameters
    ----------
    path : str or Path
        JSON with key ``"params"`` (name -> value); a fit file also has ``"model"``,
        ``"model_options"`` and ``"param_set"``.
    model : Model, str or None
        As for :func:`read_fit_file`.
    uncertainty : bool
        Deprecated: also return the uncertainty (a third value). Use :func:`read_fit_file`, which
        returns all three as one value.

    Returns
    -------
    (Model, ndarray)
        The model and its parameter vector with the file's values.

    Raises
    ------
    casship.errors.InputError
        As :func:`read_fit_file`.

    Examples
    --------
    >>> model, p = read_params("fit.json", "kvlcc2")      # doctest: +SKIP
    """
    read = read_fit_file(path, model)
    if uncertainty:
        import warnings

        warnings.warn("read_params(..., uncertainty=True) is deprecated: read_fit_file(path, model) returns the "
                      "model, the parameters and their uncertainty as one value", DeprecationWarning, stacklevel=2)
        return read.model, read.params, read.uncertainty
    return read.model, read.params


def read_fit_file(path, model=None) -> FitFile:
    """A parameter file's model, parameter vector and uncertainty (the file read and checked once).

    Parameters
    ----------
    path : str or Path
        JSON with key ``"params"`` (name -> value); a fit file also has ``"model"``,
        ``"model_options"``, ``"param_set"``, and may carry ``"param_covariance"`` and
        ``"model_discrepancy"``.
    model : Model, str or None
        The model to apply the parameters to: a built model (checked against the file), a registered
        name (built with the file's ``model_options`` when the file names the same model), or None
        (the file's own model).

    Returns
    -------
    FitFile
        ``.model``, ``.params`` and ``.uncertainty`` (None when the file carries no covariance).

    Raises
    ------
    casship.errors.InputError
        For a file that is not such JSON, a model or parameter set other than the file's (naming
        both), parameter names the model lacks, or a covariance or discrepancy that is not valid.

    Examples
    --------
    >>> fit = read_fit_file("fit.json", "kvlcc2")      # doctest: +SKIP
    >>> fit.model, fit.params, fit.uncertainty          # doctest: +SKIP
    """
    from ..model import Model
    from ..models import get_model

    path = Path(path)
    obj = load_fit_json(path)
    params = {str(k): float(v) for k, v in obj["params"].items()}
    name, options, pset = obj.get("model"), dict(obj.get("model_options") or {}), str(obj.get("param_set") or "")
    if model is None or isinstance(model, str):
        wanted = model or name
        if wanted is None:
            raise InputError(f"{path} names no model; give the model to apply it to")
        if name is not None and wanted != name:
            raise InputError(f"{path} holds parameters of model {name!r}, not {wanted!r}")
        model = get_model(wanted, **(options if wanted == name else {}))
    elif not isinstance(model, Model):
        raise InputTypeError(f"model must be a casship Model, a registered name or None, got {type(model).__name__}")
    p = check_model(model, params, name=name, options=options, param_set=pset, source=str(path))
    cov = obj.get("param_covariance")
    if not cov:
        return FitFile(model, p, None)
    unc = ParameterBelief.from_dict(cov, str(path))
    check_model(model, dict(zip(unc.names, unc.values)), name=name, options=options, param_set=pset,
                source=f"{path} (param_covariance)")
    mismatch = [n for n, v in zip(unc.names, unc.values) if not np.isclose(v, params.get(n, np.nan), rtol=1e-12)]
    if mismatch:
        raise InputError(f"{path}: param_covariance values of {mismatch} differ from the file's params")
    q, beside = discrepancy_of(obj.get("model_discrepancy"), str(path), unc.names, read=ParameterBelief.from_dict)
    # one frozen value: the covariance with the discrepancy beside it (nothing set after the fact)
    unc = dataclasses.replace(unc, psi_variance_rate=q, discrepancy_covariance=beside)
    return FitFile(model, p, unc)


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
        raise InputError(f"{source} holds parameters of model {name!r}, not {model.name!r}")
    own = model.vessel.param_set if getattr(model, "vessel", None) is not None else ""
    if param_set and own and param_set != own:
        raise InputError(f"{source} was fitted on parameter set {param_set!r}; model {model.name!r} has "
                         f"parameter set {own!r}")
    unknown = [n for n in params if n not in model.param_names]
    if unknown:
        built = f" built with options {options}" if options else ""
        raise InputError(f"{source} has parameter(s) {unknown} that model {model.name!r} lacks"
                         + (f" (it was fitted on {name!r}{built})" if name else ""))
    return np.asarray(model.params(params))


def replay_file(path, data, model=None, *, uncertainty: bool = True, **options):
    """Replay a record with a parameter (fit) file: the one path of ``casship simulate --params``.

    The file's model variant is rebuilt (or ``model`` checked against it), the record replayed with
    the file's parameters (every run, from any facility or direction, gets the same parameters: the
    file's), and, when the file carries a covariance and ``uncertainty`` is true, with prediction
    bands and index intervals.

    Parameters
    ----------
    path : str or Path
        A JSON file with ``"params"`` (a fit file from :meth:`~casship.identify.FitResult.to_json`).
    data : Dataset
        The record.
    model : Model, str or None
        See :func:`casship.identify.read_params`.
    uncertainty : bool
        Use the file's covariance for bands and intervals.
    **options
        Further arguments of :func:`casship.maneuvers.replay` (``method``, ``check_limits``, ``level``, ``samples``,
        ``seed``).

    Returns
    -------
    casship.maneuvers.ReplayResult

    Examples
    --------
    >>> res = replay_file("fit.json", read_record("run.dat"), "kvlcc2")     # doctest: +SKIP
    """
    from ..maneuvers import replay

    fit = read_fit_file(path, model)
    return replay(fit.model, data, fit.params, uncertainty=fit.uncertainty if uncertainty else None, **options)


def write_params_file(path, model, values, uncertainty=None, extra=None) -> Path:
    """Write a parameter file that replays like a fit file: a model's values and their uncertainty.

    For parameter values that come from elsewhere than a fit of this model (another facility's
    captive tests, a handbook, a sister ship): the file names the model, its options and parameter
    set, so :func:`read_fit_file` rebuilds the same variant and refuses another.

    Parameters
    ----------
    path : str or Path
    model : Model
        The model the values belong to.
    values : mapping name -> float
        Parameters that differ from the model's (the others keep the model's values).
    uncertainty : ParameterBelief, optional
        Their covariance (``param_covariance``); its names must be parameters of the model and
        its values those of the file.
    extra : mapping, optional
        More top-level entries (e.g. ``"model_discrepancy"``, provenance).

    Returns
    -------
    Path

    Raises
    ------
    casship.errors.InputError
        A name the model lacks, a value that is not finite, or an uncertainty whose values are not
        the file's.
    """
    from ..io.jsonfile import write_json

    params = model.param_dict()
    unknown = sorted(set(values) - set(params))
    if unknown:
        raise InputError(f"write_params_file: {unknown} are not parameters of {model.name!r}")
    params.update({str(k): float(v) for k, v in values.items()})
    bad = sorted(k for k, v in params.items() if not np.isfinite(v))
    if bad:
        raise InputError(f"write_params_file: parameter(s) {bad} are not finite")
    if uncertainty is not None:
        off = [n for n, v in zip(uncertainty.names, uncertainty.values)
               if n not in params or not np.isclose(v, params[n], rtol=1e-12)]
        if off:
            raise InputError(f"write_params_file: the uncertainty's values of {off} are not the file's")
    vessel = getattr(model, "vessel", None)
    content = {"model": model.name, "model_options": dict(model.meta.get("options", {})),
               "param_set": vessel.param_set if vessel is not None else "", "params": params,
               "param_covariance": uncertainty.to_dict() if uncertainty is not None else {}}
    content.update(dict(extra or {}))
    path = Path(path)
    write_json(path, content, what="parameter file")
    return path
