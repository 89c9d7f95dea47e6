"""Declaring a model: :class:`ModelBuilder` collects named states, inputs, parameters, noise channels,
outputs, ports, validity limits and the vessel, then :meth:`ModelBuilder.build` freezes them into an
immutable :class:`~casship.model.Model`.
"""
from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Mapping

import casadi as ca
import numpy as np

from .model import Model
from .vessel import Limit, Vessel
from .errors import InputError, InputTypeError

__all__ = ["ModelBuilder", "Variable", "Parameter", "Declarations"]


@dataclass(frozen=True)
class Variable:
    """A named scalar of a model (state, input, noise channel or output).

    Parameters
    ----------
    name : str
        Identifier.
    unit : str
        SI unit.
    angle : bool
        An angle (residuals wrapped to (-pi, pi]).
    doc : str
        One-line description.
    """

    name: str
    unit: str = ""
    angle: bool = False
    doc: str = ""


@dataclass(frozen=True)
class Parameter(Variable):
    """A named model parameter with its nominal value and optional bounds.

    Parameters
    ----------
    name, unit, angle, doc
        As for :class:`Variable`.
    value : float
        Nominal value.
    lower, upper : float
        Bounds.
    source : str
        Where the value comes from.
    """

    value: float = 0.0
    lower: float = -np.inf
    upper: float = np.inf
    source: str = ""


@dataclass(frozen=True)
class Declarations:
    """What a :class:`ModelBuilder` holds, as a read-only snapshot: what a :class:`~casship.model.Model`
    is built from.

    Parameters
    ----------
    name, doc : str
        Name and one-line description of the model.
    dt : float or None
        Sampling period of a discrete-time model (``None``: continuous-time).
    states, inputs, noises, outputs : tuple of Variable
        The declared variables in the order of their vectors.
    params : tuple of Parameter
        The declared parameters in the order of the parameter vector.
    symbols : mapping name -> casadi.SX
        The symbol of every state, input, parameter and noise channel.
    rates : mapping state name -> casadi.SX
        The time derivative of each state (of a discrete-time model: ``(x[k+1] - x[k]) / dt``).
    output_exprs : mapping output name -> casadi.SX
        The expression of each output.
    ports : mapping name -> casadi.SX
        The symbol of each port.
    port_terms : mapping name -> tuple of casadi.SX
        The terms fed to each port (their sum replaces the port's symbol).
    limits : mapping name -> Limit
        Declared validity ranges of states and inputs.
    vessel : Vessel or None
        The ship the model describes.
    meta : mapping
        Free-form notes of the model.
    """

    name: str
    doc: str
    dt: float | None
    states: tuple[Variable, ...]
    inputs: tuple[Variable, ...]
    params: tuple[Parameter, ...]
    noises: tuple[Variable, ...]
    outputs: tuple[Variable, ...]
    symbols: Mapping[str, ca.SX]
    rates: Mapping[str, ca.SX]
    output_exprs: Mapping[str, ca.SX]
    ports: Mapping[str, ca.SX]
    port_terms: Mapping[str, tuple[ca.SX, ...]]
    limits: Mapping[str, Limit]
    vessel: Vessel | None
    meta: Mapping


RESERVED = ("t", "time")   # the time column of every Dataset


def _check_name(name: str, taken: Mapping[str, str]) -> None:
    if not isinstance(name, str) or not name.isidentifier():
        raise InputError(f"name {name!r} is not a valid identifier")
    if name in RESERVED:
        raise InputError(f"name {name!r} is reserved for time stamps; choose another name")
    if name in taken:
        raise InputError(f"name {name!r} is already declared as a {taken[name]}")


def _as_sx(expr, what: str) -> ca.SX:
    try:
        value = ca.SX(expr)
    except Exception as exc:  # pragma: no cover - message path
        raise InputTypeError(f"{what}: cannot convert {type(expr).__name__} to a CasADi expression") from exc
    if value.shape != (1, 1):
        raise InputError(f"{what}: expected a scalar expression, got shape {value.shape}")
    return value


