"""What a node reports about bad input and its own faults: per-kind rejection counts, warnings
throttled per kind, and the guards that keep an unexpected exception in a callback from reaching
the executor (whose ``spin`` would re-raise it and end the node)."""

from __future__ import annotations

import functools
import inspect
import math
import threading
import time
from collections.abc import Callable
from typing import Any

#: Warnings about bad input are throttled to one per this many seconds per kind.
WARN_THROTTLE_S = 1.0


class Reporter:
    """Counts rejected inputs by kind and logs ``<kind> rejected: <problem>`` at most once per
    ``WARN_THROTTLE_S`` per kind; the next warning says how many were left out. Thread-safe (a
    node's fast lane and its executor both report). ``context``: the node's rclpy context; an
    rclpy error once it is shut down is the stop, not a fault (:meth:`internal_error`)."""

    def __init__(self, logger: Any, throttle_s: float = WARN_THROTTLE_S,
                 context: Any = None) -> None:
        self._logger = logger
        self._context = context
        self._throttle_s = throttle_s
        self._lock = threading.Lock()
        self._rejected: dict[str, int] = {}
        self._warned: dict[str, tuple[float, int]] = {}

    @property
    def rejected(self) -> dict[str, int]:
        """A copy of the rejection counts by kind."""
        with self._lock:
            return dict(self._rejected)

    def _count(self, kind: str) -> None:
        with self._lock:
            self._rejected[kind] = self._rejected.get(kind, 0) + 1

    def reject(self, kind: str, problem: str) -> None:
        """An input of ``kind`` was rejected for ``problem``: counted and warned about."""
        self._count(kind)
        self.warn(kind, problem)

    def warn(self, kind: str, problem: str, error: bool = False, label: str = 'rejected'
             ) -> None:
        """``<kind> <label>: <problem>`` (throttled per kind and label), as an error if
        ``error``."""
        now = time.monotonic()
        key = f'{kind} {label}'
        with self._lock:
            last, left_out = self._warned.get(key, (-math.inf, 0))
            if now - last < self._throttle_s:
                self._warned[key] = (last, left_out + 1)
                return
            self._warned[key] = (now, 0)
        text = f'{key}: {problem}' + (
            f' ({left_out} more since the last warning)' if left_out else '')
        # One severity per call site: rclpy raises when a call site changes its severity.
        if error:
            self._logger.error(text)
        else:
            self._logger.warning(text)

    def stopped(self, exc: BaseException) -> bool:
        """True when ``exc`` is rclpy's refusal of a call on a shut-down context (``RCLError:
        ... publisher's context is invalid``, an invalid handle: RuntimeErrors): a callback, the
        fast lane or a timer that was publishing when SIGINT or SIGTERM shut the context down
        on rclpy's signal thread. The context's state is final, so the test cannot race."""
        return isinstance(exc, RuntimeError) and self._context is not None and \
            not self._context.ok()

    def internal_error(self, kind: str, exc: BaseException) -> None:
        """An exception no validation anticipated (a bug): counted and logged, never raised.
        A failure of the shutdown itself (:meth:`stopped`) is a quiet stop: a debug line."""
        if self.stopped(exc):
            try:
                self._logger.debug(f'{kind} stopped by the shutdown: {exc}')
            except Exception:  # logging may be finalized already
                pass
            return
        key = f'{kind} internal error'
        self._count(key)
        try:
            self.warn(key, f'{type(exc).__name__}: {exc}', error=True)
        except Exception:  # the safety net must not throw itself
            pass


def guarded(kind: str) -> Callable:
    """Decorator of a topic or timer callback method of a node with a ``reporter``: an
    unexpected exception is counted and logged instead of reaching the executor. Nothing has been
    published by then (a node publishes an input's outputs only once all are built)."""

    def wrap(method: Callable) -> Callable:
        @functools.wraps(method)
        def run(self: Any, *args: Any) -> None:
            try:
                method(self, *args)
            except Exception as exc:  # the safety net: no callback may end the node
                self.reporter.internal_error(kind, exc)

        return run

    return wrap


def guarded_service(kind: str) -> Callable:
    """Decorator of a service callback method (plain or coroutine) of a node with a
    ``reporter``: an unexpected exception answers a fresh response with ``success: false`` and
    ``message: 'internal error: ...'``."""

    def failure(self: Any, response: Any, exc: Exception) -> Any:
        self.reporter.internal_error(kind, exc)
        fresh = type(response)()
        fresh.success = False
        fresh.message = f'internal error: {type(exc).__name__}: {exc}'
        return fresh

    def wrap(method: Callable) -> Callable:
        if inspect.iscoroutinefunction(method):
            @functools.wraps(method)
            async def run_async(self: Any, request: Any, response: Any) -> Any:
                try:
                    return await method(self, request, response)
                except Exception as exc:  # the safety net: no callback may end the node
                    return failure(self, response, exc)

            return run_async

        @functools.wraps(method)
        def run(self: Any, request: Any, response: Any) -> Any:
            try:
                return method(self, request, response)
            except Exception as exc:  # the safety net: no callback may end the node
                return failure(self, response, exc)

        return run

    return wrap
