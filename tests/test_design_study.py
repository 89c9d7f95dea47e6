"""The trial-design study (quick mode) and the trial-design page's example."""
from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

import numpy as np
from scipy.stats import chi2

from problems import get_study, trial_design

ROOT = Path(__file__).resolve().parents[1]


def _data_or_empty(tmp_path):
    """The measured-data folder when there is one, else an empty folder (part 1 is then skipped)."""
    from casship.io import data_dir

    try:
        folder = data_dir()
    except FileNotFoundError:
        folder = None
    if folder is None or not (folder / "kvlcc2_marin_free").is_dir():
        folder = tmp_path / "no-data"
        folder.mkdir()
        return folder, False
    return folder, True


def test_trial_design_quick(tmp_path):
    """The closed check always; with the shared runs also part 1 (skipped, and said so, without them)."""
    data, have = _data_or_empty(tmp_path)
    out = tmp_path / "out"
    summary = get_study("trial-design").run(out, quick=True, workers=1, data_dir=data)
    for name in ("report.md", "summary.json", "closed_check.md", "ranking_closed_check.md", "fig_closed_check.png",
                 "free_trial.csv"):
        assert (out / name).is_file(), name
    assert json.loads((out / "summary.json").read_text())["study"] == "trial-design"
    check = summary["closed_check"]
    rows, verdict = check["rows"], check["verdict"]
    assert set(rows) == {"(prior only)", verdict["recommended"], verdict["best_standard"]}
    assert verdict["ships"] == trial_design.SHIPS["quick"] and verdict["rule"] == trial_design.RULE
    # the rule, recomputed by hand from the rows: the 95 % chi-square bound of an RMS of N normal errors
    rec = rows[verdict["recommended"]]
    n = verdict["ships"]
    bound = rec["predicted_sd_m"] * np.sqrt(chi2.ppf(0.975, n) / n)
    assert verdict["upper_bound"] == pytest.approx(bound, rel=1e-12)
    assert verdict["passed"] == (rec["realised_rmse_m"] <= bound and rec["realised_rmse_m"] < rows["(prior only)"]["realised_rmse_m"])
    # the design with the stated model discrepancy is not over-confident; the one without it is, by far
    assert verdict["passed"]
    assert rec["predicted_sd_no_model_error_m"] * 3 < rec["realised_rmse_m"] <= rec["predicted_sd_m"]
    assert all(r["converged"] == n for r in rows.values())
    report = (out / "report.md").read_text()
    assert report.splitlines()[0].endswith("(quick run)")
    header = next(csv.reader((out / "free_trial.csv").open()))
    assert header == ["t_s", "rudder_deg", "n"]
    if not have:
        assert summary["fitted_ship"] is None and "Skipped: no measured data" in report
        return
    # the fitted KVLCC2's asymmetry is best resolved by a trial in both directions
    designs = summary["fitted_ship"]["designs"]
    asym = designs["port_starboard_difference"]["ranking"]
    assert asym[0]["sides"] == [-1, 1]
    assert all(r["sd_after"] < r["sd_before"] for r in asym)
    turns = [r["trial"] for r in designs["tactical_diameter"]["ranking"] if r["kind"] == "turning"]
    assert turns[0] == "turning 35 starboard"       # the target's own side teaches more about it
    # the fit is the registered kvlcc2-marin study's, run into a subfolder; the report names its covariance
    fitted = summary["fitted_ship"]
    assert (out / "kvlcc2-marin" / "fit.json").is_file() and fitted["fit_file"] == "kvlcc2-marin/fit.json"
    assert fitted["covariance"] in ("calibrated", "robust", "model-based")
    assert f"Belief: fit.json: {fitted['covariance']} covariance" in report


@pytest.mark.slow
def test_trial_design_full(tmp_path, data_dir):
    """The full closed check: its stated rule over the full count of true ships, with the sampling error reported."""
    summary = get_study("trial-design").run(tmp_path, quick=False, workers=2, data_dir=data_dir)
    check = summary["closed_check"]
    assert check["verdict"]["ships"] >= 50 and check["verdict"]["passed"]
    assert summary["fitted_ship"]["covariance"] == "calibrated"      # the study's fit.json carries its jackknife
    assert all(0 < r["sampling_se_m"] < r["realised_rmse_m"] for r in check["rows"].values())


def test_trial_design_page_example_runs(tmp_path, monkeypatch):
    from test_design_fit import write_fit

    monkeypatch.chdir(tmp_path)
    write_fit(tmp_path / "fit.json")           # the blocks marked "needs fit.json" read a fit file of kvlcc2
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "trial-design.md").read_text(), re.S)
    assert blocks
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "docs/trial-design.md", "exec"), namespace)
    assert (tmp_path / "free_trial.csv").is_file()
