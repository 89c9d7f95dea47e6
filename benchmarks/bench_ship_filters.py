"""Kalman filters on a 6-state ship model: casship (compiled) vs filterpy and a NumPy loop.

Problem: the Shi et al. (2009) Taylor response model with earth-fixed kinematics (states
``u, v, r, x, y, psi``; inputs rudder and propeller rate), explicit Euler at dt = 0.1 s, a 20/20
rudder sequence simulated with process noise on the ``u, v, r`` accelerations, position (1 m) and
heading (1 deg) measured at every sample; 3000 steps (the record of ``bench_mhe``, longer). Peers get
the same discrete model written in NumPy with a hand-written Jacobian, ``Q_x = dt^2 G Q G'``, the
heading residual wrapped, and the same prior.

* EKF batch: ``EKF(..., options={"jit": True}).filter`` (the whole record through one compiled fold,
  every diagnostic of a ``FilterResult``) vs filterpy ``ExtendedKalmanFilter`` in its loop;
  identical algorithm, estimates agree to round-off.
* EKF online: ``run.update(y, dt, u_prev, u)`` per sample (lean step, one evaluation of the compiled
  step through CasADi's buffers) vs the same filterpy loop.
* UKF batch: casship ``UKF`` (kappa = 3) vs filterpy ``UnscentedKalmanFilter`` with Julier points
  (kappa = 3), sigma points redrawn after the prediction as casship does; agree to round-off.
* EnKF (100 members): casship ``EnKF`` vs filterpy ``EnsembleKalmanFilter``; different random
  draws, so the check is the RMSE against the truth. The first call in a fresh process is measured
  in a subprocess, once with an empty compile cache and once with the cache the first one filled.
* EKF + RTS: casship ``EKF.smooth`` (compiled filter and RTS folds) vs the same EKF and RTS
  recursions written as a NumPy loop.

Timing: :func:`benchmarks.compare` (peer and casship interleaved, medians of CPU time, the spread
of the per-pair ratios). Run ``python -m benchmarks.bench_ship_filters [--quick]``.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

import casship as cs
from benchmarks import compare, compared_row, format_table, skipped_row
from benchmarks.bench_mhe import DT, problem

_SU = np.zeros((6, 3))
_SU[:3] = np.eye(3)
_H = np.hstack([np.zeros((3, 3)), np.eye(3)])


class ShipNumpy:
    """The Euler step of the Shi model with kinematics and its Jacobian, in NumPy."""

    def __init__(self, model):
        p = model.param_dict(model.params())
        self.a = [p[f"a{i}"] for i in range(1, 10)]
        self.b = [p[f"b{i}"] for i in range(1, 5)]
        self.c = [p[f"c{i}"] for i in range(1, 4)]

    def f(self, x, uin, dt=DT):
        a, b, c = self.a, self.b, self.c
        u, v, r, _, _, psi = x
        d, n = uin
        du = (a[0] * u * u + a[1] * v * v + a[2] * r * r + a[3] * d * d + a[4] * v * r + a[5] * v * d
              + a[6] * r * d + a[7] * u * n + a[8] * n * n)
        dv = b[0] * v + b[1] * r + b[2] * d + b[3] * u * r
        dr = c[0] * v + c[1] * r + c[2] * d
        cp, sp = np.cos(psi), np.sin(psi)
        return x + dt * np.array([du, dv, dr, u * cp - v * sp, u * sp + v * cp, r])

    def F(self, x, uin, dt=DT):
        a, b, c = self.a, self.b, self.c
        u, v, r, _, _, psi = x
        d, n = uin
        cp, sp = np.cos(psi), np.sin(psi)
        J = np.zeros((6, 6))
        J[0, :3] = [2 * a[0] * u + a[7] * n, 2 * a[1] * v + a[4] * r + a[5] * d, 2 * a[2] * r + a[4] * v + a[6] * d]
        J[1, :3] = [b[3] * r, b[0], b[1] + b[3] * u]
        J[2, :3] = [0.0, c[0], c[1]]
        J[3, [0, 1, 5]] = [cp, -sp, -u * sp - v * cp]
        J[4, [0, 1, 5]] = [sp, cp, u * cp - v * sp]
        J[5, 2] = 1.0
        return np.eye(6) + dt * J


def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def _residual(y, yhat):
    e = y - yhat
    e[2] = _wrap(e[2])
    return e


def _hx(x):
    return x[3:].copy()


def _run(f, U, Y, predict, update):
    out = np.empty((Y.shape[0], 6))
    for k in range(Y.shape[0]):
        if k:
            predict(U[k - 1])
        update(Y[k])
        out[k] = f.x
    return out


def filterpy_ekf(ship, U, Y, prior, Qx, R):
    from filterpy.kalman import ExtendedKalmanFilter

    class EKF(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = ship.f(self.x, u)

    f = EKF(6, 3)
    f.x, f.P, f.Q, f.R = prior.mean.copy(), prior.cov.copy(), Qx, R
    hj = lambda x: _H  # noqa: E731

    def predict(u):
        f.F = ship.F(f.x, u)
        f.predict(u)

    return _run(f, U, Y, predict, lambda y: f.update(y, hj, _hx, residual=_residual))


def filterpy_ukf(ship, U, Y, prior, Qx, R):
    from filterpy.kalman import JulierSigmaPoints, UnscentedKalmanFilter

    pts = JulierSigmaPoints(6, kappa=3.0)
    f = UnscentedKalmanFilter(6, 3, DT, _hx, lambda x, dt, u: ship.f(x, u, dt), pts, residual_z=_residual)
    f.x, f.P, f.Q, f.R = prior.mean.copy(), prior.cov.copy(), Qx, R

    def update(y):
        f.sigmas_f = pts.sigma_points(f.x, f.P)      # redraw (as casship and Koike et al. 2023)
        f.update(y)

    return _run(f, U, Y, lambda u: f.predict(u=u), update)


def filterpy_enkf(ship, U, Y, prior, Qx, R, N, seed):
    from filterpy.kalman import EnsembleKalmanFilter

    np.random.seed(seed)
    held = {"u": U[0]}
    f = EnsembleKalmanFilter(prior.mean.copy(), prior.cov.copy(), 3, DT, N, _hx,
                             lambda x, dt: ship.f(x, held["u"], dt))
    f.Q, f.R = Qx, R

    def predict(u):
        held["u"] = u
        f.predict()

    return _run(f, U, Y, predict, f.update)


def numpy_ekf_rts(ship, U, Y, prior, Qx, R):
    """EKF forward (Joseph form) and RTS backward pass as a plain NumPy loop."""
    n = Y.shape[0]
    xs, Ps = np.empty((n, 6)), np.empty((n, 6, 6))
    xp_all, Pp_all, A_all = np.empty((n, 6)), np.empty((n, 6, 6)), np.empty((n, 6, 6))
    x, P = prior.mean.copy(), prior.cov.copy()
    eye = np.eye(6)
    for k in range(n):
        if k:
            A = ship.F(x, U[k - 1])
            x = ship.f(x, U[k - 1])
            P = A @ P @ A.T + Qx
            A_all[k] = A
        xp_all[k], Pp_all[k] = x, P
        S = _H @ P @ _H.T + R
        K = np.linalg.solve(S, _H @ P).T
        x = x + K @ _residual(Y[k], _hx(x))
        IKH = eye - K @ _H
        P = IKH @ P @ IKH.T + K @ R @ K.T
        xs[k], Ps[k] = x, P
    for k in range(n - 2, -1, -1):
        G = np.linalg.solve(Pp_all[k + 1], A_all[k + 1] @ Ps[k]).T
        d = xs[k + 1] - xp_all[k + 1]
        d[5] = _wrap(d[5])
        xs[k] = xs[k] + G @ d
        Ps[k] = Ps[k] + G @ (Ps[k + 1] - Pp_all[k + 1]) @ G.T
    return xs, Ps


def case(steps: int):
    """Model, Euler step, data, prior, ``Q``, ``R`` and the peers' ``Q_x``, inputs and measurements."""
    model, dm, data, prior, Q, R = problem(steps * DT, seed=3)
    Qx = DT**2 * _SU @ Q @ _SU.T
    return model, dm, data, prior, Q, R, Qx, data.matrix(model.input_names), data.matrix(["x", "y", "psi"])


