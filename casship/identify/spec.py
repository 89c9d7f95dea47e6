"""What an identification problem is made of: one frozen value.

:class:`ProblemSpec` holds the arguments an :class:`~casship.identify.OutputErrorProblem` or an
:class:`~casship.identify.MLEProblem` was built from: the model (or estimator), the records, the
free quantities and their sharing, the prior, the starting values, bounds and scales, and the
method's own options. A problem exposes it as ``problem.spec``; cross-validation builds each fold
from a copy on other records (:meth:`ProblemSpec.with_records`), and
:meth:`~casship.identify.problem.IdentificationProblem.replace` from a copy with other settings.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from ..errors import InputError

__all__ = ["ProblemSpec", "OutputErrorOptions", "LikelihoodOptions"]

#: Settings every problem takes (keyword arguments of both constructors).
COMMON = ("free", "params", "x0", "estimate_x0", "share", "groups", "prior", "bounds", "scale", "jit")
#: Settings that hold one item per record (subset with the records).
PER_RECORD = ("x0", "record_weights", "record_params")


@dataclass(frozen=True)
class OutputErrorOptions:
    """The output-error method's own options (see :class:`~casship.identify.OutputErrorProblem`).

    Parameters
    ----------
    measured, sigma, record_weights, shooting, segment, method, record_params
        As the constructor takes them.
    """

    measured: Sequence[str] | None = None
    sigma: Any = "estimate"
    record_weights: Sequence[float] | None = None
    shooting: str = "single"
    segment: int = 50
    method: str = "rk4"
    record_params: Sequence[Mapping | None] | None = None


@dataclass(frozen=True)
class LikelihoodOptions:
    """The likelihood method's own options (see :class:`~casship.identify.MLEProblem`).

    Parameters
    ----------
    noise, prior_var, Q, R, measured, seed
        As the constructor takes them.
    """

    noise: Mapping | None = None
    prior_var: float = 1.0
    Q: Any = None
    R: Any = None
    measured: Sequence[str] | None = None
    seed: Any = 0


def _fields(value) -> dict:
    """A dataclass's fields by name, shallow (the values themselves, not copies)."""
    return {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}


@dataclass(frozen=True)
class ProblemSpec:
    """The arguments of an identification problem, as one value.

    Parameters
    ----------
    problem : type
        The problem class (:class:`~casship.identify.OutputErrorProblem`, :class:`~casship.identify.MLEProblem`).
    subject : object
        Its first argument: the model (output error) or the estimator (likelihood).
    records : sequence of Dataset
        The records.
    free, params, x0, estimate_x0, share, groups, prior, bounds, scale, jit
        The settings both problems take (see their constructors).
    options : OutputErrorOptions or LikelihoodOptions
        The method's own options (the problem class's ``OPTIONS`` type).
    subject_name : str
        The constructor's name of :attr:`subject` (``"model"`` or ``"estimator"``).
    """

    problem: type
    subject: Any
    records: Sequence
    free: Sequence[str] = ()
    params: Any = None
    x0: Any = None
    estimate_x0: Sequence[str] = ()
    share: Mapping | None = None
    groups: Mapping | None = None
    prior: Any = None
    bounds: Mapping | None = None
    scale: Mapping | None = None
    jit: bool | None = None
    options: Any = field(default_factory=OutputErrorOptions)
    subject_name: str = "model"

    @classmethod
    def from_arguments(cls, problem: type, arguments: Mapping, subject_name: str) -> "ProblemSpec":
        """The spec of a constructor call ``problem(**arguments)``.

        Parameters
        ----------
        problem : type
            The problem class.
        arguments : mapping
            Its constructor's arguments by name (the records as ``datasets``).
        subject_name : str
            The name of its first argument (``"model"`` or ``"estimator"``).
        """
        args = dict(arguments)
        subject, records = args.pop(subject_name), args.pop("datasets")
        common = {k: args.pop(k) for k in COMMON if k in args}
        return cls(problem, subject, records, **common, options=problem.OPTIONS(**args), subject_name=subject_name)

    def arguments(self) -> dict:
        """The constructor's keyword arguments that rebuild the problem."""
        return {self.subject_name: self.subject, "datasets": self.records,
                **{k: getattr(self, k) for k in COMMON}, **_fields(self.options)}

    def build(self):
        """The problem this spec describes (built anew: it folds and checks its records)."""
        return self.problem(**self.arguments())

    def replace(self, **changes) -> "ProblemSpec":
        """A copy with constructor arguments changed (``datasets=`` for the records).

        Parameters
        ----------
        **changes
            Constructor arguments of :attr:`problem`.
        """
        args = {**self.arguments(), **changes}
        return type(self).from_arguments(self.problem, args, self.subject_name)

    def with_records(self, records: Sequence, indices: Sequence[int]) -> "ProblemSpec":
        """A copy on other records: ``records`` stand for the records ``indices`` of this spec, and
        the per-record settings (``x0``, ``record_weights``, ``share`` and ``groups`` labels) are
        taken at those indices alike.

        Parameters
        ----------
        records : sequence of Dataset
            The new records, one per index.
        indices : sequence of int
            Which of this spec's records each stands for.
        """
        idx = [int(i) for i in indices]
        if len(records) != len(idx):
            raise InputError(f"with_records: {len(records)} records for {len(idx)} indices")
        kw = {"records": list(records)}
        if isinstance(self.x0, (list, tuple)):
            kw["x0"] = [self.x0[i] for i in idx]
        per = {k: [v[i] for i in idx] for k, v in _fields(self.options).items()
               if k in PER_RECORD and isinstance(v, (list, tuple))}
        kw["options"] = dataclasses.replace(self.options, **per)
        if self.share:
            kw["share"] = {n: (h if isinstance(h, str) else [list(h)[i] for i in idx]) for n, h in self.share.items()}
        if self.groups:
            kw["groups"] = {g: [list(v)[i] for i in idx] for g, v in self.groups.items()}
        return dataclasses.replace(self, **kw)
