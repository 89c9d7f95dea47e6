"""The estimator contract: one constructor, typed options and four verbs, whatever the algorithm.

:class:`Estimator` is the abstract base every estimator derives from (``docs/estimators.md``)::

    est = Est(dmodel, Q, R, *, measured=None, options=None)
    est.filter(data, prior, p=None, *, seed=None) -> FilterResult
    est.online(prior, p=None, *, u=None, seed=None) -> OnlineRun      # run.update(y, dt, u_prev, u)
    est.smooth(data, prior, p=None, *, seed=None) -> FilterResult
    est.predict(result, t, u=None, p=None, *, seed=None) -> FilterResult
    est.options                                                       # the typed options

Nothing else is promised of every estimator. The constructor rule (a
:class:`~casship.discretize.DiscreteModel`, the one meaning of ``Q`` and ``R``, measured outputs by
name, typed options whose unknown keys raise) and the check of priors live here once; records are
checked and results assembled by the shared helper :class:`~casship.estimators.records.Records`
(``est.records``), and online samples by :func:`~casship.estimators.online.check_sample`. How an
estimator does its work is its own: the recursive filters share the step-based template
:class:`~casship.estimators.base.StepEstimator`, which adds ``step`` (one step Function with named
slots, folded over a record, exported as C); the moving-horizon estimator solves a window problem
per sample and has no ``step`` at all.
"""
from __future__ import annotations

import abc
from typing import Sequence

import numpy as np

from ..data import Dataset
from ..discretize import DiscreteModel
from ..errors import InputError, InputTypeError
from ..gaussian import Gaussian, as_cov
from ..simulation import check_start
from .options import EstimatorOptions
from .records import Records
from .result import FilterResult
from .update import residual

__all__ = ["Estimator"]


class Estimator(abc.ABC):
    """The contract of every estimator (abstract; see ``docs/estimators.md``).

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
        The estimator's typed options (``Est.Options``); an unknown key raises ``InputError``.

    Attributes
    ----------
    options : EstimatorOptions
        The typed options (frozen).
    records : Records
        The shared record checks and result assembly for this estimator's model and measured outputs.

    Notes
    -----
    Subclasses implement :meth:`filter`, :meth:`online`, :meth:`smooth` and :meth:`predict`,
    honour or refuse every option they accept (a refused option raises in the constructor, naming
    it), and are registered in ``casship.estimators.ESTIMATORS`` so that the conformance suite
    checks them. The traits ``continuous``, ``stochastic`` and ``linear`` tell the suite what to
    expect; an estimator of the step family (a :class:`~casship.estimators.base.StepEstimator`)
    also has ``step``.
    """

    name = "estimator"
    Options = EstimatorOptions
    continuous = False       # Q and R enter as spectral densities Q dt, R dt
    stochastic = False       # draws random numbers (reproducible with ``seed``)
    linear = False           # needs a model linear in states, inputs and noise

    def __init__(self, dmodel: DiscreteModel, Q, R, *, measured: Sequence[str] | None = None, options=None):
        if not isinstance(dmodel, DiscreteModel):
            raise InputTypeError(f"{type(self).__name__} needs a DiscreteModel (use casship.discretize), "
                                 f"got {type(dmodel).__name__}")
        model = dmodel.model
        self.dmodel, self.model = dmodel, model
        measured = tuple(model.output_names if measured is None else measured)
        unknown = [n for n in measured if n not in model.output_names]
        if unknown:
            raise InputError(f"unknown measured output(s) {unknown}; outputs: {list(model.output_names)}")
        if not measured:
            raise InputError("at least one output must be measured")
        twice = sorted({n for n in measured if measured.count(n) > 1})
        if twice:
            raise InputError(f"measured output(s) {twice} given more than once (each sample would be used twice)")
        self.measured = measured
        self.meas_index = [model.index(n, "output") for n in measured]
        self.ny = len(measured)
        self.angle_meas = model.angle_outputs[self.meas_index]
        self.Q = as_cov(Q, model.nw, "Q", model.noise_names)
        self.R = as_cov(R, self.ny, "R", measured, allow_zero=False)
        self.options = self.Options.from_value(options, type(self).__name__)
        self.records = Records(dmodel, measured, self.options.gate, self.name)
        # the starts already found finite: a filter run again from the same start skips the check's work
        self._finite_starts: dict[bytes, None] = {}
        self._check_options()

    def _check_options(self) -> None:
        """Checks of the options against the model (raise ``InputError`` naming the option)."""

    # -- the four verbs ------------------------------------------------------------------------------
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
        """Fixed-interval smoothing of a record (each row uses the whole record), or an ``InputError``
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

    # -- priors: checked once for every estimator ---------------------------------------------------
    def check_prior(self, prior: Gaussian) -> None:
        """Check a prior belief of the state: a :class:`~casship.Gaussian` of the model's size, angles in radians.

        Parameters
        ----------
        prior : Gaussian

        Raises
        ------
        InputTypeError
            Not a Gaussian.
        InputError
            The wrong number of entries, or an angle's mean beyond 2 pi (degrees given?).
        """
        if not isinstance(prior, Gaussian):
            raise InputTypeError(f"prior must be a casship.Gaussian, got {type(prior).__name__}")
        if prior.mean.size != self.model.nx:
            raise InputError(f"prior has {prior.mean.size} entries, model {self.model.name!r} has "
                             f"{self.model.nx} states {list(self.model.state_names)}")
        for i in np.flatnonzero(self.model.angle_states):
            if abs(prior.mean[i]) > 2 * np.pi + 1e-9:
                raise InputError(f"prior mean of angle state {self.model.state_names[i]!r} is {prior.mean[i]:.4g}: "
                                 "angles are in radians (degrees given?)")

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
