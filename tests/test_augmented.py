"""Augmented-state EKF: parameters as random-walk states, recovered from simulated data."""
import numpy as np
import pytest

import casship as cs
from casship.estimators import augmented_ekf


def test_augment_structure():
    m = cs.models.nomoto_first_order()
    aug = cs.augment(m, ["K", "T"])
    assert aug.state_names == ("psi", "r", "K", "T")
    assert aug.param_names == ()
    biased = cs.augment(cs.models.nomoto_first_order(rudder_bias=True), ["K", "T"])
    assert biased.param_names == ("delta_0",) and biased.state_names == ("psi", "r", "K", "T")
    assert aug.noise_names == ("w_r", "w_K", "w_T")
    x = np.array([0.1, 0.01, 0.2, 50.0])
    xdot = np.array(aug.f(x, [0.05], aug.params(), np.zeros(3))).ravel()
    ref = np.array(m.f(x[:2], [0.05], m.params(K=0.2, T=50.0), [0.0])).ravel()
    np.testing.assert_allclose(xdot[:2], ref, rtol=1e-15)
    assert np.all(xdot[2:] == 0)
    assert aug.meta["augmented_params"] == ("K", "T")
    with pytest.raises(ValueError, match="Kx"):
        cs.augment(m, ["Kx"])
    with pytest.raises(ValueError, match="'u'"):
        cs.augment(m, disturbances=["u"])
    with pytest.raises(ValueError, match="at least one"):
        cs.augment(m, [])


def test_recovers_nomoto_parameters():
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0, 600, 0.5)
    delta = np.deg2rad(10) * np.sign(np.sin(2 * np.pi * t / 80))
    mo = m.with_outputs(["psi", "r"])
    traj = cs.simulate(mo, m.states(), t, {"delta": delta})
    data = cs.measure(traj, mo, {"psi": 1e-3, "r": 1e-4}, seed=1)
    out = augmented_ekf(mo, ["K", "T"], data, dt=0.5, Q=1e-10, R=[1e-6, 1e-8], q_params=[1e-12, 1e-8],
                        prior=cs.Gaussian(m.states(), [1e-4, 1e-6]), guess={"K": 0.05, "T": 10.0},
                        p0_params=[1e-2, 100.0], method="rk4")
    assert out.final["K"] == pytest.approx(0.1, rel=0.02)
    assert out.final["T"] == pytest.approx(20.0, rel=0.05)
    assert out.final_std["T"] < 2.0
    assert out.trajectory("K").shape == (t.size,)


def test_augment_a_discrete_time_model():
    """A parameter of a discrete-time model becomes a random walk over one step: c[k+1] = c[k] + dt w_c."""
    b = cs.ModelBuilder("decay", dt=0.25)
    v = b.state("v")
    c = b.param("c", 0.9, unit="-", doc="decay per step")
    b.next(v=c * v + b.noise("w_v"))
    b.output("v_m", v)
    aug = cs.augment(b.build(), ["c"])
    assert aug.state_names == ("v", "c") and aug.noise_names == ("w_v", "w_c") and aug.param_names == ()
    assert aug.state_vars[1].unit == "-" and aug.state_vars[1].doc == "decay per step"
    step = cs.discretize(aug).step
    np.testing.assert_allclose(np.ravel(step([2.0, 0.8], [], [], [0.1, 0.3], 0.25)),
                               [0.8 * 2.0 + 0.1, 0.8 + 0.25 * 0.3], rtol=1e-15)
