"""The C compiler: which one, with which flags, and running it with a time limit.

The compiler is ``$CC`` if set, else ``gcc``, else ``cc``. The flags are :data:`DEFAULT_FLAGS`
unless ``flags=`` or ``$CASSHIP_CFLAGS`` says otherwise; a compiler that refuses
``-march=native`` (found by compiling a one-line probe with and without it) gets
:data:`PORTABLE_FLAGS` instead, and only then. Every compiler run is limited to
``$CASSHIP_COMPILE_TIMEOUT`` seconds (default :data:`DEFAULT_TIMEOUT`); a compiler that does not
finish is stopped with everything it started, and the compile fails with :class:`CompileError`.
"""
from __future__ import annotations

import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Sequence

import casadi as ca

from ..errors import InputError, InputTypeError, SetupError
from ..progress import activity

__all__ = ["CompileError", "DEFAULT_FLAGS", "PORTABLE_FLAGS", "DEFAULT_TIMEOUT", "find_compiler", "chosen_flags",
           "compile_timeout", "accepts_native", "build_library", "run_compiler", "SUFFIX"]

DEFAULT_FLAGS = ("-O3", "-fno-math-errno", "-march=native")
"""Compiler flags used unless told otherwise, chosen by measurement (``benchmarks/bench_compile.py``,
``docs/benchmarks.md``): ``-O3`` runs the filter folds about 1.3 times faster than ``-O2`` at the same
compile time; ``-fno-math-errno`` lets ``sqrt`` and friends compile to single instructions (only
``errno`` is not set); ``-march=native`` uses the instructions of this CPU (fused multiply-add among
them, so results differ from the interpreted step in the last bits) and makes the filter and
smoother loops 10-17 % faster. Code compiled for one CPU is never loaded on another: the cache key
then includes the CPU model and features."""

PORTABLE_FLAGS = ("-O3", "-fno-math-errno")
"""The default flags without ``-march=native``, for compilers that refuse it."""

DEFAULT_TIMEOUT = 600.0
"""Seconds a compiler run may take (``$CASSHIP_COMPILE_TIMEOUT`` overrides)."""

ENV_FLAGS, ENV_TIMEOUT = "CASSHIP_CFLAGS", "CASSHIP_COMPILE_TIMEOUT"
SUFFIX = {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")
_COMPILERS: dict[str, tuple[str, str]] = {}
_NATIVE: dict[tuple[str, str], bool] = {}          # (path, version) -> accepts -march=native


class CompileError(SetupError):
    """C code could not be compiled here: no compiler, a compiler error, or the time limit (a
    :class:`casship.errors.SetupError`, so a ``RuntimeError``)."""


def find_compiler(compiler: str | None = None) -> tuple[str, str]:
    """The C compiler used: its full path and the first line of its ``--version`` (cached).

    Parameters
    ----------
    compiler : str, optional
        A compiler command or path (default: ``$CC``, else ``gcc``, else ``cc``).

    Returns
    -------
    (path, version) : tuple of str

    Raises
    ------
    CompileError
        When no such compiler is found.
    """
    names = [compiler] if compiler else [c for c in (os.environ.get("CC"), "gcc", "cc") if c]
    for name in names:
        if name in _COMPILERS:
            return _COMPILERS[name]
        path = shutil.which(name)
        if path:
            try:
                out = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=30)
                text = (out.stdout or out.stderr).strip()
                version = text.splitlines()[0] if text else ""
            except (OSError, subprocess.SubprocessError):
                version = ""
            _COMPILERS[name] = (path, version)
            return path, version
    raise CompileError(f"no C compiler found (tried {names}); install gcc or clang, or set CC")


def chosen_flags(flags: Sequence[str] | str | None) -> tuple[tuple[str, ...], bool]:
    """The flags to use and whether they are the defaults (which may fall back to the portable ones).

    Parameters
    ----------
    flags : sequence of str, str or None
        Explicit flags; ``None``: ``$CASSHIP_CFLAGS``, else :data:`DEFAULT_FLAGS`.
    """
    if flags is None:
        env = os.environ.get(ENV_FLAGS)
        return (tuple(shlex.split(env)), False) if env and env.strip() else (DEFAULT_FLAGS, True)
    if isinstance(flags, str):
        return tuple(shlex.split(flags)), False
    flags = tuple(flags)
    bad = [f for f in flags if not isinstance(f, str)]
    if bad:
        raise InputTypeError(f"compiler flags must be strings, got {bad}")
    return flags, False


