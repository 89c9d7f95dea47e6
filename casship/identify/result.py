"""The :class:`FitResult` value of an identification, and the diagnostics that fill it.

Everything a user needs to judge a fit: the estimates with standard errors from the information
matrix (the Hessian of the negative log-likelihood at the optimum), the correlation matrix,
identifiability warnings, AIC/BIC, a whiteness test of the normalised residuals and a plot of
measured against predicted outputs.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from scipy import stats

__all__ = ["FitResult", "IdentificationError", "covariance_from_information", "identifiability_warnings",
           "ljung_box"]

RHO_WARN = 0.95        # pairs correlated beyond this are reported
COND_WARN = 1e-8       # smallest / largest eigenvalue of the normalised information matrix
UNSEEN_FACTOR = 1e3    # std error beyond this many times the parameter's magnitude: data cannot see it


class IdentificationError(RuntimeError):
    """The optimiser of an identification problem did not converge (carries its ``status``)."""

    def __init__(self, message: str, status: str):
        super().__init__(message)
        self.status = status


def covariance_from_information(info: np.ndarray, names: Sequence[str]):
    """Covariance of the estimates from an information matrix, tolerating singular directions.

    Returns ``(cov, warnings)``. Directions with non-positive curvature get infinite variance in
    the parameters that load on them (and a warning); the rest is the pseudo-inverse.
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
    inv = (vec[:, good] / lam[good]) @ vec[:, good].T
    cov = inv / np.outer(d, d)
    warnings = []
    for j in np.flatnonzero(~good):
        load = np.abs(vec[:, j])
        involved = [names[i] for i in np.flatnonzero(load > 0.3)]
        kind = "negative curvature (not a minimum)" if lam[j] < -tol else "a near-singular direction"
        warnings.append(f"information matrix has {kind} along {_direction(vec[:, j], names)}: "
                        f"{', '.join(involved)} cannot be separated by the data")
        for i in np.flatnonzero(load > 0.3):
            cov[i, :] = cov[:, i] = np.nan
            cov[i, i] = np.inf
    return cov, warnings


def _direction(v: np.ndarray, names: Sequence[str]) -> str:
    order = np.argsort(-np.abs(v))[:4]
    return " ".join(f"{v[i]:+.2f}*{names[i]}" for i in order if abs(v[i]) > 0.05)


def identifiability_warnings(estimates: Mapping[str, float], std: Mapping[str, float], corr: np.ndarray,
                             names: Sequence[str], scale: Mapping[str, float]) -> list[str]:
    """Warnings on highly correlated pairs and on parameters the data cannot see."""
    out = []
    k = len(names)
    for i in range(k):
        for j in range(i + 1, k):
            rho = corr[i, j]
            if np.isfinite(rho) and abs(rho) > RHO_WARN:
                out.append(f"{names[i]} and {names[j]} are highly correlated (rho = {rho:+.3f})")
    for n in names:
        mag = max(abs(estimates[n]), abs(scale.get(n, 0.0)), 1e-12)
        if not np.isfinite(std[n]) or std[n] > UNSEEN_FACTOR * mag:
            out.append(f"the data do not determine {n}: standard error {std[n]:.3g} vs magnitude {mag:.3g}")
    return out


