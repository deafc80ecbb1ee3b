"""estimator_node in-process (as test_node_inprocess.py does for stiffness_node): the std of K_c
is computed only while ``~/cartesian_stiffness_std`` has a subscriber and
``estimation.stiffness_std`` is on; the node asks once per input, before it computes, and
publishes what that answer says, so a std is published only when it was computed."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from rclpy.context import Context  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.estimation_trials import TENSION_STD, truth_from_model  # noqa: E402

from tensegrity_stiffness.nodes.estimator_node import EstimatorInput, Reading  # noqa: E402
from tensegrity_stiffness.ros.estimator_node import EstimatorNode  # noqa: E402

#: Seconds to wait for the middleware to match (or unmatch) a subscription.
MATCH_TIMEOUT_S = 5.0


def wait_for_count(publisher, wanted: int) -> None:
    deadline = time.monotonic() + MATCH_TIMEOUT_S
    while publisher.get_subscription_count() != wanted:
        assert time.monotonic() < deadline, f'subscription count never became {wanted}'
        time.sleep(0.02)


def test_std_of_the_cartesian_stiffness_only_for_a_subscriber():
    context = Context()
    rclpy.init(context=context)
    node = EstimatorNode(context=context)
    listener = rclpy.create_node('std_listener', context=context)
    try:
        settings = node._settings
        assert settings.stiffness_std
        model = settings.model
        truth = truth_from_model(model, model.initial_screw)
        now = time.monotonic()
        tensions = truth.tensions + np.random.default_rng(0).normal(
            scale=TENSION_STD, size=model.n_strings)
        snapshot = EstimatorInput({'measured_tensions': Reading(tensions, now)}, now,
                                  truth.screw)
        k = node.stiffness_std_index()  # the std among the outputs (stamped K, K_c after it)
        std_publisher = node._output_publishers[k]
        assert std_publisher.topic_name.endswith('/cartesian_stiffness_std')

        unheard = node._outputs(settings, snapshot, node._wanted_outputs(settings))
        assert not unheard.stiffness_std
        assert np.all(np.isnan(unheard.estimate.cartesian_stiffness_std))

        subscription = listener.create_subscription(
            Float64MultiArray, std_publisher.topic_name, lambda _: None, 10)
        wait_for_count(std_publisher, 1)
        wanted = node._wanted_outputs(settings)
        heard = node._outputs(settings, snapshot, wanted)
        assert heard.stiffness_std
        assert np.all(np.isfinite(heard.estimate.cartesian_stiffness_std))
        assert wanted[k]
        # with estimation.stiffness_std off: neither computed nor published, subscriber or not
        assert not node._wanted_outputs(replace(settings, stiffness_std=False))[k]

        listener.destroy_subscription(subscription)
        wait_for_count(std_publisher, 0)
        assert not node._outputs(settings, snapshot, node._wanted_outputs(settings)).stiffness_std
    finally:
        listener.destroy_node()
        node.close()
        node.destroy_node()
        rclpy.shutdown(context=context)
