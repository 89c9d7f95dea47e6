"""The innovations' negative log-likelihood of a recursive estimator, its sensitivities and Fisher
information, folded over records (see :mod:`casship.identify._engine`).

The estimator's step Function is addressed by its slot names (the estimator contract): memory
slots carried from sample to sample, per-sample inputs, per-record ``p, Q, R`` and random draws.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from ..gaussian import Gaussian
from ..estimators.base import CONSTANT_INPUTS, SAMPLE_INPUTS
from ._engine import Engine, Job, chunk, fold, per_sample, run_jobs

__all__ = ["StepSlots", "LikelihoodEngine"]


class StepSlots:
    """An estimator's step Function seen through its slot names.

    Gives the memory slots, the per-step random draws, where the state mean sits in the memory,
    and the initial memory for a prior, all flattened to vectors (the sensitivities are taken with
    respect to flat slots).
    """

    SAMPLE = SAMPLE_INPUTS
    RECORD = CONSTANT_INPUTS

    def __init__(self, est):
        self.est = est
        self.step = est.step_function(("e", "S", "ll"))
        self.memory = tuple(est.memory)
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


class LikelihoodEngine(Engine):
    """Negative log-likelihood of the innovations of a recursive estimator over each record.

    Parameters
    ----------
    slots : StepSlots
    space : ParamSpace
    arrays : list of dict
        Per record the step's per-sample inputs (``u_prev, u, y, mask, dt, gate`` and draws, samples
        as columns), ``prior`` (Gaussian of the initial state; its mean is replaced by the record's
        initial state) and ``seed``.
    Q, R : arrays
        The estimator's noise covariances (free diagonal entries replaced per evaluation).
    jit : bool or None
    """

    def __init__(self, slots: StepSlots, space, arrays, Q, R, jit=None):
        super().__init__(space, jit)
        self.slots, self.arrays = slots, arrays
        self.Q, self.R = np.asarray(Q, dtype=float), np.asarray(R, dtype=float)
        self.ny = slots.step.size1_in("y")

    def _structure(self) -> tuple:
        return (self.slots.step, self.slots.memory, self.slots.draw_names, self.slots.mean)

    # -- symbolic --------------------------------------------------------------------------------
    def _symbols(self):
        step = self.slots.step
        sym = ca.SX if step.is_a("SXFunction") else ca.MX
        flat = {n: sym.sym(n, step.nnz_in(n)) for n in step.name_in()}
        outs = step.call({n: ca.reshape(v, step.size1_in(n), step.size2_in(n)) for n, v in flat.items()})
        return sym, flat, outs

    def _value_raw(self):
        def make():
            mem = self.slots.memory
            sym, flat, outs = self._symbols()
            rest = [n for n in flat if n not in mem]
            fun = ca.Function("ll_value", [*(flat[n] for n in mem), *(flat[n] for n in rest)],
                              [*(ca.vec(outs[n]) for n in mem), outs["ll"], ca.vec(outs["e"]), ca.vec(outs["S"])],
                              [*(f"m_{n}" for n in mem), *rest], [*(f"m_{n}_next" for n in mem), "ll", "e", "S"])
            return fold(fun, {f"m_{n}": f"m_{n}_next" for n in mem}, StepSlots.RECORD)
        return self._raw("value", make)

    def _sens_fold(self, k: int, seeds: tuple):
        """The sensitivity fold for ``k`` free values entering through the inputs ``seeds`` (a subset of
        ``u_prev, u, y, p, Q, R``; the memory always)."""
        def make():
            mem, ny = self.slots.memory, self.ny
            sym, flat, outs = self._symbols()
            wrt = (*mem, *seeds)
            d = {n: sym.sym(f"d_{n}", flat[n].numel(), k) for n in wrt}
            Hin = sym.sym("H", k, k)
            mem_next = [ca.vec(outs[n]) for n in mem]
            S = ca.reshape(outs["S"], ny, ny)
            J = ca.jtimes(ca.vertcat(*mem_next, outs["ll"], ca.vec(outs["e"]), ca.vec(S)),
                          ca.vertcat(*(flat[n] for n in wrt)), ca.vertcat(*(d[n] for n in wrt)))
            cut = np.cumsum([0] + [v.numel() for v in mem_next] + [1, ny, ny * ny])
            nm = len(mem_next)
            dmem = [J[cut[i]:cut[i + 1], :] for i in range(nm)]
            dll, de, dS = (J[cut[nm + i]:cut[nm + i + 1], :] for i in range(3))
            Si = ca.inv(S)
            M = Si @ ca.reshape(dS, ny, ny * k)                          # [Si dS_1, ..., Si dS_k]
            blocks = [M[:, i * ny:(i + 1) * ny] for i in range(k)]
            A = ca.horzcat(*[ca.vec(b) for b in blocks])
            B = ca.horzcat(*[ca.vec(b.T) for b in blocks])
            Hn = Hin + de.T @ Si @ de + 0.5 * (A.T @ B)          # Fisher information of the innovations
            rest = [n for n in flat if n not in mem]
            names_in = [*(f"m_{n}" for n in mem), *(f"dm_{n}" for n in mem), "H", *rest, *(f"d_{n}" for n in seeds)]
            ins = [*(flat[n] for n in mem), *(d[n] for n in mem), Hin, *(flat[n] for n in rest), *(d[n] for n in seeds)]
            names_out = [*(f"m_{n}_next" for n in mem), *(f"dm_{n}_next" for n in mem), "H_next", "ll", "dll", "e", "S"]
            fun = ca.Function(f"ll_sens{k}_{'_'.join(seeds)}", ins,
                              [*mem_next, *dmem, Hn, outs["ll"], dll, ca.vec(outs["e"]), ca.vec(S)], names_in, names_out)
            acc = {n: f"{n}_next" for n in (*(f"m_{n}" for n in mem), *(f"dm_{n}" for n in mem), "H")}
            return fold(fun, acc, (*StepSlots.RECORD, *(f"d_{n}" for n in seeds)))
        return self._fun(("sens", k, seeds), make)

    # -- numbers ---------------------------------------------------------------------------------
    def _job(self, r, theta, kind):
        rm = self.space.record_map(r)
        v = rm.values(theta)
        a = self.arrays[r]
        Q = self.Q - np.diag(np.diag(self.Q)) + np.diag(v["Q"])
        R = self.R - np.diag(np.diag(self.R)) + np.diag(v["R"])
        mem = self.slots.initial(Gaussian(v["x0"], a["prior"].cov), np.random.default_rng(a["seed"]))
        per = {n: a[n] for n in (*StepSlots.SAMPLE, *self.slots.draw_names)}
        per["u_prev"] = per["u_prev"] + v["u"][:, None]
        per["u"] = per["u"] + v["u"][:, None]
        per["y"] = (per["y"] - v["y"][:, None]) * per["mask"]
        consts = {"p": v["p"], "Q": Q.reshape(-1, order="F"), "R": R.reshape(-1, order="F")}
        state = {f"m_{n}": x for n, x in mem.items()}
        n = per["dt"].shape[1]
        ctx = {"rm": rm, "mask": per["mask"], "n": n}
        if kind == "value":
            return Job(self._value_fold(), state, consts, per, n), ctx
        k, E = rm.k, rm.E
        diag = lambda D: np.column_stack([np.diag(D[:, c]).reshape(-1, order="F") for c in range(k)])  # noqa: E731
        blocks = {"u_prev": E["u"], "u": E["u"], "y": -E["y"], "p": E["p"], "Q": E["Q"], "R": E["R"]}
        seeds = tuple(name for name, D in blocks.items() if D.any())
        consts.update({f"d_{s}": diag(blocks[s]) if s in ("Q", "R") else blocks[s] for s in seeds})
        for name in self.slots.memory:
            dm = np.zeros((mem[name].size, k))
            if self.slots.mean is not None and self.slots.mean[0] == name:
                row = self.slots.mean[1]
                dm[row:row + E["x0"].shape[0], :] = E["x0"]
            state[f"dm_{name}"] = dm
        state["H"] = np.zeros((k, k))
        return Job(self._sens_fold(k, seeds), state, consts, per, n), ctx

    @staticmethod
    def _chunk_cost(out, take) -> float:
        return -float(np.sum(out["ll"][:, :take]))

    def innovations(self, r, theta):
        """Innovations (N, ny, NaN where not measured) and their covariances (N, ny, ny) of record ``r``."""
        job, ctx = self._job(r, theta, "value")
        run = run_jobs([job])[0]
        E = np.vstack([out["e"][:, :take].T for _, out, take in run])
        E[ctx["mask"].T == 0] = np.nan
        S = np.concatenate([per_sample(out["S"], self.ny * self.ny, 1, take)[:, :, 0] for _, out, take in run])
        return E, S.reshape(ctx["n"], self.ny, self.ny, order="F")

    def _details(self, r, ctx, run) -> dict:
        rm, k, n, ny = ctx["rm"], ctx["rm"].k, ctx["n"], self.ny
        ll = np.concatenate([out["ll"][0, :take] for _, out, take in run])
        scores = -np.vstack([per_sample(out["dll"], 1, k, take)[:, 0, :] for _, out, take in run])
        E = np.vstack([out["e"][:, :take].T for _, out, take in run])
        S = np.concatenate([per_sample(out["S"], ny * ny, 1, take)[:, :, 0] for _, out, take in run])
        S = S.reshape(n, ny, ny, order="F")
        measured = ctx["mask"].T > 0
        resid = np.where(measured, E / np.sqrt(np.einsum("nii->ni", S)), np.nan)
        return {"f": -float(ll.sum()), "g": scores.sum(axis=0), "H": np.asarray(run[-1][1]["H_next"]),
                "cols": rm.cols, "scores": scores, "residuals": resid, "innovations": np.where(measured, E, np.nan),
                "S": S}

    def _record_gradient(self, rm, ctx, run) -> np.ndarray:
        def seeds(out, take):
            ll = np.zeros((1, chunk()))
            ll[0, :take] = -1.0
            return {"adj_ll": ll}

        mem = tuple(f"m_{n}" for n in self.slots.memory)
        adj_mem, sums = self._sweep(run, seeds, mem)
        E, nw, ny = rm.E, self.Q.shape[0], self.ny
        g = E["p"].T @ sums["p"] + E["u"].T @ (sums["u"] + sums["u_prev"])
        g += E["Q"].T @ np.diag(sums["Q"].reshape(nw, nw, order="F"))
        g += E["R"].T @ np.diag(sums["R"].reshape(ny, ny, order="F"))
        g -= E["y"].T @ sums["y"]        # unmeasured samples carry no adjoint (the residual is 0 there)
        if self.slots.mean is not None:
            slot, row = self.slots.mean
            g += E["x0"].T @ adj_mem[f"m_{slot}"][row:row + E["x0"].shape[0]]
        return g
