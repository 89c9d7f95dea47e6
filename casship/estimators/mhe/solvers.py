"""Solving one MHE window: IPOPT or SQP to convergence, or one real-time Gauss-Newton iteration."""
from __future__ import annotations

import numpy as np

from .problem import Window

__all__ = ["MHEFailed"]


class MHEFailed(RuntimeError):
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


def _real_time_iteration(win: Window, z0, par, where: str) -> np.ndarray:
    """One Gauss-Newton step; the bounded QP only when the unconstrained step leaves the bounds."""
    step = win.gn_step
    step["z"], step["p"] = z0, par
    step()
    z = step.out("z_next").ravel()
    if np.all(np.isfinite(z)) and np.all(z >= win.lbx) and np.all(z <= win.ubx):
        return z.copy()
    qp = win.gn_parts.call({"z": z0, "p": par})
    g = np.asarray(qp["g"]).ravel()
    sol = win.solver(h=qp["H"], g=qp["grad"], a=qp["G"], lba=-g, uba=-g, lbx=win.lbx - z0, ubx=win.ubx - z0)
    stats = win.solver.stats()
    z = z0 + np.asarray(sol["x"]).reshape(-1)
    if not stats["success"] or not np.all(np.isfinite(z)):
        status = stats["return_status"]
        raise MHEFailed(f"MHE (real-time iteration, N = {win.N}) failed at {where}: QP solver "
                        f"{win.solver.name()} status {status!r}", status)
    return z


def solve_window(win: Window, z0: np.ndarray, par: np.ndarray, where: str) -> np.ndarray:
    """The window's solution from the start point ``z0`` with the parameters ``par``.

    Raises :class:`MHEFailed` naming ``where`` and the solver's status when the solver fails or
    returns a point that violates the dynamics (an infeasible window).
    """
    if win.gn_step is not None:
        return _real_time_iteration(win, z0, par, where)
    sol = win.solver(x0=z0, p=par, lbx=win.lbx, ubx=win.ubx, lbg=0.0, ubg=0.0)
    status = win.solver.stats()["return_status"]
    z = np.asarray(sol["x"]).reshape(-1)
    gap = float(np.max(np.abs(np.asarray(sol["g"])), initial=0.0))
    if status not in win.ok_status or not np.all(np.isfinite(z)):
        raise MHEFailed(f"MHE ({win.solver.name()}) failed at {where}: solver status {status!r}", status)
    if not gap <= 1e-6 * max(1.0, float(np.max(np.abs(z)))):
        raise MHEFailed(f"MHE ({win.solver.name()}) failed at {where}: solver status {status!r} "
                        f"but the dynamics are violated by {gap:.3g} (infeasible window)", status)
    return z
