"""The shared study kit: tables, reports with their departures table, effects; and the rule that
studies use the estimator contract instead of branching on estimator names."""
import re
from pathlib import Path

import numpy as np
import pytest

from problems.kit import Departure, Report, effect, md_table

ROOT = Path(__file__).resolve().parents[1]


def test_report_says_quick_or_full_on_its_first_line_and_needs_departures(tmp_path):
    rep = Report("Study X", quick=True).add("text")
    with pytest.raises(ValueError, match="Departures from the paper"):
        rep.write(tmp_path)
    rep.departures([Departure("P(0)", "1e5 I", "R | for u", "none")])
    text = rep.write(tmp_path).read_text()
    assert text.splitlines()[0] == "# Study X (quick run)"
    assert "| P(0) | 1e5 I | R \\| for u | none |" in text
    assert Report("Study X", quick=False).text().splitlines()[0] == "# Study X (full run)"
    with pytest.raises(ValueError, match="at least one departure"):
        Report("Y", quick=False).departures([])


def test_md_table_and_effect():
    table = md_table({"a": {"x": 1.23456, "y": float("nan")}, "b": {"x": 2, "y": "ok"}}, first="case")
    assert table.splitlines() == ["| case | x | y |", "|---|---|---|", "| a | 1.235 | n/a |", "| b | 2 | ok |"]
    text = effect({"growth": 2.0, "gap": 0.5}, {"growth": 3.0, "gap": 0.25}, alt_name="other")
    assert text == "with other: growth: 2 -> 3 (+50 %); gap: 0.5 -> 0.25 (-50 %)"


def test_studies_do_not_branch_on_estimator_names():
    pattern = re.compile(r"""(startswith|endswith)\(\s*["'](EnKF|UKF|EKF|KF|MHE|KalmanBucy)|["'](EnKF|UKF|EKF|MHE)["']\s+in\s+name""")
    hits = [f"{p.relative_to(ROOT)}:{i}" for p in (ROOT / "problems").rglob("*.py")
            for i, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert not hits, hits


def test_no_study_module_over_600_lines():
    long = {str(p.relative_to(ROOT)): n for p in (ROOT / "problems").rglob("*.py")
            if (n := len(p.read_text().splitlines())) > 600}
    assert not long, long


def test_figure_with_fixed_margins_places_the_axes_in_inches(tmp_path):
    from problems.kit import figure

    with figure(tmp_path / "f.png", 2, 3, figsize=(12, 6), margins={"left": 1.2, "hspace": 0.6}) as (fig, axes):
        for ax in axes.ravel():
            ax.plot([0, 1], [0, 1])
    assert (tmp_path / "f.png").stat().st_size > 0
    boxes = [ax.get_position() for ax in axes.ravel()]          # figure fractions
    assert np.isclose(boxes[0].x0 * 12, 1.2) and np.isclose((1 - boxes[2].x1) * 12, 0.15)      # left, right default
    assert np.isclose((1 - boxes[0].y1) * 6, 0.35) and np.isclose(boxes[3].y0 * 6, 0.6)        # top, bottom
    assert np.isclose((boxes[0].y0 - boxes[3].y1) * 6, 0.6)                                     # the gap asked for
    assert np.isclose((boxes[1].x0 - boxes[0].x1) * 12, 0.8)                                    # the default gap
    with pytest.raises(ValueError, match="unknown margin"):
        with figure(tmp_path / "g.png", margins={"middle": 1.0}):
            pass
    with pytest.raises(ValueError, match="no room"):
        with figure(tmp_path / "h.png", 1, 2, figsize=(2, 2), margins={"wspace": 2.0}):
            pass
