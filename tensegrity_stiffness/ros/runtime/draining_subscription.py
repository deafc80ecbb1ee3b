"""Subscriptions whose callback also takes the messages queued behind its own: the executor's
per-callback cost is paid once per backlog instead of once per message (docs/nodes.md,
"QoS"). Used by the nodes for their streamed inputs without the fast lane, and by the
test and bench clients. The take is rclpy's own executor's (:func:`.rclpy_internals.take`).

A subscription may also take only the newest of what is queued (``newest_only``: the estimators'
sensor inputs, the controller's state): the older messages are passed over, counted in a
:class:`SkippedCounts`, and no backlog turns into latency (docs/nodes.md, "Newest readings
only").
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from tensegrity_stiffness.ros.runtime.rclpy_internals import take

#: A callback takes at most this many queued messages, for at most ``DRAIN_BUDGET_S`` seconds,
#: so that services, parameter changes and the other topics are served in between.
DRAIN_LIMIT = 32
DRAIN_BUDGET_S = 0.01
#: A newest-only take passes over at most this many queued messages per call (more than any
#: input queue's depth: the whole queue).
NEWEST_LIMIT = 100_000


class SkippedCounts:
    """Per topic, how many messages a newest-only subscription passed over for a newer one
    (thread-safe: the fast lane and the executor both add)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[str, int] = {}

    def add(self, topic: str, n: int) -> None:
        """``n`` more messages of ``topic`` were passed over."""
        if n:
            with self._lock:
                self._counts[topic] = self._counts.get(topic, 0) + n

    def counts(self) -> dict[str, int]:
        """A copy of the counts by topic (topics with none left out)."""
        with self._lock:
            return dict(sorted(self._counts.items()))

    def total(self) -> int:
        """All messages passed over."""
        with self._lock:
            return sum(self._counts.values())


def take_queued(subscription: Any, handle: Callable[[Any], None], limit: int = DRAIN_LIMIT,
                budget_s: float = DRAIN_BUDGET_S) -> int:
    """Take the messages already queued on ``subscription`` and pass each to ``handle``, in
    order; at most ``limit`` of them, for at most ``budget_s`` seconds. Returns how many."""
    deadline = time.perf_counter() + budget_s
    taken = 0
    while taken < limit and time.perf_counter() <= deadline:
        message = take(subscription)
        if message is None:
            break
        taken += 1
        handle(message)
    return taken


def take_newest(subscription: Any, newest: Any = None) -> tuple[Any, int]:
    """Take every message queued on ``subscription``: ``(the newest, how many older ones were
    passed over)``; ``newest`` is a message already taken (the executor's), passed over too when
    a newer one is queued. ``(newest, 0)`` when nothing is queued."""
    skipped = 0
    for _ in range(NEWEST_LIMIT):
        message = take(subscription)
        if message is None:
            break
        if newest is not None:
            skipped += 1
        newest = message
    return newest, skipped


def newest_handler(topic: str, handle: Callable[[Any], None], skipped: SkippedCounts
                   ) -> Callable[[Any, Any], None]:
    """``serve(subscription, first)``: take the rest of ``subscription``'s queue and pass only
    the newest message to ``handle``, counting the others in ``skipped`` under ``topic``."""

    def serve(subscription: Any, first: Any = None) -> None:
        message, passed_over = take_newest(subscription, first)
        skipped.add(topic, passed_over)
        if message is not None:
            handle(message)

    return serve


def create_draining_subscription(node: Any, msg_type: Any, topic: str,
                                 callback: Callable[[Any], None], qos: Any,
                                 on_error: Callable[[Exception], None] | None = None,
                                 skipped: SkippedCounts | None = None,
                                 **kwargs: Any) -> Any:
    """``node.create_subscription`` whose callback, after the executor's message, handles those
    queued behind it (:func:`take_queued`); with ``skipped`` (newest only), only the newest of
    the executor's message and those queued behind it is handled and the others are counted
    there under ``topic``. ``on_error`` gets an exception of the take itself (e.g. the
    subscription destroyed at shutdown) instead of the executor; ``callback`` guards its own."""
    subscription = None
    serve_newest = None if skipped is None else newest_handler(topic, callback, skipped)

    def run(msg: Any) -> None:
        try:
            if serve_newest is not None:
                serve_newest(subscription, msg)
                return
            callback(msg)
            take_queued(subscription, callback)
        except Exception as exc:
            if on_error is None:
                raise
            on_error(exc)

    subscription = node.create_subscription(msg_type, topic, run, qos, **kwargs)
    return subscription