def ljung_box(x: np.ndarray, lags: int | None = None) -> tuple[float, int]:
    """Ljung-Box statistic of a residual sequence (NaN rows dropped) and its degrees of freedom."""
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
    """Ljung-Box test per output channel, statistics summed over records.

    ``residuals`` is a list (one per record) of (N, ny) normalised residuals (NaN = not measured).
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


def _clean(value):
    """JSON-friendly copy (numpy to Python, non-finite floats to strings)."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if np.isfinite(v) else ("nan" if np.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def _unclean(value):
    if isinstance(value, dict):
        return {k: _unclean(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_unclean(v) for v in value]
    if value in ("nan", "inf", "-inf"):
        return float(value)
    return value


@dataclass
class FitResult:
    """Result of an identification (a value: no reference to the problem that produced it).

    Attributes
    ----------
    model : str
        Name of the identified model.
    params : dict
        All model parameters (fitted ones at their estimates, the others at their fixed values);
        ``casship.models.get_model(name).params(fit.params)`` gives the vector.
    free : list of str
        Names of the estimated quantities: model parameters, noise variances ``Q[w]`` / ``R[y]``
        and initial states ``<state>@<record>``.
    estimates, std_errors : dict
        Estimate and standard error of each free quantity (``inf`` when the data cannot see it).
    correlation, covariance : (k, k) arrays ordered like ``free``
    cost : float
        Optimal objective (negative log-likelihood, or half the weighted sum of squares).
    loglik : float
        Log-likelihood at the optimum (Gaussian; for output error with the given weights).
    n_obs : int
        Number of scalar measurements used.
    aic, bic : float
    whiteness : dict
        Per output: Ljung-Box ``statistic``, ``dof``, ``p_value`` and ``white`` (at 5 %).
    warnings : list of str
        Identifiability and solver warnings.
    method, status : str
        ``"mle-ekf"``/``"output-error"``..., and the optimiser's return status.
    iterations : int
    solve_time_s : float
    noise : dict
        Process and measurement noise variances used at the optimum (``{"Q": {...}, "R": {...}}``).
    x0 : list of dict
        Initial state of each record (prior mean or estimate).
    predictions : list of dict
        Per record ``{"t", "measured": {name: array}, "predicted": {name: array}}`` for :meth:`plot`
        (not written to JSON).
    """

    model: str
    params: dict
    free: list
    estimates: dict
    std_errors: dict
    correlation: np.ndarray
    covariance: np.ndarray
    cost: float
    loglik: float
    n_obs: int
    aic: float
    bic: float
    whiteness: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    method: str = ""
    status: str = ""
    iterations: int = 0
    solve_time_s: float = 0.0
    noise: dict = field(default_factory=dict)
    x0: list = field(default_factory=list)
    predictions: list = field(default_factory=list, repr=False)

    # -- queries -----------------------------------------------------------------------------------
    def interval(self, name: str, level: float = 0.95) -> tuple[float, float]:
        """Symmetric normal confidence interval of a free quantity."""
        if name not in self.estimates:
            raise ValueError(f"{name!r} was not estimated; free: {self.free}")
        z = stats.norm.ppf(0.5 + level / 2)
        return self.estimates[name] - z * self.std_errors[name], self.estimates[name] + z * self.std_errors[name]

    def summary(self) -> str:
        """A plain-text table of the estimates."""
        lines = [f"{self.method} fit of {self.model!r}: cost {self.cost:.6g}, status {self.status}, "
                 f"{self.iterations} iterations, {self.solve_time_s:.2f} s",
                 f"{'name':>14s} {'estimate':>14s} {'std error':>12s} {'rel':>8s}"]
        for n in self.free:
            v, s = self.estimates[n], self.std_errors[n]
            rel = abs(s / v) if v else np.inf
            lines.append(f"{n:>14s} {v:>14.6g} {s:>12.4g} {rel:>8.2%}")
        lines.append(f"AIC {self.aic:.6g}  BIC {self.bic:.6g}  n_obs {self.n_obs}")
        lines += [f"warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    # -- JSON --------------------------------------------------------------------------------------
    _SCALARS = ("cost", "loglik", "n_obs", "aic", "bic", "method", "status", "iterations", "solve_time_s")

    def to_dict(self) -> dict:
        d = {"model": self.model, "params": self.params, "free": list(self.free), "estimates": self.estimates,
             "std_errors": self.std_errors, "correlation": self.correlation, "covariance": self.covariance}
        d.update({k: getattr(self, k) for k in self._SCALARS})
        d.update(whiteness=self.whiteness, warnings=self.warnings, noise=self.noise, x0=self.x0)
        return _clean(d)

    def to_json(self, path) -> Path:
        """Write the fit as JSON (key ``"params"`` is what ``casship simulate --params`` reads)."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=2))
        return path

    @classmethod
    def from_dict(cls, d: Mapping) -> "FitResult":
        d = _unclean(dict(d))
        missing = [k for k in ("model", "params", "free", "estimates", "std_errors") if k not in d]
        if missing:
            raise ValueError(f"fit JSON lacks key(s) {missing}")
        k = len(d["free"])
        mat = lambda key: np.asarray(d.get(key, np.full((k, k), np.nan)), dtype=float).reshape(k, k)  # noqa: E731
        kw = {key: d[key] for key in cls._SCALARS if key in d}
        return cls(model=d["model"], params={n: float(v) for n, v in d["params"].items()}, free=list(d["free"]),
                   estimates={n: float(v) for n, v in d["estimates"].items()},
                   std_errors={n: float(v) for n, v in d["std_errors"].items()},
                   correlation=mat("correlation"), covariance=mat("covariance"),
                   whiteness=d.get("whiteness", {}), warnings=list(d.get("warnings", [])),
                   noise=d.get("noise", {}), x0=d.get("x0", []),
                   **{**dict(cost=np.nan, loglik=np.nan, n_obs=0, aic=np.nan, bic=np.nan), **kw})

    @classmethod
    def from_json(cls, path) -> "FitResult":
        """Read a fit written by :meth:`to_json`."""
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc})") from None
        return cls.from_dict(d)

    # -- plot --------------------------------------------------------------------------------------
    def plot(self, path) -> Path:
        """Measured against predicted outputs of every record (PNG)."""
        if not self.predictions:
            raise ValueError("this FitResult holds no predictions (read from JSON?); nothing to plot")
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        names = list(self.predictions[0]["measured"])
        nrec = len(self.predictions)
        fig, axes = plt.subplots(len(names), nrec, figsize=(4.5 * nrec + 1, 2.2 * len(names) + 0.6),
                                 squeeze=False, sharex="col")
        for c, rec in enumerate(self.predictions):
            for r, n in enumerate(names):
                ax = axes[r, c]
                ax.plot(rec["t"], rec["measured"][n], ".", ms=2, color="0.55", label="measured")
                ax.plot(rec["t"], rec["predicted"][n], "-", lw=1.0, color="C0", label=rec.get("kind", "predicted"))
                ax.set_ylabel(n)
                if r == 0:
                    ax.set_title(rec.get("label", f"record {c}"), fontsize=9)
            axes[-1, c].set_xlabel("t [s]")
        axes[0, 0].legend(fontsize=7, loc="best")
        fig.suptitle(f"{self.method} fit of {self.model}", fontsize=10)
        fig.tight_layout()
        path = Path(path)
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return path


def finish(*, model: str, params: dict, names: Sequence[str], values: np.ndarray, info: np.ndarray,
           jac_nat: np.ndarray, scale: Mapping[str, float], cost: float, loglik: float, n_obs: int,
           residuals: Sequence[np.ndarray], output_names: Sequence[str], method: str, status: str,
           iterations: int, solve_time_s: float, noise: dict, x0: list, predictions: list,
           extra_warnings: Sequence[str] = ()) -> FitResult:
    """Assemble a :class:`FitResult` from the optimum and the information matrix in decision space.

    ``jac_nat`` is the diagonal of d(natural value)/d(decision variable), for the delta method.
    """
    names = list(names)
    cov_z, warn = covariance_from_information(info, names)
    with np.errstate(invalid="ignore"):
        cov = cov_z * np.outer(jac_nat, jac_nat)
        std_v = np.sqrt(np.diag(cov))
        corr = cov / np.outer(std_v, std_v)
    estimates = {n: float(v) for n, v in zip(names, values)}
    std = {n: float(s) for n, s in zip(names, std_v)}
    warn = list(extra_warnings) + warn + identifiability_warnings(estimates, std, corr, names, scale)
    k = len(names)
    return FitResult(model=model, params=dict(params), free=names, estimates=estimates, std_errors=std,
                     correlation=corr, covariance=cov, cost=float(cost), loglik=float(loglik), n_obs=int(n_obs),
                     aic=float(2 * k - 2 * loglik), bic=float(k * np.log(max(n_obs, 1)) - 2 * loglik),
                     whiteness=whiteness(residuals, output_names), warnings=warn, method=method, status=status,
                     iterations=int(iterations), solve_time_s=float(solve_time_s), noise=noise, x0=x0,
                     predictions=predictions)
