"""The shape of the code: no import circles in casship, the studies and the examples, no module reading
another's private state, no plotting backend switched by library code, papers cited by author and
year, and no test that skips when one of casship's own modules fails to import.

**Import circles.** The modules of ``casship/``, ``problems/`` (installed as ``casship_studies``) and
``examples/`` (a package's ``__init__`` is a module) form one graph with an
edge ``A -> B`` when ``A`` imports ``B`` at run time, at module level *or inside a function*: a deferred
import hides a circle from the interpreter, not from the design. ``from P import n`` is an edge to
``P.n`` when that is a module, else to ``P``. Importing ``a.b.c`` also runs the packages ``a.b`` and
``a`` first, so those are edges too, except the packages that hold ``A`` itself (they are loaded before
``A`` runs). Imports under ``if TYPE_CHECKING:`` are not edges: they never run and only name types for
annotations. Any strongly connected part of more than one module is a circle, and fails.

**Private state.** A name with one leading underscore belongs to the module that defines it (dunder
names are Python's protocols, not private). Another module may not import it, nor read or write it
on an object (``other._x``; ``self._x`` and ``cls._x`` are the object's own, inherited ones included).
A private module (``pkg/_m.py``) is importable only from inside ``pkg``. The exceptions are listed in
``PACKAGE_INTERNAL`` with their reason; every one stays inside one subpackage of casship (``casship.X``),
and ``FOREIGN`` lists the privates of other libraries used where they offer no public way. The lists
only shrink: an entry that no longer occurs fails, so does a new reach.
"""
from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "casship"
# Where the rules on circles and private names hold: the studies and examples use the public API only.
USERS = ("casship", "problems", "examples")
# The studies' installed name (pyproject.toml) -> their folder
INSTALLED = {"casship_studies": "problems"}

#: (module, private name) -> why it may be used there. Inside one subpackage only.
PACKAGE_INTERNAL = {
    ("casship.estimators.online", "_compiled_function"):
        "StepRun is the step family's online runner; it takes the step from its estimator's cache",
    ("casship.estimators.gaps", "_run"):
        "the gap check runs the estimator's (or the MHE's arrival EKF's) run over the record it has checked",
    ("casship.estimators.online", "_draw_shapes"):
        "StepRun fills the draw slots of a stochastic estimator's step",
    ("casship.identify.mle", "_value_raw"): "the likelihood engine's unscaled value for the MLE problem",
    ("casship.maneuvers.runners", "_input_vector"): "the manoeuvres' input vector of maneuvers.inputs",
    ("casship.models.lowspeed", "_param"): "the ship models' parameter declaration of models.mmg",
    ("casship.models.wind_fourier", "_lib"): "casadi-or-numpy choice of the wind-load formulas in models.wind",
}
#: (module, private name of another library) -> why: the library offers no public way.
FOREIGN = {
    ("casship.cli", "_actions"): "argparse: a parser's arguments have no public accessor",
    ("casship.cli", "_choices_actions"): "argparse: a subcommand's one-line help has no public accessor",
    ("casship.cli", "_exit"): "os._exit (public, underscored): after a Ctrl-C the program ends without the "
                              "interpreter's teardown, which takes seconds on a busy machine",
}
# The public members of namedtuples start with an underscore.
NOT_PRIVATE = {"_replace", "_asdict", "_fields", "_make", "_field_defaults"}


# -- the modules and their imports ------------------------------------------------------------------------
def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _files(tops=("casship",)) -> dict[str, Path]:
    return {_module_name(p): p for top in tops for p in sorted((ROOT / top).rglob("*.py"))}


MODULES = _files(USERS)
CASSHIP = {m: p for m, p in MODULES.items() if m.split(".")[0] == "casship"}


def _private(name: str) -> bool:
    return name.startswith("_") and not name.endswith("__") and name not in NOT_PRIVATE


def _type_checking_only(tree: ast.AST) -> set[int]:
    """``id`` of every node under an ``if TYPE_CHECKING:``."""
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, (ast.Name, ast.Attribute)) \
                and getattr(node.test, "id", getattr(node.test, "attr", "")) == "TYPE_CHECKING":
            skip.update(id(n) for stmt in node.body for n in ast.walk(stmt))
    return skip


def _imports(module: str, path: Path):
    """``(node, target module, imported name or None)`` of every import that runs, relative ones resolved."""
    tree = ast.parse(path.read_text(), str(path))
    skip = _type_checking_only(tree)
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node, _installed(alias.name), None
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            source = _installed(".".join(base + ([node.module] if node.module else [])))
            for alias in node.names:
                yield node, source, alias.name


def _installed(name: str) -> str:
    """A module's name under its folder (``casship_studies.kit`` is ``problems.kit``)."""
    top, _, rest = name.partition(".")
    return ".".join(filter(None, (INSTALLED.get(top, top), rest)))


