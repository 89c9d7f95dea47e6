"""The value an estimator run returns: :class:`FilterResult`, and its :class:`Health` check."""
from __future__ import annotations

import json
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
from scipy import stats

from ..angles import wrap
from ..data import Dataset
from ..errors import InputError

__all__ = ["FilterResult", "Health", "not_positive_definite"]

_ARRAYS = ("t", "x", "P", "x_pred", "P_pred", "C", "K", "innovations", "S", "nis", "n_measured", "loglik_terms",
           "rejected", "inputs", "angle_states")
_NAMES = ("state_names", "state_units", "output_names", "input_names")
_PD_TOL = 1e-9      # smallest eigenvalue of the correlation matrix accepted as round-off


def not_positive_definite(P: np.ndarray) -> np.ndarray:
    """Rows ``k`` whose covariance ``P[k]`` is not symmetric positive semi-definite beyond round-off.

    The test is scale-free: a negative variance fails, otherwise the smallest eigenvalue of the
    correlation matrix ``D^-1/2 P D^-1/2`` must not be below ``-1e-9`` (a state with zero variance
    must have zero covariances too).

    Parameters
    ----------
    P : array (N, n, n)
    """
    P = np.asarray(P, dtype=float)
    if P.ndim != 3 or P.shape[1] != P.shape[2]:
        raise InputError(f"expected covariances of shape (N, n, n), got {P.shape}")
    d = np.einsum("kii->ki", P)
    bad = ~np.all(np.isfinite(P), axis=(1, 2)) | np.any(d < 0, axis=1)
    bad |= np.abs(P - P.transpose(0, 2, 1)).max(axis=(1, 2), initial=0.0) > 1e-12 * np.abs(P).max(axis=(1, 2), initial=0.0)
    zero = d <= 0
    scale = np.where(zero, 1.0, 1.0 / np.sqrt(np.where(zero, 1.0, d)))
    corr = P * scale[:, :, None] * scale[:, None, :]
    # a state with zero variance: its row and column must vanish
    bad |= np.any(zero[:, :, None] & (np.abs(corr) > 0), axis=(1, 2))
    corr = np.where(zero[:, :, None] | zero[:, None, :], 0.0, corr)
    ok = ~bad
    if ok.any():
        bad[ok] = np.linalg.eigvalsh(corr[ok]).min(axis=1) < -_PD_TOL
    return np.flatnonzero(bad)


def _frozen(a, dtype) -> bool:
    """True for a read-only array of ``dtype`` whose memory nobody can write (shared without a copy)."""
    if not isinstance(a, np.ndarray) or a.dtype != dtype:
        return False
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return True


@dataclass(frozen=True)
class Health:
    """Divergence and integrity monitor of an estimator run (from :meth:`FilterResult.health`).

    A window of ``window`` samples is flagged when its summed NIS (of the accepted updates) lies
    outside the two-sided ``1 - alpha`` chi-square interval for the number of scalar measurements
    in it, or when the innovation gate rejected most of its measured samples (more than half and
    at least three): a filter that rejects everything it is told has lost track. A covariance that
    is not positive semi-definite (``not_pd`` rows) is an error of its own: ``ok`` is then False
    whatever the NIS says.

    Parameters
    ----------
    window : int
        Samples per window.
    alpha : float
        Significance of the two-sided chi-square test.
    flagged : (n_windows,) bool
    window_start : (n_windows,) int
        First row of each window.
    nis_sum, dof : (n_windows,) arrays
        Summed NIS and number of scalar measurements.
    rejected : (n_windows,) int
        Gated samples per window.
    not_pd : (k,) int
        Rows whose covariance is not positive semi-definite.
    """

    window: int
    alpha: float
    flagged: np.ndarray
    window_start: np.ndarray
    nis_sum: np.ndarray
    dof: np.ndarray
    rejected: np.ndarray
    not_pd: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    def __repr__(self) -> str:
        return (f"Health({'ok' if self.ok else 'NOT ok'}: {int(self.flagged.sum())} of {self.flagged.size} NIS "
                f"window(s) of {self.window} flagged at alpha {self.alpha:g}, {int(np.sum(self.rejected))} rejected, "
                f"{self.not_pd.size} non-PD covariance(s))")

    @property
    def ok(self) -> bool:
        """No non-positive-definite covariance and fewer windows flagged than chance plus a margin."""
        n = self.flagged.size
        windows_ok = n == 0 or self.flagged.sum() <= max(1, int(np.ceil(2 * self.alpha * n + 2 * np.sqrt(self.alpha * n))))
        return bool(windows_ok and self.not_pd.size == 0)

    def raise_if_diverged(self) -> None:
        """Raise :class:`~casship.errors.SolverError` (a ``RuntimeError``) describing the problem if not :attr:`ok`."""
        from ..errors import SolverError

        if self.not_pd.size:
            raise SolverError(f"filter health check failed: {self.not_pd.size} covariance(s) not positive "
                              f"semi-definite (first at row {int(self.not_pd[0])})")
        if not self.ok:
            first = int(self.window_start[np.argmax(self.flagged)])
            raise SolverError(f"filter health check failed: {int(self.flagged.sum())} of {self.flagged.size} "
                              f"windows flagged (NIS outside the {100 * (1 - self.alpha):.0f}% chi-square "
                              f"interval or most samples rejected by the gate; first at row {first})")


