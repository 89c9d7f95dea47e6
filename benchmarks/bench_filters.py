"""Kalman filters and smoother: casship vs filterpy (EKF, UKF, EnKF) and pykalman (KF, RTS).

Nonlinear case (EKF, UKF, EnKF): the five-state SOG/COG/course-rate model of Fossen & Fossen
(2021), Euler-discretised at 50 Hz, GNSS positions at 5 Hz (NaN rows between fixes: predict only),
a simulated course manoeuvre with process noise. Peers get the same discrete model written in NumPy,
a hand-written Jacobian (EKF), the same Joseph-form update, ``Q = G Q G'`` and the same prior.

* EKF: identical algorithm, so the estimates must agree to round-off.
* UKF: filterpy's ``JulierSigmaPoints(kappa=3)`` (the form of Koike et al. 2023) with the sigma points redrawn after
  the prediction (what casship does; filterpy otherwise reuses the propagated points), so the
  estimates must agree to round-off.
* EnKF (N = 100): different random draws, so the check is the RMSE against the truth.

Linear case (KF, RTS): the Tomera (2011) double-integrator model (x, y, psi) at 10 Hz against
``pykalman.KalmanFilter.filter`` / ``.smooth``.

Batch = the whole record in one call (casship: ``filter`` through the folded step; peers: their
loop). Online = one Python call per sample (casship: ``run.update`` of ``est.online(prior)``, one
compiled call through bound buffers; with the lean step that returns ``x, P`` only, the default,
and with every diagnostic, ``options={"outputs": "all"}``). casship runs twice: with the step
evaluated by CasADi's virtual machine ("interpreted", the default) and compiled to C by the system
compiler (option ``jit``). Times are medians after one warm-up run, so folds are built and compiled
already; the EnKF rows also report the first run (``first_run_s``, including compilation). Times
are CPU times of the process (``time.process_time``), which other jobs on a shared machine do not
inflate. The heading measured by the linear case crosses +-180 deg; pykalman gets it unwrapped. Run
``python -m benchmarks.bench_filters [--quick]``.
"""
from __future__ import annotations

import sys
import time

import numpy as np

import casship as cs
from casship.estimators.rts import rts_smooth
from benchmarks import compare, compared_row, format_table, median_time, row, skipped_row

DT, GNSS_HZ = 0.02, 5.0


def _run_peer(f, Y, predict, update) -> np.ndarray:
    """The peer filter ``f`` over the measurements ``Y`` (NaN rows: predict only); means as rows."""
    out = np.empty((Y.shape[0], f.x.size))
    ok = np.isfinite(Y[:, 0])
    for k in range(Y.shape[0]):
        if k:
            predict()
        if ok[k]:
            update(Y[k])
        out[k] = f.x
    return out
Q_SOG = np.diag([1e-2, 1e-3])
R_SOG = np.diag([1.0, 1.0])
ALPHA1, ALPHA2 = 0.01, 0.1


def _sog_case(duration: float, seed: int = 1):
    m = cs.models.sog_cog(ALPHA1, ALPHA2)
    t = np.arange(0.0, duration, DT)
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((t.size, 2)) * np.sqrt(np.diag(Q_SOG))
    traj = cs.simulate(m, m.states(U=3.0, chi=0.3, omega_chi=0.0), t, w=w, method="euler")
    data = cs.measure(traj, m, {"x_n": 1.0, "y_n": 1.0}, rates={"x_n": GNSS_HZ, "y_n": GNSS_HZ}, seed=rng)
    prior = cs.Gaussian(m.states(x_n=0.0, y_n=0.0, U=2.5, chi=0.2), [4.0, 4.0, 1.0, 0.05, 1e-3])
    return m, cs.discretize(m, DT, method="euler"), traj, data, prior


def _fx(x, dt=DT):
    xn, yn, U, chi, om = x
    return np.array([xn + dt * U * np.cos(chi), yn + dt * U * np.sin(chi), U - dt * ALPHA1 * U,
                     chi + dt * om, om - dt * ALPHA2 * om])


