"""Validity checks: inputs and states against a model's declared ranges, fixed steps against its time constants.

A model declares the ranges its states and inputs are valid for (:meth:`casship.ModelBuilder.limit`,
``model.limits``). The simulator, the manoeuvre runners, :func:`casship.trim` and the command line
check what they are given against them with the functions here and raise a :class:`ValidityError`
(a ``ValueError``) naming the variable, the value and the range. A deliberate out-of-range study
opts in with ``check_limits=False`` (command line: ``--allow-out-of-range``). A value beyond a
bound by less than :data:`MARGIN` (1 %) of the bound's size passes: a measured rudder angle of
35.1 deg at a 35 deg stop is the stop.

A fixed-step integrator (``euler``, ``rk4``) turns a decaying mode into a growing one when its
step exceeds the stability limit of that mode; :func:`stable_step` computes the largest stable
step from the eigenvalues of the exact linearisation at the starting point and :func:`check_step`
raises for a longer step (a time gap in a record, a ``dt`` of 1000 s) instead of returning 1e29.

Examples
--------
>>> import numpy as np, casship as cs
>>> from casship.simulation import check_inputs, stable_step
>>> ship = cs.models.get_model("kvlcc2")
>>> check_inputs(ship, {"delta": np.radians(200.0)})
Traceback (most recent call last):
...
casship.simulation.validity.ValidityError: input 'delta' = 200 deg is outside its valid range [-35, 35] deg (rudder stop) of model 'kvlcc2'; pass check_limits=False (command line: --allow-out-of-range) for a deliberate out-of-range study
>>> m = cs.models.nomoto_first_order(K=0.1, T=20.0)
>>> round(stable_step(m, m.states(), m.inputs(), m.params(), "rk4"), 1)   # 2.785 T
55.7
"""
from __future__ import annotations

import warnings
from typing import Mapping

import casadi as ca
import numpy as np

from ..errors import InputError
from ..model import Model

__all__ = ["ValidityError", "ValidityWarning", "OPT_IN", "MARGIN", "check_inputs", "is_stable_step", "decaying_modes", "check_states", "warn_states",
           "stable_step", "check_step", "describe_limit", "check_start"]

#: How a caller opts in to out-of-range use (appended to every validity message).
OPT_IN = "pass check_limits=False (command line: --allow-out-of-range) for a deliberate out-of-range study"


class ValidityError(InputError):
    """A value outside the range a model is valid for, or a step beyond an integrator's stability limit."""


class ValidityWarning(UserWarning):
    """A simulated state left the range its model is valid for."""


def _variable(model: Model, name: str):
    for var in (*model.state_vars, *model.input_vars):
        if var.name == name:
            return var
    raise InputError(f"unknown state or input {name!r} of model {model.name!r}")


def describe_limit(model: Model, name: str) -> str:
    """The declared range of a state or input as text (angles in degrees), e.g. ``"[-35, 35] deg (rudder stop)"``.

    Parameters
    ----------
    model : Model
        A model with a limit on ``name``.
    name : str
        State or input name.

    Returns
    -------
    str
    """
    var = _variable(model, name)
    return model.limits[name].describe(var.unit, _is_angle(var))


def _is_angle(var) -> bool:
    return bool(var.angle or var.unit == "rad")


def _show(var, value: float) -> str:
    if _is_angle(var):
        return f"{np.degrees(value):.4g} deg"
    return f"{value:.4g}" + (f" {var.unit}" if var.unit else "")


#: Relative margin of the checks: a value beyond a bound by less than this fraction of the bound's size
#: passes (a measured rudder angle of 35.1 deg at a 35 deg stop is the stop, not a misuse).
MARGIN = 0.01


def _outside(limit, values: np.ndarray) -> np.ndarray:
    bounds = [abs(b) for b in (limit.lower, limit.upper) if np.isfinite(b)]
    tol = MARGIN * max(bounds, default=0.0)
    return ((values < limit.lower - tol) | (values > limit.upper + tol)) & np.isfinite(values)


def _check(model: Model, kind: str, name: str, values, t) -> None:
    limit = model.limits.get(name)
    if limit is None:
        return
    values = np.asarray(values, dtype=float).reshape(-1)
    bad = np.flatnonzero(_outside(limit, values))
    if bad.size:
        k = int(bad[0])
        var = _variable(model, name)
        when = f" at t = {np.asarray(t).reshape(-1)[k]:g} s" if t is not None and np.size(t) > k and values.size > 1 \
            else ""
        raise ValidityError(f"{kind} {name!r} = {_show(var, values[k])}{when} is outside its valid range "
                            f"{describe_limit(model, name)} of model {model.name!r}; {OPT_IN}")


