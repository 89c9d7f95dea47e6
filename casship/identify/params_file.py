"""Parameter files that replay: a fit (or any ``{"params": ...}`` JSON) on the model it belongs to.

A fit file written by :meth:`~casship.identify.FitResult.to_json` records the model's name, the
options it was built with (``model.meta["options"]``, e.g. a variant with extra asymmetry terms)
and the vessel's parameter-set identity. :func:`read_params` rebuilds that model and returns the
parameter vector, or refuses a model or parameter set other than the fitted one, naming both.

A fit file also carries the uncertainty of the parameters a new run is replayed with
(``"param_covariance"``: names, covariance matrix and where it comes from);
:func:`read_fit_file` returns it as a :class:`ParameterUncertainty` (``FitFile.uncertainty``), from which
replays and manoeuvre simulations draw their prediction bands. A file may also carry a
model-discrepancy estimate (``"model_discrepancy"``: ``psi_variance_growth_deg2_per_s``, a heading
variance ``q t`` that the parameter band misses, growing with the time since the start, estimated
from held-out runs); the replays then give a second, predictive heading band ``sqrt(s^2 + q t)``
beside the parameter-only one.
"""
from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, get_args

import numpy as np

from ..errors import InputError, InputTypeError

__all__ = ["read_params", "read_fit_file", "FitFile", "replay_file", "check_model", "ParameterUncertainty", "load_fit_json", "SYMMETRY_TOL",
           "Q_MAX_DEG2_PER_S", "CovarianceKind", "COVARIANCE_KINDS", "kind_from_source"]

#: Which covariance a Gaussian over parameters carries: a run-level calibration (``"calibrated"``,
#: e.g. a jackknife), the robust (sandwich) or the model-based covariance of a fit, a fit's standard
#: errors alone (independent), a prior stated by hand, or a covariance that says none of these.
CovarianceKind = Literal["calibrated", "robust", "model-based", "standard errors", "prior", "stated"]
COVARIANCE_KINDS: tuple = get_args(CovarianceKind)


def kind_from_source(source: str) -> CovarianceKind:
    """The kind of a covariance read from its prose ``source``: the rule for files older than the ``kind`` field.

    Files written since carry the kind itself (``ParameterUncertainty.kind``); only
    :meth:`ParameterUncertainty.from_dict` falls back to this rule, for a file without it.

    Parameters
    ----------
    source : str
        The covariance's stated source (e.g. ``"run-level jackknife over 16 folds"``).

    Returns
    -------
    str
        ``"calibrated"`` (a jackknife or another calibration over runs), ``"robust"`` (sandwich),
        ``"model-based"``, or ``"stated"`` (a source that says none of these).

    Examples
    --------
    >>> kind_from_source("run-level jackknife over 16 leave-one-run-out folds")
    'calibrated'
    >>> kind_from_source("robust (sandwich)")
    'robust'
    """
    text = str(source).lower()
    if "jackknife" in text or "calibrat" in text:
        return "calibrated"
    if "robust" in text or "sandwich" in text:
        return "robust"
    if "model-based" in text or "model based" in text:
        return "model-based"
    return "stated"


def _checked_kind(kind, what: str) -> str:
    """``kind`` when it is one of :data:`COVARIANCE_KINDS`, else an error naming ``what``."""
    if kind not in COVARIANCE_KINDS:
        raise InputError(f"{what}: unknown covariance kind {kind!r}; use one of {COVARIANCE_KINDS}")
    return str(kind)

#: Upper bound of a fit file's model discrepancy [deg^2/s]: beyond it the heading's 95 % band spans a
#: full turn (+-180 deg) within about 10 s, i.e. the file predicts nothing.
Q_MAX_DEG2_PER_S = 1e3


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


