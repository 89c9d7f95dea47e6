"""The one online protocol: ``run = est.online(prior, p); x = run.update(y, dt, u_prev=None, u=None)``.

:class:`OnlineRun` is what every estimator's ``online`` returns. The work per sample is done by an
engine: :class:`StepEngine` for the recursive estimators (one compiled call of the step per update,
memory kept in bound buffers), the window runner of the MHE.
"""
from __future__ import annotations

import math
from collections.abc import Mapping

import casadi as ca
import numpy as np

from .._fast import DUPLICATE_NAMES
from ..gaussian import Gaussian
from .options import DIAGNOSTICS

__all__ = ["OnlineRun", "online_step"]

_ONLINE_EXTRAS = ("mask", "u_held", "status")       # outputs of online_step beyond the step's


class OnlineRun:
    """An estimator running on a stream, one sample per :meth:`update`, its memory kept inside.

    Numbers equal :meth:`Estimator.filter` on the same record (tested for every estimator).
    Built by ``est.online(prior, p, u=..., seed=...)``.

    Parameters
    ----------
    engine : object
        Does the work per sample (the step of a recursive estimator, the window of the MHE).

    Examples
    --------
    >>> run = ekf.online(prior)                      # doctest: +SKIP
    >>> for y, dt in stream:                          # doctest: +SKIP
    ...     x = run.update(y, dt)
    >>> run.P, run.info["nis"]                        # doctest: +SKIP
    """

    def __init__(self, engine):
        self._engine = engine
        fast = getattr(engine, "compiled_update", None)
        if fast is not None:            # the same update, one call into compiled code
            self.update = fast

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
        return self._engine.update(y, dt, u_prev, u)

    @property
    def x(self) -> np.ndarray:
        """Current mean (copy)."""
        return self._engine.x

    @property
    def P(self) -> np.ndarray:
        """Current covariance (copy)."""
        return self._engine.P

    @property
    def info(self) -> Mapping:
        """Named diagnostics of the last update (those the estimator was built to return, see the
        ``outputs`` option; ``e`` is NaN where not measured, ``rejected`` is ``not accepted``)."""
        return self._engine.info

    def __repr__(self) -> str:
        return f"OnlineRun({self._engine.name}, samples={self._engine.samples})"


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


def _native_update(est):
    """The estimator's compiled online update (:class:`~casship.native_update.NativeUpdate`), or None:
    built for jit estimators without random draws, where the headers are installed (cached)."""
    if not est.options.jit or est._draw_shapes():
        return None
    key = ("update", est.options.outputs)
    if key not in est._compiled:
        from ..native_update import compile_update

        est._compiled[key] = compile_update(online_step(est), est.model.nx, est.ny, est.model.nu)
    return est._compiled[key]


