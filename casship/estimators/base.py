"""The estimator contract: one constructor, one step shape with named slots, batch, online, smoothing.

Every recursive estimator is one CasADi step Function with named slots (see
``docs/architecture.md``)::

    step(<memory>, u_prev, u, y, mask, dt, p, Q, R, gate, <draws>) -> (<memory>, <diagnostics>)

``<memory>`` is the estimator's memory (:attr:`Estimator.memory`: ``x, P`` for the Kalman family,
the ensemble ``X`` for the EnKF) under the same names on both sides; matrices keep their shape.
``y`` holds the measured outputs (NaN or anything where ``mask`` is 0), ``dt`` the time since the
previous sample (0 on the first row: update only), ``gate`` the chi-square threshold of the
innovation test, ``<draws>`` the standard-normal draws of a stochastic estimator. The diagnostics
are a subset of ``x, P, x_pred, P_pred, C, e, S, K, nis, ll, accepted`` chosen when the Function
is built, so the compiled code computes only those. Batch filtering runs the step through
``mapaccum`` over the record (:meth:`Estimator.fold`), or, compiled (option ``jit``), through one C
loop over the whole record (:class:`~casship.native_fold.NativeFold`); online use calls it through bound buffers
(:class:`~casship.estimators.online.OnlineRun`), and the same Function is exported as C.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import casadi as ca
import numpy as np
from scipy import stats

from .._fast import DUPLICATE_NAMES, BufferedCall, compile_function, run_fold
from ..data import Dataset
from ..gaussian import Gaussian, as_cov
from ..discretize import DiscreteModel
from ..native_fold import NativeFold
from ..validity import check_start
from .gaps import checked_run
from .options import DIAGNOSTICS, EstimatorOptions
from .result import FilterResult
from .update import residual

__all__ = ["Estimator", "SAMPLE_INPUTS", "CONSTANT_INPUTS", "DIAGNOSTICS", "per_sample"]

SAMPLE_INPUTS = ("u_prev", "u", "y", "mask", "dt", "gate")   # change from sample to sample
CONSTANT_INPUTS = ("p", "Q", "R")                            # the same for a whole record


def per_sample(a: np.ndarray, n: int) -> np.ndarray:
    """A fold output (``rows x c*n``, sample ``k`` in columns ``k*c .. k*c+c-1``) as an array indexed by
    sample first: ``(n,)`` for scalars, ``(n, rows)`` for vectors, ``(n, rows, c)`` for matrices.

    Parameters
    ----------
    a : array (rows, c*n)
    n : int
        Number of samples.
    """
    r, c = a.shape[0], a.shape[1] // n
    if c == 1:
        return a.T.copy() if r > 1 else a.reshape(n).copy()
    return a.reshape(r, n, c).transpose(1, 0, 2).copy()


class Estimator:
    """Base class of the estimators (not used directly): the contract they share.

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

    Attributes
    ----------
    step : casadi.Function
        The step Function with named slots (outputs: :attr:`memory` and ``options.outputs``).
    memory : tuple of str
        Names of the memory slots.
    """

    name = "estimator"
    Options = EstimatorOptions
    FOLD_CHUNK = 512
    continuous = False       # Q and R enter as spectral densities Q dt, R dt
    stochastic = False       # draws random numbers (reproducible with ``seed``)
    linear = False           # needs a model linear in states, inputs and noise

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
        self._check_options()
        self.sym = self._symbolic()
        self._steps: dict[tuple, ca.Function] = {}
        self._folds: dict[tuple, ca.Function] = {}
        self._fold_calls: dict[tuple, BufferedCall] = {}
        self._compiled: dict[tuple, ca.Function] = {}
        self._gate_cache: dict[int, float] = {}
        self._build_expressions()

    # -- what subclasses provide ------------------------------------------------------------------
    def _check_options(self) -> None:
        """Checks of the options against the model (raise ``ValueError`` naming the option)."""

    def _symbolic(self):
        """``ca.SX`` or ``ca.MX`` for the step's symbols."""
        return self.dmodel.symbolic

    def _memory_shapes(self) -> dict:
        """Name -> (rows, cols) of each memory slot."""
        nx = self.model.nx
        return {"x": (nx, 1), "P": (nx, nx)}

    def _draw_shapes(self) -> dict:
        """Name -> (rows, cols) of each per-step standard-normal draw (stochastic estimators)."""
        return {}

    def _build(self, s: dict) -> dict:  # pragma: no cover - abstract
        """Symbolic step: from the input symbols ``s`` the next memory and every diagnostic."""
        raise NotImplementedError

    def memory_from(self, prior: Gaussian, rng=None) -> dict:
        """The initial memory for the belief ``prior`` (name -> array).

        Parameters
        ----------
        prior : Gaussian
        rng : numpy.random.Generator, optional
            For estimators whose memory is drawn (an ensemble).
        """
        return {"x": prior.mean.copy(), "P": prior.cov.copy()}

    # -- the step Function -------------------------------------------------------------------------
    @property
    def memory(self) -> tuple:
        """Names of the memory slots (inputs and outputs of :attr:`step` under the same names)."""
        return tuple(self._memory_shapes())

    def _build_expressions(self) -> None:
        m, S = self.model, self.sym
        shapes = {**self._memory_shapes(),
                  "u_prev": (m.nu, 1), "u": (m.nu, 1), "y": (self.ny, 1), "mask": (self.ny, 1), "dt": (1, 1),
                  "p": (m.np, 1), "Q": (m.nw, m.nw), "R": (self.ny, self.ny), "gate": (1, 1), **self._draw_shapes()}
        self._inputs = {k: S.sym(k, *v) for k, v in shapes.items()}
        exprs = self._build(dict(self._inputs))
        missing = [k for k in (*self.memory, *DIAGNOSTICS) if k not in exprs]
        if missing:   # pragma: no cover - guards new estimators
            raise RuntimeError(f"{type(self).__name__}._build misses {missing}")
        self._exprs = exprs

    def _output_names(self, outputs) -> tuple:
        if outputs is None:
            outputs = self.options.outputs
        elif outputs == "all":
            outputs = DIAGNOSTICS
        unknown = [o for o in outputs if o not in DIAGNOSTICS and o not in self.memory]
        if unknown:
            raise ValueError(f"unknown diagnostic(s) {unknown}; known: {list(DIAGNOSTICS)}")
        return (*self.memory, *(o for o in DIAGNOSTICS if o in outputs and o not in self.memory))

    def step_function(self, outputs=None) -> ca.Function:
        """The step Function returning the memory and the diagnostics ``outputs``.

        Parameters
        ----------
        outputs : sequence of str or "all", optional
            Diagnostics among ``x, P, x_pred, P_pred, C, e, S, K, nis, ll, accepted`` (default: the
            ``outputs`` option). Only what is asked for is computed.
        """
        names = self._output_names(outputs)
        if names not in self._steps:
            self._steps[names] = ca.Function(f"{self.name.lower()}_step", list(self._inputs.values()),
                                             [self._exprs[k] for k in names], list(self._inputs), list(names),
                                             DUPLICATE_NAMES)
        return self._steps[names]

    @property
    def step(self) -> ca.Function:
        """The step Function with named slots, returning the memory and ``options.outputs``."""
        return self.step_function()

    def fold(self, n: int, outputs="all") -> ca.Function:
        """The step folded over ``n`` samples (``mapaccum`` over the memory slots), cached.

        Inputs keep the step's names: the memory (initial), the per-sample inputs with the ``n``
        samples side by side (``y`` is ``ny x n``, a draw ``z`` of ``r x c`` is ``r x c*n``), and
        ``p, Q, R`` once. Outputs: the memory and the diagnostics at every sample, side by side.

        Parameters
        ----------
        n : int
            Number of samples.
        outputs : sequence of str or "all"
            Diagnostics to return (only these are computed).
        """
        names = self._output_names(outputs)
        key = (int(n), names)
        if key not in self._folds:
            step = self.step_function(names)
            acc = step.mapaccum(f"{step.name()}_acc{n}", int(n), list(self.memory), list(self.memory), DUPLICATE_NAMES)
            ins = {k: ca.MX.sym(k, *(step.size_in(k) if k in CONSTANT_INPUTS else acc.size_in(k)))
                   for k in step.name_in()}
            outs = acc.call({k: ca.repmat(v, 1, int(n)) if k in CONSTANT_INPUTS else v for k, v in ins.items()})
            self._folds[key] = ca.Function(f"{step.name()}_fold{n}", list(ins.values()), [outs[k] for k in names],
                                           list(ins), list(names), DUPLICATE_NAMES)
        return self._folds[key]

    def _compiled_function(self, key, make) -> ca.Function:
        """``make()``, compiled to C with option ``jit`` (cached per key)."""
        if not self.options.jit:
            return make()
        if key not in self._compiled:
            self._compiled[key] = compile_function(make())
        return self._compiled[key]

    def _native_fold(self, outputs) -> NativeFold:
        """The step returning ``outputs``, compiled with its record loop (cached)."""
        key = ("native", outputs)
        if key not in self._compiled:
            self._compiled[key] = NativeFold(self.step_function(outputs), self.memory)
        return self._compiled[key]

    def _fold_call(self, size: int, outputs) -> BufferedCall:
        """The interpreted fold over ``size`` samples through buffers (compiled runs use :meth:`_native_fold`)."""
        key = (size, outputs)
        if key not in self._fold_calls:
            self._fold_calls[key] = BufferedCall(self.fold(size, outputs))
        return self._fold_calls[key]

    # -- data ------------------------------------------------------------------------------------
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
        """Check a record and turn it into the step's named inputs (per-sample inputs as columns).

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
        m = self.model
        if not isinstance(data, Dataset):
            raise TypeError(f"data must be a casship.Dataset, got {type(data).__name__}")
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
        counts = mask.sum(axis=1)
        gate = np.array([self.gate_threshold(int(c)) for c in counts]) if self.options.gate else np.full(len(data), np.inf)
        return {"u_prev": np.vstack([U[:1], U[:-1]]).T, "u": U.T, "y": np.nan_to_num(Y, nan=0.0).T,
                "mask": mask.T.astype(float), "dt": dt[None, :], "gate": gate[None, :],
                "p": m.params() if p is None else m.params(p), "Q": self.Q, "R": self.R}

    def sample_draws(self, n: int, rng) -> dict:
        """Standard-normal draws for ``n`` steps, indexed by step first (name -> ``(n, rows, cols)`` view).

        One row of ``rng.standard_normal`` per step, so the online runner draws the same numbers;
        step ``k``'s matrix is that row's block in column-major order.

        Parameters
        ----------
        n : int
            Number of steps.
        rng : numpy.random.Generator
        """
        shapes = self._draw_shapes()
        if not shapes:
            return {}
        sizes = [r * c for r, c in shapes.values()]
        z = rng.standard_normal((n, sum(sizes)))
        out, start = {}, 0
        for (name, (r, c)), size in zip(shapes.items(), sizes):
            out[name] = z[:, start:start + size].reshape(n, c, r).transpose(0, 2, 1)
            start += size
        return out

    def draws(self, n: int, rng) -> dict:
        """The draws of :meth:`sample_draws`, per-step blocks side by side (name -> ``rows x n*cols``).

        Parameters
        ----------
        n : int
            Number of steps.
        rng : numpy.random.Generator
        """
        return {name: np.ascontiguousarray(v.transpose(1, 0, 2).reshape(v.shape[1], n * v.shape[2]))
                for name, v in self.sample_draws(n, rng).items()}

    def _operating_point(self, x=None, u=None, p=None):
        """``(x, u, p)`` as arrays: zeros and the nominal parameters where not given."""
        m = self.model
        return (m.states() if x is None else np.asarray(x, dtype=float),
                m.inputs() if u is None else np.asarray(u, dtype=float), m.params() if p is None else m.params(p))

    def _check_prior(self, prior: Gaussian) -> None:
        if not isinstance(prior, Gaussian):
            raise TypeError(f"prior must be a casship.Gaussian, got {type(prior).__name__}")
        if prior.mean.size != self.model.nx:
            raise ValueError(f"prior has {prior.mean.size} entries, model {self.model.name!r} has "
                             f"{self.model.nx} states {list(self.model.state_names)}")
        for i in np.flatnonzero(self.model.angle_states):
            if abs(prior.mean[i]) > 2 * np.pi + 1e-9:
                raise ValueError(f"prior mean of angle state {self.model.state_names[i]!r} is {prior.mean[i]:.4g}: "
                                 "angles are in radians (degrees given?)")

    # -- batch -------------------------------------------------------------------------------------
    def filter(self, data: Dataset, prior: Gaussian, p=None, *, seed=None) -> FilterResult:
        """Run the estimator over a whole record in one compiled fold.

        Parameters
        ----------
        data : Dataset
            Columns named like the model inputs (finite) and measured outputs (NaN = missing).
        prior : Gaussian
            Belief about the state at the first time stamp, before its measurement.
        p : array or mapping, optional
            Model parameters (nominal by default).
        seed : int or Generator, optional
            For stochastic estimators (EnKF): fixes every draw.

        Returns
        -------
        FilterResult
        """
        self._check_prior(prior)
        if isinstance(data, Dataset) and all(n in data for n in self.model.input_names):
            self._check_start(prior, data.matrix(self.model.input_names)[0] if self.model.nu else [], p)
        # a gap too long for one prediction from the estimate before it: raise or bridge
        return checked_run(self, data, lambda d: self._run(d, prior, p, seed), p)[1]

    def _check_start(self, prior: Gaussian, u, p) -> None:
        """Refuse a prior where the model's equations are not finite (e.g. an MMG ship at rest); ``u`` is
        the first input (None: not known yet)."""
        m = self.model
        if self.dmodel.discrete or u is None:
            return
        u = np.asarray(u, dtype=float).reshape(-1)
        if u.size != m.nu or not np.all(np.isfinite(u)):
            return                                          # the callers name bad inputs
        unset = prior.defaulted() if hasattr(prior, "defaulted") else None
        check_start(m, prior.mean, u, m.params() if p is None else m.params(p), what="the prior mean", unset=unset)

    def _run(self, data: Dataset, prior: Gaussian, p, seed) -> FilterResult:
        """One run over the record as it is (the gaps checked by :meth:`filter`)."""
        arrays = self.prepare(data, p)
        n = len(data)
        rng = np.random.default_rng(seed)
        memory = self.memory_from(prior, rng)
        draws = self.sample_draws(n, rng)
        outputs = self._output_names("all")
        constants = {k: arrays[k] for k in CONSTANT_INPUTS}
        if self.options.jit:                             # one C loop over the record
            per = {**{k: arrays[k].T for k in SAMPLE_INPUTS}, **draws}
            _, outs = self._native_fold(outputs).run(n, memory=memory, per_sample=per, constants=constants,
                                                     keep=DIAGNOSTICS)
        else:
            per = {**{k: arrays[k] for k in SAMPLE_INPUTS}, **draws}
            pad = {"mask": 0.0, "dt": 0.0, **{k: 0.0 for k in draws}}
            _, outs = run_fold(lambda size: self._fold_call(size, outputs), n, self.FOLD_CHUNK, memory=memory,
                               per_sample=per, constants=constants, pad=pad, keep=DIAGNOSTICS)
        return self.result(data, arrays, outs)

    def result(self, data: Dataset, arrays: dict, out: dict, estimator: str | None = None) -> FilterResult:
        """Assemble a :class:`FilterResult` from the per-sample diagnostics of a run.

        Parameters
        ----------
        data : Dataset
            The record.
        arrays : dict
            The record as prepared by :meth:`prepare`.
        out : dict
            Diagnostic name -> array indexed by sample.
        estimator : str, optional
            Name recorded in the result (default: the estimator's).
        """
        m, n = self.model, len(data)
        mask = arrays["mask"].T
        e = np.array(out["e"], dtype=float).reshape(n, self.ny)
        e[mask == 0] = np.nan
        mat = lambda k, r, c: np.reshape(out[k], (n, r, c))  # noqa: E731
        nx, ny = m.nx, self.ny
        return FilterResult(
            t=data.t, x=np.reshape(out["x"], (n, nx)), P=mat("P", nx, nx), x_pred=np.reshape(out["x_pred"], (n, nx)),
            P_pred=mat("P_pred", nx, nx), C=mat("C", nx, nx), K=mat("K", nx, ny), innovations=e, S=mat("S", ny, ny),
            nis=np.reshape(out["nis"], n), n_measured=mask.sum(axis=1), loglik_terms=np.reshape(out["ll"], n),
            rejected=np.reshape(out["accepted"], n) < 0.5, inputs=arrays["u"].T, state_names=m.state_names,
            state_units=tuple(v.unit for v in m.state_vars), output_names=self.measured, input_names=m.input_names,
            estimator=estimator or self.name, angle_states=m.angle_states)

    def smooth(self, data: Dataset, prior: Gaussian, p=None, *, seed=None) -> FilterResult:
        """Fixed-interval smoothing of a record: the one smoothing entry point.

        The Kalman family runs :meth:`filter` and a Rauch-Tung-Striebel pass over its result
        (:func:`~casship.estimators.rts.rts_smooth`); the MHE solves one window over the whole record.

        Parameters
        ----------
        data, prior, p, seed
            As for :meth:`filter`.

        Returns
        -------
        FilterResult
            ``x, P`` smoothed (``estimator`` ``"<name>+RTS"``); predictions, innovations and
            likelihood terms those of the forward pass.
        """
        from .rts import rts_smooth

        return rts_smooth(self.filter(data, prior, p, seed=seed), jit=self.options.jit)

    def predict(self, result: FilterResult, t, u=None, p=None, *, seed=None) -> FilterResult:
        """Predict past the last sample of ``result`` (no measurements).

        The prediction lives on the estimator, not on the result, because it needs the model and
        ``Q``; the result stays a plain value that can be saved and loaded.

        Parameters
        ----------
        result : FilterResult
            A run of this estimator's model (filtered or smoothed); its last mean and covariance
            start the prediction.
        t : float or array
            A horizon [s] (predictions at the nominal step ``dmodel.dt`` up to it) or the times,
            strictly increasing and after the last sample.
        u : mapping name -> value or array, or array, optional
            Inputs over the prediction (default: the record's last input held).
        p : array or mapping, optional
            Model parameters (nominal by default).
        seed : int or Generator, optional
            For stochastic estimators.

        Returns
        -------
        FilterResult
            Rows at the prediction times (``estimator`` ``"<name> prediction"``; nothing measured).
        """
        m = self.model
        if not isinstance(result, FilterResult):
            raise TypeError(f"predict needs a FilterResult, got {type(result).__name__}")
        if result.state_names != m.state_names:
            raise ValueError(f"result has states {list(result.state_names)}; {self.name} on {m.name!r} has "
                             f"{list(m.state_names)}")
        t_last = float(result.t[-1])
        if np.ndim(t) == 0:
            steps = int(np.floor(float(t) / self.dmodel.dt + 1e-9))
            if steps < 1:
                raise ValueError(f"prediction horizon {t} s is shorter than one step ({self.dmodel.dt:g} s)")
            times = t_last + self.dmodel.dt * np.arange(1, steps + 1)
        else:
            times = np.asarray(t, dtype=float).reshape(-1)
            if times.size == 0 or not times[0] > t_last:
                raise ValueError(f"prediction times must start after the last sample t = {t_last:g} s")
        n = times.size
        if u is None:
            U = np.tile(result.inputs[-1], (n, 1))
        elif isinstance(u, Mapping):
            unknown = sorted(set(u) - set(m.input_names))
            if unknown:
                raise ValueError(f"unknown input(s) {unknown}; inputs: {list(m.input_names)}")
            U = np.tile(result.inputs[-1], (n, 1))
            for k, v in u.items():
                U[:, m.index(k, "input")] = np.broadcast_to(np.asarray(v, dtype=float), (n,))
        else:
            U = np.broadcast_to(np.asarray(u, dtype=float), (n, m.nu))
        cols = {k: np.concatenate([[result.inputs[-1, i]], U[:, i]]) for i, k in enumerate(m.input_names)}
        cols.update({k: np.full(n + 1, np.nan) for k in self.measured})
        data = Dataset(np.concatenate([[t_last], times]), cols)
        res = self.filter(data, Gaussian(result.x[-1], result.P[-1]), p, seed=seed)
        rows = {k: getattr(res, k)[1:] for k in ("t", "x", "P", "x_pred", "P_pred", "C", "K", "innovations", "S",
                                                  "nis", "n_measured", "loglik_terms", "rejected", "inputs")}
        return res.replace(**rows, estimator=f"{self.name} prediction")

    # -- online ------------------------------------------------------------------------------------
    def online(self, prior: Gaussian, p=None, *, u=None, seed=None):
        """A stateful runner on a stream, started from ``prior`` (see :class:`~casship.estimators.online.OnlineRun`).

        ``run.update(y, dt, u_prev=None, u=None) -> x`` per sample; ``run.x``, ``run.P``, ``run.info``.
        Numbers equal :meth:`filter` on the same record (a stochastic estimator draws from ``seed``
        in the same order).

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

        Returns
        -------
        OnlineRun
        """
        from .online import OnlineRun, StepEngine

        self._check_prior(prior)
        self._check_start(prior, self.model.inputs() if u is None else u, p)
        return OnlineRun(StepEngine(self, prior, p, u, np.random.default_rng(seed)))

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
