"""Subscriptions whose callback also takes the messages queued behind its own.

rclpy's executor rebuilds its wait set and wraps a task around every callback it runs, which
costs more than the node's whole computation for a screw (about 0.6 ms of 1.2 ms measured on the
2-core CI machine): at 1 kHz the node fell behind, 15% of the screws were dropped and the
latency grew to 100 ms. Taking a backlog in one callback pays that cost once per backlog. Used
by the node for ``~/screw`` and ``~/pose`` and by the test and bench clients.

Works on any rclpy subscription (it uses the take call of rclpy's own executor,
``handle.take_message``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

#: A callback takes at most this many queued messages, for at most ``DRAIN_BUDGET_S`` seconds,
#: so that services, parameter changes and the other topics are served in between.
DRAIN_LIMIT = 32
DRAIN_BUDGET_S = 0.01


def take_queued(subscription: Any, handle: Callable[[Any], None], limit: int = DRAIN_LIMIT,
                budget_s: float = DRAIN_BUDGET_S) -> int:
    """Take the messages already queued on ``subscription`` and pass each to ``handle``, in
    order; at most ``limit`` of them, for at most ``budget_s`` seconds. Returns how many."""
    deadline = time.perf_counter() + budget_s
    taken = 0
    while taken < limit and time.perf_counter() <= deadline:
        with subscription.handle:
            message = subscription.handle.take_message(subscription.msg_type, subscription.raw)
        if message is None:
            break
        taken += 1
        handle(message[0])
    return taken


def create_draining_subscription(node: Any, msg_type: Any, topic: str,
                                 callback: Callable[[Any], None], qos: Any,
                                 on_error: Callable[[Exception], None] | None = None,
                                 **kwargs: Any) -> Any:
    """``node.create_subscription`` whose callback, after the executor's message, handles those
    queued behind it (:func:`take_queued`). ``on_error`` gets an exception of the take itself
    (e.g. the subscription destroyed at shutdown) instead of the executor; ``callback`` guards
    its own."""
    subscription = None

    def run(msg: Any) -> None:
        callback(msg)
        try:
            take_queued(subscription, callback)
        except Exception as exc:
            if on_error is None:
                raise
            on_error(exc)

    subscription = node.create_subscription(msg_type, topic, run, qos, **kwargs)
    return subscription
