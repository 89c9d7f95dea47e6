"""Simulation folds, built once per process and shared by structure, compiled where they pay.

A simulation of a record runs a fold (``mapaccum``) of the discretised step ``F(x, u, p, w, dt)``
over chunks of samples, carrying the state from chunk to chunk. A replay with prediction bands runs
it once, then once more for every parameter draw of its index intervals, and propagates the exact
sensitivities of the states to the uncertain parameters. Three Functions do that work:

* :func:`simulation_fold`: ``(x, U, p, W, dt) -> X``, the states after each step of a chunk;
* the same fold mapped over parameter vectors (``Function.map``; inputs, noise and steps shared):
  every draw of a chunk in one call (:func:`fold_steps` with several parameter vectors);
* :func:`sensitivity_fold`: the step with its forward sensitivities
  ``S_{k+1} = F_x S_k + F_p E`` (``E`` selects the parameters), as used by
  :func:`casship.simulation.bands.trajectory_sensitivities`.

They depend only on the step Function (the model's equations, the integration method and its
sub-steps) and their sizes, never on the model object, the record or the parameter values. So they
are kept per process under a digest of the step, as the identification keeps its folds: the replays
of many fit files (each file rebuilds its model) build them once.

``jit`` is the runtime's compile policy (:class:`casship.runtime.JitPolicy`): ``False`` interpreted,
``True`` compiled now, ``None`` compiled if the compile cache holds the library, else compiled in the
background while evaluated interpreted. The flags keep the numbers: interpreted and compiled folds give
the same states to the last bit (tested), so where the switch happens does not change a result. A step
with an adaptive integrator (``cvodes``) always runs interpreted: CasADi generates no C code for it.
The Functions live in the runtime's one table (:func:`casship.runtime.shared_function`) and records run
through its one driver (:func:`casship.runtime.run_pieces`).
"""
from __future__ import annotations

import hashlib
import weakref

import casadi as ca
import numpy as np

from ..errors import SolverError
from ..runtime import COUNTS as _COUNTS, Job, JitPolicy, PieceFailed, fold_chunk, pieces, run_pieces, shared_function

__all__ = ["simulation_fold", "sensitivity_fold", "fold_steps", "padded", "signature",
           "IntegrationError", "solver_status", "COUNTS"]

_SIGNATURES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
COUNTS = _COUNTS.setdefault("folds", {"built": 0, "reused": 0})   # Functions built and found again


class IntegrationError(SolverError):
    """An integrator (CVODES) failed; ``status`` is its return flag, ``step`` the first step of the
    block of steps in which it failed.

    Parameters
    ----------
    message : str
        What failed, where.
    status : str
        The integrator's return flag (e.g. ``CV_TOO_MUCH_WORK``).
    step : int
        First step of the failing block.
    """

    def __init__(self, message: str, status: str, step: int):
        super().__init__(message)
        self.status, self.step = status, step


def solver_status(exc: Exception) -> str:
    """The return flag a CasADi solver error names (e.g. ``CV_TOO_MUCH_WORK``), else ``"unknown"``.

    Parameters
    ----------
    exc : Exception
    """
    import re

    found = re.findall(r'returned "?([A-Za-z_]+)"?', str(exc))
    return found[-1] if found else "unknown"



def signature(dmodel) -> str:
    """A digest of the step Function of ``dmodel``: discretisations with equal digests share their folds.

    Parameters
    ----------
    dmodel : DiscreteModel
    """
    sig = _SIGNATURES.get(dmodel)
    if sig is None:
        sig = hashlib.sha256(dmodel.F.serialize().encode()).hexdigest()
        _SIGNATURES[dmodel] = sig
    return sig


def _jit(dmodel, jit) -> JitPolicy:
    """An integrator's step is not generated as C: interpreted whatever ``jit`` says."""
    return JitPolicy.of(jit) if dmodel.symbolic is ca.SX else JitPolicy.OFF


def _shared(dmodel, key: tuple, make, jit):
    """The Function ``make()`` (compiled per ``jit``), built once per process for every
    discretisation of the same step (the runtime's table)."""
    return shared_function(("folds", signature(dmodel), *key), make, _jit(dmodel, jit))


def _size(steps: int, jit) -> int:
    """Chunk length: the runtime's :func:`~casship.runtime.fold_chunk` compiled; interpreted, a power of
    two up to it (short records)."""
    chunk = fold_chunk()
    if jit:
        return chunk
    return min(chunk, 1 << max(0, int(steps - 1).bit_length()))


