"""The on-disk compile cache (``casship.runtime``): hits equal fresh compiles, corrupted or planted
entries are never loaded, unsafe folders are refused, file-system errors mean "no cache", a hung
compiler is stopped, ``-march=native`` is dropped only when refused, concurrent processes agree,
and ``casship cache`` shows and empties the cache."""
import gc
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from processes import gone

import casship as cs
from casship import runtime as rt
from casship.cli import main as cli_main

ROOT = Path(__file__).resolve().parents[1]
posix_only = pytest.mark.skipif(sys.platform == "win32", reason="owners, modes and the stand-in compilers are POSIX")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """A private cache folder (also for estimators that compile through the environment)."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(folder))
    monkeypatch.delenv("CASSHIP_CFLAGS", raising=False)
    monkeypatch.delenv("CASSHIP_COMPILE_TIMEOUT", raising=False)
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


def _sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _twice(name):
    x = ca.SX.sym("x", 2)
    return ca.Function(name, [x], [2 * x], ["x"], ["y"])


def _y(f, x=(1.0, 2.0)):
    return np.asarray(f(x=list(x))["y"]).ravel().tolist()


# -- hits, damage, keys --------------------------------------------------------------------------------------
def test_cache_hit_equals_fresh_compile_and_interpreted(cache):
    step = _ekf_step()
    args = _args(step)
    fresh = rt.compile_function(step, cache=False)
    first = rt.compile_function(step)
    assert cache.stat().st_mode & 0o777 == 0o700                  # created private
    (lib,), (record,) = _entry_files(cache)
    meta = json.loads(record.read_text())
    assert meta["function"] == "ekf_step" and meta["sha256"] == _sha(lib)
    mtime = lib.stat().st_mtime_ns
    del first
    gc.collect()                                                  # nothing holds it: only the disk is left
    hit = rt.compile_function(step)
    assert hit.is_a("External")
    assert list(hit.name_in()) == list(step.name_in()) and list(hit.name_out()) == list(step.name_out())
    assert lib.stat().st_mtime_ns == mtime                         # loaded, not rebuilt
    ref, got_fresh, got_hit = _outputs(step, args), _outputs(fresh, args), _outputs(hit, args)
    for k in step.name_out():
        np.testing.assert_array_equal(got_hit[k], got_fresh[k])
        np.testing.assert_allclose(got_hit[k], ref[k], rtol=1e-12, atol=1e-14)


def test_hit_in_a_second_process_loads_without_compiling(cache):
    """A new Python process finds the library compiled by this one (same key across processes)."""
    rt.compile_function(_ekf_step())
    before = {f.name: f.stat().st_mtime_ns for f in cache.iterdir()}
    script = (
        "import numpy as np, casship as cs\nfrom casship.runtime import compile_function\n"
        "m = cs.models.sog_cog(0.01, 0.1)\n"
        "ekf = cs.EKF(cs.discretize(m, 0.02, method='euler'), np.diag([1e-2, 1e-3]), np.eye(2))\n"
        "print(compile_function(ekf.step_function('all')).class_name())\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=os.environ.copy(), cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "External"
    assert {f.name: f.stat().st_mtime_ns for f in cache.iterdir() if f.suffix != ".lock"} == \
        {k: v for k, v in before.items() if not k.endswith(".lock")}


@pytest.mark.parametrize("damage", ["truncate", "flip", "record"])
def test_corrupted_entry_is_never_loaded_and_rebuilt(cache, damage):
    step = _ekf_step()
    args = _args(step, seed=1)
    ref = _outputs(rt.compile_function(step, cache=False), args)
    first = rt.compile_function(step)
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
    damaged = _sha(lib)
    del first
    gc.collect()
    rebuilt = rt.compile_function(step)
    (lib2,), (record2,) = _entry_files(cache)
    assert json.loads(record2.read_text())["sha256"] == _sha(lib2)
    if damage != "record":
        assert _sha(lib2) != damaged                     # the damaged file was replaced, not loaded
    got = _outputs(rebuilt, args)
    for k in step.name_out():
        np.testing.assert_array_equal(got[k], ref[k])


def test_entry_with_another_signature_is_not_used(cache):
    """A library under the right key whose inputs differ (e.g. a hand-placed file) is rebuilt."""
    step = _ekf_step()
    x = ca.SX.sym("x")
    rt.compile_function(ca.Function("ekf_step", [x], [2 * x], ["x"], ["y"]), flags=["-O1"])
    (lib,), (record,) = _entry_files(cache)
    key = rt.cache_key(step, rt.find_compiler(), ("-O1",))
    lib.rename(cache / f"{key}{lib.suffix}")
    record.rename(cache / f"{key}.json")
    f = rt.compile_function(step, flags=["-O1"])
    assert f.n_in() == step.n_in() and list(f.name_out()) == list(step.name_out())


def test_key_changes_with_flags_compiler_and_function(cache):
    step = _ekf_step()
    other = cs.EKF(cs.discretize(cs.models.sog_cog(0.01, 0.1), 0.02, method="rk4"), np.diag([1e-2, 1e-3]),
                   np.eye(2)).step_function("all")                  # another integrator: another Function
    comp = rt.find_compiler()
    keys = {rt.cache_key(step, comp, ("-O1",)), rt.cache_key(step, comp, ("-O2",)),
            rt.cache_key(step, comp, ("-O2", "-march=native")), rt.cache_key(step, (comp[0], "other 1.0"), ("-O2",)),
            rt.cache_key(other, comp, ("-O2",))}
    assert len(keys) == 5
    assert rt.cache_key(step, comp, ("-O2",)) == rt.cache_key(_ekf_step(), comp, ("-O2",))   # rebuilt alike
    a = rt.compile_function(step, flags=["-O1"])
    b = rt.compile_function(step, flags="-O2")
    assert a is not b and len(_entry_files(cache)[0]) == 2
    assert {tuple(json.loads(r.read_text())["flags"]) for r in _entry_files(cache)[1]} == {("-O1",), ("-O2",)}


# -- where the cache is ------------------------------------------------------------------------------------------
def test_environment_and_argument_choose_the_folder_always_absolute(tmp_path, monkeypatch):
    monkeypatch.setenv("CASSHIP_CACHE_DIR", str(tmp_path / "env"))
    assert rt.cache_dir() == tmp_path / "env"
    assert rt.cache_dir(tmp_path / "arg") == tmp_path / "arg"
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("CASSHIP_CACHE_DIR", ".")
    assert rt.cache_dir() == tmp_path and rt.cache_dir().is_absolute()
    assert rt.cache_dir("rel") == tmp_path / "rel"
    monkeypatch.setenv("CASSHIP_CACHE_DIR", "off")
    assert rt.cache_dir() is None
    monkeypatch.delenv("CASSHIP_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    if sys.platform != "win32":
        assert rt.cache_dir() == tmp_path / "xdg" / "casship"


def test_cache_in_the_working_directory_works_with_jit_estimators(tmp_path, monkeypatch):
    folder = tmp_path / "work"
    folder.mkdir(mode=0o700)
    monkeypatch.chdir(folder)
    monkeypatch.setenv("CASSHIP_CACHE_DIR", ".")
    m = cs.models.sog_cog(0.01, 0.1)
    dm = cs.discretize(m, 0.02, method="euler")
    traj = cs.simulate(m, m.states(U=3.0, chi=0.3), np.arange(0.0, 2.0, 0.02), method="euler")
    data = cs.measure(traj, m, {"x_n": 1.0, "y_n": 1.0}, seed=0)
    prior = cs.Gaussian(m.states(U=2.5, chi=0.2), [4.0, 4.0, 1.0, 0.05, 1e-3])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)              # the folder is used, not refused
        res = cs.EKF(dm, np.diag([1e-2, 1e-3]), np.eye(2), options={"jit": True, "outputs": "all"}).filter(data, prior)
    ref = cs.EKF(dm, np.diag([1e-2, 1e-3]), np.eye(2)).filter(data, prior)
    np.testing.assert_allclose(res.x, ref.x, rtol=1e-11, atol=1e-11)
    info = rt.cache_info()
    assert info.path == folder and info.entries >= 1 and "ekf_step" in info.functions


def test_cache_off_keeps_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("CASSHIP_CACHE_DIR", "off")
    f = rt.compile_function(_twice("twice_off"))
    assert _y(f) == [2.0, 4.0]
    assert rt.cache_info().path is None and rt.clear_cache() == 0


# -- whose code is loaded ------------------------------------------------------------------------------------------
def _plant(folder: Path, target: ca.Function, flags, marker: Path) -> None:
    """A library under ``target``'s key with the same name and signature but other values (3 x), whose
    constructor writes ``marker`` when it is loaded, and a record that matches it."""
    x = ca.SX.sym("x", 2)
    evil = ca.Function(target.name(), [x], [3 * x], ["x"], ["y"])
    key = rt.cache_key(target, rt.find_compiler(), tuple(flags))
    with tempfile.TemporaryDirectory() as tmp:
        gen = ca.CodeGenerator("planted.c", {"with_header": False})
        gen.add(evil)
        src = Path(tmp) / "planted.c"
        src.write_text(gen.dump() + '\n#include <stdio.h>\n__attribute__((constructor)) static void planted(void) '
                       f'{{ FILE* f = fopen("{marker}", "w"); if (f) {{ fputs("ran", f); fclose(f); }} }}\n')
        lib = folder / f"{key}{'.dylib' if sys.platform == 'darwin' else '.so'}"
        subprocess.run([rt.find_compiler()[0], *flags, "-fPIC", "-shared", str(src), "-o", str(lib), "-lm"], check=True)
    (folder / f"{key}.json").write_text(json.dumps({"key": key, "function": target.name(), "bytes": lib.stat().st_size,
                                                    "sha256": _sha(lib)}))


@posix_only
@pytest.mark.parametrize("unsafe", ["world-writable", "group-writable", "foreign-owned"])
def test_a_planted_library_in_an_unsafe_folder_is_never_loaded(tmp_path, monkeypatch, unsafe):
    monkeypatch.delenv("CASSHIP_CFLAGS", raising=False)
    flags = ("-O1",)
    # the plant works: in a private folder it would be loaded (its constructor runs, it triples)
    control, control_marker = tmp_path / "control", tmp_path / "control-ran"
    control.mkdir(mode=0o700)
    _plant(control, _twice("planted_twice_control"), flags, control_marker)
    assert _y(rt.compile_function(_twice("planted_twice_control"), flags=flags, cache_dir=control)) == [3.0, 6.0]
    assert control_marker.exists()
    folder, marker = tmp_path / "cache", tmp_path / "ran"
    folder.mkdir(mode=0o700)
    _plant(folder, _twice("planted_twice"), flags, marker)
    if unsafe == "world-writable":
        folder.chmod(0o777)
    elif unsafe == "group-writable":
        folder.chmod(0o770)
    elif os.geteuid() == 0:
        os.chown(folder, 54321, 54321)                          # really another user's folder
    else:
        real = os.geteuid()
        monkeypatch.setattr(os, "geteuid", lambda: real + 1)     # the folder is seen as another user's
    with pytest.warns(RuntimeWarning, match="is not used") as seen:
        f = rt.compile_function(_twice("planted_twice"), flags=flags, cache_dir=folder)
        g = rt.compile_function(_twice("planted_twice_more"), flags=flags, cache_dir=folder)
    assert len([w for w in seen if "is not used" in str(w.message)]) == 1      # one warning
    assert _y(f) == [2.0, 4.0] and _y(g) == [2.0, 4.0]
    assert not marker.exists()                                   # never loaded
    assert len(_entry_files(folder)[0]) == 1                     # nothing added to the refused folder
    assert "NOT USED" in rt.cache_info(folder).summary()


@posix_only
def test_a_planted_library_owned_by_another_user_is_not_loaded_from_a_private_folder(tmp_path, monkeypatch):
    if os.geteuid() != 0:
        pytest.skip("only root can give a file to another user")
    monkeypatch.delenv("CASSHIP_CFLAGS", raising=False)
    folder, marker = tmp_path / "cache", tmp_path / "ran"
    folder.mkdir(mode=0o700)
    _plant(folder, _twice("planted_file"), ("-O1",), marker)
    for f in folder.iterdir():
        os.chown(f, 54321, 54321)
    assert _y(rt.compile_function(_twice("planted_file"), flags=["-O1"], cache_dir=folder)) == [2.0, 4.0]
    assert not marker.exists()


@posix_only
def test_file_system_errors_mean_no_cache_with_one_warning(tmp_path, monkeypatch):
    """A folder that cannot be written (read-only; simulated for root, who may write anywhere):
    compiled uncached, one warning, correct results."""
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    folder.chmod(0o500)
    if os.geteuid() == 0:
        real = os.mkdir

        def read_only(path, *args, **kwargs):
            if Path(path).parent == folder:
                raise PermissionError(13, "Read-only file system", str(folder))
            return real(path, *args, **kwargs)

        monkeypatch.setattr(os, "mkdir", read_only)
    with pytest.warns(RuntimeWarning, match="is not used: writing into it failed") as seen:
        a = rt.compile_function(_twice("ro_one"), flags=["-O1"], cache_dir=folder)
        b = rt.compile_function(_twice("ro_two"), flags=["-O1"], cache_dir=folder)
    assert len([w for w in seen if "is not used" in str(w.message)]) == 1
    assert _y(a) == _y(b) == [2.0, 4.0]
    folder.chmod(0o700)
    assert _entry_files(folder) == ([], [])


def test_a_path_that_is_a_file_is_refused(tmp_path):
    path = tmp_path / "not-a-folder"
    path.write_text("x")
    with pytest.warns(RuntimeWarning, match="is not used"):
        assert _y(rt.compile_function(_twice("file_path"), flags=["-O1"], cache_dir=path)) == [2.0, 4.0]


# -- the compiler ---------------------------------------------------------------------------------------------------
def test_errors_name_the_function(cache):
    f = _twice("named_thing")
    with pytest.raises(rt.CompileError, match="named_thing.*no C compiler"):
        rt.compile_function(f, compiler="no-such-compiler-casship")
    with pytest.raises(rt.CompileError, match="compiling 'named_thing' to C failed"):
        rt.compile_function(f, flags=["--no-such-flag-casship"])
    with pytest.raises(TypeError, match="casadi.Function"):
        rt.compile_function("f")
    with pytest.raises(TypeError, match="strings"):
        rt.compile_function(f, flags=[3])
    assert issubclass(rt.CompileError, RuntimeError)


def _stand_in(tmp_path, name, body):
    script = tmp_path / name
    script.write_text("#!/bin/sh\n" + body)
    script.chmod(0o755)
    return str(script)


@posix_only
def test_the_default_flags_are_bit_exact_and_march_native_is_an_opt_in(cache, tmp_path, monkeypatch):
    """The one flag set keeps the interpreted numbers (no -march=native, no contraction into fused
    multiply-adds), so a compiler that refuses -march=native compiles the defaults untouched; the
    native flags are asked for explicitly ($CASSHIP_CFLAGS), and then cache info says so."""
    assert "-march=native" not in rt.DEFAULT_FLAGS and "-ffp-contract=off" in rt.DEFAULT_FLAGS
    assert "-march=native" in rt.NATIVE_FLAGS
    real, _ = rt.find_compiler()
    picky = _stand_in(tmp_path, "picky-cc", "for a in \"$@\"; do [ \"$a\" = -march=native ] && "
                                            f"{{ echo 'unknown -march' >&2; exit 1; }}; done\nexec {real} \"$@\"\n")
    f = rt.compile_function(_twice("picky_thing"), compiler=picky)
    assert _y(f) == [2.0, 4.0]
    (record,) = _entry_files(cache)[1]
    assert json.loads(record.read_text())["flags"] == list(rt.DEFAULT_FLAGS)
    assert "last bit" in rt.cache_info().flags_note
    monkeypatch.setenv("CASSHIP_CFLAGS", " ".join(rt.NATIVE_FLAGS))
    info = rt.cache_info()
    assert info.flags == rt.NATIVE_FLAGS and "differ" in info.flags_note


@posix_only
def test_another_compile_failure_keeps_march_native(cache, tmp_path):
    """A failure that is not the compiler refusing -march=native (here: the first real compile fails)
    raises, and the next compile still uses the default flags."""
    real, _ = rt.find_compiler()
    once = tmp_path / "failed-once"
    flaky = _stand_in(tmp_path, "flaky-cc", f"case \"$*\" in *-shared*) if [ ! -e {once} ]; then touch {once}; "
                                            "echo 'internal compiler error' >&2; exit 4; fi;; esac\n"
                                            f"exec {real} \"$@\"\n")
    with pytest.raises(rt.CompileError, match="internal compiler error"):
        rt.compile_function(_twice("flaky_thing"), compiler=flaky)
    rt.compile_function(_twice("flaky_thing"), compiler=flaky)
    (record,) = _entry_files(cache)[1]
    assert json.loads(record.read_text())["flags"] == list(rt.DEFAULT_FLAGS)


@posix_only
def test_a_hung_compiler_is_stopped_with_a_clear_error(cache, tmp_path, monkeypatch):
    pidfile = tmp_path / "sleeper.pid"
    hung = _stand_in(tmp_path, "hung-cc", f"case \"$*\" in *--version*) echo 'hung 1.0'; exit 0;; esac\n"
                                          f"sleep 120 &\necho $! > {pidfile}\nwait\n")
    monkeypatch.setenv("CASSHIP_COMPILE_TIMEOUT", "1")
    t0 = time.monotonic()
    with pytest.raises(rt.CompileError, match=r"hung_thing.*did not finish within 1 s"):
        rt.compile_function(_twice("hung_thing"), compiler=hung, flags=["-O1"])
    assert time.monotonic() - t0 < 30
    pid = int(pidfile.read_text())
    deadline = time.monotonic() + 5
    while not gone(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert gone(pid)                                            # the compiler's own children stopped too
    assert not _entry_files(cache)[0]
    monkeypatch.setenv("CASSHIP_COMPILE_TIMEOUT", "soon")
    with pytest.raises(ValueError, match="CASSHIP_COMPILE_TIMEOUT"):
        rt.compile_function(_twice("hung_thing"), compiler=hung, flags=["-O1"])


# -- several processes ----------------------------------------------------------------------------------------------
CONCURRENT = """
import sys, time
from pathlib import Path
import numpy as np, casship as cs
from casship.runtime import compile_function
m = cs.models.sog_cog(0.01, 0.1)
ekf = cs.EKF(cs.discretize(m, 0.05, method='euler'), np.diag([1e-2, 1e-3]), np.eye(2))
step = ekf.step_function('all')
Path(sys.argv[1]).touch()                      # ready; all start compiling together
while not Path(sys.argv[2]).exists():
    time.sleep(0.005)
