"""Trial design, core: the expected information against the analytic Fisher matrix, the belief update,
unexcited parameters, the belief a fit leaves."""
import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship.design import Approach, ParameterBelief, Trial, criterion_value, trial_information
from casship.identify import FitResult


def toy_ship():
    """A ship whose yaw acceleration is linear in its parameters: ``r' = a delta + c + e v``, with ``v``
    never excited (``v' = 0``, ``v(0) = 0``): the outputs are linear in (a, c, e)."""
    b = cs.ModelBuilder("toy_linear_ship")
    u, v, r = b.state("u", unit="m/s"), b.state("v", unit="m/s"), b.state("r", unit="rad/s")
    x, y, psi = b.state("x", unit="m"), b.state("y", unit="m"), b.state("psi", unit="rad", angle=True)
    delta = b.input("delta", unit="rad", angle=True)
    a, c, e = b.param("a", 0.01), b.param("c", 0.001), b.param("e", 0.3)
    b.ode(u=0 * u, v=0 * v, r=a * delta + c + e * v, x=u * ca.cos(psi) - v * ca.sin(psi),
          y=u * ca.sin(psi) + v * ca.cos(psi), psi=r)
    for name in ("u", "v", "r", "x", "y", "psi"):
        b.output(name, b.sym(name))
    b.vessel = cs.Vessel("toy", L_pp=20.0, U0=2.0, rudders=("delta",), rudder_max=np.radians(35.0),
                         rudder_rate=np.radians(10.0))
    return b.build()


@pytest.fixture(scope="module")
def toy():
    m = toy_ship()
    return m, Approach(m, m.params(), dt=0.5)


def test_expected_information_of_a_linear_gaussian_toy_is_the_analytic_fisher_matrix(toy):
    m, ap = toy
    rng = np.random.default_rng(3)
    rudder = np.radians(rng.uniform(-20, 20, 120))
    trial = Trial("random", "free", ap.dt, rudder)
    s_r, s_psi = 0.002, 0.01
    info = trial_information(ap, trial, ["a", "c", "e"], {"r": s_r, "psi": s_psi}, jit=False)
    # analytic: r_k = sum_{j<k} (a delta_j + c) dt, psi_k exact for the held input (RK4 integrates the
    # quadratic exactly): psi_k = sum_{j<k} (r_j dt + (a delta_j + c) dt^2 / 2)
    dt, n = ap.dt, rudder.size
    dr = np.zeros((n + 1, 3))
    dpsi = np.zeros((n + 1, 3))
    for k in range(n):
        step = np.array([rudder[k], 1.0, 0.0]) * dt
        dr[k + 1] = dr[k] + step
        dpsi[k + 1] = dpsi[k] + dr[k] * dt + step * dt / 2
    fisher = dr.T @ dr / s_r**2 + dpsi.T @ dpsi / s_psi**2
    assert np.allclose(info[:2, :2], fisher[:2, :2], rtol=1e-8, atol=0)


def test_a_parameter_the_trial_cannot_excite_gets_zero_information(toy):
    m, ap = toy
    trial = Trial("turns", "free", ap.dt, np.radians(np.r_[15.0 * np.ones(40), -10.0 * np.ones(40)]))
    info = trial_information(ap, trial, ["a", "c", "e"], {"r": 0.002, "psi": 0.01, "y": 0.5}, jit=False)
    assert info[0, 0] > 0 and info[1, 1] > 0
    assert np.all(info[2, :] == 0) and np.all(info[:, 2] == 0)
    prior = ParameterBelief.from_std({"a": 0.005, "c": 0.001, "e": 0.1}, m.param_dict())
    after = prior.after(info)
    assert after.std["e"] == pytest.approx(prior.std["e"], rel=1e-12)       # nothing learnt about e
    assert after.std["a"] < 0.1 * prior.std["a"]