def simulation_fold(dmodel, n: int | None = None, *, jit=False) -> ca.Function:
    """``F`` folded over ``n`` steps: ``fold(x, U, p, W, dt) -> (X, x_last)`` with ``U`` (nu, n), ``W``
    (nw, n), ``dt`` (1, n), ``X`` the (nx, n) states after each step and ``x_last`` the last of them;
    shared per process by structure.

    Parameters
    ----------
    dmodel : DiscreteModel
    n : int, optional
        Steps per call (default :func:`casship.runtime.fold_chunk`).
    jit : bool, None, str or JitPolicy
        Interpreted (``False``), compiled now (``True``) or compiled from the cache / in the background
        (``None``): :class:`casship.runtime.JitPolicy`.

    Returns
    -------
    casadi.Function
    """
    n = fold_chunk() if n is None else n

    def make():
        m, n_ = dmodel.model, int(n)
        acc = dmodel.F.mapaccum(f"simulate_steps{n_}", n_)
        x, U, p = ca.MX.sym("x", m.nx), ca.MX.sym("u", m.nu, n_), ca.MX.sym("p", m.np)
        W, dt = ca.MX.sym("w", m.nw, n_), ca.MX.sym("dt", 1, n_)
        # one parameter vector for the chunk (so that a map over parameter vectors maps one column each)
        X = acc(x, U, ca.repmat(p, 1, n_), W, dt)
        return ca.Function(f"simulate_fold{n_}", [x, U, p, W, dt], [X, X[:, -1]], ["x", "u", "p", "w", "dt"],
                           ["xf", "x_last"])
    return _shared(dmodel, ("simulate", int(n)), make, jit)


def sensitivity_fold(dmodel, k: int, n: int | None = None, *, jit=False) -> ca.Function:
    """The step with forward sensitivities to ``k`` parameters, folded over ``n`` steps.

    ``fold(x, S, u, p, E, dt) -> (xn, Sn)``: ``x`` (nx, 1) and ``S`` (nx, k) the state and its sensitivities at
    the start, ``p`` (np, 1) and ``E`` (np, k) the parameter vector and its derivative with respect to
    the ``k`` parameters (a selection), the same for every step, ``u`` (nu, n), ``dt`` (1, n);
    ``xn`` (nx, n) and ``Sn`` (nx, n k) the states and sensitivities after each step, side by side.

    Parameters
    ----------
    dmodel : DiscreteModel
    k : int
        Number of parameters.
    n : int, optional
        Steps per call (default :func:`casship.runtime.fold_chunk`).
    jit : bool or None
        As for :func:`simulation_fold`.

    Returns
    -------
    casadi.Function
    """
    n = fold_chunk() if n is None else n

    def make():
        m, sym = dmodel.model, dmodel.symbolic
        x, S = sym.sym("x", m.nx), sym.sym("S", m.nx, k)
        u, p, dt = sym.sym("u", m.nu), sym.sym("p", m.np), sym.sym("dt")
        E = sym.sym("E", m.np, k)
        xn = dmodel.F(x, u, p, sym.zeros(m.nw), dt)
        Sn = ca.jtimes(xn, ca.vertcat(x, p), ca.vertcat(S, E))
        step = ca.Function("sens_step", [x, S, u, p, E, dt], [xn, Sn], ["x", "S", "u", "p", "E", "dt"], ["xn", "Sn"])
        acc = step.mapaccum(f"sens_steps{k}_{int(n)}", int(n), [0, 1], [0, 1])
        ins = [ca.MX.sym(name, *shape) for name, shape in (("x", (m.nx, 1)), ("S", (m.nx, k)), ("u", (m.nu, int(n))),
                                                           ("p", (m.np, 1)), ("E", (m.np, k)), ("dt", (1, int(n))))]
        x_, S_, u_, p_, E_, dt_ = ins
        # the parameters and their selection the same for every step of the chunk
        outs = acc(x_, S_, u_, ca.repmat(p_, 1, int(n)), ca.repmat(E_, 1, int(n)), dt_)
        return ca.Function(f"sens_fold{k}_{int(n)}", ins, list(outs), ["x", "S", "u", "p", "E", "dt"], ["xn", "Sn"])
    return _shared(dmodel, ("sensitivity", int(k), int(n)), make, jit)


