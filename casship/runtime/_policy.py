"""When casship compiles: the one compile policy (:class:`JitPolicy`) and the one table of shared Functions.

Estimators, simulation, replays and identification never compile themselves: they hand a Function
and their ``jit`` to :func:`jit_function` (or :func:`shared_function`, which also keeps it per
process under a structure key, or :func:`record_loop` for an estimator's compiled record loop), and
this module decides, with the one flag set of :mod:`._settings`.

``jit`` means the same wherever casship accepts it:

==================  ======================  ==========================================================
``jit=``            policy                  what happens
==================  ======================  ==========================================================
``False``, "off"    ``JitPolicy.OFF``       interpreted (CasADi's virtual machine); nothing compiled
``True``, "now"     ``JitPolicy.NOW``       compiled before the first use (through the on-disk cache);
                                            a failed compile raises :class:`CompileError`
``None``,           ``JitPolicy.BACKGROUND`` the compiled code if the cache holds it; else compiled in
"background"                                a background thread while the interpreted Function runs,
                                            taken over once loaded (a failure warns once and stays
                                            interpreted)
==================  ======================  ==========================================================

With the default flags the interpreted and the compiled evaluations give the same numbers to the last
bit, so the moment a background compile takes over does not change a result.
"""
from __future__ import annotations

import enum
import hashlib
import threading
import warnings
from typing import Callable, Sequence

import casadi as ca

from ._background import Compiling, compile_in_background
from ._buffers import BoundedTable
from ._cache import cached_function, compile_function
from ._loop import NativeFold, driver_source

__all__ = ["JitPolicy", "jit_function", "shared_function", "shared_functions", "record_loop", "is_compiled",
           "current_function", "BACKGROUND_FAILURES",
           "FUNCTIONS", "COUNTS"]


class JitPolicy(enum.Enum):
    """When to compile: ``OFF`` (interpreted), ``NOW`` (before the first use), ``BACKGROUND`` (from the
    cache, else in a background thread, interpreted until then). ``bool(policy)`` is whether it compiles.

    Examples
    --------
    >>> JitPolicy.of(True), JitPolicy.of(None), JitPolicy.of("off")
    (<JitPolicy.NOW: 'now'>, <JitPolicy.BACKGROUND: 'background'>, <JitPolicy.OFF: 'off'>)
    """

    OFF = "off"
    NOW = "now"
    BACKGROUND = "background"

    def __bool__(self) -> bool:
        return self is not JitPolicy.OFF

    @classmethod
    def of(cls, jit) -> "JitPolicy":
        """The policy a ``jit`` argument means: ``False`` -> OFF, ``True`` -> NOW, ``None`` -> BACKGROUND,
        a policy or its name as itself.

        Raises
        ------
        casship.errors.InputError
            For anything else, naming it.
        """
        if isinstance(jit, cls):
            return jit
        if jit is None:
            return cls.BACKGROUND
        if jit is True or jit is False:
            return cls.NOW if jit else cls.OFF
        if isinstance(jit, str) and jit.strip().lower() in {p.value for p in cls}:
            return cls(jit.strip().lower())
        from ..errors import InputError

        raise InputError(f"jit must be True (compile now), False (interpreted), None (in the background) or one of "
                         f"'off', 'now', 'background', got {jit!r}")


KEEP = 384                                  # Functions kept per process (the oldest go first)
FUNCTIONS = BoundedTable(KEEP)              # (namespace, structure..., policy) -> Function or Compiling
COUNTS: dict[str, dict[str, int]] = {}      # namespace -> Functions built and found again (profiles, tests)
_BROKEN: list[str] = []                     # why a background compile failed (later ones then stay interpreted)
BACKGROUND_FAILURES = _BROKEN               # public view (read, or cleared by a test that plants a failure)
_LOCK = threading.Lock()


def is_compiled(fun) -> bool:
    """Whether ``fun`` (a Function or a :class:`Compiling` handle) evaluates compiled code now."""
    fun = fun.function if isinstance(fun, Compiling) else fun
    return isinstance(fun, ca.Function) and fun.class_name() == "External"


def current_function(fun) -> ca.Function:
    """The Function to evaluate now: a :class:`Compiling` handle's current one, else ``fun`` itself."""
    return fun.function if isinstance(fun, Compiling) else fun


def _start(fun: ca.Function, *, extra_source: str = "") -> ca.Function | Compiling:
    """The background policy: the cached library, else a :class:`Compiling` handle."""
    from ..progress import bar

    if not extra_source:
        hit = cached_function(fun)
        if hit is not None:
            return hit
    with _LOCK:
        if _PENDING["bar"] is None:
            _PENDING["bar"] = bar(None, "compiling numeric code (running interpreted meanwhile)", unit="Function")
        _PENDING["n"] += 1
        _PENDING["bar"].total = _PENDING["n"]
        _PENDING["bar"].refresh()
    return compile_in_background(fun, on_done=_finished, extra_source=extra_source)


