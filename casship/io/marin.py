"""Reader for the MARIN free-running KVLCC2 records (SIMMAN 2008, converted to full scale).

File layout: two title lines and a blank line, then tab-separated rows
``time x0 y0 phi psi u v p r delta rev`` (no header; blank lines between rows are ignored), in
s, m, m, deg, deg, m/s, m/s, deg/s, deg/s, deg, rpm. Numbers carry three significant digits.

What the reader does, explicitly:

* **time** is rebuilt as ``row * dt``: the printed stamps are quantised (three digits), so ``dt`` is
  the least-squares slope of the printed stamps on the row index, weighted by the inverse square
  of each stamp's quantum (the largest residual, in quanta, is kept in ``meta``);
* **degrees -> radians** for ``phi, psi, p, r, delta``; **rpm -> rps** for ``rev``;
* **velocities**: the ``u, v`` columns of these files are the earth-fixed rates ``dx0/dt, dy0/dt``
  (checked against the differenced positions: in a steady turn they rotate with the heading), so
  they are rotated into body axes with the heading: ``u = x0' cos psi + y0' sin psi``,
  ``v = -x0' sin psi + y0' cos psi``. The files do not state the reference point of positions and
  velocities; in the steady turn the sway from differenced positions is about 0.17 m/s more
  negative than the recorded one (equivalent to a point about 21 m further aft);
* **rudder sign**: in the files a positive rudder angle gives a *decreasing* heading; the reader
  flips it (``delta = -delta_file``) to the MMG convention (positive rudder -> heading increases).
  Set ``flip_rudder=False`` to keep the file's sign.

The returned :class:`casship.Dataset` has columns named like the KVLCC2 model's states and inputs:
``u, v, r, x, y, psi, delta, n`` plus ``phi, p`` (roll) and ``x_dot, y_dot`` (earth-fixed rates).
``psi`` is continuous (not wrapped), as recorded.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data import Dataset
from .table import read_numeric_rows
from ..errors import InputError

__all__ = ["read_marin", "MARIN_COLUMNS", "marin_runs"]

MARIN_COLUMNS = ("time", "x0", "y0", "phi", "psi", "u", "v", "p", "r", "delta", "rev")


def _quantum(values: np.ndarray, digits: int = 3) -> np.ndarray:
    mag = np.floor(np.log10(np.where(values > 0, values, 1.0)))
    return np.where(values > 0, 10.0 ** (mag - (digits - 1)), 10.0 ** (-digits))


def read_marin(path, *, flip_rudder: bool = True) -> Dataset:
    """Read one MARIN free-running ``.dat`` file into a :class:`casship.Dataset`.

    Parameters
    ----------
    path : str or Path
        A ``MARIN_FREE_KVLCC2_*.dat`` file.
    flip_rudder : bool
        Flip the rudder sign to the MMG convention (positive rudder -> heading increases).

    Returns
    -------
    Dataset
        Columns ``u, v, r, x, y, psi, delta, n, phi, p, x_dot, y_dot`` in SI units and radians;
        ``meta`` holds ``source``, ``title``, ``dt``, ``time_residual_quanta``, ``significant_digits`` (3:
        the quantisation of every value) and ``rudder_sign_flipped``.

    Examples
    --------
    >>> from casship.io import read_marin                                  # doctest: +SKIP
    >>> data = read_marin("../shared/data/kvlcc2_marin_free/MARIN_FREE_KVLCC2_zz_10_m.dat")  # doctest: +SKIP
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MARIN file {path} does not exist")
    lines = path.read_text().splitlines()
    title = " ".join(s.strip() for s in lines[:2])
    data = read_numeric_rows(path, lines, 2, MARIN_COLUMNS)
    col = {name: data[:, i] for i, name in enumerate(MARIN_COLUMNS)}
    stamps = col["time"] - col["time"][0]
    k = np.arange(stamps.size, dtype=float)
    w = 1.0 / _quantum(np.abs(stamps)) ** 2
    dt = float(np.sum(w * k * stamps) / np.sum(w * k * k))
    if not dt > 0:
        bad = np.flatnonzero(np.diff(col["time"]) <= 0)
        where = f"; data row {bad[0] + 1} ({col['time'][bad[0] + 1]:g}) is not after {col['time'][bad[0]]:g}" \
            if bad.size else ""
        raise InputError(f"{path}: time stamps do not increase (step fitted to the stamps: {dt:g} s){where}")
    t = col["time"][0] + k * dt
    residual = float(np.max(np.abs(t - col["time"]) / _quantum(np.abs(col["time"]))))
    psi = np.radians(col["psi"])
    x_dot, y_dot = col["u"], col["v"]
    u = x_dot * np.cos(psi) + y_dot * np.sin(psi)
    v = -x_dot * np.sin(psi) + y_dot * np.cos(psi)
    sign = -1.0 if flip_rudder else 1.0
    cols = {"u": u, "v": v, "r": np.radians(col["r"]), "x": col["x0"], "y": col["y0"], "psi": psi,
            "delta": sign * np.radians(col["delta"]), "n": col["rev"] / 60.0,
            "phi": np.radians(col["phi"]), "p": np.radians(col["p"]), "x_dot": x_dot, "y_dot": y_dot}
    units = {"u": "m/s", "v": "m/s", "r": "rad/s", "x": "m", "y": "m", "psi": "rad", "delta": "rad",
             "n": "1/s", "phi": "rad", "p": "rad/s", "x_dot": "m/s", "y_dot": "m/s"}
    meta = {"source": str(path), "title": title, "dt": dt, "time_residual_quanta": residual, "significant_digits": 3,
            "rudder_sign_flipped": bool(flip_rudder), "vessel": "KVLCC2 (MARIN free running, full scale)",
            "L_pp": 320.0}
    return Dataset(t, cols, units, meta)


def marin_runs(folder) -> dict[str, Path]:
    """The MARIN files in ``folder`` by short name (``tc_-35``, ``zz_10``, ``zz_-20``).

    A file ``MARIN_FREE_KVLCC2_<short>_m.dat`` is listed as ``<short>``; other files are ignored.

    Parameters
    ----------
    folder : str or Path
        The folder holding the MARIN ``.dat`` files (e.g. ``../shared/data/kvlcc2_marin_free``).

    Returns
    -------
    dict of str to Path
        Short name -> file path, sorted by file name; empty if the folder has no MARIN file.

    Raises
    ------
    FileNotFoundError
        If ``folder`` is not a directory.

    Examples
    --------
    >>> runs = marin_runs("../shared/data/kvlcc2_marin_free")        # doctest: +SKIP
    >>> sorted(runs)                                                  # doctest: +SKIP
    ['tc_-35', 'zz_-20', 'zz_10']
    >>> data = read_marin(runs["zz_10"])                              # doctest: +SKIP
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"folder {folder} does not exist")
    out = {}
    for f in sorted(folder.glob("MARIN_FREE_KVLCC2_*_m.dat")):
        out[f.name[len("MARIN_FREE_KVLCC2_"):-len("_m.dat")]] = f
    return out
