"""Compiling CasADi Functions to C, with an on-disk cache: the one compile path of casship.

:func:`compile_function` generates C code for a ``casadi.Function``, compiles it into a shared
library with the system C compiler and loads it back through CasADi's ``external`` route. The
library is kept in a cache directory under a key made of the Function's serialised form, the
compiler (its path and version), the compiler flags and the CasADi version, so a second process
that needs the same Function loads it in milliseconds instead of compiling it again.

Where the cache lives
    ``cache_dir=`` argument, else the environment variable ``CASSHIP_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/casship`` (``~/.cache/casship`` when unset; ``%LOCALAPPDATA%\\casship`` on
    Windows). ``CASSHIP_CACHE_DIR=off`` (or ``cache=False``) compiles into a temporary folder and
    keeps nothing.

Integrity
    Every library is written beside a small JSON record with its size and SHA-256 checksum, both
    written to temporary names and renamed into place, so concurrent processes never see half a
    file. Before a cached library is loaded its checksum is verified; a truncated or altered file,
    a missing record or a library whose inputs and outputs differ from the Function's is rebuilt,
    never loaded.

The compiler is ``$CC`` if set, else ``gcc``, else ``cc``; the flags are :data:`DEFAULT_FLAGS`
(chosen by measurement, see ``docs/benchmarks.md``) unless ``flags=`` or ``CASSHIP_CFLAGS`` says
otherwise. A compiler that refuses the default ``-march=native`` gets :data:`PORTABLE_FLAGS`. ``casship cache info`` and ``casship cache clear`` show and empty the cache.
"""
from __future__ import annotations

import ctypes
import hashlib
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import casadi as ca

from .progress import activity

__all__ = ["compile_function", "cache_dir", "cache_info", "clear_cache", "CacheInfo", "DEFAULT_FLAGS", "PORTABLE_FLAGS",
           "find_compiler"]

DEFAULT_FLAGS = ("-O3", "-fno-math-errno", "-march=native")
"""Compiler flags used unless told otherwise, chosen by measurement (``benchmarks/bench_compile.py``,
``docs/benchmarks.md``): ``-O3`` runs the filter folds about 1.3 times faster than ``-O2`` at the same
compile time; ``-fno-math-errno`` lets ``sqrt`` and friends compile to single instructions (only
``errno`` is not set); ``-march=native`` uses the instructions of this CPU (fused multiply-add among
them, so results differ from the interpreted step in the last bits) and makes the filter and
smoother loops 10-17 % faster. Code compiled for one CPU is never loaded on another: the cache key
then includes the CPU model and features."""

PORTABLE_FLAGS = ("-O3", "-fno-math-errno")
"""The default flags without ``-march=native``, for compilers that do not accept it."""

_ENV_DIR, _ENV_FLAGS = "CASSHIP_CACHE_DIR", "CASSHIP_CFLAGS"
_OFF = ("off", "0", "no", "false", "none")
_SUFFIX = {"win32": ".dll", "darwin": ".dylib"}.get(sys.platform, ".so")
_LOADED: dict[tuple, tuple] = {}         # (key, folder) -> (loaded Function, ctypes library or None), this process
_COMPILERS: dict[str, tuple[str, str]] = {}
_NO_NATIVE: set[tuple[str, str]] = set()   # compilers that refused -march=native in this process
_LOCK = threading.Lock()


# -- where and with what ------------------------------------------------------------------------------
def cache_dir(path: str | os.PathLike | None = None) -> Path | None:
    """The cache directory: ``path``, else ``$CASSHIP_CACHE_DIR``, else the user cache directory.

    Parameters
    ----------
    path : str or path, optional
        An explicit directory (wins over the environment).

    Returns
    -------
    Path or None
        The directory (not created here), or ``None`` when caching is switched off
        (``CASSHIP_CACHE_DIR=off``).

    Examples
    --------
    >>> cache_dir("/tmp/my-cache")
    PosixPath('/tmp/my-cache')
    """
    if path is not None:
        return Path(path).expanduser()
    env = os.environ.get(_ENV_DIR)
    if env is not None and env.strip():
        return None if env.strip().lower() in _OFF else Path(env).expanduser()
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or str(Path.home() / "AppData" / "Local")
        return Path(base) / "casship"
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "casship"


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
    RuntimeError
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
                version = (out.stdout or out.stderr).strip().splitlines()[0] if (out.stdout or out.stderr) else ""
            except (OSError, subprocess.SubprocessError):
                version = ""
            _COMPILERS[name] = (path, version)
            return path, version
    from .errors import SetupError

    raise SetupError(f"no C compiler found (tried {names}); install gcc or clang, or set CC")


