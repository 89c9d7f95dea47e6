"""Moving-horizon estimation per sample: casship ``MHE`` vs do-mpc's MHE and a plain CasADi+IPOPT MHE.

Problem (the same for all three): the Shi et al. (2009) Taylor response model with earth-fixed
kinematics (states ``u, v, r, x, y, psi``, inputs rudder and propeller rate), explicit Euler at
dt = 0.1 s, so that the process noise on the ``u, v, r`` accelerations is exactly additive on the
discrete step (``x+ = F(x, u) + dt w``; do-mpc's MHE only knows additive noise). A 20/20-like
rudder sequence, truth simulated with that process noise; position (1 m) and heading (1 deg)
measured at 10 Hz. Horizon N = 20 and N = 50. Estimates are compared from sample N on (when the
first full window exists); the time per sample is the median CPU time (``time.process_time``) of
one estimator update over those samples (casship: ``run.update`` of ``MHE.online``, including its
EKF arrival-cost step and the data shift). All estimators run in turn, five rounds; a ratio is
formed per round and reported as the median and range over the rounds.

* casship: ``MHE`` with the EKF-updated arrival cost, NLP built once per horizon, data as its
  parameters. ``solver="ipopt"``: IPOPT warm-started from the previous solution shifted by one stage
  and improved by one Gauss-Newton step, with that step's multipliers. ``solver="rti"``: real-time
  iteration, one Gauss-Newton step per sample. Interpreted (CasADi's virtual machine; the step
  solves the KKT system by sparse QR) and compiled (``jit``: the step is a Riccati recursion over
  the stages, compiled to C through the on-disk cache).
* plain: the textbook multiple-shooting MHE written directly in CasADi: MX decision variables per
  stage in a Python loop, ``nlpsol("ipopt")`` with default options (exact Hessian), data as NLP
  parameters, warm start from the previous solution, arrival cost from an EKF lagging N samples
  behind (its prediction at the first window sample).
* do-mpc: ``do_mpc.estimator.MHE`` on a discrete do-mpc model with the same step, noise weights
  ``P_w = (dt^2 Q)^-1``, ``P_v = R^-1``, measured inputs as noise-free measurements, arrival
  weight ``P_x = P0^-1`` on its previous estimate (do-mpc's own arrival cost).

Accuracy check: position/heading/speed RMSE from sample N on; the row passes when casship's
RMSE is within 5 % of (or below) the peer's for every state. do-mpc rows also give casship's RMSE
with do-mpc's arrival cost (``arrival="fixed"``, weight ``P0^-1``): it matches do-mpc's, so both
solve the same problem and the accuracy difference is the arrival cost.

Run ``python -m benchmarks.bench_mhe [--quick]``.
"""
from __future__ import annotations

import contextlib
import io
import sys
import time
import warnings

import casadi as ca
import numpy as np

import casship as cs
from benchmarks import format_table, row, skipped_row

DT = 0.1
QD = np.array([2e-3, 2e-3, 2e-6])                 # w_u, w_v, w_r (held over a step)
STD = {"x": 1.0, "y": 1.0, "psi": np.radians(1.0)}
P0 = np.diag([0.25, 0.04, 1e-5, 4.0, 4.0, 1e-3])


def problem(duration: float, seed: int = 0):
    """Model, Euler step, data (with ``true_*`` columns), prior and noise covariances."""
    model = cs.models.shi_taylor({"c1": 0.001}).with_outputs(["x", "y", "psi"])
    dm = cs.discretize(model, DT, "euler")
    t = np.arange(0.0, duration, DT)
    rng = np.random.default_rng(seed)
    delta = np.radians(20.0) * np.sign(np.sin(2 * np.pi * t / 40.0 + 0.3))
    W = rng.standard_normal((t.size, model.nw)) * np.sqrt(QD)
    x0 = model.states(u=6.0)
    traj = cs.simulate(model, x0, t, {"delta": delta, "n": 1.5}, method="euler", w=W)
    data = cs.measure(traj, model, STD, seed=rng, keep=model.state_names)
    prior = cs.Gaussian(x0 + rng.multivariate_normal(np.zeros(model.nx), P0), P0)
    R = np.diag([STD[n] ** 2 for n in ("x", "y", "psi")])
    return model, dm, data, prior, np.diag(QD), R


def _rmse(X, data, model, start):
    truth = data.matrix([f"true_{n}" for n in model.state_names])
    err = X[start:] - truth[start:]
    err[:, model.index("psi")] = cs.wrap(err[:, model.index("psi")])
    return np.sqrt(np.mean(err**2, axis=0))


# -- casship ---------------------------------------------------------------------------------------------
CLOCK = time.process_time      # CPU time of the process: not inflated by other jobs on a shared machine


