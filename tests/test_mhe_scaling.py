"""The MHE on states of very different scales (a latitude in radians beside a yaw rate): the window
NLP scaled for the solver, the arrival cost's whitening unit-free, and no solver silently wrong."""
import numpy as np
import pytest

import casship as cs
from casship.estimators import MHEFailed
from casship.estimators.mhe.arrival import inv_sqrt

Q_S, R_S = 1e-6, 1e-16          # heading measured to 1e-8 rad, as a GNSS latitude in radians (6 cm)


def _fine_heading_case():
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, 0.5, "rk4")
    t = np.arange(0.0, 60.0, 0.5)
    rng = np.random.default_rng(1)
    delta = 0.1 * np.sign(np.sin(2 * np.pi * t / 20.0))
    tr = cs.simulate(m, m.states(psi=0.4), t, {"delta": delta}, w=rng.standard_normal((t.size, 1)) * np.sqrt(Q_S))
    data = cs.measure(tr, m, {"psi": np.sqrt(R_S)}, seed=rng, keep=("psi", "r"))
    return dm, data, cs.Gaussian([0.4, 0.0], [1e-14, 1e-5])


def test_ipopt_window_with_a_state_known_to_1e_8_equals_the_kalman_filter():
    """Before: IPOPT stopped at row 4 with 'Maximum_Iterations_Exceeded' (curvatures 1e16 beside 1e5)."""
    dm, data, prior = _fine_heading_case()
    kf = cs.KF(dm, Q_S, R_S).filter(data, prior)
    res = cs.MHE(dm, Q_S, R_S, options={"horizon": 4}).filter(data, prior)
    assert np.abs(res.x[:, 0] - kf.x[:, 0]).max() <= 1e-3 * np.sqrt(R_S)
    assert np.abs(res.x[:, 1] - kf.x[:, 1]).max() <= 1e-9
    np.testing.assert_allclose(res.P, kf.P, rtol=1e-9, atol=0)


def test_the_real_time_iteration_on_a_state_known_to_1e_8_equals_the_kalman_filter():
    """Before: its Gauss-Newton step could not be computed (a singular KKT system in floating point);
    now the system is equilibrated by the same scales."""
    dm, data, prior = _fine_heading_case()
    kf = cs.KF(dm, Q_S, R_S).filter(data, prior)
    res = cs.MHE(dm, Q_S, R_S, options={"horizon": 4, "solver": "rti"}).filter(data, prior)
    assert np.abs(res.x[:, 0] - kf.x[:, 0]).max() <= 1e-3 * np.sqrt(R_S)


@pytest.mark.parametrize("solver", ["fatrop", "sqp"])
def test_other_solvers_succeed_exactly_or_say_they_failed(solver):
    """Before: SQP returned headings 5.5e-4 rad (5.5 million standard deviations) from the filter's, as a
    success. A solver may fail on this window (their absolute tolerance meets the precision of the
    residuals), but not silently."""
    dm, data, prior = _fine_heading_case()
    kf = cs.KF(dm, Q_S, R_S).filter(data, prior)
    try:
        res = cs.MHE(dm, Q_S, R_S, options={"horizon": 4, "solver": solver}).filter(data, prior)
    except MHEFailed as exc:
        assert "failed at row" in str(exc)
        return
    assert np.abs(res.x[:, 0] - kf.x[:, 0]).max() <= 1e-3 * np.sqrt(R_S)


def test_arrival_whitening_is_unit_free():
    """``W P W' = I`` for a covariance of a latitude (1e-16 rad^2) beside speeds: before, the
    near-singularity test on ``P`` itself floored the latitude's variance at 1e-14 of the largest."""
    rng = np.random.default_rng(0)
    A = rng.standard_normal((5, 5))
    S = np.diag([1e-8, 1.3e-8, 1.0, 0.5, 0.1])
    P = S @ (A @ A.T + np.eye(5)) @ S
    W = inv_sqrt(P)
    np.testing.assert_allclose(W @ P @ W.T, np.eye(5), atol=1e-10)
    # a state with no variance still gives a finite whitening (the rest exact)
    W0 = inv_sqrt(np.diag([1.0, 0.0, 4.0]))
    assert np.all(np.isfinite(W0))
    np.testing.assert_allclose((W0.T @ W0)[[0, 2], [0, 2]], [1.0, 0.25])


