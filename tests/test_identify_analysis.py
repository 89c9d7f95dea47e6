"""Identifiability analysis before fitting, and fit files that replay on their own model only."""
import json

import numpy as np
import pytest

import casship as cs
from casship.cli import main
from casship.identify import FitResult, OutputErrorProblem, read_params

DT = 1.0


def _two_rudders(g=1.0):
    """Nomoto-like model with a second rudder input ``d2`` (gain ``c``) and a gain ``g`` that only
    ever appears multiplied by ``K``."""
    b = cs.ModelBuilder("two-rudders")
    psi, r = b.state("psi", unit="rad", angle=True), b.state("r", unit="rad/s")
    delta, d2 = b.input("delta", unit="rad"), b.input("d2", unit="rad")
    K, T, gg, c = b.param("K", 0.1), b.param("T", 20.0), b.param("g", g), b.param("c", 0.0)
    b.ode(psi=r, r=(K * gg * delta + c * d2 - r) / T + b.noise("w_r"))
    b.output("psi", psi)
    return b.build()


def _records(model, n=3, d2_noise=0.02, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(400) * DT
    out = []
    for i in range(n):
        delta = 0.15 * np.sign(np.sin(2 * np.pi * t / (90 + 20 * i)))
        d2 = delta * (1 + d2_noise * rng.standard_normal(t.size))    # almost the same signal
        tr = cs.simulate(model, model.states(), t, {"delta": delta, "d2": d2})
        out.append(cs.measure(tr, model, {"psi": 0.01}, seed=rng))
    return out


def test_identifiability_flags_correlated_and_unseen_and_proposes_a_free_set(tmp_path):
    m = _two_rudders()
    runs = _records(m)
    prob = OutputErrorProblem(m, runs, free=["K", "T", "c"], sigma={"psi": 0.01})
    idf = prob.identifiability(at={"c": 0.01})
    pairs = {(a, b) for a, b, _ in idf.correlated}
    assert ("K", "c") in pairs and all("T" not in p for p in pairs)
    assert abs(idf.correlation[0, 2]) > 0.95
    assert idf.eigenvalues[0] >= idf.eigenvalues[-1] > 0
    free = idf.propose(max_rel_std=0.05)
    assert "T" in free and not {"K", "c"} <= set(free)           # one of the correlated pair only
    assert "correlated: K and c" in idf.summary()
    assert idf.plot(tmp_path / "idf.png").stat().st_size > 10_000
    # K and g only appear as K*g: the data cannot see them separately
    prob2 = OutputErrorProblem(m, runs, free=["K", "T", "g"], sigma={"psi": 0.01})
    idf2 = prob2.identifiability()
    assert {"K", "g"} <= set(idf2.not_seen) and "T" not in idf2.not_seen
    assert idf2.eigenvalues[-1] < 1e-8 * idf2.eigenvalues[0]
    chosen = idf2.propose()
    assert "T" in chosen and len(chosen) == 2 and not {"K", "g"} <= set(chosen)


def test_fit_file_records_identity_and_replays_only_on_its_model(tmp_path, capsys):
    """A fit of a model variant (built with options) replays through ``casship simulate MODEL
    --params``; another model or parameter set is refused, naming both."""
    m = cs.models.get_model("nomoto1", rudder_bias=True)
    assert m.meta["options"] == {"rudder_bias": True}
    t = np.arange(0, 300.0, DT)
    truth = m.params(K=0.1, T=20.0, delta_0=0.01)
    tr = cs.simulate(m, m.states(), t, {"delta": 0.15 * np.sign(np.sin(2 * np.pi * t / 120))}, truth)
    data = cs.measure(tr, m, {"psi": 0.01}, seed=1)
    fit = OutputErrorProblem(m, data, free=["K", "T", "delta_0"], sigma={"psi": 0.01}).solve(
        guess={"K": 0.05, "T": 10.0})
    path = fit.to_json(tmp_path / "fit.json")
    saved = json.loads(path.read_text())
    assert saved["model"] == "nomoto1" and saved["model_options"] == {"rudder_bias": True}
    assert "delta_0" in saved["params"]
    model, p = read_params(path, "nomoto1")
    assert "delta_0" in model.param_names and p[model.index("delta_0", "param")] == pytest.approx(
        fit.estimates["delta_0"])
    csv = data.to_csv(tmp_path / "run.csv")
    assert main(["simulate", "--model", "nomoto1", "--params", str(path), "--inputs", str(csv), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["replay"]["psi_rmse_deg"] < 2.0
    with pytest.raises(ValueError, match=r"'nomoto1'.*'nomoto2'"):
        read_params(path, "nomoto2")
    with pytest.raises(ValueError, match=r"lacks.*fitted on 'nomoto1' built with options"):
        read_params(path, cs.models.nomoto_first_order())
    back = FitResult.from_json(path)
    assert back.model_options == {"rudder_bias": True} and back.records == fit.records
    ship = cs.models.get_model("kvlcc2")
    pset = FitResult.from_dict({**back.to_dict(), "model": "kvlcc2", "params": {"R_0_dash": 0.02},
                                "param_set": "kvlcc2/other-facility"})
    with pytest.raises(ValueError, match=r"'kvlcc2/other-facility'.*'kvlcc2/YY2015-full-scale'"):
        pset.apply_to(ship)
    with pytest.raises(ValueError, match=r"model 'kvlcc2', not 'kvlcc2-l7'"):
        pset.apply_to(cs.models.get_model("kvlcc2-l7"))


def test_fit_plot_is_a_free_run_with_units(tmp_path):
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0, 200.0, DT)
    tr = cs.simulate(m, m.states(), t, {"delta": 0.15 * np.sign(np.sin(2 * np.pi * t / 120))})
    data = cs.measure(tr, m, {"psi": 0.01}, seed=2)
    ekf = cs.EKF(cs.discretize(m, DT), Q=1e-7, R=1e-4)
    fit = cs.MLEProblem(ekf, data, free=["K", "T"]).solve(guess={"K": 0.05, "T": 10.0})
    pred = fit.predictions[0]
    assert pred["kind"] == "free-run simulation" and pred["angle"] == {"psi": True}
    # the free run is the model simulated with the estimates from the record's initial state
    ref = cs.simulate(m, fit.x0[0], t, {"delta": data["delta"]}, m.params(fit.params))
    np.testing.assert_allclose(pred["predicted"]["psi"], ref["psi"], atol=1e-12)
    assert fit.plot(tmp_path / "fit.png").stat().st_size > 10_000
