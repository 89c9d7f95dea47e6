"""Discretisation: convergence orders, CVODES accuracy, Van Loan, exact step Jacobians."""
import numpy as np
import pytest
import scipy.linalg

import casship as cs
from casship.models import nomoto_first_order, shi_taylor, sog_cog


def oscillator(omega=2.0):
    """Undamped oscillator ``q'' = -omega^2 q + u`` with the exact solution known in closed form."""
    b = cs.ModelBuilder("oscillator")
    q, v = b.state("q"), b.state("v")
    u = b.input("u")
    om = b.param("omega", omega)
    b.ode(q=v, v=-om**2 * q + u + b.noise("w"))
    b.output("q", q)
    return b.build()


def logistic():
    b = cs.ModelBuilder("logistic")
    x = b.state("x")
    b.ode(x=b.param("k", 1.0) * x * (1 - x))
    return b.build()


def final_error(method, dt, T=2.0, omega=2.0):
    m = oscillator(omega)
    dm = cs.discretize(m, dt, method=method)
    n = int(round(T / dt))
    X = dm.fold(n)([1.0, 0.0], np.zeros((1, n)), m.params(), np.zeros((1, n)), dt)
    exact = [np.cos(omega * T), -omega * np.sin(omega * T)]
    return np.linalg.norm(np.array(X)[:, -1] - exact)


@pytest.mark.parametrize("method, order", [("euler", 1), ("rk4", 4)])
def test_convergence_order(method, order):
    steps = [0.02, 0.01, 0.005] if method == "euler" else [0.1, 0.05, 0.025]
    errors = [final_error(method, dt) for dt in steps]
    observed = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    np.testing.assert_allclose(observed, order, atol=0.1)


def test_rk4_substeps_equal_smaller_steps():
    m = shi_taylor()
    x = m.states(u=8.0, v=0.1, r=0.01, psi=0.3)
    uu = [0.1, 1.5]
    one = cs.discretize(m, 0.5, method="rk4", substeps=4).step(x, uu)
    small = cs.discretize(m, 0.125, method="rk4")
    y = x
    for _ in range(4):
        y = small.step(y, uu)
    np.testing.assert_allclose(one, y, rtol=1e-14, atol=1e-14)


def test_cvodes_matches_the_logistic_solution():
    m = logistic()
    dm = cs.discretize(m, 1.0, method="cvodes")
    for x0, dt in ((0.1, 1.0), (0.5, 2.5), (0.9, 0.3)):
        exact = 1.0 / (1.0 + (1.0 / x0 - 1.0) * np.exp(-dt))
        assert dm.step([x0], [], dt=dt)[0] == pytest.approx(exact, rel=1e-8)


def test_dt_is_an_argument_and_f_nominal_binds_it():
    m = nomoto_first_order()
    dm = cs.discretize(m, 0.2)
    x, u, p, w = [0.1, 0.01], [0.05], m.params(), [0.0]
    np.testing.assert_array_equal(np.array(dm.F_nominal(x, u, p, w)), np.array(dm.F(x, u, p, w, 0.2)))
    assert not np.allclose(np.array(dm.F(x, u, p, w, 0.4)), np.array(dm.F(x, u, p, w, 0.2)))
    assert dm.F.name_in() == ["x", "u", "p", "w", "dt"] and dm.F_jac.name_out() == ["A", "B", "Fp", "G"]


def test_fold_equals_repeated_steps():
    m = sog_cog()
    dm = cs.discretize(m, 0.5)
    rng = np.random.default_rng(3)
    W = rng.normal(size=(m.nw, 7)) * 0.01
    x = np.array([0.0, 0.0, 5.0, 0.3, 0.01])
    X = np.array(dm.fold(7)(x, np.zeros((0, 7)), m.params(), W, 0.5))
    for k in range(7):
        x = dm.step(x, [], w=W[:, k])
        np.testing.assert_allclose(X[:, k], x, rtol=1e-15, atol=1e-15)
    assert dm.fold(7) is dm.fold(7)


# -- Van Loan --------------------------------------------------------------------------------------

def test_van_loan_scalar_ornstein_uhlenbeck():
    a, q, dt = 0.7, 2.0, 0.3
    Ad, Qd = cs.van_loan(-a, 1.0, q, dt)
    assert Ad[0, 0] == pytest.approx(np.exp(-a * dt), rel=1e-14)
    assert Qd[0, 0] == pytest.approx(q / (2 * a) * (1 - np.exp(-2 * a * dt)), rel=1e-12)


def test_van_loan_double_integrator():
    q, dt = 0.3, 0.7
    Ad, Qd = cs.van_loan([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], q, dt)
    np.testing.assert_allclose(Ad, [[1.0, dt], [0.0, 1.0]], rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(Qd, q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]), rtol=1e-12)


