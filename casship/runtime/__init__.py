"""How casship runs its CasADi Functions: buffers, the compiled record loop, the compile cache, C export.

Everything the rest of casship (and a user) needs from here is imported from ``casship.runtime``;
the modules inside are private. Functions are addressed by slot *name*, never by position.

Buffers
    :class:`BufferedCall` binds preallocated arrays to a Function's named inputs and outputs
    through CasADi's ``Function.buffer`` (``call["dt"] = 0.1; call(); call.out("x")``);
    :func:`run_fold` runs a ``mapaccum`` fold over a record of any length in pieces;
    :data:`DUPLICATE_NAMES` lets a step name its memory alike on both sides.
Compiled record loop
    :class:`NativeFold`: a step compiled together with a plain C loop over the samples, run over
    a whole record in one call (option ``jit`` of the estimators).
Compile cache
    :func:`compile_function` (C compiler, flags, on-disk cache, time limit; failures raise
    :class:`CompileError`), :func:`cached_function` (only what is compiled already),
    :func:`cache_dir`, :func:`cache_info`, :func:`clear_cache`,
    :func:`cache_key`, :func:`find_compiler`, :data:`DEFAULT_FLAGS`, :data:`PORTABLE_FLAGS`;
    ``casship cache info|clear`` on the command line. :func:`cached_function` looks a library up
    without compiling; :func:`compile_in_background` compiles in a worker thread and hands out
    the interpreted Function until then (:class:`Compiling`).
C export
    :func:`export_estimator` (an estimator's step as standalone C with its numbers),
    :func:`generate_c`, :func:`export_mhe_rti`, :func:`write_harness`, :func:`compile_c`,
    :func:`read_harness_output`, :class:`CFiles`.

No hand-written CPython C API code is compiled or loaded: compiled code is called through
CasADi's ``external`` and buffer mechanisms, and the record loop's C driver through ``ctypes``.
"""
from ._background import Compiling, compile_in_background
from ._buffers import DUPLICATE_NAMES, BoundedTable, BufferedCall, run_fold
from ._cache import CacheInfo, cache_dir, cache_info, cache_key, cached_function, clear_cache, compile_function
from ._codegen import CFiles, compile_c, export_estimator, export_mhe_rti, generate_c, read_harness_output, write_harness
from ._compiler import DEFAULT_FLAGS, DEFAULT_TIMEOUT, PORTABLE_FLAGS, CompileError, find_compiler
from ._loop import NativeFold

__all__ = ["BufferedCall", "BoundedTable", "run_fold", "DUPLICATE_NAMES", "NativeFold",
           "compile_function", "cached_function", "compile_in_background", "Compiling", "CompileError", "cache_dir", "cache_info", "clear_cache", "cache_key", "CacheInfo",
           "find_compiler", "DEFAULT_FLAGS", "PORTABLE_FLAGS", "DEFAULT_TIMEOUT",
           "CFiles", "export_estimator", "generate_c", "export_mhe_rti", "write_harness", "compile_c",
           "read_harness_output"]
