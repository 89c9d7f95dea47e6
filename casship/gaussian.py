"""The Gaussian belief value (:class:`Gaussian`) and covariance input checking (:func:`as_cov`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from .errors import InputError, InputTypeError

__all__ = ["Gaussian", "as_cov"]


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
            raise InputTypeError(f"{name}: a mapping needs channel names")
        unknown = set(value) - set(names)
        if unknown:
            raise InputError(f"{name}: unknown channel name(s) {sorted(unknown)}; known: {list(names)}")
        missing = [c for c in names if c not in value]
        if missing:
            raise InputError(f"{name}: no variance given for channel(s) {missing}")
        value = [value[c] for c in names]
    m = np.asarray(value, dtype=float)
    if m.ndim == 0:
        m = np.eye(n) * float(m)
    elif m.ndim == 1:
        if m.size != n:
            raise InputError(f"{name}: expected {n} variances, got {m.size}")
        m = np.diag(m)
    if m.shape != (n, n):
        raise InputError(f"{name}: expected shape ({n}, {n}), got {m.shape}")
    label = (lambda i: repr(names[i])) if names is not None and len(names) == n else str   # noqa: E731
    if not np.all(np.isfinite(m)):
        i, j = (int(k) for k in np.argwhere(~np.isfinite(m))[0])
        raise InputError(f"{name}: contains non-finite entries: ({label(i)}, {label(j)}) is {m[i, j]}")
    if not np.allclose(m, m.T, rtol=1e-10, atol=1e-12 * np.abs(m).max(initial=0.0)):   # relative to the scale
        i, j = (int(k) for k in np.unravel_index(np.argmax(np.abs(m - m.T)), m.shape))
        raise InputError(f"{name}: matrix is not symmetric: entry ({label(i)}, {label(j)}) is {m[i, j]:.6g}, "
                         f"entry ({label(j)}, {label(i)}) is {m[j, i]:.6g}")
    m = 0.5 * (m + m.T)
    if n:
        _check_definite(m, name, label, allow_zero)
    return m


def _check_definite(m: np.ndarray, name: str, label, allow_zero: bool) -> None:
    """Raise unless ``m`` is positive semi-definite (definite unless ``allow_zero``), naming the channel.

    The test is on the correlation matrix, so it does not depend on the channels' units: a variance
    of 1e-12 rad^2/s^2 beside 6 m^2 is as definite as any other (a test relative to the largest
    eigenvalue would call such a diagonal singular).
    """
    d = np.diag(m).copy()
    if d.min() < 0:
        i = int(np.argmin(d))
        raise InputError(f"{name}: not positive semi-definite (the variance of {label(i)} is {d[i]:.3g}); "
                         "variances must be non-negative")
    zero = d <= 0
    if zero.any():
        i = int(np.argmax(zero))
        if not allow_zero:
            raise InputError(f"{name}: must be positive definite (the variance of {label(i)} is 0)")
        if np.any(m[zero] != 0):
            j = int(np.argmax(np.any(m[zero] != 0, axis=0)))
            raise InputError(f"{name}: not positive semi-definite ({label(i)} has variance 0 but covaries with "
                             f"{label(j)})")
    keep = ~zero
    if not keep.any():
        return
    scale = 1.0 / np.sqrt(d[keep])
    eig = np.linalg.eigvalsh(m[np.ix_(keep, keep)] * np.outer(scale, scale))   # correlations: unit-free
    tol = 1e-12 * max(1.0, float(keep.sum()))
    if eig.min() < -tol:
        raise InputError(f"{name}: not positive semi-definite (smallest eigenvalue of the correlation matrix "
                         f"{eig.min():.3g}); variances must be non-negative")
    if not allow_zero and eig.min() <= tol:
        raise InputError(f"{name}: must be positive definite (smallest eigenvalue of the correlation matrix "
                         f"{eig.min():.3g}: some channels are exactly correlated)")


def _in_units(value: float, std: float, unit: str) -> str:
    """``value +- std unit``, radians (and rad/s...) shown in degrees, as people read angles."""
    base, _, rest = (unit or "").partition("/")
    if base == "rad":
        value, std, unit = np.degrees(value), np.degrees(std), "deg" + (f"/{rest}" if rest else "")
    return f"{value:.4g} +- {std:.3g}" + (f" {unit}" if unit else "")


@dataclass(frozen=True)
class Gaussian:
    """A Gaussian belief ``N(mean, cov)``.

    Parameters
    ----------
    mean : array_like, shape (n,)
    cov : array_like, shape (n, n), or (n,) variances, or scalar
    names : sequence of str, optional
        What each entry is (state names, e.g. ``model.state_names``): the repr and :meth:`summary`
        speak of them.
    units : sequence of str, optional
        Their units (``tuple(v.unit for v in model.state_vars)``); radians are shown in degrees.

    Examples
    --------
    >>> import numpy as np
    >>> Gaussian([0.1745, 0.0], np.diag([1e-4, 1e-6]), names=("psi", "r"), units=("rad", "rad/s"))
    Gaussian(psi = 9.998 +- 0.573 deg, r = 0 +- 0.0573 deg/s)
    """

    mean: np.ndarray
    cov: np.ndarray
    names: tuple = ()
    units: tuple = ()

    def __post_init__(self):
        mean = np.asarray(self.mean, dtype=float).reshape(-1)
        if not np.all(np.isfinite(mean)):
            i = int(np.flatnonzero(~np.isfinite(mean))[0])
            raise InputError(f"Gaussian: mean contains non-finite entries: entry {i} is {mean[i]}")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "cov", as_cov(self.cov, mean.size, "Gaussian covariance"))
        for key in ("names", "units"):
            value = tuple(str(v) for v in (getattr(self, key) or ()))
            if value and len(value) != mean.size:
                raise InputError(f"Gaussian: {len(value)} {key} {list(value)} for a mean of size {mean.size}")
            object.__setattr__(self, key, value)

    def _rows(self) -> list[str]:
        names = self.names or tuple(f"x[{i}]" for i in range(self.mean.size))
        units = self.units or ("",) * self.mean.size
        return [f"{n} = {_in_units(m, s, u)}" for n, m, s, u in zip(names, self.mean, self.std, units)]

    def __repr__(self) -> str:
        rows = self._rows()
        if len(rows) > 6:
            rows = rows[:5] + [f"... {len(rows) - 5} more"]
        return f"{type(self).__name__}({', '.join(rows)})"

    def summary(self) -> str:
        """Mean and standard deviation per entry (angles in degrees) and the correlations.

        Returns
        -------
        str
        """
        rows = [f"Gaussian belief over {self.mean.size} entries (mean +- standard deviation)"]
        rows += [f"  {r}" for r in self._rows()]
        std = self.std
        if self.mean.size > 1 and np.all(std > 0):
            corr = self.cov / np.outer(std, std)
            names = self.names or tuple(f"x[{i}]" for i in range(self.mean.size))
            pairs = [(abs(corr[i, j]), names[i], names[j], corr[i, j]) for i in range(len(names))
                     for j in range(i + 1, len(names)) if abs(corr[i, j]) >= 0.5]
            for _, a, b, c in sorted(pairs, reverse=True)[:10]:
                rows.append(f"  correlation {a}, {b}: {c:+.3f}")
        return "\n".join(rows)

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
