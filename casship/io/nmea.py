"""NMEA 0183 logs (GGA, RMC, VTG, HDT, HDG) into a :class:`~casship.Dataset`.

Sentences are framed and checksummed by :mod:`pynmea2`; every field casship uses is then
converted strictly (a field that is not a number, a time or a hemisphere letter is an error
naming the line), because ``pynmea2`` passes many malformed fields through unchanged.

One row of the result is one *epoch*: a time stamp carried by a GGA or RMC sentence. Sentences
without a time stamp (VTG, HDT, HDG) belong to the epoch of the last time-stamped sentence
before them. Time stamps are seconds of day; a jump back by more than 12 hours is a midnight
rollover (the day is counted on), a smaller jump back is an error.

Columns (SI units, angles in radians wrapped to (-pi, pi]; NaN = not measured in that epoch):

============ ======= =========================================================
``lat, lon`` rad     geodetic position (GGA with a fix, RMC with status A)
``x_n, y_n`` m       local North/East on WGS-84 about ``origin_deg``
``alt``      m       altitude above mean sea level (GGA)
``sog``      m/s     speed over ground (RMC, VTG)
``cog``      rad     course over ground, true (RMC, VTG)
``psi``      rad     true heading (HDT; HDG when it gives the magnetic variation)
``psi_mag``  rad     magnetic heading (HDG without variation, deviation applied)
``fix_quality, num_sats, hdop``  GGA fix quality indicator, satellites, HDOP
============ ======= =========================================================

Only columns with at least one value are returned.
"""
from __future__ import annotations

import io
import re
import warnings
from dataclasses import dataclass, field
from datetime import date as _date, datetime, timedelta, timezone
from pathlib import Path
from typing import Iterable

import numpy as np

from ..angles import wrap
from ..data import Dataset
from ..errors import InputError
from .geodesy import geodetic_to_ne

__all__ = ["read_nmea", "NMEAError", "SUPPORTED_SENTENCES"]

SUPPORTED_SENTENCES = ("GGA", "RMC", "VTG", "HDT", "HDG")
KNOT = 1852.0 / 3600.0
_DAY = 86400.0

_UNITS = {"lat": "rad", "lon": "rad", "x_n": "m", "y_n": "m", "alt": "m", "sog": "m/s", "cog": "rad",
          "psi": "rad", "psi_mag": "rad", "fix_quality": "", "num_sats": "", "hdop": ""}
_ORDER = tuple(_UNITS)

_TIME = re.compile(r"^(\d{2})(\d{2})(\d{2}(?:\.\d+)?)$")
_LAT = re.compile(r"^(\d{2})(\d{2}(?:\.\d*)?)$")
_LON = re.compile(r"^(\d{3})(\d{2}(?:\.\d*)?)$")
_DATE = re.compile(r"^(\d{2})(\d{2})(\d{2})$")


class NMEAError(InputError):
    """A malformed NMEA line, with its 1-based ``line_number`` and the ``line`` text.

    Parameters
    ----------
    source : str
        File name (or ``<string>``, ``<stream>``).
    line_number : int
        1-based line number.
    line : str
        The line.
    reason : str
        What is wrong with it.
    """

    def __init__(self, source: str, line_number: int, line: str, reason: str):
        self.source, self.line_number, self.line, self.reason = source, line_number, line, reason
        super().__init__(f"{source}, line {line_number}: {reason}: {line[:120]!r}")


class _Bad(Exception):
    """Internal: a field-level problem; becomes an :class:`NMEAError` with the line number."""


# -- strict field conversion ---------------------------------------------------------------------------
def _num(value: str, name: str, empty_ok: bool = True) -> float:
    if value == "":
        if empty_ok:
            return np.nan
        raise _Bad(f"field {name!r} is empty")
    try:
        out = float(value)
    except ValueError:
        raise _Bad(f"field {name!r} is not a number ({value!r})") from None
    if not np.isfinite(out):
        raise _Bad(f"field {name!r} is not finite ({value!r})")
    return out


def _time_of_day(value: str) -> float:
    m = _TIME.match(value)
    if not m:
        raise _Bad(f"time stamp {value!r} is not hhmmss[.ss]")
    h, mi, s = int(m[1]), int(m[2]), float(m[3])
    if h > 23 or mi > 59 or s >= 61.0:
        raise _Bad(f"time stamp {value!r} out of range")
    return 3600.0 * h + 60.0 * mi + s


def _date_field(value: str) -> _date | None:
    if value == "":
        return None
    m = _DATE.match(value)
    if not m:
        raise _Bad(f"date {value!r} is not ddmmyy")
    day, month, year = int(m[1]), int(m[2]), int(m[3])
    year += 2000 if year < 80 else 1900
    try:
        return _date(year, month, day)
    except ValueError:
        raise _Bad(f"date {value!r} is not a calendar date") from None


