"""Pacing a loop by the wall clock: wait for a deadline precisely (a twin's real-time steps)."""

from __future__ import annotations

import time

#: Sleep no closer than this to a deadline; wait the rest by spinning (s): the loop keeps its
#: 1 kHz to tens of microseconds at the cost of this much CPU per period.
SPIN_S = 1e-4


def wait_until(deadline: float, spin_s: float = SPIN_S) -> float:
    """Sleep until ``spin_s`` before ``deadline`` (``time.perf_counter`` seconds), spin the
    rest; the time it stopped."""
    while (now := time.perf_counter()) < deadline:
        if deadline - now > spin_s:
            time.sleep(deadline - now - spin_s)
    return now