def compile_timeout() -> float:
    """Seconds a compiler run may take: ``$CASSHIP_COMPILE_TIMEOUT``, else :data:`DEFAULT_TIMEOUT`."""
    env = os.environ.get(ENV_TIMEOUT)
    if env is None or not env.strip():
        return DEFAULT_TIMEOUT
    try:
        value = float(env)
    except ValueError:
        value = float("nan")
    if not value > 0:
        raise InputError(f"{ENV_TIMEOUT} must be a positive number of seconds, got {env!r}")
    return value


def run_compiler(cmd: list[str], what: str) -> subprocess.CompletedProcess:
    """Run a compiler command within the time limit (stopping it and its children when over).

    Parameters
    ----------
    cmd : list of str
        The command.
    what : str
        What is compiled, for the messages.

    Raises
    ------
    CompileError
        When the compiler cannot be started or does not finish in time.
    """
    limit = compile_timeout()
    posix = os.name == "posix"
    try:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=posix)
    except OSError as exc:
        raise CompileError(f"compiling {what}: the compiler {cmd[0]} cannot be run ({exc})") from None
    try:
        with activity(f"casship: compiling {what} to C (once; then kept in the cache)"):
            out, err = proc.communicate(timeout=limit)
    except subprocess.TimeoutExpired:
        if posix:                           # the driver and the passes it started (cc1, as, ld)
            try:
                os.killpg(proc.pid, signal.SIGKILL)
            except OSError:
                pass
        proc.kill()
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:       # a child still holds the pipes (no process groups here)
            pass
        raise CompileError(f"compiling {what}: the compiler {cmd[0]} did not finish within {limit:g} s and was "
                           f"stopped (${ENV_TIMEOUT} sets the limit)") from None
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def accepts_native(compiler: tuple[str, str]) -> bool:
    """Whether ``compiler`` (path, version) accepts ``-march=native`` (probed once per process).

    A compiler that fails the probe also without the flag is not said to refuse it (whatever is
    wrong with it shows when the real code is compiled).
    """
    if compiler not in _NATIVE:
        with tempfile.TemporaryDirectory(prefix="casship-probe-") as tmp:
            src = Path(tmp) / "probe.c"
            src.write_text("int casship_probe(int a) { return 2 * a; }\n")

            def ok(*flags):
                cmd = [compiler[0], *flags, "-c", str(src), "-o", str(Path(tmp) / "probe.o")]
                return run_compiler(cmd, "a probe").returncode == 0

            _NATIVE[compiler] = ok("-march=native") or not ok()
    return _NATIVE[compiler]


def build_library(fun: ca.Function, folder: Path, stem: str, compiler: str, flags: Sequence[str],
                  extra_source: str = "") -> Path:
    """Generate ``fun`` as C in ``folder`` (followed by ``extra_source``) and compile it into the shared
    library ``stem + suffix`` there (only its owner may write it).

    Raises
    ------
    CompileError
        Naming the Function, with the compiler's last message.
    """
    src = folder / f"{stem}.c"
    gen = ca.CodeGenerator(f"{stem}.c", {"with_header": False})
    gen.add(fun)
    src.write_text(gen.dump() + extra_source)
    lib = folder / f"{stem}{SUFFIX}"
    cmd = [compiler, *flags, "-fPIC", "-shared", str(src), "-o", str(lib), "-lm"]
    try:
        out = run_compiler(cmd, repr(fun.name()))
    finally:
        src.unlink(missing_ok=True)
    if out.returncode != 0 or not lib.is_file():
        msg = (out.stderr or out.stdout).strip().splitlines()
        raise CompileError(f"compiling {fun.name()!r} to C failed ({' '.join(cmd[:1 + len(flags)])} ...): "
                           f"{msg[-1] if msg else f'exit status {out.returncode}'}")
    os.chmod(lib, 0o700)
    return lib