class ModelBuilder:
    """Collect the symbols and equations of a model, then :meth:`build` it.

    Parameters
    ----------
    name : str
        Name of the model (used for Function names and reports).
    doc : str, optional
        One-line description with the source of the model.
    dt : float, optional
        Sampling period [s] of a discrete-time model: its states are then given as
        ``x[k+1] = F(x, u, p, w)`` with :meth:`next` instead of :meth:`ode`, and the noise ``w``
        is the discrete noise of one step (its covariance ``Q`` is the discrete ``Qd``).

    Examples
    --------
    >>> import casship as cs
    >>> b = cs.ModelBuilder("nomoto1")
    >>> psi, r = b.state("psi", angle=True), b.state("r")
    >>> delta = b.input("delta")
    >>> K, T = b.param("K", 0.08), b.param("T", 25.0)
    >>> b.ode(psi=r, r=(K * delta - r) / T + b.noise("w_r"))
    >>> b.output("psi_m", psi)
    >>> model = b.build()
    >>> model.state_names
    ('psi', 'r')
    """

    def __init__(self, name: str, doc: str = "", *, dt: float | None = None):
        self.name = name
        self.doc = doc
        if dt is not None and not (np.isfinite(float(dt)) and float(dt) > 0):
            raise InputError(f"model {name!r}: dt must be a positive sampling period, got {dt!r}")
        self.dt = None if dt is None else float(dt)
        self._kinds: dict[str, str] = {}
        self._symbols: dict[str, ca.SX] = {}
        self._states: list[Variable] = []
        self._inputs: list[Variable] = []
        self._params: list[Parameter] = []
        self._noises: list[Variable] = []
        self._outputs: list[Variable] = []
        self._ode: dict[str, ca.SX] = {}
        self._output_expr: dict[str, ca.SX] = {}
        self._ports: dict[str, ca.SX] = {}
        self._port_terms: dict[str, list[ca.SX]] = {}
        self._limits: dict[str, Limit] = {}
        self.vessel: Vessel | None = None
        self.meta: dict = {}

    # -- declarations -------------------------------------------------------------------------
    def _declare(self, kind: str, var: Variable, store: list) -> ca.SX:
        _check_name(var.name, self._kinds)
        sym = ca.SX.sym(var.name)
        self._kinds[var.name] = kind
        self._symbols[var.name] = sym
        store.append(var)
        return sym

    def state(self, name: str, *, unit: str = "", angle: bool = False, doc: str = "") -> ca.SX:
        """Declare a state; ``angle=True`` marks it as an angle (wrapped residuals).

        Parameters
        ----------
        name : str
            Identifier, unique in the model.
        unit : str
            SI unit (e.g. ``"rad"``, ``"m/s"``).
        angle : bool
            An angle: residuals are wrapped to (-pi, pi].
        doc : str
            One-line description.

        Returns
        -------
        casadi.SX
            The symbol, to write equations with.
        """
        return self._declare("state", Variable(name, unit, angle, doc), self._states)

    def input(self, name: str, *, unit: str = "", angle: bool = False, doc: str = "") -> ca.SX:
        """Declare a (known) input such as a rudder angle or propeller rate.

        Parameters
        ----------
        name : str
            Identifier, unique in the model.
        unit : str
            SI unit (e.g. ``"rad"``, ``"m/s"``).
        angle : bool
            An angle: residuals are wrapped to (-pi, pi].
        doc : str
            One-line description.

        Returns
        -------
        casadi.SX
            The symbol, to write equations with.
        """
        return self._declare("input", Variable(name, unit, angle, doc), self._inputs)

    def param(self, name: str, value: float, *, bounds: tuple[float, float] | None = None,
              unit: str = "", doc: str = "", source: str = "") -> ca.SX:
        """Declare a parameter with nominal ``value`` and optional ``bounds=(lower, upper)``.

        Parameters
        ----------
        name : str
            Identifier, unique in the model.
        value : float
            Nominal value (finite).
        bounds : (float, float), optional
            Lower and upper bound: the parameter's valid range (``Model.params`` refuses a value
            outside it; identification stays within it).
        unit : str
            SI unit (e.g. ``"rad"``, ``"m/s"``).
        doc : str
            One-line description.
        source : str
            Where the value comes from.

        Returns
        -------
        casadi.SX
            The symbol, to write equations with.
        """
        value = float(value)
        if not np.isfinite(value):
            raise InputError(f"parameter {name!r}: nominal value must be finite, got {value}")
        lower, upper = (-np.inf, np.inf) if bounds is None else (float(bounds[0]), float(bounds[1]))
        if not lower <= value <= upper:
            raise InputError(f"parameter {name!r}: nominal value {value} outside bounds {(lower, upper)}")
        par = Parameter(name, unit, False, doc, value, lower, upper, source)
        return self._declare("param", par, self._params)

    def param_as_state(self, name: str, *, doc: str = "", rate=None) -> ca.SX:
        """Turn the declared parameter ``name`` into a state (same symbol and unit; for augmented-state
        estimation), e.g. a random walk with ``rate=b.noise("w_K")``.

        Parameters
        ----------
        name : str
            A declared parameter.
        doc : str
            One-line description (default: the parameter's).
        rate : casadi.SX, optional
            Its rate: the time derivative, or in a discrete-time model the rate over a step
            ``(x[k+1] - x[k]) / dt`` (as for :meth:`add_to_ode`). Without it, give the new state an
            equation with :meth:`ode` or :meth:`next`.

        Returns
        -------
        casadi.SX
            The symbol, to write equations with.
        """
        if self._kinds.get(name) != "param":
            raise InputError(f"param_as_state: {name!r} is not a declared parameter of {self.name!r}")
        var = next(v for v in self._params if v.name == name)
        self._params = [v for v in self._params if v.name != name]
        self._kinds[name] = "state"
        self._states.append(Variable(name, var.unit, False, doc or var.doc))
        if rate is not None:
            self._ode[name] = _as_sx(rate, f"rate of {name!r}")
        return self._symbols[name]

    def noise(self, name: str, *, unit: str = "", doc: str = "") -> ca.SX:
        """Declare a process-noise channel ``w`` (zero mean; covariance given to estimators).

        Parameters
        ----------
        name : str
            Identifier, unique in the model.
        unit : str
            SI unit (e.g. ``"rad"``, ``"m/s"``).
        doc : str
            One-line description.

        Returns
        -------
        casadi.SX
            The symbol, to write equations with.
        """
        return self._declare("noise", Variable(name, unit, False, doc), self._noises)

    def port(self, name: str, size: int = 1) -> ca.SX:
        """Declare an additive port: a placeholder that later terms may feed (sum), zero if unfed.

        Parameters
        ----------
        name : str
            Identifier, unique in the model.
        size : int
            Length of the port vector.

        Returns
        -------
        casadi.SX
            The symbol, to write equations with.
        """
        _check_name(name, self._kinds)
        sym = ca.SX.sym(name, size)
        self._kinds[name] = "port"
        self._ports[name] = sym
        self._port_terms[name] = []
        return sym

    def feed(self, port: str, expr) -> None:
        """Add ``expr`` to the port ``port`` (e.g. a wind force ``vertcat(X, Y, N)`` to ``tau``).

        Parameters
        ----------
        port : str
            A declared port.
        expr : casadi.SX
            Expression of the port's shape.
        """
        if port not in self._ports:
            raise InputError(f"unknown port {port!r}; ports: {sorted(self._ports)}")
        expr = ca.SX(expr)
        if expr.shape != self._ports[port].shape:
            raise InputError(f"port {port!r} has shape {self._ports[port].shape}, got {expr.shape}")
        self._port_terms[port].append(expr)

    def limit(self, name: str, lower: float = -np.inf, upper: float = np.inf, *, why: str = "") -> None:
        """Declare the range ``[lower, upper]`` a state or input is valid for (see :class:`~casship.vessel.Limit`).

        Simulators, manoeuvre runners, trim and the command line check inputs against it and raise a
        ``ValueError`` naming the variable and the range (unless the caller opts in to out-of-range use).

        Parameters
        ----------
        name : str
            A declared state or input.
        lower, upper : float
            The valid range in the variable's SI unit (``-inf``/``inf`` for one-sided ranges).
        why : str
            The reason, shown in error messages (e.g. ``"rudder stop"``).
        """
        if self._kinds.get(name) not in ("state", "input"):
            raise InputError(f"limit: {name!r} is not a declared state or input of {self.name!r}")
        self._limits[name] = Limit(name, lower, upper, why)

    # -- equations ----------------------------------------------------------------------------
    def ode(self, **rhs) -> None:
        """Set the time derivative of states by name, e.g. ``b.ode(psi=r, r=...)``.

        Parameters
        ----------
        **rhs
            State name -> expression of its time derivative.
        """
        if self.dt is not None:
            raise InputError(f"model {self.name!r} is discrete-time (dt = {self.dt:g} s): give x[k+1] with next(...)")
        for name, expr in rhs.items():
            if self._kinds.get(name) != "state":
                raise InputError(f"ode: {name!r} is not a declared state")
            self._ode[name] = _as_sx(expr, f"ode for {name!r}")

    def next(self, **rhs) -> None:
        """Set the next state ``x[k+1]`` of a discrete-time model by name, e.g. ``b.next(x=x + dt * v)``.

        The model keeps ``(x[k+1] - x[k]) / dt`` as its rate ``f``, so that composition
        (:meth:`add_to_ode`, :func:`~casship.augment`) adds ``dt`` times a rate to the step.

        Parameters
        ----------
        **rhs
            State name -> expression of ``x[k+1]`` in the declared symbols.
        """
        if self.dt is None:
            raise InputError(f"model {self.name!r} is continuous-time: give derivatives with ode(...), or "
                             "build a discrete-time model with ModelBuilder(name, dt=...)")
        for name, expr in rhs.items():
            if self._kinds.get(name) != "state":
                raise InputError(f"next: {name!r} is not a declared state")
            self._ode[name] = (_as_sx(expr, f"next for {name!r}") - self._symbols[name]) / self.dt

    def add_to_ode(self, **rhs) -> None:
        """Add terms to existing state derivatives (for composing models).

        Parameters
        ----------
        **rhs
            State name -> expression added to its time derivative.
        """
        for name, expr in rhs.items():
            if name not in self._ode:
                raise InputError(f"add_to_ode: state {name!r} has no equation yet")
            self._ode[name] = self._ode[name] + _as_sx(expr, f"add_to_ode for {name!r}")

    def output(self, name: str, expr, *, unit: str = "", angle: bool | None = None,
               doc: str = "") -> None:
        """Declare an output ``y``; an output that is a state inherits its angle flag and unit by default.

        Parameters
        ----------
        name : str
            Identifier, unique in the model.
        expr : casadi.SX
            Expression of states, inputs and parameters (no noise).
        unit : str
            SI unit (e.g. ``"rad"``, ``"m/s"``).
        angle : bool, optional
            An angle output (by default: inherited from the state it measures).
        doc : str
            One-line description.
        """
        expr = _as_sx(expr, f"output {name!r}")
        measured = next((v for v in self._states if ca.is_equal(expr, self._symbols[v.name])), None)
        if angle is None:
            angle = measured is not None and measured.angle
        if not unit and measured is not None:
            unit = measured.unit
        if not isinstance(name, str) or not name.isidentifier():
            raise InputError(f"output name {name!r} is not a valid identifier")
        if name in RESERVED:
            raise InputError(f"output name {name!r} is reserved for time stamps; choose another name")
        if name in self._output_expr:
            raise InputError(f"output {name!r} is already declared")
        if name in self._kinds and not (self._kinds[name] == "state" and ca.is_equal(expr, self._symbols[name])):
            raise InputError(f"output {name!r} clashes with the {self._kinds[name]} of that name; an output may "
                             "share a name only with the state it measures")
        self._outputs.append(Variable(name, unit, bool(angle), doc))
        self._output_expr[name] = expr

    def drop_outputs(self) -> None:
        """Remove every declared output (to declare others, as :meth:`~casship.model.Model.with_outputs` does)."""
        self._outputs, self._output_expr = [], {}

    # -- lookup -------------------------------------------------------------------------------
    def sym(self, name: str) -> ca.SX:
        """The symbol of a declared state, input, parameter, noise channel or port.

        Parameters
        ----------
        name : str
            A declared name.

        Returns
        -------
        casadi.SX
        """
        if name in self._symbols:
            return self._symbols[name]
        if name in self._ports:
            return self._ports[name]
        raise InputError(f"unknown name {name!r} in model {self.name!r}")

    def has(self, name: str) -> bool:
        """Whether ``name`` is declared (state, input, parameter, noise channel or port).

        Parameters
        ----------
        name : str
            A name.

        Returns
        -------
        bool
            Whether ``name`` is declared.
        """
        return name in self._kinds

    # -- build --------------------------------------------------------------------------------
    def build(self) -> "Model":
        """Freeze into an immutable :class:`~casship.model.Model` (checks that every state has an equation)."""
        missing = [v.name for v in self._states if v.name not in self._ode]
        if missing:
            raise InputError(f"model {self.name!r}: states without an equation: {missing}")
        if not self._states:
            raise InputError(f"model {self.name!r} has no states")
        if self.vessel is not None:
            if not isinstance(self.vessel, Vessel):
                raise InputTypeError(f"model {self.name!r}: vessel must be a casship.Vessel, got {type(self.vessel).__name__}")
            self.vessel.check_inputs([v.name for v in self._inputs])
        return Model(self)

    def declarations(self) -> Declarations:
        """A read-only snapshot of the declarations and equations (what :meth:`build` freezes).

        Returns
        -------
        Declarations
        """
        ro = MappingProxyType
        return Declarations(
            name=self.name, doc=self.doc, dt=self.dt, states=tuple(self._states), inputs=tuple(self._inputs),
            params=tuple(self._params), noises=tuple(self._noises), outputs=tuple(self._outputs),
            symbols=ro(dict(self._symbols)), rates=ro(dict(self._ode)), output_exprs=ro(dict(self._output_expr)),
            ports=ro(dict(self._ports)), port_terms=ro({k: tuple(v) for k, v in self._port_terms.items()}),
            limits=ro(dict(self._limits)), vessel=self.vessel, meta=ro(dict(self.meta)))

    def copy(self, name: str | None = None) -> "ModelBuilder":
        """An independent copy of the builder (declarations and equations).

        Parameters
        ----------
        name : str, optional
            Name of the copy (default: this builder's).

        Returns
        -------
        ModelBuilder
        """
        new = ModelBuilder(name or self.name, self.doc, dt=self.dt)
        new._kinds = dict(self._kinds)
        new._symbols = dict(self._symbols)
        new._states, new._inputs = list(self._states), list(self._inputs)
        new._params, new._noises = list(self._params), list(self._noises)
        new._outputs = list(self._outputs)
        new._ode, new._output_expr = dict(self._ode), dict(self._output_expr)
        new._ports = dict(self._ports)
        new._port_terms = {k: list(v) for k, v in self._port_terms.items()}
        new._limits = dict(self._limits)
        new.vessel = self.vessel
        new.meta = dict(self.meta)
        return new
