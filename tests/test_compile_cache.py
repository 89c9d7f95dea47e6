"""The on-disk compile cache (casship.compile): hits equal fresh compiles, corrupted entries are rebuilt,
keys follow compiler flags, the cache command shows and empties it."""
import json
import os
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

import casship as cs
from casship import compile as cc
from casship.cli import main as cli_main


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private cache directory (also for estimators that compile through the environment),
    and a clean in-process table of loaded libraries."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(folder))
    monkeypatch.delenv("CASSHIP_CFLAGS", raising=False)
    monkeypatch.setattr(cc, "_LOADED", {})
    return folder


def _ekf_step():
    m = cs.models.sog_cog(0.01, 0.1)
    ekf = cs.EKF(cs.discretize(m, 0.02, method="euler"), np.diag([1e-2, 1e-3]), np.eye(2))
    return ekf.step_function("all")


def _args(fun, seed=0):
    rng = np.random.default_rng(seed)
    args = {n: rng.uniform(0.1, 0.9, fun.size_in(n)) for n in fun.name_in()}
    P = rng.uniform(-0.2, 0.2, (5, 5))
    args.update(P=P @ P.T + np.eye(5), R=np.eye(2), Q=np.diag([1e-2, 1e-3]), mask=np.ones((2, 1)), gate=1e300)
    return args


def _outputs(fun, args):
    return {k: np.asarray(v) for k, v in fun(**args).items()}


def _rewrite(path, data: bytes):
    """Replace a file by a new one (a loaded library must not be overwritten in place: it is mapped)."""
    tmp = path.with_name(path.name + ".new")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _entry_files(folder):
    libs = [f for f in folder.iterdir() if f.suffix in (".so", ".dylib", ".dll")]
    records = [f for f in folder.iterdir() if f.suffix == ".json"]
    return libs, records


def test_cache_hit_equals_fresh_compile_and_interpreted(cache):
    step = _ekf_step()
    args = _args(step)
    fresh = cc.compile_function(step, cache=False)
    first = cc.compile_function(step)
    libs, records = _entry_files(cache)
    assert len(libs) == 1 and len(records) == 1
    record = json.loads(records[0].read_text())
    assert record["function"] == "ekf_step" and record["flags"] == list(cc.DEFAULT_FLAGS)
    cc._LOADED.clear()                                   # a new process: only the disk is left
    hit = cc.compile_function(step)
    assert hit.is_a("External") and hit is not first
    assert list(hit.name_in()) == list(step.name_in()) and list(hit.name_out()) == list(step.name_out())
    assert os.path.getmtime(libs[0]) == os.path.getmtime(_entry_files(cache)[0][0])   # not rebuilt
    ref, got_fresh, got_hit = _outputs(step, args), _outputs(fresh, args), _outputs(hit, args)
    for k in step.name_out():
        np.testing.assert_array_equal(got_hit[k], got_fresh[k])
        np.testing.assert_allclose(got_hit[k], ref[k], rtol=1e-12, atol=1e-14)


def test_hit_in_a_second_process_loads_without_compiling(cache):
    """A new Python process finds the library compiled by this one (same key across processes)."""
    step = _ekf_step()
    cc.compile_function(step)
    before = {f.name: f.stat().st_mtime_ns for f in cache.iterdir()}
    script = (
        "import numpy as np, casship as cs, casship.compile as cc\n"
        "m = cs.models.sog_cog(0.01, 0.1)\n"
        "ekf = cs.EKF(cs.discretize(m, 0.02, method='euler'), np.diag([1e-2, 1e-3]), np.eye(2))\n"
        "f = cc.compile_function(ekf.step_function('all'))\n"
        "print(f.class_name())\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=os.environ.copy(),
                         cwd=str(Path(__file__).resolve().parents[1]))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "External"
    assert {f.name: f.stat().st_mtime_ns for f in cache.iterdir()} == before


