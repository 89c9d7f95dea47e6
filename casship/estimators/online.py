"""The one online protocol: ``run = est.online(prior, p); x = run.update(y, dt, u_prev=None, u=None)``.

:class:`OnlineRun` is what every estimator's ``online`` returns. It hands each sample to an
engine, anything that keeps the :class:`OnlineEngine` protocol: for the recursive estimators a
:class:`StepRun` (one evaluation of the step per update through CasADi's buffers, the memory kept
in them), for the MHE its window engine. Every engine checks a sample with the one
:func:`check_sample` (masked = NaN = not measured; an infinite measurement, a masked or non-finite
input, a ``dt`` that is not a finite number >= 0 refused by name), so that a sample means the same
to every estimator. A run holds a lock around every update and every read of its state, so calls
from several threads are taken one at a time, each one whole.
"""
from __future__ import annotations

import math
import numbers
import threading
import warnings
from collections.abc import Mapping
from typing import Protocol, Sequence, runtime_checkable

import casadi as ca
import numpy as np

from ..errors import InputError, InputTypeError
from ..gaussian import Gaussian
from ..runtime import DUPLICATE_NAMES, BufferedCall, is_compiled
from .gaps import gap_pieces, gap_threshold
from .options import DIAGNOSTICS

__all__ = ["OnlineRun", "OnlineEngine", "StepRun", "online_step", "check_sample", "sample_vector",
           "sample_interval", "first_input"]

_ONLINE_EXTRAS = ("mask", "u_held", "status")       # outputs of online_step beyond the step's


# -- the one sample check ------------------------------------------------------------------------------
def sample_vector(value, names: Sequence[str], what: str) -> np.ndarray:
    """One sample of ``what`` (``"y"``, ``"u_prev"`` or ``"u"``) as a float vector, one entry per name.

    A masked entry of a measurement ``y`` is NaN (not measured); a masked input is refused. A single
    number stands for a vector of one.

    Parameters
    ----------
    value : array-like or numpy.ma.MaskedArray
    names : sequence of str
        The measured outputs or the inputs, in order.
    what : str
        The argument's name, for messages.

    Returns
    -------
    numpy.ndarray of shape (len(names),)

    Raises
    ------
    InputError
        Not numbers, the wrong number of values, or a masked input (named).
    """
    size = len(names)
    if np.ma.isMaskedArray(value):                  # masked = not measured; an input must be there
        hidden = np.ma.getmaskarray(value).ravel()
        if what != "y" and hidden.any():
            raise InputError(f"{what} is masked for {[n for n, m in zip(names, hidden) if m]}; inputs must be "
                             "given")
        value = np.ma.filled(np.ma.asarray(value, dtype=float), np.nan)
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be {size} number{'s' * (size != 1)} for {list(names)}, "
                         f"got {value!r}") from None
    if v.ndim == 0 and size == 1:                   # one value: a scalar is that value
        v = v.reshape(1)
    if v.shape != (size,):
        raise InputError(f"{what} must hold {size} value{'s' * (size != 1)} for {list(names)}, got shape {v.shape}")
    return v


def sample_interval(dt) -> float:
    """The time since the previous sample as a float, or ``InputError`` if it is not a finite number >= 0.

    Parameters
    ----------
    dt : number or array of one number
    """
    if isinstance(dt, numbers.Real) and not isinstance(dt, bool):
        value = float(dt)
    elif isinstance(dt, np.ndarray) and dt.size == 1 and dt.dtype.kind in "fiu":
        value = float(dt.item())
    else:
        raise InputError(f"dt must be a number >= 0 (seconds), got {dt!r}")
    if not (value >= 0 and math.isfinite(value)):
        raise InputError(f"dt must be >= 0 and finite, got {dt}")
    return value


