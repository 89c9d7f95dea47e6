"""Where the measured data live: one rule, used by the studies, the command line and the tests.

The measured records (MARIN and HSVA free-running runs, USV GNSS logs) are never part of the
package or the repository. They are found, in this order, in

1. the folder given explicitly (``casship study NAME --data DIR``, ``data_dir("DIR")``);
2. the folder named by the environment variable ``CASSHIP_DATA``;
3. ``../shared/data`` beside a source checkout of casship (the folder that holds ``casship/`` and
   ``pyproject.toml``); an installed wheel has no such place.

A folder named by 1 or 2 must exist (a typing error is reported, never passed over); when only
rule 3 applies and its folder is absent, there are no measured data.
"""
from __future__ import annotations

import os
from pathlib import Path

__all__ = ["data_dir", "DATA_ENV"]

#: Environment variable naming the measured-data folder.
DATA_ENV = "CASSHIP_DATA"


def _checkout_default() -> Path | None:
    """``../shared/data`` beside the source checkout this casship was imported from, if any."""
    root = Path(__file__).resolve().parents[2]
    if (root / "pyproject.toml").is_file() and (root / "casship" / "__init__.py").is_file():
        return root.parent / "shared" / "data"
    return None


def data_dir(explicit: str | os.PathLike | None = None, *, required: bool = False) -> Path | None:
    """The measured-data folder by casship's rule (explicit folder, ``$CASSHIP_DATA``, ``../shared/data``).

    Parameters
    ----------
    explicit : path, optional
        A folder given by the caller (the command line's ``--data DIR``); it wins over the others.
    required : bool
        Raise when no folder is found instead of returning None.

    Returns
    -------
    Path or None
        The folder (absolute), or None when neither an explicit folder nor ``CASSHIP_DATA`` is given
        and there is no ``../shared/data`` beside a source checkout.

    Raises
    ------
    FileNotFoundError
        When the explicit folder or ``CASSHIP_DATA`` names a folder that does not exist, or when
        ``required`` and no folder is found; the message names what was looked at.

    Examples
    --------
    >>> from casship.io import data_dir
    >>> folder = data_dir()              # None when there are no measured data here
    """
    if explicit is not None and str(explicit) != "":
        path = Path(explicit).expanduser().resolve()
        if not path.is_dir():
            raise FileNotFoundError(f"data folder {str(explicit)!r} does not exist (given explicitly, e.g. --data)")
        return path
    env = os.environ.get(DATA_ENV, "")
    if env:
        path = Path(env).expanduser().resolve()
        if not path.is_dir():
            raise FileNotFoundError(f"data folder {env!r} named by ${DATA_ENV} does not exist")
        return path
    default = _checkout_default()
    if default is not None and default.is_dir():
        return default.resolve()
    if required:
        where = f"; {default} (beside this checkout) is absent" if default is not None else ""
        raise FileNotFoundError(f"no measured-data folder: give --data DIR or set ${DATA_ENV}{where}")
    return None
