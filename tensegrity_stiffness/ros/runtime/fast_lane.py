"""A node's hot subscriptions served on a thread of their own, from a lean loop on a wait set
that holds only them and a guard condition (:class:`.rclpy_internals.SubscriptionWaitSet`),
instead of by the executor; the handlers are called directly, with every message queued behind
the first (:func:`.draining_subscription.take_queued`), or only the newest of them
(``skipped``: :func:`.draining_subscription.take_newest`). Why, and what it costs and saves:
docs/nodes.md, "QoS".

Subscriptions join the lane through :meth:`FastLane.create_subscription`: they belong to a
callback group that no executor may run (:class:`LaneCallbackGroup`). Services, parameters,
timers and the other topics stay with the node's executor; both share the node's state under
the node's own locks. A running lane is also stopped at the interpreter's exit (``atexit``):
a thread still inside rclpy's C++ wait while Python finalizes would abort the process.
"""

from __future__ import annotations

import atexit
import threading
from collections.abc import Callable
from contextlib import ExitStack
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.node import Node

from tensegrity_stiffness.ros.runtime.draining_subscription import (
    SkippedCounts,
    newest_handler,
    take_queued,
)
from tensegrity_stiffness.ros.runtime.rclpy_internals import SubscriptionWaitSet

#: Longest wait between checks that the context is still up (ns).
WAIT_TIMEOUT_NS = 100_000_000


class LaneCallbackGroup(CallbackGroup):
    """A callback group that no executor runs: its entities are the fast lane's."""

    def can_execute(self, entity: Any) -> bool:
        return False

    def beginning_execution(self, entity: Any) -> bool:
        return False

    def ending_execution(self, entity: Any) -> None:
        pass


class FastLane:
    """Serves subscriptions of ``node`` on one thread. ``on_error(topic, exc)`` gets an exception
    of a handler or of a take (handlers guard their own; the lane keeps running)."""

    def __init__(self, node: Node, on_error: Callable[[str, BaseException], None]) -> None:
        self._node = node
        self._on_error = on_error
        self._group = LaneCallbackGroup()
        self._entries: list[tuple[Any, Callable[[Any], None]]] = []
        self._newest: dict[int, Callable[[Any, Any], None]] = {}
        self._stop = threading.Event()
        self._wake = node.create_guard_condition(lambda: None, callback_group=self._group)
        self._thread: threading.Thread | None = None

    def create_subscription(self, msg_type: Any, topic: str, handler: Callable[[Any], None],
                            qos: Any, skipped: SkippedCounts | None = None) -> Any:
        """A subscription of the node whose messages go to ``handler`` on the lane's thread
        (create them all before :meth:`start`): every message in order, or with ``skipped``
        only the newest of those queued at each wake-up (the others counted there under
        ``topic``)."""
        if self._thread is not None:
            raise RuntimeError('the fast lane is already running')
        subscription = self._node.create_subscription(msg_type, topic, handler, qos,
                                                      callback_group=self._group)
        self._entries.append((subscription, handler))
        if skipped is not None:
            self._newest[id(subscription)] = newest_handler(topic, handler, skipped)
        return subscription

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name='fast_lane', daemon=True)
        self._thread.start()
        atexit.register(self.stop)

    def stop(self, timeout: float = 2.0) -> None:
        """End the thread (before the node is destroyed; at the latest at exit, again if it
        outlived ``timeout`` here)."""
        self._stop.set()
        try:
            self._wake.trigger()
        except Exception:  # already destroyed: the wait times out instead
            pass
        if self._thread is not None:
            self._thread.join(timeout)
            if not self._thread.is_alive():
                atexit.unregister(self.stop)

    def _run(self) -> None:
        context = self._node.context
        entries = self._entries
        with ExitStack() as handles:
            for subscription, _ in entries:
                handles.enter_context(subscription.handle)
            handles.enter_context(self._wake.handle)
            handles.enter_context(context.handle)
            wait_set = SubscriptionWaitSet([s for s, _ in entries], [self._wake], context)
            handlers = dict((id(s), h) for s, h in entries)
            newest = self._newest
            while not self._stop.is_set() and context.ok():
                ready = wait_set.wait(WAIT_TIMEOUT_NS)  # releases the GIL
                if self._stop.is_set():
                    break
                for subscription in ready:
                    try:
                        serve_newest = newest.get(id(subscription))
                        if serve_newest is not None:
                            serve_newest(subscription)
                        else:
                            take_queued(subscription, handlers[id(subscription)])
                    except Exception as exc:  # a take of a destroyed handle, a bug
                        self._on_error(subscription.topic_name, exc)
