"""Time and traced memory of one call, shared by the benchmark tests."""
from __future__ import annotations

import time
import tracemalloc


def traced(fn, unit: float = 1e6):
    """(result, seconds, peak traced memory in ``unit`` bytes: 1e6 MB, 2**20 MiB) of one call of ``fn``."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    t0 = time.perf_counter()
    out = fn()
    dt = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] / unit
    tracemalloc.stop()
    return out, dt, peak
