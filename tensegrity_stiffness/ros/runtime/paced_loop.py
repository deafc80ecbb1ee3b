"""A loop on a thread of its own that calls ``tick`` at a fixed rate, paced by the wall clock on
absolute deadlines (no drift), with the rate it achieves: the controller's ticks. rclpy's timers
run on the executor, where every other callback (a parameter service, a target, diagnostics)
delays them and each wake-up costs a wait-set rebuild: at 500 Hz on two loaded cores they came
at 314 Hz (issue 37). Here a late tick is run at once and the periods it missed are counted.
"""

from __future__ import annotations

import atexit
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from tensegrity_stiffness.ros.runtime import pacing
from tensegrity_stiffness.ros.runtime.pacing import SPIN_S  # noqa: F401 (the name kept)

#: Longest single sleep (s) of a wait: how late a stop is seen.
STOP_POLL_S = 0.1
#: Seconds over which the achieved rate is counted.
RATE_WINDOW_S = 1.0


def wait_until(deadline: float, stop: threading.Event | None = None) -> float:
    """:func:`~tensegrity_stiffness.ros.runtime.pacing.wait_until` (sleep until
    :data:`~tensegrity_stiffness.ros.runtime.pacing.SPIN_S` before ``deadline``, spin the rest)
    that returns early when ``stop`` is set (seen within :data:`STOP_POLL_S`)."""
    return pacing.wait_until(deadline, stop=stop, max_sleep=STOP_POLL_S)


class RateCounter:
    """Events per second over the last :data:`RATE_WINDOW_S` (thread-safe enough: one writer)."""

    def __init__(self, capacity: int = 20_000) -> None:
        self._times: deque[float] = deque(maxlen=capacity)

    def record(self, now: float | None = None) -> None:
        self._times.append(time.perf_counter() if now is None else now)

    def rate(self) -> float:
        """Events in the last :data:`RATE_WINDOW_S`, per second."""
        now = time.perf_counter()
        times = list(self._times)
        return sum(1 for t in times if now - t <= RATE_WINDOW_S) / RATE_WINDOW_S


class PacedLoop:
    """Calls ``tick(due)`` every ``1 / rate`` s on a thread of its own; ``due`` is the number of
    periods since the last call (1 on time; more when a call came a whole period late: the
    missed ones, counted in ``missed``, are not run). ``on_error(exc)`` gets an exception of
    ``tick`` (which guards its own; the loop keeps running). ``ticks``, ``missed`` and
    :meth:`achieved_rate` are read by diagnostics."""

    def __init__(self, rate: float, tick: Callable[[int], None],
                 on_error: Callable[[BaseException], None], name: str = 'paced loop') -> None:
        if not rate > 0.0:
            raise ValueError(f'rate must be > 0 Hz, got {rate}')
        self.rate = float(rate)
        self.period = 1.0 / self.rate
        self._tick = tick
        self._on_error = on_error
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._counter = RateCounter(capacity=int(4 * self.rate * RATE_WINDOW_S) + 16)
        self.ticks = 0
        self.missed = 0

    def start(self) -> None:
        self._thread.start()
        atexit.register(self.stop)  # no ticking thread while Python finalizes (as the lane's)

    def stop(self, timeout: float = 2.0) -> None:
        """End the thread (before the node is destroyed; at the latest at exit)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout)
        if not self._thread.is_alive():
            atexit.unregister(self.stop)

    def achieved_rate(self) -> float:
        """Ticks in the last :data:`RATE_WINDOW_S`, per second."""
        return self._counter.rate()

    def statistics(self, name: str = 'tick') -> list[tuple[str, Any]]:
        """``(key, value)`` pairs of /diagnostics: the rate asked for, the rate achieved, the
        ticks run and the ticks missed."""
        return [(f'{name} rate [Hz]', self.rate), (f'achieved {name} rate [Hz]',
                                                   self.achieved_rate()),
                (f'{name}s', self.ticks), (f'missed {name}s', self.missed)]

    def _run(self) -> None:
        start = time.perf_counter()
        done = 0  # periods since start
        while not self._stop.is_set():
            now = wait_until(start + (done + 1) * self.period, self._stop)
            if self._stop.is_set():
                break
            due = pacing.periods_due(start, done, self.period, now)
            self.missed += due - 1
            done += due
            self.ticks += 1
            self._counter.record(now)
            try:
                self._tick(due)
            except Exception as exc:  # the safety net: the loop keeps running
                self._on_error(exc)
