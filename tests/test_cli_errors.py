"""The command line classifies an error by its type alone: casship's own (``CasshipError``) and
``OSError`` are the user's to fix (exit 2, one line); anything else, a plain ``ValueError`` raised in
casship's own code included, is a bug (exit 1, ``--debug`` for the traceback)."""
from __future__ import annotations

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
