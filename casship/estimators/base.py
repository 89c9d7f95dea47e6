"""Shared machinery of the recursive estimators: data preparation, the compiled fold over a record,
the online stepper and the :class:`FilterResult` value.

Every recursive estimator is one CasADi step Function with the signature

``step(carry, u_prev, u, y, mask, dt, p, Q, R, gate, *extra) ->
(carry_next, x, P, x_pred, P_pred, C, e, S, nis, ll, accepted)``

where ``carry`` is the estimator's memory (mean and vectorised covariance, or an ensemble), ``y``
holds the measured outputs with NaN replaced by 0 and ``mask`` flags which ones were measured,
``dt`` is the time since the previous sample (0 on the first row: update only), ``C`` is the
cross-covariance of the previous filtered state and the predicted state (what a Rauch-Tung-Striebel
smoother needs) and ``gate`` the chi-square threshold of the innovation test. Batch filtering runs
the same Function through ``mapaccum`` over the whole record; online use calls it through
preallocated buffers.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from collections.abc import Mapping
from typing import Sequence

import casadi as ca
import numpy as np
from scipy import stats

from .._fast import BufferedCall
from ..angles import wrap, wrap_sym
from ..data import Dataset, Gaussian, as_cov
from ..discretize import DiscreteModel

__all__ = ["Estimator", "FilterResult", "Health", "OnlineFilter", "StepInfo", "STEP_OUTPUTS", "compile_function", "fold_in_pieces"]

STEP_INPUTS = ["carry", "u_prev", "u", "y", "mask", "dt", "p", "Q", "R", "gate"]
STEP_OUTPUTS = ["carry_next", "x", "P", "x_pred", "P_pred", "C", "e", "S", "nis", "ll", "accepted"]
_CONSTANT_INPUTS = (6, 7, 8)   # p, Q, R: the same for every sample of a fold; all others are per sample


_CHOL: dict[int, ca.Function] = {}


def _chol_function(n: int) -> ca.Function:
    """Cholesky factor as an SX Function, callable on MX (``ca.chol`` has no MX overload)."""
    if n not in _CHOL:
        S = ca.SX.sym("S", n, n)
        _CHOL[n] = ca.Function(f"chol{n}", [S], [ca.chol(S)], ["S"], ["L"])
    return _CHOL[n]


@dataclass(frozen=True)
class Health:
    """NIS-based divergence monitor of a filter run.

    A window of ``window`` samples is flagged when its summed NIS (of the accepted updates) lies
    outside the two-sided ``1 - alpha`` chi-square interval for the number of scalar measurements
    in it, or when the innovation gate rejected most of its measured samples (more than half and
    at least three): a filter that rejects everything it is told has lost track, even though its
    accepted NIS looks fine.
    """

    window: int
    alpha: float
    flagged: np.ndarray          # (n_windows,) bool
    window_start: np.ndarray     # first row of each window
    nis_sum: np.ndarray
    dof: np.ndarray
    rejected: np.ndarray = None  # (n_windows,) gated samples per window

    @property
    def ok(self) -> bool:
        """True if fewer windows are flagged than expected by chance plus a margin."""
        n = self.flagged.size
        return bool(n == 0 or self.flagged.sum() <= max(1, int(np.ceil(2 * self.alpha * n + 2 * np.sqrt(self.alpha * n)))))

    def raise_if_diverged(self) -> None:
        if not self.ok:
            first = int(self.window_start[np.argmax(self.flagged)])
            raise RuntimeError(f"filter health check failed: {int(self.flagged.sum())} of {self.flagged.size} "
                               f"windows flagged (NIS outside the {100 * (1 - self.alpha):.0f}% chi-square "
                               f"interval or most samples rejected by the gate; first at row {first})")


@dataclass(frozen=True)
class FilterResult:
    """Result of running an estimator over a record (all arrays indexed by sample).

    Attributes
    ----------
    t : (N,) time stamps
    x, P : filtered means (N, nx) and covariances (N, nx, nx)
    x_pred, P_pred : predicted means and covariances before each update
    C : cross-covariances of the previous filtered and the current predicted state (for smoothing)
    innovations : (N, ny) residuals, NaN where the channel was not measured (angles wrapped)
    S : (N, ny, ny) innovation covariances (identity rows/columns for unmeasured channels)
    nis : (N,) normalised innovation squared
    n_measured : (N,) number of scalar measurements used per sample
    loglik_terms : (N,) log-likelihood of each sample's measurements given the past
    rejected : (N,) True where the innovation gate rejected the update
    """

    t: np.ndarray
    x: np.ndarray
    P: np.ndarray
    x_pred: np.ndarray
    P_pred: np.ndarray
    C: np.ndarray
    innovations: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    n_measured: np.ndarray
    loglik_terms: np.ndarray
    rejected: np.ndarray
    state_names: tuple
    output_names: tuple
    estimator: str
    angle_states: np.ndarray = field(repr=False, default=None)

    @property
    def loglik(self) -> float:
        """Total log-likelihood of the record (prediction-error decomposition)."""
        return float(np.sum(self.loglik_terms))

    @property
    def std(self) -> np.ndarray:
        """Standard deviations (N, nx) of the filtered states."""
        return np.sqrt(np.maximum(np.einsum("kii->ki", self.P), 0.0))

    def __getitem__(self, name: str) -> np.ndarray:
        """Estimate of a named state over the record."""
        try:
            return self.x[:, self.state_names.index(name)]
        except ValueError:
            raise ValueError(f"unknown state {name!r}; states: {list(self.state_names)}") from None

    def nees(self, x_true: np.ndarray) -> np.ndarray:
        """Normalised estimation error squared against true states (angles wrapped)."""
        err = np.asarray(x_true, dtype=float) - self.x
        if self.angle_states is not None and self.angle_states.any():
            err[:, self.angle_states] = wrap(err[:, self.angle_states])
        return np.einsum("ki,ki->k", err, np.linalg.solve(self.P, err[..., None])[..., 0])

    def health(self, window: int = 50, alpha: float = 0.01) -> Health:
        """Windowed NIS test (see :class:`Health`)."""
        n = self.nis.size // window
        if n == 0:
            empty = np.zeros(0)
            return Health(window, alpha, empty.astype(bool), empty.astype(int), empty, empty, empty.astype(int))
        used = ~self.rejected
        blocks = lambda a: a[: n * window].reshape(n, window).sum(axis=1)  # noqa: E731
        nis = blocks(np.where(used, self.nis, 0.0))
        dof = blocks(np.where(used, self.n_measured, 0))
        lo = stats.chi2.ppf(alpha / 2, np.maximum(dof, 1))
        hi = stats.chi2.ppf(1 - alpha / 2, np.maximum(dof, 1))
        measured = self.n_measured > 0
        rejected = blocks((self.rejected & measured).astype(int))
        lost = (rejected >= 3) & (2 * rejected > blocks(measured.astype(int)))
        flagged = ((dof > 0) & ((nis < lo) | (nis > hi))) | lost
        return Health(window, alpha, flagged, np.arange(n) * window, nis, dof, rejected)

    def to_dataset(self) -> Dataset:
        """Estimates and their standard deviations (``<state>_std``) as a :class:`Dataset`."""
        cols = {n: self.x[:, i] for i, n in enumerate(self.state_names)}
        std = self.std
        cols.update({f"{n}_std": std[:, i] for i, n in enumerate(self.state_names)})
        return Dataset(self.t, cols, meta={"estimator": self.estimator})


def compile_function(fun: ca.Function) -> ca.Function:
    """``fun`` compiled to C and loaded (CasADi JIT through the system C compiler, ``-O2``).

    Raises ``RuntimeError`` naming the Function when no working C compiler is found.
    """
    import tempfile

    ins = fun.sx_in() if fun.is_a("SXFunction") else fun.mx_in()
    opts = {"jit": True, "compiler": "shell", "jit_cleanup": True,
            "jit_options": {"flags": ["-O2"], "directory": tempfile.gettempdir()}}
    try:
        return ca.Function(f"{fun.name()}_jit", ins, fun.call(ins), fun.name_in(), fun.name_out(), opts)
    except RuntimeError as exc:
        raise RuntimeError(f"option 'jit': compiling {fun.name()!r} to C failed (is a C compiler "
                           f"installed?): {str(exc).splitlines()[-1]}") from None


def fold_in_pieces(fold_call, step: ca.Function, args: list, n: int, per_sample, chunk: int,
                   pad=None) -> list[np.ndarray]:
    """Run a ``mapaccum`` fold of ``step`` over ``n`` samples in pieces, through buffers.

    ``fold_call(size)`` gives a :class:`~casship._fast.BufferedCall` of the fold of ``size``
    samples; ``args[0]`` is the carry, ``args[i]`` for ``i`` in ``per_sample`` are ``n``-column
    arrays, the others constants. Pieces have ``chunk`` samples, the last one padded up to a power
    of two by repeating its last sample (``pad(views, take)`` may overwrite the padded columns);
    padded outputs are dropped. Returns the outputs over the samples, except the first, which is
    the final carry (one column).
    """
    carry = np.asarray(args[0], dtype=float).reshape(-1, order="F")
    outs, start = None, 0
    while start < n:
        size = min(chunk, 1 << (n - start - 1).bit_length())
        take = min(size, n - start)
        call = fold_call(size)
        views = call.arg_views
        call.args[0][:] = carry
        for i in range(1, len(args)):
            if i in per_sample:
                src = np.asarray(args[i], dtype=float)[:, start:start + take]
                views[i][:, :take] = src
                if take < size:
                    views[i][:, take:] = src[:, -1:] if src.shape[0] else 0.0
            else:
                block = np.asarray(args[i], dtype=float).reshape(step.size_in(i), order="F")
                views[i][...] = np.tile(block, (1, size))
        if take < size and pad is not None:
            pad(views, take)
        call()
        res = call.res_views
        if outs is None:    # column-major, so that each piece is one contiguous copy
            outs = [None] + [np.empty((r.shape[0], n), order="F") for r in res[1:]]
        for j in range(1, len(res)):
            outs[j][:, start:start + take] = res[j][:, :take]
        carry = res[0][:, take - 1].copy()
        start += take
    outs[0] = carry[:, None]
    return outs


class Estimator:
    """Base class of the recursive estimators (not used directly).

    Parameters
    ----------
    dmodel : DiscreteModel
    Q : covariance of the process noise ``w`` (nw x nw; scalar, variances, matrix or name mapping)
    R : covariance of the measured outputs (scalar, variances, matrix or name mapping)
    measured : sequence of str, optional
        Output names that are measured (default: all outputs of the model).
    options : mapping, optional
        ``gate`` (probability of the chi-square innovation gate, e.g. 0.999; off by default),
        ``jit`` (compile the step and its folds to C with the system compiler; off by default) and
        estimator-specific options.
    """

    name = "estimator"
    FOLD_CHUNK = 512
    _common_options = {"gate": None, "jit": False}
    _options: dict = {}

    def __init__(self, dmodel: DiscreteModel, Q, R, *, measured: Sequence[str] | None = None,
                 options: Mapping | None = None):
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
        self.measured = measured
        self.meas_index = [model.index(n, "output") for n in measured]
        self.ny = len(measured)
        self.angle_meas = model.angle_outputs[self.meas_index]
        self.Q = as_cov(Q, model.nw, "Q", model.noise_names)
        self.R = as_cov(R, self.ny, "R", measured, allow_zero=False)
        allowed = {**self._common_options, **self._options}
        options = dict(options or {})
        unknown = set(options) - set(allowed)
        if unknown:
            raise ValueError(f"unknown option(s) {sorted(unknown)} for {type(self).__name__}; "
                             f"known: {sorted(allowed)}")
        self.options = {**allowed, **options}
        gate = self.options["gate"]
        if gate is not None and not 0 < gate < 1:
            raise ValueError(f"option 'gate' is a probability in (0, 1), got {gate}")
        self.sym = dmodel.symbolic
        self._step = self._build_step()
        self._folds: dict[int, ca.Function] = {}
        self._fold_calls: dict[int, BufferedCall] = {}
        self._compiled_step = None
        self._online = None
        self._gated = self.options["gate"] is not None
        self._cannot_fail = bool(self.options["jit"]) or self._step.is_a("SXFunction")

    # -- symbolic helpers shared by the estimators ----------------------------------------------
    def _symbols(self):
        m, S = self.model, self.sym
        return dict(u_prev=S.sym("u_prev", m.nu), u=S.sym("u", m.nu), y=S.sym("y", self.ny),
                    mask=S.sym("mask", self.ny), dt=S.sym("dt"), p=S.sym("p", m.np),
                    Q=S.sym("Q", m.nw, m.nw), R=S.sym("R", self.ny, self.ny), gate=S.sym("gate"))

    def h_meas(self, x, u, p):
        """Symbolic measured outputs."""
        return self.model.h(x, u, p)[self.meas_index]

    def residual(self, y, yhat, mask):
        """Masked measurement residual with angle channels wrapped on the circle.

        Unmeasured channels (``mask = 0``) give exactly 0 even when ``y`` holds NaN there.
        """
        e = y - yhat
        return ca.vertcat(*[ca.if_else(mask[i] > 0, wrap_sym(e[i]) if a else e[i], 0)
                            for i, a in enumerate(self.angle_meas)])

    def masked_innovation_cov(self, HPH, R, mask):
        """``S`` with unmeasured channels replaced by unit diagonal entries (they then carry no gain)."""
        Dm = ca.diag(mask)
        return Dm @ (HPH + R) @ Dm + ca.diag(1 - mask)

    @staticmethod
    def gaussian_terms(e, S, mask):
        """NIS and log-likelihood of a masked innovation."""
        L = ca.chol(S) if isinstance(S, ca.SX) else _chol_function(S.shape[0])(S)   # upper, S = L' L
        z = ca.solve(L.T, e)
        nis = ca.dot(z, z)
        logdet = 2 * ca.sum1(ca.log(ca.diag(L)))
        ll = -0.5 * (nis + logdet + ca.sum1(mask) * np.log(2 * np.pi))
        return nis, ll

    def _build_step(self) -> ca.Function:  # pragma: no cover - abstract
        raise NotImplementedError

    # -- public -------------------------------------------------------------------------------
    @property
    def step_function(self) -> ca.Function:
        """The compiled step Function (also the one exported to C)."""
        return self._step

    def carry_from(self, prior: Gaussian, seed=None) -> np.ndarray:
        """The estimator memory for a Gaussian prior (mean and vectorised covariance)."""
        return np.concatenate([prior.mean, prior.cov.reshape(-1, order="F")])

    def extra_inputs(self, n: int, seed) -> list[np.ndarray]:
        """Per-step inputs beyond the common ones (random draws of ensemble filters)."""
        return []

    def prepare(self, data: Dataset, p=None) -> dict:
        """Check a record and turn it into the fold's input arrays (columns = samples)."""
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
        mask = np.isfinite(Y).astype(float)
        dt = np.concatenate([[0.0], np.diff(data.t)])
        U_prev = np.vstack([U[:1], U[:-1]])
        gate = np.full(len(data), np.inf)
        if self.options["gate"] is not None:
            counts = mask.sum(axis=1)
            ok = counts > 0
            gate[ok] = stats.chi2.ppf(self.options["gate"], counts[ok])
        p = m.params() if p is None else m.params(p)
        return dict(u_prev=U_prev.T, u=U.T, y=np.nan_to_num(Y, nan=0.0).T, mask=mask.T, dt=dt[None, :],
                    p=p, Q=self.Q, R=self.R, gate=gate[None, :])

    def fold(self, n: int) -> ca.Function:
        """The step Function folded over ``n`` samples (``mapaccum``), cached per length."""
        if n not in self._folds:
            self._folds[n] = self._step.mapaccum(n)
        return self._folds[n]

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
            For stochastic estimators (EnKF).
        """
        self._check_prior(prior)
        arrays = self.prepare(data, p)
        n = len(data)
        rng = np.random.default_rng(seed)
        args = [self.carry_from(prior, rng)] + [arrays[k] for k in STEP_INPUTS[1:]] + self.extra_inputs(n, rng)
        return self._result(data.t, arrays["mask"].T, self.run_fold(args, n))

    def run_fold(self, args: list, n: int) -> list[np.ndarray]:
        """Evaluate the folded step over ``n`` samples; ``args`` as for the step Function with the
        per-sample inputs as ``n``-column arrays. Returns the outputs stacked over the samples
        (``n`` columns each), except the first, which is the final carry (one column).

        The record runs in pieces of :attr:`FOLD_CHUNK` samples (the last one padded up to a power
        of two with prediction-free, update-free rows whose outputs are dropped), so only a few fold
        lengths are ever built per estimator (building a ``mapaccum`` costs much more for long
        lengths), and each piece is evaluated through preallocated buffers (no ``DM`` conversion).
        The carry is handed from piece to piece; the numbers equal one fold over the whole record.
        """
        per_sample = [i for i in range(1, len(args)) if i not in _CONSTANT_INPUTS]

        def no_op(views, take):
            views[4][:, take:] = 0.0      # mask: no update
            views[5][:, take:] = 0.0      # dt: no prediction

        return fold_in_pieces(self._fold_call, self._step, args, n, per_sample, self.FOLD_CHUNK, no_op)

    def _fold_call(self, size: int) -> BufferedCall:
        """Buffered evaluation of the fold of ``size`` samples (JIT-compiled with option ``jit``)."""
        if size not in self._fold_calls:
            fold = self.fold(size)
            self._fold_calls[size] = BufferedCall(compile_function(fold) if self.options["jit"] else fold)
        return self._fold_calls[size]

    @property
    def _eval_step(self) -> ca.Function:
        """The step Function used for numbers (compiled to C with option ``jit``)."""
        if not self.options["jit"]:
            return self._step
        if self._compiled_step is None:
            self._compiled_step = compile_function(self._step)
        return self._compiled_step

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

    def _result(self, t, mask, out) -> FilterResult:
        nx, ny, n = self.model.nx, self.ny, t.size
        _, x, P, xp, Pp, C, e, S, nis, ll, acc = out
        cube = lambda a, k: a.T.reshape(n, k, k).transpose(0, 2, 1)  # noqa: E731 (column-major blocks)
        e = e.T.copy()
        e[mask == 0] = np.nan
        return FilterResult(
            t=t, x=x.T, P=cube(P, nx), x_pred=xp.T, P_pred=cube(Pp, nx), C=cube(C, nx), innovations=e,
            S=cube(S, ny), nis=nis.ravel(), n_measured=mask.sum(axis=1).astype(int), loglik_terms=ll.ravel(),
            rejected=acc.ravel() < 0.5, state_names=self.model.state_names, output_names=self.measured,
            estimator=self.name, angle_states=self.model.angle_states)

    # -- online -----------------------------------------------------------------------------------
    def _buffered_step(self) -> BufferedCall:
        """A fresh buffered evaluator of the (compiled) step with ``p``, ``Q``, ``R`` preset."""
        call = BufferedCall(self._eval_step)
        call.args[6][:] = self.model.params()
        call.args[7][:] = self.Q.reshape(-1, order="F")
        call.args[8][:] = self.R.reshape(-1, order="F")
        call.args[9][0] = np.inf       # no gate unless set per call
        return call

    def _gate_threshold(self, n_measured: int) -> float:
        gate = self.options["gate"]
        if gate is None or n_measured == 0:
            return np.inf
        cache = self.__dict__.setdefault("_gate_cache", {})
        if n_measured not in cache:
            cache[n_measured] = float(stats.chi2.ppf(gate, n_measured))
        return cache[n_measured]

    def _set_measurement(self, a, y) -> np.ndarray:
        """Write ``y`` (NaN = not measured; the step masks it) and its mask into the buffers."""
        a[3][:] = y
        ok = np.isfinite(a[3])
        np.copyto(a[4], ok)
        if self._gated:
            a[9][0] = self._gate_threshold(int(ok.sum()))
        return ok

    def _evaluate(self, call: BufferedCall) -> None:
        if self._cannot_fail:
            call.trigger()      # SX and compiled code cannot fail: skip the status round trip
        else:
            call()

    def step(self, x, P, u_prev, y, dt, *, u=None, p=None):
        """One online step (predict over ``dt`` with ``u_prev``, then update with ``y``).

        Arguments are numpy arrays; ``y`` may hold NaN for channels not measured now. Evaluation
        goes through preallocated buffers (no CasADi ``DM`` conversion per call). Returns
        ``(x, P, info)``; ``info`` maps ``"e", "nis", "ll", "rejected", "x_pred", "P_pred"`` to
        this step's values. For a loop over a stream, :meth:`online` avoids passing ``x, P`` around.
        """
        nx = self.model.nx
        if self._online is None:
            self._online = self._buffered_step()
        call = self._online
        a = call.args
        c = a[0]
        if c.size != nx + nx * nx:
            raise ValueError(f"{type(self).__name__} with these options keeps more memory than x and P "
                             "(e.g. a re-acquisition counter); use online(prior) for step-by-step use")
        c[:nx] = x
        c[nx:] = np.asarray(P, dtype=float).ravel(order="F")
        a[1][:] = u_prev
        a[2][:] = u_prev if u is None else u
        ok = self._set_measurement(a, y)
        a[5][0] = dt
        if p is not None:
            a[6][:] = self.model.params(p)
        self._evaluate(call)
        snap = call.block.copy()
        o = call.offsets
        return snap[o[1]:o[2]], snap[o[2]:o[3]].reshape(nx, nx, order="F"), StepInfo(snap, o, ok, nx)

    def online(self, prior: Gaussian, p=None, *, u=None, seed=None) -> "OnlineFilter":
        """A stateful online runner started from ``prior`` (see :class:`OnlineFilter`)."""
        self._check_prior(prior)
        return OnlineFilter(self, prior, p, u, seed)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.model.name!r}, measured={list(self.measured)})"


class StepInfo(Mapping):
    """Diagnostics of one online step, read lazily from a snapshot of the step's outputs:
    ``e`` (innovation, NaN where not measured), ``nis``, ``ll``, ``rejected``, ``x_pred``, ``P_pred``."""

    _keys = ("e", "nis", "ll", "rejected", "x_pred", "P_pred")

    def __init__(self, snap, offsets, ok, nx):
        self._snap, self._o, self._ok, self._nx = snap, offsets, ok, nx

    def _out(self, i):
        return self._snap[self._o[i]:self._o[i + 1]]

    def __getitem__(self, key):
        if key == "e":
            return np.where(self._ok, self._out(6), np.nan)
        if key == "nis":
            return float(self._out(8)[0])
        if key == "ll":
            return float(self._out(9)[0])
        if key == "rejected":
            return bool(self._out(10)[0] < 0.5)
        if key == "x_pred":
            return self._out(3)
        if key == "P_pred":
            return self._out(4).reshape(self._nx, self._nx, order="F")
        raise KeyError(key)

    def __iter__(self):
        return iter(self._keys)

    def __len__(self):
        return len(self._keys)


class OnlineFilter:
    """Run an estimator on a stream, one sample per :meth:`update`, keeping its memory inside.

    The estimator's memory (mean and covariance, or the ensemble) stays in the step's input
    buffer between calls, so a call writes only the new measurement and time step, evaluates the
    (compiled) step Function and copies the memory back: the cheapest online use. Numbers equal
    :meth:`Estimator.filter` on the same record (ensemble filters draw from ``seed`` in the same order).

    Examples
    --------
    >>> run = ekf.online(prior)                      # doctest: +SKIP
    >>> for y, dt in stream:                          # doctest: +SKIP
    ...     x = run.update(y, dt)
    """

    def __init__(self, est: Estimator, prior: Gaussian, p=None, u=None, seed=None):
        self.est = est
        self._rng = np.random.default_rng(seed)
        self._call = call = est._buffered_step()
        if p is not None:
            call.args[6][:] = est.model.params(p)
        call.args[0][:] = est.carry_from(prior, self._rng)
        u0 = np.zeros(est.model.nu) if u is None else np.asarray(u, dtype=float)
        call.args[1][:] = u0
        call.args[2][:] = u0
        self._n_extra = len(call.args) - len(STEP_INPUTS)
        self._first = True
        nx = est.model.nx
        self._x, self._P = call.res[1], call.res[2]
        self._ok = None
        self._nx = nx
        self._carry_out = call.res[0]

    def update(self, y, dt: float, u_prev=None, u=None) -> np.ndarray:
        """Predict over ``dt`` (0 for the first sample is allowed) with the input ``u_prev`` held
        (the previous input by default), update with ``y`` (NaN = not measured); returns a copy of
        the new mean."""
        a = self._call.args
        if self._first:
            self._first = False
        else:
            a[0][:] = self._carry_out
        if u_prev is not None:
            a[1][:] = u_prev
            a[2][:] = u_prev if u is None else u
        elif u is not None:
            a[2][:] = u
        est = self.est
        self._ok = est._set_measurement(a, y)
        a[5][0] = dt
        if self._n_extra:
            for i, z in enumerate(est.extra_inputs(1, self._rng)):
                a[len(STEP_INPUTS) + i][:] = z[:, 0]
        if est._cannot_fail:
            self._call.trigger()
        else:
            self._call()
        return self._x.copy()

    @property
    def x(self) -> np.ndarray:
        """Current mean (copy)."""
        return self._x.copy()

    @property
    def P(self) -> np.ndarray:
        """Current covariance (copy)."""
        return self._P.reshape(self._nx, self._nx, order="F").copy()

    @property
    def info(self) -> StepInfo:
        """Diagnostics of the last update."""
        return StepInfo(self._call.block.copy(), self._call.offsets, self._ok, self._nx)
