"""Compiling CasADi Functions to C, with an on-disk cache: the one compile path of casship.

:func:`compile_function` generates C code for a ``casadi.Function``, compiles it into a shared
library with the system C compiler (:mod:`._compiler`) and loads it back through CasADi's
``external`` route. The library is kept in a cache folder under a key made of the Function's
serialised form, the compiler (its path and version), the compiler flags and the CasADi version,
so a second process that needs the same Function loads it in milliseconds instead of compiling it
again.

Where the cache lives
    ``cache_dir=`` argument, else the environment variable ``CASSHIP_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/casship`` (``~/.cache/casship`` when unset; ``%LOCALAPPDATA%\\casship`` on
    Windows), always as an absolute path. ``CASSHIP_CACHE_DIR=off`` (or ``cache=False``) compiles
    into a private temporary folder and keeps nothing.

Whose code is loaded
    A cache folder is created with mode 0700. Loading a library runs its code, so a folder owned
    by another user, or one that others may write into (group or world writable), is refused: one
    warning, and the process compiles into private temporary folders instead (POSIX; Windows has
    no such owner check). Each library and record must also belong to the user and be writable by
    nobody else, and a library is loaded only when its size and SHA-256 checksum match its record
    and its inputs and outputs match the Function's; anything else is rebuilt, never loaded.

Failures
    Any file-system error in the cache (a read-only folder, a full disk) means "no cache": one
    warning per folder, then private temporary folders. Concurrent compiles of one key, in threads
    or processes, take a lock file per key; the library and its record are written under temporary
    names and renamed into place, so nobody sees half a file.
"""
from __future__ import annotations

import ctypes
import hashlib
import json
import os
import platform
import shutil
import stat
import sys
import tempfile
import threading
import time
import warnings
import weakref
from contextlib import contextmanager
from pathlib import Path
from typing import Sequence

import casadi as ca

from ._compiler import SUFFIX, CompileError, build_library, building, find_compiler
from ._settings import ENV_CACHE, chosen_flags, compile_timeout
from ..errors import InputError, InputTypeError

try:                                    # file locks: fcntl on POSIX, msvcrt on Windows
    import fcntl
except ImportError:                     # pragma: no cover - Windows
    fcntl = None
try:
    import msvcrt
except ImportError:
    msvcrt = None

__all__ = ["compile_function", "cached_function", "cache_dir", "cache_key", "remove_leftovers"]

_ENV_DIR = ENV_CACHE
BUILD_PREFIX = "casship-cc-"                      # build folders: casship-cc-<key>-<pid> (leftovers of a killed process)
_OFF = ("off", "0", "no", "false", "none")
# compiled Functions loaded by this process, by (key, folder); weak: a Function nobody uses is let go
LOADED: "weakref.WeakValueDictionary[tuple, ca.Function]" = weakref.WeakValueDictionary()
_LIBRARY_OF: dict[tuple, Path] = {}        # the library file of each of them
_LIBRARIES: dict[str, ctypes.CDLL] = {}     # ctypes handles of libraries with extra source (never closed)
REFUSED: dict[Path, str] = {}              # folders not used by this process, and why (warned once)
_SWEPT: set = set()                         # folders whose leftovers this process has removed
PROCESS_LOCK = threading.RLock()


def _new_lock_after_fork() -> None:
    """A forked child gets a lock of its own: one held by a compiling thread of the parent would
    never be released there (that thread does not exist in the child)."""
    global PROCESS_LOCK
    PROCESS_LOCK = threading.RLock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_new_lock_after_fork)


# -- where ----------------------------------------------------------------------------------------------
def cache_dir(path: str | os.PathLike | None = None) -> Path | None:
    """The cache folder: ``path``, else ``$CASSHIP_CACHE_DIR``, else the user cache folder (absolute).

    Parameters
    ----------
    path : str or path, optional
        An explicit folder (wins over the environment).

    Returns
    -------
    Path or None
        The folder (not created here), or ``None`` when caching is switched off
        (``CASSHIP_CACHE_DIR=off``).

    Examples
    --------
    >>> cache_dir("/tmp/my-cache")
    PosixPath('/tmp/my-cache')
    """
    if path is None:
        env = os.environ.get(_ENV_DIR)
        if env is not None and env.strip():
            if env.strip().lower() in _OFF:
                return None
            path = env
        elif sys.platform == "win32":
            path = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local") / "casship"
        else:
            path = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "casship"
    return Path(path).expanduser().absolute()      # a library is loaded by its absolute path


