"""Symbolic model core: the immutable :class:`Model` built from named declarations.

A :class:`~casship.builder.ModelBuilder` collects CasADi ``SX`` symbols and expressions;
:meth:`~casship.builder.ModelBuilder.build` freezes them into an immutable :class:`Model` holding named CasADi Functions

* ``f(x, u, p, w) -> xdot``     continuous-time dynamics,
* ``h(x, u, p) -> y``            outputs (measurement model),
* ``f_jac(x, u, p, w) -> (A, B, Fp, G)`` and ``h_jac(x, u, p) -> (C, D, Hp)`` exact Jacobians.

Models compose through *ports*: named additive placeholders (for example a generalised force
``tau`` of a 3-DOF ship) that a later term can feed without rewriting the model, see
:meth:`Model.extend`.
"""
from __future__ import annotations

import pickle
import re
from types import MappingProxyType
from typing import TYPE_CHECKING, Callable, Iterable, Mapping, Sequence

import casadi as ca
import numpy as np

from .errors import InputError, InputTypeError

if TYPE_CHECKING:       # the builder makes models (casship.builder imports this module)
    from .builder import ModelBuilder

__all__ = ["Model"]


def _c_name(name: str) -> str:
    """``name`` as an identifier usable in CasADi Function names (``kvlcc2-l7+wind`` -> ``kvlcc2_l7_wind``)."""
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"model name must be a non-empty string, got {name!r}")
    ident = re.sub(r"\W", "_", name.strip())
    return ident if ident[0].isalpha() else f"m_{ident}"


