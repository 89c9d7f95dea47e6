"""Output folders and files: refused when not empty, replaced whole with overwrite, no half folder."""
import pytest

from casship.outdir import MARKER, check_output_file, output_file, output_folder


def _write(folder, name, text="x"):
    (folder / name).write_text(text)


def test_new_folder_is_written_with_marker(tmp_path):
    with output_folder(tmp_path / "out") as folder:
        _write(folder, "report.md")
        assert not (tmp_path / "out").exists()          # written aside until the run succeeds
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [MARKER, "report.md"]


def test_non_empty_folder_is_refused_without_overwrite(tmp_path):
    with output_folder(tmp_path / "out") as folder:
        _write(folder, "old.png")
    with pytest.raises(FileExistsError, match=r"--out .*out: folder exists and is not empty; pass --overwrite"):
        with output_folder(tmp_path / "out"):
            pass
    assert (tmp_path / "out" / "old.png").is_file()


def test_overwrite_removes_stale_files(tmp_path):
    with output_folder(tmp_path / "out") as folder:
        _write(folder, "old.png")
    with output_folder(tmp_path / "out", overwrite=True) as folder:
        _write(folder, "new.png")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [MARKER, "new.png"]
    assert [p.name for p in tmp_path.iterdir()] == ["out"]          # no temporary folders left


def test_failed_run_leaves_no_half_folder_and_keeps_the_old_one(tmp_path):
    with pytest.raises(RuntimeError, match="boom"):
        with output_folder(tmp_path / "new") as folder:
            _write(folder, "half.md")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []
    with output_folder(tmp_path / "out") as folder:
        _write(folder, "good.md")
    with pytest.raises(RuntimeError):
        with output_folder(tmp_path / "out", overwrite=True) as folder:
            raise RuntimeError("boom")
    assert (tmp_path / "out" / "good.md").is_file()


def test_folder_not_written_by_casship_is_never_cleared(tmp_path):
    (tmp_path / "mine").mkdir()
    _write(tmp_path / "mine", "thesis.tex")
    with pytest.raises(PermissionError, match="not written by casship"):
        with output_folder(tmp_path / "mine", overwrite=True):
            pass
    assert (tmp_path / "mine" / "thesis.tex").is_file()


def test_working_folder_is_never_cleared(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _write(tmp_path, MARKER)
    with pytest.raises(PermissionError, match="working folder"):
        with output_folder(".", overwrite=True):
            pass


def test_file_given_as_folder(tmp_path):
    _write(tmp_path, "report.txt")
    with pytest.raises(FileExistsError, match="is a file, not a folder"):
        with output_folder(tmp_path / "report.txt"):
            pass


def test_output_file(tmp_path):
    target = tmp_path / "fit.json"
    with output_file(target) as tmp:
        tmp.write_text("1")
    assert target.read_text() == "1"
    with pytest.raises(FileExistsError, match="fit.json: file exists; pass --overwrite"):
        check_output_file(target)
    with pytest.raises(ValueError):
        with output_file(target, overwrite=True) as tmp:
            tmp.write_text("2")
            raise ValueError("failed fit")
    assert target.read_text() == "1" and sorted(p.name for p in tmp_path.iterdir()) == ["fit.json"]
    with output_file(target, overwrite=True) as tmp:
        tmp.write_text("2")
    assert target.read_text() == "2"
    with pytest.raises(IsADirectoryError):
        check_output_file(tmp_path)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        check_output_file(tmp_path / "missing" / "fit.json")