def _not_private(st: os.stat_result) -> str | None:
    """Why a file or folder with status ``st`` may hold code written by someone else, or None."""
    if not hasattr(os, "geteuid"):      # Windows: no owner check
        return None
    if st.st_uid != os.geteuid():
        return f"it belongs to another user (uid {st.st_uid}; this process runs as uid {os.geteuid()})"
    if st.st_mode & (stat.S_IWGRP | stat.S_IWOTH):
        return f"other users may write into it (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def folder_problem(folder: Path, create: bool) -> str | None:
    """Why ``folder`` cannot hold the cache (created with mode 0700 if asked), or None."""
    try:
        if create:
            folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = folder.stat()
    except FileNotFoundError:
        return None if not create else "it cannot be created"
    except OSError as exc:
        return f"it cannot be {'created or ' * create}read ({exc.strerror or exc})"
    if not stat.S_ISDIR(st.st_mode):
        return "it is not a folder"
    return _not_private(st)


def _refuse(folder: Path, why: str) -> None:
    """Stop using ``folder`` in this process, with one warning."""
    if folder not in REFUSED:
        REFUSED[folder] = why
        warnings.warn(f"casship compile cache {folder} is not used: {why}; compiled code goes to private "
                      f"temporary folders and is not kept (use a folder of your own with mode 700, e.g. "
                      f"chmod 700 it if it is yours, or set {_ENV_DIR})", RuntimeWarning, stacklevel=4)


def _usable_folder(path) -> Path | None:
    """The cache folder to use now (created if needed), or None: caching off, or the folder refused."""
    folder = cache_dir(path)
    if folder is None or folder in REFUSED:
        return None
    why = folder_problem(folder, create=True)
    if why is not None:
        _refuse(folder, why)
        return None
    if folder not in _SWEPT:
        _SWEPT.add(folder)
        remove_leftovers(folder)
    return folder


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (a process of another user counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, OSError):
        return True
    return True


def build_owner(name: str) -> tuple[str, int] | None:
    """``(key, pid)`` of a build folder named ``casship-cc-<key>-<pid>``, else None."""
    parts = name[len(BUILD_PREFIX):].split("-") if name.startswith(BUILD_PREFIX) else []
    if len(parts) != 2 or not is_key(parts[0]) or not parts[1].isdigit():
        return None
    return parts[0], int(parts[1])


def remove_leftovers(folder: Path) -> int:
    """Remove the build folders of processes that ended without removing them (killed); returns how many."""
    removed = 0
    try:
        entries = list(folder.iterdir())
    except OSError:
        return 0
    for f in entries:
        owner = build_owner(f.name)
        if owner is not None and f.is_dir() and not _alive(owner[1]):
            shutil.rmtree(f, ignore_errors=True)
            removed += 1
    return removed


# -- keys and integrity ------------------------------------------------------------------------------------
def cache_key(fun: ca.Function, compiler: tuple[str, str], flags: Sequence[str], extra_source: str = "") -> str:
    """The cache key of ``fun`` compiled by ``compiler`` (path, version) with ``flags``.

    A SHA-256 over the Function's serialised form, the compiler, the flags, CasADi's version and
    the platform (with ``-march=native``-like flags also the CPU model and features), and any C
    source compiled with it.
    """
    h = hashlib.sha256()
    cpu = _cpu() if any("native" in f for f in flags) else ""   # code for this CPU only
    for part in ("casship-compile-1", ca.__version__, sys.platform, platform.machine(), cpu, compiler[0],
                 compiler[1], *flags, "--"):
        h.update(part.encode())
        h.update(b"\0")
    h.update(fun.serialize().encode())
    if extra_source:
        h.update(b"\0extra\0" + extra_source.encode())
    return h.hexdigest()[:40]


