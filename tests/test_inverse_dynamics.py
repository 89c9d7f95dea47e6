"""Inverse dynamics: trial smoothing (EKF + RTS) and the regression of the coefficients the model is
linear in."""
import numpy as np
import pytest

import casship as cs
from casship.identify.inverse_dynamics import inverse_dynamics, linear_in, smooth_trial
from casship.models import kvlcc2

LINEAR = ["R_0_dash", "X_vv_dash", "X_vr_dash", "X_rr_dash", "X_vvvv_dash", "Y_v_dash", "Y_r_dash", "Y_vvv_dash",
          "Y_vvr_dash", "Y_vrr_dash", "Y_rrr_dash", "N_v_dash", "N_r_dash", "N_vvv_dash", "N_vvr_dash", "N_vrr_dash",
          "N_rrr_dash", "f_alpha", "t_P", "Y_0_dash", "N_0_dash"]


def _trial(truth, seconds=1500.0, dt=1.0):
    """A rich simulated trial: zig-zag-like rudder with a faster component and a varying rate."""
    ship = kvlcc2(truth, asymmetry=True)
    t = np.arange(0.0, seconds, dt)
    delta = np.radians(20) * np.tanh(3 * np.sin(2 * np.pi * t / 300)) + np.radians(5) * np.sin(2 * np.pi * t / 77)
    n = 1.53 + 0.2 * np.sin(t / 50)
    tr = cs.simulate(ship, ship.states(u=7.97), t, {"delta": delta, "n": n})
    rates = np.asarray(ship.f.map(t.size)(tr.x.T, tr.u.T, ship.params(), np.zeros((3, t.size)))).T
    cols = {s: tr[s] for s in ship.state_names}
    cols.update(delta=delta, n=n, u_dot=rates[:, 0], v_dot=rates[:, 1], r_dot=rates[:, 2])
    return cs.Dataset(t, cols), tr


@pytest.fixture(scope="module")
def truth():
    rng = np.random.default_rng(0)
    nominal = kvlcc2(asymmetry=True).param_dict()
    out = {n: nominal[n] * (1 + 0.2 * rng.standard_normal()) for n in LINEAR}
    out.update(Y_0_dash=0.01, N_0_dash=-0.003)
    return out


def test_regression_recovers_linear_coefficients_exactly_on_noise_free_data(truth):
    data, _ = _trial(truth)
    fit = inverse_dynamics(kvlcc2(asymmetry=True), data, LINEAR)
    for n in LINEAR:
        assert fit.estimates[n] == pytest.approx(truth[n], rel=1e-8, abs=1e-12), n
    assert fit.method == "inverse-dynamics"
    assert fit.params["f_alpha"] == fit.estimates["f_alpha"]
    # two records give the same answer as one
    half = len(data) // 2
    both = inverse_dynamics(kvlcc2(asymmetry=True), [data.slice(0, half), data.slice(half, None)], LINEAR)
    for n in LINEAR:
        assert both.estimates[n] == pytest.approx(truth[n], rel=1e-8, abs=1e-12), n


def test_nonlinear_parameters_are_refused_by_name():
    ship = kvlcc2()
    flags = linear_in(ship, ["N_r_dash", "f_alpha", "a_H", "m_y_dash"])
    assert not flags["a_H"] and not flags["m_y_dash"]          # a_H multiplies f_alpha; m_y is in the mass matrix
    assert linear_in(ship, ["N_r_dash", "f_alpha"]) == {"N_r_dash": True, "f_alpha": True}
    # each alone is linear; together a_H * f_alpha is a product: both refused
    assert linear_in(ship, ["a_H"]) == {"a_H": True}
    assert linear_in(ship, ["f_alpha", "a_H"]) == {"f_alpha": False, "a_H": False}
    assert linear_in(ship, ["gamma_R_plus"]) == {"gamma_R_plus": False}
    data, _ = _trial({})
    with pytest.raises(ValueError, match="gamma_R_plus"):
        inverse_dynamics(kvlcc2(asymmetry=True), data, ["N_r_dash", "gamma_R_plus"])
    with pytest.raises(ValueError, match="r_dot"):
        inverse_dynamics(kvlcc2(asymmetry=True), data.select(["u", "v", "r", "x", "y", "psi", "delta", "n", "u_dot",
                                                              "v_dot"]), ["N_r_dash"])
    with pytest.raises(ValueError, match="prior"):
        inverse_dynamics(kvlcc2(asymmetry=True), data, ["N_r_dash"], prior={"Y_v_dash": 0.1})


def test_prior_regularises_towards_the_published_values(truth):
    data, _ = _trial(truth, seconds=600.0)
    ship = kvlcc2(asymmetry=True)
    free = ["N_r_dash", "N_v_dash", "Y_v_dash", "Y_r_dash"]
    plain = inverse_dynamics(ship, data, free)
    loose = inverse_dynamics(ship, data, free, prior={n: 1e6 for n in free})
    tight = inverse_dynamics(ship, data, free, prior={n: 1e-9 for n in free})
    nominal = ship.param_dict()
    for n in free:
        assert loose.estimates[n] == pytest.approx(plain.estimates[n], rel=1e-9)
        assert tight.estimates[n] == pytest.approx(nominal[n], rel=1e-6)


