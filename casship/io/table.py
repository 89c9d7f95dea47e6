"""Whitespace-separated numeric tables below a title block (the free-running trial files)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import InputError

__all__ = ["read_numeric_rows"]


def read_numeric_rows(path: Path, lines: Sequence[str], first: int, columns: Sequence[str]) -> np.ndarray:
    """The data rows of a trial file as a float array, every bad line named.

    Parameters
    ----------
    path : Path
        The file (for messages).
    lines : sequence of str
        All lines of the file.
    first : int
        Index of the first data line (the lines before are the title block).
    columns : sequence of str
        Column names, in file order (an empty name is a column whose meaning is not established).

    Returns
    -------
    array (rows, len(columns))

    Raises
    ------
    ValueError
        A line with the wrong number of fields or a non-numeric field (naming the line), fewer than
        three rows, or a non-finite value (naming the column and row).
    """
    rows = []
    for number, line in enumerate(lines[first:], start=first + 1):
        fields = line.split()
        if not fields:
            continue
        if len(fields) != len(columns):
            raise InputError(f"{path}: line {number} has {len(fields)} fields, expected {len(columns)} "
                             f"({' '.join(c or '?' for c in columns)})")
        try:
            rows.append([float(f) for f in fields])
        except ValueError:
            raise InputError(f"{path}: line {number} is not numeric: {line!r}") from None
    if len(rows) < 3:
        raise InputError(f"{path}: {len(rows)} data row(s); a record needs at least 3")
    data = np.asarray(rows)
    if not np.all(np.isfinite(data)):
        row, col = np.argwhere(~np.isfinite(data))[0]
        raise InputError(f"{path}: non-finite value in column {col} ({columns[col] or 'unestablished'}) "
                         f"at data row {row}")
    return data
