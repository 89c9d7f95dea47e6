"""Cost, exact gradient and Gauss-Newton / Fisher matrix of an identification problem, compiled.

One per-sample CasADi Function carries the state (or the filter's memory) together with its
forward sensitivities to the free values and is folded (``mapaccum``) over chunks of
:func:`casship.runtime.fold_chunk` samples (the runtime's one driver, :func:`casship.runtime.run_pieces`). Its inputs are the record's samples and the record's affine map of the free
values (:class:`~casship.identify._space.RecordMap`: parameter vector, biases, noise and initial
state with their derivative matrices), so the compiled code depends only on the model, the
estimator, the number of free values a record sees and which inputs they enter through, never on
the data or on which quantities are free. A record's last chunk is padded with samples that
neither predict (``dt = 0``) nor measure (``mask = 0``), which leave the memory unchanged.

Records run chunk by chunk in step: the records at the same chunk position that use the same
Function are evaluated in one call of its ``map`` over records (threads), so a many-record fit uses
the cores the machine has (the runtime's driver does that).

Build once, run many: the Functions are kept per process under the *structure* of the problem
(the model's step and output Functions, which outputs are measured, the kind and size of the
fold), so a problem of the same structure (another fold of a cross-validation, another free set
of the same size, ``replace``, ``subset``) neither builds nor compiles them again.

* Output error (:class:`OutputErrorEngine`): per sample the weighted residual ``r_k`` and its
  Jacobian ``J_k``; cost ``0.5 sum r'r``, gradient ``J'r``, Gauss-Newton matrix ``J'J``.
* Likelihood (:class:`~casship.identify._likelihood.LikelihoodEngine`): per sample the
  log-likelihood term and its gradient; the Fisher information accumulated in the fold.

Trial points of the optimiser need the cost only (a lean fold without sensitivities); the gradient
alone comes from a backward sweep of the lean fold's reverse mode (cost independent of the number
of free values).
"""
from __future__ import annotations

import hashlib

import casadi as ca
import numpy as np

from ..angles import wrap_sym
from ..runtime import COUNTS as _COUNTS, THREADS, Job, JitPolicy, fold_chunk, run_pieces, shared_function, shared_functions

__all__ = ["OutputErrorEngine", "Job", "run_jobs", "chunk", "THREADS"]

COUNTS = _COUNTS.setdefault("identify", {"built": 0, "reused": 0})   # Functions built and found again


def chunk() -> int:
    """Samples per piece of the identification's folds (the runtime's one setting)."""
    return fold_chunk()



def fold(fun: ca.Function, accumulate: dict, constants) -> ca.Function:
    """``fun`` folded over :func:`chunk` samples: inputs ``accumulate`` (name -> output name) carried
    from sample to sample (only their final values are returned), ``constants`` the same for every
    sample, all other inputs and outputs side by side per sample."""
    n = chunk()
    acc = fun.mapaccum(f"{fun.name()}_fold", n, list(accumulate), list(accumulate.values()), {})
    ins = {k: ca.MX.sym(k, fun.size1_in(k), fun.size2_in(k) * (1 if k in accumulate or k in constants else n))
           for k in fun.name_in()}
    outs = acc.call({k: ca.repmat(v, 1, n) if k in constants else v for k, v in ins.items()})
    res = {k: (outs[k][:, -fun.size2_out(k):] if k in accumulate.values() else outs[k]) for k in fun.name_out()}
    return ca.Function(f"{fun.name()}_fold{n}", list(ins.values()), list(res.values()), list(ins), list(res))


def per_sample(a, n_rows: int, cols: int, take: int) -> np.ndarray:
    """A stacked fold output (``rows x cols*chunk``) as ``(take, rows, cols)``."""
    a = np.asarray(a, dtype=float).reshape(n_rows, -1, cols)
    return a.transpose(1, 0, 2)[:take]


def run_jobs(jobs: list[Job]) -> list[list[tuple[dict, dict, int]]]:
    """Run each job piece by piece (the runtime's driver); per job the ``(args, outputs, samples)`` of
    each piece."""
    return [r["pieces"] for r in run_pieces(jobs)]


