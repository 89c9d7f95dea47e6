"""Typed options of the moving-horizon estimator and the priors of what it estimates besides the states."""
from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

import numpy as np

from ..options import EstimatorOptions, check_int
from ...errors import InputError, InputTypeError

__all__ = ["MHEOptions", "SOLVERS", "ARRIVALS"]

SOLVERS = ("ipopt", "fatrop", "sqp", "rti")
ARRIVALS = ("ekf", "fixed")
QP_SOLVERS = ("qrqp", "osqp")


def _float(value, what: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what} is a number, got {value!r}") from None


def _positive(value, what: str) -> float:
    v = _float(value, what)
    if not np.isfinite(v) or v <= 0:
        raise InputError(f"{what} must be positive and finite, got {value!r}")
    return v


def _nonneg(value, what: str) -> float:
    v = _float(value, what)
    if not np.isfinite(v) or v < 0:
        raise InputError(f"{what} must be >= 0 and finite, got {value!r}")
    return v


def bound_pair(name: str, lo, hi) -> tuple[float, float]:
    """``(lower, upper)`` with None as unbounded; raises naming ``name`` unless lower <= upper."""
    lo = -np.inf if lo is None else float(lo)
    hi = np.inf if hi is None else float(hi)
    if np.isnan(lo) or np.isnan(hi) or lo > hi:
        raise InputError(f"bounds of {name!r} must satisfy lower <= upper, got ({lo}, {hi})")
    return lo, hi


def _frozen_mapping(value, name: str, what: str):
    if value is None:
        return MappingProxyType({})
    if not isinstance(value, Mapping):
        raise InputTypeError(f"option {name!r} maps {what}, got {type(value).__name__}")
    return MappingProxyType(dict(value))


