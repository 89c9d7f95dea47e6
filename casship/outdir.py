"""Output folders and files that are never overwritten by surprise.

One rule for every command that writes results (``casship demo``, ``casship study``,
``casship identify --out`` ...):

* an existing, non-empty folder (or an existing file) is refused unless the caller passes
  ``overwrite=True`` (the ``--overwrite`` flag);
* with ``overwrite=True`` the old folder is removed as a whole, so no stale file of an earlier run
  stays beside the new ones; only a folder written by casship (it holds the marker file
  :data:`MARKER`) or an empty one is ever removed;
* results are written into a temporary sibling folder (or file) that is renamed into place when
  the run succeeds, so a failed run leaves neither a half-written folder nor a damaged old one;
* the rename never replaces what appeared (or changed) at the path while the run was working: a
  new path is claimed without replacing (a hard link for files), an old one is compared with its
  :func:`stamp` taken when the run was checked. Then nothing is replaced, the new results stay in
  their temporary sibling, and the error names both.

Examples
--------
>>> import tempfile, pathlib
>>> from casship.outdir import output_folder
>>> root = pathlib.Path(tempfile.mkdtemp())
>>> with output_folder(root / "report") as folder:
...     _ = (folder / "report.md").write_text("# results")
>>> sorted(p.name for p in (root / "report").iterdir())
['.casship-output', 'report.md']
"""
from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

__all__ = ["output_folder", "output_file", "check_output_folder", "check_output_file", "stamp", "MARKER"]

#: Name of the marker file written into every output folder (it allows ``overwrite`` to clear it).
MARKER = ".casship-output"


def stamp(path) -> tuple | None:
    """What is at ``path`` now, to tell later whether it changed: None (nothing), a file's identity,
    size and modification time, or a folder's listing with those of every entry.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    tuple or None
    """
    path = Path(path)
    try:
        st = path.lstat()
    except FileNotFoundError:
        return None
    if not path.is_dir():
        return ("file", st.st_ino, st.st_size, st.st_mtime_ns)
    entries = []
    for sub in sorted(path.rglob("*")):
        try:
            s = sub.lstat()
        except FileNotFoundError:          # removed while listing: it changed
            continue
        entries.append((str(sub.relative_to(path)), s.st_ino, s.st_size, s.st_mtime_ns))
    return ("folder", st.st_ino, tuple(entries))


def _changed(path: Path, expect, what: str, kept: Path) -> FileExistsError:
    return FileExistsError(f"{what} {path}: it changed while casship was running (something else wrote there); "
                           f"nothing was replaced; the new results are in {kept}")


def _protected(path: Path) -> str | None:
    """Reason why ``path`` must never be removed (the working folder, an ancestor of it, home, root)."""
    resolved = path.resolve()
    cwd = Path.cwd().resolve()
    if resolved == cwd or resolved in cwd.parents:
        return "it is the working folder or contains it"
    if resolved == Path.home().resolve() or resolved.parent == resolved:
        return "it is the home or root folder"
    return None


