"""Install from a wheel: build it, install it into a fresh virtual environment and run the demo and a
data study from a folder outside the repository, with the measured data given by ``--data``.

Offline: the wheel is built without build isolation (setuptools and wheel from this environment) and
installed without dependencies into a virtual environment that sees the packages of the environment
running the tests (numpy, casadi, ...), whether that is a system Python or itself a virtual
environment (:func:`fresh_venv`). The installed casship is the wheel's, not the checkout's (checked),
and the wheel holds no top-level ``problems`` package.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _run(cmd, cwd, timeout=600) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "CASSHIP_DATA", "PYTHONHOME")}
    env["MPLBACKEND"] = "Agg"
    proc = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{cmd} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def running_site_dirs() -> list[str]:
    """The folders the running interpreter imports installed packages from (its site-packages, a
    virtual environment's included, and the user site)."""
    import site
    import sysconfig

    dirs = [*site.getsitepackages(), sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]]
    if site.ENABLE_USER_SITE and site.getusersitepackages():
        dirs.append(site.getusersitepackages())
    dirs += [p for p in sys.path if p.endswith(("site-packages", "dist-packages"))]
    return list(dict.fromkeys(str(Path(d).resolve()) for d in dirs if Path(d).is_dir()))


def fresh_venv(env_dir: Path, cwd: Path) -> Path:
    """A new virtual environment at ``env_dir`` that sees the running environment's packages; its python.

    ``python -m venv --system-site-packages`` alone sees the packages of the *base* interpreter, which,
    when the tests run inside a virtual environment, lack what was installed there (casadi, ...).
    The running environment's site folders are listed in a ``.pth`` file after the new environment's
    own, so a package installed into the new environment (the wheel) comes first, and an editable
    install of the checkout in the running environment is not activated (its ``.pth`` hook is not read).
    """
    _run([sys.executable, "-m", "venv", "--without-pip", env_dir], cwd=cwd)
    py = env_dir / "bin" / "python"
    own = _run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=cwd).stdout.strip()
    Path(own, "zz_running_environment.pth").write_text("\n".join(running_site_dirs()) + "\n")
    return py


@pytest.fixture(scope="module")
def venv(tmp_path_factory):
    """A virtual environment with casship installed from a freshly built wheel; returns its bin folder."""
    base = tmp_path_factory.mktemp("wheel")
    src = base / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build", "dist")
    for name in ("casship", "problems"):
        shutil.copytree(ROOT / name, src / name, ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
          "-w", base / "dist", src], cwd=base)
    wheels = list((base / "dist").glob("casship-*.whl"))
    assert len(wheels) == 1, wheels
    with zipfile.ZipFile(wheels[0]) as zf:
        top = {name.split("/")[0] for name in zf.namelist()}
    assert top == {"casship", "casship_studies", wheels[0].name.split("-")[0] + "-" +
                   wheels[0].name.split("-")[1] + ".dist-info"}, top
    env_dir = base / "venv"
    py = fresh_venv(env_dir, base)
    _run([sys.executable, "-m", "pip", "--python", py, "install", "-q", "--no-deps", "--no-index",
          "--ignore-installed", wheels[0]], cwd=base)
    outside = base / "elsewhere"
    outside.mkdir()
    where = _run([py, "-c", "import casship, casship_studies; print(casship.__file__); "
                  "print(casship_studies.__file__)"], cwd=outside).stdout.split()
    for path in where:
        assert Path(path).resolve().is_relative_to(env_dir.resolve()), where
    return env_dir / "bin", outside


def test_demo_quick_from_the_wheel(venv):
    bindir, outside = venv
    _run([bindir / "casship", "demo", "--quick", "--out", outside / "demo"], cwd=outside)
    assert (outside / "demo" / "report.md").stat().st_size > 500
    listing = _run([bindir / "casship", "study", "--list"], cwd=outside).stdout
    assert "fossen2021" in listing and "shi2009" in listing


def test_data_study_from_the_wheel_with_data_option(venv, data_dir):
    bindir, outside = venv
    proc = _run([bindir / "casship", "study", "kvlcc2-maneuvers", "--quick", "--data", data_dir,
                 "--out", outside / "km"], cwd=outside)
    assert f"measured data from {data_dir}" in proc.stderr and "skipped" not in proc.stderr
    report = (outside / "km" / "report.md").read_text()
    assert report.splitlines()[0].endswith("(quick run)")
    # the measured MARIN turning circle is in the metrics table (measured | simulated | replayed)
    row = next(line for line in report.splitlines() if line.startswith("| turning_35 | advance_m |"))
    assert all(cell.strip() not in ("", "-", "n/a") for cell in row.split("|")[3:6]), row
    # without --data and CASSHIP_DATA an installed wheel has no data folder (no checkout around it),
    # so a study's data part is skipped with a console note (tested on the runner itself)
    found = _run([bindir.parent / "bin" / "python", "-c", "from casship.io import data_dir; print(data_dir())"],
                 cwd=outside).stdout.strip()
    assert found == "None"


@pytest.mark.slow
def test_readme_commands_in_a_fresh_virtual_environment(tmp_path):
    """The README's two commands, run in a fresh virtual environment (offline: the dependencies come from
    the running environment, see :func:`fresh_venv`): ``pip install -e . && casship demo`` and
    ``pip install -e ".[test]" && python -m pytest -q``, the latter on the test that builds a virtual
    environment itself (it used to fail inside one). CI runs the second command in full (``.ci/run``)."""
    src = tmp_path / "casship-src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build", "dist", ".pytest_cache")
    for name in ("casship", "problems", "tests", "examples", "docs", "benchmarks"):
        shutil.copytree(ROOT / name, src / name, ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    py = fresh_venv(tmp_path / "venv", tmp_path)
    install = [sys.executable, "-m", "pip", "--python", py, "install", "-q", "--no-deps", "--no-build-isolation",
               "--no-index", "-e"]
    _run(install + [src], cwd=src)
    where = _run([py, "-c", "import casship; print(casship.__file__)"], cwd=tmp_path).stdout.strip()
    assert Path(where).resolve().is_relative_to(src.resolve()), where
    _run([tmp_path / "venv" / "bin" / "casship", "demo"], cwd=src, timeout=1800)
    assert (src / "casship-demo" / "report.md").is_file()
    _run(install + [f"{src}[test]"], cwd=src)
    proc = _run([py, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_studies_wheel.py", "-k",
                 "demo_quick"], cwd=src, timeout=1800)
    assert "1 passed" in proc.stdout, proc.stdout
