"""MMG standard method and the KVLCC2 presets."""
import numpy as np
import pytest

from casship import simulate
from casship.models import get_model, kvlcc2, kvlcc2_l7
from model_checks import assert_jacobians


@pytest.mark.parametrize("factory", [kvlcc2, kvlcc2_l7])
def test_jacobians_match_central_differences(factory):
    ship = factory()
    rng = np.random.default_rng(3)
    U0 = ship.vessel.U0
    n0 = 1.8 * np.sqrt(320.0 / ship.vessel.L_pp)
    for _ in range(5):
        x = ship.states(u=U0 * rng.uniform(0.3, 1.1), v=U0 * rng.uniform(-0.2, 0.2),
                        r=U0 / ship.vessel.L_pp * rng.uniform(-0.6, 0.6), x=rng.normal(0, 100),
                        y=rng.normal(0, 100), psi=rng.uniform(-np.pi, np.pi))
        u = ship.inputs(delta=rng.uniform(-0.6, 0.6), n=n0 * rng.uniform(0.5, 1.2))
        assert_jacobians(ship, x, u)


def test_registered_names():
    assert get_model("kvlcc2").name == "kvlcc2"
    assert get_model("kvlcc2-l7").vessel.L_pp == 7.0


def test_port_starboard_symmetry():
    """The symmetric hull, rudder and (sign-balanced) wake: -delta mirrors +delta only if the
    flow-straightening and wake constants are made symmetric; with them, v, r, y, psi flip sign."""
    ship = kvlcc2({"gamma_R_minus": 0.5, "gamma_R_plus": 0.5, "C_2_plus": 1.3, "C_2_minus": 1.3})
    t = np.arange(0, 400, 0.5)
    x0 = ship.states(u=7.97)
    a = simulate(ship, x0, t, {"delta": np.radians(20), "n": 1.78})
    b = simulate(ship, x0, t, {"delta": -np.radians(20), "n": 1.78})
    for name in ("u", "x"):
        np.testing.assert_allclose(a[name], b[name], rtol=1e-9, atol=1e-9)
    for name in ("v", "r", "y", "psi"):
        np.testing.assert_allclose(a[name], -b[name], rtol=1e-9, atol=1e-9)
    assert a["psi"][-1] > np.radians(90)          # positive rudder turns to starboard


def test_default_preset_asymmetry_is_the_published_one():
    """With the published gamma_R (0.395/0.640) and C_2 (1.1/1.6) port and starboard differ."""
    ship = kvlcc2()
    t = np.arange(0, 300, 0.5)
    a = simulate(ship, ship.states(u=7.97), t, {"delta": np.radians(35), "n": 1.78})
    b = simulate(ship, ship.states(u=7.97), t, {"delta": -np.radians(35), "n": 1.78})
    assert a["psi"][-1] > 0 > b["psi"][-1]
    assert abs(a["psi"][-1] + b["psi"][-1]) > 1e-3


def test_zero_rudder_keeps_heading():
    ship = kvlcc2()
    t = np.arange(0, 600, 1.0)
    tr = simulate(ship, ship.states(u=7.97, psi=0.3), t, {"delta": 0.0, "n": 1.78})
    np.testing.assert_allclose(tr["psi"], 0.3, atol=1e-12)
    np.testing.assert_allclose(tr["v"], 0.0, atol=1e-12)
    course = np.arctan2(np.diff(tr["y"]), np.diff(tr["x"]))
    np.testing.assert_allclose(course, 0.3, atol=1e-9)


def test_no_propeller_decelerates():
    ship = kvlcc2()
    t = np.arange(0, 600, 1.0)
    tr = simulate(ship, ship.states(u=7.97), t, {"delta": 0.0, "n": 0.0})
    assert np.all(np.diff(tr["u"]) < 0)
    assert 0 < tr["u"][-1] < 0.7 * 7.97


