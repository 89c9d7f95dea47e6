"""The documentation builds without warnings with the one documented command, API reference included.

Sphinx, myst-parser and numpydoc are in the ``test`` extra, so this runs wherever the suite runs (CI).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_sphinx_html_build_without_warnings(tmp_path):
    run = subprocess.run([sys.executable, "-m", "sphinx", "-b", "html", "-q", "docs", str(tmp_path / "html")],
                         cwd=ROOT, capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, run.stderr[-2000:]
    warnings = [line for line in run.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert not warnings, "\n".join(warnings[:20])
    for page in ("index", "data", "studies", "api"):
        assert (tmp_path / "html" / f"{page}.html").stat().st_size > 2_000
    api = (tmp_path / "html" / "api.html").read_text()
    # the API reference is rendered from the docstrings, not an empty page
    for name in ("read_nmea", "read_marin", "read_record", "run_maneuver", "trim", "ValidityError",
                 "output_folder", "decimate", "resample"):
        assert f'id="casship.' in api and name in api, name
    assert "read_marin" in (tmp_path / "html" / "data.html").read_text()
