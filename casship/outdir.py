"""Output folders that never overwrite by surprise and never keep half a result.

:func:`output_folder` is the one way casship's commands write a folder of results (``casship study``,
and any command with ``--out``):

* a folder that exists and is not empty is refused unless ``overwrite=True`` (``--overwrite``);
* the work is written into a hidden staging folder beside the target and moved into place only
  when it succeeds, so a failed run leaves no half folder and an overwritten folder keeps no stale
  files from an earlier run (its old contents are removed just before the new ones move in).
"""
from __future__ import annotations

import os
import shutil
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

__all__ = ["output_folder"]

_PROTECTED = (".git", "pyproject.toml", "setup.py")


def _check_target(path: Path, overwrite: bool) -> None:
    if path.exists() and not path.is_dir():
        raise ValueError(f"output folder {str(path)!r} is a file, not a folder")
    if not path.is_dir() or not any(path.iterdir()):
        return
    if not overwrite:
        raise ValueError(f"output folder {str(path)!r} is not empty; choose another folder or pass "
                         "--overwrite to replace its contents")
    found = [name for name in _PROTECTED if (path / name).exists()]
    if found or path == Path.home().resolve() or path == Path(path.anchor):
        raise ValueError(f"refusing to overwrite {str(path)!r}: it looks like a project or home folder "
                         f"({', '.join(found) or 'home/root'})")


@contextmanager
def output_folder(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Write a folder of results safely: yields a staging folder, moved to ``path`` on success.

    Parameters
    ----------
    path : path
        The output folder. It may not exist yet; if it exists it must be empty unless ``overwrite``.
    overwrite : bool
        Replace the contents of a non-empty ``path`` (its old files are removed, none survive
        beside the new ones).

    Yields
    ------
    Path
        An empty staging folder beside ``path``; write everything there. When the block ends
        normally its contents become ``path``; when it raises, the staging folder is removed and
        ``path`` is left as it was.

    Raises
    ------
    ValueError
        ``path`` is a file, or a non-empty folder without ``overwrite``, or a project/home folder.

    Examples
    --------
    >>> from casship.outdir import output_folder
    >>> with output_folder(tmp / "run1") as out:          # doctest: +SKIP
    ...     (out / "report.md").write_text("# results")
    """
    target = Path(path).expanduser().resolve()
    _check_target(target, overwrite)
    target.parent.mkdir(parents=True, exist_ok=True)
    staging = target.parent / f".{target.name}.partial-{os.getpid()}"
    if staging.exists():
        shutil.rmtree(staging)
    staging.mkdir()
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    try:
        if target.exists():
            shutil.rmtree(target)
        staging.rename(target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
