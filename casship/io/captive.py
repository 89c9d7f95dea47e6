"""Captive (PMM) model tests: static points and the harmonic components of dynamic tests.

:func:`read_captive` reads a folder of captive-test tables (the HMRI KVLCC2 series in the layout of
``kvlcc2_hmri_captive``: ``static_rudder.csv``, ``static_drift.csv``, ``drift_rudder.csv``,
``pure_sway.csv``, ``pure_yaw.csv``, ``yaw_drift.csv``) into a :class:`CaptiveTests` value.

Conventions of the record (converted on reading, so that it speaks casship's language):

* angles in radians; the drift angle ``beta = atan(-v / u)`` (positive: the flow comes from
  starboard, the hull moves to port), as in the MMG model;
* the rudder angle ``delta`` in casship's sign (positive turns the ship to starboard). The HMRI
  tables count the rudder the other way: at ``delta_deg = +25`` their static rudder test gives
  ``Y' = +0.0015`` and ``N' = -0.0008`` (a turn to port), so ``delta = -radians(delta_deg)``;
* forces as the tables give them, non-dimensional: ``X' = X / (0.5 rho U^2 L^2)``,
  ``Y' = Y / (0.5 rho U^2 L^2)``, ``N' = N / (0.5 rho U^2 L^3)`` with ``U`` the carriage speed
  (established from the data, see ``docs/data.md``, "Captive tests");
* a dynamic test's components ``(mean, in1, out1, in2, out2, in3, out3)`` per channel: ``in_k`` is
  the coefficient of ``sin(k omega t)`` and ``out_k`` that of ``cos(k omega t)``, with the PMM
  motion ``psi = psi_max sin(omega t)`` (yaw) or ``y = y_max sin(omega t)`` (sway);
* a point repeated number for number under another condition (a copy in the workbook) is kept once,
  at its first condition; the copy's components are NaN (not measured) and listed in ``notes``.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

__all__ = ["read_captive", "CaptiveTests", "StaticTests", "DynamicTests", "HARMONICS", "CHANNELS",
           "STATIC_KINDS", "DYNAMIC_KINDS", "FORCE_SCALES"]

#: Harmonic components of a dynamic test, in order.
HARMONICS = ("mean", "in1", "out1", "in2", "out2", "in3", "out3")
#: Force channels: hull X, Y, N; rudder stock RX, RY; propeller thrust T.
CHANNELS = ("X", "Y", "N", "RX", "RY", "T")
STATIC_KINDS = ("static_rudder", "static_drift", "drift_rudder")
DYNAMIC_KINDS = ("pure_sway", "pure_yaw", "yaw_drift")
#: Non-dimensionalisation of each channel: the force divided by ``0.5 rho U^2 L^k`` with this ``k``.
FORCE_SCALES = {"X": 2, "Y": 2, "N": 3, "RX": 2, "RY": 2, "T": 2}

_STATIC_COLS = {"X": "X_prime", "Y": "Y_prime", "N": "N_prime", "RX": "RX_prime", "RY": "RY_prime", "T": "TX_prime"}
_DYN_SUFFIX = {"mean": "mean", "in1": "in", "out1": "out", "in2": "in2", "out2": "out2", "in3": "in3", "out3": "out3"}
_STATIC_FILES = {"static_rudder": ("delta_deg",), "static_drift": ("beta_deg",), "drift_rudder": ("beta_deg", "delta_deg")}
_DYN_FILES = {"pure_sway": ("vdot_prime",), "pure_yaw": ("r_prime", "rdot_prime"),
              "yaw_drift": ("beta_deg", "r_prime", "rdot_prime")}


class _TestTable:
    """What the static and the dynamic tables share: their length and the selection of one test kind."""

    _KINDS: tuple = ()
    _WHAT = ""

    def __len__(self) -> int:
        return len(self.run)

    def select(self, kind: str) -> np.ndarray:
        """Indices of the tests of one kind.

        Parameters
        ----------
        kind : str
            One of the table's kinds (:data:`STATIC_KINDS` or :data:`DYNAMIC_KINDS`).

        Returns
        -------
        array of int
        """
        if kind not in self._KINDS:
            raise InputError(f"{self._WHAT} test kind must be one of {self._KINDS}, got {kind!r}")
        return np.array([i for i, k in enumerate(self.kind) if k == kind], dtype=int)


@dataclass(frozen=True)
class StaticTests(_TestTable):
    """Static captive points (steady drift and rudder angle, no rotation).

    Parameters
    ----------
    run : (n,) int array
        Test run number.
    kind : tuple of str
        Test of each point (one of :data:`STATIC_KINDS`; a point in two tables keeps its first).
    beta, delta : (n,) arrays [rad]
        Drift angle (``atan(-v/u)``) and rudder angle (casship sign: positive turns to starboard).
    speed : (n,) array [m/s]
        Carriage speed ``U``.
    rps : (n,) array [1/s]
        Propeller rate.
    forces : dict channel -> (n,) array [-]
        Non-dimensional forces (:data:`CHANNELS`; scales in :data:`FORCE_SCALES`).
    """

    _KINDS = STATIC_KINDS
    _WHAT = "static"

    run: np.ndarray
    kind: tuple
    beta: np.ndarray
    delta: np.ndarray
    speed: np.ndarray
    rps: np.ndarray
    forces: dict



@dataclass(frozen=True)
class DynamicTests(_TestTable):
    """Dynamic (PMM) tests as harmonic components over one period.

    Parameters
    ----------
    run : (n,) int array
    kind : tuple of str
        One of :data:`DYNAMIC_KINDS` per test.
    beta : (n,) array [rad]
        Mean drift angle (0 for pure sway and pure yaw).
    speed, rps, freq_hz : (n,) arrays [m/s, 1/s, Hz]
        Carriage speed, propeller rate and PMM frequency.
    vdot_amp : (n,) array [-]
        Pure sway: coefficient of ``sin(omega t)`` in ``vdot' = vdot L / U^2`` (negative: the sway
        ``y = y_max sin(omega t)`` has ``vdot = -y_max omega^2 sin(omega t)``); NaN for yaw tests.
    r_amp, rdot_amp : (n,) arrays [-]
        Yaw tests: amplitude ``r' = psi_max omega L / U`` (of ``cos(omega t)``) and the coefficient
        of ``sin(omega t)`` in ``rdot' = rdot L^2 / U^2`` (negative); NaN for pure sway.
    components : dict channel -> (n, 7) array [-]
        Per channel the components :data:`HARMONICS` (``in_k``: ``sin(k omega t)``, ``out_k``:
        ``cos(k omega t)``); NaN where not measured.
    """

    _KINDS = DYNAMIC_KINDS
    _WHAT = "dynamic"

    run: np.ndarray
    kind: tuple
    beta: np.ndarray
    speed: np.ndarray
    rps: np.ndarray
    freq_hz: np.ndarray
    vdot_amp: np.ndarray
    r_amp: np.ndarray
    rdot_amp: np.ndarray
    components: dict



@dataclass(frozen=True)
class CaptiveTests:
    """A captive-test series: static points, dynamic PMM tests, and where they came from.

    Parameters
    ----------
    static : StaticTests
    dynamic : DynamicTests
    source : str
        The folder read.
    units : dict
        Unit (or non-dimensionalisation) of every quantity.
    notes : tuple of str
        What the reader did beyond converting (merged repeats, points marked not measured).
    resistance : dict or None
        ``{"speed": [m/s], "resistance": [N]}`` when ``resistance.csv`` is present.
    open_water : dict or None
        ``{"J", "K_T", "K_Q"}`` of the model propeller when ``open_water.csv`` is present (the
        printed columns are 10 K_T and 100 K_Q; converted).
    """

    static: StaticTests
    dynamic: DynamicTests
    source: str = ""
    units: dict = field(default_factory=dict)
    notes: tuple = ()
    resistance: dict | None = None
    open_water: dict | None = None

    def __repr__(self) -> str:
        kinds = {k: len(self.static.select(k)) for k in STATIC_KINDS}
        kinds.update({k: len(self.dynamic.select(k)) for k in DYNAMIC_KINDS})
        return f"CaptiveTests({', '.join(f'{k}={n}' for k, n in kinds.items())}, source={self.source!r})"

    def summary(self) -> str:
        """A short text: points per test kind, units and the reader's notes."""
        lines = [repr(self), "units: " + ", ".join(f"{k} [{v}]" for k, v in self.units.items())]
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)


