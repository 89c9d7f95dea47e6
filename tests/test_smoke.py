"""End-to-end smoke tests of the command line."""
import json

from casship.cli import main


def test_help_lists_demo(capsys):
    assert main([]) == 0
    assert "demo" in capsys.readouterr().out


def test_demo_quick_writes_report(tmp_path):
    assert main(["demo", "--quick", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (tmp_path / "report.md").exists()
    # the filter must beat the raw measurement noise on every channel
    for name, err in summary["rmse_ekf"].items():
        assert err < summary["rmse_measurement"][name]
