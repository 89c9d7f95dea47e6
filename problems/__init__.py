"""casship's studies: reproductions of published papers and real-data analyses on casship's public API.

Installed as the package ``casship_studies`` (this folder is its source), registered in the entry
point group ``casship.studies`` so that ``casship study NAME`` finds them. Each study is a module
defining ``STUDY = Study(...)``; its ``run(out, *, quick=False, workers=None, scheduler=None,
data_dir=None)`` writes ``report.md`` (with its "Departures from the paper" table), figures (PNG)
and tables into ``out`` through the shared kit (:mod:`.kit`) and returns the summary dict.
"""
from __future__ import annotations

import importlib
import pkgutil

from casship.studies import Study
from casship.errors import InputError


__all__ = ["Study", "studies", "get_study"]


def studies() -> dict[str, Study]:
    """All studies in this package, by name (the entry point of the ``casship.studies`` group)."""
    found = {}
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_") or info.name == "kit":
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        study = getattr(module, "STUDY", None)
        if isinstance(study, Study):
            if study.name in found:
                raise ValueError(f"two studies are named {study.name!r}")
            found[study.name] = study
    return dict(sorted(found.items()))


def get_study(name: str) -> Study:
    """The study called ``name`` (``ValueError`` listing the known ones otherwise)."""
    table = studies()
    if name not in table:
        raise InputError(f"unknown study {name!r}; known: {list(table)}")
    return table[name]
