"""The ship workflow (:func:`casship.identify_ship`) and the run-level selection rule it uses."""
import json

import numpy as np
import pytest

import casship as cs
from casship.errors import InputError
from casship.identify import Identifiability, replay_file
from casship.identify.identifiability import RunEvidence, _jackknife
from casship.identify.workflow import pool_facilities, run_evidence

TRUTH = {"K": 0.12, "T": 26.0}


def _records(seed=0, n=4):
    """Nomoto zig-zag-like runs of a ship with ``TRUTH`` (the preset is K = 0.1, T = 20)."""
    truth = cs.models.nomoto_first_order(**TRUTH)
    t = np.arange(0.0, 400.0, 1.0)
    out = []
    for i in range(n):
        amp = np.radians([10.0, -15.0, 20.0, -10.0, 12.0, -18.0][i])
        delta = amp * np.sign(np.sin(2 * np.pi * t / (90.0 + 15 * i)) + 1e-9)
        run = cs.simulate(truth, truth.states(), t, {"delta": delta})
        out.append(cs.measure(run, truth, {"psi": np.radians(0.2)}, seed=seed + i))
    return out


# -- the run-level rule on a hand-built case ------------------------------------------------------------
def _hand_built(spread: float) -> Identifiability:
    """Two quantities, unit prior; each of 4 runs carries information 25 on both (posterior/prior std
    0.1 by the model), their gradients on ``b`` pull by +-spread (the runs disagree on ``b``)."""
    names = ["a", "b"]
    F_unit = np.diag([25.0, 25.0])
    g = np.array([[0.0, spread], [0.0, -spread], [0.0, spread], [0.0, -spread]])
    ev = RunEvidence([f"run {i}" for i in range(4)], np.array([F_unit] * 4), g, np.zeros(2))
    return Identifiability(names, {"a": 1.0, "b": 1.0}, np.ones(2), 4 * F_unit, np.ones(2), evidence=ev)


def test_jackknife_of_the_leave_one_run_out_steps_is_the_hand_computed_one():
    idf = _hand_built(20.0)
    C = _jackknife(idf.evidence.information, idf.evidence.gradient, idf.evidence.prior_gradient)
    # without run u: step on b = -(g - g_u) / (1 + 75) = +-20 / 76; mean 0; (n-1)/n * sum d^2
    d = 20.0 / 76.0
    assert C[1, 1] == pytest.approx(3 / 4 * 4 * d**2)
    assert C[0, 0] == pytest.approx(0.0)


def test_a_quantity_the_runs_pull_apart_fails_the_run_level_rule_but_not_the_fisher_one():
    idf = _hand_built(60.0)            # jackknife std of b: sqrt(3) * 60 / 76 = 1.37 prior std
    assert idf.propose(max_ratio=0.5, evidence="fisher") == ["a", "b"]
    free, rows = idf.propose(max_ratio=0.5, evidence="runs", explain=True)
    assert free == ["a"]
    row = next(r for r in rows if r["quantity"] == "b")
    assert not row["chosen"] and row["ratio_if_added"] == pytest.approx(np.sqrt(3) * 60 / 76, rel=1e-9)
    # runs that agree: the model-based ratio (0.1) decides, both admitted
    assert _hand_built(1.0).propose(max_ratio=0.5, evidence="runs") == ["a", "b"]


def test_run_level_rule_needs_the_evidence_and_a_prior():
    idf = _hand_built(1.0)
    idf.evidence = None
    with pytest.raises(ValueError, match="run-level evidence"):
        idf.propose(max_ratio=0.5, evidence="runs")
    no_prior = Identifiability(["a"], {"a": 1.0}, np.ones(1), np.eye(1), np.zeros(1))
    with pytest.raises(ValueError, match="needs a prior"):
        no_prior.propose(max_ratio=0.5)


def test_a_waiting_candidate_is_chosen_only_when_the_other_cannot_be():
    idf = _hand_built(1.0)
    free = idf.propose(max_ratio=0.5, evidence="runs", after={"a": ["b"]}, max_count=1)
    assert free == ["b"]


def test_pooling_of_a_facility_quantity_is_the_normal_normal_posterior():
    pool = pool_facilities({"A": (0.02, 0.01)}, spread=0.01, prior_std=0.02)
    # mu: prior N(0, 0.02^2); one facility estimate 0.02 with variance spread^2 + se^2 = 2e-4
    prec = 1 / 0.02**2 + 1 / 2e-4
    assert pool["population"] == pytest.approx(0.02 / 2e-4 / prec)
    assert pool["new_facility_std"] == pytest.approx(np.sqrt(1 / prec + 0.01**2))
    assert pool["facilities"]["A"]["value"] == 0.02


