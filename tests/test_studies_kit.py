"""The shared study kit: tables, reports with their departures table, effects; and the rule that
studies use the estimator contract instead of branching on estimator names."""
import re
from pathlib import Path

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
