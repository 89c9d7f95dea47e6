"""Trial design on a fit file: the belief is the file's covariance block (the calibrated one when the
file carries it), the command line says which covariance it used, and the study's part 1 runs from a
fit file and reaches the kvlcc2-marin study only through the study registry."""
from __future__ import annotations

import ast
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from casship.cli import main
from casship.design import COVARIANCES, ParameterBelief, covariance_kind, fit_noise
from casship.gaussian import Gaussian
from casship.identify import FitResult, read_fit_file, read_params
from casship.models import kvlcc2

ROOT = Path(__file__).resolve().parents[1]
FREE = ["N_v_dash", "Y_v_dash", "N_vvr_dash", "psi@0"]          # a non-parameter free quantity too
JACK = ["delta_0", "N_v_dash", "Y_v_dash", "N_vvr_dash"]          # the jackknife also covers an earlier stage
SIGMA = {"psi": np.radians(0.5), "r": np.radians(0.05), "u": 0.05}


def _spd(k: int, seed: int, scale) -> np.ndarray:
    a = np.random.default_rng(seed).standard_normal((k, k))
    s = np.asarray(scale, dtype=float)
    return (a @ a.T / k + np.eye(k)) * np.outer(s, s)


def write_fit(path: Path, *, jackknife: bool = True, robust: bool = True) -> dict:
    """A fit file of the study's KVLCC2 as ``FitResult.to_json`` writes one, with three different
    covariances: model-based, robust and (optionally) a run-level jackknife that covers one more
    parameter; returns the matrices."""
    model = kvlcc2(asymmetry=True, smooth=True)
    params = model.param_dict()
    params.update(N_v_dash=-0.14, Y_v_dash=-0.29, N_vvr_dash=-0.4, delta_0=np.radians(-0.4))
    est = {n: params[n] for n in FREE[:3]} | {"psi@0": 0.01}
    scale = [0.004, 0.01, 0.03, 0.002]
    model_cov, robust_cov = _spd(4, 1, scale), _spd(4, 2, np.multiply(scale, 2.0))
    jack = _spd(4, 3, [np.radians(0.2), 0.01, 0.02, 0.05])
    fit = FitResult(model=model.name, params=params, free=FREE, estimates=est,
                    std_errors=dict(zip(FREE, np.sqrt(np.diag(model_cov)))), correlation=np.eye(4),
                    covariance=model_cov, cost=1.0, loglik=0.0, n_obs=1000, aic=0.0, bic=0.0, method="output-error",
                    noise={"sigma": {k: v / 0.5 for k, v in SIGMA.items()}, "weight_scale": 0.5},
                    model_options=dict(model.meta["options"]), param_set=model.vessel.param_set,
                    param_names=list(model.param_names), covariance_robust=robust_cov if robust else None)
    if jackknife:
        unc = ParameterBelief.from_values(JACK, [params[n] for n in JACK], jack,
                                          "run-level jackknife over 16 leave-one-run-out folds", {"folds": 16},
                                          kind="calibrated")
        fit = dataclasses.replace(fit, param_covariance=unc.to_dict())
    fit.to_json(path)
    return {"model": model_cov, "robust": robust_cov, "jackknife": jack, "params": params}


@pytest.fixture(scope="module")
def fit_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fits")
    calibrated, plain = folder / "fit.json", folder / "fit_robust.json"
    return (calibrated, write_fit(calibrated)), (plain, write_fit(plain, jackknife=False))


def test_belief_from_a_fit_file_is_its_calibrated_covariance_block(fit_files):
    (path, mats), (plain, plain_mats) = fit_files
    read = read_fit_file(path, "kvlcc2")
    model, p, unc = read.model, read.params, read.uncertainty
    belief = ParameterBelief.from_fit(path, params=model.param_dict(p))
    assert belief.kind == "calibrated" and "jackknife" in belief.source and path.name in belief.source
    assert belief.names == tuple(JACK)
    assert np.allclose(belief.cov, mats["jackknife"], rtol=1e-14, atol=0.0)
    assert belief.mean == {n: mats["params"][n] for n in JACK}
    # the same belief as the uncertainty read_fit_file returns
    assert np.allclose(unc.described().cov, belief.cov, rtol=1e-14)
    # the others on request: the blocks of the fit's free model parameters (psi@0 is not one)
    for kind, key in (("robust", "robust"), ("model", "model")):
        b = ParameterBelief.from_fit(path, covariance=kind)
        assert b.names == tuple(FREE[:3]) and b.kind == ("robust" if kind == "robust" else "model-based")
        assert np.allclose(b.cov, mats[key][:3, :3], rtol=1e-14)
    # without a jackknife the file carries the robust covariance, and that is the default
    b = ParameterBelief.from_fit(plain)
    assert b.kind == "robust" and np.allclose(b.cov, plain_mats["robust"][:3, :3], rtol=1e-14)
    with pytest.raises(ValueError, match="no calibrated.*robust"):
        ParameterBelief.from_fit(plain, covariance="jackknife")
    with pytest.raises(ValueError, match="covariance 'sandwich'"):
        ParameterBelief.from_fit(plain, covariance="sandwich")


