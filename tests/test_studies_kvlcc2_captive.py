"""The kvlcc2-captive study on the shared data (quick: the MARIN replays only)."""
from __future__ import annotations

import json

import pytest


@pytest.mark.data
@pytest.mark.slow
def test_quick_study_writes_its_summary(data_dir, tmp_path):
    from casship.studies import get_study

    if not (data_dir / "kvlcc2_hmri_captive").is_dir():
        pytest.skip("kvlcc2_hmri_captive absent")
    study = get_study("kvlcc2-captive")
    study.run(tmp_path, quick=True, data_dir=data_dir)
    s = json.loads((tmp_path / "summary.json").read_text())
    for key in ("loro", "loro_regime", "lodo", "lofo"):
        assert set(s[key]) >= {"published_mean_deg", "fit_mean_deg", "better", "of"}
    assert s["loro"]["of"] == 3                       # quick: the three MARIN runs
    assert s["captive"]["status"] == "converged"
    assert set(s["circle_left_out"]) >= {"advance_pct", "tactical_diameter_pct"}
    assert s["predictive_coverage"] is None and s["variants_tried"] >= 1
    lever = s["rudder_lever"]                          # the loading lever, reported beside
    assert lever["status"] == "converged" and lever["std_error"] > 0
    assert lever["lr_statistic"] == pytest.approx(2 * (lever["loglik_loading"] - lever["loglik_constant"]))
    assert lever["lr_statistic"] > -1e-6              # nested models: one more coefficient cannot fit worse
    assert "rudder lever against propeller loading" in (tmp_path / "report.md").read_text()
    assert (tmp_path / "report.md").read_text().startswith("# KVLCC2 MMG coefficients from HMRI captive tests alone")
    for name in ("fig_forces.png", "fig_replays.png", "coefficients.csv", "captive_fit.json"):
        assert (tmp_path / name).is_file()
