"""Checks of the command line shared by the test modules."""
from __future__ import annotations

from casship.cli import main


def one_line_error(capsys, argv, *texts) -> str:
    """Run ``casship ARGV``: exit code 2 and one error line (no traceback) holding every one of ``texts``.

    Returns
    -------
    str
        The standard error.
    """
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len([x for x in err.splitlines() if ": error: " in x]) == 1, err
    for text in texts:
        assert text in err, (text, err)
    return err
