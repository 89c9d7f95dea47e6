"""Export estimator steps (or any CasADi Function) as standalone C source and header.

The exported code is CasADi's code generation of the very Function that casship evaluates in
Python, so an onboard computer runs the same arithmetic. The generated C has no dependency beyond
the C standard library and ``libm``.

Calling convention (for a function exported as ``NAME``; all arrays ``casadi_real`` = ``double``,
matrices stored column-major, every input and output dense)::

    #include "NAME.h"
    const casadi_real *arg[NAME_SZ_ARG];   /* arg[i] points at input i  */
    casadi_real *res[NAME_SZ_RES];         /* res[i] points at output i */
    casadi_int iw[NAME_SZ_IW];             /* integer work space        */
    casadi_real w[NAME_SZ_W];              /* real work space           */
    int mem = NAME_checkout();
    int status = NAME(arg, res, iw, w, mem);   /* 0 on success */
    NAME_release(mem);

Sizes and names of the inputs and outputs are listed in a comment at the top of ``NAME.h`` and
queried at run time with ``NAME_n_in()``, ``NAME_name_in(i)``, ``NAME_sparsity_in(i)``.
For an estimator step the inputs are its memory slots (``x, P`` for the Kalman family), then
``u_prev, u, y, mask, dt, p, Q, R, gate``; the outputs are the memory slots under the same names,
then the diagnostics chosen when exporting (see :mod:`casship.estimators.base`).
``export_estimator`` also writes ``NAME_data.h`` with the estimator's parameter vector, ``Q``,
``R`` and the measured channel names.
"""
from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np

from ._buffers import DUPLICATE_NAMES
from ._compiler import CompileError, run_compiler
from ..errors import InputError, InputTypeError

__all__ = ["CFiles", "generate_c", "export_estimator", "export_mhe_rti", "write_harness", "compile_c",
           "read_harness_output"]


@dataclass(frozen=True)
class CFiles:
    """The files of one exported Function and its argument layout.

    Parameters
    ----------
    name : str
        C name of the function.
    source, header : Path
        The generated ``NAME.c`` and ``NAME.h``.
    inputs, outputs : tuple of (name, (rows, cols))
        The Function's slots in call order.
    data_header : Path or None
        ``NAME_data.h`` of an exported estimator (its numbers and names).
    """

    name: str
    source: Path
    header: Path
    inputs: tuple[tuple[str, tuple[int, int]], ...]     # (name, (rows, cols)) in call order
    outputs: tuple[tuple[str, tuple[int, int]], ...]
    data_header: Path | None = None

    @property
    def sizes_in(self) -> list[int]:
        """Number of entries of each input."""
        return [r * c for _, (r, c) in self.inputs]

    @property
    def sizes_out(self) -> list[int]:
        """Number of entries of each output."""
        return [r * c for _, (r, c) in self.outputs]


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name.isidentifier() or not name.isascii():
        raise InputError(f"C function name {name!r} is not a valid C identifier")
    return name


def _dense_copy(fun: ca.Function, name: str) -> ca.Function:
    """``fun`` under a new name with every output densified (structural zeros stored)."""
    ins = fun.sx_in() if fun.is_a("SXFunction") else fun.mx_in()
    outs = [ca.densify(o) for o in fun.call(ins)]
    for i in range(fun.n_in()):
        if not fun.sparsity_in(i).is_dense():
            raise InputError(f"{fun.name()}: input {fun.name_in(i)!r} is not dense; cannot export")
    return ca.Function(name, ins, outs, fun.name_in(), fun.name_out(), DUPLICATE_NAMES)


def _layout_comment(fun: ca.Function, title: str) -> str:
    lines = [f"/* {title}", " *", f" * int {fun.name()}(const casadi_real** arg, casadi_real** res, "
             "casadi_int* iw, casadi_real* w, int mem);", " *",
             " * inputs (dense, column-major):"]
    for i in range(fun.n_in()):
        r, c = fun.size_in(i)
        lines.append(f" *   arg[{i}] {fun.name_in(i):<10s} {r} x {c}")
    lines.append(" * outputs (dense, column-major):")
    for i in range(fun.n_out()):
        r, c = fun.size_out(i)
        lines.append(f" *   res[{i}] {fun.name_out(i):<10s} {r} x {c}")
    lines += [" * Work arrays: NAME_SZ_ARG, NAME_SZ_RES, NAME_SZ_IW, NAME_SZ_W entries (see below).",
              " * Returns 0 on success.", " */", ""]
    return "\n".join(lines).replace("NAME", fun.name())


