"""The estimator contract: one constructor, typed options and five verbs, whatever the algorithm.

:class:`Estimator` is the abstract base every estimator derives from (``docs/architecture.md``)::

    est = Est(dmodel, Q, R, *, measured=None, options=None)
    est.filter(data, prior, p=None, *, seed=None) -> FilterResult
    est.online(prior, p=None, *, u=None, seed=None) -> OnlineRun      # run.update(y, dt, u_prev, u)
    est.smooth(data, prior, p=None, *, seed=None) -> FilterResult
    est.predict(result, t, u=None, p=None, *, seed=None) -> FilterResult
    est.step                                                          # a casadi.Function, or a refusal

The constructor rule (a :class:`~casship.discretize.DiscreteModel`, the one meaning of ``Q`` and
``R``, measured outputs by name, typed options whose unknown keys raise) and the checks of records
and priors live here once. How an estimator does its work is its own: the recursive filters share
the step-based template :class:`~casship.estimators.base.StepEstimator` (one step Function with
named slots, folded over a record); the moving-horizon estimator solves a window problem per sample
and, having no step Function, refuses :attr:`step` with :class:`NoStepFunction`.
"""
from __future__ import annotations

import abc
import weakref
from typing import Sequence

import numpy as np
from scipy import stats

from ..data import Dataset
from ..discretize import DiscreteModel
from ..gaussian import Gaussian, as_cov
from ..validity import check_start
from .options import EstimatorOptions
from .result import FilterResult
from .update import residual

__all__ = ["Estimator", "NoStepFunction"]


class NoStepFunction(AttributeError):
    """An estimator without a step Function was asked for one (the message says why and what to use).

    An ``AttributeError``, so ``hasattr(est, "step")`` is false for such an estimator.
    """


