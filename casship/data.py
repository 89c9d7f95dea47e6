"""Value objects: :class:`Gaussian`, :class:`Dataset` (time + named columns) and :class:`Trajectory`.

A :class:`Dataset` is the one container for records: measured data (inputs and measurements, NaN =
"not measured") and simulated trajectories alike. Columns are looked up by name; estimators and
fits pick the columns named like the model's inputs and outputs.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

__all__ = ["Gaussian", "Dataset", "Trajectory", "check_time", "as_cov"]


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
    t = np.asarray(t, dtype=float)
    if t.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array of time stamps, got shape {t.shape}")
    if t.size == 0:
        raise ValueError(f"{name}: no time stamps")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise ValueError(f"{name}: non-finite time stamp at row {bad[0]} ({t[bad[0]]})")
    step = np.diff(t)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = bad[0]
        raise ValueError(f"{name}: time stamps must increase strictly; row {k + 1} ({t[k + 1]}) "
                         f"is not after row {k} ({t[k]})")
    return t


def as_cov(value, n: int, name: str, names: Sequence[str] | None = None, allow_zero: bool = True) -> np.ndarray:
    """Turn a covariance given as scalar, vector (diagonal), matrix or name->variance mapping into
    an (n, n) symmetric positive (semi-)definite matrix, or raise naming ``name``.

    Parameters
    ----------
    value : float, array or mapping
        Scalar (times the identity), variances, matrix, or channel name -> variance.
    n : int
        Size.
    name : str
        What the covariance is (for messages).
    names : sequence of str, optional
        Channel names of a mapping.
    allow_zero : bool
        Accept a singular (positive semi-definite) matrix.
    """
    if isinstance(value, Mapping):
        if names is None:
            raise TypeError(f"{name}: a mapping needs channel names")
        unknown = set(value) - set(names)
        if unknown:
            raise ValueError(f"{name}: unknown channel name(s) {sorted(unknown)}; known: {list(names)}")
        missing = [c for c in names if c not in value]
        if missing:
            raise ValueError(f"{name}: no variance given for channel(s) {missing}")
        value = [value[c] for c in names]
    m = np.asarray(value, dtype=float)
    if m.ndim == 0:
        m = np.eye(n) * float(m)
    elif m.ndim == 1:
        if m.size != n:
            raise ValueError(f"{name}: expected {n} variances, got {m.size}")
        m = np.diag(m)
    if m.shape != (n, n):
        raise ValueError(f"{name}: expected shape ({n}, {n}), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError(f"{name}: contains non-finite entries")
    if not np.allclose(m, m.T, rtol=1e-10, atol=1e-12 * np.abs(m).max(initial=0.0)):   # relative to the scale
        raise ValueError(f"{name}: matrix is not symmetric")
    m = 0.5 * (m + m.T)
    if n:
        eig = np.linalg.eigvalsh(m)
        tol = 1e-12 * abs(eig).max()     # relative: variances of lat/lon in rad are ~1e-14
        if eig.min() < -tol:
            raise ValueError(f"{name}: not positive semi-definite (smallest eigenvalue {eig.min():.3g}); "
                             "variances must be non-negative")
        if not allow_zero and eig.min() <= tol:
            raise ValueError(f"{name}: must be positive definite (smallest eigenvalue {eig.min():.3g})")
    return m


@dataclass(frozen=True)
class Gaussian:
    """A Gaussian belief ``N(mean, cov)``.

    Parameters
    ----------
    mean : array_like, shape (n,)
    cov : array_like, shape (n, n), or (n,) variances, or scalar
    """

    mean: np.ndarray
    cov: np.ndarray

    def __post_init__(self):
        mean = np.asarray(self.mean, dtype=float).reshape(-1)
        if not np.all(np.isfinite(mean)):
            raise ValueError("Gaussian: mean contains non-finite entries")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", as_cov(self.cov, mean.size, "Gaussian covariance"))

    @property
    def std(self) -> np.ndarray:
        """Standard deviations (square roots of the variances)."""
        return np.sqrt(np.diag(self.cov))

    def sample(self, n: int, seed=None) -> np.ndarray:
        """``n`` samples as rows, from a seed or ``numpy.random.Generator``.

        Parameters
        ----------
        n : int
        seed : int or numpy.random.Generator, optional
        """
        rng = np.random.default_rng(seed)
        return rng.multivariate_normal(self.mean, self.cov, size=n, method="eigh")


class Dataset:
    """A record: strictly increasing time stamps and named, equally long columns.

    NaN in a measurement column means "not measured at this sample". Inputs must be finite
    wherever they are used (checked by the consumers, which name the offending column and row).

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
                raise ValueError(f"column name {name!r} must be a non-empty string")
            if name == "t" or name == "time":
                raise ValueError(f"column name {name!r} is reserved for the time stamps")
            arr = np.asarray(values, dtype=float).reshape(-1)
            if arr.size != self.t.size:
                raise ValueError(f"column {name!r} has {arr.size} rows, time has {self.t.size}")
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
            raise ValueError(f"unknown column {name!r}; columns: {list(self._columns)}") from None

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
                raise ValueError(f"{what} {names[col]!r} is not finite at row {row} (t = {self.t[row]:g} s); "
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
            raise ValueError(f"decimate: k must be an integer >= 1, got {k!r}")
        if k == 1:
            return self
        idx = np.arange(0, len(self), int(k))
        if idx.size < 2:
            raise ValueError(f"decimate: k = {k} leaves {idx.size} row(s) of {len(self)}")
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
            raise TypeError(f"resample: rate must be a number [Hz], got {rate!r}") from None
        if not np.isfinite(rate) or rate <= 0:
            raise ValueError(f"resample: rate must be a positive finite number [Hz], got {rate}")
        unknown = [n for n in hold if n not in self._columns]
        if unknown:
            raise ValueError(f"resample: unknown column(s) {unknown} in hold; columns: {list(self._columns)}")
        if len(self) > 1:
            own = 1.0 / float(np.median(self.dt))
            if rate < own * (1 - 1e-9):
                raise ValueError(f"resample: rate {rate:g} Hz is below the record's rate {own:g} Hz (median step "
                                 f"{1 / own:g} s); that would drop samples: use decimate() to thin a record")
        fine = self.t[0] + np.arange(0, int(np.floor((self.t[-1] - self.t[0]) * rate + 1e-9)) + 1) / rate
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
            raise ValueError(f"unknown column(s) {unknown} in hold; columns: {list(self._columns)}")
        times = np.asarray(times, dtype=float).reshape(-1)
        tol = 1e-9 * max(1.0, float(np.abs(self.t).max()))
        if times.size and (times.min() < self.t[0] - tol or times.max() > self.t[-1] + tol):
            raise ValueError(f"with_rows: times must lie in [{self.t[0]:g}, {self.t[-1]:g}] s")
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
            raise ValueError(f"no samples between t = {t0} and {t1} s")
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
        """A dataset from a pandas DataFrame with a time column.

        Parameters
        ----------
        frame : pandas.DataFrame
            Numeric columns.
        time : str
            Name of the time column.
        units : mapping, optional
            Column -> unit (default: ``frame.attrs["units"]``).

        Returns
        -------
        Dataset
        """
        if time not in frame.columns:
            raise ValueError(f"no time column {time!r}; columns: {list(frame.columns)}")
        from pandas.api.types import is_numeric_dtype

        non_numeric = [str(c) for c in frame.columns if not is_numeric_dtype(frame[c])]
        if non_numeric:
            raise ValueError(f"non-numeric column(s) {non_numeric}")
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
            The file (errors name it; see :func:`casship.io.csv.read_frame`).
        time : str, optional
            Name of the time column; ``t`` or ``time`` by default.
        rename : mapping, optional
            Old name -> new name (e.g. ``{"heading": "psi"}``).
        scale : mapping, optional
            New name -> factor applied after renaming (e.g. ``{"psi": np.pi / 180}``).
        """
        from .io.csv import read_frame

        frame = read_frame(path)
        if time is None:
            time = next((c for c in ("t", "time") if c in frame.columns), None)
            if time is None:
                raise ValueError(f"{path}: no 't' or 'time' column; columns: {list(frame.columns)}")
        if rename:
            unknown = set(rename) - set(frame.columns)
            if unknown:
                raise ValueError(f"{path}: cannot rename unknown column(s) {sorted(unknown)}")
            frame = frame.rename(columns=dict(rename))
        try:
            data = Dataset.from_pandas(frame, time=time)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
        for name, factor in (scale or {}).items():
            data = data.with_columns(**{name: data[name] * factor})
        data.meta["source"] = str(path)
        return data


class Trajectory(Dataset):
    """A simulated record: a :class:`Dataset` whose columns include a model's states, inputs, outputs.

    Parameters
    ----------
    t, columns, units, meta
        As for :class:`Dataset`.
    model_name : str
        The model simulated.
    state_names, input_names, output_names : sequence of str
        Which columns are the model's states, inputs and outputs.

    Attributes
    ----------
    model_name : str
    state_names, input_names, output_names : tuple of str
    """

    def __init__(self, t, columns, *, model_name: str, state_names, input_names, output_names,
                 units=None, meta=None):
        super().__init__(t, columns, units, meta)
        missing = [n for n in (*state_names, *input_names, *output_names) if n not in self._columns]
        if missing:
            raise ValueError(f"trajectory of {model_name!r} has no column(s) {missing}")
        self.model_name = model_name
        self.state_names = tuple(state_names)
        self.input_names = tuple(input_names)
        self.output_names = tuple(output_names)

    def _names(self) -> dict:
        return {"model_name": self.model_name, "state_names": list(self.state_names),
                "input_names": list(self.input_names), "output_names": list(self.output_names)}

    def slice(self, start: int | None = None, stop: int | None = None) -> "Trajectory":
        """Rows ``start:stop`` as a Trajectory (names kept).

        Parameters
        ----------
        start, stop : int, optional
            Row indices.

        Returns
        -------
        Trajectory
        """
        return Trajectory.from_dataset(super().slice(start, stop), self._names())

    def _like(self, data: Dataset) -> "Trajectory":
        return Trajectory.from_dataset(data, self._names())

    # -- I/O with the names kept -----------------------------------------------------------------
    def to_pandas(self):
        """A DataFrame with ``t`` and all columns; the model and variable names go to ``frame.attrs``."""
        frame = super().to_pandas()
        frame.attrs.update(self._names())
        return frame

    @classmethod
    def from_dataset(cls, data: Dataset, model) -> "Trajectory":
        """View a record with a column for every state and input of ``model`` as a Trajectory.

        ``model`` is a :class:`~casship.Model` or a mapping with ``state_names``, ``input_names``,
        ``output_names`` (and optionally ``model_name``), e.g. the ``attrs`` of :meth:`to_pandas`.

        Parameters
        ----------
        data : Dataset
            The record.
        model : Model or mapping
            See above.

        Returns
        -------
        Trajectory
        """
        get = (lambda k: model.get(k, ())) if isinstance(model, Mapping) else (lambda k: getattr(model, k))
        names = {k: tuple(get(k)) for k in ("state_names", "input_names", "output_names")}
        name = model.get("model_name", "") if isinstance(model, Mapping) else model.name
        missing = [n for n in (*names["state_names"], *names["input_names"]) if n not in data]
        if missing:
            raise ValueError(f"record has no column(s) {missing} for the states/inputs of model {name!r}")
        outputs = tuple(n for n in names["output_names"] if n in data)
        return cls(data.t, {n: data[n] for n in data.names}, model_name=name, state_names=names["state_names"],
                   input_names=names["input_names"], output_names=outputs, units=data.units, meta=data.meta)

    @classmethod
    def from_pandas(cls, frame, time: str = "t", units: Mapping[str, str] | None = None,
                    model=None) -> "Trajectory":
        """Inverse of :meth:`to_pandas`; names from ``model`` or else from ``frame.attrs``.

        Parameters
        ----------
        frame : pandas.DataFrame
            As written by :meth:`to_pandas`.
        time : str
            Time column.
        units : mapping, optional
            Column -> unit.
        model : Model, optional
            Names of states, inputs and outputs (default: ``frame.attrs``).

        Returns
        -------
        Trajectory
        """
        source = model if model is not None else frame.attrs
        if model is None and "state_names" not in frame.attrs:
            raise ValueError("Trajectory.from_pandas: the frame carries no state names; pass model=")
        return cls.from_dataset(Dataset.from_pandas(frame, time, units), source)

    @classmethod
    def from_csv(cls, path, model=None, time: str | None = None, rename: Mapping[str, str] | None = None,
                 scale: Mapping[str, float] | None = None) -> "Trajectory":
        """Read a CSV written by :meth:`Dataset.to_csv`; ``model`` names the states, inputs and outputs.

        Parameters
        ----------
        path : str or Path
            The file.
        model : Model or mapping
            Names of states, inputs and outputs.
        time, rename, scale
            As for :meth:`Dataset.from_csv`.

        Returns
        -------
        Trajectory
        """
        if model is None:
            raise ValueError("Trajectory.from_csv needs model= (a CSV file does not store the state names)")
        return cls.from_dataset(Dataset.from_csv(path, time=time, rename=rename, scale=scale), model)

    @property
    def x(self) -> np.ndarray:
        """States as an (N, nx) array."""
        return self.matrix(self.state_names)

    @property
    def u(self) -> np.ndarray:
        """Inputs as an (N, nu) array.

        Returns
        -------
        numpy.ndarray
        """
        return self.matrix(self.input_names)

    @property
    def y(self) -> np.ndarray:
        """Outputs as an (N, ny) array.

        Returns
        -------
        numpy.ndarray
        """
        return self.matrix(self.output_names)
