"""Solving one MHE window: IPOPT, fatrop or SQP to convergence, or one real-time Gauss-Newton iteration.

A moving window warm-starts the NLP solvers with the previous window's solution shifted by one
stage and improved by Gauss-Newton steps (the real-time iteration's step, repeated while it
shrinks, at most four), with the multipliers of the dynamics from the last step. When that point
already meets the first-order optimality conditions to the solver's tolerance, strictly inside
the bounds, it is the solution the solver would return at its first convergence test, and the
solver is not called (its set-up per call costs several times a Gauss-Newton step); otherwise
(active bounds, a strongly nonlinear window) the solver iterates from there.
"""
from __future__ import annotations

import numpy as np

from ...errors import SolverError
from .problem import Window

__all__ = ["MHEFailed"]


class MHEFailed(SolverError):
    """The NLP solver of a moving-horizon window did not succeed (``status`` holds its return status).

    Parameters
    ----------
    message : str
    status : str
        The solver's return status.
    """

    def __init__(self, message: str, status: str):
        super().__init__(message)
        self.status = status


#: What a failed window suggests trying.
RESCUE = ("variables of very different scales are hard for the solvers (latitude and longitude in radians beside "
          "speeds: the model in metres, e.g. sog-cog, is better posed); the other solvers (options solver=sqp, "
          "ipopt, rti) or the EKF may succeed")


def _inside(win: Window, z: np.ndarray) -> bool:
    """``z`` finite and inside the window's bounds."""
    if not np.isfinite(z.sum()):                    # a NaN or inf anywhere makes the sum non-finite
        return False
    return win.unbounded or bool((z >= win.lbx).all() and (z <= win.ubx).all())


def _real_time_iteration(win: Window, z0, par, where: str) -> np.ndarray:
    """One Gauss-Newton step; the bounded QP only when the unconstrained step leaves the bounds."""
    step = win.gn()
    step["z"], step["p"] = z0, par
    try:
        step()
    except RuntimeError as exc:         # the step's linear solve failed: no Gauss-Newton step exists here
        raise MHEFailed(f"MHE (real-time iteration, N = {win.N}) failed at {where}: the Gauss-Newton step could "
                        f"not be computed ({exc}): the window's normal matrix is singular or not finite in floating "
                        f"point; {RESCUE}", "step_failed") from exc
    z = step.out("z_next").ravel()
    if _inside(win, z):
        return z.copy()
    parts, solver = win.qp()
    qp = parts.call({"z": z0, "p": par})
    g = np.asarray(qp["g"]).ravel()
    sol = solver(h=qp["H"], g=qp["grad"], a=qp["G"], lba=-g, uba=-g, lbx=win.lbx - z0, ubx=win.ubx - z0)
    stats = solver.stats()
    z = z0 + np.asarray(sol["x"]).reshape(-1)
    if not stats["success"] or not np.all(np.isfinite(z)):
        status = stats["return_status"]
        raise MHEFailed(f"MHE (real-time iteration, N = {win.N}) failed at {where}: QP solver "
                        f"{solver.name()} status {status!r}", status)
    return z


def gauss_newton_start(win: Window, z0: np.ndarray, par: np.ndarray, iterations: int = 4
                       ) -> tuple[np.ndarray, np.ndarray | None]:
    """A start point for the NLP solvers: ``z0`` improved by Gauss-Newton steps.

    The steps stop when one is below ``1e-9`` of the size of ``z`` (converged), would leave the
    bounds or is not finite (the last good point is kept), or after ``iterations``. On a window
    without active bounds the result is then the optimum up to the solver's tolerance, which the
    NLP solver confirms, typically without an iteration of its own.

    Parameters
    ----------
    win : Window
        The window problem.
    z0 : array
        The shifted previous solution.
    par : array
        The window's parameters.
    iterations : int
        The most Gauss-Newton steps taken.

    Returns
    -------
    z, lam_g : array, array or None
        The improved point and the last step's multipliers of the dynamics, or ``(z0, None)`` when
        not even the first step could be taken.
    """
    step = win.gn(multipliers=True)
    z, lam = z0, None
    step["p"] = par
    for _ in range(iterations):
        step["z"] = z
        try:
            step()
        except RuntimeError:
            break
        z_new, lam_new = step.out("z_next").ravel(), step.out("lam_g").ravel()
        if not (_inside(win, z_new) and np.isfinite(lam_new.sum())):
            break
        small = np.abs(z_new - z).max() <= 1e-9 * max(1.0, np.abs(z).max())
        z, lam = z_new.copy(), lam_new.copy()
        if small:
            break
    return z, lam