def _check_writable(path: Path, what: str) -> None:
    """Raise ``PermissionError`` naming ``what`` if nothing can be created beside ``path`` (a
    read-only or special folder), before any work is done. The test is the honest one: a file is
    created there and removed (permission bits say nothing of a read-only mount or of root)."""
    import tempfile

    folder = path.absolute().parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent                  # an output folder's missing parents are made later
    try:
        fd, probe = tempfile.mkstemp(prefix=".casship-probe-", dir=folder)
    except OSError as exc:
        raise PermissionError(f"{what} {path}: cannot write into the folder {folder} ({exc.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def check_output_folder(path, *, overwrite: bool = False, what: str = "--out") -> Path:
    """Check that the report folder ``path`` may be written; raise with the reason if not.

    Parameters
    ----------
    path : str or Path
        The folder a run will write.
    overwrite : bool
        Allow replacing an existing non-empty folder (one written by casship, or empty).
    what : str
        Name of the option or argument, used in messages (e.g. ``"--out"``).

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    FileExistsError
        ``path`` is a non-empty folder and ``overwrite`` is false, or it is a file.
    PermissionError
        ``overwrite`` is true but the folder was not written by casship or is protected, or nothing
        can be written beside it.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise FileExistsError(f"{what} {path}: is a file, not a folder; choose a folder name")
    if path.is_dir() and any(path.iterdir()):
        if not overwrite:
            raise FileExistsError(f"{what} {path}: folder exists and is not empty; pass --overwrite to replace "
                                  "it (its files are removed first) or choose another folder")
        reason = _protected(path)
        if reason is None and not (path / MARKER).is_file():
            reason = f"it was not written by casship (no {MARKER} file in it)"
        if reason:
            raise PermissionError(f"{what} {path}: will not replace this folder: {reason}; choose another folder")
    _check_writable(path, what)
    return path


@contextmanager
def output_folder(path, *, overwrite: bool = False, what: str = "--out") -> Iterator[Path]:
    """Context manager yielding a temporary folder that replaces ``path`` when the block succeeds.

    Parameters
    ----------
    path : str or Path
        The report folder.
    overwrite : bool
        Replace an existing non-empty folder written by casship (see :func:`check_output_folder`).
    what : str
        Name of the option, used in messages.

    Yields
    ------
    Path
        A fresh, empty sibling folder of ``path`` to write into. On success it is renamed to ``path``
        (an old ``path`` is removed first); if the block raises, it is removed and ``path`` is left
        as it was.
    """
    path = check_output_folder(path, overwrite=overwrite, what=what)
    before = stamp(path)
    parent = path.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = parent / f".{path.name}.partial-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.mkdir()
    try:
        (tmp / MARKER).write_text("written by casship; 'casship ... --overwrite' may replace this folder\n")
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if stamp(path) != before:
        raise _changed(path, before, what, tmp)
    if before is not None:
        old = parent / f".{path.name}.old-{os.getpid()}"
        path.rename(old)              # the new folder takes its place before the old one is removed
        tmp.rename(path)
        shutil.rmtree(old, ignore_errors=True)
    else:
        try:
            tmp.rename(path)          # refused if a non-empty folder or a file appeared meanwhile
        except OSError:
            raise _changed(path, before, what, tmp) from None


def check_output_file(path, *, overwrite: bool = False, what: str = "--out") -> Path:
    """Check that the result file ``path`` may be written; raise with the reason if not.

    Parameters
    ----------
    path : str or Path
        The file a run will write.
    overwrite : bool
        Allow replacing an existing file.
    what : str
        Name of the option, used in messages.

    Returns
    -------
    Path

    Raises
    ------
    FileExistsError
        ``path`` exists and ``overwrite`` is false.
    IsADirectoryError
        ``path`` is a folder.
    FileNotFoundError
        The folder ``path`` would go into does not exist.
    PermissionError
        Nothing can be written into that folder.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{what} {path}: is a folder; give a file name")
    if path.exists() and not overwrite:
        raise FileExistsError(f"{what} {path}: file exists; pass --overwrite to replace it or choose another name")
    if not path.absolute().parent.is_dir():
        raise FileNotFoundError(f"{what} {path}: folder {path.absolute().parent} does not exist")
    _check_writable(path, what)
    return path


@contextmanager
def output_file(path, *, overwrite: bool = False, what: str = "--out", expect=False) -> Iterator[Path]:
    """Context manager yielding a temporary file name that replaces ``path`` when the block succeeds.

    Parameters
    ----------
    path : str or Path
        The result file.
    overwrite : bool
        Replace an existing file.
    what : str
        Name of the option, used in messages.
    expect : tuple or None, optional
        The :func:`stamp` of ``path`` when the caller checked it (default: now). If ``path`` differs
        from it at the end, nothing is replaced.

    Yields
    ------
    Path
        A temporary sibling name with the same suffix; on success it is moved to ``path``; if the
        block raises, it is removed and ``path`` is left as it was.

    Raises
    ------
    FileExistsError
        ``path`` appeared or changed while the block ran (the new file is kept under its temporary
        name, given in the message).
    """
    path = check_output_file(path, overwrite=overwrite, what=what)
    before = stamp(path) if expect is False else expect
    tmp = path.absolute().parent / f".{path.stem}.partial-{os.getpid()}{path.suffix}"
    try:
        yield tmp
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if not tmp.exists():
        raise FileNotFoundError(f"{what} {path}: nothing was written")
    if stamp(path) != before:
        raise _changed(path, before, what, tmp)
    if before is not None:
        os.replace(tmp, path)
        return
    try:
        os.link(tmp, path)            # claims the name only if it is still free
    except FileExistsError:
        raise _changed(path, before, what, tmp) from None
    except OSError:                   # no hard links here: the rename right after the check
        os.rename(tmp, path)
        return
    tmp.unlink()
