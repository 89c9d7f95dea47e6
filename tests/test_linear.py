"""Exact linearisation, python-control round trip and trim."""
import control
import numpy as np
import pytest

import casship as cs
from casship.linear import linearize, to_iosys, trim


def _central_jacobian(fun, z0, eps=1e-6):
    cols = []
    for i in range(z0.size):
        dz = np.zeros_like(z0)
        dz[i] = eps
        cols.append((fun(z0 + dz) - fun(z0 - dz)) / (2 * eps))
    return np.column_stack(cols)


def test_linearize_equals_central_differences_and_keeps_labels():
    m = cs.models.shi_taylor()
    x0 = m.states(u=7.5, v=0.3, r=0.01, psi=0.4)
    u0 = m.inputs(delta=0.1, n=1.4)
    p = m.params()
    sys = linearize(m, x0, u0, outputs=["u", "r", "psi"])
    f = lambda x, u: np.array(m.f(x, u, p, np.zeros(m.nw))).ravel()  # noqa: E731
    A = _central_jacobian(lambda x: f(x, u0), x0)
    B = _central_jacobian(lambda u: f(x0, u), u0)
    np.testing.assert_allclose(sys.A, A, atol=1e-7)
    np.testing.assert_allclose(sys.B, B, atol=1e-7)
    assert sys.state_labels == list(m.state_names)
    assert sys.input_labels == ["delta", "n"]
    assert sys.output_labels == ["u", "r", "psi"]
    C = np.zeros((3, m.nx))
    for k, n in enumerate(["u", "r", "psi"]):
        C[k, m.index(n)] = 1.0
    np.testing.assert_array_equal(sys.C, C)
    np.testing.assert_allclose(sys.operating_point["xdot"], f(x0, u0))


def test_linearize_rejects_unknown_names():
    m = cs.models.nomoto_first_order()
    with pytest.raises(ValueError, match="bogus"):
        linearize(m, outputs=["bogus"])
    with pytest.raises(ValueError, match="bogus"):
        linearize(m, x={"bogus": 1.0})


def test_nomoto_transfer_function_from_linearisation():
    K, T = 0.2, 30.0
    m = cs.models.nomoto_first_order(K=K, T=T)
    tf = control.ss2tf(linearize(m, outputs=["r"]))
    tf = control.minreal(tf, verbose=False)
    np.testing.assert_allclose(tf.poles(), [-1 / T])
    np.testing.assert_allclose(float(tf.dcgain()), K)


def test_to_iosys_simulation_equals_casship_simulate():
    m = cs.models.shi_taylor()
    x0 = m.states(u=8.0, psi=0.2)
    t = np.linspace(0.0, 60.0, 601)
    tr = cs.simulate(m, x0, t, {"delta": 0.1, "n": 1.5}, method="rk4", max_step=0.01)
    sys = to_iosys(m, outputs=["u", "r", "psi"])
    res = control.input_output_response(sys, t, np.vstack([np.full_like(t, 0.1), np.full_like(t, 1.5)]), x0,
                                        solve_ivp_kwargs={"rtol": 1e-11, "atol": 1e-12})
    for k, name in enumerate(["u", "r", "psi"]):
        np.testing.assert_allclose(res.outputs[k], tr[name], rtol=1e-7, atol=1e-9)


def test_to_iosys_params_and_interconnect():
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    sys = to_iosys(m, outputs=["psi"])
    t = np.linspace(0, 20, 41)
    r1 = control.input_output_response(sys, t, 0.1, [0, 0], params={"K": 0.2}).outputs
    r2 = control.input_output_response(to_iosys(m, p={"K": 0.2}, outputs=["psi"]), t, 0.1, [0, 0]).outputs
    np.testing.assert_allclose(r1, r2, rtol=1e-9, atol=1e-12)
    # a proportional heading loop built with interconnect settles at the set-point
    ctrl = control.nlsys(None, lambda t, x, u, params: 2.0 * (u[0] - u[1]), inputs=["psi_ref", "psi"],
                         outputs=["delta"], name="P")
    loop = control.interconnect([sys, ctrl], inputs=["psi_ref"], outputs=["psi"])
    res = control.input_output_response(loop, np.linspace(0, 400, 401), 0.2, [0, 0])
    assert abs(res.outputs[-1] - 0.2) < 1e-3


