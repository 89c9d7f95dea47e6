"""An online update that Python calls straight into compiled code.

An online update from Python through CasADi's buffers still costs a few microseconds of Python per
sample (checking three arrays, copying them into the bound buffers, triggering the call, reading
the status, copying the mean out), several times the arithmetic of a small filter step. Here the
online step Function is compiled together with a small C entry point written against the Python
and NumPy C APIs: ``update(y, dt, u_prev=None, u=None)`` reads the arrays where they are, calls the
step on the bound buffers, flips the two buffer sets and returns a new array with the mean.

The C entry point takes only the plain case: float64 vectors of the right length (any stride), a
float or int ``dt`` within the one-step gap limit, no keywords, a valid sample. Everything else,
including every error, goes to the checked Python update it was given (``fallback``), which
therefore decides all the messages. Both work on the same buffers and the same state (which buffer
set holds the memory, how many samples were taken), so the two can alternate freely.

It needs the Python and NumPy headers at compile time; where they are missing,
:func:`compile_update` returns None and the online runner keeps to the Python update.
"""
from __future__ import annotations

import ctypes
import os
import sys
import sysconfig

import casadi as ca
import numpy as np

from .compile import compile_function

__all__ = ["NativeUpdate", "compile_update", "update_source"]

# the order of the addresses handed to the C factory
ADDRESSES = ("arg0", "arg1", "res0", "res1", "iw", "w", "y", "dt", "u_prev", "u", "held0", "held1",
             "x0", "x1", "status0", "status1", "state", "gap_limit")