def _mapped(dmodel, size: int, jit, n: int) -> ca.Function:
    """The simulation fold mapped over ``n`` parameter vectors (and states), the inputs, noise and steps
    shared (the runtime's table keeps it)."""
    if n == 1:
        return simulation_fold(dmodel, size, jit=jit)

    def make():
        fold = simulation_fold(dmodel, size, jit=jit)
        shared = [fold.index_in(name) for name in ("u", "w", "dt")]
        return fold.map(f"{fold.name()}_map{n}", "serial", n, shared, [])
    # mapped around the fold as jit hands it out (compiled or not): not compiled again
    return shared_function(("folds", signature(dmodel), "mapped", int(size), int(n), _jit(dmodel, jit)), make,
                           JitPolicy.OFF)


def padded(a: np.ndarray, total: int) -> np.ndarray:
    """Columns of ``a`` (k, n) repeated from the last one up to ``total`` columns (a chunk's padding).

    Parameters
    ----------
    a : (k, n) array
    total : int
    """
    extra = total - a.shape[1]
    if extra <= 0:
        return a
    last = a[:, -1:] if a.shape[1] else np.zeros((a.shape[0], 1))
    return np.hstack([a, np.repeat(last, extra, axis=1)])


def fold_steps(dmodel, x0, U, P, W, dt, *, jit=False) -> np.ndarray:
    """Run ``x[k+1] = F(x[k], U[k], p, W[k], dt[k])`` over all steps for one or several parameter vectors.

    The record runs in chunks through one shared fold (:func:`simulation_fold`), the state carried from
    chunk to chunk, so the result is that of a single fold; several parameter vectors run as one call
    of the fold mapped over them per chunk.

    Parameters
    ----------
    dmodel : DiscreteModel
    x0 : array_like (nx,)
        Initial state (the same for every parameter vector).
    U : array (n, nu)
        Inputs per step.
    P : array_like (np,) or (m, np)
        One parameter vector, or one per row.
    W : array (n, nw)
        Process noise per step.
    dt : array_like (n,)
        Step lengths [s].
    jit : bool or None
        See :func:`simulation_fold`.

    Returns
    -------
    numpy.ndarray
        ``(len(dt) + 1, nx)`` states for one parameter vector, ``(m, len(dt) + 1, nx)`` for ``m`` rows
        of ``P``; the first row is ``x0``.

    Raises
    ------
    IntegrationError
        An integrator step failed (naming the block of steps and the solver's status).
    """
    x0 = np.asarray(x0, dtype=float).reshape(-1)
    dt = np.asarray(dt, dtype=float).reshape(-1)
    P = np.asarray(P, dtype=float)
    single = P.ndim == 1
    P = np.atleast_2d(P)
    m, nx, steps = P.shape[0], x0.size, dt.size
    X = np.empty((m, steps + 1, nx))
    X[:, 0] = x0
    if steps == 0:
        return X[0] if single else X
    size = _size(steps, _jit(dmodel, jit))
    fun = _mapped(dmodel, size, jit, m)
    per = {"u": np.asarray(U, dtype=float)[:steps].T, "w": np.asarray(W, dtype=float)[:steps].T, "dt": dt[None, :]}
    job = Job(fun, {"x": np.repeat(x0[:, None], m, axis=1)}, {"p": P.T}, per, steps, carry={"x": "x_last"}, pad={})
    try:
        run = run_pieces([job], chunk=size)[0]["pieces"]
    except PieceFailed as exc:
        _failure(dmodel, exc.fun, exc.inputs, exc.start, exc.stop - 1)
    for (start, _, _), (_, out, take) in zip(pieces(steps, size), run):
        block = out["xf"].reshape(nx, m, size)           # the parameter vectors' chunks side by side
        X[:, start + 1:start + 1 + take] = block[:, :, :take].transpose(1, 2, 0)
    return X[0] if single else X


def _failure(dmodel, fun, inputs: dict, first: int, last: int):
    """Raise :class:`IntegrationError` for a failed chunk, with the solver's status (which only the
    exception of a plain call of the Function carries)."""
    try:
        fun(*(inputs[name] for name in fun.name_in()))
    except RuntimeError as exc:
        status = solver_status(exc)
        raise IntegrationError(f"integration of {dmodel.model.name!r} ({dmodel.method}) failed in steps "
                               f"{first}..{last}: solver status {status}", status, first) from exc
    raise IntegrationError(f"integration of {dmodel.model.name!r} ({dmodel.method}) failed in steps {first}..{last}",
                           "unknown", first)