def run_casship(dm, data, prior, Q, R, N, solver, jit=False, mhe=None):
    mhe = mhe or cs.MHE(dm, Q, R, options={"horizon": N, "solver": solver, "jit": jit})
    model = dm.model
    U = data.matrix(model.input_names)
    Y = data.matrix(mhe.measured)
    run = mhe.online(prior, u=U[0])
    X, times = np.empty((len(data), model.nx)), []
    for k in range(len(data)):
        t0 = CLOCK()
        X[k] = run.update(Y[k], DT if k else 0.0, u_prev=U[max(k - 1, 0)], u=U[k])
        times.append(CLOCK() - t0)
    return X, np.median(times[N:])


# -- plain CasADi + IPOPT -----------------------------------------------------------------------------------
def run_plain(dm, data, prior, Q, R, N):
    """A direct multiple-shooting MHE: one NLP with data as parameters, IPOPT defaults."""
    m = dm.model
    nx, nu, nw, ny = m.nx, m.nu, m.nw, 3
    Qi, Ri = np.linalg.inv(Q), np.linalg.inv(R)
    X = [ca.MX.sym(f"x{j}", nx) for j in range(N + 1)]
    Wv = [ca.MX.sym(f"w{j}", nw) for j in range(N)]
    Up = ca.MX.sym("U", nu, N + 1)
    Yp = ca.MX.sym("Y", ny, N + 1)
    xbar = ca.MX.sym("xbar", nx)
    Pinv = ca.MX.sym("Pinv", nx, nx)
    p = m.params()
    J = (X[0] - xbar).T @ Pinv @ (X[0] - xbar)
    g = []
    for j in range(N + 1):
        e = Yp[:, j] - m.h(X[j], Up[:, j], p)
        J += e.T @ Ri @ e
        if j < N:
            J += Wv[j].T @ Qi @ Wv[j]
            g.append(dm.F(X[j], Up[:, j], p, Wv[j], DT) - X[j + 1])
    z = ca.vertcat(*[v for j in range(N) for v in (X[j], Wv[j])], X[N])
    nlp = {"x": z, "p": ca.vertcat(ca.vec(Up), ca.vec(Yp), xbar, ca.vec(Pinv)), "f": J, "g": ca.vertcat(*g)}
    solver = ca.nlpsol("plain_mhe", "ipopt", nlp, {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes"}})
    ekf = cs.EKF(dm, Q, R).filter(data, prior)          # arrival cost: EKF N samples behind
    U = data.matrix(m.input_names)
    Y = data.matrix(["x", "y", "psi"])
    out = ekf.x.copy()
    times = []
    zk = None
    for k in range(N, len(data)):
        s = k - N
        par = np.concatenate([U[s:k + 1].ravel(), Y[s:k + 1].ravel(), ekf.x_pred[s],
                              np.linalg.inv(ekf.P_pred[s]).ravel()])
        if zk is None:
            zk = np.concatenate([np.concatenate([ekf.x[s + j], np.zeros(nw)]) for j in range(N)] + [ekf.x[k]])
        else:
            zk = np.concatenate([zk[nx + nw:], np.zeros(nw), zk[-nx:]])     # shift, repeat last state
        t0 = CLOCK()
        sol = solver(x0=zk, p=par, lbg=0, ubg=0)
        times.append(CLOCK() - t0)
        if not solver.stats()["success"]:
            raise RuntimeError(f"plain MHE failed at row {k}: {solver.stats()['return_status']}")
        zk = np.asarray(sol["x"]).ravel()
        out[k] = zk[-nx:]
    return out, np.median(times)


# -- do-mpc ----------------------------------------------------------------------------------------------
def run_dompc(dm, data, prior, Q, R, N):
    import do_mpc

    m = dm.model
    model = do_mpc.model.Model("discrete", "SX")
    xs = [model.set_variable("_x", n) for n in m.state_names]
    us = [model.set_variable("_u", n) for n in m.input_names]
    x, u = ca.vertcat(*xs), ca.vertcat(*us)
    xf = dm.F(x, u, m.params(), ca.DM.zeros(m.nw), DT)
    for i, n in enumerate(m.state_names):
        model.set_rhs(n, xf[i], process_noise=n in ("u", "v", "r"))
    y = m.h(x, u, m.params())
    for i, n in enumerate(("x", "y", "psi")):
        model.set_meas(f"{n}_meas", y[i], meas_noise=True)
    for i, n in enumerate(m.input_names):
        model.set_meas(f"{n}_input", us[i], meas_noise=False)
    model.setup()
    mhe = do_mpc.estimator.MHE(model)
    mhe.settings.n_horizon = N
    mhe.settings.t_step = DT
    mhe.settings.meas_from_data = True
    mhe.settings.nlpsol_opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": 0}
    mhe.set_default_objective(np.linalg.inv(prior.cov), P_v=np.linalg.inv(R),
                              P_w=np.linalg.inv(DT**2 * Q))
    mhe.setup()
    mhe.x0 = prior.mean
    mhe.set_initial_guess()
    U = data.matrix(m.input_names)
    Y = data.matrix(["x", "y", "psi"])
    out = np.empty((len(data), m.nx))
    times = []
    for k in range(len(data)):
        y0 = np.concatenate([Y[k], U[k]]).reshape(-1, 1)
        t0 = CLOCK()
        out[k] = np.asarray(mhe.make_step(y0)).ravel()
        times.append(CLOCK() - t0)
    return out, np.median(times[N:])


def _check(name, rm_c, rm_p):
    ok = bool(np.all(rm_c <= 1.05 * rm_p + 1e-12))
    show = lambda r: ", ".join(f"{v:.3g}" for v in r[[0, 1, 3, 5]])  # noqa: E731 (u, v, x, psi)
    return (f"RMSE u,v,x,psi casship [{show(rm_c)}] vs {name} [{show(rm_p)}]: "
            f"{'pass' if ok else 'FAIL'} (casship <= 1.05 peer)")


CASSHIP = (("ipopt", False), ("rti", False), ("ipopt", True), ("rti", True))


def _tag(solver, jit):
    return f"{solver}, {'compiled (jit)' if jit else 'interpreted'}"


def _dompc_quiet(*args):
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        return run_dompc(*args)


def main(quick: bool = False) -> list[dict]:
    """Per-sample times, median over the samples of a record, for casship (IPOPT and RTI, interpreted
    and compiled), do-mpc and the plain CasADi MHE, run in turn ``repeats`` times (so that all see
    the same machine load); ratios are formed per round and reported as median and range."""
    rows = []
    model, dm, data, prior, Q, R = problem(20.0 if quick else 60.0)
    repeats = 2 if quick else 5
    try:
        import do_mpc  # noqa: F401
        have_dompc = True
    except ImportError:
        have_dompc = False
    for N in (20, 50):
        ests = {c: cs.MHE(dm, Q, R, options={"horizon": N, "solver": c[0], "jit": c[1]}) for c in CASSHIP}
        times = {k: [] for k in (*CASSHIP, "plain", "do-mpc")}
        X = {}
        for _ in range(repeats):
            if have_dompc:
                X["do-mpc"], t = _dompc_quiet(dm, data, prior, Q, R, N)
                times["do-mpc"].append(t)
            X["plain"], t = run_plain(dm, data, prior, Q, R, N)
            times["plain"].append(t)
            for c in CASSHIP:
                X[c], t = run_casship(dm, data, prior, Q, R, N, *c, mhe=ests[c])
                times[c].append(t)
        rm = {k: _rmse(v, data, model, N) for k, v in X.items()}
        fixed = cs.MHE(dm, Q, R, options={"horizon": N, "arrival": "fixed"}).filter(data, prior)
        rm_f = _rmse(fixed.x, data, model, N)
        same = ("; casship with do-mpc's fixed-weight arrival cost: [" + ", ".join(f"{v:.3g}" for v in rm_f[[0, 1, 3, 5]])
                + "] (the accuracy gap is the arrival cost)")
        for peer, label in (("do-mpc", "do-mpc MHE"), ("plain", "plain CasADi+IPOPT")):
            for c in CASSHIP:
                name = f"MHE N={N} per sample, casship {_tag(*c)}"
                if peer == "do-mpc" and not have_dompc:
                    rows.append(skipped_row(name, label, "do-mpc not installed (pip install do-mpc)",
                                            float(np.median(times[c]))))
                    continue
                ratios = sorted(p / t for p, t in zip(times[peer], times[c]))
                check = _check(peer, rm[c], rm[peer]) + (same if peer == "do-mpc" else "")
                target = {("ipopt", True): "mhe_ipopt", ("rti", True): "mhe_rti"}.get(c) if N == 20 and peer == "do-mpc" else None
                r = row(name, float(np.median(times[c])), label, float(np.median(times[peer])), check,
                        below_dt_over_10=bool(np.median(times[c]) < DT / 10), repeats=repeats,
                        **({"target": target} if target else {}))
                r.update(ratio=float(np.median(ratios)), ratio_min=ratios[0], ratio_max=ratios[-1])
                rows.append(r)
    return rows


if __name__ == "__main__":
    print(format_table(main(quick="--quick" in sys.argv[1:])))
