"""Minimal progress reporting for long-running work (stderr, one line per stage)."""
from __future__ import annotations

import sys
import time
from typing import Iterable, Iterator


def progress(stages: Iterable[str], label: str, stream=None) -> Iterator[None]:
    """A generator that prints ``[label i/n] stage (elapsed)`` each time it is advanced."""
    stream = stream or sys.stderr
    stages = list(stages)
    t0 = time.perf_counter()
    for i, stage in enumerate(stages, 1):
        print(f"[{label} {i}/{len(stages)}] {stage} ({time.perf_counter() - t0:.1f} s)", file=stream, flush=True)
        yield
    print(f"[{label}] done in {time.perf_counter() - t0:.1f} s", file=stream, flush=True)
