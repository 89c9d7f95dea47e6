"""The compile cache as a whole: what it holds (:func:`cache_info`) and emptying it (:func:`clear_cache`),
leaving compiles in progress alone."""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from . import _cache as cache
from ._cache import BUILD_PREFIX, LOADED, REFUSED, build_owner, cache_dir, fcntl, folder_problem, is_key
from ._compiler import SUFFIX, CompileError, find_compiler
from ._settings import DEFAULT_FLAGS, ENV_CACHE, ENV_FLAGS, chosen_flags, compile_timeout

__all__ = ["CacheInfo", "cache_info", "Cleared", "clear_cache"]

_ENV_DIR = ENV_CACHE


# -- the cache as a whole ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CacheInfo:
    """What the compile cache holds and how compiled code runs here.

    Parameters
    ----------
    path : Path or None
        The folder (``None``: caching switched off).
    entries : int
        Compiled libraries with their records.
    bytes : int
        Disk space of the folder's files.
    functions : dict
        Function name -> number of entries.
    refused : str or None
        Why the folder is not used (then code is compiled into private temporary folders).
    compiler : str or None
        The C compiler and its version (``None``: none found, ``jit`` raises).
    flags : tuple of str
        The flags used by default here.
    flags_note : str
        Why those flags (the defaults or ``$CASSHIP_CFLAGS``).
    timeout : float
        Seconds a compiler run may take.
    paths : tuple of str
        How compiled code is called here (the online update, the record loop).
    """

    path: Path | None
    entries: int
    bytes: int
    functions: dict
    refused: str | None = None
    compiler: str | None = None
    flags: tuple = ()
    flags_note: str = ""
    timeout: float = 0.0
    paths: tuple = field(default=())

    def summary(self) -> str:
        """A few lines for people."""
        if self.path is None:
            lines = [f"compile cache: off ({_ENV_DIR}=off): compiled code goes to private temporary folders"]
        elif self.refused:
            lines = [f"compile cache: {self.path} is NOT USED: {self.refused}; compiled code goes to private "
                     "temporary folders (fix the folder or set CASSHIP_CACHE_DIR)"]
        else:
            lines = [f"compile cache: {self.path}", f"entries: {self.entries}, {self.bytes / 1e6:.1f} MB"]
        lines += [f"compiler: {self.compiler or 'none found (install gcc or clang, or set CC): option jit raises'}",
                  f"flags: {' '.join(self.flags)} ({self.flags_note})",
                  f"compile time limit: {self.timeout:g} s (CASSHIP_COMPILE_TIMEOUT)", *self.paths]
        lines += [f"  {name}: {count}" for name, count in sorted(self.functions.items())]
        return "\n".join(lines)


# How compiled code is called: the same on every platform, so no platform takes a slower path unsaid.
_PATHS = ("online update: one evaluation per sample of the step through CasADi's Function.buffer "
          "(compiled with option jit, else interpreted); the same on every platform",
          "record loop: with option jit one compiled C loop over the whole record, called through ctypes; "
          "else mapaccum folds in pieces")


def cache_info(path: str | os.PathLike | None = None) -> CacheInfo:
    """Entries and size of the compile cache, and how compiled code is built and called here.

    Parameters
    ----------
    path : str or path, optional
        The cache folder (default: see :func:`cache_dir`).

    Returns
    -------
    CacheInfo
    """
    folder = cache_dir(path)
    try:
        cc = find_compiler()
        compiler = f"{cc[0]} ({cc[1]})" if cc[1] else cc[0]
    except CompileError:
        cc = compiler = None
    flags = chosen_flags(None)
    note = ("the defaults: the interpreted numbers to the last bit" if flags == DEFAULT_FLAGS
            else f"from ${ENV_FLAGS}" + ("; -march=native: results differ from interpreted in the last bits"
                                         if any("native" in f for f in flags) else ""))
    common = {"compiler": compiler, "flags": flags, "flags_note": note, "timeout": compile_timeout(), "paths": _PATHS}
    if folder is None:
        return CacheInfo(None, 0, 0, {}, **common)
    refused = REFUSED.get(folder) or folder_problem(folder, create=False)
    if refused or not folder.is_dir():
        return CacheInfo(folder, 0, 0, {}, refused=refused, **common)
    functions: dict[str, int] = {}
    entries = size = 0
    try:
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
    except OSError as exc:
        return CacheInfo(folder, 0, 0, {}, refused=f"it cannot be read ({exc.strerror or exc})", **common)
    return CacheInfo(folder, entries, size, functions, **common)


class Cleared(int):
    """The number of files :func:`clear_cache` removed, with the keys it left alone (:attr:`busy`:
    compiles in progress in some process, whose files stay)."""

    busy: tuple = ()


def _busy(folder: Path, key: str) -> bool:
    """Whether some process (this one too) holds the lock of ``key``: a compile in progress."""
    lock = folder / f"{key}.lock"
    if fcntl is None or not lock.exists():
        return False
    try:
        fd = os.open(lock, os.O_RDWR)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)                        # closing releases the probe's lock
    return False


def clear_cache(path: str | os.PathLike | None = None) -> Cleared:
    """Delete every compiled library and record in the compile cache, except those being compiled now.

    Only files the cache writes (``<key>.so`` / ``.dylib`` / ``.dll``, ``<key>.json`` and build
    folders ``casship-cc-*``) are removed; anything else in the folder stays, and so do the empty
    lock files ``<key>.lock``. A key whose lock some process holds (a compile in progress, here or
    in another process) is left alone with its build folder, so that compile ends as it would have:
    its key is listed in the result's ``busy``. A refused folder (see :func:`cache_info`) is not touched.

    Parameters
    ----------
    path : str or path, optional
        The cache folder (default: see :func:`cache_dir`).

    Returns
    -------
    Cleared
        The number of files removed (an ``int``), with ``busy``: the keys left alone.
    """
    folder = cache_dir(path)
    if folder is None or not folder.is_dir() or folder_problem(folder, create=False):
        return Cleared(0)
    removed, busy = 0, {}
    with cache.PROCESS_LOCK:          # rebound in a forked child: read it here
        for f in sorted(folder.iterdir()):
            if f.is_dir() and f.name.startswith(BUILD_PREFIX):
                owner = build_owner(f.name)
                if owner is not None and _busy(folder, owner[0]):
                    busy[owner[0]] = True
                    continue
                shutil.rmtree(f, ignore_errors=True)
                removed += 1
            elif f.is_file() and f.suffix in (".json", SUFFIX) and is_key(f.stem):
                if _busy(folder, f.stem):
                    busy[f.stem] = True
                    continue
                f.unlink(missing_ok=True)
                removed += 1
        for k in [k for k in LOADED.keys() if k[1] == folder]:
            LOADED.pop(k, None)
    out = Cleared(removed)
    out.busy = tuple(busy)
    return out
