"""Progress through tqdm: quiet when not a terminal, drawn when asked; the stage generator keeps working."""
import io

from casship.progress import enabled, progress, track


def _run_stages(stream):
    steps = progress(["simulate", "filter"], "demo", stream=stream)
    seen = []
    for name in ("simulate", "filter"):
        next(steps)
        seen.append(name)
    next(steps, None)
    return seen


def test_quiet_when_not_a_terminal(monkeypatch):
    monkeypatch.delenv("CASSHIP_PROGRESS", raising=False)
    stream = io.StringIO()
    assert not enabled(stream)
    assert _run_stages(stream) == ["simulate", "filter"]
    assert list(track([1, 2, 3], "runs", stream=stream)) == [1, 2, 3]
    assert stream.getvalue() == ""


def test_drawn_when_forced(monkeypatch):
    monkeypatch.setenv("CASSHIP_PROGRESS", "1")
    stream = io.StringIO()
    _run_stages(stream)
    text = stream.getvalue()
    assert "demo [1/2] simulate" in text and "demo [2/2] filter" in text and "done" in text
    stream = io.StringIO()
    assert list(track(range(4), "runs", stream=stream)) == [0, 1, 2, 3]
    assert "runs:" in stream.getvalue() and "/4" in stream.getvalue()


def test_silenced_by_environment(monkeypatch):
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setenv("CASSHIP_PROGRESS", "0")
    assert not enabled(Terminal())
    monkeypatch.delenv("CASSHIP_PROGRESS")
    assert enabled(Terminal())
