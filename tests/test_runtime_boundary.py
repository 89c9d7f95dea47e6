"""The runtime behind one door: casship.runtime is imported only through its public names, imports no
other part of casship, compiles no CPython C-API code; and every casship module stays small."""
from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

import casship.runtime as rt

ROOT = Path(__file__).resolve().parents[1]
RUNTIME = ROOT / "casship" / "runtime"
CHECKED = ("casship", "tests", "benchmarks", "problems", "examples")


def _python_files():
    for top in CHECKED:
        yield from sorted((ROOT / top).rglob("*.py"))


def _module_of(path: Path) -> list[str]:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    return parts[:-1] if parts[-1] == "__init__" else parts


def _imports(path: Path):
    """``(module, names)`` of every import in ``path``, relative imports resolved."""
    tree = ast.parse(path.read_text(), str(path))
    package = _module_of(path) if path.name == "__init__.py" else _module_of(path)[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, []
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            yield module, [a.name for a in node.names]


def test_nothing_outside_the_runtime_reaches_into_it():
    bad = []
    for path in _python_files():
        if RUNTIME in path.parents:
            continue
        for module, names in _imports(path):
            if module.startswith("casship.runtime."):
                bad.append(f"{path.relative_to(ROOT)}: imports {module}")
            elif module == "casship.runtime" and any(n.startswith("_") for n in names):
                bad.append(f"{path.relative_to(ROOT)}: imports private {names} from casship.runtime")
        if re.search(r"\b(runtime|rt)\._(?!_)\w", path.read_text()):
            bad.append(f"{path.relative_to(ROOT)}: uses a private name of casship.runtime")
    assert not bad, bad


#: leaf modules the runtime may use: casship's error types and the progress display (neither imports casship)
LEAVES = ("casship.errors", "casship.progress")


def test_the_runtime_imports_no_other_part_of_casship():
    bad = [f"{p.relative_to(ROOT)}: {m}" for p in sorted(RUNTIME.glob("*.py")) for m, _ in _imports(p)
           if m.startswith("casship") and not m.startswith("casship.runtime") and m not in LEAVES]
    assert not bad, bad
    for leaf in LEAVES:                            # and the leaves stay leaves (they may use each other)
        path = ROOT / (leaf.replace(".", "/") + ".py")
        assert not [m for m, _ in _imports(path) if m.startswith("casship") and m not in LEAVES], leaf


@pytest.mark.parametrize("old", ["casship._fast", "casship.compile", "casship.native_fold", "casship.native_update",
                                 "casship.codegen"])
def test_the_former_modules_are_gone(old):
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)
    texts = [p for top in ("casship", "docs", "tests", "benchmarks", "examples", "problems") for p in (ROOT / top).rglob("*")
             if p.suffix in (".py", ".md") and p != Path(__file__)]
    texts.append(ROOT / "README.md")
    mentions = [str(p.relative_to(ROOT)) for p in texts if re.search(rf"{re.escape(old)}\b", p.read_text())]
    assert not mentions, mentions


def test_every_public_name_is_there_and_documented():
    for name in rt.__all__:
        obj = getattr(rt, name)
        if callable(obj):
            assert obj.__doc__ and obj.__doc__.strip(), name


def test_no_cpython_c_api_code_is_compiled():
    hits = [str(p.relative_to(ROOT)) for p in (ROOT / "casship").rglob("*.py")
            if re.search(r"Python\.h|PyObject|arrayobject\.h|ctypes\.PyDLL|py_object", p.read_text())]
    assert not hits, hits


def test_every_casship_module_is_at_most_600_lines():
    long = {str(p.relative_to(ROOT)): n for p in (ROOT / "casship").rglob("*.py")
            if (n := len(p.read_text().splitlines())) > 600}
    assert not long, long
