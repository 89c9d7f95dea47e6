"""Cost, exact gradient and Gauss-Newton / Fisher matrix of an identification problem, compiled.

One per-sample CasADi Function carries the state (or the filter's memory) together with its
forward sensitivities to the free values and is folded (``mapaccum``) over chunks of
:data:`CHUNK` samples. Its inputs are the record's samples and the record's affine map of the free
values (:class:`~casship.identify._space.RecordMap`: parameter vector, biases, noise and initial
state with their derivative matrices), so the compiled code depends only on the model, the
estimator and the number of free values a record sees, never on the data or on which quantities
are free. Records run chunk by chunk; a record's last chunk is padded with samples that neither
predict (``dt = 0``) nor measure (``mask = 0``), which leave the memory unchanged.

* Output error: per sample the weighted residual ``r_k`` and its Jacobian ``J_k``; cost
  ``0.5 sum r'r``, gradient ``J'r``, Gauss-Newton matrix ``J'J``.
* Likelihood: per sample the log-likelihood term and its gradient; the Fisher information of the
  innovations ``sum De' S^-1 De + 0.5 tr(S^-1 dS_i S^-1 dS_j)`` accumulated in the fold.

Trial points of the optimiser need the cost only: a lean fold without sensitivities.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..angles import wrap_sym
from ..estimators.base import CONSTANT_INPUTS, SAMPLE_INPUTS
from ._compile import compiled

__all__ = ["CHUNK", "OutputErrorEngine", "LikelihoodEngine", "StepSlots"]

CHUNK = 256


def _flat_symbols(sym, fun: ca.Function, names):
    """Flat symbols for the named inputs of ``fun`` and the same reshaped to the inputs' shapes."""
    flat = {n: sym.sym(n, fun.nnz_in(n)) for n in names}
    shaped = {n: ca.reshape(flat[n], fun.size1_in(n), fun.size2_in(n)) for n in names}
    return flat, shaped


def _fold(fun: ca.Function, accumulate: dict, constants) -> ca.Function:
    """``fun`` folded over :data:`CHUNK` samples: inputs ``accumulate`` (name -> output name) carried
    from sample to sample (only their final values are returned), ``constants`` the same for every
    sample, all other inputs and outputs side by side per sample."""
    acc = fun.mapaccum(f"{fun.name()}_fold", CHUNK, list(accumulate), list(accumulate.values()), {})
    ins = {n: ca.MX.sym(n, fun.size1_in(n), fun.size2_in(n) * (1 if n in accumulate or n in constants else CHUNK))
           for n in fun.name_in()}
    outs = acc.call({n: ca.repmat(v, 1, CHUNK) if n in constants else v for n, v in ins.items()})
    res = {n: (outs[n][:, -fun.size2_out(n):] if n in accumulate.values() else outs[n]) for n in fun.name_out()}
    return ca.Function(f"{fun.name()}_fold{CHUNK}", list(ins.values()), list(res.values()), list(ins), list(res))


def _pieces(n: int):
    """(start, stop) of the chunks of a record of ``n`` samples."""
    return [(s, min(s + CHUNK, n)) for s in range(0, n, CHUNK)]


def _chunk(a: np.ndarray, start: int, stop: int, zero: bool = False) -> np.ndarray:
    """Columns ``start:stop`` of ``a`` padded to :data:`CHUNK` (last column repeated, or zeros)."""
    part = a[:, start:stop]
    if stop - start == CHUNK:
        return part
    pad = np.zeros((a.shape[0], CHUNK - (stop - start))) if zero else np.repeat(part[:, -1:], CHUNK - (stop - start), 1)
    return np.hstack([part, pad])


def _per_sample(a, n_rows: int, cols: int, take: int) -> np.ndarray:
    """A stacked fold output (``rows x cols*CHUNK``) as ``(take, rows, cols)``."""
    a = np.asarray(a, dtype=float).reshape(n_rows, CHUNK, cols)
    return a.transpose(1, 0, 2)[:take]


