"""Shared fixtures: the measured data folder (tests needing it skip with a reason when absent)."""
from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

DATA_DIR = Path(os.environ.get("CASSHIP_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


@pytest.fixture(scope="session")
def data_dir() -> Path:
    """``../shared/data`` next to the repository (or ``$CASSHIP_DATA``); skips when absent."""
    if not DATA_DIR.is_dir():
        pytest.skip(f"measured data folder {DATA_DIR} is absent (set CASSHIP_DATA to its location)")
    return DATA_DIR
