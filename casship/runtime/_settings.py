"""Every setting of the runtime in one place: defaults and the ``CASSHIP_*`` environment variables.

=============================  ===================================================  =============================
variable                       what                                                 default
=============================  ===================================================  =============================
``CASSHIP_CACHE_DIR``          the compile cache folder, or ``off``                 ``$XDG_CACHE_HOME/casship``
``CASSHIP_CFLAGS``             compiler flags (replace :data:`DEFAULT_FLAGS`)       :data:`DEFAULT_FLAGS`
``CASSHIP_COMPILE_TIMEOUT``    seconds a compiler run may take                      :data:`DEFAULT_TIMEOUT`
``CASSHIP_FOLD_CHUNK``         samples per piece of a fold over a record            :data:`DEFAULT_CHUNK`
``CASSHIP_COMPILE_AFTER_EXIT`` ``0``: background compiles unfinished at exit are     ``1`` (handed to a detached
                               dropped, not handed to a detached process            process)
``CC``                         the C compiler                                       ``gcc``, else ``cc``
=============================  ===================================================  =============================

Values are read when they are used, so a change of the environment takes effect at once.
"""
from __future__ import annotations

import os
import shlex
from typing import Sequence

from ..errors import InputError, InputTypeError

__all__ = ["ENV_CACHE", "ENV_FLAGS", "ENV_TIMEOUT", "ENV_CHUNK", "ENV_AFTER_EXIT", "DEFAULT_FLAGS", "NATIVE_FLAGS", "DEFAULT_TIMEOUT",
           "DEFAULT_CHUNK", "chosen_flags", "compile_timeout", "fold_chunk"]

ENV_CACHE, ENV_FLAGS, ENV_TIMEOUT, ENV_CHUNK = ("CASSHIP_CACHE_DIR", "CASSHIP_CFLAGS", "CASSHIP_COMPILE_TIMEOUT",
                                                "CASSHIP_FOLD_CHUNK")
ENV_AFTER_EXIT = "CASSHIP_COMPILE_AFTER_EXIT"

DEFAULT_FLAGS = ("-O1", "-fno-math-errno", "-ffp-contract=off")
"""The one flag set casship compiles with unless told otherwise: compiled code gives the numbers of the
interpreted evaluation to the last bit (no ``-march=native``, no fused multiply-adds, no fast math;
``-fno-math-errno`` only stops ``sqrt`` from setting ``errno``), so where a background compile takes
over does not change a result. ``-O1`` because it compiles 3-5 times faster than ``-O2``/``-O3`` on the
large identification folds, and the step Functions and the record loop run as fast at ``-O1``
(``benchmarks/bench_compile.py``, ``docs/benchmarks.md``)."""

NATIVE_FLAGS = ("-O3", "-fno-math-errno", "-march=native")
"""The explicit opt-in for speed over equality (``CASSHIP_CFLAGS="-O3 -fno-math-errno -march=native"`` or
``flags=NATIVE_FLAGS``): this CPU's instructions, fused multiply-adds among them, 1.2-1.5 times faster
filter loops; results differ from the interpreted evaluation in the last bits, and the cache key then
includes the CPU model."""

DEFAULT_TIMEOUT = 600.0
"""Seconds a compiler run may take (``$CASSHIP_COMPILE_TIMEOUT`` overrides)."""

DEFAULT_CHUNK = 256
"""Samples per piece of a fold (``mapaccum``) over a record of any length (``$CASSHIP_FOLD_CHUNK``
overrides): one size, so one library per structure. Interpreted folds of short records take the next
power of two below it (less padding)."""


def chosen_flags(flags: Sequence[str] | str | None) -> tuple[str, ...]:
    """The compiler flags to use: ``flags``, else ``$CASSHIP_CFLAGS``, else :data:`DEFAULT_FLAGS`.

    Parameters
    ----------
    flags : sequence of str, str or None
        Explicit flags (a string is split like a shell command line).
    """
    if flags is None:
        env = os.environ.get(ENV_FLAGS)
        return tuple(shlex.split(env)) if env and env.strip() else DEFAULT_FLAGS
    if isinstance(flags, str):
        return tuple(shlex.split(flags))
    flags = tuple(flags)
    bad = [f for f in flags if not isinstance(f, str)]
    if bad:
        raise InputTypeError(f"compiler flags must be strings, got {bad}")
    return flags


def _positive(name: str, default: float, kind=float):
    env = os.environ.get(name)
    if env is None or not env.strip():
        return default
    try:
        value = kind(env)
    except ValueError:
        value = None
    if value is None or not value > 0 or value != value:
        raise InputError(f"{name} must be a positive {'integer' if kind is int else 'number'}, got {env!r}")
    return value


def compile_timeout() -> float:
    """Seconds a compiler run may take: ``$CASSHIP_COMPILE_TIMEOUT``, else :data:`DEFAULT_TIMEOUT`."""
    return _positive(ENV_TIMEOUT, DEFAULT_TIMEOUT)


def fold_chunk() -> int:
    """Samples per piece of a fold: ``$CASSHIP_FOLD_CHUNK``, else :data:`DEFAULT_CHUNK`."""
    return _positive(ENV_CHUNK, DEFAULT_CHUNK, int)