def _angle(value: str, hemi: str, kind: str) -> float:
    """ddmm.mmm / dddmm.mmm with hemisphere letter -> degrees (NaN when both are empty)."""
    if value == "" and hemi == "":
        return np.nan
    pattern, signs, limit = (_LAT, {"N": 1, "S": -1}, 90.0) if kind == "latitude" else \
        (_LON, {"E": 1, "W": -1}, 180.0)
    m = pattern.match(value)
    if not m:
        raise _Bad(f"{kind} {value!r} is not {'ddmm.mmm' if kind == 'latitude' else 'dddmm.mmm'}")
    if hemi not in signs:
        raise _Bad(f"{kind} hemisphere {hemi!r} is not one of {sorted(signs)}")
    minutes = float(m[2])
    if minutes >= 60.0:
        raise _Bad(f"{kind} minutes {minutes} >= 60")
    deg = int(m[1]) + minutes / 60.0
    if deg > limit:
        raise _Bad(f"{kind} {deg:.6f} deg out of range")
    return signs[hemi] * deg


def _field(data: list[str], i: int) -> str:
    return data[i].strip() if i < len(data) else ""


def _need(data: list[str], n: int, kind: str) -> None:
    if len(data) < n:
        raise _Bad(f"{kind} sentence has {len(data)} fields, expected at least {n}")


# -- per-sentence extraction: (time of day or None, date or None, {column: value}) ---------------------
def _gga(d):
    _need(d, 9, "GGA")
    tod = _time_of_day(_field(d, 0))
    quality = _num(_field(d, 5), "fix quality", empty_ok=False)
    lat, lon = _angle(_field(d, 1), _field(d, 2), "latitude"), _angle(_field(d, 3), _field(d, 4), "longitude")
    values = {"fix_quality": quality, "num_sats": _num(_field(d, 6), "satellites"),
              "hdop": _num(_field(d, 7), "HDOP"), "alt": _num(_field(d, 8), "altitude")}
    if quality > 0 and np.isfinite(lat) and np.isfinite(lon):
        values.update(lat=np.radians(lat), lon=np.radians(lon))
    return tod, None, values


def _rmc(d):
    _need(d, 9, "RMC")
    tod = _time_of_day(_field(d, 0))
    status = _field(d, 1)
    if status not in ("A", "V"):
        raise _Bad(f"RMC status {status!r} is not 'A' or 'V'")
    lat, lon = _angle(_field(d, 2), _field(d, 3), "latitude"), _angle(_field(d, 4), _field(d, 5), "longitude")
    sog, cog = _num(_field(d, 6), "speed over ground"), _num(_field(d, 7), "course over ground")
    day = _date_field(_field(d, 8))
    mode = _field(d, 11)
    values = {}
    if status == "A" and mode != "N":
        if np.isfinite(lat) and np.isfinite(lon):
            values.update(lat=np.radians(lat), lon=np.radians(lon))
        values.update(sog=sog * KNOT, cog=np.radians(cog))
    return tod, day, values


def _vtg(d):
    _need(d, 7, "VTG")
    cog = _num(_field(d, 0), "true track")
    knots, kmh = _num(_field(d, 4), "speed [kn]"), _num(_field(d, 6), "speed [km/h]")
    sog = knots * KNOT if np.isfinite(knots) else kmh / 3.6
    mode = _field(d, 8)
    if mode == "N":
        return None, None, {}
    return None, None, {"sog": sog, "cog": np.radians(cog)}


def _hdt(d):
    _need(d, 1, "HDT")
    return None, None, {"psi": np.radians(_num(_field(d, 0), "heading"))}


def _signed(value: float, letter: str, name: str) -> float:
    if not np.isfinite(value):
        return 0.0
    if letter not in ("E", "W"):
        raise _Bad(f"{name} direction {letter!r} is not 'E' or 'W'")
    return value if letter == "E" else -value


def _hdg(d):
    _need(d, 1, "HDG")
    heading = _num(_field(d, 0), "heading")
    deviation = _signed(_num(_field(d, 1), "deviation"), _field(d, 2), "deviation")
    variation = _num(_field(d, 3), "variation")
    magnetic = heading + deviation
    if np.isfinite(variation):
        return None, None, {"psi": np.radians(magnetic + _signed(variation, _field(d, 4), "variation"))}
    return None, None, {"psi_mag": np.radians(magnetic)}


_HANDLERS = {"GGA": _gga, "RMC": _rmc, "VTG": _vtg, "HDT": _hdt, "HDG": _hdg}


