"""The trial-design study (quick mode) and the trial-design page's example."""
from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import pytest

from problems import get_study

ROOT = Path(__file__).resolve().parents[1]


def test_trial_design_quick_closed_check(tmp_path):
    """Without measured data part 1 is skipped (an empty data folder); the closed check runs."""
    empty = tmp_path / "no-data"
    empty.mkdir()
    out = tmp_path / "out"
    summary = get_study("trial-design").run(out, quick=True, workers=1, data_dir=empty)
    for name in ("report.md", "summary.json", "closed_check.md", "ranking_closed_check.md", "fig_closed_check.png",
                 "free_trial.csv"):
        assert (out / name).is_file(), name
    assert json.loads((out / "summary.json").read_text())["study"] == "trial-design"
    assert summary["fitted_ship"] is None
    check = summary["closed_check"]
    rows, verdict = check["rows"], check["verdict"]
    assert verdict["recommended"] == "free" and set(rows) == {"free", verdict["best_standard_realised"]}
    # the recommended trial reduces the error more than the best standard one, and as much as predicted
    assert verdict["recommended_beats_best_standard"]
    assert rows["free"]["realised_rmse_m"] < abs(check["prior_value"] - check["true_value"]) / 10
    assert verdict["predicted_vs_realised_factor"] < 2.0
    assert all(r["converged"] == 3 for r in rows.values())
    report = (out / "report.md").read_text()
    assert report.splitlines()[0].endswith("(quick run)") and "Skipped: no measured data" in report
    header = next(csv.reader((out / "free_trial.csv").open()))
    assert header == ["t_s", "rudder_deg", "n"]


def test_trial_design_quick_on_the_fitted_ship(tmp_path, data_dir):
    """With the shared runs the fitted KVLCC2's asymmetry is best resolved by a trial in both directions."""
    summary = get_study("trial-design").run(tmp_path, quick=True, workers=1, data_dir=data_dir)
    designs = summary["fitted_ship"]["designs"]
    asym = designs["port_starboard_difference"]["ranking"]
    assert asym[0]["sides"] == [-1, 1]
    assert all(r["sd_after"] < r["sd_before"] for r in asym)
    td = designs["tactical_diameter"]["ranking"]
    one_sided = [r for r in td if r["kind"] == "turning"]
    assert one_sided[0]["trial"] == "turning 35 starboard"   # the target's own side teaches more about it
    assert (tmp_path / "fit.json").is_file()


@pytest.mark.slow
def test_trial_design_full(tmp_path, data_dir):
    summary = get_study("trial-design").run(tmp_path, quick=False, workers=2, data_dir=data_dir)
    verdict = summary["closed_check"]["verdict"]
    assert verdict["recommended_beats_best_standard"] and verdict["predicted_vs_realised_factor"] < 2.0


def test_trial_design_page_example_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "trial-design.md").read_text(), re.S)
    assert blocks
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "docs/trial-design.md", "exec"), namespace)
    assert (tmp_path / "free_trial.csv").is_file()