def generate_c(fun: ca.Function, directory, name: str | None = None, *, title: str = "") -> CFiles:
    """Write ``NAME.c`` and ``NAME.h`` for the CasADi Function ``fun`` into ``directory``.

    Parameters
    ----------
    fun : casadi.Function
        Any Function with dense inputs (e.g. an estimator's ``step``). Functions that
        embed a CVODES integrator or an external solver cannot be exported.
    directory : path
        Created if missing.
    name : str, optional
        C name of the function (default: ``fun.name()``).
    title : str
        First line of the layout comment written at the top of the header.

    Returns
    -------
    CFiles

    Examples
    --------
    >>> import casship as cs
    >>> from casship.runtime import generate_c
    >>> ekf = cs.EKF(cs.discretize(cs.models.nomoto_first_order(), 0.1), Q=1e-8, R=1e-4)
    >>> files = generate_c(ekf.step, "build", "ekf_step")     # doctest: +SKIP
    """
    if not isinstance(fun, ca.Function):
        raise InputTypeError(f"generate_c needs a casadi.Function, got {type(fun).__name__}")
    name = _check_name(name or fun.name())
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    dense = _dense_copy(fun, name)
    gen = ca.CodeGenerator(f"{name}.c", {"with_header": True})
    try:
        gen.add(dense)
        source = Path(gen.generate(str(directory) + "/"))
    except RuntimeError as exc:
        raise InputError(f"{fun.name()} cannot be exported as C (it may embed an integrator such as CVODES "
                         f"or an external solver; discretise with 'rk4' or 'euler'): {exc}") from None
    header = directory / f"{name}.h"
    unsupported = [ln.split("for", 1)[-1].strip() for ln in source.read_text().splitlines()
                   if "#error Code generation not supported" in ln]
    if unsupported:
        source.unlink()
        header.unlink(missing_ok=True)
        raise InputError(f"{fun.name()} cannot be exported as C: it embeds {', '.join(sorted(set(unsupported)))}, "
                         "which CasADi cannot generate (discretise with 'rk4' or 'euler' instead of 'cvodes')")
    header.write_text(_layout_comment(dense, title or f"{name}: generated by casship from a CasADi Function")
                      + header.read_text())
    shape = lambda f, i, out: tuple(int(s) for s in (f.size_out(i) if out else f.size_in(i)))  # noqa: E731
    return CFiles(name, source, header,
                  tuple((dense.name_in(i), shape(dense, i, False)) for i in range(dense.n_in())),
                  tuple((dense.name_out(i), shape(dense, i, True)) for i in range(dense.n_out())))


def _c_array(ctype: str, name: str, values) -> str:
    values = np.asarray(values, dtype=float).reshape(-1, order="F")
    body = ", ".join(f"{v:.17g}" for v in values) if values.size else "0"
    return f"CASSHIP_UNUSED static const {ctype} {name}[{max(values.size, 1)}] = {{{body}}};\n"


def export_estimator(estimator, directory, name: str | None = None, p=None, outputs=None) -> CFiles:
    """Export an estimator's step Function as C, plus ``NAME_data.h`` with its numbers.

    Parameters
    ----------
    estimator : Estimator
    directory : path
    name : str, optional
        C name (default ``<estimator>_step``).
    p : array or mapping, optional
        Parameter vector written to the data header (nominal by default).
    outputs : sequence of str or "all", optional
        Diagnostics the exported step returns besides its memory (default: the estimator's
        ``outputs`` option, ``x`` and ``P`` unless asked otherwise); only these are computed.

    The data header holds the dimensions (``NAME_NX``, ``NAME_NU``, ``NAME_NY``, ...), the size of
    each memory slot (``NAME_SIZE_x``, ``NAME_SIZE_P``, ...), the parameter vector ``NAME_p``, the
    covariances ``NAME_Q`` and ``NAME_R`` (column-major) and the measured channel and state names
    in order, so that an onboard program can assemble the step's inputs without Python.
    """
    step_function = getattr(estimator, "step_function", None)
    if not callable(step_function):
        raise InputTypeError(f"{type(estimator).__name__} has no step Function to export")
    fun = step_function(outputs)
    model = estimator.model
    name = _check_name(name or f"{type(estimator).__name__.lower()}_step")
    title = (f"{name}: {type(estimator).__name__} step of model '{model.name}' "
             f"(states {', '.join(model.state_names)}; measured {', '.join(estimator.measured)})")
    files = generate_c(fun, directory, name, title=title)
    pvec = model.params() if p is None else model.params(p)
    guard = f"{name.upper()}_DATA_H"
    strings = lambda names: "{" + ", ".join(f'"{n}"' for n in names) + "}"  # noqa: E731
    text = (f"/* Numbers of the exported {type(estimator).__name__} '{name}' (model '{model.name}'). */\n"
            f"#ifndef {guard}\n#define {guard}\n\n"
            "#ifndef CASSHIP_UNUSED\n#if defined(__GNUC__)\n#define CASSHIP_UNUSED __attribute__((unused))\n"
            "#else\n#define CASSHIP_UNUSED\n#endif\n#endif\n\n"
            f"#define {name}_NX {model.nx}\n#define {name}_NU {model.nu}\n#define {name}_NP {model.np}\n"
            f"#define {name}_NW {model.nw}\n#define {name}_NY {estimator.ny}\n"
            + "".join(f"#define {name}_SIZE_{slot} {fun.nnz_in(slot)}\n" for slot in estimator.memory) + "\n"
            + _c_array("double", f"{name}_p", pvec) + _c_array("double", f"{name}_Q", estimator.Q)
            + _c_array("double", f"{name}_R", estimator.R)
            + f"CASSHIP_UNUSED static const char *const {name}_states[{max(model.nx, 1)}] = {strings(model.state_names)};\n"
            + f"CASSHIP_UNUSED static const char *const {name}_measured[{max(estimator.ny, 1)}] = {strings(estimator.measured)};\n"
            + f"\n#endif /* {guard} */\n")
    data = files.source.parent / f"{name}_data.h"
    data.write_text(text)
    return CFiles(files.name, files.source, files.header, files.inputs, files.outputs, data)