def first_order_optimal(win: Window, z: np.ndarray, par: np.ndarray, lam_g: np.ndarray | None) -> bool:
    """Whether ``z`` with the multipliers ``lam_g`` solves the window: strictly inside the bounds (so
    no bound multiplier), the gradient of the Lagrangian and the dynamics gaps within the solver's
    tolerance. (The interpreted Gauss-Newton step that makes ``z`` is equilibrated by the solvers'
    scales, :meth:`Window.scaling`, so its point is accurate in each state's deviations as well; the
    compiled Riccati step needs no equilibration for that, tested on the same windows.)"""
    if lam_g is None or not np.isfinite(z.sum()):
        return False
    if not win.unbounded and not ((z > win.lbx).all() and (z < win.ubx).all()):
        return False
    call = win.kkt()
    call["z"], call["p"], call["lam_g"] = z, par, lam_g
    try:
        call()
    except RuntimeError:
        return False
    dual, gaps = call.out("dual").ravel(), call.out("primal").ravel()
    return bool(np.abs(dual).max(initial=0.0) <= win.tol and np.abs(gaps).max(initial=0.0) <= win.tol)


def solve_window(win: Window, z0: np.ndarray, par: np.ndarray, where: str, lam_g0: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None]:
    """The window's solution from the start point ``z0`` with the parameters ``par``.

    ``lam_g0`` are start values of the multipliers of the dynamics constraints (IPOPT, fatrop and
    SQP; zero by default); when ``z0`` and ``lam_g0`` already solve the window
    (:func:`first_order_optimal`) they are returned without calling the solver. Returns the
    solution and its multipliers (``None`` for the real-time iteration). Raises :class:`MHEFailed`
    naming ``where`` and the solver's status when the solver fails or returns a point that
    violates the dynamics (an infeasible window). The solvers work in the scaled variables of
    :meth:`Window.scaling`.
    """
    if win.solver is None:
        return _real_time_iteration(win, z0, par, where), None
    if first_order_optimal(win, z0, par, lam_g0):
        return z0, lam_g0
    D, Dg = win.scaling(z0, par)
    # the solvers work in scaled variables (Window.scaling): z = D zeta, gaps / D_g, multipliers * D_g
    scaled = {"x0": z0 / D, "p": np.concatenate([par, D, Dg]), "lbx": win.lbx / D, "ubx": win.ubx / D,
              "lam_g0": (0.0 if lam_g0 is None else lam_g0 * Dg) * win.lam_sign}
    if win.solver.class_name() == "IpoptInterface":     # buffers; a failure raises
        call = win.nlp_call()
        for key, value in scaled.items():
            call[key] = value
        try:
            call.trigger()
            z, g = D * call.out("x").ravel(), Dg * call.out("g").ravel()
            lam = call.out("lam_g").ravel() / Dg
            status = win.ok_status[0]
        except RuntimeError:
            status = _failed_status(win, scaled)
            z, g, lam = np.full(win.nz, np.nan), np.zeros(0), None
    else:
        sol = win.solver(**scaled, lbg=0.0, ubg=0.0)
        stats = win.solver.stats()
        status = stats.get("unified_return_status", stats["return_status"]) if win.lam_sign < 0 \
            else stats["return_status"]
        z, g = D * np.asarray(sol["x"]).reshape(-1), Dg * np.asarray(sol["g"]).ravel()
        lam = win.lam_sign * np.asarray(sol["lam_g"]).ravel() / Dg
    gap = float(np.max(np.abs(g), initial=0.0))
    if status not in win.ok_status or not np.all(np.isfinite(z)):
        raise MHEFailed(f"MHE ({win.solver.name()}) failed at {where}: solver status {status!r}; {RESCUE}", status)
    if not gap <= 1e-6 * max(1.0, float(np.max(np.abs(z)))):
        raise MHEFailed(f"MHE ({win.solver.name()}) failed at {where}: solver status {status!r} "
                        f"but the dynamics are violated by {gap:.3g} (infeasible window)", status)
    return z, lam


def _failed_status(win: Window, scaled: dict) -> str:
    """The return status of a solve that raised (solved again by a plain call, which records it)."""
    try:
        win.solver(**scaled, lbg=0.0, ubg=0.0)
    except RuntimeError:
        pass
    try:
        return str(win.solver.stats()["return_status"])
    except RuntimeError:
        return "unknown"