def _scaled_linear_case(scale):
    """The Nomoto case of ``tests/test_mhe.py`` with every variance times ``scale`` (the same problem in
    other units: a unit-free estimator gives the same estimates in standard deviations)."""
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    dm = cs.discretize(m, 0.5, "rk4")
    t = np.arange(0.0, 60.0, 0.5)
    rng = np.random.default_rng(1)
    Q, R = 1e-6 * scale, 1e-4 * scale
    delta = 0.1 * np.sign(np.sin(2 * np.pi * t / 20.0))
    tr = cs.simulate(m, m.states(psi=0.0), t, {"delta": delta}, w=rng.standard_normal((t.size, 1)) * np.sqrt(Q))
    data = cs.measure(tr, m, {"psi": np.sqrt(R)}, seed=rng, keep=("psi", "r"))
    return dm, data, cs.Gaussian([0.0, 0.0], [1e-3 * scale, 1e-5 * scale]), Q, R


@pytest.mark.parametrize("solver", ["ipopt", "sqp", "fatrop", "rti"])
def test_the_same_problem_in_smaller_units_gives_the_kalman_filter(solver):
    """Variances 1e-8 of the tested case's: before, the process noise (1e-14) was dropped as round-off
    (absolute threshold 1e-12) and every solver returned headings 0.04 standard deviations off, as a
    success; with it kept, the warm start was accepted at gaps small in radians but not in standard
    deviations (1.7e-4 off); the real-time iteration's step could not be computed. Now every solver
    equals the Kalman filter to 1e-8 standard deviations."""
    dm, data, prior, Q, R = _scaled_linear_case(1e-8)
    kf = cs.KF(dm, Q, R).filter(data, prior)
    res = cs.MHE(dm, Q, R, options={"horizon": 4, "solver": solver}).filter(data, prior)
    assert np.abs(res.x[:, 0] - kf.x[:, 0]).max() <= 1e-8 * np.sqrt(R)


def test_process_noise_factor_keeps_small_variances():
    from casship.estimators.mhe.problem import sqrt_factor

    L, diagonal = sqrt_factor(np.diag([1e-14, 0.0, 2.0]))
    assert diagonal and L.shape == (3, 2)
    np.testing.assert_allclose(L @ L.T, np.diag([1e-14, 0.0, 2.0]), rtol=1e-15, atol=0)
    Q = np.array([[1e-14, 6e-9 * 0.5], [6e-9 * 0.5, 1e-2 * 0.36]])
    L, diagonal = sqrt_factor(Q)
    assert not diagonal and L.shape == (2, 2)
    np.testing.assert_allclose(L @ L.T, Q, rtol=1e-12, atol=1e-30)
    L, _ = sqrt_factor(np.array([[1.0, 1.0], [1.0, 1.0]]))           # one direction
    assert L.shape == (2, 1)


@pytest.mark.parametrize("solver", ["rti", "ipopt"])
def test_the_compiled_riccati_step_holds_on_states_of_very_different_scales(solver):
    """With ``jit`` the Gauss-Newton step is the compiled Riccati recursion, whose small solves per stage
    hold on these windows without the equilibration the interpreted KKT solve needs."""
    dm, data, prior = _fine_heading_case()
    kf = cs.KF(dm, Q_S, R_S).filter(data, prior)
    res = cs.MHE(dm, Q_S, R_S, options={"horizon": 4, "solver": solver, "jit": True}).filter(data, prior)
    assert np.abs(res.x[:, 0] - kf.x[:, 0]).max() <= 1e-3 * np.sqrt(R_S)
    dm, data, prior, Q, R = _scaled_linear_case(1e-8)
    kf = cs.KF(dm, Q, R).filter(data, prior)
    res = cs.MHE(dm, Q, R, options={"horizon": 4, "solver": solver, "jit": True}).filter(data, prior)
    assert np.abs(res.x[:, 0] - kf.x[:, 0]).max() <= 1e-8 * np.sqrt(R)
