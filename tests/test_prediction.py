"""Prediction bands (casship.simulation.bands): exact sensitivities, coverage of a simulated truth, fit
files carrying the covariance, and per-record cost weights."""
import json

import numpy as np
import pytest

import casship as cs
from casship.identify import ParameterBelief, read_fit_file, read_params
from casship.models import kvlcc2, nomoto_first_order
from casship.simulation import trajectory_sensitivities
from casship.identify import replay_file
from casship.maneuvers import replay


@pytest.mark.parametrize("jit", [False, True])
def test_trajectory_sensitivities_equal_central_differences(jit):
    ship = kvlcc2(asymmetry=True)
    t = np.arange(0.0, 300.0, 1.0)
    U = np.column_stack([np.radians(20.0) * np.sign(np.sin(t / 40.0) + 1e-9), np.full(t.size, 1.53)])
    x0 = ship.states(u=7.97)
    names = ["N_r_dash", "Y_v_dash", "delta_0"]
    p = ship.params()
    X, S = trajectory_sensitivities(ship, x0, t, U, p, names, jit=jit)
    ref = cs.simulate(ship, x0, t, U, p)
    assert np.allclose(X[:, ship.index("psi")], ref["psi"], atol=1e-12)
    for j, name in enumerate(names):
        h = 1e-6 * max(1.0, abs(p[ship.index(name, "param")]))
        hi, lo = p.copy(), p.copy()
        hi[ship.index(name, "param")] += h
        lo[ship.index(name, "param")] -= h
        Xh = np.column_stack([cs.simulate(ship, x0, t, U, q)[s] for q in (hi, lo) for s in ("psi", "y")])
        fd_psi, fd_y = (Xh[:, 0] - Xh[:, 2]) / (2 * h), (Xh[:, 1] - Xh[:, 3]) / (2 * h)
        assert np.allclose(S[:, ship.index("psi"), j], fd_psi, rtol=1e-5, atol=1e-6 * np.abs(fd_psi).max()), name
        assert np.allclose(S[:, ship.index("y"), j], fd_y, rtol=1e-5, atol=1e-6 * np.abs(fd_y).max()), name


def _nomoto_fit(seed, truth, t, rudder):
    sim = cs.simulate(truth, truth.states(), t, {"delta": rudder})
    data = cs.measure(sim, truth, {"psi": np.radians(0.5)}, seed=seed)
    prob = cs.OutputErrorProblem(nomoto_first_order(), data, ["K", "T"], measured=["psi"],
                                 sigma={"psi": np.radians(0.5)}, estimate_x0=["psi"])   # the first row is noisy
    return prob.solve(guess={"K": 0.08, "T": 25.0}, show=False)


def test_bands_cover_a_simulated_truth_at_about_their_nominal_rate():
    truth = nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 300.0, 1.0)
    train = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 90.0) + 1e-9)
    new = np.radians(15.0) * np.sign(np.sin(2 * np.pi * t / 130.0) + 1e-9)       # a run not trained on
    true_run = cs.simulate(truth, truth.states(), t, {"delta": new})
    record = cs.Dataset(t, {"psi": true_run["psi"], "delta": new})
    inside, ratios = [], []
    for seed in range(60):
        fit = _nomoto_fit(seed, truth, t, train)
        unc = fit.uncertainty("model")
        res = replay(nomoto_first_order(), record, nomoto_first_order().params(fit.params), uncertainty=unc,
                     samples=30 if seed < 5 else 0, seed=seed)
        half = res.bands["z"] * res.bands["psi_std"]
        err = np.abs(res.trajectory["psi"] - true_run["psi"])
        inside.append([err[k] <= half[k] for k in (100, 200, 299)])
        if res.sampling:
            ratios.append(res.sampling["psi_std_ratio_sampled_to_linear"])
    rate = np.mean(inside)
    assert 0.88 <= rate <= 0.995, rate          # nominal 0.95; 180 checks (60 fits x 3 times)
    assert np.all(np.abs(np.array(ratios) - 1.0) < 0.35), ratios      # sampling checks the linearisation


