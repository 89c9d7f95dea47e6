"""One public first-sample prior (``prior_from_data``); an MLE problem's default start follows the
identification's rule for a record's start (first row of a column, NaN refused), written out by hand."""
from __future__ import annotations

import numpy as np
import pytest

import casship as cs
import casship.identify
from casship.identify import MLEProblem


def _record(first_psi=0.3):
    m = cs.models.nomoto_first_order(K=0.08, T=20.0)
    t = np.arange(120) * 0.5
    tr = cs.simulate(m, m.states(psi=0.3, r=0.002), t, {"delta": np.radians(10.0) * np.sign(np.sin(t / 15.0))})
    data = cs.measure(tr, m, {"psi": 0.01}, seed=3)
    psi = np.asarray(data["psi"], dtype=float).copy()
    psi[0] = first_psi
    return m, data.with_columns(psi=psi)


def test_one_public_first_sample_prior():
    assert not hasattr(casship.identify, "default_prior")
    assert "default_prior" not in casship.identify.__all__
    assert cs.prior_from_data is cs.estimators.prior_from_data


def test_mle_default_start_is_the_first_row_with_the_measurement_variance():
    m, data = _record()
    ekf = cs.EKF(cs.discretize(m, 0.5), Q=1e-7, R=1e-4)
    prob = MLEProblem(ekf, [data], free=["K", "T"], prior_var=0.25, jit=False)
    prior = prob._priors[0]
    i_psi, i_r = m.state_names.index("psi"), m.state_names.index("r")
    mean = np.zeros(m.nx)
    mean[i_psi] = 0.3                                  # the first row of column psi; r has no column: 0
    var = np.full(m.nx, 0.25)
    var[i_psi] = 1e-4                                  # psi is measured directly: its R
    np.testing.assert_array_equal(prior.mean, mean)
    np.testing.assert_array_equal(np.diag(prior.cov), var)
    _, gap = _record(first_psi=np.nan)
    with pytest.raises(ValueError, match="'psi' is NaN in the first row"):
        MLEProblem(ekf, [gap], free=["K", "T"], jit=False)
