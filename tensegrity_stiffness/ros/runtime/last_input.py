"""What a streaming node keeps of its last published input, and the rates of its inputs: one
object shared by the nodes' fast lane (which records), their executor (re-publishes, markers,
diagnostics) and their services (the last screw as a reference). Thread-safe."""

from __future__ import annotations

import threading
import time
from collections import deque
from typing import Any

#: Window of the input-rate and compute-time statistics in /diagnostics.
STATS_WINDOW = 1000


class LastInput:
    """``screws`` (the last published input), its ``stamp`` and ``outputs``; counts and times of
    the inputs published."""

    def __init__(self, window: int = STATS_WINDOW) -> None:
        self._lock = threading.Lock()
        self.screws: Any = None
        self.stamp: Any = None
        self.outputs: Any = None
        self._marked: Any = None
        self._published = 0
        self._times: deque[float] = deque(maxlen=window)
        self._computes: deque[float] = deque(maxlen=window)

    def record(self, screws: Any, stamp: Any, outputs: Any, started: float) -> None:
        """An input was published: its screws, stamp and outputs, computed since ``started``
        (``time.perf_counter``)."""
        now = time.monotonic()
        with self._lock:
            self.screws, self.stamp, self.outputs = screws, stamp, outputs
            self._published += 1
            self._times.append(now)
            self._computes.append(time.perf_counter() - started)

    def unmarked(self) -> tuple[Any, Any] | None:
        """``(outputs, stamp)`` of the last input if no marker was drawn for it yet (and mark
        it), else None."""
        with self._lock:
            if self.outputs is None or self.outputs is self._marked:
                return None
            self._marked = self.outputs
            return self.outputs, self.stamp

    def statistics(self) -> list[tuple[str, Any]]:
        """``(key, value)`` pairs of /diagnostics: input rate, outputs published, compute time."""
        with self._lock:
            times, computes, published = list(self._times), list(self._computes), self._published
        now = time.monotonic()
        return [
            ('input rate [Hz]', float(sum(1 for t in times if now - t <= 1.0))),
            ('outputs published', published),
            ('compute time mean [us]', 1e6 * sum(computes) / len(computes) if computes else 0.0),
            ('compute time max [us]', 1e6 * max(computes) if computes else 0.0),
        ]
