"""Simulation against scipy's solve_ivp, closed-loop inputs, measurement generation, bad input."""
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import casship as cs
from casship.models import nomoto_first_order, shi_taylor, sog_cog
from casship.simulation import fold_steps


def stable_shi():
    return shi_taylor({"c1": 0.001})


def rhs_of(model, u, p=None):
    p = model.params() if p is None else p
    w = np.zeros(model.nw)
    return lambda t, x: np.array(model.f(x, u, p, w)).ravel()


@pytest.mark.parametrize("method, tol", [("rk4", 3e-10), ("cvodes", 2e-9)])
def test_matches_solve_ivp_with_constant_inputs(method, tol):
    m = stable_shi()
    t = np.arange(0.0, 120.0 + 1e-9, 0.1)
    u = np.array([np.radians(8.0), 1.5])
    opts = {"abstol": 1e-13, "reltol": 1e-13} if method == "cvodes" else None
    traj = cs.simulate(m, m.states(u=6.0, v=0.1), t, {"delta": u[0], "n": u[1]}, method=method, options=opts)
    ref = solve_ivp(rhs_of(m, u), (0.0, 120.0), m.states(u=6.0, v=0.1), method="DOP853", t_eval=t,
                    rtol=1e-12, atol=1e-12)
    scale = np.maximum(1.0, np.abs(ref.y.T).max(axis=0))
    assert np.max(np.abs(traj.x - ref.y.T) / scale) < tol


@pytest.mark.parametrize("method", ["rk4", "cvodes"])
def test_zero_order_hold_inputs_match_solve_ivp_per_interval(method):
    m = nomoto_first_order()
    t = np.linspace(0.0, 20.0, 41)
    delta = 0.2 * np.sin(t / 3.0)
    kwargs = {"max_step": 0.05} if method == "rk4" else {"options": {"abstol": 1e-14, "reltol": 1e-12}}
    traj = cs.simulate(m, [0.1, 0.0], t, {"delta": delta}, method=method, **kwargs)
    x = np.array([0.1, 0.0])
    for k in range(t.size - 1):
        x = solve_ivp(rhs_of(m, [delta[k]]), (t[k], t[k + 1]), x, rtol=1e-12, atol=1e-14).y[:, -1]
        np.testing.assert_allclose(traj.x[k + 1], x, rtol=1e-9, atol=1e-12)


