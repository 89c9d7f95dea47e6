"""The MPC's offset from the integral of the tracking error (``offset="integral"``): its preview, its
offset-free steady state, the anti-windup, and the Python and compiled laws agreeing."""
import numpy as np
import pytest
from scipy.linalg import expm

import casship as cs
from casship import autopilot as ap
from casship.autopilot.mpc import MPCAutopilot
from casship.autopilot.mpc_design import mpc_for_design


@pytest.fixture(scope="module")
def kvlcc2():
    return ap.design_autopilot(cs.models.get_model("kvlcc2"))


def _toy(offset="integral", **kw):
    """An MPC on a small Nomoto ship (K = 0.1 1/s, T = 20 s), 1 s period, 40 steps, no reference model."""
    weights = {"q_e": 1.0, "q_r": 0.0, "r_u": 100.0}
    if offset == "integral":
        weights["q_z"] = 1e-3
    weights.update(kw)
    return MPCAutopilot(ap.Nomoto(0.1, 20.0), period=1.0, horizon=40, steer_max=0.6, rate_max=0.05, r_max=0.05,
                        offset=offset, **weights)


def test_integral_preview_is_the_integral_of_the_reference_preview(kvlcc2):
    """The exact integral of the linear reference model's course error over each step, against
    Simpson's rule on a fine grid of the same model's ``expm``."""
    mpc = mpc_for_design(kvlcc2, offset="integral")
    z = np.array([np.radians(-20.0), 1e-4, -1e-6])
    A = np.asarray(mpc.reference.system().A)
    n_fine = 200
    h = mpc.period / n_fine
    step = expm(A * h)
    x, e = z.copy(), [z[0]]
    for _ in range(int(mpc.horizon) * n_fine):
        x = step @ x
        e.append(x[0])
    e = np.array(e)
    simpson = np.concatenate([[0.0], np.cumsum([h / 3 * (e[2 * k] + 4 * e[2 * k + 1] + e[2 * k + 2])
                                                 for k in range(len(e) // 2)])])
    expected = simpson[n_fine // 2::n_fine // 2]          # at the end of each period
    got = mpc.integral_preview() @ z
    np.testing.assert_allclose(got, expected[:int(mpc.horizon)], rtol=1e-10, atol=1e-12)


def _run(mpc, bias_fed, t_end=1500.0, dt=0.5, disturbance=0.05):
    """The toy ship (exact zero-order-hold steps) under ``mpc.update`` with a constant steering
    offset ``disturbance`` the MPC is not told of (``bias_fed`` is what it is given); heading error
    over the last fifth and the memory at the end."""
    K, T = mpc.nomoto.K, mpc.nomoto.T
    Ac = np.array([[0.0, 1.0], [0.0, -1.0 / T]])
    Bc = np.array([[0.0], [K / T]])
    M = expm(np.block([[Ac, Bc], [np.zeros((1, 3))]]) * dt)
    Ad, Bd = M[:2, :2], M[:2, 2]
    x, mem, psi = np.zeros(2), mpc.memory0(0.0), []
    for _ in range(int(t_end / dt)):
        mem, cmd, _ = mpc.update(mem, 0.0, x[0], x[1], dt, bias_fed)
        x = Ad @ x + Bd * (cmd + disturbance)
        psi.append(x[0])
    psi = np.array(psi)
    return psi[-len(psi) // 5:], mem


def test_integral_makes_the_plan_offset_free_without_the_bias():
    """A steering offset of 0.05 rad nobody estimates: the plan with the integral brings the heading
    back to the command (within 1e-4 rad at the end), the plan on the bias it is given (0) holds a
    steady error (the structure the integral adds: without it the error stays)."""
    tail, mem = _run(_toy("integral"), bias_fed=0.0)
    assert np.max(np.abs(tail)) < 1e-4
    assert mem["steer_cmd"] == pytest.approx(-0.05, abs=1e-4)          # it steers the offset away
    tail_bias, _ = _run(_toy("bias"), bias_fed=0.0)
    assert np.min(np.abs(tail_bias)) > 1e-3
    # the bias, when the plan is told it, gives the same end (the default route)
    tail_told, _ = _run(_toy("bias"), bias_fed=0.05)
    assert np.max(np.abs(tail_told)) < 1e-4


def test_integral_plan_does_not_use_the_bias():
    mpc = _toy("integral")
    mem = mpc.memory0(0.0)
    mem.update(integral=0.3, steer_cmd=0.02)
    cmds = [mpc.update(mem, 0.0, 0.01, 0.001, 0.5, b)[1] for b in (0.0, 0.1)]
    assert cmds[0] == cmds[1]
    mem.update(integral=-0.3)
    assert mpc.update(mem, 0.0, 0.01, 0.001, 0.5, 0.0)[1] > cmds[0]   # a negative integral asks for more steering


def test_integral_is_held_at_the_steering_limit_when_the_error_drives_it_further():
    mpc = _toy("integral")
    lim = mpc.steer_max
    assert mpc.integral_step(1.0, -0.2, lim, 0.5) == 1.0              # at +limit, e < 0: held
    assert mpc.integral_step(1.0, 0.2, lim, 0.5) == pytest.approx(1.1)  # at +limit, e > 0: unwinds
    assert mpc.integral_step(1.0, 0.2, -lim, 0.5) == 1.0
    assert mpc.integral_step(1.0, -0.2, 0.0, 0.5) == pytest.approx(0.9)


def test_python_update_and_compiled_law_agree_with_the_integral(kvlcc2):
    """The same command and the same next integral from the same memory in a turn (integral, bias
    and steady steering nonzero)."""
    mpc = mpc_for_design(kvlcc2, offset="integral")
    dt, ref, bias, integral = kvlcc2.settings.dt, np.radians(60.0), np.radians(0.5), -3.0
    xr = np.array([np.radians(20.0), 0.6 * kvlcc2.settings.r_max, 1e-6])
    mem = mpc.memory0(0.0)
    mem.update(xr=xr, steer_cmd=0.05, integral=integral)
    mem_next, cmd, _ = mpc.update(mem, ref, np.radians(19.0), xr[1], dt, bias)
    law = mpc.law(dt)
    m0 = law.memory0(0.0)
    m0[0:3], m0[3], m0[law.MEMORY.index("integral")] = xr, 0.05, integral
    out = law.function(m0, ref, np.radians(19.0), xr[1], dt, 8.0, 0.05, bias)
    assert float(out[1]) == pytest.approx(cmd, abs=1e-9)
    assert float(out[0][law.MEMORY.index("integral")]) == pytest.approx(mem_next["integral"], abs=1e-12)
    assert abs(cmd - 0.05) > 1e-6
    mem.update(integral=0.0)
    assert abs(mpc.update(mem, ref, np.radians(19.0), xr[1], dt, bias)[1] - cmd) > 1e-6   # the integral counts


def test_integral_settings_are_checked(kvlcc2):
    with pytest.raises(cs.errors.InputError, match="offset must be"):
        MPCAutopilot(ap.Nomoto(0.1, 10.0), period=1.0, horizon=5, steer_max=1.0, rate_max=1.0, r_max=1.0,
                     offset="pid")
    with pytest.raises(cs.errors.InputError, match="q_z"):
        _toy("integral", q_z=0.0)
    with pytest.raises(cs.errors.InputError, match="q_z"):
        _toy("bias", q_z=1.0)
    with pytest.raises(cs.errors.InputError, match="offset must be"):
        mpc_for_design(kvlcc2, offset="integrator")
    mpc = mpc_for_design(kvlcc2, offset="integral")
    assert mpc.q_z == pytest.approx(mpc.q_e * (kvlcc2.settings.wn / 10) ** 2)
