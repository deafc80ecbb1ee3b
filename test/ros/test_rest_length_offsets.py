"""``joint.rest_length_offsets`` end to end: a commanded rest length c on ``~/rest_lengths`` is
the model's c + d in ``stiffness_node`` (real node, real middleware); the settings check it."""

from __future__ import annotations

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.shared_parameters import rest_length_offsets
from tensegrity_stiffness.nodes.stiffness_node import (
    STIFFNESS_NODE_PARAMETERS,
    joint_node_settings,
)

CONFIG = REPO / 'config' / 'default_joint.yaml'


def test_offsets_are_checked_and_broadcast() -> None:
    values = {spec.name: spec.default for spec in STIFFNESS_NODE_PARAMETERS}
    assert np.array_equal(rest_length_offsets(values, 12), np.zeros(12))
    values['joint.rest_length_offsets'] = [1e-3]
    assert np.array_equal(rest_length_offsets(values, 12), np.full(12, 1e-3))
    values['joint.rest_length_offsets'] = [1e-3] * 5
    with pytest.raises(ValueError, match=r'rest_length_offsets must have 1 or 12 values'):
        joint_node_settings(values)


@pytest.mark.ros
def test_commanded_rest_lengths_get_the_offsets_in_the_node() -> None:
    pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
    from std_msgs.msg import Float64MultiArray
    from support.ros_harness import NodeProcess, RosClient, repeat_until, unique_namespace

    from tensegrity_stiffness.ros.runtime.topics import LATCHED_QOS

    model = JointModel.from_yaml(CONFIG)
    d = np.linspace(-1e-3, 1e-3, model.n_strings)
    commanded = model.rest_lengths * 0.98
    xi = model.initial_screw + np.array([0.02, 0.0, -0.01, 0.0, 3e-4, 0.0])
    expected = model.evaluate(xi, commanded + d).tensions
    without = model.evaluate(xi, commanded).tensions
    assert np.max(np.abs(expected - without)) > 1e-3  # the offsets matter here
    ns = unique_namespace('offsets')
    proc = NodeProcess(ns, CONFIG, extra_args=[
        '-p', f'joint.rest_length_offsets:={[float(v) for v in d]}'])
    ros = RosClient('offsets_test')
    try:
        base = f'{ns}/stiffness_node'
        tensions = ros.subscribe(Float64MultiArray, f'{base}/string_tensions')
        rest = ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED_QOS)
        screw = ros.publisher(Float64MultiArray, f'{base}/screw')
        rest.publish(Float64MultiArray(data=commanded.tolist()))
        ros.wait_for_subscribers(screw)
        msg = repeat_until(
            lambda: screw.publish(Float64MultiArray(data=xi.tolist())),
            lambda: next((m for m in tensions.messages
                          if np.allclose(m.data, expected, rtol=0, atol=1e-12)), None),
            explain=lambda: f'last {tensions.messages[-1].data if len(tensions) else None}')
        assert msg is not None
    finally:
        ros.close()
        code = proc.stop()
    assert code == 0, proc.log()