def test_smooth_regress_refine_on_a_noisy_trial():
    """Positions (0.5 m), heading (0.05 deg) and yaw rate (0.005 deg/s) measured with noise: the
    smoothed sway velocity, yaw rate and yaw acceleration follow the truth; the regression on the
    smoothed values is biased low by the noise in its regressors (errors in variables: within 10 %
    here) and the output-error refinement started from it recovers the truth within three standard
    errors (the other coefficients are at their true values)."""
    truth = {"N_r_dash": -0.06, "N_v_dash": -0.12, "f_alpha": 2.4}
    data, tr = _trial(truth)
    rng = np.random.default_rng(4)
    sigma = {"x": 0.5, "y": 0.5, "psi": np.radians(0.05), "r": np.radians(0.005)}
    meas = cs.Dataset(data.t, {**{k: tr[k] + s * rng.standard_normal(len(data)) for k, s in sigma.items()},
                               "delta": data["delta"], "n": data["n"]})
    sm = smooth_trial(meas, sigma=sigma, jerk={"u": 1e-3, "v": 1e-3, "r": 1e-5}, measured=list(sigma))
    assert sm.meta["smoother"]["measured"] == list(sigma)
    for name in ("v", "r", "r_dot"):
        err = sm[name] - data[name]
        assert np.sqrt(np.mean(err**2)) < 0.1 * np.std(data[name]), name
    np.testing.assert_allclose(np.unwrap(sm["psi"]), tr["psi"], atol=np.radians(0.1))
    ship = kvlcc2(asymmetry=True)
    start = inverse_dynamics(ship, sm, list(truth))
    for n, v in truth.items():
        assert start.estimates[n] == pytest.approx(v, rel=0.1), n
    oe = cs.OutputErrorProblem(ship, meas, list(truth), x0={"u": 7.97}, measured=["psi", "r"],
                               sigma={"psi": sigma["psi"], "r": sigma["r"]})
    fit = oe.solve(guess=start.estimates)
    for n, v in truth.items():
        assert abs(fit.estimates[n] - v) < 3 * fit.std_errors[n], n


def test_smoother_input_checks():
    data, _ = _trial({}, seconds=50.0)
    with pytest.raises(ValueError, match="sigma"):
        smooth_trial(data, sigma={"x": 1.0, "y": 1.0}, jerk={"u": 1, "v": 1, "r": 1})
    with pytest.raises(ValueError, match="jerk"):
        smooth_trial(data, sigma={"x": 1.0, "y": 1.0, "psi": 0.01}, jerk={"u": 1, "v": 1, "r": -1})
    with pytest.raises(ValueError, match="no column"):
        smooth_trial(data.select(["x", "y", "delta"]), sigma={"x": 1.0, "y": 1.0, "psi": 0.01},
                     jerk={"u": 1, "v": 1, "r": 1})


def test_autocorrelation_sets_the_equation_weights_from_the_effective_samples(truth):
    """AR(1) equation errors (phi = 0.9: tau = 19 samples) weigh as N / tau samples: sigma = rms sqrt(tau)."""
    data, _ = _trial(truth, seconds=3000.0)
    rng = np.random.default_rng(2)
    phi, n = 0.9, len(data)
    noisy = {}
    for name, scale in (("u_dot", 1e-4), ("v_dot", 1e-4), ("r_dot", 1e-6)):
        e = np.zeros(n)
        for k in range(1, n):
            e[k] = phi * e[k - 1] + scale * rng.standard_normal()
        noisy[name] = data[name] + e
    d = data.with_columns(**noisy)
    ship = kvlcc2(truth, asymmetry=True)                 # the fixed coefficients at their true values
    free = ["N_r_dash", "N_v_dash", "Y_v_dash", "Y_r_dash", "R_0_dash"]
    prior_std = {k: 0.2 * abs(ship.param_dict()[k]) for k in free}
    fit = inverse_dynamics(ship, d, free, sigma={"u": 1.0, "v": 1.0, "r": 1.0}, prior=prior_std, autocorrelation=True)
    for name in ("u_dot", "v_dot", "r_dot"):
        rms = np.sqrt(np.mean((d[name] - data[name]) ** 2))
        ratio = fit.noise["sigma"][name] / rms
        assert ratio == pytest.approx(np.sqrt((1 + phi) / (1 - phi)), rel=0.25), name
    white = {s: fit.noise["sigma"][f"{s}_dot"] / np.sqrt((1 + phi) / (1 - phi)) for s in ("u", "v", "r")}
    plain = inverse_dynamics(ship, d, free, sigma=white, prior=prior_std)
    for k in free:                       # honest (larger) sigmas give wider posterior intervals
        assert fit.std_errors[k] > plain.std_errors[k]
