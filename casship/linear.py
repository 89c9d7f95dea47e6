"""Linear back end: exact linearisations, python-control systems and trim (equilibrium) solving.

casship does not re-implement ``lqr``, ``bode`` or ``margin``: it hands python-control exact
linearisations (from the CasADi Jacobians of the model) with the state, input and output labels
kept, and wraps a whole nonlinear model as a :class:`control.NonlinearIOSystem`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import casadi as ca
import control
import numpy as np

from .runtime import BufferedCall
from .model import Model
from .errors import InputError

__all__ = ["linearize", "to_iosys", "trim", "TrimResult", "output_map"]


def _vector(model: Model, value, kind: str) -> np.ndarray:
    """A named vector (mapping -> zeros elsewhere, or a full array) of states or inputs."""
    n, names = (model.nx, model.state_names) if kind == "state" else (model.nu, model.input_names)
    if value is None:
        return np.zeros(n)
    if isinstance(value, Mapping):
        return model.states(**value) if kind == "state" else model.inputs(**value)
    vec = np.asarray(value, dtype=float).reshape(-1)
    if vec.shape != (n,):
        raise InputError(f"expected {n} {kind} values for {list(names)}, got {vec.size}")
    if not np.all(np.isfinite(vec)):
        raise InputError(f"{kind} values must be finite, got {vec}")
    return vec


def output_map(model: Model, outputs: Sequence[str] | None = None) -> tuple[tuple[str, ...], ca.Function]:
    """Names and Function ``y(x, u, p)`` of the selected outputs.

    Parameters
    ----------
    model : Model
        The model.
    outputs : sequence of str, optional
        Model outputs or states (a state name not declared as an output is measured directly).
        By default: the model's outputs, or all states if it declares none.

    Returns
    -------
    names : tuple of str
        The selected outputs.
    function : casadi.Function
        ``y_sel(x, u, p) -> (y, C, D)`` with the outputs and their Jacobians.
    """
    if outputs is None:
        outputs = model.output_names or model.state_names
    outputs = tuple(outputs)
    if not outputs:
        raise InputError("at least one output is needed")
    y_all = model.h(model.x, model.u, model.p)
    exprs = []
    for name in outputs:
        if name in model.output_names:
            exprs.append(y_all[model.index(name, "output")])
        elif name in model.state_names:
            exprs.append(model.x[model.index(name)])
        else:
            raise InputError(f"unknown output {name!r} of model {model.name!r}; outputs: "
                             f"{list(model.output_names)}, states: {list(model.state_names)}")
    y = ca.vertcat(*exprs)
    jac = [ca.densify(ca.jacobian(y, model.x)), ca.densify(ca.jacobian(y, model.u))]
    return outputs, ca.Function("y_sel", [model.x, model.u, model.p], [ca.densify(y), *jac],
                                ["x", "u", "p"], ["y", "C", "D"])


def linearize(model: Model, x=None, u=None, p=None, outputs: Sequence[str] | None = None,
              *, name: str | None = None) -> control.StateSpace:
    """Exact linearisation of ``model`` about ``(x, u, p)`` as a labelled :class:`control.StateSpace`.

    ``A = df/dx``, ``B = df/du`` (noise at zero), ``C = dy/dx``, ``D = dy/du`` from CasADi's
    algorithmic differentiation; the system works in deviations from the operating point.

    Parameters
    ----------
    model : Model
        The model (with at least one input: python-control systems need one).
    x, u : array_like or mapping name -> value
        Operating point (unnamed entries are zero).
    p : array_like or mapping, optional
        Parameters (nominal by default).
    outputs : sequence of str, optional
        Output or state names (see :func:`output_map`).
    name : str, optional
        System name (default: the model name).

    Returns
    -------
    control.StateSpace
        With ``states``, ``inputs``, ``outputs`` labelled by the model's names. The operating
        point is kept in the attribute ``operating_point`` (dict with ``x``, ``u``, ``p``, ``y``,
        ``xdot``).

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    >>> sys = cs.linearize(m, outputs=["r"])
    >>> sys.A.tolist(), sys.B.ravel().tolist(), sys.state_labels
    ([[0.0, 1.0], [0.0, -0.05]], [0.0, 0.005], ['psi', 'r'])
    """
    if model.nu == 0:
        raise InputError(f"linearize: model {model.name!r} has no inputs, and a python-control StateSpace needs "
                         "at least one; use model.f_jac for the Jacobian A, or declare an input")
    xv, uv = _vector(model, x, "state"), _vector(model, u, "input")
    pv = model.params(p) if p is not None else model.params()
    jac = model.f_jac(x=xv, u=uv, p=pv, w=np.zeros(model.nw))
    A, B = np.array(jac["A"]), np.array(jac["B"])
    names, ysel = output_map(model, outputs)
    y, C, D = (np.array(v) for v in ysel(xv, uv, pv))
    sys = control.ss(A, B.reshape(model.nx, model.nu), C.reshape(len(names), model.nx),
                     D.reshape(len(names), model.nu), states=list(model.state_names),
                     inputs=list(model.input_names), outputs=list(names), name=name or model.name)
    sys.operating_point = {"x": xv, "u": uv, "p": pv, "y": y.reshape(-1),
                           "xdot": np.array(model.f(xv, uv, pv, np.zeros(model.nw))).reshape(-1)}
    return sys


def to_iosys(model: Model, p=None, outputs: Sequence[str] | None = None, *,
             name: str | None = None) -> control.NonlinearIOSystem:
    """The nonlinear model as a :class:`control.NonlinearIOSystem` (process noise at zero).

    The update and output functions evaluate the model's CasADi Functions through preallocated
    buffers. The system's ``params`` are the model's parameters by name; pass
    ``params={"K": ...}`` to python-control's simulation functions to change some of them.

    Parameters
    ----------
    model : Model
        The model.
    p : array_like or mapping, optional
        Parameters (nominal by default).
    outputs : sequence of str, optional
        Output or state names (see :func:`output_map`).
    name : str, optional
        System name (default: the model name).

    Returns
    -------
    control.NonlinearIOSystem

    Examples
    --------
    >>> import numpy as np, control, casship as cs
    >>> m = cs.models.nomoto_first_order()
    >>> sys = cs.to_iosys(m)
    >>> res = control.input_output_response(sys, np.linspace(0, 10, 11), 0.1)
    >>> res.outputs.shape
    (11,)
    """
    pv = model.params(p) if p is not None else model.params()
    names, ysel = output_map(model, outputs)
    f_call = BufferedCall(model.f)
    y_call = BufferedCall(ysel)
    f_in = dict(zip(model.f.name_in(), f_call.args))        # slots by name
    y_in = dict(zip(ysel.name_in(), y_call.args))
    xdot_out = dict(zip(model.f.name_out(), f_call.res))["xdot"]
    y_out = dict(zip(ysel.name_out(), y_call.res))["y"]
    pnames = model.param_names

    def set_params(slots, params):
        if params:
            slots["p"][:] = model.params(pv, **{k: params[k] for k in pnames if k in params})

    f_in["p"][:] = pv
    y_in["p"][:] = pv

    def updfcn(t, x, u, params):
        set_params(f_in, params)
        f_in["x"][:] = x
        f_in["u"][:] = np.ravel(u) if model.nu else 0.0
        f_call()
        return xdot_out.copy()

    def outfcn(t, x, u, params):
        set_params(y_in, params)
        y_in["x"][:] = x
        y_in["u"][:] = np.ravel(u) if model.nu else 0.0
        y_call()
        return y_out.copy()

    return control.nlsys(updfcn, outfcn, states=list(model.state_names), inputs=list(model.input_names),
                         outputs=list(names), params=model.param_dict(pv), name=name or model.name)


@dataclass(frozen=True)
class TrimResult:
    """An equilibrium (trim) point found by :func:`trim`.

    Parameters
    ----------
    x, u : numpy.ndarray
        State and input vectors at the trim point.
    p : numpy.ndarray
        Parameter vector used.
    xdot : numpy.ndarray
        State derivative there (zero in the ``zero`` entries).
    residual : float
        Max-norm of the zeroed derivatives.
    values : dict
        Mapping name -> solved value of each free variable (tied variables share one value).
    state_names, input_names : tuple of str
        Names of the entries of ``x`` and ``u``.
    model_name : str
        The model the point belongs to.
    """

    x: np.ndarray
    u: np.ndarray
    p: np.ndarray
    xdot: np.ndarray
    residual: float
    values: dict
    state_names: tuple = ()
    input_names: tuple = ()
    model_name: str = ""

    def __repr__(self) -> str:
        solved = ", ".join(f"{k}={v:.6g}" for k, v in self.values.items())
        return f"TrimResult({self.model_name!r}, {solved}, residual={self.residual:.2g})"

    def summary(self) -> str:
        """The solved values, the operating point by name and the residual, one line each.

        Returns
        -------
        str
        """
        lines = [f"trim of {self.model_name!r}: residual {self.residual:.3g}"]
        lines += [f"  solved {k:12s} = {v:.6g}" for k, v in self.values.items()]
        lines += [f"  state  {n:12s} = {v:.6g}" for n, v in zip(self.state_names, self.x)]
        lines += [f"  input  {n:12s} = {v:.6g}" for n, v in zip(self.input_names, self.u)]
        return "\n".join(lines)


def _default_zero(model: Model) -> list[str]:
    """States whose derivative depends on the state itself (dynamic, not pure integrators)."""
    out = []
    for i, n in enumerate(model.state_names):
        if ca.depends_on(model.xdot[i], model.x[i]):
            out.append(n)
    return out


def _free_slots(model: Model, free) -> tuple[list[str], list[list[tuple[str, int]]]]:
    """Labels and ``[(kind, index), ...]`` slots of each free entry (a name, or a tuple of tied names)."""
    labels, slots = [], []
    for entry in free:
        names = (entry,) if isinstance(entry, str) else tuple(entry)
        if not names:
            raise InputError("trim: an empty group in free")
        group = []
        for n in names:
            if n in model.state_names:
                group.append(("x", model.index(n)))
            elif n in model.input_names:
                group.append(("u", model.index(n, "input")))
            else:
                raise InputError(f"trim: unknown free variable {n!r}; states: {list(model.state_names)}, "
                                 f"inputs: {list(model.input_names)}")
        labels.append(names[0] if len(names) == 1 else "=".join(names))
        slots.append(group)
    return labels, slots


def trim(model: Model, x=None, u=None, p=None, *, free: Sequence, zero: Sequence[str] | None = None,
         tol: float = 1e-10, max_iter: int = 100, check_limits: bool = True) -> TrimResult:
    """Solve for an equilibrium: the ``free`` states/inputs such that the ``zero`` derivatives vanish.

    The one equilibrium solver of casship (the propeller rate of a straight run,
    :func:`casship.maneuvers.propeller_rate_for_speed`, is a trim). A Newton root finder (CasADi
    ``rootfinder``) with exact Jacobians solves the square system ``f_zero(x, u, p) = 0`` for the
    free variables; the other entries of ``x`` and ``u`` are held at the values given (which also
    serve as initial guesses for the free ones).

    Parameters
    ----------
    model : Model
        The model.
    x, u : array_like or mapping, optional
        Fixed values and initial guesses (zeros for unnamed entries).
    p : array_like or mapping, optional
        Parameters (nominal by default).
    free : sequence of str or tuple of str
        Names of states and/or inputs to solve for (e.g. ``["n"]`` for the propeller rate that
        holds a given speed). A tuple of names is one unknown shared by all of them (e.g.
        ``[("n1", "n2")]``: both propellers at the same rate).
    zero : sequence of str, optional
        States whose derivatives must vanish, as many as ``free``. By default the states whose
        derivative depends on themselves (velocities; pure integrators such as positions and
        heading are left free to move).
    tol : float
        Convergence tolerance on the residual (max-norm).
    max_iter : int
        Largest number of Newton iterations.
    check_limits : bool
        Check the given operating point and the solution against the model's declared ranges
        (``model.limits``); ``False`` is the explicit opt-in for an out-of-range study.

    Returns
    -------
    TrimResult

    Raises
    ------
    ValueError
        Unknown names, a non-square system, or a root finder that does not converge (the
        message gives the residual and the solver status).
    casship.simulation.validity.ValidityError
        A given value or the solution outside the model's declared ranges.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order(rudder_bias=True)
    >>> tr = cs.trim(m, p={"delta_0": 0.01}, free=["delta"], zero=["r"])
    >>> round(tr.values["delta"], 6)
    -0.01
    """
    from .simulation import check_inputs, check_states

    xv, uv = _vector(model, x, "state"), _vector(model, u, "input")
    pv = model.params(p) if p is not None else model.params()
    free = [free] if isinstance(free, str) else list(free)
    if not free:
        raise InputError("trim: name at least one free state or input")
    zero = _default_zero(model) if zero is None else list(zero)
    z_idx = model.indices(zero, "state")
    if len(free) != len(zero):
        raise InputError(f"trim: {len(free)} free variable(s) {free} but {len(zero)} zeroed derivative(s) "
                         f"{zero}; pass zero=[...] naming as many states as free variables")
    labels, slots = _free_slots(model, free)
    freed = {(kind, i) for group in slots for kind, i in group}
    if check_limits:
        check_states(model, {n: xv[i] for i, n in enumerate(model.state_names) if ("x", i) not in freed})
        check_inputs(model, {n: uv[i] for i, n in enumerate(model.input_names) if ("u", i) not in freed})
    z = ca.SX.sym("z", len(free))
    xs, us = ca.SX(ca.DM(xv)), ca.SX(ca.DM(uv)) if model.nu else ca.SX(0, 1)
    for k, group in enumerate(slots):
        for kind, i in group:
            (xs if kind == "x" else us)[i] = z[k]
    res = model.f(xs, us, pv, np.zeros(model.nw))[z_idx]
    g = ca.Function("trim_residual", [z], [res])
    z0 = np.array([(xv if group[0][0] == "x" else uv)[group[0][1]] for group in slots])
    try:
        solver = ca.rootfinder("trim", "newton", g, {"abstol": tol, "max_iter": max_iter,
                                                     "error_on_fail": False})
        zs = np.array(solver(z0)).reshape(-1)
    except RuntimeError as exc:
        reason = "the zeroed derivatives do not depend on the free variables" \
            if "singular" in str(exc) else str(exc).splitlines()[-1]
        raise InputError(f"trim of {model.name!r} failed for free {labels}, zero {zero}: {reason}") from None
    status = solver.stats().get("return_status", "")
    resid = np.array(g(zs)).reshape(-1)
    rnorm = float(np.max(np.abs(resid))) if resid.size else 0.0
    if not np.all(np.isfinite(zs)) or not np.isfinite(rnorm) or rnorm > max(tol * 100, 1e-8) \
            or not solver.stats().get("success", True):
        raise InputError(f"trim of {model.name!r} did not converge (status {status!r}, residual {rnorm:.3g}) "
                         f"for free {labels} from {dict(zip(labels, z0))}; try another initial guess")
    for k, group in enumerate(slots):
        for kind, i in group:
            (xv if kind == "x" else uv)[i] = zs[k]
    if check_limits:
        try:
            check_states(model, {n: xv[i] for i, n in enumerate(model.state_names) if ("x", i) in freed},
                         "trim solution: state")
            check_inputs(model, {n: uv[i] for i, n in enumerate(model.input_names) if ("u", i) in freed})
        except ValueError as exc:
            raise type(exc)(f"trim of {model.name!r} for zero {zero}: {exc}") from None
    xdot = np.array(model.f(xv, uv, pv, np.zeros(model.nw))).reshape(-1)
    return TrimResult(x=xv, u=uv, p=pv, xdot=xdot, residual=rnorm, values=dict(zip(labels, map(float, zs))),
                      state_names=model.state_names, input_names=model.input_names, model_name=model.name)
