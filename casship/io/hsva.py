"""Reader for the HSVA free-running KVLCC2 zig-zags (SIMMAN 2008, CPMC, model scale 1:45.7).

File layout: four title lines (cp1252, with degree signs), then twelve whitespace-separated columns
without a header, written at 0.05 s (HSVA sampled at 100 Hz, low-pass filtered, kept every fifth
value). The columns and what the reader does with them:

====  ===========================================  ==========  =====================================
col   quantity in the file                         unit        kept as
====  ===========================================  ==========  =====================================
0     time                                         s           ``t``
1, 2  x, y, earth-fixed, x along the initial course m          ``x``, ``y``
3     heading, positive turning to starboard       deg         ``psi`` [rad]
4     surge velocity                               m/s         ``u``
5     **not established** (behaves like a roll     --          left out
      angle in degrees)
6     yaw rate                                     deg/s       ``r`` [rad/s]
7     **not established** (correlates with the     --          left out
      sway velocity, not with gain 1)
8     rudder angle, positive steering to *port*    deg         ``delta`` [rad], sign flipped
9     propeller rate                               rps         ``n`` [1/s]
10    propeller thrust                             N           ``thrust``
11    propeller torque                             N m         ``torque``
====  ===========================================  ==========  =====================================

Explicit choices:

* **Rudder sign.** In these files a positive rudder angle steers to port (the ``_P`` runs start with
  a positive angle and a decreasing heading), the opposite of the MMG convention of
  :mod:`casship.models.mmg` (positive rudder -> heading increases). The reader flips it
  (``delta = -delta_file``) and records ``rudder_sign_flipped`` in ``meta``; ``flip_rudder=False``
  keeps the file's sign.
* **Unestablished channels.** Columns 5 and 7 are not read into the record: their quantity, gain and
  reference point are not known. The sway motion is carried by ``x, y`` and ``psi``; ``meta
  ["left_out"]`` says why each column is missing. (A quick check: column 7 regressed on the sway
  velocity from differenced positions and on the yaw rate gives gains near 3 and 6 and explains
  77-94 % of its variance, not the identity of a velocity at a known point.)
* **Surge velocity.** Column 4 agrees with the surge velocity from differenced positions projected on
  the heading to 0.5 % on the straight approach and in the small zig-zags, but it is lower by 1-4 % on
  average over the larger ones (the file does not say how it was measured); it is kept as recorded.
* **Scale.** The files are at model scale (L_pp = 7 m) although the test report calls its output full
  scale. With ``full_scale=True`` the record is Froude-scaled to the full-scale ship with
  ``lambda = 45.7`` (the same ratio as the MARIN files): time and velocities by ``sqrt(lambda)``,
  positions by ``lambda``, yaw rate and propeller rate by ``1/sqrt(lambda)``, thrust by
  ``lambda^3 rho_full / rho_model`` and torque by ``lambda^4 rho_full / rho_model`` (fresh water in
  the tank, 1025 kg/m^3 in the full-scale model). Froude scaling keeps the model-scale Reynolds
  number: resistance and wake are those of the model, not of the ship.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..data import Dataset
from .table import read_numeric_rows
from ..errors import InputError

__all__ = ["read_hsva", "hsva_runs", "HSVA_COLUMNS", "HSVA_SCALE"]

#: What the twelve columns of the files hold (``None`` for the two unestablished channels).
HSVA_COLUMNS = ("time", "x", "y", "psi", "u", None, "r", None, "delta", "n", "thrust", "torque")
#: Geometric scale of the HSVA model (L_pp 7.0 m of 320 m; MLA ``scale_factor: 45.7``).
HSVA_SCALE = 45.7
_L_PP_MODEL = 7.0
_RHO_MODEL, _RHO_FULL = 1000.0, 1025.0
_LEFT_OUT = {
    "column 5": "not established: about +-0.4, follows the rudder angle (correlation 0.9), behaves like a "
                "roll angle in degrees; unit and sign unknown",
    "column 7": "not established: about +-0.3, correlates with the sway velocity from positions and "
                "heading but not with gain 1 nor at a known reference point",
}
_TITLE = re.compile(r"Z\s*(\d+(?:\.\d+)?)\D+(\d+(?:\.\d+)?)")


def _maneuver(title: str) -> dict:
    """Zig-zag settings from a title line like ``Z10°/5°`` or ``Z10M-0/10M-0 starting to port``."""
    m = _TITLE.search(title)
    if not m:
        return {}
    out = {"kind": "zigzag", "rudder_deg": float(m.group(1)), "heading_deg": float(m.group(2))}
    low = title.lower()
    out["first"] = "port" if "to port" in low else "starboard"
    return out


def read_hsva(path, *, full_scale: bool = False, flip_rudder: bool = True, scale: float = HSVA_SCALE) -> Dataset:
    """Read one HSVA free-running ``.dat`` file into a :class:`casship.Dataset`.

    Parameters
    ----------
    path : str or Path
        A ``HSVA_CPMC_KVLCC2_Z_*.dat`` file.
    full_scale : bool
        Froude-scale the record to the full-scale ship (``lambda = scale``); otherwise keep model
        scale (L_pp = 7 m).
    flip_rudder : bool
        Flip the rudder sign to the MMG convention (positive rudder -> heading increases).
    scale : float
        Geometric scale ratio used with ``full_scale`` (45.7, as for the MARIN files).

    Returns
    -------
    Dataset
        Columns ``u, r, x, y, psi, delta, n, thrust, torque`` in SI units and radians (no ``v``:
        the files hold no established sway velocity). ``meta`` holds ``source``, ``title``,
        ``facility`` (``"HSVA"``), ``dt``, ``scale``, ``full_scale``, ``L_pp``,
        ``rudder_sign_flipped``, ``left_out`` (why columns 5 and 7 are not read) and ``maneuver``
        (zig-zag rudder and switch-heading angles and the first turn, from the title).

    Examples
    --------
    >>> from casship.io import read_hsva                                  # doctest: +SKIP
    >>> d = read_hsva("../shared/data/kvlcc2_hsva_free/HSVA_CPMC_KVLCC2_Z_10_10_P.dat",
    ...               full_scale=True)                                     # doctest: +SKIP
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"HSVA file {path} does not exist")
    if not (np.isfinite(scale) and scale > 0):
        raise InputError(f"scale must be a positive number, got {scale}")
    lines = path.read_text(encoding="cp1252").splitlines()
    if len(lines) < 5:
        raise InputError(f"{path}: expected 4 title lines and data rows, got {len(lines)} lines")
    title = " | ".join(s.strip() for s in lines[:4] if s.strip())
    data = read_numeric_rows(path, lines, 4, HSVA_COLUMNS)
    col = {name: data[:, i] for i, name in enumerate(HSVA_COLUMNS) if name is not None}
    t = col["time"]
    if np.any(np.diff(t) <= 0):
        k = int(np.flatnonzero(np.diff(t) <= 0)[0])
        raise InputError(f"{path}: time stamps must increase; data row {k + 1} ({t[k + 1]}) is not after {t[k]}")
    sign = -1.0 if flip_rudder else 1.0
    cols = {"u": col["u"], "r": np.radians(col["r"]), "x": col["x"], "y": col["y"], "psi": np.radians(col["psi"]),
            "delta": sign * np.radians(col["delta"]), "n": col["n"], "thrust": col["thrust"],
            "torque": col["torque"]}
    L = _L_PP_MODEL
    if full_scale:
        k, rho = np.sqrt(scale), _RHO_FULL / _RHO_MODEL
        t = t * k
        cols.update(u=cols["u"] * k, r=cols["r"] / k, x=cols["x"] * scale, y=cols["y"] * scale, n=cols["n"] / k,
                    thrust=cols["thrust"] * scale**3 * rho, torque=cols["torque"] * scale**4 * rho)
        L = _L_PP_MODEL * scale
    units = {"u": "m/s", "r": "rad/s", "x": "m", "y": "m", "psi": "rad", "delta": "rad", "n": "1/s",
             "thrust": "N", "torque": "N m"}
    meta = {"source": str(path), "title": title, "facility": "HSVA", "dt": float(np.median(np.diff(t))),
            "scale": float(scale), "full_scale": bool(full_scale), "L_pp": L,
            "rudder_sign_flipped": bool(flip_rudder), "left_out": dict(_LEFT_OUT),
            "maneuver": _maneuver(lines[2] if len(lines) > 2 else title) or _maneuver(title),
            "vessel": f"KVLCC2 (HSVA free running, {'Froude-scaled to full scale' if full_scale else 'model scale'})"}
    return Dataset(t, cols, units, meta)


def hsva_runs(folder) -> dict[str, Path]:
    """The HSVA files in a folder by short name.

    Parameters
    ----------
    folder : str or Path
        A folder holding ``HSVA_CPMC_KVLCC2_Z_*.dat`` files.

    Returns
    -------
    dict
        Short name (``Z_05_01``, ..., ``Z_10_10_P``) -> path, sorted by name.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"folder {folder} does not exist")
    return {f.name[len("HSVA_CPMC_KVLCC2_"):-len(".dat")]: f
            for f in sorted(folder.glob("HSVA_CPMC_KVLCC2_Z_*.dat"))}