def test_tau_port_and_noise_enter_through_the_mass_matrix():
    """A surge force F in ``tau`` changes du by F/(m + m_x); noise w_u adds directly."""
    ship = kvlcc2()
    pushed = ship.extend(lambda b: b.feed("tau", __import__("casadi").vertcat(b.param("F_push", 1e6), 0, 0)))
    x, u = ship.states(u=7.0), ship.inputs(n=1.7)
    f0 = np.asarray(ship.f(x, u, ship.params(), np.zeros(3))).ravel()
    f1 = np.asarray(pushed.f(x, u, pushed.params(), np.zeros(3))).ravel()
    P = ship.param_dict()
    m = P["rho"] * P["nabla"]
    m_x = P["m_x_dash"] * 0.5 * P["rho"] * P["L_pp"] ** 2 * P["d"]
    assert f1[0] - f0[0] == pytest.approx(1e6 / (m + m_x), rel=1e-12)
    fw = np.asarray(ship.f(x, u, ship.params(), np.array([0.1, 0, 0]))).ravel()
    assert fw[0] - f0[0] == pytest.approx(0.1, rel=1e-12)


def test_rudder_actuator_rate_limit():
    ship = kvlcc2(rudder_actuator=True)
    assert "delta" in ship.state_names and "delta_cmd" in ship.input_names
    t = np.arange(0, 30, 0.1)
    tr = simulate(ship, ship.states(u=7.97), t, {"delta_cmd": np.radians(35), "n": 1.78})
    rate = np.diff(tr["delta"]) / 0.1
    assert rate.max() <= np.radians(2.32) * (1 + 1e-9)
    assert rate.max() > 0.95 * np.radians(2.32)
    assert_jacobians(ship, tr.x[50], ship.inputs(delta_cmd=0.3, n=1.7))


def test_unknown_parameter_raises():
    with pytest.raises(ValueError, match="R0"):
        kvlcc2({"R0": 0.1})


# -- extended variant: asymmetry terms and smooth sign switches ---------------------------------
def _random_points(ship, count, seed):
    rng = np.random.default_rng(seed)
    U0 = ship.vessel.U0
    for _ in range(count):
        x = ship.states(u=U0 * rng.uniform(0.3, 1.1), v=U0 * rng.uniform(-0.2, 0.2),
                        r=U0 / ship.vessel.L_pp * rng.uniform(-0.6, 0.6), psi=rng.uniform(-np.pi, np.pi))
        yield x, ship.inputs(delta=rng.uniform(-0.6, 0.6), n=1.53 * rng.uniform(0.5, 1.2))


def test_asymmetry_terms_are_zero_by_default_and_leave_the_published_model_unchanged():
    pub, ext = kvlcc2(), kvlcc2(asymmetry=True)
    assert {"delta_0", "Y_0_dash", "N_0_dash"} <= set(ext.param_names)
    assert all(ext.param_dict()[k] == 0.0 for k in ("delta_0", "Y_0_dash", "N_0_dash"))
    for x, u in _random_points(pub, 20, 5):
        np.testing.assert_array_equal(np.asarray(ext.f(x, u, ext.params(), np.zeros(3))),
                                      np.asarray(pub.f(x, u, pub.params(), np.zeros(3))))
    assert pub.meta["options"] == {}
    assert ext.meta["options"] == {"asymmetry": True}
    both = kvlcc2(asymmetry=True, smooth=True, rudder_actuator=True)
    assert both.meta["options"] == {"asymmetry": True, "smooth": True, "rudder_actuator": True}
    again = get_model("kvlcc2", **both.meta["options"])
    assert again.param_names == both.param_names and again.state_names == both.state_names
    assert pub.vessel.param_set == "kvlcc2/YY2015-full-scale"
    assert ext.vessel.param_set == "kvlcc2/YY2015-full-scale+asymmetry"
    assert get_model("kvlcc2", asymmetry=True, smooth=True).vessel.param_set.endswith("+asymmetry+smooth")
    with pytest.raises(ValueError, match="asymmetry=True"):
        kvlcc2({"N_0_dash": 0.01})