def _ancestors(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def _edges(module: str, path: Path) -> set[str]:
    own = set(_ancestors(module)) | ({module} if path.name == "__init__.py" else set())
    out = set()
    for _, source, name in _imports(module, path):
        target = f"{source}.{name}" if name and f"{source}.{name}" in MODULES else source
        if target not in MODULES:
            continue
        out.add(target)
        out.update(a for a in _ancestors(target) if a not in own)
    out.discard(module)
    return out


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected parts of more than one node (Tarjan, iterative)."""
    index, low, on, stack, found, counter = {}, {}, set(), [], [], [0]
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter[0]
                    counter[0] += 1
                    stack.append(child)
                    on.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                part = []
                while True:
                    member = stack.pop()
                    on.discard(member)
                    part.append(member)
                    if member == node:
                        break
                if len(part) > 1:
                    found.append(sorted(part))
    return found


def test_the_circle_finder_finds_circles():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e"}, "f": set()}
    assert _circles(graph) == [["a", "b", "c"]]


def test_the_graph_covers_casship_the_studies_and_the_examples():
    tops = {m.split(".")[0] for m in MODULES}
    assert tops == set(USERS), tops
    graph = {m: _edges(m, p) for m, p in MODULES.items()}
    # the studies' own imports are edges (relative ones and those through the installed name)
    assert any(t.startswith("problems.") for m, ts in graph.items() if m.startswith("problems.") for t in ts)
    assert any(t.startswith("casship") for m, ts in graph.items() if m.startswith("examples.") for t in ts)


#: Circles known and not yet taken apart -> why they are tolerated for now. The list only shrinks: a
#: listed circle that is gone fails (remove it), and any other circle fails.
KNOWN_CIRCLES: dict = {}


def test_no_import_circles_in_casship_the_studies_and_the_examples():
    graph = {m: _edges(m, p) for m, p in MODULES.items()}
    circles = [part for part in _circles(graph) if frozenset(part) not in KNOWN_CIRCLES]
    detail = [[f"{a} -> {b}" for a in part for b in sorted(graph[a] & set(part))] for part in circles]
    assert not circles, detail
    stale = [sorted(k) for k in KNOWN_CIRCLES if list(k) and sorted(k) not in _circles(graph)]
    assert not stale, f"no longer a circle: remove from KNOWN_CIRCLES: {stale}"


def test_casship_never_imports_the_studies():
    """The studies use casship, never the other way round (they are found through an entry point)."""
    bad = [f"{m}: {s}" for m, p in CASSHIP.items() for _, s, _ in _imports(m, p)
           if s.split(".")[0] in ("problems", "casship_studies", "tests", "examples")]
    assert not bad, bad


# -- private names ------------------------------------------------------------------------------------------
def _own_names(tree: ast.AST) -> set[str]:
    """Names a module defines: functions, classes, assignments, ``self.x``/``cls.x`` attributes."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) \
                and isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"):
            names.add(node.attr)
        elif isinstance(node, ast.Call) and len(node.args) > 1 and isinstance(node.args[1], ast.Constant) \
                and (getattr(node.func, "id", None) == "setattr" or getattr(node.func, "attr", None) == "__setattr__"):
            names.add(node.args[1].value)
    return names


def _self(node: ast.AST) -> bool:
    return (isinstance(node, ast.Name) and node.id in ("self", "cls")) or \
        (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "super")


def _reaches(module: str, path: Path):
    """``(line, private name, what)`` of every use of another module's private name in ``module``."""
    tree = ast.parse(path.read_text(), str(path))
    own = _own_names(tree)
    for node, source, name in _imports(module, path):
        parts = source.split(".") + ([name] if name else [])
        for i, part in enumerate(parts):
            if _private(part):
                holder = ".".join(parts[:i])          # the package or module the private name is in
                inside = module == holder or module.startswith(holder + ".")
                if ".".join(parts[:i + 1]) in MODULES and inside:   # a private module, from inside its package
                    continue
                yield node.lineno, part, f"imports {'.'.join(parts[:i + 1])}"
                break
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr) and not _self(node.value) \
                and node.attr not in own:
            yield node.lineno, node.attr, f"uses {ast.unparse(node)}"
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("getattr", "setattr", "hasattr") \
                and len(node.args) > 1 and isinstance(node.args[1], ast.Constant) \
                and isinstance(node.args[1].value, str) and _private(node.args[1].value) \
                and not _self(node.args[0]) and node.args[1].value not in own:
            yield node.lineno, node.args[1].value, f"uses {ast.unparse(node)}"


def _all_reaches():
    return [(m, line, name, what) for m, p in MODULES.items() for line, name, what in _reaches(m, p)]


