"""Nothing waits and nothing breaks around compiles, checked on real processes: a command whose result is
written exits without waiting for a background compile; Ctrl-C stops the compiler (its process group)
and exits 130 at once, leaving no build folder; a killed process's build folder is removed by the next
run; ``casship cache clear`` leaves another process's compile in progress alone.

A stand-in compiler (a shell script that answers ``--version`` at once, notes its process id and
sleeps before running the real compiler) makes every compile slow enough to be caught in the act.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from processes import gone

import casship as cs
from casship import runtime as rt

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="process groups and stand-in compilers are POSIX")
ROOT = Path(__file__).resolve().parents[1]


def _slow_compiler(tmp_path: Path, seconds: float, later: float | None = None) -> tuple[str, Path]:
    """A compiler that sleeps ``seconds`` (noting its pid in a file) before compiling for real; with
    ``later``, only its first run sleeps so long, the others ``later`` seconds."""
    try:
        real, _ = rt.find_compiler()
    except rt.CompileError as exc:
        pytest.skip(f"no C compiler: {exc}")
    pids = tmp_path / "compiler-pids"
    script = tmp_path / "slow-cc"
    first = tmp_path / "compiler-first-run"
    wait = (f"sleep {seconds}" if later is None else
            f"if [ -e {first} ]; then sleep {later}; else touch {first}; sleep {seconds}; fi")
    script.write_text(f'#!/bin/sh\n[ "$1" = --version ] && exec {real} --version\n'
                      f'echo $$ >> {pids}\n{wait}\nexec {real} "$@"\n')
    script.chmod(0o755)
    return str(script), pids


def _env(cache: Path, cc: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("CASSHIP_")}
    env.update(CASSHIP_CACHE_DIR=str(cache), CC=cc, PYTHONUNBUFFERED="1",
               PYTHONPATH=os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]))
    return env


def _wait_for(check, timeout: float, what: str):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if check():
            return
        time.sleep(0.05)
    pytest.fail(f"waited {timeout} s for {what}")


def _builds(cache: Path) -> list[str]:
    return sorted(p.name for p in cache.glob("casship-cc-*")) if cache.is_dir() else []


def _record(tmp_path: Path, seconds: float = 300.0) -> Path:
    m = cs.models.nomoto_first_order(K=0.1, T=20.0)
    t = np.arange(0, seconds, 1.0)
    tr = cs.simulate(m, m.states(), t, {"delta": 0.15 * np.sign(np.sin(2 * np.pi * t / 120))})
    return cs.measure(tr, m, {"psi": 0.01}, seed=3).to_csv(tmp_path / "rec.csv")


def _identify(tmp_path: Path, cache: Path, cc: str, seconds: float = 300.0) -> subprocess.Popen:
    """``casship identify`` on a record of ``seconds`` (evaluated interpreted while its compiles run)."""
    args = [sys.executable, "-m", "casship", "identify", str(_record(tmp_path, seconds)), "--model", "nomoto1",
            "--free", "K,T", "--guess", "K=0.05,T=10", "--R", "psi=1e-4", "--out", str(tmp_path / "fit.json")]
    return subprocess.Popen(args, cwd=tmp_path, env=_env(cache, cc), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _pids(path: Path) -> list[int]:
    return [int(x) for x in path.read_text().split()] if path.exists() else []


def test_a_written_result_exits_without_waiting_for_the_background_compile(tmp_path):
    """Fresh cache: ``identify`` evaluates interpreted while the (here 60 s) compile runs, writes its fit
    and exits within 5 s of writing it; its compiler is stopped and the unfinished compiles go to a
    detached process, which puts them in the cache for the next run."""
    cc, pids = _slow_compiler(tmp_path, 60, later=0)
    cache = tmp_path / "cache"
    proc = _identify(tmp_path, cache, cc)
    try:
        written = None
        for line in proc.stdout:
            if "fit written" in line:
                written = time.monotonic()
                break
        assert written is not None, proc.stderr.read()
        assert proc.wait(timeout=30) == 0, proc.stderr.read()
        waited = time.monotonic() - written
    finally:
        proc.kill()
    started = _pids(pids)
    assert started, "the compile had started (the check would mean nothing otherwise)"
    assert waited < 5.0, f"exited {waited:.1f} s after writing its result"
    _wait_for(lambda: all(gone(p) for p in started), 5, "its compiler to be gone")
    _wait_for(lambda: len(list(cache.glob("*.json"))) >= 1 and not _builds(cache), 150,
              "the detached process to fill the cache")


def test_without_hand_off_the_unfinished_compiles_are_dropped(tmp_path):
    cc, pids = _slow_compiler(tmp_path, 60)
    cache = tmp_path / "cache"
    proc = subprocess.Popen([sys.executable, "-c", _BACKGROUND, "dropped_thing"], cwd=tmp_path,
                            env={**_env(cache, cc), "CASSHIP_COMPILE_AFTER_EXIT": "0"},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0 and "result [2, 4]" in out, err
    time.sleep(1.0)
    assert not list(cache.glob("*.json")) and _builds(cache) == []
    assert all(gone(p) for p in _pids(pids))


_BACKGROUND = """
import sys, time, casadi as ca
from casship.runtime import compile_in_background
x = ca.SX.sym("x", 2)
h = compile_in_background(ca.Function(sys.argv[1], [x], [2 * x], ["x"], ["y"]))
time.sleep(1.0)                       # the compile has started
print("result", h.function(x=[1, 2])["y"])
"""


def test_ctrl_c_during_a_compile_exits_130_at_once_with_no_build_folder(tmp_path):
    cc, pids = _slow_compiler(tmp_path, 60)
    cache = tmp_path / "cache"
    # a long record: the fit (interpreted while its compile runs) takes seconds after the compile starts,
    # so the Ctrl-C meets the command at work (on 300 samples it wrote its result within 0.2 s, and a
    # Ctrl-C after that is rightly ignored: the result is out)
    proc = _identify(tmp_path, cache, cc, seconds=200_000.0)
    try:
        _wait_for(lambda: _pids(pids) and _builds(cache), 60, "the compile to start")
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        time.sleep(0.1)
        proc.send_signal(signal.SIGINT)             # a second Ctrl-C while it cleans up changes nothing
        code = proc.wait(timeout=30)
        took = time.monotonic() - sent
        err = proc.stderr.read()
    finally:
        proc.kill()
    assert code == 130, err
    assert took < 2.0, f"exited {took:.1f} s after Ctrl-C"
    assert "interrupted" in err and "Exception ignored" not in err and "internal error" not in err, err
    assert _builds(cache) == []
    _wait_for(lambda: all(gone(p) for p in _pids(pids)), 5, "the compiler's process group to be stopped")


_COMPILE_NOW = """
import sys, casadi as ca
from casship.runtime import compile_function
x = ca.SX.sym("x", 2)
f = compile_function(ca.Function(sys.argv[1], [x], [2 * x], ["x"], ["y"]))
print("result", f(x=[1, 2])["y"])
"""


def test_ctrl_c_during_a_compile_in_the_calling_thread_stops_it_and_removes_its_folder(tmp_path):
    cc, pids = _slow_compiler(tmp_path, 60)
    cache = tmp_path / "cache"
    proc = subprocess.Popen([sys.executable, "-c", _COMPILE_NOW, "now_thing"], env=_env(cache, cc),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: _pids(pids) and _builds(cache), 60, "the compile to start")
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
        took = time.monotonic() - sent
    finally:
        proc.kill()
    assert proc.returncode != 0 and "KeyboardInterrupt" in proc.stderr.read()
    assert took < 10.0          # a plain script: its own interpreter teardown (the CLI skips it, above)
    assert _builds(cache) == []
    _wait_for(lambda: all(gone(p) for p in _pids(pids)), 5, "the compiler's process group to be stopped")


def test_a_killed_process_leaves_a_build_folder_that_the_next_run_removes(tmp_path):
    cc, pids = _slow_compiler(tmp_path, 60)
    cache = tmp_path / "cache"
    proc = subprocess.Popen([sys.executable, "-c", _COMPILE_NOW, "killed_thing"], env=_env(cache, cc),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: _pids(pids) and _builds(cache), 60, "the compile to start")
        proc.kill()                                   # no clean-up of its own
        proc.wait(timeout=10)
    finally:
        proc.kill()
    for pid in _pids(pids):                           # its compiler (own session) is not ours to leave running
        try:
            os.killpg(pid, signal.SIGKILL)
        except OSError:
            pass
    (left,) = _builds(cache)
    assert left.endswith(f"-{proc.pid}")              # named by key and process
    real, _ = rt.find_compiler()
    done = subprocess.run([sys.executable, "-c", _COMPILE_NOW, "next_thing"], env=_env(cache, real),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert _builds(cache) == []


def test_cache_clear_leaves_another_process_compile_in_progress_alone(tmp_path):
    cc, pids = _slow_compiler(tmp_path, 3)
    cache = tmp_path / "cache"
    real, _ = rt.find_compiler()
    first = subprocess.run([sys.executable, "-c", _COMPILE_NOW, "old_thing"], env=_env(cache, cc),
                           capture_output=True, text=True, timeout=120)
    assert first.returncode == 0, first.stderr          # an entry that clear removes
    proc = subprocess.Popen([sys.executable, "-c", _COMPILE_NOW, "busy_thing"], env=_env(cache, cc),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: len(_pids(pids)) >= 2 and _builds(cache), 60, "the compile to start")
        clear = subprocess.run([sys.executable, "-m", "casship", "cache", "clear", "--dir", str(cache)],
                               env=_env(cache, real), capture_output=True, text=True, timeout=60)
        assert clear.returncode == 0, clear.stderr
        assert "removed 2 file(s)" in clear.stdout                 # the old entry: library and record
        assert "left alone: 1 compile(s) in progress" in clear.stdout, clear.stdout
        assert _builds(cache)                                      # its build folder is still there
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "result [2, 4]" in out and "compilation terminated" not in err
    assert len(list(cache.glob("*.json"))) == 1 and _builds(cache) == []       # kept for the next process


def test_an_error_raised_while_a_ctrl_c_unwinds_is_still_an_interrupt(monkeypatch, capsys):
    """A library that turns the interrupt into another exception on its way out (as the rare
    "internal error ... needed a message argument" did) gives exit 130, not an internal error."""
    from casship.cli import cmd_cache, main

    def interrupted_then_broken(args):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)
        except KeyboardInterrupt:
            raise TypeError("needed a message argument") from None

    monkeypatch.setattr(cmd_cache, "run", interrupted_then_broken)
    before = signal.getsignal(signal.SIGINT)
    assert main(["cache", "info"]) == 130
    err = capsys.readouterr().err
    assert "interrupted" in err and "internal error" not in err
    assert signal.getsignal(signal.SIGINT) is before             # the handler is put back after a call


def test_a_ctrl_c_while_a_compiler_starts_is_held_until_it_is_registered():
    """Between starting a compiler (in a session of its own) and registering it, a Ctrl-C is held back and
    handed on after: otherwise it would leave that compiler running unseen."""
    from casship.runtime import interrupts_deferred

    before = signal.getsignal(signal.SIGINT)
    with interrupts_deferred() as pending:
        signal.raise_signal(signal.SIGINT)            # no KeyboardInterrupt inside the block
        reached = True
    assert reached and len(pending.caught) == 1
    assert signal.getsignal(signal.SIGINT) is before                    # the handler is back
    with pytest.raises(KeyboardInterrupt):
        pending.deliver()
    assert pending.caught == []
    # the block fails while a Ctrl-C is held: the Ctrl-C wins
    with pytest.raises(KeyboardInterrupt):
        with interrupts_deferred():
            signal.raise_signal(signal.SIGINT)
            raise OSError("the compiler cannot be run")
    assert signal.getsignal(signal.SIGINT) is before
