"""Predictions a user cares about, with their exact gradients with respect to the uncertain parameters.

A target is a manoeuvre metric of the model at the current parameters (tactical diameter, advance,
transfer, the first overshoot of a zig-zag, the port/starboard difference of any of them). Its
value and gradient come from one symbolic simulation (:class:`~.sensitivity.ManoeuvreFold`) and
its exact sensitivities: an event (a heading change of 90 or 180 deg, the zig-zag's rudder switch)
is located by linear interpolation between samples, and the implicit-function rule carries the
sensitivity of the event time into the metric. The zig-zag's switching time is itself a symbol of
the rudder law, so the gradient of the overshoot includes how the switch moves with the
parameters. The gradient is that of the metric computed on the design's grid, exactly.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import casadi as ca
import numpy as np

from ..errors import InputError
from .sensitivity import Approach

__all__ = ["Target", "TargetValue", "Turning", "FirstOvershoot", "Difference", "TARGETS", "get_target"]


@dataclass(frozen=True)
class TargetValue:
    """A target's value at the current parameters and its gradient.

    Parameters
    ----------
    name : str
    value : float
    gradient : (k,) array
        Ordered like the uncertain parameters.
    unit : str
    error_paths : tuple of (n + 1,) arrays
        Weights ``a`` of the target's first-order change ``a' e`` under a heading error ``e`` on the
        design's grid, one per independent manoeuvre (see :meth:`floor`).
    dt : float
        Step of that grid [s].
    """

    name: str
    value: float
    gradient: np.ndarray
    unit: str
    error_paths: tuple = ()
    dt: float = 0.0

    def floor(self, discrepancy: float) -> float:
        """The standard deviation of this prediction that the model's own error sets, which no trial removes.

        A fit's model discrepancy says that its heading prediction errs by a random walk of variance
        ``q t`` (``q`` = ``discrepancy`` [rad^2/s]). Carried through the kinematics (the heading error
        turns the track and moves the event that defines the metric: the 90 or 180 deg heading change,
        the zig-zag's switch), to first order, it moves the prediction by ``a' e`` (``e`` the heading
        error on the design's grid, ``a`` one of :attr:`error_paths`); its variance is ``q a' K a``,
        ``K_ij = min(t_i, t_j)``. Terms of a difference (port and starboard) err independently.

        Parameters
        ----------
        discrepancy : float
            ``q`` [rad^2/s] (0: no floor).

        Returns
        -------
        float
            In the unit of the target.
        """
        if not (np.isfinite(discrepancy) and discrepancy >= 0):
            raise InputError(f"discrepancy must be a finite non-negative heading variance growth [rad^2/s], "
                             f"got {discrepancy}")
        return float(np.sqrt(discrepancy * sum(_walk_variance(a, self.dt) for a in self.error_paths)))


def _walk_variance(a: np.ndarray, dt: float) -> float:
    """``a' K a / q`` for a random walk from zero at the first sample, ``K_ij = q min(t_i, t_j)``: the
    sum over the steps of ``dt`` times the squared tail sum of ``a`` after the step."""
    tail = np.cumsum(np.asarray(a, dtype=float)[::-1])[::-1]
    return float(dt * np.sum(tail[1:] ** 2))


def _track_error_path(X: np.ndarray, model, quantity: str, side: int, k: int, frac: float) -> np.ndarray:
    """Weights ``a`` of a turning metric's first-order change ``a' e`` under a heading error ``e`` held over
    each step: the track turned by ``e`` (``dx = -dy_nominal e``, ``dy = dx_nominal e`` per step), the
    crossing of the heading level moved by ``side e``."""
    ix, iy, ipsi = model.index("x"), model.index("y"), model.index("psi")
    along = quantity == "advance"
    pos = X[:, ix] if along else side * X[:, iy]
    w = -np.diff(X[:, iy]) if along else side * np.diff(X[:, ix])     # d pos_(j+1) / d e_j
    a = np.zeros(X.shape[0])
    a[:k - 1] += (1.0 - frac) * w[:k - 1]
    a[:k] += frac * w[:k]
    s = side * X[:, ipsi]
    span = s[k] - s[k - 1]
    a[k - 1] += (pos[k] - pos[k - 1]) * (-(1.0 - frac) * side) / span
    a[k] += (pos[k] - pos[k - 1]) * (-frac * side) / span
    return a


class Target:
    """Base class: a scalar prediction of a manoeuvre (``evaluate`` gives value and gradient)."""

    name = "target"
    unit = ""

    def evaluate(self, approach: Approach, names: Sequence[str]) -> TargetValue:  # pragma: no cover - abstract
        """Value and exact gradient with respect to the parameters ``names`` at ``approach.p``.

        Parameters
        ----------
        approach : Approach
            Model, parameters, approach speed, propeller rate and step.
        names : sequence of str
            The uncertain parameters (the gradient's order).

        Returns
        -------
        TargetValue
        """
        raise NotImplementedError


def _crossing(s: np.ndarray, ds: np.ndarray, level: float, start: int, what: str):
    """First sample interval where ``s`` reaches ``level`` (from index ``start``): the fraction of
    the step and its derivative (implicit function on the linear interpolation)."""
    idx = np.flatnonzero(s[start:] >= level)
    if idx.size == 0 or start + idx[0] == 0:
        raise InputError(f"{what}: the heading change never reaches {np.degrees(level):.4g} deg in the simulated "
                         "time (a larger rudder angle, or a longer record?)")
    k = start + idx[0]
    span = s[k] - s[k - 1]
    frac = (level - s[k - 1]) / span
    dfrac = (-(1.0 - frac) * ds[k - 1] - frac * ds[k]) / span
    return k, frac, dfrac


def _interp(v: np.ndarray, dv: np.ndarray, k: int, frac: float, dfrac: np.ndarray):
    """Value and derivative of ``v`` interpolated at ``k - 1 + frac``."""
    return (v[k - 1] + frac * (v[k] - v[k - 1]),
            (1.0 - frac) * dv[k - 1] + frac * dv[k] + (v[k] - v[k - 1]) * dfrac)


def _steps_to(approach: Approach, rudder_row, level: float, start_frac: float = 0.0, extra: int = 3,
              horizon: float = 60.0) -> int:
    """Steps until the heading change ``side * psi`` first reaches ``level`` in a plain simulation
    (no sensitivities), plus ``extra``; ``horizon`` in units of L/U."""
    from ..simulation import fold_steps

    m = approach.model
    n = int(np.ceil(horizon * approach.time_scale / approach.dt))
    U = approach.inputs(rudder_row(approach.midpoints(n)))
    X = fold_steps(approach.dmodel, approach.x0, U.T, approach.p, np.zeros((n, m.nw)), np.full(n, approach.dt))
    psi = X[:, m.index("psi")]
    reached = np.flatnonzero(np.abs(psi) >= level)
    if reached.size == 0:
        return n
    return int(min(reached[0] + extra, n))


def _check_side(side) -> None:
    if side not in (1, -1):
        raise InputError(f"side must be +1 (starboard) or -1 (port), got {side}")


def _to_heading(approach: Approach, names: Sequence[str], law, level: float, side: int, what: str, extra: int = 3):
    """Simulate ``law`` (``t -> rudder``) with its sensitivities until the heading change ``side * psi``
    reaches ``level`` (plus ``extra`` steps); returns ``X, dX``, the crossing ``k, frac, dfrac`` and the steps ``n``."""
    n = _steps_to(approach, law, level, extra=extra)
    U = approach.inputs(law(approach.midpoints(n)))
    X, dX = approach.fold(names, n).sensitivities(lambda tau: ca.MX(ca.DM(U)))
    ipsi = approach.model.index("psi")
    return (X, dX, *_crossing(side * X[:, ipsi], side * dX[:, ipsi], level, 1, what), n)


@dataclass(frozen=True)
class Turning(Target):
    """Advance, transfer or tactical diameter of a turning circle from the approach.

    Measured from the execute (t = 0, rudder moved at the vessel's rudder rate) in the frame of
    the approach heading, as :func:`casship.maneuvers.turning_metrics` does: advance along the
    approach at a 90 deg heading change, transfer across it then, tactical diameter across it at
    180 deg. Lengths are positive for a turn to either side.

    Parameters
    ----------
    quantity : {"advance", "transfer", "tactical_diameter"}
    side : {+1, -1}
        +1 starboard, -1 port.
    rudder_deg : float
        Rudder angle [deg].
    """

    quantity: str = "tactical_diameter"
    side: int = 1
    rudder_deg: float = 35.0

    def __post_init__(self):
        if self.quantity not in ("advance", "transfer", "tactical_diameter"):
            raise InputError(f"unknown turning quantity {self.quantity!r}; use advance, transfer or tactical_diameter")
        _check_side(self.side)
        if not (0 < self.rudder_deg <= 90):
            raise InputError(f"rudder_deg must be in (0, 90], got {self.rudder_deg}")

    @property
    def name(self) -> str:
        """E.g. ``tactical_diameter_starboard_35``."""
        return f"{self.quantity}_{'starboard' if self.side > 0 else 'port'}_{self.rudder_deg:g}"

    unit = "m"

    def rudder(self, approach: Approach):
        """The rudder law ``t -> delta`` [rad]: to the angle at the vessel's rate from t = 0.

        Parameters
        ----------
        approach : Approach

        Returns
        -------
        callable
        """
        delta = self.side * np.radians(self.rudder_deg)
        rate = approach.rudder_rate
        return lambda t: delta * (np.minimum(1.0, rate * np.asarray(t) / abs(delta)) if rate else np.ones_like(t))

    def evaluate(self, approach: Approach, names: Sequence[str]) -> TargetValue:
        level = np.radians(90.0 if self.quantity != "tactical_diameter" else 180.0)
        X, dX, k, frac, dfrac, _ = _to_heading(approach, names, self.rudder(approach), level, self.side, self.name)
        ix, iy = approach.model.index("x"), approach.model.index("y")
        if self.quantity == "advance":
            v, dv = _interp(X[:, ix], dX[:, ix], k, frac, dfrac)
        else:
            v, dv = _interp(self.side * X[:, iy], self.side * dX[:, iy], k, frac, dfrac)
        path = _track_error_path(X, approach.model, self.quantity, self.side, k, frac)
        return TargetValue(self.name, float(v), np.asarray(dv, dtype=float), self.unit, (path,), approach.dt)


@dataclass(frozen=True)
class FirstOvershoot(Target):
    """First overshoot angle of a zig-zag (rudder ``rudder_deg``, switch at ``heading_deg``).

    The rudder goes to ``side * rudder_deg`` at t = 0 at the vessel's rate; when the heading change
    reaches ``heading_deg`` (time ``t1``, interpolated) it is reversed at the same rate. The
    overshoot is the largest heading change after ``t1`` less ``heading_deg``. Its gradient
    combines the parameters' effect with ``t1`` held and the effect of ``t1`` (a symbol of the
    rudder law) times ``d t1 / d theta``.

    Parameters
    ----------
    rudder_deg, heading_deg : float
        Zig-zag angles [deg] (20/20 by default).
    side : {+1, -1}
        First rudder to starboard (+1) or port (-1).
    """

    rudder_deg: float = 20.0
    heading_deg: float = 20.0
    side: int = 1

    unit = "rad"

    def __post_init__(self):
        _check_side(self.side)
        if not (0 < self.rudder_deg <= 90 and 0 < self.heading_deg < 180):
            raise InputError(f"zig-zag angles must be positive degrees, got {self.rudder_deg}/{self.heading_deg}")

    @property
    def name(self) -> str:
        """E.g. ``first_overshoot_20_20_starboard``."""
        return f"first_overshoot_{self.rudder_deg:g}_{self.heading_deg:g}_{'starboard' if self.side > 0 else 'port'}"

    def law(self, approach: Approach, lib=np):
        """The rudder law ``(t, t1) -> delta`` [rad] for a switch time ``t1``.

        Parameters
        ----------
        approach : Approach
        lib : module
            ``numpy`` (numbers) or ``casadi`` (``t1`` a symbol).

        Returns
        -------
        callable
        """
        dz = np.radians(self.rudder_deg)
        rate = approach.rudder_rate or 1e6 * dz            # no rate: a step within a microsecond

        def rudder(t, t1):
            first = lib.fmin(dz, rate * t) if lib is ca else np.minimum(dz, rate * t)
            back = rate * (t - t1)
            back = lib.fmin(lib.fmax(back, 0.0), 2 * dz) if lib is ca else np.clip(back, 0.0, 2 * dz)
            return self.side * (first - back)
        return rudder

    def evaluate(self, approach: Approach, names: Sequence[str]) -> TargetValue:
        level = np.radians(self.heading_deg)
        law = self.law(approach)
        # the switch: heading change reaches the switch angle (nothing before it depends on t1)
        X, dX, k, frac, dfrac, n_switch = _to_heading(approach, names, lambda t: law(t, np.inf), level, self.side,
                                                      self.name, extra=1)
        ipsi = approach.model.index("psi")
        t1 = float((k - 1) * approach.dt + frac * approach.dt)
        dt1 = approach.dt * dfrac
        rate = approach.rudder_rate
        if rate and rate * t1 < np.radians(self.rudder_deg):
            raise InputError(f"{self.name}: the heading reaches the switch angle at {t1:.3g} s, before the rudder "
                             f"reached {self.rudder_deg:g} deg")
        # after the switch: simulate to the first peak of the heading change, t1 a symbol
        n = int(n_switch + np.ceil(4 * approach.time_scale / approach.dt))
        full = approach.fold(names, n)
        tt = approach.midpoints(n)
        law_ca = self.law(approach, ca)
        X, dX = full.sensitivities(lambda tau: approach.inputs(law_ca(ca.DM(tt).T, tau[0])), [t1])
        s = self.side * X[:, ipsi]
        after = np.arange(k, n + 1)
        j = int(after[np.argmax(s[after])])
        if j == n:
            raise InputError(f"{self.name}: no first overshoot within {n * approach.dt:g} s after the execute")
        ds = self.side * dX[j, ipsi]
        grad = ds[:-1] + ds[-1] * dt1
        # the heading error from the switch to the peak is what the model cannot predict of the overshoot
        path = np.zeros(n + 1)
        path[j] += 1.0
        path[k - 1] -= 1.0 - frac
        path[k] -= frac
        return TargetValue(self.name, float(s[j] - level), np.asarray(grad, dtype=float), self.unit, (path,),
                           approach.dt)


@dataclass(frozen=True)
class Difference(Target):
    """``first - second``: e.g. the starboard minus the port tactical diameter.

    Parameters
    ----------
    first, second : Target
    label : str
        Name of the difference.
    """

    first: Target
    second: Target
    label: str = "difference"

    @property
    def name(self) -> str:
        """The label."""
        return self.label

    @property
    def unit(self) -> str:
        """The unit of both terms."""
        return self.first.unit

    def evaluate(self, approach: Approach, names: Sequence[str]) -> TargetValue:
        a, b = self.first.evaluate(approach, names), self.second.evaluate(approach, names)
        return TargetValue(self.name, a.value - b.value, a.gradient - b.gradient, a.unit,
                           a.error_paths + b.error_paths, a.dt)


#: The named targets (``casship design-trial --target NAME``).
TARGETS = {
    "tactical_diameter": Turning("tactical_diameter", 1),
    "tactical_diameter_port": Turning("tactical_diameter", -1),
    "advance": Turning("advance", 1),
    "advance_port": Turning("advance", -1),
    "transfer": Turning("transfer", 1),
    "first_overshoot": FirstOvershoot(20.0, 20.0, 1),
    "first_overshoot_port": FirstOvershoot(20.0, 20.0, -1),
    "port_starboard_difference": Difference(Turning("tactical_diameter", 1), Turning("tactical_diameter", -1),
                                            "port_starboard_difference"),
}


def get_target(target) -> Target:
    """A :class:`Target` from a name in :data:`TARGETS` (or a Target, returned as is).

    Parameters
    ----------
    target : str or Target

    Returns
    -------
    Target

    Raises
    ------
    ValueError
        An unknown name (the known ones are listed).
    """
    if isinstance(target, Target):
        return target
    if target not in TARGETS:
        raise InputError(f"unknown target {target!r}; known: {list(TARGETS)}")
    return TARGETS[target]
