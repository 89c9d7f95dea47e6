"""Shared fixtures: every test in its own temporary folder; the measured data folder (tests needing it skip
with a reason when it is absent)."""
from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import pytest

from casship.io import DATA_ENV, data_dir as find_data_dir

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(autouse=True)
def _own_folder(tmp_path, monkeypatch):
    """Run each test in its own temporary folder (its ``tmp_path``).

    Nothing a test writes to a relative path lands in the checkout, and nothing it finds there (a
    ``fit.json`` left by following docs/getting-started.md) changes its outcome. Processes a test starts
    still import this checkout's casship, as they did when started from the checkout's root.
    """
    monkeypatch.chdir(tmp_path)
    path = os.environ.get("PYTHONPATH")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(ROOT), path]) if path else str(ROOT))


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """The measured-data folder by casship's rule (``$CASSHIP_DATA``, else ``../shared/data`` beside
    the checkout; :func:`casship.io.data_dir`); skips with the reason when there is none."""
    try:
        folder = find_data_dir()
    except FileNotFoundError as exc:
        pytest.skip(f"measured data: {exc}")
    if folder is None:
        pytest.skip(f"measured data folder absent (../shared/data beside the checkout; set {DATA_ENV} to its location)")
    return folder
