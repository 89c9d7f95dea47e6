"""Shared checks for the ship-model tests: exact Jacobians against central differences."""
from __future__ import annotations

import numpy as np


def central_jacobians(model, x, u, p, w=None, h=1e-6):
    """Central-difference Jacobians of ``model.f`` with respect to x, u and w (relative step)."""
    w = np.zeros(model.nw) if w is None else np.asarray(w, dtype=float)
    f = lambda x_, u_, w_: np.asarray(model.f(x_, u_, p, w_)).reshape(-1)
    out = []
    for k, base in enumerate((x, u, w)):
        J = np.zeros((model.nx, base.size))
        for j in range(base.size):
            step = h * max(1.0, abs(base[j]))
            hi, lo = base.copy(), base.copy()
            hi[j] += step
            lo[j] -= step
            args_hi = [x, u, w]
            args_lo = [x, u, w]
            args_hi[k], args_lo[k] = hi, lo
            J[:, j] = (f(*args_hi) - f(*args_lo)) / (2 * step)
        out.append(J)
    return out


def assert_jacobians(model, x, u, p=None, rtol=1e-5, atol=1e-8, h=1e-6):
    """Exact ``f_jac`` equals central differences at ``(x, u, p)`` (A, B and G)."""
    p = model.params() if p is None else p
    x, u = np.asarray(x, dtype=float), np.asarray(u, dtype=float)
    A, B, _, G = (np.asarray(M) for M in model.f_jac(x, u, p, np.zeros(model.nw)))
    Ad, Bd, Gd = central_jacobians(model, x, u, p, h=h)
    for name, exact, approx in (("A", A, Ad), ("B", B, Bd), ("G", G, Gd)):
        scale = np.maximum(np.abs(exact), np.abs(approx))
        bad = np.abs(exact - approx) > atol + rtol * np.maximum(scale, np.abs(exact).max(axis=1, keepdims=True))
        assert not bad.any(), (f"{model.name}: Jacobian {name} differs at {np.argwhere(bad)[:3].tolist()}: "
                               f"exact {exact[bad][:3]}, central {approx[bad][:3]}")