def _F(x, dt=DT):
    _, _, U, chi, _ = x
    A = np.eye(5)
    A[0, 2], A[0, 3] = dt * np.cos(chi), -dt * U * np.sin(chi)
    A[1, 2], A[1, 3] = dt * np.sin(chi), dt * U * np.cos(chi)
    A[2, 2], A[3, 4], A[4, 4] = 1 - dt * ALPHA1, dt, 1 - dt * ALPHA2
    return A


_H = np.hstack([np.eye(2), np.zeros((2, 3))])
_G = np.zeros((5, 2))
_G[2, 0] = _G[4, 1] = DT
_QX = _G @ Q_SOG @ _G.T


def _hx(x):
    return x[:2]


def _filterpy_ekf(Y, prior):
    from filterpy.kalman import ExtendedKalmanFilter

    class EKF(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = _fx(self.x)

    f = EKF(5, 2)
    f.x, f.P, f.Q, f.R = prior.mean.copy(), prior.cov.copy(), _QX, R_SOG
    hj = lambda x: _H  # noqa: E731

    def predict():
        f.F = _F(f.x)
        f.predict()

    return _run_peer(f, Y, predict, lambda y: f.update(y, hj, _hx))


def _filterpy_ukf(Y, prior):
    from filterpy.kalman import JulierSigmaPoints, UnscentedKalmanFilter

    pts = JulierSigmaPoints(5, kappa=3.0)
    f = UnscentedKalmanFilter(5, 2, DT, _hx, lambda x, dt: _fx(x, dt), pts)
    f.x, f.P, f.Q, f.R = prior.mean.copy(), prior.cov.copy(), _QX, R_SOG
    def update(y):
        f.sigmas_f = pts.sigma_points(f.x, f.P)      # redraw (as casship and Koike et al. 2023)
        f.update(y)

    return _run_peer(f, Y, f.predict, update)


def _filterpy_enkf(Y, prior, N, seed):
    from filterpy.kalman import EnsembleKalmanFilter

    np.random.seed(seed)
    f = EnsembleKalmanFilter(prior.mean.copy(), prior.cov.copy(), 2, DT, N, _hx, lambda x, dt: _fx(x, dt))
    f.Q, f.R = _QX, R_SOG
    return _run_peer(f, Y, f.predict, f.update)


def _online(est, data, prior):
    """Stream the record through ``est.online`` (memory kept in the step's buffers)."""
    Y = data.matrix(est.measured)
    run = est.online(prior)
    update = run.update
    means = np.empty((len(data), prior.mean.size))
    means[0] = update(Y[0], 0.0)
    for k in range(1, len(data)):
        means[k] = update(Y[k], DT)
    return means


def _rmse(x, traj):
    return np.sqrt(np.mean((x[:, :2] - traj.x[:, :2]) ** 2))


def _per_step(r, n):
    r["steps"] = n
    r["casship_us_per_step"] = 1e6 * r["casship_s"] / n
    if r.get("peer_s") is not None:
        r["peer_us_per_step"] = 1e6 * r["peer_s"] / n
    return r


def _nonlinear_rows(quick: bool) -> list[dict]:
    try:
        import filterpy  # noqa: F401
    except ImportError:
        return [skipped_row("EKF/UKF/EnKF vs filterpy", "filterpy", "filterpy not installed (pip install filterpy)")]
    m, dm, traj, data, prior = _sog_case(60.0 if quick else 600.0)
    n = len(data)
    Y = data.matrix(["x_n", "y_n"])
    rep = 3 if quick else 5
    rows = []
    label = f"SOG/COG 5 states, {n} steps at 50 Hz, GNSS 5 Hz"

    for name, cls, peer_name, peer_fun in (
            ("EKF", cs.EKF, "filterpy ExtendedKalmanFilter (hand Jacobian)", _filterpy_ekf),
            ("UKF (kappa = 3)", cs.UKF, "filterpy UnscentedKalmanFilter (Julier, kappa = 3)", _filterpy_ukf)):
        peer = peer_fun(Y, prior)
        t_fp = median_time(lambda: peer_fun(Y, prior), repeat=max(1, rep // 2))
        for jit in (False, True):
            est = cls(dm, Q_SOG, R_SOG, options={"jit": jit})
            how = "compiled (jit)" if jit else "interpreted"
            res = est.filter(data, prior)
            check = f"max |x - x_filterpy| = {np.abs(res.x - peer).max():.1e}"
            t_cs = median_time(lambda: est.filter(data, prior), repeat=rep)
            rows.append(_per_step(row(f"{name} batch, {how}, {label}", t_cs, peer_name, t_fp, check), n))
            online = _online(est, data, prior)
            check = (f"max |x_online - x_batch| = {np.abs(online - res.x).max():.1e}, "
                     f"vs filterpy {np.abs(online - peer).max():.1e}")
            t_on = median_time(lambda: _online(est, data, prior), repeat=rep)
            rows.append(_per_step(row(f"{name} online (run.update per sample), {how}, {label}", t_on, peer_name,
                                      t_fp, check), n))
            full = cls(dm, Q_SOG, R_SOG, options={"jit": jit, "outputs": "all"})
            rich = _online(full, data, prior)
            t_full = median_time(lambda: _online(full, data, prior), repeat=rep)
            rows.append(_per_step(row(f"{name} online, all diagnostics (outputs='all'), {how}, {label}", t_full,
                                      peer_name, t_fp, f"max |x_all - x_lean| = {np.abs(rich - online).max():.1e}"), n))

    N = 100
    peer = _filterpy_enkf(Y, prior, N, 3)
    t_fp = median_time(lambda: _filterpy_enkf(Y, prior, N, 3), repeat=1, warmup=0)
    rmse_fp = f"filterpy {_rmse(peer, traj):.3f} m, speed {np.sqrt(np.mean((peer[:, 2] - traj['U'])[n // 10:] ** 2)):.3f} m/s"
    for jit in (False, True):
        enkf = cs.EnKF(dm, Q_SOG, R_SOG, options={"members": N, "jit": jit})
        how = "compiled (jit)" if jit else "interpreted"
        t0 = time.perf_counter()
        res = enkf.filter(data, prior, seed=3)
        first = time.perf_counter() - t0         # wall clock, including compilation
        check = (f"position RMSE vs truth {_rmse(res.x, traj):.3f} m, speed "
                 f"{np.sqrt(np.mean((res['U'] - traj['U'])[n // 10:] ** 2)):.3f} m/s ({rmse_fp})")
        t_cs = median_time(lambda: enkf.filter(data, prior, seed=3), repeat=max(1, rep // 2))
        rows.append(_per_step(row(f"EnKF N = {N} batch, {how}, {label}", t_cs, "filterpy EnsembleKalmanFilter",
                                  t_fp, check, first_run_s=first), n))
    return rows


def _linear_rows(quick: bool) -> list[dict]:
    try:
        from pykalman import KalmanFilter
    except ImportError:
        return [skipped_row("KF/RTS vs pykalman", "pykalman", "pykalman not installed (pip install pykalman)")]
    m = cs.models.tomera_kinematic()
    dt = 0.1
    t = np.arange(0.0, 120.0 if quick else 1200.0, dt)
    dm = cs.discretize(m, dt, method="euler")
    Qc = np.diag([0.1, 0.2, 0.1, 0.2, 1.0, 1.0])
    rng = np.random.default_rng(2)
    w = rng.standard_normal((t.size, m.nw)) * np.sqrt(np.diag(Qc))
    traj = cs.simulate(m, m.states(vx=1.0, vy=0.5, psi=0.3, r=0.001), t, w=w, method="euler")
    R = np.diag([0.01, 0.01, 0.001])
    data = cs.measure(traj, m, {"x": 0.1, "y": 0.1, "psi": np.sqrt(0.001)}, seed=rng)
    prior = cs.Gaussian(m.states(psi=0.3), [1.0, 1.0, 1.0, 1.0, 0.1, 0.1])
    kf = cs.KF(dm, Qc, R)
    A, _, G = dm.linearize(m.states(), m.inputs())
    H = np.array(m.h_jac(m.states(), m.inputs(), m.params())[0])
    pk = KalmanFilter(transition_matrices=A, observation_matrices=H, transition_covariance=G @ Qc @ G.T,
                      observation_covariance=R, initial_state_mean=prior.mean, initial_state_covariance=prior.cov)
    Y = data.matrix(["x", "y", "psi"])
    Y[:, 2] = np.unwrap(Y[:, 2])     # pykalman has no angle residuals; casship wraps them
    n = t.size
    rep = 3 if quick else 5
    label = f"Tomera double integrators, 6 states, {n} steps"
    res = kf.filter(data, prior)
    xf, _ = pk.filter(Y)
    check = f"max |x - x_pykalman| = {np.abs(res.x - xf).max():.1e}"
    t_cs = median_time(lambda: kf.filter(data, prior), repeat=rep)
    t_pk = median_time(lambda: pk.filter(Y), repeat=rep)
    rows = [_per_step(row(f"KF batch, {label}", t_cs, "pykalman KalmanFilter.filter", t_pk, check), n)]
    sm = kf.smooth(data, prior)
    xs, Ps = pk.smooth(Y)
    check = f"max |xs - xs_pykalman| = {np.abs(sm.x - xs).max():.1e}, |Ps - Ps_pk| = {np.abs(sm.P - Ps).max():.1e}"
    t_cs = median_time(lambda: kf.smooth(data, prior), repeat=rep)
    t_pk = median_time(lambda: pk.smooth(Y), repeat=rep)
    rows.append(_per_step(row(f"KF + RTS smoother, {label}", t_cs, "pykalman KalmanFilter.smooth", t_pk, check), n))
    kfj = cs.KF(dm, Qc, R, options={"jit": True})
    smj = kfj.smooth(data, prior)
    t = compare(lambda: kfj.smooth(data, prior), lambda: pk.smooth(Y), rep)
    rows.append(_per_step(compared_row(
        f"KF + RTS smoother, compiled (jit), {label}", t, "pykalman KalmanFilter.smooth",
        f"max |xs - xs_pykalman| = {np.abs(smj.x - xs).max():.1e}, |Ps - Ps_pk| = {np.abs(smj.P - Ps).max():.1e}",
        target="rts_cv"), n))
    t_rts = median_time(lambda: rts_smooth(res), repeat=rep)
    t_pk_backward = max(t_pk - median_time(lambda: pk.filter(Y), repeat=rep), 0.0)
    rows.append(_per_step(row(f"RTS backward pass only, interpreted, {label}", t_rts,
                              "pykalman smooth minus filter time", t_pk_backward,
                              "same smoothed estimates as the row above"), n))
    fast = rts_smooth(res, jit=True)
    t_rts = median_time(lambda: rts_smooth(res, jit=True), repeat=rep)
    rows.append(_per_step(row(f"RTS backward pass only, compiled (jit), {label}", t_rts,
                              "pykalman smooth minus filter time", t_pk_backward,
                              f"max |xs - xs_pykalman| = {np.abs(fast.x - xs).max():.1e}"), n))
    return rows


def main(quick: bool = False) -> list[dict]:
    return _nonlinear_rows(quick) + _linear_rows(quick)


if __name__ == "__main__":
    rows = main(quick="--quick" in sys.argv)
    print(format_table(rows))
    print()
    for r in rows:
        if "casship_us_per_step" in r:
            print(f"{r['benchmark']}: casship {r['casship_us_per_step']:.2f} us/step, "
                  f"peer {r.get('peer_us_per_step', float('nan')):.2f} us/step")
