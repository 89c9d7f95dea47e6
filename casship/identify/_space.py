"""The free quantities of an identification problem and how each record sees them.

A free quantity is one of

* a model parameter (``"N_r_dash"``);
* a bias: ``"bias[n]"`` on an input (the model is driven by the measured ``n`` plus the bias) or
  ``"bias[psi]"`` on a measured output (the sensor reads the model output plus the bias);
* a noise variance ``"Q[w_r]"`` / ``"R[psi]"`` (likelihood problems; optimised through its logarithm);
* the initial value of a state in one record (``"psi@3"``).

Parameters and biases are shared by all records unless declared otherwise: a quantity that is per
record has one copy per record (``"R_0_dash@0"``, ``"R_0_dash@1"``, ...), a quantity shared by
groups has one copy per group label (``"bias[n]@HSVA"``). Records outside every group keep the fixed
value (0 for a bias).

Each record sees the free values ``theta`` through an affine map (:class:`RecordMap`): its
parameter vector, noise variances, biases and initial state are ``fixed + E @ theta[cols]``. The
matrices ``E`` are numbers, so compiled code that takes them as inputs serves every record, every
free set of the same size and every cross-validation fold. The optimiser works on scaled variables
``z = value / scale`` (``log(value)`` for variances), all of order one.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..model import Model
from ..errors import InputError

__all__ = ["Quantity", "ParamSpace", "RecordMap", "KINDS", "VAR_FLOOR"]

KINDS = ("param", "bias_in", "bias_out", "Q", "R", "x0")
VAR_FLOOR = 1e-10  # lower bound of an estimated variance, relative to its starting value


@dataclass(frozen=True)
class Quantity:
    """One free quantity.

    Attributes
    ----------
    name : str
        Its name in results (``"K"``, ``"R_0_dash@2"``, ``"bias[n]@HSVA"``, ``"Q[w_r]"``, ``"psi@0"``).
    kind : str
        One of ``param, bias_in, bias_out, Q, R, x0``.
    index : int
        Position in the parameter / input / measured-output / noise / state vector.
    records : tuple of int
        The records it acts on.
    declared : str
        The name it was declared under (``"R_0_dash"`` for ``"R_0_dash@2"``).
    start : float
        Default starting value (the fixed value it replaces; 0 for a bias).
    log : bool
        Optimised through its logarithm (variances).
    scale, lower, upper : float
    """

    name: str
    kind: str
    index: int
    records: tuple
    declared: str
    start: float
    log: bool = False
    scale: float = 1.0
    lower: float = -np.inf
    upper: float = np.inf


@dataclass(frozen=True)
class RecordMap:
    """How one record sees the free values: ``value = fixed + E @ theta[cols]`` for each block.

    ``p`` (np), ``u`` (input biases, nu), ``y`` (output biases, n measured), ``Q`` and ``R``
    (variances on the diagonal), ``x0`` (initial state): ``fixed`` holds the values with the free
    entries zeroed, ``E`` the 0/1 matrices (rows of the block, columns ``cols``).
    """

    cols: np.ndarray
    fixed: dict
    E: dict

    def values(self, theta: np.ndarray) -> dict:
        """The record's blocks at the (global) free values ``theta``."""
        loc = np.asarray(theta, dtype=float)[self.cols]
        return {k: self.fixed[k] + self.E[k] @ loc for k in self.fixed}

    @property
    def k(self) -> int:
        return int(self.cols.size)


