"""The only place that uses rclpy's implementation internals (``rclpy_implementation``, a
subscription's ``handle.take_message`` and ``handle.pointer``, a node's ``handle.get_parameters``),
for the fast lane's latency: a wait set built once for the lane's own subscriptions, refilled
per wait, and a take of the messages queued behind the first (rclpy's public alternatives, an
executor per thread, cost a wait-set rebuild and a task per message: docs/nodes.md, "QoS"); and
for the names a node's parameter file and overrides set (rclpy keeps them in a private dict).

``test/ros/test_rclpy_internals.py`` exercises every name used here against the installed
rclpy, so a release that changes them fails that test by name instead of the nodes silently.
"""

from __future__ import annotations

from typing import Any

from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.parameter import Parameter


def take(subscription: Any) -> Any | None:
    """The next message queued on ``subscription`` (an rclpy ``Subscription``), None when none
    is: the take rclpy's own executor makes."""
    with subscription.handle:
        message = subscription.handle.take_message(subscription.msg_type, subscription.raw)
    return None if message is None else message[0]


class SubscriptionWaitSet:
    """A wait set over fixed ``subscriptions`` and ``guard_conditions`` of one ``context``,
    built once; :meth:`wait` refills and waits (releasing the GIL) and returns the
    subscriptions that have messages, in the given order. Enter the handles of the
    subscriptions, the guard conditions and the context (``with``) for its lifetime."""

    def __init__(self, subscriptions: list[Any], guard_conditions: list[Any],
                 context: Any) -> None:
        self._subscriptions = subscriptions
        self._guards = guard_conditions
        self._wait_set = rclpy_implementation.WaitSet(len(subscriptions), len(guard_conditions),
                                                 0, 0, 0, 0, context.handle)

    def wait(self, timeout_ns: int) -> list[Any]:
        wait_set = self._wait_set
        wait_set.clear_entities()
        for subscription in self._subscriptions:
            wait_set.add_subscription(subscription.handle)
        for guard in self._guards:
            wait_set.add_guard_condition(guard.handle)
        wait_set.wait(timeout_ns)
        ready = wait_set.get_ready_entities('subscription')
        return [s for s in self._subscriptions if s.handle.pointer in ready]


def parameter_override_names(node: Any) -> list[str]:
    """The names of the parameters that the process's parameter files and ``-p`` overrides set
    for ``node`` (its own and the ``/**`` ones): what rclpy reads its start-up values from."""
    with node.handle:
        return sorted(node.handle.get_parameters(Parameter))