UNITS = {"beta": "rad (atan(-v/u))", "delta": "rad (positive turns to starboard)", "speed": "m/s", "rps": "1/s",
         "freq_hz": "Hz", "X": "X/(0.5 rho U^2 L^2)", "Y": "Y/(0.5 rho U^2 L^2)", "N": "N/(0.5 rho U^2 L^3)",
         "RX": "RX/(0.5 rho U^2 L^2)", "RY": "RY/(0.5 rho U^2 L^2)", "T": "T/(0.5 rho U^2 L^2)",
         "vdot_amp": "vdot L/U^2", "r_amp": "r L/U", "rdot_amp": "rdot L^2/U^2"}


def _table(path: Path, required) -> tuple[list[str], np.ndarray]:
    """A numeric CSV table with named columns; errors name the file, column and row."""
    if not path.is_file():
        raise InputError(f"{path}: captive-test file not found")
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise InputError(f"{path}: empty file")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in required if c not in header]
    if missing:
        raise InputError(f"{path}: missing column(s) {missing} (a captive-test table needs {list(required)})")
    data = np.full((len(rows) - 1, len(header)), np.nan)
    for i, row in enumerate(rows[1:]):
        if len(row) != len(header):
            raise InputError(f"{path}: data row {i + 1} has {len(row)} fields, the header {len(header)}")
        for j, val in enumerate(row):
            try:
                data[i, j] = float(val)
            except ValueError:
                raise InputError(f"{path}: column {header[j]!r}, data row {i + 1}: not a number ({val!r})") from None
    if len(data) == 0:
        raise InputError(f"{path}: no data rows")
    for j, name in enumerate(header):
        if name in required and not np.all(np.isfinite(data[:, j])):
            i = int(np.flatnonzero(~np.isfinite(data[:, j]))[0])
            raise InputError(f"{path}: column {name!r}, data row {i + 1}: not finite")
    return header, data