def test_process_noise_uses_the_exact_linearisation():
    """Undamped oscillator: e^{As} G = [sin(ws)/w, cos(ws)], so Qd is known in closed form."""
    w, q, dt = 1.5, 0.2, 0.4
    m = oscillator(w)
    Qd = cs.discretize(m, dt).process_noise(q, m.states(), m.inputs())
    s2 = np.sin(2 * w * dt) / (4 * w)
    exact = q * np.array([[(dt / 2 - s2) / w**2, np.sin(w * dt) ** 2 / (2 * w**2)],
                          [np.sin(w * dt) ** 2 / (2 * w**2), dt / 2 + s2]])
    np.testing.assert_allclose(Qd, exact, rtol=1e-12)


def test_rk4_linearisation_approximates_the_matrix_exponential():
    m = oscillator(1.0)
    A, B, G = cs.discretize(m, 0.1).linearize(m.states(), m.inputs())
    Ad = scipy.linalg.expm(np.array([[0.0, 1.0], [-1.0, 0.0]]) * 0.1)
    np.testing.assert_allclose(A, Ad, atol=1e-7)   # RK4 local error O(dt^5) = 1e-5 / 120


# -- exact step Jacobians vs central differences ---------------------------------------------------

def central(fun, args, k, h=1e-6):
    args = [np.asarray(a, dtype=float) for a in args]
    cols = []
    for i in range(args[k].size):
        step = h * max(1.0, abs(args[k][i]))
        plus, minus = [a.copy() for a in args], [a.copy() for a in args]
        plus[k][i] += step
        minus[k][i] -= step
        cols.append((np.array(fun(*plus)).ravel() - np.array(fun(*minus)).ravel()) / (2 * step))
    return np.column_stack(cols)


@pytest.mark.parametrize("method, rtol", [("euler", 1e-6), ("rk4", 1e-6), ("cvodes", 1e-6)])
def test_step_jacobians_match_central_differences(method, rtol):
    m = shi_taylor()
    if method == "cvodes":
        # tight tolerances and a larger difference step, so that the reference is not the weak side
        dm = cs.discretize(m, 0.5, method=method, options={"abstol": 1e-14, "reltol": 1e-14})
        h = 1e-4
    else:
        dm, h = cs.discretize(m, 0.5, method=method, substeps=2), 1e-6
    rng = np.random.default_rng(11)
    x = m.states(u=7.5, v=0.2, r=0.02, x=3.0, y=-1.0, psi=0.4)
    u = np.array([0.15, 1.4])
    p = m.params() * rng.uniform(0.9, 1.1, m.np)
    w = rng.normal(scale=0.01, size=m.nw)
    exact = dm.F_jac(x, u, p, w, 0.5)
    for k, label in enumerate(("A", "B", "Fp", "G")):
        approx = central(dm.F, (x, u, p, w, 0.5), k, h)
        J = np.array(exact[k])
        np.testing.assert_allclose(J, approx, rtol=rtol, atol=rtol * max(1.0, np.abs(J).max()), err_msg=label)


@pytest.mark.parametrize("kwargs, match", [
    ({"dt": 0.1, "method": "heun"}, "unknown discretisation method 'heun'"),
    ({"dt": 0.0}, "dt must be a positive finite number"),
    ({"dt": np.nan}, "dt must be a positive finite number"),
    ({"dt": 0.1, "substeps": 0}, "substeps must be >= 1"),
    ({"dt": 0.1, "method": "rk4", "options": {"abstol": 1e-6}}, r"options \['abstol'\] apply to method 'cvodes' only"),
])
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        cs.discretize(nomoto_first_order(), **kwargs)
    with pytest.raises(ValueError, match="fold length"):
        cs.discretize(nomoto_first_order(), 0.1).fold(0)


def test_cvodes_step_drives_the_ekf():
    """An adaptive-integrator discretisation (MX) works in the estimators like the explicit ones."""
    m = nomoto_first_order()
    t = np.arange(0.0, 100.0, 0.5)
    truth = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sin(t / 10.0)})
    data = cs.measure(truth, m, {"psi": 0.01}, seed=0)
    prior = cs.Gaussian(m.states(), [1e-2, 1e-4])
    adaptive = cs.EKF(cs.discretize(m, 0.5, method="cvodes"), Q=1e-8, R=1e-4).filter(data, prior)
    fine = cs.EKF(cs.discretize(m, 0.5, method="rk4", substeps=20), Q=1e-8, R=1e-4).filter(data, prior)
    np.testing.assert_allclose(adaptive.x, fine.x, atol=1e-7)
    np.testing.assert_allclose(adaptive.P, fine.P, rtol=1e-6, atol=1e-12)
    assert adaptive.loglik == pytest.approx(fine.loglik, rel=1e-7)


# -- discrete-time authoring ----------------------------------------------------------------------------

def constant_velocity(dt=0.5):
    """x[k+1] = F x[k] + w with the discrete noise w of one step (covariance Qd given directly)."""
    b = cs.ModelBuilder("cv", "constant velocity, written in discrete time", dt=dt)
    x, v = b.state("x", unit="m"), b.state("v", unit="m/s")
    b.next(x=x + dt * v + b.noise("w_x"), v=v + b.noise("w_v"))
    b.output("x_m", x)
    return b.build()