def _flags(flags: Sequence[str] | str | None) -> tuple[str, ...]:
    if flags is None:
        env = os.environ.get(_ENV_FLAGS)
        return tuple(shlex.split(env)) if env and env.strip() else DEFAULT_FLAGS
    if isinstance(flags, str):
        return tuple(shlex.split(flags))
    flags = tuple(flags)
    bad = [f for f in flags if not isinstance(f, str)]
    if bad:
        raise TypeError(f"compiler flags must be strings, got {bad}")
    return flags


def cache_key(fun: ca.Function, compiler: tuple[str, str], flags: Sequence[str], extra_source: str = "") -> str:
    """The cache key of ``fun`` compiled by ``compiler`` (path, version) with ``flags``: a SHA-256
    over the Function's serialised form, the compiler, the flags, CasADi's version and the platform
    (with ``-march=native``-like flags also the CPU model and features), and any C source compiled
    with it."""
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


# -- integrity ------------------------------------------------------------------------------------------
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


def _verified(lib: Path, record: Path) -> dict | None:
    """The entry's record if the library exists and matches its recorded size and checksum, else None."""
    try:
        meta = json.loads(record.read_text())
        if lib.stat().st_size != meta["bytes"] or _sha256(lib) != meta["sha256"]:
            return None
        return meta
    except (OSError, ValueError, KeyError, TypeError):
        return None


# -- compile and load ---------------------------------------------------------------------------------
def _build(fun: ca.Function, name: str, folder: Path, stem: str, compiler: str, flags: Sequence[str],
           extra_source: str = "") -> Path:
    """Generate ``fun`` as C in ``folder`` (followed by ``extra_source``) and compile it to the shared
    library ``stem + suffix``."""
    src = folder / f"{stem}.c"
    gen = ca.CodeGenerator(f"{stem}.c", {"with_header": False})
    gen.add(fun)
    src.write_text(gen.dump() + extra_source)
    lib = folder / f"{stem}{_SUFFIX}"
    cmd = [compiler, *flags, "-fPIC", "-shared", str(src), "-o", str(lib), "-lm"]
    try:
        with activity(f"casship: compiling {name} to C (once; then kept in the cache)"):
            out = subprocess.run(cmd, capture_output=True, text=True)
    finally:
        src.unlink(missing_ok=True)
    if out.returncode != 0 or not lib.is_file():
        msg = (out.stderr or out.stdout).strip().splitlines()
        raise RuntimeError(f"compiling {name!r} to C failed ({' '.join(cmd[:1 + len(flags)])} ...): "
                           f"{msg[-1] if msg else f'exit status {out.returncode}'}")
    return lib


def _load(fun: ca.Function, lib: Path, handle: bool) -> tuple | None:
    """``(Function, ctypes library if handle else None)`` loaded from ``lib``, or None if it does not load
    or differs from ``fun``. A ctypes handle is never closed, so it is opened only when asked for
    (libraries with extra source) and only once the library is known to be the right one."""
    try:
        loaded = ca.external(fun.name(), str(lib))
        if not _same_signature(fun, loaded):
            return None
        return loaded, ctypes.CDLL(str(lib)) if handle else None
    except (RuntimeError, OSError):
        return None


