"""Autopilot building blocks: Nomoto models, designs, reference model, law, steering gear, metrics."""
import casadi as ca
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
    assert ap.margins(ap.loop_transfer(nom, g))["closed_loop_stable"]


def test_lqr_gains_equal_control_lqr_on_the_hand_written_model(nomoto):
    g = ap.lqr_design(nomoto, q_int=1e-4, q_e=1.0, q_r=100.0, r_delta=1.0)
    a, b = 1 / nomoto.T, nomoto.K / nomoto.T
    A = np.array([[0, 1, 0], [0, 0, 1], [0, 0, -a]])
    B = np.array([[0], [0], [b]])
    K, _, E = control.lqr(A, B, np.diag([1e-4, 1.0, 100.0]), [[1.0]])
    np.testing.assert_allclose([g.Ki, g.Kp, g.Kd], np.ravel(K), rtol=1e-9)
    np.testing.assert_allclose(np.sort_complex(ap.closed_loop_tf(nomoto, g).poles()), np.sort_complex(E), atol=1e-8)


def test_design_from_the_labelled_linearisation_equals_design_from_its_nomoto_model():
    ship = cs.models.get_model("kvlcc2")
    plant = ap.steering_plant(ship)
    lin = ap.course_linearization(plant)
    assert lin.input_labels == ["delta"] and lin.output_labels == ["chi", "psi", "r"]
    nom = ap.nomoto_from_linear(lin)
    full = ap.nomoto_from_model(ship, plant.x0, plant.input_vector(0.0), steer="delta")
    assert (nom.K, nom.T1, nom.T2, nom.T3) == pytest.approx((full.K, full.T1, full.T2, full.T3), rel=1e-9)
    assert ap.pid_pole_placement(lin, 0.02) == ap.pid_pole_placement(nom, 0.02)
    assert ap.lqr_design(lin, q_int=1e-6, q_e=1.0) == ap.lqr_design(nom, q_int=1e-6, q_e=1.0)


def test_course_output_of_the_linearisation_is_exact():
    """The linearised course-over-ground output against central differences of atan2(y', x')."""
    otter = cs.models.get_model("otter")
    plant = ap.steering_plant(otter)
    lin = ap.course_linearization(plant)
    m, x0 = plant.model, plant.x0.copy()
    x0[m.index("v")], x0[m.index("r")] = 0.05, 0.02          # off the straight run, so that beta matters
    lin = ap.course_linearization(plant, x0)

    def chi(x, s):
        xd = np.ravel(m.f(x, plant.input_vector(s), plant.pvec, np.zeros(m.nw)))
        return np.arctan2(xd[m.index("y")], xd[m.index("x")])

    h = 1e-6
    row = dict(zip(lin.state_labels, np.ravel(lin.C[0])))
    for name in ("v", "r", "psi"):
        e = np.zeros(m.nx)
        e[m.index(name)] = h
        assert row[name] == pytest.approx((chi(x0 + e, 0.0) - chi(x0 - e, 0.0)) / (2 * h), rel=1e-6, abs=1e-9)
    assert float(lin.D[0, 0]) == pytest.approx((chi(x0, h) - chi(x0, -h)) / (2 * h), rel=1e-6, abs=1e-12)


def test_nomoto_from_linearised_second_order_model():
    m = cs.models.nomoto_second_order(K=0.185, T1=118.0, T2=7.8, T3=18.5)
    nom = ap.nomoto_from_model(m, steer="delta", yaw_rate="r")
    assert (nom.K, nom.T1, nom.T2, nom.T3) == pytest.approx((0.185, 118.0, 7.8, 18.5), rel=1e-6)
    assert nom.T == pytest.approx(118.0 + 7.8 - 18.5, rel=1e-6)
    with pytest.raises(ValueError, match="no output 'r'"):
        ap.nomoto_from_linear(cs.linearize(m, outputs=["psi"]))


def test_reference_model_is_the_linear_filter_without_saturation():
    ref = ap.ReferenceModel(wn=0.5, zeta=1.0)
    t = np.arange(0, 60, 0.001)
    X = ref.response(t, 0.2)
    lin = control.step_response(ref.tf(), t).outputs * 0.2
    np.testing.assert_allclose(X[:, 0], lin, atol=2e-4)       # Euler at dt = 1 ms
    assert X[-1, 0] == pytest.approx(0.2, abs=1e-6)
    # the labelled state space and the transfer function have the same characteristic polynomial
    np.testing.assert_allclose(np.poly(ref.system().A), np.ravel(ref.tf().den[0][0]), rtol=1e-12)


