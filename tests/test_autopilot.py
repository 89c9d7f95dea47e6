"""Autopilot designs, reference model, limits, metrics and the closed loop."""
import control
import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap


@pytest.fixture(scope="module")
def nomoto():
    return ap.Nomoto(K=0.185, T=107.3)


@pytest.mark.parametrize("zeta", [0.8, 1.0])
def test_pd_and_exact_pid_closed_loops_have_the_placed_poles(nomoto, zeta):
    wn = 0.05
    pd = ap.pid_pole_placement(nomoto, wn, zeta, integral=None)
    poles = np.sort_complex(ap.closed_loop_tf(nomoto, pd).poles())
    np.testing.assert_allclose(poles, np.sort_complex(np.roots([1, 2 * zeta * wn, wn**2])), atol=1e-6)
    pid = ap.pid_pole_placement(nomoto, wn, zeta, integral="exact")
    poles = np.sort_complex(ap.closed_loop_tf(nomoto, pid).poles())
    want = np.sort_complex(np.append(np.roots([1, 2 * zeta * wn, wn**2]), -0.1 * wn))
    np.testing.assert_allclose(poles, want, atol=1e-6)


def test_fossen_pid_formulas(nomoto):
    g = ap.pid_pole_placement(nomoto, 0.05, 1.0)
    m, d = nomoto.T / nomoto.K, 1 / nomoto.K
    assert g.Kp == pytest.approx(m * 0.05**2)
    assert g.Kd == pytest.approx(m * 2 * 0.05 - d)
    assert g.Ki == pytest.approx(0.005 * g.Kp)


def test_course_unstable_ship_is_stabilised():
    nom = ap.Nomoto(K=-0.019, T=-124.1 + 16.4 - 46.0)          # MSS tanker, course-unstable
    g = ap.pid_pole_placement(nom, 0.05, 1.0, integral="exact")
    assert np.all(np.real(ap.closed_loop_tf(nom, g).poles()) < 0)
    mg = ap.margins(ap.loop_transfer(nom, g))
    assert mg["closed_loop_stable"]


def test_lqr_gains_equal_control_lqr_and_stabilise(nomoto):
    g = ap.lqr_design(nomoto, q_int=1e-4, q_e=1.0, q_r=100.0, r_delta=1.0)
    a, b = 1 / nomoto.T, nomoto.K / nomoto.T
    A = np.array([[0, 1, 0], [0, 0, 1], [0, 0, -a]])
    B = np.array([[0], [0], [b]])
    K, _, E = control.lqr(A, B, np.diag([1e-4, 1.0, 100.0]), [[1.0]])
    np.testing.assert_allclose([g.Ki, g.Kp, g.Kd], np.ravel(K))
    np.testing.assert_allclose(np.sort_complex(ap.closed_loop_tf(nomoto, g).poles()), np.sort_complex(E),
                               atol=1e-8)


def test_nomoto_from_linearised_second_order_model():
    m = cs.models.nomoto_second_order(K=0.185, T1=118.0, T2=7.8, T3=18.5)
    nom = ap.nomoto_from_model(m, steer="delta", yaw_rate="r")
    assert (nom.K, nom.T1, nom.T2, nom.T3) == pytest.approx((0.185, 118.0, 7.8, 18.5), rel=1e-6)
    assert nom.T == pytest.approx(118.0 + 7.8 - 18.5, rel=1e-6)


def test_reference_model_is_the_linear_filter_without_saturation():
    ref = ap.ReferenceModel(wn=0.5, zeta=1.0)
    t = np.arange(0, 60, 0.001)
    X = ref.response(t, 0.2)
    lin = control.step_response(ref.tf(), t).outputs * 0.2
    np.testing.assert_allclose(X[:, 0], lin, atol=2e-4)       # Euler at dt = 1 ms
    assert X[-1, 0] == pytest.approx(0.2, abs=1e-6)


def test_reference_model_rate_saturation():
    ref = ap.ReferenceModel(wn=1.0, zeta=1.0, r_max=np.radians(2))
    X = ref.response(np.arange(0, 60, 0.02), np.radians(40))
    assert np.max(np.abs(X[:, 1])) <= np.radians(2) + 1e-12
    assert X[-1, 0] == pytest.approx(np.radians(40), abs=1e-3)
    # the reference crosses +-180 deg the short way round
    Xw = ref.response(np.arange(0, 60, 0.02), np.radians(-170), x0=(np.radians(170), 0, 0))
    assert np.all(np.abs(Xw[:, 0]) > np.radians(165))


def _run_ap(autopilot, chi, r, ref=0.3, n=200, dt=0.1):
    f = autopilot.function
    z = np.zeros(6)
    out = []
    for _ in range(n):
        z_next, steer, *_ = f(z, ref, chi, r, dt)
        z = np.ravel(np.array(z_next))
        out.append((float(steer), z[3]))
    return np.array(out)


def test_saturation_rate_limit_and_anti_windup(nomoto):
    g = ap.pid_pole_placement(nomoto, 0.05)
    ref = ap.ReferenceModel(10.0)                 # fast: chi_d follows the command
    lim = ap.Autopilot(g, ref, steer_max=np.radians(10), steer_rate_max=np.radians(2), anti_windup=True)
    out = _run_ap(lim, chi=0.0, r=0.0)
    assert np.max(np.abs(out[:, 0])) <= np.radians(10) + 1e-12
    assert np.max(np.abs(np.diff(out[:, 0]))) <= np.radians(2) * 0.1 + 1e-12
    assert out[-1, 0] == pytest.approx(-np.radians(10)) or out[-1, 0] == pytest.approx(np.radians(10))
    # held error with the command saturated: the integrator stops (anti-windup), without it it grows
    free = ap.Autopilot(g, ref, steer_max=np.radians(10), steer_rate_max=np.radians(2), anti_windup=False)
    wind = _run_ap(free, chi=0.0, r=0.0)
    assert abs(out[-1, 1]) < 0.5 * abs(wind[-1, 1])


