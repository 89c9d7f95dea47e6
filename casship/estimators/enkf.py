"""Ensemble Kalman filter with perturbed observations (Evensen 1994; Burgers et al. 1998; Koike et al. 2023).

The random draws are generated in numpy (from the ``seed``) and enter the compiled step as the
per-step inputs ``z_w`` (nw x N) and ``z_v`` (ny x N), so a seeded run is reproducible and the
batch fold and the online runner give identical numbers for the same draws.

Every per-member computation is one SX member step ``map``-ped over the ensemble: the forecast
(model step and outputs), the analysis, and the ensemble moments, which are sums of member
products reduced by the ``map`` (one pass around a reference member, see :func:`_moments`), not
generic dense matrix products. The inputs shared by all members go in as one packed vector. So the
size of the step Function and its compile time do not grow with the number of members, and a
step costs about the members' own arithmetic.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..gaussian import Gaussian
from .base import StepEstimator
from .options import EstimatorOptions, check_int
from .ukf import psd_sqrt, wrap_fast
from .update import from_lower, gain_and_terms, masked_innovation_cov, residual
from ..errors import InputError

__all__ = ["EnKF", "EnKFOptions"]


@dataclass(frozen=True)
class EnKFOptions(EstimatorOptions):
    """Options of :class:`EnKF` (and those of every estimator, see :class:`EstimatorOptions`).

    Parameters
    ----------
    gate, jit, outputs, max_gap, on_gap
        The options of every estimator (see :class:`~casship.estimators.EstimatorOptions`).
    members : int
        Ensemble size ``N`` (Koike et al. 2023: 100), at most :data:`MAX_MEMBERS`.
    """

    members: int = 100

    def __post_init__(self):
        super().__post_init__()
        object.__setattr__(self, "members", check_int(self.members, "members", 2))
        if self.members > MAX_MEMBERS:
            raise InputError(f"option 'members' = {self.members} is more than {MAX_MEMBERS} "
                             "(casship.estimators.enkf.MAX_MEMBERS), refused before it exhausts the memory")


#: The largest ensemble (a thousand times Koike et al.'s 100; ten million members exhausted 24 GB).
MAX_MEMBERS = 100_000


def _wrapped(d, angles):
    """``d`` (SX vector) with its angle entries wrapped to [-pi, pi)."""
    if not np.any(angles):
        return d
    return ca.vertcat(*[wrap_fast(d[i]) if angles[i] else d[i] for i in range(d.numel())])


def _over_members(name: str, per_member: dict, shared: dict, outputs: dict, members: int, summed=()) -> dict:
    """An SX member step evaluated for every member by one ``map``.

    Parameters
    ----------
    name : str
    per_member : dict name -> (SX symbol, MX columns)
        Inputs that differ between members: column ``i`` goes to member ``i``.
    shared : dict name -> (SX symbol, MX value)
        Inputs that are the same for all members. They are packed into one vector, so ``map``
        copies one block per member instead of one per input.
    outputs : dict name -> SX
        The member's outputs, in terms of the symbols.
    members : int
    summed : sequence of str
        Outputs summed over the members (the others come out column by column).

    Returns
    -------
    dict name -> MX
    """
    per_member = {k: v for k, v in per_member.items() if v[0].numel()}     # an empty mapped input makes
    shared = {k: v for k, v in shared.items() if v[0].numel()}             # CasADi's C invalid
    symbols = [v[0] for v in per_member.values()]
    packed = ca.SX.sym("shared", sum(v[0].numel() for v in shared.values()))
    pieces, start = [], 0
    for sym, _ in shared.values():
        pieces.append(ca.reshape(packed[start:start + sym.numel()], sym.shape))
        start += sym.numel()
    exprs = ca.substitute(list(outputs.values()), [v[0] for v in shared.values()], pieces) if shared \
        else list(outputs.values())
    step = ca.Function(f"{name}_member", [*symbols, packed] if shared else symbols, exprs)
    names = list(outputs)
    mapped = step.map(name, "serial", members, [len(symbols)] if shared else [], [names.index(k) for k in summed])
    args = [v[1] for v in per_member.values()]
    if shared:
        args.append(ca.vertcat(*[ca.vec(v[1]) for v in shared.values()]))
    return dict(zip(names, mapped.call(args)))


def _moments(name: str, ensembles: dict, angles: dict, pairs, members: int) -> tuple[dict, dict]:
    """Means of ensembles (columns = members) and the sample covariances of the ``pairs`` of them.

    One pass over the members, around the first member as reference ``r``: with the deviations
    ``e_i = wrap(x_i - r)`` (angle rows wrapped, so means of angles are taken on the circle), the
    mean is ``r + sum(e_i) / N`` and the covariance ``(sum(e_i f_i') - sum(e_i) sum(f_i)' / N) / (N - 1)``.
    The reference is a member, so the sums are of deviations of the ensemble's own size (no
    cancellation of large numbers). A pair of an ensemble with itself computes each entry below the
    diagonal once and is exactly symmetric.

    Parameters
    ----------
    name : str
    ensembles : dict name -> MX (rows x members)
    angles : dict name -> angle flags of the rows
    pairs : sequence of (name, name)
    members : int

    Returns
    -------
    means : dict name -> MX
    covariances : dict (name, name) -> MX
    """
    syms = {k: ca.SX.sym(k, X.shape[0]) for k, X in ensembles.items()}
    refs = {k: ca.SX.sym(f"{k}_ref", X.shape[0]) for k, X in ensembles.items()}
    dev = {k: _wrapped(syms[k] - refs[k], angles[k]) for k in ensembles}
    outputs = {f"sum_{k}": dev[k] for k in ensembles}
    for a, b in pairs:
        outputs[f"sum_{a}_{b}"] = (from_lower(lambda i, j: dev[a][i] * dev[a][j], dev[a].numel()) if a == b
                                   else dev[a] @ dev[b].T)
    first = {k: X[:, 0] for k, X in ensembles.items()}
    sums = _over_members(name, {k: (syms[k], X) for k, X in ensembles.items()},
                         {f"{k}_ref": (refs[k], first[k]) for k in ensembles}, outputs, members, list(outputs))
    means = {k: first[k] + sums[f"sum_{k}"] / members for k in ensembles}
    covs = {(a, b): (sums[f"sum_{a}_{b}"] - sums[f"sum_{a}"] @ sums[f"sum_{b}"].T / members) / (members - 1)
            for a, b in pairs}
    return means, covs


class EnKF(StepEstimator):
    """Ensemble Kalman filter with ``N`` members and perturbed observations.

    Each member is propagated through the discretised model with its own process-noise draw
    ``w ~ N(0, Q)`` held over the step; the update uses the ensemble cross-covariances and the
    observation perturbed by ``v ~ N(0, R)``. Means of angle states and outputs are taken on the
    circle, residuals wrapped. The memory is the ensemble ``X`` (nx x N); the reported ``x, P`` are
    the ensemble mean and sample covariance, ``C`` the sample cross-covariance of consecutive
    ensembles (so smoothing applies).

    Parameters
    ----------
    dmodel : DiscreteModel
    Q, R : process and measurement noise covariances (the one meaning, ``docs/architecture.md``)
    measured : sequence of str, optional
    options : EnKFOptions or mapping
        ``gate`` (on the ensemble-mean innovation), ``jit``, ``outputs``, ``members``.

    Examples
    --------
    >>> import casship as cs
    >>> m = cs.models.sog_cog()
    >>> enkf = cs.EnKF(cs.discretize(m, 0.1), Q=[1e-3, 1e-4], R=1.0, options={"members": 50})
    >>> enkf.memory
    ('X',)
    """

    name = "EnKF"
    Options = EnKFOptions
    stochastic = True

    @property
    def members(self) -> int:
        """Ensemble size."""
        return self.options.members

    def _symbolic(self):
        return ca.MX

    def _memory_shapes(self) -> dict:
        return {"X": (self.model.nx, self.members)}

    def _draw_shapes(self) -> dict:
        return {"z_w": (self.model.nw, self.members), "z_v": (self.ny, self.members)}

    def memory_from(self, prior: Gaussian, rng=None) -> dict:
        return {"X": self.ensemble(prior, rng)}

    def ensemble(self, prior: Gaussian, seed=None) -> np.ndarray:
        """Initial ensemble (nx, N) drawn from ``prior``.

        Parameters
        ----------
        prior : Gaussian
        seed : int or numpy.random.Generator, optional
        """
        self.check_prior(prior)
        return prior.sample(self.members, np.random.default_rng(seed)).T.copy()

    def _build(self, s: dict) -> dict:
        m, N, ny = self.model, self.members, self.ny
        ang, angy = m.angle_states, self.angle_meas
        X, mask = s["X"], s["mask"]
        # one factor per step for all members (an SX Function of the small Q and R)
        Qs, Rs = ca.SX.sym("Q", m.nw, m.nw), ca.SX.sym("R", ny, ny)
        LQ, LR = ca.Function("enkf_noise_roots", [Qs, Rs], [psd_sqrt(Qs), psd_sqrt(Rs)])(s["Q"], s["R"])
        S = ca.SX
        x, z_w, z_v = S.sym("x", m.nx), S.sym("z_w", m.nw), S.sym("z_v", ny)
        yf = S.sym("yf", ny)
        u_prev, u, p, dt = S.sym("u_prev", m.nu), S.sym("u", m.nu), S.sym("p", m.np), S.sym("dt")
        Lq, Lr, y, mk, K_s = S.sym("LQ", m.nw, m.nw), S.sym("LR", ny, ny), S.sym("y", ny), S.sym("mask", ny), \
            S.sym("K", m.nx, ny)
        # forecast: every member through the model with its own held noise, and its outputs
        xf = self.dmodel.F(x, u_prev, p, Lq @ z_w, dt)
        fc = _over_members("enkf_forecast", {"x": (x, X), "z_w": (z_w, s["z_w"])},
                           {"u_prev": (u_prev, s["u_prev"]), "u": (u, s["u"]), "p": (p, s["p"]), "LQ": (Lq, LQ),
                            "dt": (dt, s["dt"])}, {"xf": xf, "yf": self.h_meas(xf, u, p)}, N)
        Xf, Yf = fc["xf"], fc["yf"]
        ens, angles = {"x": Xf, "y": Yf}, {"x": ang, "y": angy}

        def analysis(means, covs) -> dict:
            """The analysis from the forecast moments (unmeasured channels carry no spread)."""
            M = ca.diag(mask)
            Sm = masked_innovation_cov(M @ covs["y", "y"] @ M, s["R"], mask)
            e = residual(s["y"], means["y"], mask, angy)
            K, nis, ll, acc = self._gain_function()(Sm, covs["x", "y"] @ M, e, mask, s["gate"])
            xa = x + K_s @ residual(y + Lr @ z_v, yf, mk, angy, wrap_fast)
            Xa = _over_members("enkf_analysis", {"xf": (x, Xf), "yf": (yf, Yf), "z_v": (z_v, s["z_v"])},
                               {"y": (y, s["y"]), "mask": (mk, mask), "K": (K_s, K), "LR": (Lr, LR)},
                               {"xa": xa}, N)["xa"]
            post, post_cov = _moments("enkf_analysis_moments", {"x": Xa}, {"x": ang}, [("x", "x")], N)
            return {"X": Xa, "x": post["x"], "P": post_cov["x", "x"], "x_pred": means["x"], "e": e, "S": Sm, "K": K,
                    "nis": nis, "ll": ll, "accepted": acc}

        lean = analysis(*_moments("enkf_forecast_moments", ens, angles, [("x", "y"), ("y", "y")], N))
        # the smoothing diagnostics P_pred and C: in passes of their own for a step that leaves them out, ...
        _, pred_cov = _moments("enkf_forecast_spread", {"x": Xf}, {"x": ang}, [("x", "x")], N)
        _, step_cov = _moments("enkf_step_spread", {"x0": X, "x": Xf}, {"x0": ang, "x": ang}, [("x0", "x")], N)
        lean.update(P_pred=pred_cov["x", "x"], C=step_cov["x0", "x"])
        # ... and in the forecast's own pass for a step that returns them (a pass costs more than its sums;
        # the forecast moments are the same sums in the same order, so every other output is identical)
        means, covs = _moments("enkf_forecast_moments", {"x0": X, **ens}, {"x0": ang, **angles},
                               [("x", "y"), ("y", "y"), ("x", "x"), ("x0", "x")], N)
        self._with_spreads = {**analysis(means, covs), "P_pred": covs["x", "x"], "C": covs["x0", "x"]}
        return lean

    def _expressions(self, names) -> list:
        exprs = self._with_spreads if "P_pred" in names or "C" in names else self._exprs
        return [exprs[k] for k in names]

    def _gain_function(self) -> ca.Function:
        """Gain (zero when gated out), NIS, log-likelihood and acceptance from ``S`` and ``Pxy`` (SX)."""
        nx, ny = self.model.nx, self.ny
        S, Pxy, e = ca.SX.sym("S", ny, ny), ca.SX.sym("Pxy", nx, ny), ca.SX.sym("e", ny)
        mask, gate = ca.SX.sym("mask", ny), ca.SX.sym("gate")
        K, nis, ll = gain_and_terms(S, Pxy.T, e, mask)
        acc = nis <= gate
        return ca.Function("enkf_gain", [S, Pxy, e, mask, gate], [acc * K, nis, ll, acc],
                           ["S", "Pxy", "e", "mask", "gate"], ["K", "nis", "ll", "accepted"])
