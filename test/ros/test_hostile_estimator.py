"""estimator_node under hostile input (issue #42), a real rclpy node in-process (its handlers
called as the executor calls them, so every step is synchronous and the test bounded): one
bad reading on an input that does not trigger estimates (a negative string length, an
asymmetric pose covariance) is dropped by name and spoils nothing else; poses out of the
joint's reach (1 m, 10 m, 1e308 m) are left out by name, not fused."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from geometry_msgs.msg import PoseWithCovarianceStamped  # noqa: E402
from rclpy.context import Context  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.estimation_trials import TENSION_STD, truth_from_model  # noqa: E402

from tensegrity_stiffness.ros import conversions  # noqa: E402
from tensegrity_stiffness.ros.estimator_node import EstimatorNode  # noqa: E402


def pose_message(T: np.ndarray, covariance: np.ndarray, frame: str
                 ) -> PoseWithCovarianceStamped:
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame
    msg.pose.pose = conversions.transform_to_pose(T)
    msg.pose.covariance = covariance.ravel().tolist()
    return msg


def test_one_bad_reading_spoils_only_itself() -> None:
    context = Context()
    rclpy.init(context=context)
    node = EstimatorNode(context=context)
    try:
        model = node._settings.model
        frame = node._settings.link1_frame
        truth = truth_from_model(model, model.initial_screw)
        rng = np.random.default_rng(7)

        def tensions() -> None:
            noisy = truth.tensions + rng.normal(scale=TENSION_STD, size=model.n_strings)
            node._on_tensions(Float64MultiArray(data=noisy.tolist()))

        tensions()
        assert node._estimates == 1, node.reporter.rejected
        lengths = np.full(model.n_strings, np.nan)
        lengths[0] = -0.01  # a negative string length on a non-trigger input
        node._on_lengths(Float64MultiArray(data=lengths.tolist()))
        assert node.reporter.rejected.get('~/measured_lengths') == 1
        asymmetric = np.diag([1e-6] * 6)
        asymmetric[0, 1] = 5e-7
        node._on_pose(pose_message(truth.transform, asymmetric, frame))
        for distance in (1.0, 10.0, 1e308):  # out of reach: left out by name
            far = truth.transform.copy()
            far[0, 3] += distance
            node._on_pose(pose_message(far, np.diag([1e-6] * 6), frame))
        assert node.reporter.rejected.get('~/measured_pose') == 4
        for _ in range(5):  # every later estimate still made (was: all failed until aged out)
            tensions()
        assert node._estimates == 6, node.reporter.rejected
        assert '~/measured_tensions' not in node.reporter.rejected
    finally:
        node.close()
        node.destroy_node()
        rclpy.shutdown(context=context)


def test_one_bad_reading_spoils_only_itself_on_a_spine() -> None:
    """The same on spine_estimator_node (its readings judged on arrival by
    check_spine_reading): a negative length of one joint, an asymmetric tip pose covariance and
    tip poses out of the spine's reach are dropped by name; every later estimate is made."""
    from tensegrity_stiffness.ros.spine_estimator_node import SpineEstimatorNode

    context = Context()
    rclpy.init(context=context)
    node = SpineEstimatorNode(context=context)
    try:
        chain = node._settings.chain
        frame = node._settings.base_frame
        screws = chain.unloaded_screws()
        tensions = np.concatenate(list(chain.evaluate(screws).tensions))
        rng = np.random.default_rng(7)

        def measured() -> None:
            noisy = tensions + rng.normal(scale=TENSION_STD, size=tensions.size)
            node._on_tensions(Float64MultiArray(data=noisy.tolist()))

        measured()
        assert node._estimates == 1, node.reporter.rejected
        lengths = np.full(tensions.size, np.nan)
        lengths[-1] = -0.01  # the last joint's last string
        node._on_lengths(Float64MultiArray(data=lengths.tolist()))
        assert node.reporter.rejected.get('~/measured_lengths') == 1
        T = chain.tip_transform(screws)
        asymmetric = np.diag([1e-6] * 6)
        asymmetric[0, 1] = 5e-7
        node._on_pose(pose_message(T, asymmetric, frame))
        for distance in (10.0, 1e308):
            far = T.copy()
            far[0, 3] += distance
            node._on_pose(pose_message(far, np.diag([1e-6] * 6), frame))
        assert node.reporter.rejected.get('~/measured_pose') == 3
        for _ in range(3):
            measured()
        assert node._estimates == 4, node.reporter.rejected
        assert '~/measured_tensions' not in node.reporter.rejected
    finally:
        node.close()
        node.destroy_node()
        rclpy.shutdown(context=context)