def _check_finite_constants(model: str, kind: str, names: Sequence[str], exprs: ca.SX, args) -> None:
    """Reject expressions holding a NaN or infinite constant (e.g. ``math.cos`` applied to a CasADi
    symbol returns NaN), naming the state or output whose expression holds it."""
    for i, name in enumerate(names):
        fun = ca.Function("check", args, [exprs[i]])
        for k in range(fun.n_instructions()):
            if fun.instruction_id(k) == ca.OP_CONST and not np.isfinite(fun.instruction_constant(k)):
                raise InputError(f"model {model!r}: the {kind} {name!r} contains the constant "
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
        # The model keeps its own copy of the builder: composition (builder, extend, with_outputs)
        # starts from it, and it reads the declarations only through their public snapshot.
        self._builder = builder.copy()
        d = self._builder.declarations()
        self.name = d.name
        self.c_name = _c_name(d.name)
        self.dt = d.dt
        self.doc = d.doc
        self.vessel = d.vessel
        self.limits = MappingProxyType({v.name: d.limits[v.name] for v in (*d.states, *d.inputs)
                                        if v.name in d.limits})
        self.meta = MappingProxyType(dict(d.meta))
        self.state_vars, self.input_vars, self.param_vars = d.states, d.inputs, d.params
        self.noise_vars, self.output_vars = d.noises, d.outputs
        self.state_names = tuple(v.name for v in d.states)
        self.input_names = tuple(v.name for v in d.inputs)
        self.param_names = tuple(v.name for v in d.params)
        self.noise_names = tuple(v.name for v in d.noises)
        self.output_names = tuple(v.name for v in d.outputs)
        self.nx, self.nu, self.np = len(self.state_names), len(self.input_names), len(self.param_names)
        self.nw, self.ny = len(self.noise_names), len(self.output_names)
        self.angle_states = np.array([v.angle for v in d.states], dtype=bool)
        self.angle_outputs = np.array([v.angle for v in d.outputs], dtype=bool)

        x = _vec(d.symbols[n] for n in self.state_names)
        u = _vec(d.symbols[n] for n in self.input_names)
        p = _vec(d.symbols[n] for n in self.param_names)
        w = _vec(d.symbols[n] for n in self.noise_names)
        port_syms = list(d.ports.values())
        port_vals = [sum(d.port_terms[k], ca.SX.zeros(sym.shape)) for k, sym in d.ports.items()]
        xdot = _vec(d.rates[n] for n in self.state_names)
        y = _vec(d.output_exprs[n] for n in self.output_names)
        if port_syms:
            # Terms may themselves refer to ports of their own kind only through states, so one
            # substitution pass resolves them.
            xdot, y = ca.substitute([xdot, y], port_syms, port_vals)
        free = set(ca.symvar(ca.vertcat(xdot, y))) - set(ca.symvar(ca.vertcat(x, u, p, w)))
        if free:
            raise InputError(f"model {self.name!r}: expressions use undeclared symbols "
                             f"{sorted(str(s) for s in free)}")
        if ca.depends_on(y, w):
            raise InputError(f"model {self.name!r}: outputs must not depend on process noise")
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
        self._derived: dict = {}   # numeric objects derived from the model (see derived); not its meaning
        self._freeze()

    # -- immutability ---------------------------------------------------------------------------
    def __setattr__(self, key, value):
        if getattr(self, "_frozen", False):
            raise AttributeError(f"Model {self.name!r} is immutable; build a new one instead")
        super().__setattr__(key, value)

    def _freeze(self):
        object.__setattr__(self, "_frozen", True)

    def __reduce__(self):
        """Pickle through the builder (for process pools), rebuilt on loading."""
        with ca.global_pickle_context():
            data = pickle.dumps(self._builder)
        return _model_from_pickle, (data,)

    def derived(self, key, make: Callable[[], object]):
        """A numeric object derived from this model (a discretisation, a mapped Function), built by
        ``make()`` once per ``key`` and kept as long as the model.

        Parameters
        ----------
        key : hashable
            What the object is (e.g. ``("discretize", "rk4", 1)``); callers choose keys that say it all.
        make : callable
            Builds the object when ``key`` is new.

        Returns
        -------
        object
            The object built for ``key``.
        """
        if key not in self._derived:
            self._derived[key] = make()
        return self._derived[key]

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
                raise InputError(f"unknown {kind} name {key!r}; known: {list(names)}")
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
                raise InputError(f"params: expected a vector of {self.np} parameters, got shape {vec.shape}")
        vec = self._named(self.param_names, overrides, "parameter", vec)
        if base is not None or overrides:
            self._check_params(vec)
        return vec

    def _check_params(self, vec: np.ndarray) -> None:
        """Every parameter finite and within its declared (physical) bounds, or ``InputError`` naming it."""

        bad = np.flatnonzero(~np.isfinite(vec) | (vec < self.param_lower) | (vec > self.param_upper))
        if bad.size:
            i = int(bad[0])
            var = self.param_vars[i]
            unit = f" {var.unit}" if var.unit and var.unit != "-" else ""
            what = "is not finite" if not np.isfinite(vec[i]) else \
                f"is outside its valid range [{self.param_lower[i]:g}, {self.param_upper[i]:g}]{unit}"
            raise InputError(f"parameter {var.name!r} = {vec[i]:g}{unit} of model {self.name!r} {what}"
                             + (f" ({var.doc})" if var.doc else ""))

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
            raise InputError(f"unknown kind {kind!r}; use one of {list(table)}")
        try:
            return table[kind].index(name)
        except ValueError:
            raise InputError(f"unknown {kind} name {name!r} in model {self.name!r}; "
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
        b.drop_outputs()
        items = outputs.items() if isinstance(outputs, Mapping) else ((n, n) for n in outputs)
        for out_name, spec in items:
            if isinstance(spec, str):
                if spec not in self.state_names:
                    raise InputError(f"with_outputs: {spec!r} is not a state of {self.name!r}")
                b.output(out_name, b.sym(spec))
            elif callable(spec):
                b.output(out_name, spec(b))
            else:
                raise InputTypeError(f"with_outputs: output {out_name!r} must be given by a state name or a "
                                     f"callable builder -> expression, got {type(spec).__name__}")
        return b.build()


def _model_from_pickle(data: bytes) -> Model:
    with ca.global_unpickle_context():
        builder = pickle.loads(data)
    return Model(builder)
