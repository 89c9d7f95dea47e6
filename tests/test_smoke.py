"""End-to-end smoke tests of the command line."""
from casship.cli import main


def test_help_lists_demo(capsys):
    assert main([]) == 0
    assert "demo" in capsys.readouterr().out

