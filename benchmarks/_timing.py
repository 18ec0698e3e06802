"""Best-of-N timing, shared by the benchmark scripts.

The smallest of several timings is the one least disturbed by the rest of the
machine (other processes, the scheduler, a cold cache), so the benchmarks
report it. Imported as ``from _timing import best_of, best_time``: the
scripts run as ``python benchmarks/<script>.py``, which puts this folder on
``sys.path``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable


def best_of(fn: Callable, repeat: int, *, number: int = 1, warmup: bool = False,
            clock: Callable[[], float] = time.perf_counter) -> tuple[float, object]:
    """Smallest time per call of ``fn()`` over ``repeat`` rounds of ``number`` calls.

    Parameters
    ----------
    fn : callable
        Called with no argument.
    repeat : int
        Rounds; the fastest counts.
    number : int
        Calls per round (for calls too short to time one by one); the round's
        time is divided by it.
    warmup : bool
        Call ``fn`` once first, untimed (numba compilation, caches).
    clock : callable
        ``time.perf_counter`` (wall time, default) or ``time.process_time``
        (CPU time of the process: on a shared machine the wall clock also counts
        the time spent waiting for a core).

    Returns
    -------
    seconds : float
        Best time per call [s].
    value : object
        What the last call returned.
    """
    value = fn() if warmup else None
    best = math.inf
    for _ in range(repeat):
        t = clock()
        for _ in range(number):
            value = fn()
        best = min(best, (clock() - t) / number)
    return best, value


def best_time(fn: Callable, repeat: int, **kw) -> float:
    """:func:`best_of` without the value: the best time per call [s]."""
    return best_of(fn, repeat, **kw)[0]


def best_wall_cpu(fn: Callable, repeat: int):
    """Best wall and best CPU time [s] of ``repeat`` calls of ``fn``, and its last value."""
    wall, cpu, out = [], [], None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu), out
