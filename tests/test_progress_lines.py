"""Progress when standard error is not a terminal: one line at most every interval (stage, fraction,
time left), nothing for short work, silenced by ``CASSHIP_PROGRESS=0`` and ``--quiet``."""
import io
import os
import re
import subprocess
import sys
import time

import pytest

from casship.errors import InputError
from casship.progress import activity, bar, interval, mode, progress, track

LINE = re.compile(r"^casship: ")


@pytest.fixture
def piped(monkeypatch):
    monkeypatch.delenv("CASSHIP_PROGRESS", raising=False)
    monkeypatch.setenv("CASSHIP_PROGRESS_INTERVAL", "0.1")
    return io.StringIO()


def test_lines_carry_stage_fraction_and_time_left(piped):
    assert mode(piped) == "lines"
    steps = progress(["simulate", "filter", "fit", "report"], "job", stream=piped)
    next(steps)
    next(steps)
    next(steps)                      # stage 3 of 4: 2 stages done
    time.sleep(0.35)
    next(steps, None)
    next(steps, None)
    lines = piped.getvalue().splitlines()
    assert lines and all(LINE.match(x) for x in lines)
    first = lines[0]
    assert "job [3/4] fit" in first and "2/4 stages (50 %)" in first and "ETA ~" in first, first
    assert lines[-1].startswith("casship: job: done in ")


def test_at_most_one_line_per_interval_and_none_for_short_work(piped):
    t0 = time.monotonic()
    with bar(100, "runs", unit="run", stream=piped) as b:
        for _ in range(10):
            time.sleep(0.05)
            b.update(10)
    elapsed = time.monotonic() - t0
    lines = [x for x in piped.getvalue().splitlines() if "done in" not in x]
    assert 1 <= len(lines) <= elapsed / 0.1 + 1
    assert all("/100 runs (" in x and "elapsed" in x for x in lines), lines
    quick = io.StringIO()
    assert list(track(range(3), "quick", stream=quick)) == [0, 1, 2]
    assert quick.getvalue() == ""


def test_a_long_call_without_steps_is_reported(piped):
    with activity("casship: compiling f to C", stream=piped):
        time.sleep(0.25)
    lines = piped.getvalue().splitlines()
    assert lines[0].startswith("casship: compiling f to C: 0:00 elapsed"), lines


def test_silenced_and_bad_interval(piped, monkeypatch):
    monkeypatch.setenv("CASSHIP_PROGRESS", "0")
    with bar(10, "x", stream=piped) as b:
        time.sleep(0.25)
        b.update(5)
    assert piped.getvalue() == "" and mode(piped) == "off"
    monkeypatch.setenv("CASSHIP_PROGRESS_INTERVAL", "-1")
    with pytest.raises(InputError, match="CASSHIP_PROGRESS_INTERVAL"):
        interval()


COMMAND = ["design-trial", "--model", "kvlcc2", "--prior-std", "N_r_dash=0.01,N_v_dash=0.03",
           "--sigma", "psi=0.0035,r=0.0002", "--dt", "4", "--zigzag", "20", "--pullout", "", "--no-spiral",
           "--duration", "600", "--max-iter", "5"]       # a short free trial: a stage of several report intervals


def test_piped_design_trial_prints_progress_lines(tmp_path):
    # the free-trial stage takes some 0.3-0.5 s on a warm cache: an interval well below it (a report every 0.2 s
    # could fall on either side of the whole stage)
    env = {**os.environ, "CASSHIP_PROGRESS_INTERVAL": "0.05"}
    env.pop("CASSHIP_PROGRESS", None)
    run = subprocess.run([sys.executable, "-m", "casship", *COMMAND], capture_output=True, text=True, env=env,
                         cwd=tmp_path, timeout=600)
    assert run.returncode == 0, run.stderr
    lines = [x for x in run.stderr.splitlines() if LINE.match(x)]
    stage = [x for x in lines if "design-trial [" in x]
    assert stage, run.stderr
    assert re.search(r"design-trial \[\d/4\] [\w ]+: \d/4 stages \(\d+ %\), \d+:\d\d elapsed", stage[0]), stage[0]
    assert "| 1 |" in run.stdout                      # the ranking still goes to standard output alone
    assert "casship:" not in run.stdout


def test_quiet_silences_the_command(tmp_path, monkeypatch, capsys):
    from casship.cli import main

    monkeypatch.delenv("CASSHIP_PROGRESS", raising=False)
    monkeypatch.setenv("CASSHIP_PROGRESS_INTERVAL", "0.05")
    assert main([*COMMAND, "--quiet"]) == 0
    err = capsys.readouterr().err
    assert not [x for x in err.splitlines() if LINE.match(x)], err


def test_a_command_names_its_stage_and_appends_its_bars(piped):
    from casship.progress import command, stage

    with command("identify", stream=piped):
        stage("fitting", 3, 4)
        with bar(None, "fit", unit="iter", stream=piped) as b:
            b.update(7)
            time.sleep(0.25)
    lines = piped.getvalue().splitlines()
    assert lines[0].startswith("casship: identify [3/4] fitting: 2/4 stages (50 %), 0:00 elapsed | fit: 7 iter"), lines
    assert "ETA" not in lines[0]                     # stages of unequal length give no time left
    assert lines[-1].startswith("casship: identify: done in")


def test_work_that_fails_is_not_called_done(piped):
    with pytest.raises(RuntimeError):
        with bar(None, "fit", stream=piped):
            time.sleep(0.25)
            raise RuntimeError("solver failed")
    assert piped.getvalue().splitlines()[-1].startswith("casship: fit: stopped after ")
