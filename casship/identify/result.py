"""The :class:`FitResult` value of an identification, and the errors and warnings of a fit.

Everything a user needs to judge and reuse a fit: estimates with standard errors (model-based and
robust), correlations, identifiability and solver warnings, the prior, each channel's share of the
cost, residual whiteness, and the identity of the model it belongs to (name, build options,
parameter set), so that a fit file replays on the model it was made for and refuses any other.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np
from scipy import stats

from ..errors import InputError, SolverError
from .fit_json import DICTS, LISTS, SCALARS, fit_fields, load_fit_json

__all__ = ["FitResult", "IdentificationError", "IdentificationWarning"]


class IdentificationError(SolverError):
    """An identification cannot proceed (e.g. a non-finite cost at the start); carries a ``status``.

    Parameters
    ----------
    message : str
        What went wrong and where.
    status : str
        Short machine-readable status (e.g. ``"nan"``).
    """

    def __init__(self, message: str, status: str):
        super().__init__(message)
        self.status = status


class IdentificationWarning(UserWarning):
    """A fit that is returned but should not be trusted as is (early stop, coloured residuals)."""


def _clean(value):
    """JSON-friendly copy (numpy to Python, non-finite floats to strings): :func:`casship.io.jsonfile.json_ready`."""
    from ..io.jsonfile import json_ready

    return json_ready(value)


@dataclass
class FitResult:
    """Result of an identification (a value: no reference to the problem that produced it).

    Parameters
    ----------
    model : str
        Name of the identified model (``casship.models.get_model(model, **model_options)`` rebuilds it).
    params : dict
        All model parameters for a *new* run: shared estimates, the other parameters (including
        per-record and per-group ones, see ``record_params``) at their fixed values.
    free : list of str
        The estimated quantities: parameters (``K``, per-record ``R_0_dash@2``, per-group
        ``N_0@HSVA``), biases ``bias[n]``, noise variances ``Q[w]`` / ``R[y]``, initial states ``psi@0``.
    estimates, std_errors : dict
        Estimate and standard error of each free quantity (``inf`` when the data cannot see it).
        With a prior, the standard errors are posterior standard deviations.
    correlation, covariance : (k, k) arrays ordered like ``free``
    cost : float
        Optimal cost (negative log-likelihood or half the weighted sum of squares, plus the prior's).
    loglik : float
        Log-likelihood of the data at the optimum (Gaussian).
    n_obs : int
        Number of scalar measurements used.
    aic, bic : float
    whiteness : dict
        Per output: Ljung-Box ``statistic``, ``dof``, ``p_value`` and ``white`` (at 5 %).
    warnings : list of str
        Solver, bound, identifiability and whiteness warnings.
    method, status : str
        ``"output-error"`` / ``"mle-ekf"``..., and the solver status (``converged``, ``stalled``,
        ``max_iterations``, ``nan``, or IPOPT's).
    iterations : int
    solve_time_s : float
    noise : dict
        Noise used at the optimum (``{"Q": {...}, "R": {...}}``, or the output-error ``sigma``).
    x0 : list of dict
        Initial state of each record (given or estimated).
    predictions : list of dict
        Per record a free-run simulation against the measured outputs, for :meth:`plot` (not in JSON).
    message : str
        The solver's explanation of its status.
    std_errors_robust : dict
        Heteroscedasticity- and autocorrelation-consistent (sandwich) standard errors: the honest
        ones when the residuals are not white (see :mod:`casship.identify.uncertainty`).
    effective_samples : dict
        Per output channel the measured and effective number of samples of the residuals.
    channel_share : dict
        ``{"start": {...}, "optimum": {...}}``: each channel's share of the weighted squared residuals.
    prior : dict
        ``{"weight", "quantities": {name: {"mean", "std"}}}`` of a MAP fit (empty without a prior).
    records : list of str
        Record labels.
    record_params : list of dict
        Per record, the parameters and biases that differ from ``params`` (its own copies).
    model_options : dict
        Options the model was built with (``model.meta["options"]``).
    param_set : str
        The vessel's parameter-set identity (``model.vessel.param_set``).
    param_names : list of str
        The model's parameter names.
    covariance_robust : (k, k) array
        The robust (sandwich) covariance of the free quantities, ordered like ``free``.
    param_covariance : dict
        The uncertainty a fit file carries for replays (see :meth:`uncertainty`), when it was set
        explicitly (e.g. a run-level jackknife); empty: the robust covariance of the shared free
        model parameters.
    verdict : dict
        The fit replayed on its records against the model it started from (and left-one-out):
        ``verdict`` (``"better"``, ``"no better"``, ``"worse"``, ``"stalled"``, ``"not judged"``),
        ``reason``, the heading RMSE per record of start and fit, ``loo`` (see
        :func:`casship.identify.verdict.judge`). Empty: not judged (``solve(verdict=None)``).
    model_discrepancy : dict
        ``psi_variance_growth_deg2_per_s``: the heading variance growing as ``q t`` that the parameter
        band misses, estimated from the fit's own runs (left-one-out when several) and how
        (``method``); replays of the fit file add it to the parameter band (the predictive band).
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
    message: str = ""
    std_errors_robust: dict = field(default_factory=dict)
    effective_samples: dict = field(default_factory=dict)
    channel_share: dict = field(default_factory=dict)
    prior: dict = field(default_factory=dict)
    records: list = field(default_factory=list)
    record_params: list = field(default_factory=list)
    model_options: dict = field(default_factory=dict)
    param_set: str = ""
    param_names: list = field(default_factory=list)
    covariance_robust: np.ndarray = None
    param_covariance: dict = field(default_factory=dict)
    verdict: dict = field(default_factory=dict)
    model_discrepancy: dict = field(default_factory=dict)

    # -- queries -----------------------------------------------------------------------------------
    @property
    def converged(self) -> bool:
        """Whether the solver met its convergence test."""
        return self.status in ("converged", "Solve_Succeeded", "Solved_To_Acceptable_Level")

    def interval(self, name: str, level: float = 0.95, *, robust: bool = False) -> tuple[float, float]:
        """Symmetric normal confidence interval of a free quantity.

        Parameters
        ----------
        name : str
            A free quantity.
        level : float
            Coverage probability.
        robust : bool
            Use the sandwich standard error (:attr:`std_errors_robust`).

        Returns
        -------
        (float, float)
        """
        if name not in self.estimates:
            raise InputError(f"{name!r} was not estimated; free: {self.free}")
        se = (self.std_errors_robust if robust else self.std_errors)[name]
        z = stats.norm.ppf(0.5 + level / 2)
        return self.estimates[name] - z * se, self.estimates[name] + z * se

    def uncertainty(self, kind: str | None = None):
        """The uncertainty of the model parameters a new run is replayed with.

        Parameters
        ----------
        kind : {None, "model", "robust"}
            ``None``: :attr:`param_covariance` when set, else the robust covariance; ``"model"``,
            ``"robust"``: the model-based or robust (sandwich) covariance of the free model
            parameters shared by all records (per-record and per-group copies and biases are not
            part of a new run's parameters).

        Returns
        -------
        ParameterBelief or None
            None when no shared model parameter is free; it carries the fit's model discrepancy
            (``psi_variance_rate``).
        """
        from .belief import ParameterBelief

        q = float(np.radians(np.radians(self.model_discrepancy.get("psi_variance_growth_deg2_per_s", 0.0) or 0.0)))
        if kind is None and self.param_covariance:
            return dataclasses.replace(ParameterBelief.from_dict(self.param_covariance, "this fit"), psi_variance_rate=q)
        if kind not in (None, "model", "robust"):
            raise InputError(f"kind must be None, 'model' or 'robust', got {kind!r}")
        robust = kind != "model" and self.covariance_robust is not None
        C = np.asarray(self.covariance_robust if robust else self.covariance, dtype=float)
        idx = [i for i, n in enumerate(self.free) if n in self.params and "@" not in n]
        if not idx:
            return None
        names = [self.free[i] for i in idx]
        return ParameterBelief.from_values(names, [self.estimates[n] for n in names], C[np.ix_(idx, idx)],
                                           "robust (sandwich)" if robust else "model-based", psi_variance_rate=q,
                                           kind="robust" if robust else "model-based")

    def record_parameters(self, record: int) -> dict:
        """All model parameters of one fitted record (its own per-record and per-group copies applied).

        Parameters
        ----------
        record : int
            Record index.

        Returns
        -------
        dict
        """
        own = self.record_params[record] if self.record_params else {}
        return {**self.params, **{k: v for k, v in own.items() if k in self.params}}

    def apply_to(self, model) -> np.ndarray:
        """The parameter vector of ``model`` with this fit's :attr:`params`.

        Parameters
        ----------
        model : Model
            The model to replay with; it must be the fitted model (same name and parameter set).

        Returns
        -------
        (np,) array

        Raises
        ------
        ValueError
            Naming both models (or both parameter sets) when they differ.
        """
        from .params_file import check_model

        return check_model(model, self.params, name=self.model, options=self.model_options,
                           param_set=self.param_set, source=f"this {self.method} fit")

    def summary(self) -> str:
        """A plain-text report: estimates, standard errors, prior, channel shares, warnings."""
        on = (", ".join(self.records) if self.records and all(r.startswith("captive:") for r in self.records)
              else f"{len(self.records) or '?'} record(s)")        # captive tests are named by their facility
        lines = [f"{self.method} fit of {self.model!r} on {on}: cost {self.cost:.6g}, "
                 f"status {self.status}, {self.iterations} iterations, {self.solve_time_s:.2f} s"]
        if self.message:
            lines.append(f"  ({self.message})")
        q = self.prior.get("quantities", {}) if self.prior else {}
        lines.append(f"{'name':>16s} {'estimate':>13s} {'std error':>11s} {'robust':>11s} {'rel':>8s}  prior")
        for n in self.free:
            v, s = self.estimates[n], self.std_errors[n]
            rel = abs(s / v) if v else np.inf
            pr = f"N({q[n]['mean']:.4g}, {q[n]['std']:.3g}^2)" if n in q else "-"
            # a standard error a million times its estimate is written in g format, not in 90 digits
            rel_text = f"{rel:>8.2%}" if rel < 1e4 else f"{100 * rel:>7.2g}%"
            lines.append(f"{n:>16s} {v:>13.6g} {s:>11.4g} {self.std_errors_robust.get(n, np.nan):>11.4g} "
                         f"{rel_text}  {pr}")
        if self.prior:
            lines.append(f"prior weight {self.prior.get('weight', 1.0):g} (MAP: standard errors are posterior)")
        for when, shares in (self.channel_share or {}).items():
            lines.append(f"channel share at {when}: " + ", ".join(f"{n} {s:.1%}" for n, s in shares.items()))
        lines.append(f"AIC {self.aic:.6g}  BIC {self.bic:.6g}  n_obs {self.n_obs}")
        lines += [f"warning: {w}" for w in self.warnings]
        lines += self._verdict_lines()
        return "\n".join(lines)

    @property
    def worse(self) -> bool:
        """Whether the fit's verdict is ``"worse"`` or ``"stalled"`` (not to be used as a better model)."""
        return self.verdict.get("verdict") in ("worse", "stalled")

    def _verdict_lines(self) -> list[str]:
        v = self.verdict
        if not v:
            return []
        lines = []
        rows = v.get("records", [])
        if rows:
            w = max(24, *(len(str(r["record"])) for r in rows))        # whole names: records differ at their start
            lines.append(f"{'replayed record':>{w}s} {'start psi RMSE':>15s} {'fit psi RMSE':>13s}"
                         + (f" {'left-one-out':>13s}" if "loo" in v else ""))
            held = {r["record"]: r["psi_rmse_deg_held_out"] for r in v.get("loo", {}).get("records", [])}
            for r in rows:
                lines.append(f"{str(r['record']):>{w}s} {r['psi_rmse_deg_start']:>11.3f} deg "
                             f"{r['psi_rmse_deg_fit']:>9.3f} deg"
                             + (f" {held.get(r['record'], np.nan):>9.3f} deg" if held else ""))
        d = self.model_discrepancy
        if d:
            lines.append(f"model discrepancy q = {d.get('psi_variance_growth_deg2_per_s', 0.0):.4g} deg^2/s "
                         f"({d.get('method', '')})")
        word = v.get("verdict", "")
        head = {"worse": "VERDICT: WORSE than its start", "stalled": "VERDICT: STALLED"}.get(word, f"verdict: {word}")
        lines.append(f"{head}: {v.get('reason', '')}")
        if word in ("worse", "stalled"):
            lines.append("  do not use this fit as an improved model (see docs/identification.md, the verdict)")
        return lines

    def __str__(self) -> str:
        return self.summary()

    # -- JSON --------------------------------------------------------------------------------------
    _SCALARS, _DICTS, _LISTS = SCALARS, DICTS, LISTS

    def to_dict(self) -> dict:
        """The fit as a JSON-friendly dict (everything but the predictions)."""
        d = {"model": self.model, "params": self.params, "free": list(self.free), "estimates": self.estimates,
             "std_errors": self.std_errors, "correlation": self.correlation, "covariance": self.covariance}
        if self.covariance_robust is not None:
            d["covariance_robust"] = self.covariance_robust
        d.update({k: getattr(self, k) for k in (*self._SCALARS, *self._DICTS, *self._LISTS)})
        try:
            unc = self.uncertainty()
        except ValueError:          # a covariance that is not finite is not carried
            unc = None
        d["param_covariance"] = unc.to_dict() if unc is not None else {}
        return _clean(d)

    def to_json(self, path) -> Path:
        """Write the fit as JSON (``casship simulate MODEL --params`` reads it).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        from ..io.jsonfile import write_json

        path = Path(path)
        write_json(path, self.to_dict(), what="fit file")
        return path

    @classmethod
    def from_dict(cls, d: Mapping) -> "FitResult":
        """A fit from :meth:`to_dict` output.

        Parameters
        ----------
        d : mapping

        Returns
        -------
        FitResult
        """
        return cls(**fit_fields(d))

    @classmethod
    def from_json(cls, path) -> "FitResult":
        """Read a fit written by :meth:`to_json`.

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        FitResult
        """
        path = Path(path)
        try:
            return cls.from_dict(load_fit_json(path))
        except ValueError as exc:
            text = str(exc)
            raise InputError(text if text.startswith(str(path)) else f"{path}: {text}") from None

    # -- plot --------------------------------------------------------------------------------------
    def plot(self, ax=None, path=None):
        """Measured outputs against the fitted model's free-run simulation, per record.

        Angles are shown in degrees. Rows are records, columns the measured outputs.

        Parameters
        ----------
        ax : matplotlib Axes or array of Axes, optional
            Draw into these axes (records x measured outputs of them) instead of a new figure.
        path : str or Path, optional
            Also write the figure there (PNG unless the suffix says otherwise).

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting`.
        """
        if not self.predictions:
            raise InputError("this FitResult holds no predictions (read from JSON?); nothing to plot")
        from ..plotting import finish, panels, split_args

        ax, path = split_args(ax, path)
        given = ax
        names = list(self.predictions[0]["measured"])
        nrec = len(self.predictions)
        fig, axes = panels(ax, nrec, len(names), figsize=(max(6.0, 3.4 * len(names) + 0.6), 1.9 * nrec + 0.8),
                           what="the fit plot (records x measured outputs)", sharex="row")
        for r, rec in enumerate(self.predictions):
            units, angle = rec.get("units", {}), rec.get("angle", {})
            for c, n in enumerate(names):
                ax = axes[r, c]
                conv = np.degrees if angle.get(n) else (lambda a: a)
                meas, pred = np.asarray(rec["measured"][n], float), np.asarray(rec["predicted"][n], float)
                if angle.get(n):
                    ok = np.isfinite(meas)
                    meas = np.where(ok, np.unwrap(np.where(ok, meas, 0.0)), np.nan)
                    pred = np.unwrap(pred) if np.all(np.isfinite(pred)) else pred
                    pred = pred + 2 * np.pi * np.round((np.nanmean(meas) - np.nanmean(pred)) / (2 * np.pi))
                ax.plot(rec["t"], conv(meas), ".", ms=1.5, color="0.55", label="measured")
                ax.plot(rec["t"], conv(pred), "-", lw=1.0, color="C0", label=rec.get("kind", "simulated"))
                unit = "deg" if angle.get(n) else units.get(n, "")
                ax.set_ylabel(f"{n} [{unit}]" if unit else n)
                if r == 0:
                    ax.set_title(n, fontsize=9)
                if c == 0:
                    ax.annotate(rec.get("label", f"record {r}"), (0.02, 0.9), xycoords="axes fraction", fontsize=7)
        for ax in axes[-1]:
            ax.set_xlabel("t [s]")
        axes[0, 0].legend(fontsize=7, loc="lower right")
        if given is None:
            fig.suptitle(f"{self.method} fit of {self.model}: measured vs free-run simulation", fontsize=10)
        return finish(fig, given, path, dpi=100)
