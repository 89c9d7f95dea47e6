"""Shared fixtures: the measured data folder (tests needing it skip with a reason when it is absent)."""
from __future__ import annotations

from pathlib import Path

import matplotlib
import pytest

from casship.io import DATA_ENV, data_dir as find_data_dir

matplotlib.use("Agg")


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
