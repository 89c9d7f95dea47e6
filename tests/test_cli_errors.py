"""The command line classifies an error by its type alone: casship's own (``CasshipError``) and
``OSError`` are the user's to fix (exit 2, one line); anything else, a plain ``ValueError`` raised in
casship's own code included, is a bug (exit 1, ``--debug`` for the traceback)."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from casship.cli import cmd_cache, is_user_error, main
from casship.errors import InputError, InputTypeError, SetupError, SolverError


def _planted(exc):
    """A command function of casship that raises ``exc`` from casship's own code (a planted bug or check)."""
    def run(args):
        raise exc
    return run


def test_a_value_error_raised_by_a_casship_bug_is_an_internal_error(monkeypatch, capsys):
    """Before: any ValueError whose innermost frame was a casship file was told to the user as their error."""
    monkeypatch.setattr(cmd_cache, "run", _planted(ValueError("operands could not be broadcast")))
    code = main(["cache", "info"])
    err = capsys.readouterr().err
    assert code == 1 and code != 2
    assert "casship cache: internal error (a bug in casship): ValueError: operands could not be broadcast" in err
    assert "--debug" in err and "Traceback" not in err
    with pytest.raises(ValueError, match="operands"):
        main(["cache", "info", "--debug"])


@pytest.mark.parametrize("exc", [InputError("--dt: must be positive, got -1"), InputTypeError("--dt: not a number"),
                                 SolverError("IPOPT: Maximum_Iterations_Exceeded"), SetupError("no C compiler"),
                                 FileNotFoundError("no such file: run.csv")])
def test_casships_own_errors_and_os_errors_are_the_users_one_line(exc, monkeypatch, capsys):
    monkeypatch.setattr(cmd_cache, "run", _planted(exc))
    assert main(["cache", "info"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f"casship cache: error: {exc}", err
    with pytest.raises(type(exc)):
        main(["cache", "info", "--debug"])


def test_classification_is_by_type_not_by_where_it_was_raised():
    assert is_user_error(InputError("x")) and is_user_error(SolverError("x")) and is_user_error(OSError("x"))
    for exc in (ValueError("x"), TypeError("x"), KeyError("x"), RuntimeError("x"), AssertionError("x")):
        assert not is_user_error(exc)
        try:                                        # raised here or anywhere else: the same answer
            raise exc
        except Exception as caught:
            assert not is_user_error(caught)


# -- the raise sites: casship's own types for what the user can fix ---------------------------------------------
ROOT = Path(__file__).resolve().parents[1]
#: (file, function) -> why its plain built-in raises are internal invariants (a casship bug if they fire),
#: not the user's to fix. The list only shrinks: an entry without such a raise fails.
INTERNAL = {
    ("casship/runtime/_buffers.py", "__init__"): "buffers bound by casship's own code to its own Functions",
    ("casship/runtime/_buffers.py", "__setitem__"): "buffers bound by casship's own code to its own Functions",
    ("casship/runtime/_buffers.py", "redirect"): "buffers bound by casship's own code to its own Functions",
    ("casship/runtime/_loop.py", "driver_source"): "the record loop is built by casship's estimators",
    ("casship/runtime/_loop.py", "_in_place"): "the record loop is driven by casship's estimators",
    ("casship/runtime/_loop.py", "__init__"): "the record loop is built by casship's estimators",
    ("casship/runtime/_loop.py", "_constant"): "the record loop is driven by casship's estimators",
    ("casship/runtime/_loop.py", "_target"): "the record loop is driven by casship's estimators",
    ("casship/runtime/_loop.py", "run"): "the record loop is driven by casship's estimators",
    ("casship/runtime/_codegen.py", "read_harness_output"): "the output of casship's own test harness",
    ("casship/io/jsonfile.py", "json_ready"): "casship writing a value of its own it cannot encode",
    ("casship/estimators/online.py", "__getitem__"): "a Mapping's KeyError (the protocol)",
    ("casship/estimators/online.py", "__init__"): "OnlineRun handed something that is not an engine by casship",
    ("problems/kit.py", "md_table"): "a study's own report",
    ("problems/kit.py", "_fixed_margins"): "a study's own figure layout",
    ("problems/kit.py", "departures"): "a study's own report",
    ("problems/kit.py", "write"): "a study's own report",
    ("problems/__init__.py", "studies"): "two studies of the package with one name",
    ("problems/filter_guidelines/scenario.py", "q_channels"): "the study's own models",
}


def _plain_raises():
    """``(file, innermost function, line)`` of every ``raise ValueError/TypeError/KeyError(...)`` in
    casship/ and problems/."""
    found = []
    for top in ("casship", "problems"):
        for path in sorted((ROOT / top).rglob("*.py")):
            tree = ast.parse(path.read_text())
            parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
            for node in ast.walk(tree):
                if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) \
                        and getattr(node.exc.func, "id", None) in ("ValueError", "TypeError", "KeyError"):
                    func = parents.get(node)
                    while func is not None and not isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
                        func = parents.get(func)
                    found.append((str(path.relative_to(ROOT)), getattr(func, "name", "<module>"), node.lineno))
    return found


def test_deliberate_raises_are_casships_own_types():
    """A plain ValueError is reported by the command line as a bug: what the user can fix raises
    ``InputError`` (``InputTypeError``), ``SolverError`` or ``SetupError``."""
    found = _plain_raises()
    bad = [f"{f}:{line} in {func}" for f, func, line in found if (f, func) not in INTERNAL]
    assert not bad, ("raise casship.errors.InputError (or another casship type) for what the user can fix, "
                     f"or list the function in INTERNAL with the reason: {bad}")
    stale = sorted(set(INTERNAL) - {(f, func) for f, func, _ in found})
    assert not stale, f"no plain raise left there: remove from INTERNAL: {stale}"