def _online(est, data, prior, U, Y):
    run = est.online(prior, u=U[0])
    update = run.update
    means = np.empty((len(data), 6))
    means[0] = update(Y[0], 0.0, U[0], U[0])
    for k in range(1, len(data)):
        means[k] = update(Y[k], DT, U[k - 1], U[k])
    return means


FIRST_CALL = """
import json, sys, time
t0 = time.perf_counter()
sys.path.insert(0, {root!r})
import numpy as np, casship as cs
from benchmarks.bench_ship_filters import case
model, dm, data, prior, Q, R, Qx, U, Y = case({steps})
t1 = time.perf_counter()
enkf = cs.EnKF(dm, Q, R, options={{"members": {members}, "jit": True}})
enkf.filter(data, prior, seed=3)
t2 = time.perf_counter()
print(json.dumps({{"setup_s": t1 - t0, "first_call_s": t2 - t1}}))
"""


def first_call_in_new_process(steps: int, members: int, cache: str) -> float:
    """Wall-clock time of building the EnKF and its first ``filter`` in a fresh Python process
    whose compile cache is the folder ``cache``."""
    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "CASSHIP_CACHE_DIR": cache}
    out = subprocess.run([sys.executable, "-c", FIRST_CALL.format(root=root, steps=steps, members=members)],
                         capture_output=True, text=True, env=env, cwd=root)
    if out.returncode != 0:
        raise RuntimeError(f"EnKF first-call subprocess failed: {out.stderr.strip().splitlines()[-1:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])["first_call_s"]


def main(quick: bool = False) -> list[dict]:
    try:
        import filterpy  # noqa: F401
    except ImportError:
        return [skipped_row("ship EKF/UKF/EnKF vs filterpy", "filterpy", "filterpy not installed (pip install filterpy)")]
    steps = 600 if quick else 3000
    model, dm, data, prior, Q, R, Qx, U, Y = case(steps)
    ship = ShipNumpy(model)
    rep = 3 if quick else 9
    label = f"Shi ship model 6 states, {steps} steps at 10 Hz"
    per = lambda r: {**r, "steps": steps, "casship_us_per_step": 1e6 * r["casship_s"] / steps,  # noqa: E731
                     "peer_us_per_step": 1e6 * r["peer_s"] / steps}
    rows = []

    ekf = cs.EKF(dm, Q, R, options={"jit": True})
    res = ekf.filter(data, prior)
    peer = filterpy_ekf(ship, U, Y, prior, Qx, R)
    t = compare(lambda: ekf.filter(data, prior), lambda: filterpy_ekf(ship, U, Y, prior, Qx, R), rep)
    rows.append(per(compared_row(f"EKF batch, compiled, {label}", t, "filterpy ExtendedKalmanFilter (hand Jacobian)",
                                 f"max |x - x_filterpy| = {np.abs(res.x - peer).max():.1e}", target="ekf_batch")))
    online = _online(ekf, data, prior, U, Y)
    t = compare(lambda: _online(ekf, data, prior, U, Y), lambda: filterpy_ekf(ship, U, Y, prior, Qx, R), rep)
    rows.append(per(compared_row(f"EKF online run.update per sample, compiled, {label}", t,
                                 "filterpy ExtendedKalmanFilter (hand Jacobian)",
                                 f"max |x_online - x_batch| = {np.abs(online - res.x).max():.1e}, "
                                 f"vs filterpy {np.abs(online - peer).max():.1e}", target="ekf_online")))

    ukf = cs.UKF(dm, Q, R, options={"jit": True})
    res_u = ukf.filter(data, prior)
    peer_u = filterpy_ukf(ship, U, Y, prior, Qx, R)
    t = compare(lambda: ukf.filter(data, prior), lambda: filterpy_ukf(ship, U, Y, prior, Qx, R), rep)
    rows.append(per(compared_row(f"UKF (kappa = 3) batch, compiled, {label}", t,
                                 "filterpy UnscentedKalmanFilter (Julier, kappa = 3)",
                                 f"max |x - x_filterpy| = {np.abs(res_u.x - peer_u).max():.1e}", target="ukf_batch")))

    xs_np, Ps_np = numpy_ekf_rts(ship, U, Y, prior, Qx, R)
    sm = ekf.smooth(data, prior)
    t = compare(lambda: ekf.smooth(data, prior), lambda: numpy_ekf_rts(ship, U, Y, prior, Qx, R), rep)
    rows.append(per(compared_row(f"EKF + RTS smoother, compiled, {label}", t, "NumPy EKF + RTS loop",
                                 f"max |xs - xs_numpy| = {np.abs(sm.x - xs_np).max():.1e}, "
                                 f"|Ps - Ps_numpy| = {np.abs(sm.P - Ps_np).max():.1e}", target="ship_rts")))

    members = 100
    truth = data.matrix([f"true_{n}" for n in model.state_names])
    rmse = lambda X: np.sqrt(np.mean((X[:, 3:5] - truth[:, 3:5]) ** 2))  # noqa: E731
    with tempfile.TemporaryDirectory(prefix="casship-bench-cache-") as cache:
        cold = first_call_in_new_process(steps, members, cache)
        warm = first_call_in_new_process(steps, members, cache)
    enkf = cs.EnKF(dm, Q, R, options={"members": members, "jit": True})
    res_e = enkf.filter(data, prior, seed=3)
    peer_e = filterpy_enkf(ship, U, Y, prior, Qx, R, members, 3)
    t = compare(lambda: enkf.filter(data, prior, seed=3),
                lambda: filterpy_enkf(ship, U, Y, prior, Qx, R, members, 3), max(1, rep // 3))
    rows.append(per(compared_row(
        f"EnKF N = {members} batch, compiled, {label}", t, "filterpy EnsembleKalmanFilter",
        f"position RMSE vs truth {rmse(res_e.x):.3f} m (filterpy {rmse(peer_e):.3f} m); first call in a new "
        f"process {cold:.1f} s with an empty compile cache, {warm:.2f} s with it filled",
        target="enkf_batch", first_call_s=cold, first_call_cached_s=warm)))
    return rows


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv)))