_PENDING: dict = {"bar": None, "n": 0, "done": 0}


def _finished(job: Compiling) -> None:
    """A background compile ended: advance the bar; a failure warns once (the caller stays interpreted)."""
    if job.error is not None and not _BROKEN and not job.cancelled:
        _BROKEN.append(str(job.error))
        warnings.warn(f"casship runs interpreted (slower): {job.error}", RuntimeWarning, stacklevel=2)
    with _LOCK:
        _PENDING["done"] += 1
        b = _PENDING["bar"]
        if b is not None:
            b.update()
            if _PENDING["done"] >= _PENDING["n"]:
                b.close()
                _PENDING.update(bar=None, n=0, done=0)


def jit_function(fun: ca.Function, jit=None) -> ca.Function | Compiling:
    """``fun`` as ``jit`` says: itself, compiled now, or (background) the cached library or a handle.

    Parameters
    ----------
    fun : casadi.Function
    jit : bool, None, str or JitPolicy
        See :class:`JitPolicy`.

    Returns
    -------
    casadi.Function or Compiling
        A :class:`Compiling` handle only with the background policy while the compile runs; its
        ``function`` is the Function to evaluate now.
    """
    policy = JitPolicy.of(jit)
    if policy is JitPolicy.OFF or (_BROKEN and policy is JitPolicy.BACKGROUND):
        return fun
    if policy is JitPolicy.NOW:
        return compile_function(fun)
    return _start(fun)


def shared_function(key: tuple, make: Callable[[], ca.Function], jit=None) -> ca.Function:
    """The Function ``make()`` under ``jit``, built once per process for every caller with the same ``key``.

    Parameters
    ----------
    key : tuple
        ``(namespace, structure...)``: the namespace (e.g. ``"identify"``) and whatever the Function
        depends on (digests of Functions, sizes), never the data.
    make : callable
        Builds the Function (called once per key and policy).
    jit : bool, None, str or JitPolicy
        See :class:`JitPolicy`. An MX Function with a node CasADi cannot generate C for (an
        adaptive integrator) is never compiled.

    Returns
    -------
    casadi.Function
        The Function to evaluate now (interpreted while a background compile runs).
    """
    policy = JitPolicy.of(jit)
    full = (*key, policy)
    counts = COUNTS.setdefault(key[0], {"built": 0, "reused": 0})
    fun = FUNCTIONS.get(full)
    if fun is None:
        fun = FUNCTIONS.keep(full, jit_function(make(), policy))
        counts["built"] += 1
    else:
        counts["reused"] += 1
    return current_function(fun)


def shared_functions(prefix: tuple) -> dict:
    """The entries of the table whose keys start with ``prefix``: key -> Function or :class:`Compiling`."""
    n = len(prefix)
    return {k: f for k, f in list(FUNCTIONS.items()) if k[:n] == prefix}


_DIGESTS = BoundedTable(KEEP)              # id(step) -> (step, digest): a step serialised once, kept alive


def _digest(step: ca.Function, memory) -> str:
    entry = _DIGESTS.get(id(step))
    if entry is None or entry[0] is not step:
        entry = _DIGESTS.keep(id(step), (step, hashlib.sha256(step.serialize().encode()).hexdigest()))
    return entry[1] + "\0" + "\0".join(memory)


def record_loop(step: ca.Function, memory: Sequence[str], jit) -> NativeFold | None:
    """The compiled record loop of ``step`` (:class:`NativeFold`) under ``jit``, or None: run interpreted.

    ``NOW`` compiles it (raising :class:`CompileError` on failure); ``BACKGROUND`` gives it once its
    library is loaded (from the cache or a background compile started by the first call), None until
    then; ``OFF`` gives None.

    Parameters
    ----------
    step : casadi.Function
    memory : sequence of str
    jit : bool, None, str or JitPolicy
    """
    policy = JitPolicy.of(jit)
    if policy is JitPolicy.OFF:
        return None
    from ._cache import cache_dir

    key = ("record-loop", _digest(step, memory), str(cache_dir()), policy)    # each cache folder gets its copy
    entry = FUNCTIONS.get(key)
    if isinstance(entry, NativeFold):
        return entry
    if policy is JitPolicy.NOW:
        return FUNCTIONS.keep(key, NativeFold(step, memory))
    if entry is None:
        source = driver_source(step.name(), step.n_in(), step.n_out())
        hit = cached_function(step, extra_source=source, library=True)
        if hit is not None:
            return FUNCTIONS.keep(key, NativeFold(step, memory, compiled=hit))
        if _BROKEN:
            return None
        entry = FUNCTIONS.keep(key, _start(step, extra_source=source))
    if entry.ready:
        return FUNCTIONS.keep(key, NativeFold(step, memory, compiled=(entry.function, entry.library)))
    return None
