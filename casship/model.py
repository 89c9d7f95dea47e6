"""Symbolic model core: declare named states, inputs, parameters, noise and outputs once.

A :class:`ModelBuilder` collects CasADi ``SX`` symbols and expressions; :meth:`ModelBuilder.build`
freezes them into an immutable :class:`Model` holding named CasADi Functions

* ``f(x, u, p, w) -> xdot``     continuous-time dynamics,
* ``h(x, u, p) -> y``            outputs (measurement model),
* ``f_jac(x, u, p, w) -> (A, B, Fp, G)`` and ``h_jac(x, u, p) -> (C, D, Hp)`` exact Jacobians.

Models compose through *ports*: named additive placeholders (for example a generalised force
``tau`` of a 3-DOF ship) that a later term can feed without rewriting the model, see
:meth:`Model.extend`.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from types import MappingProxyType
from typing import Callable, Iterable, Mapping, Sequence

import casadi as ca
import numpy as np

from .vessel import Limit, Vessel

__all__ = ["ModelBuilder", "Model", "Variable", "Parameter"]


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


RESERVED = ("t", "time")   # the time column of every Dataset


def _check_name(name: str, taken: Mapping[str, str]) -> None:
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"name {name!r} is not a valid identifier")
    if name in RESERVED:
        raise ValueError(f"name {name!r} is reserved for time stamps; choose another name")
    if name in taken:
        raise ValueError(f"name {name!r} is already declared as a {taken[name]}")


def _as_sx(expr, what: str) -> ca.SX:
    try:
        value = ca.SX(expr)
    except Exception as exc:  # pragma: no cover - message path
        raise TypeError(f"{what}: cannot convert {type(expr).__name__} to a CasADi expression") from exc
    if value.shape != (1, 1):
        raise ValueError(f"{what}: expected a scalar expression, got shape {value.shape}")
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
            raise ValueError(f"model {name!r}: dt must be a positive sampling period, got {dt!r}")
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
            Lower and upper bound (used by identification).
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
            raise ValueError(f"parameter {name!r}: nominal value must be finite, got {value}")
        lower, upper = (-np.inf, np.inf) if bounds is None else (float(bounds[0]), float(bounds[1]))
        if not lower <= value <= upper:
            raise ValueError(f"parameter {name!r}: nominal value {value} outside bounds {(lower, upper)}")
        par = Parameter(name, unit, False, doc, value, lower, upper, source)
        return self._declare("param", par, self._params)

    def param_as_state(self, name: str, *, doc: str = "") -> ca.SX:
        """Turn the declared parameter ``name`` into a state (same symbol and unit; for augmented-state
        estimation). Give it an equation with :meth:`ode`, e.g. a random walk ``b.noise(...)``.

        Parameters
        ----------
        name : str
            A declared parameter.
        doc : str
            One-line description.

        Returns
        -------
        casadi.SX
            The symbol, to write equations with.
        """
        if self._kinds.get(name) != "param":
            raise ValueError(f"param_as_state: {name!r} is not a declared parameter of {self.name!r}")
        var = next(v for v in self._params if v.name == name)
        self._params = [v for v in self._params if v.name != name]
        self._kinds[name] = "state"
        self._states.append(Variable(name, var.unit, False, doc or var.doc))
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
            raise ValueError(f"unknown port {port!r}; ports: {sorted(self._ports)}")
        expr = ca.SX(expr)
        if expr.shape != self._ports[port].shape:
            raise ValueError(f"port {port!r} has shape {self._ports[port].shape}, got {expr.shape}")
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
            raise ValueError(f"limit: {name!r} is not a declared state or input of {self.name!r}")
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
            raise ValueError(f"model {self.name!r} is discrete-time (dt = {self.dt:g} s): give x[k+1] with next(...)")
        for name, expr in rhs.items():
            if self._kinds.get(name) != "state":
                raise ValueError(f"ode: {name!r} is not a declared state")
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
            raise ValueError(f"model {self.name!r} is continuous-time: give derivatives with ode(...), or "
                             "build a discrete-time model with ModelBuilder(name, dt=...)")
        for name, expr in rhs.items():
            if self._kinds.get(name) != "state":
                raise ValueError(f"next: {name!r} is not a declared state")
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
                raise ValueError(f"add_to_ode: state {name!r} has no equation yet")
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
            raise ValueError(f"output name {name!r} is not a valid identifier")
        if name in RESERVED:
            raise ValueError(f"output name {name!r} is reserved for time stamps; choose another name")
        if name in self._output_expr:
            raise ValueError(f"output {name!r} is already declared")
        if name in self._kinds and not (self._kinds[name] == "state" and ca.is_equal(expr, self._symbols[name])):
            raise ValueError(f"output {name!r} clashes with the {self._kinds[name]} of that name; an output may "
                             "share a name only with the state it measures")
        self._outputs.append(Variable(name, unit, bool(angle), doc))
        self._output_expr[name] = expr

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
        raise ValueError(f"unknown name {name!r} in model {self.name!r}")

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
        """Freeze into an immutable :class:`Model` (checks that every state has an equation)."""
        missing = [v.name for v in self._states if v.name not in self._ode]
        if missing:
            raise ValueError(f"model {self.name!r}: states without an equation: {missing}")
        if not self._states:
            raise ValueError(f"model {self.name!r} has no states")
        if self.vessel is not None:
            if not isinstance(self.vessel, Vessel):
                raise TypeError(f"model {self.name!r}: vessel must be a casship.Vessel, got {type(self.vessel).__name__}")
            self.vessel.check_inputs([v.name for v in self._inputs])
        return Model(self)

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


def _c_name(name: str) -> str:
    """``name`` as an identifier usable in CasADi Function names (``kvlcc2-l7+wind`` -> ``kvlcc2_l7_wind``)."""
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"model name must be a non-empty string, got {name!r}")
    ident = re.sub(r"\W", "_", name.strip())
    return ident if ident[0].isalpha() else f"m_{ident}"


def _check_finite_constants(model: str, kind: str, names: Sequence[str], exprs: ca.SX, args) -> None:
    """Reject expressions holding a NaN or infinite constant (e.g. ``math.cos`` applied to a CasADi
    symbol returns NaN), naming the state or output whose expression holds it."""
    for i, name in enumerate(names):
        fun = ca.Function("check", args, [exprs[i]])
        for k in range(fun.n_instructions()):
            if fun.instruction_id(k) == ca.OP_CONST and not np.isfinite(fun.instruction_constant(k)):
                raise ValueError(f"model {model!r}: the {kind} {name!r} contains the constant "
                                 f"{fun.instruction_constant(k)} (a math/numpy function applied to a CasADi symbol? "
                                 "use casadi's functions, e.g. ca.cos)")


def _vec(symbols: Iterable[ca.SX]) -> ca.SX:
    symbols = list(symbols)
    return ca.vertcat(*symbols) if symbols else ca.SX(0, 1)


class Model:
    """An immutable model built by :class:`ModelBuilder` (continuous-time, or discrete-time with ``dt``).

    Parameters
    ----------
    builder : ModelBuilder
        The declarations and equations (copied); use :meth:`ModelBuilder.build` rather than this
        constructor.

    Attributes
    ----------
    name : str
        Model name (for registered models, the registry key: ``get_model(model.name)`` rebuilds it).
    c_name : str
        ``name`` as an identifier, used in the names of generated CasADi Functions.
    vessel : Vessel or None
        The ship the model describes (particulars, rudder and propeller inputs, parameter set).
    limits : mapping name -> Limit
        Declared validity ranges of states and inputs.
    f, h : casadi.Function
        ``f(x,u,p,w)->xdot`` and ``h(x,u,p)->y`` with named inputs and outputs.
    f_jac, h_jac : casadi.Function
        Exact Jacobians ``(A, B, Fp, G)`` of ``f`` and ``(C, D, Hp)`` of ``h``.
    state_names, input_names, param_names, noise_names, output_names : tuple of str
    dt : float or None
        Sampling period of a discrete-time model (``None``: continuous-time); its ``f`` is the
        rate over a step ``(x[k+1] - x[k]) / dt`` and :func:`~casship.discretize` gives its exact step.
    """

    def __init__(self, builder: ModelBuilder):
        self._builder = builder.copy()
        b = self._builder
        self.name = b.name
        self.c_name = _c_name(b.name)
        self.dt = getattr(b, "dt", None)
        self.doc = b.doc
        self.vessel = b.vessel
        self.limits = MappingProxyType({n: b._limits[n] for n in (*(v.name for v in b._states),
                                                                    *(v.name for v in b._inputs)) if n in b._limits})
        self.meta = MappingProxyType(dict(b.meta))
        self.state_vars = tuple(b._states)
        self.input_vars = tuple(b._inputs)
        self.param_vars = tuple(b._params)
        self.noise_vars = tuple(b._noises)
        self.output_vars = tuple(b._outputs)
        self.state_names = tuple(v.name for v in b._states)
        self.input_names = tuple(v.name for v in b._inputs)
        self.param_names = tuple(v.name for v in b._params)
        self.noise_names = tuple(v.name for v in b._noises)
        self.output_names = tuple(v.name for v in b._outputs)
        self.nx, self.nu, self.np = len(self.state_names), len(self.input_names), len(self.param_names)
        self.nw, self.ny = len(self.noise_names), len(self.output_names)
        self.angle_states = np.array([v.angle for v in b._states], dtype=bool)
        self.angle_outputs = np.array([v.angle for v in b._outputs], dtype=bool)

        x = _vec(b._symbols[n] for n in self.state_names)
        u = _vec(b._symbols[n] for n in self.input_names)
        p = _vec(b._symbols[n] for n in self.param_names)
        w = _vec(b._symbols[n] for n in self.noise_names)
        port_syms = [b._ports[k] for k in b._ports]
        port_vals = [sum(b._port_terms[k], ca.SX.zeros(b._ports[k].shape)) for k in b._ports]
        xdot = _vec(b._ode[n] for n in self.state_names)
        y = _vec(b._output_expr[n] for n in self.output_names)
        if port_syms:
            # Terms may themselves refer to ports of their own kind only through states, so one
            # substitution pass resolves them.
            xdot, y = ca.substitute([xdot, y], port_syms, port_vals)
        free = set(ca.symvar(ca.vertcat(xdot, y))) - set(ca.symvar(ca.vertcat(x, u, p, w)))
        if free:
            raise ValueError(f"model {self.name!r}: expressions use undeclared symbols "
                             f"{sorted(str(s) for s in free)}")
        if ca.depends_on(y, w):
            raise ValueError(f"model {self.name!r}: outputs must not depend on process noise")
        _check_finite_constants(self.name, "equation of state", self.state_names, xdot, [x, u, p, w])
        _check_finite_constants(self.name, "output", self.output_names, y, [x, u, p])
        self.x, self.u, self.p, self.w = x, u, p, w
        self.xdot, self.y = xdot, y
        self.f = ca.Function("f", [x, u, p, w], [xdot], ["x", "u", "p", "w"], ["xdot"])
        self.h = ca.Function("h", [x, u, p], [y], ["x", "u", "p"], ["y"])
        self.f_jac = ca.Function(
            "f_jac", [x, u, p, w],
            [ca.jacobian(xdot, x), ca.jacobian(xdot, u), ca.jacobian(xdot, p), ca.jacobian(xdot, w)],
            ["x", "u", "p", "w"], ["A", "B", "Fp", "G"])
        self.h_jac = ca.Function(
            "h_jac", [x, u, p], [ca.jacobian(y, x), ca.jacobian(y, u), ca.jacobian(y, p)],
            ["x", "u", "p"], ["C", "D", "Hp"])
        self._nominal = np.array([v.value for v in self.param_vars], dtype=float)
        self.param_lower = np.array([v.lower for v in self.param_vars], dtype=float)
        self.param_upper = np.array([v.upper for v in self.param_vars], dtype=float)
        for arr in (self.angle_states, self.angle_outputs, self._nominal, self.param_lower, self.param_upper):
            arr.setflags(write=False)
        self._cache: dict = {}   # derived numeric Functions (folds, maps); never the model's meaning
        self._freeze()

    # -- immutability ---------------------------------------------------------------------------
    def __setattr__(self, key, value):
        if getattr(self, "_frozen", False):
            raise AttributeError(f"Model {self.name!r} is immutable; build a new one instead")
        super().__setattr__(key, value)

    def _freeze(self):
        object.__setattr__(self, "_frozen", True)

    def __reduce__(self):
        """Pickle through the builder's declarations (for process pools), rebuilt on loading."""
        import pickle

        with ca.global_pickle_context():
            data = pickle.dumps(vars(self._builder))
        return _model_from_pickle, (data,)

    def _cached(self, key, make: Callable[[], object]):
        """A derived object (e.g. a discretisation or a mapped Function) built once per key."""
        if key not in self._cache:
            self._cache[key] = make()
        return self._cache[key]

    def __repr__(self) -> str:
        return (f"Model({self.name!r}, x={list(self.state_names)}, u={list(self.input_names)}, "
                f"p[{self.np}], w={list(self.noise_names)}, y={list(self.output_names)})")

    # -- named vectors --------------------------------------------------------------------------
    @staticmethod
    def _named(names: Sequence[str], values: Mapping[str, float], kind: str, base) -> np.ndarray:
        out = np.array(base, dtype=float).copy()
        index = {n: i for i, n in enumerate(names)}
        for key, val in values.items():
            if key not in index:
                raise ValueError(f"unknown {kind} name {key!r}; known: {list(names)}")
            out[index[key]] = float(val)
        return out

    def states(self, **values: float) -> np.ndarray:
        """State vector with the given named entries, zeros elsewhere.

        Parameters
        ----------
        **values
            State name -> value.

        Returns
        -------
        numpy.ndarray
            The state vector (nx,).
        """
        return self._named(self.state_names, values, "state", np.zeros(self.nx))

    def inputs(self, **values: float) -> np.ndarray:
        """Input vector with the given named entries, zeros elsewhere.

        Parameters
        ----------
        **values
            Input name -> value.

        Returns
        -------
        numpy.ndarray
            The input vector (nu,).
        """
        return self._named(self.input_names, values, "input", np.zeros(self.nu))

    def params(self, base: np.ndarray | Mapping[str, float] | None = None, **overrides: float) -> np.ndarray:
        """Nominal parameter vector, or ``base``, with named ``overrides``.

        ``base`` may be a full vector or a mapping name -> value (e.g. a fit's estimates).

        Parameters
        ----------
        base : array_like or mapping, optional
            Full vector or name -> value (nominal by default).
        **overrides
            Parameter name -> value.

        Returns
        -------
        numpy.ndarray
            The parameter vector (np,).
        """
        if base is None:
            vec = self._nominal
        elif isinstance(base, Mapping):
            vec = self._named(self.param_names, base, "parameter", self._nominal)
        else:
            vec = np.asarray(base, dtype=float)
            if vec.shape != (self.np,):
                raise ValueError(f"params: expected a vector of {self.np} parameters, got shape {vec.shape}")
        return self._named(self.param_names, overrides, "parameter", vec)

    def param_dict(self, p: np.ndarray | None = None) -> dict[str, float]:
        """Mapping name -> value of a parameter vector (nominal by default).

        Parameters
        ----------
        p : array_like, optional
            Parameter vector (nominal by default).

        Returns
        -------
        dict
        """
        vec = self._nominal if p is None else np.asarray(p, dtype=float)
        return {n: float(v) for n, v in zip(self.param_names, vec)}

    def index(self, name: str, kind: str = "state") -> int:
        """Position of a named state, input, param, noise or output in its vector.

        Parameters
        ----------
        name : str
            The name.
        kind : {"state", "input", "param", "noise", "output"}
            Which vector.

        Returns
        -------
        int
        """
        table = {"state": self.state_names, "input": self.input_names, "param": self.param_names,
                 "noise": self.noise_names, "output": self.output_names}
        if kind not in table:
            raise ValueError(f"unknown kind {kind!r}; use one of {list(table)}")
        try:
            return table[kind].index(name)
        except ValueError:
            raise ValueError(f"unknown {kind} name {name!r} in model {self.name!r}; "
                             f"known: {list(table[kind])}") from None

    def indices(self, names: Iterable[str], kind: str = "state") -> list[int]:
        """Positions of named entries in their vector (see :meth:`index`).

        Parameters
        ----------
        names : iterable of str
            The names.
        kind : str
            Which vector (see :meth:`index`).

        Returns
        -------
        list of int
        """
        return [self.index(n, kind) for n in names]

    # -- composition ------------------------------------------------------------------------------
    def builder(self, name: str | None = None) -> ModelBuilder:
        """A builder pre-loaded with this model's declarations and equations, to extend it.

        Parameters
        ----------
        name : str, optional
            Name of the new model (default: this model's).

        Returns
        -------
        ModelBuilder
        """
        return self._builder.copy(name)

    def extend(self, term: Callable[[ModelBuilder], None], name: str | None = None) -> "Model":
        """A new model with ``term(builder)`` applied (the term declares inputs/params and feeds ports).

        Examples
        --------
        >>> def push(b):
        ...     b.feed("tau", ca.vertcat(b.param("X_ext", 1.0), 0, 0))   # doctest: +SKIP
        >>> windy = ship.extend(push, name="ship+push")                     # doctest: +SKIP

        Parameters
        ----------
        term : callable
            ``term(builder)`` declares inputs/parameters and feeds ports.
        name : str, optional
            Name of the new model.

        Returns
        -------
        Model
        """
        b = self.builder(name or self.name)
        term(b)
        return b.build()

    def with_outputs(self, outputs: Mapping[str, object] | Sequence[str], name: str | None = None) -> "Model":
        """A copy whose outputs are replaced.

        ``outputs`` is a list of state names (each measured directly, output named like the state)
        or a mapping output name -> state name or callable ``builder -> expression``.

        Parameters
        ----------
        outputs : sequence of str or mapping
            See above.
        name : str, optional
            Name of the new model.

        Returns
        -------
        Model
        """
        b = self.builder(name or self.name)
        b._outputs, b._output_expr = [], {}
        items = outputs.items() if isinstance(outputs, Mapping) else ((n, n) for n in outputs)
        for out_name, spec in items:
            if isinstance(spec, str):
                if spec not in self.state_names:
                    raise ValueError(f"with_outputs: {spec!r} is not a state of {self.name!r}")
                b.output(out_name, b.sym(spec))
            elif callable(spec):
                b.output(out_name, spec(b))
            else:
                raise TypeError(f"with_outputs: output {out_name!r} must be given by a state name or a "
                                f"callable builder -> expression, got {type(spec).__name__}")
        return b.build()


def _model_from_pickle(data: bytes) -> Model:
    import pickle

    with ca.global_unpickle_context():
        state = pickle.loads(data)
    builder = ModelBuilder.__new__(ModelBuilder)
    builder.__dict__.update(state)
    return Model(builder)
