"""Every rclpy implementation internal the package uses (``ros/runtime/rclpy_internals.py``:
the wait set, a subscription's take), exercised against the installed rclpy: a release that
changes one fails here, by name, instead of the fast lane or the draining subscriptions
silently. In-process, one node, real middleware."""

from __future__ import annotations

import time

import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from contextlib import ExitStack  # noqa: E402

from std_msgs.msg import Float64MultiArray  # noqa: E402

from tensegrity_stiffness.ros.runtime.rclpy_internals import (  # noqa: E402
    SubscriptionWaitSet,
    parameter_override_names,
    take,
)


@pytest.fixture
def node():
    context = rclpy.context.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('rclpy_internals_test', context=context)
    yield node
    node.destroy_node()
    rclpy.shutdown(context=context)


def test_wait_set_reports_ready_subscriptions_and_take_reads_them_in_order(node) -> None:
    received: list = []
    group = rclpy.callback_groups.MutuallyExclusiveCallbackGroup()
    sub = node.create_subscription(Float64MultiArray, 'internals', received.append, 10,
                                   callback_group=group)
    idle = node.create_subscription(Float64MultiArray, 'internals_idle', received.append, 10,
                                    callback_group=group)
    guard = node.create_guard_condition(lambda: None)
    pub = node.create_publisher(Float64MultiArray, 'internals', 10)
    with ExitStack() as handles:
        for entity in (sub, idle, guard):
            handles.enter_context(entity.handle)
        handles.enter_context(node.context.handle)
        wait_set = SubscriptionWaitSet([sub, idle], [guard], node.context)
        assert take(sub) is None
        deadline = time.monotonic() + 20.0
        while pub.get_subscription_count() == 0:  # discovery within the process
            assert time.monotonic() < deadline, 'the publisher never matched'
            time.sleep(0.01)
        for value in (1.0, 2.0, 3.0):
            pub.publish(Float64MultiArray(data=[value]))
        ready: list = []
        while not ready:
            assert time.monotonic() < deadline, 'no message within 20 s'
            ready = wait_set.wait(100_000_000)
        assert ready == [sub]
        values = []
        while len(values) < 3:
            msg = take(sub)
            if msg is None:
                assert time.monotonic() < deadline, f'took {values} of 3'
                wait_set.wait(100_000_000)
                continue
            assert isinstance(msg, Float64MultiArray)
            values.append(msg.data[0])
        assert values == [1.0, 2.0, 3.0]
        assert take(sub) is None
        # a triggered guard condition ends a wait with no subscription ready
        guard.trigger()
        start = time.monotonic()
        assert wait_set.wait(5_000_000_000) == []
        assert time.monotonic() - start < 5.0
    assert received == []  # nothing went through a callback


def test_parameter_override_names_are_the_files_and_the_command_lines(tmp_path) -> None:
    """The names a node's parameter file (its own and ``/**``) and ``-p`` set, declared or not;
    not another node's."""
    params = tmp_path / 'p.yaml'
    params.write_text('/**:\n  ros__parameters:\n    joint:\n      stifness: [1.0]\n'
                      'other_node:\n  ros__parameters:\n    elsewhere: 1\n')
    context = rclpy.context.Context()
    rclpy.init(context=context, args=['--ros-args', '--params-file', str(params),
                                      '-p', 'qos.depth:=5'])
    node = rclpy.create_node('overrides_test', context=context)
    try:
        assert parameter_override_names(node) == ['joint.stifness', 'qos.depth']
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
