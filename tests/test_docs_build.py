"""The documentation builds with the one documented command (needs the ``docs`` extra)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_sphinx_html_build_without_warnings(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    pytest.importorskip("numpydoc")
    run = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-q", "docs", str(tmp_path / "html")],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    warnings = [line for line in run.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert not warnings, "\n".join(warnings[:20])
    for page in ("index", "data", "studies", "api"):
        assert (tmp_path / "html" / f"{page}.html").stat().st_size > 2_000
    assert "read_nmea" in (tmp_path / "html" / "api.html").read_text()