def test_propeller_induced_force_scales_with_thrust():
    """``Y_P = Y'_0 T`` and ``N_P = N'_0 L T`` enter like an extra force at midship."""
    Y0, N0 = 0.01, -0.002
    ext = kvlcc2({"Y_0_dash": Y0, "N_0_dash": N0}, asymmetry=True)
    pub = kvlcc2()
    P = pub.param_dict()
    for x, u in _random_points(pub, 5, 11):
        U = np.hypot(x[0], x[1])
        beta_P = np.arctan2(-x[1], x[0]) - P["x_P_dash"] * x[2] * P["L_pp"] / U
        C2 = P["C_2_plus"] if beta_P > 0 else P["C_2_minus"]
        u_P = x[0] * (1 - P["w_P0"]) * (1 + (1 - np.exp(-P["C_1"] * abs(beta_P))) * (C2 - 1))
        n, D = u[1], P["D_p"]
        T = P["rho"] * D**2 * (P["k_0"] * n**2 * D**2 + P["k_1"] * n * D * u_P + P["k_2"] * u_P**2)
        pushed = pub.extend(lambda b: b.feed("tau", __import__("casadi").vertcat(0, Y0 * T, N0 * P["L_pp"] * T)))
        np.testing.assert_allclose(np.asarray(ext.f(x, u, ext.params(), np.zeros(3))).ravel(),
                                   np.asarray(pushed.f(x, u, pushed.params(), np.zeros(3))).ravel(),
                                   rtol=1e-10, atol=1e-14)


def test_rudder_neutral_angle_holds_a_straight_course():
    """With the rudder at ``delta_0`` the rudder gives no side force: the ship runs straight."""
    d0 = np.radians(1.5)
    ship = kvlcc2({"delta_0": d0}, asymmetry=True)
    t = np.arange(0, 300, 1.0)
    tr = simulate(ship, ship.states(u=7.97), t, {"delta": d0, "n": 1.53})
    np.testing.assert_allclose(tr["psi"], 0.0, atol=1e-12)
    np.testing.assert_allclose(tr["v"], 0.0, atol=1e-12)
    turned = simulate(ship, ship.states(u=7.97), t, {"delta": 0.0, "n": 1.53})
    assert turned["psi"][-1] < -np.radians(5)        # delta = 0 is now a port rudder
    with pytest.raises(ValueError, match="bounds"):
        kvlcc2({"delta_0": np.radians(20)}, asymmetry=True)


@pytest.mark.parametrize("kind, rudder", [("turning", 35.0), ("turning", -35.0), ("zigzag", 10.0), ("zigzag", -20.0)])
def test_smooth_switches_keep_the_published_indices_within_one_percent(kind, rudder):
    from casship.maneuvers import run_maneuver

    exact = run_maneuver(kvlcc2(), kind, rudder_deg=rudder, speed=7.97, n=1.53).metrics
    smooth = run_maneuver(kvlcc2(smooth=True), kind, rudder_deg=rudder, speed=7.97, n=1.53).metrics
    keys = (("advance_m", "transfer_m", "tactical_diameter_m", "steady_diameter_m") if kind == "turning"
            else ("overshoot_1_deg", "overshoot_2_deg", "initial_turning_time_s", "period_s"))
    for k in keys:
        assert smooth[k] == pytest.approx(exact[k], rel=0.01), k


def test_smooth_wake_within_stated_tolerance_and_differentiable():
    """The smooth wake differs by < 0.007 from the published one; its derivative in v is continuous
    at zero drift where the published one jumps."""
    import casadi as ca

    pub, smo = kvlcc2(), kvlcc2(smooth=True)
    u_in = pub.inputs(delta=0.0, n=1.53)
    for ship in (pub, smo):
        A = [np.asarray(ship.f_jac(ship.states(u=7.97, v=s), u_in, ship.params(), np.zeros(3))[0])
             for s in (-1e-7, 1e-7)]
        jump = abs(A[0][0, 1] - A[1][0, 1])           # d(du)/dv across v = 0
        if ship is pub:
            assert jump > 1e-4
        else:
            assert jump < 1e-8
    # the documented bound on the wake factor (1 - w_P), over drift angles of +-1 rad
    from casship.models.mmg import SMOOTH_WIDTH, smooth_abs, smooth_step

    P = pub.param_dict()
    b = np.linspace(-1, 1, 20001)
    sa = np.asarray(ca.Function("a", [x := ca.SX.sym("x")], [smooth_abs(x, SMOOTH_WIDTH)]).map(b.size)(b)).ravel()
    st = np.asarray(ca.Function("s", [x], [smooth_step(x, SMOOTH_WIDTH)]).map(b.size)(b)).ravel()
    exact = 1 + (1 - np.exp(-P["C_1"] * np.abs(b))) * (np.where(b > 0, P["C_2_plus"], P["C_2_minus"]) - 1)
    smooth = 1 + (1 - np.exp(-P["C_1"] * sa)) * (P["C_2_minus"] + (P["C_2_plus"] - P["C_2_minus"]) * st - 1)
    assert np.abs((1 - P["w_P0"]) * (exact - smooth)).max() < 0.007
    assert np.all(np.abs(sa - np.abs(b)) <= SMOOTH_WIDTH)
    for x, u in _random_points(smo, 5, 7):
        assert_jacobians(smo, x, u)
    ext = kvlcc2({"delta_0": 0.01, "Y_0_dash": 0.02, "N_0_dash": -0.01}, asymmetry=True, smooth=True)
    for x, u in _random_points(ext, 5, 8):
        assert_jacobians(ext, x, u)


