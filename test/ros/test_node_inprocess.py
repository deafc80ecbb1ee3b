"""stiffness_node's parameters in-process (as rclpy's own tests do): the node is built with
``parameter_overrides`` in this process and its declarations, descriptors and whole-set
validation are checked through the node's API, with no separate process or middleware traffic."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from rclpy.context import Context  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

from tensegrity_stiffness.nodes.stiffness_node import STIFFNESS_NODE_PARAMETERS  # noqa: E402
from tensegrity_stiffness.ros.stiffness_node import StiffnessNode  # noqa: E402


@pytest.fixture(scope='module')
def node():
    context = Context()
    rclpy.init(context=context)
    node = StiffnessNode(context=context, parameter_overrides=[
        Parameter('qos.depth', value=7), Parameter('markers.max_rate', value=10.0),
        Parameter('realtime.fast_lane', value=False)])
    yield node
    node.close()
    node.destroy_node()
    rclpy.shutdown(context=context)


def test_overrides_win_over_the_table(node):
    assert node.get_parameter('qos.depth').value == 7
    assert node._settings.marker_period == pytest.approx(0.1)
    assert node.get_parameter('planar.K1').value == 100.0  # the table's default


def test_every_descriptor_comes_from_the_table(node):
    for spec in STIFFNESS_NODE_PARAMETERS:
        d = node.describe_parameter(spec.name)
        assert d.description == spec.description, spec.name
        assert d.read_only == spec.read_only, spec.name
        assert d.additional_constraints == spec.constraints, spec.name
        if spec.range is not None and spec.type == 'double':
            r = d.floating_point_range[0]
            assert (r.from_value, r.to_value) == spec.range, spec.name
        elif spec.range is not None and spec.type == 'int':
            r = d.integer_range[0]
            assert (r.from_value, r.to_value) == spec.range, spec.name


def test_a_read_only_parameter_is_refused_for_that_reason(node):
    result = node.set_parameters([Parameter('qos.depth', value=3)])[0]
    assert not result.successful and 'read-only' in result.reason, result.reason
    assert node.get_parameter('qos.depth').value == 7


def test_a_change_is_validated_as_a_whole_and_the_old_set_stays(node):
    generation = node._settings.generation
    model = node._settings.model
    result = node.set_parameters([Parameter('joint.stiffness', value=[-1.0] * 12)])[0]
    assert not result.successful and 'joint.stiffness must be > 0' in result.reason
    # two parameters that only make sense together: 11 strings, atomically
    names = list(model.string_names[:11])
    result = node.set_parameters_atomically([
        Parameter('joint.string_names', value=names),
        Parameter('joint.rest_lengths', value=list(model.rest_lengths[:11]))])
    assert not result.successful  # the node-name lists still have 12 entries
    assert node._settings.generation == generation and node._settings.model is model
    result = node.set_parameters([Parameter('planar.K2', value=12.5)])[0]
    assert result.successful, result.reason
    assert node._settings.planar.K2 == 12.5 and node._settings.generation == generation + 1
    # the topic rest lengths survive a change of another parameter
    np.testing.assert_array_equal(node._settings.model.rest_lengths, model.rest_lengths)


def test_a_range_from_the_table_is_enforced(node):
    result = node.set_parameters([Parameter('markers.max_rate', value=-1.0)])[0]
    assert not result.successful
    assert node._settings.marker_period == pytest.approx(0.1)


def test_a_publish_that_races_the_shutdown_is_a_quiet_stop():
    """The race of SIGTERM, made deterministic: the context is shut down (as rclpy's signal
    handler does, on its own thread) while a callback is about to publish. The publish fails
    with rclpy's ``RCLError: ... publisher's context is invalid``; the guarded callback (here
    the diagnostics timer's) takes it as the stop: nothing counted, no internal error logged.
    The same error while the context is up is still an internal error."""
    from diagnostic_msgs.msg import DiagnosticArray

    from tensegrity_stiffness.ros.runtime.reporting import Reporter

    context = Context()
    rclpy.init(context=context)
    node = StiffnessNode(context=context, parameter_overrides=[
        Parameter('realtime.fast_lane', value=False)])
    try:
        node._publish_diagnostics()  # publishes while up
        assert node.reporter.rejected == {}
        rclpy.shutdown(context=context)
        with pytest.raises(RuntimeError, match="publisher's context is invalid"):
            node._pub_diagnostics.publish(DiagnosticArray())
        node._publish_diagnostics()  # the race: a publish after the shutdown
        assert node.reporter.rejected == {}
        # without the context's state the same failure is a fault
        blind = Reporter(node.get_logger())
        try:
            node._pub_diagnostics.publish(DiagnosticArray())
        except RuntimeError as exc:
            blind.internal_error('diagnostics', exc)
        assert blind.rejected == {'diagnostics internal error': 1}
    finally:
        node.close()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_the_fast_lane_publishing_into_the_shutdown_stops_quietly():
    """The race as SIGTERM makes it, through the fast lane, made deterministic: the context is
    shut down (as rclpy's signal handler does on its own thread) between the lane's check of the
    context and a handler's publish, here by the handler itself on its fifth message. The
    publish fails with ``RCLError: ... publisher's context is invalid``, which the node's
    reporter takes as the stop: nothing is counted as an internal error and the lane's thread
    ends without an exception of its own."""
    import threading

    from std_msgs.msg import Float64MultiArray

    from tensegrity_stiffness.ros.runtime.fast_lane import FastLane
    from tensegrity_stiffness.ros.runtime.reporting import Reporter

    context = Context()
    rclpy.init(context=context)
    node = rclpy.create_node('lane_shutdown_test', context=context)
    reporter = Reporter(node.get_logger(), context=context)
    seen: list[BaseException] = []
    thread_errors: list[BaseException] = []
    previous_hook = threading.excepthook
    threading.excepthook = lambda args: thread_errors.append(args.exc_value)

    def on_error(topic: str, exc: BaseException) -> None:
        seen.append(exc)
        reporter.internal_error(topic, exc)

    lane = FastLane(node, on_error)
    try:
        publisher = node.create_publisher(Float64MultiArray, 'lane_loop', 10)
        handled: list[Float64MultiArray] = []
        stopped = threading.Event()

        def handler(msg: Float64MultiArray) -> None:
            handled.append(msg)
            if len(handled) == 5:
                rclpy.shutdown(context=context)  # the signal lands here
                stopped.set()
            publisher.publish(msg)  # feeds the lane (and is refused after the shutdown)

        lane.create_subscription(Float64MultiArray, 'lane_loop', handler, 10)
        lane.start()
        publisher.publish(Float64MultiArray(data=[1.0]))
        assert stopped.wait(20.0)
        lane.stop(timeout=10.0)
        assert seen, 'the shutdown did not land on a publish'
        assert all("context is invalid" in str(exc) for exc in seen), seen
        assert reporter.rejected == {}
        assert thread_errors == []
    finally:
        threading.excepthook = previous_hook
        lane.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
