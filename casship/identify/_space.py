"""Decision variables of an identification problem and the IPOPT call shared by the problems.

A free quantity is a model parameter (by name), a process/measurement noise variance (``Q[w]``,
``R[y]``, optimised through its logarithm so that it stays positive) or an initial state of one
record (``<state>@<k>``). The optimiser sees scaled variables ``z = value / scale`` (``log(value)``
for variances), so that all of them are of order one.
"""
from __future__ import annotations

import re
import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..model import Model
from .result import IdentificationError

__all__ = ["Entry", "ParamSpace", "ipopt_solve", "hess_lag_function", "HESSIANS"]

HESSIANS = ("exact", "limited-memory", "custom")
_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
VAR_FLOOR = 1e-10  # lower bound of an estimated variance, relative to its starting value


@dataclass(frozen=True)
class Entry:
    """One free quantity: its name, kind (``param``, ``Q``, ``R``, ``x0``) and where it goes."""

    name: str
    kind: str
    index: int
    record: int = -1
    log: bool = False
    scale: float = 1.0
    lower: float = -np.inf
    upper: float = np.inf


class ParamSpace:
    """The free quantities of a problem, their guesses, bounds and scaling.

    Parameters
    ----------
    model : Model
    free : sequence of str
        Names of free model parameters.
    base : array (np,)
        Values of all parameters (the fixed ones keep them).
    bounds : mapping name -> (lower, upper), optional
        Bounds added to the model's own parameter bounds (also for ``Q[..]``, ``R[..]``, ``x@k``).
    scale : mapping name -> float, optional
        Typical magnitudes; by default the guess, the nominal value, or 1.
    noise_entries : sequence of (name, kind, index, value)
        Free variances (kind ``Q`` or ``R``) with their current values.
    x0_entries : sequence of (name, record, state index, value)
    """

    def __init__(self, model: Model, free: Sequence[str], base: np.ndarray, *, bounds=None, scale=None,
                 noise_entries=(), x0_entries=()):
        free = list(free)
        if len(set(free)) != len(free):
            raise ValueError(f"free parameters listed twice: {sorted({n for n in free if free.count(n) > 1})}")
        bounds, scale = dict(bounds or {}), dict(scale or {})
        self.model, self.base = model, np.asarray(base, dtype=float)
        entries, guess = [], {}
        for n in free:
            i = model.index(n, "param")
            entries.append(Entry(n, "param", i, lower=model.param_lower[i], upper=model.param_upper[i]))
            guess[n] = self.base[i]
        for n, kind, i, v in noise_entries:
            entries.append(Entry(n, kind, i, log=True))
            guess[n] = float(v)
        for n, k, i, v in x0_entries:
            entries.append(Entry(n, "x0", i, record=k))
            guess[n] = float(v)
        names = [e.name for e in entries]
        unknown = (set(bounds) | set(scale)) - set(names)
        if unknown:
            raise ValueError(f"bounds/scale given for {sorted(unknown)}, which are not free; free: {names}")
        out = []
        for e in entries:
            lo, hi = e.lower, e.upper
            if e.name in bounds:
                b = bounds[e.name]
                if len(b) != 2 or not b[0] < b[1]:
                    raise ValueError(f"bounds of {e.name!r} must be (lower, upper) with lower < upper, got {b}")
                lo, hi = max(lo, float(b[0])), min(hi, float(b[1]))
            if e.log:
                # a variance the data cannot tell from zero stops at this floor (reported as at a bound)
                lo = max(lo, VAR_FLOOR * guess[e.name])
            s = float(scale.get(e.name, 0.0))
            if e.name in scale and not (np.isfinite(s) and s > 0):
                raise ValueError(f"scale of {e.name!r} must be positive, got {scale[e.name]}")
            if s == 0.0:
                nominal = model.params()[e.index] if e.kind == "param" else 0.0
                s = abs(guess[e.name]) or abs(nominal) or 1.0
            out.append(Entry(e.name, e.kind, e.index, e.record, e.log, 1.0 if e.log else s, lo, hi))
        self.entries = out
        self.names = names
        self.default_guess = guess

    def __len__(self) -> int:
        return len(self.entries)

    # -- maps between decision variables and values ---------------------------------------------
    def natural(self, z):
        """Values (list of expressions or floats) of the entries for decision variables ``z``."""
        return [ca.exp(z[i]) if e.log else z[i] * e.scale for i, e in enumerate(self.entries)]

    def natural_numeric(self, z: np.ndarray) -> np.ndarray:
        z = np.asarray(z, dtype=float).reshape(-1)
        return np.array([np.exp(z[i]) if e.log else z[i] * e.scale for i, e in enumerate(self.entries)])

    def jac_natural(self, z: np.ndarray) -> np.ndarray:
        """Diagonal of d(value)/dz (for the delta method)."""
        z = np.asarray(z, dtype=float).reshape(-1)
        return np.array([np.exp(z[i]) if e.log else e.scale for i, e in enumerate(self.entries)])

    def to_z(self, values: Mapping[str, float]) -> np.ndarray:
        z = []
        for e in self.entries:
            v = float(values[e.name])
            if e.log:
                if not v > 0:
                    raise ValueError(f"guess of variance {e.name!r} must be positive, got {v}")
                z.append(np.log(v))
            else:
                z.append(v / e.scale)
        return np.array(z)

    def guess_z(self, guess: Mapping[str, float] | None) -> np.ndarray:
        guess = dict(guess or {})
        unknown = set(guess) - set(self.names)
        if unknown:
            raise ValueError(f"guess for {sorted(unknown)}, which are not free; free: {self.names}")
        values = {**self.default_guess, **{k: float(v) for k, v in guess.items()}}
        for e in self.entries:
            v = values[e.name]
            if not np.isfinite(v):
                raise ValueError(f"guess of {e.name!r} is not finite")
            if not e.lower <= v <= e.upper:
                raise ValueError(f"guess {v:g} of {e.name!r} is outside its bounds [{e.lower:g}, {e.upper:g}]")
        return self.to_z(values)

    def z_bounds(self):
        lo, hi = [], []
        for e in self.entries:
            if e.log:
                lo.append(np.log(e.lower) if e.lower > 0 else -np.inf)
                hi.append(np.log(e.upper) if np.isfinite(e.upper) else np.inf)
            else:
                lo.append(e.lower / e.scale)
                hi.append(e.upper / e.scale)
        return np.array(lo), np.array(hi)

    def param_vector(self, nat, base=None) -> ca.MX | np.ndarray:
        """The full parameter vector with free entries replaced by ``nat`` (symbolic or numeric).

        ``base`` (symbolic) replaces the fixed values, for problems whose data are parameters.
        """
        if isinstance(nat, np.ndarray):
            p = self.base.copy()
            for e, v in zip(self.entries, nat):
                if e.kind == "param":
                    p[e.index] = v
            return p
        items = [ca.MX(float(v)) for v in self.base] if base is None else [base[i] for i in range(self.base.size)]
        for e, v in zip(self.entries, nat):
            if e.kind == "param":
                items[e.index] = v
        return ca.vertcat(*items) if items else ca.MX(0, 1)

    def scales(self) -> dict[str, float]:
        return {e.name: (0.0 if e.log else e.scale) for e in self.entries}