class _Engine:
    """Shared evaluation loop: per record, chunk by chunk, summing cost, gradient and curvature."""

    def __init__(self, space, jit):
        self.space, self.jit = space, jit
        self._funs: dict = {}

    def _fun(self, key, make):
        """The Function ``make()`` (a fold), built once, and compiled (``key`` ends with ``"c"``)."""
        if key not in self._funs:
            self._funs[key] = make()
        return self._funs[key]

    def _value_fold(self):
        return self._fun("value_c", lambda: compiled(self._value_raw(), jit=self.jit))

    def _reverse_fold(self):
        return self._fun("reverse_c", lambda: compiled(self._value_raw().reverse(1), jit=self.jit))

    def gradient(self, theta) -> np.ndarray:
        """Exact gradient of the cost by reverse mode: one backward sweep through the chunks of each
        record, whatever the number of free values."""
        g = np.zeros(len(self.space))
        for r in range(self.space.n_records):
            rm = self.space.record_map(r)
            g[rm.cols] += self._record_gradient(r, theta, rm)
        return g

    def _sweep(self, calls, seeds, memory: dict):
        """Backward sweep of the reverse fold over the chunk ``calls`` [(args, outs, take)]; ``seeds(outs,
        take)`` gives the adjoints of the per-sample outputs, ``memory`` maps memory inputs to the
        outputs that continue them. Returns the adjoints of the first chunk's memory and the sums of
        the adjoints of every other input over the real samples."""
        rev = self._reverse_fold()
        adj_mem = {m: np.zeros(np.asarray(calls[0][0][m]).size) for m in memory}
        sums: dict = {}
        for args, outs, take in reversed(calls):
            kw = {**args, **{f"out_{o}": v for o, v in outs.items()}, **seeds(outs, take)}
            kw.update({f"adj_{memory[m]}": adj_mem[m] for m in memory})
            res = rev(**kw)
            adj_mem = {m: np.asarray(res[f"adj_{m}"]).reshape(-1) for m in memory}
            for n in args:
                if n in memory:
                    continue
                a = np.asarray(res[f"adj_{n}"])
                part = a[:, :take].sum(axis=1) if a.shape[1] == CHUNK else a.reshape(-1)
                sums[n] = sums.get(n, 0.0) + part
        return adj_mem, sums

    def cost(self, theta) -> tuple[float, np.ndarray]:
        """Total cost and the cost of each record at the free values ``theta``."""
        per = np.array([self._record_cost(r, theta) for r in range(self.space.n_records)])
        return float(per.sum()), per

    def derivatives(self, theta):
        """Cost, gradient, curvature (Gauss-Newton or Fisher) and per-record details at ``theta``.

        Returns ``(f, g, H, details)``; ``details[r]`` holds ``f``, ``cols`` (the free values the
        record sees), per-sample ``scores`` (gradient contributions, ``(N, k_r)``) and normalised
        ``residuals`` (``(N, ny)``, NaN where not measured).
        """
        k = len(self.space)
        f, g, H, details = 0.0, np.zeros(k), np.zeros((k, k)), []
        for r in range(self.space.n_records):
            d = self._record_derivatives(r, theta)
            c = d["cols"]
            f += d["f"]
            g[c] += d["g"]
            H[np.ix_(c, c)] += d["H"]
            details.append(d)
        return f, g, 0.5 * (H + H.T), details


