"""JSON out: the one writer of casship's JSON answers and files (command line, fit files, reports).

Values are made JSON-ready by :func:`json_ready`: NumPy scalars and arrays become numbers and
lists, paths become text, complex numbers ``[real, imag]``, and non-finite floats the strings
``"nan"``, ``"inf"``, ``"-inf"`` (strict JSON has no NaN; the strings keep the three apart, and
:func:`float` reads them back).

Examples
--------
>>> import numpy as np
>>> from casship.io.jsonfile import dumps
>>> dumps({"x": np.float64(1.5), "v": np.array([1.0, np.nan])})
'{"x": 1.5, "v": [1.0, "nan"]}'
"""
from __future__ import annotations

import json
import math
from pathlib import Path, PurePath

__all__ = ["json_ready", "dumps", "write_json"]


def json_ready(value):
    """``value`` with every part JSON can hold (see the module notes).

    Parameters
    ----------
    value : object
        Dicts, lists, tuples, numbers, NumPy values, strings, paths, None.

    Returns
    -------
    object

    Raises
    ------
    TypeError
        A value of another type (naming it), rather than writing its ``repr``.
    """
    if isinstance(value, dict):
        return {str(k): json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):      # numpy scalars and arrays
        return json_ready(value.tolist())
    if isinstance(value, bool) or value is None or isinstance(value, (str, int)):
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else ("nan" if math.isnan(value) else ("inf" if value > 0 else "-inf"))
    if isinstance(value, complex):
        return [json_ready(value.real), json_ready(value.imag)]
    if isinstance(value, PurePath):
        return str(value)
    raise TypeError(f"cannot write a {type(value).__name__} as JSON: {value!r}")


def dumps(value, indent: int | None = None) -> str:
    """``value`` as JSON text (:func:`json_ready` first).

    Parameters
    ----------
    value : object
    indent : int, optional

    Returns
    -------
    str
    """
    return json.dumps(json_ready(value), indent=indent, allow_nan=False)


def write_json(path, value, *, overwrite: bool = True, what: str = "JSON file") -> Path:
    """Write ``value`` as indented JSON, atomically (:func:`casship.outdir.output_file`).

    Parameters
    ----------
    path : str or Path
    value : object
    overwrite : bool
        Replace an existing file.
    what : str
        Name of the file or option, for messages.

    Returns
    -------
    Path
    """
    from ..outdir import output_file

    text = dumps(value, indent=2)
    with output_file(path, overwrite=overwrite, what=what) as tmp:
        tmp.write_text(text)
    return Path(path)
