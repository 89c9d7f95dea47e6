"""What casship knows about a ship, as a value: :class:`Vessel` and the validity ranges :class:`Limit`.

A :class:`Vessel` travels with a :class:`~casship.model.Model` (``model.vessel``): main particulars,
scale, which inputs are rudders and propellers, the approach condition, the actuator limits and the
identity of the parameter set with its source. Code that needs to know which input steers the ship
or how long it is reads it here, never from names or strings.

A :class:`Limit` is the range a state or input of a model is valid for (``model.limits``), declared
by the model's author with :meth:`casship.ModelBuilder.limit`.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from .errors import InputError

__all__ = ["Vessel", "Limit"]


def _positive(value, what: str, vessel: str, optional: bool = False):
    if value is None and optional:
        return None
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"Vessel {vessel!r}: {what} must be a positive finite number, got {value}")
    return value


@dataclass(frozen=True, repr=False)
class Vessel:
    """Main particulars and identity of a ship.

    Parameters
    ----------
    name : str
        Ship name (e.g. ``"KVLCC2"``).
    L_pp : float
        Length between perpendiculars [m].
    B : float, optional
        Breadth [m].
    draught : float, optional
        Draught [m].
    mass : float, optional
        Displacement mass [kg].
    scale : float
        Geometric scale ratio ``lambda`` of this vessel to the ship it represents (1 at full scale,
        45.7 for a 1:45.7 model).
    U0 : float, optional
        Approach (service) speed [m/s].
    n0 : float, optional
        Propeller rate at the approach speed [1/s], when the source gives one.
    rudders : tuple of str
        Names of the model inputs that are rudder angles [rad] (commanded angles when the model has
        a rudder actuator).
    propellers : tuple of str
        Names of the model inputs that are propeller rates [1/s].
    rudder_max : float, optional
        Rudder angle limit [rad].
    rudder_rate : float, optional
        Rudder rate limit [rad/s].
    propeller_range : (float, float), optional
        Range of propeller rates the model is valid for [1/s].
    param_set : str
        Identity of the parameter set (e.g. ``"kvlcc2/YY2015"``): a fit or parameter file records it,
        and applying it to a model with another parameter set raises.
    source : str
        Where the particulars and parameters come from.
    wind : mapping, optional
        Above-water geometry for wind loads (see :func:`casship.models.add_wind`).

    Examples
    --------
    >>> from casship.models import kvlcc2
    >>> ship = kvlcc2()
    >>> ship.vessel.L_pp, ship.vessel.rudders, ship.vessel.propellers
    (320.0, ('delta',), ('n',))
    """

    name: str
    L_pp: float
    B: float | None = None
    draught: float | None = None
    mass: float | None = None
    scale: float = 1.0
    U0: float | None = None
    n0: float | None = None
    rudders: tuple = ()
    propellers: tuple = ()
    rudder_max: float | None = None
    rudder_rate: float | None = None
    propeller_range: tuple | None = None
    param_set: str = ""
    source: str = ""
    wind: Mapping | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        if not isinstance(self.name, str) or not self.name:
            raise InputError(f"Vessel name must be a non-empty string, got {self.name!r}")
        set_("L_pp", _positive(self.L_pp, "L_pp", self.name))
        for key in ("B", "draught", "mass", "U0", "n0", "rudder_max", "rudder_rate"):
            set_(key, _positive(getattr(self, key), key, self.name, optional=True))
        set_("scale", _positive(self.scale, "scale", self.name))
        for key in ("rudders", "propellers"):
            names = tuple(getattr(self, key))
            if not all(isinstance(n, str) and n.isidentifier() for n in names):
                raise InputError(f"Vessel {self.name!r}: {key} must be input names, got {names!r}")
            set_(key, names)
        if self.propeller_range is not None:
            lo, hi = (float(v) for v in self.propeller_range)
            if not lo < hi:
                raise InputError(f"Vessel {self.name!r}: propeller_range must be (lower, upper) with "
                                 f"lower < upper, got {self.propeller_range!r}")
            set_("propeller_range", (lo, hi))
        if self.wind is not None:
            set_("wind", dict(self.wind))     # a copy (not compared; a proxy would not pickle)

    def replace(self, **changes) -> "Vessel":
        """A copy with the given fields changed (e.g. another ``param_set`` after a fit).

        The copy is checked like a new :class:`Vessel`.

        Parameters
        ----------
        **changes
            Field name -> new value (the constructor's parameters, in their units).

        Returns
        -------
        Vessel
            The new vessel; this one is unchanged.

        Raises
        ------
        TypeError
            For a name that is not a field.
        ValueError
            For an invalid value (e.g. a non-positive ``L_pp``).

        Examples
        --------
        >>> from casship.models import kvlcc2
        >>> vessel = kvlcc2().vessel
        >>> vessel.replace(param_set="kvlcc2/my-fit").param_set
        'kvlcc2/my-fit'
        """
        return replace(self, **changes)

    @property
    def froude_number(self) -> float | None:
        """Froude number ``U0 / sqrt(g L_pp)`` of the approach speed (None without ``U0``)."""
        return None if self.U0 is None else self.U0 / np.sqrt(9.81 * self.L_pp)

    def check_inputs(self, input_names) -> None:
        """Raise ``ValueError`` if a rudder or propeller named here is not among ``input_names``.

        Parameters
        ----------
        input_names : sequence of str
            The input names of the model the vessel is attached to.

        Raises
        ------
        ValueError
            Naming the missing rudder or propeller inputs and listing ``input_names``.

        Examples
        --------
        >>> from casship.models import kvlcc2
        >>> kvlcc2().vessel.check_inputs(("delta",))
        Traceback (most recent call last):
        ...
        ValueError: Vessel 'KVLCC2' names input(s) ['n'] that the model does not have; inputs: ['delta']
        """
        missing = [n for n in (*self.rudders, *self.propellers) if n not in input_names]
        if missing:
            raise InputError(f"Vessel {self.name!r} names input(s) {missing} that the model does not have; "
                             f"inputs: {list(input_names)}")

    def __repr__(self) -> str:
        """One line with units; angles in degrees (``rudder_max=35.0 deg``), as people read them."""
        parts = [repr(self.name), f"L_pp={self.L_pp:g} m"]
        for key, unit in (("B", "m"), ("draught", "m"), ("mass", "kg")):
            value = getattr(self, key)
            if value is not None:
                parts.append(f"{key}={value:.6g} {unit}")
        if self.scale != 1.0:
            parts.append(f"scale=1:{self.scale:g}")
        if self.U0 is not None:
            parts.append(f"U0={self.U0:.4g} m/s")
        if self.n0 is not None:
            parts.append(f"n0={self.n0:.4g} 1/s")
        parts += [f"rudders={self.rudders!r}", f"propellers={self.propellers!r}"]
        if self.rudder_max is not None:
            parts.append(f"rudder_max={np.degrees(self.rudder_max):.1f} deg")
        if self.rudder_rate is not None:
            parts.append(f"rudder_rate={np.degrees(self.rudder_rate):.3g} deg/s")
        if self.propeller_range is not None:
            parts.append(f"propeller_range=({self.propeller_range[0]:g}, {self.propeller_range[1]:g}) 1/s")
        if self.param_set:
            parts.append(f"param_set={self.param_set!r}")
        return f"Vessel({', '.join(parts)})"

    def summary(self) -> str:
        """A few lines describing the ship."""
        rows = [f"{self.name} (parameter set {self.param_set or 'unnamed'}; scale 1:{self.scale:g})",
                f"  L_pp {self.L_pp:g} m" + (f", B {self.B:g} m" if self.B else "")
                + (f", draught {self.draught:g} m" if self.draught else "")
                + (f", mass {self.mass:.4g} kg" if self.mass else "")]
        if self.U0 is not None:
            rows.append(f"  approach speed {self.U0:.3g} m/s (Fn {self.froude_number:.3f})"
                        + (f" at {self.n0:g} rps" if self.n0 else ""))
        rows.append(f"  rudders {list(self.rudders)}, propellers {list(self.propellers)}")
        if self.rudder_max is not None:
            rows.append(f"  rudder limit {np.degrees(self.rudder_max):.1f} deg"
                        + (f", rate {np.degrees(self.rudder_rate):.2f} deg/s" if self.rudder_rate else ""))
        if self.source:
            rows.append(f"  source: {self.source}")
        return "\n".join(rows)


@dataclass(frozen=True)
class Limit:
    """The range ``[lower, upper]`` a named state or input of a model is valid for.

    Parameters
    ----------
    name : str
        State or input name.
    lower, upper : float
        Bounds (``-inf`` / ``inf`` for one-sided ranges), in the variable's SI unit.
    why : str
        The reason, shown in error messages (e.g. ``"rudder stop"``, ``"MMG model valid ahead only"``).
    """

    name: str
    lower: float = -np.inf
    upper: float = np.inf
    why: str = ""

    def __post_init__(self):
        lo, hi = float(self.lower), float(self.upper)
        if np.isnan(lo) or np.isnan(hi) or not lo < hi:
            raise InputError(f"limit of {self.name!r}: need lower < upper, got ({self.lower}, {self.upper})")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)

    def contains(self, values) -> np.ndarray:
        """Elementwise ``lower <= values <= upper``.

        Parameters
        ----------
        values : float or array_like
            Values of the limited variable, in its SI unit.

        Returns
        -------
        ndarray of bool
            Of the shape of ``values`` (0-d for a scalar); NaN gives ``False``.

        Examples
        --------
        >>> rudder = Limit("delta", -0.61, 0.61, "rudder stop")
        >>> rudder.contains([0.0, 0.7, np.nan])
        array([ True, False, False])
        """
        values = np.asarray(values, dtype=float)
        return (values >= self.lower) & (values <= self.upper)

    def describe(self, unit: str = "", angle: bool = False) -> str:
        """``"[lo, hi] unit (why)"`` with angles shown in degrees.

        Parameters
        ----------
        unit : str
            Unit of the variable, shown after the range (empty: none).
        angle : bool
            The variable is an angle [rad]: show the bounds in degrees with the unit ``deg``
            (``unit`` is then ignored).

        Returns
        -------
        str
            The range with four significant digits, then the unit and the reason if any.

        Examples
        --------
        >>> Limit("delta", -np.radians(35), np.radians(35), "rudder stop").describe(angle=True)
        '[-35, 35] deg (rudder stop)'
        >>> Limit("u", 0.0, why="ahead only").describe("m/s")
        '[0, inf] m/s (ahead only)'
        """
        conv = np.degrees if angle else (lambda v: v)
        unit = "deg" if angle else unit
        text = f"[{conv(self.lower):.4g}, {conv(self.upper):.4g}]" + (f" {unit}" if unit else "")
        return text + (f" ({self.why})" if self.why else "")
