"""JSON out: the one writer of casship's JSON answers and files (command line, fit files, reports).

Values are made JSON-ready by :func:`json_ready`: NumPy scalars and arrays become numbers and
lists, paths become text, complex numbers ``[real, imag]``, other numbers (``__float__``) floats,
and non-finite floats the strings ``"nan"``, ``"inf"``, ``"-inf"`` (strict JSON has no NaN; the
strings keep the three apart, and :func:`float` reads them back). ``nonfinite="keep"`` keeps them
as floats instead, for files read back by Python only (the studies' summaries, whose tables hold
NaN where a metric is not reached).

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
from pathlib import PurePath

from ..errors import InputError

__all__ = ["json_ready", "dumps", "write_json"]


def json_ready(value, nonfinite: str = "text"):
    """``value`` with every part JSON can hold (see the module notes).

    Parameters
    ----------
    value : object
        Dicts, lists, tuples, numbers, NumPy values, strings, paths, None.
    nonfinite : {"text", "keep"}
        Non-finite floats as the strings ``"nan"``, ``"inf"``, ``"-inf"``, or kept as floats.

    Returns
    -------
    object

    Raises
    ------
    TypeError
        A value of another type (naming it), rather than writing its ``repr``.
    """
    if nonfinite not in ("text", "keep"):
        raise InputError(f"nonfinite must be 'text' or 'keep', got {nonfinite!r}")
    if isinstance(value, dict):
        return {str(k): json_ready(v, nonfinite) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(v, nonfinite) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):      # numpy scalars and arrays
        return json_ready(value.tolist(), nonfinite)
    if isinstance(value, bool) or value is None or isinstance(value, (str, int)):
        return value
    if isinstance(value, complex):
        return [json_ready(value.real, nonfinite), json_ready(value.imag, nonfinite)]
    if isinstance(value, PurePath):
        return str(value)
    if not isinstance(value, float) and hasattr(value, "__float__"):
        value = float(value)
    if isinstance(value, float):
        if math.isfinite(value) or nonfinite == "keep":
            return value
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    raise TypeError(f"cannot write a {type(value).__name__} as JSON: {value!r}")


def dumps(value, indent: int | None = None, nonfinite: str = "text") -> str:
    """``value`` as JSON text (:func:`json_ready` first).

    Parameters
    ----------
    value : object
    indent : int, optional
    nonfinite : {"text", "keep"}
        As for :func:`json_ready`.

    Returns
    -------
    str
    """
    return json.dumps(json_ready(value, nonfinite), indent=indent, allow_nan=nonfinite == "keep")


def write_json(path, value, *, overwrite: bool = True, what: str = "JSON file", nonfinite: str = "text"):
    """Write ``value`` as indented JSON, atomically (:func:`casship.outdir.output_file`).

    Parameters
    ----------
    path : str or Path
    value : object
    overwrite : bool
        Replace an existing file.
    what : str
        Name of the file or option, for messages.
    nonfinite : {"text", "keep"}
        As for :func:`json_ready`.

    Returns
    -------
    object
        The JSON-ready value that was written.
    """
    from ..outdir import output_file

    ready = json_ready(value, nonfinite)
    text = json.dumps(ready, indent=2, allow_nan=nonfinite == "keep")
    with output_file(path, overwrite=overwrite, what=what) as tmp:
        tmp.write_text(text)
    return ready