def test_physical_bounds_on_interaction_factors():
    ship = kvlcc2()
    lo, hi = dict(zip(ship.param_names, ship.param_lower)), dict(zip(ship.param_names, ship.param_upper))
    assert (lo["w_P0"], hi["w_P0"]) == (0.0, 1.0) and (lo["kappa"], hi["kappa"]) == (0.0, 1.0)
    assert lo["epsilon"] == 0.0 and lo["R_0_dash"] == 0.0 and (lo["t_P"], hi["t_P"]) == (0.0, 1.0)
    with pytest.raises(ValueError, match="w_P0"):
        kvlcc2({"w_P0": 1.2})


# -- rudder inflow: the race added to the wake (option rudder_inflow) -----------------------------
def _rudder_force_by_hand(P, x, u, additive, c3=0.0):
    """``(X_R, Y_R, N_R)`` of Yasukawa & Yoshimura (2015) Eq. 17-27 written out, with the inflow
    ``u_R`` in the published or the race-additive form (published if_else switches) and the normal
    force ``f_alpha (sin a - c3 sin^3 a)`` (``c3 = 0``: the published sine)."""
    uu, v, r = x[0], x[1], x[2]
    delta, n = u[0], u[1]
    L, D = P["L_pp"], P["D_p"]
    U = np.sqrt(uu**2 + v**2 + 1e-12)
    beta = np.arctan2(-v, uu)
    r_dash = r * L / U
    beta_P = beta - P["x_P_dash"] * r_dash
    C2 = P["C_2_plus"] if beta_P > 0 else P["C_2_minus"]
    u_P = uu * (1 - P["w_P0"]) * (1 + (1 - np.exp(-P["C_1"] * abs(beta_P))) * (C2 - 1))
    J = u_P / (n * D)
    K_T = P["k_0"] + P["k_1"] * J + P["k_2"] * J**2
    eta, eps, kap = D / P["H_R"], P["epsilon"], P["kappa"]
    u_inf = u_P * np.sqrt(1 + 8 * K_T / (np.pi * J**2))          # momentum theory: the far race
    if additive:
        u_R = np.sqrt(eta * (eps * u_P + kap * (u_inf - u_P)) ** 2 + (1 - eta) * (eps * u_P) ** 2)
    else:
        u_R = eps * u_P * np.sqrt(eta * (1 + kap * (np.sqrt(1 + 8 * K_T / (np.pi * J**2)) - 1)) ** 2 + 1 - eta)
    beta_R = beta - P["l_R_dash"] * r_dash
    v_R = U * (P["gamma_R_minus"] if beta_R < 0 else P["gamma_R_plus"]) * beta_R
    alpha_R = delta - np.arctan2(v_R, u_R)
    F_N = 0.5 * P["rho"] * P["A_R"] * (u_R**2 + v_R**2) * P["f_alpha"] * (np.sin(alpha_R) - c3 * np.sin(alpha_R) ** 3)
    return np.array([-(1 - P["t_R"]) * F_N * np.sin(delta), -(1 + P["a_H"]) * F_N * np.cos(delta),
                     -(P["x_R_dash"] + P["a_H"] * P["x_H_dash"]) * L * F_N * np.cos(delta)])


