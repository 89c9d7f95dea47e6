"""Maximum-likelihood identification through an EKF: casship vs scipy.optimize on a NumPy EKF.

Problem: the Shi et al. (2009) response model (states ``u, v, r``, inputs rudder and propeller rate,
all three states measured, as in the paper), Euler-discretised at 1 s as in the paper, simulated
with process noise over a zig-zag-like rudder record with propeller-rate steps (so that the speed
varies and ``b2`` and ``b4`` are separable); the seven sway/yaw parameters
``b1..b4, c1..c3`` are estimated from a guess 30 % off, with ``Q`` and ``R`` known.

* casship: ``MLEProblem(EKF, data, free=...).solve()`` -- the negative log-likelihood is the EKF step
  folded over the record in CasADi, IPOPT with the exact gradient and Hessian; timed end to end
  including building the problem.
* peer: what users write today -- a NumPy EKF with hand-coded Euler Jacobians, one Python loop per
  likelihood evaluation, minimised by ``scipy.optimize.minimize`` (L-BFGS-B) with finite-difference
  gradients, from the same guess.

A third row fits with the compiled likelihood (``jit=True``): the compilation (10-20 s) is paid on a
first record and reported, and the timed fit is a new record of the same length, which reuses the
compiled code (Monte Carlo, bootstrap and cross-validation fits are of this kind).

The accuracy check compares the two optima (likelihood and parameters). Run
``python -m benchmarks.bench_identify [--quick]``.
"""
from __future__ import annotations

import sys
import time

import numpy as np
from scipy.optimize import minimize

import casship as cs
from benchmarks import format_table, row, skipped_row

FREE = ("b1", "b2", "b3", "b4", "c1", "c2", "c3")
TRUTH = {"c1": 0.001, "b2": -0.02}
DT, N_PROP = 1.0, 1.5
Q_VAR = np.array([1e-6, 1e-6, 1e-8])
R_VAR = np.array([0.02, 0.02, 1e-3]) ** 2


def make_data(n: int, seed: int = 0):
    model = cs.models.shi_taylor(TRUTH, kinematics=False)
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    delta = np.radians(20.0) * np.sign(np.sin(2 * np.pi * t / 140.0) + 1e-9)
    w = rng.standard_normal((n, 3)) * np.sqrt(Q_VAR)
    n_prop = N_PROP * (1.0 + 0.25 * np.sign(np.sin(2 * np.pi * t / 500.0) + 1e-9))  # speed changes separate b2, b4
    tr = cs.simulate(model, model.states(u=8.0), t, {"delta": delta, "n": n_prop}, method="euler", w=w)
    data = cs.measure(tr, model, dict(zip(("u", "v", "r"), np.sqrt(R_VAR))), seed=rng)
    return model, data


def numpy_nll(theta, p_all: dict, data, x0, P0):
    """Negative log-likelihood of a plain NumPy EKF (Euler step, analytic Jacobians)."""
    p = dict(p_all)
    p.update(zip(FREE, theta))
    a = [p[f"a{i}"] for i in range(1, 10)]
    b1, b2, b3, b4 = (p[f"b{i}"] for i in range(1, 5))
    c1, c2, c3 = (p[f"c{i}"] for i in range(1, 4))
    Y = np.column_stack([data["u"], data["v"], data["r"]])
    D, Nn = data["delta"], data["n"]
    Q, R = np.diag(Q_VAR), np.diag(R_VAR)
    x, P = x0.copy(), P0.copy()
    nll = 0.0
    eye = np.eye(3)
    for k in range(Y.shape[0]):
        if k > 0:
            u, v, r = x
            d, n = D[k - 1], Nn[k - 1]
            du = (a[0] * u * u + a[1] * v * v + a[2] * r * r + a[3] * d * d + a[4] * v * r + a[5] * v * d
                  + a[6] * r * d + a[7] * u * n + a[8] * n * n)
            dv = b1 * v + b2 * r + b3 * d + b4 * u * r
            dr = c1 * v + c2 * r + c3 * d
            J = np.array([[2 * a[0] * u + a[7] * n, 2 * a[1] * v + a[4] * r + a[5] * d, 2 * a[2] * r + a[4] * v + a[6] * d],
                          [b4 * r, b1, b2 + b4 * u],
                          [0.0, c1, c2]])
            A = eye + DT * J
            x = x + DT * np.array([du, dv, dr])
            P = A @ P @ A.T + (DT * DT) * Q
        e = Y[k] - x
        S = P + R
        Si = np.linalg.inv(S)
        nll += 0.5 * (e @ Si @ e + np.log(np.linalg.det(S)) + 3 * np.log(2 * np.pi))
        K = P @ Si
        x = x + K @ e
        P = (eye - K) @ P
    return nll