@dataclass
class _Report:
    skipped: list = field(default_factory=list)        # (line number, reason)
    ignored: dict = field(default_factory=dict)        # sentence type -> count
    untimed_before_first_epoch: int = 0
    superseded: dict = field(default_factory=dict)     # column -> count of overwritten values


def _encapsulated_problem(text: str) -> str | None:
    """Checksum check of a ``!``-sentence (AIS payloads use characters pynmea2 does not accept)."""
    body, star, given = text[1:].partition("*")
    if not re.match(r"^[A-Z]{5},", body):
        return "encapsulated sentence without a talker/type field"
    if star:
        calc = 0
        for ch in body:
            calc ^= ord(ch)
        if given.strip().upper() != f"{calc:02X}":
            return f"checksum error (checksum does not match: {given.strip()} != {calc:02X})"
    return None


def _first_text(exc: Exception) -> str:
    """The message of a pynmea2 exception (whose first argument may be a tuple)."""
    arg = next(iter(exc.args), str(exc))
    while isinstance(arg, tuple) and arg:
        arg = arg[0]
    return str(arg)


def _lines(source) -> tuple[str, Iterable[tuple[int, str]]]:
    if isinstance(source, str) and not source.strip():
        raise InputError("read_nmea: the source is an empty string; give a file name or the log text")
    is_text = isinstance(source, str) and ("\n" in source or source.lstrip().startswith(("$", "!")))
    if isinstance(source, (str, Path)) and not is_text:
        path = Path(source)
        if path.is_dir():
            raise IsADirectoryError(f"read_nmea: {path} is a folder, not an NMEA log file")
        if not path.is_file():
            raise FileNotFoundError(f"read_nmea: no such file {path}")
        raw = path.read_bytes()
        return str(path), enumerate(raw.decode("ascii", errors="surrogateescape").splitlines(), 1)
    if isinstance(source, str):
        return "<string>", enumerate(source.splitlines(), 1)
    if isinstance(source, io.IOBase) or hasattr(source, "read"):
        return "<stream>", enumerate(source.read().splitlines(), 1)
    return "<lines>", enumerate(source, 1)


