"""What a record says before a filter runs: the starting belief (:func:`prior_from_data`) and the
measurement noise (:func:`noise_from_data`), one rule each for the API, the CLI and the studies.

Each state starts, in this order, at

1. the value the caller gives (``x0``);
2. the first finite value of the record's column of the same name within the first ``window``
   seconds (its variance: the measurement's ``R`` when the state is measured directly, else ``var``);
3. what the track says when the record has positions (``x, y``, ``x_n, y_n`` or ``lat, lon``): a
   straight line fitted to the positions of the first ``window`` seconds gives the speed over ground
   (for the speed states ``U`` and ``u``) and the course over ground (for ``chi``, and for the heading
   ``psi`` when no heading is recorded); a yaw rate ``r`` comes from a line fitted to the recorded
   heading;
4. zero.

Where each value came from is kept in :attr:`DataPrior.sources` (and shown by
:meth:`DataPrior.describe`), so that a report or the command line can say it. A start where the
model's equations are not finite (the MMG models at rest, u = v = 0) is refused by
:func:`casship.simulation.validity.check_start`, naming the states that were left at zero.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from ..data import Dataset
from ..errors import InputError, InputTypeError
from ..gaussian import Gaussian, as_cov

__all__ = ["prior_from_data", "noise_from_data", "DataPrior", "TRACK_POSITIONS", "second_difference_std"]

#: Position columns a track is read from (North-like first), in order of preference.
TRACK_POSITIONS = (("x", "y"), ("x_n", "y_n"), ("lat", "lon"))
_TRACK_ANGLE_VAR = np.radians(20.0) ** 2         # a course from a few seconds of track: +-20 deg


@dataclass(frozen=True, repr=False)     # Gaussian's repr: names, values, angles in degrees
class DataPrior(Gaussian):
    """A :class:`~casship.Gaussian` taken from a record, with where each state's value came from.

    Parameters
    ----------
    mean, cov
        As for :class:`~casship.Gaussian`.
    names : tuple of str
        The state names.
    units : tuple of str
        Their units (angles are shown in degrees).
    sources : dict
        State name -> where its value came from (``"given"``, ``"first sample of column 'psi'"``,
        ``"speed over ground of the track (first 5 s)"``, ``"0 (default)"``, ...).
    """

    names: tuple = ()
    sources: Mapping = field(default_factory=dict)

    def describe(self) -> str:
        """One line per state: ``name = value +- std (source)``.

        Returns
        -------
        str
        """
        return "\n".join(f"{n} = {m:.6g} +- {s:.3g} ({self.sources.get(n, '')})"
                         for n, m, s in zip(self.names, self.mean, self.std))

    def defaulted(self) -> list[str]:
        """The states left at their default (zero): nothing in the record gave them.

        Returns
        -------
        list of str
        """
        return [n for n in self.names if self.sources.get(n, "").startswith("0 (default")]


def _first(data: Dataset, name: str, t_end: float):
    col = data[name]
    ok = np.flatnonzero(np.isfinite(col) & (data.t <= t_end))
    return (float(col[ok[0]]), float(data.t[ok[0]])) if ok.size else None


def _track(data: Dataset, t_end: float):
    """(speed, course, columns) from a line through the positions of the first seconds, or None."""
    for north, east in TRACK_POSITIONS:
        if north not in data or east not in data:
            continue
        n, e = np.asarray(data[north], dtype=float), np.asarray(data[east], dtype=float)
        if north == "lat":
            from ..io.geodesy import geodetic_to_ne

            ok = np.flatnonzero(np.isfinite(n) & np.isfinite(e))
            if not ok.size:
                continue
            n, e = geodetic_to_ne(n, e, n[ok[0]], e[ok[0]])
        ok = np.flatnonzero(np.isfinite(n) & np.isfinite(e) & (data.t <= t_end))
        if ok.size < 3:
            continue
        t = data.t[ok] - data.t[ok[0]]
        vn, ve = np.polyfit(t, n[ok], 1)[0], np.polyfit(t, e[ok], 1)[0]
        return float(np.hypot(vn, ve)), float(np.arctan2(ve, vn)), f"{north}, {east}"
    return None


def prior_from_data(model, data: Dataset, *, measured: Sequence[str] = (), R=None, x0: Mapping | None = None,
                    var: float = 1.0, window: float = 5.0) -> DataPrior:
    """A prior for the first sample of ``data`` by the rule of the module notes.

    Parameters
    ----------
    model : Model
        The model whose states are started.
    data : Dataset
        The record.
    measured : sequence of str
        The measured outputs (a state measured directly takes its measurement variance).
    R : array or mapping, optional
        Measurement covariance of ``measured`` (as for the estimators); default: ``var`` for all.
    x0 : mapping state -> value, optional
        Values given by the caller (they win).
    var : float
        Variance of every state not measured directly (angles from a track: (20 deg)^2 at most).
    window : float
        The first seconds of the record that are read [s].

    Returns
    -------
    DataPrior
        A Gaussian (usable wherever a prior is) with ``sources``.

    Raises
    ------
    InputError
        An unknown state in ``x0``, a non-finite value, a bad ``var`` or ``window``.

    Examples
    --------
    >>> import numpy as np, casship as cs
    >>> t = np.arange(0.0, 10.0, 0.5)
    >>> track = cs.Dataset(t, {"x_n": 3.0 * t, "y_n": 4.0 * t})
    >>> prior = cs.prior_from_data(cs.models.get_model("sog-cog"), track, measured=["x_n", "y_n"], R=0.01)
    >>> round(float(prior.mean[2]), 3), prior.sources["U"]
    (5.0, 'speed over ground of the track x_n, y_n (first 5 s)')
    """
    if not isinstance(data, Dataset):
        raise InputTypeError(f"data must be a casship.Dataset, got {type(data).__name__}")
    var, window = float(var), float(window)
    if not (np.isfinite(var) and var > 0):
        raise InputError(f"var must be a positive variance, got {var}")
    if not (np.isfinite(window) and window > 0):
        raise InputError(f"window must be a positive time [s], got {window}")
    names = tuple(model.state_names)
    measured = list(measured)
    Rm = np.eye(len(measured)) * var if R is None else as_cov(R, len(measured), "R", measured)
    x0 = dict(x0 or {})
    unknown = [k for k in x0 if k not in names]
    if unknown:
        raise InputError(f"x0: unknown state(s) {unknown}; states of {model.name!r}: {list(names)}")
    t_end = float(data.t[0]) + window
    mean, cov, sources = np.zeros(len(names)), np.full(len(names), var), {}
    track = None
    for i, name in enumerate(names):
        if name in x0:
            value = float(x0[name])
            if not np.isfinite(value):
                raise InputError(f"x0: {name} = {value} is not finite")
            mean[i], sources[name] = value, "given"
            continue
        if name in data:
            first = _first(data, name, t_end)
            if first is not None:
                mean[i] = first[0]
                sources[name] = f"first sample of column {name!r} (t = {first[1]:g} s)"
                if name in measured:
                    cov[i] = Rm[measured.index(name), measured.index(name)]
                continue
        if name in ("U", "u", "chi", "psi"):
            track = track if track is not None else (_track(data, t_end) or ())
            if track:
                speed, course, cols = track
                if name in ("U", "u"):
                    mean[i] = speed
                    sources[name] = f"speed over ground of the track {cols} (first {window:g} s)"
                else:
                    mean[i], cov[i] = course, min(var, _TRACK_ANGLE_VAR)
                    sources[name] = f"course over ground of the track {cols} (first {window:g} s)"
                continue
        if name == "r" and "psi" in data:
            psi = np.asarray(data["psi"], dtype=float)
            ok = np.flatnonzero(np.isfinite(psi) & (data.t <= t_end))
            if ok.size >= 3:
                mean[i] = float(np.polyfit(data.t[ok], np.unwrap(psi[ok]), 1)[0])
                sources[name] = f"rate of column 'psi' (first {window:g} s)"
                continue
        sources[name] = "0 (default)"
    units = tuple(getattr(v, "unit", "") for v in getattr(model, "state_vars", ()))
    return DataPrior(mean, cov, names=names, units=units if len(units) == len(names) else (), sources=sources)


def second_difference_std(y, angle: bool = False) -> float | None:
    """Standard deviation of the white noise on one channel sampled faster than its dynamics.

    The second difference of a smooth signal sampled fast is small, that of white noise has variance
    ``6 sigma^2``; the median absolute deviation of the second differences (robust to manoeuvres and
    outliers) gives ``sigma = MAD / 0.6745 / sqrt(6)``.

    Parameters
    ----------
    y : array_like
        The samples (NaN: not measured, left out).
    angle : bool
        An angle (unwrapped first).

    Returns
    -------
    float or None
        The estimate; None with fewer than 5 finite samples.
    """
    y = np.asarray(y, dtype=float)
    y = y[np.isfinite(y)]
    if y.size < 5:
        return None
    d2 = np.diff(np.unwrap(y) if angle else y, 2)
    return float(np.median(np.abs(d2 - np.median(d2))) / 0.6745 / np.sqrt(6.0))


def noise_from_data(model, data: Dataset, measured: Sequence[str]) -> tuple[dict, dict]:
    """Measurement variance of each measured channel, estimated from the record, and how.

    The second differences of a channel sampled faster than its dynamics measure its noise
    (:func:`second_difference_std`). A channel printed with few digits (trial files keep three
    significant digits) is quantised (it keeps its value between most samples): its error is at
    least the quantisation noise ``q^2 / 12`` of its typical jump ``q``; a record whose reader states
    the significant digits of its numbers (``meta["significant_digits"]``) gives the quantum of each
    value (for columns in metres or metres per second, kept in the unit they were printed in). The
    largest is taken.

    Parameters
    ----------
    model : Model
        The model (its angle outputs are unwrapped first).
    data : Dataset
        The record.
    measured : sequence of str
        The channels.

    Returns
    -------
    (dict, dict)
        Channel -> variance, and channel -> how it was found.

    Raises
    ------
    InputError
        A channel whose noise the record does not show: constant, with second differences zero at most
        samples, or too few samples (give its variance).

    Examples
    --------
    >>> import numpy as np, casship as cs
    >>> t = np.arange(0.0, 100.0)
    >>> noisy = cs.Dataset(t, {"psi": 0.01 * t + 0.001 * np.random.default_rng(1).standard_normal(t.size)})
    >>> R, how = cs.noise_from_data(cs.models.nomoto_first_order(), noisy, ["psi"])
    >>> round(float(np.sqrt(R["psi"])), 4), how["psi"]
    (0.001, 'second differences')
    """
    R, how = {}, {}
    for n in measured:
        angle = bool(model.angle_outputs[model.index(n, "output")])
        y = np.asarray(data[n], dtype=float)
        steps = np.abs(np.diff(y[np.isfinite(y)]))
        jumps = steps[steps > 0]
        # quantised: the value stays put between most samples and jumps by about one step q
        q = float(np.median(jumps)) if jumps.size and np.mean(steps == 0) > 0.5 else 0.0
        found = [(q**2 / 12, f"quantised: step {q:.3g}, q^2/12")]
        digits = data.meta.get("significant_digits")
        if digits and data.units.get(n) in ("m", "m/s") and not angle:
            # printed with a few significant digits: the quantum grows with the value (only for columns kept
            # in the unit they were printed in; angles, rates and revolutions were converted)
            v = np.abs(y[np.isfinite(y) & (y != 0)])
            if v.size:
                quanta = 10.0 ** (np.floor(np.log10(v)) - (int(digits) - 1))
                found.append((float(np.mean(quanta**2)) / 12, f"{digits} significant digits: mean quantum^2/12"))
        std = second_difference_std(y, angle)
        if std is not None and std > 0:
            found.append((std**2, "second differences"))
        var, text = max(found)
        if not var > 0:
            finite = y[np.isfinite(y)]
            why = (f"only {finite.size} measured sample(s), too few" if finite.size < 5 else "a constant channel"
                   if np.ptp(finite) == 0 else "its second differences are zero at most samples: a channel that "
                   "changes steadily, or is printed with few digits")
            label = data.meta.get("name") or data.meta.get("source")
            raise InputError(f"the noise of {n!r} cannot be estimated from the record"
                             f"{f' {label}' if label else ''} ({why}); give its variance")
        R[n], how[n] = var, text
    return R, how