class Estimator(abc.ABC):
    """The contract of every estimator (abstract; see ``docs/architecture.md``).

    Parameters
    ----------
    dmodel : DiscreteModel
    Q : covariance of the process noise ``w`` (nw x nw; scalar, variances, matrix or name mapping),
        with the one meaning stated in ``docs/architecture.md``: the covariance of ``w`` held over
        a sampling interval; estimators in continuous time use the spectral density ``Q * dt``
    R : covariance of one sampled measurement of the measured outputs (same forms)
    measured : sequence of str, optional
        Output names that are measured (default: all outputs of the model).
    options : EstimatorOptions subclass or mapping, optional
        The estimator's typed options (``Est.Options``); an unknown key raises ``ValueError``.

    Notes
    -----
    Subclasses implement :meth:`filter`, :meth:`online`, :meth:`smooth`, :meth:`predict` and
    :attr:`step`, honour or refuse every option they accept (a refused option raises in the
    constructor, naming it), and are registered in ``casship.estimators.ESTIMATORS`` so that the
    conformance suite checks them. The traits ``continuous``, ``stochastic``, ``linear`` and
    ``has_step`` tell the suite what to expect.
    """

    name = "estimator"
    Options = EstimatorOptions
    continuous = False       # Q and R enter as spectral densities Q dt, R dt
    stochastic = False       # draws random numbers (reproducible with ``seed``)
    linear = False           # needs a model linear in states, inputs and noise
    has_step = True          # False: ``step`` raises NoStepFunction

    def __init__(self, dmodel: DiscreteModel, Q, R, *, measured: Sequence[str] | None = None, options=None):
        if not isinstance(dmodel, DiscreteModel):
            raise TypeError(f"{type(self).__name__} needs a DiscreteModel (use casship.discretize), "
                            f"got {type(dmodel).__name__}")
        model = dmodel.model
        self.dmodel, self.model = dmodel, model
        measured = tuple(model.output_names if measured is None else measured)
        unknown = [n for n in measured if n not in model.output_names]
        if unknown:
            raise ValueError(f"unknown measured output(s) {unknown}; outputs: {list(model.output_names)}")
        if not measured:
            raise ValueError("at least one output must be measured")
        twice = sorted({n for n in measured if measured.count(n) > 1})
        if twice:
            raise ValueError(f"measured output(s) {twice} given more than once (each sample would be used twice)")
        self.measured = measured
        self.meas_index = [model.index(n, "output") for n in measured]
        self.ny = len(measured)
        self.angle_meas = model.angle_outputs[self.meas_index]
        self.Q = as_cov(Q, model.nw, "Q", model.noise_names)
        self.R = as_cov(R, self.ny, "R", measured, allow_zero=False)
        self.options = self.Options.from_value(options, type(self).__name__)
        self._gate_cache: dict[int, float] = {}
        # the last record prepared (a Dataset is immutable: its arrays are reused while it lives) and the
        # starts already found finite: a filter run again on the same record skips both checks' work
        self._record: tuple | None = None
        self._finite_starts: dict[bytes, None] = {}
        self._check_options()

    def _check_options(self) -> None:
        """Checks of the options against the model (raise ``ValueError`` naming the option)."""

    # -- the five verbs ------------------------------------------------------------------------------
    @abc.abstractmethod
    def filter(self, data: Dataset, prior: Gaussian, p=None, *, seed=None) -> FilterResult:
        """Estimates over a whole record (filtered: each row uses the rows up to it).

        Parameters
        ----------
        data : Dataset
            Columns named like the model inputs (finite) and measured outputs (NaN = missing).
        prior : Gaussian
            Belief about the state at the first time stamp, before its measurement.
        p : array or mapping, optional
            Model parameters (nominal by default).
        seed : int or Generator, optional
            For stochastic estimators: fixes every draw.

        Returns
        -------
        FilterResult
        """

    @abc.abstractmethod
    def online(self, prior: Gaussian, p=None, *, u=None, seed=None):
        """A stateful runner on a stream (:class:`~casship.estimators.online.OnlineRun`), numbers equal
        to :meth:`filter` on the same record.

        Parameters
        ----------
        prior : Gaussian
            Belief about the state at the first sample.
        p : array or mapping, optional
            Model parameters (nominal by default).
        u : array, optional
            Inputs before the first update (zeros by default).
        seed : int or numpy.random.Generator, optional
            For stochastic estimators.
        """

    @abc.abstractmethod
    def smooth(self, data: Dataset, prior: Gaussian, p=None, *, seed=None) -> FilterResult:
        """Fixed-interval smoothing of a record (each row uses the whole record), or a ``ValueError``
        saying why the estimator has none.

        Parameters
        ----------
        data, prior, p, seed
            As for :meth:`filter`.
        """

    @abc.abstractmethod
    def predict(self, result: FilterResult, t, u=None, p=None, *, seed=None) -> FilterResult:
        """Predict past the last sample of ``result`` (nothing measured).

        Parameters
        ----------
        result : FilterResult
            A run of this estimator's model.
        t : float or array
            A horizon [s] or the times.
        u : mapping, array, optional
            Inputs over the prediction (default: the last input held).
        p : array or mapping, optional
        seed : int or Generator, optional
        """

    @property
    @abc.abstractmethod
    def step(self):
        """The step ``casadi.Function`` with named slots, or :class:`NoStepFunction` saying why there is
        none and what to use instead."""

    # -- records and priors: checked once for every estimator -------------------------------------------
    def gate_threshold(self, n_measured: int) -> float:
        """Chi-square threshold of the gate for ``n_measured`` scalar measurements (inf: no gate).

        Parameters
        ----------
        n_measured : int
        """
        if self.options.gate is None or n_measured == 0:
            return np.inf
        if n_measured not in self._gate_cache:
            self._gate_cache[n_measured] = float(stats.chi2.ppf(self.options.gate, n_measured))
        return self._gate_cache[n_measured]

    def prepare(self, data: Dataset, p=None) -> dict:
        """Check a record and turn it into named per-sample arrays (one column per sample).

        Parameters
        ----------
        data : Dataset
            Inputs (finite) and measured outputs (NaN = not measured).
        p : array or mapping, optional
            Model parameters (nominal by default).

        Returns
        -------
        dict
            ``u_prev, u, y, mask, dt, gate`` with one column per sample, and ``p, Q, R``.
        """
        if not isinstance(data, Dataset):
            raise TypeError(f"data must be a casship.Dataset, got {type(data).__name__}")
        cached = self._record
        if cached is not None and cached[0]() is data:
            arrays = cached[1]
        else:
            arrays = self._record_arrays(data)
            self._record = (weakref.ref(data), arrays)
        m = self.model
        return {**arrays, "p": m.params() if p is None else m.params(p), "Q": self.Q, "R": self.R}

    def _record_arrays(self, data: Dataset) -> dict:
        """The checks and per-sample arrays of :meth:`prepare` that depend on the record alone (read-only)."""
        m = self.model
        missing = [n for n in (*m.input_names, *self.measured) if n not in data]
        if missing:
            raise ValueError(f"data has no column(s) {missing} needed by {self.name} on {m.name!r}; "
                             f"columns: {list(data.names)}")
        U = data.matrix(m.input_names, finite=True, what="input")
        Y = data.matrix(self.measured)
        if np.isinf(Y).any():
            row, col = np.argwhere(np.isinf(Y))[0]
            raise ValueError(f"measurement {self.measured[col]!r} is infinite at row {row}")
        for j in np.flatnonzero(self.angle_meas):
            col = Y[:, j]
            big = np.abs(col[np.isfinite(col)])
            if big.size and big.max() > 2 * np.pi + 1e-9:
                raise ValueError(f"angle measurement {self.measured[j]!r} reaches {big.max():.4g}: "
                                 "angles are in radians (degrees given?)")
        dt = np.concatenate([[0.0], np.diff(data.t)])
        self.dmodel.check_steps(dt[1:], data.t)
        mask = np.isfinite(Y)
        maskf = mask.astype(float)
        if self.options.gate:                  # the threshold per number of measured channels
            thresholds = np.array([self.gate_threshold(c) for c in range(self.ny + 1)])
            gate = thresholds[(maskf @ np.ones(self.ny)).astype(np.intp)]
        else:
            gate = np.full(len(data), np.inf)
        arrays = {"u_prev": np.vstack([U[:1], U[:-1]]).T, "u": U.T, "y": np.where(mask, Y, 0.0).T,
                  "mask": maskf.T, "dt": dt[None, :], "gate": gate[None, :]}
        for a in arrays.values():
            a.setflags(write=False)
        return arrays

    def check_prior(self, prior: Gaussian) -> None:
        """Check a prior belief of the state: a :class:`~casship.Gaussian` of the model's size, angles in radians.

        Parameters
        ----------
        prior : Gaussian

        Raises
        ------
        TypeError
            Not a Gaussian.
        ValueError
            The wrong number of entries, or an angle's mean beyond 2 pi (degrees given?).
        """
        if not isinstance(prior, Gaussian):
            raise TypeError(f"prior must be a casship.Gaussian, got {type(prior).__name__}")
        if prior.mean.size != self.model.nx:
            raise ValueError(f"prior has {prior.mean.size} entries, model {self.model.name!r} has "
                             f"{self.model.nx} states {list(self.model.state_names)}")
        for i in np.flatnonzero(self.model.angle_states):
            if abs(prior.mean[i]) > 2 * np.pi + 1e-9:
                raise ValueError(f"prior mean of angle state {self.model.state_names[i]!r} is {prior.mean[i]:.4g}: "
                                 "angles are in radians (degrees given?)")

    def result(self, data: Dataset, arrays: dict, out: dict, estimator: str | None = None) -> FilterResult:
        """Assemble a :class:`FilterResult` from the per-sample diagnostics of a run.

        Parameters
        ----------
        data : Dataset
            The record.
        arrays : dict
            The record as prepared by :meth:`prepare`.
        out : dict
            Diagnostic name -> array indexed by sample (``x, P, x_pred, P_pred, C, e, S, K, nis, ll,
            accepted``).
        estimator : str, optional
            Name recorded in the result (default: the estimator's).
        """
        m, n = self.model, len(data)
        mask = arrays["mask"].T
        e = np.where(mask > 0, np.reshape(out["e"], (n, self.ny)), np.nan)
        e.setflags(write=False)                  # the result's own array: kept without a copy
        mat = lambda k, r, c: np.reshape(out[k], (n, r, c))  # noqa: E731
        nx, ny = m.nx, self.ny
        return FilterResult(
            t=data.t, x=np.reshape(out["x"], (n, nx)), P=mat("P", nx, nx), x_pred=np.reshape(out["x_pred"], (n, nx)),
            P_pred=mat("P_pred", nx, nx), C=mat("C", nx, nx), K=mat("K", nx, ny), innovations=e, S=mat("S", ny, ny),
            nis=np.reshape(out["nis"], n), n_measured=(mask @ np.ones(ny)).astype(int), loglik_terms=np.reshape(out["ll"], n),
            rejected=np.reshape(out["accepted"], n) < 0.5, inputs=arrays["u"].T, state_names=m.state_names,
            state_units=tuple(v.unit for v in m.state_vars), output_names=self.measured, input_names=m.input_names,
            estimator=estimator or self.name, angle_states=m.angle_states)

    def _check_start(self, prior: Gaussian, u, p) -> None:
        """Refuse a prior where the model's equations are not finite (e.g. an MMG ship at rest); ``u`` is
        the first input (None: not known yet)."""
        m = self.model
        if self.dmodel.discrete or u is None:
            return
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.size != m.nu or not np.all(np.isfinite(u)):
            return                                          # the callers name bad inputs
        p = m.params() if p is None else m.params(p)
        key = b"".join(np.ascontiguousarray(a, dtype=float).tobytes() for a in (prior.mean, u, p))
        if key in self._finite_starts:
            return
        unset = prior.defaulted() if hasattr(prior, "defaulted") else None
        check_start(m, prior.mean, u, p, what="the prior mean", unset=unset)
        if len(self._finite_starts) >= 16:                 # a few recent starts are enough
            self._finite_starts.clear()
        self._finite_starts[key] = None

    def residual(self, y, yhat, mask):
        """Masked residual of the measured outputs, angle channels wrapped.

        Parameters
        ----------
        y, yhat, mask : symbolic (ny,)
        """
        return residual(y, yhat, mask, self.angle_meas)

    def h_meas(self, x, u, p):
        """Symbolic measured outputs.

        Parameters
        ----------
        x, u, p : symbolic
        """
        return self.model.h(x, u, p)[self.meas_index]

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.model.name!r}, measured={list(self.measured)})"
