"""The C compiler: which one, running it with a time limit, and stopping it.

The compiler is ``$CC`` if set, else ``gcc``, else ``cc``; the flags and the time limit come from
:mod:`._settings` (one flag set, bit-exact by default). Every compiler run is limited to
``$CASSHIP_COMPILE_TIMEOUT`` seconds; a compiler that does not finish is stopped with everything it
started (its process group), and the compile fails with :class:`CompileError`.

Nothing waits for a compiler nobody needs: a Ctrl-C while one runs in the calling thread stops it
(its process group) before the interrupt goes on (one that comes while the compiler is being started
is held until it is registered, then handled the same way), and at exit :func:`stop_compilers` stops those
still running in background threads and removes their build folders.
"""
from __future__ import annotations

import atexit
import os
import shutil
import signal
import subprocess
import sys
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Sequence

import casadi as ca

from ..errors import SetupError
from ..progress import activity
from ._settings import ENV_TIMEOUT, compile_timeout

__all__ = ["CompileError", "find_compiler", "run_compiler", "build_library", "stop_compilers", "stopping", "interrupts_deferred",
           "building", "SUFFIX"]

SUFFIX = {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")
_COMPILERS: dict[str, tuple[str, str]] = {}
_RUNNING: set = set()               # compiler processes running now
_BUILDING: set = set()              # build folders in use now
_STATE = {"stopping": False}
_STATE_LOCK = threading.Lock()


class CompileError(SetupError):
    """C code could not be compiled here: no compiler, a compiler error, or the time limit (a
    :class:`casship.errors.SetupError`, so a ``RuntimeError``)."""


def stopping() -> bool:
    """Whether this process is ending (no compiler is started any more)."""
    return _STATE["stopping"]


def _kill(proc: subprocess.Popen) -> None:
    """Stop ``proc`` and everything it started (its process group, on POSIX)."""
    if os.name == "posix":
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
    try:
        proc.kill()
    except OSError:
        pass


def stop_compilers() -> None:
    """Stop every compiler this process runs (their process groups) and remove their build folders;
    later compiles fail at once. Run at exit, so that a process whose work is done never waits for a
    background compile."""
    with _STATE_LOCK:
        _STATE["stopping"] = True
        procs, folders = list(_RUNNING), list(_BUILDING)
    for proc in procs:
        _kill(proc)
    for folder in folders:
        shutil.rmtree(folder, ignore_errors=True)


atexit.register(stop_compilers)


class building:
    """Context manager: ``folder`` is a build folder in use (removed by :func:`stop_compilers` at exit)."""

    def __init__(self, folder):
        self.folder = Path(folder)

    def __enter__(self):
        with _STATE_LOCK:
            _BUILDING.add(self.folder)
        return self.folder

    def __exit__(self, *exc):
        with _STATE_LOCK:
            _BUILDING.discard(self.folder)
        return False


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
    with interrupts_deferred() as pending:      # a Ctrl-C before the compiler is registered is held back
        with _STATE_LOCK:
            if _STATE["stopping"]:
                raise CompileError(f"compiling {what}: not started, the process is ending")
            try:
                # a session of its own: a Ctrl-C at the terminal reaches casship, which stops the group
                proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                        start_new_session=posix)
            except OSError as exc:
                raise CompileError(f"compiling {what}: the compiler {cmd[0]} cannot be run ({exc})") from None
            _RUNNING.add(proc)
    try:
        pending.deliver()                         # ... and goes on here, where it stops the compiler
        with activity(f"casship: compiling {what} to C (once; then kept in the cache)"):
            out, err = proc.communicate(timeout=limit)
    except subprocess.TimeoutExpired:
        _kill(proc)
        try:
            proc.communicate(timeout=10)
        except subprocess.TimeoutExpired:       # a child still holds the pipes (no process groups here)
            pass
        raise CompileError(f"compiling {what}: the compiler {cmd[0]} did not finish within {limit:g} s and was "
                           f"stopped (${ENV_TIMEOUT} sets the limit)") from None
    except BaseException:                       # a Ctrl-C (or any error) here: the compiler goes too
        _kill(proc)
        try:
            proc.wait(timeout=1)
        except BaseException:                   # noqa: BLE001 - a second Ctrl-C: the group is killed already
            pass
        raise
    finally:
        with _STATE_LOCK:
            _RUNNING.discard(proc)
    if _STATE["stopping"]:
        raise CompileError(f"compiling {what}: stopped, the process is ending")
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


class _Deferred:
    """The Ctrl-Cs held back by :func:`interrupts_deferred`, handed on by :meth:`deliver`."""

    def __init__(self):
        self.caught: list = []
        self.handler = None

    def __call__(self, signum, frame):
        self.caught.append((signum, frame))

    def deliver(self) -> None:
        """Run the handler that was in place for each Ctrl-C held back (the default one raises
        ``KeyboardInterrupt``)."""
        caught, self.caught = self.caught, []
        for signum, frame in caught:
            if callable(self.handler):
                self.handler(signum, frame)


@contextmanager
def interrupts_deferred():
    """Hold back Ctrl-C (SIGINT) in the block, to hand it on where it can be handled.

    Between starting a compiler in a session of its own and registering it, an interrupt would leave it
    running unseen (the terminal's Ctrl-C does not reach it). Only the main thread receives Python's
    signals; elsewhere nothing is held back. A block that fails while a Ctrl-C is held ends in that
    Ctrl-C (the interrupt wins over the error).

    Yields
    ------
    pending
        ``pending.deliver()`` runs the handler that was in place for each Ctrl-C held back (the
        default one raises ``KeyboardInterrupt``); ``pending.caught`` lists them.

    Examples
    --------
    >>> with interrupts_deferred() as pending:
    ...     started = "the work that must not be cut in two"
    >>> pending.deliver()          # nothing was held back: nothing happens
    """
    pending = _Deferred()
    if threading.current_thread() is not threading.main_thread():
        yield pending
        return
    try:
        pending.handler = signal.signal(signal.SIGINT, pending)
    except (ValueError, OSError):           # no handler can be set here (an embedded interpreter)
        yield pending
        return
    try:
        yield pending
    except BaseException:               # the block failed: its error goes on, unless a Ctrl-C came meanwhile
        signal.signal(signal.SIGINT, pending.handler)
        pending.deliver()
        raise
    signal.signal(signal.SIGINT, pending.handler)


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


def _fresh_after_fork() -> None:
    """A forked child runs none of its parent's compilers and is not ending."""
    global _STATE_LOCK
    _STATE_LOCK = threading.Lock()
    _RUNNING.clear()
    _BUILDING.clear()
    _STATE["stopping"] = False


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_fresh_after_fork)
