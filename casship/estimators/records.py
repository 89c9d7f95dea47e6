"""Records in, results out: the shared helpers that every estimator uses around its own algorithm.

:class:`Records` checks a record once for an estimator's model and measured outputs and turns it
into named per-sample arrays (one column per sample: ``u_prev, u, y, mask, dt, gate``), and
assembles the :class:`~casship.estimators.result.FilterResult` of a run from its per-sample
diagnostics. An estimator owns one (``est.records``) and calls it; the abstract contract itself
(:class:`~casship.estimators.contract.Estimator`) holds no record or result machinery, so an
estimator that does its work otherwise (a window solve per sample, a whole-record problem) is not
told how to shape its arrays.
"""
from __future__ import annotations

import weakref
from typing import Sequence

import numpy as np
from scipy import stats

from ..data import Dataset
from ..discretize import DiscreteModel
from ..errors import InputError, InputTypeError
from .result import FilterResult

__all__ = ["Records", "RESULT_DIAGNOSTICS"]

#: What :meth:`Records.result` needs per sample.
RESULT_DIAGNOSTICS = ("x", "P", "x_pred", "P_pred", "C", "e", "S", "K", "nis", "ll", "accepted")


class Records:
    """The record checks and result assembly for one estimator (its model, measured outputs and gate).

    Parameters
    ----------
    dmodel : DiscreteModel
    measured : sequence of str
        The measured outputs, in order.
    gate : float or None
        Probability of the chi-square innovation gate (None: no gate).
    name : str
        The estimator's name (in messages and results).
    """

    def __init__(self, dmodel: DiscreteModel, measured: Sequence[str], gate: float | None, name: str):
        self.dmodel, self.model, self.name = dmodel, dmodel.model, name
        self.measured = tuple(measured)
        self.ny = len(self.measured)
        self.angle_meas = self.model.angle_outputs[[self.model.index(n, "output") for n in self.measured]]
        self.gate = gate
        self._thresholds: dict[int, float] = {}
        # the last record prepared (a Dataset is immutable: its arrays are reused while it lives)
        self._last: tuple | None = None

    def gate_threshold(self, n_measured: int) -> float:
        """Chi-square threshold of the gate for ``n_measured`` scalar measurements (inf: no gate).

        Parameters
        ----------
        n_measured : int
        """
        if self.gate is None or n_measured == 0:
            return np.inf
        if n_measured not in self._thresholds:
            self._thresholds[n_measured] = float(stats.chi2.ppf(self.gate, n_measured))
        return self._thresholds[n_measured]

    def prepare(self, data: Dataset, p: np.ndarray) -> dict:
        """Check a record and turn it into named per-sample arrays (one column per sample).

        Parameters
        ----------
        data : Dataset
            Inputs (finite) and measured outputs (NaN or masked = not measured; infinite refused).
        p : array
            The parameter vector of the run.

        Returns
        -------
        dict
            ``u_prev, u, y, mask, dt, gate`` with one column per sample (read-only), and ``p``.
        """
        if not isinstance(data, Dataset):
            raise InputTypeError(f"data must be a casship.Dataset, got {type(data).__name__}")
        last = self._last
        if last is not None and last[0]() is data:
            arrays = last[1]
        else:
            arrays = self._arrays(data)
            self._last = (weakref.ref(data), arrays)
        return {**arrays, "p": p}

    def _arrays(self, data: Dataset) -> dict:
        """The checks and per-sample arrays of :meth:`prepare` that depend on the record alone."""
        m = self.model
        missing = [n for n in (*m.input_names, *self.measured) if n not in data]
        if missing:
            raise InputError(f"data has no column(s) {missing} needed by {self.name} on {m.name!r}; "
                             f"columns: {list(data.names)}")
        U = data.matrix(m.input_names, finite=True, what="input")
        Y = data.matrix(self.measured)
        if np.isinf(Y).any():
            row, col = np.argwhere(np.isinf(Y))[0]
            raise InputError(f"measurement {self.measured[col]!r} is infinite at row {row} "
                             "(NaN means not measured)")
        for j in np.flatnonzero(self.angle_meas):
            col = Y[:, j]
            big = np.abs(col[np.isfinite(col)])
            if big.size and big.max() > 2 * np.pi + 1e-9:
                raise InputError(f"angle measurement {self.measured[j]!r} reaches {big.max():.4g}: "
                                 "angles are in radians (degrees given?)")
        dt = np.concatenate([[0.0], np.diff(data.t)])
        self.dmodel.check_steps(dt[1:], data.t)
        mask = np.isfinite(Y)
        maskf = mask.astype(float)
        if self.gate:                          # the threshold per number of measured channels
            thresholds = np.array([self.gate_threshold(c) for c in range(self.ny + 1)])
            gate = thresholds[(maskf @ np.ones(self.ny)).astype(np.intp)]
        else:
            gate = np.full(len(data), np.inf)
        arrays = {"u_prev": np.vstack([U[:1], U[:-1]]).T, "u": U.T, "y": np.where(mask, Y, 0.0).T,
                  "mask": maskf.T, "dt": dt[None, :], "gate": gate[None, :]}
        for a in arrays.values():
            a.setflags(write=False)
        return arrays

    def result(self, data: Dataset, arrays: dict, out: dict, estimator: str | None = None) -> FilterResult:
        """Assemble a :class:`FilterResult` from the per-sample diagnostics of a run.

        Parameters
        ----------
        data : Dataset
            The record.
        arrays : dict
            The record as prepared by :meth:`prepare`.
        out : dict
            Diagnostic name -> array indexed by sample (:data:`RESULT_DIAGNOSTICS`).
        estimator : str, optional
            Name recorded in the result (default: the estimator's).
        """
        m, n, ny = self.model, len(data), self.ny
        mask = arrays["mask"].T
        e = np.where(mask > 0, np.reshape(out["e"], (n, ny)), np.nan)
        e.setflags(write=False)                  # the result's own array: kept without a copy
        mat = lambda k, r, c: np.reshape(out[k], (n, r, c))  # noqa: E731
        nx = m.nx
        return FilterResult(
            t=data.t, x=np.reshape(out["x"], (n, nx)), P=mat("P", nx, nx), x_pred=np.reshape(out["x_pred"], (n, nx)),
            P_pred=mat("P_pred", nx, nx), C=mat("C", nx, nx), K=mat("K", nx, ny), innovations=e, S=mat("S", ny, ny),
            nis=np.reshape(out["nis"], n), n_measured=(mask @ np.ones(ny)).astype(int), loglik_terms=np.reshape(out["ll"], n),
            rejected=np.reshape(out["accepted"], n) < 0.5, inputs=arrays["u"].T, state_names=m.state_names,
            state_units=tuple(v.unit for v in m.state_vars), output_names=self.measured, input_names=m.input_names,
            estimator=estimator or self.name, angle_states=m.angle_states)