def export_mhe_rti(mhe, directory, name: str | None = None) -> CFiles:
    """Export the real-time-iteration step of a moving-horizon estimator's window as C.

    Parameters
    ----------
    mhe : MHE
        A moving-horizon estimator (its ``horizon`` sets ``N``).
    directory : path
        Created if missing.
    name : str, optional
        C name (default ``mhe_rti_step_<N>``).

    The exported function is ``NAME(z, p) -> z_next``: one Gauss-Newton step of the window problem
    of :class:`casship.MHE` (horizon ``N`` = the estimator's ``horizon`` option), solving the
    equality-constrained Gauss-Newton problem (what ``solver="rti"`` does when no bound is active:
    with option ``jit`` by a Riccati recursion over the stages, else through a sparse QR
    factorisation of the KKT system). The layouts (column-major throughout):

    * ``z``: for each stage ``j = 0 .. N-1`` the state ``x_j`` (nx) and whitened process noise
      ``v_j`` (nv), then ``x_N``;
    * ``p``: ``xbar`` (nx, arrival-cost mean), ``W`` (nx x nx, arrival-cost whitening
      ``P^-1/2``), ``U`` (nu x N+1), ``U_prev`` (nu x N), ``Y`` (ny x N+1, 0 where missing),
      ``M`` (ny x N+1 mask), ``dt`` (1 x N), the model parameters (np).

    The arrival cost of the next window comes from the EKF step running alongside the MHE, which
    :func:`export_estimator` exports (``mhe.arrival_filter``). Bounds on states or noise need the QP
    solver and are not part of this export.
    """
    if type(mhe).__name__ != "MHE" or not hasattr(mhe, "window"):
        raise InputTypeError(f"export_mhe_rti needs a casship.MHE, got {type(mhe).__name__}")
    N = mhe.horizon
    window = mhe.window(N, "rti")
    name = _check_name(name or f"mhe_rti_step_{N}")
    m = mhe.model
    title = (f"{name}: MHE real-time-iteration step, model '{m.name}', horizon N = {N} "
             f"(nx = {m.nx}, nv = {mhe.nv}, nu = {m.nu}, ny = {mhe.ny}, np = {m.np}; "
             f"measured {', '.join(mhe.measured)}). z = [x_0 v_0 ... x_N-1 v_N-1 x_N]; "
             "p = [xbar, W, U, U_prev, Y, M, dt, params]")
    return generate_c(window.gn().fun, directory, name, title=title)


