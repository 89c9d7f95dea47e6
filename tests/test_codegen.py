"""C export of estimator steps: generated code compiled with gcc equals the Python evaluation."""
import shutil
import subprocess

import numpy as np
import pytest

import casship as cs
from casship.estimators import export_estimator
from casship.runtime import compile_c, generate_c, read_harness_output, write_harness
from casship.estimators.base import SAMPLE_INPUTS

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="gcc is not installed: C export not compiled")


def heading_ekf(gate=None, cls=None):
    """EKF (or ``cls``) on the Shi et al. model with kinematics: angle output (wrapped residual)."""
    m = cs.models.shi_taylor().with_outputs(["u", "r", "psi"])
    dm = cs.discretize(m, 0.5, method="rk4", substeps=2)
    return (cls or cs.EKF)(dm, Q=np.diag([1e-4, 1e-4, 1e-6]), R={"u": 0.01, "r": 1e-5, "psi": 1e-4},
                           options={"gate": gate})


def step_inputs(ekf, seed=0, n=12):
    """Named input sets of consecutive filter steps (memory from the Python filter), some channels missing."""
    m = ekf.model
    t = np.arange(n) * 0.5
    truth = cs.simulate(m, m.states(u=7.0, psi=3.1), t, {"delta": 0.2 * np.sin(t / 2.0), "n": 1.5})
    data = cs.measure(truth, m, {"u": 0.1, "r": 3e-3, "psi": 1e-2}, seed=seed)
    y = data.matrix(ekf.measured).copy()
    y[3, 0] = np.nan                      # a missing speed sample
    y[5, :] = np.nan                      # a row with nothing measured
    data = data.with_columns(**{name: y[:, i] for i, name in enumerate(ekf.measured)})
    prior = cs.Gaussian(m.states(u=6.5, psi=3.0), np.diag([1.0, 0.1, 1e-4, 10.0, 10.0, 0.1]))
    res = ekf.filter(data, prior)
    arrays = ekf.prepare(data)
    sets = []
    for k in range(n):
        args = {"x": prior.mean, "P": prior.cov} if k == 0 else {"x": res.x[k - 1], "P": res.P[k - 1]}
        args.update({name: arrays[name][:, k] for name in SAMPLE_INPUTS})
        args.update({name: arrays[name] for name in ("p", "Q", "R")})
        sets.append(args)
    return sets, res


def python_outputs(fun, args):
    out = fun.call(args)
    return [np.array(out[name]) for name in fun.name_out()]


@needs_gcc
@pytest.mark.parametrize("gate, cls", [(None, cs.EKF), (0.999, cs.EKF), (0.999, cs.UKF)],
                         ids=["ekf", "ekf-gated", "ukf-gated"])
