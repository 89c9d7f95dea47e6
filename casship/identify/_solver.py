"""Bounded Levenberg-Marquardt (trust-region) iterations on an exact gradient and a Gauss-Newton /
Fisher curvature, for identification costs.

Each iteration solves ``(H + lam D) d = -g`` on the variables that are not held at a bound
(``D`` the diagonal of ``H``, Marquardt's scaling), projects the step onto the bounds, and accepts it
when the cost decreases by a fair share of the predicted decrease; ``lam`` shrinks after good steps
and grows after poor ones (or a non-finite cost). Convergence is judged on the predicted remaining
decrease (half the Newton decrement ``g' H^-1 g``) measured in the cost's own statistical unit
(1 for a negative log-likelihood; the residual variance per degree of freedom for a weighted least-
squares cost): below ``tol`` the estimate is within ``sqrt(2 tol)`` standard errors of the optimum.

The solver never throws its iterate away: it returns the best point with a status
(``converged``, ``stalled``, ``max_iterations``, ``nan``) and a message.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = ["SolverReport", "trust_region", "STATUSES"]

STATUSES = ("converged", "stalled", "max_iterations", "nan")


@dataclass
class SolverReport:
    """Outcome of :func:`trust_region`."""

    z: np.ndarray
    f: float
    g: np.ndarray
    H: np.ndarray
    status: str
    message: str
    iterations: int
    seconds: float
    decrement: float
    history: list = field(default_factory=list)

    @property
    def converged(self) -> bool:
        return self.status == "converged"


def _active(z, g, lb, ub):
    with np.errstate(invalid="ignore"):
        at_lo = np.isfinite(lb) & (z <= lb + np.maximum(1e-12, 1e-10 * np.abs(lb))) & (g > 0)
        at_hi = np.isfinite(ub) & (z >= ub - np.maximum(1e-12, 1e-10 * np.abs(ub))) & (g < 0)
    return at_lo | at_hi


def _decrement(g, H, free) -> float:
    """Half the Newton decrement on the free variables (pseudo-inverse for singular directions)."""
    if not free.any():
        return 0.0
    gF, HF = g[free], H[np.ix_(free, free)]
    lam, vec = np.linalg.eigh(0.5 * (HF + HF.T))
    keep = lam > 1e-12 * max(lam.max(), 1e-300)
    proj = vec[:, keep].T @ gF
    return float(0.5 * np.sum(proj**2 / lam[keep]))


def _step(g, H, free, lam):
    """Solve ``(H + lam D) d = -g`` on the free variables (``D`` = diag of ``H``, floored)."""
    d = np.zeros_like(g)
    if not free.any():
        return d
    HF = H[np.ix_(free, free)]
    diag = np.diag(HF).copy()
    floor = 1e-10 * max(diag.max(), 1e-300)
    D = np.maximum(diag, floor)
    A = HF + lam * np.diag(D)
    try:
        L = np.linalg.cholesky(A)
        d[free] = -np.linalg.solve(L.T, np.linalg.solve(L, g[free]))
    except np.linalg.LinAlgError:
        d[free] = -np.linalg.lstsq(A, g[free], rcond=None)[0]
    return d


class _Printer:
    """Iteration, cost and elapsed time on a :func:`casship.progress.bar` (a line every 10 s when not a terminal)."""

    def __init__(self, label: str, total: int, show: bool | None):
        from ..progress import bar

        self.bar = bar(None, label, unit="iter") if show is not False else None

    def __call__(self, it: int, f: float, dec: float, lam: float) -> None:
        if self.bar is not None:
            self.bar.set_postfix_str(f"cost {f:.8g}, decrement {dec:.2g}", refresh=False)
            self.bar.n = it
            self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def trust_region(derivs: Callable, cost: Callable, z0, lb, ub, *, unit: Callable[[float], float] = lambda f: 1.0,
                 tol: float = 1e-8, max_iter: int = 100, label: str = "fit", show: bool | None = None) -> SolverReport:
    """Minimise a cost with bounded Levenberg-Marquardt iterations.

    Parameters
    ----------
    derivs : callable z -> (f, g, H)
        Cost, exact gradient and a positive semi-definite curvature (Gauss-Newton / Fisher).
    cost : callable z -> f
        Cost only (trial points); may return NaN or inf (the step is then rejected).
    z0, lb, ub : arrays
        Start (projected onto the bounds) and bounds (``-inf`` / ``inf`` allowed).
    unit : callable f -> float
        The cost's statistical unit at cost ``f`` (see the module docstring).
    tol : float
        Convergence threshold on the predicted remaining decrease, in units of ``unit(f)``.
    max_iter : int
        Iteration limit (the best iterate is returned with status ``max_iterations``).
    label : str
        Shown in the iteration lines.
    show : bool, optional
        ``False`` hides the progress bar (iteration, cost, elapsed time), which is otherwise shown when
        :mod:`casship.progress` draws bars (standard error is a terminal).

    Returns
    -------
    SolverReport
    """
    t0 = time.perf_counter()
    lb, ub = np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)
    z = np.clip(np.asarray(z0, dtype=float), lb, ub)
    f, g, H = derivs(z)
    printer = _Printer(label, max_iter, show)
    lam, nu, history = 1e-3, 2.0, []
    status, message, it, dec = "max_iterations", f"iteration limit {max_iter} reached", 0, np.inf
    rejected = 0
    while True:
        free = ~_active(z, g, lb, ub)
        dec = _decrement(g, H, free)
        u = max(unit(f), 1e-300)
        history.append((it, f, dec / u, time.perf_counter() - t0))
        printer(it, f, dec / u, lam)
        if dec <= tol * u:
            status, message = "converged", f"predicted remaining decrease {dec / u:.2g} (tolerance {tol:g})"
            break
        if it >= max_iter:
            break
        it += 1
        while True:
            d = _step(g, H, free, lam)
            zt = np.clip(z + d, lb, ub)
            d = zt - z
            pred = -(g @ d + 0.5 * d @ H @ d)
            ft = cost(zt)
            if not np.isfinite(ft):
                rejected += 1
                lam, nu = lam * nu, nu * 2
                if lam > 1e12:
                    status, message = "nan", "the cost is not finite at every trial step from the last iterate"
                    break
                continue
            rho = (f - ft) / pred if pred > 0 else -1.0
            if rho > 1e-4 or (pred <= 1e-15 * max(abs(f), 1.0) and ft <= f):
                fn, gn, Hn = derivs(zt)
                if not (np.isfinite(fn) and np.all(np.isfinite(gn)) and np.all(np.isfinite(Hn))):
                    # a finite cost whose derivatives overflow: not a point to step from
                    rejected += 1
                    lam, nu = lam * nu, nu * 2
                    if lam > 1e12:
                        status, message = "nan", "the derivatives are not finite at every trial step from the last iterate"
                        break
                    continue
                z, f, g, H = zt, fn, gn, Hn
                lam, nu = lam * max(1 / 3, 1 - (2 * rho - 1) ** 3) if rho > 0 else lam, 2.0
                rejected = 0
                break
            lam, nu = lam * nu, nu * 2
            if lam > 1e12:
                status, message = "stalled", (f"no step decreases the cost (predicted remaining decrease "
                                              f"{dec / u:.3g}, tolerance {tol:g}): the cost is not smooth or "
                                              "the curvature is poor here")
                break
        if status in ("nan", "stalled"):
            break
    printer.close()
    return SolverReport(z, float(f), g, H, status, message, it, time.perf_counter() - t0, float(dec / max(unit(f), 1e-300)),
                        history)