HARNESS = r"""/* Test harness for {name}: reads input sets from stdin, prints the outputs.
 * Each set is {n_total} numbers (all inputs, in order, column-major; "inf" allowed);
 * for each set one line per output with its entries in %.17g. Stops at end of input. */
#include <stdio.h>
#include <stdlib.h>
#include "{name}.h"

int main(void) {{
    static const int size_in[{n_in}] = {{{sizes_in}}};
    static const int size_out[{n_out}] = {{{sizes_out}}};
    static casadi_real in_buf[{n_total_alloc}], out_buf[{n_total_out_alloc}];
    const casadi_real *arg[{name}_SZ_ARG > {n_in} ? {name}_SZ_ARG : {n_in}];
    casadi_real *res[{name}_SZ_RES > {n_out} ? {name}_SZ_RES : {n_out}];
    static casadi_int iw[{name}_SZ_IW + 1];
    static casadi_real w[{name}_SZ_W + 1];
    int i, j, k, pos, mem, status, sets = 0;
    for (i = 0, pos = 0; i < {n_in}; pos += size_in[i], i++) arg[i] = in_buf + pos;
    for (i = 0, pos = 0; i < {n_out}; pos += size_out[i], i++) res[i] = out_buf + pos;
    mem = {name}_checkout();
    for (;;) {{
        for (k = 0; k < {n_total}; k++) {{
            char token[64];
            if (scanf("%63s", token) != 1) {{
                if (k == 0) {{ {name}_release(mem); return sets > 0 ? 0 : 3; }}
                fprintf(stderr, "incomplete input set %d\n", sets);
                return 2;
            }}
            in_buf[k] = strtod(token, NULL);
        }}
        status = {name}(arg, res, iw, w, mem);
        if (status) {{ fprintf(stderr, "{name} returned %d\n", status); return 1; }}
        for (i = 0, pos = 0; i < {n_out}; i++) {{
            for (j = 0; j < size_out[i]; j++, pos++) printf(j ? " %.17g" : "%.17g", out_buf[pos]);
            printf("\n");
        }}
        sets++;
    }}
}}
"""


def write_harness(files: CFiles, path=None) -> Path:
    """Write a small C program (``main``) that evaluates the exported function on stdin input sets.

    Parameters
    ----------
    files : CFiles
        The exported function.
    path : path, optional
        Where to write the program (default ``NAME_harness.c`` beside the source).

    Input: whitespace-separated numbers, one set = all inputs in call order (column-major). Output:
    for every set, one line per output. Used by the test suite to compare C with Python.
    """
    path = Path(path) if path is not None else files.source.parent / f"{files.name}_harness.c"
    n_total, n_out_total = sum(files.sizes_in), sum(files.sizes_out)
    path.write_text(HARNESS.format(
        name=files.name, n_in=len(files.inputs), n_out=len(files.outputs),
        sizes_in=", ".join(map(str, files.sizes_in)), sizes_out=", ".join(map(str, files.sizes_out)),
        n_total=n_total, n_total_alloc=max(n_total, 1), n_total_out_alloc=max(n_out_total, 1)))
    return path


def compile_c(sources: Sequence, output, compiler: str | None = None,
              flags: Sequence[str] = ("-O2", "-ffp-contract=off", "-std=c99")) -> Path:
    """Compile C ``sources`` into the executable ``output`` (``gcc`` by default), linking ``libm``.

    Parameters
    ----------
    sources : sequence of path
    output : path
        The executable to write.
    compiler : str, optional
        Compiler command (default ``gcc``, else ``cc``).
    flags : sequence of str
        Compiler flags.

    ``-ffp-contract=off`` keeps the compiler from fusing multiply-adds, so results match CasADi's
    own evaluation to the last bits. Raises ``FileNotFoundError`` without a compiler and
    :class:`CompileError` (a ``RuntimeError``) with the compiler's messages when compilation fails
    or takes longer than ``$CASSHIP_COMPILE_TIMEOUT`` seconds.
    """
    cc = compiler or shutil.which("gcc") or shutil.which("cc")
    if not cc:
        raise FileNotFoundError("no C compiler found (gcc or cc)")
    output = Path(output)
    cmd = [cc, *flags, "-o", str(output), *[str(s) for s in sources], "-lm"]
    proc = run_compiler(cmd, str(output))
    if proc.returncode != 0:
        raise CompileError(f"C compilation failed ({' '.join(cmd)}):\n{proc.stderr}")
    return output


def read_harness_output(text: str, files: CFiles) -> list[list[np.ndarray]]:
    """Parse the harness output into one list of arrays (shaped like the outputs) per input set.

    Parameters
    ----------
    text : str
        What the harness printed.
    files : CFiles
        The exported function (its output shapes).
    """
    lines = text.splitlines()          # an output without entries prints an empty line
    n_out = len(files.outputs)
    if len(lines) % n_out:
        raise ValueError(f"harness printed {len(lines)} lines, not a multiple of {n_out} outputs")
    sets = []
    for s in range(len(lines) // n_out):
        outs = []
        for i, (_, (r, c)) in enumerate(files.outputs):
            vals = np.array([float(v) for v in lines[s * n_out + i].split()])
            outs.append(vals.reshape((r, c), order="F"))
        sets.append(outs)
    return sets