f = compile_function(step, flags=['-O1'])
print(float(np.asarray(f(x=[1, 2, 3, 0.1, 0.01], P=np.eye(5), u_prev=[], u=[], y=[1, 2], mask=[1, 1], dt=0.05,
                             p=m.params(), Q=np.diag([1e-2, 1e-3]), R=np.eye(2), gate=1e300)['x']).sum()))
"""


def test_concurrent_compiles_from_several_processes_give_one_valid_library(cache, tmp_path):
    go = tmp_path / "go"
    ready = [tmp_path / f"ready{i}" for i in range(3)]
    procs = [subprocess.Popen([sys.executable, "-c", CONCURRENT, str(r), str(go)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=os.environ.copy(), cwd=ROOT) for r in ready]
    deadline = time.monotonic() + 300
    while not all(r.exists() for r in ready) and time.monotonic() < deadline and all(p.poll() is None for p in procs):
        time.sleep(0.01)
    go.touch()
    outs = [p.communicate(timeout=600) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1][-500:] for o in outs]
    assert len({o[0].strip() for o in outs}) == 1                 # the same numbers everywhere
    libs, records = _entry_files(cache)
    assert len(libs) == 1 and len(records) == 1
    assert json.loads(records[0].read_text())["sha256"] == _sha(libs[0])
    assert not [f for f in cache.iterdir() if f.name.startswith("casship-cc-")]


# -- the command ---------------------------------------------------------------------------------------------------
def test_cache_command_info_and_clear(cache, capsys):
    rt.compile_function(_twice("cmd_thing"), flags=["-O1"])
    (cache / "keep.txt").write_text("not the cache's")
    assert cli_main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert str(cache) in out and "entries: 1" in out and "cmd_thing: 1" in out
    assert "compiler: " in out and "flags: " in out and "online update: " in out and "record loop: " in out
    assert cli_main(["cache", "clear"]) == 0
    assert "removed 2 file(s)" in capsys.readouterr().out          # library and record
    assert sorted(f.suffix for f in cache.iterdir()) == [".lock", ".txt"]    # and the (empty) lock stays
    assert cli_main(["cache", "info", "--dir", str(cache / "nowhere")]) == 0
    assert "entries: 0" in capsys.readouterr().out


def test_estimator_jit_goes_through_the_cache(cache):
    m = cs.models.sog_cog(0.01, 0.1)
    dm = cs.discretize(m, 0.02, method="euler")
    ekf = cs.EKF(dm, np.diag([1e-2, 1e-3]), np.eye(2), options={"jit": True})
    traj = cs.simulate(m, m.states(U=3.0, chi=0.3), np.arange(0.0, 4.0, 0.02), method="euler")
    data = cs.measure(traj, m, {"x_n": 1.0, "y_n": 1.0}, seed=0)
    prior = cs.Gaussian(m.states(U=2.5, chi=0.2), [4.0, 4.0, 1.0, 0.05, 1e-3])
    res = ekf.filter(data, prior)
    assert "ekf_step" in rt.cache_info().functions                # the step, compiled with its record loop
    ref = cs.EKF(dm, np.diag([1e-2, 1e-3]), np.eye(2)).filter(data, prior)
    np.testing.assert_allclose(res.x, ref.x, rtol=1e-11, atol=1e-11)
