"""Estimators as standalone C: a step estimator's step with its numbers, the MHE's real-time-iteration step.

The C is CasADi's code generation of the very Function casship evaluates in Python
(:func:`casship.runtime.generate_c`; calling convention in ``docs/codegen.md``), so an onboard computer
runs the same arithmetic.

For an estimator step the inputs are its memory slots (``x, P`` for the Kalman family), then
``u_prev, u, y, mask, dt, p, Q, R, gate``; the outputs are the memory slots under the same names,
then the diagnostics chosen when exporting (see :mod:`casship.estimators.base`).
:func:`export_estimator` also writes ``NAME_data.h`` with the estimator's parameter vector, ``Q``,
``R`` and the measured channel names.
"""
from __future__ import annotations

from ..runtime import CFiles, c_array, check_c_name, generate_c
from .mhe import MHE
from ..errors import InputTypeError

__all__ = ["export_estimator", "export_mhe_rti"]


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
    name = check_c_name(name or f"{type(estimator).__name__.lower()}_step")
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
            + c_array("double", f"{name}_p", pvec) + c_array("double", f"{name}_Q", estimator.Q)
            + c_array("double", f"{name}_R", estimator.R)
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
    if not isinstance(mhe, MHE):
        raise InputTypeError(f"export_mhe_rti needs a casship.MHE, got {type(mhe).__name__}")
    N = mhe.horizon
    window = mhe.window(N, "rti")
    name = check_c_name(name or f"mhe_rti_step_{N}")
    m = mhe.model
    title = (f"{name}: MHE real-time-iteration step, model '{m.name}', horizon N = {N} "
             f"(nx = {m.nx}, nv = {mhe.nv}, nu = {m.nu}, ny = {mhe.ny}, np = {m.np}; "
             f"measured {', '.join(mhe.measured)}). z = [x_0 v_0 ... x_N-1 v_N-1 x_N]; "
             "p = [xbar, W, U, U_prev, Y, M, dt, params]")
    return generate_c(window.gn().fun, directory, name, title=title)