def hess_lag_function(z, par, hess_f) -> ca.Function:
    """IPOPT's ``nlp_hess_l(x, p, lam_f, lam_g)``: the upper triangle of ``lam_f * hess_f`` (no constraints)."""
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", 0)
    return ca.Function("nlp_hess_l", [z, par, lam_f, lam_g], [ca.triu(lam_f * hess_f)],
                       ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])


def ipopt_solve(f, z, z0, lbz, ubz, *, g=None, lbg=None, ubg=None, hessian: str = "exact",
                options: Mapping | None = None, name: str = "fit", hess_f=None, par=None, par_value=None,
                functions: Mapping | None = None):
    """Minimise ``f(z)`` (subject to ``lbg <= g(z) <= ubg``) with IPOPT.

    ``hessian="custom"`` uses the symmetric matrix expression ``hess_f(z)`` (e.g. a Gauss-Newton or
    Fisher-scoring approximation of the Hessian of ``f``; unconstrained problems only). ``par`` is a
    symbolic parameter of ``f`` (and ``hess_f``) with value ``par_value``. ``functions`` may give
    ready-made (e.g. compiled) ``grad_f: (x, p) -> (f, grad)`` and ``hess_lag: (x, p, lam_f, lam_g) ->
    triu(H)`` Functions, used by IPOPT instead of CasADi's own.
    Returns ``(z_opt, stats, seconds)``; raises :class:`IdentificationError` naming IPOPT's status if
    it does not converge.
    """
    if hessian not in HESSIANS:
        raise ValueError(f"unknown hessian {hessian!r}; use one of {HESSIANS}")
    par_sym = ca.MX.sym("p", 0) if par is None else par
    opts = {"print_time": False, "calc_lam_p": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-9,
            "ipopt.acceptable_tol": 1e-5, "ipopt.acceptable_iter": 5, "ipopt.max_iter": 300,
            "ipopt.hessian_approximation": "exact" if hessian == "custom" else hessian}
    functions = dict(functions or {})
    if hessian == "custom":
        if g is not None:
            raise ValueError("a custom Hessian is only supported without constraints")
        opts["hess_lag"] = functions.pop("hess_lag", None) or hess_lag_function(z, par_sym, hess_f)
    opts.update(functions)
    for k, v in (options or {}).items():
        opts[k if k.startswith(("ipopt.", "print_time")) else f"ipopt.{k}"] = v
    nlp = {"x": z, "f": f}
    if par is not None:
        nlp["p"] = par
    if g is not None:
        nlp["g"] = g
    solver = ca.nlpsol(re.sub(r"[^A-Za-z0-9]+", "_", name).strip("_") or "fit", "ipopt", nlp, opts)
    args = dict(x0=z0, lbx=lbz, ubx=ubz)
    if par is not None:
        args["p"] = par_value
    if g is not None:
        args.update(lbg=lbg, ubg=ubg)
    t0 = time.perf_counter()
    sol = solver(**args)
    seconds = time.perf_counter() - t0
    st = solver.stats()
    status = st.get("return_status", "unknown")
    if status not in _OK:
        raise IdentificationError(f"{name}: IPOPT did not converge (status {status!r} after "
                                  f"{st.get('iter_count', '?')} iterations)", status)
    return np.asarray(sol["x"]).reshape(-1), st, seconds
