"""Gaussian prior on free quantities: maximum a posteriori (MAP) identification.

The prior adds ``0.5 * weight * sum(((theta_i - mean_i) / std_i)^2)`` to the cost (the negative
log-likelihood, or half the weighted sum of squares, whose weights are then taken as the noise
standard deviations). Its information ``weight / std^2`` is added to the curvature, so the standard
errors of a MAP fit are posterior standard deviations. ``weight=0`` switches it off (the fit is then
the unregularised one).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from ..errors import InputError

__all__ = ["Prior"]


@dataclass(frozen=True)
class Prior:
    """Independent Gaussian priors on named free quantities.

    Parameters
    ----------
    std : mapping name -> float
        Standard deviation of each quantity with a prior. A declared name (``"R_0_dash"``,
        ``"bias[n]"``) applies to all its per-record or per-group copies; a copy's own name
        (``"R_0_dash@2"``) to that copy only. Quantities not named have no prior.
    mean : mapping name -> float, optional
        Prior means; by default the model's published (nominal) parameter values, 0 for a bias and
        the starting value for initial states and noise variances.
    weight : float
        Multiplies the prior's cost (1: the prior as stated; 0: no prior).

    Examples
    --------
    >>> from casship.identify import Prior
    >>> Prior({"K": 0.02, "T": 5.0})
    Prior(std={'K': 0.02, 'T': 5.0}, mean={}, weight=1.0)
    """

    std: Mapping = field(default_factory=dict)
    mean: Mapping = field(default_factory=dict)
    weight: float = 1.0

    def __post_init__(self):
        std = {str(k): float(v) for k, v in dict(self.std).items()}
        bad = [k for k, v in std.items() if not (np.isfinite(v) and v > 0)]
        if bad:
            raise InputError(f"prior standard deviations must be positive and finite: {bad}")
        mean = {str(k): float(v) for k, v in dict(self.mean or {}).items()}
        nan = [k for k, v in mean.items() if not np.isfinite(v)]
        if nan:
            raise InputError(f"prior means must be finite: {nan}")
        w = float(self.weight)
        if not (np.isfinite(w) and w >= 0):
            raise InputError(f"prior weight must be >= 0, got {self.weight}")
        object.__setattr__(self, "std", std)
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "weight", w)

    @classmethod
    def from_belief(cls, belief, *, weight: float = 1.0, marginal: bool = False) -> "Prior":
        """The prior a Gaussian over named parameters states: its means and standard deviations.

        A :class:`Prior` is independent per quantity, so a belief whose parameters are correlated
        is refused unless ``marginal`` (then only its marginal standard deviations are kept).

        Parameters
        ----------
        belief : casship.design.ParameterBelief
            Names, means and covariance (e.g. ``ParameterBelief.from_fit``).
        weight : float
            Multiplies the prior's cost.
        marginal : bool
            Accept a correlated belief, keeping its marginal standard deviations only.

        Returns
        -------
        Prior

        Raises
        ------
        ValueError
            A correlated belief without ``marginal``, naming the most correlated pair.

        Examples
        --------
        >>> from casship.design import ParameterBelief
        >>> b = ParameterBelief.from_std({"K": 0.02}, mean={"K": 0.1})
        >>> Prior.from_belief(b)
        Prior(std={'K': 0.02}, mean={'K': 0.1}, weight=1.0)
        """
        names, cov = list(belief.names), np.asarray(belief.cov, dtype=float)
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        if not marginal and len(names) > 1:
            with np.errstate(divide="ignore", invalid="ignore"):
                corr = np.abs(cov / np.outer(sd, sd))
            np.fill_diagonal(corr, 0.0)
            corr = np.nan_to_num(corr)
            if corr.max() > 1e-12:
                i, j = np.unravel_index(int(np.argmax(corr)), corr.shape)
                raise InputError(f"the belief correlates {names[i]} and {names[j]} (|rho| = {corr[i, j]:.3g}); a "
                                 "Prior is independent per quantity: pass marginal=True to keep the marginal "
                                 "standard deviations only")
        return cls(dict(zip(names, sd.tolist())), dict(belief.mean), weight)

    def vectors(self, space, model) -> tuple[np.ndarray, np.ndarray]:
        """Prior mean and precision (``weight / std^2``, 0 without a prior) of each free quantity.

        Parameters
        ----------
        space : ParamSpace
            The problem's free quantities.
        model : Model
            The model (its nominal parameter values are the default means).

        Returns
        -------
        (mean, precision) : arrays ordered like ``space.names``

        Raises
        ------
        ValueError
            For names that are not free.
        """
        names = set(space.names) | {e.declared for e in space.entries}
        unknown = (set(self.std) | set(self.mean)) - names
        if unknown:
            raise InputError(f"prior given for {sorted(unknown)}, which are not free; free: {space.names}")
        nominal = model.params()
        mu, prec = np.zeros(len(space)), np.zeros(len(space))
        for j, e in enumerate(space.entries):
            default = nominal[e.index] if e.kind == "param" else (0.0 if e.kind.startswith("bias") else e.start)
            mu[j] = self.mean.get(e.name, self.mean.get(e.declared, default))
            s = self.std.get(e.name, self.std.get(e.declared))
            prec[j] = 0.0 if s is None else self.weight / s**2
        return mu, prec

    def describe(self, space, model) -> dict:
        """The prior as stated for a result.

        Parameters
        ----------
        space : ParamSpace
            The problem's free quantities.
        model : Model
            The model.

        Returns
        -------
        dict
            ``{"weight": w, "quantities": {name: {"mean", "std"}}}`` of the quantities with a prior.
        """
        mu, prec = self.vectors(space, model)
        out = {e.name: {"mean": float(m), "std": float(self.std.get(e.name, self.std.get(e.declared)))}
               for e, m, p in zip(space.entries, mu, prec) if (self.std.get(e.name, self.std.get(e.declared)))}
        return {"weight": self.weight, "quantities": out}