class Engine:
    """Shared evaluation of a problem's records: cost, gradient (reverse mode), curvature."""

    def __init__(self, space, jit):
        self.space, self.jit = space, JitPolicy.of(jit)
        self._signature = None
        self._last: dict = {}     # kind -> (free values as bytes, result): the last evaluation of each kind

    def _again(self, kind: str, theta, compute):
        """``compute()``, or its result of the last call of ``kind`` at the same free values (to the
        bit): a solve checks, starts and ends at points its caller has often just evaluated."""
        key = np.asarray(theta, dtype=float).tobytes()
        last = self._last.get(kind)
        if last is None or last[0] != key:
            last = self._last[kind] = (key, compute())
        return last[1]

    def _structure(self) -> tuple:
        """What the Functions of this engine depend on: Functions and plain values (subclasses)."""
        raise NotImplementedError

    def signature(self) -> str:
        """A digest of :meth:`_structure`: engines with equal signatures share their Functions."""
        if self._signature is None:
            h = hashlib.sha256(type(self).__name__.encode())
            for part in self._structure():
                h.update(b"\0" + (part.serialize() if isinstance(part, ca.Function) else repr(part)).encode())
            self._signature = h.hexdigest()
        return self._signature

    def _fun(self, key, make):
        """The Function ``make()``, built once per process for every engine of the same structure
        (a compile still running in the background gives the interpreted Function meanwhile)."""
        return shared_function(("identify", self.signature(), chunk(), key), make, self.jit)

    def _raw(self, key, make):
        """The Function ``make()`` interpreted, built once per process per structure (the compiled ones
        are built from it)."""
        return shared_function(("identify", self.signature(), chunk(), key), make, JitPolicy.OFF)

    def functions(self) -> dict:
        """This engine's compiled Functions as built so far (a background compile still as its handle)."""
        return {k[3]: f for k, f in shared_functions(("identify", self.signature(), chunk())).items()
                if k[-1] is self.jit}

    def _value_fold(self):
        return self._fun("value_c", self._value_raw)

    def _reverse_fold(self):
        return self._fun("reverse_c", lambda: self._value_raw().reverse(1))

    def _records(self, records=None):
        return range(self.space.n_records) if records is None else records

    def cost(self, theta) -> tuple[float, np.ndarray]:
        """Total cost and the cost of each record at the free values ``theta``."""
        return self._again("cost", theta, lambda: self._cost(theta))

    def _cost(self, theta):
        runs = run_jobs([self._job(r, theta, "value")[0] for r in self._records()])
        per = np.array([sum(self._chunk_cost(out, take) for _, out, take in run) for run in runs])
        return float(per.sum()), per

    def derivatives(self, theta):
        """Cost, gradient, curvature (Gauss-Newton or Fisher) and per-record details at ``theta``.

        Returns ``(f, g, H, details)``; ``details[r]`` holds ``f``, ``cols`` (the free values the
        record sees), per-sample ``scores`` (gradient contributions, ``(N, k_r)``) and normalised
        ``residuals`` (``(N, ny)``, NaN where not measured). The arrays are shared with the next call
        at the same ``theta``: read them, do not change them.
        """
        return self._again("derivatives", theta, lambda: self._derivatives(theta))

    def _derivatives(self, theta):
        k = len(self.space)
        jobs = [self._job(r, theta, "sens") for r in self._records()]
        runs = run_jobs([j for j, _ in jobs])
        f, g, H, details = 0.0, np.zeros(k), np.zeros((k, k)), []
        for r, ((_, ctx), run) in enumerate(zip(jobs, runs)):
            d = self._details(r, ctx, run)
            c = d["cols"]
            f += d["f"]
            g[c] += d["g"]
            H[np.ix_(c, c)] += d["H"]
            details.append(d)
        return f, g, 0.5 * (H + H.T), details

    def gradient(self, theta) -> np.ndarray:
        """Exact gradient of the cost by reverse mode: one backward sweep through the chunks of each
        record, whatever the number of free values."""
        g = np.zeros(len(self.space))
        jobs = [self._job(r, theta, "value") for r in self._records()]
        for r, ((_, ctx), run) in enumerate(zip(jobs, run_jobs([j for j, _ in jobs]))):
            rm = self.space.record_map(r)
            g[rm.cols] += self._record_gradient(rm, ctx, run)
        return g

    def _sweep(self, run, seeds, memory):
        """Backward sweep of the reverse fold over a record's chunks ``run``; ``seeds(outs, take)``
        gives the adjoints of the per-sample outputs, ``memory`` the accumulated inputs. Returns the
        adjoints of the first chunk's memory and the sums of the adjoints of the other inputs."""
        rev = self._reverse_fold()
        adj_mem = {m: np.zeros(np.asarray(run[0][0][m]).size) for m in memory}
        sums: dict = {}
        for args, outs, take in reversed(run):
            kw = {**args, **{f"out_{o}": v for o, v in outs.items()}, **seeds(outs, take)}
            kw.update({f"adj_{m}_next": adj_mem[m] for m in memory})
            res = rev(**kw)
            adj_mem = {m: np.asarray(res[f"adj_{m}"]).reshape(-1) for m in memory}
            for n in args:
                if n not in memory:
                    a = np.asarray(res[f"adj_{n}"])
                    part = a[:, :take].sum(axis=1) if a.shape[1] == chunk() else a.reshape(-1)
                    sums[n] = sums.get(n, 0.0) + part
        return adj_mem, sums