class ParamSpace:
    """The free quantities of a problem, their starts, bounds, scales and record maps.

    Parameters
    ----------
    model : Model
    n_records : int
    free : sequence of str
        Declared free model parameters and biases (``"bias[n]"``, ``"bias[psi]"``).
    copies : mapping name -> list of labels
        For each declared name shared otherwise than by all records, one label per record:
        records with equal labels share a copy named ``name@label``; ``None`` means the record keeps
        the fixed value.
    base : (np,) array
        Fixed parameter values.
    measured : sequence of str
        Measured outputs (the rows of output biases and of ``R``).
    noise : sequence of (kind, channel index, name, start)
        Free variances (``kind`` ``"Q"`` or ``"R"``).
    x0 : sequence of (record, state index, start)
        Free initial states.
    x0_fixed : list of (nx,) arrays
        Initial states of the records (free entries are replaced).
    Q, R : arrays
        Fixed noise covariances (likelihood problems; zeros otherwise).
    record_base : sequence of (np,) arrays or None, optional
        Fixed parameter values of each record where they differ from ``base`` (e.g. a facility's
        own measured wake); ``None`` for a record at ``base``. A new run is at ``base``.
    bounds, scale : mapping name -> (lower, upper) / magnitude, optional
        For any free quantity; a declared name applies to all its copies.
    """

    def __init__(self, model: Model, n_records: int, free: Sequence[str], *, copies: Mapping | None = None,
                 base=None, measured: Sequence[str] = (), noise=(), x0=(), x0_fixed=None, Q=None, R=None,
                 bounds: Mapping | None = None, scale: Mapping | None = None, record_base=None):
        free = list(free)
        twice = sorted({n for n in free if free.count(n) > 1})
        if twice:
            raise InputError(f"free quantities listed twice: {twice}")
        self.model, self.n_records, self.measured = model, int(n_records), tuple(measured)
        self.base = np.asarray(model.params() if base is None else base, dtype=float)
        if record_base is not None and len(record_base) != int(n_records):
            raise InputError(f"record_base: {len(record_base)} entries for {int(n_records)} records")
        self.record_base = [self.base if b is None else np.asarray(b, dtype=float)
                            for b in (record_base if record_base is not None else [None] * int(n_records))]
        copies = dict(copies or {})
        unknown = set(copies) - set(free)
        if unknown:
            raise InputError(f"sharing declared for {sorted(unknown)}, which are not free; free: {free}")
        self.Q = np.zeros((model.nw, model.nw)) if Q is None else np.asarray(Q, dtype=float)
        self.R = np.zeros((len(self.measured),) * 2) if R is None else np.asarray(R, dtype=float)
        self.x0_fixed = [np.zeros(model.nx)] * self.n_records if x0_fixed is None else \
            [np.asarray(v, dtype=float) for v in x0_fixed]
        everyone = tuple(range(self.n_records))
        raw = []
        for n in free:
            kind, index, start = self._declared(n)
            labels = copies.get(n)
            if labels is None:
                raw.append(Quantity(n, kind, index, everyone, n, start))
                continue
            if len(labels) != self.n_records:
                raise InputError(f"sharing of {n!r}: {len(labels)} labels for {self.n_records} records")
            for label in dict.fromkeys(lab for lab in labels if lab is not None):
                recs = tuple(i for i, lab in enumerate(labels) if lab == label)
                raw.append(Quantity(f"{n}@{label}", kind, index, recs, n, start))
        for kind, i, name, start in noise:
            raw.append(Quantity(name, kind, int(i), everyone, name, float(start), log=True))
        for r, i, start in x0:
            name = f"{model.state_names[i]}@{r}"
            raw.append(Quantity(name, "x0", int(i), (int(r),), name, float(start)))
        self.entries = self._bounded(raw, dict(bounds or {}), dict(scale or {}))
        self.names = [e.name for e in self.entries]
        self.default_guess = {e.name: e.start for e in self.entries}
        self._maps = [self._record_map(r) for r in range(self.n_records)]

    # -- declaration -------------------------------------------------------------------------------
    def _declared(self, name: str):
        m = self.model
        if name.startswith("bias[") and name.endswith("]"):
            ch = name[5:-1]
            if ch in m.input_names:
                return "bias_in", m.index(ch, "input"), 0.0
            if ch in self.measured:
                return "bias_out", self.measured.index(ch), 0.0
            raise InputError(f"{name!r}: {ch!r} is neither an input {list(m.input_names)} nor a measured "
                             f"output {list(self.measured)} of {m.name!r}")
        i = m.index(name, "param")
        return "param", i, float(self.base[i])

    def _bounded(self, raw, bounds, scale) -> list[Quantity]:
        m = self.model
        names = [q.name for q in raw]
        declared = {q.declared for q in raw}
        unknown = (set(bounds) | set(scale)) - set(names) - declared
        if unknown:
            raise InputError(f"bounds/scale given for {sorted(unknown)}, which are not free; free: {names}")
        out = []
        for q in raw:
            lo, hi = (m.param_lower[q.index], m.param_upper[q.index]) if q.kind == "param" else (-np.inf, np.inf)
            b = bounds.get(q.name, bounds.get(q.declared))
            if b is not None:
                if len(b) != 2 or not float(b[0]) < float(b[1]):
                    raise InputError(f"bounds of {q.name!r} must be (lower, upper) with lower < upper, got {b}")
                lo, hi = max(lo, float(b[0])), min(hi, float(b[1]))
            if q.log:
                if not q.start > 0:
                    raise InputError(f"starting value of variance {q.name!r} must be positive, got {q.start}")
                lo = max(lo, VAR_FLOOR * q.start)   # a variance the data cannot tell from 0 stops here
            s = scale.get(q.name, scale.get(q.declared))
            if s is not None and not (np.isfinite(float(s)) and float(s) > 0):
                raise InputError(f"scale of {q.name!r} must be positive, got {s}")
            if s is None:
                nominal = m.params()[q.index] if q.kind == "param" else 0.0
                s = abs(q.start) or abs(nominal) or 1.0
            out.append(Quantity(q.name, q.kind, q.index, q.records, q.declared, q.start, q.log,
                                1.0 if q.log else float(s), lo, hi))
        return out

    def _record_map(self, r: int) -> RecordMap:
        m = self.model
        cols = np.array([j for j, e in enumerate(self.entries) if r in e.records], dtype=int)
        fixed = {"p": self.record_base[r].copy(), "u": np.zeros(m.nu), "y": np.zeros(len(self.measured)),
                 "Q": np.diag(self.Q).copy(), "R": np.diag(self.R).copy(), "x0": self.x0_fixed[r].copy()}
        block = {"param": "p", "bias_in": "u", "bias_out": "y", "Q": "Q", "R": "R", "x0": "x0"}
        E = {k: np.zeros((v.size, cols.size)) for k, v in fixed.items()}
        for c, j in enumerate(cols):
            e = self.entries[j]
            b = block[e.kind]
            if b != "u" and b != "y":
                fixed[b][e.index] = 0.0
            E[b][e.index, c] = 1.0
        return RecordMap(cols, fixed, E)

    # -- queries ---------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.entries)

    def record_map(self, r: int) -> RecordMap:
        return self._maps[r]

    def kinds(self, *kinds: str) -> list[int]:
        """Positions of the entries of the given kinds."""
        return [j for j, e in enumerate(self.entries) if e.kind in kinds]

    def declared_names(self) -> list[str]:
        return list(dict.fromkeys(e.declared for e in self.entries))

    # -- maps between decision variables and values ----------------------------------------------
    def natural(self, z) -> np.ndarray:
        z = np.asarray(z, dtype=float).reshape(-1)
        with np.errstate(over="ignore"):    # a trial step beyond float range is inf; the solver rejects it
            return np.array([np.exp(z[i]) if e.log else z[i] * e.scale for i, e in enumerate(self.entries)])

    def jac_natural(self, z) -> np.ndarray:
        """Diagonal of d(value)/dz (for the chain rule and the delta method)."""
        z = np.asarray(z, dtype=float).reshape(-1)
        return np.array([np.exp(z[i]) if e.log else e.scale for i, e in enumerate(self.entries)])

    def to_z(self, values) -> np.ndarray:
        values = np.asarray(values, dtype=float).reshape(-1)
        z = []
        for e, v in zip(self.entries, values):
            if e.log:
                if not v > 0:
                    raise InputError(f"value of variance {e.name!r} must be positive, got {v}")
                z.append(np.log(v))
            else:
                z.append(v / e.scale)
        return np.array(z)

    def theta(self, values=None) -> np.ndarray:
        """Free values as a vector ordered like :attr:`names` from a mapping (missing names keep their
        default start) or a vector; checked against the bounds."""
        if values is None or isinstance(values, Mapping):
            values = dict(values or {})
            unknown = set(values) - set(self.names)
            if unknown:
                raise InputError(f"values for {sorted(unknown)}, which are not free; free: {self.names}")
            merged = {**self.default_guess, **{k: float(v) for k, v in values.items()}}
            theta = np.array([merged[n] for n in self.names])
        else:
            theta = np.asarray(values, dtype=float).reshape(-1)
            if theta.size != len(self):
                raise InputError(f"expected {len(self)} values for {self.names}, got {theta.size}")
        return theta

    def check_bounds(self, theta) -> None:
        for e, v in zip(self.entries, theta):
            if not np.isfinite(v):
                raise InputError(f"value of {e.name!r} is not finite")
            if not e.lower <= v <= e.upper:
                raise InputError(f"value {v:g} of {e.name!r} is outside its bounds [{e.lower:g}, {e.upper:g}]")

    def z_bounds(self):
        lo, hi = [], []
        for e in self.entries:
            if e.log:
                lo.append(np.log(e.lower) if e.lower > 0 else -np.inf)
                hi.append(np.log(e.upper) if np.isfinite(e.upper) else np.inf)
            else:
                lo.append(e.lower / e.scale)
                hi.append(e.upper / e.scale)
        return np.array(lo), np.array(hi)

    def scales(self) -> dict[str, float]:
        return {e.name: (0.0 if e.log else e.scale) for e in self.entries}

    def params(self, theta, record: int | None = None) -> np.ndarray:
        """The parameter vector of ``record`` at ``theta``; without a record, the one for a new run:
        shared estimates, per-record and per-group parameters at their fixed values."""
        if record is not None:
            return self._maps[record].values(theta)["p"]
        p = self.base.copy()
        for e, v in zip(self.entries, theta):
            if e.kind == "param" and e.name == e.declared:
                p[e.index] = v
        return p