class OutputErrorEngine(_Engine):
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
    weights : (ny,) or list of (ny,) arrays
        ``1 / sigma`` per measured output (per record when a list).
    jit : bool or None
    """

    def __init__(self, dmodel, space, arrays, meas_index, weights, jit=None):
        super().__init__(space, jit)
        self.dmodel, self.model, self.arrays = dmodel, dmodel.model, arrays
        self.meas_index = list(meas_index)
        self.angle = self.model.angle_outputs[self.meas_index]
        w = np.asarray(weights, dtype=float)
        self.weights = [w[r] if w.ndim == 2 else w for r in range(space.n_records)]

    def _symbols(self, k: int | None):
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
            s = self._symbols(None)
            names = ["x", "u", "y", "mask", "dt", "p", "w"]
            fun = ca.Function("oe_value", [s[n] for n in names], [s["x_next"], s["r"]], names, ["x_next", "r"])
            return _fold(fun, {"x": "x_next"}, ("p", "w"))
        return self._fun("value", make)

    def _sens_fold(self, k: int, seeds: tuple):
        """The sensitivity fold for ``k`` free values entering through the inputs ``seeds`` (a subset of
        ``p, u, y``; the state always)."""
        def make():
            m = self.model
            s = self._symbols(k)
            sym = self.dmodel.symbolic
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
            return compiled(_fold(fun, {"x": "x_next", "dx": "dx_next"}, consts), jit=self.jit)
        return self._fun(("sens", k, seeds), make)

    def _inputs(self, r, theta):
        rm = self.space.record_map(r)
        v = rm.values(theta)
        a = self.arrays[r]
        return rm, v, {"p": v["p"], "w": self.weights[r]}, a["U"] + v["u"][:, None], a["Y"] - v["y"][:, None]

    def _record_cost(self, r, theta) -> float:
        rm, v, const, U, Y = self._inputs(r, theta)
        a, fold, x, total = self.arrays[r], self._value_fold(), v["x0"], 0.0
        for start, stop in _pieces(U.shape[1]):
            out = fold(x=x, u=_chunk(U, start, stop), y=_chunk(Y, start, stop), mask=_chunk(a["mask"], start, stop, True),
                       dt=_chunk(a["dt"], start, stop, True), **const)
            x = out["x_next"]
            total += 0.5 * float(ca.sumsqr(out["r"]))
        return total

    def residuals(self, r, theta) -> np.ndarray:
        """Weighted residuals (N, ny) of record ``r`` at ``theta`` (0 where not measured)."""
        rm, v, const, U, Y = self._inputs(r, theta)
        a, fold, x, parts = self.arrays[r], self._value_fold(), v["x0"], []
        for start, stop in _pieces(U.shape[1]):
            out = fold(x=x, u=_chunk(U, start, stop), y=_chunk(Y, start, stop), mask=_chunk(a["mask"], start, stop, True),
                       dt=_chunk(a["dt"], start, stop, True), **const)
            x = out["x_next"]
            parts.append(np.asarray(out["r"])[:, : stop - start])
        return np.hstack(parts).T

    def _record_gradient(self, r, theta, rm) -> np.ndarray:
        _, v, const, U, Y = self._inputs(r, theta)
        a, fold, x, calls = self.arrays[r], self._value_fold(), v["x0"], []
        for start, stop in _pieces(U.shape[1]):
            args = dict(x=x, u=_chunk(U, start, stop), y=_chunk(Y, start, stop),
                        mask=_chunk(a["mask"], start, stop, True), dt=_chunk(a["dt"], start, stop, True), **const)
            out = fold(**args)
            calls.append((args, out, stop - start))
            x = out["x_next"]
        adj_x, sums = self._sweep(calls, lambda out, take: {"adj_x_next": 0, "adj_r": out["r"]}, {"x": "x_next"})
        E = rm.E
        return E["p"].T @ sums["p"] + E["u"].T @ sums["u"] - E["y"].T @ sums["y"] + E["x0"].T @ adj_x["x"]

    def _record_derivatives(self, r, theta) -> dict:
        rm, v, const, U, Y = self._inputs(r, theta)
        a, k = self.arrays[r], rm.k
        blocks = {"p": rm.E["p"], "u": rm.E["u"], "y": -rm.E["y"]}
        seeds = tuple(n for n, E in blocks.items() if E.any())
        fold = self._sens_fold(k, seeds)
        const.update({f"d{n}": blocks[n] for n in seeds})
        x, dx = v["x0"], rm.E["x0"]
        R, J = [], []
        for start, stop in _pieces(U.shape[1]):
            out = fold(x=x, dx=dx, u=_chunk(U, start, stop), y=_chunk(Y, start, stop),
                       mask=_chunk(a["mask"], start, stop, True), dt=_chunk(a["dt"], start, stop, True), **const)
            x, dx = out["x_next"], out["dx_next"]
            R.append(np.asarray(out["r"])[:, : stop - start].T)
            J.append(_per_sample(out["J"], R[-1].shape[1], k, stop - start))
        R, J = np.vstack(R), np.concatenate(J)               # (N, ny), (N, ny, k)
        scores = np.einsum("nyk,ny->nk", J, R)
        Jf = J.reshape(-1, k)
        resid = np.where(a["mask"].T > 0, R, np.nan)
        return {"f": 0.5 * float(np.sum(R**2)), "g": scores.sum(axis=0), "H": Jf.T @ Jf, "cols": rm.cols,
                "scores": scores, "residuals": resid, "J": J}


class StepSlots:
    """An estimator's step Function seen through its slot names (the estimator contract).

    Gives the memory slots (carried from sample to sample under the same names), the per-sample
    and per-record inputs, the per-step random draws, where the state mean sits in the memory, and
    the initial memory for a prior, all flattened to vectors (the sensitivities are taken with
    respect to flat slots).
    """

    SAMPLE = SAMPLE_INPUTS
    RECORD = CONSTANT_INPUTS

    def __init__(self, est):
        self.est = est
        self.step = est.step_function(("e", "S", "ll"))
        self.memory = {n: n for n in est.memory}
        known = set(self.memory) | set(self.SAMPLE) | set(self.RECORD)
        self.draw_names = tuple(n for n in self.step.name_in() if n not in known)
        self.mean = ("x", 0) if "x" in self.memory else None    # (slot, first row) of the state mean

    def initial(self, prior, rng) -> dict:
        """Flat initial memory (name -> vector) for a Gaussian prior."""
        mem = self.est.memory_from(prior, rng)
        return {n: np.asarray(mem[n], dtype=float).reshape(-1, order="F") for n in self.memory}

    def draws(self, n: int, rng) -> dict:
        """Per-step draws for ``n`` steps, each step's block flattened to a column (name -> array)."""
        out = {}
        for name, a in self.est.draws(n, rng).items():
            r, c = self.step.size1_in(name), self.step.size2_in(name)
            out[name] = np.asarray(a, dtype=float).reshape(r, n, c).transpose(2, 0, 1).reshape(c * r, n)
        return out