def main(quick: bool = False) -> list[dict]:
    n = 300 if quick else 1000
    model, data = make_data(n)
    truth = model.params(TRUTH)
    guess = {k: 0.7 * truth[model.index(k, "param")] for k in FREE}
    x0 = np.array([data["u"][0], data["v"][0], data["r"][0]])
    P0 = np.diag(R_VAR)
    prior = cs.Gaussian(x0, P0)

    fits, times = {}, {}
    for hessian in ("exact", "fisher"):
        t0 = time.perf_counter()
        ekf = cs.EKF(cs.discretize(model, DT, method="euler"), Q=Q_VAR, R=R_VAR)
        fits[hessian] = cs.MLEProblem(ekf, data, free=list(FREE), x0=prior, params=TRUTH).solve(
            guess=guess, hessian=hessian)
        times[hessian] = time.perf_counter() - t0

    p_all = model.param_dict(truth)
    theta0 = np.array([guess[k] for k in FREE])
    scale = np.where(theta0 != 0, np.abs(theta0), 1e-3)
    t0 = time.perf_counter()
    res = minimize(lambda z: numpy_nll(z * scale, p_all, data, x0, P0), theta0 / scale, method="L-BFGS-B",
                   options={"maxiter": 500, "ftol": 1e-12, "gtol": 1e-6})
    t_peer = time.perf_counter() - t0
    theta_peer = res.x * scale
    rows = []
    for hessian, fit in fits.items():
        theta_cas = np.array([fit.estimates[k] for k in FREE])
        nll_same = numpy_nll(theta_cas, p_all, data, x0, P0)
        rel = np.max(np.abs(theta_peer - theta_cas) / np.array([fit.std_errors[k] for k in FREE]))
        check = (f"nll casship {fit.cost:.6f} (numpy EKF at casship optimum {nll_same:.6f}) vs scipy "
                 f"{res.fun:.6f}; max |param diff| = {rel:.2g} std errors; IPOPT iterations {fit.iterations}, "
                 f"scipy nfev {res.nfev}")
        rows.append(row(f"ML fit, Shi model, 7 params, {n} samples, {hessian} Hessian", times[hessian],
                        "scipy L-BFGS-B + FD, numpy EKF", t_peer, check, nll_casship=fit.cost,
                        nll_peer=float(res.fun), max_param_diff_std=float(rel), peer_nfev=int(res.nfev)))
    if quick:
        rows.append(skipped_row(f"ML fit, compiled (jit=True), repeat fit, {n} samples",
                                "scipy L-BFGS-B + FD, numpy EKF", "quick mode (compilation takes 10-20 s)"))
        return rows
    rows.append(_compiled_repeat(n, model, guess, p_all, scale, theta0))
    return rows


def _compiled_repeat(n, model, guess, p_all, scale, theta0) -> dict:
    """Compiled likelihood (``jit=True``): compile on one record, then fit a new record of the same
    length, which reuses the compiled code; the peer fits that new record too."""
    def fit_record(data, jit):
        x0 = np.array([data["u"][0], data["v"][0], data["r"][0]])
        ekf = cs.EKF(cs.discretize(model, DT, method="euler"), Q=Q_VAR, R=R_VAR)
        return cs.MLEProblem(ekf, data, free=list(FREE), x0=cs.Gaussian(x0, np.diag(R_VAR)), params=TRUTH,
                             jit=jit).solve(guess=guess), x0

    t0 = time.perf_counter()
    fit_record(make_data(n, seed=0)[1], True)
    t_compile = time.perf_counter() - t0
    data = make_data(n, seed=1)[1]
    t0 = time.perf_counter()
    fit, x0 = fit_record(data, True)
    t_cas = time.perf_counter() - t0
    P0 = np.diag(R_VAR)
    t0 = time.perf_counter()
    res = minimize(lambda z: numpy_nll(z * scale, p_all, data, x0, P0), theta0 / scale, method="L-BFGS-B",
                   options={"maxiter": 500, "ftol": 1e-12, "gtol": 1e-6})
    t_peer = time.perf_counter() - t0
    theta_cas = np.array([fit.estimates[k] for k in FREE])
    rel = np.max(np.abs(res.x * scale - theta_cas) / np.array([fit.std_errors[k] for k in FREE]))
    check = (f"new record (seed 1): nll casship {fit.cost:.6f} vs scipy {res.fun:.6f}; max |param diff| = "
             f"{rel:.2g} std errors; first fit incl. compilation {t_compile:.1f} s")
    return row(f"ML fit, compiled (jit=True), repeat fit on a new record, {n} samples", t_cas,
               "scipy L-BFGS-B + FD, numpy EKF", t_peer, check, compile_and_first_fit_s=t_compile,
               nll_casship=fit.cost, nll_peer=float(res.fun), max_param_diff_std=float(rel))


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
