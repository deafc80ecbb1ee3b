"""A node's hot subscriptions served on a thread of their own, from a lean loop on rclpy's wait
set, instead of by the executor.

rclpy's executors gather every entity of every node, build a new wait set and wrap a task around
each callback: 0.35-0.6 ms per message on the 2-core CI machine, more than the node's own work
for a screw. The fast lane waits on a wait set that holds only its subscriptions and a guard
condition (built once, refilled per wait: tens of microseconds) and calls the handlers directly,
taking every message queued behind the first (:func:`.draining_subscription.take_queued`).
A running lane is also stopped at the interpreter's exit (``atexit``): a daemon thread that
returns from rclpy's C++ wait while Python finalizes is ended inside a ``noexcept`` frame, and
the process aborts ("terminate called without an active exception"). That happened when SIGINT
interrupted a node's construction after its lane had started: no one held the node to close it.
Services, parameters, timers and the other topics stay with the node's executor on the main
thread; the handlers and those callbacks share the node's state under the node's own locks.

Subscriptions join the lane through :meth:`FastLane.create_subscription`: they belong to a
callback group that no executor may run (:class:`LaneCallbackGroup`), so the executor never
waits on them. ``rclpy.experimental.EventsExecutor`` was measured as the alternative and fails
in this rclpy build: it raises "Guard conditions not supported" for a node with a guard
condition, and without one its spin delivered neither timers nor messages (docs/nodes.md, QoS).
"""

from __future__ import annotations

import atexit
import threading
from collections.abc import Callable
from contextlib import ExitStack
from typing import Any

from rclpy.callback_groups import CallbackGroup
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node

from tensegrity_stiffness.ros.runtime.draining_subscription import take_queued

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
        self._stop = threading.Event()
        self._wake = node.create_guard_condition(lambda: None, callback_group=self._group)
        self._thread: threading.Thread | None = None

    def create_subscription(self, msg_type: Any, topic: str, handler: Callable[[Any], None],
                            qos: Any) -> Any:
        """A subscription of the node whose messages go to ``handler`` on the lane's thread
        (create them all before :meth:`start`)."""
        if self._thread is not None:
            raise RuntimeError('the fast lane is already running')
        subscription = self._node.create_subscription(msg_type, topic, handler, qos,
                                                      callback_group=self._group)
        self._entries.append((subscription, handler))
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
            wait_set = _rclpy.WaitSet(len(entries), 1, 0, 0, 0, 0, context.handle)
            while not self._stop.is_set() and context.ok():
                wait_set.clear_entities()
                for subscription, _ in entries:
                    wait_set.add_subscription(subscription.handle)
                wait_set.add_guard_condition(self._wake.handle)
                wait_set.wait(WAIT_TIMEOUT_NS)  # releases the GIL
                if self._stop.is_set():
                    break
                ready = wait_set.get_ready_entities('subscription')
                for subscription, handler in entries:
                    if subscription.handle.pointer in ready:
                        try:
                            take_queued(subscription, handler)
                        except Exception as exc:  # a take of a destroyed handle, a bug
                            self._on_error(subscription.topic_name, exc)
