"""Koike et al. (2023) study (``casship study filter-guidelines --quick``) and its Monte Carlo machinery."""
from __future__ import annotations

import numpy as np
import pytest

import problems
from casship.parallel import run_cases
from problems import filter_guidelines as fg


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("filter_guidelines")
    return out, problems.get_study("filter-guidelines").run(out, quick=True, workers=1)


def test_quick_study_writes_figures_tables_and_comparison(quick):
    out, summary = quick
    for fig in ("fig02_wind.png", "fig03_wind_effect.png", "fig04_rmse_wind.png", "fig05_rmse_tuned_q.png",
                "fig06_rmse_noise.png", "fig07_08_maneuvers.png", "fig09_rmse_maneuver.png", "fig10_time.png"):
        assert (out / fig).stat().st_size > 5_000, fig
    report = (out / "report.md").read_text()
    assert report.splitlines()[0].endswith("(quick run)")
    assert "Comparison with the paper's conclusions" in report and "## Departures from the paper" in report
    assert report.count("| UKF Q=0 |") >= 3 + 3 + 2          # one row per condition of each experiment
    assert set(summary["rmse"]) == {"wind", "noise", "maneuver", "wind (Fujiwara 2005)",
                                    f"wind (data std {fg.DATA_STD_ALT})"}
    assert set(summary["time_per_step"]) == {"UKF", "EnKF", "KF", "EKF"}
    # the MHE column ran, and on the same records it is as accurate as the tuned UKF (within 20 %)
    for row in summary["mhe"].values():
        assert "error" not in row, row
        for s in fg.STATES:
            assert row["rmse"][s] < 1.2 * row["ukf_same_record"][s]


def test_model_based_filters_beat_the_measurements_without_modelling_error(quick):
    _, summary = quick
    cell = summary["rmse"]["wind"]["0.0"]
    for name in ("UKF Q=0", "EKF Q=0", "UKF tuned"):
        for s in fg.STATES:
            assert cell[name][s]["mean"] < fg.DATA_STD, (name, s)
            assert cell[name][s]["failed"] == 0


def test_departures_carry_the_measured_effect_of_both_other_readings(quick):
    _, summary = quick
    deps = {d["topic"]: d for d in summary["departures"]}
    for topic in ("wind loads in the data", "data noise of experiments 1 and 3"):
        text = deps[topic]["effect"]
        assert "wind growth UKF" in text and "EnKF-UKF gap x [m]" in text and "->" in text, text
    # the paper's data noise, w ~ N(0, R) with R = diag(5e-2), is the reading taken
    assert fg.DATA_STD == pytest.approx(0.05 ** 0.5)
    head = summary["headline"]
    assert set(head) == {"wind growth UKF", "wind growth EnKF", "EnKF-UKF gap x [m]", "EnKF-UKF gap u [m/s]"}


def test_wind_modelling_error_costs_accuracy_of_the_q0_filters(quick):
    _, summary = quick
    f = summary["findings"]
    assert f["wind growth UKF Q=0"] > 1.1
    assert f["wind growth EnKF Q=0"] > 1.1
    # the persistence KF has no ship model, so the wind is no modelling error for it
    assert abs(f["wind growth KF"] - 1.0) < 0.1


def test_monte_carlo_cases_in_a_process_pool_equal_the_serial_run():
    q_kf = {s: 1e-3 for s in fg.STATES}
    cases = [{"experiment": "wind", "condition": w, "kind": "zigzag", "wind": w, "std": fg.DATA_STD, "seed": seed,
              "duration": 5.0, "q_kf": q_kf} for w, seed in ((1.64, 1), (1.64, 2))]
    serial = run_cases(fg.run_case, cases, workers=1)
    pooled = run_cases(fg.run_case, cases, workers=2)
    assert serial == pooled                                   # bit-identical, EnKF draws included
    a, b = (r["rmse"]["EnKF Q=0"]["x"] for r in serial)
    assert a != b                                             # different seeds, different noise


def test_gust_record_has_the_paper_mean_speeds():
    for mean in fg.WIND_MEANS:
        _, speed, _ = fg.gust_record(200.0, mean)
        assert np.mean(speed) == pytest.approx(mean, abs=1e-12)
        assert np.all(speed >= 0)
    with pytest.raises(ValueError, match="unknown manoeuvre"):
        fg.rudder_inputs("spiral", np.arange(3.0), None, 10.0)
