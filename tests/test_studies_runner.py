"""The study runner: the measured-data rule, safe output folders, discovery and ``casship study``."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from casship.cli import main
from casship.io import data_dir
from casship.outdir import MARKER, output_folder
from casship.errors import InputError
from casship.studies import Study, get_study, run_study, studies


# -- the data rule ---------------------------------------------------------------------------------------
def test_explicit_folder_wins_over_the_environment(tmp_path, monkeypatch):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    monkeypatch.setenv("CASSHIP_DATA", str(b))
    assert data_dir(a) == a.resolve()
    assert data_dir() == b.resolve()


def test_named_folders_must_exist(tmp_path, monkeypatch):
    with pytest.raises(FileNotFoundError, match="nowhere.*explicitly"):
        data_dir(tmp_path / "nowhere")
    monkeypatch.setenv("CASSHIP_DATA", str(tmp_path / "gone"))
    with pytest.raises(FileNotFoundError, match="gone.*CASSHIP_DATA"):
        data_dir()


def test_checkout_default_is_shared_data_beside_the_clone(monkeypatch):
    monkeypatch.delenv("CASSHIP_DATA", raising=False)
    expected = Path(__file__).resolve().parents[2] / "shared" / "data"
    found = data_dir()
    if expected.is_dir():
        assert found == expected.resolve()
    else:
        assert found is None
        with pytest.raises(FileNotFoundError, match="CASSHIP_DATA"):
            data_dir(required=True)


# -- output folders --------------------------------------------------------------------------------------
def test_output_folder_refuses_a_non_empty_folder_without_overwrite(tmp_path):
    out = tmp_path / "out"
    with output_folder(out) as staging:
        (staging / "old.png").write_text("stale")
    with pytest.raises(FileExistsError, match="not empty.*--overwrite"):
        with output_folder(out):
            pass
    assert (out / "old.png").read_text() == "stale"
    with output_folder(out, overwrite=True) as staging:
        assert staging != out and [p.name for p in staging.iterdir()] == [MARKER]
        (staging / "report.md").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "report.md"]  # the stale file is gone
    assert [p.name for p in tmp_path.iterdir()] == ["out"]                 # no staging folder left


def test_failed_run_leaves_no_half_folder_and_keeps_the_old_one(tmp_path):
    with pytest.raises(RuntimeError, match="boom"):
        with output_folder(tmp_path / "new") as staging:
            (staging / "half.md").write_text("half")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []
    old = tmp_path / "old"
    with output_folder(old) as staging:
        (staging / "report.md").write_text("kept")
    with pytest.raises(RuntimeError):
        with output_folder(old, overwrite=True) as staging:
            raise RuntimeError("boom")
    assert (old / "report.md").read_text() == "kept"
    assert [p.name for p in tmp_path.iterdir()] == ["old"]


def test_output_folder_refuses_a_file_and_a_folder_casship_did_not_write(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(FileExistsError, match="is a file"):
        with output_folder(tmp_path / "f"):
            pass
    (tmp_path / "proj").mkdir()
    (tmp_path / "proj" / "pyproject.toml").write_text("")
    with pytest.raises(PermissionError, match="not written by casship"):
        with output_folder(tmp_path / "proj", overwrite=True):
            pass
    assert (tmp_path / "proj" / "pyproject.toml").exists()


# -- discovery and the runner ----------------------------------------------------------------------------
def test_the_repository_studies_are_registered():
    names = set(studies())
    assert {"shi2009", "tomera2011", "filter-guidelines", "fossen2021"} <= names
    with pytest.raises(ValueError, match="unknown study 'nope'.*known"):
        get_study("nope")


def _failing(out, **kwargs):
    (Path(out) / "report.md").write_text("half")
    raise RuntimeError("diverged")


def _needing(out, *, data_dir=None, **kwargs):
    (Path(out) / "report.md").write_text(f"data {data_dir}")
    return {"data": str(data_dir)}


def test_run_study_announces_data_and_leaves_no_half_folder(tmp_path, capsys):
    out = tmp_path / "r"
    with pytest.raises(RuntimeError, match="diverged"):
        run_study(Study("fails", "t", _failing), out, data=tmp_path)
    assert not out.exists() and list(tmp_path.iterdir()) == []
    summary = run_study(Study("needs", "t", _needing, needs_data=True), out, quick=True, data=tmp_path)
    assert summary == {"quick": True, "data": str(tmp_path.resolve())}
    assert json.loads((out / "summary.json").read_text()) == summary
    assert f"measured data from {tmp_path.resolve()}" in capsys.readouterr().err


def test_a_study_needing_data_refuses_to_start_without(tmp_path, monkeypatch):
    monkeypatch.setenv("CASSHIP_DATA", str(tmp_path / "nowhere"))
    with pytest.raises(FileNotFoundError, match="nowhere"):
        run_study(Study("needs", "t", _needing, needs_data=True), tmp_path / "r")
    assert not (tmp_path / "r").exists()


def test_cli_refuses_a_non_empty_out_with_exit_code_2(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["study", "tomera2011", "--quick", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["keep.txt"]
    assert main(["study", "tomera2011", "--quick", "--out", str(tmp_path / "o"), "--data",
                 str(tmp_path / "missing")]) == 2
    assert "missing" in capsys.readouterr().err and not (tmp_path / "o").exists()


def _designing(out, quick=False, workers=None, scheduler=None, params=None):
    return {"params": str(params)}


def test_a_fit_file_reaches_only_a_study_that_takes_one(tmp_path, capsys):
    fit = tmp_path / "fit.json"
    fit.write_text("{}")
    summary = run_study(Study("designs", "t", _designing), tmp_path / "a", params=fit)
    assert summary["params"] == str(fit)
    with pytest.raises(InputError, match="'plain' takes no fit file.*trial-design"):
        run_study(Study("plain", "t", _failing), tmp_path / "b", params=fit)
    with pytest.raises(InputError, match="nofile.json: no such file"):
        run_study(Study("designs", "t", _designing), tmp_path / "c", params=tmp_path / "nofile.json")
    assert not (tmp_path / "b").exists() and not (tmp_path / "c").exists()
    # the command line: refused before anything is written, exit 2, the option named
    assert main(["study", "tomera2011", "--quick", "--out", str(tmp_path / "d"), "--params", str(fit)]) == 2
    assert "takes no fit file (--params)" in capsys.readouterr().err and not (tmp_path / "d").exists()