class OutputErrorEngine(Engine):
    """Weighted simulated-output residuals of a discrete model (single shooting).

    Parameters
    ----------
    dmodel : DiscreteModel
    space : ParamSpace
    arrays : list of dict
        Per record ``U`` (nu, N), ``Y`` (ny, N, 0 where not measured), ``mask`` (ny, N), ``dt`` (1, N:
        time to the next sample, 0 on the last).
    meas_index : list of int
        Rows of the model outputs that are measured.
    weights : (ny,) array
        ``1 / sigma`` per measured output.
    jit : bool or None
    record_scale : (n_records,) array, optional
        Factor of each record's residuals (the square root of its weight in the cost).
    """

    def __init__(self, dmodel, space, arrays, meas_index, weights, jit=None, record_scale=None):
        super().__init__(space, jit)
        self.dmodel, self.model, self.arrays = dmodel, dmodel.model, arrays
        self.meas_index = list(meas_index)
        self.angle = self.model.angle_outputs[self.meas_index]
        self.weights = np.asarray(weights, dtype=float)
        self.record_scale = np.ones(len(arrays)) if record_scale is None else np.asarray(record_scale, dtype=float)

    def _structure(self) -> tuple:
        return (self.dmodel.F, self.model.h, tuple(self.meas_index), tuple(bool(a) for a in self.angle),
                self.model.nw, self.dmodel.symbolic.__name__)

    def _symbols(self):
        m, ny = self.model, len(self.meas_index)
        sym = self.dmodel.symbolic
        s = {"x": sym.sym("x", m.nx), "u": sym.sym("u", m.nu), "y": sym.sym("y", ny), "mask": sym.sym("mask", ny),
             "dt": sym.sym("dt"), "p": sym.sym("p", m.np), "w": sym.sym("w", ny)}
        yhat = m.h(s["x"], s["u"], s["p"])[self.meas_index]
        e = s["y"] - yhat
        e = ca.vertcat(*[wrap_sym(e[i]) if a else e[i] for i, a in enumerate(self.angle)]) if self.angle.any() else e
        s["r"] = s["w"] * s["mask"] * e
        s["x_next"] = self.dmodel.F(s["x"], s["u"], s["p"], sym.zeros(m.nw), s["dt"])
        return s

    def _value_raw(self):
        def make():
            s = self._symbols()
            names = ["x", "u", "y", "mask", "dt", "p", "w"]
            fun = ca.Function("oe_value", [s[n] for n in names], [s["x_next"], s["r"]], names, ["x_next", "r"])
            return fold(fun, {"x": "x_next"}, ("p", "w"))
        return self._raw("value", make)

    def _sens_fold(self, k: int, seeds: tuple):
        """The sensitivity fold for ``k`` free values entering through the inputs ``seeds`` (a subset of
        ``p, u, y``; the state always)."""
        def make():
            m, sym = self.model, self.dmodel.symbolic
            s = self._symbols()
            d = {"dx": sym.sym("dx", m.nx, k)}
            d.update({f"d{n}": sym.sym(f"d{n}", s[n].numel(), k) for n in seeds})
            wrt = ca.vertcat(s["x"], *(s[n] for n in seeds))
            seed = ca.vertcat(d["dx"], *(d[f"d{n}"] for n in seeds))
            Jx = ca.jtimes(s["x_next"], wrt, seed)
            Jr = ca.jtimes(s["r"], wrt, seed)
            names = ["x", "dx", "u", "y", "mask", "dt", "p", "w", *(f"d{n}" for n in seeds)]
            fun = ca.Function(f"oe_sens{k}_{''.join(seeds)}", [s.get(n, d.get(n)) for n in names],
                              [s["x_next"], Jx, s["r"], Jr], names, ["x_next", "dx_next", "r", "J"])
            consts = ("p", "w", *(f"d{n}" for n in seeds))
            return fold(fun, {"x": "x_next", "dx": "dx_next"}, consts)
        return self._fun(("sens", k, seeds), make)

    def _job(self, r, theta, kind):
        rm = self.space.record_map(r)
        v = rm.values(theta)
        a = self.arrays[r]
        per = {"u": a["U"] + v["u"][:, None], "y": a["Y"] - v["y"][:, None], "mask": a["mask"], "dt": a["dt"]}
        consts = {"p": v["p"], "w": self.weights * self.record_scale[r]}
        if kind == "value":
            return Job(self._value_fold(), {"x": v["x0"]}, consts, per, a["U"].shape[1]), {"rm": rm}
        blocks = {"p": rm.E["p"], "u": rm.E["u"], "y": -rm.E["y"]}
        seeds = tuple(n for n, E in blocks.items() if E.any())
        consts.update({f"d{n}": blocks[n] for n in seeds})
        state = {"x": v["x0"], "dx": rm.E["x0"]}
        return Job(self._sens_fold(rm.k, seeds), state, consts, per, a["U"].shape[1]), {"rm": rm, "mask": a["mask"]}

    @staticmethod
    def _chunk_cost(out, take) -> float:
        return 0.5 * float(np.sum(out["r"][:, :take] ** 2))

    def residuals(self, r, theta) -> np.ndarray:
        """Weighted residuals (N, ny) of record ``r`` at ``theta`` (0 where not measured)."""
        run = run_jobs([self._job(r, theta, "value")[0]])[0]
        return np.hstack([out["r"][:, :take] for _, out, take in run]).T

    def _details(self, r, ctx, run) -> dict:
        rm, k = ctx["rm"], ctx["rm"].k
        R = np.vstack([out["r"][:, :take].T for _, out, take in run])                    # (N, ny)
        scores, H = [], np.zeros((k, k))
        for _, out, take in run:
            # a chunk's J (ny, chunk * k) holds sample s in columns s*k:(s+1)*k; stored column-major it
            # is a (chunk, k, ny) array without a copy. Small products by einsum: no BLAS threads
            A = np.asarray(out["J"]).T.reshape(-1, k, out["r"].shape[0])[:take]
            scores.append(np.einsum("sjy,sy->sj", A, out["r"][:, :take].T))
            H += np.einsum("sjy,sly->jl", A, A)
        scores = np.concatenate(scores)
        return {"f": 0.5 * float(np.sum(R**2)), "g": scores.sum(axis=0), "H": H, "cols": rm.cols,
                "scores": scores, "residuals": np.where(ctx["mask"].T > 0, R, np.nan)}

    def _record_gradient(self, rm, ctx, run) -> np.ndarray:
        adj_x, sums = self._sweep(run, lambda out, take: {"adj_r": out["r"]}, ("x",))
        E = rm.E
        return E["p"].T @ sums["p"] + E["u"].T @ sums["u"] - E["y"].T @ sums["y"] + E["x0"].T @ adj_x["x"]