@dataclass(frozen=True, eq=False, repr=False)
class FilterResult:
    """Result of running an estimator over a record: a frozen value (arrays read-only).

    Built by the estimators (``filter``, ``smooth``, ``predict``) or read back with :meth:`load`.

    Parameters
    ----------
    t : (N,) array
        Time stamps [s].
    x, P : (N, nx) and (N, nx, nx) arrays
        Filtered (or smoothed) means and covariances.
    x_pred, P_pred : arrays
        Predicted means and covariances before each update.
    C : (N, nx, nx) array
        Cross-covariances of the previous filtered and the current predicted state.
    K : (N, nx, ny) array
        Gains applied (zero columns for unmeasured channels, zero when rejected).
    innovations : (N, ny) array
        Residuals, NaN where the channel was not measured (angles wrapped).
    S : (N, ny, ny) array
        Innovation covariances (unit rows/columns for unmeasured channels).
    nis : (N,) array
        Normalised innovation squared.
    n_measured : (N,) int array
        Number of scalar measurements used per sample.
    loglik_terms : (N,) array
        Log-likelihood of each sample's measurements given the past.
    rejected : (N,) bool array
        True where the innovation gate rejected the update.
    inputs : (N, nu) array
        The inputs of the record.
    state_names, state_units, output_names, input_names : tuples of str
    estimator : str
        E.g. ``"EKF"``, ``"EKF+RTS"``, ``"EKF prediction"``.
    angle_states : (nx,) bool array
    """

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    x_pred: np.ndarray
    P_pred: np.ndarray
    C: np.ndarray
    K: np.ndarray
    innovations: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    n_measured: np.ndarray
    loglik_terms: np.ndarray
    rejected: np.ndarray
    inputs: np.ndarray
    state_names: tuple
    state_units: tuple
    output_names: tuple
    input_names: tuple
    estimator: str
    angle_states: np.ndarray

    def __post_init__(self):
        n = np.asarray(self.t).size
        for name in _ARRAYS:
            dtype = bool if name in ("rejected", "angle_states") else int if name == "n_measured" else float
            a = getattr(self, name)
            if not _frozen(a, dtype):
                a = np.array(a, dtype=dtype)                         # an own, read-only copy
            if name != "angle_states" and a.shape[:1] != (n,):
                raise InputError(f"FilterResult: {name} has {a.shape[0] if a.ndim else 0} rows, t has {n}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        for name in _NAMES:
            object.__setattr__(self, name, tuple(str(s) for s in getattr(self, name)))

    # -- access -----------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.t.size

    def __repr__(self) -> str:
        return (f"FilterResult({self.estimator}, N={self.t.size}, t=[{self.t[0]:g}, {self.t[-1]:g}] s, "
                f"states={list(self.state_names)}, loglik={self.loglik:.6g})")

    def __getitem__(self, name: str) -> np.ndarray:
        """Estimate of a named state over the record."""
        try:
            return self.x[:, self.state_names.index(name)]
        except ValueError:
            raise InputError(f"unknown state {name!r}; states: {list(self.state_names)}") from None

    @property
    def loglik(self) -> float:
        """Total log-likelihood of the record (prediction-error decomposition)."""
        return float(np.sum(self.loglik_terms))

    @property
    def std(self) -> np.ndarray:
        """Standard deviations (N, nx) of the estimates.

        Raises ``ValueError`` naming the row and state if a variance is negative: a covariance that
        is not positive definite is an error to report (see :meth:`health`), never clipped.
        """
        var = np.einsum("kii->ki", self.P)
        bad = np.argwhere(~(var >= 0))
        if bad.size:
            k, i = bad[0]
            raise InputError(f"variance of {self.state_names[i]!r} at row {k} is {var[k, i]:.3g}: the covariance is not "
                             f"positive definite ({len(not_positive_definite(self.P))} such rows; see health())")
        return np.sqrt(var)

    def nees(self, x_true: np.ndarray) -> np.ndarray:
        """Normalised estimation error squared against true states (angles wrapped).

        Parameters
        ----------
        x_true : (N, nx) array
        """
        x_true = np.asarray(x_true, dtype=float)
        if x_true.shape != self.x.shape:
            raise InputError(f"nees: x_true has shape {x_true.shape}, the estimates {self.x.shape} (rows, states "
                             f"{list(self.state_names)})")
        err = x_true - self.x
        if self.angle_states.any():
            err[:, self.angle_states] = wrap(err[:, self.angle_states])
        return np.einsum("ki,ki->k", err, np.linalg.solve(self.P, err[..., None])[..., 0])

    def health(self, window: int = 50, alpha: float = 0.01) -> Health:
        """Windowed NIS test and covariance integrity check (see :class:`Health`).

        Parameters
        ----------
        window : int
            Samples per window.
        alpha : float
            Significance of the two-sided chi-square test per window.
        """
        not_pd = not_positive_definite(self.P)
        n = self.nis.size // window
        if n == 0:
            empty = np.zeros(0)
            return Health(window, alpha, empty.astype(bool), empty.astype(int), empty, empty, empty.astype(int), not_pd)
        used = ~self.rejected
        blocks = lambda a: a[: n * window].reshape(n, window).sum(axis=1)  # noqa: E731
        nis = blocks(np.where(used, self.nis, 0.0))
        dof = blocks(np.where(used, self.n_measured, 0))
        lo = stats.chi2.ppf(alpha / 2, np.maximum(dof, 1))
        hi = stats.chi2.ppf(1 - alpha / 2, np.maximum(dof, 1))
        measured = self.n_measured > 0
        rejected = blocks((self.rejected & measured).astype(int))
        lost = (rejected >= 3) & (2 * rejected > blocks(measured.astype(int)))
        flagged = ((dof > 0) & ((nis < lo) | (nis > hi))) | lost
        return Health(window, alpha, flagged, np.arange(n) * window, nis, dof, rejected, not_pd)

    # -- presentation ---------------------------------------------------------------------------
    def summary(self) -> str:
        """A plain-text summary: span, final estimates with standard deviations, NIS, health."""
        h = self.health()
        m = self.n_measured > 0
        nis_rate = float(self.nis[m & ~self.rejected].sum() / max(1, self.n_measured[m & ~self.rejected].sum()))
        lines = [f"{self.estimator} over {self.t.size} samples, t = {self.t[0]:g} .. {self.t[-1]:g} s; "
                 f"{int(m.sum())} updates, {int(self.rejected.sum())} rejected",
                 f"log-likelihood {self.loglik:.6g}; NIS per measurement {nis_rate:.3f} (1 when consistent); "
                 f"health {'ok' if h.ok else 'NOT ok'} ({int(h.flagged.sum())} of {h.flagged.size} windows flagged, "
                 f"{h.not_pd.size} non-PD covariances)",
                 f"{'state':>12s} {'final':>14s} {'std':>12s}  unit"]
        var = np.diag(self.P[-1])
        for i, n in enumerate(self.state_names):
            sd = f"{np.sqrt(var[i]):12.4g}" if var[i] >= 0 else f"{'not PD':>12s}"
            lines.append(f"{n:>12s} {self.x[-1, i]:14.6g} {sd}  {self.state_units[i]}")
        return "\n".join(lines)

    def plot(self, ax=None, path=None, states=None, *, measured=None, t_measured=None):
        """Estimates with +-2 standard deviations over time, one panel per state.

        Angles and angular rates (states in rad, rad/s, ...) are drawn in degrees; axes carry the
        units. The vertical range covers the estimate, the measurements and the band wherever it is
        at most ten times its median width, so that a vague prior's band at the start does not
        flatten the rest of the record (the band is drawn whole).

        Parameters
        ----------
        ax : matplotlib Axes or sequence of Axes, optional
            Draw into these axes (one per state drawn) instead of a new figure.
        path : path, optional
            Also write the figure there (its suffix chooses the format: ``.png``, ``.pdf``,
            ``.svg``...; PNG without one).
        states : sequence of str, optional
            The states to draw (all by default).
        measured : mapping state -> array, optional
            Measurements of states to draw over the estimates (same units as the states).
        t_measured : array, optional
            Their time stamps (default: the result's).

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            The new figure; ``ax`` when given; the path when ``path`` is given (see
            :mod:`casship.plotting`).
        """
        from ..plotting import finish, panels, split_args

        ax, path = split_args(ax, path)
        names = list(self.state_names if states is None else states)
        unknown = [n for n in names if n not in self.state_names]
        if unknown:
            raise InputError(f"unknown state(s) {unknown}; states: {list(self.state_names)}")
        measured = dict(measured or {})
        unknown = [n for n in measured if n not in self.state_names]
        if unknown:
            raise InputError(f"measured: unknown state(s) {unknown}; states: {list(self.state_names)}")
        t_meas = self.t if t_measured is None else np.asarray(t_measured, dtype=float)
        idx = [self.state_names.index(n) for n in names]
        std = self.std
        given = ax
        fig, axes = panels(ax, len(names), 1, figsize=(7.5, 1.8 * len(names) + 0.8),
                           what=f"the plot of {len(names)} state(s)", sharex=True)
        for ax, name, i in zip(axes[:, 0], names, idx):
            angle = self.angle_states is not None and self.angle_states[i]
            unit = self.state_units[i] or "-"
            in_rad = angle or unit.split("/")[0] == "rad"
            scale, unit = (180 / np.pi, "deg" if angle else "deg" + unit[3:]) if in_rad else (1.0, unit)
            xv = np.unwrap(self.x[:, i]) if angle else self.x[:, i]
            xv, sv = scale * xv, scale * std[:, i]
            ax.fill_between(self.t, xv - 2 * sv, xv + 2 * sv, alpha=0.3, lw=0, label="+-2 std")
            ax.plot(self.t, xv, lw=1.0, label=self.estimator)
            shown = [xv]
            if name in measured:
                ym = np.asarray(measured[name], dtype=float)
                if angle:        # drawn on the branch of the estimate
                    ym = ym + 2 * np.pi * np.round((np.interp(t_meas, self.t, xv / scale) - ym) / (2 * np.pi))
                ax.plot(t_meas, scale * ym, ".", ms=2, label="measured")
                shown.append(scale * ym)
            narrow = sv <= 10 * np.nanmedian(sv)
            shown += [(xv - 2 * sv)[narrow], (xv + 2 * sv)[narrow]]
            values = np.concatenate(shown)
            values = values[np.isfinite(values)]
            if values.size:
                lo, hi = values.min(), values.max()
                pad = 0.05 * (hi - lo) or 0.05 * max(abs(hi), 1e-12)
                ax.set_ylim(lo - pad, hi + pad)
            ax.set_ylabel(f"{name} [{unit}]")
        labels = {}
        for ax in axes[:, 0]:
            for handle, label in zip(*ax.get_legend_handles_labels()):
                labels.setdefault(label, handle)
        axes[0, 0].legend(list(labels.values()), list(labels), loc="best", fontsize=8)
        axes[-1, 0].set_xlabel("t [s]")
        return finish(fig, given, path, dpi=120)

    def to_dataset(self) -> Dataset:
        """Estimates and their standard deviations (``<state>_std``) as a :class:`Dataset`."""
        cols = {n: self.x[:, i] for i, n in enumerate(self.state_names)}
        std = self.std
        cols.update({f"{n}_std": std[:, i] for i, n in enumerate(self.state_names)})
        units = dict(zip(self.state_names, self.state_units))
        units.update({f"{n}_std": u for n, u in units.items()})
        return Dataset(self.t, cols, units=units, meta={"estimator": self.estimator})

    # -- storage ------------------------------------------------------------------------------------
    def save(self, path) -> Path:
        """Write the result to ``path`` (numpy ``.npz``, no pickled objects); read back with :meth:`load`.

        Parameters
        ----------
        path : path
        """
        path = Path(path)
        meta = {k: list(getattr(self, k)) for k in _NAMES}
        meta["estimator"] = self.estimator
        with open(path, "wb") as fh:
            np.savez_compressed(fh, **{k: getattr(self, k) for k in _ARRAYS}, meta=np.array(json.dumps(meta)))
        return path

    @classmethod
    def load(cls, path) -> "FilterResult":
        """Read a result written by :meth:`save`.

        Parameters
        ----------
        path : path
        """
        try:
            f = np.load(Path(path), allow_pickle=False)
        except ValueError:          # numpy's answer to a file that is not .npy/.npz speaks of pickles
            raise InputError(f"{path}: not a saved FilterResult (not a numpy .npz file)") from None
        if not hasattr(f, "files"):
            raise InputError(f"{path}: not a saved FilterResult (a single .npy array, not an .npz archive)")
        with f:
            missing = [k for k in (*_ARRAYS, "meta") if k not in f.files]
            if missing:
                raise InputError(f"{path}: not a saved FilterResult (missing {missing})")
            meta = json.loads(str(f["meta"]))
            return cls(**{k: f[k] for k in _ARRAYS}, **{k: tuple(meta[k]) for k in _NAMES}, estimator=meta["estimator"])

    def replace(self, **changes) -> "FilterResult":
        """A copy with some fields replaced (checked like the constructor).

        Parameters
        ----------
        **changes
            Field name -> new value.
        """
        known = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise InputError(f"FilterResult has no field(s) {unknown}")
        return type(self)(**{**{k: getattr(self, k) for k in known}, **changes})