@dataclass(frozen=True)
class MHEOptions(EstimatorOptions):
    """Options of :class:`~casship.MHE` (and those of every estimator; ``gate`` is not available).

    Parameters
    ----------
    gate, jit, outputs, max_gap, on_gap
        The options of every estimator (see :class:`~casship.estimators.EstimatorOptions`).
    horizon : int
        Number of steps ``N`` in the window (``N + 1`` samples). ``N >= len(data) - 1`` turns
        ``filter`` into full-information estimation.
    solver : {"ipopt", "fatrop", "sqp", "rti"}
        IPOPT with the exact Hessian (default); ``"fatrop"``: the interior-point method fatrop,
        which exploits the stage structure of the window (exact Hessian); ``"sqp"``: CasADi
        ``sqpmethod`` with the Gauss-Newton Hessian and a sparse QP solver, iterated to
        convergence; ``"rti"``: real-time iteration, one Gauss-Newton step per sample from the
        shifted solution.
    qpsol : {"qrqp", "osqp"} or None
        QP solver of ``"sqp"`` and ``"rti"`` (default ``"qrqp"``); refused with the interior-point
        solvers, which have none.
    arrival : {"ekf", "fixed"}
        Arrival cost: the EKF prediction of the MHE's own filtered estimate (default), or a fixed
        weight on the previous window's estimate (double counts; for comparison only).
    huber : float or None
        Huber threshold on the whitened measurement residuals (in standard deviations).
    bounds : mapping state name -> (lower, upper)
        Bounds on states (estimated parameters default to their model bounds).
    noise_bounds : mapping noise name -> (lower, upper)
        Bounds on process-noise channels (needs a diagonal ``Q``).
    estimate : mapping parameter name -> prior std or (prior std, random-walk variance)
        Parameters estimated as extra states (prior mean: the value in ``p``; constant unless a
        random-walk variance is given).
    disturbances : mapping state name -> variance or (variance, prior std)
        Additive random-walk disturbances ``d_<state>`` on the state's derivative; the variance is
        that of the noise ``w_d_<state>`` driving ``d_<state>' = w_d_<state>`` (prior std 1 unless given).
    max_iter : int or None
        Iteration limit of the NLP solver (IPOPT and fatrop 100, SQP 50; with ``"rti"`` that of the
        SQP iterations of :meth:`~casship.MHE.smooth`).
    tol : float
        Convergence tolerance of IPOPT, fatrop and SQP (with ``"rti"``: of :meth:`~casship.MHE.smooth`).
    expand : bool or None
        Expand the window problem to scalar expressions: faster solves, a longer build. ``None``
        (default): when the window has at most ``EXPAND_NODES`` (40 000) scalar operations
        (horizon times the operations of one stage), which keeps the build near half a second
        (see ``docs/mhe.md``).
    """

    horizon: int = 20
    solver: str = "ipopt"
    qpsol: str | None = None
    arrival: str = "ekf"
    huber: float | None = None
    bounds: Mapping | None = None
    noise_bounds: Mapping | None = None
    estimate: Mapping | None = None
    disturbances: Mapping | None = None
    max_iter: int | None = None
    tol: float = 1e-8
    expand: bool | None = None

    def __post_init__(self):
        super().__post_init__()
        if self.gate is not None:
            raise InputError("MHE has no innovation gate; use option 'huber' against outliers")
        object.__setattr__(self, "horizon", check_int(self.horizon, "horizon", 1))
        for name, allowed in (("solver", SOLVERS), ("arrival", ARRIVALS)):
            if getattr(self, name) not in allowed:
                raise InputError(f"option {name!r} must be one of {allowed}, got {getattr(self, name)!r}")
        if self.qpsol is None:
            object.__setattr__(self, "qpsol", "qrqp" if self.solver in ("sqp", "rti") else None)
        elif self.solver not in ("sqp", "rti"):
            raise InputError(f"option 'qpsol' is the QP solver of solvers 'sqp' and 'rti'; solver {self.solver!r} "
                             "has none")
        elif self.qpsol not in QP_SOLVERS:
            raise InputError(f"option 'qpsol' must be one of {QP_SOLVERS}, got {self.qpsol!r}")
        if self.huber is not None:
            object.__setattr__(self, "huber", _positive(self.huber, "option 'huber' (a threshold)"))
        if self.max_iter is not None:
            object.__setattr__(self, "max_iter", check_int(self.max_iter, "max_iter", 0))
        object.__setattr__(self, "tol", _positive(self.tol, "option 'tol'"))
        if self.expand is not None and not isinstance(self.expand, bool):
            raise InputError(f"option 'expand' is True, False or None, got {self.expand!r}")
        object.__setattr__(self, "bounds", _frozen_mapping(self.bounds, "bounds", "state names to (lower, upper)"))
        for n, pair in self.bounds.items():
            bound_pair(n, *pair)
        object.__setattr__(self, "noise_bounds", _frozen_mapping(self.noise_bounds, "noise_bounds",
                                                                 "noise names to (lower, upper)"))
        for n, pair in self.noise_bounds.items():
            bound_pair(n, *pair)
        object.__setattr__(self, "estimate", _frozen_mapping(self.estimate, "estimate",
                                                             "parameter names to prior standard deviations"))
        object.__setattr__(self, "disturbances", _frozen_mapping(self.disturbances, "disturbances",
                                                                 "state names to random-walk variances"))
        self.extra_priors()            # checks the numbers

    def extra_priors(self) -> tuple[list, np.ndarray, np.ndarray]:
        """Names, prior standard deviations and random-walk variances of the estimated parameters,
        then of the disturbances, in the order of the augmented states."""
        names, std, var = [], [], []
        for n, spec in self.estimate.items():
            s0, q = (spec, 0.0) if np.ndim(spec) == 0 else tuple(spec)
            names.append(n)
            std.append(_positive(s0, f"estimate[{n!r}] prior std"))
            var.append(_nonneg(q, f"estimate[{n!r}] random-walk variance"))
        for n, spec in self.disturbances.items():
            q, s0 = (spec, 1.0) if np.ndim(spec) == 0 else tuple(spec)
            names.append(f"d_{n}")
            var.append(_nonneg(q, f"disturbances[{n!r}] variance"))
            std.append(_positive(s0, f"disturbances[{n!r}] prior std"))
        return names, np.array(std), np.array(var)