def update_source(name: str, nx: int, ny: int, nu: int) -> str:
    """C source of ``casship_update_new_<name>``, the factory of the compiled ``update``.

    The factory ``(fallback, keep, addresses)`` returns a builtin function. ``addresses`` are the
    :data:`ADDRESSES` in order: per buffer set ``c`` the argument and result pointer tables of the
    step, its work arrays, the input buffers ``y``, ``dt``, ``u_prev`` and ``u`` (shared by both
    sets), per set the outputs ``u_held``, ``x`` and ``status``, the state ``[set holding the
    memory's inputs, samples]`` (int64) and the gap limit. ``keep`` is held while the function lives
    (the owner of that memory); ``fallback`` gets every call the C code does not take.

    Parameters
    ----------
    name : str
        The C name of the generated online step.
    nx, ny, nu : int
        Its numbers of states, measured outputs and inputs.
    """
    if not name.isidentifier():
        raise ValueError(f"a step compiled with an update entry needs a C identifier as its name, got {name!r}")
    # the versions are in the source so that the cache key changes with them
    return f"""

/* casship: the online update of the step above, called from Python
   (Python {sys.version.split()[0]}, NumPy {np.__version__}) */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <stdint.h>
#include <string.h>

#define CS_NX {nx}
#define CS_NY {ny}
#define CS_NU {nu}

typedef struct {{
  const casadi_real** arg_table[2];
  casadi_real** res_table[2];
  casadi_int* iw;
  casadi_real* w;
  casadi_real *y, *dt, *u_prev, *u;
  const casadi_real *held[2], *x[2], *status[2];
  long long* state;
  const casadi_real* gap_limit;
  PyObject *fallback, *keep;
}} cs_update_t;

/* a float64 vector of n entries, copied into dst; 0 (nothing known) for anything else */
static int cs_read(PyObject* o, casadi_real* dst, npy_intp n) {{
  PyArrayObject* a;
  const char* p;
  npy_intp i, s;
  if (!PyArray_CheckExact(o)) return 0;
  a = (PyArrayObject*)o;
  if (PyArray_NDIM(a) != 1 || PyArray_DIM(a, 0) != n || PyArray_TYPE(a) != NPY_DOUBLE
      || !PyArray_ISNOTSWAPPED(a) || !PyArray_ISALIGNED(a)) return 0;
  p = PyArray_BYTES(a);
  s = PyArray_STRIDE(a, 0);
  for (i = 0; i < n; ++i) dst[i] = *(const double*)(p + i * s);
  return 1;
}}

static PyObject* cs_update(PyObject* self, PyObject* const* given, Py_ssize_t nargs, PyObject* kwnames) {{
  cs_update_t* st = (cs_update_t*)PyCapsule_GetPointer(self, "casship.update");
  PyObject *y_in, *dt_in, *u_prev_in, *u_in;
  long long cur;
  double dt;
  npy_intp nx = CS_NX;
  PyObject* x;
  if (st == NULL) return NULL;
  if (kwnames != NULL || nargs < 2 || nargs > 4) goto checked;
  y_in = given[0];
  dt_in = given[1];
  u_prev_in = nargs > 2 ? given[2] : Py_None;
  u_in = nargs > 3 ? given[3] : Py_None;
  if (PyFloat_Check(dt_in)) {{
    dt = PyFloat_AS_DOUBLE(dt_in);
  }} else if (PyLong_CheckExact(dt_in)) {{
    dt = PyLong_AsDouble(dt_in);
    if (dt == -1.0 && PyErr_Occurred()) {{ PyErr_Clear(); goto checked; }}
  }} else {{
    goto checked;
  }}
  if (!(dt >= 0 && dt <= st->gap_limit[0])) goto checked;
  if (!cs_read(y_in, st->y, CS_NY)) goto checked;
  cur = st->state[0];
#if CS_NU > 0
  if (u_prev_in != Py_None) {{
    if (!cs_read(u_prev_in, st->u_prev, CS_NU)) goto checked;
  }} else {{
    memcpy(st->u_prev, st->held[1 - cur], CS_NU * sizeof(casadi_real));
  }}
  if (u_in != Py_None) {{
    if (!cs_read(u_in, st->u, CS_NU)) goto checked;
  }} else {{
    memcpy(st->u, st->u_prev, CS_NU * sizeof(casadi_real));
  }}
#endif
  st->dt[0] = dt;
  /* a failed or invalid sample is left to the checked update, which says what is wrong */
  if ({name}(st->arg_table[cur], st->res_table[cur], st->iw, st->w, 0) || st->status[cur][0] != 0) goto checked;
  x = PyArray_SimpleNew(1, &nx, NPY_DOUBLE);
  if (x == NULL) return NULL;
  memcpy(PyArray_DATA((PyArrayObject*)x), st->x[cur], CS_NX * sizeof(casadi_real));
  st->state[0] = 1 - cur;
  st->state[1] += 1;
  return x;
checked:
  return PyObject_Vectorcall(st->fallback, given, nargs, kwnames);
}}

static void cs_release(PyObject* capsule) {{
  cs_update_t* st = (cs_update_t*)PyCapsule_GetPointer(capsule, "casship.update");
  if (st == NULL) return;
  Py_XDECREF(st->fallback);
  Py_XDECREF(st->keep);
  PyMem_Free(st);
}}

static PyMethodDef cs_update_def = {{"update", (PyCFunction)(void (*)(void))cs_update,
  METH_FASTCALL | METH_KEYWORDS, "update(y, dt, u_prev=None, u=None) -> x (see OnlineRun.update)"}};

CASADI_SYMBOL_EXPORT PyObject* casship_update_new_{name}(PyObject* fallback, PyObject* keep,
    const uint64_t* a) {{
  cs_update_t* st;
  PyObject *capsule, *f;
  if (PyArray_API == NULL && _import_array() < 0) return NULL;
  st = (cs_update_t*)PyMem_Calloc(1, sizeof(cs_update_t));
  if (st == NULL) return PyErr_NoMemory();
  st->arg_table[0] = (const casadi_real**)(uintptr_t)a[0];
  st->arg_table[1] = (const casadi_real**)(uintptr_t)a[1];
  st->res_table[0] = (casadi_real**)(uintptr_t)a[2];
  st->res_table[1] = (casadi_real**)(uintptr_t)a[3];
  st->iw = (casadi_int*)(uintptr_t)a[4];
  st->w = (casadi_real*)(uintptr_t)a[5];
  st->y = (casadi_real*)(uintptr_t)a[6];
  st->dt = (casadi_real*)(uintptr_t)a[7];
  st->u_prev = (casadi_real*)(uintptr_t)a[8];
  st->u = (casadi_real*)(uintptr_t)a[9];
  st->held[0] = (const casadi_real*)(uintptr_t)a[10];
  st->held[1] = (const casadi_real*)(uintptr_t)a[11];
  st->x[0] = (const casadi_real*)(uintptr_t)a[12];
  st->x[1] = (const casadi_real*)(uintptr_t)a[13];
  st->status[0] = (const casadi_real*)(uintptr_t)a[14];
  st->status[1] = (const casadi_real*)(uintptr_t)a[15];
  st->state = (long long*)(uintptr_t)a[16];
  st->gap_limit = (const casadi_real*)(uintptr_t)a[17];
  Py_INCREF(fallback);
  st->fallback = fallback;
  Py_INCREF(keep);
  st->keep = keep;
  capsule = PyCapsule_New(st, "casship.update", cs_release);
  if (capsule == NULL) {{
    Py_DECREF(fallback);
    Py_DECREF(keep);
    PyMem_Free(st);
    return NULL;
  }}
  f = PyCFunction_NewEx(&cs_update_def, capsule, NULL);
  Py_DECREF(capsule);
  return f;
}}
"""