def test_compiled_estimator_step_equals_python(tmp_path, gate, cls):
    ekf = heading_ekf(gate, cls)
    files = export_estimator(ekf, tmp_path, "est_step", outputs="all")
    fun = ekf.step_function("all")
    assert [n for n, _ in files.outputs] == fun.name_out()
    exe = compile_c([write_harness(files), files.source], tmp_path / "harness")
    sets, res = step_inputs(ekf)
    text = "\n".join(" ".join(f"{v:.17g}" for v in np.concatenate([np.ravel(args[n], order="F") for n in fun.name_in()]))
                     for args in sets)
    proc = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
    c_sets = read_harness_output(proc.stdout, files)
    assert len(c_sets) == len(sets)
    worst = 0.0
    for args, c_out in zip(sets, c_sets):
        for (name, _), py, c in zip(files.outputs, python_outputs(fun, args), c_out):
            py = py.reshape(c.shape, order="F") if py.size == c.size else py
            assert c.shape == py.shape, name
            worst = max(worst, float(np.max(np.abs(c - py) / np.maximum(1.0, np.abs(py)), initial=0.0)))
    print(f"max relative difference C vs Python: {worst:.3g}")
    assert worst <= 1e-12
    # the C outputs reproduce the Python filter's estimates as well
    ix, iP = fun.index_out("x"), fun.index_out("P")
    np.testing.assert_allclose(np.array([c[ix].ravel() for c in c_sets]), res.x, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(np.array([c[iP] for c in c_sets]), res.P, rtol=1e-12, atol=1e-12)


def test_generated_files_document_the_layout(tmp_path):
    ekf = heading_ekf()
    files = export_estimator(ekf, tmp_path, "nav_ekf")
    header = files.header.read_text()
    assert "int nav_ekf(const casadi_real** arg" in header
    assert "arg[0] x          6 x 1" in header and "arg[1] P          6 x 6" in header
    assert "arg[10] gate       1 x 1" in header
    assert "res[1] P          6 x 6" in header and "res[2]" not in header     # lean by default: x and P
    assert [n for n, _ in files.inputs] == ["x", "P", "u_prev", "u", "y", "mask", "dt", "p", "Q", "R", "gate"]
    data = files.data_header.read_text()
    assert "#define nav_ekf_NX 6" in data and "#define nav_ekf_NY 3" in data
    assert "#define nav_ekf_SIZE_x 6" in data and "#define nav_ekf_SIZE_P 36" in data
    assert '{"u", "r", "psi"}' in data
    # the data header's numbers are the estimator's
    q = data.split("nav_ekf_Q[9] = {")[1].split("}")[0]
    np.testing.assert_array_equal([float(v) for v in q.split(",")], ekf.Q.ravel(order="F"))


def test_export_rejects_what_cannot_be_generated(tmp_path):
    m = cs.models.nomoto_first_order()
    with pytest.raises(ValueError, match="cannot be exported as C"):
        generate_c(cs.discretize(m, 0.1, method="cvodes").F, tmp_path, "cvodes_step")
    ekf = cs.EKF(cs.discretize(m, 0.1), Q=1e-8, R=1e-4)
    with pytest.raises(ValueError, match="not a valid C identifier"):
        generate_c(ekf.step, tmp_path, "ekf-step")
    with pytest.raises(TypeError, match="needs a casadi.Function"):
        generate_c(ekf, tmp_path)
    with pytest.raises(TypeError, match="has no step Function"):
        export_estimator(m, tmp_path)


@needs_gcc
def test_compile_errors_are_reported(tmp_path):
    bad = tmp_path / "bad.c"
    bad.write_text("int main(void) { return undefined_symbol; }\n")
    with pytest.raises(RuntimeError, match="C compilation failed"):
        compile_c([bad], tmp_path / "bad")


@needs_gcc
def test_the_onboard_loop_in_the_docs_compiles_and_runs(tmp_path, monkeypatch):
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "codegen.md").read_text()
    monkeypatch.chdir(tmp_path)
    exec(re.findall(r"```python\n(.*?)```", text, re.S)[0], {})
    (tmp_path / "main.c").write_text(re.findall(r"```c\n(.*?)```", text, re.S)[1])
    exe = compile_c([tmp_path / "main.c", tmp_path / "build" / "heading_ekf.c"], tmp_path / "onboard",
                    flags=("-O2", "-ffp-contract=off", "-std=c99", "-Wall", "-Werror", f"-I{tmp_path / 'build'}"))
    out = subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout
    assert out.startswith("psi = ") and "nan" not in out


@needs_gcc
def test_compiled_mhe_rti_step_equals_python(tmp_path):
    from casship.estimators import export_mhe_rti

    m = cs.models.nomoto_first_order()
    mhe = cs.MHE(cs.discretize(m, 0.5), Q=1e-6, R=1e-4, options={"horizon": 8, "solver": "rti"})
    files = export_mhe_rti(mhe, tmp_path)
    assert files.name == "mhe_rti_step_8" and "horizon N = 8" in files.header.read_text()
    exe = compile_c([write_harness(files), files.source], tmp_path / "mhe_harness")
    fun = mhe.window(8, "rti").gn_step.fun
    nz, npar = fun.size1_in(0), fun.size1_in(1)
    rng = np.random.default_rng(4)
    sets = []
    for _ in range(5):
        z = rng.normal(scale=0.05, size=nz)
        xbar = rng.normal(scale=0.05, size=m.nx)
        W = np.diag(1.0 / rng.uniform(0.01, 0.1, m.nx))
        rest = npar - m.nx - m.nx**2 - m.np
        data = rng.uniform(0.0, 1.0, rest)
        sets.append(np.concatenate([z, xbar, W.ravel(order="F"), data, m.params()]))
    text = "\n".join(" ".join(f"{v:.17g}" for v in s) for s in sets)
    out = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True).stdout
    for s, (c,) in zip(sets, read_harness_output(out, files)):
        py = np.array(fun(s[:nz], s[nz:])).ravel()
        np.testing.assert_allclose(c.ravel(), py, rtol=1e-12, atol=1e-12 * np.abs(py).max())
    with pytest.raises(TypeError, match="needs a casship.MHE"):
        export_mhe_rti(heading_ekf(), tmp_path)
