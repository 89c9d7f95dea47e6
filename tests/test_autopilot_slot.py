"""The controller slot: python-control controllers in the compiled closed loop."""
import warnings

import control
import numpy as np
import pytest

from casship import autopilot as ap
from casship.models import get_model


@pytest.fixture(scope="module")
def kvlcc2():
    return ap.design_autopilot(get_model("kvlcc2"))


def _reference_commands(ctrl, data):
    """The controller stepped in NumPy from the logged loop signals: the discretised matrices of
    ``control.sample_system``, the observer-form anti-windup written out, the gear's limits."""
    sysd = control.sample_system(ctrl.source, ctrl.dt, method="zoh")
    A, B, C, D = (np.asarray(M, float) for M in (sysd.A, sysd.B, sysd.C, sysd.D))
    act, L = ctrl.actuator, ctrl.L
    gain = 1 - np.exp(-ctrl.dt / act.T)
    x = np.zeros(A.shape[0])
    out = []
    for k in range(len(data)):
        e = np.angle(np.exp(1j * (data["chi_hat"][k] - data["chi_d"][k])))
        sig = {"chi_d": data["chi_d"][k], "r_d": data["r_d"][k], "a_d": data["a_d"][k], "e": e,
               "chi": data["chi_d"][k] + e, "r": data["omega_hat"][k]}
        y = np.array([sig[n] for n in sysd.input_labels])
        u = float((C @ x + D @ y)[0])
        cmd = min(max(u, -act.steer_max), act.steer_max)
        change = (cmd - data["steer"][k]) * gain
        step = act.rate_max * ctrl.dt
        gear = data["steer"][k] + np.clip(change, -step, step) / gain if abs(change) > step else cmd
        out.append(cmd)
        x = A @ x + B @ y + L[:, 0] * (gear - u)
    return np.array(out)


def test_statespace_controller_in_the_compiled_loop_equals_a_stepwise_reference(kvlcc2):
    d = kvlcc2
    # a PID with a derivative filter, as python-control builds it (inputs e and r), aggressive enough
    # that the rudder saturates and the anti-windup acts
    g = d.gains
    pid = control.ss(control.tf([-2 * g.Kp], [1.0]) + control.tf([-g.Ki * 3], [1.0, 0.0]),
                     inputs=["e"], outputs=["delta_c"])
    damp = control.ss(control.tf([-g.Kd, 0.0], [5.0, 1.0]), inputs=["r"], outputs=["delta_c"])
    ctrl_sys = control.summing_junction(["a", "b"], "delta_c")
    sys = control.interconnect([control.ss(pid, outputs=["a"], name="p"), control.ss(damp, outputs=["b"], name="q"),
                                ctrl_sys], inplist=["e", "r"], inputs=["e", "r"], outlist=["delta_c"],
                               outputs=["delta_c"])
    # a fast reference model makes the 60 deg change a near step: the rudder saturates and the
    # rate limit binds
    ctrl = ap.LinearController(sys, d.settings.dt, ap.ReferenceModel(0.5), d.actuator)
    ctrl.source = sys
    loop = d.closed_loop_system(controller=ctrl)
    data = loop.run(np.radians(60.0), 900.0, seed=4)
    assert np.mean(np.abs(data["steer_cmd"]) >= d.actuator.steer_max * (1 - 1e-12)) > 0.02   # saturates
    assert np.mean(data["rate_limited"]) > 0.01
    np.testing.assert_allclose(data["steer_cmd"], _reference_commands(ctrl, data), rtol=0, atol=1e-12)
    stepwise = loop.run_stepwise(np.radians(60.0), 900.0, seed=4)
    for key in ("steer_cmd", "steer", "psi", "chi_hat"):
        np.testing.assert_allclose(data[key], stepwise[key], rtol=0, atol=1e-12)


def test_pid_controller_system_reproduces_the_linear_law(kvlcc2):
    """The design's own python-control controller in the slot is the PID law with the linear
    feed-forward, sampled: the course changes agree with the law's to a small fraction."""
    d = kvlcc2
    slot = d.simulate(controller=d.controller, warn=False)
    law = ap.design_autopilot(get_model("kvlcc2"), feedforward="linear").simulate(warn=False)
    for a, b in zip(slot.metrics, law.metrics):
        assert a["overshoot_pct"] == pytest.approx(b["overshoot_pct"], abs=0.05)


def test_transfer_function_and_lqg_controllers(kvlcc2):
    d = kvlcc2
    tf = control.tf([-d.gains.Kd, -d.gains.Kp, -d.gains.Ki], [2.0, 1.0, 0.0], inputs="e", outputs="delta_c")
    res = d.simulate("course-20", controller=tf, warn=False)
    assert all(m["overshoot_pct"] < 15 for m in res.metrics)
    nom = d.nomoto
    w = ap.defaults.default_lqr_weights(nom, d.settings.wn)
    lqg = ap.lqg_design(nom, **w, heading_var=np.radians(0.5) ** 2 * 0.1, rate_var=np.radians(0.02) ** 2 * 0.2,
                        yaw_accel_var=1e-9)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ap.RateLimitWarning)
        res = d.simulate("course-60", controller=lqg.controller, estimator="raw")
    for m in res.metrics:
        assert m["overshoot_pct"] <= 10 and np.isfinite(m["settling_time_s"])


def test_slot_errors_name_the_problem(kvlcc2):
    d = kvlcc2
    with pytest.raises(ValueError, match="not loop signals"):
        d.linear_controller(control.ss([], [], [], [[1.0]], inputs=["speed"], outputs=["u"]))
    with pytest.raises(ValueError, match="one output"):
        d.linear_controller(control.ss([], [], [], [[1.0], [2.0]], inputs=["e"], outputs=["a", "b"]))
    with pytest.raises(ValueError, match="sample time"):
        d.linear_controller(control.ss([[0.5]], [[1.0]], [[1.0]], [[0.0]], dt=0.7, inputs=["e"], outputs=["u"]))
    with pytest.raises(TypeError, match="StateSpace or TransferFunction"):
        d.linear_controller(np.eye(2))
