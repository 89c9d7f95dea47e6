"""The IPOPT call of the problems that need a general NLP solver (multiple shooting, exact Hessians).

Non-convergence is not an exception here: the caller gets the last iterate and IPOPT's status and
reports them. CasADi's evaluation warnings (``nlp_f failed: NaN detected``), which IPOPT handles by
shortening its step, are not printed.
"""
from __future__ import annotations

import re
import time
from typing import Mapping

import casadi as ca
import numpy as np

__all__ = ["ipopt_solve", "hess_lag_function", "IPOPT_OK"]

IPOPT_OK = ("Solve_Succeeded", "Solved_To_Acceptable_Level")


def hess_lag_function(z, par, hess_f) -> ca.Function:
    """IPOPT's ``nlp_hess_l(x, p, lam_f, lam_g)``: the upper triangle of ``lam_f * hess_f`` (no constraints)."""
    lam_f, lam_g = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", 0)
    return ca.Function("nlp_hess_l", [z, par, lam_f, lam_g], [ca.triu(lam_f * hess_f)],
                       ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])


def ipopt_solve(f, z, z0, lbz, ubz, *, g=None, lbg=None, ubg=None, options: Mapping | None = None,
                name: str = "fit", hess_lag=None, par=None, par_value=None, functions: Mapping | None = None):
    """Minimise ``f(z)`` subject to ``lbg <= g(z) <= ubg`` and bounds with IPOPT.

    ``hess_lag`` (optional) is a ready-made Hessian-of-the-Lagrangian Function (see
    :func:`hess_lag_function`); without it IPOPT uses CasADi's exact Hessian, or L-BFGS when
    ``options`` say ``hessian_approximation="limited-memory"``. ``par`` is a symbolic parameter of
    ``f`` with value ``par_value``; ``functions`` may give a ready-made ``grad_f``.

    Returns ``(z_opt, stats, seconds)``: the last iterate whatever IPOPT's ``return_status``.
    """
    opts = {"print_time": False, "calc_lam_p": False, "show_eval_warnings": False, "ipopt.print_level": 0,
            "ipopt.sb": "yes", "ipopt.tol": 1e-9, "ipopt.acceptable_tol": 1e-5, "ipopt.acceptable_iter": 5,
            "ipopt.max_iter": 300}
    if hess_lag is not None:
        opts["hess_lag"] = hess_lag
    opts.update(dict(functions or {}))
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
    return np.asarray(sol["x"]).reshape(-1), solver.stats(), time.perf_counter() - t0