def test_reference_model_rate_saturation_and_wrap():
    ref = ap.ReferenceModel(wn=1.0, zeta=1.0, r_max=np.radians(2))
    X = ref.response(np.arange(0, 60, 0.02), np.radians(40))
    assert np.max(np.abs(X[:, 1])) <= np.radians(2) + 1e-12
    assert X[-1, 0] == pytest.approx(np.radians(40), abs=1e-3)
    # the reference crosses +-180 deg the short way round
    Xw = ref.response(np.arange(0, 60, 0.02), np.radians(-170), x0=(np.radians(170), 0, 0))
    assert np.all(np.abs(Xw[:, 0]) > np.radians(165))


def _run_law(autopilot, chi, r, ref=0.3, n=200, dt=0.1):
    f = autopilot.function
    mem = autopilot.memory0(0.0)
    out = []
    for _ in range(n):
        o = f.call({"memory": mem, "ref": ref, "chi": chi, "r": r, "dt": dt})
        mem = np.ravel(np.array(o["memory_next"]))
        out.append((float(o["steer"]), mem[Autopilot_memory_index("z")]))
    return np.array(out)


def Autopilot_memory_index(name):
    return ap.Autopilot.MEMORY.index(name)


def test_saturation_and_anti_windup(nomoto):
    g = ap.pid_pole_placement(nomoto, 0.05)
    ref = ap.ReferenceModel(10.0)                 # fast: chi_d follows the command
    lim = ap.Autopilot(g, ref, steer_max=np.radians(10), anti_windup=True)
    out = _run_law(lim, chi=0.0, r=0.0)
    assert np.max(np.abs(out[:, 0])) <= np.radians(10) + 1e-12
    assert abs(out[-1, 0]) == pytest.approx(np.radians(10))
    # held error with the command saturated: the integrator stops (anti-windup), without it it grows
    free = ap.Autopilot(g, ref, steer_max=np.radians(10), anti_windup=False)
    wind = _run_law(free, chi=0.0, r=0.0)
    assert abs(out[-1, 1]) < 0.5 * abs(wind[-1, 1])


def test_actuator_servo_rate_limit_and_flag():
    act = ap.Actuator(steer_max=np.radians(35), rate_max=np.radians(2.32), T=1.0)
    s, c, h = ca.SX.sym("s"), ca.SX.sym("c"), ca.SX.sym("h")
    o = act.symbolic_step(s, c, h)
    f = ca.Function("a", [s, c, h], [o["steer"], o["rate_limited"]])
    dt = 0.1
    # small command: first-order servo, rate limit inactive
    nxt, flag = (float(v) for v in f(0.0, np.radians(0.1), dt))
    assert nxt == pytest.approx(np.radians(0.1) * (1 - np.exp(-dt)), rel=1e-12) and flag == 0.0
    # hard over: the change is the rate limit, flagged; the command is clipped to the angle limit
    nxt, flag = (float(v) for v in f(0.0, np.radians(90), dt))
    assert nxt == pytest.approx(np.radians(2.32) * dt, rel=1e-12) and flag == 1.0
    nxt, _ = (float(v) for v in f(np.radians(34.99), np.radians(90), dt))
    assert nxt <= np.radians(35) + 1e-15
    with pytest.raises(ValueError, match="rate_max"):
        ap.Actuator(rate_max=0.0)


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


def test_course_scenarios():
    cmd, t_end, steps = ap.course_scenario("course-30", 100.0)
    assert (t_end, steps) == (100.0, [0.0, 50.0])
    assert cmd(49.9) == pytest.approx(np.radians(30)) and cmd(50.0) == 0.0
    assert ap.course_scenario("step-10", segment=70.0)[1] == 70.0
    with pytest.raises(ValueError, match="zigzag"):
        ap.course_scenario("zigzag")


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
    lo, hi = otter.vessel.propeller_range
    # at the limit one propeller sits on its bound, the other inside the range
    assert min(abs(n1 - hi), abs(n2 - lo)) < 1e-9 * hi
    assert lo - 1e-9 <= min(n1, n2) and max(n1, n2) <= hi + 1e-9


def test_steering_plant_of_a_two_propeller_craft_and_errors():
    otter = cs.models.get_model("otter")
    plant = ap.steering_plant(otter, 1.5)
    assert plant.steer == "tau_N" and plant.x0[plant.model.index("u")] == pytest.approx(1.5)
    xdot = np.ravel(plant.model.f(plant.x0, plant.input_vector(0.0), plant.pvec, np.zeros(plant.model.nw)))
    assert abs(xdot[plant.model.index("u")]) < 1e-9          # the surge force holds the speed
    with pytest.raises(ValueError, match="names no rudder"):
        ap.steering_plant(cs.models.get_model("sog-cog"), 1.0)
    with pytest.raises(ValueError, match="unknown input"):
        ap.SteeringPlant(otter, "n1", {"n2": 1.0, "tau": 2.0})