def check_inputs(model: Model, inputs, t=None) -> None:
    """Raise :class:`ValidityError` if an input leaves its declared range.

    Parameters
    ----------
    model : Model
        The model whose ``limits`` apply.
    inputs : mapping name -> value(s), or array (N, nu) / (nu,)
        Input values (constants or time series).
    t : array_like, optional
        Time stamps of the rows, to say when the first violation happens.

    Raises
    ------
    ValidityError
        Naming the input, its value (degrees for angles), the range and the reason for it.
    """
    if isinstance(inputs, Mapping):
        items = inputs.items()
    else:
        U = np.asarray(inputs, dtype=float)
        U = U.reshape(1, -1) if U.ndim == 1 else U
        items = ((name, U[:, j]) for j, name in enumerate(model.input_names))
    for name, values in items:
        _check(model, "input", name, values, t)


def check_states(model: Model, x, what: str = "state") -> None:
    """Raise :class:`ValidityError` if a state of ``x`` lies outside its declared range.

    Parameters
    ----------
    model : Model
        The model whose ``limits`` apply.
    x : array_like (nx,) or mapping name -> value
        A state (e.g. the initial state of a simulation).
    what : str
        How to call it in the message (e.g. ``"initial state"``).

    Raises
    ------
    ValidityError
    """
    if isinstance(x, Mapping):
        items = x.items()
    else:
        x = np.asarray(x, dtype=float).reshape(-1)
        items = zip(model.state_names, x)
    for name, value in items:
        _check(model, what, name, value, None)


def warn_states(model: Model, X: np.ndarray, t: np.ndarray) -> list[str]:
    """Warn (:class:`ValidityWarning`) for every state of a trajectory that leaves its declared range.

    Parameters
    ----------
    model : Model
        The model whose ``limits`` apply.
    X : array (N, nx)
        Simulated states.
    t : array (N,)
        Time stamps [s].

    Returns
    -------
    list of str
        The warning messages (empty if the trajectory stays valid).
    """
    found = []
    for j, name in enumerate(model.state_names):
        limit = model.limits.get(name)
        if limit is None:
            continue
        bad = np.flatnonzero(_outside(limit, X[:, j]))
        if bad.size:
            k = int(bad[0])
            var = model.state_vars[j]
            found.append(f"state {name!r} of model {model.name!r} leaves its valid range {describe_limit(model, name)} "
                         f"at t = {t[k]:g} s ({_show(var, X[k, j])}); the results after that are outside the "
                         "model's validity")
    for message in found:
        warnings.warn(message, ValidityWarning, stacklevel=3)
    return found


_STABILITY = {"euler": (1.0, 1.0), "rk4": (1.0, 1.0, 1 / 2, 1 / 6, 1 / 24)}


def _amplification(method: str, z: np.ndarray) -> np.ndarray:
    coeffs = _STABILITY[method]
    return np.abs(sum(c * z**k for k, c in enumerate(coeffs)))


def _critical_steps(method: str, lam: np.ndarray) -> np.ndarray:
    """Largest ``h`` with ``|R(h lam)| <= 1`` for each decaying mode ``lam`` (bisection along each
    ray, all modes at once)."""
    lam = np.asarray(lam, dtype=complex)
    lo, hi = np.zeros(lam.shape), 8.0 / np.abs(lam)   # the stability regions of euler and rk4 lie within |z| < 3
    unbounded = _amplification(method, hi * lam) <= 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        ok = _amplification(method, mid * lam) <= 1.0 + 1e-12
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    return np.where(unbounded, np.inf, lo)


_JACOBIAN_CALLS: dict[int, tuple] = {}


def _state_jacobian(model: Model, x, u, p) -> np.ndarray:
    """``A = df/dx`` at ``(x, u, p)`` through a buffered call of ``model.f_jac`` (checked once per record
    by every batch estimator: no DM conversion)."""
    from ..runtime import BufferedCall

    key = id(model.f_jac)
    if key not in _JACOBIAN_CALLS:              # the Function is kept with its call, so its id stays unique
        if len(_JACOBIAN_CALLS) >= 64:          # a bounded cache: let the oldest model go
            del _JACOBIAN_CALLS[next(iter(_JACOBIAN_CALLS))]
        f = model.f_jac
        args = {n: ca.SX.sym(n, f.sparsity_in(n)) for n in f.name_in()}
        dense = ca.Function("state_jacobian", list(args.values()), [ca.densify(f.call(args)["A"])],
                            list(args), ["A"])
        _JACOBIAN_CALLS[key] = (f, BufferedCall(dense))
    call = _JACOBIAN_CALLS[key][1]
    call["x"], call["u"], call["p"], call["w"] = x, u, p, 0.0
    call()
    return call.out("A").copy()


def decaying_modes(model: Model, x, u, p) -> np.ndarray | None:
    """Eigenvalues with negative real part of ``A = df/dx`` at ``(x, u, p)`` (None: A not finite).

    Parameters
    ----------
    model : Model
    x, u, p : array_like
        The state, inputs and parameters.
    """
    A = _state_jacobian(model, x, u, p)
    if not np.all(np.isfinite(A)):
        return None
    lam = np.linalg.eigvals(A)
    scale = max(1e-300, float(np.abs(lam).max(initial=0.0)))
    return lam[lam.real < -1e-9 * scale]