def _col(header, data, name):
    return data[:, header.index(name)]


def _read_static(folder: Path, notes: list) -> StaticTests:
    acc = {k: [] for k in ("run", "kind", "beta", "delta", "speed", "rps", *CHANNELS)}
    seen: dict[int, tuple] = {}
    for kind, angles in _STATIC_FILES.items():
        path = folder / f"{kind}.csv"
        required = ("run", *angles, "speed_m_s", "rps", *_STATIC_COLS.values())
        header, data = _table(path, required)
        for i in range(len(data)):
            run = int(_col(header, data, "run")[i])
            beta = np.radians(data[i, header.index("beta_deg")]) if "beta_deg" in angles else 0.0
            delta = -np.radians(data[i, header.index("delta_deg")]) if "delta_deg" in angles else 0.0
            values = tuple(float(data[i, header.index(c)]) for c in _STATIC_COLS.values())
            key = (beta, delta, float(data[i, header.index("speed_m_s")]), values)
            if run in seen:
                if seen[run] != key:
                    raise InputError(f"{path}: run {run} (data row {i + 1}) differs from the run {run} read before")
                continue                       # the same point in two tables (e.g. drift 0 deg): kept once
            seen[run] = key
            acc["run"].append(run)
            acc["kind"].append(kind)
            acc["beta"].append(beta)
            acc["delta"].append(delta)
            acc["speed"].append(key[2])
            acc["rps"].append(float(data[i, header.index("rps")]))
            for c, v in zip(CHANNELS, values):
                acc[c].append(v)
    notes.append("static points in two tables (same run number and numbers) are kept once")
    return StaticTests(run=np.array(acc["run"], dtype=int), kind=tuple(acc["kind"]),
                       beta=np.array(acc["beta"]), delta=np.array(acc["delta"]), speed=np.array(acc["speed"]),
                       rps=np.array(acc["rps"]), forces={c: np.array(acc[c]) for c in CHANNELS})


def _dyn_columns(channel: str) -> list[str]:
    prefix = "T" if channel == "T" else channel
    return [f"{prefix}_{_DYN_SUFFIX[h]}_prime" for h in HARMONICS]