def test_belief_from_a_fit_adds_a_prior_for_what_the_fit_held_fixed(fit_files):
    (path, mats), _ = fit_files
    b = ParameterBelief.from_fit(path, extra_std={"N_r_dash": 0.01, "Y_0_dash": 0.05})
    k = len(JACK)
    assert b.names == (*JACK, "N_r_dash", "Y_0_dash") and b.kind == "calibrated" and "prior std of 2 more" in b.source
    assert np.allclose(b.cov[:k, :k], mats["jackknife"]) and np.allclose(np.diag(b.cov)[k:], [1e-4, 0.0025])
    assert not b.cov[:k, k:].any()
    assert b.mean["N_r_dash"] == pytest.approx(mats["params"]["N_r_dash"])
    with pytest.raises(ValueError, match=r"\['delta_0'\].*estimated"):
        ParameterBelief.from_fit(path, extra_std={"delta_0": 0.01})
    with pytest.raises(ValueError, match="already|covers"):
        b.extended({"N_r_dash": 0.02}, mats["params"])
    with pytest.raises(ValueError, match="no mean"):
        ParameterBelief.from_fit(path, extra_std={"not_a_parameter": 1.0})


def test_covariance_kinds_and_the_fit_noise(fit_files):
    (path, _), _ = fit_files
    assert [covariance_kind(s) for s in ("run-level jackknife over 16 folds", "robust (sandwich), asymmetry stage",
                                          "model-based", "by hand")] == ["calibrated", "robust", "model-based",
                                                                         "stated"]
    noise = fit_noise(path)
    assert noise == pytest.approx(SIGMA)
    assert fit_noise(FitResult.from_json(path)) == pytest.approx(SIGMA)