class StepEngine:
    """Online engine of a recursive estimator: :func:`online_step` through two bound buffer sets.

    The two calls hand the memory to each other (one writes the memory the other reads), so an
    update writes the new sample into the shared input buffers, triggers one compiled evaluation
    and flips: no copy of the memory, no ``DM`` conversion. The mask, the gate and the validity of
    the sample are worked out inside the compiled call; an invalid sample is not flipped to, so it
    changes nothing, and only then does Python look for what was wrong.

    For jit estimators without random draws, ``compiled_update`` does all of this in one call into
    compiled code (:mod:`casship.native_update`): it takes float64 vectors and a number ``dt``
    within the gap limit, and hands every other call (other types, keywords, gaps, invalid samples)
    to :meth:`update`, on the same buffers and state. None where it cannot be built.
    """

    def __init__(self, est, prior: Gaussian, p, u, rng):
        self.name = est.name
        self._est, self._rng = est, rng
        self._prior = prior
        m = est.model
        native = _native_update(est)
        fun = native.fun if native else est._compiled_function(("online", est.options.outputs),
                                                                lambda: online_step(est))
        from .._fast import BufferedCall

        first = BufferedCall(fun, cannot_fail=est.options.jit)
        self._calls = (first, first.partner(est.memory))
        # [the call whose inputs hold the memory now, samples taken]: shared with the compiled update
        self._state = np.zeros(2, np.int64)
        for k, v in est.memory_from(prior, rng).items():
            first[k] = v
        self._p = m.params() if p is None else m.params(p)
        first["p"] = self._p
        u0 = np.zeros(m.nu) if u is None else np.asarray(u, dtype=float).reshape(-1)
        if u0.size != m.nu or not np.all(np.isfinite(u0)):
            raise ValueError(f"u must be {m.nu} finite values for the inputs {list(m.input_names)}, got {u0}")
        from .gaps import gap_threshold

        # intervals beyond it are checked at the state where they happen (casship.estimators.gaps)
        self._gap_limit = np.array([gap_threshold(est)])
        first["Q"], first["R"] = est.Q, est.R
        first["thresholds"] = [est.gate_threshold(c) for c in range(est.ny + 1)]
        first["u_prev"], first["u"] = u0, u0
        self._y, self._dt = first.flat_in("y"), first.flat_in("dt")
        self._u_prev, self._u = first.flat_in("u_prev"), first.flat_in("u")
        self._held = [c.flat_out("u_held") for c in self._calls]
        for held in self._held:                         # the default u_prev of the first update
            held[:] = u0
        self._status = [c.flat_out("status") for c in self._calls]
        self._nu, self._ny = m.nu, est.ny
        self._y_shape, self._u_shape = (est.ny,), (m.nu,)
        self._draws = [(first.flat_in(k), r * c) for k, (r, c) in est._draw_shapes().items()]
        self._n_draws = sum(size for _, size in self._draws)
        self._trig = [c.trigger if not c._checked else c for c in self._calls]
        self._x = [c.flat_out("x") for c in self._calls]
        self._P = [c.out("P") for c in self._calls]
        buffers = {"y": self._y, "dt": self._dt, "u_prev": self._u_prev, "u": self._u, "state": self._state,
                   "gap_limit": self._gap_limit}
        for c in range(2):
            buffers.update({f"held{c}": self._held[c], f"x{c}": self._x[c], f"status{c}": self._status[c]})
        # one call into compiled code, handing every call it does not take to the checked update
        self.compiled_update = native.bind(self._calls, buffers, self.update) if native else None

    @property
    def _cur(self) -> int:
        return int(self._state[0])

    @property
    def samples(self) -> int:
        return int(self._state[1])

    def update(self, y, dt, u_prev=None, u=None):
        if not (dt >= 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be >= 0 and finite, got {dt}")
        if dt > self._gap_limit[0] and self._bridged(y, dt, u_prev, u):
            return self._x[1 - self._cur].copy()
        return self._update(y, dt, u_prev, u)

    def _bridged(self, y, dt, u_prev, u) -> bool:
        """A gap: checked at the current estimate; raise, or predict across it in shorter steps."""
        from .gaps import gap_pieces

        x = self._x[1 - self._cur] if self.samples else self._prior.mean
        held = self._held[1 - self._cur] if u_prev is None else self._vector(u_prev, self._nu, "u_prev",
                                                                               self._est.model.input_names)
        where = f"before update {self.samples + 1}"
        pieces = gap_pieces(self._est, x, held, self._p, float(dt), where)
        if pieces == 1:
            return False
        import warnings

        warnings.warn(f"{self._est.name}: time gap of {dt:.4g} s {where} bridged by {pieces - 1} prediction-only "
                      f"step(s) of {dt / pieces:.4g} s", UserWarning, stacklevel=3)
        nothing = np.full(self._ny, np.nan)
        u_held = held.copy()
        for _ in range(pieces - 1):
            self._update(nothing, dt / pieces, u_held, u_held)
        self._update(y, dt / pieces, u_held, u)
        return True

    def _vector(self, value, size: int, what: str, names) -> np.ndarray:
        """``value`` as a float vector of ``size``, or ``ValueError`` naming ``what`` (the slow path:
        ``_update`` takes a float array of the right shape as it is)."""
        if np.ma.isMaskedArray(value):              # masked = not measured; an input must be there
            hidden = np.ma.getmaskarray(value).ravel()
            if what != "y" and hidden.any():
                raise ValueError(f"{what} is masked for {[n for n, m in zip(names, hidden) if m]}; inputs must be "
                                 "given")
            value = np.ma.filled(np.ma.asarray(value, dtype=float), np.nan)
        try:
            v = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{what} must be {size} number{'s' * (size != 1)} for {list(names)}, "
                             f"got {value!r}") from None
        if v.ndim == 0 and size == 1:               # one value: a scalar is that value
            v = v.reshape(1)
        if v.shape != (size,):
            raise ValueError(f"{what} must hold {size} value{'s' * (size != 1)} for {list(names)}, got shape {v.shape}")
        return v

    def _refusal(self, y, u_prev, u) -> ValueError:
        """What made the compiled update report an invalid sample (its outputs are not used)."""
        est = self._est
        bad = [n for n, v in zip(est.measured, y) if np.isinf(v)]
        if bad:
            return ValueError(f"measurement(s) {bad} infinite (NaN means not measured)")
        return ValueError(f"inputs {list(est.model.input_names)} must be finite, got u_prev = {u_prev}, u = {u}")

    def _update(self, y, dt, u_prev, u):
        # shapes are checked before a buffer is written, values inside the compiled call: a refused
        # update is never flipped to, so it changes nothing
        fast = np.ndarray
        if type(y) is not fast or y.shape != self._y_shape or y.dtype != np.float64:
            y = self._vector(y, self._ny, "y", self._est.measured)
        if self._nu:
            names, shape = self._est.model.input_names, self._u_shape
            if u_prev is None:
                u_prev = self._held[1 - self._cur]
            elif type(u_prev) is not fast or u_prev.shape != shape or u_prev.dtype != np.float64:
                u_prev = self._vector(u_prev, self._nu, "u_prev", names)
            if u is None:
                u = u_prev
            elif type(u) is not fast or u.shape != shape or u.dtype != np.float64:
                u = self._vector(u, self._nu, "u", names)
            self._u_prev[...] = u_prev                  # [...] =: the quickest copy into a small array
            self._u[...] = u
        self._y[...] = y
        self._dt[0] = dt
        if self._n_draws:
            rng_state = self._rng.bit_generator.state       # a refused update draws nothing
            z = self._rng.standard_normal(self._n_draws)
            start = 0
            for buf, size in self._draws:
                buf[:] = z[start:start + size]
                start += size
        cur = self._cur
        self._trig[cur]()
        if self._status[cur][0]:
            if self._n_draws:
                self._rng.bit_generator.state = rng_state
            raise self._refusal(y, u_prev, u)
        self._state[0] = 1 - cur
        self._state[1] += 1
        return self._x[cur].copy()

    @property
    def x(self) -> np.ndarray:
        return self._x[1 - self._cur].copy() if self.samples else self._prior.mean.copy()

    @property
    def P(self) -> np.ndarray:
        return self._P[1 - self._cur].copy() if self.samples else self._prior.cov.copy()

    @property
    def info(self) -> Mapping:
        if not self.samples:
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