def compile_function(fun: ca.Function, *, flags: Sequence[str] | str | None = None, compiler: str | None = None,
                     cache_dir: str | os.PathLike | None = None, cache: bool = True, extra_source: str = "",
                     library: bool = False, include_dirs: Sequence[str] = ()):
    """``fun`` compiled to a shared library and loaded (``casadi.external``), cached on disk.

    Parameters
    ----------
    fun : casadi.Function
        Any Function CasADi can generate C code for (SX or MX, with maps and folds).
    flags : sequence of str or str, optional
        Compiler flags (default: ``$CASSHIP_CFLAGS`` or :data:`DEFAULT_FLAGS`); ``-fPIC -shared``
        are always added. Part of the cache key.
    compiler : str, optional
        The C compiler (default: ``$CC``, else ``gcc``, else ``cc``). Part of the cache key.
    cache_dir : str or path, optional
        The cache directory (default: see :func:`cache_dir`).
    cache : bool
        ``False``: compile in a temporary folder, keep nothing on disk.
    extra_source : str
        C source compiled into the same library after ``fun``'s generated code (e.g. a driver
        that calls it in a loop, see :mod:`casship.native_fold`). Part of the cache key.
    library : bool
        Also return the library as a ``ctypes.CDLL``, for calling ``extra_source``'s functions
        (only with ``extra_source``).
    include_dirs : sequence of str
        Header folders for ``extra_source`` (``-I``, after the flags). Part of the cache key.

    Returns
    -------
    casadi.Function, or (casadi.Function, ctypes.CDLL) with ``library=True``
        The compiled Function, with the same name, inputs, outputs and values as ``fun``.

    Raises
    ------
    RuntimeError
        Naming the Function when no C compiler is found or compilation fails.

    Examples
    --------
    >>> import casadi as ca
    >>> x = ca.SX.sym("x", 2)
    >>> f = compile_function(ca.Function("twice", [x], [2 * x], ["x"], ["y"]))  # doctest: +SKIP
    >>> f(x=[1, 2])["y"]                                                        # doctest: +SKIP
    DM([2, 4])
    """
    if not isinstance(fun, ca.Function):
        raise TypeError(f"compile_function needs a casadi.Function, got {type(fun).__name__}")
    try:
        cc = find_compiler(compiler)
    except RuntimeError as exc:
        raise RuntimeError(f"compiling {fun.name()!r} to C: {exc}") from None
    if library and not extra_source:
        raise ValueError("compile_function: library=True is for calling extra_source; none given")
    flags = _flags(flags)
    if flags == DEFAULT_FLAGS and cc in _NO_NATIVE:
        flags = PORTABLE_FLAGS
    includes = tuple(f"-I{d}" for d in include_dirs)
    folder = _cache_folder(cache_dir) if cache else None
    try:
        loaded = _compiled(fun, cc, (*flags, *includes), folder, extra_source)
    except RuntimeError:
        if flags != DEFAULT_FLAGS:
            raise
        loaded = _compiled(fun, cc, (*PORTABLE_FLAGS, *includes), folder, extra_source)
        _NO_NATIVE.add(cc)                  # this compiler refuses -march=native: the portable flags
    return loaded if library else loaded[0]


def _compiled(fun, cc, flags, folder, extra_source: str) -> tuple:
    """``(Function, library or None)`` from this process, the cache or a fresh compile."""
    key = cache_key(fun, cc, flags, extra_source)
    with _LOCK:
        loaded = _LOADED.get((key, folder))
        if loaded is None:
            loaded = _from_cache(fun, folder, key, bool(extra_source)) if folder is not None else None
            if loaded is None:
                loaded = _compile_into(fun, folder, key, cc, flags, extra_source)
            _LOADED[key, folder] = loaded
    return loaded


def _cache_folder(path) -> Path | None:
    folder = cache_dir(path)
    if folder is None:
        return None
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        warnings.warn(f"casship compile cache {folder} is not usable ({exc}); compiling without a cache",
                      RuntimeWarning, stacklevel=3)
        return None
    return folder


def _from_cache(fun, folder: Path, key: str, handle: bool = False) -> tuple | None:
    lib, record = folder / f"{key}{_SUFFIX}", folder / f"{key}.json"
    if not lib.exists() and not record.exists():
        return None
    if _verified(lib, record) is not None:
        loaded = _load(fun, lib, handle)
        if loaded is not None:
            return loaded
    for p in (lib, record):                     # corrupted or foreign: rebuilt by the caller
        try:
            p.unlink()
        except OSError:
            pass
    return None


