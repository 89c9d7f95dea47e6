"""One Gaussian over named parameters: the prior, the fit file's uncertainty and the trial design's
belief are one class, a fit file's covariance round-trips bit for bit, the 0.3 name warns and
yields that class, and a belief made from a fit file carries the file's model discrepancy."""
import dataclasses
import json

import numpy as np
import pytest

import casship.design
import casship.identify
from casship.gaussian import Gaussian
from casship.identify import FitResult, ParameterBelief, Prior, read_fit_file
from casship.models import nomoto_first_order

NAMES = ["K", "T"]
# Awkward floats on purpose: a round trip that loses a bit shows here.
COV = [[1.2345678901234567e-4, 3.3333333333333335e-3], [3.3333333333333335e-3, 4.000000000000001]]
BESIDE = [[2.0e-4, 1.0e-3], [1.0e-3, 2.5]]
Q_DEG2_S = 0.37


def _fit_file(tmp_path, *, discrepancy=True):
    """A nomoto1 fit file carrying a calibrated covariance (and a model discrepancy)."""
    m = nomoto_first_order()
    params = {"K": 0.1234567890123, "T": 21.098765432101}
    unc = ParameterBelief.from_values(NAMES, [params[n] for n in NAMES], COV, "run-level jackknife over 7 folds",
                                      {"folds": 7}, kind="calibrated")
    fit = FitResult(model=m.name, params=params, free=NAMES, estimates=dict(params),
                    std_errors={n: float(np.sqrt(COV[i][i])) for i, n in enumerate(NAMES)}, correlation=np.eye(2),
                    covariance=np.asarray(COV), cost=1.0, loglik=0.0, n_obs=100, aic=0.0, bic=0.0,
                    param_names=list(m.param_names), param_covariance=unc.to_dict(),
                    model_discrepancy={"psi_variance_growth_deg2_per_s": Q_DEG2_S,
                                       "estimated_with": {"names": NAMES, "values": [params[n] for n in NAMES],
                                                          "matrix": BESIDE, "kind": "robust"}} if discrepancy else {})
    return fit.to_json(tmp_path / "fit.json")


def test_the_prior_the_uncertainty_and_the_design_belief_are_one_class(tmp_path):
    assert casship.design.ParameterBelief is casship.identify.ParameterBelief
    path = _fit_file(tmp_path)
    assert type(read_fit_file(path).uncertainty) is ParameterBelief
    assert type(FitResult.from_json(path).uncertainty()) is ParameterBelief
    assert type(ParameterBelief.from_fit(path)) is ParameterBelief
    independent = ParameterBelief.from_prior(Prior({"K": 0.02}, {"K": 0.1}))
    assert type(independent) is ParameterBelief and independent.to_prior() == Prior({"K": 0.02}, {"K": 0.1})
    with pytest.raises(dataclasses.FrozenInstanceError):
        read_fit_file(path).uncertainty.psi_variance_rate = 0.0          # a value: changed copies only


def test_a_fit_files_covariance_round_trips_bit_for_bit(tmp_path):
    path = _fit_file(tmp_path)
    written = json.loads(path.read_text())["param_covariance"]
    unc = read_fit_file(path).uncertainty
    assert unc.to_dict() == written                                     # exact floats, names, kind, info
    again = ParameterBelief.from_dict(unc.to_dict())
    np.testing.assert_array_equal(again.covariance, unc.covariance)
    np.testing.assert_array_equal(again.values, unc.values)
    assert (again.names, again.source, again.kind, again.info) == (unc.names, unc.source, unc.kind, unc.info)
    # the whole file, read and written again, is the same text
    FitResult.from_json(path).to_json(tmp_path / "again.json")
    assert (tmp_path / "again.json").read_text() == path.read_text()


def test_the_03_name_warns_and_yields_the_one_class():
    with pytest.warns(DeprecationWarning, match="ParameterUncertainty is deprecated"):
        u = casship.identify.ParameterUncertainty(["K", "T"], [0.1, 20.0], [[1e-4, 0.0], [0.0, 4.0]],
                                                  "by hand", {"n": 1}, 1e-6, None, "prior")
    assert type(u) is ParameterBelief
    assert (u.names, u.source, u.info, u.psi_variance_rate, u.kind) == (("K", "T"), "by hand", {"n": 1}, 1e-6, "prior")
    assert u.std == pytest.approx({"K": 0.01, "T": 2.0}, rel=1e-15)
    np.testing.assert_array_equal(u.values, [0.1, 20.0])
    with pytest.warns(DeprecationWarning), pytest.raises(ValueError, match="not positive semi-definite"):
        casship.identify.ParameterUncertainty(["a", "b"], [0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])


def test_a_belief_from_a_fit_file_carries_its_model_discrepancy(tmp_path):
    path = _fit_file(tmp_path)
    q = np.radians(np.radians(Q_DEG2_S))
    read = read_fit_file(path).uncertainty
    belief = ParameterBelief.from_fit(path)
    for b in (read, belief):
        assert b.psi_variance_rate == pytest.approx(q, rel=1e-15)
        np.testing.assert_array_equal(b.discrepancy_covariance, BESIDE)
    assert belief.kind == "calibrated" and "jackknife" in belief.source
    # widened by a prior on a parameter the fit held fixed: the discrepancy's covariance grows alike
    wider = ParameterBelief(("K",), Gaussian([0.1], [[1e-4]]), psi_variance_rate=q,
                            discrepancy_covariance=[[4e-4]]).extended({"T": 2.0}, {"T": 20.0})
    np.testing.assert_array_equal(wider.discrepancy_covariance, [[4e-4, 0.0], [0.0, 4.0]])
    assert wider.psi_variance_rate == q
    # a trial's information narrows the parameters, not the model's own discrepancy
    after = belief.after(np.diag([1e6, 1e-2]))
    assert after.psi_variance_rate == belief.psi_variance_rate and after.std["K"] < 0.1 * belief.std["K"]
    # the fit's own covariances carry the rate alone (the covariance beside it is the file's)
    robust = ParameterBelief.from_fit(path, covariance="model")
    assert robust.psi_variance_rate == pytest.approx(q, rel=1e-15) and robust.discrepancy_covariance is None
    # no discrepancy in the file: none in the belief
    (tmp_path / "plain").mkdir()
    plain = _fit_file(tmp_path / "plain", discrepancy=False)
    assert ParameterBelief.from_fit(plain).psi_variance_rate == 0.0


def test_a_belief_covariance_is_judged_on_its_correlations_not_its_units():
    """Before: the discrepancy covariance was judged definite relative to its largest entry: an
    indefinite block of coefficients with variances 1e-12 (a correlation of 2) beside a time
    constant's variance of 100 was accepted (the parameters' own covariance is a Gaussian's, which
    was already judged on its correlations)."""
    names, values = ["N_r", "N_v", "T"], [1e-3, -2e-3, 20.0]
    good = [[1e-12, 0.5e-12, 0.0], [0.5e-12, 1e-12, 0.0], [0.0, 0.0, 100.0]]
    bad = [[1e-12, 2e-12, 0.0], [2e-12, 1e-12, 0.0], [0.0, 0.0, 100.0]]
    for field in ("covariance", "discrepancy"):
        with pytest.raises(ValueError, match="not positive semi-definite.*correlation"):
            ParameterBelief.from_values(names, values, bad if field == "covariance" else good,
                                        discrepancy_covariance=bad if field == "discrepancy" else None)
    belief = ParameterBelief.from_values(names, values, good, discrepancy_covariance=good)
    assert belief.std["N_r"] == pytest.approx(1e-6, rel=1e-12)
