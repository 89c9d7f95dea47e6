"""Packaging: every package is listed, the studies install as ``casship_studies`` (never as the
generic ``problems``) and register in the ``casship.studies`` entry-point group."""
from __future__ import annotations

import tomllib
from pathlib import Path

from setuptools import find_packages

ROOT = Path(__file__).resolve().parents[1]


def _setuptools() -> dict:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_every_package_is_listed_and_the_studies_are_renamed():
    cfg = _setuptools()
    listed = set(cfg["tool"]["setuptools"]["packages"])
    found = set(find_packages(str(ROOT), include=["casship", "casship.*"]))
    found |= {"casship_studies" + name[len("problems"):]
              for name in find_packages(str(ROOT), include=["problems", "problems.*"])}
    missing = sorted(found - listed)
    assert not missing, f"add {missing} to [tool.setuptools] packages in pyproject.toml"
    assert not sorted(listed - found), "pyproject.toml lists packages that do not exist"
    assert not any(name == "problems" or name.startswith("problems.") for name in listed)
    assert cfg["tool"]["setuptools"]["package-dir"] == {"casship_studies": "problems"}


def test_studies_register_in_the_entry_point_group():
    cfg = _setuptools()
    group = cfg["project"]["entry-points"]["casship.studies"]
    assert group == {"casship": "casship_studies:studies"}
    import casship.studies

    assert casship.studies.ENTRY_POINT_GROUP == "casship.studies"


def test_casship_never_imports_the_studies_by_name():
    offenders = []
    for path in (ROOT / "casship").rglob("*.py"):
        for line in path.read_text().splitlines():
            words = line.strip().split()
            if words[:1] in (["import"], ["from"]) and len(words) > 1 and words[1].split(".")[0] in (
                    "problems", "casship_studies"):
                offenders.append(f"{path.relative_to(ROOT)}: {line.strip()}")
    assert not offenders, offenders