def read_nmea(source, *, origin_deg: tuple[float, float] | None = None, skip_bad: bool = False,
              require_checksum: bool = False) -> Dataset:
    """Read an NMEA 0183 log into a :class:`~casship.Dataset` (one row per time-stamped epoch).

    Parameters
    ----------
    source : str, Path, file object or iterable of str
        A file path, the log text itself (a string with line breaks), an open text stream or
        an iterable of lines.
    origin_deg : (lat, lon), optional
        Origin of the local North-East frame in degrees; the first position fix by default.
    skip_bad : bool
        ``False`` (default): the first malformed line raises :class:`NMEAError` with its line
        number. ``True``: malformed lines are skipped and *reported* -- a warning names how many
        and the first one, and ``data.meta["nmea"]["skipped"]`` lists ``(line number, reason)``.
    require_checksum : bool
        Treat a sentence without a ``*hh`` checksum as malformed (a wrong checksum always is).

    Returns
    -------
    Dataset
        Time ``t`` [s] from the first epoch; ``meta["start_utc"]`` (ISO 8601) when an RMC date is
        present, else ``meta["start_time_of_day_s"]``; ``meta["nmea"]`` holds the report
        (skipped lines, ignored sentence types, superseded values). Columns: see the module doc.

    Raises
    ------
    NMEAError
        Malformed line (unless ``skip_bad``), time stamp going backwards, unknown hemisphere...
    ValueError
        No time-stamped sentence in the log.

    Examples
    --------
    >>> log = ("$GPGGA,120000.00,6325.8000,N,01023.5000,E,1,08,0.9,5.0,M,0.0,M,,*54\\n"
    ...        "$HEHDT,45.0,T*1E\\n")
    >>> data = read_nmea(log)
    >>> data.names
    ('lat', 'lon', 'x_n', 'y_n', 'alt', 'psi', 'fix_quality', 'num_sats', 'hdop')
    """
    import pynmea2

    name, numbered = _lines(source)
    report = _Report()
    rows: list[dict] = []
    times: list[float] = []
    first_date: tuple[int, _date] | None = None       # (row index, date) of the first RMC date
    day, last_tod = 0, None

    def bad(lineno: int, line: str, reason: str) -> None:
        if not skip_bad:
            raise NMEAError(name, lineno, line, reason)
        report.skipped.append((lineno, reason))

    for lineno, line in numbered:
        if isinstance(line, bytes):
            line = line.decode("ascii", errors="surrogateescape")
        text = line.strip()
        if not text:
            continue
        try:
            text.encode("ascii")
        except UnicodeEncodeError:
            bad(lineno, line, "non-ASCII characters")
            continue
        if not text.startswith(("$", "!")):
            bad(lineno, line, "does not start with '$' or '!'")
            continue
        if require_checksum and not re.search(r"\*[0-9A-Fa-f]{2}$", text):
            bad(lineno, line, "no checksum")
            continue
        if text.startswith("!"):                 # encapsulated (AIS) sentences: checked, counted, not used
            reason = _encapsulated_problem(text)
            if reason:
                bad(lineno, line, reason)
            else:
                kind = text[1:].split(",", 1)[0][2:] or "?"
                report.ignored[kind] = report.ignored.get(kind, 0) + 1
            continue
        try:
            msg = pynmea2.parse(text)
        except pynmea2.ChecksumError as exc:
            bad(lineno, line, f"checksum error ({_first_text(exc)})")
            continue
        except (pynmea2.ParseError, ValueError, TypeError, AttributeError) as exc:
            bad(lineno, line, f"cannot parse ({_first_text(exc)})")
            continue
        kind = getattr(msg, "sentence_type", None)
        if kind not in _HANDLERS:
            report.ignored[kind or "?"] = report.ignored.get(kind or "?", 0) + 1
            continue
        try:
            tod, day_date, values = _HANDLERS[kind]([str(v) for v in msg.data])
        except _Bad as exc:
            bad(lineno, line, str(exc))
            continue
        if tod is not None:
            if last_tod is not None and tod < last_tod:
                if last_tod - tod > _DAY / 2:
                    day += 1                      # midnight rollover
                else:
                    bad(lineno, line, f"time stamp goes back from {last_tod:.3f} s to {tod:.3f} s of day")
                    continue
            elif last_tod is not None and tod - last_tod > _DAY / 2:
                bad(lineno, line, f"time stamp goes back across midnight ({last_tod:.3f} s to {tod:.3f} s of day)")
                continue
            t_abs = day * _DAY + tod
            if not times or t_abs > times[-1]:
                times.append(t_abs)
                rows.append({})
            last_tod = tod
            if day_date is not None and first_date is None:
                first_date = (len(rows) - 1, day_date, tod)
        elif not rows:
            report.untimed_before_first_epoch += 1
            continue
        row = rows[-1]
        for col, val in values.items():
            if col in row and np.isfinite(row[col]):
                report.superseded[col] = report.superseded.get(col, 0) + 1
            row[col] = val
    if not rows:
        raise InputError(f"{name}: no time-stamped (GGA or RMC) sentence found")
    if report.skipped:
        first = report.skipped[0]
        warnings.warn(f"{name}: skipped {len(report.skipped)} malformed line(s); first: line {first[0]}: {first[1]} "
                      "(all listed in data.meta['nmea']['skipped'])", stacklevel=2)
    return _to_dataset(name, np.array(times), rows, report, first_date, origin_deg)


def _to_dataset(name, times, rows, report, first_date, origin_deg) -> Dataset:
    n = len(rows)
    cols = {c: np.full(n, np.nan) for c in _ORDER if any(c in r for r in rows)}
    for i, row in enumerate(rows):
        for c, v in row.items():
            cols[c][i] = v
    for c in ("cog", "psi", "psi_mag"):
        if c in cols:
            cols[c] = wrap(cols[c])
    meta = {"source": name, "format": "NMEA 0183"}
    if "lat" in cols:
        fixes = np.flatnonzero(np.isfinite(cols["lat"]))
        if fixes.size:
            if origin_deg is None:
                lat0, lon0 = cols["lat"][fixes[0]], cols["lon"][fixes[0]]
            else:
                lat0, lon0 = np.radians(float(origin_deg[0])), np.radians(float(origin_deg[1]))
            cols["x_n"], cols["y_n"] = geodetic_to_ne(cols["lat"], cols["lon"], lat0, lon0)
            meta["origin_deg"] = (float(np.degrees(lat0)), float(np.degrees(lon0)))
    cols = {c: cols[c] for c in _ORDER if c in cols}
    if first_date is not None:
        row, day_date, tod = first_date
        start = datetime(day_date.year, day_date.month, day_date.day, tzinfo=timezone.utc) \
            + timedelta(seconds=tod - (times[row] - times[0]))
        meta["start_utc"] = start.isoformat()
    else:
        meta["start_time_of_day_s"] = float(times[0] % _DAY)
    meta["nmea"] = {"skipped": list(report.skipped), "ignored": dict(report.ignored),
                    "untimed_before_first_epoch": report.untimed_before_first_epoch,
                    "superseded": dict(report.superseded)}
    return Dataset(times - times[0], cols, units={c: _UNITS[c] for c in cols}, meta=meta)