def _cpu() -> str:
    """The CPU model and feature flags (for keys of code compiled with ``-march=native``)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return platform.processor()
    wanted = [line for line in text.splitlines() if line.startswith(("model name", "flags", "Features"))]
    return "\n".join(dict.fromkeys(wanted))


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _same_signature(a: ca.Function, b: ca.Function) -> bool:
    if a.n_in() != b.n_in() or a.n_out() != b.n_out():
        return False
    if list(a.name_in()) != list(b.name_in()) or list(a.name_out()) != list(b.name_out()):
        return False
    return (all(a.sparsity_in(i) == b.sparsity_in(i) for i in range(a.n_in()))
            and all(a.sparsity_out(i) == b.sparsity_out(i) for i in range(a.n_out())))


def _verified(lib: Path, record: Path) -> bool:
    """Whether the library and its record are the user's alone and the library matches the record."""
    try:
        if _not_private(lib.stat()) or _not_private(record.stat()):
            return False
        meta = json.loads(record.read_text())
        return lib.stat().st_size == meta["bytes"] and _sha256(lib) == meta["sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return False


def _entry(folder: Path, key: str) -> tuple[Path, Path]:
    return folder / f"{key}{SUFFIX}", folder / f"{key}.json"


# -- load ------------------------------------------------------------------------------------------------------
def _load(fun: ca.Function, lib: Path) -> ca.Function | None:
    """The Function loaded from ``lib``, or None if it does not load or differs from ``fun``."""
    try:
        loaded = ca.external(fun.name(), str(lib))
    except (RuntimeError, OSError):
        return None
    return loaded if _same_signature(fun, loaded) else None


def _library(lib: Path) -> ctypes.CDLL:
    """A ctypes handle of a loaded library (for the functions of its extra source)."""
    handle = _LIBRARIES.get(str(lib))
    if handle is None:
        handle = _LIBRARIES[str(lib)] = ctypes.CDLL(str(lib))
    return handle


def _from_cache(fun, folder: Path, key: str, clean: bool) -> tuple | None:
    """``(Function, library path)`` of a verified cache entry, or None; ``clean`` (under the key's
    lock) deletes a damaged or foreign entry so that it is rebuilt."""
    lib, record = _entry(folder, key)
    if not lib.exists() and not record.exists():
        return None
    loaded = _load(fun, lib) if _verified(lib, record) else None
    if loaded is not None:
        return loaded, lib
    if clean:
        for p in (lib, record):
            p.unlink(missing_ok=True)
    return None


@contextmanager
def _key_lock(folder: Path, key: str):
    """Hold the lock file of ``key`` (waits at most the compile time limit, then raises OSError)."""
    fd = os.open(folder / f"{key}.lock", os.O_RDWR | os.O_CREAT, 0o600)   # kept: see clear_cache
    deadline = time.monotonic() + compile_timeout() + 30.0
    try:
        while True:
            try:
                if fcntl is not None:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                elif msvcrt is not None:    # pragma: no cover - Windows
                    msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise OSError(f"another process has held the lock of {key} for too long") from None
                time.sleep(0.05)
        yield
    finally:
        os.close(fd)                        # closing releases the lock


# -- compile ---------------------------------------------------------------------------------------------------
def compile_function(fun: ca.Function, *, flags: Sequence[str] | str | None = None, compiler: str | None = None,
                     cache_dir: str | os.PathLike | None = None, cache: bool = True, extra_source: str = "",
                     library: bool = False):
    """``fun`` compiled to a shared library and loaded (``casadi.external``), cached on disk.

    Parameters
    ----------
    fun : casadi.Function
        Any Function CasADi can generate C code for (SX or MX, with maps and folds).
    flags : sequence of str or str, optional
        Compiler flags (default: ``$CASSHIP_CFLAGS``, else :data:`DEFAULT_FLAGS`, which keep the
        interpreted numbers to the last bit; :data:`NATIVE_FLAGS` is the opt-in for speed);
        ``-fPIC -shared`` are always added. Part of the cache key.
    compiler : str, optional
        The C compiler (default: ``$CC``, else ``gcc``, else ``cc``). Part of the cache key.
    cache_dir : str or path, optional
        The cache folder (default: see :func:`cache_dir`).
    cache : bool
        ``False``: compile in a private temporary folder, keep nothing on disk.
    extra_source : str
        C source compiled into the same library after ``fun``'s generated code (e.g. the record
        loop of :class:`NativeFold`). Part of the cache key.
    library : bool
        Also return the library as a ``ctypes.CDLL``, for calling ``extra_source``'s functions
        (only with ``extra_source``).

    Returns
    -------
    casadi.Function, or (casadi.Function, ctypes.CDLL) with ``library=True``
        The compiled Function, with the same name, inputs, outputs and values as ``fun``.

    Raises
    ------
    CompileError
        Naming the Function when no C compiler is found, compiling fails or takes longer than
        ``$CASSHIP_COMPILE_TIMEOUT`` seconds.

    Examples
    --------
    >>> import casadi as ca
    >>> x = ca.SX.sym("x", 2)
    >>> f = compile_function(ca.Function("twice", [x], [2 * x], ["x"], ["y"]))  # doctest: +SKIP
    >>> f(x=[1, 2])["y"]                                                        # doctest: +SKIP
    DM([2, 4])
    """
    if not isinstance(fun, ca.Function):
        raise InputTypeError(f"compile_function needs a casadi.Function, got {type(fun).__name__}")
    if library and not extra_source:
        raise InputError("compile_function: library=True is for calling extra_source; none given")
    try:
        cc = find_compiler(compiler)
    except CompileError as exc:
        raise CompileError(f"compiling {fun.name()!r} to C: {exc}") from None
    flags = chosen_flags(flags)
    with PROCESS_LOCK:
        folder = _usable_folder(cache_dir) if cache else None
        loaded, lib = _compiled(fun, cc, flags, folder, extra_source)
    if lib is None:         # not under the process lock: other threads look up and load meanwhile
        loaded, lib = _compile(fun, cc, flags, folder, extra_source)
    return (loaded, _library(lib)) if library else loaded


def cached_function(fun: ca.Function, *, flags: Sequence[str] | str | None = None, extra_source: str = "",
                    library: bool = False):
    """``fun`` compiled, if this process or the cache already holds its library; else None, at once.

    Never compiles and never waits for a compile running in another thread (then None).

    Parameters
    ----------
    fun : casadi.Function
    flags, extra_source, library
        As for :func:`compile_function`.
    """
    try:
        cc = find_compiler(None)
    except CompileError:
        return None
    flags = chosen_flags(flags)
    if not PROCESS_LOCK.acquire(blocking=False):
        return None
    try:
        loaded, lib = _compiled(fun, cc, flags, _usable_folder(None), extra_source)
    finally:
        PROCESS_LOCK.release()
    if loaded is None:
        return None
    return (loaded, _library(lib)) if library else loaded


def _compiled(fun, cc, flags, folder, extra_source) -> tuple:
    """``(Function, library path)`` already loaded by this process or in the cache, else ``(None, None)``."""
    key = cache_key(fun, cc, flags, extra_source)
    loaded = LOADED.get((key, folder))
    if loaded is not None:
        return loaded, _LIBRARY_OF[key, folder]
    if folder is not None:
        try:
            hit = _from_cache(fun, folder, key, clean=False)
        except OSError as exc:
            _refuse(folder, f"reading it failed ({exc})")
            hit = None
        if hit is not None:
            return _remember(hit, key, folder)
    return None, None


def _remember(hit: tuple, key: str, folder) -> tuple:
    loaded, lib = hit
    with PROCESS_LOCK:
        LOADED[key, folder], _LIBRARY_OF[key, folder] = loaded, lib
    return loaded, lib


def _compile(fun, cc, flags, folder, extra_source) -> tuple:
    """Compile into the cache folder (under the key's lock), or a private temporary folder."""
    key = cache_key(fun, cc, flags, extra_source)
    if folder is not None:
        try:
            with _key_lock(folder, key):
                hit = _from_cache(fun, folder, key, clean=True)  # another process may have built it meanwhile
                if hit is None:
                    hit = _compile_into(fun, folder, key, cc, flags, extra_source)
            return _remember(hit, key, folder)
        except OSError as exc:                  # read-only, full, or locked too long
            _refuse(folder, f"writing into it failed ({exc})")
    with tempfile.TemporaryDirectory(prefix=BUILD_PREFIX, ignore_cleanup_errors=True) as tmp, building(tmp):
        lib = build_library(fun, Path(tmp), f"f{key[:16]}", cc[0], flags, extra_source)
        loaded = _load(fun, lib)
        if loaded is None:
            raise CompileError(f"the compiled library of {fun.name()!r} could not be loaded")
        if extra_source:
            _library(lib)                   # opened while the file exists
        return _remember((loaded, lib), key, None)


def _compile_into(fun, folder: Path, key: str, cc: tuple[str, str], flags, extra_source: str) -> tuple:
    t0 = time.perf_counter()
    tmp = folder / f"{BUILD_PREFIX}{key}-{os.getpid()}"       # named by key and process: see remove_leftovers
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(mode=0o700)
    try:
        with building(tmp):
            return _build_into(fun, folder, key, cc, flags, extra_source, tmp, t0)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _build_into(fun, folder: Path, key: str, cc, flags, extra_source: str, tmp: Path, t0: float) -> tuple:
    built = build_library(fun, Path(tmp), f"f{key[:16]}", cc[0], flags, extra_source)
    meta = {"key": key, "function": fun.name(), "bytes": built.stat().st_size, "sha256": _sha256(built),
            "compiler": cc[0], "compiler_version": cc[1], "flags": list(flags), "casadi": ca.__version__,
            "created": time.strftime("%Y-%m-%dT%H:%M:%S"), "compile_s": round(time.perf_counter() - t0, 3)}
    tmp_record = Path(tmp) / "record.json"
    tmp_record.write_text(json.dumps(meta, indent=1))
    os.chmod(tmp_record, 0o600)
    lib, record = _entry(folder, key)
    os.replace(built, lib)                  # library first: a record always describes a whole file
    os.replace(tmp_record, record)
    loaded = _load(fun, lib) if _verified(lib, record) else None
    if loaded is None:
        raise CompileError(f"the compiled library of {fun.name()!r} in {folder} could not be loaded")
    return loaded, lib


def is_key(stem: str) -> bool:
    return len(stem) == 40 and all(c in "0123456789abcdef" for c in stem)