def is_stable_step(model: Model, x, u, p, method: str, h: float) -> bool:
    """Whether the step ``h`` [s] keeps every decaying mode of ``model`` at ``(x, u, p)`` stable.

    The same test as :func:`stable_step` at one step (``|R(h lam)| <= 1`` for every decaying mode),
    without searching for the limit: the cheap check of a record whose longest interval is ``h``.

    Parameters
    ----------
    model : Model
        Continuous-time model.
    x, u, p : array_like
        State, input and parameter vectors of the linearisation point.
    method : str
        Fixed-step method (any other method is always stable).
    h : float
        The step [s].

    Returns
    -------
    bool
    """
    if method not in _STABILITY:
        return True
    lam = decaying_modes(model, np.asarray(x, dtype=float), np.asarray(u, dtype=float), p)
    return lam is None or bool(np.all(_amplification(method, h * lam.astype(complex)) <= 1.0 + 1e-12))


def stable_step(model: Model, x, u, p, method: str) -> float:
    """Largest stable step [s] of a fixed-step ``method`` for ``model`` linearised at ``(x, u, p)``.

    Every decaying mode ``lam`` (eigenvalue of ``A = df/dx`` with negative real part) must keep
    ``|R(h lam)| <= 1``, with ``R`` the method's stability polynomial (``1 + z`` for ``euler``,
    the quartic Taylor polynomial for ``rk4``). For a real eigenvalue that is ``h <= 2 T`` (euler)
    and ``h <= 2.785 T`` (rk4), ``T = -1/lam`` the mode's time constant.

    Parameters
    ----------
    model : Model
        Continuous-time model.
    x, u, p : array_like
        State, input and parameter vectors of the linearisation point.
    method : {"euler", "rk4"}
        Fixed-step method (any other method has no step limit: ``inf``).

    Returns
    -------
    float
        The step limit [s] (``inf`` when no decaying mode constrains it).
    """
    if method not in _STABILITY:
        return np.inf
    decaying = decaying_modes(model, x, u, p)
    if decaying is None:
        return np.inf
    return float(_critical_steps(method, decaying).min(initial=np.inf))


def check_step(model: Model, h: float, x, u, p, method: str, *, where: str = "") -> float:
    """Raise :class:`ValidityError` if the fixed step ``h`` exceeds the stability limit of ``method``.

    Parameters
    ----------
    model : Model
        Continuous-time model.
    h : float
        The (sub-)step the integrator will take [s].
    x, u, p : array_like
        Linearisation point (e.g. the initial state and inputs of a simulation).
    method : str
        Integration method (only ``euler`` and ``rk4`` have a step limit).
    where : str
        Where the step occurs, for the message (e.g. ``" between t = 10 and 1e4 s"``).

    Returns
    -------
    float
        The step limit [s].

    Raises
    ------
    ValidityError
        Naming the step, the limit and the fastest time constant, with the ways out.
    """
    limit = stable_step(model, x, u, p, method)
    if h > limit:
        raise ValidityError(f"time step {h:.4g} s{where} exceeds the {method} stability limit {limit:.4g} s of model "
                            f"{model.name!r} (eigenvalues of its linearisation at the start); use a shorter step, "
                            "max_step= (sub-steps) or method='cvodes' (adaptive), or " + OPT_IN)
    return limit


def check_start(model: Model, x, u, p, *, what: str = "the starting state", unset: list[str] | None = None,
                option: str = "x0") -> None:
    """Raise :class:`ValidityError` if the model's equations are not finite at ``(x, u, p)``.

    An estimator linearises the model at its prior: where the Jacobian is not finite (the MMG
    models at rest, ``u = v = 0``, divide by the speed) every estimate would be NaN.

    Parameters
    ----------
    model : Model
        Continuous-time model.
    x, u, p : array_like
        The start (e.g. a prior mean and the first input) and the parameters.
    what : str
        How to call the start in the message.
    unset : list of str, optional
        The states nothing gave a value (named in the message as the ones to give); default (or
        none): the states at zero.
    option : str
        How the caller gives starting values (e.g. ``"x0"`` or ``"--x0"``).

    Raises
    ------
    ValidityError
        Naming the start, the states to give and how.
    """
    x = np.asarray(x, dtype=float)
    A = _state_jacobian(model, x, np.asarray(u, dtype=float), p)
    if np.all(np.isfinite(A)):
        return
    if not unset:
        unset = [n for n, v in zip(model.state_names, x) if v == 0.0]
    shown = ", ".join(f"{n} = {v:.4g}" for n, v in zip(model.state_names, x))
    give = ", ".join(f"{n}=..." for n in unset) or "a state where it is defined"
    raise ValidityError(f"model {model.name!r} cannot start at {what} ({shown}): its equations are not finite "
                        f"there (e.g. at rest for a model that divides by the speed); give the starting value: "
                        f"{option} {give}")
