"""Records: :class:`Dataset` (time stamps + named columns), :func:`check_time` and :func:`read_frame`.

The Gaussian belief lives in :mod:`casship.gaussian`, simulated records in :mod:`casship.trajectory`.

A :class:`Dataset` is the one container for records: measured data (inputs and measurements, NaN =
"not measured") and simulated trajectories alike. Columns are looked up by name; estimators and
fits pick the columns named like the model's inputs and outputs.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from .errors import InputError, InputTypeError

__all__ = ["Dataset", "check_time", "check_rows", "MAX_ROWS", "read_frame"]


#: Largest number of rows casship creates in one record (a time grid, a resampled record): 20 million
#: rows are 160 MB per column; more is refused before memory runs out.
MAX_ROWS = 20_000_000


def check_rows(n: float, what: str) -> int:
    """``n`` as the number of rows of a record about to be created, or ``InputError`` above :data:`MAX_ROWS`.

    Parameters
    ----------
    n : float
        Rows (e.g. a duration divided by a step).
    what : str
        What would be created, for the message (e.g. ``"simulate: 1e+09 s at 0.5 s"``).

    Returns
    -------
    int
    """

    if np.isnan(n):
        raise InputError(f"{what}: the number of rows is not a number (a NaN duration or step)")
    if not n <= MAX_ROWS:
        raise InputError(f"{what} would make {n:.3g} rows, more than casship creates in one record "
                         f"({MAX_ROWS:.3g}, casship.data.MAX_ROWS); use a longer step or a shorter span")
    return int(n)


def check_time(t, name: str = "time") -> np.ndarray:
    """Validate a time vector: 1-D, finite, strictly increasing. Returns it as float array.

    Parameters
    ----------
    t : array_like
        Time stamps [s].
    name : str
        Name used in error messages.

    Returns
    -------
    numpy.ndarray
    """
    if np.ma.isMaskedArray(t) and np.ma.getmaskarray(t).any():
        raise InputError(f"{name}: masked time stamp at row {int(np.flatnonzero(np.ma.getmaskarray(t))[0])}; every "
                         "row needs its time")
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise InputError(f"{name}: expected a 1-D array of time stamps, got shape {t.shape}")
    if t.size == 0:
        raise InputError(f"{name}: no time stamps")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise InputError(f"{name}: non-finite time stamp at row {bad[0]} ({t[bad[0]]})")
    step = np.diff(t)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = bad[0]
        raise InputError(f"{name}: time stamps must increase strictly; row {k + 1} ({t[k + 1]}) "
                         f"is not after row {k} ({t[k]})")
    return t


class Dataset:
    """A record: strictly increasing time stamps and named, equally long columns.

    NaN in a measurement column means "not measured at this sample" (so does a masked entry of a
    masked array). Inputs must be finite wherever they are used (checked by the consumers, which
    name the offending column and row).

    Parameters
    ----------
    t : array_like, shape (N,)
        Time stamps [s].
    columns : mapping str -> array_like, shape (N,)
    units : mapping str -> str, optional
    meta : mapping, optional
        Free-form description (source, vessel, ...).
    """

    def __init__(self, t, columns: Mapping[str, Iterable[float]], units: Mapping[str, str] | None = None,
                 meta: Mapping | None = None):
        self.t = check_time(t)
        self.t.setflags(write=False)
        cols = {}
        for name, values in columns.items():
            if not isinstance(name, str) or not name:
                raise InputError(f"column name {name!r} must be a non-empty string")
            if name == "t" or name == "time":
                raise InputError(f"column name {name!r} is reserved for the time stamps")
            if np.ma.isMaskedArray(values):      # masked = not measured (NaN)
                values = np.ma.filled(np.ma.asarray(values, dtype=float), np.nan)
            arr = np.asarray(values, dtype=float).reshape(-1)
            if arr.size != self.t.size:
                raise InputError(f"column {name!r} has {arr.size} rows, time has {self.t.size}")
            arr.setflags(write=False)
            cols[name] = arr
        self._columns = cols
        self.units = dict(units or {})
        self.meta = dict(meta or {})

    # -- access -----------------------------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Column names (the time column aside).

        Returns
        -------
        tuple of str
        """
        return tuple(self._columns)

    def __len__(self) -> int:
        return self.t.size

    def __contains__(self, name: str) -> bool:
        return name in self._columns

    def __getitem__(self, name: str) -> np.ndarray:
        if name in ("t", "time"):
            return self.t
        try:
            return self._columns[name]
        except KeyError:
            raise InputError(f"unknown column {name!r}; columns: {list(self._columns)}") from None

    def matrix(self, names: Sequence[str], *, finite: bool = False, what: str = "column") -> np.ndarray:
        """Stack named columns into an (N, len(names)) array; ``finite=True`` rejects NaN/inf.

        Parameters
        ----------
        names : sequence of str
            Columns.
        finite : bool
            Reject NaN and inf (naming column and row).
        what : str
            What the columns are, for the message (e.g. ``"input"``).

        Returns
        -------
        numpy.ndarray
        """
        if not names:
            return np.zeros((len(self), 0))
        out = np.column_stack([self[n] for n in names])
        if finite:
            bad = ~np.isfinite(out)
            if bad.any():
                row, col = np.argwhere(bad)[0]
                raise InputError(f"{what} {names[col]!r} is not finite at row {row} (t = {self.t[row]:g} s); "
                                 "NaN is only allowed in measurements")
        return out

    @property
    def dt(self) -> np.ndarray:
        """Time steps ``diff(t)`` [s].

        Returns
        -------
        numpy.ndarray
        """
        return np.diff(self.t)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(N={len(self)}, t=[{self.t[0]:g}, {self.t[-1]:g}] s, "
                f"columns={list(self._columns)})")

    # -- derived datasets -------------------------------------------------------------------------
    def with_columns(self, **columns) -> "Dataset":
        """A new dataset with columns added or replaced.

        Parameters
        ----------
        **columns
            Column name -> values (one per row).

        Returns
        -------
        Dataset
        """
        merged = dict(self._columns)
        merged.update(columns)
        return Dataset(self.t, merged, self.units, self.meta)

    def _like(self, data: "Dataset") -> "Dataset":
        """``data`` as this dataset's type (a Trajectory keeps its names)."""
        return data

    def decimate(self, k: int) -> "Dataset":
        """Every ``k``-th row, starting with the first (a Trajectory stays a Trajectory).

        Parameters
        ----------
        k : int
            Decimation factor (``1`` returns the record unchanged).

        Returns
        -------
        Dataset
            ``meta["decimated"]`` records the overall factor.

        Raises
        ------
        ValueError
            ``k`` is not an integer >= 1, or leaves fewer than two rows.

        Examples
        --------
        >>> import numpy as np
        >>> d = Dataset(np.arange(10.0), {"psi": np.arange(10.0)})
        >>> d.decimate(3).t
        array([0., 3., 6., 9.])
        """
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
            raise InputError(f"decimate: k must be an integer >= 1, got {k!r}")
        if k == 1:
            return self
        idx = np.arange(0, len(self), int(k))
        if idx.size < 2:
            raise InputError(f"decimate: k = {k} leaves {idx.size} row(s) of {len(self)}")
        meta = {**self.meta, "decimated": int(k) * int(self.meta.get("decimated", 1))}
        data = Dataset(self.t[idx], {n: v[idx] for n, v in self._columns.items()}, self.units, meta)
        return self._like(data)

    def resample(self, rate: float, *, hold: Sequence[str] = ()) -> "Dataset":
        """Insert rows so that the record has a row at least every ``1 / rate`` seconds.

        The new rows lie on the grid ``t[0] + k / rate``; every original row is kept at its own time
        stamp. Columns named in ``hold`` (inputs) keep their last value on the new rows (zero-order
        hold); every other column is NaN there ("not measured"), so a filter predicts through them.
        Use it to run an estimator faster than the sensors; use :meth:`decimate` to thin a record.

        Parameters
        ----------
        rate : float
            Rate of the grid [Hz]; not below the record's own rate (``1 / median(dt)``).
        hold : sequence of str
            Columns held between samples (e.g. the model's inputs).

        Returns
        -------
        Dataset

        Raises
        ------
        ValueError
            Non-positive or non-finite rate, a rate below the record's rate (that would drop
            samples), or an unknown column in ``hold``.

        Examples
        --------
        >>> import numpy as np
        >>> d = Dataset([0.0, 1.0], {"delta": [0.1, 0.2], "psi": [0.0, 0.5]})
        >>> r = d.resample(2.0, hold=["delta"])
        >>> r.t, r["delta"], r["psi"]
        (array([0. , 0.5, 1. ]), array([0.1, 0.1, 0.2]), array([0. , nan, 0.5]))
        """
        try:
            rate = float(rate)
        except (TypeError, ValueError):
            raise InputTypeError(f"resample: rate must be a number [Hz], got {rate!r}") from None
        if not np.isfinite(rate) or rate <= 0:
            raise InputError(f"resample: rate must be a positive finite number [Hz], got {rate}")
        unknown = [n for n in hold if n not in self._columns]
        if unknown:
            raise InputError(f"resample: unknown column(s) {unknown} in hold; columns: {list(self._columns)}")
        if len(self) > 1:
            own = 1.0 / float(np.median(self.dt))
            if rate < own * (1 - 1e-9):
                raise InputError(f"resample: rate {rate:g} Hz is below the record's rate {own:g} Hz (median step "
                                 f"{1 / own:g} s); that would drop samples: use decimate() to thin a record")
        rows = check_rows(np.floor((self.t[-1] - self.t[0]) * rate + 1e-9) + 1,
                          f"resample: {self.t[-1] - self.t[0]:g} s at {rate:g} Hz")
        fine = self.t[0] + np.arange(0, rows) / rate
        data = self.with_rows(fine, hold=hold)
        data.meta["resampled_hz"] = rate
        return data

    def with_rows(self, times, *, hold: Sequence[str] = ()) -> "Dataset":
        """The record with rows added at ``times`` (stamps equal to an existing row add nothing).

        On a new row the ``hold`` columns keep the value of the row before (zero-order hold) and
        every other column is NaN ("not measured"); the original rows are kept as they are.

        Parameters
        ----------
        times : array_like
            Time stamps [s] within ``[t[0], t[-1]]``.
        hold : sequence of str
            Columns held from the previous row (e.g. the model's inputs).

        Returns
        -------
        Dataset

        Raises
        ------
        ValueError
            An unknown column in ``hold``, or a time outside the record.
        """
        unknown = [n for n in hold if n not in self._columns]
        if unknown:
            raise InputError(f"unknown column(s) {unknown} in hold; columns: {list(self._columns)}")
        times = np.asarray(times, dtype=float).reshape(-1)
        tol = 1e-9 * max(1.0, float(np.abs(self.t).max()))
        if times.size and (times.min() < self.t[0] - tol or times.max() > self.t[-1] + tol):
            raise InputError(f"with_rows: times must lie in [{self.t[0]:g}, {self.t[-1]:g}] s")
        t = np.union1d(times, self.t)
        t = t[np.concatenate([[True], np.diff(t) > tol])]
        idx = np.searchsorted(self.t, t + tol, side="right") - 1
        exact = np.abs(self.t[idx] - t) <= tol
        t = np.where(exact, self.t[idx], t)                       # original stamps kept exactly
        cols = {name: (v[idx] if name in hold else np.where(exact, v[idx], np.nan))
                for name, v in self._columns.items()}
        return Dataset(t, cols, self.units, dict(self.meta))

    def select(self, names: Sequence[str]) -> "Dataset":
        """A dataset with only the named columns.

        Parameters
        ----------
        names : sequence of str
            Columns to keep.

        Returns
        -------
        Dataset
        """
        return Dataset(self.t, {n: self[n] for n in names}, {n: self.units.get(n, "") for n in names}, self.meta)

    def slice(self, start: int | None = None, stop: int | None = None) -> "Dataset":
        """Rows ``start:stop``.

        Parameters
        ----------
        start, stop : int, optional
            Row indices as in ``rows[start:stop]``.

        Returns
        -------
        Dataset
        """
        sl = slice(start, stop)
        return Dataset(self.t[sl], {n: v[sl] for n, v in self._columns.items()}, self.units, self.meta)

    def between(self, t0: float, t1: float) -> "Dataset":
        """Rows with ``t0 <= t <= t1``.

        Parameters
        ----------
        t0, t1 : float
            Time window [s].

        Returns
        -------
        Dataset
        """
        idx = np.flatnonzero((self.t >= t0) & (self.t <= t1))
        if idx.size == 0:
            raise InputError(f"no samples between t = {t0} and {t1} s")
        return self.slice(idx[0], idx[-1] + 1)

    # -- I/O -----------------------------------------------------------------------------------------
    def to_pandas(self):
        """The record as a pandas DataFrame.

        Returns
        -------
        pandas.DataFrame
            With a column ``t``; the units in ``frame.attrs["units"]``.
        """
        import pandas as pd

        frame = pd.DataFrame({"t": self.t, **self._columns})
        frame.attrs["units"] = dict(self.units)
        return frame

    @classmethod
    def from_pandas(cls, frame, time: str = "t", units: Mapping[str, str] | None = None) -> "Dataset":
        """A dataset from a pandas DataFrame with a time column (or an index of that name).

        Parameters
        ----------
        frame : pandas.DataFrame
            Numeric columns.
        time : str
            Name of the time column, or of the frame's index (``frame.set_index("t")``) [s].
        units : mapping, optional
            Column -> unit (default: ``frame.attrs["units"]``).

        Returns
        -------
        Dataset
        """
        twice = sorted({str(c) for c in frame.columns if list(frame.columns).count(c) > 1})
        if twice:
            raise InputError(f"column(s) {twice} appear more than once in the frame; which one is meant cannot be told")
        if time not in frame.columns and frame.index.name == time:
            frame = frame.reset_index()
        if time not in frame.columns:
            raise InputError(f"no time column {time!r} (nor an index of that name); columns: {list(frame.columns)}, "
                             f"index: {frame.index.name!r}; give time=NAME")
        from pandas.api.types import is_numeric_dtype

        non_numeric = [str(c) for c in frame.columns if not is_numeric_dtype(frame[c])]
        if non_numeric:
            raise InputError(f"non-numeric column(s) {non_numeric}")
        cols = {str(c): frame[c].to_numpy(dtype=float) for c in frame.columns if c != time}
        return cls(frame[time].to_numpy(dtype=float), cols, units or frame.attrs.get("units"))

    def to_csv(self, path) -> Path:
        """Write ``t`` and all columns as CSV with a header row.

        Parameters
        ----------
        path : str or Path
            The file.

        Returns
        -------
        Path
        """
        path = Path(path)
        header = ",".join(["t", *self._columns])
        data = np.column_stack([self.t, *self._columns.values()])
        np.savetxt(path, data, delimiter=",", header=header, comments="", fmt="%.17g")
        return path

    @classmethod
    def from_csv(cls, path, time: str | None = None, rename: Mapping[str, str] | None = None,
                 scale: Mapping[str, float] | None = None) -> "Dataset":
        """Read a CSV with a header row of column names.

        Parameters
        ----------
        path : str or Path
            The file (errors name it; see :func:`read_frame`).
        time : str, optional
            Name of the time column; ``t`` or ``time`` by default.
        rename : mapping, optional
            Old name -> new name (e.g. ``{"heading": "psi"}``).
        scale : mapping, optional
            New name -> factor applied after renaming (e.g. ``{"psi": np.pi / 180}``).
        """
        frame = read_frame(path)
        if time is None:
            time = next((c for c in ("t", "time") if c in frame.columns), None)
            if time is None:
                raise InputError(f"{path}: no 't' or 'time' column; columns: {list(frame.columns)}")
        if rename:
            unknown = set(rename) - set(frame.columns)
            if unknown:
                raise InputError(f"{path}: cannot rename unknown column(s) {sorted(unknown)}")
            frame = frame.rename(columns=dict(rename))
        try:
            data = Dataset.from_pandas(frame, time=time)
        except ValueError as exc:
            raise InputError(f"{path}: {exc}") from None
        for name, factor in (scale or {}).items():
            data = data.with_columns(**{name: data[name] * factor})
        data.meta["source"] = str(path)
        return data