def test_fit_files_carry_the_covariance_and_replay_with_bands(tmp_path):
    truth = nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 300.0, 1.0)
    rudder = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 90.0) + 1e-9)
    fit = _nomoto_fit(0, truth, t, rudder)
    path = fit.to_json(tmp_path / "fit.json")
    read = read_fit_file(path)
    model, p, unc = read.model, read.params, read.uncertainty
    assert unc.names == ("K", "T") and unc.source == "robust (sandwich)"
    assert np.allclose(unc.covariance, fit.uncertainty().covariance)
    assert read_params(path)[1] == pytest.approx(p) and len(read_params(path)) == 2     # one arity
    with pytest.warns(DeprecationWarning, match="read_fit_file"):
        assert read_params(path, uncertainty=True)[2].names == unc.names
    record = cs.Dataset(t, {"psi": cs.simulate(truth, truth.states(), t, {"delta": rudder})["psi"], "delta": rudder})
    res = replay_file(path, record, samples=10)
    assert res.bands["psi_std"][-1] > 0 and res.band_summary()["level"] == 0.95
    assert replay_file(path, record, uncertainty=False).bands == {}
    # a covariance whose values disagree with the file's parameters is refused, naming them
    doc = json.loads(path.read_text())
    doc["param_covariance"]["values"][0] += 1.0
    path.write_text(json.dumps(doc))
    for read in (read_fit_file, read_params):                 # one reader: both refuse it
        with pytest.raises(ValueError, match=r"\['K'\] differ"):
            read(path)


def test_parameter_belief_checks_its_input():
    with pytest.raises(ValueError, match="not positive semi-definite"):
        ParameterBelief.from_values(["a", "b"], [0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="not finite for"):
        ParameterBelief.from_values(["a"], [0.0], [[np.nan]])
    u = ParameterBelief.from_values(["K", "T"], [0.1, 20.0], [[1e-4, 0.0], [0.0, 4.0]])
    m = nomoto_first_order()
    draws = u.sample(m, m.params(), 4000, seed=1)
    assert np.std(draws[:, m.index("T", "param")]) == pytest.approx(2.0, rel=0.05)


def test_record_weights_count_a_record_as_that_many_copies():
    truth = nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 200.0, 1.0)
    runs = [cs.measure(cs.simulate(truth, truth.states(), t, {"delta": a * np.sign(np.sin(t / 20) + 1e-9)}), truth,
                       {"psi": 0.01}, seed=i) for i, a in enumerate((0.1, -0.15))]
    kw = dict(measured=["psi"], sigma={"psi": 0.01})
    weighted = cs.OutputErrorProblem(nomoto_first_order(), runs, ["K", "T"], record_weights=[2.0, 1.0], **kw)
    copies = cs.OutputErrorProblem(nomoto_first_order(), [runs[0], runs[0], runs[1]], ["K", "T"], **kw)
    v = {"K": 0.09, "T": 18.0}
    assert weighted.cost(v) == pytest.approx(copies.cost(v), rel=1e-12)
    assert weighted.gradient(v) == pytest.approx(copies.gradient(v), rel=1e-10)
    assert weighted.subset([1]).record_weights.tolist() == [1.0]
    with pytest.raises(ValueError, match=r"record\(s\) \[1\]"):
        cs.OutputErrorProblem(nomoto_first_order(), runs, ["K", "T"], record_weights=[1.0, -1.0], **kw)


