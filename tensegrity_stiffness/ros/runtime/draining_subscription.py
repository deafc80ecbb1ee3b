"""Subscriptions whose callback also takes the messages queued behind its own: the executor's
per-callback cost is paid once per backlog instead of once per message (docs/nodes.md,
"QoS"). Used by the nodes for their streamed inputs without the fast lane, and by the
test and bench clients. The take is rclpy's own executor's (:func:`.rclpy_internals.take`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from tensegrity_stiffness.ros.runtime.rclpy_internals import take

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
        message = take(subscription)
        if message is None:
            break
        taken += 1
        handle(message)
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
