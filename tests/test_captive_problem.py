"""CaptiveProblem: coefficients of a known MMG recovered from its noisy synthetic captive tests."""
from __future__ import annotations

import numpy as np
import pytest

from casship.errors import InputError
from casship.identify import FitResult
from casship.identify.captive import CaptiveProblem
from casship.models import kvlcc2_l7

from captive_records import design, synthetic

FREE = ["Y_v_dash", "Y_r_dash", "Y_vvv_dash", "Y_vvr_dash", "N_v_dash", "N_r_dash", "N_vvr_dash", "N_vrr_dash",
        "m_y_dash", "J_z_dash", "a_H", "x_H_dash", "t_R", "delta_0"]
TRUE = {"Y_v_dash": -0.34, "Y_r_dash": 0.10, "Y_vvv_dash": -1.2, "Y_vvr_dash": 0.45, "N_v_dash": -0.13,
        "N_r_dash": -0.055, "N_vvr_dash": -0.22, "N_vrr_dash": 0.07, "m_y_dash": 0.25, "J_z_dash": 0.013,
        "a_H": 0.25, "x_H_dash": -0.40, "t_R": 0.45, "delta_0": 0.01}
NOISE = {"static:X": 2e-4, "static:Y": 3e-4, "static:N": 1e-4, "dynamic:X": 5e-5, "dynamic:Y": 1e-4,
         "dynamic:N": 4e-5}


@pytest.fixture(scope="module")
def fitted():
    ship = kvlcc2_l7(asymmetry=True, smooth=True)
    tests = synthetic(ship, ship.params(TRUE), design(), noise=NOISE, seed=7)
    pb = CaptiveProblem(ship, tests, FREE, facility="RIG")
    return pb, pb.solve(show=False)


def test_recovers_the_coefficients_within_their_standard_errors(fitted):
    pb, fit = fitted
    assert isinstance(fit, FitResult) and fit.converged
    z = {n: (fit.estimates[pb.joint_name(n)] - v) / fit.std_errors[pb.joint_name(n)] for n, v in TRUE.items()}
    assert all(abs(v) < 3.0 for v in z.values()), z
    # the errors are the ones of the noise: chi-square of the standardised errors near its dof
    assert sum(v**2 for v in z.values()) < 2.5 * len(z)
    # the fit moved every coefficient from the published start towards the truth
    start = dict(zip(pb.free, pb.theta()))
    for n, v in TRUE.items():
        jn = pb.joint_name(n)
        assert abs(fit.estimates[jn] - v) < abs(start[jn] - v) + 3 * fit.std_errors[jn]


def test_noise_levels_are_estimated_per_group(fitted):
    """Each within three sampling standard deviations of a standard-deviation estimate (1 / sqrt(2 n))."""
    _, fit = fitted
    for g, s in NOISE.items():
        assert fit.noise["sigma"][g] == pytest.approx(s, rel=3 / np.sqrt(2 * fit.noise["n"][g]))


def test_facility_quantities_carry_the_facility_name(fitted):
    pb, fit = fitted
    assert "delta_0@RIG" in fit.free and "N_vvr_dash" in fit.free
    assert "delta_0@RIG" in fit.summary()
    term = pb.cost_term(fit)
    assert term.names == tuple(fit.free) and term.n_obs == fit.n_obs
    r, J = term.residual(np.array([fit.estimates[n] for n in term.names]))
    # whitened residuals at the optimum: about one per value; gradient zero
    assert 0.7 < float(r @ r) / len(r) < 1.3
    assert np.max(np.abs(J.T @ r)) < 1e-3 * np.max(np.abs(J.T @ r) + np.linalg.norm(J, axis=0))


def test_prior_and_bad_names():
    ship = kvlcc2_l7(asymmetry=True, smooth=True)
    tests = synthetic(ship, ship.params(), design(), noise={k: 1e-4 for k in NOISE}, seed=1)
    with pytest.raises(ValueError, match="Z_dash"):
        CaptiveProblem(ship, tests, ["Z_dash"])
    with pytest.raises(InputError, match="not free"):
        CaptiveProblem(ship, tests, ["Y_v_dash"], prior={"N_v_dash": 0.1})
    with pytest.raises(InputError, match="unknown group"):
        CaptiveProblem(ship, tests, ["Y_v_dash"], sigma={"static:Q": 1.0})
    pb = CaptiveProblem(ship, tests, ["Y_v_dash", "delta_0"], facility="F", prior={"delta_0@F": 0.001})
    assert pb.free == ["Y_v_dash", "delta_0@F"]
    fit = pb.solve(show=False)
    assert fit.prior["quantities"]["delta_0@F"]["std"] == 0.001
    assert fit.std_errors["delta_0@F"] < 0.001
    assert pb.cost_term(fit).prior_std == {"delta_0@F": 0.001}