# -- the workflow on simulated data ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def nomoto_fit():
    model = cs.models.nomoto_first_order(K=0.1, T=20.0)
    return cs.identify_ship(_records(), model, candidates=["K", "T"], prior={"K": 0.05, "T": 10.0})


def test_workflow_recovers_a_known_ship_and_records_every_choice(nomoto_fit):
    fit = nomoto_fit
    assert sorted(fit.free) == ["K", "T"]
    for name, true in TRUTH.items():
        est, se = fit.fit.estimates[name], fit.fit.std_errors_robust[name]
        assert abs(est / true - 1) < 0.05, (name, est)
        assert abs(est - true) < 4 * se + 0.01 * true
    steps = [c["step"] for c in fit.choices]
    for step in ("propulsion", "start", "cost", "prior", "free set", "refinement"):
        assert step in steps
    assert all(c["reason"] for c in fit.choices)
    assert "records" in next(c["reason"] for c in fit.choices if c["step"] == "free set")   # 4 runs: runs are units
    assert "because" in fit.summary()


def test_workflow_overrides_and_bad_input():
    model = cs.models.nomoto_first_order(K=0.1, T=20.0)
    recs = _records(n=2)
    fit = cs.identify_ship(recs, model, free=["K"], prior={"K": 0.05}, weights={"psi": 0.01})
    assert fit.free == ["K"] and fit.sigma == {"psi": 0.01}
    assert {"step": "free set", "choice": "K", "reason": "given (--free)"} in fit.choices
    with pytest.raises(InputError, match="no stated prior"):
        cs.identify_ship(recs, model, candidates=["K", "T"])
    with pytest.raises(InputError, match="not parameters"):
        cs.identify_ship(recs, model, free=["N_r_dash"], prior={"N_r_dash": 1.0})


def test_two_records_are_judged_by_blocks():
    model = cs.models.nomoto_first_order(K=0.1, T=20.0)
    prob = cs.OutputErrorProblem(model, _records(n=2), ["K", "T"], sigma={"psi": 0.01},
                                 prior=cs.identify.Prior({"K": 0.05, "T": 10.0}))
    ev = run_evidence(prob)
    assert ev.kind == "blocks" and len(ev.labels) == 6
    # the blocks add up to the records' gradient; the information to the records' in total
    f, g, H, _ = prob.engine.derivatives(prob.space.theta(None))
    assert np.allclose(ev.gradient.sum(axis=0), g)
    assert np.allclose(ev.information.sum(axis=0), H)


def test_predictive_band_is_never_narrower_than_the_parameter_band(nomoto_fit, tmp_path):
    path = nomoto_fit.to_json(tmp_path / "fit.json", extra={"model_discrepancy": {
        "psi_variance_growth_deg2_per_s": 0.01}})
    content = json.loads(path.read_text())
    assert content["workflow"]["choices"] == nomoto_fit.choices
    rep = replay_file(path, _records(seed=10, n=1)[0], samples=0)
    s, wide = rep.bands["psi_std"], rep.bands["psi_std_predictive"]
    assert np.all(wide >= s) and wide[-1] > s[-1]


def test_joined_evidence_adds_candidates_counts_in_every_replicate_and_keeps_its_own_quantities():
    """A cost term (as captive tests give) on ``T`` and on a quantity of its own facility (``K@X``):
    ``T`` becomes a candidate, the joint fit holds one ``T`` for both and ``K@X`` beside it."""
    from casship.identify import CostTerm

    def residual(v):
        return np.array([(v[0] - TRUTH["T"]) / 0.5, (v[1] - 0.3) / 0.01]), np.array([[2.0, 0.0], [0.0, 100.0]])

    term = CostTerm(label="captive:X", names=("T", "K@X"), start=np.array([20.0, 0.2]),
                    lower=np.array([1.0, 0.0]), upper=np.array([500.0, 1.0]), residual=residual, n_obs=2)
    model = cs.models.nomoto_first_order(K=0.1, T=20.0)
    fit = cs.identify_ship(_records(n=4), model, candidates=["K"], prior={"K": 0.05, "T": 10.0}, terms=[term])
    assert "T" in fit.free and "K@X" in fit.fit.free
    assert fit.fit.estimates["T"] == pytest.approx(TRUTH["T"], rel=0.03)
    assert fit.fit.estimates["K@X"] == pytest.approx(0.3, abs=1e-3)
    assert any(c["step"] == "joined evidence" and "T" in c["reason"] for c in fit.choices)
    assert "K@X" not in fit.params()           # a facility's own quantity is not the ship's
