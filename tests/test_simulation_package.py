"""The simulation pieces in one package (casship.simulation), replay beside its metrics
(casship.maneuvers.replay), and the former module paths as warning shims giving the same objects."""
from __future__ import annotations

import ast
import importlib
import sys
import warnings
from pathlib import Path

import pytest

import casship as cs

ROOT = Path(__file__).resolve().parents[1]

#: former path -> (its new module, the package to import from)
MOVED = {
    "casship.simulate": ("casship.simulation.simulate", "casship.simulation"),
    "casship.folds": ("casship.simulation.folds", "casship.simulation"),
    "casship.prediction": ("casship.simulation.bands", "casship.simulation"),
    "casship.validity": ("casship.simulation.validity", "casship.simulation"),
    "casship.validation": ("casship.maneuvers.replay", "casship.maneuvers"),
}
SHIM_FILES = {ROOT / (old.replace(".", "/") + ".py") for old in MOVED}


def _fresh_import(name: str):
    """Import ``name`` anew (a module runs, and warns, only at its first import in a process)."""
    sys.modules.pop(name, None)
    return importlib.import_module(name)


@pytest.mark.parametrize("old", sorted(MOVED))
def test_each_former_path_warns_naming_the_new_place_and_gives_the_same_objects(old):
    new, door = MOVED[old]
    module = importlib.import_module(new)
    with pytest.warns(DeprecationWarning, match=rf"{old} is deprecated: import from {door}"):
        shim = _fresh_import(old)
    assert shim is not module and shim.__name__ == old
    assert list(shim.__all__) == list(module.__all__) and module.__all__
    for name in module.__all__:
        assert getattr(shim, name) is getattr(module, name), name
    private = sorted(n for n, v in vars(module).items() if n.startswith("_") and not n.startswith("__")
                     and callable(v) and getattr(v, "__module__", None) == new)
    for name in private:                             # old callers of private helpers get the same objects
        assert getattr(shim, name) is getattr(module, name), name
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        shim.not_a_name
    # the names the old module exported are reached through the new door as well
    package = importlib.import_module(door)
    assert all(getattr(package, n) is getattr(module, n) for n in module.__all__ if n in package.__all__)


def test_the_former_module_simulate_keeps_the_function_on_the_package():
    """``casship.simulate`` is both a function (``cs.simulate(...)``) and the former module's path."""
    from casship.simulation.simulate import simulate

    with pytest.warns(DeprecationWarning):
        shim = _fresh_import("casship.simulate")
    assert callable(cs.simulate) and cs.simulate is simulate and cs.simulate is not shim
    assert shim.simulate is simulate
    from casship import simulate as imported     # the name, not the module, after the module was imported
    assert imported is simulate
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    traj = cs.simulate(m, m.states(), [0.0, 1.0, 2.0], {"delta": 0.1})
    assert traj["r"][0] == 0.0 and traj["r"][-1] > 0.0


def test_the_new_packages_export_what_their_all_lists():
    sim = importlib.import_module("casship.simulation")
    names = [n for mod in ("simulate", "folds", "bands", "validity")
             for n in importlib.import_module(f"casship.simulation.{mod}").__all__]
    assert set(sim.__all__) == set(names) and len(sim.__all__) == len(set(sim.__all__))
    missing = [n for n in sim.__all__ if not hasattr(sim, n)]
    assert not missing, missing
    man = importlib.import_module("casship.maneuvers")
    missing = [n for n in man.__all__ if not hasattr(man, n)]
    assert not missing, missing
    replay = importlib.import_module("casship.maneuvers.replay")
    assert set(replay.__all__) <= set(man.__all__)
    assert cs.maneuvers.replay is replay.replay and cs.maneuvers.ReplayResult is replay.ReplayResult
    for name in ("simulate", "simulate_many", "measure"):             # the top-level names stay
        assert getattr(cs, name) is getattr(sim, name)


def _imports(path: Path, root: Path = ROOT) -> list[tuple[int, str, bool]]:
    """``(line, name, is_module)`` of every import in ``path``, relative ones resolved: a module imported
    (``import M``, the ``P`` of ``from P import n``) and, not surely a module, each ``P.n``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    package = parts[:-1]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, True) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            source = ".".join(base + ([node.module] if node.module else []))
            out += [(node.lineno, source, True)] + [(node.lineno, f"{source}.{a.name}", False) for a in node.names]
    return out


def _former(path: Path, root: Path = ROOT) -> list[str]:
    """The imports of a former path in ``path``. ``from casship import simulate`` is the function, not the
    former module; ``casship.folds`` and the others are modules whichever way they are imported."""
    bad = []
    for line, name, is_module in _imports(path, root):
        if (name in MOVED and (is_module or name != "casship.simulate")) or name.startswith(tuple(o + "." for o in MOVED)):
            bad.append(f"{path.relative_to(root)}:{line}: {name}")
    return bad


def test_the_import_scanner_sees_every_form(tmp_path):
    (tmp_path / "casship" / "sub").mkdir(parents=True)
    path = tmp_path / "casship" / "sub" / "m.py"
    path.write_text("from ..folds import x\nfrom .. import validity\nimport casship.prediction\n"
                    "from casship.simulate import fold_steps\nfrom casship.validation import replay\n"
                    "from casship.simulation.folds import y\nfrom casship import simulate\n"
                    "from .folds import z\n")
    found = [hit.split(": ")[1] for hit in _former(path, tmp_path)]
    assert found == ["casship.folds", "casship.folds.x", "casship.validity", "casship.prediction",
                     "casship.simulate", "casship.simulate.fold_steps", "casship.validation",
                     "casship.validation.replay"], found


def test_nothing_in_casship_the_studies_or_the_examples_imports_a_former_path():
    bad = [hit for top in ("casship", "problems", "examples") for path in sorted((ROOT / top).rglob("*.py"))
           if path not in SHIM_FILES for hit in _former(path)]
    assert not bad, bad


def test_the_docs_name_no_former_module():
    """The docs, README, benchmarks and tests speak of the new places (``casship.simulate`` is the function)."""
    import re

    pattern = re.compile(r"\bcasship\.(folds|prediction|validation|validity)\b|\bcasship\.simulate\.\w|"
                         r"automodule:: casship\.simulate\b")
    texts = [p for top in ("docs", "benchmarks", "tests", "problems", "examples") for p in (ROOT / top).rglob("*")
             if p.suffix in (".py", ".md") and p != Path(__file__)]
    hits = [f"{p.relative_to(ROOT)}:{n}" for p in [*texts, ROOT / "README.md"]
            for n, line in enumerate(p.read_text().splitlines(), 1)
            if pattern.search(line) and "deprecated" not in line]
    assert not hits, hits


def test_the_shims_warn_once_per_import_not_on_use():
    with pytest.warns(DeprecationWarning):
        shim = _fresh_import("casship.folds")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert shim.fold_steps is importlib.import_module("casship.simulation").fold_steps
