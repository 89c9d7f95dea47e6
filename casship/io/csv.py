"""CSV files and pandas frames with named columns and units into a :class:`~casship.Dataset`.

``columns`` maps each casship name to ``"source_column:unit"``; values are converted to SI units
and radians on the way in (degrees only at the edge), e.g.::

    data = read_csv("trial.csv", time="time:s",
                    columns={"psi": "heading:deg", "U": "speed:kn", "n": "rev:rpm", "delta": "rudder:deg"})

Unknown source columns or units raise ``ValueError`` naming them; NaN in the time column is an
error, NaN elsewhere means "not measured". Angles (``rad`` after conversion from ``deg``) can be
wrapped to (-pi, pi] with ``wrap=[...]``; geodetic columns become a local North-East frame with
``latlon=("lat", "lon")``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..angles import wrap as _wrap
from ..data import Dataset, read_frame
from .geodesy import geodetic_to_ne
from ..errors import InputError, InputTypeError

__all__ = ["read_csv", "from_frame", "UNITS"]

# unit -> (SI unit, factor, offset): value_SI = factor * value + offset
UNITS: dict[str, tuple[str, float, float]] = {
    "": ("", 1.0, 0.0), "-": ("", 1.0, 0.0), "1": ("", 1.0, 0.0),
    "m": ("m", 1.0, 0.0), "cm": ("m", 0.01, 0.0), "mm": ("m", 1e-3, 0.0), "km": ("m", 1e3, 0.0),
    "nmi": ("m", 1852.0, 0.0),
    "s": ("s", 1.0, 0.0), "ms": ("s", 1e-3, 0.0), "min": ("s", 60.0, 0.0), "h": ("s", 3600.0, 0.0),
    "rad": ("rad", 1.0, 0.0), "deg": ("rad", np.pi / 180.0, 0.0),
    "m/s": ("m/s", 1.0, 0.0), "kn": ("m/s", 1852.0 / 3600.0, 0.0), "knot": ("m/s", 1852.0 / 3600.0, 0.0),
    "km/h": ("m/s", 1.0 / 3.6, 0.0),
    "rad/s": ("rad/s", 1.0, 0.0), "deg/s": ("rad/s", np.pi / 180.0, 0.0), "deg/min": ("rad/s", np.pi / 10800.0, 0.0),
    "m/s^2": ("m/s^2", 1.0, 0.0), "rad/s^2": ("rad/s^2", 1.0, 0.0), "deg/s^2": ("rad/s^2", np.pi / 180.0, 0.0),
    "Hz": ("1/s", 1.0, 0.0), "rps": ("1/s", 1.0, 0.0), "1/s": ("1/s", 1.0, 0.0), "rpm": ("1/s", 1.0 / 60.0, 0.0),
    "N": ("N", 1.0, 0.0), "kN": ("N", 1e3, 0.0), "Nm": ("Nm", 1.0, 0.0), "kNm": ("Nm", 1e3, 0.0),
    "kg": ("kg", 1.0, 0.0), "t": ("kg", 1e3, 0.0),
    "degC": ("K", 1.0, 273.15), "K": ("K", 1.0, 0.0), "%": ("", 0.01, 0.0),
}


def _spec(spec: str, what: str) -> tuple[str, str]:
    if not isinstance(spec, str) or not spec:
        raise InputTypeError(f"{what}: expected 'source_column' or 'source_column:unit', got {spec!r}")
    source, sep, unit = spec.rpartition(":")
    if not sep:
        source, unit = spec, ""
    if unit not in UNITS:
        raise InputError(f"{what}: unknown unit {unit!r}; known units: {sorted(u for u in UNITS if u)}")
    return source, unit


def from_frame(frame, columns: Mapping[str, str] | None = None, *, time: str = "t:s",
               wrap: Sequence[str] = (), latlon: tuple[str, str] | None = None,
               origin_deg: tuple[float, float] | None = None, name: str = "<frame>") -> Dataset:
    """A :class:`~casship.Dataset` from a pandas DataFrame with named columns and units.

    Parameters
    ----------
    frame : pandas.DataFrame
    columns : mapping new name -> ``"source_column:unit"``, optional
        The columns to keep, renamed and converted to SI (``deg`` -> rad, ``kn`` -> m/s, ``rpm``
        -> 1/s, ...; see :data:`UNITS`). A spec without ``:unit`` is taken as is. By default every
        numeric column except the time column is kept unchanged.
    time : str
        ``"source_column:unit"`` of the time stamps (``"t:s"`` by default); the result's time
        starts where the file's does (no shift).
    wrap : sequence of str
        New names of angle columns to wrap to (-pi, pi] after conversion.
    latlon : (lat, lon), optional
        New names of geodetic columns (converted to rad via their units); adds ``x_n``, ``y_n``
        [m], local North-East on WGS-84 about ``origin_deg`` (the first finite position by default).
    origin_deg : (lat, lon), optional
        Origin of the local North-East frame [deg] (the first finite position by default).
    name : str
        Source name used in error messages and ``meta["source"]``.

    Returns
    -------
    Dataset
    """
    t_source, t_unit = _spec(time, "time")
    if t_source not in frame.columns:
        raise InputError(f"{name}: no time column {t_source!r}; columns: {list(frame.columns)}")
    if UNITS[t_unit][0] != "s":
        raise InputError(f"{name}: time unit {t_unit!r} is not a unit of time")
    if columns is None:
        columns = {str(c): str(c) for c in frame.columns
                   if c != t_source and np.issubdtype(frame[c].dtype, np.number)}
    out, units = {}, {}
    for new, spec in columns.items():
        source, unit = _spec(spec, f"{name}: column {new!r}")
        if source not in frame.columns:
            raise InputError(f"{name}: column {new!r} refers to unknown source column {source!r}; "
                             f"columns: {list(frame.columns)}")
        try:
            values = frame[source].to_numpy(dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{name}: source column {source!r} is not numeric") from None
        si, factor, offset = UNITS[unit]
        out[new] = values * factor + offset
        units[new] = si
    for c in wrap:
        if c not in out:
            raise InputError(f"{name}: cannot wrap unknown column {c!r}; columns: {list(out)}")
        if units[c] != "rad":
            raise InputError(f"{name}: column {c!r} is in {units[c]!r}, not an angle in rad")
        out[c] = _wrap(out[c])
    meta = {"source": name}
    if latlon is not None:
        lat_name, lon_name = latlon
        for c in latlon:
            if c not in out:
                raise InputError(f"{name}: latlon column {c!r} is not among the columns {list(out)}")
            if units[c] != "rad":
                raise InputError(f"{name}: latlon column {c!r} must be an angle (give ':deg' or ':rad')")
        lat, lon = out[lat_name], out[lon_name]
        if origin_deg is None:
            ok = np.flatnonzero(np.isfinite(lat) & np.isfinite(lon))
            if not ok.size:
                raise InputError(f"{name}: no finite position to take as origin")
            lat0, lon0 = lat[ok[0]], lon[ok[0]]
        else:
            lat0, lon0 = np.radians(origin_deg[0]), np.radians(origin_deg[1])
        out["x_n"], out["y_n"] = geodetic_to_ne(lat, lon, lat0, lon0)
        units["x_n"] = units["y_n"] = "m"
        meta["origin_deg"] = (float(np.degrees(lat0)), float(np.degrees(lon0)))
    try:
        t = frame[t_source].to_numpy(dtype=float) * UNITS[t_unit][1]
    except (TypeError, ValueError):
        raise InputError(f"{name}: time column {t_source!r} is not numeric") from None
    try:
        return Dataset(t, out, units, meta)
    except ValueError as exc:
        raise InputError(f"{name}: {exc}") from None


def read_csv(path, columns: Mapping[str, str] | None = None, *, time: str = "t:s", wrap: Sequence[str] = (),
             latlon: tuple[str, str] | None = None, origin_deg: tuple[float, float] | None = None,
             **read_options) -> Dataset:
    """Read a CSV file with a header row into a :class:`~casship.Dataset`, converting units to SI.

    Parameters are those of :func:`from_frame`; ``read_options`` go to :func:`pandas.read_csv`
    (e.g. ``sep=";"``). :meth:`casship.Dataset.from_csv` covers files that are already in SI
    units with casship's names; this reader is for everything else.

    Parameters
    ----------
    path : str, Path or file object
        The CSV file (header row).
    columns, time, wrap, latlon, origin_deg
        As for :func:`from_frame`.
    **read_options
        Passed to :func:`pandas.read_csv`.

    Returns
    -------
    Dataset

    Examples
    --------
    >>> import io
    >>> text = "time,heading,speed\\n0,90,10\\n1,91,10\\n"
    >>> data = read_csv(io.StringIO(text), {"psi": "heading:deg", "U": "speed:kn"}, time="time:s")
    >>> round(float(data["psi"][0]), 4), round(float(data["U"][0]), 4)
    (1.5708, 5.1444)
    """
    frame = read_frame(path, **read_options)
    name = str(path) if isinstance(path, (str, Path)) else "<csv>"
    return from_frame(frame, columns, time=time, wrap=wrap, latlon=latlon, origin_deg=origin_deg, name=name)