class LikelihoodEngine(_Engine):
    """Negative log-likelihood of the innovations of a recursive estimator over each record.

    Parameters
    ----------
    slots : StepSlots
    space : ParamSpace
    arrays : list of dict
        Per record the step's per-sample inputs (``u_prev, u, y, mask, dt, gate`` and draws, samples
        as columns) and ``prior`` (Gaussian of the initial state; its mean is replaced by the free
        initial states), ``rng_seed``.
    Q, R : arrays
        The estimator's noise covariances (free diagonal entries replaced per evaluation).
    jit : bool or None
    """

    def __init__(self, slots: StepSlots, space, arrays, Q, R, jit=None):
        super().__init__(space, jit)
        self.slots, self.arrays = slots, arrays
        self.Q, self.R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
        self.ny = slots.step.size1_in("y")

    # -- symbolic --------------------------------------------------------------------------------
    def _symbols(self):
        step = self.slots.step
        sym = ca.SX if step.is_a("SXFunction") else ca.MX
        flat, shaped = _flat_symbols(sym, step, step.name_in())
        outs = step.call(shaped)
        return sym, flat, outs

    def _value_raw(self):
        def make():
            sl = self.slots
            sym, flat, outs = self._symbols()
            mem_in = {f"m_{n}": flat[n] for n in sl.memory}
            mem_out = {f"m_{n}_next": ca.vec(outs[o]) for n, o in sl.memory.items()}
            rest = [n for n in flat if n not in sl.memory]
            fun = ca.Function("ll_value", [*mem_in.values(), *(flat[n] for n in rest)],
                              [*mem_out.values(), outs["ll"], ca.vec(outs["e"]), ca.vec(outs["S"])],
                              [*mem_in, *rest], [*mem_out, "ll", "e", "S"])
            return _fold(fun, dict(zip(mem_in, mem_out)), StepSlots.RECORD)
        return self._fun("value", make)

    def _sens_fold(self, k: int, seeds: tuple):
        """The sensitivity fold for ``k`` free values entering through the inputs ``seeds`` (a subset of
        ``u_prev, u, y, p, Q, R``; the memory always)."""
        def make():
            sl, ny = self.slots, self.ny
            sym, flat, outs = self._symbols()
            wrt = (*sl.memory, *seeds)
            d = {n: sym.sym(f"d_{n}", flat[n].numel(), k) for n in wrt}
            Hin = sym.sym("H", k, k)
            mem_next = [ca.vec(outs[o]) for o in sl.memory.values()]
            S = ca.reshape(outs["S"], ny, ny)
            J = ca.jtimes(ca.vertcat(*mem_next, outs["ll"], ca.vec(outs["e"]), ca.vec(S)),
                          ca.vertcat(*(flat[n] for n in wrt)), ca.vertcat(*(d[n] for n in wrt)))
            sizes = np.cumsum([0] + [v.numel() for v in mem_next] + [1, ny, ny * ny])
            nm = len(mem_next)
            dmem = [J[sizes[i]:sizes[i + 1], :] for i in range(nm)]
            dll = J[sizes[nm]:sizes[nm + 1], :]
            de = J[sizes[nm + 1]:sizes[nm + 2], :]
            dS = J[sizes[nm + 2]:sizes[nm + 3], :]
            Si = ca.inv(S)
            M = Si @ ca.reshape(dS, ny, ny * k)                          # [Si dS_1, ..., Si dS_k]
            blocks = [M[:, i * ny:(i + 1) * ny] for i in range(k)]
            A = ca.horzcat(*[ca.vec(b) for b in blocks])
            B = ca.horzcat(*[ca.vec(b.T) for b in blocks])
            Hn = Hin + de.T @ Si @ de + 0.5 * (A.T @ B)
            mem_in = {f"m_{n}": flat[n] for n in sl.memory}
            dmem_in = {f"dm_{n}": d[n] for n in sl.memory}
            rest = [n for n in flat if n not in sl.memory]
            consts = [f"d_{n}" for n in seeds]
            names_in = [*mem_in, *dmem_in, "H", *rest, *consts]
            ins = [*mem_in.values(), *dmem_in.values(), Hin, *(flat[n] for n in rest), *(d[n] for n in seeds)]
            names_out = [*(f"{n}_next" for n in mem_in), *(f"{n}_next" for n in dmem_in), "H_next", "ll", "dll", "e",
                         "S"]
            fun = ca.Function(f"ll_sens{k}_{'_'.join(seeds)}", ins,
                              [*mem_next, *dmem, Hn, outs["ll"], dll, ca.vec(outs["e"]), ca.vec(S)], names_in, names_out)
            accumulate = {n: f"{n}_next" for n in (*mem_in, *dmem_in, "H")}
            return compiled(_fold(fun, accumulate, (*StepSlots.RECORD, *consts)), jit=self.jit)
        return self._fun(("sens", k, seeds), make)

    # -- numbers ---------------------------------------------------------------------------------
    def _record_inputs(self, r, theta):
        rm = self.space.record_map(r)
        v = rm.values(theta)
        a = self.arrays[r]
        Q = self.Q - np.diag(np.diag(self.Q)) + np.diag(v["Q"])
        R = self.R - np.diag(np.diag(self.R)) + np.diag(v["R"])
        prior = a["prior"]
        from ..data import Gaussian

        mem = self.slots.initial(Gaussian(v["x0"], prior.cov), np.random.default_rng(a["seed"]))
        per = {n: a[n] for n in (*StepSlots.SAMPLE, *self.slots.draw_names)}
        per["u_prev"] = per["u_prev"] + v["u"][:, None]
        per["u"] = per["u"] + v["u"][:, None]
        per["y"] = (per["y"] - v["y"][:, None]) * per["mask"]
        return rm, mem, per, {"p": v["p"], "Q": Q.reshape(-1, order="F"), "R": R.reshape(-1, order="F")}

    def _chunks(self, per, start, stop):
        zero = ("mask", "dt")
        return {n: _chunk(a, start, stop, n in zero) for n, a in per.items()}

    def _record_cost(self, r, theta) -> float:
        rm, mem, per, const = self._record_inputs(r, theta)
        fold, total = self._value_fold(), 0.0
        mem = {f"m_{n}": v for n, v in mem.items()}
        for start, stop in _pieces(per["dt"].shape[1]):
            out = fold(**mem, **self._chunks(per, start, stop), **const)
            mem = {n: out[f"{n}_next"] for n in mem}
            total -= float(ca.sum2(out["ll"]))
        return total

    def innovations(self, r, theta):
        """Innovations (N, ny, NaN where not measured) and their covariances (N, ny, ny) of record ``r``."""
        rm, mem, per, const = self._record_inputs(r, theta)
        fold, E, S = self._value_fold(), [], []
        mem = {f"m_{n}": v for n, v in mem.items()}
        n = per["dt"].shape[1]
        for start, stop in _pieces(n):
            out = fold(**mem, **self._chunks(per, start, stop), **const)
            mem = {k: out[f"{k}_next"] for k in mem}
            E.append(np.asarray(out["e"])[:, : stop - start].T)
            S.append(_per_sample(out["S"], self.ny * self.ny, 1, stop - start)[:, :, 0])
        E = np.vstack(E)
        E[per["mask"].T == 0] = np.nan
        return E, np.concatenate(S).reshape(n, self.ny, self.ny, order="F")

    def _record_gradient(self, r, theta, rm) -> np.ndarray:
        _, mem, per, const = self._record_inputs(r, theta)
        fold, calls = self._value_fold(), []
        state = {f"m_{n}": v for n, v in mem.items()}
        for start, stop in _pieces(per["dt"].shape[1]):
            args = {**state, **self._chunks(per, start, stop), **const}
            out = fold(**args)
            calls.append((args, out, stop - start))
            state = {n: out[f"{n}_next"] for n in state}

        def seeds(out, take):
            ll = np.zeros((1, CHUNK))
            ll[0, :take] = -1.0
            return {"adj_ll": ll, "adj_e": 0, "adj_S": 0}

        adj_mem, sums = self._sweep(calls, seeds, {n: f"{n}_next" for n in state})
        E, nw, ny = rm.E, self.Q.shape[0], self.ny
        g = E["p"].T @ sums["p"] + E["u"].T @ (sums["u"] + sums["u_prev"])
        g += E["Q"].T @ np.diag(sums["Q"].reshape(nw, nw, order="F")) + E["R"].T @ np.diag(sums["R"].reshape(ny, ny, order="F"))
        g -= E["y"].T @ sums["y"]        # unmeasured samples carry no adjoint (the residual is 0 there)
        if self.slots.mean is not None:
            slot, row = self.slots.mean
            g += E["x0"].T @ adj_mem[f"m_{slot}"][row:row + E["x0"].shape[0]]
        return g

    def _record_derivatives(self, r, theta) -> dict:
        rm, mem, per, const = self._record_inputs(r, theta)
        k = rm.k
        E = rm.E
        diag = lambda D: np.column_stack([np.diag(D[:, c]).reshape(-1, order="F") for c in range(k)])  # noqa: E731
        blocks = {"u_prev": E["u"], "u": E["u"], "y": -E["y"], "p": E["p"], "Q": E["Q"], "R": E["R"]}
        seeds = tuple(n for n, D in blocks.items() if D.any())
        fold = self._sens_fold(k, seeds)
        const.update({f"d_{n}": diag(blocks[n]) if n in ("Q", "R") else blocks[n] for n in seeds})
        dmem = {}
        for n in self.slots.memory:
            dm = np.zeros((mem[n].size, k))
            if self.slots.mean is not None and self.slots.mean[0] == n:
                row = self.slots.mean[1]
                dm[row:row + E["x0"].shape[0], :] = E["x0"]
            dmem[f"dm_{n}"] = dm
        state = {**{f"m_{n}": v for n, v in mem.items()}, **dmem, "H": np.zeros((k, k))}
        ll, dll, E_s, S_s = [], [], [], []
        n = per["dt"].shape[1]
        for start, stop in _pieces(n):
            out = fold(**state, **self._chunks(per, start, stop), **const)
            state = {s: out[f"{s}_next"] for s in state}
            take = stop - start
            ll.append(np.asarray(out["ll"]).reshape(-1)[:take])
            dll.append(_per_sample(out["dll"], 1, k, take)[:, 0, :])
            E_s.append(np.asarray(out["e"])[:, :take].T)
            S_s.append(_per_sample(out["S"], self.ny * self.ny, 1, take)[:, :, 0])
        ll, scores = np.concatenate(ll), -np.vstack(dll)
        E_s, S_s = np.vstack(E_s), np.concatenate(S_s).reshape(n, self.ny, self.ny, order="F")
        sd = np.sqrt(np.einsum("nii->ni", S_s))
        resid = np.where(per["mask"].T > 0, E_s / sd, np.nan)
        return {"f": -float(ll.sum()), "g": scores.sum(axis=0), "H": np.asarray(state["H"]), "cols": rm.cols,
                "scores": scores, "residuals": resid, "innovations": np.where(per["mask"].T > 0, E_s, np.nan),
                "S": S_s}
