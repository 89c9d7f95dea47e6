"""How casship runs its CasADi Functions: buffers, the compiled record loop, the compile cache, C export.

Everything the rest of casship (and a user) needs from here is imported from ``casship.runtime``;
the modules inside are private. Functions are addressed by slot *name*, never by position.

Buffers
    :class:`BufferedCall` binds preallocated arrays to a Function's named inputs and outputs
    through CasADi's ``Function.buffer`` (``call["dt"] = 0.1; call(); call.out("x")``);
    :data:`DUPLICATE_NAMES` lets a step name its memory alike on both sides.
Compile policy (the one door for compiling)
    :class:`JitPolicy` (``off`` / ``now`` / ``background``; ``jit=True`` is ``now``, ``False`` ``off``,
    ``None`` ``background``): :func:`jit_function` (a Function under a policy),
    :func:`shared_function` (the one table of Functions shared per process by structure),
    :func:`record_loop` (an estimator's compiled record loop, :class:`NativeFold`),
    :func:`run_pieces` with :class:`Job` (the one chunk-and-pad fold driver; :func:`pieces`,
    :func:`piece`), :func:`fold_chunk` (the one chunk setting).
    Nothing outside this package compiles or keeps a Function table of its own.
Settings
    One flag set, bit-exact by default (:data:`DEFAULT_FLAGS`; :data:`NATIVE_FLAGS` is the explicit
    opt-in for ``-march=native``), the time limit, the chunk length and the cache folder, with their
    ``CASSHIP_*`` environment variables: see ``casship.runtime._settings``.
Compile cache
    :func:`compile_function` (C compiler, flags, on-disk cache, time limit; failures raise
    :class:`CompileError`), :func:`cached_function` (only what is compiled already),
    :func:`cache_dir`, :func:`cache_info`, :func:`clear_cache` (leaves compiles in progress alone),
    :func:`cache_key`, :func:`find_compiler`, :func:`stop_compilers` (run at exit: no process waits
    for a compile nobody needs); ``casship cache info|clear`` on the command line.
    :func:`compile_in_background` compiles in a daemon worker thread and hands out the interpreted
    Function until then (:class:`Compiling`); at exit what is not finished is handed to a detached
    process that compiles it for the next run (:func:`hand_off`, :func:`finish_handed_off`).
C export
    :func:`generate_c` (any Function as standalone C), :func:`write_harness`, :func:`compile_c`,
    :func:`read_harness_output`, :class:`CFiles`; an estimator's export lives with the estimators
    (``casship.estimators.export``).

No hand-written CPython C API code is compiled or loaded: compiled code is called through
CasADi's ``external`` and buffer mechanisms, and the record loop's C driver through ``ctypes``.
"""
from ._background import Compiling, compile_in_background, finish_handed_off, hand_off
from ._buffers import DUPLICATE_NAMES, BoundedTable, BufferedCall
from ._pieces import THREADS, Job, PieceFailed, piece, pieces, run_pieces
from ._cache import cache_dir, cache_key, cached_function, compile_function
from ._housekeeping import CacheInfo, Cleared, cache_info, clear_cache
from ._codegen import CFiles, c_array, check_c_name, compile_c, generate_c, read_harness_output, write_harness
from ._compiler import CompileError, find_compiler, interrupts_deferred, stop_compilers
from ._loop import NativeFold
from ._policy import (BACKGROUND_FAILURES, COUNTS, FUNCTIONS, JitPolicy, current_function, is_compiled, jit_function, record_loop, shared_function,
                      shared_functions)
from ._settings import DEFAULT_CHUNK, DEFAULT_FLAGS, DEFAULT_TIMEOUT, NATIVE_FLAGS, fold_chunk

__all__ = ["BufferedCall", "BoundedTable", "Job", "PieceFailed", "run_pieces", "THREADS", "pieces", "piece", "DUPLICATE_NAMES", "NativeFold",
           "JitPolicy", "jit_function", "shared_function", "shared_functions", "record_loop", "is_compiled",
           "current_function", "COUNTS", "FUNCTIONS", "BACKGROUND_FAILURES",
           "fold_chunk", "DEFAULT_CHUNK",
           "compile_function", "cached_function", "compile_in_background", "Compiling", "hand_off", "finish_handed_off", "CompileError", "cache_dir",
           "cache_info", "clear_cache", "cache_key", "CacheInfo", "Cleared", "stop_compilers", "interrupts_deferred",
           "find_compiler", "DEFAULT_FLAGS", "NATIVE_FLAGS", "DEFAULT_TIMEOUT",
           "CFiles", "generate_c", "write_harness", "compile_c", "read_harness_output", "c_array", "check_c_name"]
