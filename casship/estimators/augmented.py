"""Augmented-state estimation: chosen parameters become random-walk states (the method of Shi et al. 2009).

``augment(model, ["K", "T"])`` rebuilds the same symbolic model with ``K`` and ``T`` moved from
the parameter vector to the state vector, each with ``dK/dt = w_K`` (a random walk driven by a new
noise channel). Any estimator then tracks states and parameters together; :func:`augmented_ekf`
runs the EKF and returns the parameter trajectories.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..data import Dataset

from ..gaussian import Gaussian, as_cov
from ..discretize import discretize
from ..model import Model
from .result import FilterResult
from .ekf import EKF
from ..errors import InputError

__all__ = ["augment", "augmented_ekf", "AugmentedResult", "per_name", "augmented_prior", "augmented_noise"]


def augment(model: Model, params: Sequence[str] = (), *, disturbances: Sequence[str] = (), noise_prefix: str = "w_",
            name: str | None = None) -> Model:
    """A model whose named parameters are random-walk states, optionally with random-walk disturbances.

    Parameters
    ----------
    model : Model
    params : sequence of str
        Parameter names to estimate; they are appended to the states in this order, each with
        ``dK/dt = w_K`` (a random walk driven by the new noise channel ``<noise_prefix>K``).
    disturbances : sequence of str
        States ``s`` whose derivative gets an unknown additive term ``d_s``; ``d_s`` is a new state
        with ``d_s' = w_d_s`` (a random walk driven by the new noise channel ``w_d_s``).
    noise_prefix : str
        Prefix of the parameters' noise channels.
    name : str, optional
        Name of the new model (default ``"<model>_aug"``).

    Returns
    -------
    Model
        States ``(*model.state_names, *params, *("d_" + s for s in disturbances))``, noise
        ``(*model.noise_names, w_<param>..., w_d_<state>...)``, the other parameters unchanged;
        ``meta["augmented_params"]`` lists ``params``.

    Examples
    --------
    >>> import casship as cs
    >>> aug = cs.augment(cs.models.nomoto_first_order(), ["K", "T"])
    >>> aug.state_names
    ('psi', 'r', 'K', 'T')
    """
    params, disturbances = list(params), list(disturbances)
    if not params and not disturbances:
        raise InputError("augment: name at least one parameter or disturbance")
    unknown = [p for p in params if p not in model.param_names]
    if unknown:
        raise InputError(f"augment: unknown parameter(s) {unknown} of model {model.name!r}; "
                         f"parameters: {list(model.param_names)}")
    if len(set(params)) != len(params):
        raise InputError(f"augment: parameter names repeated in {params}")
    for state in disturbances:
        if state not in model.state_names:
            raise InputError(f"cannot add a disturbance to {state!r}: not a state of {model.name!r}; "
                             f"states: {list(model.state_names)}")
    if len(set(disturbances)) != len(disturbances):
        raise InputError(f"disturbances repeat a state: {disturbances}")
    b = model.builder(name or f"{model.name}_aug")
    docs = {v.name: v.doc for v in model.param_vars}
    for pname in params:
        b.param_as_state(pname, doc=docs[pname] or "augmented parameter (random walk)",
                         rate=b.noise(f"{noise_prefix}{pname}"))
    for state in disturbances:
        unit = model.state_vars[model.index(state)].unit
        d = b.state(f"d_{state}", unit=f"{unit}/s" if unit else "", doc=f"additive disturbance on d{state}/dt")
        b.add_to_ode(**{state: d})
        b.ode(**{f"d_{state}": b.noise(f"w_d_{state}")})
    b.meta["augmented_params"] = tuple(params)
    b.meta["augmented_from"] = model.name
    return b.build()


def per_name(value, names: Sequence[str], what: str) -> np.ndarray:
    """One value per name from a scalar, a sequence or a mapping with exactly ``names`` as keys.

    Parameters
    ----------
    value : float, sequence or mapping
    names : sequence of str
    what : str
        What the values are (for messages).
    """
    names = list(names)
    if isinstance(value, Mapping):
        missing, extra = [n for n in names if n not in value], sorted(set(value) - set(names))
        if missing or extra:
            raise InputError(f"{what}: give exactly the names {names} (missing {missing}, unknown {extra})")
        return np.array([float(value[n]) for n in names])
    arr = np.asarray(value, dtype=float)
    if arr.ndim and arr.size != len(names):
        raise InputError(f"{what}: expected {len(names)} values for {names}, got {arr.size}")
    arr = np.broadcast_to(arr, (len(names),)).astype(float)
    if not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise InputError(f"{what}: values must be finite and >= 0, got {arr.tolist()}")
    return arr


def augmented_prior(prior: Gaussian, mean, var) -> Gaussian:
    """``prior`` extended by independent entries of mean ``mean`` and variance ``var``.

    Parameters
    ----------
    prior : Gaussian
    mean, var : arrays
    """
    mean, var = np.asarray(mean, dtype=float), np.asarray(var, dtype=float)
    n = prior.mean.size
    cov = np.zeros((n + mean.size, n + mean.size))
    cov[:n, :n] = prior.cov
    cov[n:, n:] = np.diag(var)
    return Gaussian(np.concatenate([prior.mean, mean]), cov)


def augmented_noise(Q: np.ndarray, variances) -> np.ndarray:
    """Block-diagonal ``diag(Q, variances)`` for the noise of an augmented model.

    Parameters
    ----------
    Q : (n, n) array
    variances : array
        Variances of the new noise channels.
    """
    v = np.asarray(variances, dtype=float)
    Qa = np.zeros((Q.shape[0] + v.size,) * 2)
    Qa[:Q.shape[0], :Q.shape[0]] = Q
    Qa[Q.shape[0]:, Q.shape[0]:] = np.diag(v)
    return Qa


@dataclass(frozen=True)
class AugmentedResult:
    """Result of :func:`augmented_ekf`: the filter run and the parameter trajectories.

    Parameters
    ----------
    result : FilterResult
    params : tuple of str
        The estimated parameters (states of the augmented model).
    """

    result: FilterResult
    params: tuple

    def trajectory(self, name: str) -> np.ndarray:
        """Estimate of parameter ``name`` over the record.

        Parameters
        ----------
        name : str
        """
        if name not in self.params:
            raise InputError(f"unknown augmented parameter {name!r}; estimated: {list(self.params)}")
        return self.result[name]

    def plot(self, ax=None, path=None):
        """The estimated parameters over the record with +-2 standard deviations (one panel each).

        Parameters
        ----------
        ax : matplotlib Axes or sequence of Axes, optional
            One per parameter, instead of a new figure.
        path : str or Path, optional
            Also write the figure there.

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting` and :meth:`FilterResult.plot`.
        """
        return self.result.plot(ax, path, states=list(self.params))

    @property
    def final(self) -> dict[str, float]:
        """Parameter estimates at the end of the record."""
        return {n: float(self.result[n][-1]) for n in self.params}

    @property
    def final_std(self) -> dict[str, float]:
        """Their standard deviations at the end of the record."""
        std = self.result.std[-1]
        return {n: float(std[self.result.state_names.index(n)]) for n in self.params}


def augmented_ekf(model: Model, params: Sequence[str], data: Dataset, *, dt: float, Q, R, q_params,
                  prior: Gaussian, guess: Mapping[str, float] | None = None, p0_params=1e5,
                  measured: Sequence[str] | None = None, method: str = "euler", p=None,
                  options: Mapping | None = None) -> AugmentedResult:
    """Estimate states and the named parameters together with an EKF on the augmented model.

    Parameters
    ----------
    model : Model
    params : sequence of str
        Parameters to estimate (random-walk states).
    data : Dataset
    dt : float
        Nominal step of the discretisation (``method``, Euler as in Shi et al. 2009 by default).
    Q : covariance of the model's own process noise.
    R : covariance of the measured outputs.
    q_params : float, sequence or mapping
        Random-walk variances of the parameters per step.
    prior : Gaussian
        Belief about the model's own states.
    guess : mapping, optional
        Initial parameter values (default: zero, as in Shi et al. 2009).
    p0_params : float, sequence or mapping
        Initial parameter variances (Shi et al. 2009: ``1e5``).
    p : array or mapping, optional
        Values of the parameters that are not estimated (nominal by default).
    measured : sequence of str, optional
        Measured outputs (all by default).
    method : str
        Discretisation method.
    options : EKFOptions or mapping, optional
        Options of the EKF.
    """
    aug = augment(model, params)
    names = list(params)
    Qa = augmented_noise(as_cov(Q, model.nw, "Q", model.noise_names), per_name(q_params, names, "q_params"))
    guess = dict(guess or {})
    unknown = set(guess) - set(names)
    if unknown:
        raise InputError(f"guess: unknown parameter(s) {sorted(unknown)}; estimated: {names}")
    prior_a = augmented_prior(prior, [guess.get(n, 0.0) for n in names], per_name(p0_params, names, "p0_params"))
    rest = model.params() if p is None else model.params(p)
    p_aug = aug.params({k: v for k, v in zip(model.param_names, rest) if k not in names})
    ekf = EKF(discretize(aug, dt, method=method), Qa, R, measured=measured, options=options)
    return AugmentedResult(ekf.filter(data, prior_a, p_aug), tuple(names))