def test_no_module_reaches_into_another_modules_private_names():
    allowed = {**PACKAGE_INTERNAL, **FOREIGN}
    bad = [f"{m}:{line} {what}" for m, line, name, what in _all_reaches() if (m, name) not in allowed]
    assert not bad, bad


def test_the_allowed_reaches_are_current_and_stay_inside_one_subpackage():
    used = {(m, name) for m, _, name, _ in _all_reaches()}
    stale = sorted(set(PACKAGE_INTERNAL) - used) + sorted(set(FOREIGN) - used)
    assert not stale, f"no longer used: remove from PACKAGE_INTERNAL or FOREIGN: {stale}"
    definers = {}
    for m, p in CASSHIP.items():
        for name in _own_names(ast.parse(p.read_text())):
            definers.setdefault(name, set()).add(m)
    for module, name in FOREIGN:
        assert name not in definers, f"{name} is casship's own (defined in {sorted(definers[name])}), not foreign"
    for module, name in PACKAGE_INTERNAL:
        subpackage = ".".join(module.split(".")[:2])
        assert subpackage in CASSHIP and CASSHIP[subpackage].name == "__init__.py", \
            f"{module} is not inside a subpackage of casship: {name} cannot be package-internal"
        assert any(d == subpackage or d.startswith(subpackage + ".") for d in definers.get(name, ())), \
            f"{name}, used by {module}, is not defined in {subpackage}"


def test_the_private_name_finder_sees_reaches(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("from casship.identify._solver import x\nfrom casship.data import _hidden\n"
                    "import casship.identify._engine as e\n\n\nclass A:\n    def f(self, other):\n"
                    "        self._mine = other._theirs\n        return getattr(other, '_x'), self._mine, o._mine\n")
    found = sorted((name, what.split()[0]) for _, name, what in _reaches("casship.elsewhere", path))
    assert found == [("_engine", "imports"), ("_hidden", "imports"), ("_solver", "imports"),
                     ("_theirs", "uses"), ("_x", "uses")]


# -- plots, citations, tests ---------------------------------------------------------------------------------
def test_library_code_never_switches_the_plotting_backend():
    """``matplotlib.use`` in a library takes inline plots away from a notebook user: figures are made with
    ``matplotlib.figure.Figure`` (or ``pyplot.subplots`` without a switch)."""
    pattern = re.compile(r"\b(matplotlib|mpl)\s*\.\s*use\s*\(|switch_backend\s*\(")
    hits = sorted(str(p.relative_to(ROOT)) for top in USERS for p in (ROOT / top).rglob("*.py")
                  if pattern.search(p.read_text()))
    assert not hits, hits


#: Internal ids of the reproduced papers, however spelt ("seed 002", "seed_003", "seed-paper", "seed papers").
FILE_IDS = re.compile(r"seed[ _-]?00\d|seed[ _-]papers?", re.IGNORECASE)


def test_the_file_id_pattern_sees_every_spelling():
    for text in ("seed 002", "seed_003", "seed004", "seed-paper reproductions", "the Seed papers", "seed_paper"):
        assert FILE_IDS.search(text), text
    for text in ("seeded simulation", "seed=3", "a seed per paper"):
        assert not FILE_IDS.search(text), text


def test_papers_are_cited_by_author_and_year():
    """No internal file ids ("seed 002") for the papers reproduced; they are cited by author and year."""
    pattern = FILE_IDS
    texts = [p for top in ("casship", "problems", "docs", "tests", "examples", "benchmarks")
             for p in (ROOT / top).rglob("*") if p.suffix in (".py", ".md") and p != Path(__file__)]
    hits = [f"{p.relative_to(ROOT)}:{n}: {line.strip()}" for p in [*texts, ROOT / "README.md"]
            for n, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert not hits, hits


def test_no_test_skips_when_a_casship_module_fails_to_import():
    """A broken casship module must fail the suite, not skip the tests that need it."""
    bad = []
    for path in sorted((ROOT / "tests").rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "importorskip" and node.args \
                    and isinstance(node.args[0], ast.Constant) and str(node.args[0].value).split(".")[0] == "casship":
                bad.append(f"{path.name}:{node.lineno} importorskip({node.args[0].value!r})")
            if isinstance(node, ast.Try) and any(
                    isinstance(h.type, ast.Name) and h.type.id in ("ImportError", "ModuleNotFoundError")
                    for h in node.handlers) and any(
                    isinstance(n, (ast.Import, ast.ImportFrom)) and "casship" in ast.unparse(n)
                    for stmt in node.body for n in ast.walk(stmt)):
                bad.append(f"{path.name}:{node.lineno} import of casship under 'except ImportError'")
    assert not bad, bad