def test_step_metrics_on_known_responses():
    t = np.linspace(0, 200, 20001)
    T = 10.0
    y = 0.5 * (1 - np.exp(-t / T))
    mt = ap.step_metrics(t, y, 0.5)
    assert mt["rise_time_s"] == pytest.approx(T * np.log(9), abs=0.02)
    assert mt["overshoot_pct"] == 0.0
    assert mt["settling_time_s"] == pytest.approx(-T * np.log(0.02), abs=0.02)
    assert mt["iae_deg_s"] == pytest.approx(np.degrees(0.5 * T), rel=1e-4)
    zeta, wn = 0.5, 0.3
    wd = wn * np.sqrt(1 - zeta**2)
    y2 = 0.3 * (1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta / np.sqrt(1 - zeta**2) * np.sin(wd * t)))
    m2 = ap.step_metrics(t, y2, 0.3, steer=np.sin(t))
    assert m2["overshoot_pct"] == pytest.approx(100 * np.exp(-zeta * np.pi / np.sqrt(1 - zeta**2)), rel=1e-4)
    assert m2["steady_state_error_deg"] == pytest.approx(0.0, abs=1e-6)
    assert m2["steer_rate_max"] == pytest.approx(1.0, abs=1e-3)


def test_closed_loop_on_nonlinear_ship_reaches_the_course():
    m = cs.models.shi_taylor(params={"c1": 0.0005})
    tr = cs.trim(m, x={"u": 8.0}, u={"n": 1.0}, free=["n"], zero=["u"])
    nom = ap.nomoto_from_model(m, tr.x, tr.u)
    g = ap.pid_pole_placement(nom, 0.05)
    pilot = ap.Autopilot(g, ap.ReferenceModel(0.05, 1.0, np.radians(1.0)), np.radians(35), np.radians(2.3))
    plant = ap.SteeringPlant(m, "delta", {"n": tr.values["n"]})
    cmd, t_end, steps = ap.course_scenario("course-20", 600)
    res = ap.simulate_autopilot(plant, pilot, cmd, t_end, step_times=steps, x0=tr.x, estimator="truth")
    first, second = res.metrics
    assert abs(first["steady_state_error_deg"]) < 0.2 and abs(second["steady_state_error_deg"]) < 0.2
    assert first["overshoot_deg"] < 2.0
    d = res.data
    assert np.all(np.abs(d["steer"]) <= np.radians(35) + 1e-12)
    assert np.max(np.abs(np.diff(d["steer"]))) <= np.radians(2.3) * 0.02 + 1e-12


def test_fit_nomoto_recovers_a_simulated_nomoto_ship():
    K, T = 0.08, 40.0
    m = cs.models.nomoto_first_order(K=K, T=T)
    t = np.arange(0.0, 600.0, 1.0)
    delta = np.radians(10) * np.sign(np.sin(2 * np.pi * t / 150.0) + 1e-9)
    tr = cs.simulate(m, m.states(), t, {"delta": delta}, max_step=0.1)
    rng = np.random.default_rng(4)
    data = cs.Dataset(t, {"delta": delta, "psi": tr["psi"] + np.radians(0.1) * rng.standard_normal(t.size)})
    nom, fit = ap.fit_nomoto(data, heading_var=np.radians(0.1) ** 2, guess=ap.Nomoto(0.05, 20.0))
    assert abs(nom.K - K) < 4 * fit.std_errors["K"]
    assert abs(nom.T - T) < 4 * fit.std_errors["T"]
    assert abs(fit.params["delta_0"]) < 4 * fit.std_errors["delta_0"]


def test_twin_propeller_allocation_inverts_the_thrust_law():
    import casadi as ca

    otter = cs.models.get_model("otter")
    pd = otter.param_dict()
    alloc = ap.twin_propeller_allocation(otter)
    tx, tn = ca.SX.sym("tx"), ca.SX.sym("tn")
    n = alloc({"tau_X": tx, "tau_N": tn}, {k: ca.SX(v) for k, v in pd.items()})
    f = ca.Function("f", [tx, tn], [n["n1"], n["n2"]])
    for tau_x, tau_n in ((100.0, 10.0), (20.0, -15.0), (5.0, 30.0)):
        n1, n2 = (float(v) for v in f(tau_x, tau_n))
        T = [(pd["k_pos"] if v >= 0 else pd["k_neg"]) * v * abs(v) for v in (n1, n2)]
        assert T[0] + T[1] == pytest.approx(tau_x, rel=1e-12)
        assert pd["y_pont"] * (T[0] - T[1]) == pytest.approx(tau_n, rel=1e-12)
    limit = ap.twin_propeller_yaw_limit(otter, 100.0)
    n1, n2 = (float(v) for v in f(100.0, limit))
    # at the limit one propeller sits exactly on its bound and the other inside its range
    on_bound = [n1 == pytest.approx(otter.vessel.propeller_range[1], rel=1e-9), n2 == pytest.approx(otter.vessel.propeller_range[0], rel=1e-9)]
    assert any(on_bound)
    assert otter.vessel.propeller_range[0] - 1e-9 <= min(n1, n2) and max(n1, n2) <= otter.vessel.propeller_range[1] + 1e-9
