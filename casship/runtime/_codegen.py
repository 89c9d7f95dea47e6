"""Export any CasADi Function as standalone C source and header (estimators export theirs through
:mod:`casship.estimators.export`).

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

__all__ = ["CFiles", "generate_c", "write_harness", "compile_c", "read_harness_output", "c_array", "check_c_name"]


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


def check_c_name(name: str) -> str:
    """``name`` if it is a valid C identifier, else ``ValueError`` naming it."""
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
    name = check_c_name(name or fun.name())
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


def c_array(ctype: str, name: str, values) -> str:
    """A C array definition ``static const ctype name[] = {...}`` of ``values`` (column-major, 17 digits).

    Parameters
    ----------
    ctype, name : str
    values : array_like
    """
    values = np.asarray(values, dtype=float).reshape(-1, order="F")
    body = ", ".join(f"{v:.17g}" for v in values) if values.size else "0"
    return f"CASSHIP_UNUSED static const {ctype} {name}[{max(values.size, 1)}] = {{{body}}};\n"


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
