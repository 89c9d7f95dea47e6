"""Typed estimator options: one frozen dataclass per estimator, built from a dataclass or a mapping.

``EKF(dm, Q, R, options={"gate": 0.999})`` and ``EKF(dm, Q, R, options=EKFOptions(gate=0.999))``
are the same; an unknown key raises ``ValueError`` naming it and listing the known ones, and a
value out of range raises naming the option.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Mapping

from ..errors import InputError, InputTypeError

__all__ = ["EstimatorOptions", "DIAGNOSTICS", "check_int", "check_number"]

# Diagnostics a step Function can return besides its memory slots, in their fixed order.
DIAGNOSTICS = ("x", "P", "x_pred", "P_pred", "C", "e", "S", "K", "nis", "ll", "accepted")


def check_int(value, name: str, low: int) -> int:
    """``value`` as an int ``>= low``, or ``ValueError`` naming the option.

    Parameters
    ----------
    value : number
    name : str
        The option (for the message).
    low : int
        Smallest value allowed.
    """
    if isinstance(value, bool) or not check_number(value, name).is_integer() or int(value) < low:
        raise InputError(f"option {name!r} must be an integer >= {low}, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class EstimatorOptions:
    """Options of every estimator.

    Parameters
    ----------
    gate : float or None
        Probability of the chi-square innovation gate (e.g. 0.999); off by default. A sample whose
        normalised innovation squared exceeds the quantile for the number of channels measured is
        not used for the update and is reported as rejected (a NIS equal to the quantile passes).
    jit : bool, None, str or casship.runtime.JitPolicy
        When to compile the step and its record loop to C (the runtime's one policy):
        ``False`` interpreted, ``True`` compiled before the first run, ``None`` compiled from the
        cache or in the background while the first runs go interpreted (the same numbers: the
        default flags keep them to the last bit). Stored as a :class:`~casship.runtime.JitPolicy`.
    outputs : tuple of str or "all"
        Diagnostics the step Function :attr:`StepEstimator.step` (and the online runner) returns
        besides the memory: a subset of ``x, P, x_pred, P_pred, C, e, S, K, nis, ll, accepted``
        that contains ``x`` and ``P``. The compiled code computes only what is asked for; the
        default is the lean ``("x", "P")``. ``filter`` always computes every diagnostic.
    max_gap : float or None
        Longest sample interval [s] predicted in one step; by default the stability limit of a
        fixed-step discretisation (see :mod:`casship.estimators.gaps`).
    on_gap : {"raise", "bridge"}
        What a longer interval does: raise ``ValueError`` naming it, or be bridged by
        prediction-only steps (with a warning).
    """

    gate: float | None = None
    jit: object = False
    outputs: tuple = ("x", "P")
    max_gap: float | None = None
    on_gap: str = "raise"

    def __post_init__(self):
        if self.gate is not None:
            gate = check_number(self.gate, "gate")
            if not 0 < gate < 1:
                raise InputError(f"option 'gate' is a probability in (0, 1), got {self.gate!r}")
            object.__setattr__(self, "gate", gate)
        from ..runtime import JitPolicy

        try:
            object.__setattr__(self, "jit", JitPolicy.of(self.jit))
        except ValueError:
            raise InputError(f"option 'jit' is True, False, None or one of 'off', 'now', 'background', "
                             f"got {self.jit!r}") from None
        outputs = DIAGNOSTICS if self.outputs == "all" else self.outputs
        if isinstance(outputs, str):
            outputs = (outputs,)
        outputs = tuple(outputs)
        unknown = [o for o in outputs if o not in DIAGNOSTICS]
        if unknown:
            raise InputError(f"option 'outputs': unknown diagnostic(s) {unknown}; known: {list(DIAGNOSTICS)} or 'all'")
        if "x" not in outputs or "P" not in outputs:
            raise InputError(f"option 'outputs' must contain 'x' and 'P', got {list(outputs)}")
        object.__setattr__(self, "outputs", tuple(o for o in DIAGNOSTICS if o in outputs))
        if self.max_gap is not None:
            gap = check_number(self.max_gap, "max_gap")
            if not (gap > 0 and gap < float("inf")):
                raise InputError(f"option 'max_gap' is a positive time [s] (or None), got {self.max_gap!r}")
            object.__setattr__(self, "max_gap", gap)
        if self.on_gap not in ("raise", "bridge"):
            raise InputError(f"option 'on_gap' is 'raise' or 'bridge', got {self.on_gap!r}")

    @classmethod
    def known(cls) -> list[str]:
        """Names of the options."""
        return [f.name for f in fields(cls)]

    @classmethod
    def from_value(cls, value, owner: str) -> "EstimatorOptions":
        """Options from ``None`` (defaults), an instance of this class or a mapping of names to values.

        Parameters
        ----------
        value : None, EstimatorOptions or mapping
        owner : str
            The estimator (for messages).
        """
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, EstimatorOptions):
            raise InputTypeError(f"{owner} takes {cls.__name__}, got {type(value).__name__}")
        if not isinstance(value, Mapping):
            raise InputTypeError(f"options of {owner} must be a {cls.__name__} or a mapping, got {type(value).__name__}")
        unknown = sorted(set(value) - set(cls.known()))
        if unknown:
            raise InputError(f"unknown option(s) {unknown} for {owner}; known: {sorted(cls.known())}")
        return cls(**dict(value))

    def replace(self, **changes) -> "EstimatorOptions":
        """A copy with some options changed (checked like the constructor).

        Parameters
        ----------
        **changes
            Option name -> new value.
        """
        unknown = sorted(set(changes) - set(self.known()))
        if unknown:
            raise InputError(f"unknown option(s) {unknown}; known: {sorted(self.known())}")
        return replace(self, **changes)


def check_number(value, name: str) -> float:
    """An option's value as a float, or :class:`~casship.errors.InputError` naming the option.

    Parameters
    ----------
    value : object
        A number, or text that reads as one (an option from the command line).
    name : str
        The option (for the message).

    Returns
    -------
    float
    """
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"option {name!r} is a number, got {value!r}") from None
