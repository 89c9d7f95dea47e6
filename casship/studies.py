"""Studies as values, found through an entry-point group, and run into a safe output folder.

A study reproduces a paper or analyses measured data with casship's public API and writes a folder
of results (``report.md``, figures, tables, ``summary.json``). casship itself ships none: the
studies of the source repository (its ``problems/`` folder) are installed as the package
``casship_studies``, which registers them in the entry-point group ``casship.studies``::

    [project.entry-points."casship.studies"]
    casship = "casship_studies:studies"

Any other package can register its own studies the same way (an entry point naming a
:class:`Study`, or a callable returning a mapping of them). In a source checkout whose package
metadata predate the entry point, the ``problems/`` folder beside ``casship/`` is loaded as
``casship_studies`` instead (nothing else is searched; a folder named ``problems`` elsewhere on the
path is never imported).
"""
from __future__ import annotations

import importlib.util
import inspect
import sys
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Callable, Mapping

from .io.jsonfile import write_json
from .io.datadir import data_dir as _data_dir
from .outdir import output_folder
from .errors import InputError, InputTypeError

__all__ = ["Study", "studies", "get_study", "run_study", "ENTRY_POINT_GROUP"]

#: Entry-point group under which packages register studies.
ENTRY_POINT_GROUP = "casship.studies"
_PACKAGE = "casship_studies"


@dataclass(frozen=True)
class Study:
    """A runnable study.

    Parameters
    ----------
    name : str
        Command-line name (``casship study NAME``).
    title : str
        One line saying what it reproduces or analyses.
    run : callable
        ``run(out, *, quick=False, workers=None, scheduler=None, data_dir=None) -> dict``: writes
        its results into the folder ``out`` and returns the summary (JSON-ready). ``data_dir`` is
        the measured-data folder (None: found by :func:`casship.io.data_dir`); a study without
        measured data may leave the argument out.
    needs_data : bool
        True when the study cannot run at all without the measured data (studies with an optional
        data part run without them and say what they skipped).
    """

    name: str
    title: str
    run: Callable[..., dict]
    needs_data: bool = False


def _checkout_studies():
    """The ``problems`` folder beside this casship's source checkout, imported as ``casship_studies``."""
    if _PACKAGE in sys.modules:
        return sys.modules[_PACKAGE]
    root = Path(__file__).resolve().parents[1]
    init = root / "problems" / "__init__.py"
    if not ((root / "pyproject.toml").is_file() and init.is_file()):
        return None
    spec = importlib.util.spec_from_file_location(_PACKAGE, init, submodule_search_locations=[str(init.parent)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[_PACKAGE] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[_PACKAGE]
        raise
    return module


def _collect(obj, origin: str, found: dict) -> None:
    items = obj() if callable(obj) and not isinstance(obj, Study) else obj
    if isinstance(items, Study):
        items = {items.name: items}
    if not isinstance(items, Mapping):
        raise InputTypeError(f"studies entry point {origin!r} gave {type(items).__name__}, not a Study or a mapping")
    for name, study in items.items():
        if not isinstance(study, Study):
            raise InputTypeError(f"studies entry point {origin!r}: {name!r} is not a casship.studies.Study")
        if study.name in found:
            raise InputError(f"two studies are named {study.name!r} (the second from {origin!r})")
        found[study.name] = study


def studies() -> dict[str, Study]:
    """Every registered study, by name (sorted).

    Examples
    --------
    >>> from casship.studies import studies
    >>> "fossen2021" in studies()          # doctest: +SKIP
    True
    """
    found: dict[str, Study] = {}
    eps = list(entry_points(group=ENTRY_POINT_GROUP))
    for ep in eps:
        _collect(ep.load(), f"{ep.name} = {ep.value}", found)
    if not any(ep.value.split(":")[0].split(".")[0] == _PACKAGE for ep in eps):
        module = _checkout_studies()
        if module is not None:
            _collect(module.studies, f"{_PACKAGE} (source checkout)", found)
    return dict(sorted(found.items()))


def get_study(name: str) -> Study:
    """The study called ``name``.

    Parameters
    ----------
    name : str
        Study name (``casship study --list`` shows them).

    Returns
    -------
    Study

    Raises
    ------
    ValueError
        For an unknown name, listing the known ones.
    """
    table = studies()
    if name not in table:
        raise InputError(f"unknown study {name!r}; known: {list(table)}")
    return table[name]


def run_study(study: Study | str, out, *, quick: bool = False, workers: int | None = None,
              scheduler: str | None = None, data=None, overwrite: bool = False, stream=None, params=None) -> dict:
    """Run a study into the folder ``out`` (see :func:`casship.outdir.output_folder`).

    The measured-data folder is found by :func:`casship.io.data_dir` (``data`` first, then
    ``CASSHIP_DATA``, then ``../shared/data`` beside a checkout) and announced on ``stream``
    (stderr by default), as is its absence; a study that needs the data and finds none raises
    before anything is written. The summary goes to ``out/summary.json`` (with ``"quick"`` set).

    Parameters
    ----------
    study : Study or str
    out : path
        Output folder; a non-empty one is refused unless ``overwrite``.
    quick : bool
        The study's small, fast variant.
    workers, scheduler
        Passed to the study (process pool size, Dask scheduler address).
    data : path, optional
        Measured-data folder (``--data DIR``).
    overwrite : bool
        Replace the contents of a non-empty ``out``.
    stream : file, optional
        Where to announce the data folder (default ``sys.stderr``).
    params : path, optional
        A fit file for a study that designs or checks on one (``--params``; e.g. ``trial-design``,
        which then skips the fit it would otherwise run).

    Returns
    -------
    dict
        The study's summary.
    """
    stream = stream or sys.stderr
    study = get_study(study) if isinstance(study, str) else study
    takes = inspect.signature(study.run).parameters
    if params is not None:
        if "params" not in takes:
            with_params = sorted(n for n, s in studies().items() if "params" in inspect.signature(s.run).parameters)
            raise InputError(f"study {study.name!r} takes no fit file (--params); studies that do: {with_params}")
        if not Path(params).is_file():
            raise InputError(f"--params {params}: no such file")
    folder = _data_dir(data, required=study.needs_data)
    if folder is None:
        print(f"study {study.name}: no measured-data folder found (give --data DIR or set CASSHIP_DATA); "
              "parts that need measured data are skipped", file=stream)
    else:
        print(f"study {study.name}: measured data from {folder}", file=stream)
    with output_folder(out, overwrite=overwrite) as staging:
        kwargs = dict(quick=quick, workers=workers, scheduler=scheduler)
        if params is not None:
            kwargs["params"] = Path(params)
        if "data_dir" in takes or any(p.kind is p.VAR_KEYWORD for p in takes.values()):
            kwargs["data_dir"] = folder
        elif study.needs_data:
            raise InputTypeError(f"study {study.name!r} needs measured data but its run() takes no data_dir")
        summary = study.run(staging, **kwargs)
        summary = write_json(staging / "summary.json", {"quick": bool(quick), **(summary or {})}, nonfinite="keep")
    return summary
