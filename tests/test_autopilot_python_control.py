"""The designs as python-control objects: same poles and margins as casship's own analysis."""
import control
import numpy as np
import pytest

import casship as cs
from casship import autopilot as ap


@pytest.fixture(scope="module")
def kvlcc2():
    return ap.design_autopilot(cs.models.get_model("kvlcc2"))


def test_controller_is_a_labelled_state_space_with_the_pid_law(nomoto=ap.Nomoto(0.185, 107.3)):
    g = ap.pid_pole_placement(nomoto, 0.05)
    C = g.controller()
    assert isinstance(C, control.StateSpace)
    assert C.input_labels == ["chi_d", "r_d", "a_d", "chi", "r"] and C.output_labels == ["delta_c"]
    # feedback part: -(Kp + Ki/s) on the course, -Kd on the rate
    s = 0.3j
    H = C(s)
    assert H[0, 3] == pytest.approx(-(g.Kp + g.Ki / s))
    assert H[0, 4] == pytest.approx(-g.Kd)
    assert H[0, 2] == pytest.approx(g.m) and H[0, 1] == pytest.approx(g.d + g.Kd)


def test_interconnected_closed_loop_has_the_placed_poles():
    """control.interconnect of the labelled Nomoto plant and the controller gives the poles that the
    pole placement put there (no servo, no delay, no estimator)."""
    nom = ap.Nomoto(0.185, 107.3)
    g = ap.pid_pole_placement(nom, 0.05, 0.9, integral="exact")
    L, closed = ap.loop_systems(nom.system(), g, ap.Actuator(), controlled="psi")
    want = np.sort_complex(np.array(g.poles))
    np.testing.assert_allclose(np.sort_complex(closed.poles()), want, atol=1e-8)
    np.testing.assert_allclose(np.sort_complex(control.feedback(L, 1).poles()), want, atol=1e-8)


def test_margins_are_python_controls(kvlcc2):
    L = kvlcc2.loop
    gm, pm, wpc, wgc = control.margin(L)
    mg = kvlcc2.margins
    assert mg["gain_margin_db"] == pytest.approx(20 * np.log10(gm), rel=1e-9)
    assert mg["phase_margin_deg"] == pytest.approx(pm, rel=1e-9)
    assert mg["gain_crossover_rad_s"] == pytest.approx(wgc, rel=1e-9)
    gms, _, _, _, _, _ = control.stability_margins(L, returnall=True)
    gms = np.asarray(gms)
    assert mg["upper_gain_margin_db"] == pytest.approx(20 * np.log10(gms[gms > 1].min()), rel=1e-9)
    assert mg["lower_gain_margin_db"] == pytest.approx(20 * np.log10(gms[gms < 1].max()), rel=1e-9)
    # the closed loop of the design and feedback(L, 1) agree on stability (all poles in the left half plane)
    assert mg["closed_loop_stable"]
    assert np.all(np.real(control.ss(kvlcc2.closed_loop).poles()) < 1e-9)


def test_conditionally_stable_loop_python_control_reports_the_lower_margin():
    """A slow PID on a sluggish ship: the lower gain margin is nearer 0 dB than the upper one, and
    control.margin returns it (negative in dB). casship reports it as python-control does and both
    readings beside it."""
    nom = ap.Nomoto(0.17, 550.0)
    g = ap.pid_pole_placement(nom, 0.01, 1.0, integral="exact", wi_ratio=0.5)
    L = ap.loop_transfer(nom, g, actuator_T=1.0, delay=0.2, order=1)
    mg = ap.margins(L)
    gm = control.margin(L)[0]
    assert gm < 1 and mg["gain_margin_side"] == "lower"
    assert mg["gain_margin_db"] == pytest.approx(20 * np.log10(gm), rel=1e-9)
    assert mg["lower_gain_margin_db"] == pytest.approx(mg["gain_margin_db"], rel=1e-9)
    assert mg["upper_gain_margin_db"] > 0 > mg["lower_gain_margin_db"]
    # the readings mean what they say: scaling the loop gain past either margin destabilises it
    for db, stable in ((mg["upper_gain_margin_db"] - 0.5, True), (mg["upper_gain_margin_db"] + 0.5, False),
                       (mg["lower_gain_margin_db"] + 0.5, True), (mg["lower_gain_margin_db"] - 0.5, False)):
        poles = control.feedback(10 ** (db / 20) * L, 1).poles()
        assert bool(np.all(np.real(poles) < 0)) == stable, db


def test_bode_phase_on_the_branch_of_the_phase_margin(kvlcc2):
    L = kvlcc2.loop
    mg = kvlcc2.margins
    w = np.logspace(-5, 1, 2000)
    phase = ap.bode_phase_deg(L, w)
    assert -360.0 <= phase[0] <= 0.0
    at_crossover = np.interp(np.log(mg["gain_crossover_rad_s"]), np.log(w), phase)
    assert at_crossover == pytest.approx(-180.0 + mg["phase_margin_deg"], abs=0.5)


def test_plot_design_writes_a_png(kvlcc2, tmp_path):
    path = ap.plot_design(kvlcc2.loop, tmp_path / "loop.png", "kvlcc2", kvlcc2.closed_loop)
    assert path.exists() and path.stat().st_size > 10_000


def test_lqg_estimator_is_control_lqe_and_casships_kf_converges_to_dlqe():
    """LQG: the Kalman gain of the python-control system is control.lqe's; the casship filter on the
    same heading model (EKF on a linear model = KF) converges to the steady state of control.dlqe."""
    nom = ap.Nomoto(0.185, 107.3)
    heading_var, rate_var, q_r = np.radians(0.5) ** 2, np.radians(0.02) ** 2, 1e-9
    lqg = ap.lqg_design(nom, q_int=1e-6, q_e=1.0, q_r=100.0, heading_var=heading_var, rate_var=rate_var,
                        yaw_accel_var=q_r, bias_var=1e-8)
    assert lqg.controller.input_labels == ["chi_d", "r_d", "a_d", "psi_m", "r_m"]
    assert np.all(np.real(lqg.estimator.poles()) < 0)
    dt = 0.5
    obs = ap.heading_observer(nom.K, nom.T)
    kf = ap.heading_kf(obs, dt, compass_std=np.sqrt(heading_var), gyro_std=np.sqrt(rate_var), q_r=q_r, q_b=1e-8,
                      options={"outputs": ("x", "P", "P_pred")})
    dm = cs.discretize(obs, dt, "rk4")
    A, _, _, G = (np.asarray(v) for v in dm.F_jac(np.zeros(3), 0.0, obs.params(), np.zeros(obs.nw), dt))
    C = np.eye(2, 3)
    _, P_dlqe, _ = control.dlqe(A, G, C, kf.Q, kf.R)
    run = kf.online(cs.Gaussian(np.zeros(3), np.diag([1e-4, 1e-6, 1e-2])), u=np.zeros(1))
    for _ in range(4000):
        run.update(np.zeros(2), dt)
    np.testing.assert_allclose(run.info["P_pred"], P_dlqe, rtol=1e-9)


def test_design_value_summary_and_repr(kvlcc2):
    s = kvlcc2.summary()
    assert s["steer"] == "delta" and s["sources"]["speed"].startswith("the vessel's approach speed")
    assert "PM=" in repr(kvlcc2)
    assert isinstance(kvlcc2.controller, control.StateSpace)
    assert kvlcc2.closed_loop.input_labels == ["chi_ref"]
    assert kvlcc2.closed_loop.output_labels == ["chi", "r", "delta_c", "delta"]