def _header_dirs() -> tuple[str, str] | None:
    """The folders of the Python and NumPy headers, or None where they are not installed."""
    python = sysconfig.get_paths().get("include")
    numpy_inc = np.get_include()
    if not python or not os.path.isfile(os.path.join(python, "Python.h")) \
            or not os.path.isfile(os.path.join(numpy_inc, "numpy", "arrayobject.h")):
        return None
    return python, numpy_inc


class NativeUpdate:
    """An online step compiled with its C ``update`` entry point.

    Parameters
    ----------
    online : casadi.Function
        The online step (see :func:`casship.estimators.online.online_step`): inputs ``y``, ``dt``,
        ``u_prev``, ``u`` among others, outputs ``x``, ``u_held`` and ``status`` among others.
    nx, ny, nu : int
        Its numbers of states, measured outputs and inputs.

    Raises
    ------
    RuntimeError
        When the headers are missing or compiling fails.
    """

    def __init__(self, online: ca.Function, nx: int, ny: int, nu: int):
        if sys.platform == "win32":         # an extension there links against the Python library
            raise RuntimeError("the compiled update is not built on Windows")
        headers = _header_dirs()
        if headers is None:
            raise RuntimeError("the Python or NumPy C headers are not installed")
        name = online.name()
        self.fun, lib = compile_function(online, library=True, include_dirs=headers,
                                         extra_source=update_source(name, nx, ny, nu))
        factory = getattr(ctypes.PyDLL(lib._name), f"casship_update_new_{name}")
        factory.restype = ctypes.py_object
        factory.argtypes = [ctypes.py_object, ctypes.py_object, ctypes.c_void_p]
        self._factory = factory
        self._work = (self.fun.sz_arg(), self.fun.sz_res(), self.fun.sz_iw(), self.fun.sz_w())

    def bind(self, calls, buffers: dict, fallback):
        """The compiled ``update`` working on the buffers of ``calls``.

        Parameters
        ----------
        calls : pair of BufferedCall
            The two buffer sets of :attr:`fun` (they hand the memory to each other).
        buffers : dict
            Flat float64 arrays by name: ``y``, ``dt``, ``u_prev``, ``u`` (inputs shared by both
            sets), ``held0/1``, ``x0/1``, ``status0/1`` (outputs per set), ``state`` (int64, 2) and
            ``gap_limit`` (1).
        fallback : callable
            The checked update, called with the same arguments whenever the C code does not take
            a call.
        """
        sz_arg, sz_res, sz_iw, sz_w = self._work
        tables = {}
        for c, call in enumerate(calls):
            arg, res = np.zeros(max(sz_arg, 1), np.uint64), np.zeros(max(sz_res, 1), np.uint64)
            arg[:len(call.args)] = [a.ctypes.data for a in call.args]
            res[:len(call.res)] = [r.ctypes.data for r in call.res]
            tables[f"arg{c}"], tables[f"res{c}"] = arg, res
        tables["iw"], tables["w"] = np.zeros(max(sz_iw, 1), np.int64), np.zeros(max(sz_w, 1))
        arrays = {**tables, **buffers}
        if arrays["state"].dtype != np.int64:
            raise ValueError("the update state must be an int64 array")
        addresses = np.array([arrays[k].ctypes.data for k in ADDRESSES], np.uint64)
        keep = (tuple(calls), tuple(arrays.values()))           # everything the addresses point into
        return self._factory(fallback, keep, addresses.ctypes.data)


def compile_update(online: ca.Function, nx: int, ny: int, nu: int) -> NativeUpdate | None:
    """:class:`NativeUpdate` of ``online``, or None where it cannot be built here (no headers, or
    the compiler refuses them); the online runner then keeps to its Python update.

    Parameters
    ----------
    online : casadi.Function
    nx, ny, nu : int
    """
    try:
        return NativeUpdate(online, nx, ny, nu)
    except (RuntimeError, OSError, AttributeError):
        return None
