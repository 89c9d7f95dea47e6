"""Fit files read one way: non-symmetric covariances, duplicated names, absurd discrepancies and null
fields are refused with a message naming the entry, by every command that reads them."""
import json

import numpy as np
import pytest

import casship as cs
from casship.cli import main
from casship.identify import FitResult, ParameterBelief, read_fit_file, read_params
from casship.identify.verdict import Q_MAX_DEG2_PER_S


@pytest.fixture(scope="module")
def fit_doc():
    truth = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0.0, 200.0, 1.0)
    delta = 0.15 * np.sign(np.sin(2 * np.pi * t / 80) + 1e-9)
    data = cs.measure(cs.simulate(truth, truth.states(), t, {"delta": delta}), truth, {"psi": 0.01}, seed=2)
    prob = cs.OutputErrorProblem(cs.models.get_model("nomoto1"), [data], ["K", "T"], measured=["psi"],
                                 sigma={"psi": 0.01})
    fit = prob.solve(guess={"K": 0.05, "T": 10.0}, show=False)
    return json.loads(json.dumps(fit.to_dict())), data


def _write(tmp_path, doc, name="fit.json"):
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def _simulate(path, data, tmp_path):
    csv = data.to_csv(tmp_path / "run.csv")
    return main(["simulate", "--model", "nomoto1", "--params", str(path), "--inputs", str(csv), "--samples", "0"])


def test_a_non_symmetric_covariance_is_refused_naming_the_entry(fit_doc, tmp_path, capsys):
    doc, data = fit_doc
    bad = json.loads(json.dumps(doc))
    m = np.asarray(bad["param_covariance"]["matrix"])
    m[0, 1] = m[0, 1] + 0.5 * np.sqrt(m[0, 0] * m[1, 1])
    bad["param_covariance"]["matrix"] = m.tolist()
    path = _write(tmp_path, bad)
    with pytest.raises(ValueError, match=r"param_covariance.matrix is not symmetric: entry \(K, T\)"):
        read_fit_file(path)
    assert _simulate(path, data, tmp_path) == 2
    assert "not symmetric: entry (K, T)" in capsys.readouterr().err
    # round-off is not refused (averaged away)
    ok = json.loads(json.dumps(doc))
    m = np.asarray(ok["param_covariance"]["matrix"])
    m[0, 1] *= 1 + 1e-12
    ok["param_covariance"]["matrix"] = m.tolist()
    assert read_fit_file(_write(tmp_path, ok, "ok.json")).uncertainty is not None


def test_duplicated_names_are_refused_by_every_reader(fit_doc, tmp_path, capsys):
    doc, data = fit_doc
    text = json.dumps(doc)
    dup_key = text.replace('"params": {', '"params": {"K": 0.2, ', 1)      # "K" twice in one object
    path = _write(tmp_path, dup_key)
    for read in (lambda: read_params(path), lambda: FitResult.from_json(path)):
        with pytest.raises(ValueError, match="'K' is given more than once"):
            read()
    assert _simulate(path, data, tmp_path) == 2
    assert "'K' is given more than once" in capsys.readouterr().err
    ship = _write(tmp_path, '{"model": "kvlcc2", "params": {"N_r_dash": -0.049, "N_r_dash": -0.05}}', "ship.json")
    assert main(["design-trial", "--model", "kvlcc2", "--params", str(ship)]) == 2
    assert "'N_r_dash' is given more than once" in capsys.readouterr().err
    twice = json.loads(text)
    twice["param_covariance"]["names"] = ["K", "K"]
    twice["param_covariance"]["values"] = [twice["params"]["K"]] * 2
    path = _write(tmp_path, twice, "names.json")
    with pytest.raises(ValueError, match=r"param_covariance: parameter name\(s\) \['K'\] given more than once"):
        read_fit_file(path)
    assert _simulate(path, data, tmp_path) == 2
    twice = json.loads(text)
    twice["free"] = ["K", "K"]
    with pytest.raises(ValueError, match=r"free names \['K'\] given more than once"):
        FitResult.from_json(_write(tmp_path, twice, "free.json"))


@pytest.mark.parametrize("q, ok", [(1e300, False), (-1.0, False), (float("nan"), False), (Q_MAX_DEG2_PER_S, True),
                                   (2 * Q_MAX_DEG2_PER_S, False), (0.0, True)])
def test_model_discrepancy_bounds(fit_doc, tmp_path, q, ok):
    doc, _ = fit_doc
    d = json.loads(json.dumps(doc))
    d["model_discrepancy"] = {"psi_variance_growth_deg2_per_s": q}
    path = _write(tmp_path, json.dumps(d).replace("NaN", '"nan"') if q != q else d)
    if ok:
        assert read_fit_file(path).uncertainty.psi_variance_rate == pytest.approx(np.radians(np.radians(q)))
    else:
        with pytest.raises(ValueError, match=r"model_discrepancy.psi_variance_growth_deg2_per_s must be a number in "
                                             r"\[0, 1000\] deg\^2/s"):
            read_fit_file(path)
    with pytest.raises(ValueError, match="psi_variance_rate"):
        ParameterBelief.from_values(["K"], [0.1], [[1e-4]], psi_variance_rate=1e300)


@pytest.mark.parametrize("field, where", [("param_covariance.matrix", "param_covariance.matrix is null"),
                                          ("param_covariance.values", "param_covariance lacks the values"),
                                          ("covariance", "covariance is null"),
                                          ("covariance_robust", "covariance_robust is null")])
def test_null_covariances_name_the_field(fit_doc, tmp_path, capsys, field, where):
    doc, data = fit_doc
    d = json.loads(json.dumps(doc))
    if "." in field:
        a, b = field.split(".")
        d[a][b] = None
    else:
        d[field] = None
    path = _write(tmp_path, d)
    with pytest.raises(ValueError, match=where):
        if field.startswith("param_covariance"):
            read_fit_file(path)
        else:
            FitResult.from_json(path)
    if field.startswith("param_covariance"):
        assert _simulate(path, data, tmp_path) == 2
        err = capsys.readouterr().err
        assert field.split(".")[0] in err and "cannot reshape" not in err
