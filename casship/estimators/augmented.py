"""Augmented-state estimation: chosen parameters become random-walk states (seed 000's method).

``augment(model, ["K", "T"])`` rebuilds the same symbolic model with ``K`` and ``T`` moved from
the parameter vector to the state vector, each with ``dK/dt = w_K`` (a random walk driven by a new
noise channel). Any estimator then tracks states and parameters together; :func:`augmented_ekf`
runs the EKF and returns the parameter trajectories.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..data import Dataset, Gaussian, as_cov
from ..discretize import discretize
from ..model import Model, Variable
from .base import FilterResult
from .ekf import EKF

__all__ = ["augment", "augmented_ekf", "AugmentedResult"]


def augment(model: Model, params: Sequence[str], *, noise_prefix: str = "w_", name: str | None = None) -> Model:
    """A model whose named parameters are random-walk states.

    Parameters
    ----------
    model : Model
    params : sequence of str
        Parameter names to estimate; they are appended to the states in this order.
    noise_prefix : str
        The random walk of parameter ``K`` is driven by the noise channel ``<noise_prefix>K``.
    name : str, optional
        Name of the new model (default ``"<model>_aug"``).

    Returns
    -------
    Model
        States ``(*model.state_names, *params)``, noise ``(*model.noise_names, w_<param>...)``, the
        other parameters unchanged; ``meta["augmented_params"]`` lists ``params``.

    Examples
    --------
    >>> import casship as cs
    >>> aug = cs.augment(cs.models.nomoto_first_order(), ["K", "T"])
    >>> aug.state_names
    ('psi', 'r', 'K', 'T')
    """
    params = list(params)
    if not params:
        raise ValueError("augment: name at least one parameter")
    unknown = [p for p in params if p not in model.param_names]
    if unknown:
        raise ValueError(f"augment: unknown parameter(s) {unknown} of model {model.name!r}; "
                         f"parameters: {list(model.param_names)}")
    if len(set(params)) != len(params):
        raise ValueError(f"augment: parameter names repeated in {params}")
    b = model.builder(name or f"{model.name}_aug")
    by_name = {v.name: v for v in model.param_vars}
    b._params = [v for v in b._params if v.name not in params]
    for pname in params:
        var = by_name[pname]
        b._kinds[pname] = "state"
        b._states.append(Variable(pname, var.unit, False, var.doc or "augmented parameter (random walk)"))
        b._ode[pname] = b.noise(f"{noise_prefix}{pname}")
    b.meta["augmented_params"] = tuple(params)
    b.meta["augmented_from"] = model.name
    return b.build()


@dataclass(frozen=True)
class AugmentedResult:
    """Result of :func:`augmented_ekf`: the filter run and the parameter trajectories."""

    result: FilterResult
    params: tuple

    def trajectory(self, name: str) -> np.ndarray:
        """Estimate of parameter ``name`` over the record."""
        if name not in self.params:
            raise ValueError(f"unknown augmented parameter {name!r}; estimated: {list(self.params)}")
        return self.result[name]

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
        Nominal step of the discretisation (``method``, Euler as in seed 000 by default).
    Q : covariance of the model's own process noise.
    R : covariance of the measured outputs.
    q_params : float, sequence or mapping
        Random-walk variances of the parameters per step.
    prior : Gaussian
        Belief about the model's own states.
    guess : mapping, optional
        Initial parameter values (default: zero, as in seed 000).
    p0_params : float, sequence or mapping
        Initial parameter variances (seed 000: ``1e5``).
    p : array or mapping, optional
        Values of the parameters that are not estimated (nominal by default).
    """
    aug = augment(model, params)
    names = list(params)

    def per_param(value, what):
        if isinstance(value, Mapping):
            missing = [n for n in names if n not in value]
            if missing or set(value) - set(names):
                raise ValueError(f"{what}: give exactly the parameters {names}")
            return np.array([value[n] for n in names], dtype=float)
        arr = np.broadcast_to(np.asarray(value, dtype=float), (len(names),))
        return arr.astype(float)

    q = per_param(q_params, "q_params")
    Qm = as_cov(Q, model.nw, "Q", model.noise_names)
    Qa = np.zeros((aug.nw, aug.nw))
    Qa[: model.nw, : model.nw] = Qm
    Qa[model.nw:, model.nw:] = np.diag(q)
    guess = dict(guess or {})
    unknown = set(guess) - set(names)
    if unknown:
        raise ValueError(f"guess: unknown parameter(s) {sorted(unknown)}; estimated: {names}")
    mean = np.concatenate([prior.mean, [guess.get(n, 0.0) for n in names]])
    cov = np.zeros((aug.nx, aug.nx))
    cov[: model.nx, : model.nx] = prior.cov
    cov[model.nx:, model.nx:] = np.diag(per_param(p0_params, "p0_params"))
    rest = model.params() if p is None else model.params(p)
    p_aug = aug.params({k: v for k, v in zip(model.param_names, rest) if k not in names})
    ekf = EKF(discretize(aug, dt, method=method), Qa, R, measured=measured, options=options)
    return AugmentedResult(ekf.filter(data, Gaussian(mean, cov), p_aug), tuple(names))
