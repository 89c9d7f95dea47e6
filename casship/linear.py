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

from ._fast import BufferedCall
from .model import Model

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
        raise ValueError(f"expected {n} {kind} values for {list(names)}, got {vec.size}")
    if not np.all(np.isfinite(vec)):
        raise ValueError(f"{kind} values must be finite, got {vec}")
    return vec


def output_map(model: Model, outputs: Sequence[str] | None = None) -> tuple[tuple[str, ...], ca.Function]:
    """Names and Function ``y(x, u, p)`` of the selected outputs.

    ``outputs`` may name model outputs or states (a state name not declared as an output is
    measured directly). By default: the model's outputs, or all states if it declares none.
    """
    if outputs is None:
        outputs = model.output_names or model.state_names
    outputs = tuple(outputs)
    if not outputs:
        raise ValueError("at least one output is needed")
    y_all = model.h(model.x, model.u, model.p)
    exprs = []
    for name in outputs:
        if name in model.output_names:
            exprs.append(y_all[model.index(name, "output")])
        elif name in model.state_names:
            exprs.append(model.x[model.index(name)])
        else:
            raise ValueError(f"unknown output {name!r} of model {model.name!r}; outputs: "
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
    xv, uv = _vector(model, x, "state"), _vector(model, u, "input")
    pv = model.params(p) if p is not None else model.params()
    A, B, _, _ = (np.array(v) for v in model.f_jac(xv, uv, pv, np.zeros(model.nw)))
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
    pnames = model.param_names

    def set_params(call, params):
        if params:
            call.args[2][:] = model.params(pv, **{k: params[k] for k in pnames if k in params})

    f_call.args[2][:] = pv
    y_call.args[2][:] = pv

    def updfcn(t, x, u, params):
        set_params(f_call, params)
        f_call.args[0][:] = x
        f_call.args[1][:] = np.ravel(u) if model.nu else 0.0
        return f_call()[0].copy()

    def outfcn(t, x, u, params):
        set_params(y_call, params)
        y_call.args[0][:] = x
        y_call.args[1][:] = np.ravel(u) if model.nu else 0.0
        return y_call()[0].copy()

    return control.nlsys(updfcn, outfcn, states=list(model.state_names), inputs=list(model.input_names),
                         outputs=list(names), params=model.param_dict(pv), name=name or model.name)


@dataclass(frozen=True)
class TrimResult:
    """An equilibrium (trim) point.

    Attributes
    ----------
    x, u : state and input vectors at the trim point
    p : parameter vector used
    xdot : state derivative there (zero in the ``zero`` entries)
    residual : max-norm of the zeroed derivatives
    values : mapping name -> solved value of each free variable
    """

    x: np.ndarray
    u: np.ndarray
    p: np.ndarray
    xdot: np.ndarray
    residual: float
    values: dict


def _default_zero(model: Model) -> list[str]:
    """States whose derivative depends on the state itself (dynamic, not pure integrators)."""
    out = []
    for i, n in enumerate(model.state_names):
        if ca.depends_on(model.xdot[i], model.x[i]):
            out.append(n)
    return out


def trim(model: Model, x=None, u=None, p=None, *, free: Sequence[str], zero: Sequence[str] | None = None,
         tol: float = 1e-10, max_iter: int = 100) -> TrimResult:
    """Solve for an equilibrium: the ``free`` states/inputs such that the ``zero`` derivatives vanish.

    A Newton root finder (CasADi ``rootfinder``) with exact Jacobians solves the square system
    ``f_zero(x, u, p) = 0`` for the free variables; the other entries of ``x`` and ``u`` are held
    at the values given (which also serve as initial guesses for the free ones).

    Parameters
    ----------
    model : Model
    x, u : array_like or mapping, optional
        Fixed values and initial guesses (zeros for unnamed entries).
    p : array_like or mapping, optional
        Parameters (nominal by default).
    free : sequence of str
        Names of states and/or inputs to solve for (e.g. ``["n"]`` for the propeller rate that
        holds a given speed).
    zero : sequence of str, optional
        States whose derivatives must vanish, as many as ``free``. By default the states whose
        derivative depends on themselves (velocities; pure integrators such as positions and
        heading are left free to move).
    tol : float
        Convergence tolerance on the residual (max-norm).

    Returns
    -------
    TrimResult

    Raises
    ------
    ValueError
        Unknown names, a non-square system, or a root finder that does not converge (the
        message gives the residual and the solver status).

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.nomoto_first_order(rudder_bias=True)
    >>> tr = cs.trim(m, p={"delta_0": 0.01}, free=["delta"], zero=["r"])
    >>> round(tr.values["delta"], 6)
    -0.01
    """
    xv, uv = _vector(model, x, "state"), _vector(model, u, "input")
    pv = model.params(p) if p is not None else model.params()
    free = list(free)
    if not free:
        raise ValueError("trim: name at least one free state or input")
    zero = _default_zero(model) if zero is None else list(zero)
    z_idx = model.indices(zero, "state")
    if len(free) != len(zero):
        raise ValueError(f"trim: {len(free)} free variable(s) {free} but {len(zero)} zeroed derivative(s) "
                         f"{zero}; pass zero=[...] naming as many states as free variables")
    sel = []
    for n in free:
        if n in model.state_names:
            sel.append(("x", model.index(n)))
        elif n in model.input_names:
            sel.append(("u", model.index(n, "input")))
        else:
            raise ValueError(f"trim: unknown free variable {n!r}; states: {list(model.state_names)}, "
                             f"inputs: {list(model.input_names)}")
    z = ca.SX.sym("z", len(free))
    xs, us = ca.SX(ca.DM(xv)), ca.SX(ca.DM(uv)) if model.nu else ca.SX(0, 1)
    for k, (kind, i) in enumerate(sel):
        if kind == "x":
            xs[i] = z[k]
        else:
            us[i] = z[k]
    res = model.f(xs, us, pv, np.zeros(model.nw))[z_idx]
    g = ca.Function("trim_residual", [z], [res])
    z0 = np.array([xv[i] if kind == "x" else uv[i] for kind, i in sel])
    try:
        solver = ca.rootfinder("trim", "newton", g, {"abstol": tol, "max_iter": max_iter,
                                                     "error_on_fail": False})
        zs = np.array(solver(z0)).reshape(-1)
    except RuntimeError as exc:
        reason = "the zeroed derivatives do not depend on the free variables" \
            if "singular" in str(exc) else str(exc).splitlines()[-1]
        raise ValueError(f"trim of {model.name!r} failed for free {free}, zero {zero}: {reason}") from None
    status = solver.stats().get("return_status", "")
    resid = np.array(g(zs)).reshape(-1)
    rnorm = float(np.max(np.abs(resid))) if resid.size else 0.0
    if not np.all(np.isfinite(zs)) or not np.isfinite(rnorm) or rnorm > max(tol * 100, 1e-8) \
            or not solver.stats().get("success", True):
        raise ValueError(f"trim of {model.name!r} did not converge (status {status!r}, residual {rnorm:.3g}) "
                         f"for free {free} from {dict(zip(free, z0))}; try another initial guess")
    for k, (kind, i) in enumerate(sel):
        (xv if kind == "x" else uv)[i] = zs[k]
    xdot = np.array(model.f(xv, uv, pv, np.zeros(model.nw))).reshape(-1)
    return TrimResult(x=xv, u=uv, p=pv, xdot=xdot, residual=rnorm, values=dict(zip(free, map(float, zs))))
