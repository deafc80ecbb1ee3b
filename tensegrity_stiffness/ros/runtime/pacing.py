"""Pacing a loop by the wall clock: wait for a deadline precisely (a twin's real-time steps)."""

from __future__ import annotations

import math
import threading
import time

#: Sleep no closer than this to a deadline; wait the rest by spinning (s): the loop keeps its
#: 1 kHz to tens of microseconds at the cost of this much CPU per period.
SPIN_S = 1e-4


def wait_until(deadline: float, spin_s: float = SPIN_S, *,
               stop: threading.Event | None = None, max_sleep: float = math.inf) -> float:
    """Sleep until ``spin_s`` before ``deadline`` (``time.perf_counter`` seconds), spin the
    rest; the time it stopped. With ``stop``: early once it is set, each sleep at most
    ``max_sleep`` s (how late the stop may be seen)."""
    while (now := time.perf_counter()) < deadline:
        if stop is not None and stop.is_set():
            break
        if deadline - now > spin_s:
            time.sleep(min(deadline - now - spin_s, max_sleep))
    return now


def periods_due(start: float, done: int, period: float, now: float) -> int:
    """Periods of a loop on absolute deadlines ``start + k period`` (``perf_counter`` s) due at
    ``now`` after ``done`` of them: 1 on time, more when ``now`` is whole periods late (the
    missed ones, run at once or counted, are ``due - 1``)."""
    return max(1, int((now - start) / period) - done)