def test_discrete_model_steps_exactly_and_only_on_its_grid():
    m = constant_velocity()
    assert m.dt == 0.5
    dm = cs.discretize(m)
    assert dm.discrete and dm.method == "discrete" and cs.discretize(m, 0.5).discrete
    xf = dm.step([1.0, 2.0], [], w=[0.1, -0.2])
    np.testing.assert_allclose(xf, [1.0 + 0.5 * 2.0 + 0.1, 2.0 - 0.2], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(dm.step([1.0, 2.0], [], dt=0.0), [1.0, 2.0])     # a zero step is no step
    tr = cs.simulate(m, m.states(v=1.0), np.arange(0.0, 5.0, 0.5))
    np.testing.assert_allclose(tr["x"], np.arange(10) * 0.5, atol=1e-13)
    with pytest.raises(ValueError, match="steps dt = 0.5 s; row 1"):
        cs.simulate(m, m.states(), np.arange(0.0, 3.0, 0.3))
    with pytest.raises(ValueError, match="discrete-time with dt = 0.5"):
        cs.discretize(m, 0.1)
    with pytest.raises(ValueError, match="no method"):
        cs.discretize(m, method="rk4")
    with pytest.raises(ValueError, match="discrete-time"):
        cs.simulate(m, m.states(), np.arange(0.0, 3.0, 0.5), method="euler")


def test_discrete_and_continuous_builders_refuse_the_other_kind():
    b = cs.ModelBuilder("d", dt=0.1)
    x = b.state("x")
    with pytest.raises(ValueError, match="next"):
        b.ode(x=-x)
    c = cs.ModelBuilder("c")
    y = c.state("y")
    with pytest.raises(ValueError, match="continuous-time"):
        c.next(y=y)
    with pytest.raises(ValueError, match="positive sampling period"):
        cs.ModelBuilder("bad", dt=0.0)
    with pytest.raises(ValueError, match="not a declared state"):
        b.next(z=x)


def test_discrete_model_filters_like_the_textbook_kf_and_dlqe():
    """KF on a model written in discrete time with Qd given directly: equal to a plain numpy KF and,
    at the end, to control.dlqe; every estimator that runs in discrete time accepts the model."""
    import control

    m = constant_velocity()
    dm = cs.discretize(m)
    Qd = 0.01 * np.array([[0.5**4 / 4, 0.5**3 / 2], [0.5**3 / 2, 0.5**2]])
    t = np.arange(0.0, 100.0, 0.5)
    rng = np.random.default_rng(1)
    tr = cs.simulate(m, m.states(v=1.0), t, w=rng.multivariate_normal([0.0, 0.0], Qd, t.size))
    data = cs.measure(tr, m, {"x_m": 0.5}, seed=2)
    prior = cs.Gaussian([0.0, 0.0], [1.0, 1.0])
    kf = cs.KF(dm, Qd, 0.25).filter(data, prior)
    F, H = np.array([[1.0, 0.5], [0.0, 1.0]]), np.array([[1.0, 0.0]])
    x, P = prior.mean.copy(), prior.cov.copy()
    for k, y in enumerate(data["x_m"]):
        if k:
            x, P = F @ x, F @ P @ F.T + Qd
        K = P @ H.T / (H @ P @ H.T + 0.25)
        x, P = x + (K * (y - H @ x)).ravel(), (np.eye(2) - K @ H) @ P @ (np.eye(2) - K @ H).T + 0.25 * K @ K.T
        np.testing.assert_allclose(kf.x[k], x, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(kf.P[k], P, rtol=1e-10, atol=1e-14)
    L, Pss, _ = control.dlqe(F, np.eye(2), H, Qd, np.array([[0.25]]))
    np.testing.assert_allclose(kf.P_pred[-1], Pss, rtol=1e-9)
    L2, P2 = cs.KF(dm, Qd, 0.25).steady_state()
    np.testing.assert_allclose(L2, L, rtol=1e-10)
    for est in (cs.EKF(dm, Qd, 0.25), cs.UKF(dm, Qd, 0.25),
                cs.MHE(dm, Qd, 0.25, options={"horizon": 4, "solver": "rti"})):
        np.testing.assert_allclose(est.filter(data, prior).x, kf.x, rtol=1e-8, atol=1e-8)
    with pytest.raises(ValueError, match="KalmanBucy needs a continuous-time model"):
        cs.KalmanBucy(dm, Qd, 0.25)
    with pytest.raises(ValueError, match="covariance='continuous' needs a continuous-time model"):
        cs.EKF(dm, Qd, 0.25, options={"covariance": "continuous"})
    with pytest.raises(ValueError, match="row 3"):
        cs.KF(dm, Qd, 0.25).filter(cs.Dataset([0.0, 0.5, 1.0, 1.7], {"x_m": [0.0, 0.5, 1.0, 1.7]}), prior)