@pytest.mark.parametrize("damage", ["truncate", "flip", "record"])
def test_corrupted_entry_is_detected_and_rebuilt(cache, damage):
    step = _ekf_step()
    args = _args(step, seed=1)
    ref = _outputs(cc.compile_function(step, cache=False), args)
    cc.compile_function(step)
    (lib,), (record,) = _entry_files(cache)
    good = lib.read_bytes()
    if damage == "truncate":
        _rewrite(lib, good[: len(good) // 2])
    elif damage == "flip":                               # same size, one byte changed: checksum differs
        data = bytearray(good)
        data[len(data) // 2] ^= 0xFF
        _rewrite(lib, bytes(data))
    else:
        record.write_text("{not json")
    cc._LOADED.clear()
    assert cc._from_cache(step, cache, record.stem) is None     # detected: never loaded
    assert not lib.exists() and not record.exists()             # and removed
    rebuilt = cc.compile_function(step)
    (lib2,), (record2,) = _entry_files(cache)
    assert lib2.read_bytes() != good[: len(good) // 2] and cc._verified(lib2, record2) is not None
    got = _outputs(rebuilt, args)
    for k in step.name_out():
        np.testing.assert_array_equal(got[k], ref[k])


def test_entry_with_another_signature_is_not_used(cache):
    """A library under the right key whose inputs differ (e.g. a hand-placed file) is rebuilt."""
    step = _ekf_step()
    x = ca.SX.sym("x")
    other = ca.Function("ekf_step", [x], [2 * x], ["x"], ["y"])
    cc.compile_function(other)
    (lib,), (record,) = _entry_files(cache)
    key = cc.cache_key(step, cc.find_compiler(), cc.DEFAULT_FLAGS)
    lib.rename(cache / f"{key}{lib.suffix}")
    record.rename(cache / f"{key}.json")
    cc._LOADED.clear()
    f = cc.compile_function(step)
    assert f.n_in() == step.n_in() and list(f.name_out()) == list(step.name_out())


def test_key_changes_with_flags_compiler_and_function(cache):
    step = _ekf_step()
    other = cs.EKF(cs.discretize(cs.models.sog_cog(0.01, 0.1), 0.02, method="rk4"), np.diag([1e-2, 1e-3]),
                   np.eye(2)).step_function("all")                  # another integrator: another Function
    comp = cc.find_compiler()
    keys = {cc.cache_key(step, comp, ("-O1",)), cc.cache_key(step, comp, ("-O2",)),
            cc.cache_key(step, comp, ("-O2", "-march=native")), cc.cache_key(step, (comp[0], "other 1.0"), ("-O2",)),
            cc.cache_key(other, comp, ("-O2",))}
    assert len(keys) == 5
    assert cc.cache_key(step, comp, ("-O2",)) == cc.cache_key(_ekf_step(), comp, ("-O2",))   # rebuilt alike
    a = cc.compile_function(step, flags=["-O1"])
    b = cc.compile_function(step, flags="-O2")
    assert a is not b and len(_entry_files(cache)[0]) == 2
    assert {tuple(json.loads(r.read_text())["flags"]) for r in _entry_files(cache)[1]} == {("-O1",), ("-O2",)}


def test_environment_and_argument_choose_the_directory(tmp_path, monkeypatch):
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "env"))
    assert cc.cache_dir() == tmp_path / "env"
    assert cc.cache_dir(tmp_path / "arg") == tmp_path / "arg"
    monkeypatch.setenv("CASSHIP_CACHE_DIR", "off")
    assert cc.cache_dir() is None
    monkeypatch.delenv("CASSHIP_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    if sys.platform != "win32":
        assert cc.cache_dir() == tmp_path / "xdg" / "casship"


def test_cache_off_keeps_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("CASSHIP_CACHE_DIR", "off")
    monkeypatch.setattr(cc, "_LOADED", {})
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    x = ca.SX.sym("x", 2)
    f = cc.compile_function(ca.Function("twice_off", [x], [2 * x], ["x"], ["y"]))
    np.testing.assert_array_equal(np.asarray(f(x=[1.0, 2.0])["y"]).ravel(), [2.0, 4.0])
    assert cc.cache_info().path is None and cc.clear_cache() == 0


def test_errors_name_the_function(cache):
    x = ca.SX.sym("x")
    f = ca.Function("named_thing", [x], [x], ["x"], ["y"])
    with pytest.raises(RuntimeError, match="named_thing.*no C compiler"):
        cc.compile_function(f, compiler="no-such-compiler-casship")
    with pytest.raises(RuntimeError, match="compiling 'named_thing' to C failed"):
        cc.compile_function(f, flags=["--no-such-flag-casship"])
    with pytest.raises(TypeError, match="casadi.Function"):
        cc.compile_function("f")
    with pytest.raises(TypeError, match="strings"):
        cc.compile_function(f, flags=[3])


def test_estimator_jit_goes_through_the_cache(cache):
    m = cs.models.sog_cog(0.01, 0.1)
    dm = cs.discretize(m, 0.02, method="euler")
    ekf = cs.EKF(dm, np.diag([1e-2, 1e-3]), np.eye(2), options={"jit": True})
    traj = cs.simulate(m, m.states(U=3.0, chi=0.3), np.arange(0.0, 4.0, 0.02), method="euler")
    data = cs.measure(traj, m, {"x_n": 1.0, "y_n": 1.0}, seed=0)
    prior = cs.Gaussian(m.states(U=2.5, chi=0.2), [4.0, 4.0, 1.0, 0.05, 1e-3])
    res = ekf.filter(data, prior)
    names = set(cc.cache_info().functions)
    assert "ekf_step" in names                     # the step, compiled with its record loop
    ref = cs.EKF(dm, np.diag([1e-2, 1e-3]), np.eye(2)).filter(data, prior)
    np.testing.assert_allclose(res.x, ref.x, rtol=1e-11, atol=1e-11)


def test_cache_command_info_and_clear(cache, capsys):
    x = ca.SX.sym("x")
    cc.compile_function(ca.Function("cmd_thing", [x], [x + 1], ["x"], ["y"]))
    (cache / "keep.txt").write_text("not the cache's")
    assert cli_main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert str(cache) in out and "entries: 1" in out and "cmd_thing: 1" in out
    assert cli_main(["cache", "clear"]) == 0
    assert "removed 2 file(s)" in capsys.readouterr().out
    assert [f.name for f in cache.iterdir()] == ["keep.txt"]
    assert cli_main(["cache", "info", "--dir", str(cache / "nowhere")]) == 0
    assert "entries: 0" in capsys.readouterr().out


@pytest.mark.skipif(sys.platform == "win32", reason="the stand-in compiler is a shell script")
def test_a_compiler_refusing_march_native_gets_the_portable_flags(cache, tmp_path, monkeypatch):
    """The default flags include -march=native; a compiler that refuses it still compiles, with the
    portable flags (and they are what the cache records)."""
    real, _ = cc.find_compiler()
    picky = tmp_path / "picky-cc"
    picky.write_text("#!/bin/sh\nfor a in \"$@\"; do [ \"$a\" = -march=native ] && { echo 'unknown -march' >&2; exit 1; }; "
                     f"done\nexec {real} \"$@\"\n")
    picky.chmod(0o755)
    monkeypatch.setattr(cc, "_NO_NATIVE", set())
    x = ca.SX.sym("x", 2)
    f = cc.compile_function(ca.Function("picky_thing", [x], [3 * x], ["x"], ["y"]), compiler=str(picky))
    np.testing.assert_array_equal(np.array(f(x=[1.0, 2.0])["y"]).ravel(), [3.0, 6.0])
    (record,) = [p for p in cache.iterdir() if p.suffix == ".json"]
    assert json.loads(record.read_text())["flags"] == list(cc.PORTABLE_FLAGS)
    assert "-march=native" in cc.DEFAULT_FLAGS and cc.find_compiler(str(picky)) in cc._NO_NATIVE