def read_frame(path, **read_options):
    """A CSV file with a header row as a pandas DataFrame, with errors that name the file.

    Parameters
    ----------
    path : str, Path or file object
        The CSV file.
    **read_options
        Passed to :func:`pandas.read_csv` (e.g. ``sep=";"``).

    Returns
    -------
    pandas.DataFrame
        At least one data row.

    Raises
    ------
    FileNotFoundError, IsADirectoryError
        The file does not exist or is a folder.
    ValueError
        An empty file, a file with a header but no data rows, or one pandas cannot parse.
    """
    import pandas as pd

    name = str(path) if isinstance(path, (str, Path)) else "<csv>"
    if isinstance(path, (str, Path)):
        if Path(path).is_dir():
            raise IsADirectoryError(f"{name}: is a folder, not a CSV file")
        if not Path(path).is_file():
            raise FileNotFoundError(f"{name}: no such file")
    try:
        frame = pd.read_csv(path, **read_options)
    except pd.errors.EmptyDataError:
        raise InputError(f"{name}: empty file (no header row with column names)") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise InputError(f"{name}: not a readable CSV file ({str(exc).splitlines()[0]})") from None
    if frame.shape[0] == 0:
        raise InputError(f"{name}: no data rows below the header {list(frame.columns)}")
    if isinstance(path, (str, Path)) and not read_options:
        _refuse_short_rows(Path(path), frame.shape[1])
    header = _header(path, read_options)
    twice = sorted({c for c in header if header.count(c) > 1})
    if twice:
        raise InputError(f"{name}: column(s) {twice} appear more than once in the header; which one is meant "
                         "cannot be told: rename or remove the copies")
    return frame


def _refuse_short_rows(path: Path, width: int) -> None:
    """A row with fewer fields than the header (a truncated line) is an error: pandas would fill the
    missing fields with NaN, which a measured column reads as "not measured"."""
    import csv

    with path.open(newline="") as f:
        for number, row in enumerate(csv.reader(f), start=1):
            if row and len(row) < width:
                raise InputError(f"{path}: line {number} has {len(row)} field(s), the header {width}: a truncated "
                                 "row (write an empty field, a,,c, where a value is missing)")


def _header(path, read_options) -> list[str]:
    """The header row as written (pandas renames a repeated name ``psi`` to ``psi.1``)."""
    import pandas as pd

    options = {k: v for k, v in read_options.items() if k in ("sep", "delimiter", "comment", "skiprows", "encoding")}
    if not isinstance(path, (str, Path)):
        if not hasattr(path, "seek"):
            return []
        path.seek(0)
    row = pd.read_csv(path, header=None, nrows=1, dtype=str, keep_default_na=False, **options)
    return [str(v).strip() for v in row.iloc[0].tolist()] if len(row) else []