@pytest.mark.parametrize("inflow", ["published", "race-additive"])
def test_rudder_force_matches_a_hand_computation(inflow):
    from casship.models.mmg import mmg_forces

    ship = kvlcc2(rudder_inflow=inflow)
    P = ship.param_dict()
    no_rudder = dict(P, f_alpha=0.0)
    for x, u in _random_points(ship, 8, 21):
        total = np.array([float(f) for f in mmg_forces(P, *x[:3], *u, rudder_inflow=inflow)])
        rest = np.array([float(f) for f in mmg_forces(no_rudder, *x[:3], *u, rudder_inflow=inflow)])
        np.testing.assert_allclose(total - rest, _rudder_force_by_hand(P, x, u, inflow != "published"),
                                   rtol=1e-7, atol=1.0)


def test_race_additive_inflow_is_an_option_that_leaves_the_published_model_alone():
    pub, add = kvlcc2(), kvlcc2(rudder_inflow="race-additive")
    assert pub.meta["options"] == {} and add.meta["options"] == {"rudder_inflow": "race-additive"}
    assert add.vessel.param_set == "kvlcc2/YY2015-full-scale+race-additive"
    again = get_model("kvlcc2", **add.meta["options"])
    # the two forms agree where the wake ratio is one, and differ elsewhere
    one = {"epsilon": 1.0}
    pub1, add1 = kvlcc2(one), kvlcc2(one, rudder_inflow="race-additive")
    for x, u in _random_points(pub, 6, 8):
        np.testing.assert_allclose(np.asarray(add1.f(x, u, add1.params(), np.zeros(3))),
                                   np.asarray(pub1.f(x, u, pub1.params(), np.zeros(3))), rtol=1e-12, atol=1e-15)
        assert not np.allclose(np.asarray(again.f(x, u, again.params(), np.zeros(3))),
                               np.asarray(pub.f(x, u, pub.params(), np.zeros(3))), rtol=1e-6, atol=0.0)
    # a heavily loaded propeller (tight turn): a larger wake ratio raises the rudder force less
    P = pub.param_dict()
    turn = (np.array([3.0, -1.0, 0.0073]), np.array([np.radians(35.0), 1.53]))
    ratio = {}
    for additive in (False, True):
        lo = _rudder_force_by_hand(P, *turn, additive)[1]
        hi = _rudder_force_by_hand(dict(P, epsilon=1.2 * P["epsilon"]), *turn, additive)[1]
        ratio[additive] = hi / lo
    assert ratio[True] < ratio[False]
    with pytest.raises(ValueError, match="rudder_inflow"):
        kvlcc2(rudder_inflow="wake")


# -- rudder lift: loss of lift slope at large effective angle (option rudder_lift) -----------------
@pytest.mark.parametrize("inflow", ["published", "race-additive"])
def test_cubic_rudder_lift_matches_a_hand_computation(inflow):
    from casship.models.mmg import mmg_forces

    ship = kvlcc2({"c_alpha3": 0.4}, rudder_lift="cubic", rudder_inflow=inflow)
    P = ship.param_dict()
    assert P["c_alpha3"] == 0.4
    no_rudder = dict(P, f_alpha=0.0)
    for x, u in _random_points(ship, 8, 23):
        total = np.array([float(f) for f in mmg_forces(P, *x[:3], *u, rudder_inflow=inflow)])
        rest = np.array([float(f) for f in mmg_forces(no_rudder, *x[:3], *u, rudder_inflow=inflow)])
        np.testing.assert_allclose(total - rest, _rudder_force_by_hand(P, x, u, inflow != "published", c3=0.4),
                                   rtol=1e-7, atol=1.0)