def _read_dynamic(folder: Path, notes: list) -> DynamicTests:
    acc = {k: [] for k in ("run", "kind", "beta", "speed", "rps", "freq_hz", "vdot_amp", "r_amp", "rdot_amp")}
    comps = {c: [] for c in CHANNELS}
    seen: dict[int, tuple] = {}
    for kind, extra in _DYN_FILES.items():
        path = folder / f"{kind}.csv"
        required = ("run", *extra, "speed_m_s", "rps", "freq_hz", *[c for ch in CHANNELS for c in _dyn_columns(ch)])
        header, data = _table(path, required)
        for i in range(len(data)):
            run = int(_col(header, data, "run")[i])
            beta = np.radians(data[i, header.index("beta_deg")]) if "beta_deg" in extra else 0.0
            values = {c: data[i, [header.index(n) for n in _dyn_columns(c)]] for c in CHANNELS}
            flat = tuple(np.concatenate([values[c] for c in CHANNELS]).tolist())
            if run in seen:
                first_beta, first_flat = seen[run]
                if first_flat != flat:
                    raise InputError(f"{path}: run {run} (data row {i + 1}) differs from the run {run} read before")
                if np.isclose(first_beta, beta):
                    continue                  # the same test in two tables (yaw with drift 0 = pure yaw)
                # the same numbers under another condition: a copy in the workbook, not a measurement
                notes.append(f"{kind}: run {run} repeated at drift {np.degrees(beta):g} deg (first at "
                             f"{np.degrees(first_beta):g} deg) number for number: that point is not measured (NaN)")
                values = {c: np.full(len(HARMONICS), np.nan) for c in CHANNELS}
            else:
                seen[run] = (beta, flat)
            acc["run"].append(run)
            acc["kind"].append(kind)
            acc["beta"].append(beta)
            acc["speed"].append(float(data[i, header.index("speed_m_s")]))
            acc["rps"].append(float(data[i, header.index("rps")]))
            acc["freq_hz"].append(float(data[i, header.index("freq_hz")]))
            acc["vdot_amp"].append(float(data[i, header.index("vdot_prime")]) if "vdot_prime" in extra else np.nan)
            acc["r_amp"].append(float(data[i, header.index("r_prime")]) if "r_prime" in extra else np.nan)
            acc["rdot_amp"].append(float(data[i, header.index("rdot_prime")]) if "rdot_prime" in extra else np.nan)
            for c in CHANNELS:
                comps[c].append(values[c])
    notes.append("dynamic tests in two tables (yaw with drift 0 = pure yaw) are kept once, as the first")
    return DynamicTests(run=np.array(acc["run"], dtype=int), kind=tuple(acc["kind"]),
                        **{k: np.array(acc[k], dtype=float) for k in ("beta", "speed", "rps", "freq_hz", "vdot_amp",
                                                                      "r_amp", "rdot_amp")},
                        components={c: np.array(comps[c]) for c in CHANNELS})


def read_captive(folder) -> CaptiveTests:
    """Read a folder of captive-test tables into a :class:`CaptiveTests` value.

    Parameters
    ----------
    folder : str or Path
        Folder holding ``static_rudder.csv``, ``static_drift.csv``, ``drift_rudder.csv``,
        ``pure_sway.csv``, ``pure_yaw.csv`` and ``yaw_drift.csv`` (and optionally
        ``resistance.csv`` and ``open_water.csv``).

    Returns
    -------
    CaptiveTests

    Raises
    ------
    InputError
        A missing folder or file, a missing column, a field that is not a number (naming the file,
        the column and the row), or one run number with different numbers in two tables.

    Examples
    --------
    >>> from casship.io import read_captive                              # doctest: +SKIP
    >>> tests = read_captive("../shared/data/kvlcc2_hmri_captive")       # doctest: +SKIP
    >>> tests.dynamic.select("pure_yaw")                                 # doctest: +SKIP
    """
    folder = Path(folder)
    if folder.is_file():
        raise InputError(f"{folder}: a file; the captive tests are read from their folder ({folder.parent})")
    if not folder.is_dir():
        raise InputError(f"{folder}: captive-test folder not found")
    notes: list[str] = []
    static = _read_static(folder, notes)
    dynamic = _read_dynamic(folder, notes)
    resistance = open_water = None
    if (folder / "resistance.csv").is_file():
        header, data = _table(folder / "resistance.csv", ("speed_m_s", "resistance_N"))
        resistance = {"speed": _col(header, data, "speed_m_s"), "resistance": _col(header, data, "resistance_N")}
    if (folder / "open_water.csv").is_file():
        header, data = _table(folder / "open_water.csv", ("J", "KT_model_as_printed", "KQ_model_as_printed"))
        open_water = {"J": _col(header, data, "J"), "K_T": _col(header, data, "KT_model_as_printed") / 10.0,
                      "K_Q": _col(header, data, "KQ_model_as_printed") / 100.0}
        notes.append("open water: the printed columns are 10 K_T and 100 K_Q (converted)")
    return CaptiveTests(static=static, dynamic=dynamic, source=str(folder), units=dict(UNITS), notes=tuple(notes),
                        resistance=resistance, open_water=open_water)