def test_belief_update_equals_the_information_form_and_keeps_a_known_direction():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(4, 4))
    P = A @ A.T + 0.1 * np.eye(4)
    B = rng.normal(size=(4, 6))
    info = B @ B.T
    prior = ParameterBelief(("p1", "p2", "p3", "p4"), cs.Gaussian(np.zeros(4), P))
    after = prior.after(info)
    assert np.allclose(after.cov, np.linalg.inv(np.linalg.inv(P) + info), rtol=1e-9, atol=1e-12)
    singular = ParameterBelief(("p1", "p2"), cs.Gaussian([0.0, 0.0], np.diag([1.0, 0.0])))
    post = singular.after(np.eye(2))
    assert post.cov[1, 1] == 0 and post.cov[0, 0] == pytest.approx(0.5)
    g = np.array([1.0, -2.0, 0.5, 3.0])
    assert after.variance_of(g) < prior.variance_of(g)
    assert criterion_value(prior, prior, "D") == pytest.approx(0.0, abs=1e-12)
    assert criterion_value(prior, prior, "A") == pytest.approx(1.0)
    assert criterion_value(after, prior, "D") < 0 and criterion_value(after, prior, "A") < 1
    with pytest.raises(ValueError, match="criterion 'E'"):
        criterion_value(after, prior, "E")


def test_belief_from_a_fit_keeps_the_copy_of_its_params_and_marginalises_the_rest():
    names = ["K", "T@A", "T@B", "psi@0"]
    cov = np.array([[4.0, 1.0, 0.5, 0.2], [1.0, 9.0, 0.3, 0.1], [0.5, 0.3, 16.0, 0.0], [0.2, 0.1, 0.0, 1.0]]) * 1e-4
    fit = FitResult(model="nomoto1", params={"K": 0.1, "T": 20.0}, free=names,
                    estimates={"K": 0.1, "T@A": 21.0, "T@B": 20.0, "psi@0": 0.0},
                    std_errors=dict(zip(names, np.sqrt(np.diag(cov)))), correlation=np.eye(4), covariance=cov,
                    cost=0.0, loglik=0.0, n_obs=100, aic=0.0, bic=0.0)
    b = ParameterBelief.from_fit(fit, extra_std={"T_r": 0.5}, params={"K": 0.1, "T": 20.0, "T_r": 1.0})
    assert b.names == ("K", "T", "T_r")
    assert np.allclose(b.cov[:2, :2], cov[np.ix_([0, 2], [0, 2])])          # T's copy of group B (= params)
    assert b.cov[2, 2] == pytest.approx(0.25) and b.cov[0, 2] == 0
    assert b.mean == {"K": 0.1, "T": 20.0, "T_r": 1.0}
    with pytest.raises(ValueError, match="estimated"):
        ParameterBelief.from_fit(fit, extra_std={"K": 1.0})
    no_cov = FitResult(**{**fit.__dict__, "covariance": np.full((4, 4), np.nan)})
    assert ParameterBelief.from_fit(no_cov).std["T"] == pytest.approx(0.04)


def test_bad_beliefs_and_noise_are_named(toy):
    m, ap = toy
    with pytest.raises(ValueError, match=r"\['a'\]"):
        ParameterBelief.from_std({"a": 0.0}, m.param_dict())
    with pytest.raises(ValueError, match="no mean"):
        ParameterBelief.from_std({"zz": 1.0}, m.param_dict())
    trial = Trial("turn", "turning", ap.dt, np.radians(15.0) * np.ones(10))
    with pytest.raises(ValueError, match="heading"):
        trial_information(ap, trial, ["a"], {"heading": 0.01}, jit=False)
    with pytest.raises(ValueError, match="positive"):
        trial_information(ap, trial, ["a"], {"psi": -1.0}, jit=False)
    with pytest.raises(ValueError, match="step"):
        trial_information(ap, Trial("t", "free", 0.25, np.zeros(10)), ["a"], {"psi": 0.01}, jit=False)
