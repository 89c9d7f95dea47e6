"""Prediction-error maximum likelihood through a recursive filter.

The negative log-likelihood of a record given the parameters is the sum over its samples of
``0.5 (e_k' S_k^-1 e_k + log det S_k + m_k log 2 pi)``, with ``e_k`` and ``S_k`` the innovations and
their covariances from the filter. :class:`MLEProblem` builds it symbolically as the filter's step
Function folded over each record (``Estimator.fold``) with the parameters, ``Q`` and ``R`` as CasADi
symbols, so the gradient and the Hessian that IPOPT uses are exact.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from ..angles import wrap
from ..data import Dataset, Gaussian
from ..discretize import DiscreteModel
from .._fast import compile_function
from ..estimators.base import SAMPLE_INPUTS, Estimator
from ._space import ParamSpace, hess_lag_function, ipopt_solve
from .result import FitResult, finish

__all__ = ["MLEProblem", "default_prior"]

CHUNK = 200  # samples per folded chunk of a record
_COMPILED: dict = {}  # compiled objective, gradient and curvature per problem structure (jit=True)


def _as_records(datasets) -> list[Dataset]:
    records = [datasets] if isinstance(datasets, Dataset) else list(datasets)
    if not records:
        raise ValueError("no data records given")
    for i, d in enumerate(records):
        if not isinstance(d, Dataset):
            raise TypeError(f"record {i} is a {type(d).__name__}, not a casship.Dataset")
    return records


def default_prior(model, data: Dataset, R: np.ndarray, measured: Sequence[str], prior_var: float = 1.0) -> Gaussian:
    """A prior for the first sample of ``data``: states named like a column start at its first value.

    States measured directly (an output of the same name) get the measurement variance, the others
    mean 0 (unless a column gives them) and variance ``prior_var``.
    """
    mean = np.zeros(model.nx)
    var = np.full(model.nx, float(prior_var))
    for i, s in enumerate(model.state_names):
        if s in data and np.isfinite(data[s][0]):
            mean[i] = data[s][0]
        if s in measured:
            var[i] = R[list(measured).index(s), list(measured).index(s)]
    return Gaussian(mean, var)


class MLEProblem:
    """Maximum-likelihood identification of model parameters through a filter (prediction error).

    Parameters
    ----------
    estimator : Estimator or DiscreteModel
        A recursive estimator (``EKF``, ``UKF``, ...) whose model carries the parameters. A
        :class:`~casship.DiscreteModel` is wrapped in an :class:`~casship.EKF` with ``Q``, ``R`` and
        ``measured``.
    datasets : Dataset or sequence of Dataset
        Records (experiments) with the model's inputs and measured outputs (NaN = missing).
    free : sequence of str
        Names of the model parameters to estimate.
    params : array or mapping, optional
        Values of the other parameters (nominal by default).
    noise : mapping, optional
        Diagonal noise variances to estimate: ``{"Q": ["w_r"], "R": True}`` (``True`` = all channels).
        They appear as ``Q[w_r]``, ``R[psi]`` among the free quantities.
    x0 : Gaussian, sequence of Gaussian or mapping state -> value, optional
        Prior of the initial state of each record (one for all, or one per record). By default
        states named like a data column start at its first value (see :func:`default_prior`).
    estimate_x0 : sequence of str
        States whose initial means are estimated per record (named ``<state>@<record index>``).
    prior_var : float
        Variance of unmeasured states in the default prior.
    bounds, scale : mapping name -> (lower, upper) / typical magnitude, optional
        For any free quantity (model bounds apply too).
    Q, R, measured
        Only with a DiscreteModel: the filter's noise covariances and measured outputs.
    seed : int
        For stochastic estimators (EnKF): fixes the draws (common random numbers across evaluations).
    jit : bool
        Compile the objective, its gradient and the curvature to C (system compiler) before solving.
        The compiled code does not depend on the data and is kept per problem structure (estimator,
        record lengths, free quantities), so repeated fits of equally long records (Monte Carlo,
        bootstrap, cross-validation) pay the compilation once.

    Examples
    --------
    >>> import numpy as np, casship as cs
    >>> m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    >>> t = np.arange(0, 200, 1.0)
    >>> tr = cs.simulate(m, m.states(), t, {"delta": 0.1 * np.sign(np.sin(t / 30))})
    >>> data = cs.measure(tr, m, {"psi": 0.01}, seed=1)
    >>> ekf = cs.EKF(cs.discretize(m, 1.0), Q=1e-10, R=1e-4)
    >>> fit = cs.MLEProblem(ekf, data, free=["K", "T"]).solve(guess={"K": 0.05, "T": 10.0})
    >>> abs(fit.params["K"] - 0.1) < 3 * fit.std_errors["K"]
    True
    """

    method = "mle"

    def __init__(self, estimator, datasets, free: Sequence[str] = (), *, params=None, noise: Mapping | None = None,
                 x0=None, estimate_x0: Sequence[str] = (), prior_var: float = 1.0, bounds: Mapping | None = None,
                 scale: Mapping | None = None, Q=None, R=None, measured=None, seed=0, jit: bool = False):
        if isinstance(estimator, DiscreteModel):
            from ..estimators import EKF

            if Q is None or R is None:
                raise ValueError("with a DiscreteModel give the noise covariances Q and R (or pass an estimator)")
            estimator = EKF(estimator, Q, R, measured=measured)
        elif not isinstance(estimator, Estimator):
            raise TypeError(f"MLEProblem needs an estimator or a DiscreteModel, got {type(estimator).__name__}")
        elif Q is not None or R is not None or measured is not None:
            raise ValueError("Q, R and measured are given to the estimator, not to MLEProblem")
        self.estimator = est = estimator
        self.model = m = est.model
        self.records = _as_records(datasets)
        self.method = f"mle-{est.name.lower()}"
        base = m.params(params) if params is not None else m.params()
        self._priors = self._make_priors(x0, prior_var)
        noise_entries = self._noise_entries(noise)
        estimate_x0 = list(estimate_x0)
        m.indices(estimate_x0, "state")
        x0_entries = [(f"{s}@{k}", k, m.index(s), self._priors[k].mean[m.index(s)])
                      for k in range(len(self.records)) for s in estimate_x0]
        if x0_entries and "x" not in est.memory:
            raise ValueError(f"estimate_x0 needs a mean/covariance filter; {est.name} keeps {list(est.memory)}")
        self.space = ParamSpace(m, free, base, bounds=bounds, scale=scale, noise_entries=noise_entries,
                                x0_entries=x0_entries)
        if not len(self.space):
            raise ValueError("nothing to estimate: give free parameters, noise or estimate_x0")
        self._seed = seed
        self.jit = bool(jit)
        self._build()

    # -- set-up ------------------------------------------------------------------------------------
    def _make_priors(self, x0, prior_var) -> list[Gaussian]:
        est, m, n = self.estimator, self.model, len(self.records)
        if x0 is None or isinstance(x0, Mapping):
            priors = [default_prior(m, d, est.R, est.measured, prior_var) for d in self.records]
            if isinstance(x0, Mapping):
                vals = m.states(**x0)
                idx = m.indices(x0, "state")
                priors = [Gaussian(np.where(np.isin(np.arange(m.nx), idx), vals, g.mean), g.cov) for g in priors]
            return priors
        if isinstance(x0, Gaussian):
            priors = [x0] * n
        else:
            priors = list(x0)
            if len(priors) != n:
                raise ValueError(f"x0: {len(priors)} priors for {n} records")
        for g in priors:
            est._check_prior(g)
        return priors

    def _noise_entries(self, noise):
        est, m = self.estimator, self.model
        noise = dict(noise or {})
        unknown = set(noise) - {"Q", "R"}
        if unknown:
            raise ValueError(f"noise: unknown key(s) {sorted(unknown)}; use 'Q' and/or 'R'")
        out = []
        for kind, channels, mat in (("Q", m.noise_names, est.Q), ("R", est.measured, est.R)):
            sel = noise.get(kind, ())
            sel = list(channels) if sel is True else list(sel)
            bad = [c for c in sel if c not in channels]
            if bad:
                raise ValueError(f"noise {kind}: unknown channel(s) {bad}; channels: {list(channels)}")
            for c in sel:
                i = list(channels).index(c)
                v = mat[i, i] if mat[i, i] > 0 else 1e-6
                out.append((f"{kind}[{c}]", kind, i, v))
        return out

    def _build(self) -> None:
        est, sp, m = self.estimator, self.space, self.model
        k = len(sp)
        rng = np.random.default_rng(self._seed)
        # The records, initial memories, fixed parameters and base covariances are packed into one
        # parameter vector: the symbolic functions (and their compiled versions) do not embed the data.
        blocks, layout, self._arrays = [], [], []
        for r, data in enumerate(self.records):
            arr = est.prepare(data)
            self._arrays.append(arr)
            named = {k: arr[k] for k in SAMPLE_INPUTS if k != "gate"}
            named.update(est.draws(len(data), rng))
            named.update({f"memory:{k}": v for k, v in est.memory_from(self._priors[r], rng).items()})
            shapes = {k: np.atleast_2d(np.asarray(v, dtype=float).T).T.shape for k, v in named.items()}
            layout.append(shapes)
            blocks += [np.asarray(v, dtype=float).reshape(-1, order="F") for v in named.values()]
        blocks += [sp.base, est.Q.reshape(-1, order="F"), est.R.reshape(-1, order="F")]
        self._pnum = np.concatenate(blocks)
        P = ca.MX.sym("data", self._pnum.size)
        offset = [0]

        def take(size):
            v = P[offset[0]: offset[0] + size]
            offset[0] += size
            return v

        recs = [{k: ca.reshape(take(r * c), r, c) for k, (r, c) in shapes.items()} for shapes in layout]
        pb = take(m.np)
        Q0 = ca.reshape(take(m.nw * m.nw), m.nw, m.nw)
        R0 = ca.reshape(take(est.ny * est.ny), est.ny, est.ny)
        theta = ca.MX.sym("theta", k)
        nat = [theta[i] for i in range(k)]
        p = sp.param_vector(nat, base=pb)
        Q, R = self._cov_sym(nat, "Q", Q0), self._cov_sym(nat, "R", R0)
        nll, rec_out = 0, []
        ny = est.ny
        for r, rec in enumerate(recs):
            n = rec["dt"].shape[1]
            memory = {name[len("memory:"):]: v for name, v in rec.items() if name.startswith("memory:")}
            x0_items = [(e, v) for e, v in zip(sp.entries, nat) if e.kind == "x0" and e.record == r]
            if x0_items:
                mean = [memory["x"][i] for i in range(m.nx)]
                for e, v in x0_items:
                    mean[e.index] = v
                memory["x"] = ca.vertcat(*mean)
            per = {name: v for name, v in rec.items() if not name.startswith("memory:")}
            e_parts, S_parts = [], []
            # chunks of one cached fold: derivative graphs are built per chunk length, not per record length
            for start in range(0, n, CHUNK):
                stop = min(start + CHUNK, n)
                width = stop - start
                args = {name: v[:, start * (v.shape[1] // n): stop * (v.shape[1] // n)] for name, v in per.items()}
                out = est.fold(width, ("x", "P", "e", "S", "ll")).call(
                    {**memory, **args, "p": p, "Q": Q, "R": R, "gate": ca.DM.inf(1, width)})
                memory = {name: out[name][:, -(out[name].shape[1] // width):] for name in est.memory}
                nll = nll - ca.sum2(out["ll"])
                e_parts.append(out["e"])
                S_parts.append(ca.reshape(out["S"], ny * ny, width))
            rec_out += [ca.horzcat(*e_parts), ca.horzcat(*S_parts)]
        self._nll = ca.Function("nll", [theta, P], [nll], ["theta", "data"], ["nll"])
        self._grad = ca.Function("nll_grad", [theta, P], [ca.gradient(nll, theta)], ["theta", "data"], ["g"])
        self._records_fn = ca.Function("records", [theta, P], rec_out)

    def _cov_sym(self, nat, kind, base):
        free = [(e.index, v) for e, v in zip(self.space.entries, nat) if e.kind == kind]
        if not free:
            return base
        n = base.shape[0]
        drop = np.zeros(n)
        diag = [ca.MX(0.0)] * n
        for i, v in free:
            drop[i] = 1.0
            diag[i] = v
        return base - ca.diag(ca.diag(base) * ca.DM(drop)) + ca.diag(ca.vertcat(*diag))

    # -- evaluation --------------------------------------------------------------------------------
    @property
    def free(self) -> list[str]:
        return list(self.space.names)

    def _theta(self, values) -> np.ndarray:
        if isinstance(values, Mapping):
            unknown = set(values) - set(self.space.names)
            if unknown:
                raise ValueError(f"values for {sorted(unknown)}, which are not free; free: {self.free}")
            merged = {**self.space.default_guess, **values}
            return np.array([float(merged[n]) for n in self.space.names])
        theta = np.asarray(values, dtype=float).reshape(-1)
        if theta.size != len(self.space):
            raise ValueError(f"expected {len(self.space)} values for {self.free}, got {theta.size}")
        return theta

    def negloglik(self, values=None) -> float:
        """Negative log-likelihood at the free values (mapping by name or vector ordered like ``free``)."""
        return float(self._nll(self._theta(values or {}), self._pnum))

    def gradient(self, values=None) -> np.ndarray:
        """Exact gradient of :meth:`negloglik` with respect to the free values."""
        return np.asarray(self._grad(self._theta(values or {}), self._pnum)).reshape(-1)

    # -- solve -------------------------------------------------------------------------------------
    def fisher_expr(self, z, theta, data) -> ca.MX:
        """Fisher information of the innovations with respect to ``z`` (``theta`` = values at ``z``,
        ``data`` the symbolic data vector).

        ``sum_k De_k' S_k^-1 De_k + 0.5 tr(S_k^-1 dS_k/dz_i S_k^-1 dS_k/dz_j)``: the expected Hessian
        of the negative log-likelihood (Fisher scoring; always positive semi-definite).
        """
        ny, k = self.estimator.ny, z.shape[0]
        outs = self._records_fn(theta, data)
        outs = [outs] if isinstance(outs, ca.MX) else outs
        e_s, S_s = ca.SX.sym("e", ny), ca.SX.sym("S", ny * ny)
        de_s, dS_s = ca.SX.sym("de", k * ny), ca.SX.sym("dS", k * ny * ny)
        A = ca.reshape(de_s, k, ny).T
        Si = ca.inv(ca.reshape(S_s, ny, ny))
        dS = ca.reshape(dS_s, k, ny * ny)
        M = [Si @ ca.reshape(dS[i, :], ny, ny) for i in range(k)]
        T2 = ca.SX(k, k)
        for i in range(k):
            for j in range(i, k):
                T2[i, j] = T2[j, i] = 0.5 * ca.trace(M[i] @ M[j])
        per = ca.Function("fisher_sample", [e_s, S_s, de_s, dS_s], [A.T @ Si @ A + T2])
        info = 0
        for r in range(len(self.records)):
            e, S = outs[2 * r], outs[2 * r + 1]
            n = e.shape[1]
            # forward sensitivities along the unit vectors (no sparsity sweep through the record)
            J = ca.jtimes(ca.vertcat(ca.vec(e), ca.vec(S)), z, ca.MX.eye(k)).T
            Je = ca.reshape(J[:, : ny * n], k * ny, n)
            JS = ca.reshape(J[:, ny * n:], k * ny * ny, n)
            info = info + per.map(f"fisher_{r}", "serial", n, [], [0])(e, S, Je, JS)
        return 0.5 * (info + info.T)

    def solve(self, guess: Mapping[str, float] | None = None, *, hessian: str = "fisher",
              information: str = "fisher", options: Mapping | None = None) -> FitResult:
        """Maximise the likelihood with IPOPT from ``guess`` (free name -> value).

        Parameters
        ----------
        guess : mapping, optional
            Starting values (default: the fixed parameter values, the estimator's noise and the priors).
        hessian : {"fisher", "exact", "limited-memory"}
            Curvature IPOPT uses: the Fisher information of the innovations (scoring, from exact
            first-order sensitivities; cheap and positive semi-definite), the exact Hessian of the
            likelihood (second-order CasADi derivatives through the fold) or IPOPT's L-BFGS.
        information : {"fisher", "hessian"}
            Matrix inverted for the standard errors: Fisher information or observed information
            (exact Hessian) at the optimum.
        options : mapping, optional
            IPOPT options (e.g. ``{"max_iter": 100, "tol": 1e-8}``).

        Raises
        ------
        IdentificationError
            If IPOPT does not converge (the message and ``.status`` give IPOPT's status).
        """
        sp = self.space
        if hessian not in ("fisher", "exact", "limited-memory"):
            raise ValueError(f"unknown hessian {hessian!r}; use 'fisher', 'exact' or 'limited-memory'")
        if information not in ("fisher", "hessian"):
            raise ValueError(f"information must be 'fisher' or 'hessian', got {information!r}")
        z = ca.MX.sym("z", len(sp))
        P = ca.MX.sym("data", self._pnum.size)
        theta = ca.vertcat(*sp.natural(z))
        f = self._nll(theta, P)
        lbz, ubz = sp.z_bounds()
        info_kind = "fisher" if information == "fisher" else "exact"

        def curvature(kind):
            if kind == "fisher":
                return self.fisher_expr(z, theta, P)
            # forward-over-reverse directional derivatives along the unit vectors: the dense Hessian
            # without a sparsity sweep through the whole record
            H = ca.jtimes(ca.gradient(f, z), z, ca.MX.eye(len(sp)))
            return 0.5 * (H + H.T)

        kinds = sorted({hessian, info_kind} - {"limited-memory"})
        functions = None
        if self.jit:
            key = (type(self.estimator).__name__, self.estimator.step_function("all").serialize(),
                   tuple(len(d) for d in self.records), CHUNK, self._pnum.size,
                   tuple((e.kind, e.index, e.record, e.log, e.scale) for e in sp.entries), hessian, info_kind)
            if key not in _COMPILED:
                comp = {"grad_f": compile_function(ca.Function("nlp_grad_f", [z, P], [f, ca.gradient(f, z)],
                                                               ["x", "p"], ["f", "grad_f_x"]))}
                for kind in kinds:
                    comp[kind] = compile_function(hess_lag_function(z, P, curvature(kind)))
                _COMPILED[key] = comp
            comp = _COMPILED[key]
            functions = {"grad_f": comp["grad_f"]}
            if hessian != "limited-memory":
                functions["hess_lag"] = comp[hessian]
            curv = {}
        else:
            curv = {kind: curvature(kind) for kind in kinds}
        z_opt, st, seconds = ipopt_solve(f, z, sp.guess_z(guess), lbz, ubz,
                                         hessian="limited-memory" if hessian == "limited-memory" else "custom",
                                         hess_f=curv.get(hessian), options=options, name=self.method,
                                         par=P, par_value=self._pnum, functions=functions)
        if self.jit:
            upper = np.asarray(_COMPILED[key][info_kind](z_opt, self._pnum, 1.0, np.zeros(0)))
            info = upper + upper.T - np.diag(np.diag(upper))
        else:
            info = np.asarray(ca.Function("nll_information", [z, P], [curv[info_kind]])(z_opt, self._pnum))
        return self._result(z_opt, info, st, seconds)

    def _result(self, z_opt, info, st, seconds) -> FitResult:
        sp, m, est = self.space, self.model, self.estimator
        values = sp.natural_numeric(z_opt)
        cost = float(self._nll(values, self._pnum))
        p = sp.param_vector(values)
        outs = self._records_fn(values, self._pnum)
        outs = [np.asarray(o) for o in ([outs] if isinstance(outs, ca.DM) else outs)]
        residuals, predictions, n_obs = [], [], 0
        ny = est.ny
        for r, data in enumerate(self.records):
            e, S = outs[2 * r].T.copy(), outs[2 * r + 1]
            mask = self._arrays[r]["mask"].T > 0.5
            n_obs += int(mask.sum())
            sd = np.sqrt(np.stack([S[i * ny + i] for i in range(ny)], axis=1))
            e[~mask] = np.nan
            residuals.append(e / sd)
            y = data.matrix(est.measured)
            yhat = y - e
            yhat[:, est.angle_meas] = wrap(yhat[:, est.angle_meas])
            predictions.append({"t": data.t, "label": data.meta.get("name", data.meta.get("source", f"record {r}")),
                                "kind": "one-step prediction",
                                "measured": {n: y[:, j] for j, n in enumerate(est.measured)},
                                "predicted": {n: yhat[:, j] for j, n in enumerate(est.measured)}})
        Qd, Rd = np.diag(est.Q).copy(), np.diag(est.R).copy()
        x0 = [dict(zip(m.state_names, g.mean.tolist())) for g in self._priors]
        for e, v in zip(sp.entries, values):
            if e.kind == "Q":
                Qd[e.index] = v
            elif e.kind == "R":
                Rd[e.index] = v
            elif e.kind == "x0":
                x0[e.record][m.state_names[e.index]] = float(v)
        noise = {"Q": dict(zip(m.noise_names, Qd.tolist())), "R": dict(zip(est.measured, Rd.tolist()))}
        warn = [f"{e.name} ended at a bound ({v:g})" for e, v in zip(sp.entries, values)
                if np.isclose(v, e.lower, rtol=1e-6, atol=1e-12) or np.isclose(v, e.upper, rtol=1e-6, atol=1e-12)]
        return finish(model=m.name, params=m.param_dict(p), names=sp.names, values=values, info=info,
                      jac_nat=sp.jac_natural(z_opt), scale=sp.scales(), cost=cost, loglik=-cost, n_obs=n_obs,
                      residuals=residuals, output_names=est.measured, method=self.method,
                      status=st.get("return_status", ""), iterations=st.get("iter_count", 0), solve_time_s=seconds,
                      noise=noise, x0=x0, predictions=predictions, extra_warnings=warn)

    def __repr__(self) -> str:
        return (f"MLEProblem({self.model.name!r}, {len(self.records)} record(s), free={self.free}, "
                f"estimator={self.estimator.name})")
