"""How far to trust a fit's standard errors: residual whiteness, effective sample size, sandwich.

Standard errors from the information matrix assume white residuals and a correct model. Real
records break both: model-structure error leaves slowly varying, strongly autocorrelated
residuals, and each sample then carries much less information than the matrix assumes.

* :func:`whiteness` -- Ljung-Box test per output channel (statistics summed over records).
* :func:`effective_samples` -- per channel, the number of independent samples the residuals are
  worth (record length over the integrated autocorrelation time).
* :func:`sandwich_covariance` -- the honest alternative used by casship: the Godambe information
  ``H B^-1 H`` (the sandwich ``H^-1 B H^-1`` inverted) plus the prior's precision, with ``H`` the
  information of the data and ``B`` the long-run covariance of the per-sample scores (gradient
  contributions), estimated with Bartlett weights and Andrews' (1991) AR(1)
  plug-in bandwidth (at most a quarter of the record), records independent. It is chosen over an effective-sample-size inflation
  because it is consistent under misspecification (White 1982), accounts for each parameter's own
  score autocorrelation (a channel-wide correction inflates all parameters alike), and combines
  channels and records correctly; the effective sample sizes are reported as a diagnostic.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy import stats

__all__ = ["ljung_box", "whiteness", "effective_samples", "sandwich_covariance", "covariance_from_information"]

COND_WARN = 1e-8       # smallest / largest eigenvalue of the normalised information matrix


def ljung_box(x, lags: int | None = None) -> tuple[float, int]:
    """Ljung-Box statistic of a residual sequence (NaN rows dropped) and its degrees of freedom.

    Parameters
    ----------
    x : array_like
        Residual sequence.
    lags : int, optional
        Number of lags (default ``min(20, N // 5)``).

    Returns
    -------
    (float, int)
        The statistic and the number of lags (0 when the sequence is too short or constant).
    """
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    n = x.size
    if n < 10:
        return 0.0, 0
    lags = int(lags or min(20, max(1, n // 5)))
    x = x - x.mean()
    denom = np.dot(x, x)
    if denom == 0:
        return 0.0, 0
    acf = np.array([np.dot(x[:-h], x[h:]) / denom for h in range(1, lags + 1)])
    q = n * (n + 2) * np.sum(acf**2 / (n - np.arange(1, lags + 1)))
    return float(q), lags


def whiteness(residuals: Sequence[np.ndarray], names: Sequence[str], alpha: float = 0.05) -> dict:
    """Ljung-Box test per output channel, statistics and degrees of freedom summed over records.

    Parameters
    ----------
    residuals : sequence of (N, ny) arrays
        Normalised residuals of each record (NaN = not measured).
    names : sequence of str
        Channel names.
    alpha : float
        Test level.

    Returns
    -------
    dict
        Per channel ``statistic``, ``dof``, ``p_value`` and ``white`` (p-value above ``alpha``).
    """
    out = {}
    for j, name in enumerate(names):
        q, dof = 0.0, 0
        for r in residuals:
            qi, di = ljung_box(r[:, j])
            q, dof = q + qi, dof + di
        p = float(stats.chi2.sf(q, dof)) if dof else float("nan")
        out[name] = {"statistic": q, "dof": dof, "p_value": p, "white": bool(dof and p > alpha)}
    return out


def _acf(x: np.ndarray, max_lag: int) -> np.ndarray:
    x = x - x.mean()
    n = x.size
    spec = np.fft.rfft(x, 2 * n)
    acov = np.fft.irfft(spec * np.conj(spec))[: max_lag + 1]
    return acov / acov[0] if acov[0] > 0 else np.zeros(max_lag + 1)


def effective_samples(residuals: Sequence[np.ndarray], names: Sequence[str]) -> dict:
    """Effective number of independent samples of each channel's residuals, summed over records.

    ``N / tau`` with ``tau = 1 + 2 sum rho_l`` over the initial positive sequence of the
    autocorrelation (Geyer 1992). White residuals give about ``N``.

    Parameters
    ----------
    residuals : sequence of (N, ny) arrays
        Residuals of each record (NaN = not measured; the measured samples are taken in order).
    names : sequence of str
        Channel names.

    Returns
    -------
    dict
        Per channel ``{"n": measured samples, "n_eff": effective samples, "tau": n / n_eff}``.
    """
    out = {}
    for j, name in enumerate(names):
        n, n_eff = 0, 0.0
        for r in residuals:
            x = r[:, j]
            x = x[np.isfinite(x)]
            if x.size < 4:
                n += x.size
                n_eff += x.size
                continue
            rho = _acf(x, min(x.size - 1, 2000))
            tau = 1.0
            for lag in range(1, rho.size - 1, 2):
                pair = rho[lag] + rho[lag + 1]
                if pair <= 0:
                    break
                tau += 2 * pair
            n += x.size
            n_eff += x.size / max(tau, 1.0)
        out[name] = {"n": int(n), "n_eff": float(n_eff), "tau": float(n / n_eff) if n_eff > 0 else float("inf")}
    return out


def _bandwidth(s: np.ndarray) -> int:
    """Andrews (1991) AR(1) plug-in bandwidth of the Bartlett kernel for the columns of ``s``."""
    n = s.shape[0]
    num = den = 0.0
    for a in range(s.shape[1]):
        x = s[:, a]
        x0, x1 = x[:-1], x[1:]
        d = np.dot(x0, x0)
        if d <= 0:
            continue
        rho = float(np.clip(np.dot(x0, x1) / d, -0.97, 0.97))
        sig2 = float(np.mean((x1 - rho * x0) ** 2))
        num += 4 * rho**2 * sig2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += sig2**2 / (1 - rho) ** 4
    alpha = num / den if den > 0 else 0.0
    # capped at a quarter of the record: the scores sum to zero at the optimum, so a bandwidth near
    # the record length would estimate a long-run variance near zero
    return int(min(n // 4, np.ceil(1.1447 * (alpha * n) ** (1 / 3))))


def sandwich_covariance(H: np.ndarray, prior_precision: np.ndarray, scores: Sequence[tuple[np.ndarray, np.ndarray]],
                        k: int, names: Sequence[str]):
    """Robust covariance from the Godambe (sandwich) information ``H B^-1 H``, plus the prior's precision.

    Without a prior this is the heteroscedasticity- and autocorrelation-consistent covariance
    ``H^-1 B H^-1``; with one, the posterior covariance with the data's curvature replaced by its
    robust counterpart. When the residuals are white and the model right, ``B = H`` and it equals
    the model-based covariance.

    Parameters
    ----------
    H : (k, k) array
        Information of the data (curvature of the data cost at the optimum).
    prior_precision : (k,) array
        Precision of the prior (0 without one).
    scores : sequence of (scores, cols)
        Per record the per-sample score contributions ``(N_r, k_r)`` and the positions ``cols`` of
        its free values among the ``k``; records are independent.
    k : int
        Number of free values.
    names : sequence of str
        Names of the free values (for warnings about singular directions).

    Returns
    -------
    (cov, lags)
        The covariance ``(k, k)`` (inf/NaN where the data do not determine a direction) and the
        Bartlett bandwidth used in each record.
    """
    B = np.zeros((k, k))
    lags = []
    for s, cols in scores:
        s = np.asarray(s, dtype=float)
        if s.size == 0:
            lags.append(0)
            continue
        L = _bandwidth(s)
        G = s.T @ s
        for lag in range(1, L + 1):
            w = 1.0 - lag / (L + 1.0)
            C = s[lag:].T @ s[:-lag]
            G += w * (C + C.T)
        B[np.ix_(cols, cols)] += G
        lags.append(L)
    d = np.sqrt(np.abs(np.diag(B)))
    d[d == 0] = 1.0
    Binv = np.linalg.pinv(B / np.outer(d, d), rcond=COND_WARN, hermitian=True) / np.outer(d, d)
    G = H @ Binv @ H + np.diag(prior_precision)
    return covariance_from_information(0.5 * (G + G.T), names)[0], lags


def covariance_from_information(info: np.ndarray, names: Sequence[str]):
    """Covariance of the estimates from an information matrix, tolerating singular directions.

    Parameters
    ----------
    info : (k, k) array
        Information matrix.
    names : sequence of str
        Names of the free quantities (for the warnings).

    Returns
    -------
    (cov, warnings)
        Directions with non-positive curvature get infinite variance in the parameters that load on
        them (and a warning naming them); the rest is the pseudo-inverse.
    """
    info = 0.5 * (info + info.T)
    k = info.shape[0]
    if k == 0:
        return np.zeros((0, 0)), []
    d = np.sqrt(np.abs(np.diag(info)))
    d[d == 0] = 1.0
    normed = info / np.outer(d, d)
    lam, vec = np.linalg.eigh(normed)
    tol = COND_WARN * max(lam.max(), 1e-300)
    good = lam > tol
    cov = ((vec[:, good] / lam[good]) @ vec[:, good].T) / np.outer(d, d)
    warnings = []
    for j in np.flatnonzero(~good):
        load = np.abs(vec[:, j])
        involved = [names[i] for i in np.flatnonzero(load > 0.3)]
        kind = "negative curvature (not a minimum)" if lam[j] < -tol else "a near-singular direction"
        order = np.argsort(-load)[:4]
        direction = " ".join(f"{vec[i, j]:+.2f}*{names[i]}" for i in order if load[i] > 0.05)
        warnings.append(f"information matrix has {kind} along {direction}: "
                        f"{', '.join(involved)} cannot be separated by the data")
        for i in np.flatnonzero(load > 0.3):
            cov[i, :] = cov[:, i] = np.nan
            cov[i, i] = np.inf
    return cov, warnings