def check_sample(y, dt, u_prev, u, measured: Sequence[str], inputs: Sequence[str]):
    """The one check of an online sample, used by every engine before it changes anything.

    Parameters
    ----------
    y : array-like (ny,)
        The measured outputs, NaN (or masked) where not measured.
    dt : float
        Time since the previous sample [s].
    u_prev, u : array-like (nu,) or None
        Inputs held since the previous sample, and now (None: the engine's default).
    measured, inputs : sequence of str
        The names of the measured outputs and of the inputs.

    Returns
    -------
    tuple
        ``(y, dt, u_prev, u)``: float vectors (masked entries of ``y`` NaN), ``dt`` a float, ``u_prev`` and
        ``u`` None where not given.

    Raises
    ------
    InputError
        Naming the item: a measurement that is infinite, an input that is masked or not finite, a
        vector of the wrong length, a ``dt`` that is not a finite number >= 0.
    """
    y = sample_vector(y, measured, "y")
    dt = sample_interval(dt)
    infinite = [n for n, v in zip(measured, y) if np.isinf(v)]
    if infinite:
        raise InputError(f"measurement(s) {infinite} infinite (NaN means not measured)")
    vectors = []
    for what, value in (("u_prev", u_prev), ("u", u)):
        if value is not None:
            value = sample_vector(value, inputs, what)
            bad = [n for n, v in zip(inputs, value) if not np.isfinite(v)]
            if bad:
                raise InputError(f"inputs {bad} must be finite, got {what} = {value}")
        vectors.append(value)
    return (y, dt, *vectors)


def first_input(u, inputs: Sequence[str]) -> np.ndarray:
    """The inputs before the first update of a run: zeros when None, else finite values, one per input.

    Parameters
    ----------
    u : array-like or None
    inputs : sequence of str
    """
    if u is None:
        return np.zeros(len(inputs))
    return check_sample(np.zeros(0), 0.0, None, u, (), inputs)[3]


@runtime_checkable
class OnlineEngine(Protocol):
    """What does the work of an :class:`OnlineRun` per sample (a recursive estimator's step, the MHE's
    window). ``update`` checks its sample with :func:`check_sample` before it changes anything, so a
    refused sample leaves the engine as it was.

    Parameters
    ----------
    *args, **kwargs
        None: a protocol is not instantiated; an engine is any object with these members.

    Attributes
    ----------
    name : str
        The estimator's name (in messages).
    """

    name: str

    @property
    def samples(self) -> int:
        """Samples taken so far."""

    def update(self, y, dt, u_prev, u) -> np.ndarray:
        """Take one sample; return a copy of the new mean.

        Parameters
        ----------
        y, dt, u_prev, u
            As for :meth:`OnlineRun.update` (``u_prev`` and ``u`` None: the engine's defaults).
        """

    @property
    def x(self) -> np.ndarray:
        """Current mean (copy)."""

    @property
    def P(self) -> np.ndarray:
        """Current covariance (copy)."""

    @property
    def info(self) -> Mapping:
        """Named diagnostics of the last update."""


class OnlineRun:
    """An estimator running on a stream, one sample per :meth:`update`, its memory kept inside.

    Numbers equal :meth:`Estimator.filter` on the same record (tested for every estimator).
    Built by ``est.online(prior, p, u=..., seed=...)``. Safe to share between threads: an update
    (and a read of ``x``, ``P`` or ``info``) holds the run's lock, so concurrent calls are taken one
    at a time, in the order the threads get the lock.

    Parameters
    ----------
    engine : OnlineEngine
        Does the work per sample (the step of a recursive estimator, the window of the MHE).

    Examples
    --------
    >>> run = ekf.online(prior)                      # doctest: +SKIP
    >>> for y, dt in stream:                          # doctest: +SKIP
    ...     x = run.update(y, dt)
    >>> run.P, run.info["nis"]                        # doctest: +SKIP
    """

    def __init__(self, engine: OnlineEngine):
        if not isinstance(engine, OnlineEngine):     # a casship bug, not the user's
            raise TypeError(f"OnlineRun needs an OnlineEngine, got {type(engine).__name__}")
        self._engine = engine
        self._lock = threading.RLock()

    def update(self, y, dt: float, u_prev=None, u=None) -> np.ndarray:
        """Predict over ``dt`` (0: no prediction, e.g. the first sample) with the input ``u_prev`` held
        (default: the ``u`` of the previous update), then update with ``y`` (NaN = not measured now)
        using the outputs at input ``u`` (default: ``u_prev``).

        Parameters
        ----------
        y : array (ny,)
            The measured outputs now, NaN where not measured.
        dt : float
            Time since the previous sample [s].
        u_prev, u : array (nu,), optional
            Inputs held since the previous sample, and now.

        Returns
        -------
        array
            A copy of the new mean.
        """
        with self._lock:
            return self._engine.update(y, dt, u_prev, u)

    @property
    def samples(self) -> int:
        """Samples taken so far."""
        return self._engine.samples

    @property
    def x(self) -> np.ndarray:
        """Current mean (copy)."""
        with self._lock:
            return self._engine.x

    @property
    def P(self) -> np.ndarray:
        """Current covariance (copy)."""
        with self._lock:
            return self._engine.P

    @property
    def info(self) -> Mapping:
        """Named diagnostics of the last update (those the estimator was built to return, see the
        ``outputs`` option; ``e`` is NaN where not measured, ``rejected`` is ``not accepted``)."""
        with self._lock:
            return self._engine.info

    def __repr__(self) -> str:
        return f"OnlineRun({self._engine.name}, samples={self._engine.samples})"

    # A run's memory lives in CasADi's buffers (and the MHE's window), under a lock: a shallow copy
    # would share them with the original (an update of one changes the other), and neither buffers
    # nor lock pickle. Said plainly rather than left to copy and pickle.
    def _refuse(self, what: str):
        name = self.__dict__.get("name") or getattr(self.__dict__.get("_engine"), "name", "estimator")
        raise InputTypeError(f"an online {name} run cannot be {what}: its memory lives in the "
                             "estimator's buffers; keep its state (run.x, run.P) and start another run with "
                             "est.online(casship.Gaussian(run.x, run.P), p)")

    def __copy__(self):
        self._refuse("copied (a copy would share its buffers with this run)")

    def __deepcopy__(self, memo):
        self._refuse("copied")

    def __reduce_ex__(self, protocol):
        self._refuse("pickled")


