"""Studies that reproduce the seed papers and analyse real data with casship's public API.

Each study is a module (or package) in this folder that defines ``STUDY = Study(...)``; the
``casship study`` command discovers them. A study's ``run(out, quick=False, workers=None,
scheduler=None)`` writes figures (PNG), tables (Markdown/CSV) and ``summary.json`` into ``out``
and returns the summary dict.
"""
from __future__ import annotations

import importlib
import pkgutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

__all__ = ["Study", "studies", "get_study", "DATA_DIR"]

# The measured data live next to the repository, never inside it.
DATA_DIR = Path(__file__).resolve().parents[2] / "shared" / "data"


@dataclass(frozen=True)
class Study:
    """A runnable study: ``run(out: Path, quick: bool, workers, scheduler) -> dict``."""

    name: str
    title: str
    run: Callable[..., dict]
    needs_data: bool = False


def studies() -> dict[str, Study]:
    """All studies in this package, by name."""
    found = {}
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        study = getattr(module, "STUDY", None)
        if isinstance(study, Study):
            if study.name in found:
                raise ValueError(f"two studies are named {study.name!r}")
            found[study.name] = study
    return dict(sorted(found.items()))


def get_study(name: str) -> Study:
    table = studies()
    if name not in table:
        raise ValueError(f"unknown study {name!r}; known: {list(table)}")
    return table[name]