def test_a_files_model_discrepancy_gives_a_predictive_band_that_covers_a_drifting_truth(tmp_path):
    # truth = the model's replay + a heading random walk of variance q t (a discrepancy the parameters
    # cannot explain); the file carries q [deg^2/s]: the predictive band covers at the nominal rate,
    # the parameter band does not
    truth = nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 300.0, 1.0)
    rudder = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 90.0) + 1e-9)
    path = _nomoto_fit(0, truth, t, rudder).to_json(tmp_path / "fit.json")
    q_deg2 = 0.02
    doc = json.loads(path.read_text())
    doc["model_discrepancy"] = {"psi_variance_growth_deg2_per_s": q_deg2}
    path.write_text(json.dumps(doc))
    assert read_fit_file(path).uncertainty.psi_variance_rate == pytest.approx(np.radians(np.radians(q_deg2)))
    new = np.radians(15.0) * np.sign(np.sin(2 * np.pi * t / 130.0) + 1e-9)
    clean = cs.simulate(truth, truth.states(), t, {"delta": new})["psi"]
    rng = np.random.default_rng(3)
    param, predictive = [], []
    for _ in range(40):
        walk = np.concatenate([[0.0], np.cumsum(rng.standard_normal(t.size - 1) * np.sqrt(np.radians(np.radians(q_deg2))))])
        res = replay_file(path, cs.Dataset(t, {"psi": clean + walk, "delta": new}), samples=0)
        param.append(res.bands["coverage"])
        predictive.append(res.bands["coverage_predictive"])
    assert 0.9 <= np.mean(predictive) <= 0.99, np.mean(predictive)
    assert np.mean(param) < 0.6, np.mean(param)
    summary = res.band_summary()
    assert summary["psi_predictive_halfwidth_end_deg"] == pytest.approx(
        1.959964 * np.sqrt(np.degrees(res.bands["psi_std"][-1]) ** 2 + q_deg2 * 299.0), rel=1e-5)
    doc["model_discrepancy"] = {"psi_variance_growth_deg2_per_s": -1.0}
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match="psi_variance_growth_deg2_per_s"):
        read_fit_file(path)


def test_the_predictive_band_adds_the_discrepancy_to_the_parameter_bands_own_covariance(tmp_path):
    # one covariance for both bands: the predictive band is sqrt(s^2 + q t) with s the parameter band's
    # standard deviation, so it is never narrower than the parameter band (an estimated_with covariance
    # is read and checked, but does not narrow the predictive band)
    truth = nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 200.0, 1.0)
    rudder = np.radians(10.0) * np.sign(np.sin(2 * np.pi * t / 90.0) + 1e-9)
    path = _nomoto_fit(0, truth, t, rudder).to_json(tmp_path / "fit.json")
    doc = json.loads(path.read_text())
    names = doc["param_covariance"]["names"]
    wide = (np.asarray(doc["param_covariance"]["matrix"]) * 100.0).tolist()
    narrow = doc["param_covariance"]
    q_deg2 = 0.01
    doc["param_covariance"] = {**narrow, "matrix": wide, "source": "wide"}
    doc["model_discrepancy"] = {"psi_variance_growth_deg2_per_s": q_deg2, "estimated_with": narrow}
    path.write_text(json.dumps(doc))
    data = cs.Dataset(t, {"psi": cs.simulate(truth, truth.states(), t, {"delta": rudder})["psi"], "delta": rudder})
    res = replay_file(path, data, samples=0)
    doc.pop("model_discrepancy")
    narrow_only = tmp_path / "narrow.json"
    narrow_only.write_text(json.dumps({**doc, "param_covariance": narrow}))
    s_narrow = replay_file(narrow_only, data, samples=0).bands["psi_std"]
    np.testing.assert_allclose(res.bands["psi_std"], 10.0 * s_narrow, rtol=1e-9)   # the parameter band: the wide one
    expected = np.sqrt((10.0 * s_narrow) ** 2 + np.radians(np.radians(q_deg2)) * (t - t[0]))
    np.testing.assert_allclose(res.bands["psi_std_predictive"], expected, rtol=1e-9)
    assert np.all(res.bands["psi_std_predictive"] >= res.bands["psi_std"])
    # the covariance must be of the same parameters, in the same order
    bad = json.loads(path.read_text())
    bad["model_discrepancy"]["estimated_with"] = {**narrow, "names": names[::-1]}
    path.write_text(json.dumps(bad))
    if len(names) > 1:
        with pytest.raises(ValueError, match="estimated_with has parameters"):
            read_fit_file(path)
