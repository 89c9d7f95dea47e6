"""``casship cache info`` / ``casship cache clear``: the on-disk cache of compiled code (:mod:`casship.runtime`)."""
from __future__ import annotations


#: One-line description (the command list of ``casship --help``).
HELP = "show or empty the cache of compiled C code (option jit)"


def register(sub) -> None:
    p = sub.add_parser("cache", help=HELP,
                       description="Compiled steps, folds and likelihoods are kept as shared libraries in a "
                                   "cache directory ($CASSHIP_CACHE_DIR, else $XDG_CACHE_HOME/casship or "
                                   "~/.cache/casship), so that a new process does not compile them again. A folder "
                                   "that belongs to another user or that others may write into is not used.")
    p.add_argument("action", choices=("info", "clear"), help="info: where, how many entries, how big, which compiler, "
                                                             "flags and time limit, how compiled code is called; "
                                                             "clear: delete every compiled library (a compile in "
                                                             "progress is left alone and finishes)")
    p.add_argument("--dir", default=None, help="the cache directory (default: as described above)")
    p.set_defaults(func=run)


def run(args) -> int:
    from ..runtime import cache_info, clear_cache

    if args.action == "info":
        print(cache_info(args.dir).summary())
        return 0
    info = cache_info(args.dir)
    if info.path is None:
        print("compile cache is off; nothing to clear")
        return 0
    if info.refused:
        print(f"compile cache {info.path} is not used ({info.refused}); nothing removed")
        return 0
    removed = clear_cache(args.dir)
    print(f"removed {removed} file(s) ({info.bytes / 1e6:.1f} MB) from {info.path}")
    if removed.busy:
        print(f"left alone: {len(removed.busy)} compile(s) in progress in another process or thread "
              f"({', '.join(k[:12] for k in removed.busy)}); they finish as they would have")
    return 0