def test_cli_says_which_covariance_it_used(fit_files, tmp_path, capsys):
    from casship.cli.cmd_design_trial import COVARIANCES as CLI_COVARIANCES

    assert CLI_COVARIANCES == COVARIANCES
    (path, _), (plain, _) = fit_files
    common = ["design-trial", "--model", "kvlcc2", "--params", str(path), "--dt", "4", "--turning", "35",
              "--zigzag", "20", "--pullout", "", "--no-spiral", "--no-free"]
    assert main(common) == 0
    text = capsys.readouterr().out
    assert text.startswith("belief: calibrated (fit.json: calibrated covariance (run-level jackknife")
    assert main(common + ["--covariance", "model", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["belief"]["covariance"] == "model-based" and out["belief"]["names"] == FREE[:3]
    assert out["noise"] == pytest.approx(SIGMA)
    assert main(common + ["--prior-std", "N_r_dash=0.01", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["belief"]["covariance"] == "calibrated" and out["belief"]["names"] == [*JACK, "N_r_dash"]
    assert main(["design-trial", "--model", "kvlcc2", "--params", str(plain), "--covariance", "jackknife",
                 "--no-free"]) == 2
    assert "no calibrated (jackknife) covariance" in capsys.readouterr().err
    assert main(["design-trial", "--model", "kvlcc2", "--prior-std", "N_r_dash=0.01", "--sigma", "psi=0.01",
                 "--covariance", "robust", "--no-free"]) == 2
    assert "--params" in capsys.readouterr().err


def _imports(path: Path) -> list[str]:
    """Every module a file imports (relative imports spelled with their leading dots)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = "." * node.level + (node.module or "")
            out += [base] if node.module else [f"{base}{a.name}" for a in node.names]
    return out


def test_the_study_reaches_kvlcc2_marin_only_through_the_registry():
    source = ROOT / "problems" / "trial_design.py"
    imports = _imports(source)
    assert imports, "no imports found: the check would be empty"
    marin = [m for m in imports if "kvlcc2_marin" in m]
    assert not marin, f"problems/trial_design.py imports {marin}: use the registered study and its fit.json"
    text = source.read_text()
    assert "import_module" not in text and "__import__" not in text       # no import by a string either
    assert "casship.studies" in imports and '"kvlcc2-marin"' in text


def test_part_one_runs_from_a_fit_file(fit_files, tmp_path):
    from problems import trial_design

    (path, mats), _ = fit_files
    out = tmp_path / "out"
    out.mkdir()
    rep = trial_design.Report("part 1", quick=True)
    res = trial_design.design_on_fit(path, out, rep, dt=4.0, max_iter=0, free=False)
    assert res["covariance"] == "calibrated" and "jackknife" in res["belief"]
    names = res["uncertain"]
    assert names[:len(JACK)] == JACK and len(set(names)) == len(names)
    model = kvlcc2(asymmetry=True, smooth=True)
    assert set(names) == set(JACK) | set(trial_design.prior_std(model, trial_design.HELD_PRIOR))
    asym = res["designs"]["port_starboard_difference"]["ranking"]
    assert all(r["sd_after"] < r["sd_before"] for r in asym)
    assert asym[0]["sides"] == [-1, 1]            # the asymmetry wants both directions
    for name in ("ranking_fit_tactical_diameter.md", "fig_fit_port_starboard_difference.png"):
        assert (out / name).is_file(), name


def test_the_covariance_kind_is_typed_and_travels_with_the_file(fit_files, tmp_path):
    (path, _), (plain, _) = fit_files
    import json
    carried = json.loads(path.read_text())["param_covariance"]
    assert carried["kind"] == "calibrated"                       # written where the covariance is made
    assert ParameterBelief.from_dict(carried).kind == "calibrated"
    # The file's kind wins over its prose: a source that mentions a jackknife but says robust is robust.
    says_robust = dict(carried, kind="robust")
    assert ParameterBelief.from_dict(says_robust).kind == "robust"
    assert covariance_kind(ParameterBelief.from_dict(says_robust)) == "robust"
    # A file older than the field: the prose rule, once, on reading.
    old = {k: v for k, v in carried.items() if k != "kind"}
    assert ParameterBelief.from_dict(old).kind == "calibrated"
    older = tmp_path / "old_fit.json"
    obj = json.loads(path.read_text())
    obj["param_covariance"] = old
    older.write_text(json.dumps(obj))
    assert ParameterBelief.from_fit(older).kind == "calibrated"
    # The fit's own covariances are made with their kind.
    fit = FitResult.from_json(plain)
    assert fit.uncertainty(kind="model").kind == "model-based"
    assert fit.uncertainty(kind="robust").kind == "robust"
    with pytest.raises(ValueError, match="covariance kind 'sandwich'"):
        ParameterBelief.from_dict(dict(carried, kind="sandwich"))
    with pytest.raises(ValueError, match="covariance kind"):
        ParameterBelief(("K",), Gaussian([0.1], [[1.0]]), kind="guess")


def test_one_belief_converts_to_a_prior_and_an_uncertainty_and_back(fit_files):
    from casship.identify import Prior
    (path, made), _ = fit_files
    belief = ParameterBelief.from_fit(path)
    with pytest.warns(DeprecationWarning, match="to_uncertainty"):      # 0.3's conversions: the belief itself
        unc = belief.to_uncertainty()
    assert (unc.names, unc.kind, unc.source) == (belief.names, "calibrated", belief.source)
    np.testing.assert_array_equal(unc.covariance, belief.cov)
    with pytest.warns(DeprecationWarning, match="from_uncertainty"):
        again = ParameterBelief.from_uncertainty(unc, source=belief.source)
    assert (again.names, again.mean, again.source, again.kind) == (belief.names, belief.mean, belief.source, belief.kind)
    np.testing.assert_array_equal(again.cov, belief.cov)
    with pytest.raises(ValueError, match="correlates"):
        belief.to_prior()                                    # the jackknife covariance is not diagonal
    prior = belief.to_prior(marginal=True, weight=0.5)
    assert prior.weight == 0.5
    assert prior.std == pytest.approx(dict(zip(JACK, np.sqrt(np.diag(made["jackknife"])))), rel=1e-14)
    assert prior.mean == pytest.approx({n: made["params"][n] for n in JACK}, rel=1e-14)
    independent = ParameterBelief.from_std({"K": 0.02, "T": 5.0}, {"K": 0.1, "T": 20.0})
    assert Prior.from_belief(independent) == Prior({"K": 0.02, "T": 5.0}, {"K": 0.1, "T": 20.0})
    back = ParameterBelief.from_prior(Prior({"K": 0.02, "T": 5.0}, {"K": 0.1}), {"T": 20.0, "other": 1.0})
    assert (back.names, back.mean, back.std, back.kind) == (("K", "T"), {"K": 0.1, "T": 20.0}, {"K": 0.02, "T": 5.0},
                                                             "prior")


def test_part_1_runs_the_fold_families_the_fit_file_depends_on():
    from problems import kvlcc2_marin, trial_design

    assert trial_design.PART1_FOLDS == kvlcc2_marin.FIT_FILE_FAMILIES
    assert set(trial_design.PART1_FOLDS) <= set(kvlcc2_marin.FOLD_FAMILIES)