def test_cubic_rudder_lift_in_straight_run_scales_the_force_by_one_minus_c_sin_squared():
    """Straight ahead (v = r = 0) the effective angle is the rudder angle: at 35 deg, c_alpha3 = 0.5
    leaves 1 - 0.5 sin^2(35 deg) = 0.835505 of the published rudder force, at 10 deg 0.984923."""
    from casship.models.mmg import mmg_forces

    pub = kvlcc2().param_dict()
    cubic = kvlcc2({"c_alpha3": 0.5}, rudder_lift="cubic").param_dict()
    for delta_deg, kept in ((35.0, 0.835505), (10.0, 0.984923), (-35.0, 0.835505)):
        delta = np.radians(delta_deg)
        f = [np.array([float(v) for v in mmg_forces(P, 7.97, 0.0, 0.0, delta, 1.53)])
             - np.array([float(v) for v in mmg_forces(dict(P, f_alpha=0.0), 7.97, 0.0, 0.0, delta, 1.53)])
             for P in (pub, cubic)]
        np.testing.assert_allclose(f[1], kept * f[0], rtol=1e-6)


@pytest.mark.parametrize("option, value, param, moved, suffix", [
    ("rudder_lift", "cubic", "c_alpha3", 0.5, "cubic-lift"),
    ("rudder_lever", "loading", "x_HJ_dash", -2.0, "loading-lever")])
def test_a_model_variant_is_an_option_that_leaves_the_published_model_alone(option, value, param, moved, suffix):
    pub, variant = kvlcc2(), kvlcc2(**{option: value})
    assert variant.param_dict()[param] == 0.0 and param not in pub.param_names
    assert variant.meta["options"] == {option: value}
    assert variant.vessel.param_set == f"kvlcc2/YY2015-full-scale+{suffix}"
    assert get_model("kvlcc2", **variant.meta["options"]).vessel.param_set == variant.vessel.param_set
    other = kvlcc2({param: moved}, **{option: value})
    for x, u in _random_points(pub, 10, 9):       # at its preset the variant is the published model, exactly
        np.testing.assert_array_equal(np.asarray(variant.f(x, u, variant.params(), np.zeros(3))),
                                      np.asarray(pub.f(x, u, pub.params(), np.zeros(3))))
        assert not np.allclose(np.asarray(other.f(x, u, other.params(), np.zeros(3))),
                               np.asarray(pub.f(x, u, pub.params(), np.zeros(3))), rtol=1e-6, atol=0.0)
    assert_jacobians(other, *next(_random_points(other, 1, 4)))
    assert kvlcc2_l7(**{option: value}).vessel.param_set == f"kvlcc2/YY2015-L7+{suffix}"
    with pytest.raises(ValueError, match=f"{option}='{value}'"):
        kvlcc2({param: 0.1})
    with pytest.raises(ValueError, match=option):
        kvlcc2(**{option: "no-such-form"})


def test_cubic_rudder_lift_beyond_its_bound_is_refused():
    with pytest.raises(ValueError, match="c_alpha3"):
        kvlcc2({"c_alpha3": 1.5}, rudder_lift="cubic")      # beyond the bound: the force would peak below 35 deg


# -- rudder lever: the hull's share of the rudder force moving with the loading (option rudder_lever) --
def test_loading_rudder_lever_moves_the_yaw_moment_by_the_hand_computed_amount():
    """Straight ahead (v = r = 0: 1 - w_P = 1 - w_P0) the loading lever adds a_H x'_HJ L J_P RY to the
    yaw moment (RY = -F_N cos(delta)), with J_P = u (1 - w_P0) n D / (n^2 D^2 + 1e-6); X and Y stay."""
    from casship.models.mmg import mmg_force_parts

    pub = kvlcc2().param_dict()
    lever = kvlcc2({"x_HJ_dash": -2.0}, rudder_lever="loading").param_dict()
    for delta_deg, n in ((35.0, 1.53), (-20.0, 1.78), (10.0, 0.9)):
        delta = np.radians(delta_deg)
        a, b = (mmg_force_parts(P, 7.97, 0.0, 0.0, delta, n) for P in (pub, lever))
        D = pub["D_p"]
        J_P = 7.97 * (1 - pub["w_P0"]) * n * D / (n**2 * D**2 + 1e-6)
        expected = pub["a_H"] * -2.0 * pub["L_pp"] * J_P * float(a["RY"])
        assert abs(expected) > 1e6                       # a moment the test can see
        np.testing.assert_allclose(float(b["N"]) - float(a["N"]), expected, rtol=1e-9)
        for c in ("X", "Y", "RY", "T"):
            assert float(b[c]) == float(a[c])
