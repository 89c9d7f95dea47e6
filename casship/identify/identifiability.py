"""Which parameters the records can determine, before fitting: Fisher information analysis.

:meth:`~casship.identify.OutputErrorProblem.identifiability` (and the same method of
:class:`~casship.identify.MLEProblem`) evaluates the Fisher information of the free quantities at a
point (exact sensitivities of the outputs or innovations) and returns an :class:`Identifiability`
value. Model parameters are analysed in *relative* units: the information is scaled by each
parameter's magnitude (its value, or its typical scale when the value is 0), so an eigenvalue
``lam`` says that the data determine the direction to a relative standard error ``1 / sqrt(lam)``.
Initial states, biases and noise variances, whose values may sit near zero, are analysed in their
own units (magnitude 1).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from .uncertainty import covariance_from_information
from ..errors import InputError

__all__ = ["Identifiability", "MAX_REL_STD", "MAX_CORR", "MAX_RATIO", "RunEvidence"]

MAX_REL_STD = 0.5   # default: a parameter the data see has a relative standard error below this
MAX_CORR = 0.95     # pairs correlated beyond this are flagged
MAX_RATIO = 0.5     # prior-ratio rule: a quantity is admitted when its posterior/prior std is at most this


@dataclass
class RunEvidence:
    """What each run (or block of a run) contributes to the information, for run-level uncertainty.

    Parameters
    ----------
    labels : list of str
        One label per unit (a record, or a block of a record when there are few records).
    information : (n, k, k) array
        Each unit's Gauss-Newton information of the data cost (natural units).
    gradient : (n, k) array
        Each unit's gradient of the data cost at the point.
    prior_gradient : (k,) array
        Gradient of the prior's cost at the point (``P (theta - mu)``).
    kind : str
        ``"records"`` or ``"blocks"`` (how the units were formed).
    fixed_information, fixed_gradient : array, optional
        Evidence present in every replicate (e.g. captive tests joined to the runs): added to each
        leave-one-unit-out estimate, never left out.
    """

    labels: list
    information: np.ndarray
    gradient: np.ndarray
    prior_gradient: np.ndarray
    kind: str = "records"
    fixed_information: np.ndarray | None = None
    fixed_gradient: np.ndarray | None = None

    def __post_init__(self):
        self.labels = list(self.labels)
        self.information = np.asarray(self.information, dtype=float)
        self.gradient = np.asarray(self.gradient, dtype=float)
        self.prior_gradient = np.asarray(self.prior_gradient, dtype=float).reshape(-1)
        n, k = self.gradient.shape
        if self.information.shape != (n, k, k) or len(self.labels) != n or self.prior_gradient.size != k:
            raise InputError(f"RunEvidence: {len(self.labels)} labels, information {self.information.shape}, "
                             f"gradient {self.gradient.shape}, prior_gradient {self.prior_gradient.shape}")
        if n < 3:
            raise InputError(f"RunEvidence: a jackknife needs at least 3 units, got {n}")
        self.fixed_information = (np.zeros((k, k)) if self.fixed_information is None
                                  else np.asarray(self.fixed_information, dtype=float))
        self.fixed_gradient = np.zeros(k) if self.fixed_gradient is None else np.asarray(self.fixed_gradient, dtype=float)


def _marginals(S: np.ndarray, names):
    cov, _ = covariance_from_information(S, names)
    with np.errstate(invalid="ignore", divide="ignore"):
        std = np.sqrt(np.diag(cov))
        corr = cov / np.outer(std, std)
    return std, corr


@dataclass
class Identifiability:
    """Fisher-information analysis of a problem's free quantities at a point.

    Made by :meth:`~casship.identify.IdentificationProblem.identifiability`.

    Parameters
    ----------
    names : list of str
        The free quantities.
    at : dict
        The point (name -> value) the information was evaluated at.
    magnitudes : (k,) array
        The magnitudes that make the analysis relative (``|value|``, or the scale when it is 0).
    information : (k, k) array
        Fisher information of the data in natural units (without the prior).
    prior_precision : (k,) array
        Precision of the prior on each quantity (0 without a prior); not in the analysis unless
        asked (``with_prior=True`` in :meth:`propose`).
    max_rel_std, max_corr : float
        Thresholds of the report: quantities with ``rel_std`` above ``max_rel_std`` are reported as
        not seen by the data, pairs with ``|correlation|`` above ``max_corr`` as correlated.
    evidence : RunEvidence, optional
        Each run's share of the information and gradient: :meth:`propose` with ``evidence="runs"``
        judges a set by the spread of its leave-one-unit-out estimates (a linearised jackknife).
    kinds : list of str, optional
        Kind of each quantity (``param``, ``x0``, ``bias_in``, ``bias_out``, ``Q``, ``R``): by
        default :meth:`propose` chooses among the parameters and keeps the others.
    confounded : dict, optional
        Port/starboard asymmetry quantities the records cannot tell from the turning dynamics (no
        mirror pair, see :mod:`casship.identify.asymmetry`), with the reason; :meth:`propose` never
        chooses or keeps them.

    Attributes
    ----------
    eigenvalues : (k,) array
        Eigenvalues of the relative information, largest first.
    eigenvectors : (k, k) array
        The directions (columns, unit length, in relative units).
    sensitivity : (k,) array
        ``sqrt`` of the relative information's diagonal: ``1 / sensitivity`` is the relative standard
        error a quantity would have if it were the only one free.
    rel_std : (k,) array
        Relative standard error of each quantity with all of them free (``inf``: not seen).
    correlation : (k, k) array
        Correlation of the estimates with all of them free.
    """

    names: list
    at: dict
    magnitudes: np.ndarray
    information: np.ndarray
    prior_precision: np.ndarray
    eigenvalues: np.ndarray = field(init=False)
    eigenvectors: np.ndarray = field(init=False)
    sensitivity: np.ndarray = field(init=False)
    rel_std: np.ndarray = field(init=False)
    correlation: np.ndarray = field(init=False)
    max_rel_std: float = MAX_REL_STD
    max_corr: float = MAX_CORR
    kinds: list = None
    confounded: dict = field(default_factory=dict)
    evidence: RunEvidence | None = None

    def __post_init__(self):
        self.names = list(self.names)
        self.kinds = list(self.kinds) if self.kinds is not None else ["param"] * len(self.names)
        S = self._relative(with_prior=False)
        lam, vec = np.linalg.eigh(S)
        order = np.argsort(-lam)
        self.eigenvalues, self.eigenvectors = lam[order], vec[:, order]
        for j in range(vec.shape[1]):            # sign convention: largest loading positive
            i = np.argmax(np.abs(self.eigenvectors[:, j]))
            self.eigenvectors[:, j] *= np.sign(self.eigenvectors[i, j]) or 1.0
        self.sensitivity = np.sqrt(np.clip(np.diag(S), 0, None))
        self.rel_std, self.correlation = _marginals(S, self.names)

    def _relative(self, with_prior: bool, idx=None) -> np.ndarray:
        M = self.magnitudes if idx is None else self.magnitudes[idx]
        info = self.information if idx is None else self.information[np.ix_(idx, idx)]
        S = info * np.outer(M, M)
        if with_prior:
            S = S + np.diag((self.prior_precision if idx is None else self.prior_precision[idx]) * M**2)
        return 0.5 * (S + S.T)

    # -- findings --------------------------------------------------------------------------------
    @property
    def correlated(self) -> list[tuple[str, str, float]]:
        """Pairs ``(a, b, rho)`` with ``|rho|`` above :attr:`max_corr`."""
        out = []
        k = len(self.names)
        for i in range(k):
            for j in range(i + 1, k):
                rho = self.correlation[i, j]
                if np.isfinite(rho) and abs(rho) > self.max_corr:
                    out.append((self.names[i], self.names[j], float(rho)))
        return out

    @property
    def not_seen(self) -> list[str]:
        """Quantities whose relative standard error (all free) exceeds :attr:`max_rel_std` (own units for
        initial states, biases and noise)."""
        return [n for n, s in zip(self.names, self.rel_std) if not (np.isfinite(s) and s <= self.max_rel_std)]

    def direction(self, j: int, top: int = 4) -> str:
        """Eigen-direction ``j`` as text, e.g. ``"+0.71*N_r_dash -0.70*Y_r_dash"``.

        Parameters
        ----------
        j : int
            Index of the direction (0: best determined).
        top : int
            Number of loadings shown.
        """
        v = self.eigenvectors[:, j]
        order = np.argsort(-np.abs(v))[:top]
        return " ".join(f"{v[i]:+.2f}*{self.names[i]}" for i in order if abs(v[i]) > 0.05)

    def propose(self, *, max_rel_std: float | None = None, max_corr: float | None = None,
                candidates: Sequence[str] | None = None, keep: Sequence[str] | None = None,
                with_prior: bool = False, max_ratio: float | None = None, max_count: int | None = None,
                after: dict | None = None, evidence: str = "fisher", explain: bool = False):
        """A free set chosen by a stated criterion: greedy D-optimal forward selection.

        Starting from ``keep``, add one at a time the candidate that most increases the determinant of
        the information of the set, among those that pass the rule; stop when none qualifies (or at
        ``max_count``). Two rules:

        * ``max_ratio=None`` (relative rule): every candidate in the set has a relative standard
          error at most ``max_rel_std``, no pair correlated beyond ``max_corr``.
        * ``max_ratio`` given (prior-ratio rule; every candidate needs a prior): in prior-normalised
          units (``P`` the prior covariance) the set's posterior covariance is ``C = (I + P^1/2 F
          P^1/2)^-1``; every chosen quantity has a posterior/prior standard deviation
          ``sqrt(C_ii) <= max_ratio`` and no two are correlated beyond ``max_corr``. With
          ``evidence="runs"`` the standard deviation is the larger of ``sqrt(C_ii)`` and the
          run-level one: the spread of the leave-one-unit-out MAP estimates (one Gauss-Newton step
          from the point without that unit, :attr:`evidence`), ``C_jack = (n - 1) / n sum (d_u -
          mean)(d_u - mean)'``. A quantity the runs pull different ways fails however much
          information the model says they hold.

        Quantities flagged in :attr:`confounded` are never chosen.

        Parameters
        ----------
        max_rel_std, max_corr : float, optional
            Thresholds of the relative rule (default: the value's own); ``max_corr`` serves both.
        candidates : sequence of str, optional
            Quantities to choose from (default: the model parameters not in ``keep``).
        keep : sequence of str, optional
            Quantities always free; they enter the information of the set but not the criteria
            (default: the quantities that are not model parameters: initial states, biases, noise).
        with_prior : bool
            Relative rule: count the prior's precision as information (the prior-ratio rule always does).
        max_ratio : float, optional
            Use the prior-ratio rule with this threshold (:data:`MAX_RATIO` is the usual 0.5).
        max_count : int, optional
            At most this many candidates.
        after : dict, optional
            Candidate -> candidates it waits for: considered only when none of those can be added.
        evidence : {"fisher", "runs"}
            Prior-ratio rule: the model-based information alone, or with the run-level spread
            (needs :attr:`evidence`).
        explain : bool
            Also return one row per candidate: why it was chosen or not.

        Returns
        -------
        list of str, or (list of str, list of dict) with ``explain``
            ``keep`` followed by the chosen candidates in the order they were added.

        Examples
        --------
        >>> idf = problem.identifiability()          # doctest: +SKIP
        >>> free = idf.propose(max_rel_std=0.2)      # doctest: +SKIP
        """
        tol_s = self.max_rel_std if max_rel_std is None else float(max_rel_std)
        tol_c = self.max_corr if max_corr is None else float(max_corr)
        if evidence not in ("fisher", "runs"):
            raise InputError(f"evidence must be 'fisher' or 'runs', got {evidence!r}")
        if evidence == "runs" and (self.evidence is None or max_ratio is None):
            raise InputError("evidence='runs' needs max_ratio and the run-level evidence (Identifiability.evidence)")
        index = {n: i for i, n in enumerate(self.names)}
        if keep is None:
            keep = [n for n, k in zip(self.names, self.kinds) if k != "param"]
        if candidates is None:
            candidates = [n for n, k in zip(self.names, self.kinds) if k == "param"]
        keep = [n for n in keep if n not in self.confounded]
        candidates = [n for n in candidates if n not in self.confounded]
        after = dict(after or {})
        unknown = [n for n in (*keep, *candidates, *after, *(m for v in after.values() for m in v)) if n not in index]
        if unknown:
            raise InputError(f"unknown quantities {sorted(set(unknown))}; free: {self.names}")
        chosen = [index[n] for n in keep]
        fixed = set(chosen)
        pool = [index[n] for n in candidates if n not in keep]
        waits = {index[k]: [index[n] for n in v] for k, v in after.items()}
        if max_ratio is not None:
            prec = np.asarray(self.prior_precision, dtype=float)
            need = [self.names[i] for i in (*chosen, *pool) if not prec[i] > 0]
            if need:
                raise InputError(f"the prior-ratio rule needs a prior on every quantity; none on {need}")
            trial = self._ratio_trial(float(max_ratio), tol_c, fixed, evidence)
        else:
            trial = lambda S, c: self._relative_trial(S, c, tol_s, tol_c, with_prior, fixed)  # noqa: E731
        rows = []
        limit = len(pool) if max_count is None else int(max_count)
        while pool and len(chosen) - len(fixed) < limit:
            best = None
            for c in pool:
                val, ratio, corr = trial(chosen, c)
                if val is None or any(f in pool and trial(chosen, f)[0] is not None for f in waits.get(c, ())):
                    continue
                if best is None or val > best[0]:
                    best = (val, c, ratio, corr)
            if best is None:
                break
            chosen.append(best[1])
            pool.remove(best[1])
            rows.append({"quantity": self.names[best[1]], "chosen": True, "ratio_when_added": best[2],
                         "max_corr": best[3]})
        for c in pool:
            _, ratio, corr = trial(chosen, c)
            rows.append({"quantity": self.names[c], "chosen": False, "ratio_if_added": ratio, "max_corr_if_added": corr})
        for q, why in self.confounded.items():
            rows.append({"quantity": q, "chosen": False, "confounded": why})
        free = [self.names[i] for i in chosen]
        return (free, rows) if explain else free

    def _relative_trial(self, chosen, c, tol_s, tol_c, with_prior, fixed):
        idx = chosen + [c]
        S = self._relative(with_prior, idx)
        sign, logdet = np.linalg.slogdet(S)
        if sign <= 0:
            return None, np.inf, np.nan
        std, corr = _marginals(S, [self.names[i] for i in idx])
        cand = [j for j, i in enumerate(idx) if i not in fixed]
        sub = np.abs(corr[np.ix_(cand, cand)]) - np.eye(len(cand))
        worst = float(np.nanmax(sub)) if sub.size else 0.0
        if not np.all(np.isfinite(std[cand])) or np.max(std[cand]) > tol_s or worst > tol_c:
            return None, float(std[-1]), worst
        return float(logdet), float(std[-1]), worst

    def _ratio_trial(self, max_ratio, max_corr, fixed, evidence):
        s = 1.0 / np.sqrt(np.asarray(self.prior_precision, dtype=float))
        Fs = np.asarray(self.information, dtype=float) * np.outer(s, s)
        ev = self.evidence if evidence == "runs" else None
        if ev is not None:
            Fu = ev.information * np.outer(s, s)[None]
            gu = ev.gradient * s[None]
            b = ev.prior_gradient * s            # the prior's gradient in normalised units
            Fc, gc = ev.fixed_information * np.outer(s, s), ev.fixed_gradient * s

        def trial(chosen, c):
            S = chosen + [c]
            M = np.eye(len(S)) + Fs[np.ix_(S, S)]
            C = np.linalg.inv(M)
            var = np.diag(C).copy()
            if ev is not None:
                var = np.maximum(var, np.diag(_jackknife(Fu[:, S][:, :, S], gu[:, S], b[S], Fc[np.ix_(S, S)], gc[S])))
            d = np.sqrt(np.diag(C))
            cand = [j for j, i in enumerate(S) if i not in fixed]
            corr = np.abs(C / np.outer(d, d) - np.eye(len(S)))[np.ix_(cand, cand)]
            worst = float(corr.max()) if corr.size else 0.0
            ratio = np.sqrt(var)
            if ratio[cand].max() > max_ratio or worst > max_corr:
                return None, float(ratio[-1]), worst
            return float(np.linalg.slogdet(M)[1]), float(ratio[-1]), worst
        return trial

    # -- presentation ----------------------------------------------------------------------------
    def summary(self) -> str:
        """A plain-text report: directions, per-quantity sensitivities, flagged pairs, unseen quantities."""
        lines = [f"identifiability of {len(self.names)} free quantities (relative units)",
                 f"{'direction':>9s} {'eigenvalue':>11s} {'rel. std':>9s}  loadings"]
        for j, lam in enumerate(self.eigenvalues):
            s = 1 / np.sqrt(lam) if lam > 0 else np.inf
            lines.append(f"{j:>9d} {lam:>11.3g} {s:>9.3g}  {self.direction(j)}")
        lines.append(f"{'name':>16s} {'value':>11s} {'alone':>9s} {'all free':>9s}")
        for i, n in enumerate(self.names):
            alone = 1 / self.sensitivity[i] if self.sensitivity[i] > 0 else np.inf
            lines.append(f"{n:>16s} {self.at[n]:>11.4g} {alone:>9.3g} {self.rel_std[i]:>9.3g}")
        for a, b, rho in self.correlated:
            lines.append(f"correlated: {a} and {b} (rho = {rho:+.3f})")
        if self.not_seen:
            lines.append(f"not seen by the data (relative std error > {self.max_rel_std:g}): {', '.join(self.not_seen)}")
        for q, why in self.confounded.items():
            lines.append(f"confounded: {q}: {why}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"Identifiability({len(self.names)} quantities, {len(self.correlated)} correlated pair(s), "
                f"not seen: {self.not_seen})")

    def plot(self, ax=None, path=None):
        """Relative standard errors of the eigen-directions and of each quantity, and the loadings.

        Parameters
        ----------
        ax : sequence of three matplotlib Axes, optional
            Draw into these axes instead of a new figure.
        path : str or Path, optional
            Also write the figure there (PNG unless the suffix says otherwise).

        Returns
        -------
        matplotlib.figure.Figure, the axes given, or Path
            See :mod:`casship.plotting`.
        """
        from ..plotting import finish, panels, split_args

        ax, path = split_args(ax, path)
        given = ax
        k = len(self.names)
        fig, axes = panels(ax, 1, 3, figsize=(13, 0.35 * k + 2.5), what="the identifiability plot",
                           gridspec_kw={"width_ratios": [1, 1, 1.4]})
        axes = axes.ravel()
        lam = np.where(self.eigenvalues > 0, self.eigenvalues, np.nan)
        axes[0].barh(np.arange(k), 1 / np.sqrt(lam), color="C0")
        axes[0].set_xscale("log")
        axes[0].axvline(self.max_rel_std, color="C3", lw=1, ls="--")
        axes[0].set_yticks(np.arange(k), [f"dir {j}" for j in range(k)])
        axes[0].invert_yaxis()
        axes[0].set_xlabel("relative std error of direction [-]")
        rel = np.where(np.isfinite(self.rel_std), self.rel_std, np.nan)
        axes[1].barh(np.arange(k), rel, color="C1", label="all free")
        with np.errstate(divide="ignore"):
            axes[1].plot(1 / self.sensitivity, np.arange(k), "k|", ms=10, label="alone")
        axes[1].set_xscale("log")
        axes[1].axvline(self.max_rel_std, color="C3", lw=1, ls="--")
        axes[1].set_yticks(np.arange(k), self.names)
        axes[1].invert_yaxis()
        axes[1].set_xlabel("relative std error [-]")
        axes[1].legend(fontsize=7)
        im = axes[2].imshow(self.eigenvectors, cmap="RdBu_r", vmin=-1, vmax=1, aspect="auto")
        axes[2].set_xticks(np.arange(k), [str(j) for j in range(k)])
        axes[2].set_yticks(np.arange(k), self.names)
        axes[2].set_xlabel("direction (best determined first)")
        fig.colorbar(im, ax=axes[2], label="loading [-]")
        return finish(fig, given, path)


def _jackknife(Fu: np.ndarray, gu: np.ndarray, b: np.ndarray, Fc=0.0, gc=0.0) -> np.ndarray:
    """Jackknife covariance of the leave-one-unit-out MAP steps in prior-normalised units.

    ``Fu`` (n, k, k) and ``gu`` (n, k): each unit's information and data-cost gradient; ``b`` the
    prior's gradient; ``Fc``, ``gc`` evidence in every replicate. Without unit ``u`` the Gauss-Newton
    MAP step is ``-(I + F + F_c - F_u)^-1 (g + g_c - g_u + b)``.
    """
    n, k = gu.shape
    F, g = Fu.sum(axis=0) + Fc, gu.sum(axis=0) + gc
    steps = np.array([-np.linalg.solve(np.eye(k) + F - Fu[u], g - gu[u] + b) for u in range(n)])
    d = steps - steps.mean(axis=0)
    return (n - 1) / n * d.T @ d