class _Info(Mapping):
    """Diagnostics of one update, copied when read."""

    def __init__(self, values: dict, available: tuple, estimator: str):
        self._values, self._available, self._estimator = values, available, estimator

    def __getitem__(self, key):
        if key not in self._values:
            hint = (f"; build the estimator with options={{'outputs': 'all'}} (or include {key!r})"
                    if key in DIAGNOSTICS or key == "rejected" else "")
            raise KeyError(f"{key!r} is not among the diagnostics of this {self._estimator} run "
                           f"{list(self._values)}{hint}")
        return self._values[key]

    def __iter__(self):
        return iter(self._values)

    def __len__(self):
        return len(self._values)


def online_step(est) -> ca.Function:
    """The estimator's step (``options.outputs``) with the per-sample work of an online update inside.

    Inputs: the step's, without ``mask`` and ``gate``, plus ``thresholds`` (the gate for 0 .. ny
    measured channels). From the raw ``y`` (NaN = not measured) it forms the mask, the cleaned
    measurement and the gate, then runs the step. Extra outputs: ``mask``, ``u_held`` (the ``u`` of
    this update, the next one's default ``u_prev``) and ``status``, the number of values that make
    the update invalid (an infinite measurement, a non-finite input); a caller that sees a non-zero
    status throws the outputs away.

    Parameters
    ----------
    est : Estimator
    """
    step = est.step_function()
    kind = ca.SX if step.is_a("SXFunction") else ca.MX
    ins = {k: kind.sym(k, *step.size_in(k)) for k in step.name_in() if k not in ("mask", "gate")}
    thresholds = kind.sym("thresholds", est.ny + 1)
    y = ins["y"]
    measured = ca.fabs(y) < ca.inf                      # false for NaN and for +-inf
    count = ca.sum1(measured)
    gate = thresholds[est.ny]
    for c in reversed(range(est.ny)):
        gate = ca.if_else(count == c, thresholds[c], gate)
    out = step.call({**ins, "y": ca.if_else(measured, y, 0), "mask": measured, "gate": gate})
    finite_inputs = ca.sum1(ca.fabs(ins["u_prev"]) < ca.inf) + ca.sum1(ca.fabs(ins["u"]) < ca.inf)
    status = ca.sum1(ca.fabs(y) == ca.inf) + 2 * est.model.nu - finite_inputs
    names = [*step.name_out(), *_ONLINE_EXTRAS]
    values = [*(out[k] for k in step.name_out()), measured, ins["u"], status]
    return ca.Function(f"{step.name()}_online", [*ins.values(), thresholds], values, [*ins, "thresholds"], names,
                       DUPLICATE_NAMES)