def test_long_records_are_folded_in_blocks_exactly():
    m = sog_cog()
    n = 2500                                   # not a multiple of the block length
    t = np.arange(n) * 0.2
    rng = np.random.default_rng(5)
    W = rng.normal(scale=0.01, size=(n, m.nw))
    traj = cs.simulate(m, [0.0, 0.0, 4.0, 0.2, 0.001], t, w=W)
    dm = cs.discretize(m, 0.2)
    X = np.array(dm.F.mapaccum(n - 1)([0.0, 0.0, 4.0, 0.2, 0.001], np.zeros((0, n - 1)), m.params(),
                                       W[:-1].T, np.full((1, n - 1), 0.2)))
    # equal up to round-off (a wrong block boundary would show as a jump of order one)
    np.testing.assert_allclose(traj.x[1:], X.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(fold_steps(dm, traj.x[0], np.zeros((n, 0)), m.params(), W, np.diff(t)), traj.x)


def test_irregular_time_grid():
    m = nomoto_first_order()
    t = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.05, 0.3, 200)])
    traj = cs.simulate(m, [0.0, 0.0], t, {"delta": 0.1}, method="cvodes", options={"abstol": 1e-14, "reltol": 1e-12})
    ref = solve_ivp(rhs_of(m, [0.1]), (t[0], t[-1]), [0.0, 0.0], method="DOP853", t_eval=t, rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(traj.x, ref.y.T, rtol=1e-9, atol=1e-13)


def test_trajectory_columns_and_metadata():
    m = shi_taylor()
    t = np.arange(0.0, 5.0, 0.5)
    traj = cs.simulate(m, {"u": 7.0}, t, {"delta": 0.0, "n": 1.5}, p={"a9": 0.1})
    assert isinstance(traj, cs.Trajectory)
    assert traj.state_names == m.state_names and traj.input_names == ("delta", "n")
    assert traj.x.shape == (t.size, 6) and traj.u.shape == (t.size, 2) and traj.y.shape == (t.size, 3)
    np.testing.assert_array_equal(traj["u"], traj.x[:, 0])
    assert traj.meta["params"]["a9"] == 0.1 and traj.meta["method"] == "rk4"
    assert traj.units["u"] == "m/s"
    frame = traj.to_pandas()
    assert list(frame.columns[:4]) == ["t", "u", "v", "r"]


# -- closed loop -----------------------------------------------------------------------------------

def test_callable_inputs_close_the_loop():
    m = nomoto_first_order()
    t = np.arange(0.0, 200.0, 0.5)
    gain, psi_ref = 2.0, 0.3

    def autopilot(time, x):
        return [np.clip(gain * (psi_ref - x[0]) - 20.0 * x[1], -0.6, 0.6)]

    traj = cs.simulate(m, m.states(), t, autopilot)
    expected = [autopilot(tk, xk)[0] for tk, xk in zip(t, traj.x)]
    np.testing.assert_allclose(traj["delta"], expected, rtol=0, atol=0)
    # the same inputs replayed open loop give the same states
    replay = cs.simulate(m, m.states(), t, {"delta": traj["delta"]})
    np.testing.assert_allclose(replay.x, traj.x, rtol=1e-14, atol=1e-15)
    assert abs(traj["psi"][-1] - psi_ref) < 0.02


@pytest.mark.parametrize("bad", [lambda t, x: [0.1, 0.2], lambda t, x: [np.nan]])
def test_callable_inputs_are_checked(bad):
    m = nomoto_first_order()
    with pytest.raises(ValueError, match="input function returned"):
        cs.simulate(m, m.states(), np.arange(0.0, 1.0, 0.1), bad)


def test_dataset_inputs():
    m = nomoto_first_order()
    t = np.arange(0.0, 10.0, 0.1)
    data = cs.Dataset(t, {"delta": 0.1 * np.ones(t.size), "other": np.zeros(t.size)})
    a = cs.simulate(m, m.states(), t, data)
    b = cs.simulate(m, m.states(), t, {"delta": 0.1})
    np.testing.assert_array_equal(a.x, b.x)
    with pytest.raises(ValueError, match=r"input data cover t = \[0, 9.9\] s, the simulation needs \[1, 10.9\] s"):
        cs.simulate(m, m.states(), t + 1.0, data)
    # a record on its own (coarser, irregular) grid is held between its time stamps
    t_log = np.array([0.0, 2.05, 5.0, 9.95])
    log = cs.Dataset(t_log, {"delta": [0.1, -0.2, 0.05, 0.3]})
    held = cs.simulate(m, m.states(), t, log)
    expected = np.array([0.1, -0.2, 0.05, 0.3])[np.searchsorted(t_log, t + 1e-12, side="right") - 1]
    np.testing.assert_array_equal(held["delta"], expected)
    assert held["delta"][20] == 0.1 and held["delta"][21] == -0.2 and held["delta"][50] == 0.05
    with pytest.raises(ValueError, match=r"no column for input\(s\) \['delta'\]"):
        cs.simulate(m, m.states(), t, data.select(["other"]))


# -- measurements ----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def turning():
    m = sog_cog().with_outputs(["x_n", "y_n", "chi"])
    t = np.arange(0.0, 200.0, 0.02)            # 50 Hz
    return m, cs.simulate(m, [0.0, 0.0, 5.0, 3.0, 0.05], t)


def test_measure_is_seeded_and_has_the_requested_noise(turning):
    m, traj = turning
    std = {"x_n": 2.0, "y_n": 0.5}
    a = cs.measure(traj, m, std, seed=4)
    b = cs.measure(traj, m, std, seed=4)
    c = cs.measure(traj, m, std, seed=5)
    np.testing.assert_array_equal(a["x_n"], b["x_n"])
    assert not np.allclose(a["x_n"], c["x_n"])
    assert "chi" not in a.names
    n = len(traj)
    for name, sigma in std.items():
        err = a[name] - traj[name]
        # sample variance of n Gaussian draws: relative standard error sqrt(2/n) ~ 0.6 %
        assert abs(np.var(err) / sigma**2 - 1.0) < 4 * np.sqrt(2.0 / n)
        assert abs(np.mean(err)) < 4 * sigma / np.sqrt(n)
    rng = np.random.default_rng(4)
    np.testing.assert_allclose(a["x_n"] - traj["x_n"], 2.0 * rng.standard_normal(n), rtol=0, atol=1e-12)


def test_per_channel_rates_leave_nan_elsewhere(turning):
    m, traj = turning
    data = cs.measure(traj, m, {"x_n": 1.0, "y_n": 1.0, "chi": 0.01}, rates={"x_n": 5.0, "y_n": 5.0}, seed=1,
                      keep=("U",))
    rows = np.flatnonzero(np.isfinite(data["x_n"]))
    np.testing.assert_array_equal(rows, np.arange(0, len(traj), 10))
    np.testing.assert_array_equal(np.isfinite(data["y_n"]), np.isfinite(data["x_n"]))
    assert np.isfinite(data["chi"]).all()
    np.testing.assert_array_equal(data["true_U"], traj["U"])


def test_rates_that_do_not_divide_the_grid_rate():
    t = np.arange(0.0, 10.0, 0.02)
    from casship.simulation.simulate import sample_mask
    rows = np.flatnonzero(sample_mask(t, 3.0))
    assert rows.size == 30                          # 3 Hz over 10 s
    # each sample lands on the first row at or after k / 3 s
    np.testing.assert_allclose(t[rows] - np.arange(30) / 3.0, np.ceil(np.arange(30) / 3.0 / 0.02 - 1e-6) * 0.02
                               - np.arange(30) / 3.0, atol=1e-9)
    assert sample_mask(t, 100.0).all()


def test_angle_outputs_are_wrapped(turning):
    m, traj = turning
    assert traj["chi"].max() > np.pi                # the course turns past 180 deg
    data = cs.measure(traj, m, {"chi": 0.01}, seed=2)
    assert data["chi"].max() <= np.pi and data["chi"].min() > -np.pi
    # on the circle the measurement is the truth plus small noise
    err = cs.wrap(data["chi"] - traj["chi"])
    assert np.abs(err).max() < 6 * 0.01
    assert abs(np.std(err) / 0.01 - 1.0) < 0.05


@pytest.mark.parametrize("kwargs, match", [
    ({"std": {"speed": 1.0}}, r"unknown output name\(s\) \['speed'\]"),
    ({"std": {"x_n": -1.0}}, "standard deviation of 'x_n'"),
    ({"std": {"x_n": np.nan}}, "standard deviation of 'x_n'"),
    ({"std": {"x_n": 1.0}, "rates": {"y_n": 5.0}}, r"rates given for unmeasured output\(s\) \['y_n'\]"),
    ({"std": {"x_n": 1.0}, "rates": {"x_n": 0.0}}, "rate of 'x_n'"),
    ({"std": {"x_n": 1.0}, "keep": ("nothing",)}, "unknown column 'nothing'"),
])
def test_measure_rejects_bad_arguments(turning, kwargs, match):
    m, traj = turning
    with pytest.raises(ValueError, match=match):
        cs.measure(traj, m, seed=0, **kwargs)


# -- bad input -------------------------------------------------------------------------------------

@pytest.mark.parametrize("t, match", [
    ([0.0, 0.2, 0.1, 0.3], r"must increase strictly; row 2"),
    ([0.0, 0.1, 0.1, 0.3], r"must increase strictly; row 2"),
    ([0.0, np.nan, 0.2], "non-finite time stamp at row 1"),
    ([[0.0, 0.1]], "1-D array"),
    ([], "no time stamps"),
])
def test_bad_time_stamps(t, match):
    m = nomoto_first_order()
    with pytest.raises(ValueError, match=match):
        cs.simulate(m, m.states(), t, {"delta": 0.0})


def test_bad_inputs_name_the_item():
    m = shi_taylor()
    t = np.arange(0.0, 1.0, 0.1)
    x0 = m.states(u=5.0)
    delta = np.zeros(t.size)
    delta[4] = np.nan
    with pytest.raises(ValueError, match=r"input 'delta' is not finite at row 4"):
        cs.simulate(m, x0, t, {"delta": delta, "n": 1.0})
    with pytest.raises(ValueError, match=r"unknown input name\(s\) \['rpm'\]"):
        cs.simulate(m, x0, t, {"delta": 0.0, "n": 1.0, "rpm": 3.0})
    with pytest.raises(ValueError, match=r"no value given for input\(s\) \['n'\]"):
        cs.simulate(m, x0, t, {"delta": 0.0})
    with pytest.raises(ValueError, match=r"input 'n' has shape \(3,\)"):
        cs.simulate(m, x0, t, {"delta": 0.0, "n": [1.0, 2.0, 3.0]})
    with pytest.raises(ValueError, match=r"inputs have shape \(10, 3\), expected \(10, 2\)"):
        cs.simulate(m, x0, t, np.zeros((10, 3)))
    with pytest.raises(ValueError, match=r"needs inputs \['delta', 'n'\]"):
        cs.simulate(m, x0, t)
    with pytest.raises(ValueError, match="x0 has 5 entries"):
        cs.simulate(m, x0[:5], t, np.zeros((10, 2)))
    with pytest.raises(ValueError, match="x0 contains non-finite"):
        cs.simulate(m, np.full(6, np.nan), t, np.zeros((10, 2)))
    with pytest.raises(ValueError, match="unknown state name 'speed'"):
        cs.simulate(m, {"speed": 1.0}, t, np.zeros((10, 2)))
    with pytest.raises(ValueError, match=r"w has shape \(10, 2\), expected \(10, 3\)"):
        cs.simulate(m, x0, t, np.zeros((10, 2)), w=np.zeros((10, 2)))
    with pytest.raises(ValueError, match="max_step must be a positive"):
        cs.simulate(m, x0, t, np.zeros((10, 2)), max_step=-1.0)
    with pytest.raises(ValueError, match=r"input 'delta' reaches 35 rad: angles are in radians \(degrees given\?\)"):
        cs.simulate(m, x0, t, {"delta": 35.0, "n": 1.0})
    with pytest.raises(ValueError, match="unknown discretisation method"):
        cs.simulate(m, x0, t, np.zeros((10, 2)), method="heun")


def test_divergence_is_reported():
    b = cs.ModelBuilder("blowup")
    x = b.state("x")
    b.ode(x=x**2)
    with pytest.raises(FloatingPointError, match="diverged at t ="):
        cs.simulate(b.build(), [1.0], np.arange(0.0, 5.0, 0.1))


def test_integrator_failure_names_the_solver_status():
    from casship.simulation import IntegrationError

    b = cs.ModelBuilder("blowup")
    x = b.state("x")
    b.ode(x=x**2)                                   # finite-time blow-up at t = 1 s
    with pytest.raises(IntegrationError, match=r"'blowup' \(cvodes\) failed .*solver status CV_\w+") as info:
        cs.simulate(b.build(), [1.0], np.arange(0.0, 5.0, 0.1), method="cvodes")
    assert info.value.status.startswith("CV_") and isinstance(info.value, RuntimeError)


def test_piecewise_constant_inputs_fail_with_the_step_and_time():
    from casship.simulation import IntegrationError

    b = cs.ModelBuilder("blowup_u")
    x = b.state("x")
    b.ode(x=x**2 + b.input("a"))
    t = np.arange(0.0, 5.0, 0.1)
    with pytest.raises(IntegrationError, match=r"failed in steps 0\.\.48: solver status CV_\w+ \(from t = 0 s\)"):
        cs.simulate(b.build(), [1.0], t, {"a": 0.01 * np.sin(t)}, method="cvodes")


def test_outputs_are_evaluated_or_taken_from_the_states():
    m = shi_taylor()
    inputs = {"delta": 0.1, "n": 1.5}
    t = np.arange(0.0, 300.0, 0.5)                  # several blocks of the output map
    plain = cs.simulate(m, m.states(u=7.0), t, inputs)
    np.testing.assert_array_equal(plain.y, plain.x[:, :3])
    derived = m.with_outputs({"speed": lambda b: (b.sym("u") ** 2 + b.sym("v") ** 2) ** 0.5, "psi": "psi",
                              "rudder": lambda b: b.sym("delta")})
    traj = cs.simulate(derived, derived.states(u=7.0), t, inputs)
    np.testing.assert_allclose(traj["speed"], np.hypot(traj["u"], traj["v"]), rtol=1e-15)
    np.testing.assert_array_equal(traj["rudder"], traj["delta"])


# -- validity: declared ranges and the stability limit of fixed steps -------------------------------------
def _kvlcc2():
    ship = cs.models.get_model("kvlcc2")
    return ship, ship.states(u=ship.vessel.U0)


def test_inputs_outside_the_declared_range_raise_naming_input_value_and_range():
    from casship.simulation import ValidityError

    ship, x0 = _kvlcc2()
    t = np.arange(0.0, 20.0, 1.0)
    delta = np.where(t < 10, 0.0, np.radians(200.0))
    with pytest.raises(ValidityError, match=r"input 'delta' = 200 deg at t = 10 s is outside its valid range "
                                            r"\[-35, 35\] deg \(rudder stop\) of model 'kvlcc2'; pass check_limits=False"):
        cs.simulate(ship, x0, t, {"delta": delta, "n": 1.5})
    with pytest.raises(ValidityError, match=r"input 'n' = -2 1/s .* \[0, 3.06\] 1/s"):
        cs.simulate(ship, x0, t, {"delta": 0.0, "n": -2.0})
    with pytest.raises(ValidityError, match=r"initial state 'u' = 30 m/s is outside its valid range \[0, 15.95\] m/s"):
        cs.simulate(ship, ship.states(u=30.0), t, {"delta": 0.0, "n": 1.5})


def test_closed_loop_inputs_are_checked_after_the_run():
    from casship.simulation import ValidityError

    ship, x0 = _kvlcc2()
    with pytest.raises(ValidityError, match=r"input 'delta' = 40 deg at t = 5 s"):
        cs.simulate(ship, x0, np.arange(0.0, 10.0, 1.0),
                    lambda t, x: ship.inputs(delta=np.radians(40.0) if t >= 5 else 0.0, n=1.5))


def test_explicit_opt_in_for_an_out_of_range_study():
    ship, x0 = _kvlcc2()
    t = np.arange(0.0, 20.0, 1.0)
    tr = cs.simulate(ship, x0, t, {"delta": np.radians(45.0), "n": 1.5}, check_limits=False)
    assert tr["r"][-1] > 0


def test_margin_of_one_percent_at_a_bound():
    ship, x0 = _kvlcc2()
    t = np.arange(0.0, 5.0, 1.0)
    cs.simulate(ship, x0, t, {"delta": np.radians(35.1), "n": 1.5})       # a measured angle at the stop


def test_state_leaving_its_range_warns_with_the_time():
    from casship.simulation import ValidityWarning

    b = cs.ModelBuilder("drift")
    pos = b.state("pos", unit="m")
    b.ode(pos=b.input("vel", unit="m/s"))
    b.limit("pos", -1.0, 1.0, why="calibrated range")
    m = b.build()
    with pytest.warns(ValidityWarning, match=r"state 'pos' of model 'drift' leaves its valid range \[-1, 1\] m "
                                             r"\(calibrated range\) at t = 1.1 s \(1.1 m\)"):
        tr = cs.simulate(m, [0.0], np.arange(0.0, 2.0, 0.1), {"vel": 1.0})
    assert tr["pos"][-1] == pytest.approx(1.9)


def test_step_beyond_the_stability_limit_raises_instead_of_exploding():
    from casship.simulation import ValidityError, stable_step

    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    # a 1e4 s gap in the time stamps: rk4 with one step per interval would return ~1e29
    t = np.concatenate([np.arange(0.0, 100.0, 10.0), 1e4 + np.arange(0.0, 100.0, 10.0)])
    with pytest.raises(ValidityError, match=r"time step 9910 s \(interval 9, 9910 s long\) exceeds the rk4 "
                                            r"stability limit 55.71 s of model 'nomoto1'"):
        cs.simulate(m, m.states(), t, {"delta": 0.1})
    # the ways out give the same, finite answer: sub-steps or the adaptive integrator
    a = cs.simulate(m, m.states(), t, {"delta": 0.1}, max_step=20.0)
    b = cs.simulate(m, m.states(), t, {"delta": 0.1}, method="cvodes")
    np.testing.assert_allclose(a["r"], b["r"], rtol=1e-4, atol=1e-12)
    np.testing.assert_allclose(a["r"][-1], 0.1 * 0.1, rtol=1e-9)           # steady state K delta
    # the limit is exact for a real eigenvalue: 2 T (euler), 2.785 T (rk4)
    x, u, p = m.states(), m.inputs(), m.params()
    assert stable_step(m, x, u, p, "euler") == pytest.approx(40.0, rel=1e-9)
    assert stable_step(m, x, u, p, "rk4") == pytest.approx(20.0 * 2.785293563, rel=1e-6)
    assert stable_step(m, x, u, p, "cvodes") == np.inf


def test_step_limit_of_a_lightly_damped_mode_for_euler():
    from casship.simulation import stable_step

    b = cs.ModelBuilder("oscillator")
    pos, vel = b.state("pos"), b.state("vel")
    b.ode(pos=vel, vel=-pos - 0.02 * vel)                 # lam = -0.01 +- 1j
    m = b.build()
    lam = complex(-0.01, np.sqrt(1 - 0.01**2))
    h = stable_step(m, m.states(), m.inputs(), m.params(), "euler")
    assert h == pytest.approx(-2 * lam.real / abs(lam) ** 2, rel=1e-8)      # |1 + h lam| = 1
    assert abs(1 + (1.01 * h) * lam) > 1 > abs(1 + (0.99 * h) * lam)


@pytest.mark.parametrize("method", ["euler", "rk4"])
def test_one_step_stability_test_agrees_with_the_limit(method):
    from casship.simulation import is_stable_step, stable_step

    m = cs.models.get_model("shi-taylor")
    x, u, p = m.states(u=7.0, r=0.01), m.inputs(delta=0.1, n=1.5), m.params()
    h = stable_step(m, x, u, p, method)
    assert np.isfinite(h)
    assert is_stable_step(m, x, u, p, method, 0.999 * h) and not is_stable_step(m, x, u, p, method, 1.001 * h)
    assert is_stable_step(m, x, u, p, "cvodes", 1e6)


def test_duplicate_and_nan_time_stamps_are_named():
    m = cs.models.nomoto_first_order()
    with pytest.raises(ValueError, match=r"t: time stamps must increase strictly; row 2 \(1.0\) is not after row 1"):
        cs.simulate(m, m.states(), [0.0, 1.0, 1.0, 2.0], {"delta": 0.0})
    with pytest.raises(ValueError, match=r"t: non-finite time stamp at row 1"):
        cs.simulate(m, m.states(), [0.0, np.nan, 2.0], {"delta": 0.0})
