"""The step-based estimators (the Kalman family): the contract of :mod:`.contract` through one step Function.

Every recursive estimator is one CasADi step Function with named slots (see
``docs/architecture.md``)::

    step(<memory>, u_prev, u, y, mask, dt, p, Q, R, gate, <draws>) -> (<memory>, <diagnostics>)

``<memory>`` is the estimator's memory (:attr:`StepEstimator.memory`: ``x, P`` for the Kalman family,
the ensemble ``X`` for the EnKF) under the same names on both sides; matrices keep their shape.
``y`` holds the measured outputs (NaN or anything where ``mask`` is 0), ``dt`` the time since the
previous sample (0 on the first row: update only), ``gate`` the chi-square threshold of the
innovation test, ``<draws>`` the standard-normal draws of a stochastic estimator. The diagnostics
are a subset of ``x, P, x_pred, P_pred, C, e, S, K, nis, ll, accepted`` chosen when the Function
is built, so the compiled code computes only those. Batch filtering runs the step through
``mapaccum`` over the record (:meth:`StepEstimator.fold`), or, compiled (option ``jit``), through one C
loop over the whole record (:class:`~casship.runtime.NativeFold`); online use calls it through bound buffers
(:class:`~casship.estimators.online.OnlineRun`), and the same Function is exported as C.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..data import Dataset, check_rows
from ..errors import InputError, InputTypeError
from ..gaussian import Gaussian
from ..discretize import DiscreteModel
from ..runtime import DUPLICATE_NAMES, Job, NativeFold, current_function, jit_function, record_loop, run_pieces
from .contract import Estimator
from .gaps import checked_run
from .options import DIAGNOSTICS
from .result import FilterResult

__all__ = ["StepEstimator", "SAMPLE_INPUTS", "CONSTANT_INPUTS", "DIAGNOSTICS", "per_sample"]

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


#: The most random numbers a stochastic estimator draws up front for one record (2 GB of float64).
MAX_DRAWS = 250_000_000


class StepEstimator(Estimator):
    """Base class of the recursive estimators (not used directly): the contract through one step Function.

    Parameters
    ----------
    dmodel, Q, R, measured, options
        As for :class:`~casship.estimators.contract.Estimator` (the contract).

    Attributes
    ----------
    step : casadi.Function
        The step Function with named slots (outputs: :attr:`memory` and ``options.outputs``).
    memory : tuple of str
        Names of the memory slots.
    """

    def __init__(self, dmodel: DiscreteModel, Q, R, *, measured: Sequence[str] | None = None, options=None):
        super().__init__(dmodel, Q, R, measured=measured, options=options)
        self.sym = self._symbolic()
        self._steps: dict[tuple, ca.Function] = {}
        self._folds: dict[tuple, ca.Function] = {}
        self._jitted: dict[tuple, object] = {}     # what the runtime handed out under option jit
        self._names: dict[tuple, tuple] = {}
        self._build_expressions()

    # -- what subclasses provide ------------------------------------------------------------------
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

    def _expressions(self, names) -> list:
        """The expressions of the outputs ``names`` (an estimator may build them differently for a
        step that returns more)."""
        return [self._exprs[k] for k in names]

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
        elif isinstance(outputs, str) and outputs == "all":
            outputs = DIAGNOSTICS
        key = outputs if isinstance(outputs, tuple) else None
        if key in self._names:                      # asked once per run: not worked out again
            return self._names[key]
        memory = self.memory
        unknown = [o for o in outputs if o not in DIAGNOSTICS and o not in memory]
        if unknown:
            raise InputError(f"unknown diagnostic(s) {unknown}; known: {list(DIAGNOSTICS)}")
        names = (*memory, *(o for o in DIAGNOSTICS if o in outputs and o not in memory))
        if key is not None:
            self._names[key] = names
        return names

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
                                             self._expressions(names), list(self._inputs), list(names),
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
        """``make()`` under option ``jit`` (the runtime's policy), kept per key: interpreted, compiled, or
        (background) compiled once the library is loaded."""
        if not self.options.jit:
            return make()
        if key not in self._jitted:
            self._jitted[key] = jit_function(make(), self.options.jit)
        return current_function(self._jitted[key])

    def _native_fold(self, outputs) -> NativeFold | None:
        """The step returning ``outputs`` with its compiled record loop under option ``jit``, or None
        (run the interpreted fold: ``jit`` off, or a background compile not loaded yet)."""
        key = ("native", outputs)
        loop = self._jitted.get(key)
        if loop is None and self.options.jit:
            loop = record_loop(self.step_function(outputs), self.memory, self.options.jit)
            if loop is not None:
                self._jitted[key] = loop
        return loop

    # -- records: the step's per-sample slots ------------------------------------------------------
    def gate_threshold(self, n_measured: int) -> float:
        """Chi-square threshold of the gate for ``n_measured`` scalar measurements (inf: no gate).

        Parameters
        ----------
        n_measured : int
        """
        return self.records.gate_threshold(n_measured)

    def prepare(self, data: Dataset, p=None) -> dict:
        """Check a record and turn it into the step's per-sample and constant slots.

        Parameters
        ----------
        data : Dataset
            Inputs (finite) and measured outputs (NaN or masked = not measured).
        p : array or mapping, optional
            Model parameters (nominal by default).

        Returns
        -------
        dict
            ``u_prev, u, y, mask, dt, gate`` with one column per sample (see
            :meth:`Records.prepare <casship.estimators.records.Records.prepare>`), and ``p, Q, R``.
        """
        m = self.model
        return {**self.records.prepare(data, m.params() if p is None else m.params(p)), "Q": self.Q, "R": self.R}

    def result(self, data: Dataset, arrays: dict, out: dict, estimator: str | None = None) -> FilterResult:
        """The :class:`FilterResult` of a run (see :meth:`Records.result
        <casship.estimators.records.Records.result>`).

        Parameters
        ----------
        data, arrays, out, estimator
            The record, its prepared arrays, the per-sample diagnostics and the name to record.
        """
        return self.records.result(data, arrays, out, estimator)

    # -- data ------------------------------------------------------------------------------------
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
        if n * sum(sizes) > MAX_DRAWS:
            raise InputError(f"{self.name}: {n} steps x {sum(sizes)} random draws per step would need "
                             f"{8 * n * sum(sizes) / 1e9:.3g} GB at once (more than {8 * MAX_DRAWS / 1e9:g} GB, "
                             "casship.estimators.base.MAX_DRAWS): fewer members or a shorter record")
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

    # -- batch -------------------------------------------------------------------------------------
    def filter(self, data: Dataset, prior: Gaussian, p=None, *, seed=None) -> FilterResult:
        """Run the estimator over a whole record in one compiled fold.

        Parameters
        ----------
        data, prior, p, seed
            As for :meth:`Estimator.filter <casship.estimators.contract.Estimator.filter>`.

        Returns
        -------
        FilterResult
        """
        self.check_prior(prior)
        if isinstance(data, Dataset) and all(n in data for n in self.model.input_names):
            self._check_start(prior, [data[n][0] for n in self.model.input_names], p)
        # a gap too long for one prediction from the estimate before it: raise or bridge
        return checked_run(self, data, lambda d: self._run(d, prior, p, seed), p)[1]

    def _run(self, data: Dataset, prior: Gaussian, p, seed) -> FilterResult:
        """One run over the record as it is (the gaps checked by :meth:`filter`)."""
        arrays = self.prepare(data, p)
        n = len(data)
        stochastic = bool(self._draw_shapes())
        rng = np.random.default_rng(seed) if stochastic or seed is not None else None   # a fresh one costs
        memory = self.memory_from(prior, rng)
        draws = self.sample_draws(n, rng) if stochastic else {}
        outputs = self._output_names("all")
        constants = {k: arrays[k] for k in CONSTANT_INPUTS}
        loop = self._native_fold(outputs)
        if loop is not None:                             # one C loop over the record
            per = {**{k: arrays[k].T for k in SAMPLE_INPUTS}, **draws}
            _, outs = loop.run(n, memory=memory, per_sample=per, constants=constants, keep=DIAGNOSTICS)
        else:                                            # the fold in pieces (the runtime's one driver)
            per = {**{k: arrays[k] for k in SAMPLE_INPUTS},
                   **{k: np.ascontiguousarray(v.transpose(1, 0, 2).reshape(v.shape[1], n * v.shape[2]))
                      for k, v in draws.items()}}
            pad = {"mask": 0.0, "dt": 0.0, **{k: 0.0 for k in draws}}
            job = Job(lambda size: self.fold(size, outputs), memory, constants, per, n,
                      carry={m: m for m in self.memory}, pad=pad)
            outs = run_pieces([job], shrink=True, collect=DIAGNOSTICS, record=False)[0]
        return self.result(data, arrays, outs)

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
            raise InputTypeError(f"predict needs a FilterResult, got {type(result).__name__}")
        if result.state_names != m.state_names:
            raise InputError(f"result has states {list(result.state_names)}; {self.name} on {m.name!r} has "
                             f"{list(m.state_names)}")
        t_last = float(result.t[-1])
        if np.ndim(t) == 0:
            steps = check_rows(np.floor(float(t) / self.dmodel.dt + 1e-9),
                               f"{self.name} prediction: {float(t):g} s at steps of {self.dmodel.dt:g} s")
            if steps < 1:
                raise InputError(f"prediction horizon {t} s is shorter than one step ({self.dmodel.dt:g} s)")
            times = t_last + self.dmodel.dt * np.arange(1, steps + 1)
        else:
            times = np.asarray(t, dtype=float).reshape(-1)
            if times.size == 0 or not times[0] > t_last:
                raise InputError(f"prediction times must start after the last sample t = {t_last:g} s")
        n = times.size
        if u is None:
            U = np.tile(result.inputs[-1], (n, 1))
        elif isinstance(u, Mapping):
            unknown = sorted(set(u) - set(m.input_names))
            if unknown:
                raise InputError(f"unknown input(s) {unknown}; inputs: {list(m.input_names)}")
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
        prior, p, u, seed
            As for :meth:`Estimator.online <casship.estimators.contract.Estimator.online>`.

        Returns
        -------
        OnlineRun
        """
        from .online import StepRun

        self.check_prior(prior)
        self._check_start(prior, self.model.inputs() if u is None else u, p)
        return StepRun(self, prior, p, u, np.random.default_rng(seed))