class StepRun(OnlineRun):
    """The online run of a recursive estimator: :func:`online_step` through two bound buffer sets.

    The two calls hand the memory to each other (one writes the memory the other reads), so an
    update writes the new sample into the shared input buffers, triggers one evaluation (compiled
    with option ``jit``) and flips: no copy of the memory, no ``DM`` conversion. The mask, the gate
    and the validity of the sample are worked out inside the evaluation; an invalid sample is not
    flipped to, so it changes nothing, and only then does Python look for what was wrong. Float64
    vectors of the right length and a float ``dt`` within the one-step gap limit take the short
    way; anything else is converted (or refused) first, and a gap is bridged or refused.

    Parameters
    ----------
    est : Estimator
        A recursive estimator (its step Function).
    prior : Gaussian
    p : array or mapping or None
        Model parameters (nominal when None).
    u : array or None
        Inputs before the first update (zeros when None).
    rng : numpy.random.Generator
        The draws of a stochastic estimator.
    """

    def __init__(self, est, prior: Gaussian, p, u, rng):
        self._lock = threading.RLock()
        self.name = est.name
        self._est, self._rng = est, rng
        self._prior = prior
        m = est.model
        fun = est._compiled_function(("online", est.options.outputs), lambda: online_step(est))
        first = BufferedCall(fun, cannot_fail=is_compiled(fun))
        self._calls = (first, first.partner(est.memory))
        self._cur, self._samples = 0, 0         # the call whose inputs hold the memory now, samples taken
        for k, v in est.memory_from(prior, rng).items():
            first[k] = v
        self._p = m.params() if p is None else m.params(p)
        first["p"] = self._p
        u0 = first_input(u, m.input_names)
        # intervals beyond it are checked at the state where they happen (casship.estimators.gaps)
        self._limit = float(gap_threshold(est))
        first["Q"], first["R"] = est.Q, est.R
        first["thresholds"] = [est.gate_threshold(c) for c in range(est.ny + 1)]
        first["u_prev"], first["u"] = u0, u0
        # the sample's buffers as memoryviews: a copy into one takes only float64 vectors of its length
        self._y, self._u_prev, self._u = (memoryview(first.flat_in(k)) for k in ("y", "u_prev", "u"))
        self._dt = memoryview(first.flat_in("dt"))
        self._held = [memoryview(c.flat_out("u_held")) for c in self._calls]
        for held in self._held:                         # the default u_prev of the first update
            held[:] = u0
        self._nu, self._ny = m.nu, est.ny
        self._draws = [(first.flat_in(k), r * c) for k, (r, c) in est._draw_shapes().items()]
        self._n_draws = sum(size for _, size in self._draws)
        self._x = [c.flat_out("x") for c in self._calls]
        self._P = [c.out("P") for c in self._calls]
        # per buffer set: evaluate (CasADi's buffered call itself where it cannot fail), status, mean
        self._sets = tuple((c.trigger if not c.checked else c, c.flat_out("status"), c.flat_out("x"))
                           for c in self._calls)

    def update(self, y, dt: float, u_prev=None, u=None) -> np.ndarray:
        # (documented by OnlineRun.update) The short way, written out: this is the per-sample cost
        # of every online filter. A copy
        # into a memoryview takes only a float64 vector of the right length (any stride) and
        # raises for anything else, which then goes the long way (converted, or refused by name).
        self._lock.acquire()
        try:
            if not (isinstance(dt, float) and 0.0 <= dt <= self._limit):
                dt = self._irregular_dt(dt, y, u_prev, u)
                if dt is None:                              # a gap, bridged
                    return self._x[1 - self._cur].copy()
            # shapes are checked by the copies, values inside the evaluation: a refused update is
            # never flipped to, so it changes nothing the run keeps (the inputs are rewritten each time)
            cur = self._cur
            evaluate, status, x = self._sets[cur]
            if isinstance(y, np.ma.MaskedArray):        # its buffer holds no mask: the long way
                y = sample_vector(y, self._est.measured, "y")
            try:
                self._y[:] = y
            except (TypeError, ValueError):
                self._y[:] = sample_vector(y, self._est.measured, "y")
            if self._nu:
                if u_prev is None:
                    u_prev = self._held[1 - cur]
                elif isinstance(u_prev, np.ma.MaskedArray):
                    u_prev = sample_vector(u_prev, self._est.model.input_names, "u_prev")
                if isinstance(u, np.ma.MaskedArray):
                    u = sample_vector(u, self._est.model.input_names, "u")
                try:
                    self._u_prev[:] = u_prev
                except (TypeError, ValueError):
                    self._u_prev[:] = sample_vector(u_prev, self._est.model.input_names, "u_prev")
                try:
                    self._u[:] = self._u_prev if u is None else u
                except (TypeError, ValueError):
                    self._u[:] = sample_vector(u, self._est.model.input_names, "u")
            self._dt[0] = dt
            rng_state = self._draw() if self._n_draws else None
            evaluate()
            if status[0]:
                if rng_state is not None:                   # a refused update draws nothing
                    self._rng.bit_generator.state = rng_state
                self._refuse_sample(dt)
            self._cur = 1 - cur
            self._samples += 1
            return x.copy()
        finally:
            self._lock.release()

    def _draw(self) -> dict:
        """Write the standard-normal draws of one step into their buffers; the generator's state before."""
        state = self._rng.bit_generator.state
        z = self._rng.standard_normal(self._n_draws)
        start = 0
        for buf, size in self._draws:
            buf[:] = z[start:start + size]
            start += size
        return state

    def _irregular_dt(self, dt, y, u_prev, u) -> float | None:
        """``dt`` as a float within the one-step limit, or None when the gap was bridged here;
        ``InputError`` for a ``dt`` that is not a number >= 0 or a gap that is refused."""
        value = sample_interval(dt)
        if value <= self._limit or not self._bridged(y, value, u_prev, u):
            return value
        return None

    def _bridged(self, y, dt, u_prev, u) -> bool:
        """A gap: checked at the current estimate; raise, or predict across it in shorter steps."""
        x = self._x[1 - self._cur] if self._samples else self._prior.mean
        held = np.array(self._held[1 - self._cur]) if u_prev is None else sample_vector(u_prev, self._est.model.input_names,
                                                                                        "u_prev")
        where = f"before update {self._samples + 1}"
        pieces = gap_pieces(self._est, x, held, self._p, float(dt), where)
        if pieces == 1:
            return False
        warnings.warn(f"{self._est.name}: time gap of {dt:.4g} s {where} bridged by {pieces - 1} prediction-only "
                      f"step(s) of {dt / pieces:.4g} s", UserWarning, stacklevel=4)
        nothing = np.full(self._ny, np.nan)
        u_held = held.copy()
        for _ in range(pieces - 1):
            self.update(nothing, dt / pieces, u_held, u_held)
        self.update(y, dt / pieces, u_held, u)
        return True

    def _refuse_sample(self, dt) -> None:
        """Raise what made the evaluation report an invalid sample (its outputs are not used): the
        sample as written into the buffers, through the one :func:`check_sample`."""
        est = self._est
        check_sample(np.array(self._y), dt, np.array(self._u_prev), np.array(self._u), est.measured,
                     est.model.input_names)
        raise RuntimeError(f"{est.name}: the online step reported an invalid sample that check_sample accepts")

    @property
    def samples(self) -> int:
        """Samples taken so far."""
        return self._samples

    @property
    def x(self) -> np.ndarray:
        """Current mean (copy)."""
        with self._lock:
            return self._x[1 - self._cur].copy() if self._samples else self._prior.mean.copy()

    @property
    def P(self) -> np.ndarray:
        """Current covariance (copy)."""
        with self._lock:
            return self._P[1 - self._cur].copy() if self._samples else self._prior.cov.copy()

    @property
    def info(self) -> Mapping:
        """Named diagnostics of the last update (see :attr:`OnlineRun.info`)."""
        with self._lock:
            return self._info()

    def _info(self) -> Mapping:
        if not self._samples:
            return _Info({}, (), self.name)
        call = self._calls[1 - self._cur]
        values = {}
        for k in call.names_out:
            if k in self._est.memory and k not in DIAGNOSTICS or k in ("x", "P", *_ONLINE_EXTRAS):
                continue
            v = call.out(k)
            if k == "e":
                values[k] = np.where(call.out("mask").ravel() > 0, v.ravel(), np.nan)
            elif k == "accepted":
                values["rejected"] = bool(v[0, 0] < 0.5)
            elif v.size == 1:
                values[k] = float(v[0, 0])
            else:
                values[k] = (v.ravel() if v.shape[1] == 1 else v).copy()
        return _Info(values, tuple(values), self.name)

    def __repr__(self) -> str:
        return f"OnlineRun({self.name}, samples={self._samples})"