def _compile_into(fun, folder: Path | None, key: str, cc: tuple[str, str], flags, extra_source: str) -> tuple:
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="casship-cc-", dir=folder, ignore_cleanup_errors=True) as tmp:
        stem = f"f{key[:16]}"
        built = _build(fun, fun.name(), Path(tmp), stem, cc[0], flags, extra_source)
        if folder is None:
            loaded = _load(fun, built, bool(extra_source))
            if loaded is None:
                raise RuntimeError(f"the compiled library of {fun.name()!r} could not be loaded")
            return loaded
        size, digest = built.stat().st_size, _sha256(built)
        lib, record = folder / f"{key}{_SUFFIX}", folder / f"{key}.json"
        meta = {"key": key, "function": fun.name(), "bytes": size, "sha256": digest, "compiler": cc[0],
                "compiler_version": cc[1], "flags": list(flags), "casadi": ca.__version__,
                "created": time.strftime("%Y-%m-%dT%H:%M:%S"), "compile_s": round(time.perf_counter() - t0, 3)}
        tmp_record = Path(tmp) / "record.json"
        tmp_record.write_text(json.dumps(meta, indent=1))
        os.replace(built, lib)                  # library first: a record always describes a whole file
        os.replace(tmp_record, record)
    loaded = _load(fun, lib, bool(extra_source)) if _verified(lib, record) else None
    if loaded is None:
        raise RuntimeError(f"the compiled library of {fun.name()!r} in {folder} could not be loaded")
    return loaded


# -- the cache as a whole -------------------------------------------------------------------------------
@dataclass(frozen=True)
class CacheInfo:
    """What the compile cache holds.

    Parameters
    ----------
    path : Path or None
        The directory (``None``: caching switched off).
    entries : int
        Compiled libraries with their records.
    bytes : int
        Disk space of the directory's files.
    functions : dict
        Function name -> number of entries.
    """

    path: Path | None
    entries: int
    bytes: int
    functions: dict

    def summary(self) -> str:
        """A few lines for people."""
        if self.path is None:
            return f"compile cache: off ({_ENV_DIR}=off)"
        lines = [f"compile cache: {self.path}", f"entries: {self.entries}, {self.bytes / 1e6:.1f} MB",
                 f"default flags: {' '.join(_flags(None))}"]
        lines += [f"  {name}: {count}" for name, count in sorted(self.functions.items())]
        return "\n".join(lines)


def cache_info(path: str | os.PathLike | None = None) -> CacheInfo:
    """Entries and size of the compile cache.

    Parameters
    ----------
    path : str or path, optional
        The cache directory (default: see :func:`cache_dir`).

    Returns
    -------
    CacheInfo
    """
    folder = cache_dir(path)
    if folder is None:
        return CacheInfo(None, 0, 0, {})
    if not folder.is_dir():
        return CacheInfo(folder, 0, 0, {})
    functions: dict[str, int] = {}
    entries = size = 0
    for f in folder.iterdir():
        if f.is_file():
            size += f.stat().st_size
            if f.suffix == ".json":
                try:
                    name = json.loads(f.read_text())["function"]
                except (OSError, ValueError, KeyError, TypeError):
                    name = "(unreadable record)"
                functions[name] = functions.get(name, 0) + 1
                entries += 1
    return CacheInfo(folder, entries, size, functions)


def clear_cache(path: str | os.PathLike | None = None) -> int:
    """Delete every compiled library and record in the compile cache.

    Only files the cache writes (``<key>.so`` / ``.dylib`` / ``.dll``, ``<key>.json`` and left-over
    ``casship-cc-*`` build folders) are removed; anything else in the directory stays.

    Parameters
    ----------
    path : str or path, optional
        The cache directory (default: see :func:`cache_dir`).

    Returns
    -------
    int
        The number of files removed.
    """
    folder = cache_dir(path)
    if folder is None or not folder.is_dir():
        return 0
    removed = 0
    for f in folder.iterdir():
        if f.is_dir() and f.name.startswith("casship-cc-"):
            shutil.rmtree(f, ignore_errors=True)
            removed += 1
        elif f.is_file() and f.suffix in (".json", _SUFFIX) and _is_key(f.stem):
            f.unlink(missing_ok=True)
            removed += 1
    with _LOCK:
        _LOADED.clear()
    return removed


def _is_key(stem: str) -> bool:
    return len(stem) == 40 and all(c in "0123456789abcdef" for c in stem)
