"""JointProblem: a captive-test term and a free-running problem in one objective."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize

import casship as cs
from casship.builder import ModelBuilder
from casship.errors import InputError
from casship.identify import OutputErrorProblem
from casship.identify.captive import CaptiveProblem
from casship.identify.cost_term import JointProblem
from casship.models.mmg import declare_ship_states, rigid_body_3dof

from captive_records import design, synthetic

TRUE = {"Yv": -900.0, "Yr": 300.0, "Nv": -400.0, "Nr": -2500.0, "Yd": 150.0, "Nd": -80.0, "m": 1200.0,
        "m_x": 60.0, "m_y": 900.0, "I_zG": 4000.0, "J_z": 700.0, "x_G": 0.0, "rho": 1000.0, "L_pp": 5.0}
START = {"Yv": -800.0, "Nv": -350.0, "Nr": -2200.0, "Nd": -60.0}
CAPTIVE_SIGMA = {"static:Y": 2e-4, "static:N": 1e-4, "dynamic:Y": 1e-4, "dynamic:N": 5e-5}


def rudder_ship(values=None):
    """A linear ship with a rudder: Y = Yv v + Yr r + Yd delta, N = Nv v + Nr r + Nd delta (U = 1.2 m/s)."""
    b = ModelBuilder("rudder-ship")
    states = declare_ship_states(b)
    u, v, r = states[:3]
    delta = b.input("delta")
    b.input("n")
    vals = dict(TRUE, **(values or {}))
    P = {k: b.param(k, val) for k, val in vals.items()}
    force = (-50.0 * (u - 1.2), P["Yv"] * v + P["Yr"] * r + P["Yd"] * delta, P["Nv"] * v + P["Nr"] * r + P["Nd"] * delta)
    rigid_body_3dof(b, force, m=P["m"], m_x=P["m_x"], m_y=P["m_y"], I_zG=P["I_zG"], J_z=P["J_z"], x_G=P["x_G"],
                    states=states)
    return b.build()


@pytest.fixture(scope="module")
def problems():
    ship = rudder_ship(START)
    truth = ship.params(TRUE)
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 120.0, 0.5)
    delta = 0.3 * np.sign(np.sin(2 * np.pi * t / 40.0))
    tr = cs.simulate(ship, ship.states(u=1.2), t, {"delta": delta, "n": 10.0}, truth)
    rec = cs.measure(tr, ship, {"r": 2e-3, "psi": 5e-3}, seed=rng)
    oe = OutputErrorProblem(ship, [rec], free=["Yv", "Nv", "Nr", "Nd"], measured=["r", "psi"],
                            sigma={"r": 2e-3, "psi": 5e-3}, prior={"Nd": 50.0}, x0=[ship.states(u=1.2)])
    # the captive rig has its own rudder (Nd differs), the same hull
    rig_truth = ship.params(dict(TRUE, Nd=-120.0))
    tests = synthetic(ship, rig_truth, design(U=1.2, L=5.0), channels=("Y", "N"), noise=CAPTIVE_SIGMA, seed=4)
    cap = CaptiveProblem(ship, tests, ["Yv", "Nv", "Nr", "Nd"], facility="RIG", facility_params=("Nd",),
                         channels=("Y", "N"), sigma=CAPTIVE_SIGMA)
    return oe, cap


def test_joint_estimate_equals_stacking_by_hand(problems):
    oe, cap = problems
    term = cap.cost_term(sigma=CAPTIVE_SIGMA)
    joint = JointProblem(oe, [term])
    assert joint.free == ["Yv", "Nv", "Nr", "Nd", "Nd@RIG"]
    fit = joint.solve(show=False, tol=1e-12)
    assert fit.converged

    # by hand: the free-running cost (data + prior) plus half the squared whitened captive residuals
    names = joint.free

    def f(x):
        main = dict(zip(names[:4], x[:4]))
        r, _ = term.residual(np.array([x[0], x[1], x[2], x[4]]))
        return oe.cost(main) + 0.5 * float(r @ r)

    def g(x):
        main = dict(zip(names[:4], x[:4]))
        r, J = term.residual(np.array([x[0], x[1], x[2], x[4]]))
        out = np.concatenate([oe.gradient(main), [0.0]])
        out[[0, 1, 2, 4]] += J.T @ r
        return out

    x0 = np.array([START[n] for n in names[:4]] + [START["Nd"]])
    scale = np.abs(x0)
    res = minimize(lambda z: f(z * scale), x0 / scale, jac=lambda z: g(z * scale) * scale, method="BFGS",
                   options={"gtol": 1e-10, "maxiter": 500})
    by_hand = res.x * scale
    est = np.array([fit.estimates[n] for n in names])
    np.testing.assert_allclose(est, by_hand, rtol=1e-5)
    # the joint covariance: the inverse of the problem's information, its prior and the term's J'J
    main = dict(zip(names[:4], est[:4]))
    _, J = term.residual(est[[0, 1, 2, 4]])
    H = np.zeros((5, 5))
    H[:4, :4] = oe.information(main) + np.diag(oe.prior_precision)
    H[np.ix_([0, 1, 2, 4], [0, 1, 2, 4])] += J.T @ J
    np.testing.assert_allclose(fit.covariance, np.linalg.inv(H), rtol=1e-6)
    # the joint gradient is the by-hand gradient
    np.testing.assert_allclose(joint.gradient(dict(zip(names, est))), g(est), rtol=1e-9, atol=1e-9)
    # hull from both records, each rudder its own
    for n in ("Yv", "Nv", "Nr"):
        assert abs(fit.estimates[n] - TRUE[n]) < 3 * fit.std_errors[n]
    assert abs(fit.estimates["Nd"] - TRUE["Nd"]) < 3 * fit.std_errors["Nd"]
    assert abs(fit.estimates["Nd@RIG"] + 120.0) < 3 * fit.std_errors["Nd@RIG"]


def test_joint_is_sharper_than_either_alone(problems):
    oe, cap = problems
    joint = JointProblem(oe, [cap.cost_term(sigma=CAPTIVE_SIGMA)]).solve(show=False)
    alone = cap.solve(show=False)
    for n in ("Yv", "Nv", "Nr"):
        assert joint.std_errors[n] <= alone.std_errors[n]


def test_a_fixed_parameter_of_the_problem_is_not_estimated_by_a_term(problems):
    oe, cap = problems
    other = CaptiveProblem(cap.model, cap.tests, ["Yv", "Yr"], facility="RIG", channels=("Y", "N"), sigma=CAPTIVE_SIGMA)
    with pytest.raises(InputError, match="'Yr'.*holds fixed"):
        JointProblem(oe, [other.cost_term(sigma=CAPTIVE_SIGMA)])
    with pytest.raises(InputError, match="at least one"):
        JointProblem(oe, [])
    # held at the problem's value instead: the term's Yr column is not estimated
    joint = JointProblem(oe, [other.cost_term(sigma=CAPTIVE_SIGMA)], hold_fixed=True)
    assert joint.free == ["Yv", "Nv", "Nr", "Nd"]
    at = {"Yv": -880.0, "Nv": -420.0, "Nr": -2400.0, "Nd": -75.0}
    r, J = other.cost_term(sigma=CAPTIVE_SIGMA).residual(np.array([-880.0, TRUE["Yr"]]))
    expect = oe.gradient(at)
    expect[0] += J[:, 0] @ r
    np.testing.assert_allclose(joint.gradient(at), expect, rtol=1e-10)


def test_a_pseudo_measurement_term_equals_a_prior_in_an_mle_problem():
    """A term r = (K - 0.07) / 0.01 adds to a filter likelihood exactly what the prior N(0.07, 0.01^2) adds."""
    from casship.identify import CostTerm, MLEProblem, Prior

    m = cs.models.nomoto_first_order(K=0.08, T=20.0)
    rng = np.random.default_rng(5)
    t = np.arange(200) * 1.0
    tr = cs.simulate(m, m.states(), t, {"delta": 0.15 * np.sign(np.sin(2 * np.pi * t / 120.0))},
                     w=np.sqrt(1e-7) * rng.standard_normal((200, m.nw)))
    rec = cs.measure(tr, m, {"psi": 0.01}, seed=rng)
    ekf = cs.EKF(cs.discretize(m, 1.0), Q=1e-7, R=1e-4)
    term = CostTerm("pseudo K", ("K",), np.array([0.07]), np.array([0.0]), np.array([1.0]),
                    lambda v: (np.array([(v[0] - 0.07) / 0.01]), np.array([[1.0 / 0.01]])), 1)
    plain = MLEProblem(ekf, [rec], free=["K", "T"])
    joint = JointProblem(plain, [term]).solve(guess={"K": 0.05, "T": 15.0}, show=False, tol=1e-12)
    with_prior = MLEProblem(ekf, [rec], free=["K", "T"], prior=Prior({"K": 0.01}, mean={"K": 0.07}))
    ref = with_prior.solve(guess={"K": 0.05, "T": 15.0}, show=False, tol=1e-12)
    for n in ("K", "T"):
        assert joint.estimates[n] == pytest.approx(ref.estimates[n], rel=1e-6)
        assert joint.std_errors[n] == pytest.approx(ref.std_errors[n], rel=1e-6)
    assert joint.cost == pytest.approx(ref.cost, rel=1e-9)
