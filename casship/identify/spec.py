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
from types import MappingProxyType
from typing import Any, Mapping, Sequence

from ..errors import InputError

__all__ = ["ProblemSpec"]

#: Settings every problem takes (keyword arguments of both constructors).
COMMON = ("free", "params", "x0", "estimate_x0", "share", "groups", "prior", "bounds", "scale", "jit")
#: Settings that hold one item per record (subset with the records).
PER_RECORD = ("x0", "record_weights")


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
    options : mapping
        The method's own options (output error: ``measured, sigma, record_weights, shooting,
        segment, method``; likelihood: ``noise, prior_var, Q, R, measured, seed``).
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
    options: Mapping = field(default_factory=dict)
    subject_name: str = "model"

    def __post_init__(self):
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))

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
        return cls(problem, subject, records, **common, options=args, subject_name=subject_name)

    def arguments(self) -> dict:
        """The constructor's keyword arguments that rebuild the problem."""
        return {self.subject_name: self.subject, "datasets": self.records,
                **{k: getattr(self, k) for k in COMMON}, **self.options}

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
        options = dict(self.options)
        for key in PER_RECORD:
            if isinstance(options.get(key), (list, tuple)):
                options[key] = [options[key][i] for i in idx]
        kw["options"] = options
        if self.share:
            kw["share"] = {n: (h if isinstance(h, str) else [list(h)[i] for i in idx]) for n, h in self.share.items()}
        if self.groups:
            kw["groups"] = {g: [list(v)[i] for i in idx] for g, v in self.groups.items()}
        return dataclasses.replace(self, **kw)
