"""Moving-horizon estimation: analytic equivalences, Monte Carlo accuracy, arrival cost, constraints."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
from casship.estimators import MHEFailed

Q_LIN, R_LIN = 1e-6, 1e-4


def linear_case(seed=1, duration=60.0, dt=0.5, psi0=0.0, gaps=True):
    """Nomoto (linear) with process noise, heading measured with a gap of missing samples."""
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, dt, "rk4")
    t = np.arange(0.0, duration, dt)
    rng = np.random.default_rng(seed)
    delta = 0.1 * np.sign(np.sin(2 * np.pi * t / 20.0))
    W = rng.standard_normal((t.size, 1)) * np.sqrt(Q_LIN)
    tr = cs.simulate(m, m.states(psi=psi0), t, {"delta": delta}, w=W)
    data = cs.measure(tr, m, {"psi": np.sqrt(R_LIN)}, seed=rng, keep=("psi", "r"))
    if gaps:
        y = data["psi"].copy()
        y[5:9] = np.nan
        y[30 % y.size] = np.nan
        data = data.with_columns(psi=y)
    prior = cs.Gaussian([psi0 + 0.01, 0.0], [1e-3, 1e-5])
    return m, dm, tr, data, prior


def psi_err(a, b):
    return cs.wrap(np.asarray(a) - np.asarray(b))


@pytest.mark.parametrize("solver", ["ipopt", "fatrop", "sqp", "rti"])
@pytest.mark.parametrize("N", [1, 4])
def test_linear_mhe_equals_kalman_filter(solver, N):
    _, dm, _, data, prior = linear_case()
    kf = cs.KF(dm, Q_LIN, R_LIN).filter(data, prior)
    res = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": N, "solver": solver}).filter(data, prior)
    scale = np.abs(kf.x).max(axis=0)
    assert np.all(np.abs(res.x - kf.x).max(axis=0) <= 1e-7 * scale)
    np.testing.assert_allclose(res.P, kf.P, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(res.x_pred, kf.x_pred, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(res.loglik, kf.loglik, rtol=1e-6)
    assert np.isnan(res.innovations[5:9]).all() and np.isfinite(res.innovations[9:30]).all()


def test_full_information_equals_rts_smoother():
    _, dm, _, data, prior = linear_case()
    smooth = cs.KF(dm, Q_LIN, R_LIN).smooth(data, prior)
    full = cs.MHE(dm, Q_LIN, R_LIN).smooth(data, prior)
    assert full.estimator == "MHE-full"
    np.testing.assert_allclose(full.x, smooth.x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(full.P, smooth.P, rtol=1e-8, atol=1e-16)
    # the moving window as long as the record is full-information estimation: its last state is
    # the filtered (= smoothed) estimate at the end
    growing = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": len(data) - 1}).filter(data, prior)
    np.testing.assert_allclose(growing.x[-1], smooth.x[-1], atol=1e-9)


def test_heading_across_pi_is_wrapped():
    _, dm, _, data, prior = linear_case(psi0=np.pi - 0.05, gaps=False)
    psi_m = data["psi"]
    assert psi_m.max() > 3.0 and psi_m.min() < -3.0          # the record crosses +-pi
    kf = cs.KF(dm, Q_LIN, R_LIN).filter(data, prior)
    res = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 5, "solver": "rti"}).filter(data, prior)
    assert np.abs(psi_err(res["psi"], kf["psi"])).max() < 1e-7
    np.testing.assert_allclose(res["r"], kf["r"], atol=1e-9)


def test_online_runner_reproduces_filter():
    _, dm, _, data, prior = linear_case(duration=20.0)
    mhe = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 6, "solver": "ipopt", "outputs": "all"})
    batch = mhe.filter(data, prior)
    U, Y = data.matrix(["delta"]), data.matrix(["psi"])
    run = mhe.online(prior, u=U[0])
    for k in range(len(data)):
        dt = data.t[k] - data.t[k - 1] if k else 0.0
        x = run.update(Y[k], dt, u_prev=U[max(k - 1, 0)], u=U[k])
        np.testing.assert_allclose(x, batch.x[k], atol=1e-10)
        np.testing.assert_allclose(run.P, batch.P[k], atol=1e-14)
        assert np.isnan(run.info["e"]).all() == np.isnan(Y[k]).all()
        assert run.info["nis"] == pytest.approx(batch.nis[k], rel=1e-9, abs=1e-12)
    with pytest.raises(ValueError, match=r"y must hold 1 value for \['psi'\]"):
        run.update([0.0, 0.0], 0.5)


def gps_case(seed, duration=60.0, dt=0.5):
    """Nonlinear: Taylor response model, position only, uncertain initial heading (matched model)."""
    m = cs.models.shi_taylor().with_outputs(["x", "y"])
    dm = cs.discretize(m, dt, "rk4")
    t = np.arange(0.0, duration, dt)
    rng = np.random.default_rng(seed)
    Qd = np.array([1e-4, 1e-4, 1e-6])
    W = rng.standard_normal((t.size, 3)) * np.sqrt(Qd)
    x0 = m.states(u=8.0)
    tr = cs.simulate(m, x0, t, {"delta": 0.3 * np.sign(np.sin(2 * np.pi * t / 40)), "n": 1.5}, w=W)
    data = cs.measure(tr, m, {"x": 1.0, "y": 1.0}, seed=rng)
    P0 = np.diag([1.0, 0.25, 1e-4, 4.0, 4.0, 1.0])
    prior = cs.Gaussian(x0 + rng.multivariate_normal(np.zeros(6), P0), P0)
    return m, dm, tr, data, prior, Qd, {"x": 1.0, "y": 1.0}


def rmse(est, truth, angle_cols=(5,)):
    err = est - truth
    for c in angle_cols:
        err[:, c] = cs.wrap(err[:, c])
    return np.sqrt(np.mean(err**2, axis=0))


def test_nonlinear_mhe_beats_ekf_monte_carlo():
    ekf_rmse, mhe_rmse = [], []
    for seed in range(4):
        m, dm, tr, data, prior, Qd, R = gps_case(seed)
        ekf = cs.EKF(dm, Qd, R).filter(data, prior)
        mhe = cs.MHE(dm, Qd, R, options={"horizon": 10}).filter(data, prior)
        ekf_rmse.append(rmse(ekf.x, tr.x))
        mhe_rmse.append(rmse(mhe.x, tr.x))
    ekf_mean, mhe_mean = np.mean(ekf_rmse, axis=0), np.mean(mhe_rmse, axis=0)
    assert np.all(mhe_mean <= ekf_mean), (mhe_mean, ekf_mean)
    assert mhe_mean[0] < 0.8 * ekf_mean[0]        # surge speed: the clearest gain


def test_fatrop_gives_ipopt_estimates_to_solver_tolerance():
    """A nonlinear window with a Huber cost (the Gauss-Newton warm start is not the optimum, so both
    solvers iterate): fatrop, exploiting the stage structure, and IPOPT reach the same estimates."""
    m, dm, tr, data, prior, Qd, R = gps_case(0, duration=30.0)
    res = {}
    for solver in ("ipopt", "fatrop"):
        mhe = cs.MHE(dm, Qd, R, options={"horizon": 10, "solver": solver, "huber": 1.0, "tol": 1e-9})
        res[solver] = mhe.filter(data, prior)
        assert mhe.window(10).solver.name() == f"mhe_{solver}_10"
    scale = np.abs(res["ipopt"].x).max(axis=0)
    assert np.all(np.abs(res["fatrop"].x - res["ipopt"].x).max(axis=0) <= 1e-7 * scale)
    # and the estimates are not simply the start point: the Huber cost moves them off the quadratic one
    plain = cs.MHE(dm, Qd, R, options={"horizon": 10}).filter(data, prior)
    assert np.abs(plain.x - res["ipopt"].x).max() > 1e3 * np.abs(res["fatrop"].x - res["ipopt"].x).max()


def test_solver_is_skipped_only_where_the_warm_start_solves_the_window(monkeypatch):
    """Where the Gauss-Newton warm start already meets the first-order conditions to the solver's
    tolerance, IPOPT is not called; the estimates equal those with IPOPT called on every window."""
    import casship.estimators.mhe.solvers as solvers

    m, dm, tr, data, prior, Qd, R = gps_case(1, duration=20.0)
    check, accepted = solvers.first_order_optimal, []
    monkeypatch.setattr(solvers, "first_order_optimal", lambda *a: accepted.append(check(*a)) or accepted[-1])
    skipping = cs.MHE(dm, Qd, R, options={"horizon": 10}).filter(data, prior)
    assert 0 < sum(accepted) < len(accepted)          # both happen on this record
    monkeypatch.setattr(solvers, "first_order_optimal", lambda *a: False)
    always = cs.MHE(dm, Qd, R, options={"horizon": 10}).filter(data, prior)
    scale = np.abs(always.x).max(axis=0)
    assert np.all(np.abs(skipping.x - always.x).max(axis=0) <= 1e-7 * scale)


def test_every_accepted_option_is_honoured_or_refused():
    _, dm, _, data, prior = linear_case(duration=10.0)
    # refused: the gate (the MHE uses every sample; Huber is its guard), a QP solver the solver lacks
    with pytest.raises(ValueError, match="MHE has no innovation gate; use option 'huber'"):
        cs.MHE(dm, Q_LIN, R_LIN, options={"gate": 0.99})
    for solver in ("ipopt", "fatrop"):
        with pytest.raises(ValueError, match=f"option 'qpsol' is the QP solver of solvers 'sqp' and 'rti'; "
                                             f"solver '{solver}' has none"):
            cs.MHE(dm, Q_LIN, R_LIN, options={"solver": solver, "qpsol": "osqp"})
    assert cs.MHE(dm, Q_LIN, R_LIN, options={"solver": "rti"}).options.qpsol == "qrqp"
    with pytest.raises(ValueError, match="explicit discretisation"):
        cs.MHE(cs.discretize(dm.model, 0.5, "cvodes"), Q_LIN, R_LIN)
    # expand: by the rule (a small window is expanded, one past EXPAND_NODES is not), or as asked;
    # the estimates are the same either way
    from casship.estimators.mhe.problem import EXPAND_NODES, stage_nodes

    auto = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4})
    assert auto.window(4).expanded and auto.window(4).solver.oracle().is_a("SXFunction")
    big = EXPAND_NODES // stage_nodes(auto) + 1
    assert not auto.window(big).expanded and auto.window(big).solver.oracle().is_a("MXFunction")
    plain = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4, "expand": False})
    assert not plain.window(4).expanded
    np.testing.assert_allclose(plain.filter(data, prior).x, auto.filter(data, prior).x, rtol=0, atol=1e-10)
    # outputs: what the online run reports besides x and P
    lean = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4, "outputs": ("x", "P", "nis", "e")}).online(prior)
    lean.update(data.matrix(["psi"])[0], 0.0)
    assert set(lean.info) == {"nis", "e", "solve_time"}
    full = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4, "outputs": "all"}).online(prior)
    full.update(data.matrix(["psi"])[0], 0.0)
    assert set(full.info) == {"x_pred", "P_pred", "C", "e", "S", "K", "nis", "ll", "rejected", "solve_time"}
    with pytest.raises(KeyError):
        lean.info["K"]
    # time gaps: the options of every estimator, in batch, smoothing and online alike
    t = data.t + np.where(np.arange(len(data)) >= 10, 20.0, 0.0)
    gapped = cs.Dataset(t, {"delta": data["delta"], "psi": data["psi"]})
    capped = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4, "max_gap": 5.0})
    for run in (capped.filter, capped.smooth):
        with pytest.raises(ValueError, match="MHE: time gap of 20.5 s between t = 4.5 and 25 s .* longer than 5 s"):
            run(gapped, prior)
    bridged = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4, "max_gap": 5.0, "on_gap": "bridge"})
    with pytest.warns(UserWarning, match="bridged by 8 prediction-only row"):
        sm = bridged.smooth(gapped, prior)
    with pytest.warns(UserWarning, match="bridged by 8 prediction-only row"):
        kf = cs.KF(dm, Q_LIN, R_LIN, options={"max_gap": 5.0, "on_gap": "bridge"}).smooth(gapped, prior)
    np.testing.assert_allclose(sm.x, kf.x, rtol=0, atol=1e-9)       # full information = RTS, across the gap


def test_the_mhe_has_no_step_function():
    _, dm, _, data, prior = linear_case(duration=5.0)
    mhe = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4})
    assert not hasattr(mhe, "step") and not hasattr(cs.MHE, "step")
    with pytest.raises(TypeError, match="MLEProblem folds a recursive estimator's step"):
        cs.MLEProblem(mhe, data, free=["K"])
    # the EKF that supplies the arrival cost is an estimator of its own, with its step
    assert isinstance(mhe.arrival_filter, cs.EKF)
    assert mhe.arrival_filter.step.name_in()[:2] == ["x", "P"]


def test_arrival_cost_does_not_double_count():
    """KF is optimal on a linear model: the EKF-updated arrival cost matches it, the fixed-weight
    prior centred on the previous window's estimate (data counted twice) is clearly worse, even
    with the stationary covariance as its weight."""
    kf_r, ekf_r, fixed_r = [], [], []
    for seed in range(3):
        _, dm, tr, data, _ = linear_case(seed=seed, duration=100.0, gaps=False)
        kf0 = cs.KF(dm, Q_LIN, R_LIN).filter(data, cs.Gaussian([0, 0], [1e-2, 1e-4]))
        P_inf = kf0.P_pred[-1]
        prior = cs.Gaussian(np.zeros(2), P_inf)
        kf = cs.KF(dm, Q_LIN, R_LIN).filter(data, prior)
        kf_r.append(rmse(kf.x, tr.x, (0,)))
        for arrival, out in (("ekf", ekf_r), ("fixed", fixed_r)):
            res = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 3, "arrival": arrival, "solver": "rti"}
                         ).filter(data, prior)
            out.append(rmse(res.x, tr.x, (0,)))
    kf_m, ekf_m, fixed_m = (np.mean(a, axis=0) for a in (kf_r, ekf_r, fixed_r))
    np.testing.assert_allclose(ekf_m, kf_m, rtol=1e-6)
    assert fixed_m[0] > 1.1 * kf_m[0]


def test_huber_loss_resists_outliers():
    _, dm, tr, data, prior = linear_case(seed=5, gaps=False)
    y = data["psi"].copy()
    rng = np.random.default_rng(7)
    bad = rng.choice(np.arange(10, y.size), size=8, replace=False)
    y[bad] += rng.choice([-1, 1], size=bad.size) * 0.3
    data = data.with_columns(psi=y)
    plain = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 8}).filter(data, prior)
    robust = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 8, "huber": 2.0}).filter(data, prior)
    e_plain = rmse(plain.x, tr.x, (0,))
    e_robust = rmse(robust.x, tr.x, (0,))
    assert np.all(e_robust < 0.5 * e_plain), (e_robust, e_plain)


@pytest.mark.parametrize("solver", ["ipopt", "fatrop", "sqp", "rti"])
def test_state_and_noise_bounds_respected(solver):
    _, dm, _, data, prior = linear_case(gaps=False)
    kf = cs.KF(dm, Q_LIN, R_LIN).filter(data, prior)
    cap = 0.5 * np.abs(kf["r"]).max()
    mhe = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 4, "solver": solver, "bounds": {"r": (-cap, cap)},
                                              "noise_bounds": {"w_r": (-5e-4, 5e-4)}})
    res = mhe.filter(data, prior)
    # fatrop relaxes every bound by about 1e-8 (absolute) and has no option to turn that off; IPOPT
    # runs with bound_relax_factor = 0 (docs/mhe.md)
    relax = 1e-8 if solver == "fatrop" else 0.0
    assert np.all(np.abs(res["r"]) <= cap * (1 + 1e-6) + relax)
    assert np.abs(res["r"]).max() > 0.99 * cap          # the bound is active
    assert np.abs(res["psi"] - kf["psi"]).max() < 0.05


@pytest.mark.parametrize("solver", ["ipopt", "fatrop", "sqp", "rti"])
def test_solver_failure_raises_with_status(solver):
    _, dm, _, data, prior = linear_case(gaps=False)
    # no process noise allowed and r pinned to zero while the rudder turns the ship: infeasible
    mhe = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 3, "solver": solver, "bounds": {"r": (0.0, 0.0)},
                                              "noise_bounds": {"w_r": (0.0, 0.0)}})
    with pytest.raises(MHEFailed, match="status") as info:
        mhe.filter(data, prior)
    assert info.value.status not in ("Solve_Succeeded", "")
    if solver != "ipopt":
        return
    # a Huber cost, so that the Gauss-Newton warm start is not already the optimum, as it is for a
    # linear model with a quadratic cost
    short = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 3, "max_iter": 0, "huber": 0.5})
    with pytest.raises(RuntimeError, match="Maximum_Iterations_Exceeded"):
        short.filter(data, prior)


def test_parameter_and_disturbance_estimation():
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, 0.5, "rk4")
    t = np.arange(0.0, 200.0, 0.5)
    delta = 0.1 * np.sign(np.sin(2 * np.pi * t / 30))
    prior = cs.Gaussian([0.0, 0.0], [1e-4, 1e-6])
    # constant parameter: K true 0.15, nominal 0.1
    data = cs.measure(cs.simulate(m, m.states(), t, {"delta": delta}, p={"K": 0.15}), m, {"psi": 0.01}, seed=3)
    mhe = cs.MHE(dm, 1e-10, 1e-4, options={"horizon": 20, "estimate": {"K": 0.05}, "bounds": {"K": (0.0, 0.5)}})
    res = mhe.filter(data, prior)
    assert res.state_names == ("psi", "r", "K")
    assert abs(res["K"][-1] - 0.15) < 3 * res.std[-1, 2] and res.std[-1, 2] < 0.01
    # an unmodelled constant yaw moment, estimated as a random-walk disturbance on r'
    push = m.extend(lambda b: b.add_to_ode(r=b.param("N_ext", 5e-4)), name="nomoto+push")
    data2 = cs.measure(cs.simulate(push, push.states(), t, {"delta": delta}), push, {"psi": 0.01}, seed=4,
                       keep=("r",))
    mhe2 = cs.MHE(dm, 1e-10, 1e-4, options={"horizon": 20, "disturbances": {"r": (1e-10, 1e-3)}})
    res2 = mhe2.filter(data2, prior)
    assert res2.state_names == ("psi", "r", "d_r")
    assert abs(res2["d_r"][-1] - 5e-4) < 3 * res2.std[-1, 2]
    ekf = cs.EKF(dm, 1e-10, 1e-4).filter(data2, prior)
    assert rmse(res2.x[:, 1:2], data2["true_r"][:, None], ())[0] < 0.3 * rmse(ekf.x[:, 1:2], data2["true_r"][:, None], ())[0]


def test_augment_model_names():
    m = cs.models.nomoto_first_order()
    aug = cs.augment(m, ["K"], disturbances=["r"])
    assert aug.state_names == ("psi", "r", "K", "d_r")
    assert aug.noise_names == ("w_r", "w_K", "w_d_r")
    assert "K" not in aug.param_names


def test_bad_input_raises_naming_the_item():
    m = cs.models.nomoto_first_order()
    dm = cs.discretize(m, 0.5)
    with pytest.raises(ValueError, match="horizn"):
        cs.MHE(dm, 1e-6, 1e-4, options={"horizn": 5})
    with pytest.raises(ValueError, match="solver"):
        cs.MHE(dm, 1e-6, 1e-4, options={"solver": "newton"})
    with pytest.raises(ValueError, match="'u'"):
        cs.MHE(dm, 1e-6, 1e-4, options={"disturbances": {"u": 1e-6}})
    with pytest.raises(ValueError, match="Kp"):
        cs.MHE(dm, 1e-6, 1e-4, options={"estimate": {"Kp": 0.1}})
    with pytest.raises(ValueError, match="'r'"):
        cs.MHE(dm, 1e-6, 1e-4, options={"bounds": {"r": (1.0, -1.0)}})
    with pytest.raises(ValueError, match="huber"):
        cs.MHE(dm, 1e-6, 1e-4, options={"huber": -1.0})
    _, dm2, _, data, prior = linear_case(duration=5.0)
    bad = data.with_columns(delta=np.where(np.arange(len(data)) == 3, np.nan, data["delta"]))
    with pytest.raises(ValueError, match="delta"):
        cs.MHE(dm2, 1e-6, 1e-4).filter(bad, prior)
    with pytest.raises(ValueError, match="prior has 3"):
        cs.MHE(dm2, 1e-6, 1e-4).filter(data, cs.Gaussian(np.zeros(3), 1.0))


def test_all_missing_window_predicts():
    _, dm, _, data, prior = linear_case(gaps=False)
    y = data["psi"].copy()
    y[10:25] = np.nan                                   # longer than the horizon
    data = data.with_columns(psi=y)
    kf = cs.KF(dm, Q_LIN, R_LIN).filter(data, prior)
    res = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 5, "solver": "rti"}).filter(data, prior)
    np.testing.assert_allclose(res.x, kf.x, atol=1e-9)
    assert (res.n_measured[10:25] == 0).all()


def test_correlated_measurement_noise_and_partial_rows_equal_kf():
    """Non-diagonal R with rows where only some channels are measured (whitening of the measured block)."""
    m = cs.models.tomera_kinematic()
    dm = cs.discretize(m, 0.5, "rk4")
    t = np.arange(0.0, 30.0, 0.5)
    rng = np.random.default_rng(11)
    W = rng.standard_normal((t.size, m.nw)) * 1e-2
    tr = cs.simulate(m, m.states(vx=1.0, vy=0.5, r=0.01), t, w=W)
    R = np.array([[1.0, 0.6, 0.0], [0.6, 2.0, 0.01], [0.0, 0.01, 1e-3]])
    noise = rng.multivariate_normal(np.zeros(3), R, t.size)
    Y = tr.matrix(["x", "y", "psi"]) + noise
    Y[3:7, 1] = np.nan                   # y missing, x and psi measured
    Y[10, :2] = np.nan
    data = cs.Dataset(t, {"x": Y[:, 0], "y": Y[:, 1], "psi": cs.wrap(Y[:, 2])})
    Q = np.full(m.nw, 1e-4)
    prior = cs.Gaussian(m.states(vx=1.0), np.eye(m.nx))
    kf = cs.KF(dm, Q, R).filter(data, prior)
    res = cs.MHE(dm, Q, R, options={"horizon": 3, "solver": "rti"}).filter(data, prior)
    np.testing.assert_allclose(res.x, kf.x, atol=1e-8)


def test_irregular_time_stamps_equal_kf():
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, 0.5, "rk4")
    rng = np.random.default_rng(21)
    t = np.cumsum(rng.uniform(0.2, 1.0, 80))
    tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(2 * np.pi * t / 20.0))})
    data = cs.measure(tr, m, {"psi": 0.01}, seed=rng)
    prior = cs.Gaussian([0.0, 0.0], [1e-3, 1e-5])
    kf = cs.KF(dm, Q_LIN, R_LIN).filter(data, prior)
    for solver in ("ipopt", "rti"):
        res = cs.MHE(dm, Q_LIN, R_LIN, options={"horizon": 6, "solver": solver}).filter(data, prior)
        np.testing.assert_allclose(res.x, kf.x, atol=1e-9)