@dataclass
class ParameterUncertainty:
    """Gaussian uncertainty of some model parameters: their values and covariance.

    Parameters
    ----------
    names : list of str
        Model parameter names, in the order of ``covariance``.
    values : (k,) array
        Their values (the estimates).
    covariance : (k, k) array
        Covariance [units of the parameters squared].
    source : str
        Where the covariance comes from (e.g. ``"model-based"``, ``"robust (sandwich)"``,
        ``"run-level jackknife"``).
    info : dict
        Further facts about the covariance (e.g. the number of folds of a jackknife).
    psi_variance_rate : float
        Model discrepancy: a heading variance growing linearly with the time since the start of a
        replay [rad^2/s], added to the parameter band's variance in the predictive band (0: none).
    discrepancy_covariance : (k, k) array, optional
        The covariance of the same parameters that ``psi_variance_rate`` was estimated beside (the
        predictive band adds ``q t`` to the band of this covariance, as in its estimation); None:
        ``covariance``.
    kind : CovarianceKind
        Which covariance it is (one of :data:`COVARIANCE_KINDS`), set where the covariance is made
        and written to the file beside ``source``.

    Examples
    --------
    >>> u = ParameterUncertainty(["K", "T"], [0.1, 20.0], [[1e-4, 0.0], [0.0, 4.0]])
    >>> [round(float(s), 3) for s in u.std]
    [0.01, 2.0]
    """

    names: list
    values: np.ndarray
    covariance: np.ndarray
    source: str = ""
    info: dict = field(default_factory=dict)
    psi_variance_rate: float = 0.0
    discrepancy_covariance: np.ndarray | None = None
    kind: CovarianceKind = "stated"

    def __post_init__(self):
        self.kind = _checked_kind(self.kind, "ParameterUncertainty")
        self.psi_variance_rate = float(self.psi_variance_rate)
        q_max = float(np.radians(np.radians(Q_MAX_DEG2_PER_S)))
        if not (np.isfinite(self.psi_variance_rate) and 0.0 <= self.psi_variance_rate <= q_max):
            raise InputError(f"ParameterUncertainty: psi_variance_rate must be finite, >= 0 and <= {q_max:.4g} rad^2/s "
                             f"({Q_MAX_DEG2_PER_S:g} deg^2/s), got {self.psi_variance_rate}")
        self.names = [str(n) for n in self.names]
        twice = sorted({n for n in self.names if self.names.count(n) > 1})
        if twice:
            raise InputError(f"ParameterUncertainty: parameter name(s) {twice} given more than once")
        self.values = np.asarray(self.values, dtype=float).reshape(-1)
        if self.values.size != len(self.names):
            raise InputError(f"ParameterUncertainty: {self.values.size} values for {len(self.names)} names")
        self.covariance = _checked_covariance(self.covariance, self.names, "covariance")
        if self.discrepancy_covariance is not None:
            self.discrepancy_covariance = _checked_covariance(self.discrepancy_covariance, self.names,
                                                              "discrepancy_covariance")

    @property
    def std(self) -> np.ndarray:
        """Standard deviation of each parameter."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def sample(self, model, p, n: int, seed=0) -> np.ndarray:
        """``n`` parameter vectors of ``model``: ``p`` with these parameters drawn from the Gaussian.

        Parameters
        ----------
        model : Model
        p : array_like
            The full parameter vector (the other parameters keep these values).
        n : int
            Number of draws.
        seed : int or numpy.random.Generator

        Returns
        -------
        (n, np) array
        """
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        idx = model.indices(self.names, "param")
        w, V = np.linalg.eigh(self.covariance)
        L = V * np.sqrt(np.clip(w, 0.0, None))
        draws = self.values + rng.standard_normal((int(n), len(self.names))) @ L.T
        out = np.tile(np.asarray(p, dtype=float), (int(n), 1))
        out[:, idx] = draws
        return out

    def to_dict(self) -> dict:
        """JSON-friendly form (``names``, ``values``, ``matrix``, ``source``, ``kind``, ``info``)."""
        return {"names": list(self.names), "values": self.values.tolist(), "matrix": self.covariance.tolist(),
                "source": self.source, "kind": self.kind, "info": dict(self.info)}

    @classmethod
    def from_dict(cls, d, where: str = "the file", *, key: str = "param_covariance") -> "ParameterUncertainty":
        """Read the form of :meth:`to_dict`.

        Parameters
        ----------
        d : mapping
            With ``names``, ``values``, ``matrix`` (and optionally ``source``, ``kind``, ``info``); a
            file without ``kind`` (older than the field) gets the kind its ``source`` states
            (:func:`kind_from_source`).
        where : str
            What holds it (for the messages).
        key : str
            The field of the file that holds it (for the messages).

        Returns
        -------
        ParameterUncertainty

        Raises
        ------
        ValueError
            Naming the field: missing or null names, values or matrix, a shape other than the names',
            a name given twice, a matrix not symmetric beyond round-off (naming the entry) or not
            positive semi-definite.
        """
        field_ = f"{where}: {key}"
        if not isinstance(d, Mapping):
            raise InputError(f"{field_}: expected an object with names, values and matrix, got {type(d).__name__}")
        missing = [k for k in ("names", "matrix") if k not in d]
        if missing:
            raise InputError(f"{field_} lacks {missing}")
        names = d["names"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise InputError(f"{field_}.names: expected a list of parameter names, got {names!r}")
        values = d.get("values")
        if values is None:
            raise InputError(f"{field_} lacks the values of {names}")
        _numbers(values, (len(names),), f"{field_}.values")
        _numbers(d["matrix"], (len(names), len(names)), f"{field_}.matrix")
        source = str(d.get("source", ""))
        kind = _checked_kind(d["kind"], f"{field_}.kind") if "kind" in d else kind_from_source(source)
        try:
            return cls(names, values, d["matrix"], source, dict(d.get("info") or {}), kind=kind)
        except ValueError as exc:
            msg = str(exc).removeprefix("ParameterUncertainty: ")
            raise InputError(f"{field_}.matrix {msg.removeprefix('covariance ')}" if msg.startswith("covariance ")
                             else f"{field_}: {msg}") from None


def _numbers(value, shape: tuple, what: str) -> None:
    """Refuse a JSON value that is not a (nested) list of numbers of ``shape``, naming ``what``."""
    if value is None:
        raise InputError(f"{what} is null; a fit file carries a {' x '.join(map(str, shape))} list of numbers there")
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a {' x '.join(map(str, shape))} list of numbers, got {value!r:.80}") from None
    if a.shape != shape:
        raise InputError(f"{what}: shape {a.shape}, {' x '.join(map(str, shape))} wanted")


#: Relative asymmetry of a covariance entry tolerated as round-off (``|a_ij - a_ji| / sqrt(a_ii a_jj)``).
SYMMETRY_TOL = 1e-8


def _checked_covariance(matrix, names, what: str) -> np.ndarray:
    """``matrix`` as a symmetric positive semi-definite covariance of ``names``, or ``ValueError``.

    An asymmetry within round-off (:data:`SYMMETRY_TOL`) is averaged away; beyond it the entry is named.
    """
    k = len(names)
    if matrix is None:
        raise InputError(f"ParameterUncertainty: {what} is null ({k} x {k} wanted for {list(names)})")
    try:
        a = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"ParameterUncertainty: {what} is not a matrix of numbers") from None
    if a.size != k * k:
        raise InputError(f"ParameterUncertainty: {what} has {a.size} entries, {k} x {k} wanted for {list(names)}")
    a = a.reshape(k, k)
    if not np.all(np.isfinite(a)):
        bad = [n for n, d in zip(names, np.diag(a)) if not np.isfinite(d)]
        raise InputError(f"ParameterUncertainty: {what} not finite for {bad or list(names)}")
    scale = np.sqrt(np.abs(np.outer(np.diag(a), np.diag(a))))
    gap = np.abs(a - a.T)
    bad = gap > SYMMETRY_TOL * np.maximum(scale, np.abs(a).max(initial=0.0) * 1e-12) + 1e-300
    if bad.any():
        i, j = (int(x) for x in np.argwhere(np.triu(bad, 1))[0])
        raise InputError(f"ParameterUncertainty: {what} is not symmetric: entry ({names[i]}, {names[j]}) = {a[i, j]:.6g} "
                         f"but ({names[j]}, {names[i]}) = {a[j, i]:.6g} (beyond round-off)")
    a = 0.5 * (a + a.T)
    if np.linalg.eigvalsh(a).min(initial=0.0) < -1e-9 * max(1.0, np.abs(a).max()):
        raise InputError(f"ParameterUncertainty: {what} is not positive semi-definite")
    return a


@dataclass(frozen=True)
class FitFile:
    """A parameter file read once: the model it belongs to, its parameter vector and their uncertainty.

    Parameters
    ----------
    model : Model
        The model the parameters belong to (rebuilt with the file's options when named).
    params : ndarray
        The model's parameter vector with the file's values.
    uncertainty : ParameterUncertainty or None
        The file's parameter covariance and model discrepancy (None when it carries none).
    """

    model: object
    params: np.ndarray
    uncertainty: "ParameterUncertainty | None"


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
    unc = ParameterUncertainty.from_dict(cov, str(path))
    check_model(model, dict(zip(unc.names, unc.values)), name=name, options=options, param_set=pset,
                source=f"{path} (param_covariance)")
    mismatch = [n for n, v in zip(unc.names, unc.values) if not np.isclose(v, params.get(n, np.nan), rtol=1e-12)]
    if mismatch:
        raise InputError(f"{path}: param_covariance values of {mismatch} differ from the file's params")
    discrepancy = obj.get("model_discrepancy") or {}
    if discrepancy:
        if not isinstance(discrepancy, dict):
            raise InputError(f"{path}: model_discrepancy must be an object, got {discrepancy!r:.60}")
        q = discrepancy.get("psi_variance_growth_deg2_per_s")
        if not isinstance(q, (int, float)) or isinstance(q, bool) or not np.isfinite(q) or not 0 <= q <= Q_MAX_DEG2_PER_S:
            raise InputError(f"{path}: model_discrepancy.psi_variance_growth_deg2_per_s must be a number in "
                             f"[0, {Q_MAX_DEG2_PER_S:g}] deg^2/s (beyond, the 95 % heading band spans a full turn within "
                             f"about 10 s), got {q!r}")
        unc.psi_variance_rate = float(np.radians(np.radians(q)))
        beside = discrepancy.get("estimated_with")
        if beside is not None:      # the covariance whose band q completes (same parameters, same order)
            base = ParameterUncertainty.from_dict(beside, str(path), key="model_discrepancy.estimated_with")
            if base.names != unc.names:
                raise InputError(f"{path}: model_discrepancy.estimated_with has parameters {base.names}, "
                                 f"param_covariance {unc.names}; they must be the same, in the same order")
            unc.discrepancy_covariance = base.covariance          # checked as it was read
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
        Further arguments of :func:`casship.validation.replay` (``method``, ``check_limits``, ``level``, ``samples``,
        ``seed``).

    Returns
    -------
    casship.validation.ReplayResult

    Examples
    --------
    >>> res = replay_file("fit.json", read_record("run.dat"), "kvlcc2")     # doctest: +SKIP
    """
    from ..validation import replay

    fit = read_fit_file(path, model)
    return replay(fit.model, data, fit.params, uncertainty=fit.uncertainty if uncertainty else None, **options)
