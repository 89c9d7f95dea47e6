"""One reader for every record format casship reads: :func:`read_record` picks the right one.

=========== ================================================= ================================
format      files                                             reader
=========== ================================================= ================================
``csv``     ``*.csv`` (header row, SI units, casship names)    :meth:`casship.Dataset.from_csv`
``marin``   ``*.dat`` MARIN free-running records               :func:`casship.io.read_marin`
``hsva``    ``HSVA_*.dat`` HSVA free-running records          :func:`casship.io.read_hsva`
``nmea``    ``*.nmea``, ``*.nme``, ``*.log`` or text whose     :func:`casship.io.read_nmea`
            first line starts with ``$`` or ``!``
=========== ================================================= ================================
"""
from __future__ import annotations

from pathlib import Path

from ..data import Dataset
from .hsva import read_hsva
from .marin import read_marin
from .nmea import read_nmea
from ..errors import InputError

__all__ = ["read_record", "record_format", "RECORD_FORMATS"]

RECORD_FORMATS = ("csv", "marin", "hsva", "nmea")


def record_format(path) -> str:
    """The format :func:`read_record` reads ``path`` as, from its suffix (and, for other suffixes, its first line).

    Parameters
    ----------
    path : str or Path
        An existing file.

    Returns
    -------
    str
        One of :data:`RECORD_FORMATS`.

    Examples
    --------
    >>> record_format("MARIN_FREE_KVLCC2_zz_10_m.dat"), record_format("HSVA_CPMC_KVLCC2_Z_10_05.dat")
    ('marin', 'hsva')
    """
    return _sniff(Path(path))


def _sniff(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return "csv"
    if suffix in (".nmea", ".nme", ".log"):
        return "nmea"
    if suffix == ".dat":
        return "hsva" if path.name.upper().startswith("HSVA") else "marin"
    with path.open("rb") as stream:
        for raw in stream:
            text = raw.strip()
            if text:
                return "nmea" if text[:1] in (b"$", b"!") else "csv"
    return "csv"


def read_record(path, *, format: str | None = None) -> Dataset:
    """Read a record (CSV, MARIN ``.dat``, HSVA ``.dat``, NMEA log) into a :class:`~casship.Dataset`.

    Parameters
    ----------
    path : str or Path
        The file.
    format : {"csv", "marin", "hsva", "nmea"}, optional
        The format; by default from the suffix (and, for other suffixes, the first line).

    Returns
    -------
    Dataset
        ``meta["source"]`` names the file and ``meta["format"]`` the format read.

    Raises
    ------
    FileNotFoundError, IsADirectoryError
        No such file, or a folder.
    ValueError
        An unknown format, or what the format's reader finds wrong (naming the file).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "run.csv"
    >>> _ = path.write_text("t,psi\\n0,0.1\\n1,0.2\\n")
    >>> read_record(path).meta["format"]
    'csv'
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"record {path}: is a folder, not a file")
    if not path.is_file():
        raise FileNotFoundError(f"record {path}: no such file")
    if format is None:
        format = _sniff(path)
    if format not in RECORD_FORMATS:
        raise InputError(f"record {path}: unknown format {format!r}; use one of {RECORD_FORMATS}")
    if format == "csv":
        data = Dataset.from_csv(path)
    elif format == "marin":
        data = read_marin(path)
    elif format == "nmea":
        data = read_nmea(path)
    else:
        data = read_hsva(path)
    data.meta.setdefault("source", str(path))
    data.meta["format"] = format
    return data