def test_trim_propeller_rate_for_speed():
    m = cs.models.shi_taylor()
    tr = trim(m, x={"u": 8.0}, u={"n": 1.0}, free=["n"], zero=["u"])
    # analytic: a1 u^2 + a9 n^2 = 0  ->  n = u sqrt(-a1 / a9)
    a1, a9 = m.param_dict()["a1"], m.param_dict()["a9"]
    assert tr.values["n"] == pytest.approx(8.0 * np.sqrt(-a1 / a9), rel=1e-10)
    assert abs(tr.xdot[m.index("u")]) < 1e-10


def test_trim_reports_failures_clearly():
    m = cs.models.shi_taylor()
    with pytest.raises(ValueError, match="free variable"):
        trim(m, x={"u": 8.0}, u={"n": 1.0}, free=["n"])
    with pytest.raises(ValueError, match="do not depend"):
        trim(m, x={"u": 8.0}, u={"n": 1.0}, p={"a9": 0.0}, free=["n"], zero=["u"])
    with pytest.raises(ValueError, match="did not converge"):
        trim(m, x={"u": 8.0}, u={"n": 1.0}, p={"a9": -0.1}, free=["n"], zero=["u"])
    with pytest.raises(ValueError, match="bogus"):
        trim(m, free=["bogus"], zero=["u"])


def test_trim_checks_the_declared_ranges():
    from casship.simulation import ValidityError

    ship = cs.models.get_model("kvlcc2")
    # 100 m/s is outside the model's speed range (it would "solve" for about -16 rps)
    with pytest.raises(ValidityError, match=r"state 'u' = 100 m/s is outside its valid range \[0, 15.95\] m/s"):
        trim(ship, x={"u": 100.0}, u={"n": 1.0}, free=["n"], zero=["u"])
    # a solution outside the propeller range is named with the range
    with pytest.raises(ValidityError, match=r"trim of 'kvlcc2' for zero \['u'\]: input 'n' = .* is outside its valid "
                                            r"range \[0, 3.06\] 1/s"):
        trim(ship, x={"u": 15.9}, u={"n": 3.0}, p={"R_0_dash": 0.06}, free=["n"], zero=["u"])
    tr = trim(ship, x={"u": 100.0}, u={"n": 10.0}, free=["n"], zero=["u"], check_limits=False)
    assert abs(tr.xdot[ship.index("u")]) < 1e-8


def test_trim_ties_free_variables_to_one_value():
    boat = cs.models.get_model("otter")
    tr = trim(boat, x={"u": 1.5}, u={"n1": 50.0, "n2": 50.0}, free=[("n1", "n2")], zero=["u"])
    (label, n), = tr.values.items()
    assert label == "n1=n2"
    assert tr.u[boat.index("n1", "input")] == tr.u[boat.index("n2", "input")] == n
    assert abs(tr.xdot[boat.index("u")]) < 1e-9
    assert abs(tr.xdot[boat.index("r")]) < 1e-9                  # equal rates: no yaw moment


def test_trim_result_reads_short():
    m = cs.models.shi_taylor()
    tr = trim(m, x={"u": 8.0}, u={"n": 1.0}, free=["n"], zero=["u"])
    assert repr(tr).startswith("TrimResult('shi-taylor', n=") and "residual=" in repr(tr)
    assert len(repr(tr)) < 80
    text = tr.summary()
    assert "solved n" in text and "state  u" in text and "input  delta" in text


def test_linearize_without_inputs_says_why():
    b = cs.ModelBuilder("oscillator")
    pos, vel = b.state("pos"), b.state("vel")
    b.ode(pos=vel, vel=-pos)
    b.output("pos", pos)
    with pytest.raises(ValueError, match=r"model 'oscillator' has no inputs"):
        linearize(b.build())
